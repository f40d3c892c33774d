//! Engine benchmarks behind BENCHMARKS.md: wall time per step and Newton iterations per step
//! for the heavy top, the N-link pendulum chains, beams and a chain of spring-dampers,
//! release build, one thread.
//!
//! ```text
//! cargo bench -p flexmb --bench engine              # all cases, each in its own process
//! cargo bench -p flexmb --bench engine -- chain_1000  # one case
//! FLEXMB_THREADS=2 cargo bench -p flexmb --bench engine -- beam_10000  # on 2 threads
//! cargo bench -p flexmb --bench engine -- threads   # the table of 1 against 2 threads
//! FLEXMB_SPHERES_OUT=s.json cargo bench -p flexmb --bench engine -- spheres_100  # + events
//! cargo bench -p flexmb --bench engine -- check     # flexmb check of 10 000 to 100 000 links
//! cargo bench -p flexmb --bench engine -- check_50000  # one of them
//! ```
//! `FLEXMB_SPHERES_OUT` also writes spheres_n's events and final state (JSON) for
//! `benches/exudyn_spheres_100.py`, the same problem in Exudyn.
//! Each case runs in a child process so that its peak memory (VmHWM) is its own.
//!
//! `FLEXMB_THREADS=N` assembles on `N` threads whatever the size of the model (the size
//! threshold of `flexmb::parallel` is bypassed for the dynamic cases, so that the crossover
//! can be measured); without it every case runs on one thread. `threads` runs beams and chains alternately on
//! 1 and 2 threads, `FLEXMB_REPEAT` times each (default 5), and prints the best and the
//! median of each.

use flexmb::input::{read_model_file, Analysis};
use flexmb::{Simulation, State};
use std::path::PathBuf;
use std::time::Instant;

mod common;
use common::peak_memory_mb;

const CASES: &[&str] = &[
    "heavy_top_se3",
    "heavy_top_r3so3",
    "heavy_top_updates",
    "lie_updates_other",
    "chain_10",
    "chain_100",
    "chain_1000",
    "chain_10000",
    "right_angle_cantilever",
    "roll_up",
    "beam_100",
    "beam_1000",
    "beam_10000",
    "springs_500",
    "spheres_100",
];

fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

struct Outcome {
    steps: usize,
    iterations: usize,
    seconds: f64,
    state: State,
}

/// The number of threads of this run: `FLEXMB_THREADS`, else one.
fn thread_count() -> usize {
    std::env::var("FLEXMB_THREADS").map_or(1, |n| n.parse().expect("FLEXMB_THREADS: a number"))
}

/// The threads of this run's assembly, forced whatever the model's size.
fn threads() -> flexmb::parallel::Threads {
    flexmb::parallel::Threads::forced(thread_count())
}

fn solve(file: &str, overrides: &[String]) -> Outcome {
    let mf = read_model_file(&example(file), overrides).expect("model file");
    let Analysis::Dynamic(mut settings) = mf.analysis else {
        panic!("{file} is not a dynamic analysis")
    };
    settings.threads = thread_count();
    let mut sim = Simulation::new(&mf.model, settings).expect("initial conditions");
    sim.data.threads = threads();
    let t0 = Instant::now();
    let stats = sim
        .run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("run");
    Outcome {
        steps: stats.steps,
        iterations: stats.newton_iterations,
        seconds: t0.elapsed().as_secs_f64(),
        state: sim.state.clone(),
    }
}

/// Heavy top with rho_inf = 0.6 to t = 1 s at several steps: error of the centre of mass
/// against the reference x_G(1 s) (benchmarks.md Sect. 1.2) and solve time.
fn heavy_top(file: &str) {
    println!("| case | h [s] | steps | error x_G(1 s) [m] | solve time [ms] | time/step [us] | Newton it./step |");
    println!("|---|---|---|---|---|---|---|");
    let steps = [1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5, 4.5e-5, 3.125e-5];
    heavy_top_rows(file, file, &[], &steps);
}

/// The configuration updates compared (`[solver] lie_update`), each with its overrides.
const UPDATES: [(&str, &[&str]); 5] = [
    ("bruls_cardona", &[]),
    ("lie_algebra", &["solver.lie_update=lie_algebra"]),
    (
        "lie_algebra_r3xso3",
        &["solver.lie_update=lie_algebra_r3xso3"],
    ),
    ("commutator 1/12", &["solver.lie_update=commutator"]),
    (
        "commutator 0.2",
        &[
            "solver.lie_update=commutator",
            "solver.lie_update_sigma=0.2",
        ],
    ),
];

