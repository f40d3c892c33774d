//! The discrete adjoint: a forward run that keeps its trajectory, then one backward sweep
//! for all criteria (module documentation of [`super`]).

use super::criteria::{weight, History};
use super::matrix::StepMatrix;
use super::pipeline::{self, prepare_function, Prepared, Spare};
use super::{pick, state_bytes, Gradients, Problem, SensitivityError, Stats};
use crate::data::Data;
use crate::data::Layout;
use crate::model::Model;
use crate::solve::observe::Observers;
use crate::solve::step::{StateTangent, StepFunction};
use crate::solve::trajectory::{Trajectory, TrajectoryStep};
use crate::state::State;

/// The backward sweep's state: one cotangent of the state and of the parameters per
/// criterion.
struct Backward<'a> {
    problem: &'a Problem,
    layout: &'a Layout,
    data: &'a mut Data,
    spare: &'a mut Spare,
    /// The step Jacobian's values (scratch).
    values: Vec<f64>,
    hs: Vec<f64>,
    history: &'a History,
    /// `sbar` per criterion.
    bars: Vec<StateTangent>,
    /// `pbar` per criterion (design parameters).
    pbars: Vec<Vec<f64>>,
    index: Vec<Option<usize>>,
    scratch: Model,
}

impl Backward<'_> {
    /// Adds `c_n f_s(s_n)` and `c_n f_p(s_n)` of point `n`.
    fn point(&mut self, n: usize, state: &State) {
        let p = self.problem;
        let weights: Vec<f64> = p
            .criteria
            .criteria
            .iter()
            .map(|c| weight(c.kind, n, &self.hs))
            .collect();
        if weights.iter().all(|&w| w == 0.0) {
            return;
        }
        let grads = p.criteria.point_gradients(
            &p.model,
            self.layout,
            state,
            &self.history.values[n],
            &weights,
            (&p.params, &p.design, &mut self.scratch),
        );
        for (g, coef) in &grads {
            for (c, &cc) in coef.iter().enumerate() {
                if cc != 0.0 {
                    g.add_to(cc, &mut self.bars[c]);
                    for &(id, d) in &g.params {
                        if let Some(k) = self.index[id.0 as usize] {
                            self.pbars[c][k] += cc * d;
                        }
                    }
                }
            }
        }
    }

    /// Step `n` backward: `sbar_n` to `sbar_{n-1}`, the step prepared here.
    fn step(&mut self, step: &TrajectoryStep) -> Result<(), String> {
        let p = self.problem;
        let settings = p.dynamic().map_err(|e| e.to_string())?;
        let spare = std::mem::take(self.spare);
        let at = (step.index, &step.start, step.h, &step.unknowns[..]);
        let (data, values) = (&mut *self.data, &mut self.values);
        let (f, mut matrix) =
            prepare_function(&p.model, self.layout, settings, at, data, spare, values)?;
        self.backward(step, &f, &mut matrix);
        *self.spare = Spare::after(matrix, &f);
        Ok(())
    }

    /// Step `n` backward with its Jacobian prepared on another thread; gives the
    /// preparation's storage back.
    fn finish(&mut self, prepared: Prepared<&TrajectoryStep>) -> Result<Spare, String> {
        let p = self.problem;
        let settings = p.dynamic().map_err(|e| e.to_string())?;
        let Prepared {
            step,
            partials,
            mut matrix,
        } = prepared;
        let f = StepFunction::new(&p.model, self.layout, &step.start, settings, step.h)
            .with_partials(partials);
        self.backward(step, &f, &mut matrix);
        Ok(Spare::after(matrix, &f))
    }

    /// Step `n` backward: `f` its step function, `matrix` its factorized Jacobian.
    fn backward(&mut self, step: &TrajectoryStep, f: &StepFunction, matrix: &mut StepMatrix) {
        let p = self.problem;
        let x = &step.unknowns;
        for c in 0..self.bars.len() {
            // from the state after the step's held states are set to the step's end
            self.bars[c].hold_transposed(&step.held);
            let (mut mu, mut start, pe) =
                f.end_vjp(x, &self.bars[c], Some((&p.params, &p.design)), self.data);
            matrix.solve_transpose(&mut mu);
            start.add_scaled(-1.0, &f.start_vjp(x, &mu, self.data));
            let pr = f.parameter_vjp_for(x, &p.params, &p.design, &mu, self.data);
            pick(&self.index, &pr, &mut self.pbars[c], -1.0);
            if !pe.is_empty() {
                pick(&self.index, &pe, &mut self.pbars[c], 1.0);
            }
            self.bars[c] = start;
        }
        self.point(step.index - 1, &step.start);
    }
}

