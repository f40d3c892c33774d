//! Lie group generalized-alpha time integration of the index-3 DAE
//!
//! ```text
//! M vdot - hat(v)^T M v + g(q, t) + B(q)^T lambda = 0,    Phi(q, t) = 0,
//! ```
//!
//! one step `n -> n+1` (Brüls & Cardona 2010, Eqs. (40)-(44); Arnold & Brüls 2007):
//!
//! ```text
//! q_{n+1} = q_n exp(tilde(dq)),   dq = h v_n + (1/2 - beta) h^2 a_n + beta h^2 a_{n+1}
//! v_{n+1} = v_n + (1 - gamma) h a_n + gamma h a_{n+1}
//! (1 - alpha_m) a_{n+1} + alpha_m a_n = (1 - alpha_f) vdot_{n+1} + alpha_f vdot_n
//! ```
//!
//! **Stabilized index-2 formulation** (Gear, Gupta & Leimkuhler 1985 on the Lie group:
//! Arnold, Brüls & Cardona 2015, Numer. Math. 129, Sect. 3; Arnold & Hante 2017): the
//! velocity-level constraint `B(q) v + Phi_t = 0` is imposed at `t_{n+1}` as well, with one
//! more unknown `zeta` per constraint row that moves the configuration only,
//! `q_{n+1} = q_n exp(tilde(dq + B(q_n)^T zeta))`. It removes the weak instability of the
//! index-3 form without numerical damping (`rho_inf = 1`), at the cost of `m` more unknowns;
//! [`Formulation::Auto`] uses it for `rho_inf >= 0.95`.
//!
//! The step reads as a checklist: `predict`, then repeat { `update_configuration`,
//! `assemble` (residual and iteration matrix), `factorize`, `solve`, `correct`, judge the
//! weighted corrections with [`Convergence`] } until the accepted iterate's error is within
//! the tolerance (see [`super::newton`]: a correction from a reused matrix is never taken
//! for the error), then `finish_step` (configuration and algorithmic acceleration). A failed
//! step is retried first with a fresh iteration matrix if it used a reused one, then with
//! redundant constraint rows chosen again if they change ([`initial::reselect_redundant_rows`]),
//! then with a quarter of the step size down to `h_min`; the run stops with a diagnosis
//! (step, time, the worst equation and its node or joint) below `h_min` or when step
//! reductions keep coming back (more than 100 plus one per 10 accepted steps). The output
//! callback is called at every output time, so what was computed is never lost; output
//! times and `t_end` are reached exactly, by steps never shorter than `h / 2`.

use super::generalized_alpha::GaParameters;
use super::initial::{self, initial_accelerations, load_nodes, mass_scale, prepare_layout};
use super::linear::{Backend, LinearError, LinearSolver};
use super::newton::{weighted_norm, Convergence, NewtonSettings, Verdict, Verification};
use crate::assembly::{assemble, ConstraintRhs, Scaling};
use crate::data::{Data, Layout};
use crate::elements::Coefficients;
use crate::error::{SettingsError, SolveError};
use crate::model::Model;
use crate::state::State;
use flexmb_lie::Vec6;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Which form of the constraints the integrator imposes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Formulation {
    /// Position-level constraints only (index 3).
    Index3,
    /// Position- and velocity-level constraints (stabilized index 2, GGL).
    StabilizedIndex2,
    /// Index 3 for `rho_inf < 0.95`, stabilized index 2 above (where index 3 without
    /// numerical damping can become unstable).
    Auto,
}

/// The member of the generalized-alpha family to use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scheme {
    /// Chung & Hulbert's optimal parameters for `DynamicSettings::rho_inf`.
    GeneralizedAlpha,
    /// HHT-alpha (Hilber, Hughes & Taylor 1977), `alpha` in `[0, 1/3]`.
    Hht { alpha: f64 },
    /// Newmark with `alpha_m = alpha_f = 0` (`beta = 1/4, gamma = 1/2`: trapezoidal rule).
    Newmark { beta: f64, gamma: f64 },
}

impl Scheme {
    /// Spectral radius at infinity: how much the scheme damps the highest frequencies
    /// (1: not at all). Newmark with `gamma > 1/2` counts as damped.
    pub fn spectral_radius_at_infinity(&self, rho_inf: f64) -> f64 {
        match *self {
            Scheme::GeneralizedAlpha => rho_inf,
            Scheme::Hht { alpha } => (1.0 - alpha) / (1.0 + alpha),
            Scheme::Newmark { gamma, .. } => {
                if gamma <= 0.5 + 1e-12 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }

    /// The four parameters of the scheme.
    pub fn parameters(&self, rho_inf: f64) -> GaParameters {
        match *self {
            Scheme::GeneralizedAlpha => GaParameters::from_rho_inf(rho_inf),
            Scheme::Hht { alpha } => GaParameters::hht(alpha),
            Scheme::Newmark { beta, gamma } => GaParameters {
                alpha_m: 0.0,
                alpha_f: 0.0,
                beta,
                gamma,
            },
        }
    }
}

/// Settings of a dynamic analysis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynamicSettings {
    /// Final time \[s\].
    pub t_end: f64,
    /// Nominal step size \[s\].
    pub h: f64,
    /// Spectral radius at infinity, in `[0, 1]`.
    pub rho_inf: f64,
    /// Time between outputs \[s\]; 0 for every step.
    pub output_interval: f64,
    /// Smallest step size tried before giving up \[s\].
    pub h_min: f64,
    pub newton: NewtonSettings,
    pub formulation: Formulation,
    pub scheme: Scheme,
    /// Nodal viscous damping `alpha D v` [1/s] (0: none); for pseudo-dynamic statics.
    pub nodal_damping: f64,
    /// Loads and gravity grow linearly from 0 over this time and then stay \[s\] (0: applied
    /// at once).
    pub load_ramp: f64,
    /// Factor on loads and gravity (1 in a dynamic analysis; the target load factor of a
    /// pseudo-dynamic static analysis).
    pub load_scale: f64,
    /// Re-check every accepted step with a freshly built matrix and record the largest
    /// estimated error ([`Simulation::verification`]); costs one more factorization per
    /// step.
    pub verify: bool,
}

impl DynamicSettings {
    /// Factor on loads and gravity at time `t` (the ramp, if any).
    pub fn load_factor_at(&self, t: f64) -> f64 {
        let ramp = if self.load_ramp > 0.0 {
            (t / self.load_ramp).clamp(0.0, 1.0)
        } else {
            1.0
        };
        self.load_scale * ramp
    }