/// The configuration updates of the generalized-alpha step compared on the heavy top
/// (BENCHMARKS.md, "Error constant: variants compared"): each update on both groups.
fn heavy_top_updates() {
    println!("| update, group | h [s] | steps | error x_G(1 s) [m] | solve time [ms] | time/step [us] | Newton it./step |");
    println!("|---|---|---|---|---|---|---|");
    let steps = [1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5, 3.125e-5];
    for (name, set) in UPDATES {
        for (group, file) in [
            ("R3xSO(3)", "heavy_top_r3so3.toml"),
            ("SE(3)", "heavy_top.toml"),
        ] {
            heavy_top_rows(&format!("{name}, {group}"), file, set, &steps);
        }
    }
}

/// The configuration updates on other problems (BENCHMARKS.md, "Error constant: variants
/// compared"): the largest node position error at the end against the same model at h/32
/// with the Brüls-Cardona update, rho_inf = 0.6. The asymmetric top is the heavy top with
/// the inertia (0.234375, 0.46875, 0.35) kg m^2 about its centre of mass.
fn lie_updates_other() {
    let asymmetric = "body.top.inertia=[0.234375, 0.46875, 0.35]";
    let cases: [(&str, &str, &str, f64, [f64; 2]); 6] = [
        (
            "asymmetric top",
            "heavy_top_r3so3.toml",
            "R3xSO3",
            1.0,
            [2.5e-4, 1.25e-4],
        ),
        (
            "asymmetric top",
            "heavy_top_r3so3.toml",
            "SE3",
            1.0,
            [2.5e-4, 1.25e-4],
        ),
        ("chain_10", "chain_10.toml", "SE3", 1.0, [1e-3, 5e-4]),
        ("chain_10", "chain_10.toml", "R3xSO3", 1.0, [1e-3, 5e-4]),
        ("Bricard", "bricard.toml", "SE3", 2.0, [1e-3, 5e-4]),
        ("Bricard", "bricard.toml", "R3xSO3", 2.0, [1e-3, 5e-4]),
    ];
    print!("| model, group | h [s] |");
    for (name, _) in UPDATES {
        print!(" {name} |");
    }
    println!();
    println!("|---|---|---|---|---|---|---|");
    for (name, file, group, t_end, steps) in cases {
        let base = |h: f64| {
            let mut o = vec![
                format!("model.group={group}"),
                format!("solver.h={h}"),
                "solver.rho_inf=0.6".to_string(),
                format!("solver.t_end={t_end}"),
                "solver.output_interval=0".to_string(),
            ];
            if name == "asymmetric top" {
                o.push(asymmetric.to_string());
            }
            o
        };
        let reference = solve(file, &base(steps[1] / 32.0)).state;
        for h in steps {
            print!("| {name}, {group} | {h:.3e} |");
            for (_, set) in UPDATES {
                let mut o = base(h);
                o.extend(set.iter().map(|s| s.to_string()));
                let end = solve(file, &o).state;
                let error = (end.q.iter().zip(&reference.q))
                    .map(|(a, b)| (a.x - b.x).norm())
                    .fold(0.0, f64::max);
                print!(" {error:.3e} |");
            }
            println!();
        }
    }
}

/// One table row per step size of the heavy top `file` with the overrides `set`.
fn heavy_top_rows(case: &str, file: &str, set: &[&str], steps: &[f64]) {
    let reference = [0.17334396, 0.64008859, -0.74849079];
    for &h in steps {
        let mut overrides: Vec<String> = vec![
            format!("solver.h={h}"),
            "solver.rho_inf=0.6".into(),
            "solver.t_end=1.0".into(),
            "solver.output_interval=0".into(),
        ];
        overrides.extend(set.iter().map(|s| s.to_string()));
        let o = solve(file, &overrides);
        let x = o.state.q[0].x;
        let err = ((x[0] - reference[0]).powi(2)
            + (x[1] - reference[1]).powi(2)
            + (x[2] - reference[2]).powi(2))
        .sqrt();
        println!(
            "| {case} | {h:.3e} | {} | {err:.3e} | {:.2} | {:.2} | {:.2} |",
            o.steps,
            o.seconds * 1e3,
            o.seconds * 1e6 / o.steps as f64,
            o.iterations as f64 / o.steps as f64
        );
    }
}

