//! A rigid frame: position and orientation, the storage shared by both node groups.

use crate::so3;
use crate::{Mat3, Vec3};

/// Position `x` (inertial frame) and rotation `r` (body to inertial) of a node.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Frame {
    /// Position of the frame origin in the inertial frame.
    pub x: Vec3,
    /// Rotation matrix mapping body-frame components to inertial components.
    pub r: Mat3,
}

impl Default for Frame {
    fn default() -> Self {
        Self::identity()
    }
}

impl Frame {
    /// The identity: origin, no rotation.
    pub fn identity() -> Self {
        Self {
            x: Vec3::zeros(),
            r: Mat3::identity(),
        }
    }

    /// A frame from a position and a rotation matrix.
    pub fn new(x: Vec3, r: Mat3) -> Self {
        Self { x, r }
    }

    /// SE(3) product `self * other` (homogeneous matrices).
    pub fn compose(&self, other: &Frame) -> Frame {
        Frame {
            x: self.x + self.r * other.x,
            r: self.r * other.r,
        }
    }

    /// SE(3) inverse.
    pub fn inverse(&self) -> Frame {
        let rt = self.r.transpose();
        Frame {
            x: -(rt * self.x),
            r: rt,
        }
    }

    /// Maps a point given in this frame to the inertial frame.
    pub fn point(&self, p: &Vec3) -> Vec3 {
        self.x + self.r * p
    }

    /// Unit quaternion `(w, x, y, z)` of the rotation, `w >= 0`.
    pub fn quaternion(&self) -> [f64; 4] {
        so3::to_quaternion(&self.r)
    }

    /// Removes round-off drift from the rotation matrix.
    pub fn orthonormalize(&mut self) {
        self.r = so3::orthonormalize(&self.r);
    }
}
