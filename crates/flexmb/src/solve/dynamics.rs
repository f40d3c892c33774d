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
//! One attempt at a step reads as a checklist ([`Simulation::step`]): [`step::predict`],
//! then the [`NewtonSolver`] iterates on `StepSystem` { [`step::total_increments`] and
//! [`step::kinematics`] (`q = q_n exp(dq + B_n^T zeta)`, `T`), [`assemble`] (residual and,
//! when the matrix is rebuilt, iteration matrix), factorize, solve, [`step::correct`], judge
//! the weighted corrections with [`super::newton::Convergence`] } until the accepted
//! iterate's error is within the tolerance (a correction from a reused matrix is never taken
//! for the error), then [`step::finish`] (configuration and algorithmic acceleration). A
//! failed attempt is repeated first with a fresh iteration matrix if it used a reused one
//! (the solver's policy), then with redundant constraint rows chosen again if they change
//! ([`initial::reselect_redundant_rows`]), then with a quarter of the step size down to
//! `h_min` (`StepControl`); the step fails with a diagnosis (step, time, the worst
//! equation and its node or joint) below `h_min` or when step reductions keep coming back
//! (more than 100 plus one per 10 accepted steps). [`Simulation::run`] reports to its
//! observer at every output time, so what was computed is never lost; output times and
//! `t_end` are reached exactly, by steps never shorter than `h / 2` (`StepClock`).
//! [`Simulation::memory`] and [`Simulation::restore`] take and restore everything the next
//! steps depend on, bit for bit.

use super::generalized_alpha::GaParameters;
use super::initial::{self, initial_accelerations, mass_scale, prepare_layout};
use super::newton::{
    weighted_norm, MultiplierLimit, NewtonError, NewtonFailure, NewtonInfo, NewtonMemory,
    NewtonPolicy, NewtonSettings, NewtonSolver, NonlinearSystem, Norms, Verification,
};
use super::step;
use crate::assembly::{assemble, Iterate};
use crate::data::{Block, Data, Layout};
use crate::elements::{
    Context, ElementKernel, ElementRef, Kernel, Local, LocalBuffers, NodeState, StepLimit, Vec12,
};
use crate::error::{SettingsError, SolveError};
use crate::model::Model;
use crate::parallel::Threads;
use crate::sensors::node_states_into;
use crate::solve::observe::{Observer, Sample, StepRecord};
use crate::state::State;
use flexmb_lie::Vec6;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Which form of the constraints the integrator imposes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Formulation {
    /// Position-level constraints only (index 3).
    Index3,
    /// Position- and velocity-level constraints (stabilized index 2, GGL).
    StabilizedIndex2,
    /// Index 3 for `rho_inf < 0.95`, stabilized index 2 above (where index 3 without
    /// numerical damping can become unstable).
    Auto,
}

/// How the configuration update of a step is built from the scheme's increment
/// (module documentation of [`super::step`], "Configuration update").
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum LieUpdate {
    /// `q_{n+1} = q_n exp(dq)` (Brüls & Cardona 2010, Eqs. (40)-(44)).
    #[default]
    BrulsCardona,
    /// `q_{n+1} = q_n exp(dq + sigma h^2 [v_n, v_{n+1}])`: the Lie bracket term of the
    /// exact local flow (`sigma = 1/12`, the two-term Magnus update) or a larger weight that
    /// also cancels part of the scheme's own error for fast rotation (step module
    /// documentation; `BENCHMARKS.md`, "Error constant: variants compared").
    Commutator { sigma: f64 },
    /// The scheme's relations applied to the local coordinates `Theta` of each step,
    /// `q(t) = q_n exp(Theta(t))`, with `v = T(Theta) Theta'` and the algorithmic
    /// accelerations carried from one step's chart to the next (the Lie algebra approach of
    /// Arnold, Cardona & Brüls 2016; step module documentation, "Lie algebra update").
    /// Dynamics only; the step function differentiates it like the other updates.
    LieAlgebra,
    /// The same with the local coordinates of R3xSO(3) on either group:
    /// `q(t) = q_n o (Theta_u, exp(Theta_w))`, on SE(3) the translation in the frame of
    /// `q_n` and the rotation vector apart ([`flexmb_lie::Chart::TranslationRotation`]);
    /// identical to [`LieUpdate::LieAlgebra`] on R3xSO(3).
    LieAlgebraR3xSO3,
}

impl LieUpdate {
    /// Whether the step's relations act on local coordinates (the Lie algebra updates).
    pub fn in_chart(self) -> bool {
        matches!(self, LieUpdate::LieAlgebra | LieUpdate::LieAlgebraR3xSO3)
    }
}

/// The member of the generalized-alpha family to use.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// The configuration update ([`LieUpdate`]).
    #[serde(default)]
    pub lie_update: LieUpdate,
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
    /// Threads of the assembly (0: all cores; 1: sequential): the results are the same bits
    /// whatever the number, and models below [`crate::parallel::MIN_PARALLEL_ITEMS`] items
    /// stay sequential.
    #[serde(default)]
    pub threads: usize,
    /// The predictor extrapolates the accelerations and the multipliers each linearly or
    /// quadratically, whichever predicted the last step better (index 3; the stabilized
    /// form stays linear); `false`: linearly (`BENCHMARKS.md`, "A quadratic predictor where
    /// it predicts better").
    #[serde(default)]
    pub adaptive_predictor: bool,
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
        if let LieUpdate::Commutator { sigma } = self.lie_update {
            SettingsError::range("lie_update_sigma", sigma, 0.0, 1.0)?;
        }
        let p = self.scheme.parameters(self.rho_inf);
        let derived = [p.beta_prime(self.h), p.gamma_prime(self.h)];
        if derived.iter().any(|d| !d.is_normal()) {
            return Err(SettingsError::new(
                &["h"],
                format!("{:e} s gives a non-finite beta' or gamma'", self.h),
            ));
        }
        check_threads(self.threads)?;
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
            lie_update: LieUpdate::BrulsCardona,
            nodal_damping: 0.0,
            load_ramp: 0.0,
            load_scale: 1.0,
            verify: false,
            threads: 0,
            adaptive_predictor: false,
        }
    }
}

/// Rejects a thread count above [`crate::parallel::MAX_THREADS`].
pub(crate) fn check_threads(threads: usize) -> Result<(), SettingsError> {
    use crate::parallel::MAX_THREADS;
    if threads > MAX_THREADS {
        return Err(SettingsError::new(
            &["threads"],
            format!("must be between 0 (all cores) and {MAX_THREADS}, got {threads}"),
        ));
    }
    Ok(())
}

/// Work done by a solver, for summaries and for spotting cost changes in review.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// (configuration converged, multiplier corrections no longer halving from one exact
    /// correction to the next).
    pub multiplier_floor_steps: usize,
    /// Largest weighted multiplier correction of those steps (in units of the tolerance).
    pub multiplier_floor: f64,
    /// Time at the end of the step with that correction \[s\].
    #[serde(default)]
    pub multiplier_floor_t: f64,
    /// Converged steps repeated shorter because an event asked for it (a contact closing
    /// too deep; counted in `rejected_steps` too).
    #[serde(default)]
    pub event_rejections: usize,
}

impl Stats {
    /// The counts of the work done.
    pub fn work(&self) -> crate::solve::observe::Work {
        crate::solve::observe::Work {
            steps: self.steps,
            newton_iterations: self.newton_iterations,
            rejected_steps: self.rejected_steps,
            factorizations: self.factorizations,
        }
    }
}

