//! The vocabulary that element kernels ([`crate::elements`]) and constraint kernels
//! ([`crate::joints`]) share: the kinematics of a node as a kernel sees it, the local
//! vector and matrix of a two-node kernel, and how a parameter derivative was obtained.

use flexmb_lie::{Frame, Mat6, Vec6};
use nalgebra::{SMatrix, SVector};

/// Local vector of a two-node element: `[node a (6), node b (6)]` (joints, and the
/// fixed-size arithmetic inside two-node elements).
pub type Vec12 = SVector<f64, 12>;
/// Local matrix of a two-node element, rows and columns ordered like [`Vec12`].
pub type Mat12 = SMatrix<f64, 12, 12>;

/// Kinematics of one node as an element sees it.
#[derive(Clone, Copy, Debug)]
pub struct NodeState {
    /// Configuration `q` (position, rotation).
    pub q: Frame,
    /// Velocity `v` in the group's convention (SE(3): body frame; R3xSO(3): inertial translation).
    pub v: Vec6,
    /// Acceleration `vdot`, same convention.
    pub vdot: Vec6,
    /// Tangent operator `T(h dq)` of the current increment (identity outside Newton).
    pub t: Mat6,
}

impl NodeState {
    /// A node fixed in space (the ground).
    pub fn ground(frame: Frame) -> Self {
        Self {
            q: frame,
            v: Vec6::zeros(),
            vdot: Vec6::zeros(),
            t: Mat6::identity(),
        }
    }
}

/// How a parameter derivative was obtained.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DerivativeMethod {
    /// From the formula (exact up to round-off).
    Analytic,
    /// Central difference on a perturbed copy of one element or joint
    /// ([`crate::elements::central_difference`], [`crate::joints::parameters`]).
    FiniteDifference,
}

/// Relative step of [`crate::elements::central_difference`]: about the cube root of the machine epsilon,
/// which balances the round-off error (`eps / h`) against the `O(h^2)` truncation error of a
/// central difference.
pub const FD_STEP: f64 = 6e-6;
