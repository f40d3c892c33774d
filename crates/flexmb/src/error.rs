//! Typed errors with the context a user needs to fix the cause.

use crate::model::ItemRef;

/// An inconsistent or unphysical model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("{item_table} '{name}' (#{index}), field '{field}': {message}", item_table = item.table, name = item.name, index = item.index + 1, field = item.field)]
    Invalid { item: ItemRef, message: String },
}

impl ModelError {
    /// The item and field the error is about.
    pub fn item(&self) -> &ItemRef {
        match self {
            ModelError::Invalid { item, .. } => item,
        }
    }
}

/// A solver setting outside its range ([`crate::solve::DynamicSettings::check`] and its
/// siblings): the model-file keys of `[solver]` the rule is about (the first is the one to
/// blame unless the file or a `--set` says otherwise) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("solver field '{}': {message}", keys[0])]
pub struct SettingsError {
    pub keys: Vec<&'static str>,
    pub message: String,
}

impl SettingsError {
    pub(crate) fn new(keys: &[&'static str], message: impl Into<String>) -> Self {
        Self {
            keys: keys.to_vec(),
            message: message.into(),
        }
    }

    /// `Err` unless `v > 0` and `lo <= v <= hi` (`lo > 0`).
    pub(crate) fn positive(key: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), Self> {
        if v <= 0.0 {
            return Err(Self::new(&[key], format!("must be positive, got {v}")));
        }
        Self::range(key, v, lo, hi)
    }

    /// `Err` unless `lo <= v <= hi`.
    pub(crate) fn range(key: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), Self> {
        if crate::model::limits::within(v, lo, hi) {
            Ok(())
        } else {
            Err(Self::new(
                &[key],
                format!(
                    "must be between {lo:e} and {hi:e} (see 'Ranges' in docs/model-format.md), got {v:e}"
                ),
            ))
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
    Linear(#[from] crate::solve::linear::LinearError),
    /// The consistent initial accelerations cannot be computed (e.g. `[M B^T; B 0]` is
    /// singular): the unknown blamed, if any, and the diagnosis.
    #[error("consistent initial accelerations at t = {t}: {message}")]
    InitialAccelerations {
        t: f64,
        unknown: Option<crate::data::UnknownId>,
        message: String,
    },
    /// The initial states of the elements cannot be computed: the equations of the control
    /// blocks' outputs at t = 0, solved at the initial kinematics, have a singular matrix,
    /// a value that is not finite, or do not converge (`error`); `unknown` and
    /// `worst_equation` name the output blamed.
    #[error("the initial states of the elements at t = 0 cannot be solved: {error}; worst equation: {worst_equation}")]
    InitialStates {
        error: Box<crate::solve::NewtonError>,
        unknown: Option<crate::data::UnknownId>,
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
        error: Box<crate::solve::NewtonError>,
        /// The unknown it blames.
        unknown: Option<crate::data::UnknownId>,
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
        error: Box<crate::solve::NewtonError>,
        unknown: Option<crate::data::UnknownId>,
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