    /// Rejects settings out of their ranges (`docs/model-format.md`, "Ranges"): every
    /// derived quantity (`beta'`, `gamma'`, `h_min`, the number of steps and outputs) is
    /// finite, normal and bounded, so that no loop of the run can stall on an underflow or
    /// run for ever. The model-file reader reports these errors at their keys.
    pub fn check(&self) -> Result<(), SettingsError> {
        use crate::model::limits::{MAX_STEPS, MAX_TIME, MIN_STEP};
        SettingsError::positive("t_end", self.t_end, MIN_STEP, MAX_TIME)?;
        SettingsError::positive("h", self.h, MIN_STEP, MAX_TIME)?;
        let steps = self.t_end / self.h;
        if steps > MAX_STEPS {
            return Err(SettingsError::new(
                &["h", "t_end"],
                format!(
                    "t_end / h = {steps:e} steps exceeds {MAX_STEPS:e} (t_end = {:e}, h = {:e}): beyond it t + h loses the precision of the step; increase h or reduce t_end",
                    self.t_end, self.h
                ),
            ));
        }
        SettingsError::range("rho_inf", self.rho_inf, 0.0, 1.0)?;
        let out = self.output_interval;
        if out != 0.0 {
            SettingsError::positive("output_interval", out, MIN_STEP, MAX_TIME)?;
            if self.t_end / out > MAX_STEPS {
                return Err(SettingsError::new(
                    &["output_interval", "t_end"],
                    format!(
                        "t_end / output_interval = {:e} outputs exceeds {MAX_STEPS:e}: give 0 (every step) or a longer interval",
                        self.t_end / out
                    ),
                ));
            }
        }
        if !(MIN_STEP * self.h <= self.h_min && self.h_min <= self.h) {
            return Err(SettingsError::new(
                &["h_min", "h"],
                format!(
                    "must be between 1e-12 h = {:e} and h = {:e}, got {:e}",
                    MIN_STEP * self.h,
                    self.h,
                    self.h_min
                ),
            ));
        }
        match self.scheme {
            Scheme::GeneralizedAlpha => {}
            Scheme::Hht { alpha } => SettingsError::range("hht_alpha", alpha, 0.0, 1.0 / 3.0)?,
            Scheme::Newmark { beta, gamma } => {
                let stable = (0.5..=10.0).contains(&gamma)
                    && (0.25 * (gamma + 0.5).powi(2) - 1e-12..=100.0).contains(&beta);
                if !stable {
                    return Err(SettingsError::new(
                        &["newmark_beta", "newmark_gamma", "scheme"],
                        format!(
                            "Newmark needs gamma in [1/2, 10] and beta in [(gamma + 1/2)^2 / 4, 100] for unconditional stability, got beta = {beta}, gamma = {gamma}"
                        ),
                    ));
                }
            }
        }
        let p = self.scheme.parameters(self.rho_inf);
        let derived = [p.beta_prime(self.h), p.gamma_prime(self.h)];
        if derived.iter().any(|d| !d.is_normal()) {
            return Err(SettingsError::new(
                &["h"],
                format!("{:e} s gives a non-finite beta' or gamma'", self.h),
            ));
        }
        self.newton.check()
    }

    /// Whether the stabilized index-2 formulation is used.
    pub fn stabilized(&self) -> bool {
        match self.formulation {
            Formulation::Index3 => false,
            Formulation::StabilizedIndex2 => true,
            Formulation::Auto => self.scheme.spectral_radius_at_infinity(self.rho_inf) >= 0.95,
        }
    }
}

impl DynamicSettings {
    /// Defaults for a given end time and step.
    pub fn new(t_end: f64, h: f64) -> Self {
        Self {
            t_end,
            h,
            rho_inf: 0.9,
            output_interval: 0.0,
            h_min: h * 1e-4,
            newton: NewtonSettings::default(),
            formulation: Formulation::Auto,
            scheme: Scheme::GeneralizedAlpha,
            nodal_damping: 0.0,
            load_ramp: 0.0,
            load_scale: 1.0,
            verify: false,
        }
    }
}

/// Work done by a solver, for summaries and for spotting cost changes in review.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stats {
    pub steps: usize,
    pub newton_iterations: usize,
    pub rejected_steps: usize,
    pub factorizations: usize,
    pub max_iterations_in_a_step: usize,
    /// Steps accepted at a singular configuration (regularized constraint block) with the
    /// configuration converged and the multipliers not determined by the equations.
    pub undetermined_multipliers: usize,
    /// Times the redundant constraint rows were chosen again as the mechanism moved.
    pub reselections: usize,
    /// Shortest accepted step \[s\] (0 before the first).
    pub smallest_step: f64,
    /// Steps accepted with the multipliers at their round-off floor above the tolerance
    /// (exact matrix, configuration converged, multiplier corrections no longer decreasing).
    pub multiplier_floor_steps: usize,
    /// Largest weighted multiplier correction of those steps (in units of the tolerance).
    pub multiplier_floor: f64,
}

/// Why a step failed (before step-size reduction decides what to do).
#[derive(Clone, Debug)]
struct StepFailure {
    reason: String,
    worst_unknown: Option<usize>,
}

