//! The run of a model file into an output directory: what `flexmb run` does.
//!
//! Contract: [`run`] writes `summary.json` with status `running` once the analysis is set up
//! (with its unknowns and linear solver; room is then kept for the last summary, see
//! [`crate::output`]), then the result files of [`crate::output`] step by step, and finally
//! the summary with the outcome: `ok`; `failed` with `error_kind` `model` (rejected before the first step:
//! invalid settings, inconsistent initial conditions, singular initial mass matrix; no CSV
//! file is written), `analysis` (a step could not converge; the rows up to it are kept) or
//! `output` (a result file could not be written); `interrupted` (the interrupt flag was
//! set; every completed output step is kept); or `incomplete` (the analysis stopped at a
//! limit of its settings before its end, [`SolveError::Incomplete`]: every converged step
//! is kept and the warnings say which setting to raise). The counts (`steps`, ...) are those
//! of the work done, whatever the outcome; `outputs` the output steps in the result files,
//! and `t_reached` the time (load factor) up to which they are complete: that of the last
//! completed step, or of the last output step written when a result file could not be
//! written (the solver may have gone further).
//!
//! The directory must have been taken over by [`OutputDir::prepare`] (which removes the
//! results of an earlier run).

use crate::data::Layout;
use crate::error::SolveError;
use crate::input::{Analysis, ModelFile};
use crate::output::writer::{Open, Stopped, Writer, Written};
use crate::output::{
    ErrorKind, OutputDir, OutputError, Reached, Status, StoreFormat, Summary, CHECKPOINT_FILE,
};
use crate::sensors::SensorEvaluator;
use crate::solve::dynamics::Checkpoint;
use crate::solve::observe::{Observer, Observers, Sample};
use crate::solve::{DynamicSettings, Simulation, StaticSettings, Statics, StepInfo};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

/// What a run did: its summary (the outcome, whether or not `summary.json` could record it)
/// and, when the summary file could not be written, why.
#[derive(Debug)]
pub struct Report {
    pub summary: Summary,
    pub unwritten: Option<OutputError>,
}

/// How a run is carried out, besides its model file.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunOptions {
    /// Dynamic analysis: write `checkpoint.json` every this much simulated time \[s\] and
    /// at the end. A dynamic run stopped by the interrupt flag always writes one.
    pub checkpoint_interval: Option<f64>,
    /// Go on from the `checkpoint.json` of `out` (opened with [`OutputDir::reopen`]): the
    /// result files are cut back to the steps it recorded and the run continues them, as
    /// the run that wrote it would have (bit for bit). The model must be the same and so
    /// must the solver settings, except a later `t_end` and the number of threads.
    pub resume: bool,
}

/// What `checkpoint.json` holds: the simulation's memory and where the result files stood.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct RunCheckpoint {
    pub checkpoint: Checkpoint,
    /// Result files and their lengths in bytes.
    pub files: Vec<(String, u64)>,
    /// Output steps written.
    pub outputs: usize,
    /// Memory of the sensors (unwrapped angles).
    pub sensors: SensorEvaluator,
}

/// Runs the analysis a model file declares into `out`. `progress(t, t_end)` is called at
/// every output step; `interrupt`, when set (e.g. by a signal handler), stops the run before
/// its next step with status `interrupted`. A result file that cannot be written ends the
/// run with `failed` and `error_kind` `output`.
pub fn run(
    file: &ModelFile,
    out: &OutputDir,
    options: RunOptions,
    progress: &mut dyn FnMut(f64, f64),
    interrupt: Option<Arc<AtomicBool>>,
) -> Report {
    run_with(file, out, options, &[], progress, interrupt)
}

