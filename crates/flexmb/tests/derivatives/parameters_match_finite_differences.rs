//! Every parameter derivative `dR/dp` of `flexmb::parameter_derivatives` against central
//! differences of the equations themselves, the parameter moved by `Parameters::set` on a
//! copy of the whole model (the path a user takes), at random node kinematics on the manifold
//! (configurations `exp` of random algebra vectors, as in `tangents_match_finite_differences`).
//! Every parameter kind of the registry is checked, on both groups where it exists.

use flexmb::elements::{
    evaluate_owned, Context, DerivativeMethod, ElementKernel, ElementRef, Local, NodeState, Vec12,
};
use flexmb::joints;
use flexmb::model::parameters::{
    BodyParam, BushingParam, ContactParam, GearParam, JointParam, LoadParam, NodeParam, RopeParam,
    RotationalSpringParam, SectionParam, SpringLawParam, SpringParam, WormGearParam,
};
use flexmb::model::{
    BeamMass, BeamSection, JointKind, Load, LoadFrame, Model, NodeId, ParamId, ParamKind,
    Parameters, SpringDamper, TimeFunction,
};
use flexmb::parameter_derivatives::{
    constraint_force_derivative, residual_derivative, residual_derivative_transpose, Columns,
    Weights,
};
use flexmb_lie::{Frame, Group, Mat3, Mat6, Vec3, Vec6};
use std::collections::BTreeSet;

use crate::common;

use crate::common::Lcg;

/// Where the equations are evaluated.
struct Point {
    nodes: Vec<NodeState>,
    /// Element states and rates.
    x: Vec<f64>,
    xdot: Vec<f64>,
    t: f64,
    lambda: Vec<f64>,
    load_factor: f64,
}

impl Point {
    fn view(&self) -> flexmb::parameter_derivatives::Point<'_> {
        flexmb::parameter_derivatives::Point {
            nodes: &self.nodes,
            x: &self.x,
            xdot: &self.xdot,
            t: self.t,
            lambda: &self.lambda,
            load_factor: self.load_factor,
            inputs: None,
        }
    }
}

/// The unscaled equations `(r + B^T lambda, Phi, B v + Phi_t, e)` of `model` at `at`: the sum
/// of the element kernels (with their mass matrices as the assembly builds them) and the
/// joint rows, in joint order, and the elements' state equations in element order.
fn equations(model: &Model, at: &Point) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let ctx = Context::at(model, at.t, at.load_factor);
    let pair = |slots: [Option<NodeId>; 2]| {
        slots.map(|s| s.map_or(NodeState::ground(Frame::identity()), |n| at.nodes[n.0]))
    };
    let mut r = vec![0.0; 6 * model.nodes.len()];
    let mut add = |slots: &[Option<NodeId>], local: &[f64]| {
        for (k, s) in slots.iter().enumerate() {
            if let Some(n) = s {
                for i in 0..6 {
                    r[6 * n.0 + i] += local[6 * k + i];
                }
            }
        }
    };
    let mut e_rows = vec![];
    for e in ElementRef::all(model) {
        let kernel = e.kernel(model);
        let slots: Vec<_> = (0..kernel.n_slots()).map(|k| kernel.node(k)).collect();
        let nodes: Vec<NodeState> = slots
            .iter()
            .map(|s| s.map_or(NodeState::ground(Frame::identity()), |n| at.nodes[n.0]))
            .collect();
        let states = e_rows.len()..e_rows.len() + kernel.n_states();
        let lambda: Vec<f64> = kernel
            .multiplier_rows()
            .iter()
            .map(|&r| at.lambda[r])
            .collect();
        let read = |v: &[f64]| -> Vec<f64> { kernel.state_reads().iter().map(|&i| v[i]).collect() };
        let (read_x, read_xdot) = (read(&at.x), read(&at.xdot));
        let local = Local {
            nodes: &nodes,
            x: &at.x[states.clone()],
            xdot: &at.xdot[states],
            lambda: &lambda,
            read_x: &read_x,
            read_xdot: &read_xdot,
        };
        let (local, _) = evaluate_owned(&kernel, &ctx, &local, None);
        add(&slots, local.as_slice());
        let n = 6 * slots.len() + kernel.n_states();
        e_rows.extend_from_slice(&local.as_slice()[6 * slots.len()..n]);
    }
    let (mut phi, mut psi) = (vec![], vec![]);
    for joint in &model.joints {
        let rows = joints::rows(joint);
        let slots = [joint.node_a, joint.node_b];
        let nodes = pair(slots);
        let lambda = &at.lambda[phi.len()..phi.len() + rows.len()];
        let jv = joints::evaluate_joint(model.group, joint, &rows, &nodes, at.t, lambda, None);
        let mut v = Vec12::zeros();
        for (k, s) in slots.iter().enumerate() {
            if s.is_some() {
                v.fixed_rows_mut::<6>(6 * k).copy_from(&nodes[k].v);
            }
        }
        let mut force = Vec12::zeros();
        for i in 0..rows.len() {
            phi.push(jv.phi[i]);
            psi.push(jv.b[i].dot(&v) + jv.phi_t[i]);
            force += jv.b[i] * lambda[i];
        }
        add(&slots, force.as_slice());
    }
    (r, phi, psi, e_rows)
}

fn n_rows(model: &Model) -> usize {
    model.joints.iter().map(|j| joints::rows(j).len()).sum()
}

/// Random node kinematics near the model's initial configuration (beams: near their
/// reference shape), multipliers and a load factor other than 1.
fn point(model: &Model, rng: &mut Lcg, spread: f64) -> Point {
    let nodes = model
        .nodes
        .iter()
        .map(|n| NodeState {
            q: model.group.integrate(&n.frame, &rng.v6(spread)),
            v: rng.v6(2.0),
            vdot: rng.v6(3.0),
            t: Mat6::identity(),
        })
        .collect();
    let n_states = flexmb::data::Layout::new(model).n_states;
    Point {
        nodes,
        x: (0..n_states).map(|_| 0.2 * rng.next()).collect(),
        xdot: (0..n_states).map(|_| rng.next()).collect(),
        t: 0.37,
        lambda: (0..n_rows(model)).map(|_| rng.next() * 10.0).collect(),
        load_factor: 0.8,
    }
}