/// A dynamic analysis in progress: model (borrowed, immutable), data and state.
pub struct Simulation<'m> {
    pub model: &'m Model,
    pub data: Data,
    pub state: State,
    pub settings: DynamicSettings,
    pub params: GaParameters,
    pub stats: Stats,
    /// Notes for the user (e.g. redundant constraints removed).
    pub warnings: Vec<String>,
    /// Checked before every step: when it is set, [`Simulation::run`] returns
    /// [`SolveError::Interrupted`] with every completed output step already delivered.
    pub interrupt: Option<Arc<AtomicBool>>,
    /// What [`DynamicSettings::verify`] found (`None` when it is off).
    pub verification: Option<Verification>,
    /// The second factorization of `verify`.
    verify_solver: Option<LinearSolver>,
    /// Round-off floor of the scaled multipliers' tolerance (`n_active`).
    mu_floor: Vec<f64>,
    /// Smallest relative pivot of the first factorization after the redundant rows were
    /// chosen (see [`Self::watch_redundant_rows`]).
    pivot_reference: Option<f64>,
    /// Time of the first re-selection of redundant rows.
    first_reselection: f64,
    /// State at the start of the current step (restored when a step is rejected).
    saved: State,
    /// Largest nodal mass of the model \[kg\]: the equilibrium rows are divided by it.
    mass: f64,
    /// Steps left with the regularization on (switched on by a singular matrix or a failure).
    regularized_steps: usize,
    /// `(h, regularization)` of the factorized iteration matrix, `None` if there is none.
    jacobian: Option<(f64, f64)>,
    /// Steps since the iteration matrix was last factorized.
    jacobian_age: usize,
    /// Configuration increments of the current step (scratch, `6 n_nodes`).
    increments: Vec<f64>,
    /// Total increments `dq + B(q_n)^T zeta` (stabilized formulation; scratch, `6 n_nodes`).
    total: Vec<f64>,
    /// Stabilization unknowns of the current step (`n_active`).
    zeta: Vec<f64>,
    /// Accelerations and multipliers at the start of the previous step, for the predictor.
    previous: Previous,
    /// Whether the current step iterated with a reused (stale) iteration matrix.
    used_stale_matrix: bool,
    /// Rebuild the iteration matrix at every iteration of the next step.
    fresh_only: bool,
}

/// Why a step's multipliers could not be converged to the tolerance (its configuration was).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum MultiplierLimit {
    /// A singular configuration: the equations do not determine them.
    Undetermined,
    /// Round-off of an ill-conditioned system.
    RoundOff,
}

/// Weighted norms of one Newton correction ([`super::newton::weighted_norm`]).
struct CorrectionNorms {
    q: f64,
    worst_q: usize,
    mu: f64,
    worst_mu: usize,
    zeta: f64,
}

impl CorrectionNorms {
    fn all(&self) -> f64 {
        self.q.max(self.mu).max(self.zeta)
    }

    /// Configuration and stabilization unknowns (not the multipliers).
    fn configuration(&self) -> f64 {
        self.q.max(self.zeta)
    }

    /// The unknown with the largest weighted correction.
    fn worst(&self) -> usize {
        if self.q >= self.mu {
            self.worst_q
        } else {
            self.worst_mu
        }
    }
}

/// Start of the previous accepted step (`h = 0` when there is none).
#[derive(Clone, Debug, Default)]
struct Previous {
    h: f64,
    vdot: Vec<Vec6>,
    lambda: Vec<f64>,
}

/// Size of the constraint-block regularization when it is on (see [`Scaling`]), relative to
/// the mass block (normalized to O(1)).
const REGULARIZATION: f64 = 1e-9;

/// Steps that keep the regularization after a singular matrix or a rejected step.
const REGULARIZED_STEPS: usize = 20;

/// A step that needed more iterations than this with a reused dense matrix has the matrix
/// rebuilt at the next step (full Newton typically needs 2 to 3).
const STALE_ITERATIONS: usize = 3;

impl<'m> Simulation<'m> {
    /// Validates the model, builds the data and computes consistent initial conditions.
    pub fn new(model: &'m Model, settings: DynamicSettings) -> Result<Self, SolveError> {
        model
            .validate()
            .map_err(|e| SolveError::Model(e.to_string()))?;
        settings.check()?;
        let (layout, warnings) = prepare_layout(model);
        let n_rows = layout.n_rows;
        let model_error = |e: LinearError| SolveError::Model(e.to_string());
        let mut data = Data::new(model, layout.clone()).map_err(model_error)?;
        let mut state = State::initial(model, n_rows);
        initial_accelerations(model, &mut data, &mut state, settings.load_factor_at(0.0))?;
        if settings.stabilized() {
            let mut stabilized = layout;
            stabilized.stabilized = true;
            data = Data::new(model, stabilized).map_err(model_error)?;
            load_nodes(&state, &mut data);
        }
        Ok(Self {
            model,
            saved: state.clone(),
            data,
            state,
            params: settings.scheme.parameters(settings.rho_inf),
            settings,
            stats: Stats::default(),
            warnings,
            interrupt: None,
            verification: None,
            verify_solver: None,
            mu_floor: Vec::new(),
            pivot_reference: None,
            first_reselection: 0.0,
            mass: mass_scale(model),
            regularized_steps: 0,
            jacobian: None,
            jacobian_age: 0,
            increments: Vec::new(),
            total: Vec::new(),
            zeta: Vec::new(),
            previous: Previous::default(),
            used_stale_matrix: false,
            fresh_only: false,
        })
    }

    /// Runs to `t_end`, calling `output` at t = 0 and at every output time. Stops at the
    /// first error of `output` or when a step cannot be completed even at `h_min`.
    pub fn run(
        &mut self,
        output: &mut dyn FnMut(&Simulation) -> Result<(), String>,
    ) -> Result<Stats, SolveError> {
        let result = self.run_steps(output);
        if self.stats.undetermined_multipliers > 0 {
            self.warnings.push(format!(
                "{} steps passed singular configurations (a rank-deficient constraint matrix, e.g. a dead point): positions and velocities are converged there, the multipliers (joint reactions) are not determined by the equations at those steps",
                self.stats.undetermined_multipliers
            ));
        }
        if self.stats.multiplier_floor_steps > 0 {
            self.warnings.push(format!(
                "at {} steps the multipliers (joint reactions) could not be converged below {:.2e} times their tolerance (rtol times the largest force of the model): round-off of an ill-conditioned constraint system; positions and velocities are converged",
                self.stats.multiplier_floor_steps, self.stats.multiplier_floor
            ));
        }
        if self.stats.reselections > 0 {
            self.warnings.push(format!(
                "the redundant constraint rows were chosen again {} times as the mechanism moved (first at t = {:.6e} s), where the rows kept came close to losing rank",
                self.stats.reselections, self.first_reselection
            ));
        }
        if let Some(w) = self.verification.as_ref().and_then(Verification::warning) {
            self.warnings.push(w);
        }
        result
    }

