//! Sensitivity analysis of a dynamic run: the gradients of criteria with respect to model
//! parameters, exact for the computed discrete solution (Brüls & Eberhard 2008; Sonneville
//! & Brüls 2014, Multibody Syst. Dyn. 31, for the Lie group formulation).
//!
//! # The discrete equations differentiated
//!
//! Step `n` of the Lie group generalized-alpha method ([`crate::solve::step`]) is a system
//! `R(x_n; s_{n-1}, p) = 0` in its unknowns `x_n = (dq, mu, zeta, dx)` given the start
//! `s_{n-1} = (q, v, vdot, a, lambda, x, xdot, w)` and the parameters `p`; the end state is
//! explicit, `s_n = E(x_n, s_{n-1}, p)` (`q_n = q_{n-1} exp(dq + B(q_{n-1})^T zeta)`, the
//! other relations affine). Configuration tangents live in the algebra: `dq/dp = q
//! tilde(w)`, `w` a vector of 6 per node ([`StateTangent`]). A criterion is
//! `J = sum_n c_n f(s_n, p)` ([`criteria`]: `c_n` the terminal or trapezoidal weights).
//!
//! **Direct differentiation** (one linear solve per parameter and step, with the exact
//! Jacobian `J_x = dR/dx` factorized once per step at the converged point):
//!
//! ```text
//! ds_0/dp        from the initial accelerations ([`initial`])
//! J_x dx_n/dp    = -(dR/ds_{n-1} ds_{n-1}/dp + dR/dp)
//! ds_n/dp        = E_x dx_n/dp + E_s ds_{n-1}/dp + E_p
//! dJ/dp          = sum_n c_n (f_s ds_n/dp + f_p)
//! ```
//!
//! **Discrete adjoint** (one backward sweep, one transposed solve per criterion and step,
//! cost independent of the number of parameters): with `sbar_N = c_N f_s(s_N)` and
//! `pbar = sum_n c_n f_p(s_n)`, for `n = N, ..., 1`
//!
//! ```text
//! J_x^T mu_n     = E_x^T sbar_n
//! sbar_{n-1}     = E_s^T sbar_n - (dR/ds_{n-1})^T mu_n + c_{n-1} f_s(s_{n-1})
//! pbar          += E_p^T sbar_n - (dR/dp)^T mu_n
//! dJ/dp          = pbar + sbar_0 . ds_0/dp
//! ```
//!
//! The products are those of [`crate::solve::step::StepFunction`] (`start_jvp`, `start_vjp`,
//! `parameter_jvp`, `parameter_vjp_for`, `end_jvp`, `end_vjp`, `jacobian_values`); the same code serves
//! both methods, so they agree to round-off. The Jacobian of a step does not depend on the
//! recursion, only on the step: with several threads, workers prepare the steps' Jacobians
//! ahead of it (`pipeline.rs`), with the same results bit for bit. The step sizes of the run
//! are taken as given
//! (an adaptive step sequence is not differentiated). The backward sweep needs every step's
//! start, unknowns and end: kept in memory when they fit in
//! [`Problem::memory_budget`], otherwise recomputed from checkpoints every `k` steps
//! ([`crate::solve::trajectory::Trajectory`]).
//!
//! # Events
//!
//! The gradients are those of the step equations along the run's steps. Where an element's
//! law switches, that is not the derivative of the criterion: an **event**
//! ([`crate::elements::ElementKernel::event`]) is a contact that closes or opens, a flank of
//! a gear pair with backlash or damping that closes or opens, a hold of a control diagram
//! that samples. There the step control places the steps by the event (the step sizes
//! depend on the parameters), the element resets a held state between steps (a contact's
//! impact velocity, a hold's value: maps the step equations do not contain) or a force
//! jumps (a gear's damping on a closing flank). On a steel ball dropped on a plane
//! (`examples/ball_drop.toml`: restitution 0.8, its height at t = 1 s, `h = 1e-2`) the
//! adjoint gave d height / d restitution = -132, +210 and -93.6 at `h` = 1e-2, 1e-4 and
//! 2e-5, where central differences with a relative step of 1e-2 give +0.48; on the gear
//! rattle of `examples/gear_rattle.toml` (at `h = 1e-4` to 0.04 s, its wheel's speed and the
//! integral of the squared transmission error with respect to the mesh's damping, stiffness
//! and backlash) the adjoint and central differences differed in sign on four of six.
//!
//! So the direct and adjoint methods, and the optimizer, stop a run at its first event with
//! [`SensitivityError::Event`], which names the element and the time. The decision is the
//! run's ([`crate::solve::Simulation::last_step_event`] after every step), not the model's:
//! a contact that does not close during the run, a gear pair whose flank does not open, have
//! no event, and their gradients are exact. So are those of a run whose steps are cut to
//! reach output times (the cuts do not depend on the parameters), and those of laws with
//! kinks that have no event (force tables, one-sided springs, slack ropes, limiters): the
//! derivative of the side a step ends on (one-sided at a kink a step ends on; a damped
//! one-sided spring's force jumps where it engages, and its gradients across that are not
//! meaningful either). Followed exactly: the samples of a hold, at fixed times, whose map is a
//! copy of states ([`crate::elements::ElementKernel::event_map`],
//! [`crate::solve::StepEvent::held`]): the direct method's tangents take it after the step
//! ([`StateTangent::hold`]), the adjoint's cotangents its transpose before it. (Before, a
//! model with a hold was refused: with a hold of period 0.1 s between the controller and the
//! motor of `examples/pid_mass_spring.toml`, the held value's derivative decayed like e^-t
//! from its start, 2.6 % off on the position at t = 0.08 s. The statics' diagonal of the
//! hold's row, `x = x_start`, leaked into the step's `dE/dx` and the initial tangents'
//! `dG/dx_0`, which take their coefficients one at a time.) The finite differences
//! ([`finite_differences`]) run through events: with a step larger than the events' noise
//! they estimate the gradient.
//!
//! # References
//! - O. Brüls, P. Eberhard, Sensitivity analysis for dynamic mechanical systems with finite
//!   rotations, Int. J. Numer. Meth. Eng. 74 (2008) 1897-1927.
//! - V. Sonneville, O. Brüls, Sensitivity analysis for multibody systems formulated on a Lie
//!   group, Multibody Syst. Dyn. 31 (2014) 47-67.