/// The kind of a parameter, its item's name replaced by a placeholder.
fn pattern(params: &Parameters, id: ParamId) -> String {
    let item = match params.kind(id) {
        ParamKind::Gravity(_) => return "model.gravity.<k>".into(),
        ParamKind::Node(_, p) => match p {
            NodeParam::Velocity(_) => "node.<n>.velocity.<k>",
            NodeParam::AngularVelocity(_) => "node.<n>.angular_velocity_body.<k>",
        },
        ParamKind::Body(_, p) => match p {
            BodyParam::Mass => "body.<b>.mass",
            BodyParam::Com(_) => "body.<b>.com.<k>",
            BodyParam::Inertia(_) => "body.<b>.inertia.<k>",
        },
        ParamKind::Beam(_, p) => match p {
            SectionParam::Stiffness(i, j) if i == j => "beam.<r>.section.<C_ii>",
            SectionParam::Stiffness(..) => "beam.<r>.section.stiffness.<i>.<j>",
            SectionParam::MassPerLength => "beam.<r>.section.rhoA",
            SectionParam::RotaryInertia(i, j) if i == j => "beam.<r>.section.<J_ii>",
            SectionParam::RotaryInertia(..) => "beam.<r>.section.rotary_inertia.<i>.<j>",
            SectionParam::DampingMass => "beam.<r>.damping.mass",
            SectionParam::DampingStiffness => "beam.<r>.damping.stiffness",
        },
        ParamKind::Joint(_, p) => match p {
            JointParam::Position(_) => "joint.<j>.position.<k>",
            JointParam::Drive(_) => "joint.<j>.drive.<amplitude>",
        },
        ParamKind::Load(_, p) => match p {
            LoadParam::Force(_) => "load.<l>.force.<k>",
            LoadParam::Torque(_) => "load.<l>.torque.<k>",
            LoadParam::Amplitude(_) => "load.<l>.function.<amplitude>",
        },
        ParamKind::Spring(_, p) => match p {
            SpringParam::Stiffness => "spring.<s>.stiffness",
            SpringParam::Damping => "spring.<s>.damping",
            SpringParam::RestLength => "spring.<s>.rest_length",
            SpringParam::PointA(_) => "spring.<s>.point_a.<k>",
            SpringParam::PointB(_) => "spring.<s>.point_b.<k>",
            SpringParam::RelaxationStiffness => "spring.<s>.relaxation_stiffness",
            SpringParam::RelaxationDamping => "spring.<s>.relaxation_damping",
        },
        ParamKind::Contact(_, p) => match p {
            ContactParam::Stiffness => "contact.<c>.stiffness",
            ContactParam::Exponent => "contact.<c>.exponent",
            ContactParam::Restitution => "contact.<c>.restitution",
            ContactParam::Friction => "contact.<c>.friction.coefficient",
            ContactParam::ViscousFriction => "contact.<c>.friction.viscous",
        },
        ParamKind::Rope(_, p) => match p {
            RopeParam::Stiffness => "rope.<r>.stiffness",
            RopeParam::Damping => "rope.<r>.damping",
            RopeParam::RestLength => "rope.<r>.rest_length",
            RopeParam::Point(..) => "rope.<r>.points.<i>.point.<k>",
        },
        ParamKind::Gear(_, p) => match p {
            GearParam::MeshStiffness => "gear.<g>.mesh_stiffness",
            GearParam::Damping => "gear.<g>.damping",
            GearParam::Backlash => "gear.<g>.backlash",
            GearParam::StiffnessVariation(_) => "gear.<g>.stiffness_variation.<n>",
            GearParam::TransmissionError(_) => "gear.<g>.transmission_error.<n>",
        },
        ParamKind::SpringLaw(_, p) => match p {
            SpringLawParam::Preload => "spring.<s>.preload",
            SpringLawParam::Polynomial(..) => "spring.<s>.<side>polynomial.<j>",
            SpringLawParam::TableForce(..) => "spring.<s>.<side>force_table.<i>",
        },
        ParamKind::RotationalSpring(_, p) => match p {
            RotationalSpringParam::Stiffness => "rotational_spring.<s>.stiffness",
            RotationalSpringParam::Damping => "rotational_spring.<s>.damping",
            RotationalSpringParam::Angle => "rotational_spring.<s>.angle",
            RotationalSpringParam::Law(SpringLawParam::Preload) => "rotational_spring.<s>.preload",
            RotationalSpringParam::Law(_) => "rotational_spring.<s>.<side><curve>.<i>",
        },
        ParamKind::Bushing(_, p) => match p {
            BushingParam::Stiffness(..) => "bushing.<b>.stiffness.<i>.<j>",
            BushingParam::Damping(..) => "bushing.<b>.damping.<i>.<j>",
        },
        ParamKind::WormGear(_, p) => match p {
            WormGearParam::MeshStiffness => "worm_gear.<g>.mesh_stiffness",
            WormGearParam::Damping => "worm_gear.<g>.damping",
            WormGearParam::Friction => "worm_gear.<g>.friction",
            WormGearParam::WasherRadius => "worm_gear.<g>.washer_radius",
        },
        ParamKind::Control(_) => {
            let path = params.path(id);
            let key = path.rsplit('.').next().unwrap_or_default();
            let key = key.split('[').next().unwrap_or_default();
            return format!("control.<b>.{key}");
        }
    };
    item.into()
}

/// What the checks saw: the kinds checked, those by finite differences, the largest error.
#[derive(Default)]
struct Seen {
    kinds: BTreeSet<String>,
    by_differences: BTreeSet<String>,
    worst: f64,
}

/// Largest entry of `a - b` relative to the largest of `b`.
fn relative_error(a: &[f64], b: &[f64]) -> (f64, f64) {
    let scale = b.iter().chain(a).fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    (diff, scale)
}