    fn run_steps(
        &mut self,
        output: &mut dyn FnMut(&Simulation) -> Result<(), String>,
    ) -> Result<Stats, SolveError> {
        let s = self.settings;
        let out_dt = s.output_interval;
        output(self).map_err(SolveError::Output)?;
        let mut k_out = 1usize;
        let mut clock = StepClock::new(s.h);
        let mut successes = 0usize;
        let mut reductions = 0usize;
        while self.state.t < s.t_end {
            if interrupted(&self.interrupt) {
                return Err(SolveError::Interrupted {
                    reached: self.state.t,
                });
            }
            let target = if out_dt > 0.0 {
                (k_out as f64 * out_dt).min(s.t_end)
            } else {
                s.t_end
            };
            let t_new = clock.next(self.state.t, target);
            if t_new <= self.state.t {
                return Err(SolveError::StepUnderflow {
                    t: self.state.t,
                    h: clock.h,
                });
            }
            let h_try = t_new - self.state.t;
            match self.step(t_new) {
                Ok(iterations) => {
                    self.stats.steps += 1;
                    self.stats.max_iterations_in_a_step =
                        self.stats.max_iterations_in_a_step.max(iterations);
                    self.watch_redundant_rows();
                    if self.stats.steps == 1 || h_try < self.stats.smallest_step {
                        self.stats.smallest_step = h_try;
                    }
                    successes += 1;
                    clock.advance(t_new);
                    if clock.h < s.h && successes >= 4 {
                        clock.restart(t_new, (2.0 * clock.h).min(s.h));
                        successes = 0;
                    }
                    let reached = self.state.t == target;
                    if out_dt == 0.0 || reached {
                        output(self).map_err(SolveError::Output)?;
                        if reached && out_dt > 0.0 {
                            k_out += 1;
                        }
                    }
                }
                Err(failure) => {
                    self.stats.rejected_steps += 1;
                    if self.used_stale_matrix {
                        // Iterations with a reused matrix may have led Newton astray: retry
                        // the same step with a fresh matrix before reducing it.
                        self.state = self.saved.clone();
                        self.used_stale_matrix = false;
                        self.fresh_only = true;
                        continue;
                    }
                    self.state = self.saved.clone();
                    if self.reselect_redundant_rows() {
                        // The rows kept as independent had lost rank: retry with new ones.
                        continue;
                    }
                    self.regularized_steps = REGULARIZED_STEPS;
                    successes = 0;
                    clock.restart(self.state.t, h_try * 0.25);
                    reductions += 1;
                    // Give up when the step can no longer shrink, or when rejections keep
                    // coming back after the step size recovers (an unstable solution).
                    // (Retries with a fresh matrix above do not count: they do not reduce h.)
                    let thrashing = reductions > 100 + self.stats.steps / 10;
                    if clock.h < s.h_min || thrashing {
                        let worst = failure
                            .worst_unknown
                            .map(|i| self.data.layout.describe_unknown(self.model, i))
                            .unwrap_or_else(|| "unknown".into());
                        return Err(SolveError::NewtonFailed {
                            step: self.stats.steps + 1,
                            t: self.state.t,
                            h: h_try,
                            reductions,
                            reason: if thrashing {
                                format!(
                                    "{} ({} steps rejected so far)",
                                    failure.reason, self.stats.rejected_steps
                                )
                            } else {
                                failure.reason
                            },
                            worst_equation: worst,
                        });
                    }
                }
            }
        }
        Ok(self.stats)
    }

    /// After an accepted step of a model with redundant constraint rows: when the smallest
    /// relative pivot of the iteration matrix has fallen a hundredfold since the rows were
    /// chosen, the kept rows may be losing rank; they are chosen again at the current
    /// configuration ([`initial::reselect_redundant_rows`]). A genuine singular
    /// configuration (a dead point) triggers the check too and keeps its rows.
    fn watch_redundant_rows(&mut self) {
        let layout = &self.data.layout;
        if layout.n_active == layout.n_rows {
            return;
        }
        let Some(pivot) = self.data.solver.min_pivot_ratio() else {
            return;
        };
        match self.pivot_reference {
            None => self.pivot_reference = Some(pivot),
            Some(reference) if pivot < 1e-2 * reference => {
                self.reselect_redundant_rows();
                self.pivot_reference = None;
            }
            Some(_) => {}
        }
    }

    /// Chooses the redundant constraint rows again at the current configuration; when they
    /// change, rebuilds the data for the new rows (the multipliers of the rows removed now
    /// are zero; the total constraint force, hence the motion, does not depend on which
    /// rows carry it) and returns `true`.
    fn reselect_redundant_rows(&mut self) -> bool {
        let model = self.model;
        let Some(redundant) =
            initial::reselect_redundant_rows(model, &self.data.layout, &self.state.q)
        else {
            return false;
        };
        let mut layout = Layout::new(model);
        layout.stabilized = self.data.layout.stabilized;
        layout.deactivate_rows(model, &redundant);
        let Ok(data) = Data::new(model, layout) else {
            return false;
        };
        self.data = data;
        load_nodes(&self.state, &mut self.data);
        for &row in &redundant {
            self.state.lambda[row] = 0.0;
        }
        self.saved.clone_from(&self.state);
        self.jacobian = None;
        self.previous.h = 0.0;
        self.verify_solver = None;
        self.pivot_reference = None;
        self.stats.reselections += 1;
        if self.stats.reselections == 1 {
            self.first_reselection = self.state.t;
        }
        true
    }