pub mod check;
pub mod criteria;
pub mod expression;
pub mod initial;
pub mod matrix;
pub mod optimize;
pub mod report;
pub mod sensor_derivative;

mod adjoint;
mod direct;
mod finite_differences;
mod pipeline;
pub(crate) mod statics;

pub use adjoint::{adjoint, adjoint_in, Workspace};
pub use criteria::{CriteriaSet, Criterion, CriterionKind, Reference};
pub use direct::direct;
pub use finite_differences::{criteria_values, finite_differences};

use crate::data::Layout;
use crate::error::SolveError;
use crate::model::{Model, ParamId, Parameters};
use crate::solve::observe::{Observer, Sample, StepRecord};
use crate::solve::step::StateTangent;
use crate::solve::trajectory::TrajectoryStep;
use crate::solve::Analysis;
use crate::solve::{DynamicSettings, StepEvent};
use criteria::History;
use std::sync::Arc;

/// How the gradients are computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Direct differentiation ([`direct`]).
    Direct,
    /// The discrete adjoint ([`adjoint`]).
    Adjoint,
    /// Central finite differences ([`finite_differences`]), for checking.
    Fd,
}

/// A design parameter: a model parameter by its path, with the scale of the optimizer's
/// variable `u = p / scale` and optional bounds on `p`.
#[derive(Clone, Debug, PartialEq)]
pub struct DesignParameter {
    pub path: String,
    pub id: ParamId,
    pub scale: f64,
    pub lower: Option<f64>,
    pub upper: Option<f64>,
}

