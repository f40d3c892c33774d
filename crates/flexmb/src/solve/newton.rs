//! Newton settings, the weighted convergence norm and the acceptance test.
//!
//! **Norm.** Convergence is judged on the corrections, each weighted by `atol + rtol |value|`
//! (Arnold & Hante 2017, "Implementation details of a generalized-alpha DAE Lie group
//! method", J. Comput. Nonlinear Dyn. 12, 021002, Sect. 4), rather than on a residual that
//! mixes forces, moments and constraint units: an iterate is within the tolerance when the
//! root mean square of its weighted errors is at most 1.
//!
//! **Acceptance.** What must be at most 1 is the error of the iterate that is accepted, not
//! the size of the last correction. The two agree only for a Newton step with the exact
//! iteration matrix at the current iterate, which converges quadratically: the error left
//! after a correction `dx_k` is `O(|dx_k|^2)`. A correction computed with a reused (or
//! regularized, or approximate) matrix converges linearly at a rate `theta` that the size of
//! one correction says nothing about: a stale matrix can make `|dx_1|` small and leave an
//! error of the same size or larger. [`Convergence`] therefore estimates the rate from
//! successive corrections and bounds the error of the new iterate by
//!
//! ```text
//! theta_k = |dx_k| / |dx_{k-1}|,     |x_{k+1} - x*| <= theta_k / (1 - theta_k) |dx_k|
//! ```
//!
//! (Hairer & Wanner 1996, *Solving Ordinary Differential Equations II*, 2nd ed., Sect. IV.8,
//! "Stopping criterion"; the same estimate drives the matrix-reuse strategy of Gustafsson &
//! Söderlind 1997, SIAM J. Sci. Comput. 18, 23-40). An iterate is accepted when
//!
//! * the correction came from the exact matrix at that iterate and `|dx_k| <= 1`, or
//! * `k >= 2`, `theta_k < 1` and `theta_k / (1 - theta_k) |dx_k| <= kappa` with
//!   [`KAPPA`] `= 0.01`, or
//! * the correction is exactly zero (the residual vanishes).
//!
//! So a correction made with a reused matrix is never accepted on its own size: at least two
//! corrections are needed to measure the rate. `kappa` plays the part of Hairer & Wanner's
//! safety factor (0.01 to 0.1 there): an exact Newton step lands far inside the tolerance
//! (its error is quadratic in `|dx|`), and a linearly converging one must too, or the two
//! give different answers that differ by up to the tolerance at every step. Measured on a
//! free body near its intermediate axis (`tests/matrix_reuse.rs`, 20 s at h = 2.5e-3): full
//! Newton flips at 8.2875, 13.5675 and 18.845 s (13.56625 s at h / 2); with a reused matrix
//! the acceptance on one correction's size gave 7.84, 12.275 and 16.605 s, this test with
//! kappa = 1 about 8.6 and 14.15 s, and with kappa = 0.01 8.29, 13.5775 and 18.8675 s
//! (BENCHMARKS.md has the cost).

use crate::error::SettingsError;

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

