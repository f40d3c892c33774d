//! Static analysis: equilibrium `g_int(q) - lambda g_ext(q) + B(q)^T mu = 0`, `Phi(q) = 0`,
//! followed in the load factor `lambda` (gravity and applied loads are scaled by it).
//!
//! * Load control with adaptive increments: Newton on the configuration increment (a vector
//!   of the Lie algebra, `q = q_k exp(dq)`) and the multipliers at a prescribed `lambda`; the
//!   increment grows after easy steps and is halved after a failed one.
//! * Arc-length continuation (Crisfield 1981, "A fast incremental/iterative solution
//!   procedure that handles snap-through", Comput. Struct. 13; cylindrical form): `lambda`
//!   becomes an unknown and the increment is constrained by `|dq| = Delta l`, so the path is
//!   followed through limit points. Each iteration solves the same iteration matrix twice,
//!   `S da = -R` and `S db = dR/dlambda`, and picks the root of the constraint closest to the
//!   previous direction.
//!
//! The iteration matrix is `[[K_t T, B^T], [B T, 0]]` (the dynamic one without mass and
//! damping), with the equilibrium rows scaled by `1 / max diag K_t` so that forces and
//! constraints are of comparable size.

use super::dynamics::IntoShared;
use super::initial::prepare_layout;
use super::newton::{
    newton_correction, weighted_norm, NewtonError, NewtonFailure, NewtonPolicy, NewtonSettings,
    NewtonSolver, NonlinearSystem, Norms, Verification,
};
use crate::assembly::{assemble, ConstraintRhs, Iterate, Scaling};
use crate::data::{Block, Data};
use crate::elements::{Coefficients, NodeState};
use crate::error::{SettingsError, SolveError};
use crate::linear::LinearError;
use crate::model::limits::within;
use crate::model::Model;
use crate::sensors::node_states;
use crate::solve::observe::{Observer, Sample, Work};
use crate::state::State;
use flexmb_lie::Vec6;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Smallest arc length tried, relative to the first one.
const ARC_LENGTH_MIN: f64 = 1e-6;

/// How the load factor is controlled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum StaticMethod {
    /// Prescribed load factor, adaptive increments.
    LoadControl,
    /// Arc-length continuation (Crisfield), passes limit points.
    ArcLength,
    /// Pseudo-dynamic (dynamic relaxation): the loads are ramped over a pseudo time in a
    /// heavily damped dynamic analysis (nodal viscous damping, rho_inf = 0); the inertia
    /// regularizes singular or ill-conditioned tangents (mechanisms, buckling).
    PseudoDynamic,
}

/// Settings of a static analysis.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StaticSettings {
    /// Final load factor (the loads and gravity of the model are multiplied by it).
    pub load_factor: f64,
    /// First load increment (load control) [load factor].
    pub initial_increment: f64,
    /// Smallest load increment before giving up (load control).
    pub min_increment: f64,
    /// Largest load increment (load control).
    pub max_increment: f64,
    pub method: StaticMethod,
    /// Arc length of the first step (arc-length method) [m, rad]; later steps adapt between
    /// 1e-6 and 4 times this value.
    pub arc_length: f64,
    /// Pseudo-dynamic method: pseudo time of the load ramp \[s\] (the analysis runs twice as
    /// long, the second half at full load to settle); steps of `initial_increment` times it.
    pub pseudo_time: f64,
    /// Pseudo-dynamic method: nodal viscous damping `alpha` [1/s].
    pub pseudo_damping: f64,
    /// Most load steps. An analysis that has taken this many before `load_factor` stops
    /// there with [`SolveError::Incomplete`] (every converged step kept): load control and
    /// arc length alike (the path of arc length may be long, with snap-backs).
    pub max_steps: usize,
    /// Newton iterations aimed at per step: increments grow when fewer are needed.
    pub target_iterations: usize,
    /// Adapt the load increment (load control); `false`: uniform steps of
    /// `initial_increment`, and a failed step stops the analysis.
    pub adaptive: bool,
    pub newton: NewtonSettings,
    /// Re-check every converged load step with a Newton correction from the accepted
    /// configuration and record the largest estimated error ([`Statics::verification`]).
    pub verify: bool,
    /// Threads of the assembly (0: all cores; 1: sequential), as
    /// [`super::DynamicSettings::threads`].
    #[serde(default)]
    pub threads: usize,
}

impl StaticSettings {
    /// Load control to `lambda = 1` starting with 10 increments.
    pub fn new() -> Self {
        Self {
            load_factor: 1.0,
            initial_increment: 0.1,
            min_increment: 1e-6,
            max_increment: 1.0,
            method: StaticMethod::LoadControl,
            arc_length: 0.1,
            max_steps: 10_000,
            target_iterations: 6,
            adaptive: true,
            verify: false,
            threads: 0,
            pseudo_time: 1.0,
            pseudo_damping: 20.0,
            newton: NewtonSettings {
                rtol: 1e-8,
                atol: 1e-10,
                max_iterations: 25,
                reuse_jacobian: false,
                max_contraction: 0.5,
                max_jacobian_age: 1,
            },
        }
    }
}