/// What one accepted step did ([`Simulation::step`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepInfo {
    /// Time at the end of the step \[s\].
    pub t: f64,
    /// Size of the step \[s\].
    pub h: f64,
    /// Newton iterations of the step, failed attempts included.
    pub iterations: usize,
    /// Attempts rejected before this one (a reused matrix that failed, redundant rows chosen
    /// again, step-size reductions).
    pub rejected: usize,
    /// Whether the accepted attempt iterated with a reused (not freshly built) matrix.
    pub reused_matrix: bool,
    /// Whether the iteration matrix was regularized (a singular configuration).
    pub regularized: bool,
}

/// An event of a step ([`Simulation::last_step_event`]): an element's law switched in it.
#[derive(Clone, Debug, PartialEq)]
pub struct StepEvent {
    /// Time at the end of the step \[s\].
    pub t: f64,
    /// What happened, naming the item: `contact 'floor' closes`, `hold 'zoh' samples`.
    pub what: String,
    /// The held states the step's end sets, as copies `(target, source)` of states (indices
    /// in the state vector, sources read before targets are set), when every event of the
    /// step is at a time the motion does not move ([`crate::elements::ElementKernel::event_map`]):
    /// a run's derivatives then go through it. `None`: not followed.
    pub held: Option<crate::elements::HeldStates>,
}

/// A model that a simulation can hold: the simulation shares it, so a binding or another
/// thread can keep it too. A borrowed model is copied once.
pub trait IntoShared {
    fn into_shared(self) -> Arc<Model>;
}

impl IntoShared for Arc<Model> {
    fn into_shared(self) -> Arc<Model> {
        self
    }
}

impl IntoShared for &Arc<Model> {
    fn into_shared(self) -> Arc<Model> {
        Arc::clone(self)
    }
}

impl IntoShared for Model {
    fn into_shared(self) -> Arc<Model> {
        Arc::new(self)
    }
}

impl IntoShared for &Model {
    fn into_shared(self) -> Arc<Model> {
        Arc::new(self.clone())
    }
}

/// A dynamic analysis in progress: the model (shared, immutable), the data, the state, and
/// the parts that act on them: the integrator's memory, the Newton solver and its policies,
/// the step-size controller and the statistics.
pub struct Simulation {
    pub model: Arc<Model>,
    pub data: Data,
    pub state: State,
    pub settings: DynamicSettings,
    pub params: GaParameters,
    pub stats: Stats,
    /// What may be wrong with the results, for the user (e.g. steps accepted outside the
    /// tolerance under `--verify`).
    pub warnings: Vec<String>,
    /// Information for the user on what the run did as expected (e.g. redundant constraint
    /// rows of closed loops left out).
    pub notes: Vec<String>,
    /// Checked before every step: when it is set, [`Simulation::run`] returns
    /// [`SolveError::Interrupted`] with every completed output step already delivered.
    pub interrupt: Option<Arc<AtomicBool>>,
    /// What [`DynamicSettings::verify`] found (`None` when it is off).
    pub verification: Option<Verification>,
    newton: NewtonSolver,
    integrator: Integrator,
    control: StepControl,
    redundancy: RedundancyWatch,
    /// Largest nodal mass of the model \[kg\]: the equilibrium rows are divided by it.
    mass: f64,
    /// Whether the start of the run was reported to an observer.
    started: bool,
    /// Keep each accepted step's unknowns ([`Simulation::last_step`]): set by an observer
    /// that wants steps, or by [`Simulation::keep_last_step`].
    keep_steps: bool,
    /// The elements with events ([`crate::elements::ElementRef::has_events`]), indices in the layout.
    events: Vec<usize>,
    /// Node kinematics at the start and the end of the step just converged, when there are
    /// events ([`Simulation::event_limit`]).
    event_nodes: [Vec<NodeState>; 2],
    /// The elements that can switch ([`crate::elements::ElementRef::can_switch`]), indices
    /// in the layout ([`Simulation::last_step_event`]).
    switching: Vec<usize>,
}

/// The memory of a simulation at a step boundary: with the model and the settings,
/// everything the next steps depend on, so that a simulation restored from it
/// ([`Simulation::restore`]) takes the same steps as the one it was taken from, bit for
/// bit. That includes the factorized iteration matrix, which later steps may reuse: its
/// values are kept and factorized again.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Memory {
    pub state: State,
    pub stats: Stats,
    pub verification: Option<Verification>,
    /// Constraint rows left out as redundant.
    pub redundant_rows: Vec<usize>,
    previous: Previous,
    mu_floor: Vec<f64>,
    control: StepControl,
    redundancy: RedundancyWatch,
    newton: NewtonMemory,
    /// The held iteration matrix (values in pattern order).
    matrix: Option<Vec<f64>>,
}

/// A self-contained checkpoint of a dynamic run: model, settings and [`Memory`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Checkpoint {
    /// Format version ([`Checkpoint::VERSION`]).
    pub version: u32,
    pub model: Model,
    pub settings: DynamicSettings,
    pub memory: Memory,
}

impl Checkpoint {
    pub const VERSION: u32 = 1;
}

/// The memory of the generalized-alpha integrator between steps, and its scratch.
#[derive(Clone, Debug, Default)]
struct Integrator {
    /// State at the start of the current step (restored when a step is rejected).
    saved: State,
    /// Accelerations and multipliers at the start of the previous step, for the predictor.
    previous: Previous,
    /// Configuration increments of the current step (`6 n_nodes`).
    increments: Vec<f64>,
    /// Stabilization unknowns of the current step (`n_active`).
    zeta: Vec<f64>,
    /// Total increments `dq + B(q_n)^T zeta` (scratch, `6 n_nodes`).
    total: Vec<f64>,
    /// Rows of `B(q_n)` (`n_rows`; stabilized formulation).
    b_start: Vec<Vec12>,
    /// Node kinematics of the current iterate (`n_nodes`).
    nodes: Vec<NodeState>,
    /// Round-off floor of the scaled multipliers' tolerance (`n_active`).
    mu_floor: Vec<f64>,
    /// Row scale `s` of the current step ([`step::Start::scale`]).
    scale: f64,
    /// The converged unknowns of the last accepted step, in its layout.
    unknowns: Vec<f64>,
    /// The rows left out as redundant in the last accepted step (the rows may be chosen
    /// again right after it).
    redundant_rows: Vec<usize>,
}

/// Start of the previous accepted step (`h = 0` when there is none).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Previous {
    h: f64,
    vdot: Vec<Vec6>,
    lambda: Vec<f64>,
    /// The start of the step before (`h2 = 0` when there is none).
    #[serde(default)]
    h2: f64,
    #[serde(default)]
    vdot2: Vec<Vec6>,
    #[serde(default)]
    lambda2: Vec<f64>,
    /// Whether the accelerations and the multipliers are extrapolated quadratically (else
    /// linearly): the order that predicted the last step better
    /// ([`Previous::choose_and_shift`]).
    #[serde(default)]
    quadratic: [bool; 2],
}

