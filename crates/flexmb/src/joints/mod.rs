//! Kinematic joints as holonomic constraints `Phi(q, t) = 0` between two node frames.
//!
//! A joint connects joint frame A (fixed on node A, or on the ground) and joint frame B
//! (on node B). Each kind is a list of scalar rows built from the primitives of
//! [`primitives`] (Haug 1989, Sect. 3.3; Géradin & Cardona 2001, Ch. 8), with
//! `x_a, y_a, z_a` the axes of joint frame A, `d` the vector from joint point A to B:
//!
//! | kind | rows |
//! |---|---|
//! | fixed | `x_a.d, y_a.d, z_a.d, y_a.z_b, z_a.x_b, x_a.y_b` |
//! | spherical | `x_a.d, y_a.d, z_a.d` |
//! | revolute (z) | `x_a.d, y_a.d, z_a.d, z_a.x_b, z_a.y_b` |
//! | prismatic (z) | `x_a.d, y_a.d, y_a.z_b, z_a.x_b, x_a.y_b` |
//! | cylindrical (z) | `x_a.d, y_a.d, z_a.x_b, z_a.y_b` |
//! | universal (z_a, z_b) | `x_a.d, y_a.d, z_a.d, z_a.z_b` |
//! | planar (normal z) | `z_a.d, z_a.x_b, z_a.y_b` |
//! | gear | `sin(z_a phi_a + sigma z_b phi_b) / z_a` ([`gear`]) |
//!
//! A driven revolute joint adds `cos(theta_d) y_a.x_b - sin(theta_d) x_a.x_b = sin(theta - theta_d)`,
//! a driven prismatic joint `z_a.d - s_d(t)`. The rows' gradients with respect to a variation
//! `q -> q exp(w)` form the constraint matrix `B(q)` of the equations of motion
//! (Brüls & Cardona 2010, Eq. (37)).

pub mod gear;
pub mod parameters;
pub mod primitives;

use crate::kernel::{Mat12, NodeState, Vec12};
use crate::model::{Joint, JointKind, Model, NodeId};
use flexmb_lie::{so3::hat, Frame, Group, Vec3};
use primitives::{dot1, dot1_into, dot2, dot2_into, Primitive};

/// One scalar constraint row of a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Row {
    /// Axis `a` of frame A perpendicular to axis `b` of frame B.
    Dot1 { a: usize, b: usize },
    /// Joint point B has no component along axis `a` of frame A.
    Dot2 { a: usize },
    /// Driven rotation about z: `sin(theta - theta_d(t)) = 0`.
    DriveAngle,
    /// Driven translation along z: `z_a.d - s_d(t) = 0`.
    DriveSlide,
    /// The ratio of a gear joint ([`gear`]).
    Gear,
}

impl Row {
    /// What the row holds, in the joint's words (axes of joint frame A).
    pub fn describe(&self) -> String {
        const AXIS: [&str; 3] = ["x", "y", "z"];
        match *self {
            Row::Dot2 { a } => format!("translation along the joint's {} axis", AXIS[a]),
            Row::Dot1 { a, b } if a == b => {
                format!("the two {} axes kept perpendicular", AXIS[a])
            }
            Row::Dot1 { a, b } => format!("rotation about the joint's {} axis", AXIS[3 - a - b]),
            Row::DriveAngle => "the driven rotation".into(),
            Row::DriveSlide => "the driven translation".into(),
            Row::Gear => "the gear ratio".into(),
        }
    }
}

/// The rows of every joint of a model, the index of each joint's first row among all rows,
/// and the number of rows: the numbering of `State::lambda`.
pub fn row_table(model: &Model) -> (Vec<Vec<Row>>, Vec<usize>, usize) {
    let rows: Vec<Vec<Row>> = model.joints.iter().map(self::rows).collect();
    let mut starts = Vec::with_capacity(rows.len());
    let mut n = 0;
    for r in &rows {
        starts.push(n);
        n += r.len();
    }
    (rows, starts, n)
}

