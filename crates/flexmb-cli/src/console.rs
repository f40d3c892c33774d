//! Messages to the terminal.
//!
//! Contract: writing to stdout or stderr never panics and never changes the exit code. A
//! closed or broken stream (`flexmb check model.toml | head -c0`, a closed terminal) loses
//! the message; the exit code and the result files still say what happened.

use std::fmt::Arguments;
use std::io::Write;

/// Writes one line to stdout.
pub fn say(line: Arguments) {
    let _ = writeln!(std::io::stdout().lock(), "{line}");
}

/// Writes one line to stderr.
pub fn tell(line: Arguments) {
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}