impl Previous {
    /// The predictor of a step of size `h` (`None` without a previous step).
    fn extrapolation(&self, h: f64) -> Option<step::Extrapolation<'_>> {
        (self.h > 0.0).then(|| {
            let order = |quadratic: bool| {
                let h2 = if quadratic { self.h2 } else { 0.0 };
                step::Extrapolation::weights(h, self.h, h2)
            };
            step::Extrapolation {
                weights: [order(self.quadratic[0]), order(self.quadratic[1])],
                vdot: [&self.vdot, &self.vdot2],
                lambda: [&self.lambda, &self.lambda2],
            }
        })
    }

    /// After an accepted step of size `h` from `start` to `end`: for the accelerations and
    /// for the multipliers apart, the order (linear or quadratic) whose prediction of `end`
    /// was the closer by a factor 2 (the quadratic needs two earlier points; `quadratic`
    /// false keeps the linear one); then the start becomes the last earlier point.
    /// Accelerations and multipliers that are smooth over three steps are predicted an order
    /// better; multipliers that carry the configuration's error within its tolerance times
    /// `1 / h^2` (index 3), and quantities that jump (an impact), keep the linear
    /// extrapolation, which amplifies that noise less.
    fn choose_and_shift(&mut self, h: f64, start: &State, end: &State, quadratic: bool) {
        if !quadratic || self.h == 0.0 {
            self.quadratic = [false; 2];
        } else if self.h2 > 0.0 {
            let lin = step::Extrapolation::weights(h, self.h, 0.0);
            let quad = step::Extrapolation::weights(h, self.h, self.h2);
            // Squared misses of both predictions (`step::predict`'s own arithmetic) over
            // the points `(y_{n+1}, y_n, y_{n-1}, y_{n-2})`.
            let misses = |points: &mut dyn Iterator<Item = [f64; 4]>| {
                let miss = |w: &[f64; 3], y: &[f64; 4]| {
                    (y[0] - step::Extrapolation::at(w, y[1], |k| y[2 + k])).powi(2)
                };
                points.fold((0.0, 0.0), |(l, q), y| {
                    (l + miss(&lin, &y), q + miss(&quad, &y))
                })
            };
            let (vdot, vdot2) = (&self.vdot, &self.vdot2);
            let (lin_v, quad_v) = misses(&mut (0..end.vdot.len()).flat_map(|i| {
                (0..6).map(move |c| [end.vdot[i][c], start.vdot[i][c], vdot[i][c], vdot2[i][c]])
            }));
            let (lin_l, quad_l) = misses(&mut (0..end.lambda.len()).map(|r| {
                [
                    end.lambda[r],
                    start.lambda[r],
                    self.lambda[r],
                    self.lambda2[r],
                ]
            }));
            // An order changes when the other predicted at least twice as well (in the
            // squared error): a near tie keeps the order, so that round-off (a model
            // scaled by 1e7) does not flip it.
            let keep = |current: bool, lin: f64, quad: f64| match current {
                true => lin >= 0.5 * quad,
                false => quad < 0.5 * lin,
            };
            self.quadratic = [
                keep(self.quadratic[0], lin_v, quad_v),
                keep(self.quadratic[1], lin_l, quad_l),
            ];
        }
        self.h2 = self.h;
        std::mem::swap(&mut self.vdot, &mut self.vdot2);
        std::mem::swap(&mut self.lambda, &mut self.lambda2);
        self.h = h;
        self.vdot.clone_from(&start.vdot);
        self.lambda.clone_from(&start.lambda);
    }
}

/// Step-size control and the output schedule of a run.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct StepControl {
    clock: StepClock,
    /// Steps accepted since the step size last changed.
    successes: usize,
    /// Step-size reductions so far.
    reductions: usize,
    /// Index of the next output time.
    k_out: usize,
}

impl StepControl {
    fn new(h: f64) -> Self {
        Self {
            clock: StepClock::new(h),
            successes: 0,
            reductions: 0,
            k_out: 1,
        }
    }

    /// The next stop: the next output time, or the end.
    fn target(&self, s: &DynamicSettings) -> f64 {
        if s.output_interval > 0.0 {
            (self.k_out as f64 * s.output_interval).min(s.t_end)
        } else {
            s.t_end
        }
    }

    /// A step to `t_new` was accepted: the step size recovers after 4 accepted steps.
    fn accepted(&mut self, t_new: f64, h_nominal: f64) {
        self.successes += 1;
        self.clock.advance(t_new);
        if self.clock.h < h_nominal && self.successes >= 4 {
            self.clock
                .restart(t_new, (2.0 * self.clock.h).min(h_nominal));
            self.successes = 0;
        }
    }

    /// Steps from `t` on are at most `h_max` long (an event's limit); the step size recovers
    /// as after a reduction.
    fn limit(&mut self, t: f64, h_max: f64) {
        if self.clock.h > h_max {
            self.successes = 0;
            self.clock.restart(t, h_max);
        }
    }

    /// A step of size `h_try` from `t` failed: a quarter of it is tried next.
    fn reduce(&mut self, t: f64, h_try: f64) {
        self.successes = 0;
        self.clock.restart(t, h_try * 0.25);
        self.reductions += 1;
    }
}

/// Watch on the redundant constraint rows (see [`Simulation::watch_redundant_rows`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct RedundancyWatch {
    /// Smallest relative pivot of the first factorization after the rows were chosen.
    pivot_reference: Option<f64>,
    /// Time of the first re-selection.
    first_reselection: f64,
}

/// Steps that keep the regularization after a singular matrix or a rejected step.
const REGULARIZED_STEPS: usize = 20;

impl Simulation {
    /// Validates the model, builds the data and computes consistent initial conditions.
    pub fn new(model: impl IntoShared, settings: DynamicSettings) -> Result<Self, SolveError> {
        let model = model.into_shared();
        model.validate()?;
        settings.check()?;
        let (layout, note) = prepare_layout(&model);
        let threads = Threads::for_model(&model, settings.threads);
        let mut data = Data::new(&model, layout.clone())?.with_threads(threads.clone());
        let mut state = State::initial(&model, &layout)?;
        initial_accelerations(&model, &mut data, &mut state, settings.load_factor_at(0.0))?;
        if settings.stabilized() {
            let mut stabilized = layout;
            stabilized.stabilized = true;
            data = Data::new(&model, stabilized)?.with_threads(threads);
        }
        let policy = Self::policy(&settings);
        Ok(Self {
            integrator: Integrator {
                saved: state.clone(),
                ..Default::default()
            },
            mass: mass_scale(&model),
            model,
            data,
            state,
            params: settings.scheme.parameters(settings.rho_inf),
            newton: NewtonSolver::new(policy, settings.verify),
            control: StepControl::new(settings.h),
            settings,
            stats: Stats::default(),
            warnings: Vec::new(),
            notes: note.into_iter().collect(),
            interrupt: None,
            verification: None,
            redundancy: RedundancyWatch::default(),
            started: false,
            keep_steps: false,
            events: Vec::new(),
            event_nodes: Default::default(),
            switching: Vec::new(),
        }
        .with_events())
    }

    /// The simulation with its lists of elements with events and of elements that can
    /// switch.
    fn with_events(mut self) -> Self {
        let elements = &self.data.layout.elements;
        let model = &self.model;
        let which = |has: fn(&ElementRef, &Model) -> bool| -> Vec<usize> {
            (0..elements.len())
                .filter(|&e| has(&elements[e], model))
                .collect()
        };
        self.events = which(ElementRef::has_events);
        self.switching = which(ElementRef::can_switch);
        self
    }

    /// Runs to `t_end`, reporting to `observer` at the start (t = 0; not again when the run
    /// goes on after an interruption or was resumed from a checkpoint), at every output time
    /// and, if it asks, after every step. Stops at the first error of the observer, when
    /// the interrupt flag is set, or when a step cannot be completed even at `h_min`; it can
    /// be called again to go on.
    pub fn run(&mut self, observer: &mut dyn Observer) -> Result<Stats, SolveError> {
        let result = self.run_until(self.settings.t_end, observer);
        self.add_run_notes();
        result
    }

    /// The memory of the run now (between steps).
    pub fn memory(&self) -> Memory {
        let layout = &self.data.layout;
        Memory {
            state: self.state.clone(),
            stats: self.stats,
            verification: self.verification.clone(),
            redundant_rows: layout.redundant_rows(),
            previous: self.integrator.previous.clone(),
            mu_floor: self.integrator.mu_floor.clone(),
            control: self.control,
            redundancy: self.redundancy,
            newton: self.newton.memory(),
            matrix: self.newton.holds_matrix().then(|| self.data.values.clone()),
        }
    }

