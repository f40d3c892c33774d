//! Static large-rotation beam problems against analytic and published references, built
//! with the Rust API and run from the example model files.

use crate::common;

use flexmb::model::{BeamSection, Load, LoadFrame, Model, TimeFunction};
use flexmb::solve::{StaticSettings, Statics};
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use std::f64::consts::PI;

/// Straight cantilever along x of length `l` with `n` elements, clamped at the origin.
fn cantilever(l: f64, n: usize, section: &BeamSection) -> (Model, flexmb::model::NodeId) {
    let mut m = Model::new(Group::SE3);
    let root = m.add_node("root", Frame::identity());
    let ids = m.add_straight_beam(
        "beam",
        root,
        Vec3::new(l, 0.0, 0.0),
        None,
        n,
        &Vec3::z(),
        section,
    );
    m.add_joint(
        "clamp",
        flexmb::model::JointKind::Fixed,
        None,
        Some(root),
        Vec3::zeros(),
        Mat3::identity(),
        None,
    );
    (m, *ids.last().expect("tip"))
}

/// Roll-up of a cantilever by an end moment M = 2 pi EI / L (Simo & Vu-Quoc 1986; exact
/// solution: a circle of radius EI/M, benchmarks.md Sect. 4.1). The two-node SE(3) element
/// represents constant curvature exactly, so the discrete solution is exact for any mesh.
#[test]
fn cantilever_rolls_up_into_a_full_circle() {
    let (l, ei) = (1.0, 2.0);
    let section = BeamSection::diagonal([1e4, 1e4, 1e4, 2.0, ei, ei], 1.0, [0.1, 0.05, 0.05]);
    let (mut model, tip) = cantilever(l, 10, &section);
    let m = 2.0 * PI * ei / l;
    model.loads.push(Load {
        name: "moment".into(),
        node: tip,
        force: Vec3::zeros(),
        torque: Vec3::new(0.0, -m, 0.0),
        frame: LoadFrame::Body,
        function: TimeFunction::Constant { value: 1.0 },
        input: None,
    });
    let mut settings = StaticSettings::new();
    settings.initial_increment = 0.25;
    let mut statics = Statics::new(&model, settings).expect("starts");
    let mut checked = 0;
    statics
        .run(&mut |s: &flexmb::observe::Sample| {
            let lam = s.at;
            let x = s.state.q[tip.0].x;
            let (ex, ez) = if lam == 0.0 {
                (l, 0.0)
            } else {
                let rho = l / (2.0 * PI * lam);
                (
                    rho * (2.0 * PI * lam).sin(),
                    rho * (1.0 - (2.0 * PI * lam).cos()),
                )
            };
            assert!(
                (x.x - ex).abs() < 1e-8 && (x.z - ez).abs() < 1e-8 && x.y.abs() < 1e-10,
                "lambda {lam}: tip {x:?} vs ({ex}, {ez})"
            );
            checked += 1;
            Ok(())
        })
        .expect("converges");
    assert!((statics.load_factor - 1.0).abs() < 1e-12);
    let tip_q = statics.state.q[tip.0];
    assert!(tip_q.x.norm() < 1e-8, "tip back at the root: {:?}", tip_q.x);
    assert!(
        (tip_q.r - Mat3::identity()).norm() < 1e-8,
        "tip rotation 2 pi"
    );
    assert!(checked >= 5);
    println!(
        "roll-up: {} steps, {} Newton iterations",
        statics.stats.steps, statics.stats.newton_iterations
    );
}