/// The constraint rows of a joint.
pub fn rows(joint: &Joint) -> Vec<Row> {
    use Row::*;
    let mut out = match joint.kind {
        JointKind::Fixed => vec![
            Dot2 { a: 0 },
            Dot2 { a: 1 },
            Dot2 { a: 2 },
            Dot1 { a: 1, b: 2 },
            Dot1 { a: 2, b: 0 },
            Dot1 { a: 0, b: 1 },
        ],
        JointKind::Spherical => vec![Dot2 { a: 0 }, Dot2 { a: 1 }, Dot2 { a: 2 }],
        JointKind::Revolute => vec![
            Dot2 { a: 0 },
            Dot2 { a: 1 },
            Dot2 { a: 2 },
            Dot1 { a: 2, b: 0 },
            Dot1 { a: 2, b: 1 },
        ],
        JointKind::Prismatic => vec![
            Dot2 { a: 0 },
            Dot2 { a: 1 },
            Dot1 { a: 1, b: 2 },
            Dot1 { a: 2, b: 0 },
            Dot1 { a: 0, b: 1 },
        ],
        JointKind::Cylindrical => vec![
            Dot2 { a: 0 },
            Dot2 { a: 1 },
            Dot1 { a: 2, b: 0 },
            Dot1 { a: 2, b: 1 },
        ],
        JointKind::Universal => vec![
            Dot2 { a: 0 },
            Dot2 { a: 1 },
            Dot2 { a: 2 },
            Dot1 { a: 2, b: 2 },
        ],
        JointKind::Planar => vec![Dot2 { a: 2 }, Dot1 { a: 2, b: 0 }, Dot1 { a: 2, b: 1 }],
        JointKind::Gear { .. } => vec![Gear],
    };
    if joint.drive.is_some() {
        match joint.kind {
            JointKind::Revolute => out.push(DriveAngle),
            JointKind::Prismatic => out.push(DriveSlide),
            _ => {}
        }
    }
    out
}

/// A row evaluated at `(q, t)` in group coordinates.
#[derive(Clone, Copy, Debug)]
pub struct RowValue {
    /// `Phi`.
    pub phi: f64,
    /// Row of `B`: `dPhi/dw` (12 entries, node A then node B).
    pub b: Vec12,
    /// `dB^T/dw` for a unit multiplier (12 x 12).
    pub h: Mat12,
    /// `dPhi/dt`.
    pub phi_t: f64,
    /// `d(b)/dt` (driven rows only).
    pub b_t: Vec12,
    /// `d2Phi/dt2`.
    pub phi_tt: f64,
}

impl RowValue {
    /// Convective term of the acceleration-level constraint at velocity `v` (12):
    /// `d2Phi/dt2 - B vdot = v^T H v + 2 b_t . v + phi_tt`.
    pub fn convective(&self, v: &Vec12) -> f64 {
        v.dot(&(self.h * v)) + 2.0 * self.b_t.dot(v) + self.phi_tt
    }
}

/// Frames of a joint's two nodes (identity for the ground).
pub fn node_frames(joint: &Joint, nodes: &[NodeState; 2]) -> (Frame, Frame) {
    let fa = if joint.node_a.is_some() {
        nodes[0].q
    } else {
        Frame::identity()
    };
    let fb = if joint.node_b.is_some() {
        nodes[1].q
    } else {
        Frame::identity()
    };
    (fa, fb)
}

