//! The HDF5 results file, `results.h5`: written as a run goes ([`H5Format`], a
//! [`flexmb::output::StoreFormat`]) and read back into [`Results`] ([`read`]).
//!
//! Layout (docs/results-format.md is the user's description):
//! * root attributes: `format` = `flexmb results`, `version` = 1, `title`, `analysis`
//!   (`dynamic` or `static`), `group`, `first` (`time` or `load_factor`);
//! * `model/info`: the [`ModelInfo`] as one JSON string (names, bodies, beams, joints,
//!   springs, display shapes with their defaults, sensors and units);
//! * one row per output step, first axis extendable: `time` or `load_factor` (N),
//!   `nodes/position` (N x nodes x 3), `nodes/orientation` (N x nodes x 4, w x y z),
//!   `nodes/velocity` (N x nodes x 6), `joints/position` (N x joints x 3),
//!   `joints/reaction` (N x joints x 6), `joints/multipliers` (N x rows),
//!   `beams/strain` and `beams/stress` (N x elements x 6), `sensors/values` (N x sensors);
//!   a dataset whose rows would be empty (no joints, no beams, ...) is not written;
//! * names beside the data: `nodes/names`, `joints/names`, `beams/names`, `sensors/names`,
//!   `sensors/units`;
//! * one row per accepted step (static: per converged load step): `solver/steps`, a
//!   compound of `at`, `h`, `iterations`, `rejected` and `fresh_matrix` (a [`StepStat`]).
//!
//! The store is written on the run's writer thread ([`flexmb::output::writer`]): output steps
//! are held in memory ([`Store::write`]) and, at every [`Store::sync`] (after each batch of
//! output steps the writer takes, at checkpoints and at the end of the run, whatever its
//! outcome), written with one HDF5 write per dataset, `time` (`load_factor`) last, and the
//! file flushed. A reader takes the length of `time` as the number of complete output
//! steps, so a run killed at any moment leaves a file with every output step of the last
//! sync.

use crate::info::ModelInfo;
use crate::snapshot::{Results, Snapshot, StepStat};
use flexmb::output::{OutputDir, OutputError, Store, StoreFormat, RESULTS_H5_FILE};
use flexmb::solve::StepInfo;
use hdf5::types::{FixedUnicode, VarLenUnicode};
use hdf5::{Dataset, File, H5Type, Hyperslab, SliceOrIndex};
use std::path::{Path, PathBuf};

/// Version of the layout, root attribute `version`.
pub const VERSION: u32 = 1;
/// Rows a chunk holds at most, and its size aimed at \[bytes\].
const CHUNK_ROWS: usize = 1024;
const CHUNK_BYTES: usize = 8 * 1024;

/// Why a results file cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{}: not an HDF5 file flexmb can read: {message}", path.display())]
    Format { path: PathBuf, message: String },
}

/// The per-output-step datasets: name, shape of a row, and the row of a snapshot.
type Row = fn(&Snapshot) -> &[f64];
fn series(info: &ModelInfo) -> Vec<(&'static str, Vec<usize>, Row)> {
    let joint_rows = info.joints.iter().map(|j| j.rows).sum();
    let (n, j, b, s) = (
        info.nodes.len(),
        info.joints.len(),
        info.beams.len(),
        info.sensors.len(),
    );
    let all: Vec<(&'static str, Vec<usize>, Row)> = vec![
        ("nodes/position", vec![n, 3], |s| s.position.as_flattened()),
        ("nodes/orientation", vec![n, 4], |s| {
            s.orientation.as_flattened()
        }),
        ("nodes/velocity", vec![n, 6], |s| s.velocity.as_flattened()),
        ("joints/position", vec![j, 3], |s| {
            s.joint_position.as_flattened()
        }),
        ("joints/reaction", vec![j, 6], |s| {
            s.joint_reaction.as_flattened()
        }),
        ("joints/multipliers", vec![joint_rows], |s| &s.multipliers),
        ("beams/strain", vec![b, 6], |s| s.beam_strain.as_flattened()),
        ("beams/stress", vec![b, 6], |s| s.beam_stress.as_flattened()),
        ("sensors/values", vec![s], |s| &s.sensors),
    ];
    all.into_iter()
        .filter(|(_, shape, _)| shape.iter().product::<usize>() > 0)
        .collect()
}

