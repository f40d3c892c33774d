//! # flexmb: finite-element flexible multibody dynamics on Lie groups
//!
//! flexmb assembles rigid bodies, geometrically exact beams, kinematic joints, springs and
//! applied loads into one monolithic index-3 DAE whose nodes live on a Lie group (R3xSO(3)
//! or SE(3)), and integrates it with the Lie group generalized-alpha method (Brüls & Cardona
//! 2010; Arnold & Brüls 2007), in index-3 or stabilized index-2 form; static equilibrium is
//! followed by load control, arc length or a pseudo-dynamic run. Newton iterates on vectors
//! of the Lie algebra: no rotation parameterization, no singularity.
//!
//! Layout of the crate (one concept per module; `docs/architecture.md` follows one step
//! through them):
//!
//! | module | what lives there |
//! |---|---|
//! | [`model`] | the immutable [`Model`]: nodes, bodies, beams, joints, loads, springs, sensors; [`model::Parameters`], its parameters by path |
//! | [`state`] | the [`State`]: q, v, vdot, a, lambda |
//! | [`data`] | [`data::Layout`] (the blocks of the Newton vector, typed [`data::UnknownId`]) and [`Data`]: sparsity pattern, matrix values, residual, linear solver |
//! | [`elements`] | force elements (rigid body, beam, load, spring) behind small capability traits |
//! | [`joints`] | holonomic constraints built from two primitives |
//! | [`assembly`] | the residual and iteration matrix at an explicit iterate, in one traversal |
//! | [`parallel`] | the threads of the assembly: the setting, the size below which a model stays sequential |
//! | [`parameter_derivatives`] | derivatives of the equations with respect to model parameters |
//! | [`solve`] | the Newton solver, the generalized-alpha step as functions, dynamics (step control, checkpoints), statics (load control, arc length, pseudo-dynamic), initial conditions, the trajectory for a backward sweep, the linear solver |
//! | [`sensors`] | output channels |
//! | [`input`] | the TOML model file |
//! | [`observe`] | observers: what a run reports to at its output points and steps |
//! | [`output`] | result files: `sensors.csv`, `nodes.csv`, `beams.csv`, `summary.json`, `checkpoint.json` |
//! | [`driver`] | the run of a model file into an output directory (`flexmb run`) |
//! | [`error`] | typed errors with their diagnosis |
//!
//! The convenient API: build or read a [`Model`], then
//! `Simulation::new(&model, settings)?.run(&mut |s: &observe::Sample| { ... })`, or step by
//! step with [`Simulation::step`].

pub mod assembly;
pub mod data;
pub mod driver;
pub mod elements;
pub mod error;
pub mod input;
pub mod joints;
pub mod kernel;
#[cfg(test)]
mod layers;
pub mod linear;
pub mod model;
pub mod output;
pub mod parallel;
pub mod parameter_derivatives;
pub mod sensitivity;
pub mod sensors;
pub mod solve;
pub mod state;

pub use data::Data;
pub use error::{ModelError, SolveError};
pub use model::Model;
/// Observers of a run ([`solve::observe`]), kept under this path too.
pub use solve::observe;
pub use solve::{DynamicSettings, Simulation};
pub use state::State;