    /// One generalized-alpha step to `t_new`; returns the Newton iterations used.
    ///
    /// Newton's iteration matrix is reused across iterations and steps while the iteration
    /// contracts fast (a chord method: the converged solution is the same, each iteration is
    /// cheaper); it is rebuilt when `h` or the regularization changes, when the contraction
    /// rate exceeds [`NewtonSettings::max_contraction`], when the iteration diverges, after
    /// [`NewtonSettings::max_jacobian_age`] steps, and, for dense (small) systems, at the next
    /// step after a step that needed more than 3 iterations with it.
    fn step(&mut self, t_new: f64) -> Result<usize, StepFailure> {
        self.saved.clone_from(&self.state);
        let h = t_new - self.saved.t;
        let p = self.params;
        let bp = p.beta_prime(h);
        let gp = p.gamma_prime(h);
        // Equilibrium rows times 1 / (beta' m) with m the largest nodal mass: the mass block
        // is O(1) whatever h and the units of mass, like the constraint block.
        let scale = 1.0 / (bp * self.mass);
        let mut sc = Scaling {
            row_scale: scale,
            coef: Coefficients {
                m: 1.0 / self.mass,
                c: gp * scale,
                k: scale,
            },
            constraint_rhs: ConstraintRhs::Position,
            load_factor: self.settings.load_factor_at(t_new),
            regularization: if self.regularized_steps > 0 {
                REGULARIZATION
            } else {
                0.0
            },
            velocity_scale: 1.0 / gp,
            nodal_damping: self.settings.nodal_damping,
        };
        let stabilized = self.data.layout.stabilized;
        if stabilized {
            crate::assembly::constraint_rows(self.model, &mut self.data, self.saved.t);
            self.data.b_start.clone_from(&self.data.b_rows);
            self.zeta.clear();
            self.zeta.resize(self.data.layout.n_active, 0.0);
        }
        self.regularized_steps = self.regularized_steps.saturating_sub(1);
        let mut dq = std::mem::take(&mut self.increments);
        self.predict(h, &mut dq);
        self.state.t = t_new;
        let max_mu = self.force_scale() * scale;
        let newton = self.settings.newton;
        let mut convergence = Convergence::default();
        // Of the configuration (and stabilization) unknowns alone: at a singular configuration
        // (regularized matrix) the multipliers are not determined.
        let mut configuration = Convergence::default();
        let mut previous_mu = None;
        let same_matrix = self
            .jacobian
            .is_some_and(|(hj, reg)| (hj - h).abs() <= 1e-6 * h && reg == sc.regularization);
        let mut refresh = !newton.reuse_jacobian
            || self.fresh_only
            || !same_matrix
            || self.jacobian_age >= newton.max_jacobian_age;
        let fresh_only = std::mem::take(&mut self.fresh_only);
        self.used_stale_matrix = false;
        let mut result = Err(StepFailure {
            reason: "no iteration".into(),
            worst_unknown: None,
        });
        // Iteration at which the matrix was last rebuilt in this step (0: a reused matrix).
        let mut last_factorization = 0;
        for iteration in 1..=newton.max_iterations {
            let fresh = refresh || fresh_only;
            self.used_stale_matrix |= !fresh;
            let total = self.total_increments(&dq);
            self.update_configuration(&total, fresh);
            self.total = total;
            assemble(
                self.model,
                &mut self.data,
                t_new,
                &self.state.lambda,
                &sc,
                fresh,
            );
            if let Some(i) = self.data.residual.iter().position(|r| !r.is_finite()) {
                result = Err(StepFailure {
                    reason: "non-finite residual".into(),
                    worst_unknown: Some(i),
                });
                break;
            }
            if fresh {
                self.update_multiplier_floor();
                if let Err(failure) = self.factorize(&mut sc) {
                    result = Err(failure);
                    break;
                }
                self.jacobian = Some((h, sc.regularization));
                self.jacobian_age = 0;
                last_factorization = iteration;
                refresh = false;
            }
            if let Err(failure) = self.solve() {
                result = Err(failure);
                break;
            }
            self.correct(&mut dq, gp, bp, scale);
            let norms = self.correction_norms(&dq, max_mu);
            let err = norms.all();
            self.stats.newton_iterations += 1;
            // The matrix is the exact Jacobian at this iterate only when it was just built,
            // without regularization, and for index 3 (the stabilized rows omit the
            // O(h) derivative of B(q) v with respect to q).
            let exact = fresh && sc.regularization == 0.0 && !stabilized;
            let verdict = convergence.update(&[norms.q, norms.mu, norms.zeta], exact);
            let configuration_converged = matches!(
                configuration.update(&[norms.q, norms.zeta], exact),
                Verdict::Converged { .. }
            );
            // Multipliers that Newton cannot converge further: at a singular configuration
            // (regularized matrix) the equations do not determine them; with the exact
            // matrix, multiplier corrections that no longer halve are round-off (a 100 000-
            // link chain: 3 to 5 times the tolerance, whatever the number of iterations).
            // The step is then accepted on its configuration, and the run says so.
            let limit = if sc.regularization > 0.0 {
                Some(MultiplierLimit::Undetermined)
            } else if exact && previous_mu.is_some_and(|p| norms.mu > 0.5 * p) {
                Some(MultiplierLimit::RoundOff)
            } else {
                None
            };
            previous_mu = Some(norms.mu);
            let limit = limit.filter(|_| configuration_converged);
            let theta = match (verdict, limit) {
                (Verdict::Continue { theta }, None) => theta,
                (verdict, limit) => {
                    if matches!(verdict, Verdict::Continue { .. }) {
                        match limit {
                            Some(MultiplierLimit::Undetermined) => {
                                self.stats.undetermined_multipliers += 1;
                            }
                            Some(MultiplierLimit::RoundOff) => {
                                self.stats.multiplier_floor_steps += 1;
                                self.stats.multiplier_floor =
                                    self.stats.multiplier_floor.max(norms.mu);
                            }
                            None => {}
                        }
                    }
                    let total = self.total_increments(&dq);
                    self.finish_step(&total);
                    self.total = total;
                    if self.settings.verify {
                        let undetermined = limit == Some(MultiplierLimit::Undetermined);
                        self.verify_step(&dq, &sc, max_mu, undetermined);
                    }
                    result = Ok(iteration);
                    break;
                }
            };
            let worst = norms.worst();
            if let Some(theta) = theta.filter(|&t| t > newton.max_contraction) {
                if !fresh {
                    // A stale matrix converges too slowly: rebuild it and go on. For a large
                    // (sparse) matrix the first rate of a step is not enough to pay for a
                    // factorization: the first correction carries the predictor's error,
                    // which one block can lose at once, so that a block it then moves looks
                    // slow (a 1000-link chain: multipliers 0.37 -> 0.26, truly converging at
                    // 0.007); only a first rate above 1 rebuilds it, later rates above the
                    // threshold do. A small (dense) matrix is cheap to rebuild at once.
                    let dense = self.data.solver.backend() == Backend::Dense;
                    if dense || iteration >= 3 || theta > 1.0 {
                        refresh = true;
                    }
                } else if iteration >= 3 && theta > 1.0 {
                    result = Err(StepFailure {
                        reason: format!(
                            "Newton diverging (weighted correction {err:.3e}, contraction rate {theta:.3})"
                        ),
                        worst_unknown: Some(worst),
                    });
                    break;
                }
            }
            if iteration == newton.max_iterations {
                result = Err(StepFailure {
                    reason: format!(
                        "no convergence in {iteration} iterations (weighted correction {err:.3e})"
                    ),
                    worst_unknown: Some(worst),
                });
            }
        }
        self.increments = dq;
        match result {
            Ok(iterations) => {
                self.jacobian_age += 1;
                // Iterations done with the matrix the next step would reuse.
                if iterations - last_factorization.saturating_sub(1) > STALE_ITERATIONS
                    && self.data.solver.backend() == Backend::Dense
                {
                    // The reused matrix has drifted from the current one: a small (dense)
                    // matrix is cheaper to rebuild for the next step than extra iterations
                    // at every step. A large sparse factorization costs several iterations,
                    // so it waits for the contraction test.
                    self.jacobian_age = newton.max_jacobian_age;
                }
                self.previous.h = h;
                self.previous.vdot.clone_from(&self.saved.vdot);
                self.previous.lambda.clone_from(&self.saved.lambda);
            }
            Err(_) => {
                self.jacobian = None;
                self.previous.h = 0.0;
            }
        }
        result
    }

