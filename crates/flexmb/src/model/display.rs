//! Display geometry: what a body or a beam looks like in the results (the HDF5 file, the
//! Paraview series and the browser animation). It has no effect on the mechanics.
//!
//! A [`Shape`] is attached to a node at a frame given in the node frame; a [`Tube`] gives
//! the drawn radius of the elements of one beam. What is not given gets a default when the
//! results are written (a body's equivalent inertia box, a beam's tube from its section).

use flexmb_lie::{Frame, Vec3};

use super::NodeId;

/// The display geometry of a model.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Display {
    pub shapes: Vec<Shape>,
    pub tubes: Vec<Tube>,
}

/// A shape fixed on a node.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Shape {
    pub node: NodeId,
    pub kind: ShapeKind,
    /// Placement of the shape's own frame in the node frame.
    pub frame: Frame,
    /// Red, green, blue in [0, 1].
    pub colour: [f64; 3],
}

/// The geometry of a [`Shape`], in its own frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ShapeKind {
    /// A box of side lengths `size` \[m\] along the shape axes, centred on its origin.
    Box { size: Vec3 },
    /// A cylinder along the shape's z axis, centred on its origin.
    Cylinder { radius: f64, length: f64 },
    /// A sphere centred on the origin.
    Sphere { radius: f64 },
    /// A triangle mesh read from an STL or OBJ file when the model file is read: `path` as
    /// given in the model file, the vertices (already multiplied by the file's `scale`) \[m\]
    /// and the triangles (three vertex indices each, counter-clockwise seen from outside).
    Mesh {
        path: String,
        vertices: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
    },
}

/// The drawn radius of the beam elements `first .. first + count` of [`super::Model::beams`]
/// (the elements of one `[[beam]]`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Tube {
    pub first: usize,
    pub count: usize,
    /// Radius \[m\], > 0.
    pub radius: f64,
}

impl ShapeKind {
    /// The name of the kind in the model file and the results: `box`, `cylinder`, `sphere`,
    /// `mesh`.
    pub fn name(&self) -> &'static str {
        match self {
            ShapeKind::Box { .. } => "box",
            ShapeKind::Cylinder { .. } => "cylinder",
            ShapeKind::Sphere { .. } => "sphere",
            ShapeKind::Mesh { .. } => "mesh",
        }
    }
}
