//! # flexmb: finite-element flexible multibody dynamics on Lie groups
//!
//! flexmb assembles rigid bodies, kinematic joints, springs and applied loads into one
//! monolithic index-3 DAE whose nodes live on a Lie group (R3xSO(3) or SE(3)), and integrates
//! it with the Lie group generalized-alpha method (Brüls & Cardona 2010; Arnold & Brüls
//! 2007). Newton iterates on vectors of the Lie algebra: no rotation parameterization, no
//! singularity.
//!
//! Layout of the crate (one concept per module):
//!
//! | module | what lives there |
//! |---|---|
//! | [`model`] | the immutable [`Model`]: nodes, bodies, joints, loads, springs, sensors |
//! | [`state`] | the [`State`]: q, v, vdot, a, lambda |
//! | [`data`] | [`Data`]: numbering of unknowns, sparsity pattern, scratch, linear solver |
//! | [`elements`] | force elements (rigid body, load, spring) behind one small trait |
//! | [`joints`] | holonomic constraints built from two primitives |
//! | [`assembly`] | the Newton system from element and joint contributions |
//! | [`solve`] | generalized-alpha, initial conditions, Newton, linear solver |
//! | [`sensors`] | output channels |
//! | [`input`] | the TOML model file |
//! | [`observe`] | observers: what a run reports to at its output points and steps |
//! | [`output`] | `sensors.csv` and `summary.json` |
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
pub mod model;
pub mod observe;
pub mod output;
pub mod sensors;
pub mod solve;
pub mod state;

pub use data::Data;
pub use error::{ModelError, SolveError};
pub use model::Model;
pub use solve::{DynamicSettings, Simulation};
pub use state::State;