/// The sensitivity analysis a model file asks for (`[sensitivity]`, `[[design_parameter]]`,
/// `[[reference]]`, `[[criterion]]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Setup {
    pub design: Vec<DesignParameter>,
    pub criteria: CriteriaSet,
    pub method: Method,
    /// Relative step of the finite differences.
    pub fd_step: f64,
    /// Bytes the adjoint may keep for the trajectory.
    pub memory_budget: usize,
}

impl Setup {
    /// The problem of this setup on `model` (the model of the same file) and its analysis.
    pub fn problem(&self, model: Arc<Model>, analysis: Analysis) -> Problem {
        let design = self.design.iter().map(|d| d.id).collect();
        Problem {
            memory_budget: self.memory_budget,
            scales: self.design.iter().map(|d| d.scale).collect(),
            ..Problem::new(model, analysis, design, self.criteria.clone())
        }
    }
}

/// The gradients of `problem` by `method` (`fd_step`: relative step of finite differences;
/// `progress`: the adjoint's backward sweep, `(steps done, steps)`).
pub fn gradients(
    problem: &Problem,
    method: Method,
    fd_step: f64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Gradients, SensitivityError> {
    match (method, &problem.analysis) {
        (Method::Fd, _) => finite_differences(problem, fd_step),
        (method, Analysis::Static(_)) => statics::gradients(problem, method == Method::Direct),
        (Method::Direct, _) => direct(problem),
        (Method::Adjoint, _) => adjoint(problem, progress),
    }
}

/// Default relative step of the finite differences.
pub const DEFAULT_FD_STEP: f64 = 1e-6;

/// The range of the relative step of the finite differences, `[sensitivity] fd_step` and
/// `--fd-step` alike: from where a step still moves a parameter by many units of its
/// round-off (2.2e-16 relative) to where a central difference is no longer a derivative.
pub const FD_STEP_RANGE: (f64, f64) = (1e-12, 0.1);

/// The range of the adjoint's memory budget in MiB, `[sensitivity] memory_budget_mb` and
/// `--memory-mb` alike.
pub const MEMORY_BUDGET_MB_RANGE: (f64, f64) = (1.0, 1e6);

/// What a sensitivity analysis can fail on, in two classes ([`SensitivityError::is_refusal`]):
/// a problem that cannot be analysed as it is asked (the model, its settings, the analysis
/// asked for, an event in the run), and a run that failed.
#[derive(Debug, thiserror::Error)]
pub enum SensitivityError {
    #[error(transparent)]
    Solve(#[from] SolveError),
    /// A matrix of the derivatives is singular.
    #[error("sensitivity: {0} is singular; the derivatives are not defined there")]
    Singular(String),
    /// The problem asks for something the method does not do (found before the first step).
    #[error("sensitivity: {0}")]
    Unsupported(String),
    /// The run ended where the derivatives cannot be taken (a static analysis whose final
    /// point is not an equilibrium).
    #[error("sensitivity: {0}")]
    Unconverged(String),
    /// The adjoint's memory budget is too small for one segment of steps and its
    /// checkpoints (sizes in bytes).
    #[error(
        "sensitivity: the memory budget of {} MiB is too small for the adjoint of {steps} steps (a step takes about {step_bytes} bytes, a checkpoint {checkpoint_bytes}); it needs at least {} MiB (--memory-mb, or memory_budget_mb of [sensitivity])",
        mib(*budget),
        (10.0 * mib(*needed)).ceil() / 10.0
    )]
    MemoryBudget {
        budget: usize,
        needed: usize,
        steps: usize,
        step_bytes: usize,
        checkpoint_bytes: usize,
    },
    /// The run has an event (module documentation, "Events"): `what` happened in the step
    /// that ends at `t`, the run's first event.
    #[error(
        "sensitivity: {what} in the step ending at t = {t:.6e} s, the run's first event: the gradients of a run through an event are not exact (the steps are placed by it, held states are reset at it, a force switches), so they are not computed; what works: --method fd with a step larger than the event's noise (e.g. --fd-step 1e-2), or a model without the event (a smooth law: e.g. a one-sided spring instead of a contact; docs/model-format.md, \"Sensitivity analysis\")"
    )]
    Event { what: String, t: f64 },
    /// A run of the finite differences failed (`failed`: why), or its step leaves the
    /// parameter unchanged (`failed: None`).
    #[error(
        "finite differences: {}",
        match failed {
            Some(e) => format!("the run with {path} = {value} (step {step:e}) failed: {e}"),
            None => format!("the step {step:e} leaves {path} = {value} unchanged: choose a larger --fd-step"),
        }
    )]
    FiniteDifference {
        path: String,
        value: f64,
        step: f64,
        failed: Option<Box<SensitivityError>>,
    },
    /// The optimizer stopped on an error of its own.
    #[error("optimization: {0}")]
    Optimization(String),
}

