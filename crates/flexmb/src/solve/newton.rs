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
//! * `k >= 2`, `theta_k < 1` and `theta_k / (1 - theta_k) max(|dx_k|, |dx_k|_c) <= kappa`
//!   with [`KAPPA`] `= 0.01` (`|dx_k|_c` below, "Where the error lands"), or
//! * the correction is exactly zero (the residual vanishes).
//!
//! So a correction made with a reused matrix is never accepted on its own size: at least two
//! corrections are needed to measure the rate. `kappa` plays the part of Hairer & Wanner's
//! safety factor (0.01 to 0.1 there): an exact Newton step lands far inside the tolerance
//! (its error is quadratic in `|dx|`), and a linearly converging one must too, or the two
//! give different answers that differ by up to the tolerance at every step. Measured on a
//! free body near its intermediate axis (`tests/physics/matrix_reuse.rs`, 20 s at h = 2.5e-3): full
//! Newton flips at 8.2875, 13.5675 and 18.845 s (13.56625 s at h / 2); with a reused matrix
//! the acceptance on one correction's size gave 7.84, 12.275 and 16.605 s, this test with
//! kappa = 1 about 8.6 and 14.15 s, and with kappa = 0.01 8.29, 13.5775 and 18.8675 s
//! (BENCHMARKS.md has the cost).
//!
//! **Rates.** The rate is the largest ratio of successive corrections over the blocks and
//! the carried norm below, the last measured. A ratio is a lower bound of the matrix's
//! contraction: a sharp drop can say that the correction lost its fast part (the predictor's
//! error) rather than that the matrix improved. Keeping instead the slowest rate measured
//! with the same matrix in the solve changed no error measured here (the free body below,
//! 5.58e-7 against 5.60e-7 rad/s at 1 s) and cost the flexible four-bar four times the
//! factorizations in its first second (119 against 29; a first ratio distorted by the
//! predicted multipliers, 0.63), so the last rate is kept. The refresh decisions use the blocks' rate ([`Verdict::Continue`]).
//!
//! **Where the error lands.** `|dx|_c` ([`Norms::carried`]) measures the same correction
//! where the system carries it furthest: in a time step, a configuration error `e` is an
//! error `gamma' e` of the velocities and `beta' e` of the accelerations (`1/h` and `1/h^2`
//! times larger), which every later step inherits. The error a linearly converging iterate
//! keeps is its estimate itself, of one sign from step to step (a stale matrix errs the
//! same way while the motion is smooth), so a bound relative to the configuration increment
//! (`rtol h |v|`) or absolute (`atol`) sums to a velocity error of `kappa rtol |v| T / h` or
//! `kappa atol T / h^2` over a run of length `T`: it grows as the step shrinks, and the
//! scheme's order is lost. Measured on the free body above on R3xSO(3) (trust issue, round
//! 2; `tests/physics/matrix_reuse.rs`): with the configuration norm alone a reused matrix ended
//! 9.5e-6 rad/s from the exact solution after 1 s where fresh matrices end 5.7e-7, and at
//! `rtol = 1e-10` its flip times stopped converging (7.8e-5 s at h = 2.5e-3, 3.5e-4 s at
//! h = 1.25e-3, where fresh matrices give 1.45e-5 and 3.6e-6 s). On SE(3) the same body's
//! mass matrix is constant, a reused matrix converges at rates near 1e-9, and the defect
//! did not show. Judged at the level of the accelerations, relative to the model's
//! accelerations `A`, the error such iterates leave sums to at most `kappa gamma rtol A T`
//! in the velocities, whatever `h`: the reused matrix gives the fresh matrices' error and
//! order. An exact correction is still accepted on its size: the error it leaves is
//! quadratic, below the tolerance at every level. The time step judges its iterates so
//! where its fresh matrix is exact or nearly (index 3); the stabilized form's matrix is an
//! approximation whose iterates are all accepted on rates, fresh or reused
//! (`StepSystem::carried_norm` in `super::dynamics`). A correction that no longer shrinks
//! in `|dx|_c` while the blocks' do has reached the round-off of the accelerations, and
//! `|dx|_c` is then left out.

use crate::data::Data;
pub use crate::error::NewtonError;
use crate::error::SettingsError;
use crate::linear::{Backend, LinearError, LinearSolver};

/// Tolerances and limits of the Newton iteration.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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