/// 45 degree bend (Bathe & Bolourchi 1979): arc of radius 100 in the x-y plane, tip force
/// in z. Continuum reference (variant A: EA = 1e7, EI = 833 333, GJ = 833 333, GA = 5e6),
/// benchmarks.md Sect. 4.2: tip at P = 600 (47.1504, 15.6848, 53.4749).
#[test]
fn bathe_bolourchi_bend_matches_continuum_reference() {
    let section = BeamSection::diagonal(
        [1e7, 5e6, 5e6, 833_333.0, 833_333.0, 833_333.0],
        1.0,
        [1.0, 0.5, 0.5],
    );
    let (r, n) = (100.0, 32);
    let mut m = Model::new(Group::SE3);
    let frame = |phi: f64| {
        let x = Vec3::new(phi.cos(), phi.sin(), 0.0);
        let z = Vec3::z();
        Mat3::from_columns(&[x, z.cross(&x), z])
    };
    let point = |phi: f64| Vec3::new(r * phi.sin(), r * (1.0 - phi.cos()), 0.0);
    let mut ids = vec![];
    for i in 0..=n {
        let phi = PI / 4.0 * i as f64 / n as f64;
        ids.push(m.add_node(&format!("n{i}"), Frame::new(point(phi), frame(phi))));
    }
    for i in 0..n {
        let (p0, p1) = (
            PI / 4.0 * i as f64 / n as f64,
            PI / 4.0 * (i + 1) as f64 / n as f64,
        );
        m.add_beam(
            &format!("e{i}"),
            [ids[i], ids[i + 1]],
            section.clone(),
            [frame(p0), frame(p1)],
        );
    }
    m.add_joint(
        "clamp",
        flexmb::model::JointKind::Fixed,
        None,
        Some(ids[0]),
        Vec3::zeros(),
        Mat3::identity(),
        None,
    );
    let tip = ids[n];
    m.loads.push(Load {
        name: "p".into(),
        node: tip,
        force: Vec3::new(0.0, 0.0, 600.0),
        torque: Vec3::zeros(),
        frame: LoadFrame::Inertial,
        function: TimeFunction::Constant { value: 1.0 },
        input: None,
    });
    let mut settings = StaticSettings::new();
    settings.initial_increment = 0.1;
    let mut statics = Statics::new(&m, settings).expect("starts");
    let mut at = vec![];
    statics
        .run(&mut |s: &flexmb::observe::Sample| {
            at.push((s.at, s.state.q[tip.0].x));
            Ok(())
        })
        .expect("converges");
    let x = statics.state.q[tip.0].x;
    let reference = Vec3::new(47.1504, 15.6848, 53.4749);
    println!("bend: tip {x:?}, error {:.3e}", (x - reference).norm());
    assert!((x - reference).norm() < 0.05, "tip {x:?} vs {reference:?}");
}

/// Von Mises truss (two inclined springs meeting at an apex that slides vertically) under a
/// vertical dead load: the exact equilibrium path lambda P = 2 k (L0 - L) y / L has a limit
/// point and snaps through; arc-length continuation must follow it past the limit point
/// (Crisfield 1981, Comput. Struct. 13, Sect. 5: the shallow truss).
#[test]
fn arc_length_follows_the_von_mises_truss_through_its_limit_points() {
    use flexmb::model::SpringDamper;
    use flexmb::solve::StaticMethod;
    let (b, h0, k): (f64, f64, f64) = (1.0, 0.2, 1000.0);
    let l0 = (b * b + h0 * h0).sqrt();
    let mut m = Model::new(Group::SE3);
    let apex = m.add_node(
        "apex",
        Frame::new(Vec3::new(0.0, h0, 0.0), Mat3::identity()),
    );
    // The apex slides along y: a prismatic joint whose axis (joint z) is the global y axis.
    let slide = Mat3::from_columns(&[Vec3::z(), Vec3::x(), Vec3::y()]);
    m.add_joint(
        "slide",
        flexmb::model::JointKind::Prismatic,
        None,
        Some(apex),
        Vec3::new(0.0, h0, 0.0),
        slide,
        None,
    );
    for (name, x) in [("left", -b), ("right", b)] {
        m.springs.push(SpringDamper {
            name: name.into(),
            node_a: None,
            node_b: Some(apex),
            point_a: Vec3::new(x, 0.0, 0.0),
            point_b: Vec3::zeros(),
            stiffness: k,
            damping: 0.0,
            rest_length: l0,
            relaxation: None,
        });
    }
    m.loads.push(Load {
        name: "p".into(),
        node: apex,
        force: Vec3::new(0.0, -1.0, 0.0),
        torque: Vec3::zeros(),
        frame: LoadFrame::Inertial,
        function: TimeFunction::Constant { value: 1.0 },
        input: None,
    });
    let mut settings = StaticSettings::new();
    settings.method = StaticMethod::ArcLength;
    settings.arc_length = 0.01;
    settings.load_factor = 10.0;
    let mut statics = Statics::new(&m, settings).expect("starts");
    let mut path = vec![];
    statics
        .run(&mut |s: &flexmb::observe::Sample| {
            let y = s.state.q[apex.0].x.y;
            let l = (b * b + y * y).sqrt();
            let exact = 2.0 * k * (l0 - l) * y / l;
            assert!(
                (s.at - exact).abs() < 1e-6 * (1.0 + exact.abs()),
                "y {y}: lambda {} vs {exact}",
                s.at
            );
            path.push((y, s.at));
            Ok(())
        })
        .expect("follows the path");
    // Largest load factor before the path turns back, smallest one after it.
    let turn = path
        .windows(2)
        .position(|w| w[1].1 < w[0].1)
        .expect("the path turns back");
    let lmax = path[..=turn].iter().fold(f64::MIN, |m, p| m.max(p.1));
    let lmin = path[turn..].iter().fold(f64::MAX, |m, p| m.min(p.1));
    // Limit loads of the exact path: max of 2 k (L0 - L) y / L over 0 < y < h0 and its mirror.
    let exact_max = (1..10_000)
        .map(|i| {
            let y = h0 * i as f64 / 10_000.0;
            let l = (b * b + y * y).sqrt();
            2.0 * k * (l0 - l) * y / l
        })
        .fold(f64::MIN, f64::max);
    // The converged points sample the path (steps of at most 4 x 0.01 in y): the largest and
    // smallest sampled loads are within a few percent of the limit loads.
    assert!(
        lmax > 0.95 * exact_max && lmax <= exact_max * (1.0 + 1e-9),
        "upper limit point: {lmax} (exact {exact_max})"
    );
    assert!(
        lmin < -0.95 * exact_max && lmin >= -exact_max * (1.0 + 1e-9),
        "lower limit point: {lmin} (exact {})",
        -exact_max
    );
    assert!(
        statics.load_factor >= 10.0 - 1e-9,
        "reached the final load factor: {}",
        statics.load_factor
    );
    assert!(
        path.last().unwrap().0 < -h0,
        "snapped through: y = {}",
        path.last().unwrap().0
    );
    println!(
        "von Mises truss: {} steps, limit loads {lmin:.4} / {lmax:.4} (exact +-{exact_max:.4})",
        path.len()
    );
}

