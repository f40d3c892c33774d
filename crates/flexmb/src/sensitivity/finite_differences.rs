//! Central finite differences of the criteria: `2 n_p + 1` runs, for checking the exact
//! gradients on any model.

use super::criteria::History;
use super::{Gradients, Problem, SensitivityError, Stats};

/// The criteria of `problem` (one run), its steps and its warnings.
pub fn criteria_values(
    problem: &Problem,
) -> Result<(Vec<f64>, usize, Vec<String>), SensitivityError> {
    if let crate::solve::Analysis::Static(settings) = &problem.analysis {
        let (statics, history) = super::statics::solve(problem, settings)?;
        let steps = statics.stats.steps;
        return Ok((problem.criteria.values(&history), steps, statics.warnings));
    }
    let settings = *problem.dynamic()?;
    let mut sim = crate::solve::Simulation::new(std::sync::Arc::clone(&problem.model), settings)?;
    let layout = sim.data.layout.clone();
    let mut rec = super::Recorder {
        problem,
        layout: &layout,
        redundant: layout.redundant_rows(),
        events: None,
        history: History::default(),
        steps: None,
        most_steps: 0,
        count: 0,
    };
    problem
        .criteria
        .record(&problem.model, &layout, &sim.state, &mut rec.history);
    let stats = sim.run(&mut rec)?;
    Ok((
        problem.criteria.values(&rec.history),
        stats.steps,
        sim.warnings,
    ))
}

/// The criteria of `problem` and their central differences with relative step `step`:
/// `dJ/dp_k = (J(p + e_k d_k) - J(p - e_k d_k)) / (2 d_k)`, `d_k = step max(|p_k|, scale_k)`
/// (the design parameter's typical magnitude, [`Problem::scales`]). A step that leaves a
/// parameter unchanged (`p_k +- d_k == p_k`: a step below the parameter's round-off) is an
/// error, not a zero derivative.
pub fn finite_differences(problem: &Problem, step: f64) -> Result<Gradients, SensitivityError> {
    let (values, steps, warnings) = criteria_values(problem)?;
    let p0 = problem.values();
    let mut gradients = vec![vec![0.0; p0.len()]; values.len()];
    let mut fd_steps = Vec::with_capacity(p0.len());
    for k in 0..p0.len() {
        let d = step * p0[k].abs().max(problem.scales[k]);
        let error =
            |value: f64, failed: Option<SensitivityError>| SensitivityError::FiniteDifference {
                path: problem.params.path(problem.design[k]).to_string(),
                value,
                step: d,
                failed: failed.map(Box::new),
            };
        if p0[k] + d == p0[k] || p0[k] - d == p0[k] {
            return Err(error(p0[k], None));
        }
        let at = |sign: f64| {
            let mut p = p0.clone();
            p[k] += sign * d;
            criteria_values(&problem.with_values(&p))
                .map(|r| r.0)
                .map_err(|e| error(p[k], Some(e)))
        };
        let (plus, minus) = (at(1.0)?, at(-1.0)?);
        for c in 0..values.len() {
            gradients[c][k] = (plus[c] - minus[c]) / (2.0 * d);
        }
        fd_steps.push(d);
    }
    Ok(Gradients {
        values,
        gradients,
        fd_steps: Some(fd_steps),
        stats: Stats {
            forward_runs: 2 * p0.len() + 1,
            steps,
            ..Stats::default()
        },
        warnings,
    })
}