/// The shared checker: every parameter of `model` at `at`, analytic against central
/// differences through `Parameters::set`; also `J_p^T w` against the columns and the
/// constraint-force term against the columns of joint parameters.
fn check_model(name: &str, model: &Model, at: &Point, seen: &mut Seen) {
    let params = Parameters::new(model);
    let (nd, nr, ns) = (6 * model.nodes.len(), n_rows(model), at.x.len());
    let mut rng = Lcg(99);
    let w_r: Vec<f64> = (0..nd).map(|_| rng.next()).collect();
    let w_phi: Vec<f64> = (0..nr).map(|_| rng.next()).collect();
    let w_psi: Vec<f64> = (0..nr).map(|_| rng.next()).collect();
    let w_e: Vec<f64> = (0..ns).map(|_| rng.next()).collect();
    let mut grad = vec![0.0; params.len()];
    let weights = Weights {
        r: &w_r,
        phi: &w_phi,
        psi: &w_psi,
        e: &w_e,
    };
    residual_derivative_transpose(model, &params, &at.view(), weights, &mut grad);
    for id in params.ids() {
        let path = params.path(id);
        let (mut dr, mut dphi, mut dpsi) = (vec![0.0; nd], vec![0.0; nr], vec![0.0; nr]);
        let mut de = vec![0.0; ns];
        let columns = Columns {
            dr: &mut dr,
            dphi: &mut dphi,
            dpsi: &mut dpsi,
            de: &mut de,
        };
        let method = residual_derivative(model, &params, id, &at.view(), columns);
        let kind = pattern(&params, id);
        if method == DerivativeMethod::FiniteDifference {
            seen.by_differences.insert(kind.clone());
        }
        seen.kinds.insert(kind);

        let p = params.value(model, id);
        let h = 1e-6 * p.abs().max(1.0);
        let eval = |v: f64| {
            let mut copy = model.clone();
            params.set(&mut copy, id, v);
            equations(&copy, at)
        };
        let (plus, minus) = (eval(p + h), eval(p - h));
        let fd = |a: &[f64], b: &[f64]| -> Vec<f64> {
            a.iter().zip(b).map(|(x, y)| (x - y) / (2.0 * h)).collect()
        };
        let analytic: Vec<f64> = [&dr[..], &dphi, &dpsi, &de].concat();
        let differences = [
            fd(&plus.0, &minus.0),
            fd(&plus.1, &minus.1),
            fd(&plus.2, &minus.2),
            fd(&plus.3, &minus.3),
        ];
        let differences = differences.concat();
        let (diff, scale) = relative_error(&analytic, &differences);
        if scale < 1e-12 {
            // independent of the parameter at this point (initial-state parameters)
            assert!(
                diff == 0.0,
                "{name}: {path}: {analytic:?} vs {differences:?}"
            );
        } else {
            let error = diff / scale;
            seen.worst = seen.worst.max(error);
            assert!(
                error < 1e-6,
                "{name}: {path} ({method:?}): relative error {error:.3e}\nanalytic {analytic:?}\ndifferences {differences:?}"
            );
        }

        let dot = |w: &[f64], d: &[f64]| w.iter().zip(d).map(|(a, b)| a * b).sum::<f64>();
        let column = dot(&w_r, &dr) + dot(&w_phi, &dphi) + dot(&w_psi, &dpsi) + dot(&w_e, &de);
        let g = grad[id.0 as usize];
        assert!(
            (g - column).abs() <= 1e-12 * (1.0 + column.abs()),
            "{name}: {path}: J_p^T w {g} vs the column {column}"
        );

        let mut dforce = vec![0.0; nd];
        constraint_force_derivative(model, &params, id, &at.nodes, at.t, &at.lambda, &mut dforce);
        if let ParamKind::Joint(j, _) = params.kind(id) {
            // (a block diagram acting along the joint adds its own term to dr)
            if !model.control.uses_joint(j) {
                assert_eq!(dforce, dr, "{name}: {path}: d(B^T lambda)/dp");
            }
        } else {
            assert!(dforce.iter().all(|x| *x == 0.0), "{name}: {path}");
        }
    }
}

/// Two bodies (offset centres of mass, full inertias), springs between them and to the
/// ground (the latter with a Maxwell branch: one element state), a dead load with a sine and a follower load with a table, gravity, a revolute
/// joint between the bodies, a driven revolute and a driven prismatic joint to the ground.
fn mechanism(group: Group) -> Model {
    let mut m = Model::new(group);
    m.gravity = Vec3::new(0.3, -9.81, 1.2);
    let a = m.add_node("a", Frame::new(Vec3::new(0.1, 0.2, -0.3), Mat3::identity()));
    let b = m.add_node(
        "b",
        flexmb_lie::se3::exp(&Vec6::new(1.0, -0.4, 0.2, 0.3, -0.5, 0.7)),
    );
    m.nodes[b.0].velocity = Vec3::new(0.5, 0.0, 1.0);
    let c = m.add_node("c", Frame::new(Vec3::new(-0.5, 0.4, 0.1), Mat3::identity()));
    let inertia = Mat3::new(0.3, 0.01, -0.02, 0.01, 0.4, 0.03, -0.02, 0.03, 0.5);
    m.add_body("body_a", a, 2.5, Vec3::new(0.3, -0.7, 0.2), inertia);
    m.add_body("body_b", b, 1.5, Vec3::new(-0.1, 0.2, 0.4), inertia * 2.0);
    m.add_body("body_c", c, 0.8, Vec3::new(0.0, 0.1, 0.0), inertia);
    m.springs.push(SpringDamper {
        name: "s".into(),
        node_a: Some(a),
        node_b: Some(b),
        point_a: Vec3::new(0.2, 0.1, -0.3),
        point_b: Vec3::new(-0.1, 0.4, 0.2),
        stiffness: 120.0,
        damping: 3.5,
        rest_length: 0.4,
        relaxation: None,
    });
    m.springs.push(SpringDamper {
        name: "tether".into(),
        node_a: None,
        node_b: Some(b),
        point_a: Vec3::new(1.0, 2.0, 0.5),
        point_b: Vec3::new(0.1, 0.0, 0.3),
        stiffness: 50.0,
        damping: 0.5,
        rest_length: 1.0,
        relaxation: Some(flexmb::model::Relaxation {
            stiffness: 30.0,
            damping: 4.0,
        }),
    });
    // A rope from the ground over a and b to c (four slots), taut.
    let at = |node: Option<NodeId>, point: Vec3| flexmb::model::RopePoint { node, point };
    m.ropes.push(flexmb::model::Rope {
        name: "hoist".into(),
        points: vec![
            at(None, Vec3::new(2.0, 1.5, 0.0)),
            at(Some(a), Vec3::new(0.1, 0.0, 0.2)),
            at(Some(b), Vec3::new(0.0, -0.2, 0.1)),
            at(Some(c), Vec3::zeros()),
        ],
        stiffness: 80.0,
        damping: 1.5,
        rest_length: 0.1,
    });
    m.loads.push(Load {
        name: "push".into(),
        node: a,
        force: Vec3::new(1.0, -2.0, 3.0),
        torque: Vec3::new(-0.5, 0.7, 0.2),
        frame: LoadFrame::Inertial,
        function: TimeFunction::Sine {
            amplitude: 2.0,
            frequency: 1.0,
            phase: 0.3,
            offset: 0.5,
        },
        input: None,
    });
    m.loads.push(Load {
        name: "follow".into(),
        node: b,
        force: Vec3::new(0.0, 4.0, -1.0),
        torque: Vec3::new(0.3, 0.0, 0.9),
        frame: LoadFrame::Body,
        function: TimeFunction::Table {
            points: vec![(0.0, 0.0), (0.5, 2.0), (1.0, -1.0)],
        },
        input: None,
    });
    let axis = flexmb_lie::so3::exp(&Vec3::new(0.3, 0.2, -0.4));
    m.add_joint(
        "pivot",
        JointKind::Revolute,
        Some(a),
        Some(b),
        Vec3::new(0.4, -0.2, 0.3),
        axis,
        None,
    );
    let motor = m.add_joint(
        "motor",
        JointKind::Revolute,
        None,
        Some(a),
        Vec3::new(0.1, 0.2, -0.3),
        Mat3::identity(),
        None,
    );
    m.joints[motor.0].drive = Some(TimeFunction::Sine {
        amplitude: 0.4,
        frequency: 0.5,
        phase: 0.1,
        offset: 0.2,
    });
    let slider = m.add_joint(
        "slider",
        JointKind::Prismatic,
        None,
        Some(c),
        Vec3::new(-0.5, 0.4, 0.1),
        axis,
        None,
    );
    m.joints[slider.0].drive = Some(TimeFunction::Linear {
        slope: 0.6,
        start: 0.1,
        offset: -0.05,
    });
    m
}