impl SensitivityError {
    /// Whether the problem cannot be analysed as it is asked: the model, its settings or
    /// initial conditions (found before the first step, as `flexmb run` finds them), a
    /// method that does not apply, a memory budget too small, an event in the run, a
    /// finite-difference step that leaves a parameter unchanged. `flexmb` exits with 2 for
    /// these and with 1 for the rest: a run that failed (a step that did not converge, a
    /// singular matrix of the derivatives).
    pub fn is_refusal(&self) -> bool {
        match self {
            SensitivityError::Solve(e) => e.is_before_first_step(),
            SensitivityError::Unsupported(_)
            | SensitivityError::MemoryBudget { .. }
            | SensitivityError::Event { .. } => true,
            SensitivityError::FiniteDifference { failed, .. } => {
                failed.as_ref().is_none_or(|e| e.is_refusal())
            }
            SensitivityError::Singular(_)
            | SensitivityError::Unconverged(_)
            | SensitivityError::Optimization(_) => false,
        }
    }
}

/// Bytes in MiB.
fn mib(bytes: usize) -> f64 {
    bytes as f64 / (1u64 << 20) as f64
}

/// A sensitivity analysis: a dynamic run of `model`, its design parameters and criteria.
#[derive(Clone)]
pub struct Problem {
    pub model: Arc<Model>,
    /// The analysis differentiated: a dynamic run, or a static one (its final point).
    pub analysis: Analysis,
    /// The registry of `model`'s parameters.
    pub params: Parameters,
    /// The parameters differentiated with respect to.
    pub design: Vec<ParamId>,
    /// Their typical magnitudes (the finite differences' step is relative to
    /// `max(|p|, scale)`); 1 by default.
    pub scales: Vec<f64>,
    pub criteria: CriteriaSet,
    /// Bytes the adjoint may keep for the trajectory (default [`DEFAULT_MEMORY_BUDGET`]).
    pub memory_budget: usize,
}

/// Default memory budget of the adjoint's trajectory: 256 MiB.
pub const DEFAULT_MEMORY_BUDGET: usize = 256 << 20;

impl Problem {
    pub fn new(
        model: Arc<Model>,
        analysis: Analysis,
        design: Vec<ParamId>,
        criteria: CriteriaSet,
    ) -> Self {
        let params = Parameters::new(&model);
        Self {
            model,
            analysis,
            params,
            scales: vec![1.0; design.len()],
            design,
            criteria,
            memory_budget: DEFAULT_MEMORY_BUDGET,
        }
    }

    /// The settings of a dynamic analysis (an error for a static one).
    pub fn dynamic(&self) -> Result<&DynamicSettings, SensitivityError> {
        self.analysis.dynamic().ok_or_else(|| {
            SensitivityError::Unsupported(
                "this method differentiates a dynamic analysis; a static one goes through sensitivity::gradients".into(),
            )
        })
    }

    /// The design parameters' current values.
    pub fn values(&self) -> Vec<f64> {
        self.design
            .iter()
            .map(|&id| self.params.value(&self.model, id))
            .collect()
    }

    /// The same problem with the design parameters set to `values`.
    pub fn with_values(&self, values: &[f64]) -> Self {
        let mut model = (*self.model).clone();
        for (&id, &v) in self.design.iter().zip(values) {
            self.params.set(&mut model, id, v);
        }
        Self {
            model: Arc::new(model),
            ..self.clone()
        }
    }

