//! The run of a model file into an output directory: what `flexmb run` does.

use crate::input::{Analysis, ModelFile};
use crate::output::{CsvWriter, Summary};
use crate::sensors::SensorEvaluator;
use crate::solve::Simulation;
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
    let start = Instant::now();
    let model = &file.model;
    let Analysis::Dynamic(settings) = &file.analysis;
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
