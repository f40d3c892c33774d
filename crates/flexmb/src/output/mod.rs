//! Results on disk: the files of one run in its output directory.
//!
//! Contract (stable, documented in README.md, section "Outputs"):
//! * A run owns the files named in [`RESULT_FILES`] (and the temporary file of the summary)
//!   in its output directory: [`OutputDir::prepare`] removes them when the run starts, so
//!   every result file in the directory afterwards was written by this run. Other files are
//!   left alone.
//! * `sensors.csv`: header `time,<sensor names>` (`load_factor` for a static analysis), one
//!   row per output step; `nodes.csv`: `time,node,x,y,z,qw,qx,qy,qz` for every node at every
//!   output step; `beams.csv` (models with beams): `time,element,<6 strains>,<6 stress
//!   resultants>` per beam element and output step. The files are written on the run's
//!   writer thread ([`writer`]): the rows of one output step go to the operating system in one
//!   write per file, and the end of the run waits for every output step handed over, so a
//!   run that fails or is interrupted keeps every completed output step.
//! * Numbers in the CSV files are written in the shortest form that reads back to the same
//!   `f64` bit for bit (plain decimals for magnitudes in `[1e-5, 1e16)` and zero, scientific
//!   notation such as `1.7976931348623157e308` otherwise); a non-finite value would be written
//!   `NaN`, `inf` or `-inf`.
//! * `summary.json` is replaced atomically (written to a temporary file in the same
//!   directory, synced, then renamed over the old one): a reader, a kill or a full disk never
//!   leaves a partial summary. Its `status` is [`Status`]: `running` from the start, then
//!   `ok`, `failed` (with `error_kind` and `error`), `interrupted` or `incomplete`.
//! * The end of a run is always recorded: the first summary of a run (status `running`) is
//!   written after room for the last one is kept, a file of [`SUMMARY_ROOM`] bytes or more
//!   (`.summary.json.room`, filled with bytes that do not compress). The last summary is
//!   written in its place (the file is truncated, which frees its blocks, written and renamed
//!   over `summary.json`): it needs no new inode and no more blocks than the room freed, so
//!   a disk that filled during the run cannot keep it from being written, and it is cut to
//!   fit ([`Summary::json_within`]).
//! * A run can be ended at once from another thread (a second signal,
//!   [`OutputDir::end_now`]): the summary then says `interrupted` with the output steps the
//!   result files hold, the files' writer having been stopped between two output steps.

pub mod snapshot;
pub mod writer;

use crate::solve::observe::Work;
use serde::Serialize;
pub use snapshot::Snapshot;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{Seek, SeekFrom, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, TryLockError};
use std::time::{Duration, Instant};

/// The summary of the run.
pub const SUMMARY_FILE: &str = "summary.json";
/// Sensor values, one row per output step.
pub const SENSORS_FILE: &str = "sensors.csv";
/// Position and orientation of every node, per output step.
pub const NODES_FILE: &str = "nodes.csv";
/// Strains and stress resultants of every beam element, per output step.
pub const BEAMS_FILE: &str = "beams.csv";
/// The memory of a dynamic run, to resume it (`flexmb run --resume DIR`).
pub const CHECKPOINT_FILE: &str = "checkpoint.json";
/// The HDF5 results file (written by the `flexmb-results` crate's store).
pub const RESULTS_H5_FILE: &str = "results.h5";
/// The plot of the sensors a run draws at its end (`flexmb run`).
pub const SUMMARY_PLOT_FILE: &str = "summary.png";
/// The browser animation of a run (`flexmb run --view`).
pub const VIEW_FILE: &str = "view.html";
/// Every result file a run may write. A run removes all of them from its output directory
/// when it starts (a resumed run keeps them and goes on writing).
pub const RESULT_FILES: [&str; 13] = [
    SUMMARY_FILE,
    SENSORS_FILE,
    NODES_FILE,
    BEAMS_FILE,
    RESULTS_H5_FILE,
    SUMMARY_PLOT_FILE,
    VIEW_FILE,
    CHECKPOINT_FILE,
    GRADIENTS_JSON_FILE,
    GRADIENTS_CSV_FILE,
    GRADIENT_CHECK_FILE,
    OPTIMIZATION_CSV_FILE,
    OPTIMIZATION_JSON_FILE,
];
/// `flexmb optimize`: one row per improvement, `evaluation,criterion,<parameters>,d/d
/// <parameters>` ([`crate::sensitivity::report::optimization_csv`]).
pub const OPTIMIZATION_CSV_FILE: &str = "optimization.csv";
/// `flexmb optimize`: the criterion, the status, the iterations and runs, the first and last
/// improvements.
pub const OPTIMIZATION_JSON_FILE: &str = "optimization.json";
/// The criteria and their gradients of `flexmb sensitivity` (JSON).
pub const GRADIENTS_JSON_FILE: &str = "gradients.json";
/// The same as CSV: `criterion,parameter,value,gradient,scaled_gradient,fd_step`.
pub const GRADIENTS_CSV_FILE: &str = "gradients.csv";
/// `flexmb sensitivity --check`: the adjoint against finite differences.
pub const GRADIENT_CHECK_FILE: &str = "gradient_check.csv";
/// Where a new summary is written before it is renamed over [`SUMMARY_FILE`].
const SUMMARY_TEMP_FILE: &str = ".summary.json.tmp";
/// Where a new checkpoint is written before it is renamed over [`CHECKPOINT_FILE`].
const CHECKPOINT_TEMP_FILE: &str = ".checkpoint.json.tmp";
/// The room kept for the last summary of a run, in which it is written.
const SUMMARY_ROOM_FILE: &str = ".summary.json.room";
/// Least size of the room kept for the last summary \[bytes\]: one page of memory (a
/// tmpfs) or one block of most file systems, more than a summary needs beyond the first
/// one but for its warnings and error, which are cut to fit.
pub const SUMMARY_ROOM: u64 = 4096;
/// The room is at least this much more than the first summary \[bytes\]: the counts, the
/// error kind and `verify` of the last one.
const SUMMARY_ROOM_MARGIN: u64 = 2048;