/// The norms [`Convergence`] tracks: the blocks, then the carried norm ([`Norms::carried`]).
const TRACKED: usize = MAX_BLOCKS + 1;

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
    /// Weighted norms of the previous correction, blocks then carried (`None` before the
    /// first).
    previous: Option<[f64; TRACKED]>,
    /// The contraction rate of the last correction over the blocks whose previous correction
    /// was outside the tolerance (above 1; `None` if none was), what judges a reused matrix
    /// ([`Self::matrix_rate`]).
    matrix_rate: Option<f64>,
    /// Judge corrections from the exact matrix on their size alone (no rate estimate).
    pub exact_by_size: bool,
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
    /// [`MAX_BLOCKS`]) and `carried` ([`Norms::carried`], 0 if the system has none),
    /// computed with the exact matrix at the iterate it starts from if `exact`.
    pub fn update(&mut self, blocks: &[f64], carried: f64, exact: bool) -> Verdict {
        let mut norms = [0.0; TRACKED];
        norms[..blocks.len()].copy_from_slice(blocks);
        norms[MAX_BLOCKS] = carried;
        let size = blocks.iter().fold(0.0f64, |m, &v| m.max(v));
        // The blocks' rate, over those outside the tolerance before the correction if
        // `outside`.
        let rate = |outside: bool| {
            self.previous.and_then(|previous| {
                norms[..MAX_BLOCKS]
                    .iter()
                    .zip(previous)
                    .filter(|(&now, before)| now > NEGLIGIBLE && (!outside || *before > 1.0))
                    .map(|(&now, before)| now / before)
                    .reduce(f64::max)
            })
        };
        let theta = rate(false).or(self.previous.map(|_| 0.0));
        self.matrix_rate = rate(true);
        // The carried norm counts while it contracts: a correction that no longer shrinks in
        // it, where the blocks' do, has reached the round-off of the accelerations (`beta'`
        // times that of the increments, large at small steps and stiff couplings).
        let carried_rate = self
            .previous
            .map(|p| p[MAX_BLOCKS])
            .filter(|&before| carried > NEGLIGIBLE && before > 0.0)
            .map(|before| carried / before);
        let carried_counts = carried_rate.is_none_or(|r| r < 1.0);
        let dx = if carried_counts {
            size.max(carried)
        } else {
            size
        };
        let bound = theta.map(|t| carried_rate.filter(|&r| r < 1.0).map_or(t, |r| t.max(r)));
        self.previous = Some(norms);
        if dx == 0.0 {
            return Verdict::Converged { estimate: 0.0 };
        }
        if dx.is_nan() {
            return Verdict::Continue { theta: None };
        }
        if exact && size <= 1.0 {
            // Quadratic convergence: the error left is O(dx^2), far below dx at every level.
            return Verdict::Converged { estimate: size };
        }
        if exact && self.exact_by_size {
            return Verdict::Continue { theta };
        }
        match bound {
            Some(rate) if rate < 1.0 => {
                let estimate = rate / (1.0 - rate) * dx;
                if estimate <= KAPPA {
                    Verdict::Converged { estimate }
                } else {
                    Verdict::Continue { theta }
                }
            }
            _ => Verdict::Continue { theta },
        }
    }

    /// The contraction rate that says whether a reused matrix still converges fast enough:
    /// that of the last correction over the blocks whose previous correction was outside the
    /// tolerance (`None` when none was). A block whose correction was already within the
    /// tolerance (the predictor's multipliers, or every block of a step predicted well) is
    /// then moved by the others' corrections through the coupling of the equations and by
    /// round-off, ratios that say little of the matrix (the heavy top on R3xSO(3): its dense
    /// matrix was rebuilt at every step); its rate counts from the next correction on. The
    /// acceptance test keeps the rate of every block.
    pub fn matrix_rate(&self) -> Option<f64> {
        self.matrix_rate
    }
}

/// What the verify mode of an analysis found: every accepted step re-checked by a Newton
/// correction from the accepted iterate with a freshly built matrix, whose weighted norm
/// estimates the error left in the step in units of the tolerance (at most 1: within it).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Verification {
    /// Steps checked.
    pub steps: usize,
    /// Largest estimated error (NaN if a check found a singular matrix; `null` in JSON).
    #[serde(deserialize_with = "nan_from_null")]
    pub max_error: f64,
    /// Time (or load factor) of the step with the largest error.
    pub t: f64,
    /// The equation with the largest weighted correction at that step.
    pub worst_equation: String,
}

