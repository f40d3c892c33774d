//! Control blocks on arms (issue 11): a rigid two-link arm tracking a joint trajectory by
//! computed torque, against its exactly linear error dynamics
//! (`examples/two_link_arm_tracking.toml`), and a flexible one-link arm slewed by a DC motor
//! under PD control, collocated (hub angle) against non-collocated (tip position) feedback
//! (`examples/flexible_arm_dc_motor.toml`; Cannon & Schmitz, Initial experiments on the
//! end-point control of a flexible one-link robot, Int. J. Robotics Research 3(3) (1984)
//! 62-75).

use crate::common;

/// The gains of `two_link_arm_tracking.toml`: `e'' + KD e' + KP e = 0`.
const KP: f64 = 100.0;
const KD: f64 = 14.0;

/// The error and its rate of `e'' + KD e' + KP e = 0` from `e(0) = e0`, `e'(0) = ed0`
/// (underdamped: `KD^2 < 4 KP`).
fn error_dynamics(t: f64, e0: f64, ed0: f64) -> (f64, f64) {
    let s = KD / 2.0;
    let wd = (KP - s * s).sqrt();
    let (c, sn) = ((wd * t).cos(), (wd * t).sin());
    let b = (ed0 + s * e0) / wd;
    let env = (-s * t).exp();
    let e = env * (e0 * c + b * sn);
    let ed = env * (-s * (e0 * c + b * sn) + wd * (-e0 * sn + b * c));
    (e, ed)
}

/// The initial errors `(e, e')` of the two joints: the references of the file at t = 0 (the
/// arm starts at rest with zero joint coordinates).
fn initial_errors() -> [(f64, f64); 2] {
    use std::f64::consts::PI;
    let w2 = 2.0 * PI * 0.8;
    [
        (0.2, 0.5 * PI),
        (-0.3 + 0.8 * 0.4f64.sin(), 0.8 * w2 * 0.4f64.cos()),
    ]
}

/// Largest deviation of the errors and their rates from the closed form over a run.
fn tracking_deviation(hist: &common::History) -> (f64, f64) {
    let (mut de, mut ded) = (0.0f64, 0.0f64);
    for (j, &(e0, ed0)) in initial_errors().iter().enumerate() {
        let e = hist.series(&format!("e{}", j + 1));
        let ed = hist.series(&format!("de{}", j + 1));
        for (&(t, ej), &(_, edj)) in e.iter().zip(&ed) {
            let (ee, eed) = error_dynamics(t, e0, ed0);
            de = de.max((ej - ee).abs());
            ded = ded.max((edj - eed).abs());
        }
    }
    (de, ded)
}

/// Least-squares slope of `y` against `x`.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    sxy / sxx
}

/// Computed torque with the arm's exact (constant) mass matrix: each joint's error follows
/// `e'' + kd e' + kp e = 0` from the initial error of a start off the reference. The
/// coupled scheme is second order, so the deviation from the closed form is `C h^2`; it is
/// checked at two step sizes (the order within 0.15 of 2, and below 5e-6 rad at h = 1e-3 s,
/// 2.5e-5 of the initial error), and the decay rate `kd / 2` of the invariant
/// `sqrt(wd^2 e^2 + (e' + s e)^2) = E0 exp(-s t)` is fitted to 0.5 %.
#[test]
fn two_link_arm_tracking_error_follows_the_linear_error_dynamics() {
    let hs = [2e-3, 1e-3];
    let mut errs = Vec::new();
    let mut last = None;
    for &h in &hs {
        let hist = common::run(
            "two_link_arm_tracking.toml",
            &[&format!("solver.h={h}"), "solver.t_end=1.0"],
        );
        let (de, ded) = tracking_deviation(&hist);
        eprintln!(
            "h = {h}: |e - closed form| <= {de:.3e} rad, |e' - closed form| <= {ded:.3e} rad/s"
        );
        errs.push(de);
        last = Some(hist);
    }
    let order = common::order(&hs, &errs);
    eprintln!("two-link arm: deviations {errs:?}, order {order:.3}");
    assert!(errs[1] < 5e-6, "deviation at h = 1e-3: {:.3e}", errs[1]);
    assert!((order - 2.0).abs() < 0.15, "order {order}");

    let hist = last.expect("runs");
    let s = KD / 2.0;
    let wd = (KP - s * s).sqrt();
    for j in 1..=2 {
        let e = hist.series(&format!("e{j}"));
        let ed = hist.series(&format!("de{j}"));
        let (t, log_inv): (Vec<f64>, Vec<f64>) = e
            .iter()
            .zip(&ed)
            .map(|(&(t, e), &(_, ed))| {
                let inv = ((wd * e).powi(2) + (ed + s * e).powi(2)).sqrt();
                (t, inv.ln())
            })
            .unzip();
        let rate = -slope(&t, &log_inv);
        let ratio = log_inv.last().expect("rows").exp() / log_inv[0].exp();
        eprintln!("joint {j}: decay rate {rate:.5} 1/s (kd / 2 = {s}), invariant ratio over 1 s {ratio:.4e}");
        assert!((rate - s).abs() < 5e-3 * s, "joint {j}: decay rate {rate}");
        assert!(
            (ratio / (-s).exp() - 1.0).abs() < 0.01,
            "joint {j}: the invariant drops by {ratio:.4e} in 1 s"
        );
    }
}

/// Local extrema of `|y - y_ref|` for `t >= from`: `(t, y - y_ref)`.
fn peaks(series: &[(f64, f64)], y_ref: f64, from: f64) -> Vec<(f64, f64)> {
    series
        .windows(3)
        .filter(|w| w[1].0 >= from)
        .filter_map(|w| {
            let [a, b, c] = [w[0].1 - y_ref, w[1].1 - y_ref, w[2].1 - y_ref];
            let extremum = (b - a) * (c - b) < 0.0;
            (extremum && b.abs() >= a.abs() && b.abs() > c.abs()).then_some((w[1].0, b))
        })
        .collect()
}