/// Why the results could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output path exists and is not a directory.
    #[error("{}: not a directory", path.display())]
    NotADirectory { path: PathBuf },
    /// A file system operation on `path` failed; `action` says which, e.g. "cannot write".
    #[error("{}: {action}: {source}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
}

impl OutputError {
    fn io<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(std::io::Error) -> Self + 'a {
        move |source| OutputError::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    }
}

/// The output directory of a run, taken over by [`OutputDir::prepare`]. Its clones (the
/// run's threads, a signal handler's) share what the run has recorded there: the summary
/// written last and how far the result files go.
#[derive(Clone, Debug)]
pub struct OutputDir {
    path: PathBuf,
    shared: Arc<Shared>,
}

/// What the clones of an [`OutputDir`] share.
#[derive(Debug, Default)]
struct Shared {
    record: Mutex<Record>,
    /// Held by the run's writer thread while it writes a batch of output steps
    /// ([`OutputDir::lock_files`]).
    files: Mutex<()>,
    /// The run has been ended by [`OutputDir::end_now`]: the summary and the result files
    /// are no longer written.
    ended: AtomicBool,
}

/// What a run has recorded in its directory.
#[derive(Debug, Default)]
struct Record {
    /// The summary written last (`None` before the first).
    summary: Option<Summary>,
    /// When the first summary with status `running` was written.
    started: Option<Instant>,
    /// How far the result files go.
    reached: Reached,
}

/// A run ended at once by [`OutputDir::end_now`]: the summary written, if any, and the run's
/// writer thread held (between two batches) until this is dropped.
pub struct EndedNow<'a> {
    pub summary: Result<Option<Summary>, OutputError>,
    _writer: Option<MutexGuard<'a, ()>>,
}

/// How far the result files of a run go: the output steps the writer thread last made
/// durable in every file, and where the run stood at the last of them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Reached {
    /// Output steps in every result file.
    pub rows: usize,
    /// The first column (time or load factor) of the last of them.
    pub at: f64,
    /// The work done up to it.
    pub work: Work,
    /// Wall time the run's thread had spent on output up to it \[s\].
    pub output_seconds: f64,
}

