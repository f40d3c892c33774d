//! The `flexmb` command line: commands, exit codes, output folders, results files, resume, signals, sensitivity.
//!
//! One test binary per concept (the engine issue, item 7): each file below is a module.

#[path = "../common/mod.rs"]
mod common;

mod broken_pipe;
mod cli;
mod exit_codes;
mod output_dir;
mod results_file;
mod resume;
mod sensitivity;
mod signals;
