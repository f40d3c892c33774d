//! Errors in a model and its settings, with the item and field to blame.

use super::ItemRef;

/// An inconsistent or unphysical model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("{item_table} '{name}' (#{index}), field '{field}': {message}", item_table = item.table, name = item.name, index = item.index + 1, field = item.field)]
    Invalid { item: ItemRef, message: String },
}

impl ModelError {
    /// The item and field the error is about.
    pub fn item(&self) -> &ItemRef {
        match self {
            ModelError::Invalid { item, .. } => item,
        }
    }
}

/// A solver setting outside its range ([`crate::solve::DynamicSettings::check`] and its
/// siblings): the model-file keys of `[solver]` the rule is about (the first is the one to
/// blame unless the file or a `--set` says otherwise) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("solver field '{}': {message}", keys[0])]
pub struct SettingsError {
    pub keys: Vec<&'static str>,
    pub message: String,
}

impl SettingsError {
    pub(crate) fn new(keys: &[&'static str], message: impl Into<String>) -> Self {
        Self {
            keys: keys.to_vec(),
            message: message.into(),
        }
    }

    /// `Err` unless `v > 0` and `lo <= v <= hi` (`lo > 0`).
    pub(crate) fn positive(key: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), Self> {
        if v <= 0.0 {
            return Err(Self::new(&[key], format!("must be positive, got {v}")));
        }
        Self::range(key, v, lo, hi)
    }

    /// `Err` unless `lo <= v <= hi`.
    pub(crate) fn range(key: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), Self> {
        if super::limits::within(v, lo, hi) {
            Ok(())
        } else {
            Err(Self::new(
                &[key],
                format!(
                    "must be between {lo:e} and {hi:e} (see 'Ranges' in docs/model-format.md), got {v:e}"
                ),
            ))
        }
    }
}
