//! Typed errors with the context a user needs to fix the cause: the model's
//! ([`ModelError`], [`SettingsError`], defined with the model) and an analysis' ([`SolveError`],
//! with the Newton solver's [`NewtonError`] and the unknown [`UnknownId`] a failure blames).

use crate::linear::LinearError;
use crate::model::{JointId, NodeId};
pub use crate::model::{ModelError, SettingsError};

/// One unknown of the Newton vector, by what it belongs to: the typed form of an index that
/// failures and diagnoses carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnknownId {
    /// Component (0 to 5: x, y, z, rx, ry, rz) of a node's increment; its equation is that
    /// component of the node's equilibrium.
    Node { node: NodeId, component: u8 },
    /// Multiplier of a joint's row (0-based within the joint); its equation is the row.
    Multiplier { joint: JointId, row: u8 },
    /// Stabilization unknown of a joint's row; its equation is the row at velocity level.
    Stabilization { joint: JointId, row: u8 },
    /// State `index` (0-based) of element `element` (index in [`crate::data::Layout::elements`]); its
    /// equation is the element's equation for it.
    State { element: usize, index: u16 },
}

/// Why a Newton solve failed, with the unknown to blame (an index of the Newton vector;
/// [`crate::data::Layout::unknown`] names it).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NewtonError {
    #[error("non-finite residual")]
    NonFiniteResidual { unknown: usize },
    #[error("non-finite Newton correction")]
    NonFiniteCorrection { unknown: usize },
    #[error("singular iteration matrix ({source})")]
    Singular {
        unknown: Option<usize>,
        source: LinearError,
    },
    #[error("Newton diverging (weighted correction {error:.3e}, contraction rate {rate:.3})")]
    Diverging {
        error: f64,
        rate: f64,
        unknown: usize,
    },
    #[error("no convergence in {iterations} iterations (weighted correction {error:.3e})")]
    MaxIterations {
        iterations: usize,
        error: f64,
        unknown: usize,
    },
    /// A failure particular to the system (e.g. no real root of the arc-length constraint).
    #[error("{message}")]
    System {
        message: String,
        unknown: Option<usize>,
    },
}

impl NewtonError {
    /// The unknown to blame, if any.
    pub fn unknown(&self) -> Option<usize> {
        match *self {
            NewtonError::NonFiniteResidual { unknown }
            | NewtonError::NonFiniteCorrection { unknown }
            | NewtonError::Diverging { unknown, .. }
            | NewtonError::MaxIterations { unknown, .. } => Some(unknown),
            NewtonError::Singular { unknown, .. } | NewtonError::System { unknown, .. } => unknown,
        }
    }
}

/// A failure during an analysis, with its diagnosis.
#[derive(Debug, Clone, thiserror::Error)]
pub enum SolveError {
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The linear solver could not be set up for the model (its pattern).
    #[error("linear solver: {0}")]
    Linear(#[from] crate::linear::LinearError),
    /// The consistent initial accelerations cannot be computed (e.g. `[M B^T; B 0]` is
    /// singular): the unknown blamed, if any, and the diagnosis.
    #[error("consistent initial accelerations at t = {t}: {message}")]
    InitialAccelerations {
        t: f64,
        unknown: Option<UnknownId>,
        message: String,
    },
    /// The initial states of the elements cannot be computed: the equations of the control
    /// blocks' outputs at t = 0, solved at the initial kinematics, have a singular matrix,
    /// a value that is not finite, or do not converge (`error`); `unknown` and
    /// `worst_equation` name the output blamed.
    #[error("the initial states of the elements at t = 0 cannot be solved: {error}; worst equation: {worst_equation}")]
    InitialStates {
        error: Box<NewtonError>,
        unknown: Option<UnknownId>,
        worst_equation: String,
    },
    #[error(transparent)]
    Settings(#[from] SettingsError),
    #[error("inconsistent initial conditions: {0}")]
    InconsistentInitialConditions(String),
    #[error("Newton failed at step {step}, t = {t:.6e} s (last step tried h = {h:.3e} s, {reductions} step-size reductions): {reason}; worst equation: {worst_equation}")]
    NewtonFailed {
        step: usize,
        t: f64,
        h: f64,
        reductions: usize,
        /// The failure of the last attempt.
        error: Box<NewtonError>,
        /// The unknown it blames.
        unknown: Option<UnknownId>,
        /// `error` in words, with the count of rejected steps when reductions kept coming.
        reason: String,
        /// `unknown` in words.
        worst_equation: String,
    },
    #[error("static analysis failed at load step {step}, load factor {load_factor:.6e} (last increment tried {increment:.3e}, {rejected} rejected steps): {reason}; worst equation: {worst_equation}")]
    StaticFailed {
        step: usize,
        load_factor: f64,
        increment: f64,
        rejected: usize,
        /// The failure of the last attempt.
        error: Box<NewtonError>,
        unknown: Option<UnknownId>,
        reason: String,
        worst_equation: String,
    },
    #[error("the step size {h:.3e} s is below the resolution of the time t = {t:.6e} s (t + h == t): the run cannot advance")]
    StepUnderflow { t: f64, h: f64 },
    /// A checkpoint that cannot be resumed.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error("output error: {0}")]
    Output(String),
    /// The run was stopped from outside (a signal) through the solver's interrupt flag; the
    /// results up to `reached` (time or load factor) are complete.
    #[error("interrupted at {reached:.6e}")]
    Interrupted { reached: f64 },
    /// The analysis stopped at a limit of its settings before its end (a static analysis:
    /// `max_steps` load steps before the final load factor `end`). Nothing failed: the
    /// results up to `reached` (the load factor of the last converged step) are complete;
    /// `reason` names the limit and the setting to raise.
    #[error("the analysis stopped at load factor {reached:.6e}, before its final load factor {end}: {reason}")]
    Incomplete {
        reached: f64,
        end: f64,
        reason: String,
    },
}

impl SolveError {
    /// Whether the error rejects the model before its first step: the model, the settings,
    /// the linear solver's setup, the initial conditions or a checkpoint (what `flexmb run`
    /// reports as `error_kind` `model`, exit code 2), not a step that failed.
    pub fn is_before_first_step(&self) -> bool {
        matches!(
            self,
            SolveError::Model(_)
                | SolveError::Linear(_)
                | SolveError::InitialAccelerations { .. }
                | SolveError::Settings(_)
                | SolveError::InconsistentInitialConditions(_)
                | SolveError::Checkpoint(_)
        )
    }
}