    /// The index in the design of each parameter of the registry (`None`: not a design
    /// parameter).
    fn design_index(&self) -> Vec<Option<usize>> {
        let mut out = vec![None; self.params.len()];
        for (k, id) in self.design.iter().enumerate() {
            out[id.0 as usize] = Some(k);
        }
        out
    }
}

/// The result of a sensitivity analysis.
#[derive(Clone, Debug, PartialEq)]
pub struct Gradients {
    /// Value of each criterion.
    pub values: Vec<f64>,
    /// `dJ_c/dp_k`, `[criterion][design parameter]`.
    pub gradients: Vec<Vec<f64>>,
    /// The step of each parameter (finite differences only).
    pub fd_steps: Option<Vec<f64>>,
    pub stats: Stats,
    /// The warnings of the (nominal) run: what it says about its own solution holds for
    /// the gradients too.
    pub warnings: Vec<String>,
}

/// What a sensitivity analysis did.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Stats {
    /// Forward runs (finite differences: `2 n_p + 1`).
    pub forward_runs: usize,
    /// Steps of the forward run.
    pub steps: usize,
    /// Steps recomputed from checkpoints for the backward sweep (adjoint).
    pub recomputed_steps: usize,
    /// Checkpoints kept (adjoint; 0 when every step was kept).
    pub checkpoints: usize,
    /// Peak bytes of the trajectory kept (adjoint, estimated from the sizes of the stored
    /// vectors).
    pub trajectory_bytes: usize,
    /// Wall time of the adjoint's forward run, recording included \[s\] (0 for the other
    /// methods).
    pub forward_seconds: f64,
    /// Wall time of the adjoint's backward sweep, recomputation from checkpoints included
    /// \[s\] (0 for the other methods).
    pub sweep_seconds: f64,
    /// Threads that computed the steps' exact Jacobians and their factorizations (1: the
    /// thread of the run; 0 for the methods without them: finite differences, statics).
    pub jacobian_threads: usize,
}

/// The fourth-order central difference `(8 (f(e) - f(-e)) - (f(2e) - f(-2e))) / (12 e)` of
/// a vector function (truncation `O(e^4)`; exact for polynomials of degree up to 4).
pub(crate) fn fourth_order_difference(eps: f64, f: &mut dyn FnMut(f64) -> Vec<f64>) -> Vec<f64> {
    let (p1, m1, p2, m2) = (f(eps), f(-eps), f(2.0 * eps), f(-2.0 * eps));
    (0..p1.len())
        .map(|i| (8.0 * (p1[i] - m1[i]) - (p2[i] - m2[i])) / (12.0 * eps))
        .collect()
}

/// The length scale of a model for differences in positions: the largest distance of a node
/// from the origin, at least 1 mm.
pub(crate) fn length_scale(model: &Model) -> f64 {
    model
        .nodes
        .iter()
        .map(|n| n.frame.x.norm())
        .fold(1e-3f64, f64::max)
}

/// Bytes of a state (its vectors' payload).
fn state_bytes(s: &crate::state::State) -> usize {
    let n = s.q.len();
    8 * (12 * n + 18 * n + s.lambda.len() + 3 * s.x.len())
}

/// The design parameters' part of a vector over the whole registry.
fn pick(index: &[Option<usize>], full: &[f64], out: &mut [f64], sign: f64) {
    for (i, k) in index.iter().enumerate() {
        if let Some(k) = k {
            out[*k] += sign * full[i];
        }
    }
}