#[test]
fn parameter_derivatives_match_finite_differences_on_bodies_springs_loads_and_joints() {
    let mut seen = Seen::default();
    let mut rng = Lcg(5);
    for group in [Group::R3xSO3, Group::SE3] {
        let model = mechanism(group);
        for _ in 0..2 {
            let at = point(&model, &mut rng, 1.0);
            check_model(&format!("mechanism on {group:?}"), &model, &at, &mut seen);
        }
    }
    println!("worst relative error {:.2e}", seen.worst);
}

/// A straight 2-element beam on SE(3) (full section with couplings, damping), clamped at one
/// end by a fixed joint, a tip body, gravity.
fn beam(mass_kind: BeamMass) -> Model {
    let mut m = Model::new(Group::SE3);
    m.gravity = Vec3::new(0.3, -9.81, 1.2);
    let mut c = Mat6::from_diagonal(&Vec6::new(1e3, 4e2, 5e2, 30.0, 40.0, 60.0));
    for (i, j, v) in [(0, 4, 15.0), (3, 5, 5.0), (1, 2, -20.0)] {
        c[(i, j)] = v;
        c[(j, i)] = v;
    }
    let section = BeamSection {
        stiffness: c,
        mass_per_length: 2.0,
        rotary_inertia: Mat3::new(0.3, 0.01, 0.0, 0.01, 0.2, 0.02, 0.0, 0.02, 0.1),
        damping_mass: 0.7,
        damping_stiffness: 0.03,
    };
    let root = m.add_node("root", Frame::identity());
    let end = Vec3::new(1.2, 0.5, -0.3);
    let ids = m.add_straight_beam("rod", root, end, None, 2, &Vec3::z(), &section);
    for b in &mut m.beams {
        b.mass_kind = mass_kind;
    }
    m.add_body(
        "tip",
        ids[2],
        0.5,
        Vec3::new(0.1, 0.0, 0.0),
        Mat3::identity() * 0.01,
    );
    m.add_clamp("clamp", root);
    m
}

#[test]
fn parameter_derivatives_match_finite_differences_on_a_two_element_beam() {
    let mut seen = Seen::default();
    let mut rng = Lcg(6);
    for kind in [BeamMass::Lumped, BeamMass::Consistent] {
        let model = beam(kind);
        let params = Parameters::new(&model);
        assert_eq!(
            params.beam_elements(0),
            [0, 1],
            "one beam 'rod' of two elements"
        );
        let at = point(&model, &mut rng, 0.2);
        check_model(&format!("{kind:?} beam"), &model, &at, &mut seen);
        // Elements of other sections (one design variable per element, as topology
        // optimization sets them): no path of the whole beam, each element's own paths.
        let mut model = model;
        model.beams[1].section.stiffness[(4, 4)] *= 1.7;
        model.beams[1].section.mass_per_length *= 0.6;
        let params = Parameters::new(&model);
        assert!(params.id("beam.rod.section.EI2").is_err());
        for (k, e) in [(0, 0), (1, 1)] {
            let id = params
                .id(&format!("beam.rod.element.{k}.section.EI2"))
                .unwrap();
            let ParamKind::Beam(item, _) = params.kind(id) else {
                panic!("a beam parameter")
            };
            assert_eq!(params.beam_elements(item), [e]);
        }
        check_model(
            &format!("{kind:?} beam, elements apart"),
            &model,
            &at,
            &mut seen,
        );
    }
    println!("worst relative error {:.2e}", seen.worst);
}