    /// Predictor: `vdot_{n+1} = vdot_n`, `lambda_{n+1} = lambda_n`, and the `v`, `a` and
    /// increment that the generalized-alpha formulas give for it.
    fn predict(&mut self, h: f64, dq: &mut Vec<f64>) {
        let p = self.params;
        let n = self.data.layout.n_nodes;
        dq.clear();
        dq.resize(6 * n, 0.0);
        // Linear extrapolation of vdot and lambda from the last two steps when there are
        // two (a closer start saves Newton iterations; the solution does not depend on it).
        let ratio = if self.previous.h > 0.0 {
            h / self.previous.h
        } else {
            0.0
        };
        for i in 0..n {
            let (v0, vd0, a0) = (self.saved.v[i], self.saved.vdot[i], self.saved.a[i]);
            let vd1 = if ratio > 0.0 {
                vd0 + (vd0 - self.previous.vdot[i]) * ratio
            } else {
                vd0
            };
            let a1 =
                (vd0 * p.alpha_f + vd1 * (1.0 - p.alpha_f) - a0 * p.alpha_m) / (1.0 - p.alpha_m);
            self.state.vdot[i] = vd1;
            self.state.v[i] = v0 + a0 * (h * (1.0 - p.gamma)) + a1 * (h * p.gamma);
            let inc = v0 * h + a0 * (h * h * (0.5 - p.beta)) + a1 * (h * h * p.beta);
            dq[6 * i..6 * i + 6].copy_from_slice(inc.as_slice());
        }
        if ratio > 0.0 {
            for (k, l) in self.state.lambda.iter_mut().enumerate() {
                *l += (*l - self.previous.lambda[k]) * ratio;
            }
        }
    }

    /// `q = q_n exp(dq)` and, when the matrix is rebuilt, the tangent operators `T(dq)`.
    fn update_configuration(&mut self, dq: &[f64], tangents: bool) {
        let group = self.model.group;
        for (i, node) in self.data.nodes.iter_mut().enumerate() {
            let inc = Vec6::from_column_slice(&dq[6 * i..6 * i + 6]);
            node.q = group.integrate(&self.saved.q[i], &inc);
            node.v = self.state.v[i];
            node.vdot = self.state.vdot[i];
            if tangents {
                node.t = group.tangent(&inc);
            }
        }
    }

    /// Numeric factorization of the iteration matrix, regularized if it is singular.
    fn factorize(&mut self, sc: &mut Scaling) -> Result<(), StepFailure> {
        self.stats.factorizations += 1;
        let mut factorized = self.data.solver.factorize(&self.data.values);
        if matches!(factorized, Err(LinearError::Singular { .. })) && sc.regularization == 0.0 {
            sc.regularization = REGULARIZATION;
            self.regularized_steps = REGULARIZED_STEPS;
            let n_unknowns = self.data.layout.n_unknowns();
            let nd = self.data.layout.n_dofs;
            let diag = self.data.values.len() - n_unknowns;
            for v in &mut self.data.values[diag + nd..] {
                *v = -sc.regularization;
            }
            factorized = self.data.solver.factorize(&self.data.values);
        }
        factorized.map_err(|e| StepFailure {
            reason: format!("singular iteration matrix ({e})"),
            worst_unknown: match e {
                LinearError::Singular { column } => column,
                _ => None,
            },
        })
    }

    /// Newton correction `dx = -S^-1 residual`.
    fn solve(&mut self) -> Result<(), StepFailure> {
        let dx = &mut self.data.correction;
        for (d, r) in dx.iter_mut().zip(&self.data.residual) {
            *d = -r;
        }
        self.data.solver.solve_in_place(dx);
        match dx.iter().position(|d| !d.is_finite()) {
            Some(i) => Err(StepFailure {
                reason: "non-finite Newton correction".into(),
                worst_unknown: Some(i),
            }),
            None => Ok(()),
        }
    }

