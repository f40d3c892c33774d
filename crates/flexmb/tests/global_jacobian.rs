//! The assembled iteration matrix against central differences of the assembled residual,
//! on the manifold (`q = q0 exp(dq)`, differences in `dq`): covers scatter, the tangent
//! operator T(dq), the group conversions and the constraint blocks together.

use flexmb::assembly::{assemble, ConstraintRhs, Iterate, Scaling};
use flexmb::data::{Data, Layout};
use flexmb::elements::{Coefficients, NodeState};
use flexmb::model::{BeamSection, JointKind, Load, LoadFrame, Model, TimeFunction};
use flexmb_lie::{Frame, Group, Mat3, Vec3, Vec6};

fn residual(
    model: &Model,
    data: &mut Data,
    q0: &[Frame],
    dq: &[f64],
    lambda: &[f64],
    sc: &Scaling,
    matrix: bool,
) -> Vec<f64> {
    let nodes: Vec<NodeState> = (0..q0.len())
        .map(|i| {
            let inc = Vec6::from_column_slice(&dq[6 * i..6 * i + 6]);
            NodeState {
                t: model.group.tangent(&inc),
                ..NodeState::ground(model.group.integrate(&q0[i], &inc))
            }
        })
        .collect();
    let it = Iterate {
        nodes: &nodes,
        t: 0.3,
        lambda,
        b_start: &[],
        x: &[],
        xdot: &[],
    };
    assemble(model, data, &it, sc, matrix);
    data.residual.clone()
}

#[test]
fn assembled_stiffness_matches_finite_differences_of_the_residual() {
    let section = BeamSection::diagonal([1e4, 8e3, 9e3, 2.0, 3.0, 2.5], 1.0, [0.1, 0.05, 0.05]);
    let mut m = Model::new(Group::SE3);
    m.gravity = Vec3::new(0.0, -9.81, 0.0);
    let root = m.add_node("root", Frame::identity());
    let ids = m.add_straight_beam(
        "beam",
        root,
        Vec3::new(1.0, 0.0, 0.0),
        None,
        4,
        &Vec3::z(),
        &section,
    );
    m.add_clamp("clamp", root);
    m.add_joint(
        "pin",
        JointKind::Spherical,
        Some(ids[2]),
        Some(ids[4]),
        Vec3::new(1.0, 0.0, 0.0),
        Mat3::identity(),
        None,
    );
    m.loads.push(Load {
        name: "moment".into(),
        node: ids[4],
        force: Vec3::new(0.0, 3.0, 1.0),
        torque: Vec3::new(0.0, -5.0, 1.0),
        frame: LoadFrame::Body,
        function: TimeFunction::Constant { value: 1.0 },
    });
    let layout = Layout::new(&m);
    let n_rows = layout.n_rows;
    let mut data = Data::new(&m, layout).expect("data");
    let nd = data.layout.n_dofs;
    let nu = data.layout.n_unknowns();
    let q0: Vec<Frame> = m.nodes.iter().map(|n| n.frame).collect();
    // A large increment (rotations up to ~1 rad) and non-zero multipliers.
    let dq: Vec<f64> = (0..nd).map(|k| 0.4 * ((k as f64 * 1.7).sin())).collect();
    let lambda: Vec<f64> = (0..n_rows).map(|k| 2.0 * (k as f64 * 0.9).cos()).collect();
    let sc = Scaling {
        row_scale: 1.0,
        coef: Coefficients {
            k: 1.0,
            ..Coefficients::STIFFNESS
        },
        constraint_rhs: ConstraintRhs::Position,
        load_factor: 1.0,
        regularization: 0.0,
        velocity_scale: 1.0,
        nodal_damping: 0.0,
        state_scale: 1.0,
    };
    residual(&m, &mut data, &q0, &dq, &lambda, &sc, true);
    let mut dense = vec![vec![0.0; nu]; nu];
    for ((i, j), v) in data.pattern.iter().zip(&data.values) {
        dense[*i][*j] += v;
    }
    let eps = 1e-6;
    let mut worst: f64 = 0.0;
    let scale = dense.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    for k in 0..nd {
        let (mut p, mut q) = (dq.clone(), dq.clone());
        p[k] += eps;
        q[k] -= eps;
        let rp = residual(&m, &mut data, &q0, &p, &lambda, &sc, false);
        let rm = residual(&m, &mut data, &q0, &q, &lambda, &sc, false);
        for i in 0..nu {
            let fd = (rp[i] - rm[i]) / (2.0 * eps);
            worst = worst.max((fd - dense[i][k]).abs());
        }
    }
    // Columns of the multipliers: the residual is linear in them (B^T).
    for (row, slot) in data.layout.row_unknown.clone().iter().enumerate() {
        let Some(c) = slot else { continue };
        let (mut lp, mut lm) = (lambda.clone(), lambda.clone());
        lp[row] += eps;
        lm[row] -= eps;
        let rp = residual(&m, &mut data, &q0, &dq, &lp, &sc, false);
        let rm = residual(&m, &mut data, &q0, &dq, &lm, &sc, false);
        for i in 0..nd {
            worst = worst.max(((rp[i] - rm[i]) / (2.0 * eps) - dense[i][nd + c]).abs());
        }
    }
    assert!(
        worst < 1e-6 * scale,
        "largest difference {worst:e} (matrix scale {scale:e})"
    );
}