    /// A self-contained checkpoint of the run now (between steps).
    pub fn checkpoint(&self) -> Checkpoint {
        Checkpoint {
            version: Checkpoint::VERSION,
            model: (*self.model).clone(),
            settings: self.settings,
            memory: self.memory(),
        }
    }

    /// A run resumed from a checkpoint: it goes on exactly as the run that wrote it would
    /// have. `t_end` may be later than the checkpoint's (the run is extended).
    pub fn resume(checkpoint: Checkpoint, t_end: f64) -> Result<Self, SolveError> {
        let c = checkpoint;
        if c.version != Checkpoint::VERSION {
            return Err(SolveError::Checkpoint(format!(
                "format version {} is not {}",
                c.version,
                Checkpoint::VERSION
            )));
        }
        if t_end < c.memory.state.t {
            return Err(SolveError::Checkpoint(format!(
                "t_end = {t_end} is before the checkpoint's time {}",
                c.memory.state.t
            )));
        }
        let settings = DynamicSettings {
            t_end,
            ..c.settings
        };
        let model = Arc::new(c.model);
        // The note on the rows left out at the start, which the run that wrote the
        // checkpoint gave too (`restore` alone does not repeat this QR).
        let (_, note) = prepare_layout(&model);
        let mut sim = Self::restore(model, settings, c.memory)?;
        sim.notes = note.into_iter().collect();
        Ok(sim)
    }

    /// A simulation of `model` with `settings` restored to a memory taken from one of the
    /// same model and settings ([`Simulation::memory`]).
    pub fn restore(
        model: Arc<Model>,
        settings: DynamicSettings,
        memory: Memory,
    ) -> Result<Self, SolveError> {
        let c = memory;
        model.validate()?;
        settings.check()?;
        let (_, _, n_rows) = crate::joints::row_table(&model);
        if c.redundant_rows.iter().any(|&r| r >= n_rows) {
            return Err(SolveError::Checkpoint(
                "its redundant rows are not rows of the model".into(),
            ));
        }
        let layout = Layout::with_rows(&model, settings.stabilized(), &c.redundant_rows);
        let threads = Threads::for_model(&model, settings.threads);
        let mut data = Data::new(&model, layout)?.with_threads(threads);
        let mut newton = NewtonSolver::new(Self::policy(&settings), settings.verify);
        let holds_values = c.matrix.is_some();
        if let Some(values) = c.matrix {
            if values.len() != data.values.len() {
                return Err(SolveError::Checkpoint(
                    "its iteration matrix does not fit the model".into(),
                ));
            }
            data.values = values;
            data.solver.factorize(&data.values)?;
        }
        if c.newton.holds_matrix() && !holds_values {
            return Err(SolveError::Checkpoint(
                "it names an iteration matrix it does not hold".into(),
            ));
        }
        newton.restore(c.newton);
        let n = model.nodes.len();
        let rows = data.layout.n_rows;
        let consistent = c.state.q.len() == n
            && c.state.v.len() == n
            && c.state.vdot.len() == n
            && c.state.a.len() == n
            && c.state.lambda.len() == rows
            && [&c.state.x, &c.state.xdot, &c.state.w]
                .iter()
                .all(|v| v.len() == data.layout.n_states)
            && (c.previous.h == 0.0
                || (c.previous.vdot.len() == n && c.previous.lambda.len() == rows))
            && (c.previous.h2 == 0.0
                || (c.previous.vdot2.len() == n && c.previous.lambda2.len() == rows))
            && (!holds_values || c.mu_floor.len() == data.layout.n_active);
        if !consistent {
            return Err(SolveError::Checkpoint(
                "its state does not fit the model".into(),
            ));
        }
        Ok(Self {
            integrator: Integrator {
                saved: c.state.clone(),
                previous: c.previous,
                mu_floor: c.mu_floor,
                ..Default::default()
            },
            mass: mass_scale(&model),
            model,
            data,
            state: c.state,
            params: settings.scheme.parameters(settings.rho_inf),
            newton,
            control: c.control,
            settings,
            stats: c.stats,
            warnings: Vec::new(),
            notes: Vec::new(),
            interrupt: None,
            verification: c.verification,
            redundancy: c.redundancy,
            started: true,
            keep_steps: false,
            events: Vec::new(),
            event_nodes: Default::default(),
            switching: Vec::new(),
        }
        .with_events())
    }

    fn policy(settings: &DynamicSettings) -> NewtonPolicy {
        NewtonPolicy {
            settings: settings.newton,
            regularized_solves: REGULARIZED_STEPS,
            divergence_rate: 1.0,
            diverge_after: 3,
            exact_by_size: false,
        }
    }

