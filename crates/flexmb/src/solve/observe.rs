//! Observers: what an analysis calls at its output points, and after every step for those
//! that ask, so that outputs (result files, progress, a trajectory for a backward sweep,
//! checkpoints) are composed by the caller instead of being written inside the solver.
//!
//! A dynamic run calls [`Observer::output`] at `t = 0` and at every output time, and, when
//! [`Observer::wants_steps`], [`Observer::step`] after every accepted step with a
//! [`StepRecord`]: the start `s_n`, the step size, the converged unknowns `x_{n+1}` and the
//! end `s_{n+1}` (what [`crate::solve::step::StepFunction`] needs to re-evaluate the step);
//! [`Observer::accepted`] gets every accepted step's statistics, for all observers.
//! A static run calls `output` at load factor 0 and after every converged load step.

use crate::data::Data;
use crate::model::Model;
use crate::solve::StepInfo;
use crate::state::State;

/// A point of a run as observers see it.
#[derive(Clone, Copy)]
pub struct Sample<'a> {
    pub model: &'a Model,
    pub data: &'a Data,
    pub state: &'a State,
    /// Time \[s\] (dynamics) or load factor (statics): the first column of the results.
    pub at: f64,
    /// The work done to reach it.
    pub work: Work,
}

/// The work an analysis has done: accepted steps (load steps), Newton iterations, rejected
/// attempts and factorizations of the iteration matrix (of every attempt).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Work {
    pub steps: usize,
    pub newton_iterations: usize,
    pub rejected_steps: usize,
    pub factorizations: usize,
}

/// One accepted step of a dynamic run.
#[derive(Clone, Copy)]
pub struct StepRecord<'a> {
    /// The simulation after the step (e.g. for [`crate::solve::Simulation::memory`]).
    pub simulation: &'a crate::solve::Simulation,
    /// Number of the step (1 for the first).
    pub index: usize,
    /// The state at the start of the step, `s_n`.
    pub start: &'a State,
    /// The converged unknowns `x_{n+1}` in the layout of the Newton vector (scaled
    /// multipliers `mu = s lambda`; see [`crate::solve::step`]).
    pub unknowns: &'a [f64],
    /// The constraint rows left out as redundant in the step (the layout of `unknowns`).
    pub redundant_rows: &'a [usize],
    /// The state at the end, `s_{n+1}`.
    pub end: &'a State,
    pub info: &'a StepInfo,
}

/// Something a run reports to. An error stops the run ([`crate::error::SolveError::Output`]), with
/// every earlier output delivered.
pub trait Observer {
    /// Called at every output point.
    fn output(&mut self, sample: &Sample) -> Result<(), String>;
    /// Whether [`Observer::step`] should be called (the simulation then keeps a copy of each
    /// step's unknowns).
    fn wants_steps(&self) -> bool {
        false
    }
    /// Called after every accepted step of a dynamic run when [`Observer::wants_steps`].
    fn step(&mut self, _record: &StepRecord) -> Result<(), String> {
        Ok(())
    }
    /// Called after every accepted step of a dynamic run, and every converged load step of a
    /// static run by load control or arc length (the load factor as `t`, the increment as
    /// `h`), with its statistics (costs the run nothing more: no copy of the step is kept).
    fn accepted(&mut self, _info: &StepInfo) -> Result<(), String> {
        Ok(())
    }
}

/// A closure is an observer of the output points.
impl<F: FnMut(&Sample) -> Result<(), String>> Observer for F {
    fn output(&mut self, sample: &Sample) -> Result<(), String> {
        self(sample)
    }
}

/// Several observers, called in order.
pub struct Observers<'a>(pub Vec<&'a mut dyn Observer>);

impl Observer for Observers<'_> {
    fn output(&mut self, sample: &Sample) -> Result<(), String> {
        self.0.iter_mut().try_for_each(|o| o.output(sample))
    }
    fn wants_steps(&self) -> bool {
        self.0.iter().any(|o| o.wants_steps())
    }
    fn step(&mut self, record: &StepRecord) -> Result<(), String> {
        self.0
            .iter_mut()
            .filter(|o| o.wants_steps())
            .try_for_each(|o| o.step(record))
    }
    fn accepted(&mut self, info: &StepInfo) -> Result<(), String> {
        self.0.iter_mut().try_for_each(|o| o.accepted(info))
    }
}