/// Largest `|y - y_ref|` over `[t0, t1]`.
fn amplitude(series: &[(f64, f64)], y_ref: f64, t0: f64, t1: f64) -> f64 {
    series
        .iter()
        .filter(|(t, _)| (t0..=t1).contains(t))
        .map(|(_, y)| (y - y_ref).abs())
        .fold(0.0, f64::max)
}

/// Collocated PD (on the hub angle, the file as it is): the step of 0.2 rad at t = 0 kicks
/// the hub forward, and the tip first moves the wrong way (its inertial y coordinate goes
/// negative while the hub is already well ahead: the non-minimum-phase response of the tip);
/// then the loop settles the hub on the reference and the tip on `L sin(0.2)`, the vibration
/// damped by the collocated PD and the back-EMF.
#[test]
fn flexible_arm_collocated_pd_settles_and_the_tip_starts_the_wrong_way() {
    let hist = common::run(
        "flexible_arm_dc_motor.toml",
        &["solver.h=4e-3", "solver.t_end=3.0"],
    );
    let hub = hist.series("hub_angle");
    let tip = hist.series("tip_y");
    // the wrong-way motion, in the first 0.15 s
    let (t_min, y_min) = tip
        .iter()
        .filter(|(t, _)| *t <= 0.15)
        .copied()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("rows");
    let hub_then = hist.at("hub_angle", t_min);
    eprintln!(
        "collocated: tip y min {y_min:.4e} m at t = {t_min} s, the hub then at {hub_then:.4} rad; \
         peak torque {:.3} N m",
        hist.series("torque")
            .iter()
            .map(|r| r.1.abs())
            .fold(0.0, f64::max)
    );
    assert!(
        y_min < -0.01,
        "the tip does not start the wrong way: min y {y_min}"
    );
    assert!(
        hub_then > 0.05,
        "hub angle {hub_then} when the tip is at its lowest"
    );
    // settling
    let theta_ref = 0.2;
    let early = amplitude(&hub, theta_ref, 0.0, 1.0);
    let late = amplitude(&hub, theta_ref, 2.5, 3.0);
    let tip_late = amplitude(&tip, theta_ref.sin(), 2.5, 3.0);
    let overshoot = hub.iter().map(|r| r.1).fold(f64::MIN, f64::max) - theta_ref;
    eprintln!(
        "collocated: hub overshoot {overshoot:.4} rad; |hub - ref| <= {early:.3e} over [0, 1] s, \
         {late:.3e} over [2.5, 3] s; |tip y - L sin(ref)| <= {tip_late:.3e} m over [2.5, 3] s"
    );
    assert!(late < 2e-3, "the hub does not settle: |hub - ref| = {late}");
    assert!(tip_late < 3e-3, "the tip does not settle: {tip_late}");
    assert!(late < 0.02 * early, "no decay: {early} -> {late}");
}

/// The same PD, fed the tip position instead of the hub angle (non-collocated), on a small
/// step (0.01 rad: the motion stays linear): the flexible mode is destabilized and grows
/// exponentially, the hub moving against the tip, while the collocated loop with the same
/// gains and step settles. The growth rate and frequency are fitted to the extrema of the
/// hub's deviation from the reference.
#[test]
fn flexible_arm_non_collocated_pd_is_unstable() {
    let theta_ref = 0.01;
    let small = format!("block.reference.function.value={theta_ref}");
    let base = ["solver.h=4e-3", "solver.t_end=1.5", small.as_str()];
    let collocated = common::run("flexible_arm_dc_motor.toml", &base);
    let mut non = base.to_vec();
    non.extend(["block.feedback.gain=0", "block.tip_feedback.gain=1"]);
    let non_collocated = common::run("flexible_arm_dc_motor.toml", &non);

    let ratio = |h: &common::History| {
        let hub = h.series("hub_angle");
        amplitude(&hub, theta_ref, 1.0, 1.5) / amplitude(&hub, theta_ref, 0.25, 0.75)
    };
    let (rc, rn) = (ratio(&collocated), ratio(&non_collocated));
    let p = peaks(&non_collocated.series("hub_angle"), theta_ref, 0.3);
    let (t, log_a): (Vec<f64>, Vec<f64>) = p.iter().map(|&(t, d)| (t, d.abs().ln())).unzip();
    let growth = slope(&t, &log_a);
    let half_period = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    let omega = std::f64::consts::PI / half_period;
    let alternating = p.windows(2).all(|w| w[0].1 * w[1].1 < 0.0);
    eprintln!(
        "hub deviation amplitude [1, 1.5] s / [0.25, 0.75] s: collocated {rc:.3e}, \
         non-collocated {rn:.3}; non-collocated growth {growth:.3} 1/s at {omega:.2} rad/s \
         ({} extrema)",
        p.len()
    );
    // against the tip: at the hub's extrema the tip deviates the other way
    let tip_opposite = p.iter().all(|&(t, d)| {
        let tip = non_collocated.at("tip_y", t) - theta_ref;
        tip * d < 0.0
    });
    assert!(rc < 0.5, "collocated: no decay ({rc})");
    assert!(rn > 3.0, "non-collocated: no growth ({rn})");
    assert!(growth > 1.0, "non-collocated growth rate {growth}");
    assert!(alternating && p.len() >= 8, "not an oscillation: {p:?}");
    assert!(tip_opposite, "the hub does not move against the tip");
}