/// The simulation of a problem and its consistent start, with the tangents `ds_0/dp_k`.
fn start(
    problem: &Problem,
) -> Result<(crate::solve::Simulation, Vec<StateTangent>), SensitivityError> {
    let settings = *problem.dynamic()?;
    let mut ids = problem.design.clone();
    ids.sort_unstable();
    if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
        return Err(SensitivityError::Unsupported(format!(
            "parameter '{}' is twice in the design",
            problem.params.path(w[0])
        )));
    }
    let sim = crate::solve::Simulation::new(Arc::clone(&problem.model), settings)?;
    let redundant = sim.data.layout.redundant_rows();
    let tangents = initial::initial_tangents(
        &problem.model,
        &problem.params,
        &problem.design,
        &sim.state,
        &redundant,
        settings.load_factor_at(0.0),
    )?;
    Ok((sim, tangents))
}

/// The watch on a run's events (module documentation, "Events"): the first step with one
/// stops the run, and the event is kept for the error that says so.
#[derive(Default)]
struct EventWatch(Option<StepEvent>);

impl EventWatch {
    /// An observer's answer to an accepted step: the held states its end sets (copies of
    /// states, [`StepEvent::held`]; empty without an event), or an error (which stops the
    /// run) if the step has an event the derivatives do not go through.
    fn step(&mut self, record: &StepRecord) -> Result<crate::elements::HeldStates, String> {
        match record.simulation.last_step_event() {
            Some(StepEvent {
                held: Some(held), ..
            }) => Ok(held),
            Some(event) => {
                let stopped = format!("stopped at an event: {}", event.what);
                self.0 = Some(event);
                Err(stopped)
            }
            None => Ok(Vec::new()),
        }
    }

    /// The outcome of the run watched: the event that stopped it, if any, else `run`'s.
    fn outcome<T>(self, run: Result<T, SolveError>) -> Result<T, SensitivityError> {
        match self.0 {
            Some(StepEvent { t, what, .. }) => Err(SensitivityError::Event { what, t }),
            None => Ok(run?),
        }
    }
}

/// A forward run's record: the criteria's sensor values at every point and, when asked
/// (`steps: Some`), every step, for a backward sweep. A run whose redundant rows are chosen
/// again is stopped: its gradients are not computed; so is one with an event, when
/// `events` watches them.
struct Recorder<'a> {
    problem: &'a Problem,
    layout: &'a Layout,
    /// The rows the layout leaves out as redundant.
    redundant: Vec<usize>,
    /// The watch on events (`None`: a run of the finite differences, which go through
    /// them).
    events: Option<EventWatch>,
    history: History,
    /// Every step, while kept: `None` from the start, or once more than `most_steps` came.
    /// The first `count` are this run's; the slots beyond are storage of an earlier run,
    /// overwritten in place (an optimizer's [`Workspace`]: no new memory to fault in).
    steps: Option<Vec<TrajectoryStep>>,
    most_steps: usize,
    count: usize,
}

impl Observer for Recorder<'_> {
    fn output(&mut self, _: &Sample) -> Result<(), String> {
        Ok(())
    }
    fn wants_steps(&self) -> bool {
        true
    }
    fn step(&mut self, record: &StepRecord) -> Result<(), String> {
        let p = self.problem;
        if record.redundant_rows != self.redundant.as_slice() {
            return Err(reselected(record.start.t));
        }
        let held = match &mut self.events {
            Some(events) => events.step(record)?,
            None => Vec::new(),
        };
        p.criteria
            .record(&p.model, self.layout, record.end, &mut self.history);
        if self.count >= self.most_steps {
            self.steps = None;
        }
        if let Some(steps) = &mut self.steps {
            if steps.len() == self.count {
                steps.push(TrajectoryStep::default());
            }
            let step = &mut steps[self.count];
            step.index = record.index;
            step.h = record.info.h;
            step.start.clone_from(record.start);
            step.unknowns.clear();
            step.unknowns.extend_from_slice(record.unknowns);
            step.redundant_rows.clear();
            step.redundant_rows.extend_from_slice(record.redundant_rows);
            step.held = held;
        }
        self.count += 1;
        Ok(())
    }
}

/// The message of a run whose redundant rows were chosen again.
fn reselected(t: f64) -> String {
    format!(
        "the redundant constraint rows were chosen again at t = {t:.6e} s; the derivatives of a run across such a change are not computed (the multipliers change their meaning)"
    )
}
