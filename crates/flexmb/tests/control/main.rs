//! Control blocks coupled with the mechanics.
//!
//! One test binary per concept (the engine issue, item 7): each file below is a module.

#[path = "../common/mod.rs"]
mod common;

mod control;
mod control_arms;