#[test]
fn roll_up_example_follows_the_exact_circle_at_every_load_step() {
    let run = common::run_static("roll_up.toml", &[]);
    assert!(run.rows.len() >= 5);
    for (lam, _) in &run.rows {
        let (x, z) = (run.at("tip_x", *lam), run.at("tip_z", *lam));
        let (ex, ez) = if *lam == 0.0 {
            (1.0, 0.0)
        } else {
            let rho = 1.0 / (2.0 * PI * lam);
            (
                rho * (2.0 * PI * lam).sin(),
                rho * (1.0 - (2.0 * PI * lam).cos()),
            )
        };
        assert!(
            (x - ex).abs() < 1e-8 && (z - ez).abs() < 1e-8,
            "lambda {lam}: ({x}, {z}) vs ({ex}, {ez})"
        );
        // Constant bending moment M = 2 pi EI lambda / L along the beam.
        let m = run.at("root_moment", *lam);
        assert!((m.abs() - 2.0 * PI * 2.0 * lam).abs() < 1e-6, "moment {m}");
    }
    assert!((run.rows.last().unwrap().0 - 1.0).abs() < 1e-12);
}

#[test]
fn bend_example_matches_the_continuum_reference_at_the_published_loads() {
    // Uniform steps of 50 so that the published load levels are output steps.
    let run = common::run_static("bend_45.toml", &["solver.max_increment=50.0"]);
    let reference = [
        (300.0, [58.7791, 22.2448, 40.1919]),
        (450.0, [52.2386, 18.5082, 48.5029]),
        (600.0, [47.1504, 15.6848, 53.4749]),
    ];
    for (p, r) in reference {
        let x = [run.at("tip_x", p), run.at("tip_y", p), run.at("tip_z", p)];
        let err = (0..3).map(|k| (x[k] - r[k]).powi(2)).sum::<f64>().sqrt();
        // 32 two-node elements: O(h^2) mesh error of about 0.01 (0.02 % of the tip motion).
        assert!(err < 0.03, "P = {p}: tip {x:?} vs {r:?} (error {err})");
    }
}

#[test]
fn bend_converges_under_mesh_refinement() {
    let errs: Vec<f64> = [8, 16, 32]
        .iter()
        .map(|n| {
            let run = common::run_static(
                "bend_45.toml",
                &[
                    &format!("beam.arc.elements={n}"),
                    &format!("load.tip_force.node=\"arc.{n}\""),
                    &format!("sensor.tip_x.node=\"arc.{n}\""),
                    &format!("sensor.tip_y.node=\"arc.{n}\""),
                    &format!("sensor.tip_z.node=\"arc.{n}\""),
                ],
            );
            let r = [47.1504, 15.6848, 53.4749];
            let x = [run.last("tip_x"), run.last("tip_y"), run.last("tip_z")];
            (0..3).map(|k| (x[k] - r[k]).powi(2)).sum::<f64>().sqrt()
        })
        .collect();
    println!("bend errors for 8, 16, 32 elements: {errs:?}");
    let p = common::order(&[8.0f64.recip(), 16.0f64.recip(), 32.0f64.recip()], &errs);
    assert!(p > 1.7, "mesh convergence order {p} ({errs:?})");
}

