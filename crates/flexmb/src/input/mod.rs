//! The TOML model file: a front end that builds the same [`Model`] a Rust user builds by hand
//! (with [`Model::new`], [`Model::add_node`], [`Model::add_body`], [`Model::add_joint`],
//! [`Model::add_beam`], ...) plus the settings of the analysis to run on it, dynamic or static.
//! `[[beam]]` items are meshed here into nodes `<name>.<i>` and elements `<name>[<i>]`.
//!
//! The format is documented in `docs/model-format.md`. Every error names the file, the line
//! and the path of the field (`body[2].mass`), including the errors of [`Model::validate`],
//! which are mapped back to the line of the offending field.
//!
//! ```no_run
//! use flexmb::input::{read_model_file, Analysis};
//! let file = read_model_file("top.toml".as_ref(), &["solver.h=5e-4".to_string()])?;
//! let Analysis::Dynamic(settings) = file.analysis else { panic!("not dynamic") };
//! let mut sim = flexmb::Simulation::new(&file.model, settings).unwrap();
//! # Ok::<(), flexmb::input::InputError>(())
//! ```
//!
//! Overrides (`--set` on the command line) are `key.path=value` strings applied to the parsed
//! document before it is interpreted:
//! - `solver.h=0.0005`, `model.gravity.2=-1.62` (array element by index),
//! - `body.top.mass=2` (item of an array of tables selected by its `name`) or `body.0.mass=2`
//!   (by 0-based index; a number is always taken as an index),
//! - a key that does not exist is inserted when its parent table exists (`solver.rtol=1e-8`);
//!   an unknown parent is an error.
//!
//! The value is parsed as TOML (number, boolean, string, array, inline table); a bare word
//! that is not a TOML value is taken as a string (`model.group=R3xSO3`). A replaced value keeps
//! the position of the value it replaces, so errors about it point at that line and name the
//! override.

mod beam;
mod build;
mod contact;
mod control;
mod display;
mod error;
mod fields;
mod overrides;
mod reader;
mod sensitivity;
mod time_function;
mod worm_gear;

pub use error::{InputError, ItemLabel, Location};

use crate::model::Model;
use reader::{Source, Value};
use std::path::Path;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

/// A model file read and checked: the model, the analysis to run, and the free-text
/// description (the title is in [`Model::title`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFile {
    pub model: Model,
    pub analysis: Analysis,
    pub description: String,
    /// The sensitivity analysis it declares, if any.
    pub sensitivity: Option<crate::sensitivity::Setup>,
}

pub use crate::solve::Analysis;

/// Largest model file read, in bytes (256 MiB): a larger file, or a device such as
/// `/dev/zero`, is an error before it fills the memory.
pub const MAX_FILE_BYTES: usize = 256 << 20;

/// Reads, overrides and checks a model file. Errors are reported with `path` as file name.
///
/// The file must be a regular file or a pipe (FIFO) of UTF-8 text of at most
/// [`MAX_FILE_BYTES`]; it is read in pieces and rejected as soon as it exceeds the limit or
/// contains a NUL byte. A FIFO is opened without waiting for a writer (without one, it
/// reads as empty).
pub fn read_model_file(path: &Path, overrides: &[String]) -> Result<ModelFile, InputError> {
    let file = path.display().to_string();
    let text = read_limited(path).map_err(|source| InputError::Io {
        file: file.clone(),
        source,
    })?;
    parse_model_str(&text, &file, overrides)
}

/// The text of the file at `path`, read as [`read_model_file`] says.
fn read_limited(path: &Path) -> std::io::Result<String> {
    use std::io::{Error, ErrorKind, Read};
    let invalid = |message: String| Error::new(ErrorKind::InvalidData, message);
    let too_large = || {
        invalid(format!(
            "the file exceeds the limit of {MAX_FILE_BYTES} bytes (256 MiB)"
        ))
    };
    let meta = std::fs::metadata(path)?;
    let kind = meta.file_type();
    if kind.is_dir() {
        return Err(invalid("is a directory, not a model file".into()));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_char_device() || kind.is_block_device() || kind.is_socket() {
            return Err(invalid(
                "is a device or a socket, not a model file (give a regular file or a pipe)".into(),
            ));
        }
    }
    if kind.is_file() && meta.len() > MAX_FILE_BYTES as u64 {
        return Err(too_large());
    }
    // A pipe is read as it comes, waiting for its writer like any program reading a pipe;
    // more than MAX_FILE_BYTES from it is refused like a larger file.
    let mut reader = std::fs::File::open(path)?;
    let mut bytes = Vec::new();
    let mut chunk = vec![0u8; 1 << 16];
    loop {
        let n = match reader.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if let Some(at) = chunk[..n].iter().position(|&b| b == 0) {
            return Err(invalid(format!(
                "is not a text file (a NUL byte at byte {})",
                bytes.len() + at
            )));
        }
        if bytes.len() + n > MAX_FILE_BYTES {
            return Err(too_large());
        }
        bytes.extend_from_slice(&chunk[..n]);
    }
    if bytes.is_empty() {
        return Err(invalid("is empty".into()));
    }
    String::from_utf8(bytes).map_err(|e| {
        invalid(format!(
            "is not UTF-8 text (invalid byte at byte {})",
            e.utf8_error().valid_up_to()
        ))
    })
}

/// Parses, overrides and checks the text of a model file; `file_name` is used in errors.
/// A text longer than [`MAX_FILE_BYTES`] is an error.
pub fn parse_model_str(
    source: &str,
    file_name: &str,
    overrides: &[String],
) -> Result<ModelFile, InputError> {
    let mut src = Source::new(file_name, source);
    if source.len() > MAX_FILE_BYTES {
        return Err(InputError::Syntax {
            location: src.location(MAX_FILE_BYTES),
            message: format!("the model exceeds the limit of {MAX_FILE_BYTES} bytes (256 MiB)"),
        });
    }
    let table = DeTable::parse(source).map_err(|e| {
        let at = e.span().map_or(0, |s| s.start);
        InputError::Syntax {
            location: src.location(at),
            message: crate::model::clip(e.message().trim(), reader::MESSAGE),
        }
    })?;
    let mut root: Value<'_> = Spanned::new(0..0, DeValue::Table(table.into_inner()));
    overrides::apply(&mut root, overrides, &mut src)?;
    build::build(&src, &root)
}
