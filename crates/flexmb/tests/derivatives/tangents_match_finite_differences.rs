//! Every analytic derivative against central differences taken on the manifold
//! (`q -> q exp(+-eps e_k)`, never `q +- eps e_k`): element tangents K, C, M; joint
//! gradients B and their derivatives H. One shared checker serves all. Parameter derivatives:
//! `parameters_match_finite_differences.rs`.

use flexmb::elements::contact::ContactElement;
use flexmb::elements::{
    evaluate_owned, Coefficients, Context, ElementKernel, Local, Mat12, NodeState, Vec12,
};
use flexmb::joints;
use flexmb::model::contact::{Bristles, Contact, ContactLaw, ContactShape, Dissipation, Friction};
use flexmb::model::{
    Beam, BeamMass, BeamSection, JointKind, Load, LoadFrame, Model, NodeId, RigidBody,
    SpringDamper, TimeFunction,
};
use flexmb_lie::{Frame, Group, Mat3, Mat6, Vec3, Vec6};
use nalgebra::DMatrix;

use crate::common;

use crate::common::Lcg;

const EPS: f64 = 1e-6;

fn perturb(group: Group, nodes: &[NodeState], k: usize, e: f64, what: char) -> Vec<NodeState> {
    let mut out = nodes.to_vec();
    let (a, i) = (k / 6, k % 6);
    let mut d = Vec6::zeros();
    d[i] = e;
    match what {
        'q' => out[a].q = group.integrate(&nodes[a].q, &d),
        'v' => out[a].v += d,
        _ => out[a].vdot += d,
    }
    out
}

fn assert_close(analytic: &DMatrix<f64>, fd: &DMatrix<f64>, what: &str, active: &[bool]) {
    let scale = 1.0 + fd.abs().max();
    for i in 0..fd.nrows() {
        for j in 0..fd.ncols() {
            if !active[i] || !active[j] {
                continue;
            }
            let (a, f) = (analytic[(i, j)], fd[(i, j)]);
            assert!(
                (a - f).abs() < 2e-6 * scale,
                "{what}: entry ({i}, {j}) analytic {a:.9e} vs finite difference {f:.9e}"
            );
        }
    }
}

/// Two node slots from a perturbed copy.
fn two(nodes: Vec<NodeState>) -> [NodeState; 2] {
    nodes.try_into().expect("two slots")
}

fn dense(m: &Mat12) -> DMatrix<f64> {
    DMatrix::from_column_slice(12, 12, m.as_slice())
}

/// Per entry of a two-slot local vector: whether its slot is a node.
fn entries(active: [bool; 2]) -> Vec<bool> {
    (0..12).map(|i| active[i / 6]).collect()
}

fn coefficients(m: f64, c: f64, k: f64, x: f64, xdot: f64) -> Coefficients {
    Coefficients {
        m,
        c,
        k,
        x,
        xdot,
        y: x,
    }
}

/// The shared checker for force elements: K (with T = I), C and M.
fn check_element(name: &str, kernel: &dyn ElementKernel, model: &Model, nodes: &[NodeState]) {
    check_element_with_states(name, kernel, model, nodes, &[], &[]);
}

/// [`check_element`] for an element with states `x` (rates `xdot`): also the columns of
/// `dr/dx` and `dr/dxdot`, and every row of the state equations.
fn check_element_with_states(
    name: &str,
    kernel: &dyn ElementKernel,
    model: &Model,
    nodes: &[NodeState],
    x: &[f64],
    xdot: &[f64],
) {
    check_states(
        name,
        kernel,
        model,
        nodes,
        (x, xdot, &Reads::default()),
        (&[], EPS),
    );
}

/// What an element reads besides its nodes and states: multipliers, other elements' states
/// and their rates.
#[derive(Default)]
struct Reads {
    lambda: Vec<f64>,
    x: Vec<f64>,
    xdot: Vec<f64>,
}

impl Reads {
    /// The local inputs of an element at `nodes` with states `x`, rates `xdot` and these
    /// reads.
    fn local<'a>(&'a self, nodes: &'a [NodeState], x: &'a [f64], xdot: &'a [f64]) -> Local<'a> {
        Local {
            nodes,
            x,
            xdot,
            lambda: &self.lambda,
            read_x: &self.x,
            read_xdot: &self.xdot,
        }
    }
}

/// [`check_element_with_states`] for an element with states `held` (local state indices)
/// that are held values (equation `xdot = 0`): each coefficient's matrix against central
/// differences of the residual, and in statics (stiffness without a rate term) the matrix
/// reads their equations as `x = x_start` (diagonal 1) while the residual stays `xdot`. The
/// element reads the multipliers `reads.lambda` ([`ElementKernel::multiplier_rows`]; their
/// columns carry no coefficient and are checked with every coefficient) and other elements'
/// states `reads.x`, `reads.xdot` ([`ElementKernel::state_reads`]; checked like its own).
fn check_states(
    name: &str,
    kernel: &dyn ElementKernel,
    model: &Model,
    nodes: &[NodeState],
    (x, xdot, reads): (&[f64], &[f64], &Reads),
    (held, eps): (&[usize], f64),
) {
    let group = model.group;
    let ctx = Context::at(model, 0.37, 1.0);
    let nodes = &nodes[..kernel.n_slots()];
    let n6 = 6 * nodes.len();
    let n = kernel.n_local();
    let nx = n6 + x.len();
    let nl = nx + reads.lambda.len();
    assert_eq!(n, nl + reads.x.len(), "{name}: local size");
    let active: Vec<bool> = (0..n)
        .map(|i| i >= n6 || kernel.node(i / 6).is_some())
        .collect();
    let eval_with = |nodes: &[NodeState], x: &[f64], xdot: &[f64], reads: &Reads| {
        evaluate_owned(kernel, &ctx, &reads.local(nodes, x, xdot), None).0
    };
    let eval = |nodes: &[NodeState], x: &[f64], xdot: &[f64]| eval_with(nodes, x, xdot, reads);
    for (what, coef) in [
        ('q', coefficients(0.0, 0.0, 1.0, 0.0, 0.0)),
        ('v', coefficients(0.0, 1.0, 0.0, 0.0, 0.0)),
        ('a', coefficients(1.0, 0.0, 0.0, 0.0, 0.0)),
        ('x', coefficients(0.0, 0.0, 0.0, 1.0, 0.0)),
        ('d', coefficients(0.0, 0.0, 0.0, 0.0, 1.0)),
    ] {
        let (r, s) = evaluate_owned(kernel, &ctx, &reads.local(nodes, x, xdot), Some(&coef));
        // the residual written with the matrix is the residual alone
        let r_alone = eval(nodes, x, xdot);
        assert!(
            (&r - &r_alone).amax() <= 1e-13 * (1.0 + r_alone.amax()),
            "{name}: residual with the matrix {r:?} vs alone {r_alone:?}"
        );
        let mut fd = DMatrix::zeros(n, n);
        for k in 0..n {
            if !active[k] {
                continue;
            }
            let moved = |v: &[f64], i: usize, e: f64| {
                let mut v = v.to_vec();
                v[i] += e;
                v
            };
            // the inputs read, one moved
            let read = |f: &dyn Fn(&mut Reads)| {
                let mut r = Reads {
                    lambda: reads.lambda.clone(),
                    x: reads.x.clone(),
                    xdot: reads.xdot.clone(),
                };
                f(&mut r);
                eval_with(nodes, x, xdot, &r)
            };
            let (rp, rm) = if k >= nl {
                let i = k - nl;
                match what {
                    'x' => (read(&|r| r.x[i] += eps), read(&|r| r.x[i] -= eps)),
                    'd' => (read(&|r| r.xdot[i] += eps), read(&|r| r.xdot[i] -= eps)),
                    _ => continue,
                }
            } else if k >= nx {
                let i = k - nx;
                (read(&|r| r.lambda[i] += eps), read(&|r| r.lambda[i] -= eps))
            } else if k < n6 {
                if matches!(what, 'x' | 'd') {
                    continue;
                }
                (
                    eval(&perturb(group, nodes, k, eps, what), x, xdot),
                    eval(&perturb(group, nodes, k, -eps, what), x, xdot),
                )
            } else {
                let i = k - n6;
                match what {
                    'x' => (
                        eval(nodes, &moved(x, i, eps), xdot),
                        eval(nodes, &moved(x, i, -eps), xdot),
                    ),
                    'd' => (
                        eval(nodes, x, &moved(xdot, i, eps)),
                        eval(nodes, x, &moved(xdot, i, -eps)),
                    ),
                    _ => continue,
                }
            };
            fd.set_column(k, &((rp - rm) / (2.0 * eps)));
        }
        assert_close(
            &s,
            &fd,
            &format!("{name} on {group:?}, derivative wrt {what}"),
            &active,
        );
    }
    // The statics' matrix (stiffness and states, no rate term) reads the held values'
    // equations as x = x_start.
    let statics = coefficients(0.0, 0.0, 1.0, 1.0, 0.0);
    let (_, s) = evaluate_owned(kernel, &ctx, &reads.local(nodes, x, xdot), Some(&statics));
    for &i in held {
        assert_eq!(s[(n6 + i, n6 + i)], 1.0, "{name}: a held value in statics");
    }
}

