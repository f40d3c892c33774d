//! Parallel assembly gives the same bits as the sequential one, whatever the number of
//! threads: whole runs (a beam above the size threshold, a rigid chain, spring-dampers with
//! element states, the stabilized formulation, statics, sensitivity gradients by the direct
//! and adjoint methods) and single assemblies (every kind of constraint right-hand side, with
//! and without the matrix). Equality is on the bits of
//! every number, not within a tolerance.

use flexmb::assembly::{assemble, ConstraintRhs, Iterate, Scaling};
use flexmb::data::{Data, Layout};
use flexmb::elements::{Coefficients, NodeState};
use flexmb::input::{read_model_file, Analysis};
use flexmb::model::{BeamSection, Model, NodeId, Relaxation, SpringDamper};
use flexmb::parallel::{Threads, MIN_PARALLEL_ITEMS};
use flexmb::{DynamicSettings, Simulation, State};
use flexmb_lie::{Frame, Group, Mat3, Vec3, Vec6};
use std::path::PathBuf;

/// The bits of every number of a state.
fn bits(s: &State) -> Vec<u64> {
    let mut out = vec![s.t.to_bits()];
    for q in &s.q {
        out.extend(q.x.iter().chain(q.r.iter()).map(|v| v.to_bits()));
    }
    for v in s.v.iter().chain(&s.vdot).chain(&s.a) {
        out.extend(v.iter().map(|v| v.to_bits()));
    }
    for v in [&s.lambda, &s.x, &s.xdot, &s.w] {
        out.extend(v.iter().map(|v| v.to_bits()));
    }
    out
}

/// A cantilever of `n` beam elements (1 m) under gravity, clamped at its root.
fn cantilever(n: usize) -> Model {
    let section = BeamSection::diagonal([1e6, 1e6, 1e6, 1e3, 1e3, 1e3], 1.0, [20.0, 10.0, 10.0]);
    let mut m = Model::new(Group::SE3);
    m.gravity = Vec3::new(0.0, 0.0, -9.81);
    let root = m.add_node("root", Frame::identity());
    m.add_straight_beam(
        "beam",
        root,
        Vec3::new(1.0, 0.0, 0.0),
        None,
        n,
        &Vec3::z(),
        &section,
    );
    m.add_clamp("clamp", root);
    m
}

/// `n` bodies hung by spring-dampers, every other one with a Maxwell branch (an element
/// state).
fn springs(n: usize) -> Model {
    let mut m = Model::new(Group::SE3);
    m.gravity = Vec3::new(0.0, 0.0, -9.81);
    for i in 0..n {
        let at = Frame::new(Vec3::new(i as f64 * 0.1, 0.0, 0.0), Mat3::identity());
        let id = m.add_node(&format!("n{i}"), at);
        m.add_body(
            &format!("b{i}"),
            id,
            1.0,
            Vec3::zeros(),
            Mat3::identity() * 1e-2,
        );
        m.springs.push(SpringDamper {
            name: format!("s{i}"),
            node_a: i.checked_sub(1).map(NodeId),
            node_b: Some(id),
            point_a: Vec3::new(if i == 0 { -0.07 } else { 0.03 }, 0.01, 0.0),
            point_b: Vec3::new(-0.05, 0.01, 0.0),
            stiffness: 1e4,
            damping: 1.0,
            rest_length: 0.02,
            relaxation: (i % 2 == 1).then_some(Relaxation {
                stiffness: 5e3,
                damping: 50.0,
            }),
        });
    }
    m
}

/// The final state and the work counts of a run of `model` on `threads` (forced whatever the
/// size of the model, after the initial conditions, when `force` is set; through the
/// setting otherwise).
fn run(model: &Model, mut settings: DynamicSettings, threads: usize, force: bool) -> Vec<u64> {
    settings.threads = threads;
    let mut sim = Simulation::new(model, settings).expect("starts");
    if force {
        sim.data.threads = Threads::forced(threads);
    }
    assert_eq!(sim.data.threads.count(), threads, "the threads asked for");
    let stats = sim
        .run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("runs");
    let mut out = bits(&sim.state);
    out.extend([stats.steps, stats.newton_iterations, stats.factorizations].map(|n| n as u64));
    out
}