/// [`run`] with more result files: one [`crate::output::Store`] of each of `formats`,
/// written at every output step beside the CSV files, on the run's writer thread (a file
/// that cannot be written fails the run as a CSV file would).
pub fn run_with(
    file: &ModelFile,
    out: &OutputDir,
    options: RunOptions,
    formats: &[&dyn StoreFormat],
    progress: &mut dyn FnMut(f64, f64),
    interrupt: Option<Arc<AtomicBool>>,
) -> Report {
    let start = Instant::now();
    let model = &file.model;
    let (analysis, t_end) = match &file.analysis {
        Analysis::Dynamic(s) => ("dynamic", s.t_end),
        Analysis::Static(s) => ("static", s.load_factor),
    };
    let mut summary = Summary {
        status: Status::Running,
        title: model.title.clone(),
        analysis: analysis.into(),
        group: model.group.name().into(),
        t_end,
        ..Default::default()
    };
    let target = Target {
        out,
        formats,
        summary: &summary,
    };
    let ended = match &file.analysis {
        Analysis::Dynamic(settings) => {
            run_dynamic(model, settings, target, options, progress, interrupt)
        }
        Analysis::Static(_) if options.resume || options.checkpoint_interval.is_some() => {
            Ended::rejected(SolveError::Checkpoint(
                "only a dynamic analysis has checkpoints".into(),
            ))
        }
        Analysis::Static(settings) => run_static(model, settings, target, progress, interrupt),
    };
    let output_seconds = ended.output_seconds;
    let started = !matches!(ended.outcome, Outcome::Failed(ErrorKind::Model, _));
    ended.record(&mut summary);
    if started && model.sensors.is_empty() {
        summary.notes.push(NO_SENSORS.into());
    }
    let wall = start.elapsed().as_secs_f64();
    summary.wall_seconds = wall;
    summary.solve_seconds = (wall - output_seconds).max(0.0);
    let unwritten = out.write_summary(&summary).err();
    Report { summary, unwritten }
}

/// The note of a run of a model without sensors: no history to write or draw.
pub const NO_SENSORS: &str = "the model has no sensors: sensors.csv holds the time alone and there is no history to plot (no summary.png); add [[sensor]] items to record some";

/// How an analysis ended: its work counts and the error that stopped it, if any.
struct Ended {
    work: Tally,
    outcome: Outcome,
    /// Output steps in the result files.
    outputs: usize,
    /// Time spent writing result files \[s\].
    output_seconds: f64,
}

/// Work counts and notes of a run (zero for a run rejected before the first step).
#[derive(Default)]
struct Tally {
    work: crate::solve::observe::Work,
    reached: f64,
    unknowns: usize,
    linear_solver: String,
    warnings: Vec<String>,
    notes: Vec<String>,
    verify: Option<crate::solve::Verification>,
}

/// How a run ended (the status of its summary).
enum Outcome {
    Completed,
    Interrupted,
    /// Stopped at a limit of the settings; the sentence says which to raise.
    Incomplete(String),
    Failed(ErrorKind, String),
    /// A result file could not be written; the error is kept for the caller.
    Output(OutputError),
}

impl Ended {
    /// A run rejected before its first step.
    fn rejected(e: SolveError) -> Self {
        Self {
            work: Tally::default(),
            outcome: Outcome::Failed(ErrorKind::Model, e.to_string()),
            outputs: 0,
            output_seconds: 0.0,
        }
    }

    /// The outcome of a run that started: a write error takes precedence over the solver's
    /// report of it. The files hold the output steps `written` reached; when one could not be
    /// written, the run is complete up to the last of them only.
    fn of_run(
        mut work: Tally,
        result: Result<(), SolveError>,
        written: Written,
        output_seconds: f64,
    ) -> Self {
        if written.error.is_some() {
            work.reached = written.reached.at;
        }
        let outcome = match (written.error, result) {
            (Some(e), _) => Outcome::Output(e),
            (None, Ok(())) => Outcome::Completed,
            (None, Err(SolveError::Interrupted { .. })) => Outcome::Interrupted,
            (None, Err(e @ SolveError::Incomplete { .. })) => Outcome::Incomplete(e.to_string()),
            (None, Err(e)) => Outcome::Failed(ErrorKind::Analysis, e.to_string()),
        };
        Self {
            work,
            outcome,
            outputs: written.reached.rows,
            output_seconds,
        }
    }