/// Two balls on a plane, one against the other, with friction: every contact is closed
/// (penetrations of a few mm that the random point's spread of 1 mm keeps).
fn contacts(group: Group) -> Model {
    use flexmb::model::contact::{Contact, ContactLaw, ContactShape, Dissipation, Friction};
    let mut m = Model::new(group);
    m.gravity = Vec3::new(0.3, -9.81, 1.2);
    let a = m.add_node(
        "a",
        Frame::new(Vec3::new(0.0, 0.0, 0.095), Mat3::identity()),
    );
    let b = m.add_node(
        "b",
        Frame::new(Vec3::new(0.195, 0.0, 0.096), Mat3::identity()),
    );
    for (name, n) in [("a", a), ("b", b)] {
        m.add_body(name, n, 1.2, Vec3::zeros(), Mat3::identity() * 1e-3);
    }
    let law = |dissipation, exponent| ContactLaw {
        dissipation,
        stiffness: 3e4,
        exponent,
        restitution: 0.7,
        min_impact_velocity: 1e-3,
    };
    let friction = Some(Friction {
        coefficient: 0.3,
        stiction_velocity: 0.05,
        viscous: 20.0,
        bristles: None,
    });
    let sphere = |radius| ContactShape::Sphere {
        center: Vec3::zeros(),
        radius,
        inside: false,
    };
    let plane = ContactShape::Plane {
        point: Vec3::zeros(),
        normal: Vec3::z(),
    };
    let pairs = [
        (
            "floor_a",
            None,
            a,
            plane,
            Dissipation::LankaraniNikravesh,
            1.5,
        ),
        ("floor_b", None, b, plane, Dissipation::Flores, 1.5),
        (
            "ab",
            Some(a),
            b,
            sphere(0.1),
            Dissipation::HuntCrossley,
            1.0,
        ),
        // chi(e) of the exact restitution: its derivative in e
        (
            "ab_exact",
            Some(a),
            b,
            sphere(0.1),
            Dissipation::ExactRestitution,
            1.3,
        ),
    ];
    for (name, node_a, node_b, shape_a, dissipation, exponent) in pairs {
        // the second floor contact with bristles (LuGre)
        let bristles = (name == "floor_b").then_some(flexmb::model::contact::Bristles {
            stiffness: 300.0,
            damping: 2.0,
            static_coefficient: 0.45,
        });
        m.contacts.push(Contact {
            name: name.into(),
            node_a,
            node_b: Some(node_b),
            shape_a,
            shape_b: sphere(0.1),
            law: law(dissipation, exponent),
            friction: friction.map(|f| Friction { bristles, ..f }),
        });
    }
    m
}

#[test]
fn parameter_derivatives_match_finite_differences_on_contacts() {
    let mut seen = Seen::default();
    let mut rng = Lcg(8);
    for group in [Group::R3xSO3, Group::SE3] {
        let model = contacts(group);
        for _ in 0..2 {
            let mut at = point(&model, &mut rng, 1e-3);
            for node in at.nodes.iter_mut() {
                node.v *= 0.05;
            }
            // the impact velocities (held states): positive; bristle deflections small
            at.x.iter_mut().for_each(|x| *x = 1.0 + x.abs());
            let start = flexmb::elements::ElementItem::Contact(1).state_start(&model);
            for k in 1..4 {
                at.x[start + k] = 1e-3 * (k as f64 - 2.0);
            }
            check_model(&format!("contacts on {group:?}"), &model, &at, &mut seen);
        }
    }
    assert!(
        seen.kinds.contains("contact.<c>.friction.viscous"),
        "{:?}",
        seen.kinds
    );
    println!("worst relative error {:.2e}", seen.worst);
}

#[test]
fn parameter_kinds_by_finite_differences_are_the_listed_ones() {
    // Every kind of parameter occurs in the test models above, and these, and only these,
    // use the finite-difference default: a new one shows up here.
    let mut seen = Seen::default();
    let mut rng = Lcg(7);
    let at = point(&mechanism(Group::SE3), &mut rng, 1.0);
    check_model("mechanism", &mechanism(Group::SE3), &at, &mut seen);
    let at = point(&beam(BeamMass::Lumped), &mut rng, 0.2);
    check_model("beam", &beam(BeamMass::Lumped), &at, &mut seen);
    let mut at = point(&contacts(Group::SE3), &mut rng, 1e-3);
    at.x.iter_mut().for_each(|x| *x = 1.0 + x.abs());
    check_model("contacts", &contacts(Group::SE3), &at, &mut seen);
    let model = gears(Group::SE3);
    check_model(
        "gears",
        &model,
        &gear_point(&model, &mut rng, 0.01),
        &mut seen,
    );
    let by_differences: Vec<&str> = seen.by_differences.iter().map(String::as_str).collect();
    assert_eq!(
        by_differences,
        [
            "gear.<g>.transmission_error.<n>",
            "joint.<j>.position.<k>",
            "rope.<r>.points.<i>.point.<k>",
            "spring.<s>.point_a.<k>",
            "spring.<s>.point_b.<k>"
        ]
    );
    assert_eq!(seen.kinds.len(), 39, "kinds checked: {:#?}", seen.kinds);
}

/// A helical gear pair (stiffness harmonics, transmission error, damping, backlash) between
/// two wheels on revolute joints to the ground, and a gear joint between the second wheel
/// and a third.
fn gears(group: Group) -> Model {
    use flexmb::model::{GearGeometry, Harmonic};
    let mut m = Model::new(group);
    let axis = Vec3::new(0.1, 0.2, 1.0).normalize();
    let r = flexmb::model::frame_from_axis(&axis, None);
    let across = r.column(0).into_owned();
    let centers = [
        Vec3::new(0.1, 0.2, 0.3),
        Vec3::new(0.1, 0.2, 0.3) + across * 0.26,
    ];
    let a = m.add_node("a", Frame::new(centers[0], r));
    let b = m.add_node("b", Frame::new(centers[1], r));
    let c = m.add_node("c", Frame::new(centers[1] + r.column(1) * 0.3, r));
    for (i, n) in [a, b, c].into_iter().enumerate() {
        // heavy wheels: the gravity columns stand out of the round-off of the mesh force
        m.add_body(
            &format!("w{i}"),
            n,
            1e3,
            Vec3::zeros(),
            Mat3::identity() * 10.0,
        );
        let at = m.nodes[n.0].frame.x;
        m.add_joint(
            &format!("bearing{i}"),
            JointKind::Revolute,
            None,
            Some(n),
            at,
            r,
            None,
        );
    }
    let geometry = GearGeometry {
        teeth_a: 20,
        teeth_b: 31,
        module: 0.01,
        pressure_angle: 20f64.to_radians(),
        helix_angle: 12f64.to_radians(),
        internal: false,
    };
    let g = m.add_gear_pair("mesh", [Some(a), Some(b)], centers, &axis, geometry, 2e7);
    let gear = &mut m.gears[g];
    gear.damping = 3e3;
    gear.backlash = 2e-4;
    gear.stiffness_variation = vec![
        Harmonic {
            amplitude: 0.2,
            phase: 0.3,
        },
        Harmonic {
            amplitude: 0.05,
            phase: -1.0,
        },
    ];
    gear.transmission_error = vec![Harmonic {
        amplitude: 1e-5,
        phase: 0.7,
    }];
    gear.stiffness_table = vec![(0.1, 1.3), (0.3, 0.7), (0.65, 1.25)];
    let cc = m.nodes[c.0].frame.x;
    m.add_gear_joint(
        "ratio",
        [Some(b), Some(c)],
        [centers[1], cc],
        &axis,
        (31, 17, false),
    );
    m
}