    /// The next step of size `h` from the current state as a function of its unknowns
    /// ([`step::StepFunction`]): residual, exact Jacobian and the products with its
    /// derivatives.
    pub fn step_function(&self, h: f64) -> step::StepFunction<'_> {
        step::StepFunction::new(
            &self.model,
            &self.data.layout,
            &self.state,
            &self.settings,
            h,
        )
    }

    /// Adds what the run should tell the user about the steps so far to its warnings (what
    /// may be wrong) and notes (what is expected); [`Simulation::run`] calls it at its end.
    pub fn add_run_notes(&mut self) {
        if self.stats.undetermined_multipliers > 0 {
            self.warnings.push(format!(
                "{} steps passed singular configurations (a rank-deficient constraint matrix, e.g. a dead point): positions and velocities are converged there, the multipliers (joint reactions) are not determined by the equations at those steps",
                self.stats.undetermined_multipliers
            ));
        }
        if self.stats.multiplier_floor_steps > 0 {
            self.warnings.push(format!(
                "at {} steps the multipliers (joint reactions and servo forces) stopped converging, their last corrections up to {:.2e} times their tolerance (rtol times the largest force of the model; atol and rtol for a servo force; the largest at t = {:.6e} s), two exact Newton corrections in a row: round-off of an ill-conditioned constraint system, whose equations nearly leave a combination of the reactions undetermined (e.g. near a singular position); positions and velocities are converged",
                self.stats.multiplier_floor_steps, self.stats.multiplier_floor, self.stats.multiplier_floor_t
            ));
        }
        if self.stats.reselections > 0 {
            // Expected of a closed loop that moves: information.
            self.notes.push(format!(
                "the redundant constraint rows were chosen again {} times as the mechanism moved (first at t = {:.6e} s), where the rows kept came close to losing rank",
                self.stats.reselections, self.redundancy.first_reselection
            ));
        }
        if let Some(w) = self.verification.as_ref().and_then(Verification::warning) {
            self.warnings.push(w);
        }
    }

    /// [`Simulation::run`] until the first step that ends at or after `t_stop` (a step
    /// boundary: the steps are those of an uninterrupted run), without adding the notes.
    pub fn run_until(
        &mut self,
        t_stop: f64,
        observer: &mut dyn Observer,
    ) -> Result<Stats, SolveError> {
        if !self.started {
            // The start (a resumed run was started by the run that wrote its checkpoint).
            observer
                .output(&self.sample())
                .map_err(SolveError::Output)?;
            self.started = true;
        }
        let wants_steps = observer.wants_steps();
        self.keep_steps |= wants_steps;
        while self.state.t < self.settings.t_end.min(t_stop) {
            if interrupted(&self.interrupt) {
                return Err(SolveError::Interrupted {
                    reached: self.state.t,
                });
            }
            let target = self.control.target(&self.settings);
            let info = self.step()?;
            observer.accepted(&info).map_err(SolveError::Output)?;
            if wants_steps {
                let record = StepRecord {
                    simulation: self,
                    index: self.stats.steps,
                    start: &self.integrator.saved,
                    unknowns: &self.integrator.unknowns,
                    redundant_rows: &self.integrator.redundant_rows,
                    end: &self.state,
                    info: &info,
                };
                observer.step(&record).map_err(SolveError::Output)?;
            }
            if self.settings.output_interval == 0.0 || self.state.t == target {
                observer
                    .output(&self.sample())
                    .map_err(SolveError::Output)?;
            }
        }
        Ok(self.stats)
    }

    /// The current point of the run, for observers.
    pub fn sample(&self) -> Sample<'_> {
        Sample {
            model: &self.model,
            data: &self.data,
            state: &self.state,
            at: self.state.t,
            work: self.stats.work(),
        }
    }

    /// The converged unknowns of the last accepted step in the layout of its Newton vector
    /// (increments, scaled multipliers `mu = s lambda` and stabilization unknowns), and the
    /// constraint rows that were left out as redundant in it; empty unless steps are kept
    /// ([`Simulation::keep_last_step`]).
    pub fn last_step(&self) -> (&[f64], &[usize]) {
        (&self.integrator.unknowns, &self.integrator.redundant_rows)
    }

    /// Keep the unknowns of every accepted step for [`Simulation::last_step`] (a copy per
    /// step; [`Simulation::run`] turns it on for an observer that wants steps).
    pub fn keep_last_step(&mut self, keep: bool) {
        self.keep_steps = keep;
    }

    fn step_unknowns_into(&self, x: &mut Vec<f64>) {
        let it = &self.integrator;
        let layout = &self.data.layout;
        let step = (&it.increments[..], &self.state.lambda[..], &it.zeta[..]);
        let states = (&it.saved.x[..], &self.state.x[..]);
        step::pack_unknowns(layout, it.scale, step, states, x);
    }

    /// Takes one step toward the next output time (or the end), reducing the step size
    /// after failures, and returns what it did. Fails with a diagnosis when the step cannot
    /// be completed at `h_min` (or reductions keep coming back); the state is then the one
    /// at the start of the step.
    pub fn step(&mut self) -> Result<StepInfo, SolveError> {
        let s = self.settings;
        let mut info = StepInfo {
            t: self.state.t,
            h: 0.0,
            iterations: 0,
            rejected: 0,
            reused_matrix: false,
            regularized: false,
        };
        loop {
            let target = self.control.target(&s);
            let t_new = self.control.clock.next(self.state.t, target);
            if t_new <= self.state.t {
                return Err(SolveError::StepUnderflow {
                    t: self.state.t,
                    h: self.control.clock.h,
                });
            }
            let h_try = t_new - self.state.t;
            let attempt = self.attempt(t_new);
            let work = match &attempt {
                Ok(n) | Err(NewtonFailure { info: n, .. }) => *n,
            };
            self.stats.newton_iterations += work.iterations;
            self.stats.factorizations += work.factorizations;
            self.stats.rejected_steps += work.retries;
            info.iterations += work.iterations;
            info.rejected += work.retries;
            match attempt {
                Ok(newton) => {
                    let (retry, next) = self.event_limit(h_try);
                    if let Some(h_event) = retry.filter(|_| h_try > s.h_min) {
                        // An event (a contact's onset) wants a shorter step: repeat it.
                        self.stats.rejected_steps += 1;
                        self.stats.event_rejections += 1;
                        info.rejected += 1;
                        self.state.clone_from(&self.integrator.saved);
                        self.control.limit(self.state.t, h_event.max(s.h_min));
                        continue;
                    }
                    self.accepted(&newton, h_try);
                    if let Some(cap) = next {
                        self.control.limit(self.state.t, cap.max(s.h_min));
                    }
                    self.update_element_states();
                    // The next output time, once this one is reached (t_end, if it is not an
                    // output time, is not one: a run extended past it goes on to it).
                    let output_time = self.control.k_out as f64 * s.output_interval;
                    if s.output_interval > 0.0 && self.state.t == output_time {
                        self.control.k_out += 1;
                    }
                    info.t = self.state.t;
                    info.h = h_try;
                    info.reused_matrix = newton.reused_matrix;
                    info.regularized = newton.regularized;
                    return Ok(info);
                }
                Err(failure) => {
                    self.stats.rejected_steps += 1;
                    info.rejected += 1;
                    self.state.clone_from(&self.integrator.saved);
                    if self.reselect_redundant_rows() {
                        // The rows kept as independent had lost rank: retry with new ones.
                        continue;
                    }
                    self.newton.regularize_next();
                    self.control.reduce(self.state.t, h_try);
                    // Give up when the step can no longer shrink, or when rejections keep
                    // coming back after the step size recovers (an unstable solution).
                    let thrashing = self.control.reductions > 100 + self.stats.steps / 10;
                    if self.control.clock.h < s.h_min || thrashing {
                        return Err(self.failed(failure.error, h_try, thrashing));
                    }
                }
            }
        }
    }

    /// What the elements with events ([`crate::elements::ElementRef::has_events`]) ask of the
    /// step of size `h` just converged, from the saved state to the current one
    /// ([`crate::elements::ElementKernel::step_limit`]): the shortest retry (the step is
    /// rejected), and the shortest limit on the next steps. Takes the node kinematics of both
    /// ends into `event_nodes`, for [`Simulation::update_element_states`].
    fn event_limit(&mut self, h: f64) -> (Option<f64>, Option<f64>) {
        let (mut retry, mut next) = (None::<f64>, None::<f64>);
        if self.events.is_empty() {
            return (retry, next);
        }
        let [n0, n1] = &mut self.event_nodes;
        node_states_into(&self.integrator.saved, n0);
        node_states_into(&self.state, n1);
        let shortest = |a: Option<f64>, b: f64| Some(a.map_or(b, |a| a.min(b)));
        self.visit_events(|kernel, ctx, start, end, _| {
            match kernel.step_limit(ctx, start, end, h) {
                Some(StepLimit::Retry(r)) => retry = shortest(retry, r),
                Some(StepLimit::Next(n)) => next = shortest(next, n),
                None => {}
            }
        });
        (retry, next)
    }

    /// After an accepted step (its node kinematics in `event_nodes`, from
    /// [`Simulation::event_limit`]): the elements with events set their held states
    /// ([`crate::elements::ElementKernel::update_states`]).
    fn update_element_states(&mut self) {
        if self.events.is_empty() {
            return;
        }
        let mut updates = Vec::with_capacity(self.events.len());
        self.visit_events(|kernel, ctx, start, end, x0| {
            let mut x = end.x.to_vec();
            kernel.update_states(ctx, start, end, &mut x);
            updates.push((x0, x));
        });
        for (x0, x) in updates {
            self.state.x[x0..x0 + x.len()].copy_from_slice(&x);
        }
    }

    /// The event of the last accepted step, if an element that can switch
    /// ([`crate::elements::ElementRef::can_switch`]) had one in it
    /// ([`crate::elements::ElementKernel::event`]): the first such element's whose event
    /// a run's derivatives do not go through (`held: None`), else the first one's with the
    /// held states of them all ([`StepEvent::held`]), at the step's end. Evaluated when
    /// asked (by an observer's [`Observer::step`]); `None` before the first step.
    pub fn last_step_event(&self) -> Option<StepEvent> {
        let (start, end) = (&self.integrator.saved, &self.state);
        if self.switching.is_empty() || start.t == end.t {
            return None;
        }
        let mut nodes: [Vec<NodeState>; 2] = Default::default();
        node_states_into(start, &mut nodes[0]);
        node_states_into(end, &mut nodes[1]);
        let (mut first, mut uncovered) = (None, None);
        let mut held = Vec::new();
        self.visit(&self.switching, &nodes, |kernel, ctx, start, end, x0| {
            let Some(what) = kernel.event(ctx, start, end) else {
                return;
            };
            match kernel.event_map(ctx, start, end) {
                Some(map) => held.extend(map.into_iter().map(|(a, b)| (x0 + a, x0 + b))),
                None => {
                    uncovered.get_or_insert(what.clone());
                }
            }
            first.get_or_insert(what);
        });
        let t = end.t;
        match uncovered {
            Some(what) => Some(StepEvent {
                t,
                what,
                held: None,
            }),
            None => first.map(|what| StepEvent {
                t,
                what,
                held: Some(held),
            }),
        }
    }

    /// Calls `visit` with each element with events, the context at the end of the step, the
    /// element's kinematics and states at the start and end of the step (node kinematics
    /// from `event_nodes`) and the index of its first state.
    fn visit_events(&self, visit: impl FnMut(&Kernel<'_>, &Context, &Local, &Local, usize)) {
        self.visit(&self.events, &self.event_nodes, visit);
    }

    /// [`Simulation::visit_events`] for the elements `elements` (indices in the layout), with
    /// the node kinematics `nodes` at the start and end of the step.
    fn visit(
        &self,
        elements: &[usize],
        nodes: &[Vec<NodeState>; 2],
        mut visit: impl FnMut(&Kernel<'_>, &Context, &Local, &Local, usize),
    ) {
        let layout = &self.data.layout;
        let t = self.state.t;
        let ctx = Context::at(&self.model, t, self.settings.load_factor_at(t));
        let (start, end) = (&self.integrator.saved, &self.state);
        let [n0, n1] = nodes;
        let (mut b0, mut b1) = (LocalBuffers::default(), LocalBuffers::default());
        for &e in elements {
            let kernel = layout.elements[e].kernel(&self.model);
            let x0 = layout.state_start[e];
            b0.gather(&kernel, n0, (&start.x, &start.xdot, x0), &start.lambda);
            b1.gather(&kernel, n1, (&end.x, &end.xdot, x0), &end.lambda);
            visit(&kernel, &ctx, &b0.local(n0), &b1.local(n1), x0);
        }
    }

    /// The diagnosis of a step that cannot be completed.
    fn failed(&self, error: NewtonError, h: f64, thrashing: bool) -> SolveError {
        let worst = error
            .unknown()
            .map(|i| self.data.layout.describe_unknown(&self.model, i))
            .unwrap_or_else(|| "unknown".into());
        let unknown = error.unknown().map(|i| self.data.layout.unknown(i));
        SolveError::NewtonFailed {
            step: self.stats.steps + 1,
            t: self.state.t,
            h,
            reductions: self.control.reductions,
            reason: if thrashing {
                format!(
                    "{error} ({} steps rejected so far)",
                    self.stats.rejected_steps
                )
            } else {
                error.to_string()
            },
            error: Box::new(error),
            unknown,
            worst_equation: worst,
        }
    }

    /// Bookkeeping of an accepted step of size `h`.
    fn accepted(&mut self, newton: &NewtonInfo, h: f64) {
        let t_new = self.state.t;
        self.stats.steps += 1;
        self.stats.max_iterations_in_a_step = self
            .stats
            .max_iterations_in_a_step
            .max(newton.final_iterations);
        match newton.multiplier_limit {
            Some(MultiplierLimit::Undetermined) => self.stats.undetermined_multipliers += 1,
            Some(MultiplierLimit::RoundOff) => {
                self.stats.multiplier_floor_steps += 1;
                if newton.multiplier_norm > self.stats.multiplier_floor {
                    self.stats.multiplier_floor = newton.multiplier_norm;
                    self.stats.multiplier_floor_t = t_new;
                }
            }
            None => {}
        }
        if let Some(check) = &newton.check {
            let layout = &self.data.layout;
            Verification::add(&mut self.verification, check, t_new, layout, &self.model);
        }
        if self.keep_steps {
            // What the step was, in its own layout (the rows may be chosen again now).
            let mut unknowns = std::mem::take(&mut self.integrator.unknowns);
            self.step_unknowns_into(&mut unknowns);
            self.integrator.unknowns = unknowns;
            self.integrator.redundant_rows = self.data.layout.redundant_rows();
        }
        self.watch_redundant_rows();
        if self.stats.steps == 1 || h < self.stats.smallest_step {
            self.stats.smallest_step = h;
        }
        self.control.accepted(t_new, self.settings.h);
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
        match self.redundancy.pivot_reference {
            None => self.redundancy.pivot_reference = Some(pivot),
            Some(reference) if pivot < 1e-2 * reference => {
                self.reselect_redundant_rows();
                self.redundancy.pivot_reference = None;
            }
            Some(_) => {}
        }
    }

    /// Chooses the redundant constraint rows again at the current configuration; when they
    /// change, rebuilds the data for the new rows (the multipliers of the rows removed now
    /// are zero; the total constraint force, hence the motion, does not depend on which
    /// rows carry it) and returns `true`.
    fn reselect_redundant_rows(&mut self) -> bool {
        let model = &*self.model;
        let Some(redundant) =
            initial::reselect_redundant_rows(model, &self.data.layout, &self.state.q)
        else {
            return false;
        };
        let layout = Layout::with_rows(model, self.data.layout.stabilized, &redundant);
        let Ok(data) = Data::new(model, layout) else {
            return false;
        };
        self.data = data.with_threads(self.data.threads.clone());
        for &row in &redundant {
            self.state.lambda[row] = 0.0;
        }
        self.integrator.previous.h = 0.0;
        self.newton.forget_matrix();
        self.redundancy.pivot_reference = None;
        self.stats.reselections += 1;
        if self.stats.reselections == 1 {
            self.redundancy.first_reselection = self.state.t;
        }
        true
    }

    /// One attempt at the generalized-alpha step to `t_new` (see [`step`] for the step as
    /// functions): the predictor, then the Newton solve of [`StepSystem`].
    fn attempt(&mut self, t_new: f64) -> Result<NewtonInfo, NewtonFailure> {
        let model = &*self.model;
        let it = &mut self.integrator;
        it.saved.clone_from(&self.state);
        let h = t_new - it.saved.t;
        let start = step::Start::new(self.params, h, self.mass, &self.settings, t_new);
        it.scale = start.scale;
        let stabilized = self.data.layout.stabilized;
        node_states_into(&it.saved, &mut it.nodes);
        if stabilized {
            it.b_start.resize(self.data.layout.n_rows, Vec12::zeros());
            crate::assembly::constraint_rows(
                model,
                &self.data.layout,
                &it.nodes,
                it.saved.t,
                &mut it.b_start,
            );
        }
        let extrapolate = it.previous.extrapolation(h);
        step::predict(
            &self.params,
            &start.first,
            h,
            &it.saved,
            extrapolate.as_ref(),
            start.chart(model.group),
            &mut self.state,
            &mut it.increments,
        );
        self.state.t = t_new;
        let max_mu = force_scale(model, &self.data, &it.saved, &self.settings) * start.scale;
        let accelerations = acceleration_scale(model, &it.saved, &self.settings);
        let servo_forces = servo_forces(model, &self.data.layout);
        let mut sys = StepSystem {
            model,
            start,
            settings: &self.settings,
            saved: &it.saved,
            state: &mut self.state,
            dq: &mut it.increments,
            zeta: &mut it.zeta,
            total: &mut it.total,
            nodes: &mut it.nodes,
            b_start: &it.b_start,
            mu_floor: &mut it.mu_floor,
            max_mu,
            accelerations,
            servo_forces: &servo_forces,
            previous: &mut it.previous,
        };
        sys.reset_zeta(self.data.layout.n_active);
        let result = self.newton.solve(&mut sys, &mut self.data, h);
        match result {
            Ok(info) => {
                sys.finish(&self.data.layout, &self.data.threads);
                let it = &mut self.integrator;
                // The stabilized form keeps the linear predictor: there the approximate
                // matrix's rates, measured from a closer start, look slower and rebuild it
                // (the Bricard mechanism, index 2: a factorization at every step with
                // either quantity quadratic, against 177 in 10 000 steps).
                let quadratic = self.settings.adaptive_predictor && !self.data.layout.stabilized;
                it.previous
                    .choose_and_shift(h, &it.saved, &self.state, quadratic);
                Ok(info)
            }
            Err(failure) => {
                self.integrator.previous.h = 0.0;
                Err(failure)
            }
        }
    }
}

/// The Newton system of one generalized-alpha step: the iterate `(dq, mu, zeta)` held as
/// the increments, the state's `v`, `vdot` and multipliers (updated by the corrections as
/// the scheme's affine relations give them) and the stabilization unknowns.
struct StepSystem<'a> {
    model: &'a Model,
    start: step::Start,
    settings: &'a DynamicSettings,
    saved: &'a State,
    state: &'a mut State,
    dq: &'a mut Vec<f64>,
    zeta: &'a mut Vec<f64>,
    total: &'a mut Vec<f64>,
    nodes: &'a mut Vec<NodeState>,
    b_start: &'a [Vec12],
    mu_floor: &'a mut Vec<f64>,
    /// Scaled force scale of the multipliers' tolerance ([`force_scale`]).
    max_mu: f64,
    /// The model's accelerations, translation and rotation ([`acceleration_scale`]).
    accelerations: [f64; 2],
    /// The states that are the forces of servo constraints ([`servo_forces`]).
    servo_forces: &'a [usize],
    previous: &'a mut Previous,
}

