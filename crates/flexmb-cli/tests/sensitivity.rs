//! `flexmb sensitivity MODEL --out DIR [--method direct|adjoint|fd]`: the gradients of the
//! examples' criteria by direct differentiation and by the discrete adjoint agree to round-off
//! (both are exact for the computed discrete solution), and with central finite differences
//! to what finite differences allow; `--check` writes the comparison; models without
//! criteria or with a bad expression are refused with file, line and field.

mod common;

use common::{flexmb, out_dir, repo};
use serde_json::Value;

/// Runs `flexmb sensitivity` on an example with `args` and returns `gradients.json`.
fn gradients(example: &str, name: &str, args: &[&str]) -> Value {
    let out = out_dir(name);
    let output = flexmb()
        .args(["sensitivity", repo(example).to_str().unwrap(), "--out"])
        .arg(&out)
        .arg("--quiet")
        .args(args)
        .output()
        .expect("runs");
    assert!(
        output.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = std::fs::read_to_string(out.join("gradients.json")).expect("gradients.json");
    serde_json::from_str(&text).expect("JSON")
}

/// `(criterion, parameter, dJ/dp)` of a `gradients.json`.
fn table(g: &Value) -> Vec<(String, String, f64)> {
    let mut out = Vec::new();
    for c in g["criteria"].as_array().expect("criteria") {
        let name = c["name"].as_str().unwrap().to_string();
        for (path, v) in c["gradient"].as_object().expect("gradient") {
            out.push((name.clone(), path.clone(), v.as_f64().unwrap()));
        }
    }
    out
}

/// Largest relative difference between two tables of gradients, each entry relative to the
/// largest gradient of its criterion times `floor` at least.
fn worst(a: &Value, b: &Value, floor: f64) -> (f64, String) {
    let (ta, tb) = (table(a), table(b));
    assert_eq!(ta.len(), tb.len());
    let mut largest = std::collections::HashMap::new();
    for (c, _, v) in &ta {
        let e = largest.entry(c.clone()).or_insert(0.0f64);
        *e = e.max(v.abs());
    }
    let mut out = (0.0, String::new());
    for ((c, p, x), (c2, p2, y)) in ta.iter().zip(&tb) {
        assert_eq!((c, p), (c2, p2));
        let scale = x.abs().max(y.abs()).max(floor * largest[c]);
        let r = (x - y).abs() / scale;
        if r > out.0 {
            out = (r, format!("{c} / {p}: {x:e} against {y:e}"));
        }
    }
    out
}

/// The three methods on one example: direct and adjoint within `exact`, the adjoint and
/// central differences within `fd` (entries below `1e-6` of the criterion's largest
/// gradient are compared to that floor).
fn agree(example: &str, name: &str, set: &[&str], exact: f64, fd: f64) {
    let mut args: Vec<&str> = Vec::new();
    for s in set {
        args.extend(["--set", s]);
    }
    let with = |m: &'static str| {
        let mut a = args.clone();
        a.extend(["--method", m, "--fd-step", "1e-5"]);
        a
    };
    let d = gradients(example, &format!("{name}-direct"), &with("direct"));
    let a = gradients(example, &format!("{name}-adjoint"), &with("adjoint"));
    let f = gradients(example, &format!("{name}-fd"), &with("fd"));
    let (e_exact, at) = worst(&d, &a, 1e-12);
    assert!(
        e_exact < exact,
        "{name}: direct and adjoint differ by {e_exact:e} ({at})"
    );
    let (e, at) = worst(&a, &f, 1e-6);
    assert!(
        e < fd,
        "{name}: adjoint and finite differences differ by {e:e} ({at})"
    );
    println!("{name}: direct-adjoint {e_exact:.2e}; adjoint-fd {e:.2e} ({at})");
    for (c, cd) in d["criteria"].as_array().unwrap().iter().enumerate() {
        let (x, y) = (
            cd["value"].as_f64().unwrap(),
            a["criteria"][c]["value"].as_f64().unwrap(),
        );
        assert_eq!(x, y, "{name}: the criterion's value is the same run");
    }
}