impl NewtonSettings {
    /// Rejects settings out of their ranges (`docs/model-format.md`, "Ranges").
    pub fn check(&self) -> Result<(), SettingsError> {
        use crate::model::limits::{MAX_PHYSICAL, MIN_PHYSICAL};
        SettingsError::range("rtol", self.rtol, MIN_PHYSICAL, 1.0)?;
        SettingsError::range("atol", self.atol, MIN_PHYSICAL, MAX_PHYSICAL)?;
        if !(1..=10_000).contains(&self.max_iterations) {
            return Err(SettingsError::new(
                &["max_iterations"],
                format!("must be between 1 and 10000, got {}", self.max_iterations),
            ));
        }
        if !(self.max_contraction >= MIN_PHYSICAL && self.max_contraction < 1.0) {
            return Err(SettingsError::new(
                &["max_contraction"],
                format!("must be in [1e-30, 1), got {:e}", self.max_contraction),
            ));
        }
        if self.max_jacobian_age < 1 {
            return Err(SettingsError::new(
                &["max_jacobian_age"],
                "must be at least 1",
            ));
        }
        Ok(())
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

/// Safety factor on the estimated error of an iterate reached by a correction that did not
/// come from the exact iteration matrix (see the module documentation).
pub const KAPPA: f64 = 0.01;

/// Weighted correction below which a block is converged to round-off: its ratio of
/// successive corrections is noise and does not enter the contraction rate (measured on
/// the spin-up after its drive stops: increments at 5e-7 of the tolerance with ratios of
/// 0.3 to 0.7 while the multipliers converge at 0.06).
pub const NEGLIGIBLE: f64 = 1e-4 * KAPPA;

/// Most blocks of unknowns [`Convergence`] tracks separately.
pub const MAX_BLOCKS: usize = 4;

/// The acceptance test of one Newton solve (see the module documentation), fed the weighted
/// norms of each correction as it is applied, one per block of unknowns (e.g. increments,
/// multipliers, stabilization). The error is their largest; the contraction rate is the
/// slowest of the blocks' rates, because the size of a first correction is mostly the
/// predictor's error, which one block can lose at once while another block still converges
/// slowly (measured on the 100-link chain: multipliers 54 -> 0.59, increments 0.85 -> 0.17;
/// the ratio of the largest norms, 0.011, would have accepted a step whose error a fresh
/// matrix then measured at 1.2).
#[derive(Clone, Copy, Debug, Default)]
pub struct Convergence {
    /// Weighted norms of the previous correction (`None` before the first).
    previous: Option<[f64; MAX_BLOCKS]>,
}

/// What the iteration should do after a correction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verdict {
    /// The new iterate is within the tolerance; `estimate` bounds its weighted error.
    Converged { estimate: f64 },
    /// Iterate again; `theta` is the measured contraction rate (`None` after one correction).
    Continue { theta: Option<f64> },
}

impl Convergence {
    /// Judges the iterate reached by a correction with the weighted norms `blocks` (at most
    /// [`MAX_BLOCKS`]); `exact` says whether the correction came from the exact iteration
    /// matrix at the iterate it started from.
    pub fn update(&mut self, blocks: &[f64], exact: bool) -> Verdict {
        let mut norms = [0.0; MAX_BLOCKS];
        norms[..blocks.len()].copy_from_slice(blocks);
        let dx = norms.iter().fold(0.0f64, |m, &v| m.max(v));
        let theta = self.previous.map(|previous| {
            norms
                .iter()
                .zip(previous)
                .filter(|(&now, _)| now > NEGLIGIBLE)
                .map(|(&now, before)| now / before)
                .fold(0.0f64, |m, v| m.max(v))
        });
        self.previous = Some(norms);
        if dx == 0.0 {
            return Verdict::Converged { estimate: 0.0 };
        }
        if dx.is_nan() {
            return Verdict::Continue { theta: None };
        }
        if exact && dx <= 1.0 {
            // Quadratic convergence: the error left is O(dx^2), far below dx.
            return Verdict::Converged { estimate: dx };
        }
        match theta {
            Some(theta) if theta < 1.0 => {
                let estimate = theta / (1.0 - theta) * dx;
                if estimate <= KAPPA {
                    Verdict::Converged { estimate }
                } else {
                    Verdict::Continue { theta: Some(theta) }
                }
            }
            theta => Verdict::Continue { theta },
        }
    }
}

/// What the verify mode of an analysis found: every accepted step re-checked by a Newton
/// correction from the accepted iterate with a freshly built matrix, whose weighted norm
/// estimates the error left in the step in units of the tolerance (at most 1: within it).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Verification {
    /// Steps checked.
    pub steps: usize,
    /// Largest estimated error (NaN if a check found a singular matrix).
    pub max_error: f64,
    /// Time (or load factor) of the step with the largest error.
    pub t: f64,
    /// The equation with the largest weighted correction at that step.
    pub worst_equation: String,
}