#[test]
fn beam_run_same_bits_on_1_2_and_3_threads() {
    // Above the size threshold: the setting alone makes it parallel, initial accelerations
    // included.
    let n = MIN_PARALLEL_ITEMS;
    let model = cantilever(n);
    let settings = DynamicSettings::new(0.01, 1e-3);
    let one = run(&model, settings, 1, false);
    assert_eq!(one, run(&model, settings, 2, false));
    assert_eq!(one, run(&model, settings, 3, false));
}

#[test]
fn small_beam_forced_parallel_same_bits_as_sequential() {
    let model = cantilever(20);
    assert_eq!(
        Threads::for_model(&model, 2).count(),
        1,
        "a small model stays sequential"
    );
    let settings = DynamicSettings::new(0.02, 1e-3);
    let one = run(&model, settings, 1, false);
    assert_eq!(one, run(&model, settings, 2, true));
}

fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

fn chain_settings(overrides: &[&str]) -> (Model, DynamicSettings) {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let mf = read_model_file(&example("chain_100.toml"), &overrides).expect("model file");
    let Analysis::Dynamic(settings) = mf.analysis else {
        panic!("chain_100.toml is dynamic")
    };
    (mf.model, settings)
}

#[test]
fn chain_run_same_bits_on_1_and_2_threads() {
    let (model, settings) = chain_settings(&["solver.t_end=0.05"]);
    let one = run(&model, settings, 1, false);
    assert_eq!(one, run(&model, settings, 2, true));
    assert_eq!(one, run(&model, settings, 3, true));
}

#[test]
fn stabilized_chain_run_same_bits_on_1_and_2_threads() {
    // rho_inf = 1: the stabilized index-2 formulation (velocity-level rows, B B_n^T).
    let (model, settings) = chain_settings(&["solver.t_end=0.03", "solver.rho_inf=1.0"]);
    assert!(settings.stabilized());
    let one = run(&model, settings, 1, false);
    assert_eq!(one, run(&model, settings, 2, true));
}

#[test]
fn springs_with_states_run_same_bits_on_1_and_2_threads() {
    let model = springs(150);
    let settings = DynamicSettings::new(0.02, 1e-3);
    let one = run(&model, settings, 1, false);
    assert_eq!(one, run(&model, settings, 2, true));
}

#[test]
fn static_beam_same_bits_on_1_and_2_threads() {
    let model = cantilever(MIN_PARALLEL_ITEMS);
    let solve = |threads: usize| {
        let mut settings = flexmb::solve::StaticSettings::new();
        settings.threads = threads;
        let mut statics = flexmb::solve::Statics::new(&model, settings).expect("starts");
        assert_eq!(statics.data.threads.count(), threads);
        let stats = statics
            .run(&mut |_: &flexmb::observe::Sample| Ok(()))
            .expect("converges");
        let mut out = bits(&statics.state);
        out.push(stats.newton_iterations as u64);
        out
    };
    assert_eq!(solve(1), solve(2));
}