/// Evaluates one row of a joint in physical coordinates, plus its time derivatives.
fn evaluate_physical(
    joint: &Joint,
    row: Row,
    fa: &Frame,
    fb: &Frame,
    t: f64,
) -> (Primitive, f64, Vec12, f64) {
    let qa = &joint.frame_a;
    let qb = &joint.frame_b;
    let axis_a = |i: usize| qa.r.column(i).into_owned();
    let axis_b = |i: usize| qb.r.column(i).into_owned();
    match row {
        Row::Dot1 { a, b } => (
            dot1(fa, &axis_a(a), fb, &axis_b(b)),
            0.0,
            Vec12::zeros(),
            0.0,
        ),
        Row::Dot2 { a } => (
            dot2(fa, &axis_a(a), &qa.x, fb, &qb.x),
            0.0,
            Vec12::zeros(),
            0.0,
        ),
        Row::DriveAngle => {
            let (th, thd, thdd) = joint.drive.as_ref().map_or((0.0, 0.0, 0.0), |f| f.eval(t));
            let p1 = dot1(fa, &axis_a(1), fb, &axis_b(0)); // y_a . x_b = sin(theta)
            let p2 = dot1(fa, &axis_a(0), fb, &axis_b(0)); // x_a . x_b = cos(theta)
            let (s, c) = th.sin_cos();
            let prim = Primitive {
                phi: c * p1.phi - s * p2.phi,
                g: p1.g * c - p2.g * s,
                h: p1.h * c - p2.h * s,
            };
            let (cd, sd) = (-s * thd, c * thd);
            let (cdd, sdd) = (-c * thd * thd - s * thdd, -s * thd * thd + c * thdd);
            let phi_t = cd * p1.phi - sd * p2.phi;
            let g_t = p1.g * cd - p2.g * sd;
            let phi_tt = cdd * p1.phi - sdd * p2.phi;
            (prim, phi_t, g_t, phi_tt)
        }
        Row::DriveSlide => {
            let (s, sd, sdd) = joint.drive.as_ref().map_or((0.0, 0.0, 0.0), |f| f.eval(t));
            let mut p = dot2(fa, &axis_a(2), &qa.x, fb, &qb.x);
            p.phi -= s;
            (p, -sd, Vec12::zeros(), -sdd)
        }
        Row::Gear => (gear::row(joint, fa, fb), 0.0, Vec12::zeros(), 0.0),
    }
}

/// Evaluates one row in the group's coordinates (see [`crate::elements::physical`]):
/// `b_g = P^T g_p`, `H_g = P^T H_p P + blockdiag([[0, tilde(R^T g_x)], [0, 0]])`.
pub fn evaluate_row(
    group: Group,
    joint: &Joint,
    row: Row,
    nodes: &[NodeState; 2],
    t: f64,
) -> RowValue {
    let (fa, fb) = node_frames(joint, nodes);
    let (p, phi_t, g_t, phi_tt) = evaluate_physical(joint, row, &fa, &fb, t);
    let active = [joint.node_a.is_some(), joint.node_b.is_some()];
    let mut out = RowValue {
        phi: p.phi,
        b: p.g,
        h: p.h,
        phi_t,
        b_t: g_t,
        phi_tt,
    };
    if group == Group::SE3 {
        let frames = [fa, fb];
        let mut pm = Mat12::identity();
        for a in 0..2 {
            if active[a] {
                pm.fixed_view_mut::<3, 3>(6 * a, 6 * a)
                    .copy_from(&frames[a].r);
            }
        }
        out.b = pm.transpose() * p.g;
        out.b_t = pm.transpose() * g_t;
        out.h = pm.transpose() * p.h * pm;
        for a in 0..2 {
            if active[a] {
                let f: Vec3 = out.b.fixed_rows::<3>(6 * a).into_owned();
                let mut blk = out.h.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3);
                blk += hat(&f);
            }
        }
    }
    for a in 0..2 {
        if !active[a] {
            out.b.fixed_rows_mut::<6>(6 * a).fill(0.0);
            out.b_t.fixed_rows_mut::<6>(6 * a).fill(0.0);
            out.h.fixed_rows_mut::<6>(6 * a).fill(0.0);
            out.h.fixed_columns_mut::<6>(6 * a).fill(0.0);
        }
    }
    out
}

/// Joint coordinate: rotation angle about z (in `(-pi, pi]`, unwrap over time) for revolute
/// and cylindrical joints; slide along z for prismatic joints; 0 otherwise.
pub fn coordinate(joint: &Joint, nodes: &[NodeState; 2]) -> f64 {
    let (fa, fb) = node_frames(joint, nodes);
    let ja = fa.compose(&joint.frame_a);
    let jb = fb.compose(&joint.frame_b);
    match joint.kind {
        JointKind::Revolute | JointKind::Cylindrical => {
            let xb = jb.r.column(0);
            xb.dot(&ja.r.column(1)).atan2(xb.dot(&ja.r.column(0)))
        }
        JointKind::Prismatic => ja.r.column(2).dot(&(jb.x - ja.x)),
        _ => 0.0,
    }
}