impl OutputDir {
    /// Creates the directory (and its parents) if needed and removes the result files of an
    /// earlier run ([`RESULT_FILES`] and the summary's temporary file); other files stay.
    pub fn prepare(path: &Path) -> Result<Self, OutputError> {
        if path.exists() && !path.is_dir() {
            return Err(OutputError::NotADirectory {
                path: path.to_path_buf(),
            });
        }
        std::fs::create_dir_all(path)
            .map_err(OutputError::io(path, "cannot create the output directory"))?;
        let dir = Self::at(path);
        for name in RESULT_FILES.iter().chain([
            &SUMMARY_TEMP_FILE,
            &SUMMARY_ROOM_FILE,
            &CHECKPOINT_TEMP_FILE,
        ]) {
            let file = dir.file(name);
            match std::fs::remove_file(&file) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(OutputError::io(&file, "cannot remove the earlier result")(
                        e,
                    ))
                }
                _ => {}
            }
        }
        Ok(dir)
    }

    /// The output directory of an earlier run, to resume it: nothing is removed.
    pub fn reopen(path: &Path) -> Result<Self, OutputError> {
        if !path.is_dir() {
            return Err(OutputError::NotADirectory {
                path: path.to_path_buf(),
            });
        }
        Ok(Self::at(path))
    }

    fn at(path: &Path) -> Self {
        Self {
            path: path.to_path_buf(),
            shared: Arc::default(),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Path of the file `name` in the directory.
    pub fn file(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// Replaces `summary.json` atomically: the JSON goes to a temporary file in the same
    /// directory, is synced to the disk and renamed over the old summary (the directory is
    /// then synced too), so `summary.json` is always either the old or the new summary.
    ///
    /// A summary with status `running` is written after room is kept for the last one (a
    /// file of at least [`SUMMARY_ROOM`] bytes and `SUMMARY_ROOM_MARGIN` more than this
    /// summary; an error if it cannot be kept, and then nothing is written). Any other
    /// summary is the last: it is written in that room when there is one, cut to fit.
    /// After [`OutputDir::end_now`] nothing is written: the run's end is recorded.
    pub fn write_summary(&self, summary: &Summary) -> Result<(), OutputError> {
        let mut record = lock(&self.shared.record);
        if self.shared.ended.load(Ordering::SeqCst) {
            return Ok(());
        }
        self.record_summary(&mut record, summary)
    }

    /// [`OutputDir::write_summary`], the record held.
    fn record_summary(&self, record: &mut Record, summary: &Summary) -> Result<(), OutputError> {
        if summary.status == Status::Running {
            let text = summary.json();
            self.keep_room(text.len() as u64 + SUMMARY_ROOM_MARGIN)?;
            self.replace(SUMMARY_FILE, SUMMARY_TEMP_FILE, &text)?;
            record.started.get_or_insert_with(Instant::now);
        } else {
            match std::fs::metadata(self.file(SUMMARY_ROOM_FILE)) {
                Ok(room) => {
                    let text = summary.json_within(room.len() as usize);
                    self.replace(SUMMARY_FILE, SUMMARY_ROOM_FILE, &text)?
                }
                Err(_) => self.replace(SUMMARY_FILE, SUMMARY_TEMP_FILE, &summary.json())?,
            }
        }
        record.summary = Some(summary.clone());
        Ok(())
    }

    /// Makes the room for the last summary at least `bytes` (rounded up to
    /// [`SUMMARY_ROOM`]): written, so that the file system allocates it, with bytes that do
    /// not compress (a compressing file system would keep little room for zeros). A room
    /// that cannot be made or grown is taken back.
    fn keep_room(&self, bytes: u64) -> Result<(), OutputError> {
        let path = self.file(SUMMARY_ROOM_FILE);
        let size = bytes.next_multiple_of(SUMMARY_ROOM);
        let had = std::fs::metadata(&path).map_or(None, |m| Some(m.len()));
        let from = had.unwrap_or(0);
        if from >= size {
            return Ok(());
        }
        // xorshift64: a fixed sequence of bytes that no compressor shortens
        let mut x = 0x9e37_79b9_7f4a_7c15_u64;
        let fill: Vec<u8> = (from..size)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x as u8
            })
            .collect();
        let written = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .and_then(|mut f| f.write_all(&fill));
        written.map_err(|e| {
            let _ = match had {
                Some(len) => File::options()
                    .write(true)
                    .open(&path)
                    .and_then(|f| f.set_len(len)),
                None => std::fs::remove_file(&path),
            };
            OutputError::io(&path, "cannot keep room for the last summary")(e)
        })
    }

    /// Holds the result files for the run's writer thread while it writes a batch of output
    /// steps; `None` once the run has been ended by [`OutputDir::end_now`] (nothing more is
    /// written).
    pub fn lock_files(&self) -> Option<MutexGuard<'_, ()>> {
        let files = lock(&self.shared.files);
        (!self.shared.ended.load(Ordering::SeqCst)).then_some(files)
    }

    /// Records how far the result files go, once the writer has made it durable.
    pub fn files_reached(&self, reached: Reached) {
        lock(&self.shared.record).reached = reached;
    }

    /// Ends the run at once, from another thread (a second signal; the caller ends the
    /// process next). Waits at most `wait` for the writer thread to finish its batch of
    /// output steps and stops it there, then writes the summary of a run stopped where its
    /// files stand: status `interrupted`, `outputs`, `t_reached` and the counts of the last
    /// output step in the files, `note` among the warnings (with a word when the writer
    /// could not be stopped in time: the files may then hold more steps than `outputs`, the
    /// last perhaps incomplete). Its `summary` is that summary, or `None` when the run had
    /// not written its first summary yet or had already written its last; the run's writer
    /// (and so the run's own end) is held until it is dropped.
    pub fn end_now(&self, note: &str, wait: Duration) -> EndedNow<'_> {
        let deadline = Instant::now() + wait;
        let files = loop {
            match self.shared.files.try_lock() {
                Ok(files) => break Some(files),
                Err(TryLockError::Poisoned(files)) => break Some(files.into_inner()),
                Err(TryLockError::WouldBlock) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(TryLockError::WouldBlock) => break None,
            }
        };
        let mut record = lock(&self.shared.record);
        let stopped = files.is_some();
        let mut ended = EndedNow {
            summary: Ok(None),
            _writer: files,
        };
        let Some(mut summary) = record.summary.clone() else {
            return ended;
        };
        if summary.status != Status::Running {
            return ended;
        }
        self.shared.ended.store(true, Ordering::SeqCst);
        let r = record.reached;
        summary.status = Status::Interrupted;
        summary.outputs = r.rows;
        summary.t_reached = r.at;
        summary.count(r.work);
        summary.wall_seconds = record.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
        summary.solve_seconds = (summary.wall_seconds - r.output_seconds).max(0.0);
        summary.warnings.push(if stopped {
            note.to_string()
        } else {
            format!("{note} (the result files were still being written: they may hold more output steps than `outputs`, the last perhaps incomplete)")
        });
        ended.summary = self
            .record_summary(&mut record, &summary)
            .map(|()| Some(summary));
        ended
    }

    /// Replaces `checkpoint.json` atomically, as [`OutputDir::write_summary`] does.
    pub fn write_checkpoint(&self, text: &str) -> Result<(), OutputError> {
        self.replace(CHECKPOINT_FILE, CHECKPOINT_TEMP_FILE, text)
    }

    /// Replaces the file `name` atomically, as [`OutputDir::write_summary`] does.
    pub fn write_file(&self, name: &str, text: &str) -> Result<(), OutputError> {
        self.replace(name, &format!(".{name}.tmp"), text)
    }

    /// Writes `text` to `name` through the temporary file `temp`, synced and renamed.
    fn replace(&self, name: &str, temp: &str, text: &str) -> Result<(), OutputError> {
        let temp = self.file(temp);
        let target = self.file(name);
        let written = File::create(&temp)
            .and_then(|mut f| {
                f.write_all(text.as_bytes())?;
                f.sync_all()
            })
            .map_err(OutputError::io(&temp, "cannot write"));
        if let Err(e) = written {
            let _ = std::fs::remove_file(&temp);
            return Err(e);
        }
        std::fs::rename(&temp, &target).map_err(OutputError::io(&target, "cannot replace"))?;
        // The rename is durable once the directory is synced. Only some platforms can open a
        // directory for syncing, and the summary is complete without it: errors are ignored.
        if let Ok(dir) = File::open(&self.path) {
            let _ = dir.sync_all();
        }
        Ok(())
    }
}

/// The value of a mutex, also when a thread panicked holding it (what it guards stays
/// consistent: a summary, counts).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Appends `x` to `out` in the shortest decimal form that parses back to the same bits:
/// plain for zero and magnitudes in `[1e-5, 1e16)`, scientific otherwise; `NaN`, `inf` and
/// `-inf` for non-finite values.
pub fn push_number(out: &mut String, x: f64) {
    if !x.is_finite() {
        write!(out, "{x}").expect("writing into a String cannot fail");
        return;
    }
    // Ryu prints the shortest round-trip digits, plain for magnitudes in [1e-5, 1e16) and
    // scientific otherwise, as `{}` and `{:e}` would, several times faster; a whole number
    // keeps a ".0" that `{}` leaves out, and a value halfway between two shortest decimals
    // gets the even last digit where std rounds up (both read back to the same bits).
    let mut buffer = ryu::Buffer::new();
    let text = buffer.format_finite(x);
    out.push_str(text.strip_suffix(".0").unwrap_or(text));
}