    /// `dq += dx`, `v += gamma' dx`, `vdot += beta' dx`, `lambda += dmu / s`, and
    /// `zeta += dzeta` in the stabilized formulation.
    fn correct(&mut self, dq: &mut [f64], gp: f64, bp: f64, scale: f64) {
        let dx = &self.data.correction;
        let nd = self.data.layout.n_dofs;
        if self.data.layout.stabilized {
            let na = self.data.layout.n_active;
            for (z, d) in self.zeta.iter_mut().zip(&dx[nd + na..]) {
                *z += d;
            }
        }
        for i in 0..self.data.layout.n_nodes {
            let d = Vec6::from_column_slice(&dx[6 * i..6 * i + 6]);
            for k in 0..6 {
                dq[6 * i + k] += d[k];
            }
            self.state.v[i] += d * gp;
            self.state.vdot[i] += d * bp;
        }
        for (row, slot) in self.data.layout.row_unknown.iter().enumerate() {
            if let Some(k) = slot {
                self.state.lambda[row] += dx[nd + k] / scale;
            }
        }
    }

    /// Force scale of the multipliers' tolerance at the start of the step: the largest
    /// multiplier and the largest nodal force `m (|vdot| + |g|)` (or moment `J |vdot|`). A
    /// joint carrying no load yet (multipliers near zero) is then judged against the forces
    /// of the system instead of against round-off.
    fn force_scale(&self) -> f64 {
        let g = self.model.gravity.norm() * self.settings.load_factor_at(self.saved.t);
        let nodal = self
            .saved
            .vdot
            .iter()
            .zip(&self.data.nodal_mass)
            .map(|(a, m)| {
                let translation = m[0] * (a.fixed_rows::<3>(0).norm() + g);
                translation.max(m[3] * a.fixed_rows::<3>(3).norm())
            })
            .fold(0.0, f64::max);
        let lambda = self.saved.lambda.iter().fold(0.0f64, |m, l| m.max(l.abs()));
        lambda.max(nodal)
    }

    /// Round-off floor of each active scaled multiplier, `1000 eps L D_k` (`L` the size of
    /// the model, `D_k` the largest diagonal entry of the iteration matrix just assembled on
    /// the dofs of the row's nodes: mass, damping and stiffness, scaled): the size of the
    /// round-off in the equilibrium rows that the multiplier balances. It matters only where
    /// every force of the model is near zero (a mechanism starting from rest without
    /// gravity), and keeps the test from asking for a multiplier below round-off.
    fn update_multiplier_floor(&mut self) {
        let length = self.saved.q.iter().fold(1e-3f64, |m, q| m.max(q.x.norm()));
        let roundoff = 1e3 * f64::EPSILON * length;
        let data = &mut self.data;
        data.diagonal.fill(0.0);
        for &(i, slot) in &data.diagonal_slots {
            data.diagonal[i] += data.values[slot];
        }
        let layout = &data.layout;
        self.mu_floor.clear();
        self.mu_floor.resize(layout.n_active, 0.0);
        for (j, joint) in self.model.joints.iter().enumerate() {
            let start = layout.joint_row_start[j];
            let mut d = 0.0f64;
            for n in [joint.node_a, joint.node_b].into_iter().flatten() {
                d = data.diagonal[6 * n.0..6 * n.0 + 6]
                    .iter()
                    .fold(d, |m, v| m.max(v.abs()));
            }
            for r in 0..layout.joint_rows[j].len() {
                if let Some(k) = layout.row_unknown[start + r] {
                    self.mu_floor[k] = roundoff * d;
                }
            }
        }
    }

    /// Weighted norms of the Newton correction in `data.correction` (after it was applied):
    /// increments relative to `dq`; multipliers with the tolerance `rtol max_mu + floor_k`
    /// (`max_mu` the scaled [`Self::force_scale`], `floor` from
    /// [`Self::update_multiplier_floor`]); stabilization unknowns relative to `zeta`.
    fn correction_norms(&self, dq: &[f64], max_mu: f64) -> CorrectionNorms {
        let newton = &self.settings.newton;
        let layout = &self.data.layout;
        let (nd, na) = (layout.n_dofs, layout.n_active);
        let dx = &self.data.correction;
        let (q, worst_q) = weighted_norm(&dx[..nd], dq, &|_| newton.atol, newton.rtol);
        let (mut mu, mut worst_mu) = (0.0, nd);
        if na > 0 {
            let relative = newton.rtol * max_mu;
            let dmu = &dx[nd..nd + na];
            let (e, w) = weighted_norm(dmu, dmu, &|k| relative + self.mu_floor[k], 0.0);
            (mu, worst_mu) = (e, nd + w);
        }
        let zeta = if layout.stabilized {
            weighted_norm(&dx[nd + na..], &self.zeta, &|_| newton.atol, newton.rtol).0
        } else {
            0.0
        };
        CorrectionNorms {
            q,
            worst_q,
            mu,
            worst_mu,
            zeta,
        }
    }