/// A point near the initial configuration with wheel a turned by `turn` about its axis
/// (into the drive flank of the mesh).
fn gear_point(model: &Model, rng: &mut Lcg, turn: f64) -> Point {
    let mut at = point(model, rng, 1e-4);
    let axis = model.gears[0].frame_a.r.column(2).into_owned();
    let turned = flexmb_lie::join(&Vec3::zeros(), &(axis * turn));
    at.nodes[0].q = model.group.integrate(&at.nodes[0].q, &turned);
    at
}

#[test]
fn parameter_derivatives_match_finite_differences_on_gear_pairs() {
    let mut seen = Seen::default();
    let mut rng = Lcg(8);
    for group in [Group::R3xSO3, Group::SE3] {
        let model = gears(group);
        for turn in [0.01, -0.01] {
            let at = gear_point(&model, &mut rng, turn);
            check_model(
                &format!("gears on {group:?} (turn {turn})"),
                &model,
                &at,
                &mut seen,
            );
        }
    }
    let expected = [
        "gear.<g>.backlash",
        "gear.<g>.damping",
        "gear.<g>.mesh_stiffness",
        "gear.<g>.stiffness_variation.<n>",
        "gear.<g>.transmission_error.<n>",
    ];
    for kind in expected {
        assert!(seen.kinds.contains(kind), "{kind} checked");
    }
    println!("worst relative error {:.2e}", seen.worst);
}

/// Two bodies joined by nonlinear springs: a preloaded table law, separate curves per side
/// (a polynomial in compression, a table in extension) with a Maxwell branch, a bump stop
/// that acts (always compressed at these kinematics) and a strap from the ground.
fn nonlinear_springs(group: Group) -> Model {
    use flexmb::model::{ForceCurve, SpringLaw, SpringSide};
    let mut m = Model::new(group);
    let a = m.add_node("a", Frame::new(Vec3::new(0.1, 0.2, -0.3), Mat3::identity()));
    let b = m.add_node(
        "b",
        flexmb_lie::se3::exp(&Vec6::new(1.0, -0.4, 0.2, 0.3, -0.5, 0.7)),
    );
    let inertia = Mat3::new(0.3, 0.01, -0.02, 0.01, 0.4, 0.03, -0.02, 0.03, 0.5);
    m.add_body("body_a", a, 2.5, Vec3::new(0.3, -0.7, 0.2), inertia);
    m.add_body("body_b", b, 1.5, Vec3::new(-0.1, 0.2, 0.4), inertia * 2.0);
    let spring = |name: &str, node_a, rest_length| SpringDamper {
        name: name.into(),
        node_a,
        node_b: Some(b),
        point_a: Vec3::new(0.2, 0.1, -0.3),
        point_b: Vec3::new(-0.1, 0.4, 0.2),
        stiffness: 120.0,
        damping: 3.5,
        rest_length,
        relaxation: None,
    };
    let table = ForceCurve::Table(vec![(-3.0, -80.0), (0.1, 5.0), (0.5, 60.0), (4.0, 90.0)]);
    m.springs.push(spring("table", Some(a), 0.4));
    let mut law = SpringLaw::new(0);
    law.law.preload = 12.0;
    law.law.curve = Some(table.clone());
    m.spring_laws.push(law);
    let mut sides = spring("sides", Some(a), 1.2);
    sides.relaxation = Some(flexmb::model::Relaxation {
        stiffness: 30.0,
        damping: 4.0,
    });
    m.springs.push(sides);
    let mut law = SpringLaw::new(1);
    law.law.preload = -3.0;
    law.law.compression = Some(ForceCurve::Polynomial(vec![40.0, -15.0, 30.0]));
    law.law.extension = Some(table);
    m.spring_laws.push(law);
    m.springs.push(spring("bump", Some(a), 8.0));
    let mut law = SpringLaw::new(2);
    law.law.acts = SpringSide::Compression;
    law.law.curve = Some(ForceCurve::Polynomial(vec![0.0, 0.0, 2.0]));
    m.spring_laws.push(law);
    let mut strap = spring("strap", None, 0.01);
    strap.point_a = Vec3::new(-2.0, -3.0, 1.0);
    m.springs.push(strap);
    let mut law = SpringLaw::new(3);
    law.law.acts = SpringSide::Extension;
    law.law.curve = Some(ForceCurve::Polynomial(vec![10.0, 5.0]));
    m.spring_laws.push(law);
    m
}

#[test]
fn parameter_derivatives_match_finite_differences_on_nonlinear_springs() {
    let mut seen = Seen::default();
    let mut rng = Lcg(8);
    for group in [Group::R3xSO3, Group::SE3] {
        let model = nonlinear_springs(group);
        model.validate().expect("valid");
        for _ in 0..3 {
            let at = point(&model, &mut rng, 0.5);
            check_model(
                &format!("nonlinear springs on {group:?}"),
                &model,
                &at,
                &mut seen,
            );
        }
    }
    let laws: Vec<&String> = seen
        .kinds
        .iter()
        .filter(|k| k.contains("<side>") || k.ends_with("preload"))
        .collect();
    assert_eq!(laws.len(), 3, "{laws:?}");
    println!("worst relative error {:.2e}", seen.worst);
}