/// A CSV file written one output step at a time: the rows of a step are collected in memory
/// and handed to the operating system in one write by [`CsvFile::commit`]. A write that
/// fails part way (a full disk) is cut back, so the file ends with the last complete step.
struct CsvFile {
    file: File,
    path: PathBuf,
    pending: String,
    /// Bytes of the complete steps written.
    len: u64,
}

impl CsvFile {
    /// Creates the file and writes the header line.
    fn create(path: PathBuf, header: &str) -> Result<Self, OutputError> {
        let file = File::create(&path).map_err(OutputError::io(&path, "cannot create"))?;
        let mut csv = Self {
            file,
            path,
            pending: String::new(),
            len: 0,
        };
        csv.pending.push_str(header);
        csv.pending.push('\n');
        csv.commit()?;
        Ok(csv)
    }

    /// Starts a row with the number in the first column and, if given, a label.
    fn start_row(&mut self, first: f64, label: Option<&str>) {
        push_number(&mut self.pending, first);
        if let Some(label) = label {
            self.pending.push(',');
            self.pending.push_str(label);
        }
    }

    /// Appends one number to the row.
    fn field(&mut self, x: f64) {
        self.pending.push(',');
        push_number(&mut self.pending, x);
    }

    fn end_row(&mut self) {
        self.pending.push('\n');
    }

    /// Writes the pending rows in one write; after a failed write, cuts the file back to the
    /// complete steps before it (best effort: the write error is the one reported).
    fn commit(&mut self) -> Result<(), OutputError> {
        let result = self.file.write_all(self.pending.as_bytes());
        let written = self.pending.len() as u64;
        self.pending.clear();
        match result {
            Ok(()) => {
                self.len += written;
                Ok(())
            }
            Err(e) => {
                self.truncate(self.len);
                Err(OutputError::io(&self.path, "cannot write")(e))
            }
        }
    }

    /// Opens an existing file and cuts it back to its first `len` bytes (the steps a
    /// checkpoint recorded), to write on from there.
    fn reopen(path: PathBuf, len: u64) -> Result<Self, OutputError> {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .map_err(OutputError::io(&path, "cannot open"))?;
        let size = file
            .metadata()
            .map_err(OutputError::io(&path, "cannot read"))?
            .len();
        if size < len {
            return Err(OutputError::Io {
                path,
                action: "is shorter than the checkpoint recorded",
                source: std::io::Error::from(std::io::ErrorKind::UnexpectedEof),
            });
        }
        let mut csv = Self {
            file,
            path,
            pending: String::new(),
            len,
        };
        csv.file
            .set_len(len)
            .and_then(|()| csv.file.seek(SeekFrom::Start(len)).map(|_| ()))
            .map_err(OutputError::io(&csv.path, "cannot cut back"))?;
        Ok(csv)
    }

    /// Cuts the file back to `len` bytes and writes on from there (best effort).
    fn truncate(&mut self, len: u64) {
        let _ = self.file.set_len(len);
        let _ = self.file.seek(SeekFrom::Start(len));
        self.len = len;
        self.pending.clear();
    }
}

/// The CSV result files of a run: `sensors.csv`, `nodes.csv` and, for a model with beams,
/// `beams.csv`, written one output step at a time. The rows of a step are staged for every
/// file, then each file gets one write; if one of them fails (a full disk), every file is
/// cut back to the previous step, so the files always hold the same complete steps.
pub struct ResultFiles {
    sensors: CsvFile,
    nodes: CsvFile,
    beams: Option<CsvFile>,
    /// The labels of the rows of `nodes.csv` and `beams.csv`.
    node_names: Vec<String>,
    beam_names: Vec<String>,
}

impl ResultFiles {
    /// Creates the files in `dir` with their headers; the first column is named `first`
    /// (`time` or `load_factor`), the sensor columns `sensor_names`.
    pub fn create(
        dir: &OutputDir,
        first: &str,
        model: &crate::model::Model,
        sensor_names: &[String],
    ) -> Result<Self, OutputError> {
        let mut header = first.to_string();
        for n in sensor_names {
            header.push(',');
            header.push_str(n);
        }
        let sensors = CsvFile::create(dir.file(SENSORS_FILE), &header)?;
        let nodes = CsvFile::create(
            dir.file(NODES_FILE),
            &format!("{first},node,x,y,z,qw,qx,qy,qz"),
        )?;
        let beams = if model.beams.is_empty() {
            None
        } else {
            Some(CsvFile::create(
                dir.file(BEAMS_FILE),
                &format!("{first},element,{}", BEAM_QUANTITIES.join(",")),
            )?)
        };
        Ok(Self {
            sensors,
            nodes,
            beams,
            node_names: model.nodes.iter().map(|n| n.name.clone()).collect(),
            beam_names: model.beams.iter().map(|b| b.name.clone()).collect(),
        })
    }

    /// The files of an earlier run of `model`, cut back to the lengths
    /// [`ResultFiles::lengths`] returned when its checkpoint was written.
    pub fn reopen(
        dir: &OutputDir,
        model: &crate::model::Model,
        lengths: &[(String, u64)],
    ) -> Result<Self, OutputError> {
        let open = |name: &str| -> Result<Option<CsvFile>, OutputError> {
            lengths
                .iter()
                .find(|(n, _)| n == name)
                .map(|&(_, len)| CsvFile::reopen(dir.file(name), len))
                .transpose()
        };
        let missing = |name: &str| OutputError::Io {
            path: dir.file(name),
            action: "is not in the checkpoint",
            source: std::io::Error::from(std::io::ErrorKind::NotFound),
        };
        Ok(Self {
            sensors: open(SENSORS_FILE)?.ok_or_else(|| missing(SENSORS_FILE))?,
            nodes: open(NODES_FILE)?.ok_or_else(|| missing(NODES_FILE))?,
            beams: open(BEAMS_FILE)?,
            node_names: model.nodes.iter().map(|n| n.name.clone()).collect(),
            beam_names: model.beams.iter().map(|b| b.name.clone()).collect(),
        })
    }

