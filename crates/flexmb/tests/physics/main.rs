//! Physics against analytic solutions, published references and conservation laws; the solver's behaviour (matrix reuse, restarts, robustness, threads, scaling).
//!
//! One test binary per concept (the engine issue, item 7): each file below is a module.

#[path = "../common/mod.rs"]
mod common;

mod beams_dynamic;
mod beams_static;
mod bushing;
mod chains;
mod contact;
mod driveline;
mod element_states;
mod force_laws;
mod gears;
mod heavy_top;
mod iftomm;
mod linear_oscillator;
mod matrix_reuse;
mod pendulum;
mod restart;
mod robustness;
mod rope;
mod slider_crank;
mod threads;
