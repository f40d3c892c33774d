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
        inputs: None,
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
        input: None,
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
    for ((i, j), v) in data.pattern().into_iter().zip(&data.values) {
        dense[i][j] += v;
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

#[test]
fn assembled_stiffness_with_gears_on_flexible_shafts_matches_finite_differences() {
    // Two shafts (beams along z) carrying a helical gear pair at their tips (in contact,
    // with backlash, stiffness harmonics and transmission error) and, at their roots, an
    // ideal gear joint; revolute bearings at the roots.
    let section = BeamSection::diagonal([1e6, 8e5, 8e5, 2e3, 3e3, 3e3], 1.0, [0.1, 0.05, 0.05]);
    let mut m = Model::new(Group::SE3);
    let geometry = flexmb::model::GearGeometry {
        teeth_a: 20,
        teeth_b: 31,
        module: 0.01,
        pressure_angle: 20f64.to_radians(),
        helix_angle: 15f64.to_radians(),
        internal: false,
    };
    let a0 = 0.26;
    let ra = m.add_node("ra", Frame::identity());
    let rb = m.add_node("rb", Frame::new(Vec3::new(a0, 0.0, 0.0), Mat3::identity()));
    let sa = m.add_straight_beam(
        "sa",
        ra,
        Vec3::new(0.0, 0.0, 0.5),
        None,
        2,
        &Vec3::x(),
        &section,
    );
    let sb = m.add_straight_beam(
        "sb",
        rb,
        Vec3::new(a0, 0.0, 0.5),
        None,
        2,
        &Vec3::x(),
        &section,
    );
    let (ta, tb) = (sa[2], sb[2]);
    let centers = [m.nodes[ta.0].frame.x, m.nodes[tb.0].frame.x];
    let g = m.add_gear_pair(
        "mesh",
        [Some(ta), Some(tb)],
        centers,
        &Vec3::z(),
        geometry,
        1e7,
    );
    m.gears[g].damping = 1e3;
    m.gears[g].backlash = 1e-4;
    m.gears[g].stiffness_variation = vec![flexmb::model::Harmonic {
        amplitude: 0.2,
        phase: 0.3,
    }];
    m.gears[g].transmission_error = vec![flexmb::model::Harmonic {
        amplitude: 1e-5,
        phase: 0.2,
    }];
    let roots = [m.nodes[ra.0].frame.x, m.nodes[rb.0].frame.x];
    m.add_gear_joint(
        "ratio",
        [Some(ra), Some(rb)],
        roots,
        &Vec3::z(),
        (20, 31, false),
    );
    for (name, n) in [("bearing_a", ra), ("bearing_b", rb)] {
        let at = m.nodes[n.0].frame.x;
        m.add_joint(
            name,
            JointKind::Revolute,
            None,
            Some(n),
            at,
            Mat3::identity(),
            None,
        );
    }
    let layout = Layout::new(&m);
    let n_rows = layout.n_rows;
    let mut data = Data::new(&m, layout).expect("data");
    let nd = data.layout.n_dofs;
    let nu = data.layout.n_unknowns();
    let q0: Vec<Frame> = m.nodes.iter().map(|n| n.frame).collect();
    // A small increment, and the pinion's tip turned into the drive flank.
    let mut dq: Vec<f64> = (0..nd).map(|k| 1e-4 * ((k as f64 * 1.7).sin())).collect();
    // the tip's section frame has x along z: its rotation about the shaft is component 3
    dq[6 * ta.0 + 3] += 0.01;
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
    for ((i, j), v) in data.pattern().into_iter().zip(&data.values) {
        dense[i][j] += v;
    }
    let eps = 1e-7;
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
    let gear_force = {
        let nodes: Vec<flexmb::elements::NodeState> = q0
            .iter()
            .enumerate()
            .map(|(i, q)| {
                let inc = Vec6::from_column_slice(&dq[6 * i..6 * i + 6]);
                NodeState::ground(m.group.integrate(q, &inc))
            })
            .collect();
        let pair = [nodes[ta.0], nodes[tb.0]];
        let ctx = flexmb::elements::Context::at(&m, 0.3, 1.0);
        m.gears[g].mesh_force(&ctx, &flexmb::elements::Local::nodes(&pair))
    };
    assert!(
        gear_force > 0.0,
        "the drive flank is in contact ({gear_force} N)"
    );
    println!(
        "gears on shafts: largest difference {:.2e} of the matrix scale {scale:.2e}",
        worst / scale
    );
    assert!(
        worst < 1e-6 * scale,
        "largest difference {worst:e} (matrix scale {scale:e})"
    );
}