/// A number, or NaN for `null` (how JSON writes NaN).
fn nan_from_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
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

    /// Records what the verify mode measured at the step (or load step) ending at `at`,
    /// starting the record if there is none.
    pub fn add(
        slot: &mut Option<Self>,
        check: &Check,
        at: f64,
        layout: &crate::data::Layout,
        model: &crate::model::Model,
    ) {
        slot.get_or_insert_with(Self::default)
            .record(check.error, at, || {
                check
                    .worst
                    .map(|i| layout.describe_unknown(model, i))
                    .unwrap_or_default()
            });
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

/// Weighted norms of one Newton correction, one per block of unknowns (at most
/// [`MAX_BLOCKS`]), and the unknown with the largest weighted term.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Norms {
    pub blocks: [f64; MAX_BLOCKS],
    /// Blocks in use.
    pub n: usize,
    /// The block of the multipliers, if the system has one: a step may be accepted on the
    /// other blocks alone where the multipliers cannot be converged (see
    /// [`MultiplierLimit`]).
    pub multipliers: Option<usize>,
    /// The block of the stabilization unknowns `zeta` (the velocity-level multipliers of the
    /// stabilized form), if any: where the multipliers are undetermined (a regularized
    /// matrix), so are they along the same rows, and the solve is accepted without them too.
    pub stabilization: Option<usize>,
    /// Index (in the Newton vector) of the unknown with the largest weighted correction.
    pub worst: usize,
    /// The correction where the system carries it furthest (0 where it has no such level):
    /// for a time step, the configuration corrections at the level of the accelerations
    /// they move, `beta' dx` against `rtol` times the model's acceleration scale. It bounds
    /// the error of an iterate reached at a linear rate, not the size of an exact Newton
    /// correction (module documentation, "Where the error lands").
    pub carried: f64,
}

impl Norms {
    /// The largest block norm.
    pub fn max(&self) -> f64 {
        self.blocks[..self.n].iter().fold(0.0f64, |m, &v| m.max(v))
    }

    /// The block norms without the multipliers' (and, when `undetermined`, without the
    /// stabilization unknowns').
    fn configuration(&self, undetermined: bool) -> ([f64; MAX_BLOCKS], usize) {
        let mut out = [0.0; MAX_BLOCKS];
        let mut n = 0;
        for (k, &v) in self.blocks[..self.n].iter().enumerate() {
            let zeta = undetermined && Some(k) == self.stabilization;
            if Some(k) != self.multipliers && !zeta {
                out[n] = v;
                n += 1;
            }
        }
        (out, n)
    }

    /// Whether the stabilization unknowns' correction is within their tolerance (true
    /// without them).
    fn stabilization_within(&self) -> bool {
        self.stabilization.is_none_or(|k| self.blocks[k] <= 1.0)
    }

    fn multiplier_norm(&self) -> f64 {
        self.multipliers.map_or(0.0, |k| self.blocks[k])
    }
}

/// A nonlinear system `R(x) = 0` that [`NewtonSolver`] solves: the time step of dynamics, a
/// load step or an arc-length step of statics, the consistent initial accelerations. The
/// system holds its iterate `x` and everything the residual depends on; the solver holds
/// the iteration matrix and decides when to rebuild it.
pub trait NonlinearSystem {
    /// The residual at the current iterate into `data.residual` and, when `matrix`, the
    /// iteration matrix into `data.values` with `-regularization` on the diagonal of the
    /// constraint block.
    fn assemble(&mut self, data: &mut Data, matrix: bool, regularization: f64);
    /// Called after a fresh matrix is assembled, before it is factorized.
    fn matrix_assembled(&mut self, _data: &mut Data) {}
    /// The Newton correction into `data.correction`, the matrix being factorized in
    /// `data.solver`: by default `dx = -S^-1 R`.
    fn correction(&mut self, data: &mut Data) -> Result<(), NewtonError> {
        newton_correction(data);
        Ok(())
    }
    /// Applies `data.correction` to the iterate.
    fn apply(&mut self, data: &Data);
    /// Weighted norms of `data.correction` at the current iterate.
    fn norms(&self, data: &Data) -> Norms;
    /// Whether a fresh matrix without regularization is the exact Jacobian `dR/dx` at the
    /// iterate (quadratic convergence; see [`Convergence`]).
    fn exact_matrix(&self) -> bool {
        true
    }
    /// Whether a fresh matrix is exact or so close to it that its own contraction is far
    /// below [`NewtonSettings::max_contraction`]: a reused one is then rebuilt on the rates
    /// of the blocks outside the tolerance, as an exact one ([`Convergence::matrix_rate`]).
    /// Its iterates are still accepted on measured rates unless [`Self::exact_matrix`].
    fn near_exact_matrix(&self) -> bool {
        self.exact_matrix()
    }
    /// Puts the iterate back to its start, for a second attempt with a fresh matrix.
    fn restart(&mut self) {}
}