    /// The name and length in bytes of each file (complete steps only).
    pub fn lengths(&self) -> Vec<(String, u64)> {
        let mut out = vec![
            (SENSORS_FILE.to_string(), self.sensors.len),
            (NODES_FILE.to_string(), self.nodes.len),
        ];
        if let Some(b) = &self.beams {
            out.push((BEAMS_FILE.to_string(), b.len));
        }
        out
    }

    /// Cuts every file back to the lengths [`ResultFiles::lengths`] returned (best effort):
    /// the steps written since then are taken back, e.g. when another result file could not
    /// take them.
    pub fn cut_back(&mut self, lengths: &[(String, u64)]) {
        let find = |name: &str| lengths.iter().find(|(n, _)| n == name).map(|&(_, l)| l);
        let files = [
            (SENSORS_FILE, Some(&mut self.sensors)),
            (NODES_FILE, Some(&mut self.nodes)),
            (BEAMS_FILE, self.beams.as_mut()),
        ];
        for (name, file) in files {
            if let (Some(f), Some(len)) = (file, find(name)) {
                f.truncate(len);
            }
        }
    }

    /// Appends the rows of one output step: the sensor values, the configuration of every
    /// node and the strains and stress resultants of every beam element.
    pub fn write_step(&mut self, s: &Snapshot) -> Result<(), OutputError> {
        let t = s.at;
        self.sensors.start_row(t, None);
        for &v in &s.sensors {
            self.sensors.field(v);
        }
        self.sensors.end_row();
        for ((name, x), q) in self.node_names.iter().zip(&s.position).zip(&s.orientation) {
            self.nodes.start_row(t, Some(name));
            for &v in x.iter().chain(q) {
                self.nodes.field(v);
            }
            self.nodes.end_row();
        }
        if let Some(beams) = self.beams.as_mut() {
            let states = s.beam_strain.iter().zip(&s.beam_stress);
            for (name, (strain, stress)) in self.beam_names.iter().zip(states) {
                beams.start_row(t, Some(name));
                for &v in strain.iter().chain(stress) {
                    beams.field(v);
                }
                beams.end_row();
            }
        }
        let mut files: Vec<&mut CsvFile> = [Some(&mut self.sensors), Some(&mut self.nodes)]
            .into_iter()
            .chain([self.beams.as_mut()])
            .flatten()
            .collect();
        let before: Vec<u64> = files.iter().map(|f| f.len).collect();
        for k in 0..files.len() {
            if let Err(e) = files[k].commit() {
                for (f, &len) in files.iter_mut().zip(&before) {
                    f.truncate(len);
                }
                return Err(e);
            }
        }
        Ok(())
    }
}

/// A results file written beside the CSV files, step by step, by a format that lives outside
/// the engine (the HDF5 file of `flexmb-results`): [`crate::driver::run_with`] creates one
/// per [`StoreFormat`] on the run's writer thread ([`writer`]), which calls it at every
/// output step after the CSV rows.
pub trait Store {
    /// Appends one output step (it may wait in memory until the next [`Store::sync`]).
    fn write(&mut self, snapshot: &Snapshot) -> Result<(), OutputError>;
    /// Records an accepted step of a dynamic run (called before the output of its time).
    fn step(&mut self, info: &crate::solve::StepInfo) -> Result<(), OutputError>;
    /// Puts every step received so far into the file and makes it durable (flushed: a run
    /// killed afterwards leaves a file with these steps), then says where the file stands,
    /// for a checkpoint: names and counts that [`StoreFormat::reopen`] gets back to go on
    /// from there. Called after every batch of output steps the writer thread takes, at
    /// every checkpoint and when the run ends, whatever its outcome.
    fn sync(&mut self) -> Result<Vec<(String, u64)>, OutputError>;
}

/// How to create (or reopen, for a resumed run) a [`Store`] in an output directory; called
/// on the run's writer thread.
pub trait StoreFormat: Sync {
    /// A new file for a run of `model`; `analysis` is `dynamic` or `static`.
    fn create(
        &self,
        dir: &OutputDir,
        model: &crate::model::Model,
        analysis: &str,
    ) -> Result<Box<dyn Store>, OutputError>;
    /// The file of an earlier run, cut back to the `marks` its checkpoint recorded (all the
    /// marks of the checkpoint: the store picks its own).
    fn reopen(
        &self,
        dir: &OutputDir,
        model: &crate::model::Model,
        marks: &[(String, u64)],
    ) -> Result<Box<dyn Store>, OutputError>;
}

/// Where a run stands, `status` in `summary.json`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// The run started and has not ended (or was killed without a chance to say so).
    #[default]
    Running,
    /// The analysis reached its end.
    Ok,
    /// The run stopped on an error; `error_kind` and `error` say which and why.
    Failed,
    /// The run was stopped from outside (a signal); results up to `t_reached` are complete.
    Interrupted,
    /// The analysis stopped at a limit of its settings before its end (`max_steps` load
    /// steps before the final load factor): nothing failed, results up to `t_reached` are
    /// complete, and a warning says which setting to raise.
    Incomplete,
}

/// What kind of error stopped a failed run, `error_kind` in `summary.json`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ErrorKind {
    /// The model file or the model was rejected before the first step (nothing was solved).
    Model,
    /// The analysis failed (Newton or a static step could not converge).
    Analysis,
    /// A result file could not be written.
    Output,
}