fn chain(n: usize) {
    let mut set = vec!["solver.output_interval=0".to_string()];
    let file = if example(&format!("chain_{n}.toml")).exists() {
        example(&format!("chain_{n}.toml"))
    } else {
        // Larger chains are not committed: the same chain, written here, over 0.1 s.
        set.push("solver.t_end=0.1".into());
        chain_file(n)
    };
    let o = solve(file.to_str().expect("path"), &set);
    println!(
        "| chain_{n} | {} | {:.3} | {:.1} | {:.2} | {:.2} | {:.1} |",
        o.steps,
        o.seconds,
        o.seconds * 1e6 / o.steps as f64,
        o.seconds * 1e6 / (o.steps * n) as f64,
        o.iterations as f64 / o.steps as f64,
        peak_memory_mb()
    );
}

/// Right-angle cantilever, 10 elements per leg, h = 0.125, 30 s (the example file).
fn right_angle_cantilever() {
    let o = solve(
        "right_angle_cantilever.toml",
        &["solver.output_interval=0".into()],
    );
    println!(
        "| right_angle_cantilever (20 elements) | {} | {:.1} | {:.1} | {:.2} | {:.2} |",
        o.steps,
        o.seconds * 1e3,
        o.seconds * 1e6 / o.steps as f64,
        o.seconds * 1e6 / (o.steps * 20) as f64,
        o.iterations as f64 / o.steps as f64
    );
}

/// Roll-up (static, 10 elements): adaptive load stepping.
fn roll_up() {
    let mf = read_model_file(&example("roll_up.toml"), &[]).expect("model file");
    let Analysis::Static(mut settings) = mf.analysis else {
        panic!("roll_up.toml is static")
    };
    settings.threads = thread_count();
    let t0 = Instant::now();
    let mut statics = flexmb::solve::Statics::new(&mf.model, settings).expect("starts");
    let stats = statics
        .run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("converges");
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "| roll_up (10 elements, static) | {} load steps | {:.2} | {} Newton iterations | | |",
        stats.steps,
        dt * 1e3,
        stats.newton_iterations
    );
}

/// A straight cantilever of `n` elements (10 m, right-angle cantilever section) under
/// gravity: 20 steps of h = 1e-3 s.
fn long_beam(n: usize) {
    use flexmb::model::{BeamSection, Model};
    use flexmb_lie::{Frame, Group, Vec3};
    let section = BeamSection::diagonal([1e6, 1e6, 1e6, 1e3, 1e3, 1e3], 1.0, [20.0, 10.0, 10.0]);
    let mut m = Model::new(Group::SE3);
    m.gravity = Vec3::new(0.0, 0.0, -9.81);
    let root = m.add_node("root", Frame::identity());
    m.add_straight_beam(
        "beam",
        root,
        Vec3::new(10.0, 0.0, 0.0),
        None,
        n,
        &Vec3::z(),
        &section,
    );
    m.add_clamp("clamp", root);
    let mut s = flexmb::DynamicSettings::new(0.02, 1e-3);
    s.rho_inf = 0.5;
    s.threads = thread_count();
    timed_row(
        &format!("beam_{n}"),
        n,
        Simulation::new(&m, s).expect("starts"),
    );
}

/// Runs `sim` and prints its row: steps, solve time, time per step and per item (`n` of
/// them: elements, springs), Newton iterations per step.
fn timed_row(case: &str, n: usize, mut sim: Simulation) {
    sim.data.threads = threads();
    let t0 = Instant::now();
    let stats = sim
        .run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("runs");
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "| {case} | {} | {:.1} | {:.1} | {:.2} | {:.2} |",
        stats.steps,
        dt * 1e3,
        dt * 1e6 / stats.steps as f64,
        dt * 1e6 / (stats.steps * n) as f64,
        stats.newton_iterations as f64 / stats.steps as f64
    );
}

