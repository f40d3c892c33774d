//! Control blocks coupled to the mechanics (`[[block]]`, `flexmb::elements::control`):
//! closed loops against the exact solutions of their linear ODEs, the order of the coupled
//! generalized-alpha scheme, its spectral radius at infinity, and the examples.

mod common;

use nalgebra::{DMatrix, DVector};

/// `exp(A t) z0`, by scaling and squaring of the Taylor series (the test's reference; `A`
/// small and dense).
fn expm_apply(a: &DMatrix<f64>, t: f64, z0: &DVector<f64>) -> DVector<f64> {
    let norm = (a * t).abs().max() * a.nrows() as f64;
    let squarings = (norm.max(1.0).log2().ceil() as i32 + 4).max(0);
    let at = a * (t / 2f64.powi(squarings));
    let n = a.nrows();
    let mut e = DMatrix::identity(n, n);
    let mut term = DMatrix::identity(n, n);
    for k in 1..30 {
        term = &term * &at / k as f64;
        e += &term;
    }
    for _ in 0..squarings {
        e = &e * &e;
    }
    e * z0
}

/// The PID loop of `examples/pid_mass_spring.toml` as `z' = A z`, `z = (x, x', x_i, x_f, r)`.
fn pid_loop() -> DMatrix<f64> {
    let (m, k, c) = (2.0, 50.0, 1.0);
    let (kp, ki, kd, tf) = (200.0, 400.0, 20.0, 0.01);
    // e = r - x; F = kp e + ki x_i + kd (e - x_f) / tf
    let f_row = [-(kp + kd / tf), 0.0, ki, -kd / tf, kp + kd / tf];
    let mut a = DMatrix::zeros(5, 5);
    a[(0, 1)] = 1.0;
    for j in 0..5 {
        a[(1, j)] = f_row[j] / m;
    }
    a[(1, 0)] -= k / m;
    a[(1, 1)] -= c / m;
    a[(2, 0)] = -1.0;
    a[(2, 4)] = 1.0;
    a[(3, 0)] = -1.0 / tf;
    a[(3, 3)] = -1.0 / tf;
    a[(3, 4)] = 1.0 / tf;
    a
}

/// Largest error of the sensor `x` against the exact closed-loop response, over the run.
fn pid_error(h: f64) -> (f64, common::History) {
    let hist = common::run("pid_mass_spring.toml", &[&format!("solver.h={h}")]);
    let a = pid_loop();
    let z0 = DVector::from_vec(vec![0.0, 0.0, 0.0, 0.0, 0.1]);
    let err = hist
        .series("x")
        .iter()
        .map(|&(t, x)| (x - expm_apply(&a, t, &z0)[0]).abs())
        .fold(0.0, f64::max);
    (err, hist)
}

#[test]
fn pid_mass_spring_follows_the_exact_closed_loop_at_second_order() {
    let hs = [2e-3, 1e-3, 5e-4];
    let mut errs = Vec::new();
    for &h in &hs {
        let (err, hist) = pid_error(h);
        if h == 1e-3 {
            // the force at t = 0: the PID's proportional and filtered-derivative kick
            let f0 = hist.series("force")[0].1;
            assert!(
                (f0 - (200.0 + 20.0 / 0.01) * 0.1).abs() < 1e-9,
                "F(0) = {f0}"
            );
        }
        errs.push(err);
    }
    let order = common::order(&hs, &errs);
    eprintln!("PID loop: errors {errs:?}, order {order:.3}");
    assert!(errs[1] < 1e-5, "error at h = 1e-3: {:.3e}", errs[1]);
    assert!((order - 2.0).abs() < 0.15, "order {order}");
}