    /// Writes the counts and the outcome into the summary; returns the output error, if any.
    fn record(self, summary: &mut Summary) {
        let w = self.work;
        summary.count(w.work);
        summary.outputs = self.outputs;
        summary.t_reached = w.reached;
        summary.unknowns = w.unknowns;
        summary.linear_solver = w.linear_solver;
        summary.warnings = w.warnings;
        summary.notes = w.notes;
        summary.verify = w.verify;
        match self.outcome {
            Outcome::Completed => summary.status = Status::Ok,
            Outcome::Interrupted => summary.status = Status::Interrupted,
            Outcome::Incomplete(warning) => {
                summary.status = Status::Incomplete;
                summary.warnings.push(warning);
            }
            Outcome::Failed(kind, message) => summary.fail(kind, message),
            Outcome::Output(e) => summary.fail(ErrorKind::Output, e.to_string()),
        }
    }
}

/// The result files as the solver's thread sees them: at every output point the sensors are
/// evaluated and the step is handed to the writer thread, which writes the files. Keeps the
/// time the solver's thread spends on output and the error of a checkpoint file.
struct ResultSink<'m, 'w> {
    model: &'m crate::model::Model,
    sensors: SensorEvaluator,
    writer: Writer<'w>,
    /// Wall time of the solver's thread spent on output \[s\]: evaluating the sensors,
    /// copying the state and handing it over (waiting when the writer is behind), the
    /// checkpoints and the wait for the writer at the end.
    seconds: f64,
    /// The writer thread has stopped (on an error that [`Writer::finish`] returns).
    stopped: bool,
    /// A checkpoint that could not be written.
    error: Option<OutputError>,
}

impl ResultSink<'_, '_> {
    /// Runs `f`, counting its time as output time; a writer that has stopped stops the run.
    fn timed<T>(&mut self, f: impl FnOnce(&mut Self) -> Result<T, Stopped>) -> Result<T, String> {
        let t0 = Instant::now();
        let result = f(self);
        self.seconds += t0.elapsed().as_secs_f64();
        result.map_err(|Stopped| {
            self.stopped = true;
            "the result files could not be written".to_string()
        })
    }

    /// Whether the run must stop for its outputs.
    fn failed(&self) -> bool {
        self.stopped || self.error.is_some()
    }
}

impl Observer for ResultSink<'_, '_> {
    fn output(&mut self, s: &Sample) -> Result<(), String> {
        self.timed(|sink| {
            let values = sink.sensors.evaluate(sink.model, s.data, s.state);
            let seconds = sink.seconds;
            sink.writer.output(s, values, seconds)
        })
    }
    fn accepted(&mut self, info: &StepInfo) -> Result<(), String> {
        self.timed(|sink| sink.writer.step(info))
    }
}

/// The progress callback as an observer.
struct Progress<'p> {
    report: &'p mut dyn FnMut(f64, f64),
    end: f64,
}

impl Observer for Progress<'_> {
    fn output(&mut self, s: &Sample) -> Result<(), String> {
        (self.report)(s.at, self.end);
        Ok(())
    }
}

/// Where a run writes: its directory, the stores beside the CSV files, and its summary as
/// it starts (status `running`).
#[derive(Clone, Copy)]
struct Target<'a> {
    out: &'a OutputDir,
    formats: &'a [&'a dyn StoreFormat],
    summary: &'a Summary,
}

/// The result files of a run being opened: where, which, how far they go already, the
/// sensors' memory and the rows of the multipliers; and the summary of the run set up.
struct Opening<'a> {
    target: Target<'a>,
    running: Summary,
    open: Open,
    start: Reached,
    sensors: SensorEvaluator,
    layout: Layout,
}

impl Target<'_> {
    /// The summary of the run once its analysis is set up on `data` (`warnings` said while
    /// setting it up).
    fn running(&self, data: &crate::data::Data, warnings: &[String]) -> Summary {
        Summary {
            unknowns: data.layout.n_unknowns(),
            linear_solver: linear_solver(data),
            warnings: warnings.to_vec(),
            ..self.summary.clone()
        }
    }
}