impl StaticSettings {
    /// Rejects settings out of their ranges (`docs/model-format.md`, "Ranges"): every
    /// increment and its smallest allowed value are finite and normal, so that no loop can
    /// stall on an underflow (a halved increment falls below its positive minimum after
    /// finitely many halvings), and the load factor always advances. The model-file reader
    /// reports these errors at their keys (`increment` is `initial_increment`).
    pub fn check(&self) -> Result<(), SettingsError> {
        use crate::model::limits::{MAX_KINEMATIC, MAX_STEPS, MAX_TIME, MIN_STEP};
        let lf = self.load_factor;
        if !within(lf.abs(), MIN_STEP, MAX_TIME) {
            return Err(SettingsError::new(
                &["load_factor"],
                format!("its size must be between {MIN_STEP:e} and {MAX_TIME:e} (it may be negative, not 0), got {lf:e}"),
            ));
        }
        for (key, v) in [
            ("increment", self.initial_increment),
            ("min_increment", self.min_increment),
            ("max_increment", self.max_increment),
        ] {
            SettingsError::positive(key, v, MIN_STEP, MAX_TIME)?;
        }
        let floor = MIN_STEP * lf.abs().max(1.0);
        if self.min_increment < floor {
            return Err(SettingsError::new(
                &["min_increment", "load_factor"],
                format!(
                    "min_increment = {:e} is below 1e-12 times the load factor {lf} ({floor:e}): the load factor would not advance; raise min_increment",
                    self.min_increment
                ),
            ));
        }
        if self.min_increment > self.max_increment {
            return Err(SettingsError::new(
                &["min_increment", "max_increment"],
                format!(
                    "min_increment = {} exceeds max_increment = {}",
                    self.min_increment, self.max_increment
                ),
            ));
        }
        if self.initial_increment < self.min_increment {
            return Err(SettingsError::new(
                &["increment", "min_increment"],
                format!(
                    "increment = {} is below min_increment = {}",
                    self.initial_increment, self.min_increment
                ),
            ));
        }
        // Its minimum, 1e-6 of it, stays a meaningful length (>= 1e-15).
        SettingsError::range("arc_length", self.arc_length, 1e-9, MAX_KINEMATIC)?;
        SettingsError::positive("pseudo_time", self.pseudo_time, MIN_STEP, MAX_TIME)?;
        SettingsError::range("pseudo_damping", self.pseudo_damping, 0.0, MAX_KINEMATIC)?;
        if self.method == StaticMethod::PseudoDynamic {
            // The pseudo-dynamic run takes steps of increment x pseudo_time over 2 pseudo_time.
            let h = self.initial_increment * self.pseudo_time;
            let steps = 2.0 / self.initial_increment;
            if !within(h, MIN_STEP, MAX_TIME) || steps > MAX_STEPS {
                return Err(SettingsError::new(
                    &["increment", "pseudo_time"],
                    format!(
                        "the pseudo-dynamic step increment x pseudo_time = {h:e} s over 2 pseudo_time ({steps:e} steps) must be at least {MIN_STEP:e} s and make at most {MAX_STEPS:e} steps"
                    ),
                ));
            }
        }
        if !(1..=100_000_000).contains(&self.max_steps) {
            return Err(SettingsError::new(
                &["max_steps"],
                format!("must be between 1 and 100000000, got {}", self.max_steps),
            ));
        }
        if !(1..=10_000).contains(&self.target_iterations) {
            return Err(SettingsError::new(
                &["target_iterations"],
                format!(
                    "must be between 1 and 10000, got {}",
                    self.target_iterations
                ),
            ));
        }
        super::dynamics::check_threads(self.threads)?;
        self.newton.check()
    }
}

impl Default for StaticSettings {
    fn default() -> Self {
        Self::new()
    }
}

/// A static analysis in progress.
pub struct Statics {
    pub model: Arc<Model>,
    pub data: Data,
    /// Converged configuration and multipliers (velocities stay zero).
    pub state: State,
    pub settings: StaticSettings,
    /// Load factor of the converged state.
    pub load_factor: f64,
    pub stats: Work,
    /// What may be wrong with the results, for the user.
    pub warnings: Vec<String>,
    /// Information for the user on what the analysis did as expected (e.g. redundant
    /// constraint rows of closed loops left out).
    pub notes: Vec<String>,
    /// Checked before every load step (and every step of a pseudo-dynamic run): when it is
    /// set, [`Statics::run`] returns [`SolveError::Interrupted`].
    pub interrupt: Option<Arc<AtomicBool>>,
    /// What [`StaticSettings::verify`] found (`None` when it is off).
    pub verification: Option<Verification>,
    newton: NewtonSolver,
    /// Node kinematics of the current iterate (`n_nodes`).
    nodes: Vec<NodeState>,
    /// Scale of the equilibrium rows (`1 / max diag K_t` at the start).
    row_scale: f64,
}

