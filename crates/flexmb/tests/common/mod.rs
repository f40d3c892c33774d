//! Helpers shared by the physics tests: run an example model file with overrides and
//! collect its sensor time histories.

#![allow(dead_code)]

use flexmb::input::{read_model_file, Analysis};
use flexmb::sensors::SensorEvaluator;
use flexmb::solve::Statics;
use flexmb::{Simulation, SolveError};
use std::path::PathBuf;

/// Path of a file in the repository's `examples/` folder.
pub fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

/// Path of a file in the repository's `tests/reference/` folder.
pub fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/reference")
        .join(name)
}

/// Sensor histories of a run: column names and rows `(t, values)`.
pub struct History {
    pub names: Vec<String>,
    pub rows: Vec<(f64, Vec<f64>)>,
    pub stats: flexmb::solve::Stats,
    pub warnings: Vec<String>,
    pub notes: Vec<String>,
}

impl History {
    /// Index of a sensor column.
    pub fn column(&self, name: &str) -> usize {
        self.names
            .iter()
            .position(|n| n == name)
            .unwrap_or_else(|| panic!("no sensor '{name}'"))
    }

    /// Value of a sensor at the output time closest to `t`.
    pub fn at(&self, name: &str, t: f64) -> f64 {
        let c = self.column(name);
        let row = self
            .rows
            .iter()
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .expect("rows");
        assert!(
            (row.0 - t).abs() < 1e-9,
            "no output at t = {t} (closest {})",
            row.0
        );
        row.1[c]
    }

    /// Time series of one sensor.
    pub fn series(&self, name: &str) -> Vec<(f64, f64)> {
        let c = self.column(name);
        self.rows.iter().map(|(t, v)| (*t, v[c])).collect()
    }

    pub fn last(&self, name: &str) -> f64 {
        let c = self.column(name);
        self.rows.last().expect("rows").1[c]
    }
}

/// Runs an example with `--set` style overrides; returns the histories or the solver error.
pub fn try_run(name: &str, overrides: &[&str]) -> Result<History, SolveError> {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let file = read_model_file(&example(name), &overrides).unwrap_or_else(|e| panic!("{e}"));
    let Analysis::Dynamic(settings) = file.analysis else {
        panic!("{name} is not a dynamic analysis")
    };
    run_model(&file.model, settings)
}

/// Runs a model built or modified in Rust.
pub fn run_model(
    model: &flexmb::model::Model,
    settings: flexmb::DynamicSettings,
) -> Result<History, SolveError> {
    let mut sim = Simulation::new(model, settings)?;
    let mut sensors = SensorEvaluator::new(model);
    let mut rows = Vec::new();
    let result = sim.run(&mut |s: &flexmb::observe::Sample| {
        rows.push((s.state.t, sensors.evaluate(s.model, s.data, s.state)));
        Ok(())
    });
    let stats = result?;
    Ok(History {
        names: SensorEvaluator::names(model),
        rows,
        stats,
        warnings: sim.warnings.clone(),
        notes: sim.notes.clone(),
    })
}

/// Like [`try_run`], panicking with the diagnosis on failure.
pub fn run(name: &str, overrides: &[&str]) -> History {
    try_run(name, overrides).unwrap_or_else(|e| panic!("{name} {overrides:?}: {e}"))
}