/// Whether the joint coordinate is an angle (to be unwrapped).
pub fn coordinate_is_angle(joint: &Joint) -> bool {
    matches!(joint.kind, JointKind::Revolute | JointKind::Cylindrical)
}

/// Force and torque (about the joint point) exerted by the joint on node B, inertial frame,
/// from the multipliers `lambda` of its rows: `(f, m) = -B_b^T lambda` converted to physical
/// coordinates.
pub fn reaction_on_b(
    joint: &Joint,
    rows: &[Row],
    nodes: &[NodeState; 2],
    lambda: &[f64],
    t: f64,
) -> (Vec3, Vec3) {
    let (fa, fb) = node_frames(joint, nodes);
    let mut gp = Vec12::zeros();
    for (row, l) in rows.iter().zip(lambda) {
        let (p, ..) = evaluate_physical(joint, *row, &fa, &fb, t);
        gp += p.g * *l;
    }
    let force = -gp.fixed_rows::<3>(6).into_owned();
    let moment_node = -(fb.r * gp.fixed_rows::<3>(9).into_owned());
    let point = fb.point(&joint.frame_b.x);
    let torque = moment_node - (point - fb.x).cross(&force);
    (force, torque)
}

/// Most rows a joint can have (fixed joint: 6; driven prismatic: 6).
pub const MAX_ROWS: usize = 6;

/// All rows of a joint evaluated at once, in group coordinates: the fast path of the
/// Newton loop (one transformation to group coordinates per joint instead of per row).
#[derive(Clone, Copy, Debug)]
pub struct JointValues {
    pub n_rows: usize,
    /// `Phi` per row.
    pub phi: [f64; MAX_ROWS],
    /// Rows of `B` (group coordinates).
    pub b: [Vec12; MAX_ROWS],
    /// `dPhi/dt` per row.
    pub phi_t: [f64; MAX_ROWS],
}