/// Everything one assembly writes, as bits.
fn assembly_bits(
    model: &Model,
    layout: &Layout,
    threads: Threads,
    sc: &Scaling,
    matrix: bool,
) -> Vec<u64> {
    let mut data = Data::new(model, layout.clone())
        .expect("data")
        .with_threads(threads);
    // A moved, turning, accelerating configuration with multipliers and element states.
    let nodes: Vec<NodeState> = model
        .nodes
        .iter()
        .enumerate()
        .map(|(i, node)| {
            let k = i as f64;
            let inc = Vec6::new(0.01 * k.sin(), 0.02, -0.01, 0.1 * k.cos(), 0.05, 0.02 * k);
            NodeState {
                q: model.group.integrate(&node.frame, &inc),
                v: inc * 3.0,
                vdot: inc * -2.0,
                t: model.group.tangent(&(inc * 0.1)),
            }
        })
        .collect();
    let lambda: Vec<f64> = (0..layout.n_rows).map(|r| (r as f64 * 0.7).sin()).collect();
    let b_start = vec![flexmb::elements::Vec12::from_element(0.3); layout.n_rows];
    let x: Vec<f64> = (0..layout.n_states).map(|i| 1e-3 * i as f64).collect();
    let it = Iterate {
        nodes: &nodes,
        t: 0.2,
        lambda: &lambda,
        b_start: &b_start,
        x: &x,
        xdot: &x,
        inputs: None,
    };
    assemble(model, &mut data, &it, sc, matrix);
    let mut out: Vec<u64> = data.residual.iter().map(|v| v.to_bits()).collect();
    out.extend(data.phi.iter().map(|v| v.to_bits()));
    out.extend(
        data.b_rows
            .iter()
            .flat_map(|b| b.iter().map(|v| v.to_bits())),
    );
    if matrix {
        out.extend(data.values.iter().map(|v| v.to_bits()));
    }
    out
}

#[test]
fn single_assembly_same_bits_for_every_right_hand_side() {
    let (chain, _) = chain_settings(&[]);
    let mut beam_and_springs = cantilever(70);
    let extra = springs(80);
    let offset = beam_and_springs.nodes.len();
    for (node, body) in extra.nodes.iter().zip(&extra.bodies) {
        let id = beam_and_springs.add_node(&node.name, node.frame);
        beam_and_springs.add_body(&body.name, id, body.mass, body.com, body.inertia);
    }
    for s in &extra.springs {
        let mut s = s.clone();
        s.node_a = s.node_a.map(|n| NodeId(n.0 + offset));
        s.node_b = s.node_b.map(|n| NodeId(n.0 + offset));
        beam_and_springs.springs.push(s);
    }
    let coef = Coefficients {
        m: 0.7,
        c: 0.3,
        k: 1.1,
        x: 0.9,
        xdot: 0.4,
        y: 0.3,
    };
    for model in [&chain, &beam_and_springs] {
        for stabilized in [false, true] {
            let mut layout = Layout::new(model);
            layout.stabilized = stabilized;
            for rhs in [
                ConstraintRhs::Position,
                ConstraintRhs::Velocity,
                ConstraintRhs::Acceleration,
            ] {
                let sc = Scaling {
                    row_scale: 0.37,
                    coef,
                    constraint_rhs: rhs,
                    load_factor: 0.8,
                    regularization: 1e-6,
                    velocity_scale: 2.5,
                    nodal_damping: 0.1,
                    state_scale: 0.6,
                };
                for matrix in [true, false] {
                    let one = assembly_bits(model, &layout, Threads::sequential(), &sc, matrix);
                    for n in [2, 3] {
                        let many = assembly_bits(model, &layout, Threads::forced(n), &sc, matrix);
                        assert!(
                            one == many,
                            "{n} threads, stabilized {stabilized}, {rhs:?}, matrix {matrix}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn sensitivity_gradients_same_bits_on_1_and_2_threads() {
    // 150 + 150 beam elements: the forward run, the direct method's and the adjoint's
    // assemblies all parallel with 2 threads.
    let gradients = |threads: usize| {
        let set: Vec<String> = [
            "beam.0.elements=150",
            "beam.1.elements=150",
            "solver.t_end=0.5",
            &format!("solver.threads={threads}"),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let file = read_model_file(&example("right_angle_cantilever_sensitivity.toml"), &set)
            .expect("model file");
        let setup = file.sensitivity.as_ref().expect("sensitivity");
        let problem = setup.problem(std::sync::Arc::new(file.model.clone()), file.analysis);
        let mut out = Vec::new();
        for g in [
            flexmb::sensitivity::direct(&problem).expect("direct"),
            flexmb::sensitivity::adjoint(&problem, &mut |_, _| {}).expect("adjoint"),
        ] {
            out.extend(g.values.iter().map(|v| v.to_bits()));
            out.extend(g.gradients.iter().flatten().map(|v| v.to_bits()));
        }
        out
    };
    assert_eq!(gradients(1), gradients(2));
}
