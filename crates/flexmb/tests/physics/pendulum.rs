//! Simple pendulum (IFToMM benchmark A01): period against the exact elliptic-integral value
//! and energy conservation of the undamped scheme (rho_inf = 1).
//!
//! Exact period for a release from the horizontal: T = 4 sqrt(L/g) K(k), k = sin(45 deg)
//! (K the complete elliptic integral of the first kind), computed below from the
//! arithmetic-geometric mean: K(k) = pi / (2 agm(1, sqrt(1 - k^2))).

use crate::common::run;
use std::f64::consts::PI;

fn exact_period(l: f64, g: f64) -> f64 {
    let (mut a, mut b) = (1.0f64, (1.0f64 - 0.5).sqrt());
    for _ in 0..30 {
        let (an, bn) = (0.5 * (a + b), (a * b).sqrt());
        a = an;
        b = bn;
    }
    4.0 * (l / g).sqrt() * PI / (2.0 * a)
}

/// Times at which `f` crosses `level` upwards (linear interpolation between outputs).
fn upward_crossings(series: &[(f64, f64)], level: f64) -> Vec<f64> {
    series
        .windows(2)
        .filter(|w| w[0].1 < level && w[1].1 >= level)
        .map(|w| w[0].0 + (level - w[0].1) / (w[1].1 - w[0].1) * (w[1].0 - w[0].0))
        .collect()
}

#[test]
fn pendulum_period_matches_elliptic_integral() {
    let t_exact = exact_period(1.0, 9.81);
    // Published value (benchmarks.md A01): 2.3678419476 s.
    assert!((t_exact - 2.3678419476).abs() < 1e-9);
    let run = run("pendulum.toml", &[]);
    let crossings = upward_crossings(&run.series("angle"), -PI / 2.0);
    assert!(crossings.len() >= 4, "{crossings:?}");
    for w in crossings.windows(2) {
        let period = w[1] - w[0];
        assert!(
            (period - t_exact).abs() < 2e-5,
            "period {period} vs {t_exact}"
        );
    }
    // Position at 10 s (benchmarks.md A01, mass released at (+1, 0)).
    assert!((run.at("x", 10.0) - 0.2750874626).abs() < 1e-4);
    assert!((run.at("y", 10.0) + 0.9614192051).abs() < 1e-4);
}

#[test]
fn pendulum_energy_is_conserved_without_numerical_damping() {
    let max_error = |h: &str| {
        let r = run(
            "pendulum.toml",
            &["solver.rho_inf=1.0", "solver.output_interval=0.01", h],
        );
        r.series("energy")
            .iter()
            .fold(0.0f64, |m, (_, e)| m.max(e.abs()))
    };
    // E(0) = 0 (V = m g y, released at y = 0). The trapezoidal rule (rho_inf = 1) has no
    // numerical dissipation: the energy error stays bounded at O(h^2) over the 10 s (four
    // periods) instead of drifting.
    let e1 = max_error("solver.h=1e-3");
    let e2 = max_error("solver.h=2e-3");
    assert!(e1 < 2e-5, "max |E| = {e1} J at h = 1e-3");
    let ratio = e2 / e1;
    assert!(
        (3.0..5.0).contains(&ratio),
        "energy error ratio {ratio} for h doubled"
    );
}

#[test]
fn pendulum_joint_reaction_is_three_times_the_weight_at_the_bottom() {
    // Released from the horizontal: v^2 = 2 g L at the bottom, so the pivot pulls the bob
    // up with m g + m v^2 / L = 3 m g (and with 0 at the release, where the link is slack
    // in the radial direction: m v^2 / L = 0 and gravity is perpendicular to the link).
    let run = run("pendulum.toml", &["solver.t_end=1.0"]);
    let ys = run.series("y");
    let (k, _) = ys
        .iter()
        .enumerate()
        .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1))
        .expect("rows");
    let (fx, fy) = (
        run.rows[k].1[run.column("reaction_x")],
        run.rows[k].1[run.column("reaction_y")],
    );
    assert!(
        (fy - 3.0 * 9.81).abs() < 1e-2,
        "vertical reaction at the bottom {fy}"
    );
    assert!(fx.abs() < 5e-2, "horizontal reaction at the bottom {fx}");
    let f0 = run.rows[0].1[run.column("reaction_x")].hypot(run.rows[0].1[run.column("reaction_y")]);
    assert!(f0 < 1e-6, "reaction at release {f0}");
}

/// The trust issue's reproducer: 12 000 steps of 1.25e-4 s to 1.5 s took a 12 001st step of
/// a few 1e-16 s and wrote t = 1.5 twice. Every step now ends on the time grid, the last
/// exactly on t_end, and none is shorter than h / 2.
#[test]
fn pendulum_takes_no_sliver_step_at_the_end() {
    let run = run(
        "pendulum.toml",
        &[
            "solver.t_end=1.5",
            "solver.h=1.25e-4",
            "solver.output_interval=0",
        ],
    );
    assert_eq!(run.stats.steps, 12_000);
    assert_eq!(run.rows.len(), 12_001);
    assert_eq!(run.rows.last().unwrap().0, 1.5);
    assert!(run.rows.windows(2).all(|w| w[1].0 > w[0].0));
    assert!(run.stats.smallest_step >= 0.5 * 1.25e-4);
}
