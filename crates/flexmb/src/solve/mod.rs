//! Solvers: one Newton iteration ([`newton`]) over the [`newton::NonlinearSystem`] trait
//! serves the generalized-alpha step on the Lie group ([`dynamics`]: [`Simulation`], step
//! control, checkpoints), static equilibrium by load control, arc length or a
//! pseudo-dynamic run ([`statics`]) and the consistent initial accelerations ([`initial`]);
//! [`step`] writes the step's relations as functions, with the step residual's exact
//! Jacobian for derivatives; [`trajectory`] keeps a run for a backward sweep; [`linear`] is
//! the sparse or dense LU behind all of them; [`generalized_alpha`] the scheme's parameters.

pub mod dynamics;
pub mod generalized_alpha;
pub mod initial;
pub mod newton;
pub mod observe;
pub mod statics;
pub mod step;
pub mod trajectory;

/// The sparse linear solvers, a lower layer ([`crate::linear`]); kept under this path too.
pub use crate::linear;
pub use dynamics::{
    DynamicSettings, Formulation, IntoShared, LieUpdate, Scheme, Simulation, Stats, StepEvent,
    StepInfo,
};
pub use generalized_alpha::{FirstOrderParameters, GaParameters};
pub use initial::{initial_accelerations, prepare_layout};
pub use newton::{NewtonError, NewtonSettings, Verification};
pub use statics::{StaticMethod, StaticSettings, Statics};

/// An analysis and its settings: what the `[solver]` table of a model file requests.
#[derive(Clone, Debug, PartialEq)]
pub enum Analysis {
    /// `analysis = "dynamic"`: time integration with the Lie group generalized-alpha method.
    Dynamic(DynamicSettings),
    /// `analysis = "static"`: equilibrium followed in the load factor.
    Static(StaticSettings),
}

impl Analysis {
    /// The dynamic settings, if this is a dynamic analysis.
    pub fn dynamic(&self) -> Option<&DynamicSettings> {
        match self {
            Analysis::Dynamic(s) => Some(s),
            Analysis::Static(_) => None,
        }
    }
}