/// `data.correction = -S^-1 data.residual` with the factorization in `data.solver`.
pub fn newton_correction(data: &mut Data) {
    let dx = &mut data.correction;
    for (d, r) in dx.iter_mut().zip(&data.residual) {
        *d = -r;
    }
    data.solver.solve_in_place(dx);
}

/// Why a solve's multipliers could not be converged to the tolerance (its other unknowns
/// were): the solve is accepted on the other blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MultiplierLimit {
    /// A singular configuration (regularized matrix): the equations do not determine them,
    /// nor, in the stabilized form, the stabilization unknowns along the same rows, which
    /// are then judged on the size of their correction alone (within the tolerance).
    Undetermined,
    /// Round-off of an ill-conditioned system: their corrections no longer halve from one
    /// correction with the exact matrix to the next.
    RoundOff,
}

/// What [`NewtonSolver`] remembers between solves (a checkpoint's part).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NewtonMemory {
    /// `(key, regularization)` of the factorized matrix, `None` if there is none.
    matrix: Option<(f64, f64)>,
    /// Solves since the matrix was last factorized.
    age: usize,
    /// Rebuild the matrix at every iteration of the next attempt.
    fresh_only: bool,
    /// Solves left with the regularization on.
    regularized_solves: usize,
}

impl NewtonMemory {
    /// Whether a factorized matrix is held.
    pub fn holds_matrix(&self) -> bool {
        self.matrix.is_some()
    }
}

/// What a converged solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NewtonInfo {
    /// Corrections computed (all attempts).
    pub iterations: usize,
    /// Corrections of the attempt that converged.
    pub final_iterations: usize,
    pub factorizations: usize,
    /// Attempts that failed with a reused matrix and were repeated with fresh ones.
    pub retries: usize,
    /// Whether the converged attempt used a reused matrix.
    pub reused_matrix: bool,
    /// Set when the multipliers were not converged (the other unknowns were).
    pub multiplier_limit: Option<MultiplierLimit>,
    /// Weighted norm of the last multiplier correction.
    pub multiplier_norm: f64,
    /// Whether the matrix was regularized.
    pub regularized: bool,
    /// What the verify mode measured (`None` when it is off).
    pub check: Option<Check>,
}

/// A failed solve: the error and the work done.
#[derive(Clone, Debug, PartialEq)]
pub struct NewtonFailure {
    pub error: NewtonError,
    pub info: NewtonInfo,
}

/// How [`NewtonSolver`] treats a system.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonPolicy {
    pub settings: NewtonSettings,
    /// Regularize a singular constraint block ([`REGULARIZATION`]) for this many solves
    /// instead of failing (0: fail).
    pub regularized_solves: usize,
    /// A fresh matrix whose iterates contract more slowly than this rate, from iteration
    /// `diverge_after` on, fails the solve as diverging.
    pub divergence_rate: f64,
    pub diverge_after: usize,
    /// Accept an iterate reached with the exact matrix on the size of its correction alone
    /// (`|dx| <= 1`), never on the rate estimate of [`Convergence`]: statics, whose
    /// continuation paths are followed from where each step stops.
    pub exact_by_size: bool,
}

/// Size of the constraint-block regularization when it is on, relative to the mass block
/// (normalized to O(1)). It makes the iteration matrix regular at a singular configuration
/// (a transient rank loss of `B`, as in a four-bar passing its dead point) and tends to the
/// least-norm multipliers; the residual is unchanged, so a converged solution is exact.
pub const REGULARIZATION: f64 = 1e-9;

/// A solve that needed more iterations than this with a reused dense matrix has the matrix
/// rebuilt at the next solve (full Newton typically needs 2 to 3).
const STALE_ITERATIONS: usize = 3;

