//! The writer thread of a run: the result files are created, written and flushed on a thread
//! of their own while the solver goes on.
//!
//! At each output step the solver's thread copies the state and sends it with the sensor
//! values through a bounded channel, in one message with the statistics of the accepted
//! steps before it when there are stores ([`Writer::output`], [`Writer::step`]): that is all
//! the output costs it (with the sensors, which it evaluates), unless the writer has fallen
//! a channel's length behind and it waits.
//!
//! The writer thread creates the files (the CSV files of [`ResultFiles`] and one [`Store`]
//! per [`StoreFormat`]: the HDF5 library's start-up and the file's creation overlap the first
//! steps of the solve), then takes what the channel holds as one batch: it computes each
//! output step's [`Snapshot`] (node positions and velocities, joint reactions, beam strains
//! and stress resultants), writes its CSV rows (one write per file and step) and gives it to
//! the stores; after the batch it syncs the stores ([`Store::sync`]: the HDF5 file is
//! written and flushed) and pauses for `PAUSE` (1 ms). When output steps come further
//! apart than that, a batch is one output step; when they come faster, or the writer falls
//! behind, one sync covers every step it has received. A run killed by SIGKILL thus loses the output steps that had not
//! reached the writer (sent during its pause or waiting in the channel) and those of the
//! batch being written.
//!
//! Errors: the writer stops at its first error (a full disk) and drops its end of the
//! channel, so that the solver's next send fails ([`Stopped`]) and the run stops;
//! [`Writer::finish`] waits for the thread and returns the error. A store that fails takes
//! the CSV files back to the steps of its last sync, so that every file holds the same
//! steps; whatever the outcome, the stores are synced once more when the thread ends.
//! [`Writer::sync`] (a checkpoint) waits until every step sent is in the files.
//!
//! The writer holds the directory's files ([`OutputDir::lock_files`]) while it writes a
//! batch and syncs the stores, and then records how far the files go
//! ([`OutputDir::files_reached`]), so that a run ended at once from another thread
//! ([`OutputDir::end_now`]) stops it between two batches and says what the files hold.

use super::{OutputDir, OutputError, Reached, ResultFiles, Snapshot, Store, StoreFormat};
use crate::data::Layout;
use crate::model::Model;
use crate::sensors::SensorEvaluator;
use crate::solve::observe::Sample;
use crate::solve::StepInfo;
use crate::state::State;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::{Scope, ScopedJoinHandle};
use std::time::Duration;

/// Bytes of output steps the channel holds at most, about, and its bounds in messages (an
/// output step, or accepted steps without one).
const HELD_BYTES: usize = 16 << 20;
const MIN_MESSAGES: usize = 16;
const MAX_MESSAGES: usize = 1024;

/// The files the writer opens.
pub enum Open {
    /// New files; `first` names their first column (`time` or `load_factor`).
    Create { first: &'static str },
    /// The files of a resumed run, cut back to the `lengths` (and marks) its checkpoint
    /// recorded.
    Reopen { lengths: Vec<(String, u64)> },
}

/// Where the files stand after a sync, for a checkpoint.
pub struct Synced {
    /// The CSV files' lengths in bytes and the stores' marks.
    pub files: Vec<(String, u64)>,
    /// Output steps in every file.
    pub rows: usize,
}

/// How the writer thread ended: how far every file goes, and its first error.
pub struct Written {
    pub reached: Reached,
    pub error: Option<OutputError>,
}

/// The writer thread has stopped on an error, which [`Writer::finish`] returns.
#[derive(Debug)]
pub struct Stopped;

/// An output step as the solver's thread hands it over: the accepted steps before it, a
/// copy of the state, from which the writer computes the step's [`Snapshot`], and the sensor
/// values. The writer sends it back once written, to be filled again: after the first
/// steps, the copies cost no allocation.
#[derive(Default)]
struct Taken {
    steps: Vec<StepInfo>,
    at: f64,
    state: State,
    sensors: Vec<f64>,
    /// The work done up to it, and the output time of the solver's thread \[s\].
    work: crate::solve::observe::Work,
    output_seconds: f64,
}

impl Taken {
    /// Copies `sample` into the buffers of an earlier output step.
    fn fill(&mut self, sample: &Sample, sensors: Vec<f64>, output_seconds: f64) {
        // (`State::clone_from` reuses the vectors)
        self.state.clone_from(sample.state);
        self.at = sample.at;
        self.sensors = sensors;
        self.work = sample.work;
        self.output_seconds = output_seconds;
    }
}

enum Message {
    /// An output step.
    Output(Box<Taken>),
    /// Accepted steps with no output step after them yet (before a sync, at the end of the
    /// run, or [`MAX_STEPS`] of them).
    Steps(Vec<StepInfo>),
    /// Sync the stores and answer where the files stand.
    Sync(SyncSender<Synced>),
}

/// How long the writer pauses after a batch with output steps before it takes the next one
/// (cut short at a checkpoint and at the end of the run): output steps that come faster
/// are written and flushed together, and the solver's sends do not wake the writer each
/// time (a wake-up costs the sender several microseconds, as much as computing an output
/// step of a small model).
const PAUSE: Duration = Duration::from_millis(1);

/// Accepted steps the solver's end holds at most before it sends them (they go with the
/// next output step, one message, unless there are this many).
const MAX_STEPS: usize = 4096;

/// The solver's end of the writer thread.
pub struct Writer<'scope> {
    sender: SyncSender<Message>,
    /// The output steps the writer has written, to be filled again.
    returned: Receiver<Box<Taken>>,
    thread: ScopedJoinHandle<'scope, Written>,
    /// Whether there are stores: they get the accepted steps (the CSV files do not).
    stores: bool,
    /// The accepted steps not sent yet.
    steps: Vec<StepInfo>,
}