impl Verification {
    /// A warning for the user when a step was accepted outside the tolerance (or could not be
    /// checked); `None` when every step passed.
    pub fn warning(&self) -> Option<String> {
        (self.max_error.is_nan() || self.max_error > 1.0).then(|| {
            format!(
                "verify: a step was accepted with an estimated error of {:.3e} times the Newton tolerance at {:.6e} (worst equation: {}); {} steps checked",
                self.max_error, self.t, self.worst_equation, self.steps
            )
        })
    }

    /// Records the check of one step: its estimated error (NaN when no estimate could be
    /// made), where it is, and the equation (evaluated only if the step is the worst so far).
    pub fn record(&mut self, error: f64, at: f64, worst_equation: impl FnOnce() -> String) {
        self.steps += 1;
        if error.is_nan() || error > self.max_error {
            self.max_error = error;
            self.t = at;
            self.worst_equation = worst_equation();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linearly converging iteration `e_{k+1} = rho e_k` (the chord method with a stale
    /// matrix): the accepted iterate's true error must be within the tolerance whatever the
    /// rate and the starting error, and a first correction below 1 is not enough.
    #[test]
    fn accepted_iterate_is_within_tolerance_for_any_linear_rate() {
        for rho in [0.01, 0.1, 0.3, 0.5, 0.7, 0.9, 0.95] {
            for e0 in [1e-3, 0.5, 0.99, 3.0, 1e3] {
                let mut c = Convergence::default();
                let mut error: f64 = e0; // error of the current iterate
                let mut accepted = None;
                for _ in 0..500 {
                    let dx = (1.0 - rho) * error; // correction computed with the stale matrix
                    error *= rho; // error of the new iterate
                    if let Verdict::Converged { estimate } = c.update(&[dx], false) {
                        accepted = Some((error, estimate));
                        break;
                    }
                }
                let (error, estimate) = accepted.expect("converges");
                assert!(
                    error <= KAPPA * (1.0 + 1e-12),
                    "rho {rho}, e0 {e0}: error {error}"
                );
                assert!(
                    error <= estimate * (1.0 + 1e-9),
                    "the estimate bounds the error"
                );
            }
        }
        // One small stale correction is never accepted; an exactly zero one is.
        let mut c = Convergence::default();
        assert_eq!(c.update(&[1e-3], false), Verdict::Continue { theta: None });
        let mut c = Convergence::default();
        assert_eq!(
            c.update(&[0.0], false),
            Verdict::Converged { estimate: 0.0 }
        );
    }

    /// The slowest block sets the rate: a block that lost most of its (predictor) error in
    /// the first correction does not hide a slowly converging one.
    #[test]
    fn slowest_block_sets_the_rate() {
        let mut c = Convergence::default();
        assert!(matches!(
            c.update(&[0.85, 54.0], false),
            Verdict::Continue { .. }
        ));
        match c.update(&[0.17, 0.59], false) {
            Verdict::Continue { theta } => assert!((theta.unwrap() - 0.2).abs() < 1e-12),
            v => panic!("{v:?}"),
        }
        // A block that was exactly zero and no longer is: no rate can be claimed.
        let mut c = Convergence::default();
        c.update(&[1.0, 0.0], false);
        assert!(matches!(
            c.update(&[1e-3, 1e-3], false),
            Verdict::Continue { .. }
        ));
    }

    /// An exact Newton correction below the tolerance is accepted at once; a diverging
    /// sequence never is.
    #[test]
    fn exact_correction_accepted_and_divergence_is_not() {
        let mut c = Convergence::default();
        assert_eq!(c.update(&[0.5], true), Verdict::Converged { estimate: 0.5 });
        let mut c = Convergence::default();
        for dx in [2.0, 4.0, 8.0, 16.0] {
            assert!(matches!(c.update(&[dx], false), Verdict::Continue { .. }));
        }
    }
}