/// Extremum of `p(u)` near sample `k`: vertex of the parabola through samples k-1, k, k+1.
fn vertex(samples: &[(f64, f64)], k: usize) -> f64 {
    let ((x0, y0), (x1, y1), (x2, y2)) = (samples[k - 1], samples[k], samples[k + 1]);
    let d = (x0 - x1) * (x0 - x2) * (x1 - x2);
    let a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / d;
    let b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / d;
    let c = (x1 * x2 * (x1 - x2) * y0 + x2 * x0 * (x2 - x0) * y1 + x0 * x1 * (x0 - x1) * y2) / d;
    c - b * b / (4.0 * a)
}

/// Lee's frame followed by arc-length continuation through its snap-back, against the
/// independent reference of tests/reference/lee_frame_reference.* (shooting solution of
/// the extensible elastica, 10 digits): first limit load 18.5567 kN (literature: about
/// 18.5 kN), lowest load on the path -9.4144 kN. Mesh convergence from 12 cm to 6 cm elements.
#[test]
fn lee_frame_limit_loads_converge_to_the_reference() {
    let limits = |n: usize| {
        let (c, l, r) = (10 * n, 2 * n, 8 * n);
        let run = common::run_static(
            "lee_frame.toml",
            &[
                &format!("beam.column.elements={c}"),
                &format!("beam.beam_left.elements={l}"),
                &format!("beam.beam_right.elements={r}"),
                &format!("beam.beam_left.start_node=\"column.{c}\""),
                &format!("beam.beam_right.start_node=\"beam_left.{l}\""),
                &format!("joint.B.node_b=\"beam_right.{r}\""),
                &format!("load.P.node=\"beam_left.{l}\""),
                &format!("sensor.x.node=\"beam_left.{l}\""),
                &format!("sensor.y.node=\"beam_left.{l}\""),
                "solver.arc_length=1.0",
            ],
        );
        let path: Vec<(f64, f64)> = run
            .rows
            .iter()
            .map(|(p, v)| (v[run.column("x")] - 24.0, *p))
            .collect();
        let k_max = (1..path.len() - 1)
            .find(|&k| path[k].1 >= path[k - 1].1 && path[k].1 > path[k + 1].1)
            .expect("a maximum");
        let k_min = (k_max + 1..path.len() - 1)
            .find(|&k| path[k].1 <= path[k - 1].1 && path[k].1 < path[k + 1].1)
            .expect("a minimum");
        (vertex(&path, k_max), vertex(&path, k_min))
    };
    let (max1, min1) = limits(1);
    let (max2, min2) = limits(2);
    println!(
        "Lee frame limit loads: 12 cm elements {max1:.4} / {min1:.4}, 6 cm {max2:.4} / {min2:.4}"
    );
    let (ref_max, ref_min) = (18.5567, -9.4144);
    assert!(
        (max2 - ref_max).abs() < 0.005 * ref_max,
        "limit load {max2}"
    );
    assert!(
        (min2 - ref_min).abs() < 0.01 * ref_min.abs(),
        "lowest load {min2}"
    );
    // Mesh refinement moves both towards the reference at second order (4 times closer), so
    // Richardson extrapolation lands on it.
    assert!((max2 - ref_max).abs() < 0.3 * (max1 - ref_max).abs());
    assert!((min2 - ref_min).abs() < 0.3 * (min1 - ref_min).abs());
    let (rich_max, rich_min) = (max2 + (max2 - max1) / 3.0, min2 + (min2 - min1) / 3.0);
    assert!(
        (rich_max - ref_max).abs() < 5e-4 * ref_max,
        "extrapolated limit load {rich_max}"
    );
    assert!(
        (rich_min - ref_min).abs() < 1e-3 * ref_min.abs(),
        "extrapolated lowest load {rich_min}"
    );
}

/// examples/lee_frame.toml does what its header promises: arc-length continuation follows
/// the path through the snap-through and the snap-back (the lowest load, about -9.4 kN,
/// tests/reference/lee_frame_reference.md) and on up to the final load of 40 kN, within its
/// `max_steps` (an analysis that takes them all stops short with `SolveError::Incomplete`,
/// which `run_static` reports).
#[test]
fn lee_frame_example_follows_the_path_to_the_load_its_header_promises() {
    let run = common::run_static("lee_frame.toml", &[]);
    let loads: Vec<f64> = run.rows.iter().map(|(p, _)| *p).collect();
    assert_eq!(loads[loads.len() - 1], 40.0, "the final load factor");
    let lowest = loads.iter().fold(f64::INFINITY, |m, &p| m.min(p));
    assert!(
        lowest < -9.0,
        "the snap-back is passed: lowest load {lowest}"
    );
    println!("Lee frame example: {} load steps", run.stats.steps);
}