fn h5_error<'a>(
    path: &'a Path,
    action: &'static str,
) -> impl FnOnce(hdf5::Error) -> OutputError + 'a {
    // HDF5's messages span lines; one line per cause.
    move |e| OutputError::Io {
        path: path.to_path_buf(),
        action,
        source: std::io::Error::other(
            e.to_string()
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" "),
        ),
    }
}

/// An extendable dataset: rows of `shape` along a first, unlimited axis.
struct Column {
    data: Dataset,
    shape: Vec<usize>,
}

impl Column {
    fn create<T: H5Type>(file: &File, name: &str, shape: &[usize]) -> hdf5::Result<Self> {
        let row: usize = shape.iter().product::<usize>() * std::mem::size_of::<T>();
        let rows = (CHUNK_BYTES / row.max(1)).clamp(1, CHUNK_ROWS);
        let mut extents = vec![hdf5::Extent::resizable(0)];
        extents.extend(shape.iter().map(|&d| hdf5::Extent::from(d)));
        let mut chunk = vec![rows];
        chunk.extend_from_slice(shape);
        let data = file
            .new_dataset::<T>()
            .obj_track_times(false)
            .chunk(chunk)
            .shape(extents)
            .create(name)?;
        Ok(Self {
            data,
            shape: shape.to_vec(),
        })
    }

    fn open(file: &File, name: &str) -> hdf5::Result<Self> {
        let data = file.dataset(name)?;
        let shape = data.shape()[1..].to_vec();
        Ok(Self { data, shape })
    }

    fn rows(&self) -> usize {
        self.data.shape()[0]
    }

    /// Sets the number of rows.
    fn resize(&self, rows: usize) -> hdf5::Result<()> {
        let mut dims = vec![rows];
        dims.extend_from_slice(&self.shape);
        self.data.resize(dims)
    }

    /// Appends `values.len() / row size` rows at `at`.
    fn append<T: H5Type>(&self, at: usize, values: &[T]) -> hdf5::Result<()> {
        let row = self.shape.iter().product::<usize>().max(1);
        let rows = values.len() / row;
        if rows == 0 {
            return Ok(());
        }
        self.resize(at + rows)?;
        let mut dims = vec![rows];
        dims.extend_from_slice(&self.shape);
        let view = ndarray::ArrayView::from_shape(ndarray::IxDyn(&dims), values)
            .map_err(|e| hdf5::Error::from(e.to_string()))?;
        let mut sel = vec![SliceOrIndex::from(at..at + rows)];
        sel.extend(self.shape.iter().map(|_| SliceOrIndex::from(..)));
        self.data.write_slice(view, Hyperslab::from(sel))
    }
}

/// The HDF5 results file of a run being written.
pub struct H5Store {
    file: File,
    path: PathBuf,
    time: Column,
    /// Each dataset of output steps, the row of a snapshot, and the rows not written yet.
    columns: Vec<(Column, Row, Vec<f64>)>,
    steps: Column,
    /// Output steps and solver steps written.
    rows: usize,
    step_rows: usize,
    /// Output steps (their times) and solver steps not written yet.
    times: Vec<f64>,
    pending: Vec<StepStat>,
}

/// The dataset of the solver's steps.
const STEPS: &str = "solver/steps";

/// Marks of the store in a checkpoint.
const MARK_OUTPUTS: &str = "results.h5:outputs";
const MARK_STEPS: &str = "results.h5:steps";