/// Runs an analysis with the result files (written by a writer thread) and the progress as
/// its observers (`run` gets both), once its summary says it runs (a summary that cannot be
/// written ends the run there, as a result file would); returns the analysis' result, what
/// was written (with the first write error) and the output time of the solver's thread.
fn observed<R>(
    model: &crate::model::Model,
    files: Opening,
    mut progress: Progress,
    run: impl FnOnce(&mut ResultSink, &mut Progress) -> Result<R, SolveError>,
) -> (Result<(), SolveError>, Written, f64) {
    let Target { out, formats, .. } = files.target;
    if let Err(e) = out.write_summary(&files.running) {
        let written = Written {
            reached: files.start,
            error: Some(e),
        };
        return (Ok(()), written, 0.0);
    }
    std::thread::scope(|scope| {
        let t0 = Instant::now();
        let writer = Writer::spawn(
            scope,
            out,
            model,
            (files.layout, formats),
            files.open,
            files.start,
        );
        let mut sink = ResultSink {
            model,
            sensors: files.sensors,
            writer,
            seconds: t0.elapsed().as_secs_f64(),
            stopped: false,
            error: None,
        };
        let result = run(&mut sink, &mut progress);
        // Whatever the outcome, the files get every step handed over.
        let t1 = Instant::now();
        let mut written = sink.writer.finish();
        let seconds = sink.seconds + t1.elapsed().as_secs_f64();
        if let Some(e) = sink.error {
            written.error.get_or_insert(e);
        }
        (result.map(|_| ()), written, seconds)
    })
}

/// The linear solver of `data` in words (`dense`, `block`, ...).
fn linear_solver(data: &crate::data::Data) -> String {
    format!("{:?}", data.solver.backend()).to_lowercase()
}

/// Static analysis: `sensors.csv` has the load factor in its first column.
fn run_static(
    model: &crate::model::Model,
    settings: &StaticSettings,
    target: Target,
    progress: &mut dyn FnMut(f64, f64),
    interrupt: Option<Arc<AtomicBool>>,
) -> Ended {
    let mut statics = match Statics::new(model, *settings) {
        Ok(s) => s,
        Err(e) => return Ended::rejected(e),
    };
    statics.interrupt = interrupt;
    let progress = Progress {
        report: progress,
        end: settings.load_factor,
    };
    let files = Opening {
        target,
        running: target.running(&statics.data, &statics.warnings),
        open: Open::Create {
            first: "load_factor",
        },
        start: Reached::default(),
        sensors: SensorEvaluator::new(model),
        layout: statics.data.layout.clone(),
    };
    let (result, written, seconds) = observed(model, files, progress, |sink, progress| {
        statics.run(&mut Observers(vec![sink, progress]))
    });
    let work = Tally {
        work: statics.stats,
        reached: statics.load_factor,
        unknowns: statics.data.layout.n_unknowns(),
        linear_solver: linear_solver(&statics.data),
        warnings: statics.warnings.clone(),
        notes: statics.notes.clone(),
        verify: statics.verification.clone(),
    };
    Ended::of_run(work, result, written, seconds)
}

