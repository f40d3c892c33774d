//! Newton settings and the weighted convergence norm.
//!
//! Convergence is judged on the corrections, each weighted by `atol + rtol |value|`
//! (Arnold & Hante 2017, "Implementation details of a generalized-alpha DAE Lie group
//! method", J. Comput. Nonlinear Dyn. 12, 021002, Sect. 4), rather than on a residual that
//! mixes forces, moments and constraint units: the iteration stops when the root mean square
//! of the weighted corrections is at most 1.

/// Tolerances and limits of the Newton iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonSettings {
    /// Relative tolerance on the unknowns.
    pub rtol: f64,
    /// Absolute tolerance on the configuration increments [m or rad].
    pub atol: f64,
    /// Iterations before a step is rejected.
    pub max_iterations: usize,
    /// Reuse the factorized iteration matrix across iterations and steps (chord method)
    /// while it contracts fast enough.
    pub reuse_jacobian: bool,
    /// Contraction rate (ratio of successive weighted corrections) above which a reused
    /// matrix is rebuilt.
    pub max_contraction: f64,
    /// Steps after which a reused matrix is rebuilt anyway.
    pub max_jacobian_age: usize,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        Self {
            rtol: 1e-6,
            atol: 1e-9,
            max_iterations: 12,
            reuse_jacobian: true,
            max_contraction: 0.25,
            max_jacobian_age: 100,
        }
    }
}

/// Root mean square of `dx_i / (atol_i + rtol |x_i|)` and the index of the largest term.
pub fn weighted_norm(
    dx: &[f64],
    x: &[f64],
    atol: &dyn Fn(usize) -> f64,
    rtol: f64,
) -> (f64, usize) {
    let mut sum = 0.0;
    let mut worst = (0.0, 0);
    for (i, (d, v)) in dx.iter().zip(x).enumerate() {
        let e = d / (atol(i) + rtol * v.abs());
        let e2 = e * e;
        sum += e2;
        if e2 > worst.0 || !e2.is_finite() {
            worst = (e2, i);
        }
    }
    ((sum / dx.len().max(1) as f64).sqrt(), worst.1)
}