/// The one Newton iteration of flexmb, with its policies: the acceptance test
/// ([`Convergence`], module documentation), reuse of the factorized matrix across
/// iterations and solves (a chord method) while it contracts fast, a second attempt with a
/// fresh matrix when an attempt with a reused one fails, regularization of a singular
/// constraint block, and the verify mode.
///
/// The matrix is reused while its key (e.g. the step size) and regularization are those
/// of the factorized one; it is rebuilt when the contraction rate exceeds
/// [`NewtonSettings::max_contraction`] (for a large sparse matrix only from the third
/// iteration, or above 1: the first rate carries the predictor's error; where a fresh
/// matrix is exact, the first rate only of the blocks the predictor left outside the tolerance,
/// [`Convergence::matrix_rate`]), after
/// [`NewtonSettings::max_jacobian_age`] solves, and, for dense (small) systems, at the next
/// solve after one that needed more than 3 iterations with it.
pub struct NewtonSolver {
    pub policy: NewtonPolicy,
    /// What it remembers between solves.
    memory: NewtonMemory,
    /// Verify mode: every accepted iterate re-checked ([`NewtonInfo::check`]).
    verify: bool,
    /// Values of the verify mode's matrix (kept apart, so that `data.values` always holds
    /// the factorized matrix).
    verify_values: Vec<f64>,
    /// The second factorization of the verify mode.
    verify_solver: Option<LinearSolver>,
}

impl NewtonSolver {
    pub fn new(policy: NewtonPolicy, verify: bool) -> Self {
        Self {
            policy,
            memory: NewtonMemory {
                matrix: None,
                age: 0,
                fresh_only: false,
                regularized_solves: 0,
            },
            verify,
            verify_values: Vec::new(),
            verify_solver: None,
        }
    }

    /// What the solver remembers between solves, for a checkpoint.
    pub(crate) fn memory(&self) -> NewtonMemory {
        self.memory
    }

    /// Restores what [`NewtonSolver::memory`] returned; the matrix it names must be
    /// factorized in the data.
    pub(crate) fn restore(&mut self, memory: NewtonMemory) {
        self.memory = memory;
    }

    /// Whether a factorized matrix is held (its values are `data.values`).
    pub fn holds_matrix(&self) -> bool {
        self.memory.holds_matrix()
    }

    /// Forgets the factorized matrix (the data was rebuilt).
    pub fn forget_matrix(&mut self) {
        self.memory.matrix = None;
        self.verify_solver = None;
    }

    /// Keeps the regularization on for the next solves (after a rejected step).
    pub fn regularize_next(&mut self) {
        self.memory.regularized_solves = self.policy.regularized_solves;
    }