/// The Newton system of a static load step: the increment `dq` from the last converged
/// configuration `q0` and the multipliers, at a given load factor; in the arc-length form
/// the load factor is an unknown too.
struct LoadStep<'a> {
    model: &'a Model,
    q0: &'a [flexmb_lie::Frame],
    nodes: &'a mut [NodeState],
    lambda: &'a mut Vec<f64>,
    dq: Vec<f64>,
    /// The element states of the iterate (their equations at rest, `xdot = 0`).
    x: Vec<f64>,
    /// Zero rates (`n_states`).
    rates: Vec<f64>,
    row_scale: f64,
    newton: NewtonSettings,
    /// Load factor of the iterate.
    load_factor: f64,
    /// Arc-length continuation: the constraint `|dq| = dl` and its state.
    arc: Option<ArcLength>,
    /// The iterate's start `(dq, lambda, load factor, load increment, states)`, for a
    /// second attempt with fresh matrices.
    first: (Vec<f64>, Vec<f64>, f64, f64, Vec<f64>),
}

/// The arc-length part of a load step (Crisfield's cylindrical constraint).
struct ArcLength {
    dl: f64,
    /// Load factor at the start of the step.
    lambda0: f64,
    /// Load increment so far.
    dlambda: f64,
    /// `dR/dlambda` at the iterate (scaled).
    load_derivative: Vec<f64>,
    /// `x_b = S^-1 (-dR/dlambda)`.
    xb: Vec<f64>,
    /// Load-factor part of the last correction.
    dmu: f64,
}

/// The scaling of statics: the iteration matrix `K_t T` with equilibrium rows times
/// `row_scale`, loads and gravity times the load factor.
/// `1 / max diag K_t` of the matrix last assembled in `data` (equilibrium rows), `None`
/// when that diagonal is zero: the row scale of statics, which brings the stiffness block
/// to the scale of the constraint block.
pub(crate) fn stiffness_row_scale(data: &Data) -> Option<f64> {
    let nd = data.layout.n_dofs;
    let kmax = data
        .diagonal_slots
        .iter()
        .filter(|&&(i, _)| i < nd)
        .fold(0.0f64, |m, &(_, slot)| m.max(data.values[slot].abs()));
    (kmax > 0.0).then(|| 1.0 / kmax)
}

pub(crate) fn scaling(row_scale: f64, load_factor: f64) -> Scaling {
    Scaling {
        row_scale,
        coef: Coefficients {
            m: 0.0,
            c: 0.0,
            k: row_scale,
            x: row_scale,
            xdot: 0.0,
            y: row_scale,
        },
        constraint_rhs: ConstraintRhs::Position,
        load_factor,
        regularization: 0.0,
        velocity_scale: 1.0,
        nodal_damping: 0.0,
        state_scale: row_scale,
    }
}

impl<'a> LoadStep<'a> {
    /// The load step from `q0` moved by `dq`, with the element states `x`, at
    /// `load_factor` (no arc length, no start kept for a second attempt).
    fn new(
        model: &'a Model,
        (q0, nodes, lambda): (
            &'a [flexmb_lie::Frame],
            &'a mut [NodeState],
            &'a mut Vec<f64>,
        ),
        (dq, x): (Vec<f64>, Vec<f64>),
        (row_scale, newton): (f64, NewtonSettings),
        load_factor: f64,
    ) -> Self {
        Self {
            model,
            q0,
            nodes,
            lambda,
            dq,
            rates: vec![0.0; x.len()],
            x,
            row_scale,
            newton,
            load_factor,
            arc: None,
            first: Default::default(),
        }
    }

    /// `q = q_0 exp(dq)` and the tangent operators into the node kinematics.
    fn set_configuration(&mut self) {
        let group = self.model.group;
        for (i, node) in self.nodes.iter_mut().enumerate() {
            let inc = Vec6::from_column_slice(&self.dq[6 * i..6 * i + 6]);
            node.q = group.integrate(&self.q0[i], &inc);
            node.v = Vec6::zeros();
            node.vdot = Vec6::zeros();
            node.t = group.tangent(&inc);
        }
    }

    fn assemble_at(&self, data: &mut Data, load_factor: f64, matrix: bool) {
        let it = Iterate {
            nodes: self.nodes,
            t: load_factor,
            lambda: self.lambda,
            b_start: &[],
            x: &self.x,
            xdot: &self.rates,
            inputs: None,
        };
        assemble(
            self.model,
            data,
            &it,
            &scaling(self.row_scale, load_factor),
            matrix,
        );
    }

    /// `lambda += dmu / s` for the multiplier part of a Newton vector.
    fn add_multipliers(&mut self, layout: &crate::data::Layout, x: &[f64], factor: f64) {
        let nd = layout.n_dofs;
        for (row, slot) in layout.row_unknown.iter().enumerate() {
            if let Some(k) = slot {
                self.lambda[row] += factor * x[nd + k] / self.row_scale;
            }
        }
    }
}