/// What the adjoint keeps between calls on problems of one structure (an optimizer's
/// iterations): the scratch data of the layout, with the step Jacobian's positions, the
/// factorization's symbolic analysis, and the storage of the trajectory's steps (within
/// the memory budget).
#[derive(Default)]
pub struct Workspace {
    data: Option<Data>,
    spare: Spare,
    steps: Vec<TrajectoryStep>,
    /// The scratch and the storage of the threads that prepare the sweep's steps ahead of
    /// it.
    sweepers: Vec<Option<Data>>,
    sweepers_spares: Vec<std::sync::Mutex<Vec<Spare>>>,
}

impl Workspace {
    /// The scratch data for `layout` of `model`: the one kept if it has that layout.
    fn data(
        &mut self,
        model: &crate::model::Model,
        layout: &Layout,
        threads: &crate::parallel::Threads,
    ) -> Result<&mut Data, SensitivityError> {
        if !refit(&mut self.data, model, layout)? {
            self.data = self.data.take().map(|d| d.with_threads(threads.clone()));
            self.spare = Spare::default();
        }
        Ok(self.data.as_mut().expect("set above"))
    }
}

/// Makes `kept` scratch data for `layout` of `model`: kept if it has that layout (with the
/// model's nodal masses: its parameters may have moved), built otherwise (then `false`).
fn refit(
    kept: &mut Option<Data>,
    model: &crate::model::Model,
    layout: &Layout,
) -> Result<bool, SensitivityError> {
    let fits = kept.as_ref().is_some_and(|d| {
        d.layout.active_rows == layout.active_rows
            && d.layout.stabilized == layout.stabilized
            && d.layout.n_unknowns() == layout.n_unknowns()
    });
    match kept {
        Some(data) if fits => data.nodal_mass = crate::data::nodal_mass(model),
        _ => {
            *kept = Some(Data::new(model, layout.clone()).map_err(crate::error::SolveError::from)?)
        }
    }
    Ok(fits)
}