/// Least-squares slope of log(err) against log(h).
pub fn order(h: &[f64], err: &[f64]) -> f64 {
    let x: Vec<f64> = h.iter().map(|v| v.ln()).collect();
    let y: Vec<f64> = err.iter().map(|v| v.ln()).collect();
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(&y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    sxy / sxx
}

/// Runs a static example; the rows' first entry is the load factor.
pub fn run_static(name: &str, overrides: &[&str]) -> History {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let file = read_model_file(&example(name), &overrides).unwrap_or_else(|e| panic!("{e}"));
    let Analysis::Static(settings) = file.analysis else {
        panic!("{name} is not a static analysis")
    };
    let model = &file.model;
    let mut statics = Statics::new(model, settings).unwrap_or_else(|e| panic!("{name}: {e}"));
    let mut sensors = SensorEvaluator::new(model);
    let mut rows = Vec::new();
    let stats = statics
        .run(&mut |s: &flexmb::observe::Sample| {
            rows.push((s.at, sensors.evaluate(s.model, s.data, s.state)));
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    History {
        names: SensorEvaluator::names(model),
        rows,
        stats: flexmb::solve::Stats {
            steps: stats.steps,
            newton_iterations: stats.newton_iterations,
            rejected_steps: stats.rejected_steps,
            factorizations: stats.factorizations,
            ..Default::default()
        },
        warnings: statics.warnings.clone(),
        notes: statics.notes.clone(),
    }
}

/// A simulation of an example file, with `--set` overrides.
pub fn example_simulation(file: &str, overrides: &[&str]) -> flexmb::Simulation {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let mf = flexmb::input::read_model_file(&example(file), &overrides).expect("model file");
    let flexmb::input::Analysis::Dynamic(settings) = mf.analysis else {
        panic!("{file} is a dynamic analysis")
    };
    flexmb::Simulation::new(mf.model, settings).expect("starts")
}

/// A deterministic pseudo-random sequence (a linear congruential generator) for the tests'
/// sample points and directions.
pub struct Lcg(pub u64);

impl Lcg {
    /// The next number, uniform in [-1, 1].
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    /// A vector with components in [-s, s].
    pub fn v3(&mut self, s: f64) -> flexmb_lie::Vec3 {
        flexmb_lie::Vec3::new(self.next(), self.next(), self.next()) * s
    }

    /// A 6-vector with components in [-s, s].
    pub fn v6(&mut self, s: f64) -> flexmb_lie::Vec6 {
        let (a, b) = (self.v3(s), self.v3(s));
        flexmb_lie::join(&a, &b)
    }

    /// Node kinematics away from the identity, with velocities and accelerations.
    pub fn node(&mut self, group: flexmb_lie::Group) -> flexmb::elements::NodeState {
        flexmb::elements::NodeState {
            q: group.exp(&self.v6(1.5)),
            v: self.v6(2.0),
            vdot: self.v6(3.0),
            t: flexmb_lie::Mat6::identity(),
        }
    }
}

/// A worm (node "worm", 4 threads, pitch radius 20 mm) meshing with a wheel (node "wheel", 9
/// teeth, centre distance 32 mm: lead angle 14.9 deg) at a random place and orientation, the
/// nodes at the frames' origins; stiffness 1e8 N/m, damping 2e3 N s/m, friction 0.1 and a
/// thrust washer of radius 15 mm. For the derivative checks.
pub fn worm_pair(group: flexmb_lie::Group, rng: &mut Lcg, left_hand: bool) -> flexmb::model::Model {
    use flexmb_lie::Frame;
    let mut model = flexmb::model::Model::new(group);
    let axis = rng.v3(1.0).normalize();
    let across = axis.cross(&rng.v3(1.0)).normalize();
    let ca = rng.v3(0.5);
    let cb = ca + across * 0.032;
    let wheel_axis = axis.cross(&across);
    let a = model.add_node("worm", Frame::new(ca, group.exp(&rng.v6(1.0)).r));
    let b = model.add_node("wheel", Frame::new(cb, group.exp(&rng.v6(1.0)).r));
    // the centres given off the common perpendicular: the frames are at its feet
    let centers = [ca - axis * 0.01, cb + wheel_axis * 0.02];
    let g = model.add_worm_gear(
        "mesh",
        [Some(a), Some(b)],
        centers,
        [axis, -wheel_axis],
        (4, 9, 0.02),
        1e8,
    );
    let gear = &mut model.worm_gears[g];
    gear.damping = 2e3;
    gear.friction = 0.1;
    gear.washer_radius = 0.015;
    gear.left_hand = left_hand;
    model
}

/// A model with a block diagram that holds every kind of block, measurement and actuator
/// (for the derivative checks): nodes `a` and `b`, a revolute joint `hinge` between them
/// and a prismatic joint `slide` from the ground to `b`, frames turned off the axes.
pub fn control_diagram(group: flexmb_lie::Group) -> flexmb::model::Model {
    use flexmb::model::control::{Block, BlockKind, ControlSystem, Quantity, Signal, Target};
    use flexmb::model::{Joint, JointId, JointKind, Model, NodeId, TimeFunction};
    use flexmb_lie::Frame;
    let mut rng = Lcg(31);
    let mut m = Model::new(group);
    let a = m.add_node("a", Frame::identity());
    let b = m.add_node("b", Frame::identity());
    let joint = |name: &str, kind, node_a: Option<NodeId>, rng: &mut Lcg| Joint {
        name: name.into(),
        kind,
        node_a,
        node_b: Some(b),
        frame_a: flexmb_lie::Group::SE3.exp(&rng.v6(0.6)),
        frame_b: flexmb_lie::Group::SE3.exp(&rng.v6(0.6)),
        drive: None,
    };
    m.joints
        .push(joint("hinge", JointKind::Revolute, Some(a), &mut rng));
    m.joints
        .push(joint("slide", JointKind::Prismatic, None, &mut rng));
    let (hinge, slide) = (JointId(0), JointId(1));
    let s = |block: usize| Signal { block, output: 0 };
    let axis = |rng: &mut Lcg| rng.v3(1.0).normalize();
    let point = |rng: &mut Lcg| rng.v3(0.5);
    let block = |name: &str, kind: BlockKind, params: Vec<f64>, inputs: Vec<Signal>| Block {
        name: name.into(),
        kind,
        params,
        inputs,
    };
    let measure = |name: &str, q: Quantity| block(name, BlockKind::Measure(q), vec![], vec![]);
    let blocks = vec![
        block(
            "src",
            BlockKind::Source(TimeFunction::Sine {
                amplitude: 0.4,
                frequency: 1.3,
                phase: 0.2,
                offset: 0.1,
            }),
            vec![],
            vec![],
        ),
        measure(
            "pos",
            Quantity::Position {
                node: a,
                point: point(&mut rng),
                axis: axis(&mut rng),
            },
        ),
        measure(
            "vel",
            Quantity::Velocity {
                node: b,
                point: point(&mut rng),
                axis: axis(&mut rng),
            },
        ),
        measure(
            "acc",
            Quantity::Acceleration {
                node: a,
                point: point(&mut rng),
                axis: axis(&mut rng),
            },
        ),
        measure(
            "omega",
            Quantity::AngularVelocity {
                node: b,
                axis: axis(&mut rng),
            },
        ),
        measure("angle", Quantity::JointCoordinate { joint: hinge }),
        measure("rate", Quantity::JointRate { joint: hinge }),
        measure("slide", Quantity::JointCoordinate { joint: slide }),
        measure("slide_rate", Quantity::JointRate { joint: slide }),
        block(
            "sum",
            BlockKind::Sum {
                signs: vec![1.0, -1.0, 0.5],
            },
            vec![],
            vec![s(0), s(1), s(2)],
        ),
        block(
            "gain",
            BlockKind::Gain { rows: 2, cols: 2 },
            vec![1.5, -0.3, 0.7, 2.0],
            vec![s(3), s(4)],
        ),
        block(
            "product",
            BlockKind::Product { inputs: 2 },
            vec![],
            vec![s(5), s(6)],
        ),
        block(
            "integrator",
            BlockKind::Integrator,
            vec![1.7, 0.0],
            vec![s(9)],
        ),
        block("lag", BlockKind::Lag, vec![0.8, 0.3, 0.0], vec![s(10)]),
        block(
            "pid",
            BlockKind::Pid,
            vec![3.0, 2.0, 0.5, 0.05, -0.6, 0.4, 0.7],
            vec![s(7)],
        ),
        block(
            "ss",
            BlockKind::StateSpace {
                states: 2,
                inputs: 2,
                outputs: 1,
            },
            vec![
                -1.0, 0.5, -0.3, -2.0, 1.0, 0.2, 0.0, 0.7, 0.4, -0.9, 0.3, 0.1, 0.0, 0.0,
            ],
            vec![s(8), s(11)],
        ),
        block(
            "tf",
            BlockKind::TransferFunction { num: 2, den: 3 },
            vec![0.5, 2.0, 1.0, 0.8, 4.0],
            vec![Signal {
                block: 10,
                output: 1,
            }],
        ),
        block(
            "saturation",
            BlockKind::Saturation,
            vec![-0.35, 0.3],
            vec![s(12)],
        ),
        block(
            "dead_zone",
            BlockKind::DeadZone,
            vec![-0.2, 0.1],
            vec![s(13)],
        ),
        block(
            "rate_limiter",
            BlockKind::RateLimiter,
            vec![2.0, 1.5, 0.2],
            vec![s(14)],
        ),
        block(
            "lookup",
            BlockKind::Lookup {
                breakpoints: vec![-1.0, -0.2, 0.3, 1.0],
            },
            vec![0.5, -0.4, 0.9, 0.2],
            vec![s(16)],
        ),
        block(
            "hold",
            BlockKind::Hold { period: 0.01 },
            vec![],
            vec![s(18)],
        ),
        block(
            "motor",
            BlockKind::DcMotor,
            vec![1.2, 0.05, 0.3, 0.25],
            vec![s(17), s(6)],
        ),
        block(
            "force",
            BlockKind::Actuator(Target::Force {
                node: a,
                point: point(&mut rng),
                axis: axis(&mut rng),
                follower: false,
            }),
            vec![],
            vec![s(22)],
        ),
        block(
            "moment",
            BlockKind::Actuator(Target::Moment {
                node: b,
                axis: axis(&mut rng),
                follower: true,
            }),
            vec![],
            vec![s(15)],
        ),
        block(
            "torque",
            BlockKind::Actuator(Target::Joint { joint: hinge }),
            vec![],
            vec![s(19)],
        ),
        block(
            "push",
            BlockKind::Actuator(Target::Joint { joint: slide }),
            vec![],
            vec![s(20)],
        ),
        block(
            "follower",
            BlockKind::Actuator(Target::Force {
                node: b,
                point: point(&mut rng),
                axis: axis(&mut rng),
                follower: true,
            }),
            vec![],
            vec![s(21)],
        ),
        block(
            "servo",
            BlockKind::Servo {
                quantity: Quantity::JointCoordinate { joint: hinge },
                target: Target::Joint { joint: hinge },
                function: TimeFunction::Sine {
                    amplitude: 0.3,
                    frequency: 0.8,
                    phase: 0.0,
                    offset: 0.0,
                },
            },
            vec![0.5],
            vec![],
        ),
        // non-collocated: a force on node a prescribes the position of node b
        block(
            "servo_far",
            BlockKind::Servo {
                quantity: Quantity::Position {
                    node: b,
                    point: point(&mut rng),
                    axis: axis(&mut rng),
                },
                target: Target::Force {
                    node: a,
                    point: point(&mut rng),
                    axis: axis(&mut rng),
                    follower: false,
                },
                function: TimeFunction::Sine {
                    amplitude: 0.2,
                    frequency: 0.6,
                    phase: 0.4,
                    offset: 0.1,
                },
            },
            vec![-0.7],
            vec![],
        ),
    ];
    let mut blocks = blocks;
    // Reactions: the hinge's and the slide's constraint forces and a moment, fed back to
    // node a; on SE(3), a beam element between the nodes and one of its section forces.
    let n = blocks.len();
    let reaction = |joint: JointId, moment: bool, rng: &mut Lcg| Quantity::ConstraintForce {
        joint,
        axis: axis(rng),
        moment,
    };
    blocks.push(measure("reaction", reaction(hinge, false, &mut rng)));
    blocks.push(measure("reaction_moment", reaction(hinge, true, &mut rng)));
    blocks.push(measure("slide_force", reaction(slide, false, &mut rng)));
    // A contact always closed at the random configurations of the tests: a sphere of radius
    // 3 on b against the plane z = 0 of a (the nodes lie within about 1 of each other),
    // with bristle friction (three states besides the impact velocity).
    use flexmb::model::contact::{Bristles, Contact, ContactLaw, ContactShape, Dissipation};
    m.contacts.push(Contact {
        name: "touch".into(),
        node_a: Some(a),
        node_b: Some(b),
        shape_a: ContactShape::Plane {
            point: flexmb_lie::Vec3::zeros(),
            normal: flexmb_lie::Vec3::z(),
        },
        shape_b: ContactShape::Sphere {
            center: flexmb_lie::Vec3::zeros(),
            radius: 3.0,
            inside: false,
        },
        law: ContactLaw {
            dissipation: Dissipation::LankaraniNikravesh,
            // (soft: its force at the tests' deep penetrations stays of order 1, so that
            // the parameter test's differences keep their digits)
            stiffness: 0.05,
            exponent: 1.5,
            restitution: 0.7,
            min_impact_velocity: 1e-3,
        },
        friction: Some(flexmb::model::contact::Friction {
            coefficient: 0.4,
            stiction_velocity: 0.3,
            viscous: 0.2,
            bristles: Some(Bristles {
                stiffness: 300.0,
                damping: 2.0,
                static_coefficient: 0.6,
            }),
        }),
    });
    blocks.push(measure(
        "contact_force",
        Quantity::ContactForce {
            contact: 0,
            axis: axis(&mut rng),
        },
    ));
    let mut fed = vec![s(n), s(n + 1), s(n + 2), s(n + 3)];
    if group == flexmb_lie::Group::SE3 {
        // (soft: the random configurations strain it far, and the differences of the
        // parameter test divide its residual by their step)
        let mut c =
            flexmb_lie::Mat6::from_diagonal(&flexmb_lie::Vec6::new(10.0, 4.0, 5.0, 0.3, 0.4, 0.6));
        c[(0, 4)] = 0.15;
        c[(4, 0)] = 0.15;
        let section = flexmb::model::BeamSection {
            stiffness: c,
            mass_per_length: 2.0,
            rotary_inertia: flexmb_lie::Mat3::identity() * 0.1,
            // (nonzero: the beam applies damping only when it is positive, so a central
            // difference about 0 would see half of it)
            damping_mass: 0.7,
            damping_stiffness: 0.03,
        };
        m.beams.push(flexmb::model::Beam::new(
            "link",
            [a, b],
            section,
            [flexmb_lie::Mat3::identity(); 2],
            flexmb_lie::Vec6::new(1.3, 0.0, 0.0, 0.1, 0.2, 0.5),
            flexmb::model::BeamMass::Lumped,
        ));
        blocks.push(measure(
            "bending",
            Quantity::SectionForce {
                beam: 0,
                component: 4,
            },
        ));
        fed.push(s(n + 4));
    }
    let k = fed.len();
    blocks.push(block(
        "reactions",
        BlockKind::Sum {
            signs: vec![0.01; k],
        },
        vec![],
        fed,
    ));
    blocks.push(block(
        "reaction_push",
        BlockKind::Actuator(Target::Force {
            node: a,
            point: point(&mut rng),
            axis: axis(&mut rng),
            follower: false,
        }),
        vec![],
        vec![s(blocks.len() - 1)],
    ));
    m.control = ControlSystem::new(blocks);
    m
}