/// The model file of an `n`-link chain like `examples/chain_1000.toml` (written by
/// `examples/generate/make_examples.py`), in the temporary directory.
fn chain_file(n: usize) -> PathBuf {
    use std::fmt::Write;
    let mut text = String::from(
        "flexmb = 1\ntitle = \"chain\"\n[model]\ngroup = \"SE3\"\ngravity = [0.0, -9.81, 0.0]\n\
         [solver]\nanalysis = \"dynamic\"\nt_end = 1.0\nh = 1e-3\nrho_inf = 0.6\n",
    );
    for i in 0..n {
        let _ = write!(
            text,
            "[[body]]\nname = \"link{i}\"\nmass = 1.0\nposition = [{}, 0.0, 0.0]\n\
             inertia = {{ box = [1.0, 0.1, 0.1] }}\n",
            i as f64 + 0.5
        );
    }
    for i in 0..n {
        let a = if i == 0 {
            "ground".to_string()
        } else {
            format!("link{}", i - 1)
        };
        let _ = write!(
            text,
            "[[joint]]\nname = \"j{i}\"\ntype = \"revolute\"\nnode_a = \"{a}\"\n\
             node_b = \"link{i}\"\nposition = [{}, 0.0, 0.0]\naxis = [0.0, 0.0, 1.0]\n",
            i as f64
        );
    }
    let path = std::env::temp_dir().join(format!("flexmb_bench_chain_{n}.toml"));
    std::fs::write(&path, text).expect("write the chain");
    path
}