/// The criteria of `problem` and their gradients by the discrete adjoint. `progress` is
/// called with `(steps done, steps)` during the backward sweep.
pub fn adjoint(
    problem: &Problem,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Gradients, SensitivityError> {
    adjoint_in(problem, &mut Workspace::default(), progress)
}

/// [`adjoint`] with the scratch of `workspace`, kept for the next call.
pub fn adjoint_in(
    problem: &Problem,
    workspace: &mut Workspace,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Gradients, SensitivityError> {
    let (mut sim, tangents) = super::start(problem)?;
    let layout = sim.data.layout.clone();
    let settings = problem.dynamic()?;
    // Every step kept if the run's estimated steps fit in the budget, else checkpoints.
    // The memory: checkpoints every `k` steps, always (a segment of k steps and the
    // checkpoints of up to 2 N steps fit the budget, N estimated as t_end / h), and every
    // step as long as the steps fit beside the checkpoints. A run that takes more steps
    // than that (steps shortened for output times or after failures) drops the steps it
    // kept and sweeps from the checkpoints instead.
    let state = state_bytes(&sim.state);
    let step_bytes = state + 8 * layout.n_unknowns() + 64;
    let expected = ((settings.t_end / settings.h).ceil() as usize).max(1) + 1;
    let budget = problem.memory_budget;
    let memory_bytes = state + 8 * (sim.data.values.len() + 6 * layout.n_unknowns()) + 256;
    let checkpoints_of = |k: usize| (2 * expected / k + 1) * memory_bytes;
    let total = |k: usize| k * step_bytes + checkpoints_of(k);
    let best = ((2 * expected * memory_bytes) as f64 / step_bytes as f64).sqrt() as usize;
    let best = best.clamp(1, expected);
    if total(best) > budget {
        return Err(SensitivityError::MemoryBudget {
            budget,
            needed: total(best),
            steps: expected,
            step_bytes,
            checkpoint_bytes: memory_bytes,
        });
    }
    let every = (best..=expected)
        .take_while(|&k| total(k) <= budget)
        .last()
        .unwrap_or(best);
    let checkpoints_bytes = checkpoints_of(every);
    let mut trajectory = Trajectory::new(&sim, every);
    let mut forward = super::Recorder {
        problem,
        layout: &layout,
        redundant: layout.redundant_rows(),
        events: Some(super::EventWatch::default()),
        history: History::default(),
        steps: Some(std::mem::take(&mut workspace.steps)),
        most_steps: budget.saturating_sub(checkpoints_bytes) / step_bytes,
        count: 0,
    };
    problem
        .criteria
        .record(&problem.model, &layout, &sim.state, &mut forward.history);
    let clock = std::time::Instant::now();
    let run = sim.run(&mut Observers(vec![&mut trajectory, &mut forward]));
    let events = forward.events.take().unwrap_or_default();
    events.outcome(run)?;
    let forward_seconds = clock.elapsed().as_secs_f64();
    let n_steps = forward.count;
    let history = forward.history;
    let mut stats = Stats {
        forward_runs: 1,
        steps: n_steps,
        forward_seconds,
        jacobian_threads: 1,
        ..Stats::default()
    };
    let n_c = problem.criteria.len();
    workspace.data(&problem.model, &layout, &sim.data.threads)?;
    let Workspace {
        data,
        spare,
        steps: kept,
        sweepers,
        sweepers_spares,
    } = workspace;
    let mut back = Backward {
        problem,
        layout: &layout,
        data: data.as_mut().expect("prepared above"),
        spare,
        values: Vec::new(),
        hs: history.steps(),
        history: &history,
        bars: vec![StateTangent::zeros_of(&layout); n_c],
        pbars: vec![vec![0.0; problem.design.len()]; n_c],
        index: problem.design_index(),
        scratch: (*problem.model).clone(),
    };
    let clock = std::time::Instant::now();
    back.point(n_steps, &sim.state);
    let mut done = 0;
    let mut progress = |_: &TrajectoryStep| -> Result<(), String> {
        done += 1;
        progress(done, n_steps);
        Ok(())
    };
    let checkpoints = trajectory.checkpoints() * memory_bytes;
    // The steps' Jacobians on the threads of the setting (from the size where they pay).
    let workers = crate::parallel::resolve(settings.threads).min(n_steps);
    let parallel = workers > 1 && layout.n_unknowns() >= pipeline::PARALLEL_FROM;
    if parallel {
        stats.jacobian_threads = workers;
        sweepers.resize_with(workers, || None);
        sweepers_spares.resize_with(workers, Default::default);
        // (A spare factorization of another pattern rebuilds its analysis.)
        for kept in sweepers.iter_mut() {
            refit(kept, &problem.model, &layout)?;
        }
    }
    // The sweep through consecutive steps, from the last.
    let mut sweep = |steps: &[TrajectoryStep]| -> Result<(), crate::error::SolveError> {
        if parallel {
            let scratch: Vec<&mut Data> = sweepers.iter_mut().flatten().collect();
            pipeline::run(
                &problem.model,
                &layout,
                settings,
                scratch,
                sweepers_spares,
                steps.iter().rev(),
                &mut |prepared| {
                    let step = prepared.step;
                    let spare = back.finish(prepared)?;
                    progress(step)?;
                    Ok(spare)
                },
            )
        } else {
            steps.iter().rev().try_for_each(|step| {
                back.step(step)?;
                progress(step)
            })
        }
        .map_err(crate::error::SolveError::Output)
    };
    match forward.steps {
        Some(mut steps) => {
            stats.trajectory_bytes = checkpoints + n_steps * step_bytes;
            sweep(&steps[..n_steps])?;
            // Kept for the next call, without the slots of an earlier, longer run (the
            // storage held stays what this run's budget allowed).
            steps.truncate(n_steps);
            *kept = steps;
        }
        None => {
            stats.checkpoints = trajectory.checkpoints();
            stats.recomputed_steps = n_steps;
            stats.trajectory_bytes = checkpoints + every * step_bytes;
            // One segment at a time, recomputed from its checkpoint.
            for k in (0..trajectory.checkpoints()).rev() {
                sweep(&trajectory.segment(k)?)?;
            }
        }
    }
    stats.sweep_seconds = clock.elapsed().as_secs_f64();
    let mut gradients = back.pbars;
    for (c, g) in gradients.iter_mut().enumerate() {
        for (k, ds) in tangents.iter().enumerate() {
            g[k] += back.bars[c].dot(ds);
        }
    }
    Ok(Gradients {
        values: problem.criteria.values(&history),
        gradients,
        fd_steps: None,
        stats,
        warnings: sim.warnings,
    })
}
