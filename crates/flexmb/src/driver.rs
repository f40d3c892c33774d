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

/// Static analysis: `sensors.csv` has the load factor in its first column.
fn run_static(
    file: &ModelFile,
    settings: &StaticSettings,
    out_dir: &Path,
    progress: &mut dyn FnMut(f64, f64),
) -> std::io::Result<Summary> {
    let start = Instant::now();
    let model = &file.model;
    let mut summary = Summary {
        status: "running".into(),
        title: model.title.clone(),
        analysis: "static".into(),
        group: model.group.name().into(),
        t_end: settings.load_factor,
        ..Default::default()
    };
    let summary_path = out_dir.join("summary.json");
    summary.write(&summary_path)?;
    let names = SensorEvaluator::names(model);
    let mut csv =
        CsvWriter::create_with_first_column(&out_dir.join("sensors.csv"), "load_factor", &names)?;
    let mut shape = ShapeWriter::create(out_dir, "load_factor", model)?;
    let mut statics = match Statics::new(model, *settings) {
        Ok(s) => s,
        Err(e) => {
            summary.status = "failed".into();
            summary.error = Some(e.to_string());
            summary.wall_seconds = start.elapsed().as_secs_f64();
            summary.write(&summary_path)?;
            return Ok(summary);
        }
    };
    summary.unknowns = statics.data.layout.n_unknowns();
    summary.linear_solver = format!("{:?}", statics.data.solver.backend()).to_lowercase();
    summary.warnings = statics.warnings.clone();
    let mut sensors = SensorEvaluator::new(model);
    let mut output_seconds = 0.0;
    let target = settings.load_factor;
    let result = statics.run(&mut |s| {
        let t0 = Instant::now();
        let values = sensors.evaluate(s.model, &s.data, &s.state);
        csv.row(s.load_factor, &values)
            .map_err(|e| format!("writing {}: {e}", csv.path().display()))?;
        shape
            .write(s.load_factor, s.model, &s.state)
            .map_err(|e| format!("writing nodes.csv: {e}"))?;
        progress(s.load_factor, target);
        output_seconds += t0.elapsed().as_secs_f64();
        Ok(())
    });
    let wall = start.elapsed().as_secs_f64();
    summary.steps = statics.stats.steps;
    summary.newton_iterations = statics.stats.newton_iterations;
    summary.rejected_steps = statics.stats.rejected_steps;
    summary.factorizations = statics.stats.factorizations;
    summary.outputs = statics.stats.steps + 1;
    summary.newton_iterations_per_step =
        statics.stats.newton_iterations as f64 / statics.stats.steps.max(1) as f64;
    summary.t_reached = statics.load_factor;
    summary.warnings = statics.warnings.clone();
    summary.wall_seconds = wall;
    summary.solve_seconds = (wall - output_seconds).max(0.0);
    match result {
        Ok(_) => summary.status = "ok".into(),
        Err(e) => {
            summary.status = "failed".into();
            summary.error = Some(e.to_string());
        }
    }
    summary.write(&summary_path)?;
    Ok(summary)
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
    let mut summary = Summary {
        status: "running".into(),
        title: model.title.clone(),
        analysis: "dynamic".into(),
        group: model.group.name().into(),
        t_end: settings.t_end,
        ..Default::default()
    };
    let summary_path = out_dir.join("summary.json");
    summary.write(&summary_path)?;
    let names = SensorEvaluator::names(model);
    let mut csv = CsvWriter::create(&out_dir.join("sensors.csv"), &names)?;
    let mut shape = ShapeWriter::create(out_dir, "time", model)?;
    let mut sim = match Simulation::new(model, *settings) {
        Ok(sim) => sim,
        Err(e) => {
            summary.status = "failed".into();
            summary.error = Some(e.to_string());
            summary.wall_seconds = start.elapsed().as_secs_f64();
            summary.write(&summary_path)?;
            return Ok(summary);
        }
    };
    summary.unknowns = sim.data.layout.n_unknowns();
    summary.linear_solver = format!("{:?}", sim.data.solver.backend()).to_lowercase();
    summary.warnings = sim.warnings.clone();
    let mut sensors = SensorEvaluator::new(model);
    let mut output_seconds = 0.0;
    let t_end = settings.t_end;
    let result = sim.run(&mut |s| {
        let t0 = Instant::now();
        let values = sensors.evaluate(s.model, &s.data, &s.state);
        csv.row(s.state.t, &values)
            .map_err(|e| format!("writing {}: {e}", csv.path().display()))?;
        shape
            .write(s.state.t, s.model, &s.state)
            .map_err(|e| format!("writing nodes.csv: {e}"))?;
        progress(s.state.t, t_end);
        output_seconds += t0.elapsed().as_secs_f64();
        Ok(())
    });
    let wall = start.elapsed().as_secs_f64();
    let stats = sim.stats;
    summary.steps = stats.steps;
    summary.newton_iterations = stats.newton_iterations;
    summary.rejected_steps = stats.rejected_steps;
    summary.factorizations = sim.data.solver.factorizations();
    summary.outputs = stats.outputs;
    summary.newton_iterations_per_step = stats.newton_iterations as f64 / stats.steps.max(1) as f64;
    summary.t_reached = sim.state.t;
    summary.wall_seconds = wall;
    summary.solve_seconds = (wall - output_seconds).max(0.0);
    match result {
        Ok(_) => summary.status = "ok".into(),
        Err(e) => {
            summary.status = "failed".into();
            summary.error = Some(e.to_string());
        }
    }
    summary.write(&summary_path)?;
    Ok(summary)
}