fn models() -> Vec<Model> {
    let mut out = vec![];
    for group in [Group::R3xSO3, Group::SE3] {
        let mut m = Model::new(group);
        m.gravity = Vec3::new(0.3, -9.81, 1.2);
        m.add_node("a", Frame::identity());
        m.add_node("b", Frame::identity());
        out.push(m);
    }
    out
}

#[test]
fn rigid_body_tangents_match_finite_differences() {
    let mut rng = Lcg(1);
    for model in models() {
        for com in [Vec3::zeros(), Vec3::new(0.3, -0.7, 0.2)] {
            let body = RigidBody {
                name: "b".into(),
                node: NodeId(0),
                mass: 2.5,
                com,
                inertia: Mat3::new(0.3, 0.01, -0.02, 0.01, 0.4, 0.03, -0.02, 0.03, 0.5),
            };
            let nodes = [rng.node(model.group), rng.node(model.group)];
            check_element("rigid body", &body, &model, &nodes);
        }
    }
}

#[test]
fn load_tangents_match_finite_differences() {
    let mut rng = Lcg(2);
    for model in models() {
        for frame in [LoadFrame::Inertial, LoadFrame::Body] {
            let load = Load {
                name: "l".into(),
                node: NodeId(0),
                force: Vec3::new(1.0, -2.0, 3.0),
                torque: Vec3::new(-0.5, 0.7, 0.2),
                frame,
                function: TimeFunction::Sine {
                    amplitude: 2.0,
                    frequency: 1.0,
                    phase: 0.3,
                    offset: 0.5,
                },
                input: None,
            };
            let nodes = [rng.node(model.group), rng.node(model.group)];
            check_element("load", &load, &model, &nodes);
        }
    }
}

#[test]
fn rope_tangents_match_finite_differences() {
    // A rope on four slots: from the ground over a point of node a, a point of node b and a
    // second point of node a (one node on two slots), taut.
    use flexmb::model::{Rope, RopePoint};
    let mut rng = Lcg(5);
    for model in models() {
        for _ in 0..3 {
            let at = |node: Option<usize>, p: Vec3| RopePoint {
                node: node.map(NodeId),
                point: p,
            };
            let rope = Rope {
                name: "r".into(),
                points: vec![
                    at(None, Vec3::new(2.0, 1.0, -0.5)),
                    at(Some(0), Vec3::new(0.2, 0.1, -0.3)),
                    at(Some(1), Vec3::new(-0.1, 0.4, 0.2)),
                    at(Some(0), Vec3::new(-0.3, 0.0, 0.25)),
                ],
                stiffness: 150.0,
                damping: 2.5,
                rest_length: 0.05,
            };
            let (a, b) = (rng.node(model.group), rng.node(model.group));
            let nodes = [NodeState::ground(Frame::identity()), a, b, a];
            check_element("rope", &rope, &model, &nodes);
        }
    }
}

#[test]
fn spring_damper_tangents_match_finite_differences() {
    // With a Maxwell branch, also the element state z (the branch damper's elongation) and
    // its rate: columns dr/dz, dr/dzdot and the row of the state equation.
    let mut rng = Lcg(3);
    let branch = flexmb::model::Relaxation {
        stiffness: 80.0,
        damping: 7.0,
    };
    for model in models() {
        for (ground_a, relaxation) in [
            (false, None),
            (true, None),
            (false, Some(branch)),
            (true, Some(branch)),
        ] {
            let spring = SpringDamper {
                name: "s".into(),
                node_a: (!ground_a).then_some(NodeId(0)),
                node_b: Some(NodeId(1)),
                point_a: Vec3::new(0.2, 0.1, -0.3),
                point_b: Vec3::new(-0.1, 0.4, 0.2),
                stiffness: 120.0,
                damping: 3.5,
                rest_length: 0.4,
                relaxation,
            };
            let mut nodes = [rng.node(model.group), rng.node(model.group)];
            if ground_a {
                nodes[0] = NodeState::ground(Frame::identity());
            }
            let n = spring.n_states();
            let x: Vec<f64> = (0..n).map(|_| 0.3 * rng.next()).collect();
            let xdot: Vec<f64> = (0..n).map(|_| 2.0 * rng.next()).collect();
            let name = format!("spring-damper (Maxwell branch: {})", relaxation.is_some());
            check_element_with_states(&name, &spring, &model, &nodes, &x, &xdot);
        }
    }
}

