//! Gradients exact for the discrete scheme (direct and adjoint), the trajectory store, and runs with events.
//!
//! One test binary per concept (the engine issue, item 7): each file below is a module.

#[path = "../common/mod.rs"]
mod common;

mod sensitivity;
mod sensitivity_events;
mod trajectory;
