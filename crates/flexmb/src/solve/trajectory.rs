//! The trajectory of a dynamic run, kept for a backward sweep (a discrete adjoint runs the
//! steps in reverse and needs, at each, the start `s_n`, the step size and the converged
//! unknowns `x_{n+1}` of [`super::step::StepFunction`]; the end `s_{n+1}` is the next step's
//! start, or the run's last state, and is not kept twice).
//!
//! Keeping every step costs memory in proportion to the run. A [`Trajectory`] keeps the
//! [`Memory`] of the simulation every `every` steps (checkpointing in the sense of Griewank
//! & Walther 2000, ACM TOMS 26, "Revolve", with equidistant checkpoints) and recomputes the
//! steps between two checkpoints when the sweep reaches them: `n / every` memories and
//! `every` steps in memory at a time, for one more forward run. A restored simulation takes
//! the same steps as the original, bit for bit (`tests/physics/restart.rs`), so the sweep sees
//! exactly the trajectory of the run.

use super::dynamics::{DynamicSettings, Memory, Simulation};
use crate::error::SolveError;
use crate::model::Model;
use crate::solve::observe::{Observer, Sample, StepRecord};
use crate::state::State;
use std::sync::Arc;

/// One step of a trajectory.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrajectoryStep {
    /// Number of the step in the run (1 for the first).
    pub index: usize,
    /// Step size \[s\].
    pub h: f64,
    /// The state at the start, `s_n`.
    pub start: State,
    /// The converged unknowns `x_{n+1}` (layout of the Newton vector).
    pub unknowns: Vec<f64>,
    /// The constraint rows left out as redundant in the step (with the model, they give
    /// the layout of `unknowns`).
    pub redundant_rows: Vec<usize>,
    /// The held states its end sets, copies `(target, source)` of states
    /// ([`crate::solve::StepEvent::held`]). Empty without an event, and also for an event
    /// the derivatives do not go through (`StepEvent::held` is `None`: the sensitivity
    /// drivers refuse such a run; [`crate::solve::Simulation::last_step_event`] tells them
    /// apart).
    pub held: crate::elements::HeldStates,
}

impl TrajectoryStep {
    /// The time at the end of the step.
    pub fn t_end(&self) -> f64 {
        self.start.t + self.h
    }
}

/// The steps of a run, kept as checkpoints every `every` steps (an [`Observer`]).
pub struct Trajectory {
    model: Arc<Model>,
    settings: DynamicSettings,
    every: usize,
    /// Steps the simulation had taken when the trajectory started.
    first: usize,
    /// The memory at the start of step `first + k every + 1`, for `k = 0, 1, ...`.
    checkpoints: Vec<Memory>,
    /// Steps recorded.
    steps: usize,
}

impl Trajectory {
    /// A trajectory of `sim` from where it stands (call before running it), keeping a
    /// checkpoint every `every` steps (at least 1).
    pub fn new(sim: &Simulation, every: usize) -> Self {
        Self {
            model: Arc::clone(&sim.model),
            settings: sim.settings,
            every: every.max(1),
            first: sim.stats.steps,
            checkpoints: vec![sim.memory()],
            steps: 0,
        }
    }

    /// Steps recorded.
    pub fn len(&self) -> usize {
        self.steps
    }

    pub fn is_empty(&self) -> bool {
        self.steps == 0
    }

    /// Checkpoints kept.
    pub fn checkpoints(&self) -> usize {
        self.checkpoints.len()
    }

    /// The steps from checkpoint `k` to the next one, recomputed.
    pub fn segment(&self, k: usize) -> Result<Vec<TrajectoryStep>, SolveError> {
        let first = k * self.every;
        let count = self.every.min(self.steps.saturating_sub(first));
        let index0 = self.first + first;
        if count == 0 {
            return Ok(Vec::new());
        }
        let memory = self.checkpoints[k].clone();
        let mut sim = Simulation::restore(Arc::clone(&self.model), self.settings, memory)?;
        sim.keep_last_step(true);
        let mut out = Vec::with_capacity(count);
        for i in 1..=count {
            let start = sim.state.clone();
            let info = sim.step()?;
            let (unknowns, redundant_rows) = sim.last_step();
            let held = sim.last_step_event().and_then(|e| e.held);
            out.push(TrajectoryStep {
                index: index0 + i,
                h: info.h,
                start,
                unknowns: unknowns.to_vec(),
                redundant_rows: redundant_rows.to_vec(),
                held: held.unwrap_or_default(),
            });
        }
        Ok(out)
    }

    /// Calls `f` on every step from the last to the first, recomputing one segment at a
    /// time.
    pub fn backward(
        &self,
        f: &mut dyn FnMut(&TrajectoryStep) -> Result<(), String>,
    ) -> Result<(), SolveError> {
        for k in (0..self.checkpoints.len()).rev() {
            for step in self.segment(k)?.iter().rev() {
                f(step).map_err(SolveError::Output)?;
            }
        }
        Ok(())
    }
}

impl Observer for Trajectory {
    fn output(&mut self, _: &Sample) -> Result<(), String> {
        Ok(())
    }

    fn wants_steps(&self) -> bool {
        true
    }

    fn step(&mut self, record: &StepRecord) -> Result<(), String> {
        self.steps = record.index - self.first;
        if self.steps.is_multiple_of(self.every) {
            self.checkpoints.push(record.simulation.memory());
        }
        Ok(())
    }
}
