//! The results of a flexmb run, for people to look at.
//!
//! A run's results are one [`Results`]: the model's metadata ([`ModelInfo`]: names, the
//! bodies, beams and joints, the display geometry, the sensors and their units), one
//! [`Snapshot`] per output step (time or load factor, node configurations and velocities,
//! joint points and reactions, beam strains and stress resultants, sensor values) and the
//! solver's statistics per step ([`StepStat`]). They are written as the run goes into the
//! HDF5 results file ([`h5`], docs/results-format.md) and read back from it; the plots, the
//! Paraview series and the browser animation are drawn from a [`Results`] ([`plot`]: sensor
//! histories; [`vtk`] with [`geometry`]: the Paraview series; [`view`]: one self-contained
//! HTML page with three.js).

pub mod geometry;
pub mod h5;
pub mod info;
pub mod plot;
pub mod snapshot;
pub mod view;
pub mod vtk;

pub use info::ModelInfo;
pub use plot::{Layout, PlotError, Summary};
pub use snapshot::{Results, Snapshot, StepStat};
pub use view::{write_html, ViewError};
pub use vtk::{export_vtk, VtkError, VtkSeries};