/// What `summary.json` holds.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Summary {
    pub status: Status,
    pub title: String,
    /// `dynamic` or `static`.
    pub analysis: String,
    pub group: String,
    /// End time \[s\] (dynamic) or final load factor (static).
    pub t_end: f64,
    /// Time \[s\] (or load factor) reached by the last completed step.
    pub t_reached: f64,
    pub steps: usize,
    pub newton_iterations: usize,
    pub rejected_steps: usize,
    pub factorizations: usize,
    /// Output steps written (rows of `sensors.csv`).
    pub outputs: usize,
    pub newton_iterations_per_step: f64,
    /// Wall time of the whole run including output \[s\].
    pub wall_seconds: f64,
    /// Wall time spent in the solver only \[s\]: `wall_seconds` less the time the run's
    /// thread spent on output (evaluating the sensors, handing the output steps to the
    /// writer thread, waiting for it at the end); the writer's work runs beside the solve.
    pub solve_seconds: f64,
    pub unknowns: usize,
    pub linear_solver: String,
    /// What may be wrong with the results.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Information on what the run did as expected (redundant constraint rows left out,
    /// files not written and why).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// What `--verify` found: every accepted step re-checked with a fresh matrix.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verify: Option<crate::solve::Verification>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_kind: Option<ErrorKind>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Summary {
    /// The summary as `summary.json` holds it.
    fn json(&self) -> String {
        let mut text = serde_json::to_string_pretty(self)
            .expect("a summary (strings, numbers, lists) always serializes");
        text.push('\n');
        text
    }

    /// `Summary::json` in at most `room` bytes, when that can be done by leaving out
    /// warnings (from the last; a last warning says how many) and then cutting the error
    /// message (which ends with `...` then).
    pub fn json_within(&self, room: usize) -> String {
        let mut text = self.json();
        let mut cut = self.clone();
        let mut kept = self.warnings.len();
        while text.len() > room {
            if kept > 0 {
                kept -= 1;
                cut.warnings.truncate(kept);
                cut.warnings.push(format!(
                    "{} more warnings left out of this file (on the standard error of the run)",
                    self.warnings.len() - kept
                ));
            } else if let Some(error) = cut.error.as_mut().filter(|e| e.len() > 3) {
                let excess = text.len() - room + 3;
                let mut end = error.len().saturating_sub(excess);
                while !error.is_char_boundary(end) {
                    end -= 1;
                }
                error.truncate(end);
                error.push_str("...");
            } else {
                break;
            }
            text = cut.json();
        }
        text
    }

    /// Sets the counts of the work done.
    pub fn count(&mut self, work: Work) {
        self.steps = work.steps;
        self.newton_iterations = work.newton_iterations;
        self.rejected_steps = work.rejected_steps;
        self.factorizations = work.factorizations;
        self.newton_iterations_per_step = work.newton_iterations as f64 / work.steps.max(1) as f64;
    }

    /// Marks the summary failed with the kind and message of the error.
    pub fn fail(&mut self, kind: ErrorKind, error: String) {
        self.status = Status::Failed;
        self.error_kind = Some(kind);
        self.error = Some(error);
    }
}