    /// Solves the system from its current iterate. `key` identifies the matrix (a reused
    /// one must have been built with the same key). An attempt that fails with a reused
    /// matrix is repeated once from the start with fresh ones.
    pub fn solve<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        data: &mut Data,
        key: f64,
    ) -> Result<NewtonInfo, NewtonFailure> {
        let mut info = NewtonInfo::default();
        loop {
            let result = self.attempt(sys, data, key, &mut info);
            match result {
                Ok(()) => return Ok(info),
                Err(_) if info.reused_matrix => {
                    // Iterations with a reused matrix may have led Newton astray: once more
                    // from the start, with fresh matrices.
                    info.retries += 1;
                    self.memory.fresh_only = true;
                    sys.restart();
                }
                Err(error) => return Err(NewtonFailure { error, info }),
            }
        }
    }

    fn attempt<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        data: &mut Data,
        key: f64,
        info: &mut NewtonInfo,
    ) -> Result<(), NewtonError> {
        let newton = self.policy.settings;
        let mut regularization = if self.memory.regularized_solves > 0 {
            REGULARIZATION
        } else {
            0.0
        };
        self.memory.regularized_solves = self.memory.regularized_solves.saturating_sub(1);
        let mut convergence = Convergence {
            exact_by_size: self.policy.exact_by_size,
            ..Convergence::default()
        };
        // Of the unknowns other than the multipliers: where the multipliers cannot be
        // converged, the solve is accepted on these.
        let mut configuration = convergence;
        let mut previous_mu = None;
        let same_matrix = self
            .memory
            .matrix
            .is_some_and(|(k, reg)| (k - key).abs() <= 1e-6 * key.abs() && reg == regularization);
        let mut refresh = !newton.reuse_jacobian
            || self.memory.fresh_only
            || !same_matrix
            || self.memory.age >= newton.max_jacobian_age;
        let fresh_only = std::mem::take(&mut self.memory.fresh_only);
        info.reused_matrix = false;
        // Iteration at which the matrix was last rebuilt (0: a reused matrix).
        let mut last_factorization = 0;
        let result = (|| {
            for iteration in 1..=newton.max_iterations {
                // Without reuse every iteration is a full Newton iteration.
                let fresh = refresh || fresh_only || !newton.reuse_jacobian;
                info.reused_matrix |= !fresh;
                sys.assemble(data, fresh, regularization);
                if let Some(i) = data.residual.iter().position(|r| !r.is_finite()) {
                    return Err(NewtonError::NonFiniteResidual { unknown: i });
                }
                if fresh {
                    sys.matrix_assembled(data);
                    info.factorizations += 1;
                    let mut factorized = data.solver.factorize(&data.values);
                    if matches!(factorized, Err(LinearError::Singular { .. }))
                        && regularization == 0.0
                        && self.policy.regularized_solves > 0
                    {
                        regularization = REGULARIZATION;
                        self.memory.regularized_solves = self.policy.regularized_solves;
                        sys.assemble(data, true, regularization);
                        info.factorizations += 1;
                        factorized = data.solver.factorize(&data.values);
                    }
                    if let Err(e) = factorized {
                        return Err(NewtonError::Singular {
                            unknown: match e {
                                LinearError::Singular { column } => column,
                                _ => None,
                            },
                            source: e,
                        });
                    }
                    self.memory.matrix = Some((key, regularization));
                    self.memory.age = 0;
                    last_factorization = iteration;
                    refresh = false;
                }
                sys.correction(data)?;
                if let Some(i) = data.correction.iter().position(|d| !d.is_finite()) {
                    return Err(NewtonError::NonFiniteCorrection { unknown: i });
                }
                sys.apply(data);
                let norms = sys.norms(data);
                let err = norms.max();
                info.iterations += 1;
                let exact = fresh && regularization == 0.0 && sys.exact_matrix();
                let verdict = convergence.update(&norms.blocks[..norms.n], norms.carried, exact);
                let (blocks, n) = norms.configuration(regularization > 0.0);
                // The configuration alone, for the multipliers' limits below: where the
                // multipliers stall (a dead point, round-off) the accelerations they drive
                // stall with them, and judged there too (`Norms::carried`) the four-bar's
                // steps near its dead points were never settled (Newton failed at 2.66 s).
                let configuration_converged = matches!(
                    configuration.update(&blocks[..n], 0.0, exact),
                    Verdict::Converged { .. }
                );
                // Multipliers that Newton cannot converge further: at a singular configuration
                // (regularized matrix) the equations do not determine them; with the exact
                // matrix, multiplier corrections that no longer halve from one exact
                // correction to the next are round-off (a 100 000-link chain: 3 to 5 times the
                // tolerance, whatever the number of iterations). The solve is then accepted on
                // its configuration, and says so. (The stabilization unknowns left out of the
                // configuration when undetermined must still have moved by less than their
                // tolerance.)
                let mu = norms.multiplier_norm();
                let settled = configuration_converged && norms.stabilization_within();
                let stalled = previous_mu.is_some_and(|(p, _)| mu > 0.5 * p);
                let limit = if regularization > 0.0 {
                    Some(MultiplierLimit::Undetermined)
                } else if exact && stalled && previous_mu.is_some_and(|(_, e)| e) {
                    Some(MultiplierLimit::RoundOff)
                } else {
                    None
                };
                if exact && stalled && settled && limit.is_none() {
                    // The first exact correction after corrections with a reused matrix
                    // starts Newton's quadratic convergence and may well be larger than
                    // theirs: only the next exact one tells round-off. Taking it for round-off
                    // accepted the four-bar near its singular positions after corrections of
                    // up to 3.9e6 times the tolerance, reported as the multipliers' floor,
                    // where `--verify` estimated the error left at 4.4 at most.
                    refresh = true;
                }
                previous_mu = Some((mu, exact));
                let limit = limit.filter(|_| settled);
                let theta = match (verdict, limit) {
                    (Verdict::Continue { theta }, None) => theta,
                    (verdict, limit) => {
                        if matches!(verdict, Verdict::Continue { .. }) {
                            info.multiplier_limit = limit;
                        }
                        info.multiplier_norm = mu;
                        info.final_iterations = iteration;
                        info.regularized = regularization > 0.0;
                        if self.verify {
                            let undetermined = limit == Some(MultiplierLimit::Undetermined);
                            info.check =
                                Some(self.verify_solve(sys, data, regularization, undetermined));
                        }
                        return Ok(iteration);
                    }
                };
                if let Some(theta) = theta.filter(|&t| t > newton.max_contraction) {
                    if !fresh {
                        // A stale matrix converges too slowly: rebuild it and go on. For a
                        // large (sparse) matrix the first rate of a solve is not enough to pay
                        // for a factorization: the first correction carries the predictor's
                        // error, which one block can lose at once, so that a block it then
                        // moves looks slow (a 1000-link chain: multipliers 0.37 -> 0.26, truly
                        // converging at 0.007); only a first rate above 1 rebuilds it, later
                        // rates above the threshold do. A small (dense) matrix is cheap to
                        // rebuild at once, on the first rate of the blocks the predictor left
                        // outside the tolerance ([`Convergence::matrix_rate`]) when a fresh
                        // matrix is exact; from the third correction on, or with an
                        // approximate matrix (the stabilized form, which accepts on rates
                        // alone: a gear mesh under a driven pinion stalls its zeta there at a
                        // rate of 1; a regularized one), every block's rate counts.
                        let dense = data.solver.backend() == Backend::Dense;
                        let exact_when_fresh = sys.near_exact_matrix() && regularization == 0.0;
                        let rate = if iteration >= 3 || !exact_when_fresh {
                            Some(theta)
                        } else {
                            convergence.matrix_rate()
                        };
                        if let Some(rate) = rate.filter(|&t| t > newton.max_contraction) {
                            if dense || iteration >= 3 || rate > 1.0 {
                                refresh = true;
                            }
                        }
                    } else if iteration >= self.policy.diverge_after
                        && theta > self.policy.divergence_rate
                    {
                        return Err(NewtonError::Diverging {
                            error: err,
                            rate: theta,
                            unknown: norms.worst,
                        });
                    }
                }
                if iteration == newton.max_iterations {
                    return Err(NewtonError::MaxIterations {
                        iterations: iteration,
                        error: err,
                        unknown: norms.worst,
                    });
                }
            }
            unreachable!("max_iterations >= 1")
        })();
        match result {
            Ok(iterations) => {
                self.memory.age += 1;
                // Iterations done with the matrix the next solve would reuse.
                if iterations - last_factorization.saturating_sub(1) > STALE_ITERATIONS
                    && data.solver.backend() == Backend::Dense
                {
                    // The reused matrix has drifted from the current one: a small (dense)
                    // matrix is cheaper to rebuild for the next solve than extra iterations
                    // at every one. A large sparse factorization costs several iterations,
                    // so it waits for the contraction test.
                    self.memory.age = newton.max_jacobian_age;
                }
                Ok(())
            }
            Err(e) => {
                self.memory.matrix = None;
                Err(e)
            }
        }
    }

    /// Verify mode: a Newton correction from the accepted iterate with a freshly built and
    /// factorized matrix (a second factorization, so a reused one is kept) estimates the
    /// error left in the solve, in units of the tolerance (NaN when the matrix is singular),
    /// with the unknown of the largest weighted term. Where the multipliers are undetermined
    /// only the other blocks count.
    fn verify_solve<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        data: &mut Data,
        regularization: f64,
        undetermined: bool,
    ) -> Check {
        // `data.values` holds the factorized matrix, which the next solve may reuse: the
        // check's matrix goes to a buffer of its own.
        self.verify_values.resize(data.values.len(), 0.0);
        std::mem::swap(&mut data.values, &mut self.verify_values);
        sys.assemble(data, true, regularization);
        if self.verify_solver.is_none() {
            self.verify_solver = LinearSolver::new(data.residual.len(), &data.pattern()).ok();
        }
        let factorized = self
            .verify_solver
            .as_mut()
            .and_then(|solver| solver.factorize(&data.values).ok().map(|()| solver));
        let check = match factorized {
            None => Check::default(),
            Some(solver) => {
                let dx = &mut data.correction;
                for (d, r) in dx.iter_mut().zip(&data.residual) {
                    *d = -r;
                }
                solver.solve_in_place(dx);
                let norms = sys.norms(data);
                let error = if undetermined {
                    let (blocks, n) = norms.configuration(regularization > 0.0);
                    blocks[..n].iter().fold(0.0f64, |m, &v| m.max(v))
                } else {
                    norms.max()
                };
                Check {
                    error,
                    worst: Some(norms.worst),
                }
            }
        };
        std::mem::swap(&mut data.values, &mut self.verify_values);
        check
    }
}

