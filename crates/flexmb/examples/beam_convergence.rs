//! Mesh and step convergence of the beam benchmarks against their references: the tables of
//! BENCHMARKS.md, section "Beam benchmarks: convergence".
//!
//! Run with `cargo run --release -p flexmb --example beam_convergence` (about 20 s).
//! Every case runs an example model file of `examples/` with `--set` style overrides.

use flexmb::input::{read_model_file, Analysis};
use flexmb::sensors::SensorEvaluator;
use flexmb::solve::Statics;
use flexmb::Simulation;
use std::f64::consts::PI;
use std::path::PathBuf;
use std::time::Instant;

/// Sensor histories `(t or load factor, values)` of one run, with its Newton iterations.
struct Run {
    names: Vec<String>,
    rows: Vec<(f64, Vec<f64>)>,
    iterations: usize,
    steps: usize,
    seconds: f64,
    /// Spectral radius at infinity of a dynamic run.
    rho_inf: Option<f64>,
}

impl Run {
    fn series(&self, name: &str) -> Vec<(f64, f64)> {
        let c = self
            .names
            .iter()
            .position(|n| n == name)
            .unwrap_or_else(|| panic!("no sensor {name}"));
        self.rows.iter().map(|(t, v)| (*t, v[c])).collect()
    }

    fn last(&self, name: &str) -> f64 {
        self.series(name).last().expect("rows").1
    }
}

fn run(example: &str, overrides: &[String]) -> Run {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(example);
    let file = read_model_file(&path, overrides).unwrap_or_else(|e| panic!("{e}"));
    let model = &file.model;
    let mut sensors = SensorEvaluator::new(model);
    let mut rows = Vec::new();
    let start = Instant::now();
    let mut rho_inf = None;
    let (iterations, steps) = match file.analysis {
        Analysis::Dynamic(settings) => {
            rho_inf = Some(settings.rho_inf);
            let mut sim = Simulation::new(model, settings).unwrap_or_else(|e| panic!("{e}"));
            let stats = sim
                .run(&mut |s: &flexmb::observe::Sample| {
                    rows.push((s.state.t, sensors.evaluate(s.model, s.data, s.state)));
                    Ok(())
                })
                .unwrap_or_else(|e| panic!("{example} {overrides:?}: {e}"));
            (stats.newton_iterations, stats.steps)
        }
        Analysis::Static(settings) => {
            let mut statics = Statics::new(model, settings).unwrap_or_else(|e| panic!("{e}"));
            let stats = statics
                .run(&mut |s: &flexmb::observe::Sample| {
                    rows.push((s.at, sensors.evaluate(s.model, s.data, s.state)));
                    Ok(())
                })
                .unwrap_or_else(|e| panic!("{example} {overrides:?}: {e}"));
            (stats.newton_iterations, stats.steps)
        }
    };
    Run {
        names: SensorEvaluator::names(model),
        rows,
        iterations,
        steps,
        seconds: start.elapsed().as_secs_f64(),
        rho_inf,
    }
}

fn set(items: &[String]) -> Vec<String> {
    items.to_vec()
}

/// Log2 of successive error ratios: the observed order for a refinement by 2.
fn orders(errors: &[f64]) -> Vec<String> {
    std::iter::once("".to_string())
        .chain(
            errors
                .windows(2)
                .map(|w| format!("{:.2}", (w[0] / w[1]).log2())),
        )
        .collect()
}

fn roll_up() {
    println!("### Roll-up (analytic: tip on the circle of radius L / (2 pi lambda))\n");
    println!("| elements | load steps | Newton it. | max tip error over the load steps [m] |");
    println!("|---|---|---|---|");
    for n in [3, 5, 10, 20] {
        let tip = format!("\"beam.{n}\"");
        let r = run(
            "roll_up.toml",
            &set(&[
                format!("beam.beam.elements={n}"),
                format!("load.moment.node={tip}"),
                format!("sensor.tip_x.node={tip}"),
                format!("sensor.tip_y.node={tip}"),
                format!("sensor.tip_z.node={tip}"),
            ]),
        );
        let (x, z) = (r.series("tip_x"), r.series("tip_z"));
        let err = x
            .iter()
            .zip(&z)
            .map(|((lam, x), (_, z))| {
                let (ex, ez) = if *lam == 0.0 {
                    (1.0, 0.0)
                } else {
                    let rho = 1.0 / (2.0 * PI * lam);
                    (
                        rho * (2.0 * PI * lam).sin(),
                        rho * (1.0 - (2.0 * PI * lam).cos()),
                    )
                };
                (x - ex).hypot(z - ez)
            })
            .fold(0.0f64, f64::max);
        println!("| {n} | {} | {} | {err:.1e} |", r.steps, r.iterations);
    }
    println!();
}

