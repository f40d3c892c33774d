//! Errors of the model-file front end: every one names the file, the line and the field.

use std::fmt;

/// A position in a model file (line and column are 1-based, the column counts characters).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    pub file: String,
    pub line: u32,
    pub column: u32,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file, self.line, self.column)
    }
}

/// The model item a field belongs to, e.g. body 'crank'.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ItemLabel {
    /// Table name in the model file: "node", "body", "beam", "joint", "load", "spring",
    /// "sensor".
    pub table: &'static str,
    pub name: String,
}

/// Why a model file could not be turned into a [`crate::model::Model`] and its analysis settings.
///
/// The `Display` form is `FILE:LINE:COL: field 'body[2].mass' (body 'crank'): message`.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The file could not be read (missing, unreadable, not UTF-8).
    #[error("{file}: cannot read the model file: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML.
    #[error("{location}: TOML syntax error: {message}")]
    Syntax { location: Location, message: String },
    /// A field is unknown, missing, of the wrong type or has an invalid value, or the model it
    /// describes fails [`crate::model::Model::validate`]. When a `--set` override gave the field
    /// its value, the message ends with `(value set by --set '...')`.
    #[error("{location}: field '{field}'{}: {message}", ItemSuffix(.item))]
    Field {
        location: Location,
        /// Path of the field in the file, e.g. `body[2].mass` (array indices are 0-based).
        field: String,
        item: Option<ItemLabel>,
        message: String,
    },
    /// A `--set KEY.PATH=VALUE` override that cannot be applied. The location is that of the
    /// deepest part of the key path that exists in the file.
    #[error("{location}: --set '{text}': field '{field}': {message}")]
    Override {
        location: Location,
        text: String,
        field: String,
        message: String,
    },
}

impl InputError {
    /// Where in the file the error is (`None` only when the file could not be read).
    pub fn location(&self) -> Option<&Location> {
        match self {
            InputError::Io { .. } => None,
            InputError::Syntax { location, .. }
            | InputError::Field { location, .. }
            | InputError::Override { location, .. } => Some(location),
        }
    }

    /// Path of the field the error is about, e.g. `body[2].mass`.
    pub fn field(&self) -> Option<&str> {
        match self {
            InputError::Field { field, .. } | InputError::Override { field, .. } => Some(field),
            _ => None,
        }
    }
}

struct ItemSuffix<'a>(&'a Option<ItemLabel>);

impl fmt::Display for ItemSuffix<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(item) => write!(f, " ({} '{}')", item.table, item.name),
            None => Ok(()),
        }
    }
}
