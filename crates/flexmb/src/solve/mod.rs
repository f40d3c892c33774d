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
pub mod linear;
pub mod newton;
pub mod statics;
pub mod step;
pub mod trajectory;

pub use dynamics::{
    DynamicSettings, Formulation, IntoShared, LieUpdate, Scheme, Simulation, Stats, StepEvent,
    StepInfo,
};
pub use generalized_alpha::{FirstOrderParameters, GaParameters};
pub use initial::{initial_accelerations, prepare_layout};
pub use newton::{NewtonError, NewtonSettings, Verification};
pub use statics::{StaticMethod, StaticSettings, Statics};