fn bend() {
    println!("### 45-degree bend (Bathe & Bolourchi 1979), tip at P = 600 against the continuum (47.1504, 15.6848, 53.4749)\n");
    println!("| elements | tip x | tip y | tip z | error [m] | order |");
    println!("|---|---|---|---|---|---|");
    let reference = [47.1504, 15.6848, 53.4749];
    let mut rows = vec![];
    for n in [8, 16, 32, 64] {
        let tip = format!("\"arc.{n}\"");
        let r = run(
            "bend_45.toml",
            &set(&[
                format!("beam.arc.elements={n}"),
                format!("load.tip_force.node={tip}"),
                format!("sensor.tip_x.node={tip}"),
                format!("sensor.tip_y.node={tip}"),
                format!("sensor.tip_z.node={tip}"),
            ]),
        );
        let x = [r.last("tip_x"), r.last("tip_y"), r.last("tip_z")];
        let err = (0..3)
            .map(|k| (x[k] - reference[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        rows.push((n, x, err));
    }
    let ord = orders(&rows.iter().map(|r| r.2).collect::<Vec<_>>());
    for ((n, x, err), o) in rows.iter().zip(ord) {
        println!(
            "| {n} | {:.4} | {:.4} | {:.4} | {err:.4} | {o} |",
            x[0], x[1], x[2]
        );
    }
    println!();
}

/// Extremum of the parabola through three samples around `k`.
fn vertex(s: &[(f64, f64)], k: usize) -> f64 {
    let ((x0, y0), (x1, y1), (x2, y2)) = (s[k - 1], s[k], s[k + 1]);
    let d = (x0 - x1) * (x0 - x2) * (x1 - x2);
    let a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / d;
    let b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / d;
    let c = (x1 * x2 * (x1 - x2) * y0 + x2 * x0 * (x2 - x0) * y1 + x0 * x1 * (x0 - x1) * y2) / d;
    c - b * b / (4.0 * a)
}

fn lee() {
    println!("### Lee's frame, limit loads by arc length against tests/reference/lee_frame_reference (18.5567 / -9.4144 kN)\n");
    println!("| element length [cm] | elements | arc-length steps | first limit load [kN] | error | lowest load [kN] | error |");
    println!("|---|---|---|---|---|---|---|");
    for n in [1, 2, 4] {
        let (c, l, r) = (10 * n, 2 * n, 8 * n);
        let run = run(
            "lee_frame.toml",
            &set(&[
                format!("beam.column.elements={c}"),
                format!("beam.beam_left.elements={l}"),
                format!("beam.beam_right.elements={r}"),
                format!("beam.beam_left.start_node=\"column.{c}\""),
                format!("beam.beam_right.start_node=\"beam_left.{l}\""),
                format!("joint.B.node_b=\"beam_right.{r}\""),
                format!("load.P.node=\"beam_left.{l}\""),
                format!("sensor.x.node=\"beam_left.{l}\""),
                format!("sensor.y.node=\"beam_left.{l}\""),
                "solver.arc_length=1.0".to_string(),
            ]),
        );
        let path: Vec<(f64, f64)> = run
            .series("x")
            .iter()
            .map(|(p, x)| (x - 24.0, *p))
            .collect();
        let k_max = (1..path.len() - 1)
            .find(|&k| path[k].1 >= path[k - 1].1 && path[k].1 > path[k + 1].1)
            .expect("a maximum");
        let k_min = (k_max + 1..path.len() - 1)
            .find(|&k| path[k].1 <= path[k - 1].1 && path[k].1 < path[k + 1].1)
            .expect("a minimum");
        let (max, min) = (vertex(&path, k_max), vertex(&path, k_min));
        println!(
            "| {:.0} | {} | {} | {max:.4} | {:+.2e} | {min:.4} | {:+.2e} |",
            12.0 / n as f64,
            c + l + r,
            run.steps,
            max - 18.5567,
            min + 9.4144
        );
    }
    println!();
}

fn right_angle() {
    println!("### Right-angle cantilever (Simo & Vu-Quoc 1988), peaks of the out-of-plane displacement\n");
    println!("Reference (digitized, benchmarks.md Sect. 2.2): elbow max 5.50 at 3.0 s; tip max 8.06-8.29 at 7.7-7.8 s; tip min -9.62..-9.67 at 16.0-16.2 s.\n");
    println!("| elements per leg | h [s] | rho_inf | elbow max (t) | tip max (t) | tip min (t) | Newton it./step |");
    println!("|---|---|---|---|---|---|---|");
    for (n, h) in [
        (5, 0.125),
        (10, 0.125),
        (20, 0.125),
        (10, 0.25),
        (10, 0.0625),
        (20, 0.03125),
    ] {
        let r = run(
            "right_angle_cantilever.toml",
            &set(&[
                format!("beam.leg1.elements={n}"),
                format!("beam.leg2.elements={n}"),
                format!("beam.leg2.start_node=\"leg1.{n}\""),
                format!("load.impulse.node=\"leg1.{n}\""),
                format!("sensor.elbow_w.node=\"leg1.{n}\""),
                format!("sensor.tip_w.node=\"leg2.{n}\""),
                format!("solver.h={h}"),
            ]),
        );
        let extremum = |name: &str, t0: f64, t1: f64, max: bool| {
            r.series(name)
                .into_iter()
                .filter(|(t, _)| *t >= t0 && *t <= t1)
                .fold((0.0, if max { f64::MIN } else { f64::MAX }), |a, (t, v)| {
                    if (max && v > a.1) || (!max && v < a.1) {
                        (t, v)
                    } else {
                        a
                    }
                })
        };
        let (e, tmax, tmin) = (
            extremum("elbow_w", 0.0, 6.0, true),
            extremum("tip_w", 5.0, 10.0, true),
            extremum("tip_w", 12.0, 19.0, false),
        );
        println!(
            "| {n} | {h} | {} | {:.3} ({:.2}) | {:.3} ({:.2}) | {:.3} ({:.2}) | {:.2} |",
            r.rho_inf.expect("dynamic"),
            e.1,
            e.0,
            tmax.1,
            tmax.0,
            tmin.1,
            tmin.0,
            r.iterations as f64 / r.steps as f64
        );
    }
    println!();
}

fn spin_up() {
    println!("### Spin-up (Simo & Vu-Quoc 1986), transverse tip deflection in the hub frame\n");
    println!("Reference (benchmarks.md Sect. 5.3): min u2 = -0.5738 m at 6.75 s.\n");
    println!("| elements | h [s] | min u2 [m] | t [s] | error [m] |");
    println!("|---|---|---|---|---|");
    for (n, h) in [
        (5, 0.01),
        (10, 0.01),
        (20, 0.01),
        (40, 0.01),
        (10, 0.02),
        (10, 0.005),
    ] {
        let tip = format!("\"arm.{n}\"");
        let r = run(
            "spin_up.toml",
            &set(&[
                format!("beam.arm.elements={n}"),
                format!("sensor.tip_x.node={tip}"),
                format!("sensor.tip_y.node={tip}"),
                format!("solver.h={h}"),
                "solver.t_end=10.0".to_string(),
            ]),
        );
        let (psi, x, y) = (r.series("psi"), r.series("tip_x"), r.series("tip_y"));
        let (t, u2) = psi
            .iter()
            .zip(&x)
            .zip(&y)
            .map(|(((t, psi), (_, x)), (_, y))| (*t, -x * psi.sin() + y * psi.cos()))
            .fold((0.0, f64::MAX), |m, r| if r.1 < m.1 { r } else { m });
        println!("| {n} | {h} | {u2:.5} | {t:.2} | {:+.2e} |", u2 + 0.5738);
    }
    println!();
}

fn four_bar() {
    println!("### Flexible four-bar (Bauchau), no published numbers: step convergence and energy balance, 0-3 s\n");
    println!("| h [s] | coupler mid z at 3 s [m] | difference to h / 2 | work - energy [J] | energy [J] |");
    println!("|---|---|---|---|---|");
    let omega = |t: f64| {
        if t < 1.0 {
            0.6 * (t - (2.0 * PI * t).sin() / (2.0 * PI))
        } else {
            0.6
        }
    };
    let mut rows = vec![];
    for h in [4e-3, 2e-3, 1e-3, 5e-4] {
        let r = run(
            "flexible_four_bar.toml",
            &set(&[format!("solver.h={h}"), "solver.t_end=3.0".to_string()]),
        );
        let tau = r.series("drive_torque");
        let mut work = 0.0;
        for k in 1..tau.len() {
            let (t0, t1) = (tau[k - 1].0, tau[k].0);
            work += 0.5 * (tau[k - 1].1 * omega(t0) + tau[k].1 * omega(t1)) * (t1 - t0);
        }
        let energy = r.last("kinetic") + r.last("potential");
        rows.push((h, r.last("coupler_mid_z"), work - energy, energy));
    }
    for (k, (h, z, de, e)) in rows.iter().enumerate() {
        let diff = rows
            .get(k + 1)
            .map(|next| format!("{:.2e}", (z - next.1).abs()))
            .unwrap_or_default();
        println!("| {h} | {z:.8e} | {diff} | {de:+.2e} | {e:.5} |");
    }
    println!();
}

fn slider_crank() {
    println!("### Flexible slider-crank (Simeon), case U, against tests/reference/slider_crank_reference_caseU.csv (Timoshenko)\n");
    println!("Maxima over the 101 reference times (every 1 ms); peak of the reference deflection 1.869e-3 m.\n");
    println!("| elements | h [s] | mass | max error w_mid [m] | % of peak | order | max error x_B [m] | solve time [s] |");
    println!("|---|---|---|---|---|---|---|---|");
    let text = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/reference/slider_crank_reference_caseU.csv"),
    )
    .expect("reference");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).expect(n);
    let (ct, cx, cw) = (
        col("time"),
        col("slider_x_timoshenko"),
        col("rod_mid_deflection_timoshenko"),
    );
    let reference: Vec<(f64, f64, f64)> = lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|s| s.parse().expect("number")).collect();
            (v[ct], v[cx], v[cw])
        })
        .collect();
    let peak = reference.iter().fold(0.0f64, |m, r| m.max(r.2.abs()));
    let cases = [
        (8, 1e-5, "lumped"),
        (16, 1e-5, "lumped"),
        (32, 1e-5, "lumped"),
        (64, 1e-5, "lumped"),
        (16, 1e-5, "consistent"),
        (32, 1e-5, "consistent"),
        (32, 2e-6, "lumped"),
        (32, 1e-6, "lumped"),
    ];
    let mut mesh_errors = vec![];
    for (n, h, mass) in cases {
        let r = run(
            "slider_crank.toml",
            &set(&[
                format!("beam.rod.elements={n}"),
                format!("beam.rod.mass_matrix={mass}"),
                format!("joint.slider_pin.node_b=\"rod.{n}\""),
                format!("sensor.mid_x.node=\"rod.{}\"", n / 2),
                format!("sensor.mid_y.node=\"rod.{}\"", n / 2),
                format!("sensor.rod_axial_force.beam=\"rod[{}]\"", n / 2),
                format!("solver.h={h}"),
            ]),
        );
        let s: Vec<Vec<(f64, f64)>> = ["a_x", "a_y", "mid_x", "mid_y", "b_x", "b_y", "slider_x"]
            .iter()
            .map(|c| r.series(c))
            .collect();
        let at = |k: usize, t: f64| {
            s[k].iter()
                .find(|(tt, _)| (tt - t).abs() < 1e-9)
                .map(|v| v.1)
                .expect("output at the reference time")
        };
        let (mut ew, mut ex) = (0.0f64, 0.0f64);
        for (t, x, w) in &reference {
            let (ax, ay, mx, my, bx, by) = (
                at(0, *t),
                at(1, *t),
                at(2, *t),
                at(3, *t),
                at(4, *t),
                at(5, *t),
            );
            let (dx, dy) = (bx - ax, by - ay);
            let l = dx.hypot(dy);
            let wm = (mx - 0.5 * (ax + bx)) * (-dy / l) + (my - 0.5 * (ay + by)) * (dx / l);
            ew = ew.max((wm - w).abs());
            ex = ex.max((at(6, *t) - x).abs());
        }
        let order = if h == 1e-5 && mass == "lumped" {
            mesh_errors.push(ew);
            orders(&mesh_errors).pop().unwrap_or_default()
        } else {
            String::new()
        };
        println!(
            "| {n} | {h:e} | {mass} | {ew:.3e} | {:.2} | {order} | {ex:.2e} | {:.2} |",
            100.0 * ew / peak,
            r.seconds
        );
    }
    println!();
}

fn main() {
    let only: Vec<String> = std::env::args().skip(1).collect();
    let cases: [(&str, fn()); 7] = [
        ("roll_up", roll_up),
        ("bend", bend),
        ("lee", lee),
        ("right_angle", right_angle),
        ("spin_up", spin_up),
        ("four_bar", four_bar),
        ("slider_crank", slider_crank),
    ];
    for (name, f) in cases {
        if only.is_empty() || only.iter().any(|o| o == name) {
            f();
        }
    }
}