/// Evaluates every row of a joint; if `k` is given, sets it to
/// `K_c = sum_r lambda_r dB_r^T/dw` in group coordinates (12 x 12).
pub fn evaluate_joint(
    group: Group,
    joint: &Joint,
    rows: &[Row],
    nodes: &[NodeState; 2],
    t: f64,
    lambda: &[f64],
    mut k: Option<&mut Mat12>,
) -> JointValues {
    let (fa, fb) = node_frames(joint, nodes);
    let qa = &joint.frame_a;
    let qb = &joint.frame_b;
    let axis_a = |i: usize| qa.r.column(i).into_owned();
    let axis_b = |i: usize| qb.r.column(i).into_owned();
    let mut out = JointValues {
        n_rows: rows.len(),
        phi: [0.0; MAX_ROWS],
        b: [Vec12::zeros(); MAX_ROWS],
        phi_t: [0.0; MAX_ROWS],
    };
    if let Some(k) = k.as_deref_mut() {
        k.fill(0.0);
    }
    let mut force = Vec12::zeros();
    for (r, row) in rows.iter().enumerate() {
        let w = lambda[r];
        let (phi, g) = match *row {
            Row::Dot1 { a, b } => dot1_into(&fa, &axis_a(a), &fb, &axis_b(b), w, k.as_deref_mut()),
            Row::Dot2 { a } => dot2_into(&fa, &axis_a(a), &qa.x, &fb, &qb.x, w, k.as_deref_mut()),
            Row::DriveAngle => {
                let (th, thd, _) = joint.drive.as_ref().map_or((0.0, 0.0, 0.0), |f| f.eval(t));
                let (s, c) = th.sin_cos();
                let (p1, g1) = dot1_into(&fa, &axis_a(1), &fb, &axis_b(0), w * c, k.as_deref_mut());
                let (p2, g2) =
                    dot1_into(&fa, &axis_a(0), &fb, &axis_b(0), -w * s, k.as_deref_mut());
                out.phi_t[r] = -s * thd * p1 - c * thd * p2;
                (c * p1 - s * p2, g1 * c - g2 * s)
            }
            Row::DriveSlide => {
                let (sd, sdd, _) = joint.drive.as_ref().map_or((0.0, 0.0, 0.0), |f| f.eval(t));
                out.phi_t[r] = -sdd;
                let (p, g) = dot2_into(&fa, &axis_a(2), &qa.x, &fb, &qb.x, w, k.as_deref_mut());
                (p - sd, g)
            }
            Row::Gear => {
                let p = gear::row(joint, &fa, &fb);
                if let Some(k) = k.as_deref_mut() {
                    *k += p.h * w;
                }
                (p.phi, p.g)
            }
        };
        out.phi[r] = phi;
        out.b[r] = g;
        force += g * w;
    }
    let active = [joint.node_a.is_some(), joint.node_b.is_some()];
    if group == Group::SE3 {
        let rots = [fa.r, fb.r];
        for b in out.b.iter_mut().take(rows.len()) {
            for a in 0..2 {
                let v = rots[a].transpose() * b.fixed_rows::<3>(6 * a);
                b.fixed_rows_mut::<3>(6 * a).copy_from(&v);
            }
        }
        if let Some(k) = k.as_deref_mut() {
            // K_g = P^T K_p P + blockdiag([[0, tilde(R^T f)], [0, 0]]), P = diag(R_a, I, R_b, I)
            for i in 0..4 {
                for j in 0..4 {
                    let mut blk: flexmb_lie::Mat3 = k.fixed_view::<3, 3>(3 * i, 3 * j).into_owned();
                    if i % 2 == 0 {
                        blk = rots[i / 2].transpose() * blk;
                    }
                    if j % 2 == 0 {
                        blk *= rots[j / 2];
                    }
                    k.fixed_view_mut::<3, 3>(3 * i, 3 * j).copy_from(&blk);
                }
            }
            for a in 0..2 {
                let f = rots[a].transpose() * force.fixed_rows::<3>(6 * a);
                let mut blk = k.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3);
                blk += hat(&f);
            }
        }
    }
    for a in 0..2 {
        if !active[a] {
            for b in out.b.iter_mut().take(rows.len()) {
                b.fixed_rows_mut::<6>(6 * a).fill(0.0);
            }
            if let Some(k) = k.as_deref_mut() {
                k.fixed_rows_mut::<6>(6 * a).fill(0.0);
                k.fixed_columns_mut::<6>(6 * a).fill(0.0);
            }
        }
    }
    out
}

/// The capability set every constraint offers, mirroring [`crate::elements::ElementKernel`]:
/// its nodes and rows, the rows' values, gradients and gradient derivatives (what the
/// residual and the iteration matrix need). Derivatives with respect to model parameters
/// are the capability [`parameters::ConstraintParameters`].
pub trait ConstraintKernel {
    /// The two nodes (`None` = ground).
    fn nodes(&self) -> [Option<NodeId>; 2];
    /// The scalar rows.
    fn rows(&self) -> Vec<Row>;
    /// Values and gradients of all rows, and `K_c = sum lambda_r dB_r^T/dw` if asked.
    fn evaluate(
        &self,
        group: Group,
        rows: &[Row],
        nodes: &[NodeState; 2],
        t: f64,
        lambda: &[f64],
        k: Option<&mut Mat12>,
    ) -> JointValues;
}

impl ConstraintKernel for Joint {
    fn nodes(&self) -> [Option<NodeId>; 2] {
        [self.node_a, self.node_b]
    }
    fn rows(&self) -> Vec<Row> {
        rows(self)
    }
    fn evaluate(
        &self,
        group: Group,
        rows: &[Row],
        nodes: &[NodeState; 2],
        t: f64,
        lambda: &[f64],
        k: Option<&mut Mat12>,
    ) -> JointValues {
        evaluate_joint(group, self, rows, nodes, t, lambda, k)
    }
}