impl NonlinearSystem for LoadStep<'_> {
    fn assemble(&mut self, data: &mut Data, matrix: bool, _: f64) {
        self.set_configuration();
        if let Some(arc) = &mut self.arc {
            // dR/dlambda of the scaled system: applied loads (`lambda f(t)` with
            // `t = lambda`), gravity and driven joints (`Phi_t`). The internal forces cancel
            // exactly in the forward difference `(R(lambda + delta) - R(lambda)) / delta`,
            // `delta = sqrt(eps) max(1, |lambda|)`, which costs one residual assembly and
            // holds for any load function.
            let lambda = self.load_factor;
            let delta = f64::EPSILON.sqrt() * lambda.abs().max(1.0);
            let (ahead, at) = (
                scaling(self.row_scale, lambda + delta),
                scaling(self.row_scale, lambda),
            );
            let it = Iterate {
                nodes: self.nodes,
                t: lambda + delta,
                lambda: self.lambda,
                b_start: &[],
                x: &self.x,
                xdot: &self.rates,
                inputs: None,
            };
            assemble(self.model, data, &it, &ahead, false);
            arc.load_derivative.clone_from(&data.residual);
            let it = Iterate { t: lambda, ..it };
            assemble(self.model, data, &it, &at, matrix);
            for (d, r) in arc.load_derivative.iter_mut().zip(&data.residual) {
                *d = (*d - r) / delta;
            }
        } else {
            self.assemble_at(data, self.load_factor, matrix);
        }
    }

    fn correction(&mut self, data: &mut Data) -> Result<(), NewtonError> {
        let Some(arc) = &mut self.arc else {
            newton_correction(data);
            return Ok(());
        };
        let nd = data.layout.n_dofs;
        // x_b = S^-1 (-dR/dlambda): the response to a unit load increment.
        arc.xb.clear();
        arc.xb.extend(arc.load_derivative.iter().map(|v| -v));
        data.solver.solve_in_place(&mut arc.xb);
        let xb = &arc.xb;
        let norm_b = xb[..nd].iter().map(|v| v * v).sum::<f64>();
        // x_a = S^-1 (-R)
        newton_correction(data);
        let xa = &data.correction;
        // |dq + xa + dmu xb|^2 = dl^2
        let u: Vec<f64> = (0..nd).map(|k| self.dq[k] + xa[k]).collect();
        let a1 = norm_b;
        let a2 = 2.0 * u.iter().zip(xb).map(|(a, b)| a * b).sum::<f64>();
        let a3 = u.iter().map(|v| v * v).sum::<f64>() - arc.dl * arc.dl;
        let disc = a2 * a2 - 4.0 * a1 * a3;
        if disc < 0.0 || a1 <= 0.0 {
            return Err(NewtonError::System {
                message: "no real root of the arc-length constraint".into(),
                unknown: None,
            });
        }
        let roots = [
            (-a2 + disc.sqrt()) / (2.0 * a1),
            (-a2 - disc.sqrt()) / (2.0 * a1),
        ];
        // Crisfield: the root whose new increment is closest to the current one.
        let dq = &self.dq;
        let score = |m: f64| (0..nd).map(|k| (u[k] + m * xb[k]) * dq[k]).sum::<f64>();
        arc.dmu = if score(roots[0]) >= score(roots[1]) {
            roots[0]
        } else {
            roots[1]
        };
        for (d, b) in data.correction.iter_mut().zip(xb) {
            *d += arc.dmu * b;
        }
        Ok(())
    }

    fn apply(&mut self, data: &Data) {
        let nd = data.layout.n_dofs;
        for (q, d) in self.dq.iter_mut().zip(&data.correction[..nd]) {
            *q += d;
        }
        if let Some(arc) = &mut self.arc {
            arc.dlambda += arc.dmu;
            self.load_factor = arc.lambda0 + arc.dlambda;
        }
        self.add_multipliers(&data.layout, &data.correction, 1.0);
        let states = &data.correction[data.layout.block(Block::States)];
        for (x, d) in self.x.iter_mut().zip(states) {
            *x += d;
        }
    }

    /// The increments' weighted correction; with arc length also the load factor's,
    /// `|dmu| / (rtol |dlambda| + atol)`.
    fn restart(&mut self) {
        let (dq, lambda, load_factor, dlambda, x) = &self.first;
        self.dq.clone_from(dq);
        self.lambda.clone_from(lambda);
        self.x.clone_from(x);
        self.load_factor = *load_factor;
        if let Some(arc) = &mut self.arc {
            arc.dlambda = *dlambda;
        }
    }

    fn norms(&self, data: &Data) -> Norms {
        let nd = data.layout.n_dofs;
        let newton = &self.newton;
        let (q, worst) = weighted_norm(
            &data.correction[..nd],
            &self.dq,
            &|_| newton.atol,
            newton.rtol,
        );
        let mut norms = Norms {
            n: 1,
            worst,
            ..Norms::default()
        };
        norms.blocks[0] = q;
        if let Some(arc) = &self.arc {
            norms.n = 2;
            norms.blocks[1] =
                arc.dmu.abs() / (newton.rtol * arc.dlambda.abs().max(1e-12) + newton.atol);
        }
        if !self.x.is_empty() {
            let states = data.layout.block(Block::States);
            let dx = &data.correction[states.clone()];
            let (x, worst) = weighted_norm(dx, &self.x, &|_| newton.atol, newton.rtol);
            let k = norms.n;
            norms.blocks[k] = x;
            norms.n += 1;
            if x > norms.blocks[..k].iter().fold(0.0f64, |m, &v| m.max(v)) {
                norms.worst = states.start + worst;
            }
        }
        norms
    }
}