impl StepSystem<'_> {
    fn reset_zeta(&mut self, n_active: usize) {
        self.zeta.clear();
        self.zeta.resize(n_active, 0.0);
    }

    /// `dq + B(q_n)^T zeta` into `total` (stabilized), `dq` otherwise.
    fn update_total(&mut self, layout: &Layout) {
        step::total_increments(layout, self.dq, self.zeta, self.b_start, self.total);
        let (group, v_1) = (self.model.group, &self.state.v);
        step::commutator_correction(&self.start, group, self.saved, v_1, self.total);
    }

    /// The node corrections `dx` where the step carries them furthest (the Newton module's
    /// "Where the error lands"): the accelerations move by `beta' dx`, weighted by `rtol`
    /// times the model's accelerations of the same kind (translation, rotation; a kind
    /// without acceleration is left to the configuration norm), the root mean square over
    /// the node unknowns. The weight has a floor at the round-off of the increments
    /// (`1000 eps` times each node's increment of that kind), which a chord iteration cannot
    /// go below. Index 3 only ([`NonlinearSystem::norms`]' caller): there a fresh matrix is
    /// exact or nearly, so that a reused one must reach what it reaches; the stabilized
    /// form's matrix is an approximation whose own iterates converge linearly (0.15 per
    /// correction on the stabilized heavy top), and judged at this level they do not reach
    /// it in `max_iterations` at `rtol = 1e-10` (`tests/sensitivity/sensitivity.rs`, stabilized top).
    fn carried_norm(&self, dx: &[f64]) -> f64 {
        let (bp, rtol) = (self.start.bp, self.settings.newton.rtol);
        let mut sum = 0.0;
        for (d, inc) in dx.chunks_exact(6).zip(self.dq.chunks_exact(6)) {
            for part in 0..2 {
                let a = self.accelerations[part];
                if a == 0.0 {
                    continue;
                }
                let range = 3 * part..3 * part + 3;
                let increment = inc[range.clone()].iter().map(|v| v * v).sum::<f64>().sqrt();
                let roundoff = 1e3 * f64::EPSILON * increment;
                let weight = rtol * a + bp * roundoff;
                sum += d[range]
                    .iter()
                    .map(|d| (bp * d / weight).powi(2))
                    .sum::<f64>();
            }
        }
        (sum / dx.len().max(1) as f64).sqrt()
    }

    /// Final configuration and algorithmic acceleration.
    fn finish(&mut self, layout: &Layout, threads: &crate::parallel::Threads) {
        self.update_total(layout);
        step::finish(
            &self.start,
            self.model.group,
            self.saved,
            self.total,
            self.state,
            threads,
        );
    }
}

