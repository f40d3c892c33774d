//! Results on disk: `sensors.csv` (written row by row as the run goes) and `summary.json`.
//!
//! Contract (stable, documented in README.md):
//! * `sensors.csv`: header `time,<sensor names>`, one row per output step, flushed as it is
//!   written, so a run that fails or is killed keeps every completed output step;
//! * `nodes.csv`: the deformed shape, one row per node and output step:
//!   `time,node,x,y,z,qw,qx,qy,qz` (position and unit quaternion of every node);
//! * `beams.csv` (models with beams): `time,element,<6 strains>,<6 stress resultants>` per
//!   beam element and output step;
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
    /// Time reached by the last completed step \[s\].
    pub t_reached: f64,
    pub steps: usize,
    pub newton_iterations: usize,
    pub rejected_steps: usize,
    pub factorizations: usize,
    pub outputs: usize,
    pub newton_iterations_per_step: f64,
    /// Wall time of the whole run including output \[s\].
    pub wall_seconds: f64,
    /// Wall time spent in the solver only \[s\].
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

/// Streams the deformed shape (every node) and the beam element strains and stress
/// resultants of every output step.
pub struct ShapeWriter {
    nodes: BufWriter<File>,
    beams: Option<BufWriter<File>>,
}

impl ShapeWriter {
    /// Creates `nodes.csv` (and `beams.csv` if the model has beams) in `dir`; the first column
    /// is named `first` (`time` or `load_factor`).
    pub fn create(dir: &Path, first: &str, model: &crate::Model) -> std::io::Result<Self> {
        let mut nodes = BufWriter::new(File::create(dir.join("nodes.csv"))?);
        writeln!(nodes, "{first},node,x,y,z,qw,qx,qy,qz")?;
        nodes.flush()?;
        let beams = if model.beams.is_empty() {
            None
        } else {
            let mut b = BufWriter::new(File::create(dir.join("beams.csv"))?);
            writeln!(
                b,
                "{first},element,axial_strain,shear_strain_2,shear_strain_3,torsion,curvature_2,curvature_3,axial_force,shear_force_2,shear_force_3,torque,bending_moment_2,bending_moment_3"
            )?;
            b.flush()?;
            Some(b)
        };
        Ok(Self { nodes, beams })
    }

    /// Appends the rows of one output step and flushes them.
    pub fn write(
        &mut self,
        t: f64,
        model: &crate::Model,
        state: &crate::State,
    ) -> std::io::Result<()> {
        for (node, q) in model.nodes.iter().zip(&state.q) {
            let quat = q.quaternion();
            writeln!(
                self.nodes,
                "{t:.12e},{},{:.15e},{:.15e},{:.15e},{:.15e},{:.15e},{:.15e},{:.15e}",
                node.name, q.x.x, q.x.y, q.x.z, quat[0], quat[1], quat[2], quat[3]
            )?;
        }
        self.nodes.flush()?;
        if let Some(out) = self.beams.as_mut() {
            let nodes = crate::sensors::node_states(state);
            for b in &model.beams {
                let st = b.state(&[nodes[b.nodes[0].0], nodes[b.nodes[1].0]]);
                write!(out, "{t:.12e},{}", b.name)?;
                for v in st.strain.iter().chain(st.stress.iter()) {
                    write!(out, ",{v:.15e}")?;
                }
                writeln!(out)?;
            }
            out.flush()?;
        }
        Ok(())
    }
}
