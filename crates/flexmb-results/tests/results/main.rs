//! Results files and views: collection, HDF5, plots, VTK, the browser animation.
//!
//! One test binary per concept (the engine issue, item 7): each file below is a module.

mod browser;
mod collect;
mod h5;
mod plot;
mod vtk;