impl Statics {
    /// Validates the model and builds the data at the initial configuration (`lambda = 0`).
    pub fn new(model: impl IntoShared, settings: StaticSettings) -> Result<Self, SolveError> {
        let model = model.into_shared();
        model.validate()?;
        settings.check()?;
        let (layout, note) = prepare_layout(&model);
        let mut state = State::initial(&model, &layout)?;
        let threads = crate::parallel::Threads::for_model(&model, settings.threads);
        let mut data = Data::new(&model, layout)?.with_threads(threads);
        for v in state.v.iter_mut() {
            *v = Vec6::zeros();
        }
        let nodes = node_states(&state);
        // Row scale from the stiffness at the start.
        let mut row_scale = 1.0;
        let (mut scratch_nodes, mut scratch_lambda) = (nodes.clone(), state.lambda.clone());
        let mut start = LoadStep::new(
            &model,
            (&state.q, &mut scratch_nodes, &mut scratch_lambda),
            (vec![0.0; data.layout.n_dofs], state.x.clone()),
            (row_scale, settings.newton),
            0.0,
        );
        start.assemble(&mut data, true, 0.0);
        row_scale = stiffness_row_scale(&data).unwrap_or(row_scale);
        let policy = NewtonPolicy {
            settings: settings.newton,
            regularized_solves: 0,
            divergence_rate: 10.0,
            diverge_after: 4,
            exact_by_size: true,
        };
        Ok(Self {
            model,
            data,
            state,
            newton: NewtonSolver::new(policy, settings.verify),
            settings,
            load_factor: 0.0,
            stats: Work::default(),
            warnings: Vec::new(),
            notes: note.into_iter().collect(),
            interrupt: None,
            verification: None,
            nodes,
            row_scale,
        })
    }

    /// Runs to the final load factor, calling `output` at `lambda = 0` and after every
    /// converged load step. Stops with [`SolveError::Incomplete`] when `max_steps` load steps
    /// did not reach it (the state is then the last converged one), with
    /// [`SolveError::StaticFailed`] when a step cannot converge.
    pub fn run(&mut self, output: &mut dyn Observer) -> Result<Work, SolveError> {
        output.output(&self.sample()).map_err(SolveError::Output)?;
        let result = match self.settings.method {
            StaticMethod::LoadControl => self.run_load_control(output),
            StaticMethod::ArcLength => self.run_arc_length(output),
            StaticMethod::PseudoDynamic => self.run_pseudo_dynamic(output),
        };
        if let Some(w) = self.verification.as_ref().and_then(Verification::warning) {
            self.warnings.push(w);
        }
        result.map(|()| self.stats)
    }

    fn run_load_control(&mut self, output: &mut dyn Observer) -> Result<(), SolveError> {
        let s = self.settings;
        let mut inc = s.initial_increment.min(s.max_increment);
        let target = s.load_factor;
        let eps = 1e-12 * target.abs().max(1.0);
        let mut since = self.stats;
        while (target - self.load_factor).abs() > eps {
            self.check_interrupt()?;
            if self.stats.steps >= s.max_steps {
                return Err(self.incomplete("load control", "solver.max_steps (or max_increment)"));
            }
            let remaining = target - self.load_factor;
            let step = if remaining.abs() <= inc * (1.0 + 1e-9) {
                remaining
            } else {
                inc * remaining.signum()
            };
            let before = self.stats;
            match self.solve_at(self.load_factor + step) {
                Ok(iterations) => {
                    self.load_factor = if step == remaining {
                        target
                    } else {
                        self.load_factor + step
                    };
                    self.stats.steps += 1;
                    self.accepted(output, step, &mut since, &before)?;
                    output.output(&self.sample()).map_err(SolveError::Output)?;
                    if s.adaptive {
                        if iterations <= s.target_iterations / 2 {
                            inc = (inc * 1.5).min(s.max_increment);
                        } else if 2 * iterations > 3 * s.target_iterations {
                            inc *= 0.7;
                        }
                    }
                }
                Err(error) => {
                    self.stats.rejected_steps += 1;
                    inc *= 0.5;
                    if inc < s.min_increment || !s.adaptive {
                        return Err(self.failure(error, inc));
                    }
                }
            }
        }
        Ok(())
    }