/// A uniformly distributed load on a cantilever, lumped to the nodes, against the linear
/// Timoshenko solution w = q L^4 / (8 EI) + q L^2 / (2 GA) (small load: the geometrically
/// exact beam reduces to it). The constant-strain two-node element with nodal loads is
/// nodally exact for this problem at any mesh (the residual difference, about 1e-8, is the
/// geometric nonlinearity of the exact beam at w / L = 1e-4).
#[test]
fn distributed_load_on_a_cantilever_matches_beam_theory() {
    let (l, ei, ga, q) = (2.0f64, 1e4, 1e7, 1.0);
    let exact = q * l.powi(4) / (8.0 * ei) + q * l * l / (2.0 * ga);
    let mut errors = vec![];
    for n in [4, 8, 16] {
        let section = BeamSection::diagonal([1e8, ga, ga, 1e4, ei, ei], 1.0, [0.1, 0.05, 0.05]);
        let (mut model, tip) = cantilever(l, n, &section);
        let elements: Vec<usize> = (0..model.beams.len()).collect();
        let added = model.add_beam_load(
            "q",
            &elements,
            Vec3::new(0.0, 0.0, -q),
            Vec3::zeros(),
            LoadFrame::Inertial,
            TimeFunction::Constant { value: 1.0 },
        );
        assert_eq!(added, n + 1);
        let total: f64 = model.loads.iter().map(|l| l.force.z).sum();
        assert!((total + q * l).abs() < 1e-12, "total load {total}");
        let mut statics = Statics::new(&model, StaticSettings::new()).expect("starts");
        statics
            .run(&mut |_: &flexmb::observe::Sample| Ok(()))
            .expect("converges");
        let w = -statics.state.q[tip.0].x.z;
        errors.push(((w - exact) / exact).abs());
    }
    println!("distributed load: relative tip errors {errors:?}");
    assert!(errors.iter().all(|e| *e < 1e-6), "{errors:?}");
}

/// The pseudo-dynamic method (damped dynamic run with the load ramped) settles on the same
/// static state as load control: the 45-degree bend at P = 600, with critical damping of the
/// first mode (omega_1 about 0.5 rad/s, so alpha = 1/s) and a 30 s ramp.
#[test]
fn pseudo_dynamic_settles_on_the_static_solution() {
    let control = common::run_static("bend_45.toml", &[]);
    let relaxed = common::run_static(
        "bend_45.toml",
        &[
            "solver.method=\"pseudo_dynamic\"",
            "solver.pseudo_time=30.0",
            "solver.pseudo_damping=1.0",
            "solver.increment=0.01",
        ],
    );
    assert!(relaxed.warnings.is_empty(), "{:?}", relaxed.warnings);
    assert!((relaxed.rows.last().unwrap().0 - 600.0).abs() < 1e-9);
    for c in ["tip_x", "tip_y", "tip_z"] {
        assert!(
            (relaxed.last(c) - control.last(c)).abs() < 1e-5,
            "{c}: {} vs {}",
            relaxed.last(c),
            control.last(c)
        );
    }
}

#[test]
fn arc_length_follows_a_non_proportional_load() {
    // The bend with the tip force growing as lambda f(lambda), f(lambda) = (1 + lambda /
    // 600) / 2 (docs/model-format.md, time functions in statics): arc length must reach the
    // same equilibrium at lambda = 600 as load control. (Its load derivative used to be
    // f(1) F, which made it crawl at lambda < 1.) The cylindrical arc length cannot start
    // where the load derivative vanishes (f(lambda) = lambda / 600, a load growing as
    // lambda^2, was used here: it passed or failed with the rounding of the linear solver).
    let table =
        r#"load.tip_force.function={ type = "table", points = [[0.0, 0.5], [600.0, 1.0]] }"#;
    let control = common::run_static("bend_45.toml", &[table]);
    let arc = common::run_static("bend_45.toml", &[table, "solver.method=arc_length"]);
    assert!((arc.rows.last().unwrap().0 - 600.0).abs() < 1e-9);
    for sensor in ["tip_x", "tip_y", "tip_z"] {
        let (a, b) = (arc.last(sensor), control.last(sensor));
        assert!((a - b).abs() < 1e-8, "{sensor}: {a} against {b}");
    }
}