#[test]
fn joint_gradients_and_their_derivatives_match_finite_differences() {
    let mut rng = Lcg(4);
    for base in models() {
        let group = base.group;
        for kind in [
            JointKind::Fixed,
            JointKind::Spherical,
            JointKind::Revolute,
            JointKind::Prismatic,
            JointKind::Cylindrical,
            JointKind::Universal,
            JointKind::Planar,
        ] {
            for ground_a in [false, true] {
                let mut model = base.clone();
                model.nodes[0].frame = group.exp(&rng.v6(1.0));
                model.nodes[1].frame = group.exp(&rng.v6(1.0));
                let ob = (kind == JointKind::Universal).then(|| {
                    flexmb_lie::so3::exp(&Vec3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0))
                });
                let id = model.add_joint(
                    "j",
                    kind,
                    (!ground_a).then_some(NodeId(0)),
                    Some(NodeId(1)),
                    rng.v3(1.0),
                    flexmb_lie::so3::exp(&rng.v3(1.0)),
                    ob,
                );
                if matches!(kind, JointKind::Revolute | JointKind::Prismatic) {
                    model.joints[id.0].drive = Some(TimeFunction::Sine {
                        amplitude: 0.4,
                        frequency: 0.5,
                        phase: 0.1,
                        offset: 0.0,
                    });
                }
                let joint = &model.joints[id.0];
                let mut nodes = [rng.node(group), rng.node(group)];
                if ground_a {
                    nodes[0] = NodeState::ground(Frame::identity());
                }
                let active = [!ground_a, true];
                let t = 0.8;
                // The fast joint-level path agrees with the row-by-row evaluation.
                let rows = joints::rows(joint);
                let lambda: Vec<f64> = (0..rows.len()).map(|_| rng.next() * 10.0).collect();
                let mut k = Mat12::zeros();
                let jv =
                    joints::evaluate_joint(group, joint, &rows, &nodes, t, &lambda, Some(&mut k));
                let mut k_rows = Mat12::zeros();
                for (r, row) in rows.iter().enumerate() {
                    let rv = joints::evaluate_row(group, joint, *row, &nodes, t);
                    assert!((rv.phi - jv.phi[r]).abs() < 1e-14);
                    assert!((rv.phi_t - jv.phi_t[r]).abs() < 1e-12);
                    assert!((rv.b - jv.b[r]).norm() < 1e-13, "{kind:?} row {r}");
                    k_rows += rv.h * lambda[r];
                }
                assert!(
                    (k - k_rows).norm() < 1e-12 * (1.0 + k.norm()),
                    "{kind:?} on {group:?}"
                );
                for row in joints::rows(joint) {
                    let rv = joints::evaluate_row(group, joint, row, &nodes, t);
                    let mut fd_b = Vec12::zeros();
                    let mut fd_h = Mat12::zeros();
                    for k in 0..12 {
                        if !active[k / 6] {
                            continue;
                        }
                        let p = joints::evaluate_row(
                            group,
                            joint,
                            row,
                            &two(perturb(group, &nodes, k, EPS, 'q')),
                            t,
                        );
                        let m = joints::evaluate_row(
                            group,
                            joint,
                            row,
                            &two(perturb(group, &nodes, k, -EPS, 'q')),
                            t,
                        );
                        fd_b[k] = (p.phi - m.phi) / (2.0 * EPS);
                        fd_h.set_column(k, &((p.b - m.b) / (2.0 * EPS)));
                    }
                    let what = format!("{kind:?} row {row:?} on {group:?} (ground a: {ground_a})");
                    for k in 0..12 {
                        assert!(
                            (rv.b[k] - fd_b[k]).abs() < 1e-7,
                            "{what}: B entry {k}: {} vs {}",
                            rv.b[k],
                            fd_b[k]
                        );
                    }
                    assert_close(
                        &dense(&rv.h),
                        &dense(&fd_h),
                        &format!("{what}: H"),
                        &entries(active),
                    );
                    // time derivatives of driven rows
                    let tp = joints::evaluate_row(group, joint, row, &nodes, t + EPS);
                    let tm = joints::evaluate_row(group, joint, row, &nodes, t - EPS);
                    assert!(
                        (rv.phi_t - (tp.phi - tm.phi) / (2.0 * EPS)).abs() < 1e-7,
                        "{what}: Phi_t"
                    );
                    assert!(
                        (rv.phi_tt - (tp.phi_t - tm.phi_t) / (2.0 * EPS)).abs() < 1e-6,
                        "{what}: Phi_tt"
                    );
                    for k in 0..12 {
                        assert!(
                            (rv.b_t[k] - (tp.b[k] - tm.b[k]) / (2.0 * EPS)).abs() < 1e-7,
                            "{what}: B_t"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn beam_tangents_match_finite_differences() {
    let mut rng = Lcg(6);
    let mut model = Model::new(Group::SE3);
    model.gravity = Vec3::new(0.3, -9.81, 1.2);
    model.add_node("a", Frame::identity());
    model.add_node("b", Frame::identity());
    // A full (non-diagonal) symmetric positive definite section.
    let mut c = flexmb_lie::Mat6::from_diagonal(&Vec6::new(1e3, 4e2, 5e2, 30.0, 40.0, 60.0));
    c[(0, 4)] = 15.0;
    c[(4, 0)] = 15.0;
    c[(3, 5)] = 5.0;
    c[(5, 3)] = 5.0;
    let section = BeamSection {
        stiffness: c,
        mass_per_length: 2.0,
        rotary_inertia: Mat3::new(0.3, 0.01, 0.0, 0.01, 0.2, 0.02, 0.0, 0.02, 0.1),
        damping_mass: 0.7,
        damping_stiffness: 0.03,
    };
    for (offsets, curved, mass_kind) in [
        (false, false, BeamMass::Consistent),
        (true, false, BeamMass::Lumped),
        (true, true, BeamMass::Consistent),
        (true, true, BeamMass::Lumped),
    ] {
        // Reference: a straight (or curved) element of length ~1.3 with arbitrary offsets.
        let d0 = if curved {
            Vec6::new(1.3, 0.0, 0.0, 0.1, 0.2, 0.5)
        } else {
            Vec6::new(1.3, 0.0, 0.0, 0.0, 0.0, 0.0)
        };
        let o = |on: bool, rng: &mut Lcg| {
            if on {
                flexmb_lie::so3::exp(&rng.v3(1.0))
            } else {
                Mat3::identity()
            }
        };
        let offset_a = o(offsets, &mut rng);
        let offset_b = o(offsets, &mut rng);
        let beam = Beam::new(
            "b",
            [NodeId(0), NodeId(1)],
            section.clone(),
            [offset_a, offset_b],
            d0,
            mass_kind,
        );
        // Deformed configurations: node b near a exp(d0), with large rotations of the whole.
        for _ in 0..3 {
            let mut nodes = [rng.node(Group::SE3), rng.node(Group::SE3)];
            let ha = nodes[0]
                .q
                .compose(&Frame::new(Vec3::zeros(), beam.offset_a));
            let hb = ha.compose(&flexmb_lie::se3::exp(&(d0 + rng.v6(0.3))));
            nodes[1].q = Frame::new(hb.x, hb.r * beam.offset_b.transpose());
            check_element("beam", &beam, &model, &nodes);
        }
    }
}

#[test]
fn beam_tangent_is_invariant_under_rigid_motion() {
    // Sonneville, Cardona & Brüls 2014, Sect. 4.3: K_t depends on the relative motion only.
    let mut rng = Lcg(8);
    let mut model = Model::new(Group::SE3);
    model.add_node("a", Frame::identity());
    model.add_node("b", Frame::identity());
    let section = BeamSection::diagonal([1e3, 4e2, 5e2, 30.0, 40.0, 60.0], 1.0, [0.1, 0.05, 0.05]);
    let d0 = Vec6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let beam = Beam::new(
        "b",
        [NodeId(0), NodeId(1)],
        section,
        [Mat3::identity(); 2],
        d0,
        BeamMass::Consistent,
    );
    let ctx = context(&model);
    let stiffness = |nodes: &[NodeState; 2]| {
        let coef = coefficients(0.0, 0.0, 1.0, 0.0, 0.0);
        evaluate_owned(&beam, &ctx, &Local::nodes(nodes), Some(&coef))
    };
    let mut nodes = [NodeState::ground(Frame::identity()); 2];
    nodes[1].q = flexmb_lie::se3::exp(&(d0 + rng.v6(0.4)));
    let (r0, k0) = stiffness(&nodes);
    let rigid = flexmb_lie::se3::exp(&rng.v6(2.0));
    let moved = [
        NodeState::ground(rigid.compose(&nodes[0].q)),
        NodeState::ground(rigid.compose(&nodes[1].q)),
    ];
    let (r1, k1) = stiffness(&moved);
    assert!((&r0 - r1).norm() < 1e-9 * r0.norm());
    assert!((&k0 - k1).norm() < 1e-9 * k0.norm());
}

/// Context at t = 0, gravity and loads at full scale.
fn context(model: &Model) -> Context<'_> {
    Context::at(model, 0.0, 1.0)
}

/// Simpson's rule for `f` on [0, 1] with `n` (even) intervals.
fn simpson(n: usize, f: impl Fn(f64) -> f64) -> f64 {
    let sum: f64 = (0..=n)
        .map(|i| {
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            w * f(i as f64 / n as f64)
        })
        .sum();
    sum / (3.0 * n as f64)
}

/// A section with a coupled (non-diagonal) rotary inertia.
fn massive_section() -> BeamSection {
    let mut section = BeamSection::diagonal([1e3; 6], 2.5, [0.3, 0.2, 0.1]);
    section.rotary_inertia[(1, 2)] = 0.03;
    section.rotary_inertia[(2, 1)] = 0.03;
    section
}

/// Node frames of an element in its reference relative position `d0` from a random frame
/// of node a; also the section frame at a.
fn reference_placement(d0: &Vec6, offsets: &[Mat3; 2], rng: &mut Lcg) -> (Frame, Frame, Frame) {
    let ha = flexmb_lie::se3::exp(&rng.v6(1.0));
    let sa = ha.compose(&Frame::new(Vec3::zeros(), offsets[0]));
    let sb = sa.compose(&flexmb_lie::se3::exp(d0));
    (ha, Frame::new(sb.x, sb.r * offsets[1].transpose()), sa)
}

#[test]
fn beam_mass_is_exact_for_rigid_motions() {
    // Kinetic energy of a straight element moving rigidly, against the integral of
    // 1/2 rho A |pdot(s)|^2 + 1/2 omega^T J omega over the axis (Simpson, 2000 intervals):
    // exact with the consistent mass, and with the lumped mass for translations only.
    let mut rng = Lcg(21);
    let model = Model::new(Group::SE3);
    let ctx = context(&model);
    let section = massive_section();
    let length = 1.7;
    let d0 = Vec6::new(length, 0.0, 0.0, 0.0, 0.0, 0.0);
    let offsets = [
        flexmb_lie::so3::exp(&rng.v3(1.0)),
        flexmb_lie::so3::exp(&rng.v3(1.0)),
    ];
    for kind in [BeamMass::Consistent, BeamMass::Lumped] {
        let beam = Beam::new(
            "b",
            [NodeId(0), NodeId(1)],
            section.clone(),
            offsets,
            d0,
            kind,
        );
        for translation_only in [false, true] {
            let (ha, hb, sa) = reference_placement(&d0, &offsets, &mut rng);
            let mut eta_a = rng.v6(2.0);
            if translation_only {
                eta_a.fixed_rows_mut::<3>(3).fill(0.0);
            }
            let mut nodes = [NodeState::ground(ha), NodeState::ground(hb)];
            nodes[0].v = eta_a;
            nodes[1].v = flexmb_lie::se3::big_ad(&hb.inverse().compose(&ha)) * eta_a;
            let energy = beam.kinetic_energy(&ctx, &Local::nodes(&nodes));

            let xdot = ha.r * eta_a.fixed_rows::<3>(0);
            let omega = ha.r * eta_a.fixed_rows::<3>(3);
            let translational = length
                * simpson(2000, |xi| {
                    (xdot + omega.cross(&(sa.r * Vec3::new(xi * length, 0.0, 0.0)))).norm_squared()
                });
            let omega_sec = sa.r.transpose() * omega;
            let exact = 0.5 * section.mass_per_length * translational
                + 0.5 * length * omega_sec.dot(&(section.rotary_inertia * omega_sec));
            let error = (energy - exact).abs() / exact;
            if kind == BeamMass::Consistent || translation_only {
                assert!(error < 1e-10, "{kind:?}: {energy} against {exact}");
            } else {
                // lumping drops the rotation of the mass about the element's middle
                assert!(error > 1e-3, "{kind:?}: {energy} against {exact}");
            }
        }
    }
}

#[test]
fn consistent_beam_mass_is_the_kinetic_energy_of_the_interpolation() {
    // 1/2 v^T M v against 1/2 L int eta^T M_s eta dxi, with the section velocity eta(xi) of
    // the element's own field H(xi) = S_a exp(xi log(S_a^-1 S_b)) differentiated in time
    // (central differences of the nodes moving as H exp(t v)); nodes in the reference relative
    // position, arbitrary (non-rigid) velocities, straight and curved elements with offsets.
    let mut rng = Lcg(33);
    let model = Model::new(Group::SE3);
    let ctx = context(&model);
    let section = massive_section();
    let mut ms = Mat6::zeros();
    ms.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Mat3::identity() * section.mass_per_length));
    ms.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&section.rotary_inertia);
    for d0 in [
        Vec6::new(1.3, 0.0, 0.0, 0.0, 0.0, 0.0),
        Vec6::new(1.3, 0.0, 0.0, 0.1, 0.2, 0.5),
    ] {
        let offsets = [
            flexmb_lie::so3::exp(&rng.v3(1.0)),
            flexmb_lie::so3::exp(&rng.v3(1.0)),
        ];
        let beam = Beam::new(
            "b",
            [NodeId(0), NodeId(1)],
            section.clone(),
            offsets,
            d0,
            BeamMass::Consistent,
        );
        let (ha, hb, _) = reference_placement(&d0, &offsets, &mut rng);
        let (va, vb) = (rng.v6(2.0), rng.v6(2.0));
        let mut nodes = [NodeState::ground(ha), NodeState::ground(hb)];
        nodes[0].v = va;
        nodes[1].v = vb;
        let energy = beam.kinetic_energy(&ctx, &Local::nodes(&nodes));

        let field = |t: f64, xi: f64| {
            let a = ha
                .compose(&flexmb_lie::se3::exp(&(va * t)))
                .compose(&Frame::new(Vec3::zeros(), offsets[0]));
            let b = hb
                .compose(&flexmb_lie::se3::exp(&(vb * t)))
                .compose(&Frame::new(Vec3::zeros(), offsets[1]));
            let d = flexmb_lie::se3::log(&a.inverse().compose(&b));
            a.compose(&flexmb_lie::se3::exp(&(d * xi)))
        };
        let eps = 1e-5;
        let exact = 0.5
            * beam.length
            * simpson(200, |xi| {
                let h0 = field(0.0, xi).inverse();
                let eta = (flexmb_lie::se3::log(&h0.compose(&field(eps, xi)))
                    - flexmb_lie::se3::log(&h0.compose(&field(-eps, xi))))
                    / (2.0 * eps);
                eta.dot(&(ms * eta))
            });
        let error = (energy - exact).abs() / exact;
        assert!(
            error < 1e-7,
            "d0 {d0:?}: {energy} against {exact} ({error:e})"
        );
    }
}

/// A contact whose shapes are placed, in the frames of `nodes`, so that B penetrates A by
/// `depth` along a random direction: every shape pair, with and without friction.
fn contacts(nodes: &[NodeState; 2], rng: &mut Lcg, depth: f64) -> Vec<Contact> {
    let (a, b) = (&nodes[0].q, &nodes[1].q);
    let unit = |rng: &mut Lcg| rng.v3(1.0).normalize();
    let n = unit(rng);
    let on_a = a.x + rng.v3(0.5);
    let in_a = |p: &Vec3| a.inverse().point(p);
    let in_b = |p: &Vec3| b.inverse().point(p);
    let dir_a = |d: &Vec3| a.r.transpose() * d;
    let (ra, rb) = (0.3, 0.1);
    // B's centre: touching A's surface at `on_a` with normal n, minus the penetration.
    let centre = |surface: Vec3| surface + n * (rb - depth);
    // A cylinder axis normal to n.
    let axis = n.cross(&unit(rng)).normalize();
    let law = |dissipation| ContactLaw {
        dissipation,
        stiffness: 2e4,
        exponent: 1.5,
        restitution: 0.7,
        min_impact_velocity: 1e-3,
    };
    let pairs = vec![
        (
            ContactShape::Plane {
                point: in_a(&on_a),
                normal: dir_a(&n),
            },
            centre(on_a),
        ),
        (
            ContactShape::Sphere {
                center: in_a(&(on_a - n * ra)),
                radius: ra,
                inside: false,
            },
            centre(on_a),
        ),
        (
            ContactShape::Sphere {
                center: in_a(&(on_a + n * ra)),
                radius: ra,
                inside: true,
            },
            // inside: B's centre towards A's centre, B penetrating A's wall
            on_a + n * (rb - depth),
        ),
        (
            ContactShape::Cylinder {
                point: in_a(&(on_a - n * ra)),
                axis: dir_a(&axis),
                radius: ra,
                inside: false,
            },
            centre(on_a),
        ),
        (
            ContactShape::Cylinder {
                point: in_a(&(on_a + n * ra)),
                axis: dir_a(&axis),
                radius: ra,
                inside: true,
            },
            on_a + n * (rb - depth),
        ),
    ];
    let mut out = Vec::new();
    for (k, (shape_a, c_b)) in pairs.into_iter().enumerate() {
        let dissipation = [
            Dissipation::LankaraniNikravesh,
            Dissipation::HuntCrossley,
            Dissipation::Flores,
            Dissipation::ExactRestitution,
        ][k % 4];
        for friction in [
            None,
            // sliding (Coulomb)
            Some(Friction {
                coefficient: 0.4,
                stiction_velocity: 1e-3,
                viscous: 0.3,
                bristles: None,
            }),
            // within the stiction velocity
            Some(Friction {
                coefficient: 0.4,
                stiction_velocity: 50.0,
                viscous: 0.0,
                bristles: None,
            }),
            // bristles (LuGre): three more states
            Some(Friction {
                coefficient: 0.4,
                stiction_velocity: 0.3,
                viscous: 0.2,
                bristles: Some(Bristles {
                    stiffness: 300.0,
                    damping: 2.0,
                    static_coefficient: 0.6,
                }),
            }),
        ] {
            out.push(Contact {
                name: format!("{} {}", shape_a.keyword(), k),
                node_a: Some(NodeId(0)),
                node_b: Some(NodeId(1)),
                shape_a,
                shape_b: ContactShape::Sphere {
                    center: in_b(&c_b),
                    radius: rb,
                    inside: false,
                },
                law: law(dissipation),
                friction,
            });
        }
        // a circle B on a cylinder A (parallel axes): planar cams
        if let ContactShape::Cylinder { .. } = shape_a {
            out.push(Contact {
                name: format!("circles {k}"),
                node_a: Some(NodeId(0)),
                node_b: Some(NodeId(1)),
                shape_a,
                shape_b: ContactShape::Cylinder {
                    point: in_b(&c_b),
                    axis: b.r.transpose() * axis,
                    radius: rb,
                    inside: false,
                },
                law: law(dissipation),
                friction: None,
            });
        }
    }
    out
}

/// A contact's states (impact velocity 0.7, bristle deflections) and rates.
fn contact_states(contact: &Contact, rng: &mut Lcg) -> (Vec<f64>, Vec<f64>) {
    let n = contact.n_states();
    let x = (0..n)
        .map(|k| if k == 0 { 0.7 } else { 1e-3 * rng.next() })
        .collect();
    let xdot = (0..n)
        .map(|k| if k == 0 { 0.0 } else { 0.05 * rng.next() })
        .collect();
    (x, xdot)
}

#[test]
fn contact_tangents_match_finite_differences() {
    // Closed contacts (penetration 2 mm) of every shape pair, law and friction regime, with
    // the impact velocity x as the held state (column dr/dx checked by differences).
    let mut rng = Lcg(11);
    for model in models() {
        for _ in 0..3 {
            let mut nodes = [rng.node(model.group), rng.node(model.group)];
            for n in nodes.iter_mut() {
                n.v *= 0.05; // keep F_n > 0: deltadot small against v_imp
            }
            for contact in contacts(&nodes, &mut rng, 2e-3) {
                let element = ContactElement {
                    contact: &contact,
                    effective_mass: 1.0,
                };
                let ctx = Context::at(&model, 0.0, 1.0);
                let (x, xdot) = contact_states(&contact, &mut rng);
                let local = Local {
                    nodes: &nodes,
                    x: &x,
                    xdot: &xdot,
                    ..Local::nodes(&nodes)
                };
                let state = element.state(&ctx, &local);
                assert!(
                    (state.gap + 2e-3).abs() < 1e-12 && state.normal_force > 0.0,
                    "{}: placed with penetration 2e-3, gap {} force {}",
                    contact.name,
                    state.gap,
                    state.normal_force
                );
                let name = format!(
                    "contact '{}' (friction {:?})",
                    contact.name, contact.friction
                );
                let held: Vec<usize> = (0..x.len()).collect();
                check_states(
                    &name,
                    &element,
                    &model,
                    &nodes,
                    (&x, &xdot, &Reads::default()),
                    (&held, EPS),
                );
            }
        }
    }
}

/// Two wheels on nodes at random frames (`group`), wheel A's centre and axis random, wheel
/// B at a standard centre distance across the axis; external or internal, spur or helical.
fn gear_model(group: Group, internal: bool, helical: bool, rng: &mut Lcg) -> (Model, usize) {
    let mut model = Model::new(group);
    model.add_node("a", group.exp(&rng.v6(1.0)));
    model.add_node("b", group.exp(&rng.v6(1.0)));
    let geometry = flexmb::model::GearGeometry {
        teeth_a: 20,
        teeth_b: if internal { 57 } else { 31 },
        module: 0.01,
        pressure_angle: 20f64.to_radians(),
        helix_angle: if helical { 15f64.to_radians() } else { 0.0 },
        internal,
    };
    let [ra, rb] = geometry.pitch_radii();
    let axis = rng.v3(1.0).normalize();
    let across = axis.cross(&rng.v3(1.0)).normalize();
    let ca = rng.v3(0.5);
    let cb = ca + across * ((ra + geometry.sigma() * rb).abs() * 1.02) + axis * 0.01;
    // the nodes at the wheel centres: a turn of a node is a turn of its wheel
    model.nodes[0].frame.x = ca;
    model.nodes[1].frame.x = cb;
    let g = model.add_gear_pair(
        "g",
        [Some(NodeId(0)), Some(NodeId(1))],
        [ca, cb],
        &axis,
        geometry,
        2e8,
    );
    let gear = &mut model.gears[g];
    gear.damping = 3e3;
    gear.backlash = 2e-4;
    gear.stiffness_variation = vec![
        flexmb::model::Harmonic {
            amplitude: 0.2,
            phase: 0.3,
        },
        flexmb::model::Harmonic {
            amplitude: 0.05,
            phase: -1.0,
        },
    ];
    gear.transmission_error = vec![flexmb::model::Harmonic {
        amplitude: 1e-5,
        phase: 0.7,
    }];
    gear.mesh_phase = 0.4;
    gear.stiffness_table = vec![(0.0, 1.3), (0.3, 0.7), (0.65, 1.25)];
    (model, g)
}

/// Node kinematics near the initial configuration with wheel A turned by `turn` about its
/// axis (into the drive flank for `turn > 0`), small random motion and random velocities.
fn gear_nodes(model: &Model, g: usize, turn: f64, rng: &mut Lcg) -> [NodeState; 2] {
    let group = model.group;
    let axis = model.gears[g].frame_a.r.column(2).into_owned();
    let mut nodes = [0, 1].map(|i| NodeState {
        q: group.integrate(&model.nodes[i].frame, &rng.v6(2e-4)),
        v: rng.v6(2.0),
        vdot: rng.v6(3.0),
        t: Mat6::identity(),
    });
    nodes[0].q = group.integrate(
        &nodes[0].q,
        &flexmb_lie::join(&Vec3::zeros(), &(axis * turn)),
    );
    nodes
}

#[test]
fn gear_pair_tangents_match_finite_differences() {
    // Both flanks in contact in turn (wheel A turned one way, then the other), external and
    // internal, spur and helical, a wheel on the ground or not.
    let mut rng = Lcg(11);
    for group in [Group::R3xSO3, Group::SE3] {
        for (internal, helical) in [(false, false), (true, false), (false, true), (true, true)] {
            let (mut model, g) = gear_model(group, internal, helical, &mut rng);
            let original = model.gears[g].clone();
            for turn in [0.01, -0.01] {
                for ground_a in [false, true] {
                    model.gears[g] = original.clone();
                    let mut nodes = gear_nodes(&model, g, turn, &mut rng);
                    let mut gear = original.clone();
                    if ground_a {
                        // wheel A fixed where node A is now
                        gear.node_a = None;
                        gear.frame_a = nodes[0].q.compose(&gear.frame_a);
                        nodes[0] = NodeState::ground(Frame::identity());
                    }
                    model.gears[g] = gear.clone();
                    let ctx = context(&model);
                    let force = gear.mesh_force(&ctx, &Local::nodes(&nodes));
                    assert!(
                        force * turn > 0.0,
                        "turn {turn}: the flank is in contact (force {force})"
                    );
                    let name = format!(
                        "gear pair (internal {internal}, helical {helical}, turn {turn}, ground a {ground_a})"
                    );
                    check_element(&name, &gear, &model, &nodes);
                }
            }
        }
    }
}

#[test]
fn contact_tangents_match_one_sided_differences_at_the_onset() {
    // Near the onset the force K delta^(3/2) has a derivative growing like sqrt(delta):
    // differences are taken on one side of it only (steps well below the distance to the
    // onset). Open side (gap 1e-6): force and matrix are zero. Closed side (penetration
    // 1e-6, steps 2e-9): the matrix matches the differences.
    let mut rng = Lcg(12);
    for model in models() {
        let nodes = [rng.node(model.group), rng.node(model.group)];
        let slow: [NodeState; 2] = nodes.map(|mut n| {
            n.v *= 1e-3;
            n
        });
        for (depth, eps) in [(-1e-6, 1e-7), (1e-6, 2e-9)] {
            for contact in contacts(&slow, &mut rng, depth) {
                let element = ContactElement {
                    contact: &contact,
                    effective_mass: 1.0,
                };
                let name = format!("contact '{}' at penetration {depth:e}", contact.name);
                let (x, xdot) = contact_states(&contact, &mut rng);
                let held: Vec<usize> = (0..x.len()).collect();
                check_states(
                    &name,
                    &element,
                    &model,
                    &slow,
                    (&x, &xdot, &Reads::default()),
                    (&held, eps),
                );
            }
        }
    }
}

#[test]
fn gear_pair_tangent_is_one_sided_at_the_backlash_edge() {
    // At the contact onset (penetration +1e-12 m, no damping) the force is continuous and
    // its derivative jumps: K matches the difference taken on the contact side only.
    let mut rng = Lcg(12);
    for group in [Group::R3xSO3, Group::SE3] {
        let (mut model, g) = gear_model(group, false, false, &mut rng);
        let gear = &mut model.gears[g];
        gear.damping = 0.0;
        gear.transmission_error.clear();
        gear.stiffness_variation.clear();
        let gear = gear.clone();
        let ctx = context(&model);
        let [ra, _] = gear.geometry.base_radii();
        // turn wheel A until the drive flank just touches (bisection on the force)
        let mut nodes = gear_nodes(&model, g, 0.0, &mut rng);
        for n in &mut nodes {
            n.v = Vec6::zeros();
        }
        let axis = gear.frame_a.r.column(2).into_owned();
        let base = nodes[0].q;
        let turned = |t: f64| {
            let mut out = nodes;
            out[0].q = group.integrate(&base, &flexmb_lie::join(&Vec3::zeros(), &(axis * t)));
            out
        };
        let penetration = |t: f64| gear.mesh_force(&ctx, &Local::nodes(&turned(t))) / 2e8;
        let (mut lo, mut hi) = (-0.01, 0.01);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if penetration(mid) > 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let at = turned(hi + 1e-12 / ra);
        let coef = coefficients(0.0, 0.0, 1.0, 0.0, 0.0);
        let (_, s) = evaluate_owned(&gear, &ctx, &Local::nodes(&at), Some(&coef));
        // one-sided difference along the turn of wheel A (into contact)
        let h = 1e-8;
        let r = |t: f64| evaluate_owned(&gear, &ctx, &Local::nodes(&turned(t)), None).0;
        let t0 = hi + 1e-12 / ra;
        let fd = (r(t0 + h) - r(t0)) / h;
        let mut dir = Vec12::zeros();
        dir.fixed_rows_mut::<3>(3).copy_from(&axis);
        let analytic = &s * nalgebra::DVector::from_column_slice(dir.as_slice());
        let scale = fd.abs().max();
        assert!(scale > 1e3, "the contact carries stiffness ({scale})");
        assert!(
            (&analytic - &fd).abs().max() < 1e-5 * scale,
            "{group:?}: one-sided K {analytic:?} vs {fd:?}"
        );
        // on the other side, no force and no stiffness
        let before = turned(lo - 1e-9);
        let (r0, s0) = evaluate_owned(&gear, &ctx, &Local::nodes(&before), Some(&coef));
        assert!(
            r0.norm() == 0.0 && s0.norm() == 0.0,
            "{group:?}: no force in the backlash"
        );
    }
}

#[test]
fn gear_joint_gradients_and_their_derivatives_match_finite_differences() {
    let mut rng = Lcg(13);
    for group in [Group::R3xSO3, Group::SE3] {
        for internal in [false, true] {
            for ground_a in [false, true] {
                let (mut model, g) = gear_model(group, internal, false, &mut rng);
                let geo = model.gears[g].geometry;
                let nodes = gear_nodes(&model, g, 0.03, &mut rng);
                let (fa, fb) = (model.gears[g].frame_a, model.gears[g].frame_b);
                let frame_a = if ground_a {
                    model.nodes[0].frame.compose(&fa)
                } else {
                    fa
                };
                model.joints.push(flexmb::model::Joint {
                    name: "gear".into(),
                    kind: JointKind::Gear {
                        teeth_a: geo.teeth_a,
                        teeth_b: geo.teeth_b,
                        internal,
                    },
                    node_a: (!ground_a).then_some(NodeId(0)),
                    node_b: Some(NodeId(1)),
                    frame_a,
                    frame_b: fb,
                    drive: None,
                });
                let joint = model.joints.last().unwrap();
                let mut nodes = nodes;
                if ground_a {
                    nodes[0] = NodeState::ground(Frame::identity());
                }
                let active = [!ground_a, true];
                let rows = joints::rows(joint);
                assert_eq!(rows.len(), 1);
                let lambda = [7.5];
                let mut k = Mat12::zeros();
                let jv =
                    joints::evaluate_joint(group, joint, &rows, &nodes, 0.0, &lambda, Some(&mut k));
                let rv = joints::evaluate_row(group, joint, rows[0], &nodes, 0.0);
                assert!((rv.phi - jv.phi[0]).abs() < 1e-14);
                assert!((rv.b - jv.b[0]).norm() < 1e-13);
                assert!((k - rv.h * lambda[0]).norm() < 1e-12 * (1.0 + k.norm()));
                let mut fd_b = Vec12::zeros();
                let mut fd_h = Mat12::zeros();
                for c in 0..12 {
                    if !active[c / 6] {
                        continue;
                    }
                    let at = |e: f64| {
                        joints::evaluate_row(
                            group,
                            joint,
                            rows[0],
                            &two(perturb(group, &nodes, c, e, 'q')),
                            0.0,
                        )
                    };
                    let (p, m) = (at(EPS), at(-EPS));
                    fd_b[c] = (p.phi - m.phi) / (2.0 * EPS);
                    fd_h.set_column(c, &((p.b - m.b) / (2.0 * EPS)));
                }
                let what =
                    format!("gear joint (internal {internal}) on {group:?} (ground a {ground_a})");
                let tol = 1e-7 * (1.0 + fd_b.abs().max());
                assert!(
                    (rv.b - fd_b).abs().max() < tol,
                    "{what}: B {:?} vs {:?}",
                    rv.b,
                    fd_b
                );
                assert_close(
                    &dense(&rv.h),
                    &dense(&fd_h),
                    &format!("{what}: H"),
                    &entries(active),
                );
            }
        }
    }
}
/// A spring-damper between a point of node a (or the ground) and a point of node b, with a
/// nonlinear law.
fn law_spring(ground_a: bool, rest_length: f64) -> SpringDamper {
    SpringDamper {
        name: "s".into(),
        node_a: (!ground_a).then_some(NodeId(0)),
        node_b: Some(NodeId(1)),
        point_a: Vec3::new(0.2, 0.1, -0.3),
        point_b: Vec3::new(-0.1, 0.4, 0.2),
        stiffness: 120.0,
        damping: 3.5,
        rest_length,
        relaxation: None,
    }
}

/// Length of a spring's segment at `nodes`, computed as the element computes it.
fn spring_length(spring: &SpringDamper, nodes: &[NodeState]) -> f64 {
    (nodes[1].q.point(&spring.point_b) - nodes[0].q.point(&spring.point_a)).norm()
}

#[test]
fn nonlinear_spring_tangents_match_finite_differences() {
    // Tables, polynomials, separate curves per side, preload, and stops (one-sided springs)
    // while they act, at random kinematics (away from a table point or a stop's onset).
    use flexmb::elements::spring::SpringElement;
    use flexmb::model::{ForceCurve, ForceLaw, SpringSide};
    use std::borrow::Cow;
    let table = ForceCurve::Table(vec![(-0.5, -80.0), (0.1, 5.0), (0.5, 60.0), (1.0, 90.0)]);
    let cubic = ForceCurve::Polynomial(vec![40.0, -15.0, 30.0]);
    let mut laws = vec![];
    for (curve, compression, extension) in [
        (Some(table.clone()), None, None),
        (Some(cubic.clone()), None, None),
        (None, Some(cubic.clone()), Some(table.clone())),
    ] {
        let law = ForceLaw {
            preload: 7.5,
            curve,
            compression,
            extension,
            acts: SpringSide::Both,
        };
        laws.push((law, 0.4));
    }
    // stops that act: a bump stop always compressed, a strap always stretched
    let bump = ForceLaw {
        acts: SpringSide::Compression,
        curve: Some(ForceCurve::Polynomial(vec![40.0, 0.0, 2.0])),
        ..ForceLaw::default()
    };
    laws.push((bump, 5.0));
    let strap = ForceLaw {
        acts: SpringSide::Extension,
        curve: Some(table.clone()),
        ..ForceLaw::default()
    };
    laws.push((strap, 0.01));
    let mut rng = Lcg(8);
    for model in models() {
        for (law, rest_length) in &laws {
            for ground_a in [false, true] {
                let spring = law_spring(ground_a, *rest_length);
                let element = SpringElement {
                    spring: Cow::Borrowed(&spring),
                    law: Some(law),
                };
                let mut nodes = [rng.node(model.group), rng.node(model.group)];
                if ground_a {
                    nodes[0] = NodeState::ground(Frame::identity());
                }
                let name = format!("nonlinear spring {law:?}");
                let ctx = Context::at(&model, 0.37, 1.0);
                let (r, _) = evaluate_owned(&element, &ctx, &Local::nodes(&nodes), None);
                assert!(r.norm() > 1.0, "{name}: acts");
                check_element(&name, &element, &model, &nodes);
            }
        }
    }
}

/// The tangent stiffness of a spring at a point where its law has a kink (elongation `e`
/// exactly at a table point, or at a stop's onset) against one-sided differences taken on
/// the side of increasing length (second order: `(-3 r(0) + 4 r(h) - r(2h)) / 2h`, `h` of
/// the sign that lengthens the spring), the side whose slope the element uses; the damping
/// columns against central differences.
fn check_at_kink(
    name: &str,
    element: &dyn ElementKernel,
    spring: &SpringDamper,
    model: &Model,
    nodes: &[NodeState],
) {
    let group = model.group;
    let ctx = Context::at(model, 0.37, 1.0);
    let active: Vec<bool> = (0..12).map(|i| element.node(i / 6).is_some()).collect();
    let eval = |nodes: &[NodeState]| evaluate_owned(element, &ctx, &Local::nodes(nodes), None).0;
    let l0 = spring_length(spring, nodes);
    let r0 = eval(nodes);
    for (what, coef) in [
        ('q', coefficients(0.0, 0.0, 1.0, 0.0, 0.0)),
        ('v', coefficients(0.0, 1.0, 0.0, 0.0, 0.0)),
    ] {
        let (_, s) = evaluate_owned(element, &ctx, &Local::nodes(nodes), Some(&coef));
        let mut fd = DMatrix::zeros(12, 12);
        for k in (0..12).filter(|&k| active[k]) {
            let column = if what == 'q' {
                let lengthens = spring_length(spring, &perturb(group, nodes, k, EPS, 'q')) >= l0;
                let h = if lengthens { EPS } else { -EPS };
                let r1 = eval(&perturb(group, nodes, k, h, 'q'));
                let r2 = eval(&perturb(group, nodes, k, 2.0 * h, 'q'));
                (&r1 * 4.0 - &r0 * 3.0 - r2) / (2.0 * h)
            } else {
                let rp = eval(&perturb(group, nodes, k, EPS, 'v'));
                let rm = eval(&perturb(group, nodes, k, -EPS, 'v'));
                (rp - rm) / (2.0 * EPS)
            };
            fd.set_column(k, &column);
        }
        assert_close(
            &s,
            &fd,
            &format!("{name} on {group:?}, derivative wrt {what}"),
            &active,
        );
    }
}

#[test]
fn nonlinear_spring_tangents_at_a_table_point_and_a_stop_onset_are_one_sided() {
    use flexmb::elements::spring::SpringElement;
    use flexmb::model::{ForceCurve, ForceLaw, SpringSide};
    use std::borrow::Cow;
    let mut rng = Lcg(9);
    for model in models() {
        for ground_a in [false, true] {
            let mut nodes = [rng.node(model.group), rng.node(model.group)];
            if ground_a {
                nodes[0] = NodeState::ground(Frame::identity());
            }
            // the slope jumps from 50 to 400 N/m at the table point e_1 = l - l0 (exactly the
            // elongation the element computes)
            let spring = law_spring(ground_a, 0.3);
            let e1 = spring_length(&spring, &nodes) - spring.rest_length;
            let law = ForceLaw {
                curve: Some(ForceCurve::Table(vec![
                    (e1 - 1.0, -50.0),
                    (e1, 0.0),
                    (e1 + 1.0, 400.0),
                ])),
                ..ForceLaw::default()
            };
            let element = SpringElement {
                spring: Cow::Borrowed(&spring),
                law: Some(&law),
            };
            check_at_kink("table point", &element, &spring, &model, &nodes);
            // stops at their onset (l = l0): a compression stop is off there (its slope from
            // the side of longer length is zero), an extension stop is on
            for acts in [SpringSide::Compression, SpringSide::Extension] {
                let mut nodes = nodes;
                let mut spring = law_spring(ground_a, 0.0);
                spring.rest_length = spring_length(&spring, &nodes);
                let law = ForceLaw {
                    acts,
                    curve: Some(ForceCurve::Polynomial(vec![300.0, 0.0, 5e3])),
                    ..ForceLaw::default()
                };
                let element = SpringElement {
                    spring: Cow::Borrowed(&spring),
                    law: Some(&law),
                };
                // the spring lengthening (ldot > 0: T = c ldot > 0), so that the extension
                // stop acts at its onset
                let ctx = Context::at(&model, 0.37, 1.0);
                if element.tension(&ctx, &Local::nodes(&nodes)) == 0.0 {
                    for n in &mut nodes {
                        n.v = -n.v;
                    }
                }
                let tension = element.tension(&ctx, &Local::nodes(&nodes));
                assert_eq!(
                    tension > 0.0,
                    acts == SpringSide::Extension,
                    "{acts:?}: {tension}"
                );
                check_at_kink(
                    &format!("{acts:?} stop at its onset"),
                    &element,
                    &spring,
                    &model,
                    &nodes,
                );
            }
        }
    }
}

#[test]
fn rotational_spring_tangents_match_finite_differences() {
    // About the axis of a revolute (and a cylindrical) joint between random frames, to the
    // ground or between two nodes, linear and with a nonlinear law; with the element state
    // (the tracked angle) several turns away from the geometric angle's branch. Its state
    // row (xdot - thetadot) and the columns of the state are checked too.
    use flexmb::elements::rotational_spring::RotationalSpringElement;
    use flexmb::model::{ForceCurve, ForceLaw, JointKind, RotationalSpring};
    let mut rng = Lcg(10);
    let laws = [
        ForceLaw::default(),
        ForceLaw {
            preload: 3.0,
            curve: Some(ForceCurve::Polynomial(vec![5.0, 0.0, 0.02])),
            ..ForceLaw::default()
        },
    ];
    for base in models() {
        let group = base.group;
        for (kind, ground_a) in [
            (JointKind::Revolute, false),
            (JointKind::Revolute, true),
            (JointKind::Cylindrical, false),
        ] {
            for law in &laws {
                let mut model = base.clone();
                model.nodes[0].frame = group.exp(&rng.v6(1.0));
                model.nodes[1].frame = group.exp(&rng.v6(1.0));
                let joint = model.add_joint(
                    "hinge",
                    kind,
                    (!ground_a).then_some(NodeId(0)),
                    Some(NodeId(1)),
                    rng.v3(1.0),
                    flexmb_lie::so3::exp(&rng.v3(1.0)),
                    None,
                );
                let spring = RotationalSpring {
                    name: "torsion".into(),
                    joint,
                    stiffness: 35.0,
                    damping: 1.5,
                    angle: 0.3,
                    law: law.clone(),
                };
                let element = RotationalSpringElement {
                    spring: &spring,
                    joint: &model.joints[joint.0],
                };
                let mut nodes = [rng.node(group), rng.node(group)];
                if ground_a {
                    nodes[0] = NodeState::ground(Frame::identity());
                }
                // the state: the geometric angle plus four turns, nudged
                let (theta_g, ..) =
                    flexmb::elements::rotational_spring::joint_angle(element.joint, &nodes);
                let x = [theta_g + 8.0 * std::f64::consts::PI + 0.1];
                let name = format!("rotational spring on a {kind:?} joint, law {law:?}");
                check_element_with_states(&name, &element, &model, &nodes, &x, &[0.7]);
                let ctx = Context::at(&model, 0.37, 1.0);
                let local = Local {
                    nodes: &nodes,
                    x: &x,
                    xdot: &[0.7],
                    ..Local::nodes(&nodes)
                };
                let theta = element.angle(&ctx, &local);
                assert!(
                    (theta - theta_g - 8.0 * std::f64::consts::PI).abs() < 1e-12,
                    "{name}: the angle is on the state's turn: {theta} vs {theta_g} + 8 pi"
                );
            }
        }
    }
}

/// A symmetric positive definite 6 x 6 matrix with couplings.
fn spd6(rng: &mut Lcg, diagonal: [f64; 6]) -> Mat6 {
    let a = Mat6::from_fn(|_, _| rng.next());
    Mat6::from_diagonal(&Vec6::from_column_slice(&diagonal)) + a * a.transpose()
}

#[test]
fn bushing_tangents_match_finite_differences() {
    // Both forms, between two nodes and from the ground, frame offsets on both sides,
    // relative rotations up to about 2 rad, coupled stiffness and damping.
    use flexmb::model::{Bushing, BushingForm};
    let mut rng = Lcg(11);
    for model in models() {
        for (form, ground_a) in [
            (BushingForm::LargeRotation, false),
            (BushingForm::LargeRotation, true),
            (BushingForm::LargeRotation, false),
            (BushingForm::SmallRotation, false),
            (BushingForm::SmallRotation, true),
            (BushingForm::SmallRotation, false),
        ] {
            let bushing = Bushing {
                name: "mount".into(),
                node_a: (!ground_a).then_some(NodeId(0)),
                node_b: Some(NodeId(1)),
                frame_a: Group::SE3.exp(&rng.v6(1.0)),
                frame_b: Group::SE3.exp(&rng.v6(1.0)),
                stiffness: spd6(&mut rng, [300.0, 200.0, 250.0, 40.0, 30.0, 50.0]),
                damping: spd6(&mut rng, [3.0, 2.0, 2.5, 0.4, 0.3, 0.5]),
                form,
            };
            let mut nodes = [rng.node(model.group), rng.node(model.group)];
            if ground_a {
                nodes[0] = NodeState::ground(Frame::identity());
            }
            check_element(&format!("bushing, {form:?}"), &bushing, &model, &nodes);
        }
    }
}

/// The elastic residual is the gradient of the potential energy: at rest (no damping
/// force), `r . e_k = dV/dw_k` by central differences on the manifold, for every node
/// direction `k` of an element with a potential.
fn check_energy_gradient(
    name: &str,
    kernel: &dyn ElementKernel,
    model: &Model,
    nodes: &[NodeState],
    x: &[f64],
) {
    let group = model.group;
    let ctx = Context::at(model, 0.37, 1.0);
    let mut rest = nodes.to_vec();
    for n in &mut rest {
        n.v = Vec6::zeros();
        n.vdot = Vec6::zeros();
    }
    let xdot = vec![0.0; x.len()];
    let local = Local {
        nodes: &rest,
        x,
        xdot: &xdot,
        ..Local::nodes(&rest)
    };
    let (r, _) = evaluate_owned(kernel, &ctx, &local, None);
    let energy = |nodes: &[NodeState]| {
        kernel.potential_energy(
            &ctx,
            &Local {
                nodes,
                x,
                xdot: &xdot,
                ..Local::nodes(nodes)
            },
        )
    };
    let scale = 1.0 + r.abs().max();
    for k in (0..6 * rest.len()).filter(|&k| kernel.node(k / 6).is_some()) {
        let dv = (energy(&perturb(group, &rest, k, EPS, 'q'))
            - energy(&perturb(group, &rest, k, -EPS, 'q')))
            / (2.0 * EPS);
        assert!(
            (dv - r[k]).abs() < 1e-6 * scale,
            "{name}: dV/dw_{k} = {dv:.9e} vs residual {:.9e}",
            r[k]
        );
    }
}

#[test]
fn elastic_forces_are_the_gradients_of_the_potential_energies() {
    use flexmb::elements::rotational_spring::{joint_angle, RotationalSpringElement};
    use flexmb::elements::spring::SpringElement;
    use flexmb::model::{Bushing, BushingForm, ForceCurve, ForceLaw, RotationalSpring, SpringSide};
    use std::borrow::Cow;
    let mut rng = Lcg(12);
    let table = ForceCurve::Table(vec![(-0.5, -80.0), (0.1, 5.0), (0.5, 60.0), (1.0, 90.0)]);
    let cubic = ForceCurve::Polynomial(vec![40.0, 0.0, 2.0]);
    for model in models() {
        let group = model.group;
        // nonlinear springs: preloaded two-sided table, per-side curves, an acting bump stop
        for (law, rest_length) in [
            (
                ForceLaw {
                    preload: 7.5,
                    curve: Some(table.clone()),
                    ..ForceLaw::default()
                },
                0.4,
            ),
            (
                ForceLaw {
                    compression: Some(cubic.clone()),
                    extension: Some(table.clone()),
                    ..ForceLaw::default()
                },
                0.8,
            ),
            (
                ForceLaw {
                    acts: SpringSide::Compression,
                    curve: Some(cubic.clone()),
                    ..ForceLaw::default()
                },
                5.0,
            ),
        ] {
            let mut spring = law_spring(false, rest_length);
            spring.damping = 0.0;
            let element = SpringElement {
                spring: Cow::Borrowed(&spring),
                law: Some(&law),
            };
            let nodes = [rng.node(group), rng.node(group)];
            check_energy_gradient(&format!("spring {law:?}"), &element, &model, &nodes, &[]);
        }
        // a rotational spring with a law, wound four turns
        let mut m = model.clone();
        m.nodes[0].frame = group.exp(&rng.v6(1.0));
        m.nodes[1].frame = group.exp(&rng.v6(1.0));
        let joint = m.add_joint(
            "hinge",
            flexmb::model::JointKind::Revolute,
            Some(NodeId(0)),
            Some(NodeId(1)),
            rng.v3(1.0),
            flexmb_lie::so3::exp(&rng.v3(1.0)),
            None,
        );
        let spring = RotationalSpring {
            name: "torsion".into(),
            joint,
            stiffness: 35.0,
            damping: 0.0,
            angle: 0.3,
            law: ForceLaw {
                preload: 3.0,
                curve: Some(ForceCurve::Polynomial(vec![5.0, 0.0, 0.02])),
                ..ForceLaw::default()
            },
        };
        let element = RotationalSpringElement {
            spring: &spring,
            joint: &m.joints[joint.0],
        };
        let nodes = [rng.node(group), rng.node(group)];
        let x = [joint_angle(element.joint, &nodes).0 + 8.0 * std::f64::consts::PI];
        check_energy_gradient("rotational spring", &element, &m, &nodes, &x);
        // bushings
        {
            for form in [BushingForm::LargeRotation, BushingForm::SmallRotation] {
                let bushing = Bushing {
                    name: "mount".into(),
                    node_a: Some(NodeId(0)),
                    node_b: Some(NodeId(1)),
                    frame_a: Group::SE3.exp(&rng.v6(1.0)),
                    frame_b: Group::SE3.exp(&rng.v6(1.0)),
                    stiffness: spd6(&mut rng, [300.0, 200.0, 250.0, 40.0, 30.0, 50.0]),
                    damping: Mat6::zeros(),
                    form,
                };
                let nodes = [rng.node(group), rng.node(group)];
                check_energy_gradient(&format!("bushing {form:?}"), &bushing, &model, &nodes, &[]);
            }
        }
    }
}

#[test]
fn worm_gear_tangents_match_finite_differences() {
    // Each flank in contact in turn (the worm turned one way, then the other), sliding
    // (Coulomb: |v_s| above the stiction velocity, also at the washer) and sticking (the
    // regularization's linear range), right and left hand, the worm on the ground or not.
    let mut rng = Lcg(21);
    for group in [Group::R3xSO3, Group::SE3] {
        for left_hand in [false, true] {
            let model = common::worm_pair(group, &mut rng, left_hand);
            let original = model.worm_gears[0].clone();
            let axis = original.frame_a.r.column(2).into_owned();
            for (turn, slip) in [(0.02, true), (-0.02, true), (0.02, false), (-0.02, false)] {
                for ground_a in [false, true] {
                    let speed = if slip { 0.5 } else { 1e-5 };
                    let mut nodes = [0, 1].map(|i| NodeState {
                        q: group.integrate(&model.nodes[i].frame, &rng.v6(1e-6)),
                        v: rng.v6(speed),
                        vdot: rng.v6(3.0),
                        t: Mat6::identity(),
                    });
                    let twist = flexmb_lie::join(&Vec3::zeros(), &(axis * turn));
                    nodes[0].q = group.integrate(&nodes[0].q, &twist);
                    let mut gear = original.clone();
                    if ground_a {
                        gear.node_a = None;
                        gear.frame_a = nodes[0].q.compose(&gear.frame_a);
                        nodes[0] = NodeState::ground(Frame::identity());
                    }
                    let mut model = model.clone();
                    model.worm_gears[0] = gear.clone();
                    let ctx = context(&model);
                    let state = gear.state(&ctx, &Local::nodes(&nodes));
                    let v_e = gear.stiction_velocity;
                    // a left-handed thread loads the other flank for the same turn
                    let hand = if left_hand { -1.0 } else { 1.0 };
                    assert!(
                        state.normal_force * turn * hand > 0.0
                            && (state.slip_velocity.abs() > 2.0 * v_e) == slip
                            && (state.slip_velocity.abs() < 0.5 * v_e) != slip
                            && state.washer_torque != 0.0,
                        "left hand {left_hand}, turn {turn}, slip {slip}: {state:?}"
                    );
                    let name = format!(
                        "worm gear (left hand {left_hand}, turn {turn}, slip {slip}, ground a {ground_a})"
                    );
                    check_element(&name, &gear, &model, &nodes);
                }
            }
        }
    }
}

#[test]
fn control_block_tangents_match_finite_differences() {
    // Every kind of block, measurement and actuator in one diagram
    // (`common::control_diagram`), at random node kinematics, states and rates; the hold's
    // state is a held value.
    use flexmb::elements::control::{slots, ControlElement};
    use flexmb::model::control::BlockKind;
    let mut rng = Lcg(17);
    for group in [Group::R3xSO3, Group::SE3] {
        let model = common::control_diagram(group);
        let slots = slots(&model);
        let element = ControlElement::new(&model, &slots);
        let hold = model
            .control
            .blocks
            .iter()
            .position(|b| matches!(b.kind, BlockKind::Hold { .. }))
            .map(|b| model.control.state_start[b])
            .expect("a hold");
        for _ in 0..3 {
            let nodes: Vec<NodeState> = slots
                .nodes
                .iter()
                .map(|s| match s {
                    Some(_) => rng.node(group),
                    None => NodeState::ground(Frame::identity()),
                })
                .collect();
            let n = model.control.n_unknowns;
            let x: Vec<f64> = (0..n).map(|_| 0.5 * rng.next()).collect();
            let xdot: Vec<f64> = (0..n).map(|_| 0.5 * rng.next()).collect();
            let lambda: Vec<f64> = slots.rows.iter().map(|_| 20.0 * rng.next()).collect();
            assert_eq!(lambda.len(), 10, "the hinge's 5 rows and the slide's 5");
            // the contact's impact velocity and bristles
            let reads = Reads {
                lambda,
                x: vec![0.7, 1e-3 * rng.next(), 1e-3 * rng.next(), 1e-3 * rng.next()],
                xdot: (0..4)
                    .map(|k| if k == 0 { 0.0 } else { 0.05 * rng.next() })
                    .collect(),
            };
            assert_eq!(slots.states.len(), 4, "the contact's states");
            check_states(
                "control blocks",
                &element,
                &model,
                &nodes,
                (&x, &xdot, &reads),
                (&[hold], EPS),
            );
        }
    }
}