    /// `--verify`: a Newton correction from the accepted iterate with a freshly built and
    /// factorized matrix (a second factorization, so a reused one is kept) estimates the
    /// error left in the step, in units of the tolerance. Records the largest.
    fn verify_step(&mut self, dq: &[f64], sc: &Scaling, max_mu: f64, undetermined: bool) {
        let total = self.total_increments(dq);
        self.update_configuration(&total, true);
        self.total = total;
        assemble(
            self.model,
            &mut self.data,
            self.state.t,
            &self.state.lambda,
            sc,
            true,
        );
        if self.verify_solver.is_none() {
            let n = self.data.layout.n_unknowns();
            self.verify_solver = LinearSolver::new(n, &self.data.pattern).ok();
        }
        let factorized = match &mut self.verify_solver {
            Some(solver) => solver.factorize(&self.data.values).is_ok(),
            None => false,
        };
        // A singular matrix at the accepted point gives no estimate (the step itself was
        // accepted with the regularization): recorded as NaN.
        let mut error = (f64::NAN, None);
        if let (true, Some(solver)) = (factorized, &mut self.verify_solver) {
            let dx = &mut self.data.correction;
            for (d, r) in dx.iter_mut().zip(&self.data.residual) {
                *d = -r;
            }
            solver.solve_in_place(dx);
            let norms = self.correction_norms(dq, max_mu);
            let e = if undetermined {
                norms.configuration()
            } else {
                norms.all()
            };
            error = (e, Some(norms.worst()));
        }
        let (model, layout) = (self.model, &self.data.layout);
        self.verification
            .get_or_insert_with(Verification::default)
            .record(error.0, self.state.t, || {
                error
                    .1
                    .map(|i| layout.describe_unknown(model, i))
                    .unwrap_or_default()
            });
        load_nodes(&self.state, &mut self.data);
    }

    /// `dq + B(q_n)^T zeta` in the stabilized formulation, `dq` otherwise. Returns a copy
    /// held in a reused buffer.
    fn total_increments(&mut self, dq: &[f64]) -> Vec<f64> {
        let mut total = std::mem::take(&mut self.total);
        total.clear();
        total.extend_from_slice(dq);
        if self.data.layout.stabilized {
            let layout = &self.data.layout;
            for (n, rows) in layout.node_rows.iter().enumerate() {
                for &(row, slot) in rows {
                    let zeta = self.zeta[layout.row_unknown[row].expect("active row")];
                    for i in 0..6 {
                        total[6 * n + i] += self.data.b_start[row][6 * slot + i] * zeta;
                    }
                }
            }
        }
        total
    }

    /// Final configuration and algorithmic acceleration
    /// `a_{n+1} = (alpha_f vdot_n + (1 - alpha_f) vdot_{n+1} - alpha_m a_n) / (1 - alpha_m)`.
    fn finish_step(&mut self, dq: &[f64]) {
        let p = self.params;
        let group = self.model.group;
        for i in 0..self.data.layout.n_nodes {
            let inc = Vec6::from_column_slice(&dq[6 * i..6 * i + 6]);
            let mut q = group.integrate(&self.saved.q[i], &inc);
            q.orthonormalize();
            self.state.q[i] = q;
            self.state.a[i] = (self.saved.vdot[i] * p.alpha_f
                + self.state.vdot[i] * (1.0 - p.alpha_f)
                - self.saved.a[i] * p.alpha_m)
                / (1.0 - p.alpha_m);
        }
        load_nodes(&self.state, &mut self.data);
    }
}

/// The ends of the steps of a run. Steps of size `h` end at `anchor + k h` (`k` steps since
/// `h` last changed), free of the round-off that summing `t += h` accumulates; the last
/// steps before a target (an output time or the end) end exactly on it, and none is shorter
/// than `h / 2` unless the whole interval is: a remainder below `h / 2` is shared with the
/// step before it (two equal steps), a remainder within round-off of `h` is taken whole.
#[derive(Clone, Copy, Debug)]
struct StepClock {
    /// Current step size \[s\].
    h: f64,
    anchor: f64,
    k: usize,
}

impl StepClock {
    fn new(h: f64) -> Self {
        Self {
            h,
            anchor: 0.0,
            k: 0,
        }
    }

    fn regular(&self) -> f64 {
        self.anchor + (self.k + 1) as f64 * self.h
    }

    /// End of the next step from `t` toward `target`.
    fn next(&self, t: f64, target: f64) -> f64 {
        let remaining = target - t;
        if remaining <= self.h * (1.0 + 1e-9) {
            target
        } else if remaining < 1.5 * self.h {
            t + 0.5 * remaining
        } else {
            self.regular()
        }
    }

    /// The step to `t_new` was accepted.
    fn advance(&mut self, t_new: f64) {
        if t_new == self.regular() {
            self.k += 1;
        } else {
            self.restart(t_new, self.h);
        }
    }

    /// Steps of size `h` from `t` on.
    fn restart(&mut self, t: f64, h: f64) {
        *self = Self { h, anchor: t, k: 0 };
    }
}

/// Whether an interrupt flag is set.
pub(crate) fn interrupted(flag: &Option<Arc<AtomicBool>>) -> bool {
    flag.as_ref().is_some_and(|f| f.load(Ordering::Relaxed))
}

#[cfg(test)]
mod tests {
    use super::StepClock;

    /// Steps from 0 to `t_end` as the run loop takes them with a [`StepClock`].
    fn steps(t_end: f64, h: f64) -> Vec<f64> {
        let (mut t, mut clock, mut out) = (0.0, StepClock::new(h), vec![]);
        while t < t_end {
            let t_new = clock.next(t, t_end);
            clock.advance(t_new);
            out.push(t_new - t);
            t = t_new;
        }
        assert_eq!(t, t_end, "the last step ends exactly on the end time");
        out
    }

    /// The pendulum reproducer of the trust issue: 12 000 steps of 1.25e-4 s to 1.5 s took a
    /// 12 001st step of a few 1e-16 s. No step may be shorter than h / 2.
    #[test]
    fn no_sliver_step_at_the_end() {
        let s = steps(1.5, 1.25e-4);
        assert_eq!(s.len(), 12_000);
        for (t_end, h) in [
            (1.0, 0.3),
            (1.0, 0.4),
            (10.0, 1e-3),
            (0.1, 1e-5),
            (1.0, 0.7),
        ] {
            let s = steps(t_end, h);
            let shortest = s.iter().cloned().fold(f64::INFINITY, f64::min);
            let longest = s.iter().cloned().fold(0.0, f64::max);
            assert!(
                shortest >= 0.5 * h * (1.0 - 1e-9),
                "{t_end} {h}: {shortest}"
            );
            assert!(longest <= h * (1.0 + 1e-9), "{t_end} {h}: {longest}");
        }
        // A whole interval shorter than h is one step.
        assert_eq!(steps(0.1, 0.3), vec![0.1]);
    }
}
