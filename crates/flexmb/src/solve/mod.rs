//! Solvers: generalized-alpha time integration on the Lie group, consistent initial
//! conditions, and the linear solver behind both.

pub mod dynamics;
pub mod generalized_alpha;
pub mod initial;
pub mod linear;
pub mod newton;
pub mod statics;
pub mod step;
pub mod trajectory;

pub use dynamics::{DynamicSettings, Formulation, IntoShared, Scheme, Simulation, Stats, StepInfo};
pub use generalized_alpha::GaParameters;
pub use initial::{initial_accelerations, prepare_layout};
pub use newton::{NewtonError, NewtonSettings, Verification};
pub use statics::{StaticMethod, StaticSettings, StaticStats, Statics};