/// The simulation and result files of a dynamic run: new, or resumed from the checkpoint
/// in `out`.
fn start_dynamic<'a>(
    model: &crate::model::Model,
    settings: &DynamicSettings,
    target: Target<'a>,
    options: RunOptions,
) -> Result<(Simulation, Opening<'a>), SolveError> {
    let out = target.out;
    if !options.resume {
        let sim = Simulation::new(model, *settings)?;
        let files = Opening {
            target,
            running: target.running(&sim.data, &sim.warnings),
            open: Open::Create { first: "time" },
            start: Reached::default(),
            sensors: SensorEvaluator::new(model),
            layout: sim.data.layout.clone(),
        };
        return Ok((sim, files));
    }
    let bad = |m: String| SolveError::Checkpoint(m);
    let path = out.file(CHECKPOINT_FILE);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| bad(format!("{}: cannot read: {e}", path.display())))?;
    let saved: RunCheckpoint = serde_json::from_str(&text).map_err(|e| {
        bad(format!(
            "{}: not a checkpoint of this version: {e}",
            path.display()
        ))
    })?;
    if saved.checkpoint.model != *model {
        return Err(bad(format!(
            "{}: the model differs from the one the checkpoint was written with",
            path.display()
        )));
    }
    // The threads change nothing in the results: a run may go on with another number.
    let mut written = saved.checkpoint.settings;
    written.t_end = settings.t_end;
    written.threads = settings.threads;
    if written != *settings {
        return Err(bad(format!(
            "{}: the solver settings differ from those the checkpoint was written with (only t_end and threads may change)",
            path.display()
        )));
    }
    if saved.sensors.len() != model.sensors.len() {
        return Err(bad(format!(
            "{}: its sensor memory does not fit the model",
            path.display()
        )));
    }
    let RunCheckpoint {
        mut checkpoint,
        files,
        outputs,
        sensors,
    } = saved;
    checkpoint.settings.threads = settings.threads;
    let sim = Simulation::resume(checkpoint, settings.t_end)?;
    // the files are complete up to the checkpoint
    let start = Reached {
        rows: outputs,
        at: sim.state.t,
        work: sim.stats.work(),
        output_seconds: 0.0,
    };
    let files = Opening {
        target,
        running: target.running(&sim.data, &sim.warnings),
        open: Open::Reopen { lengths: files },
        start,
        sensors,
        layout: sim.data.layout.clone(),
    };
    Ok((sim, files))
}

/// Writes the checkpoint of a dynamic run and of its result files (once the writer has put
/// every step handed over into them). A checkpoint that cannot be written is kept as the
/// sink's error.
fn write_checkpoint(out: &OutputDir, sim: &Simulation, sink: &mut ResultSink) {
    let Ok(synced) = sink.timed(|sink| sink.writer.sync()) else {
        return;
    };
    let saved = RunCheckpoint {
        checkpoint: sim.checkpoint(),
        files: synced.files,
        outputs: synced.rows,
        sensors: sink.sensors.clone(),
    };
    let text = serde_json::to_string(&saved).expect("a checkpoint (numbers, strings) serializes");
    sink.error = out.write_checkpoint(&text).err();
}

/// Dynamic analysis: `sensors.csv` has the time in its first column. The run goes in
/// stretches between checkpoints when asked to write them.
fn run_dynamic(
    model: &crate::model::Model,
    settings: &DynamicSettings,
    target: Target,
    options: RunOptions,
    progress: &mut dyn FnMut(f64, f64),
    interrupt: Option<Arc<AtomicBool>>,
) -> Ended {
    let out = target.out;
    let (mut sim, files) = match start_dynamic(model, settings, target, options) {
        Ok(started) => started,
        Err(e) => return Ended::rejected(e),
    };
    sim.interrupt = interrupt;
    let t_end = settings.t_end;
    let progress = Progress {
        report: progress,
        end: t_end,
    };
    let (result, written, seconds) = observed(model, files, progress, |sink, progress| {
        let result = loop {
            // The next multiple of the interval after now; an interval too small to advance
            // the time (or not positive) leaves only the checkpoint at the end.
            let stop = options.checkpoint_interval.map_or(t_end, |i| {
                let next = ((sim.state.t / i).floor() + 1.0) * i;
                [next, next + i]
                    .into_iter()
                    .find(|&t| t > sim.state.t && i > 0.0)
                    .unwrap_or(t_end)
            });
            let result = sim.run_until(stop, &mut Observers(vec![&mut *sink, &mut *progress]));
            let checkpoint = match &result {
                Ok(_) => options.checkpoint_interval.is_some(),
                Err(e) => matches!(e, SolveError::Interrupted { .. }),
            };
            if checkpoint && !sink.failed() {
                write_checkpoint(out, &sim, sink);
            }
            if result.is_err() || sink.failed() || sim.state.t >= t_end {
                break result;
            }
        };
        sim.add_run_notes();
        result
    });
    let work = Tally {
        work: sim.stats.work(),
        reached: sim.state.t,
        unknowns: sim.data.layout.n_unknowns(),
        linear_solver: linear_solver(&sim.data),
        warnings: sim.warnings.clone(),
        notes: sim.notes.clone(),
        verify: sim.verification.clone(),
    };
    Ended::of_run(work, result, written, seconds)
}
