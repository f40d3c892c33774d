//! Results on disk: `sensors.csv` (written row by row as the run goes) and `summary.json`.
//!
//! Contract (stable, documented in README.md):
//! * `sensors.csv`: header `time,<sensor names>`, one row per output step, flushed as it is
//!   written, so a run that fails or is killed keeps every completed output step;
//! * `summary.json`: at least `status` ("running" while the run goes, then "ok" or "failed"),
//!   `steps`, `newton_iterations`, `rejected_steps`, `wall_seconds`; a failed run also has
//!   `error` (the diagnosis).

use serde::Serialize;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Streams sensor rows to a CSV file.
pub struct CsvWriter {
    out: BufWriter<File>,
    path: PathBuf,
}

impl CsvWriter {
    /// Creates the file and writes the header `time,<names>`.
    pub fn create(path: &Path, names: &[String]) -> std::io::Result<Self> {
        Self::create_with_first_column(path, "time", names)
    }

    /// Creates the file and writes the header `<first>,<names>`.
    pub fn create_with_first_column(
        path: &Path,
        first: &str,
        names: &[String],
    ) -> std::io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        write!(out, "{first}")?;
        for n in names {
            write!(out, ",{n}")?;
        }
        writeln!(out)?;
        out.flush()?;
        Ok(Self {
            out,
            path: path.to_path_buf(),
        })
    }

    /// Appends one row and flushes it to the operating system.
    pub fn row(&mut self, t: f64, values: &[f64]) -> std::io::Result<()> {
        write!(self.out, "{t:.12e}")?;
        for v in values {
            write!(self.out, ",{v:.15e}")?;
        }
        writeln!(self.out)?;
        self.out.flush()
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// What `summary.json` holds.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Summary {
    pub status: String,
    pub title: String,
    pub analysis: String,
    pub group: String,
    pub t_end: f64,
    /// Time reached by the last completed step [s].
    pub t_reached: f64,
    pub steps: usize,
    pub newton_iterations: usize,
    pub rejected_steps: usize,
    pub factorizations: usize,
    pub outputs: usize,
    pub newton_iterations_per_step: f64,
    /// Wall time of the whole run including output [s].
    pub wall_seconds: f64,
    /// Wall time spent in the solver only [s].
    pub solve_seconds: f64,
    pub unknowns: usize,
    pub linear_solver: String,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Summary {
    /// Writes the summary as pretty JSON.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(path, text + "\n")
    }
}