/// What the verify mode measured at an accepted iterate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Check {
    /// Estimated error in units of the tolerance (NaN: no estimate, singular matrix).
    pub error: f64,
    /// The unknown with the largest weighted correction.
    pub worst: Option<usize>,
}

impl Default for Check {
    fn default() -> Self {
        Self {
            error: f64::NAN,
            worst: None,
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
                    if let Verdict::Converged { estimate } = c.update(&[dx], 0.0, false) {
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
        assert_eq!(
            c.update(&[1e-3], 0.0, false),
            Verdict::Continue { theta: None }
        );
        let mut c = Convergence::default();
        assert_eq!(
            c.update(&[0.0], 0.0, false),
            Verdict::Converged { estimate: 0.0 }
        );
    }

    /// A correction judged where it lands (`carried`): while it contracts, its rate and size
    /// bound the error, so blocks converged in the configuration's norm do not accept an
    /// iterate whose accelerations are still outside the tolerance; once it stops shrinking
    /// (round-off of the accelerations) it is left out.
    #[test]
    fn carried_norm_bounds_the_error_while_it_contracts() {
        let mut c = Convergence::default();
        c.update(&[1e-2], 50.0, false);
        // Blocks alone: rate 0.1, estimate 1e-4 (accepted); carried: rate 0.5, size 25.
        match c.update(&[1e-3], 25.0, false) {
            Verdict::Continue { theta } => assert!((theta.unwrap() - 0.1).abs() < 1e-12),
            v => panic!("{v:?}"),
        }
        // The carried norm down to 2.5e-3: the estimate is the slowest rate (the blocks')
        // times the largest norm, the carried one.
        match c.update(&[1e-4], 2.5e-3, false) {
            Verdict::Converged { estimate } => {
                assert!((estimate - 0.1 / 0.9 * 2.5e-3).abs() < 1e-15, "{estimate}")
            }
            v => panic!("{v:?}"),
        }
        // Round-off: the carried norm grows while the blocks shrink, and no longer counts
        // (counted, its rate of 1.2 would keep iterating).
        let mut c = Convergence::default();
        c.update(&[1e-2], 0.5, false);
        assert!(matches!(
            c.update(&[1e-4], 0.6, false),
            Verdict::Converged { .. }
        ));
        // An exact correction is accepted on the blocks' size whatever the carried norm.
        let mut c = Convergence::default();
        assert!(matches!(
            c.update(&[0.5], 80.0, true),
            Verdict::Converged { estimate } if estimate == 0.5
        ));
    }

    /// The slowest block sets the rate: a block that lost most of its (predictor) error in
    /// the first correction does not hide a slowly converging one.
    #[test]
    fn slowest_block_sets_the_rate() {
        let mut c = Convergence::default();
        assert!(matches!(
            c.update(&[0.85, 54.0], 0.0, false),
            Verdict::Continue { .. }
        ));
        match c.update(&[0.17, 0.59], 0.0, false) {
            Verdict::Continue { theta } => assert!((theta.unwrap() - 0.2).abs() < 1e-12),
            v => panic!("{v:?}"),
        }
        // A block that was exactly zero and no longer is: no rate can be claimed.
        let mut c = Convergence::default();
        c.update(&[1.0, 0.0], 0.0, false);
        assert!(matches!(
            c.update(&[1e-3, 1e-3], 0.0, false),
            Verdict::Continue { .. }
        ));
    }

    /// An exact Newton correction below the tolerance is accepted at once; a diverging
    /// sequence never is.
    #[test]
    fn exact_correction_accepted_and_divergence_is_not() {
        let mut c = Convergence::default();
        assert_eq!(
            c.update(&[0.5], 0.0, true),
            Verdict::Converged { estimate: 0.5 }
        );
        let mut c = Convergence::default();
        for dx in [2.0, 4.0, 8.0, 16.0] {
            assert!(matches!(
                c.update(&[dx], 0.0, false),
                Verdict::Continue { .. }
            ));
        }
    }
}