impl NonlinearSystem for StepSystem<'_> {
    fn assemble(&mut self, data: &mut Data, matrix: bool, regularization: f64) {
        self.update_total(&data.layout);
        step::kinematics(
            &self.start,
            self.model.group,
            self.saved,
            self.state,
            self.total,
            matrix,
            self.nodes,
            &data.threads,
        );
        if matrix {
            // The commutator update: the increments' columns take T (I + E) (step module
            // documentation); the stabilized form's zeta columns take it too, which costs
            // that form's Newton iteration a contraction of order sigma h |v| only.
            for (node, v) in self.nodes.iter_mut().zip(&self.saved.v) {
                if let Some(e) = self.start.increment_map(self.model.group, v) {
                    node.t *= e;
                }
            }
        }
        let sc = self.start.scaling(regularization);
        let it = Iterate {
            nodes: self.nodes,
            t: self.state.t,
            lambda: &self.state.lambda,
            b_start: self.b_start,
            x: &self.state.x,
            xdot: &self.state.xdot,
            inputs: None,
        };
        assemble(self.model, data, &it, &sc, matrix);
    }

    fn matrix_assembled(&mut self, data: &mut Data) {
        update_multiplier_floor(self.model, self.saved, data, self.mu_floor);
    }

    fn apply(&mut self, data: &Data) {
        step::correct(
            &data.layout,
            &data.correction,
            (&self.start, self.model.group, self.total),
            self.dq,
            self.zeta,
            self.state,
        );
    }

    fn norms(&self, data: &Data) -> Norms {
        let newton = &self.settings.newton;
        let layout = &data.layout;
        let (nd, na) = (layout.n_dofs, layout.n_active);
        let dx = &data.correction;
        let (q, worst_q) = weighted_norm(&dx[..nd], self.dq, &|_| newton.atol, newton.rtol);
        let (mut mu, mut worst_mu) = (0.0, nd);
        if na > 0 {
            let relative = newton.rtol * self.max_mu;
            let dmu = &dx[nd..nd + na];
            let (e, w) = weighted_norm(dmu, dmu, &|k| relative + self.mu_floor[k], 0.0);
            (mu, worst_mu) = (e, nd + w);
        }
        let zeta = if layout.stabilized {
            let range = layout.block(Block::Stabilization);
            weighted_norm(&dx[range], self.zeta, &|_| newton.atol, newton.rtol).0
        } else {
            0.0
        };
        let states = &dx[layout.block(Block::States)];
        let (mut x, mut worst_x) =
            weighted_norm(states, &self.state.x, &|_| newton.atol, newton.rtol);
        if !self.servo_forces.is_empty() {
            // A servo's force is a constraint force: judged with the multipliers, whose
            // corrections that stop halving with the exact matrix are taken for round-off
            // once the configuration has converged (`NewtonSolver`). A non-collocated
            // servo's needs it: the round-off of its correction grows as h^-7 on the
            // two-car example (flexmb::elements::control, "Servo constraints").
            let weight = |i: usize| newton.atol + newton.rtol * self.state.x[i].abs();
            let (mut sum_x, mut sum_s, mut worst_s) = (0.0, 0.0, (0.0, 0));
            for (i, d) in states.iter().enumerate() {
                let e = (d / weight(i)).powi(2);
                if self.servo_forces.contains(&i) {
                    sum_s += e;
                    if e > worst_s.0 || !e.is_finite() {
                        worst_s = (e, i);
                    }
                } else {
                    sum_x += e;
                }
            }
            let (ns, nx) = (
                self.servo_forces.len(),
                states.len() - self.servo_forces.len(),
            );
            x = (sum_x / nx.max(1) as f64).sqrt();
            if x == 0.0 || self.servo_forces.contains(&worst_x) {
                worst_x = (0..states.len())
                    .filter(|i| !self.servo_forces.contains(i))
                    .max_by(|&a, &b| {
                        (states[a] / weight(a))
                            .abs()
                            .total_cmp(&(states[b] / weight(b)).abs())
                    })
                    .unwrap_or(0);
            }
            let servo = (sum_s / ns as f64).sqrt();
            let total = (mu * mu * na as f64 + sum_s) / (na + ns) as f64;
            if servo > mu {
                worst_mu = layout.state_offset() + worst_s.1;
            }
            mu = total.sqrt();
        }
        let worst = if x > q.max(mu) {
            layout.state_offset() + worst_x
        } else if q >= mu {
            worst_q
        } else {
            worst_mu
        };
        Norms {
            blocks: [q, mu, zeta, x],
            n: 4,
            multipliers: Some(1),
            stabilization: layout.stabilized.then_some(2),
            worst,
            carried: if self.near_exact_matrix() {
                self.carried_norm(&dx[..nd])
            } else {
                0.0
            },
        }
    }

    fn exact_matrix(&self) -> bool {
        if self.start.in_chart() {
            // The Lie algebra updates: the matrix omits the derivatives of `M` and `N` in
            // `v = M Theta'` and `vdot = M Theta'' + N` ([`Self::near_exact_matrix`]).
            return false;
        }
        // The stabilized form's iteration matrix is an approximation: it omits the O(h)
        // derivative of B(q) v with respect to q, the equilibrium rows' dependence on zeta
        // (through q), and the T in B T B(q_n)^T ([`step::StepFunction::jacobian`] has them
        // all). Index 3: the matrix is exact.
        self.b_start.is_empty()
    }

    fn near_exact_matrix(&self) -> bool {
        // The Lie algebra updates' matrix, in right-trivialized corrections, has `gamma'`
        // and `beta'` where the Jacobian also has the derivatives of `M` and `N` (step
        // module documentation), of size |v| and |v|^2 + |vdot|: a contraction of order
        // h^2 |v|^2 on inertia and beta h |v| / (2 gamma) on damping for the exponential
        // chart, of order h |v| in R3xSO(3)'s chart on SE(3). The stabilized form's matrix
        // is approximate anyway, and keeps its rule: near exact is index 3, whatever the
        // update.
        self.b_start.is_empty()
    }

    fn restart(&mut self) {
        // As a new attempt after a failure: from the start of the step, predictor without
        // extrapolation.
        let t = self.state.t;
        self.state.clone_from(self.saved);
        self.previous.h = 0.0;
        step::predict(
            &self.start.params,
            &self.start.first,
            self.start.h,
            self.saved,
            None,
            self.start.chart(self.model.group),
            self.state,
            self.dq,
        );
        self.state.t = t;
        let n = self.zeta.len();
        self.reset_zeta(n);
    }
}