impl<'scope> Writer<'scope> {
    /// Starts the thread, which opens the files of `model` in `out` (one store of each of
    /// `formats`) and writes them until [`Writer::finish`]; `layout` numbers the rows of the
    /// states' multipliers, `start` is how far the files go when they are opened.
    pub fn spawn(
        scope: &'scope Scope<'scope, '_>,
        out: &'scope OutputDir,
        model: &'scope Model,
        (layout, formats): (Layout, &'scope [&'scope dyn StoreFormat]),
        open: Open,
        start: Reached,
    ) -> Self {
        let capacity = capacity(model);
        let (sender, receiver) = sync_channel(capacity);
        let (recycle, returned) = sync_channel(capacity);
        let thread = scope.spawn(move || {
            out.files_reached(start);
            let opened = Files::open(out, model, (layout, formats), open, start, recycle);
            let mut files = match opened {
                Ok(files) => files,
                Err(e) => {
                    return Written {
                        reached: start,
                        error: Some(e),
                    }
                }
            };
            let error = files.serve(&receiver, capacity).err();
            // Whatever the outcome, the stores get every step the CSV files have (unless the
            // run was ended at once).
            let last = out.lock_files().and_then(|_files| files.sync().err());
            Written {
                reached: files.reached,
                error: error.or(last),
            }
        });
        Self {
            sender,
            returned,
            thread,
            stores: !formats.is_empty(),
            steps: Vec::new(),
        }
    }

    /// Hands over the output step `sample` with its sensor values; `output_seconds` is the
    /// time the solver's thread has spent on output so far.
    pub fn output(
        &mut self,
        sample: &Sample,
        sensors: Vec<f64>,
        output_seconds: f64,
    ) -> Result<(), Stopped> {
        let mut taken = self.returned.try_recv().unwrap_or_default();
        taken.fill(sample, sensors, output_seconds);
        // The accepted steps go with it; its (emptied) list takes the next ones.
        std::mem::swap(&mut taken.steps, &mut self.steps);
        self.send(Message::Output(taken))
    }

    /// Takes an accepted step for the stores (sent with the next output step); says whether
    /// the writer is still there.
    pub fn step(&mut self, info: &StepInfo) -> Result<(), Stopped> {
        if self.thread.is_finished() {
            return Err(Stopped);
        }
        if self.stores {
            self.steps.push(*info);
            if self.steps.len() >= MAX_STEPS {
                self.send_steps()?;
            }
        }
        Ok(())
    }

    /// Waits until every step handed over is in the files and the stores are synced.
    pub fn sync(&mut self) -> Result<Synced, Stopped> {
        self.send_steps()?;
        let (reply, answer) = sync_channel(1);
        self.send(Message::Sync(reply))?;
        self.thread.thread().unpark();
        answer.recv().map_err(|_| Stopped)
    }

    /// Waits until every step handed over is in the files and the thread has ended.
    pub fn finish(mut self) -> Written {
        // A writer that has stopped has its error.
        let _ = self.send_steps();
        drop(self.sender);
        self.thread.thread().unpark();
        self.thread
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    }

    /// Sends the accepted steps held, if any.
    fn send_steps(&mut self) -> Result<(), Stopped> {
        if self.steps.is_empty() {
            return Ok(());
        }
        let steps = std::mem::take(&mut self.steps);
        self.send(Message::Steps(steps))
    }

    fn send(&self, message: Message) -> Result<(), Stopped> {
        self.sender.send(message).map_err(|_| Stopped)
    }
}

/// Messages the channel holds: [`HELD_BYTES`] of output steps of `model`, within bounds.
fn capacity(model: &Model) -> usize {
    // The values of an output step, about: the state's 30 per node (configuration,
    // velocities, accelerations) and up to 6 multipliers per joint, and the sensors.
    let values = 1 + 30 * model.nodes.len() + 6 * model.joints.len() + model.sensors.len();
    (HELD_BYTES / (8 * values)).clamp(MIN_MESSAGES, MAX_MESSAGES)
}