/// Two bodies on a revolute joint (one also on a cylindrical joint to the ground), with
/// rotational springs about both axes: a linear one and one with a preloaded table law.
fn rotational_springs(group: Group) -> Model {
    use flexmb::model::{ForceCurve, ForceLaw, RotationalSpring};
    let mut m = Model::new(group);
    m.gravity = Vec3::new(0.3, -9.81, 1.2);
    let a = m.add_node("a", Frame::new(Vec3::new(0.1, 0.2, -0.3), Mat3::identity()));
    let b = m.add_node(
        "b",
        flexmb_lie::se3::exp(&Vec6::new(1.0, -0.4, 0.2, 0.3, -0.5, 0.7)),
    );
    let inertia = Mat3::new(0.3, 0.01, -0.02, 0.01, 0.4, 0.03, -0.02, 0.03, 0.5);
    m.add_body("body_a", a, 2.5, Vec3::new(0.3, -0.7, 0.2), inertia);
    m.add_body("body_b", b, 1.5, Vec3::new(-0.1, 0.2, 0.4), inertia * 2.0);
    let axis = flexmb_lie::so3::exp(&Vec3::new(0.3, 0.2, -0.4));
    let hinge = m.add_joint(
        "hinge",
        JointKind::Revolute,
        Some(a),
        Some(b),
        Vec3::new(0.4, -0.2, 0.3),
        axis,
        None,
    );
    let shaft = m.add_joint(
        "shaft",
        JointKind::Cylindrical,
        None,
        Some(a),
        Vec3::new(0.1, 0.2, -0.3),
        Mat3::identity(),
        None,
    );
    m.rotational_springs.push(RotationalSpring {
        name: "coil".into(),
        joint: hinge,
        stiffness: 35.0,
        damping: 1.5,
        angle: 0.3,
        law: ForceLaw::default(),
    });
    m.rotational_springs.push(RotationalSpring {
        name: "clock".into(),
        joint: shaft,
        stiffness: 5.0,
        damping: 0.5,
        angle: -0.2,
        law: ForceLaw {
            preload: 2.0,
            curve: Some(ForceCurve::Table(vec![
                (-4.0, -30.0),
                (0.0, 0.0),
                (4.0, 80.0),
            ])),
            ..ForceLaw::default()
        },
    });
    m
}

#[test]
fn parameter_derivatives_match_finite_differences_on_rotational_springs() {
    let mut seen = Seen::default();
    let mut rng = Lcg(9);
    for group in [Group::R3xSO3, Group::SE3] {
        let model = rotational_springs(group);
        model.validate().expect("valid");
        for _ in 0..3 {
            let mut at = point(&model, &mut rng, 0.5);
            // the tracked angles (element states) on the branch of the geometric angle
            for (i, s) in model.rotational_springs.iter().enumerate() {
                let joint = &model.joints[s.joint.0];
                let slot = |n: Option<NodeId>| {
                    n.map_or(NodeState::ground(Frame::identity()), |n| at.nodes[n.0])
                };
                let nodes = [slot(joint.node_a), slot(joint.node_b)];
                at.x[i] = flexmb::elements::rotational_spring::joint_angle(joint, &nodes).0 + 0.2;
            }
            check_model(
                &format!("rotational springs on {group:?}"),
                &model,
                &at,
                &mut seen,
            );
        }
    }
    let kinds: Vec<&String> = seen
        .kinds
        .iter()
        .filter(|k| k.starts_with("rotational_spring"))
        .collect();
    assert_eq!(kinds.len(), 5, "{kinds:?}");
    assert!(seen
        .by_differences
        .iter()
        .all(|k| !k.starts_with("rotational")));
    println!("worst relative error {:.2e}", seen.worst);
}

/// Two bodies on bushings: one between them with frame offsets and full matrices
/// (large-rotation form), one from the ground (small-rotation form).
fn bushings(group: Group) -> Model {
    use flexmb::model::Bushing;
    let mut m = Model::new(group);
    let a = m.add_node("a", Frame::new(Vec3::new(0.1, 0.2, -0.3), Mat3::identity()));
    let b = m.add_node(
        "b",
        flexmb_lie::se3::exp(&Vec6::new(1.0, -0.4, 0.2, 0.3, -0.5, 0.7)),
    );
    let inertia = Mat3::new(0.3, 0.01, -0.02, 0.01, 0.4, 0.03, -0.02, 0.03, 0.5);
    m.add_body("body_a", a, 2.5, Vec3::new(0.3, -0.7, 0.2), inertia);
    m.add_body("body_b", b, 1.5, Vec3::new(-0.1, 0.2, 0.4), inertia * 2.0);
    let full = |d: [f64; 6], c: f64| {
        let mut k = Mat6::from_diagonal(&Vec6::from_column_slice(&d));
        for (i, j) in [(0, 4), (1, 5), (2, 3), (3, 5)] {
            k[(i, j)] = c;
            k[(j, i)] = c;
        }
        k
    };
    let at = Frame::new(
        Vec3::new(0.5, 0.0, -0.1),
        flexmb_lie::so3::exp(&Vec3::new(0.2, -0.3, 0.1)),
    );
    m.bushings.push(Bushing {
        name: "link".into(),
        node_a: Some(a),
        node_b: Some(b),
        frame_a: m.nodes[a.0].frame.inverse().compose(&at),
        frame_b: m.nodes[b.0].frame.inverse().compose(&at),
        stiffness: full([300.0, 200.0, 250.0, 40.0, 30.0, 50.0], 5.0),
        damping: full([3.0, 2.0, 2.5, 0.4, 0.3, 0.5], 0.05),
        form: flexmb::model::BushingForm::LargeRotation,
    });
    m.bushings.push(Bushing {
        name: "mount".into(),
        node_a: None,
        node_b: Some(a),
        frame_a: m.nodes[a.0].frame,
        frame_b: Frame::identity(),
        stiffness: full([100.0, 120.0, 140.0, 10.0, 12.0, 14.0], 2.0),
        damping: full([1.0, 1.2, 1.4, 0.1, 0.12, 0.14], 0.02),
        form: flexmb::model::BushingForm::SmallRotation,
    });
    m
}