/// A chain of 500 bodies on SE(3) hung by spring-dampers with offset attachment points
/// (every other one with a Maxwell branch: an element state), under gravity: 200 steps of
/// h = 1e-3 s. The force elements' share of a step.
fn springs(n: usize) {
    use flexmb::model::{Model, NodeId, Relaxation, SpringDamper};
    use flexmb_lie::{Frame, Group, Mat3, Vec3};
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
    }
    for i in 0..n {
        m.springs.push(SpringDamper {
            name: format!("s{i}"),
            node_a: i.checked_sub(1).map(NodeId),
            node_b: Some(NodeId(i)),
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
    let mut s = flexmb::DynamicSettings::new(0.2, 1e-3);
    s.threads = thread_count();
    let sim = Simulation::new(&m, s).expect("starts");
    timed_row(&format!("springs_{n}"), n, sim);
}

/// `n` steel balls (radius 20 mm, 0.26 kg) in a row 45 mm apart, 1 mm above a plane, rolling
/// towards each other at +-0.3 m/s (alternately) under gravity: n ball-plane contacts with
/// Coulomb friction (mu = 0.3) and n - 1 ball-ball contacts, Hertz stiffness of steel,
/// Lankarani-Nikravesh law with e = 0.8; 0.2 s at a nominal h = 1e-3 s. Steps, time per step
/// and per contact, Newton iterations per step, rejected steps (of them cut by the impacts'
/// step control).
fn spheres(n: usize) {
    use flexmb::model::contact::{Contact, ContactLaw, ContactShape, Dissipation, Friction};
    use flexmb::model::{Model, NodeId};
    use flexmb_lie::{Frame, Group, Mat3, Vec3};
    let (r, mass) = (0.02, 0.263);
    let mut m = Model::new(Group::R3xSO3);
    m.gravity = Vec3::new(0.0, 0.0, -9.81);
    for i in 0..n {
        let at = Frame::new(Vec3::new(i as f64 * 0.045, 0.0, r + 1e-3), Mat3::identity());
        let id = m.add_node(&format!("n{i}"), at);
        m.nodes[id.0].velocity = Vec3::new(if i % 2 == 0 { 0.3 } else { -0.3 }, 0.0, 0.0);
        m.add_body(
            &format!("b{i}"),
            id,
            mass,
            Vec3::zeros(),
            Mat3::identity() * 0.4 * mass * r * r,
        );
    }
    // Hertz: E* = E / (2 (1 - nu^2)) for two steels, K = 4/3 E* sqrt(R*)
    let e_star = 210e9 / (2.0 * (1.0 - 0.09));
    let law = |radius: f64| ContactLaw {
        dissipation: Dissipation::LankaraniNikravesh,
        stiffness: 4.0 / 3.0 * e_star * radius.sqrt(),
        exponent: 1.5,
        restitution: 0.8,
        min_impact_velocity: 1e-3,
    };
    let ball = |radius| ContactShape::Sphere {
        center: Vec3::zeros(),
        radius,
        inside: false,
    };
    for i in 0..n {
        m.contacts.push(Contact {
            name: format!("floor{i}"),
            node_a: None,
            node_b: Some(NodeId(i)),
            shape_a: ContactShape::Plane {
                point: Vec3::zeros(),
                normal: Vec3::z(),
            },
            shape_b: ball(r),
            law: law(r),
            friction: Some(Friction {
                coefficient: 0.3,
                stiction_velocity: 1e-3,
                viscous: 0.0,
                bristles: None,
            }),
        });
        if i > 0 {
            m.contacts.push(Contact {
                name: format!("pair{i}"),
                node_a: Some(NodeId(i - 1)),
                node_b: Some(NodeId(i)),
                shape_a: ball(r),
                shape_b: ball(r),
                law: law(r / 2.0),
                friction: None,
            });
        }
    }
    let mut s = flexmb::DynamicSettings::new(0.2, 1e-3);
    s.threads = thread_count();
    let mut sim = Simulation::new(&m, s).expect("starts");
    sim.data.threads = threads();
    // FLEXMB_SPHERES_OUT=FILE.json: also record the run's events and final state for the
    // comparison with Exudyn (benches/exudyn_spheres_100.py); the timed figures of
    // BENCHMARKS.md come from runs without it.
    let out = std::env::var_os("FLEXMB_SPHERES_OUT");
    let mut events = SphereEvents::new(r);
    let t0 = Instant::now();
    let stats = sim
        .run(&mut |sample: &flexmb::observe::Sample| {
            if out.is_some() {
                events.observe(sample.state);
            }
            Ok(())
        })
        .expect("runs");
    let dt = t0.elapsed().as_secs_f64();
    if let Some(path) = out {
        let report = events.report(&sim.state, mass, stats.steps, dt);
        std::fs::write(&path, report.to_string()).expect("writes FLEXMB_SPHERES_OUT");
    }
    let contacts = m.contacts.len();
    println!(
        "| spheres_{n} | {contacts} | {} | {:.1} | {:.1} | {:.2} | {:.2} | {} ({} by impacts) | {:.1e} |",
        stats.steps,
        dt * 1e3,
        dt * 1e6 / stats.steps as f64,
        dt * 1e6 / (stats.steps * contacts) as f64,
        stats.newton_iterations as f64 / stats.steps as f64,
        stats.rejected_steps,
        stats.event_rejections,
        stats.smallest_step,
    );
}

/// What the comparison of `spheres_n` with Exudyn looks at, taken at the end of every
/// accepted step (gaps interpolated linearly in time between step ends): the first contact
/// of balls 0 and 1, their velocities when it first opens again, the landing of ball 0, how
/// many times the ball-ball and ball-plane contacts close, and the final state.
struct SphereEvents {
    radius: f64,
    last: Option<(f64, Vec<f64>, Vec<f64>)>,
    first_contact_01: Option<f64>,
    separation_01: Option<(f64, f64, f64)>,
    landing_0: Option<f64>,
    pair_closures: usize,
    floor_closures: usize,
}

impl SphereEvents {
    fn new(radius: f64) -> Self {
        Self {
            radius,
            last: None,
            first_contact_01: None,
            separation_01: None,
            landing_0: None,
            pair_closures: 0,
            floor_closures: 0,
        }
    }

    /// The ball-ball gaps (pair i - 1, i) and the ball-plane gaps of `state`.
    fn gaps(&self, state: &State) -> (Vec<f64>, Vec<f64>) {
        let x: Vec<_> = state.q.iter().map(|f| f.x).collect();
        let pairs = x
            .windows(2)
            .map(|w| (w[1] - w[0]).norm() - 2.0 * self.radius)
            .collect();
        let floor = x.iter().map(|p| p.z - self.radius).collect();
        (pairs, floor)
    }

    fn observe(&mut self, state: &State) {
        let (pairs, floor) = self.gaps(state);
        if let Some((t_prev, pairs_prev, floor_prev)) = &self.last {
            let crossing = |g0: f64, g1: f64| t_prev + (state.t - t_prev) * g0 / (g0 - g1);
            for (i, (&g0, &g1)) in pairs_prev.iter().zip(&pairs).enumerate() {
                if g0 >= 0.0 && g1 < 0.0 {
                    self.pair_closures += 1;
                    if i == 0 && self.first_contact_01.is_none() {
                        self.first_contact_01 = Some(crossing(g0, g1));
                    }
                }
                if i == 0 && g0 < 0.0 && g1 >= 0.0 && self.separation_01.is_none() {
                    let (v0, v1) = (state.v[0][0], state.v[1][0]);
                    self.separation_01 = Some((crossing(g0, g1), v0, v1));
                }
            }
            for (i, (&g0, &g1)) in floor_prev.iter().zip(&floor).enumerate() {
                if g0 >= 0.0 && g1 < 0.0 {
                    self.floor_closures += 1;
                    if i == 0 && self.landing_0.is_none() {
                        self.landing_0 = Some(crossing(g0, g1));
                    }
                }
            }
        }
        self.last = Some((state.t, pairs, floor));
    }

    /// The events and the final positions, velocities and world angular velocities about y.
    fn report(&self, state: &State, mass: f64, steps: usize, seconds: f64) -> serde_json::Value {
        let x: Vec<_> = state.q.iter().map(|f| [f.x.x, f.x.z]).collect();
        let v: Vec<_> = state.v.iter().map(|v| [v[0], v[2]]).collect();
        // R3xSO(3): v = (u inertial, Omega body); the world angular velocity is R Omega.
        let wy: Vec<_> = state
            .q
            .iter()
            .zip(&state.v)
            .map(|(f, v)| (f.r * flexmb_lie::Vec3::new(v[3], v[4], v[5])).y)
            .collect();
        serde_json::json!({
            "tool": "flexmb",
            "t": state.t,
            "mass": mass,
            "steps": steps,
            "solve_seconds": seconds,
            "first_contact_01": self.first_contact_01,
            "separation_01": self.separation_01,
            "landing_0": self.landing_0,
            "pair_closures": self.pair_closures,
            "floor_closures": self.floor_closures,
            "x": x,
            "v": v,
            "wy": wy,
        })
    }
}

/// CPU seconds (user and system) of this process so far, from `/proc/self/stat` (Linux,
/// 100 ticks a second): on a shared machine the wall time counts the other processes too.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // The fields after the command name (in parentheses): utime and stime are the 12th and
    // 13th.
    let fields: Vec<&str> = stat
        .rfind(')')
        .map_or("", |end| &stat[end + 1..])
        .split_whitespace()
        .collect();
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok());
    match (ticks(11), ticks(12)) {
        (Some(user), Some(system)) => (user + system) / 100.0,
        _ => f64::NAN,
    }
}