/// The names of a beam element's 6 strains and 6 stress resultants, in the order of
/// `BeamState::strain` then `BeamState::stress`: the columns of `beams.csv` and the arrays of
/// the Paraview series.
pub const BEAM_QUANTITIES: [&str; 12] = [
    "axial_strain",
    "shear_strain_2",
    "shear_strain_3",
    "torsion",
    "curvature_2",
    "curvature_3",
    "axial_force",
    "shear_force_2",
    "shear_force_3",
    "torque",
    "bending_moment_2",
    "bending_moment_3",
];

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("flexmb-output-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// Values at the edges of `f64`: extremes, subnormals, signed zero, values with 17
    /// significant digits, the plain/scientific switch points and non-finite values.
    fn hard_values() -> Vec<f64> {
        let mut v = vec![
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            f64::MIN_POSITIVE / 3.0, // subnormal
            5e-324,                  // smallest subnormal
            -5e-324,
            0.0,
            -0.0,
            1.0 / 3.0,
            -2.0 / 3.0,
            0.1,
            0.1 + 0.2,
            1e-5,
            1e-5 * (1.0 - f64::EPSILON),
            1e16,
            1e16 * (1.0 - f64::EPSILON),
            std::f64::consts::PI * 1e300,
            1.0 + f64::EPSILON,
            123_456_789.123_456_79,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        // Pseudo-random bit patterns (a fixed linear congruential sequence) over all exponents.
        let mut bits = 0x2545_f491_4f6c_dd1d_u64;
        for _ in 0..2000 {
            bits = bits
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            v.push(f64::from_bits(bits));
        }
        v
    }

    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn numbers_read_back_bit_identical() {
        for x in hard_values() {
            let mut s = String::new();
            push_number(&mut s, x);
            let back: f64 = s.parse().unwrap_or_else(|e| panic!("{s}: {e}"));
            assert!(same(x, back), "{x:e} written as {s} reads back as {back:e}");
        }
    }

    #[test]
    fn numbers_are_plain_in_the_usual_range_and_scientific_outside() {
        let show = |x: f64| {
            let mut s = String::new();
            push_number(&mut s, x);
            s
        };
        assert_eq!(show(0.1), "0.1");
        assert_eq!(show(-0.0), "-0");
        assert_eq!(show(1e-5), "0.00001");
        assert_eq!(show(9.9e-6), "9.9e-6");
        assert_eq!(show(1e16), "1e16");
        assert_eq!(show(f64::MAX), "1.7976931348623157e308");
        assert_eq!(show(5e-324), "5e-324");
        assert_eq!(show(f64::NAN), "NaN");
        assert_eq!(show(f64::NEG_INFINITY), "-inf");
    }

    #[test]
    fn sensor_rows_read_back_bit_identical() {
        let dir = temp_dir("rows");
        let out = OutputDir::prepare(&dir).unwrap();
        let values = hard_values();
        let names: Vec<String> = (0..values.len()).map(|i| format!("s{i}")).collect();
        let model = crate::model::Model::new(flexmb_lie::Group::SE3);
        let mut files = ResultFiles::create(&out, "time", &model, &names).unwrap();
        // Each row: a time taken from the list and every value, rotated by the row number.
        for row in 0..5 {
            let mut rotated = values.clone();
            rotated.rotate_left(row);
            let step = Snapshot {
                at: values[row],
                sensors: rotated,
                ..Default::default()
            };
            files.write_step(&step).unwrap();
        }
        let text = std::fs::read_to_string(out.file(SENSORS_FILE)).unwrap();
        let mut lines = text.lines();
        assert_eq!(
            lines.next().unwrap().split(',').count(),
            1 + values.len(),
            "header"
        );
        let mut rows = 0;
        for (row, line) in lines.enumerate() {
            let fields: Vec<f64> = line.split(',').map(|f| f.parse().unwrap()).collect();
            assert!(same(fields[0], values[row]));
            let mut rotated = values.clone();
            rotated.rotate_left(row);
            assert_eq!(fields.len(), 1 + rotated.len());
            for (got, want) in fields[1..].iter().zip(&rotated) {
                assert!(same(*got, *want), "{got:e} != {want:e}");
            }
            rows += 1;
        }
        assert_eq!(rows, 5);
    }

    #[test]
    fn labelled_rows_read_back_bit_identical() {
        // The row layout of nodes.csv and beams.csv: number, label, numbers.
        let dir = temp_dir("labelled");
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(NODES_FILE);
        let mut csv = CsvFile::create(path.clone(), "time,node,x").unwrap();
        let values = hard_values();
        for (i, pair) in values.chunks(2).enumerate() {
            csv.start_row(pair[0], Some(&format!("n{i}")));
            csv.field(pair[pair.len() - 1]);
            csv.end_row();
        }
        csv.commit().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let rows: Vec<&str> = text.lines().skip(1).collect();
        assert_eq!(rows.len(), values.len().div_ceil(2));
        for ((i, line), pair) in rows.iter().enumerate().zip(values.chunks(2)) {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields[1], format!("n{i}"));
            assert!(same(fields[0].parse().unwrap(), pair[0]));
            assert!(same(fields[2].parse().unwrap(), pair[pair.len() - 1]));
        }
    }

    #[test]
    fn prepare_removes_earlier_results_and_keeps_other_files() {
        let dir = temp_dir("prepare");
        std::fs::create_dir_all(&dir).unwrap();
        for name in
            RESULT_FILES
                .iter()
                .chain([&SUMMARY_TEMP_FILE, &SUMMARY_ROOM_FILE, &"notes.txt"])
        {
            std::fs::write(dir.join(name), "earlier").unwrap();
        }
        OutputDir::prepare(&dir).unwrap();
        let mut left: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        assert_eq!(left, ["notes.txt"]);
        assert_eq!(
            std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
            "earlier"
        );
    }

    #[test]
    fn prepare_refuses_a_file_and_creates_missing_directories() {
        let dir = temp_dir("not-dir");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("plain");
        std::fs::write(&file, "").unwrap();
        let err = OutputDir::prepare(&file).unwrap_err();
        assert!(matches!(err, OutputError::NotADirectory { .. }), "{err}");
        assert!(err.to_string().ends_with("plain: not a directory"), "{err}");
        assert!(OutputDir::prepare(&dir.join("a/b"))
            .unwrap()
            .path()
            .is_dir());
    }

    #[test]
    fn summary_is_replaced_whole_or_not_at_all() {
        let dir = temp_dir("summary");
        let out = OutputDir::prepare(&dir).unwrap();
        let mut summary = Summary {
            title: "first".into(),
            ..Default::default()
        };
        out.write_summary(&summary).unwrap();
        let first = std::fs::read_to_string(out.file(SUMMARY_FILE)).unwrap();
        assert!(first.contains("\"status\": \"running\""), "{first}");
        assert!(
            !out.file(SUMMARY_TEMP_FILE).exists(),
            "no temporary file left"
        );
        // The temporary file cannot be created (a directory is in its place): the write fails
        // and the earlier summary is untouched, never truncated.
        std::fs::create_dir(out.file(SUMMARY_TEMP_FILE)).unwrap();
        summary.title = "second".into();
        let err = out.write_summary(&summary).unwrap_err();
        assert!(err.to_string().contains(SUMMARY_TEMP_FILE), "{err}");
        assert_eq!(
            std::fs::read_to_string(out.file(SUMMARY_FILE)).unwrap(),
            first
        );
        std::fs::remove_dir(out.file(SUMMARY_TEMP_FILE)).unwrap();
        summary.fail(ErrorKind::Analysis, "why".into());
        out.write_summary(&summary).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.file(SUMMARY_FILE)).unwrap())
                .unwrap();
        assert_eq!(json["status"], "failed");
        assert_eq!(json["error_kind"], "analysis");
        assert_eq!(json["error"], "why");
    }

    /// The first summary of a run keeps room for the last: a file of 4096 bytes (one page,
    /// one block), allocated (not sparse) and filled with bytes that do not compress. The
    /// last summary is written in it, so that it needs neither a new inode nor more blocks
    /// than the room: `summary.json` is then the room's inode, renamed. A summary too long
    /// for the room leaves out warnings, then cuts its error, to fit.
    #[cfg(unix)]
    #[test]
    fn the_last_summary_is_written_in_the_room_kept_by_the_first() {
        use std::os::unix::fs::MetadataExt;
        let dir = temp_dir("room");
        let out = OutputDir::prepare(&dir).unwrap();
        let mut summary = Summary {
            title: "room".into(),
            ..Default::default()
        };
        out.write_summary(&summary).unwrap();
        let room = std::fs::metadata(out.file(SUMMARY_ROOM_FILE)).expect("room kept");
        assert_eq!(room.len(), SUMMARY_ROOM);
        assert!(room.blocks() * 512 >= room.len(), "allocated: {room:?}");
        let bytes = std::fs::read(out.file(SUMMARY_ROOM_FILE)).unwrap();
        let zeros = bytes.iter().filter(|&&b| b == 0).count();
        assert!(zeros < bytes.len() / 64, "{zeros} zero bytes");
        summary.warnings = (0..500)
            .map(|k| format!("warning {k}: {}", "x".repeat(40)))
            .collect();
        summary.fail(ErrorKind::Output, "disk full ".repeat(1000));
        out.write_summary(&summary).unwrap();
        let last = std::fs::metadata(out.file(SUMMARY_FILE)).unwrap();
        assert_eq!(last.ino(), room.ino(), "the room became the summary");
        assert!(last.len() <= SUMMARY_ROOM, "{} bytes", last.len());
        assert!(!out.file(SUMMARY_ROOM_FILE).exists());
        assert!(!out.file(SUMMARY_TEMP_FILE).exists());
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.file(SUMMARY_FILE)).unwrap())
                .unwrap();
        assert_eq!(json["status"], "failed");
        let warnings = json["warnings"].as_array().unwrap();
        let note = warnings.last().unwrap().as_str().unwrap();
        assert!(
            note.ends_with(
                "more warnings left out of this file (on the standard error of the run)"
            ),
            "{note}"
        );
        let error = json["error"].as_str().unwrap();
        assert!(
            error.starts_with("disk full") && error.ends_with("..."),
            "{error}"
        );
    }

    /// A run ended at once from another thread (a second signal): the writer thread is
    /// stopped between two batches (`end_now` waits for the batch it holds), and the summary
    /// says `interrupted` with the output steps the files hold, the time of the last and the
    /// work done up to it. Nothing is written after it; a run that has written its last
    /// summary keeps it.
    #[test]
    fn a_run_ended_at_once_records_what_its_files_hold() {
        let dir = temp_dir("end-now");
        let out = OutputDir::prepare(&dir).unwrap();
        let note = "ended at once";
        let wait = Duration::from_secs(10);
        assert!(
            out.end_now(note, wait).summary.unwrap().is_none(),
            "not started"
        );
        let running = Summary {
            title: "ended".into(),
            analysis: "dynamic".into(),
            ..Default::default()
        };
        out.write_summary(&running).unwrap();
        let work = Work {
            steps: 12,
            newton_iterations: 30,
            rejected_steps: 1,
            factorizations: 4,
        };
        out.files_reached(Reached {
            rows: 13,
            at: 0.012,
            work,
            output_seconds: 0.0,
        });
        let ended = std::thread::scope(|scope| {
            let files = out.lock_files().expect("the run goes on");
            let ending = scope.spawn(|| out.end_now(note, wait).summary);
            // the batch being written when the signal came
            std::thread::sleep(Duration::from_millis(50));
            out.files_reached(Reached {
                rows: 14,
                at: 0.013,
                work: Work { steps: 13, ..work },
                output_seconds: 0.0,
            });
            drop(files);
            ending.join().unwrap()
        });
        let ended = ended.unwrap().expect("the run was going on");
        assert_eq!(ended.status, Status::Interrupted);
        assert_eq!(
            (ended.outputs, ended.t_reached, ended.steps),
            (14, 0.013, 13)
        );
        assert_eq!(ended.warnings, [note]);
        assert!(out.lock_files().is_none(), "the writer stops");
        // the run's own last summary is not written over it
        let mut ok = running.clone();
        ok.status = Status::Ok;
        out.write_summary(&ok).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.file(SUMMARY_FILE)).unwrap())
                .unwrap();
        assert_eq!(json["status"], "interrupted");
        assert_eq!(json["outputs"], 14);
        // a run that ended by itself keeps its summary
        let other = OutputDir::prepare(&temp_dir("end-after")).unwrap();
        other.write_summary(&running).unwrap();
        other.write_summary(&ok).unwrap();
        assert!(other.end_now(note, wait).summary.unwrap().is_none());
        assert!(other.lock_files().is_some());
    }
}