fn write_attr(file: &File, name: &str, value: &str) -> hdf5::Result<()> {
    let v: VarLenUnicode = value
        .parse()
        .map_err(|_| hdf5::Error::from("a string with a NUL"))?;
    file.new_attr::<VarLenUnicode>()
        .create(name)?
        .write_scalar(&v)
}

/// Writes `values` as a dataset of UTF-8 strings: fixed-length (the shortest of 32, 128 or
/// 1024 bytes that holds them all) when they fit, variable-length otherwise. Writing
/// variable-length strings costs HDF5 about 1 ms a dataset, a fixed-length array some 50 us;
/// h5py reads both as `bytes`.
fn write_strings(file: &File, name: &str, values: &[String]) -> hdf5::Result<()> {
    fn fixed<const N: usize>(file: &File, name: &str, values: &[String]) -> hdf5::Result<()> {
        let v = values
            .iter()
            .map(|s| s.replace('\0', "").parse::<FixedUnicode<N>>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| hdf5::Error::from(e.to_string()))?;
        file.new_dataset_builder()
            .obj_track_times(false)
            .with_data(&v)
            .create(name)?;
        Ok(())
    }
    let longest = values.iter().map(String::len).max().unwrap_or(0);
    match longest {
        0 if values.is_empty() => Ok(()),
        0..=32 => fixed::<32>(file, name, values),
        33..=128 => fixed::<128>(file, name, values),
        129..=1024 => fixed::<1024>(file, name, values),
        _ => {
            let v: Vec<VarLenUnicode> = values
                .iter()
                .map(|s| s.replace('\0', "").parse().expect("no NUL left"))
                .collect();
            file.new_dataset_builder()
                .obj_track_times(false)
                .with_data(&v)
                .create(name)?;
            Ok(())
        }
    }
}