/// What `flexmb check` does with an `n`-link chain (the file of [`chain_file`]), phase by
/// phase in CPU seconds: reading (TOML, the model, `Model::validate`), the solver's set-up
/// (the layout, the iteration matrix's pattern, the block LU's structure: `Data::new`), the
/// consistent initial accelerations (assembly, factorization, solve); then the wall time of
/// the three and the peak memory of the process, also per link.
fn check(n: usize) {
    let path = chain_file(n);
    let (wall, start) = (Instant::now(), cpu_seconds());
    let file = read_model_file(&path, &[]).expect("model file");
    let read = cpu_seconds();
    let Analysis::Dynamic(settings) = file.analysis else {
        unreachable!("the chain is dynamic")
    };
    let (layout, _) = flexmb::solve::prepare_layout(&file.model);
    let mut state = State::initial(&file.model, &layout).expect("initial states");
    let mut data = flexmb::Data::new(&file.model, layout).expect("solver");
    let set_up = cpu_seconds();
    let load = settings.load_factor_at(0.0);
    flexmb::solve::initial_accelerations(&file.model, &mut data, &mut state, load)
        .expect("consistent");
    let initial = cpu_seconds();
    let wall = wall.elapsed().as_secs_f64();
    let memory = peak_memory_mb();
    println!(
        "| {n} | {:.2} | {:.2} | {:.2} | {:.2} | {wall:.2} | {:.1} | {memory:.0} | {:.1} |",
        read - start,
        set_up - read,
        initial - set_up,
        initial - start,
        (initial - start) * 1e6 / n as f64,
        memory * 1024.0 / n as f64,
    );
}

/// [`check`] of 10 000, 50 000 and 100 000 links, each in its own process.
fn check_table() {
    println!("| links | read [CPU s] | solver set-up [CPU s] | initial accelerations [CPU s] | total [CPU s] | wall [s] | CPU/link [us] | peak memory [MB] | memory/link [kB] |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for n in [10_000, 50_000, 100_000] {
        print_child(&format!("check_{n}"));
    }
}

