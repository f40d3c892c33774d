//! The model file: reading, located errors for bad input, limits, time functions and display geometry.
//!
//! One test binary per concept (the engine issue, item 7): each file below is a module.

#[path = "../common/mod.rs"]
mod common;

mod beam_elements;
mod display_geometry;
mod fuzz_model_reader;
mod input_limits;
mod inputs;
mod model_file_errors;
mod time_functions;