/// Tight Newton tolerances, so that the finite differences see the discrete solution and
/// not the iteration's error.
const TIGHT: [&str; 2] = ["solver.rtol=1e-12", "solver.atol=1e-14"];

#[test]
fn heavy_top_gradients_agree_on_both_groups() {
    // x_G(t) components and the integral of the squared nutation angle with respect to mass,
    // inertia, centre of mass and initial spin. Observed: direct-adjoint below 1e-12,
    // adjoint-fd (relative step 1e-5) 1.8e-6 on R3xSO(3), less on SE(3).
    for group in ["SE3", "R3xSO3"] {
        let g = format!("model.group={group}");
        let set = [TIGHT[0], TIGHT[1], "solver.t_end=0.3", g.as_str()];
        agree(
            "examples/heavy_top_sensitivity.toml",
            &format!("top-{group}"),
            &set,
            1e-8,
            1e-5,
        );
    }
}

#[test]
fn right_angle_cantilever_gradients_agree() {
    // Tip displacement with respect to EI, GJ, rhoA of member 2 and the impulse's peak.
    let set = [TIGHT[0], TIGHT[1], "solver.t_end=3.0"];
    agree(
        "examples/right_angle_cantilever_sensitivity.toml",
        "rac",
        &set,
        1e-8,
        1e-5,
    );
}

#[test]
fn check_writes_the_comparison_table() {
    let out = out_dir("check");
    let output = flexmb()
        .args([
            "sensitivity",
            repo("examples/heavy_top_sensitivity.toml")
                .to_str()
                .unwrap(),
        ])
        .arg("--out")
        .arg(&out)
        .args([
            "--check",
            "--quiet",
            "--set",
            "solver.t_end=0.1",
            "--set",
            "solver.rtol=1e-12",
        ])
        .output()
        .expect("runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("largest relative difference"), "{stdout}");
    let rows = common::rows(&out.join("gradient_check.csv"));
    assert_eq!(rows.len(), 4 * 5, "4 criteria, 5 parameters");
    for r in &rows {
        let diff: f64 = r[5].parse().unwrap();
        assert!(diff < 1e-4, "{r:?}");
    }
    let csv = common::rows(&out.join("gradients.csv"));
    assert_eq!(csv.len(), 20);
}

#[test]
fn a_model_without_criteria_or_with_a_bad_one_is_refused() {
    let out = out_dir("none");
    let output = flexmb()
        .args([
            "sensitivity",
            repo("examples/pendulum.toml").to_str().unwrap(),
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("[[criterion]]"), "{stderr}");

    let out = out_dir("bad");
    let output = flexmb()
        .args([
            "sensitivity",
            repo("examples/heavy_top_sensitivity.toml")
                .to_str()
                .unwrap(),
        ])
        .arg("--out")
        .arg(&out)
        .args(["--set", "criterion.nutation.integral=sq(com_q)"])
        .output()
        .expect("runs");
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("heavy_top_sensitivity.toml:")
            && stderr.contains("criterion[3].integral")
            && stderr.contains("unknown name 'com_q'"),
        "{stderr}"
    );
}

#[test]
fn static_bend_and_lee_frame_gradients_agree() {
    // The 45-degree bend's tip at P = 600 with respect to EI2, EI3, GJ and the load (load
    // control), Lee's frame's loaded point at P = 15 kN with respect to EA and EI3 (the final
    // point of an arc-length run). Observed: direct-adjoint 1e-12 or less, adjoint-fd below
    // 1e-7 (entries above 1e-6 of each criterion's largest gradient).
    let tight = ["solver.rtol=1e-12"];
    agree(
        "examples/bend_45_sensitivity.toml",
        "bend",
        &tight,
        1e-8,
        1e-5,
    );
    agree(
        "examples/lee_frame_sensitivity.toml",
        "lee",
        &tight,
        1e-8,
        1e-5,
    );
}

#[test]
fn half_car_comfort_gradients_agree() {
    // The integral of the squared vertical acceleration (chassis and driver's seat) with
    // respect to the suspension's damping and stiffness; the road bump is a raised cosine
    // met by the rear wheel a wheelbase later (a delayed function).
    let set = [TIGHT[0], TIGHT[1], "solver.t_end=0.6"];
    agree("examples/half_car.toml", "half-car", &set, 1e-8, 1e-5);
}

#[test]
fn optimize_lowers_the_half_car_comfort_criterion() {
    let out = out_dir("optimize");
    let output = flexmb()
        .args(["optimize", repo("examples/half_car.toml").to_str().unwrap()])
        .arg("--out")
        .arg(&out)
        .args(["--iterations", "10", "--set", "solver.t_end=0.8"])
        .output()
        .expect("runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let rows = common::rows(&out.join("optimization.csv"));
    let column = |r: &Vec<String>, k: usize| r[k].parse::<f64>().unwrap();
    let (first, last) = (&rows[0], &rows[rows.len() - 1]);
    // evaluation, criterion, 4 parameters, 4 gradients
    assert_eq!(first.len(), 10);
    let (f0, f1) = (column(first, 1), column(last, 1));
    assert!(f1 < 0.8 * f0, "the criterion went from {f0} to {f1}");
    for r in rows.windows(2) {
        assert!(
            column(&r[1], 1) < column(&r[0], 1),
            "each row improves: {r:?}"
        );
    }
    // The free parameters (the dampers, bounded) moved and stayed in their bounds; the
    // springs (no bounds) were held.
    for k in [2, 3] {
        let c = column(last, k);
        assert!((100.0..=20000.0).contains(&c) && c != 2000.0, "damper {c}");
    }
    assert_eq!(column(last, 4), 30000.0);
    // At the optimum the dampers' gradient is small against the start's.
    let g0 = column(first, 6).hypot(column(first, 7));
    let g1 = column(last, 6).hypot(column(last, 7));
    assert!(g1 < 1e-2 * g0, "gradient {g0:e} -> {g1:e}");
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("optimization.json")).unwrap())
            .unwrap();
    assert_eq!(json["criterion"], "comfort");
}