#[test]
fn parameter_derivatives_match_finite_differences_on_bushings() {
    let mut seen = Seen::default();
    // (a seed at which no rate of the deformation is near zero: the relative error of a
    // column is measured against its own size)
    let mut rng = Lcg(12);
    for group in [Group::SE3, Group::R3xSO3] {
        let model = bushings(group);
        model.validate().expect("valid");
        for _ in 0..3 {
            let at = point(&model, &mut rng, 0.8);
            check_model(&format!("bushings on {group:?}"), &model, &at, &mut seen);
        }
    }
    let kinds: Vec<&String> = seen
        .kinds
        .iter()
        .filter(|k| k.starts_with("bushing"))
        .collect();
    assert_eq!(kinds.len(), 2, "{kinds:?}");
    assert!(seen
        .by_differences
        .iter()
        .all(|k| !k.starts_with("bushing")));
    println!("worst relative error {:.2e}", seen.worst);
}

#[test]
fn parameter_derivatives_match_finite_differences_on_worm_gears() {
    // Both flanks, sliding and sticking (the same velocities, below a large stiction
    // velocity: the regularization's linear range).
    let mut seen = Seen::default();
    let mut rng = Lcg(13);
    for group in [Group::R3xSO3, Group::SE3] {
        let mut model = common::worm_pair(group, &mut rng, false);
        model.validate().expect("valid");
        let axis = model.worm_gears[0].frame_a.r.column(2).into_owned();
        for (turn, v_e) in [(0.02, 1e-3), (-0.02, 1e-3), (0.02, 10.0), (-0.02, 10.0)] {
            model.worm_gears[0].stiction_velocity = v_e;
            let mut at = point(&model, &mut rng, 1e-6);
            at.nodes.iter_mut().for_each(|n| n.v *= 0.3);
            let twist = flexmb_lie::join(&Vec3::zeros(), &(axis * turn));
            at.nodes[0].q = group.integrate(&at.nodes[0].q, &twist);
            let gear = &model.worm_gears[0];
            let ctx = Context::at(&model, 0.0, 1.0);
            let state = gear.state(&ctx, &Local::nodes(&at.nodes));
            let slip = state.slip_velocity.abs() / v_e;
            assert!(
                state.normal_force * turn > 0.0 && !(0.5..=2.0).contains(&slip),
                "{state:?}"
            );
            let name = format!("worm gear on {group:?} (turn {turn}, |v_s| / v_e {slip:.3})");
            check_model(&name, &model, &at, &mut seen);
        }
    }
    let kinds: Vec<&str> = seen
        .kinds
        .iter()
        .map(String::as_str)
        .filter(|k| k.starts_with("worm_gear"))
        .collect();
    assert_eq!(kinds.len(), 4, "{kinds:?}");
    assert!(seen.by_differences.iter().all(|k| !k.starts_with("worm")));
    println!("worst relative error {:.2e}", seen.worst);
}

#[test]
fn parameter_derivatives_match_finite_differences_on_control_blocks() {
    // Every block with parameters (`common::control_diagram`): gains, time constants,
    // limits, PID gains, state-space and transfer-function coefficients, lookup values,
    // motor constants.
    let mut seen = Seen::default();
    let mut rng = Lcg(22);
    for group in [Group::SE3, Group::R3xSO3] {
        let model = common::control_diagram(group);
        model.validate().expect("valid");
        for _ in 0..2 {
            let at = point(&model, &mut rng, 0.5);
            check_model(
                &format!("control blocks on {group:?}"),
                &model,
                &at,
                &mut seen,
            );
        }
    }
    let kinds: Vec<&String> = seen
        .kinds
        .iter()
        .filter(|k| k.starts_with("control"))
        .collect();
    // every named parameter of every kind of block (A, B, C, D, x0, num, den, values,
    // the amplitudes of a source, ...)
    assert_eq!(kinds.len(), 26, "{kinds:?}");
    assert!(seen
        .by_differences
        .iter()
        .all(|k| !k.starts_with("control")));
    println!("worst relative error {:.2e}", seen.worst);
}

#[test]
fn exact_restitution_factor_derivative_matches_finite_differences() {
    // chi(e) of the law of the exact restitution (`law = "exact_restitution"`): the root of
    // G(chi, e) = chi (1 + e) - ln(1 + chi) + ln(1 - chi e) = 0 in (0, 1/e), its derivative by
    // the implicit function theorem against central differences of the root solve itself.
    use flexmb::model::contact::exact_restitution_factor;
    let mut worst = 0.0f64;
    for e in [0.05, 0.3, 0.5, 0.7, 0.8, 0.95, 0.999] {
        let (chi, dchi_de) = exact_restitution_factor(e);
        // the root, to round-off: G's Newton correction relative to chi (G evaluated as
        // written here, its terms of size chi cancelling to one of size chi^2 (1 - e^2))
        let g = chi * (1.0 + e) - chi.ln_1p() + (-chi * e).ln_1p();
        let g_chi = 1.0 + e - 1.0 / (1.0 + chi) - e / (1.0 - chi * e);
        let correction = (g / g_chi / chi).abs();
        let round_off = 10.0 * f64::EPSILON / (chi * (1.0 - e * e));
        assert!(
            chi > 0.0 && chi * e < 1.0 && correction < 1e-13 + round_off,
            "e = {e}: chi {chi}, G {g}, correction {correction}"
        );
        let h = 1e-6 * e.min(1.0 - e);
        let fd =
            (exact_restitution_factor(e + h).0 - exact_restitution_factor(e - h).0) / (2.0 * h);
        let error = (dchi_de - fd).abs() / fd.abs();
        println!("e = {e}: chi {chi:.6}, dchi/de {dchi_de:.6} (differences {fd:.6})");
        worst = worst.max(error);
        assert!(error < 1e-6, "e = {e}: dchi/de {dchi_de} vs {fd}");
    }
    // e = 1: no dissipation, and the limit of the derivative (Hunt & Crossley's slope)
    let (chi, dchi_de) = exact_restitution_factor(1.0);
    let h = 1e-6;
    let one_sided = (chi - exact_restitution_factor(1.0 - h).0) / h;
    assert_eq!(chi, 0.0);
    assert!(
        (dchi_de - one_sided).abs() < 1e-5,
        "{dchi_de} vs {one_sided}"
    );
    println!("worst relative error {worst:.2e}");
}
