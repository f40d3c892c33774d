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
//! `assemble` (residual and iteration matrix), `factorize`, `solve`, `correct`, check the
//! weighted norm } until converged, then `update_algorithmic_acceleration`. A failed step is
//! retried first with a fresh iteration matrix if it used a reused one, then with a quarter
//! of the step size down to `h_min`; the run stops with a diagnosis (step, time, the worst
//! equation and its node or joint) below `h_min` or when step reductions keep coming back
//! (more than 100 plus one per 10 accepted steps). The output callback is
//! called at every output time, so what was computed is never lost.

use super::generalized_alpha::GaParameters;
use super::initial::{initial_accelerations, load_nodes, prepare_layout};
use super::linear::{Backend, LinearError};
use super::newton::{weighted_norm, NewtonSettings};
use crate::assembly::{assemble, ConstraintRhs, Scaling};
use crate::data::Data;
use crate::elements::Coefficients;
use crate::error::SolveError;
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
    pub outputs: usize,
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
    /// State at the start of the current step (restored when a step is rejected).
    saved: State,
    /// Size of the constraint-block regularization when it is on (see [`Scaling`]).
    regularization: f64,
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

/// Start of the previous accepted step (`h = 0` when there is none).
#[derive(Clone, Debug, Default)]
struct Previous {
    h: f64,
    vdot: Vec<Vec6>,
    lambda: Vec<f64>,
}

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
        check_settings(&settings)?;
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
            regularization: 1e-9 / mass_scale(model),
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
        let s = self.settings;
        let eps = 1e-9 * s.h;
        let out_dt = if s.output_interval > 0.0 {
            s.output_interval
        } else {
            0.0
        };
        output(self).map_err(SolveError::Output)?;
        self.stats.outputs += 1;
        let mut k_out = 1usize;
        let mut h = s.h;
        let mut successes = 0usize;
        let mut reductions = 0usize;
        while self.state.t < s.t_end - eps {
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
            let mut h_try = h.min(target - self.state.t);
            if target - (self.state.t + h_try) < eps {
                h_try = target - self.state.t;
            }
            match self.step(h_try) {
                Ok(iterations) => {
                    self.stats.steps += 1;
                    self.stats.max_iterations_in_a_step =
                        self.stats.max_iterations_in_a_step.max(iterations);
                    successes += 1;
                    if h < s.h && successes >= 4 {
                        h = (2.0 * h).min(s.h);
                        successes = 0;
                    }
                    let reached = (self.state.t - target).abs() <= eps;
                    if out_dt == 0.0 || reached {
                        output(self).map_err(SolveError::Output)?;
                        self.stats.outputs += 1;
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
                    self.regularized_steps = REGULARIZED_STEPS;
                    self.state = self.saved.clone();
                    successes = 0;
                    h = h_try * 0.25;
                    reductions += 1;
                    // Give up when the step can no longer shrink, or when rejections keep
                    // coming back after the step size recovers (an unstable solution).
                    // (Retries with a fresh matrix above do not count: they do not reduce h.)
                    let thrashing = reductions > 100 + self.stats.steps / 10;
                    if h < s.h_min || thrashing {
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

    /// One generalized-alpha step of size `h`; returns the Newton iterations used.
    ///
    /// Newton's iteration matrix is reused across iterations and steps while the iteration
    /// contracts fast (a chord method: the converged solution is the same, each iteration is
    /// cheaper); it is rebuilt when `h` or the regularization changes, when the contraction
    /// rate exceeds [`NewtonSettings::max_contraction`], when the iteration diverges, after
    /// [`NewtonSettings::max_jacobian_age`] steps, and, for dense (small) systems, at the next
    /// step after a step that needed more than 3 iterations with it.
    fn step(&mut self, h: f64) -> Result<usize, StepFailure> {
        self.saved.clone_from(&self.state);
        let p = self.params;
        let nd = self.data.layout.n_dofs;
        let bp = p.beta_prime(h);
        let gp = p.gamma_prime(h);
        let scale = 1.0 / bp;
        let mut sc = Scaling {
            row_scale: scale,
            coef: Coefficients {
                m: 1.0,
                c: gp * scale,
                k: scale,
            },
            constraint_rhs: ConstraintRhs::Position,
            load_factor: self.settings.load_factor_at(self.saved.t + h),
            regularization: if self.regularized_steps > 0 {
                self.regularization
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
        let t_new = self.saved.t + h;
        let mut dq = std::mem::take(&mut self.increments);
        self.predict(h, &mut dq);
        self.state.t = t_new;
        let max_mu = self.saved.lambda.iter().fold(0.0f64, |m, l| m.max(l.abs())) * scale;
        let newton = self.settings.newton;
        let mut previous = f64::INFINITY;
        let mut previous_mu = f64::INFINITY;
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
            let e_zeta = if stabilized {
                let na = self.data.layout.n_active;
                let dz = &self.data.correction[nd + na..];
                for (z, d) in self.zeta.iter_mut().zip(dz) {
                    *z += d;
                }
                weighted_norm(dz, &self.zeta, &|_| newton.atol, newton.rtol).0
            } else {
                0.0
            };
            // weighted norms of the corrections: increments, then multipliers relative to
            // the largest multiplier of the previous step
            let dx = &self.data.correction;
            let (e_q, worst_q) = weighted_norm(&dx[..nd], &dq, &|_| newton.atol, newton.rtol);
            let mut e_mu = 0.0;
            let mut worst_mu = 0;
            if self.data.layout.n_active > 0 && max_mu > 0.0 {
                let mu_atol = newton.rtol * max_mu;
                let mu = &dx[nd..nd + self.data.layout.n_active];
                let (e, w) = weighted_norm(mu, mu, &|_| mu_atol, 0.0);
                e_mu = e;
                worst_mu = nd + w;
            }
            let err = e_q.max(e_mu).max(e_zeta);
            self.stats.newton_iterations += 1;
            // The multipliers of a badly scaled mechanism can stall at their round-off floor
            // once the configuration has converged: accept when they stop decreasing.
            let multipliers_stalled =
                iteration >= 2 && e_q.max(e_zeta) <= 1.0 && e_mu > 0.5 * previous_mu;
            if err <= 1.0 || multipliers_stalled {
                let total = self.total_increments(&dq);
                self.finish_step(&total);
                self.total = total;
                result = Ok(iteration);
                break;
            }
            let worst = if e_q >= e_mu { worst_q } else { worst_mu };
            let contraction = err / previous;
            if iteration >= 2 && contraction > newton.max_contraction {
                if !fresh {
                    // A stale matrix converges too slowly: rebuild it and go on.
                    refresh = true;
                } else if iteration >= 3 && contraction > 1.0 {
                    result = Err(StepFailure {
                        reason: format!(
                            "Newton diverging (weighted correction {err:.3e} after {previous:.3e})"
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
            previous = err;
            previous_mu = e_mu;
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
            sc.regularization = self.regularization;
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

    /// `dq += dx`, `v += gamma' dx`, `vdot += beta' dx`, `lambda += dmu / s`.
    fn correct(&mut self, dq: &mut [f64], gp: f64, bp: f64, scale: f64) {
        let dx = &self.data.correction;
        let nd = self.data.layout.n_dofs;
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

/// Whether an interrupt flag is set.
pub(crate) fn interrupted(flag: &Option<Arc<AtomicBool>>) -> bool {
    flag.as_ref().is_some_and(|f| f.load(Ordering::Relaxed))
}

/// Largest nodal mass of the model [kg] (1 if there is none): the scale of the
/// regularization of singular iteration matrices.
fn mass_scale(model: &Model) -> f64 {
    let bodies = model.bodies.iter().map(|b| b.mass);
    let beams = model
        .beams
        .iter()
        .map(|b| 0.5 * b.section.mass_per_length * b.length);
    let m = bodies.chain(beams).fold(0.0, f64::max);
    if m > 0.0 {
        m
    } else {
        1.0
    }
}

fn check_settings(s: &DynamicSettings) -> Result<(), SolveError> {
    let bad = |f: &str, m: &str| Err(SolveError::Model(format!("solver field '{f}': {m}")));
    if !(s.h > 0.0 && s.h.is_finite()) {
        return bad("h", "must be positive");
    }
    if !(s.t_end > 0.0 && s.t_end.is_finite()) {
        return bad("t_end", "must be positive");
    }
    if !(0.0..=1.0).contains(&s.rho_inf) {
        return bad("rho_inf", "must be in [0, 1]");
    }
    if s.output_interval < 0.0 {
        return bad("output_interval", "must be >= 0");
    }
    Ok(())
}
