//! Tangent matrices, step Jacobians and parameter derivatives against finite differences on the manifold; the parameter registry.
//!
//! One test binary per concept (the engine issue, item 7): each file below is a module.

#[path = "../common/mod.rs"]
mod common;

mod global_jacobian;
mod parameter_registry;
mod parameters_match_finite_differences;
mod step_jacobians;
mod tangents_match_finite_differences;
