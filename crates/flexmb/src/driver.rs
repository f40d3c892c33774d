//! The run of a model file into an output directory: what `flexmb run` does.

use crate::input::{Analysis, ModelFile};
use crate::output::{CsvWriter, ShapeWriter, Summary};
use crate::sensors::SensorEvaluator;
use crate::solve::{Simulation, StaticSettings, Statics};
use std::path::Path;
use std::time::Instant;

/// Runs the analysis a model file declares, writing `sensors.csv` and `summary.json` into
/// `out_dir` (created if needed). `progress(t, t_end)` is called at every output.
/// Returns the summary; `status` is "ok" or "failed" (the error then says why).
pub fn run(
    file: &ModelFile,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64, f64),
) -> std::io::Result<Summary> {
    std::fs::create_dir_all(out_dir)?;
    match &file.analysis {
        Analysis::Dynamic(settings) => run_dynamic(file, settings, out_dir, progress),
        Analysis::Static(settings) => run_static(file, settings, out_dir, progress),
    }
}

/// The files written at every output step (sensors, deformed shape, beam results) and the
/// time spent writing them.
struct Outputs<'m> {
    model: &'m crate::Model,
    sensors: SensorEvaluator,
    csv: CsvWriter,
    shape: ShapeWriter,
    seconds: f64,
}

impl<'m> Outputs<'m> {
    /// Creates the files; `first` names the first column (`time` or `load_factor`).
    fn create(out_dir: &Path, first: &str, model: &'m crate::Model) -> std::io::Result<Self> {
        let names = SensorEvaluator::names(model);
        Ok(Self {
            model,
            sensors: SensorEvaluator::new(model),
            csv: CsvWriter::create_with_first_column(&out_dir.join("sensors.csv"), first, &names)?,
            shape: ShapeWriter::create(out_dir, first, model)?,
            seconds: 0.0,
        })
    }

    /// Appends the rows of one output step (flushed).
    fn write(&mut self, x: f64, data: &crate::Data, state: &crate::State) -> Result<(), String> {
        let t0 = Instant::now();
        let values = self.sensors.evaluate(self.model, data, state);
        self.csv
            .row(x, &values)
            .map_err(|e| format!("writing {}: {e}", self.csv.path().display()))?;
        self.shape
            .write(x, self.model, state)
            .map_err(|e| format!("writing nodes.csv: {e}"))?;
        self.seconds += t0.elapsed().as_secs_f64();
        Ok(())
    }
}

/// Summary of a run that is starting.
fn starting(
    model: &crate::Model,
    analysis: &str,
    t_end: f64,
    out_dir: &Path,
) -> std::io::Result<Summary> {
    let summary = Summary {
        status: "running".into(),
        title: model.title.clone(),
        analysis: analysis.into(),
        group: model.group.name().into(),
        t_end,
        ..Default::default()
    };
    summary.write(&out_dir.join("summary.json"))?;
    Ok(summary)
}

/// Records a run that could not start (model or initial conditions rejected).
fn not_started(
    mut summary: Summary,
    error: &crate::SolveError,
    start: Instant,
    out_dir: &Path,
) -> std::io::Result<Summary> {
    summary.status = "failed".into();
    summary.error = Some(error.to_string());
    summary.wall_seconds = start.elapsed().as_secs_f64();
    summary.write(&out_dir.join("summary.json"))?;
    Ok(summary)
}

/// Work counts, timings and status of a finished run.
struct Finished {
    steps: usize,
    newton_iterations: usize,
    rejected_steps: usize,
    factorizations: usize,
    outputs: usize,
    reached: f64,
    warnings: Vec<String>,
}

fn finished(
    mut summary: Summary,
    f: Finished,
    result: Result<(), crate::SolveError>,
    start: Instant,
    output_seconds: f64,
    out_dir: &Path,
) -> std::io::Result<Summary> {
    let wall = start.elapsed().as_secs_f64();
    summary.steps = f.steps;
    summary.newton_iterations = f.newton_iterations;
    summary.rejected_steps = f.rejected_steps;
    summary.factorizations = f.factorizations;
    summary.outputs = f.outputs;
    summary.newton_iterations_per_step = f.newton_iterations as f64 / f.steps.max(1) as f64;
    summary.t_reached = f.reached;
    summary.warnings = f.warnings;
    summary.wall_seconds = wall;
    summary.solve_seconds = (wall - output_seconds).max(0.0);
    match result {
        Ok(()) => summary.status = "ok".into(),
        Err(e) => {
            summary.status = "failed".into();
            summary.error = Some(e.to_string());
        }
    }
    summary.write(&out_dir.join("summary.json"))?;
    Ok(summary)
}

/// Static analysis: `sensors.csv` has the load factor in its first column.
fn run_static(
    file: &ModelFile,
    settings: &StaticSettings,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64, f64),
) -> std::io::Result<Summary> {
    let start = Instant::now();
    let model = &file.model;
    let mut summary = starting(model, "static", settings.load_factor, out_dir)?;
    let mut statics = match Statics::new(model, *settings) {
        Ok(s) => s,
        Err(e) => return not_started(summary, &e, start, out_dir),
    };
    summary.unknowns = statics.data.layout.n_unknowns();
    summary.linear_solver = format!("{:?}", statics.data.solver.backend()).to_lowercase();
    let mut outputs = Outputs::create(out_dir, "load_factor", model)?;
    let target = settings.load_factor;
    let result = statics.run(&mut |s| {
        outputs.write(s.load_factor, &s.data, &s.state)?;
        progress(s.load_factor, target);
        Ok(())
    });
    let output_seconds = outputs.seconds;
    let stats = statics.stats;
    let f = Finished {
        steps: stats.steps,
        newton_iterations: stats.newton_iterations,
        rejected_steps: stats.rejected_steps,
        factorizations: stats.factorizations,
        outputs: stats.steps + 1,
        reached: statics.load_factor,
        warnings: statics.warnings.clone(),
    };
    finished(
        summary,
        f,
        result.map(|_| ()),
        start,
        output_seconds,
        out_dir,
    )
}

/// Dynamic analysis: `sensors.csv` has the time in its first column.
fn run_dynamic(
    file: &ModelFile,
    settings: &crate::solve::DynamicSettings,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64, f64),
) -> std::io::Result<Summary> {
    let start = Instant::now();
    let model = &file.model;
    let mut summary = starting(model, "dynamic", settings.t_end, out_dir)?;
    let mut sim = match Simulation::new(model, *settings) {
        Ok(sim) => sim,
        Err(e) => return not_started(summary, &e, start, out_dir),
    };
    summary.unknowns = sim.data.layout.n_unknowns();
    summary.linear_solver = format!("{:?}", sim.data.solver.backend()).to_lowercase();
    let mut outputs = Outputs::create(out_dir, "time", model)?;
    let t_end = settings.t_end;
    let result = sim.run(&mut |s| {
        outputs.write(s.state.t, &s.data, &s.state)?;
        progress(s.state.t, t_end);
        Ok(())
    });
    let output_seconds = outputs.seconds;
    let f = Finished {
        steps: sim.stats.steps,
        newton_iterations: sim.stats.newton_iterations,
        rejected_steps: sim.stats.rejected_steps,
        factorizations: sim.data.solver.factorizations(),
        outputs: sim.stats.outputs,
        reached: sim.state.t,
        warnings: sim.warnings.clone(),
    };
    finished(
        summary,
        f,
        result.map(|_| ()),
        start,
        output_seconds,
        out_dir,
    )
}