/// The model's accelerations at the start of the step, against which the acceleration
/// errors of an iterate are judged ([`StepSystem::carried_norm`]): the largest
/// translational acceleration of a node plus gravity \[m/s^2\], and the largest angular
/// acceleration \[rad/s^2\] (each node's `vdot`, in the group's frame). The multipliers'
/// tolerance takes the forces of the same accelerations ([`force_scale`]).
fn acceleration_scale(model: &Model, saved: &State, settings: &DynamicSettings) -> [f64; 2] {
    let g = model.gravity.norm() * settings.load_factor_at(saved.t);
    let scale = saved.vdot.iter().fold([0.0f64; 2], |[t, r], a| {
        [
            t.max(a.fixed_rows::<3>(0).norm() + g),
            r.max(a.fixed_rows::<3>(3).norm()),
        ]
    });
    // A kind whose accelerations are round-off beside the other's (the translations of
    // wheels on their bearings) has none to judge against.
    let noise = ACCELERATION_NOISE * scale[0].max(scale[1]);
    scale.map(|a| if a > noise { a } else { 0.0 })
}

/// Accelerations of one kind (translation or rotation, SI units) below this fraction of the
/// other kind's are taken for round-off by [`acceleration_scale`] (a gear pair on bearings:
/// 1e-27 to 4e-20 m/s^2 beside 620 rad/s^2).
const ACCELERATION_NOISE: f64 = 1e-8;

/// Force scale of the multipliers' tolerance at the start of the step: the largest
/// multiplier and the largest nodal force `m (|vdot| + |g|)` (or moment `J |vdot|`). A
/// joint carrying no load yet (multipliers near zero) is then judged against the forces of
/// the system instead of against round-off.
fn force_scale(model: &Model, data: &Data, saved: &State, settings: &DynamicSettings) -> f64 {
    let g = model.gravity.norm() * settings.load_factor_at(saved.t);
    let nodal = saved
        .vdot
        .iter()
        .zip(&data.nodal_mass)
        .map(|(a, m)| {
            let translation = m[0] * (a.fixed_rows::<3>(0).norm() + g);
            translation.max(m[3] * a.fixed_rows::<3>(3).norm())
        })
        .fold(0.0, f64::max);
    let lambda = saved.lambda.iter().fold(0.0f64, |m, l| m.max(l.abs()));
    lambda.max(nodal)
}

/// The states of `layout` that are the forces of servo constraints (the outputs of servo
/// blocks, indices among the states).
fn servo_forces(model: &Model, layout: &Layout) -> Vec<usize> {
    let system = &model.control;
    // the diagram is the last element (`ElementItem::all`): its unknowns end the states
    let start = layout.n_states - system.n_unknowns;
    system
        .blocks
        .iter()
        .enumerate()
        .filter(|(_, b)| matches!(b.kind, crate::model::control::BlockKind::Servo { .. }))
        .map(|(b, _)| start + system.output_start[b])
        .collect()
}

/// Round-off floor of each active scaled multiplier, `1000 eps L D_k` (`L` the size of the
/// model, `D_k` the largest diagonal entry of the iteration matrix just assembled on the
/// dofs of the row's nodes: mass, damping and stiffness, scaled): the size of the round-off
/// in the equilibrium rows that the multiplier balances. It matters only where every force
/// of the model is near zero (a mechanism starting from rest without gravity), and keeps
/// the test from asking for a multiplier below round-off.
fn update_multiplier_floor(model: &Model, saved: &State, data: &mut Data, mu_floor: &mut Vec<f64>) {
    let length = saved.q.iter().fold(1e-3f64, |m, q| m.max(q.x.norm()));
    let roundoff = 1e3 * f64::EPSILON * length;
    data.diagonal.fill(0.0);
    for &(i, slot) in &data.diagonal_slots {
        data.diagonal[i] += data.values[slot];
    }
    let layout = &data.layout;
    mu_floor.clear();
    mu_floor.resize(layout.n_active, 0.0);
    for (j, joint) in model.joints.iter().enumerate() {
        let start = layout.joint_row_start[j];
        let mut d = 0.0f64;
        for n in [joint.node_a, joint.node_b].into_iter().flatten() {
            d = data.diagonal[6 * n.0..6 * n.0 + 6]
                .iter()
                .fold(d, |m, v| m.max(v.abs()));
        }
        for r in 0..layout.joint_rows[j].len() {
            if let Some(k) = layout.row_unknown[start + r] {
                mu_floor[k] = roundoff * d;
            }
        }
    }
}

/// The ends of the steps of a run. Steps of size `h` end at `anchor + k h` (`k` steps since
/// `h` last changed), free of the round-off that summing `t += h` accumulates; the last
/// steps before a target (an output time or the end) end exactly on it, and none is shorter
/// than `h / 2` unless the whole interval is: a remainder below `h / 2` is shared with the
/// step before it (two equal steps), a remainder within round-off of `h` is taken whole.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct StepClock {
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
