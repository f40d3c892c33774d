//! The generalized-alpha family on the linear test equation q'' + omega^2 q = 0 (a mass on a
//! spring, along the spring's axis so the problem is exactly linear), against the analytic
//! algorithmic damping ratio and period error of Chung & Hulbert (1993), J. Appl. Mech. 60,
//! 371-375, Figs. 1-2 (values recomputed from the amplification matrix in benchmarks.md
//! Sect. 7.3), at Omega = omega h = 0.1. HHT and Newmark run as special cases.

use flexmb::model::{Model, SpringDamper};
use flexmb::solve::Scheme;
use flexmb::{DynamicSettings, Simulation};
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use std::f64::consts::PI;

/// x(t) and v(t) of the oscillator at every step (omega = 1, h = 0.1, 60 periods).
fn oscillate(scheme: Scheme, rho_inf: f64) -> Vec<(f64, f64, f64)> {
    let mut m = Model::new(Group::SE3);
    let n = m.add_node(
        "mass",
        Frame::new(Vec3::new(0.01, 0.0, 0.0), Mat3::identity()),
    );
    m.add_body("mass", n, 1.0, Vec3::zeros(), Mat3::identity() * 1e-3);
    m.springs.push(SpringDamper {
        name: "spring".into(),
        node_a: None,
        node_b: Some(n),
        point_a: Vec3::new(-1.0, 0.0, 0.0),
        point_b: Vec3::zeros(),
        stiffness: 1.0,
        damping: 0.0,
        rest_length: 1.0,
        relaxation: None,
    });
    let mut s = DynamicSettings::new(120.0 * PI, 0.1);
    s.rho_inf = rho_inf;
    s.scheme = scheme;
    s.newton.rtol = 1e-12;
    s.newton.atol = 1e-15;
    let mut sim = Simulation::new(&m, s).expect("starts");
    let mut out = vec![];
    sim.run(&mut |s: &flexmb::observe::Sample| {
        out.push((s.state.t, s.state.q[0].x.x, s.state.v[0][0]));
        Ok(())
    })
    .expect("runs");
    out
}

/// (relative period error, algorithmic damping ratio) measured from the history.
fn measure(history: &[(f64, f64, f64)]) -> (f64, f64) {
    let crossings: Vec<f64> = history
        .windows(2)
        .filter(|w| w[0].1 < 0.0 && w[1].1 >= 0.0)
        .map(|w| w[0].0 + (-w[0].1) / (w[1].1 - w[0].1) * (w[1].0 - w[0].0))
        .collect();
    let periods = crossings.len() - 1;
    let t_bar = (crossings[periods] - crossings[0]) / periods as f64;
    // Energy averaged over each numerical period decays as exp(-2 xi omega_bar t).
    let (mut ts, mut logs) = (vec![], vec![]);
    for w in crossings.windows(2) {
        let e: Vec<f64> = history
            .iter()
            .filter(|(t, ..)| *t >= w[0] && *t < w[1])
            .map(|(_, x, v)| 0.5 * (x * x + v * v))
            .collect();
        ts.push(0.5 * (w[0] + w[1]));
        logs.push((e.iter().sum::<f64>() / e.len() as f64).ln());
    }
    let n = ts.len() as f64;
    let (mt, ml) = (ts.iter().sum::<f64>() / n, logs.iter().sum::<f64>() / n);
    let slope = ts
        .iter()
        .zip(&logs)
        .map(|(t, l)| (t - mt) * (l - ml))
        .sum::<f64>()
        / ts.iter().map(|t| (t - mt).powi(2)).sum::<f64>();
    let omega_bar = 2.0 * PI / t_bar;
    (t_bar / (2.0 * PI) - 1.0, -slope / (2.0 * omega_bar))
}

#[test]
fn generalized_alpha_family_matches_chung_hulbert_at_omega_h_0_1() {
    // (scheme, rho_inf, period error, damping ratio), benchmarks.md Sect. 7.3, Omega = 0.1.
    let cases = [
        (Scheme::GeneralizedAlpha, 0.0, 4.50e-3, 4.83e-4),
        (Scheme::GeneralizedAlpha, 0.5, 1.25e-3, 1.84e-5),
        (Scheme::GeneralizedAlpha, 0.9, 8.43e-4, 7.28e-8),
        (Scheme::GeneralizedAlpha, 1.0, 8.33e-4, 0.0),
        (Scheme::Hht { alpha: 0.3 }, 1.0, 1.24e-3, 1.83e-5),
        (Scheme::Hht { alpha: 0.05 }, 1.0, 9.48e-4, 5.62e-6),
        (
            Scheme::Newmark {
                beta: 0.25,
                gamma: 0.5,
            },
            1.0,
            8.33e-4,
            0.0,
        ),
    ];
    for (scheme, rho, period_error, xi) in cases {
        let (pe, xi_measured) = measure(&oscillate(scheme, rho));
        println!("{scheme:?} rho {rho}: period error {pe:.4e} (ref {period_error:.3e}), xi {xi_measured:.4e} (ref {xi:.3e})");
        assert!(
            (pe - period_error).abs() < 0.005 * period_error,
            "{scheme:?} rho {rho}: period error {pe}"
        );
        // Damping: 2 % of the reference (3 digits are tabulated), or 1e-10 for the undamped ones.
        assert!(
            (xi_measured - xi).abs() < (0.02 * xi).max(1e-10),
            "{scheme:?} rho {rho}: xi {xi_measured}"
        );
    }
}