impl H5Store {
    /// Creates `path` (replacing a file there) with the metadata of `info`.
    pub fn create(path: &Path, info: &ModelInfo) -> hdf5::Result<Self> {
        // No modification times in the file (its bytes still depend on how the output
        // steps were batched, and on the padding of the solver steps' records).
        let file = File::with_options()
            .with_fcpl(|p| p.obj_track_times(false))
            .create(path)?;
        write_attr(&file, "format", "flexmb results")?;
        file.new_attr::<u32>()
            .create("version")?
            .write_scalar(&VERSION)?;
        write_attr(&file, "title", &info.title)?;
        write_attr(&file, "analysis", &info.analysis)?;
        write_attr(&file, "group", &info.group)?;
        write_attr(&file, "first", &info.first)?;
        let json = serde_json::to_string(info).expect("the model's metadata serializes");
        let json: VarLenUnicode = json
            .parse()
            .map_err(|_| hdf5::Error::from("metadata with a NUL"))?;
        for g in ["model", "nodes", "joints", "beams", "sensors", "solver"] {
            file.create_group_builder()
                .obj_track_times(false)
                .create(g)?;
        }
        file.new_dataset::<VarLenUnicode>()
            .obj_track_times(false)
            .create("model/info")?
            .write_scalar(&json)?;
        let names = |v: Vec<&String>| v.into_iter().cloned().collect::<Vec<_>>();
        write_strings(&file, "nodes/names", &info.nodes)?;
        write_strings(
            &file,
            "joints/names",
            &names(info.joints.iter().map(|j| &j.name).collect()),
        )?;
        write_strings(
            &file,
            "beams/names",
            &names(info.beams.iter().map(|b| &b.name).collect()),
        )?;
        write_strings(
            &file,
            "sensors/names",
            &names(info.sensors.iter().map(|s| &s.name).collect()),
        )?;
        write_strings(
            &file,
            "sensors/units",
            &names(info.sensors.iter().map(|s| &s.unit).collect()),
        )?;
        let columns = series(info)
            .into_iter()
            .map(|(name, shape, row)| {
                Ok((Column::create::<f64>(&file, name, &shape)?, row, Vec::new()))
            })
            .collect::<hdf5::Result<_>>()?;
        let time = Column::create::<f64>(&file, &info.first, &[])?;
        let steps = Column::create::<StepStat>(&file, STEPS, &[])?;
        file.flush()?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            time,
            columns,
            steps,
            rows: 0,
            step_rows: 0,
            times: Vec::new(),
            pending: Vec::new(),
        })
    }

    /// The file of an earlier run, cut back to `rows` output steps and `step_rows` solver
    /// steps.
    pub fn reopen(path: &Path, rows: usize, step_rows: usize) -> hdf5::Result<Self> {
        let file = File::open_rw(path)?;
        let info = read_info(&file)?;
        let columns: Vec<(Column, Row, Vec<f64>)> = series(&info)
            .into_iter()
            .map(|(name, _, row)| Ok((Column::open(&file, name)?, row, Vec::new())))
            .collect::<hdf5::Result<_>>()?;
        let time = Column::open(&file, &info.first)?;
        let steps = Column::open(&file, STEPS)?;
        if time.rows() < rows || steps.rows() < step_rows {
            return Err(hdf5::Error::from(
                "the file holds fewer steps than the checkpoint recorded",
            ));
        }
        time.resize(rows)?;
        for (c, ..) in &columns {
            c.resize(rows)?;
        }
        steps.resize(step_rows)?;
        file.flush()?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            time,
            columns,
            steps,
            rows,
            step_rows,
            times: Vec::new(),
            pending: Vec::new(),
        })
    }

    /// Appends one output step; it is written by the next [`H5Store::write_pending`].
    pub fn append(&mut self, snapshot: &Snapshot) {
        for (_, row, values) in &mut self.columns {
            values.extend_from_slice(row(snapshot));
        }
        self.times.push(snapshot.at);
    }

    /// Writes the output and solver steps held in memory, `time` last, and flushes the file.
    pub fn write_pending(&mut self) -> hdf5::Result<()> {
        self.steps.append(self.step_rows, &self.pending)?;
        self.step_rows += self.pending.len();
        self.pending.clear();
        for (column, _, values) in &mut self.columns {
            column.append(self.rows, values)?;
            values.clear();
        }
        self.time.append(self.rows, &self.times)?;
        self.rows += self.times.len();
        self.times.clear();
        self.file.flush()
    }

    /// Records a solver step; it is written with the next output step.
    pub fn push_step(&mut self, step: StepStat) {
        self.pending.push(step);
    }
}

/// Rows still in memory when the store goes are written (best effort: the driver syncs it
/// and reports the errors first).
impl Drop for H5Store {
    fn drop(&mut self) {
        if !(self.times.is_empty() && self.pending.is_empty()) {
            let _ = self.write_pending();
        }
    }
}

impl Store for H5Store {
    fn write(&mut self, snapshot: &Snapshot) -> Result<(), OutputError> {
        self.append(snapshot);
        Ok(())
    }

    fn step(&mut self, info: &StepInfo) -> Result<(), OutputError> {
        self.push_step(StepStat::of(info));
        Ok(())
    }

    fn sync(&mut self) -> Result<Vec<(String, u64)>, OutputError> {
        let path = self.path.clone();
        self.write_pending()
            .map_err(h5_error(&path, "cannot write"))?;
        Ok(vec![
            (MARK_OUTPUTS.into(), self.rows as u64),
            (MARK_STEPS.into(), self.step_rows as u64),
        ])
    }
}

/// Writes `results.h5` in the output directory of a run ([`flexmb::driver::run_with`]).
pub struct H5Format;

impl StoreFormat for H5Format {
    fn create(
        &self,
        dir: &OutputDir,
        model: &flexmb::Model,
        analysis: &str,
    ) -> Result<Box<dyn Store>, OutputError> {
        let path = dir.file(RESULTS_H5_FILE);
        let store = H5Store::create(&path, &ModelInfo::of(model, analysis))
            .map_err(h5_error(&path, "cannot create"))?;
        Ok(Box::new(store))
    }