    /// The current point of the analysis, for observers (`at` is the load factor).
    pub fn sample(&self) -> Sample<'_> {
        Sample {
            model: &self.model,
            data: &self.data,
            state: &self.state,
            at: self.load_factor,
            work: self.stats,
        }
    }

    fn check_interrupt(&self) -> Result<(), SolveError> {
        if super::dynamics::interrupted(&self.interrupt) {
            return Err(SolveError::Interrupted {
                reached: self.load_factor,
            });
        }
        Ok(())
    }

    /// The diagnosis of a load step that could not converge: `error` of its last attempt,
    /// with the increment `inc` tried.
    fn failure(&self, error: NewtonError, inc: f64) -> SolveError {
        let unknown = error.unknown();
        let mut reason = error.to_string();
        if matches!(error, NewtonError::Singular { .. }) {
            reason.push_str(": a mechanism (try method = \"pseudo_dynamic\") or a limit point (try method = \"arc_length\")");
        }
        SolveError::StaticFailed {
            step: self.stats.steps + 1,
            load_factor: self.load_factor,
            increment: inc,
            rejected: self.stats.rejected_steps,
            reason,
            worst_equation: unknown
                .map(|i| self.data.layout.describe_unknown(&self.model, i))
                .unwrap_or_else(|| "unknown".into()),
            unknown: unknown.map(|i| self.data.layout.unknown(i)),
            error: Box::new(error),
        }
    }

    /// The end of an analysis by `method` that has taken `max_steps` load steps before its
    /// final load factor; `raise` names the settings that let it go further.
    fn incomplete(&self, method: &str, raise: &str) -> SolveError {
        SolveError::Incomplete {
            reached: self.load_factor,
            end: self.settings.load_factor,
            reason: format!(
                "{method} took max_steps = {} load steps; raise {raise}",
                self.settings.max_steps
            ),
        }
    }

    /// Solves a load step's system from the last converged state moved by `dq` (zero, or
    /// the arc-length predictor); on success takes the converged configuration and
    /// multipliers into the state. Returns the iterations, the arc-length part and the
    /// configuration increment of the step.
    fn solve_step(
        &mut self,
        load_factor: f64,
        (dq, x): (Vec<f64>, Vec<f64>),
        arc: Option<ArcLength>,
    ) -> Result<(usize, Option<ArcLength>, Vec<f64>), NewtonError> {
        let mut lambda = self.state.lambda.clone();
        let first = (
            dq.clone(),
            lambda.clone(),
            load_factor,
            arc.as_ref().map_or(0.0, |a| a.dlambda),
            x.clone(),
        );
        let mut sys = LoadStep {
            first,
            arc,
            ..LoadStep::new(
                &self.model,
                (&self.state.q, &mut self.nodes, &mut lambda),
                (dq, x),
                (self.row_scale, self.settings.newton),
                load_factor,
            )
        };
        let result = self.newton.solve(&mut sys, &mut self.data, 0.0);
        let work = match &result {
            Ok(info) | Err(NewtonFailure { info, .. }) => *info,
        };
        self.stats.newton_iterations += work.iterations;
        self.stats.factorizations += work.factorizations;
        let info = result.map_err(|f| f.error)?;
        let (dq, reached, arc) = (std::mem::take(&mut sys.dq), sys.load_factor, sys.arc.take());
        self.state.x = std::mem::take(&mut sys.x);
        let group = self.model.group;
        for (i, q) in self.state.q.iter_mut().enumerate() {
            *q = group.integrate(q, &Vec6::from_column_slice(&dq[6 * i..6 * i + 6]));
            q.orthonormalize();
        }
        self.state.lambda = lambda;
        self.state.t = reached;
        if let Some(check) = &info.check {
            let layout = &self.data.layout;
            Verification::add(&mut self.verification, check, reached, layout, &self.model);
        }
        Ok((info.final_iterations, arc, dq))
    }

    /// Tells the observer of a converged load step: `h` is its load increment, `since` the
    /// statistics after the previous converged step (its iterations count the failed
    /// attempts too, as a dynamic step's do), `before` those before its accepted attempt.
    fn accepted(
        &self,
        output: &mut dyn Observer,
        h: f64,
        since: &mut Work,
        before: &Work,
    ) -> Result<(), SolveError> {
        let info = super::StepInfo {
            t: self.load_factor,
            h,
            iterations: self.stats.newton_iterations - since.newton_iterations,
            rejected: self.stats.rejected_steps - since.rejected_steps,
            reused_matrix: self.stats.factorizations == before.factorizations,
            regularized: false,
        };
        *since = self.stats;
        output.accepted(&info).map_err(SolveError::Output)
    }

    /// Newton at a fixed load factor (load control). On success the state holds the
    /// converged configuration; returns the iterations.
    fn solve_at(&mut self, lambda: f64) -> Result<usize, NewtonError> {
        let nd = self.data.layout.n_dofs;
        self.solve_step(lambda, (vec![0.0; nd], self.state.x.clone()), None)
            .map(|(iterations, _, _)| iterations)
    }

    fn run_arc_length(&mut self, output: &mut dyn Observer) -> Result<(), SolveError> {
        let s = self.settings;
        let target = s.load_factor;
        let mut dl = s.arc_length;
        let dl_min = s.arc_length * ARC_LENGTH_MIN;
        let dl_max = s.arc_length * 4.0;
        // Direction of the previous converged increment, for the predictor's sign.
        let mut previous: Option<Vec<f64>> = None;
        let mut since = self.stats;
        while (target - self.load_factor) * target.signum() > 1e-12 * target.abs().max(1.0) {
            self.check_interrupt()?;
            if self.stats.steps >= s.max_steps {
                return Err(self.incomplete(
                    "arc-length continuation",
                    "solver.max_steps (or arc_length)",
                ));
            }
            let saved = self.state.clone();
            let lambda0 = self.load_factor;
            let before = self.stats;
            match self.arc_length_step(dl, previous.as_deref(), target.signum()) {
                Ok((dq, dlambda, iterations)) => {
                    if (lambda0 + dlambda - target) * target.signum() > 0.0 {
                        // Crossed the final load factor: end exactly on it with a load-control
                        // solve from the last converged state (or keep the crossing point).
                        let crossed = std::mem::replace(&mut self.state, saved);
                        if self.solve_at(target).is_ok() {
                            self.load_factor = target;
                        } else {
                            self.state = crossed;
                            self.load_factor = lambda0 + dlambda;
                        }
                        self.stats.steps += 1;
                        self.accepted(output, self.load_factor - lambda0, &mut since, &before)?;
                        output.output(&self.sample()).map_err(SolveError::Output)?;
                        break;
                    }
                    self.stats.steps += 1;
                    self.load_factor = lambda0 + dlambda;
                    self.accepted(output, dlambda, &mut since, &before)?;
                    output.output(&self.sample()).map_err(SolveError::Output)?;
                    previous = Some(dq);
                    let ratio = (s.target_iterations as f64 / iterations.max(1) as f64).sqrt();
                    dl = (dl * ratio.clamp(0.5, 2.0)).min(dl_max);
                }
                Err(error) => {
                    self.stats.rejected_steps += 1;
                    dl *= 0.5;
                    if dl < dl_min {
                        return Err(self.failure(error, dl));
                    }
                }
            }
        }
        Ok(())
    }

    /// One arc-length step (Crisfield's cylindrical constraint `|dq| = dl`): the predictor
    /// along the tangent at the last converged state, then Newton on the increment, the
    /// multipliers and the load factor. Returns the converged increment, the load increment
    /// and the iterations.
    fn arc_length_step(
        &mut self,
        dl: f64,
        previous: Option<&[f64]>,
        direction: f64,
    ) -> Result<(Vec<f64>, f64, usize), NewtonError> {
        let nd = self.data.layout.n_dofs;
        let lambda0 = self.load_factor;
        let mut lambda = self.state.lambda.clone();
        let mut predictor = LoadStep {
            arc: Some(ArcLength {
                dl,
                lambda0,
                dlambda: 0.0,
                load_derivative: Vec::new(),
                xb: Vec::new(),
                dmu: 0.0,
            }),
            ..LoadStep::new(
                &self.model,
                (&self.state.q, &mut self.nodes, &mut lambda),
                (vec![0.0; nd], self.state.x.clone()),
                (self.row_scale, self.settings.newton),
                lambda0,
            )
        };
        predictor.assemble(&mut self.data, true, 0.0);
        if let Some(i) = self.data.residual.iter().position(|r| !r.is_finite()) {
            return Err(NewtonError::NonFiniteResidual { unknown: i });
        }
        self.stats.factorizations += 1;
        self.data
            .solver
            .factorize(&self.data.values)
            .map_err(|e| NewtonError::Singular {
                unknown: match e {
                    LinearError::Singular { column } => column,
                    _ => None,
                },
                source: e,
            })?;
        let mut arc = predictor.arc.take().expect("arc");
        let mut xb: Vec<f64> = arc.load_derivative.iter().map(|v| -v).collect();
        self.data.solver.solve_in_place(&mut xb);
        let norm_b = xb[..nd].iter().map(|v| v * v).sum::<f64>();
        // Predictor: dlambda along the tangent, signed to continue the path.
        let mut sign = direction;
        if let Some(pq) = previous {
            // Follow the path: the new tangent points along the last increment
            // (Feng, Peric & Owen 1996), which turns lambda back at limit points.
            let dot: f64 = pq.iter().zip(&xb[..nd]).map(|(a, b)| a * b).sum();
            sign = dot.signum();
        }
        let dlam = sign * dl / norm_b.sqrt().max(1e-300);
        predictor.add_multipliers(&self.data.layout, &xb, dlam);
        arc.dlambda = dlam;
        // The predictor moves the configuration (and the element states) along the tangent.
        let dq = xb[..nd].iter().map(|b| dlam * b).collect();
        let states = &xb[self.data.layout.block(Block::States)];
        let x = predictor
            .x
            .iter()
            .zip(states)
            .map(|(x, b)| x + dlam * b)
            .collect();
        let saved_lambda = std::mem::replace(&mut self.state.lambda, lambda);
        // Arc length has no divergence test: the constraint keeps the iterates bounded.
        let policy = self.newton.policy;
        self.newton.policy.diverge_after = usize::MAX;
        let result = self.solve_step(lambda0 + dlam, (dq, x), Some(arc));
        self.newton.policy = policy;
        match result {
            Ok((iterations, Some(arc), dq)) => Ok((dq, arc.dlambda, iterations)),
            Ok(_) => unreachable!("an arc-length step keeps its arc"),
            Err(e) => {
                self.state.lambda = saved_lambda;
                Err(e)
            }
        }
    }

    /// Pseudo-dynamic solution: a damped dynamic run with the loads ramped from 0 to the final
    /// load factor over `pseudo_time`, then held for as long again to settle. Each step is
    /// reported as a load step as soon as it is computed, so a run that fails or is
    /// interrupted keeps every completed step.
    fn run_pseudo_dynamic(&mut self, output: &mut dyn Observer) -> Result<(), SolveError> {
        let s = self.settings;
        let t_ramp = s.pseudo_time;
        let mut d = super::DynamicSettings::new(2.0 * t_ramp, s.initial_increment * t_ramp);
        d.rho_inf = 0.0;
        d.nodal_damping = s.pseudo_damping;
        d.load_ramp = t_ramp;
        d.load_scale = s.load_factor;
        d.newton.rtol = s.newton.rtol;
        d.newton.atol = s.newton.atol;
        d.newton.max_iterations = s.newton.max_iterations;
        d.verify = s.verify;
        d.threads = s.threads;
        let mut sim = super::Simulation::new(&self.model, d)?;
        sim.interrupt.clone_from(&self.interrupt);
        let mut last_speed = 0.0f64;
        let result = sim.run(&mut |sim: &Sample| {
            if sim.state.t == 0.0 {
                return Ok(()); // the start was reported by `run`
            }
            last_speed = sim.state.v.iter().fold(0.0f64, |m, v| m.max(v.norm()));
            self.state.clone_from(sim.state);
            for v in self.state.v.iter_mut() {
                *v = Vec6::zeros();
            }
            self.load_factor = d.load_factor_at(sim.state.t);
            // (the dynamic run is all the work of a pseudo-dynamic analysis)
            self.stats = sim.work;
            output.output(&self.sample())
        });
        self.stats = sim.stats.work();
        self.verification.clone_from(&sim.verification);
        match result {
            Err(SolveError::Interrupted { .. }) => {
                return Err(SolveError::Interrupted {
                    reached: self.load_factor,
                })
            }
            Err(e) => return Err(e),
            Ok(_) => {}
        }
        if last_speed > 1e-6 {
            self.warnings.push(format!(
                "pseudo-dynamic analysis: largest nodal velocity {last_speed:.3e} at the end; increase pseudo_time or pseudo_damping for a settled static state"
            ));
        }
        if self.data.layout.n_states > 0 {
            self.check_states_settled()?;
        }
        Ok(())
    }

    /// After a pseudo-dynamic run of a model with element states: the states relax on
    /// their own time (a Maxwell branch: `c_m / k_m`), which the nodal speeds do not show.
    /// One Newton correction of the static equations from the final state estimates how far
    /// the states are from the equilibrium; more than `1e-3` of their size (the
    /// approximation dynamic relaxation makes otherwise), a warning.
    fn check_states_settled(&mut self) -> Result<(), SolveError> {
        let mut lambda = self.state.lambda.clone();
        let mut sys = LoadStep::new(
            &self.model,
            (&self.state.q, &mut self.nodes, &mut lambda),
            (vec![0.0; self.data.layout.n_dofs], self.state.x.clone()),
            (self.row_scale, self.settings.newton),
            self.load_factor,
        );
        sys.assemble(&mut self.data, true, 0.0);
        self.data.solver.factorize(&self.data.values)?;
        newton_correction(&mut self.data);
        let states = self.data.layout.block(Block::States);
        let dx = &self.data.correction[states.clone()];
        let size = sys
            .x
            .iter()
            .fold(self.settings.newton.atol, |m, v| m.max(v.abs()));
        let (k, distance) =
            dx.iter().enumerate().fold(
                (0, 0.0f64),
                |w, (k, d)| if d.abs() > w.1 { (k, d.abs()) } else { w },
            );
        if distance > 1e-3 * size {
            let worst = self
                .data
                .layout
                .describe_unknown(&self.model, states.start + k);
            self.warnings.push(format!(
                "pseudo-dynamic analysis: the element states are {distance:.3e} from the static equilibrium (largest state {size:.3e}; worst: {worst}); they relax on their own time (a Maxwell branch: relaxation_damping / relaxation_stiffness): increase pseudo_time, or use load_control"
            ));
        }
        Ok(())
    }
}