#[cfg(test)]
mod same_as_std {
    use super::push_number;
    use std::fmt::Write as _;

    /// The formatting of std, which [`push_number`] reproduces but for ties.
    fn with_std(x: f64) -> String {
        let magnitude = x.abs();
        let plain = magnitude == 0.0 || (1e-5..1e16).contains(&magnitude) || !x.is_finite();
        let mut out = String::new();
        if plain {
            write!(out, "{x}").unwrap();
        } else {
            write!(out, "{x:e}").unwrap();
        }
        out
    }

    #[test]
    fn numbers_are_written_as_std_writes_them_but_for_ties() {
        let mut cases = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            1e-5,
            9.999999999999999e-6,
            1e16,
            9999999999999998.0,
            1e15,
            123456789.0,
            1e-7,
            2.5e-7,
            1.7976931348623157e308,
            5e-324,
            -2.2250738585072014e-308,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            12.566370614359172,
            1e21,
            1e22,
            1e23,
        ];
        // Bit patterns over the whole range (a fixed linear congruential sequence).
        let mut bits: u64 = 0x9e37_79b9_7f4a_7c15;
        for _ in 0..200_000 {
            bits = bits
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            cases.push(f64::from_bits(bits));
        }
        // And numbers of everyday sizes.
        for k in 0..20_000 {
            cases.push((k as f64 - 10_000.0) * 0.001_7);
            cases.push((k as f64).powi(3) * 1e-9);
        }
        let mut ties = 0;
        for x in cases {
            let mut mine = String::new();
            push_number(&mut mine, x);
            let theirs = with_std(x);
            if mine != theirs {
                // A value exactly halfway between two shortest decimals: std rounds the last
                // digit up, Ryu to even; both read back to the same bits.
                assert_eq!(mine.len(), theirs.len(), "{mine} against {theirs}");
                assert_eq!(
                    mine.contains('e'),
                    theirs.contains('e'),
                    "{mine} against {theirs}"
                );
                ties += 1;
            }
            if x.is_finite() {
                assert_eq!(
                    mine.parse::<f64>().unwrap().to_bits(),
                    x.to_bits(),
                    "{mine}"
                );
            }
        }
        assert!(
            ties < 100,
            "{ties} numbers written otherwise than std writes them"
        );
    }
}