/// Gradients are those of the criteria as declared, at the end of the analysis: a forward
/// run that stops short of it (Lee's frame, arc length, at `max_steps` before its final load
/// factor) gives none, and says so with the exit status of an analysis stopped before its
/// end (4). An optimization that stops at `--iterations` before L-BFGS converged keeps its
/// history and exits with 4 too, saying to raise it.
#[test]
fn sensitivity_and_optimize_stopped_short_exit_4() {
    let out = out_dir("lee-incomplete");
    let output = flexmb()
        .args([
            "sensitivity",
            repo("examples/lee_frame_sensitivity.toml")
                .to_str()
                .unwrap(),
            "--out",
        ])
        .arg(&out)
        .args(["--quiet", "--set", "solver.max_steps=3"])
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(4), "{stderr}");
    assert!(stderr.contains("raise solver.max_steps"), "{stderr}");
    assert!(!out.join("gradients.json").exists());
    let out = out_dir("optimize-incomplete");
    let output = flexmb()
        .args(["optimize", repo("examples/half_car.toml").to_str().unwrap()])
        .arg("--out")
        .arg(&out)
        .args(["--iterations", "1", "--set", "solver.t_end=0.8"])
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(4), "{stderr}");
    assert!(stderr.contains("raise --iterations"), "{stderr}");
    assert!(common::rows(&out.join("optimization.csv")).len() >= 2);
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("optimization.json")).unwrap())
            .unwrap();
    assert_eq!(json["status"], "Maximum number of iterations reached");
}