fn run_case(case: &str) {
    match case {
        "right_angle_cantilever" => right_angle_cantilever(),
        "roll_up" => roll_up(),
        c if c.starts_with("beam_") => long_beam(c[5..].parse().expect("beam size")),
        "heavy_top_se3" => heavy_top("heavy_top.toml"),
        "heavy_top_r3so3" => heavy_top("heavy_top_r3so3.toml"),
        "heavy_top_updates" => heavy_top_updates(),
        "lie_updates_other" => lie_updates_other(),
        c if c.starts_with("chain_") => chain(c[6..].parse().expect("chain size")),
        c if c.starts_with("check_") => check(c[6..].parse().expect("chain size")),
        c if c.starts_with("springs_") => springs(c[8..].parse().expect("chain size")),
        c if c.starts_with("spheres_") => spheres(c[8..].parse().expect("number of balls")),
        other => panic!("unknown case {other}; cases: {CASES:?}"),
    }
}

/// Time per step [us] of `case` on `threads` threads, in a child process (the 4th column of
/// its row).
fn time_per_step(case: &str, threads: usize) -> f64 {
    let exe = std::env::current_exe().expect("own path");
    let out = std::process::Command::new(&exe)
        .arg(case)
        .env("FLEXMB_THREADS", threads.to_string())
        .output()
        .expect("child");
    assert!(
        out.status.success(),
        "{case} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let row = String::from_utf8_lossy(&out.stdout);
    row.split('|')
        .nth(4)
        .and_then(|c| c.trim().parse().ok())
        .unwrap_or_else(|| panic!("no time in {row}"))
}

/// Beams and chains on 1 and 2 threads, alternately, `FLEXMB_REPEAT` times each: best and
/// median time per step and the speedup of the best.
fn threads_table() {
    let repeat: usize =
        std::env::var("FLEXMB_REPEAT").map_or(5, |r| r.parse().expect("FLEXMB_REPEAT: a number"));
    println!("| case | items | 1 thread, best [us/step] | median | 2 threads, best [us/step] | median | speedup (best) | speedup (median) |");
    println!("|---|---|---|---|---|---|---|---|");
    for (case, items) in [
        ("beam_100", 101),
        ("chain_100", 200),
        ("beam_300", 301),
        ("beam_1000", 1001),
        ("chain_1000", 2000),
        ("beam_10000", 10001),
    ] {
        let (mut one, mut two) = (Vec::new(), Vec::new());
        for _ in 0..repeat {
            one.push(time_per_step(case, 1));
            two.push(time_per_step(case, 2));
        }
        let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            let n = v.len();
            0.5 * (v[(n - 1) / 2] + v[n / 2])
        };
        let (b1, b2) = (best(&one), best(&two));
        let (m1, m2) = (median(&mut one), median(&mut two));
        println!(
            "| {case} | {items} | {b1:.1} | {m1:.1} | {b2:.1} | {m2:.1} | {:.2} | {:.2} |",
            b1 / b2,
            m1 / m2
        );
    }
}

fn main() {
    // `cargo bench` passes `--bench`; ignore flags.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    match args.first().map(String::as_str) {
        Some("threads") => return threads_table(),
        Some("check") => return check_table(),
        Some(case) => return run_case(case),
        None => {}
    }
    for case in CASES {
        if *case == "right_angle_cantilever" {
            println!("\n| case | steps | solve time [ms] | time/step [us] | time/step/element [us] | Newton it./step |");
            println!("|---|---|---|---|---|---|");
        }
        if *case == "springs_500" {
            println!("\n| case | steps | solve time [ms] | time/step [us] | time/step/spring [us] | Newton it./step |");
            println!("|---|---|---|---|---|---|");
        }
        if *case == "heavy_top_updates" || *case == "lie_updates_other" {
            println!();
        }
        if *case == "spheres_100" {
            println!("\n| case | contacts | steps | solve time [ms] | time/step [us] | time/step/contact [us] | Newton it./step | rejected steps | smallest step [s] |");
            println!("|---|---|---|---|---|---|---|---|---|");
        }
        if *case == "chain_10" {
            println!("\n| case | steps | solve time [s] | time/step [us] | time/step/link [us] | Newton it./step | peak memory [MB] |");
            println!("|---|---|---|---|---|---|---|");
        }
        print_child(case);
    }
}

/// Runs `case` in a child process (its peak memory its own) and prints what it printed.
fn print_child(case: &str) {
    let exe = std::env::current_exe().expect("own path");
    let out = std::process::Command::new(&exe)
        .arg(case)
        .output()
        .expect("child");
    print!("{}", String::from_utf8_lossy(&out.stdout));
    if !out.status.success() {
        eprintln!("{case} failed: {}", String::from_utf8_lossy(&out.stderr));
    }
}