    fn reopen(
        &self,
        dir: &OutputDir,
        _model: &flexmb::Model,
        marks: &[(String, u64)],
    ) -> Result<Box<dyn Store>, OutputError> {
        let path = dir.file(RESULTS_H5_FILE);
        let mark = |name: &str| {
            marks
                .iter()
                .find(|(n, _)| n == name)
                .map(|&(_, v)| v as usize)
        };
        let (Some(rows), Some(steps)) = (mark(MARK_OUTPUTS), mark(MARK_STEPS)) else {
            return Err(OutputError::Io {
                path,
                action: "is not in the checkpoint",
                source: std::io::Error::from(std::io::ErrorKind::NotFound),
            });
        };
        let store =
            H5Store::reopen(&path, rows, steps).map_err(h5_error(&path, "cannot reopen"))?;
        Ok(Box::new(store))
    }
}

fn read_info(file: &File) -> hdf5::Result<ModelInfo> {
    let json: VarLenUnicode = file.dataset("model/info")?.read_scalar()?;
    serde_json::from_str(json.as_str()).map_err(|e| hdf5::Error::from(e.to_string()))
}

/// Reads a results file: `path` is the file or the output directory of a run (then its
/// `results.h5`). Every complete output step is read (the length of `time`), also from the
/// file of a run that was killed.
pub fn read(path: &Path) -> Result<Results, ReadError> {
    let path = if path.is_dir() {
        path.join(RESULTS_H5_FILE)
    } else {
        path.to_path_buf()
    };
    let bad = |e: hdf5::Error| ReadError::Format {
        path: path.clone(),
        message: e.to_string(),
    };
    let file = File::open(&path).map_err(bad)?;
    let info = read_info(&file).map_err(bad)?;
    let time: Vec<f64> = file
        .dataset(&info.first)
        .and_then(|d| d.read_raw())
        .map_err(bad)?;
    let n = time.len();
    let mut snapshots: Vec<Snapshot> = time
        .iter()
        .map(|&at| Snapshot {
            at,
            ..Default::default()
        })
        .collect();
    for (name, shape, _) in series(&info) {
        let values: Vec<f64> = file.dataset(name).and_then(|d| d.read_raw()).map_err(bad)?;
        let row = shape.iter().product::<usize>();
        if values.len() < n * row {
            return Err(bad(hdf5::Error::from(format!(
                "{name} is shorter than time"
            ))));
        }
        for (s, chunk) in snapshots.iter_mut().zip(values.chunks_exact(row)) {
            fill(s, name, chunk);
        }
    }
    let steps = file
        .dataset(STEPS)
        .and_then(|d| d.read_raw::<StepStat>())
        .map_err(bad)?;
    Ok(Results {
        info,
        snapshots,
        steps,
    })
}

/// Puts one row of dataset `name` into its snapshot.
fn fill(s: &mut Snapshot, name: &str, row: &[f64]) {
    fn arrays<const N: usize>(row: &[f64]) -> Vec<[f64; N]> {
        row.chunks_exact(N)
            .map(|c| c.try_into().expect("chunks of N"))
            .collect()
    }
    match name {
        "nodes/position" => s.position = arrays(row),
        "nodes/orientation" => s.orientation = arrays(row),
        "nodes/velocity" => s.velocity = arrays(row),
        "joints/position" => s.joint_position = arrays(row),
        "joints/reaction" => s.joint_reaction = arrays(row),
        "joints/multipliers" => s.multipliers = row.to_vec(),
        "beams/strain" => s.beam_strain = arrays(row),
        "beams/stress" => s.beam_stress = arrays(row),
        "sensors/values" => s.sensors = row.to_vec(),
        _ => unreachable!("every series has a field"),
    }
}