/// What the writer thread writes, and what it computes the output steps with.
struct Files<'m> {
    out: &'m OutputDir,
    model: &'m Model,
    layout: Layout,
    csv: ResultFiles,
    stores: Vec<Box<dyn Store>>,
    /// How far the CSV files go.
    reached: Reached,
    /// The CSV files' lengths and how far they went when the stores were last synced.
    synced: (Vec<(String, u64)>, Reached),
    /// Where the output steps written go back to the solver's thread.
    recycle: SyncSender<Box<Taken>>,
}

impl<'m> Files<'m> {
    fn open(
        out: &'m OutputDir,
        model: &'m Model,
        (layout, formats): (Layout, &[&dyn StoreFormat]),
        open: Open,
        start: Reached,
        recycle: SyncSender<Box<Taken>>,
    ) -> Result<Self, OutputError> {
        let (csv, stores) = match open {
            Open::Create { first } => {
                let names = SensorEvaluator::names(model);
                let analysis = if first == "time" { "dynamic" } else { "static" };
                let csv = ResultFiles::create(out, first, model, &names)?;
                let stores = formats
                    .iter()
                    .map(|f| f.create(out, model, analysis))
                    .collect::<Result<_, _>>()?;
                (csv, stores)
            }
            Open::Reopen { lengths } => {
                let csv = ResultFiles::reopen(out, model, &lengths)?;
                let stores = formats
                    .iter()
                    .map(|f| f.reopen(out, model, &lengths))
                    .collect::<Result<_, _>>()?;
                (csv, stores)
            }
        };
        let synced = (csv.lengths(), start);
        Ok(Self {
            out,
            model,
            layout,
            csv,
            stores,
            reached: start,
            synced,
            recycle,
        })
    }

    /// Writes what comes through the channel until the solver's end is dropped (or the run
    /// is ended at once), syncing the stores after every batch that has an output step; a
    /// batch is at most `batch` messages more than the first.
    fn serve(&mut self, receiver: &Receiver<Message>, batch: usize) -> Result<(), OutputError> {
        while let Ok(first) = receiver.recv() {
            let Some(held) = self.out.lock_files() else {
                return Ok(());
            };
            let mut outputs = self.take(first)?;
            for message in receiver.try_iter().take(batch) {
                outputs |= self.take(message)?;
            }
            if outputs {
                self.sync()?;
                drop(held);
                // Not waiting on the channel, the writer is not woken by each send.
                std::thread::park_timeout(PAUSE);
            }
        }
        Ok(())
    }

    /// Writes one message; says whether it was an output step.
    fn take(&mut self, message: Message) -> Result<bool, OutputError> {
        match message {
            Message::Output(mut taken) => {
                self.steps(&taken.steps)?;
                let (state, at) = (&taken.state, taken.at);
                let sensors = std::mem::take(&mut taken.sensors);
                // The CSV files need neither the velocities nor the joints.
                let snapshot = if self.stores.is_empty() {
                    Snapshot::capture_shape(self.model, state, at, sensors)
                } else {
                    Snapshot::capture(self.model, &self.layout, state, at, sensors)
                };
                self.csv.write_step(&snapshot)?;
                self.reached = Reached {
                    rows: self.reached.rows + 1,
                    at,
                    work: taken.work,
                    output_seconds: taken.output_seconds,
                };
                self.each_store(|s| s.write(&snapshot))?;
                // Back to the solver's thread (unless it has enough), with the sensors' list.
                taken.sensors = snapshot.sensors;
                taken.steps.clear();
                let _ = self.recycle.try_send(taken);
                Ok(true)
            }
            Message::Steps(steps) => {
                self.steps(&steps)?;
                Ok(false)
            }
            Message::Sync(reply) => {
                let files = self.sync()?;
                // The solver waits for the answer (or for the thread's end).
                let _ = reply.send(Synced {
                    files,
                    rows: self.reached.rows,
                });
                Ok(false)
            }
        }
    }

    /// Gives the stores accepted steps.
    fn steps(&mut self, steps: &[StepInfo]) -> Result<(), OutputError> {
        for info in steps {
            self.each_store(|s| s.step(info))?;
        }
        Ok(())
    }

    /// Syncs the stores and records how far the files go: returns the lengths of the CSV
    /// files and the stores' marks.
    fn sync(&mut self) -> Result<Vec<(String, u64)>, OutputError> {
        let mut files = self.csv.lengths();
        for marks in self.each_store(|s| s.sync())? {
            files.extend(marks);
        }
        self.synced = (self.csv.lengths(), self.reached);
        self.out.files_reached(self.reached);
        Ok(files)
    }

    /// Calls `f` on every store; when one fails, the CSV files are cut back to the steps of
    /// the last sync (a step goes to every file or to none).
    fn each_store<T>(
        &mut self,
        mut f: impl FnMut(&mut dyn Store) -> Result<T, OutputError>,
    ) -> Result<Vec<T>, OutputError> {
        let result: Result<Vec<T>, _> = self.stores.iter_mut().map(|s| f(s.as_mut())).collect();
        if result.is_err() {
            let (lengths, reached) = &self.synced;
            self.csv.cut_back(lengths);
            self.reached = *reached;
        }
        result
    }
}
