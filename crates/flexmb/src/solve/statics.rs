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

use super::initial::{load_nodes, prepare_layout};
use super::linear::LinearError;
use super::newton::{weighted_norm, NewtonSettings};
use crate::assembly::{assemble, ConstraintRhs, Scaling};
use crate::data::Data;
use crate::elements::Coefficients;
use crate::error::SolveError;
use crate::model::Model;
use crate::state::State;
use flexmb_lie::{Mat6, Vec6};

/// How the load factor is controlled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StaticMethod {
    /// Prescribed load factor, adaptive increments.
    LoadControl,
    /// Arc-length continuation (Crisfield), passes limit points.
    ArcLength,
}

/// Settings of a static analysis.
#[derive(Clone, Copy, Debug, PartialEq)]
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
    /// Arc length of the first step (arc-length method) [m, rad].
    pub arc_length: f64,
    /// Most load steps.
    pub max_steps: usize,
    /// Newton iterations aimed at per step: increments grow when fewer are needed.
    pub target_iterations: usize,
    pub newton: NewtonSettings,
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

impl Default for StaticSettings {
    fn default() -> Self {
        Self::new()
    }
}

/// Work done by a static analysis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StaticStats {
    pub steps: usize,
    pub newton_iterations: usize,
    pub rejected_steps: usize,
    pub factorizations: usize,
}

/// A static analysis in progress.
pub struct Statics<'m> {
    pub model: &'m Model,
    pub data: Data,
    /// Converged configuration and multipliers (velocities stay zero).
    pub state: State,
    pub settings: StaticSettings,
    /// Load factor of the converged state.
    pub load_factor: f64,
    pub stats: StaticStats,
    pub warnings: Vec<String>,
    /// Scale of the equilibrium rows (`1 / max diag K_t` at the start).
    row_scale: f64,
}

/// What one Newton solve at a load step returns.
struct Converged {
    iterations: usize,
}

impl<'m> Statics<'m> {
    /// Validates the model and builds the data at the initial configuration (`lambda = 0`).
    pub fn new(model: &'m Model, settings: StaticSettings) -> Result<Self, SolveError> {
        model
            .validate()
            .map_err(|e| SolveError::Model(e.to_string()))?;
        let (layout, warnings) = prepare_layout(model);
        let n_rows = layout.n_rows;
        let mut data = Data::new(model, layout).map_err(|e| SolveError::Model(e.to_string()))?;
        let mut state = State::initial(model, n_rows);
        for v in state.v.iter_mut() {
            *v = Vec6::zeros();
        }
        load_nodes(&state, &mut data);
        let mut s = Self {
            model,
            data,
            state,
            settings,
            load_factor: 0.0,
            stats: StaticStats::default(),
            warnings,
            row_scale: 1.0,
        };
        // Row scale from the stiffness at the start.
        s.assemble(0.0, true);
        let nd = s.data.layout.n_dofs;
        let kmax = s
            .data
            .pattern
            .iter()
            .zip(&s.data.values)
            .filter(|((i, j), _)| i == j && *i < nd)
            .fold(0.0f64, |m, (_, v)| m.max(v.abs()));
        if kmax > 0.0 {
            s.row_scale = 1.0 / kmax;
        }
        Ok(s)
    }

    fn scaling(&self, lambda: f64) -> Scaling {
        Scaling {
            row_scale: self.row_scale,
            coef: Coefficients {
                m: 0.0,
                c: 0.0,
                k: self.row_scale,
            },
            constraint_rhs: ConstraintRhs::Position,
            load_factor: lambda,
            regularization: 0.0,
            velocity_scale: 1.0,
        }
    }

    fn assemble(&mut self, lambda: f64, matrix: bool) {
        let sc = self.scaling(lambda);
        assemble(
            self.model,
            &mut self.data,
            lambda,
            &self.state.lambda,
            &sc,
            matrix,
        );
    }

    /// Runs to the final load factor, calling `output` at `lambda = 0` and after every
    /// converged load step.
    pub fn run(
        &mut self,
        output: &mut dyn FnMut(&Statics) -> Result<(), String>,
    ) -> Result<StaticStats, SolveError> {
        output(self).map_err(SolveError::Output)?;
        match self.settings.method {
            StaticMethod::LoadControl => self.run_load_control(output)?,
            StaticMethod::ArcLength => self.run_arc_length(output)?,
        }
        Ok(self.stats)
    }

    fn run_load_control(
        &mut self,
        output: &mut dyn FnMut(&Statics) -> Result<(), String>,
    ) -> Result<(), SolveError> {
        let s = self.settings;
        let mut inc = s.initial_increment.min(s.max_increment);
        let target = s.load_factor;
        let eps = 1e-12 * target.abs().max(1.0);
        while (target - self.load_factor).abs() > eps {
            if self.stats.steps >= s.max_steps {
                return Err(self.failure(
                    "the maximum number of load steps was reached".into(),
                    None,
                    inc,
                ));
            }
            let remaining = target - self.load_factor;
            let step = if remaining.abs() <= inc * (1.0 + 1e-9) {
                remaining
            } else {
                inc * remaining.signum()
            };
            let saved = self.state.clone();
            match self.solve_at(self.load_factor + step, None) {
                Ok(c) => {
                    self.load_factor = if step == remaining {
                        target
                    } else {
                        self.load_factor + step
                    };
                    self.stats.steps += 1;
                    output(self).map_err(SolveError::Output)?;
                    if c.iterations <= s.target_iterations / 2 {
                        inc = (inc * 1.5).min(s.max_increment);
                    } else if c.iterations > s.target_iterations {
                        inc *= 0.7;
                    }
                }
                Err((reason, worst)) => {
                    self.stats.rejected_steps += 1;
                    self.state = saved;
                    load_nodes(&self.state, &mut self.data);
                    inc *= 0.5;
                    if inc < s.min_increment {
                        return Err(self.failure(reason, worst, inc));
                    }
                }
            }
        }
        Ok(())
    }

    fn failure(&self, reason: String, worst: Option<usize>, inc: f64) -> SolveError {
        SolveError::NewtonFailed {
            step: self.stats.steps + 1,
            t: self.load_factor,
            h: inc,
            reductions: self.stats.rejected_steps,
            reason: format!(
                "static analysis at load factor {:.6e}: {reason}",
                self.load_factor
            ),
            worst_equation: worst
                .map(|i| self.data.layout.describe_unknown(self.model, i))
                .unwrap_or_else(|| "unknown".into()),
        }
    }

    /// Newton at a fixed load factor (load control), or with the load factor as an unknown
    /// constrained by the arc length `arc` (`Some((delta_l, previous increment))`).
    /// On success the state holds the converged configuration; returns the iterations.
    fn solve_at(
        &mut self,
        lambda: f64,
        _arc: Option<f64>,
    ) -> Result<Converged, (String, Option<usize>)> {
        let n = self.data.layout.n_nodes;
        let nd = self.data.layout.n_dofs;
        let group = self.model.group;
        let q0 = self.state.q.clone();
        let mut dq = vec![0.0; nd];
        let newton = self.settings.newton;
        let mut previous = f64::INFINITY;
        for iteration in 1..=newton.max_iterations {
            for i in 0..n {
                let inc = Vec6::from_column_slice(&dq[6 * i..6 * i + 6]);
                let node = &mut self.data.nodes[i];
                node.q = group.integrate(&q0[i], &inc);
                node.v = Vec6::zeros();
                node.vdot = Vec6::zeros();
                node.t = group.tangent(&inc);
            }
            self.assemble(lambda, true);
            if let Some(i) = self.data.residual.iter().position(|r| !r.is_finite()) {
                return Err(("non-finite residual".into(), Some(i)));
            }
            self.stats.factorizations += 1;
            if let Err(e) = self.data.solver.factorize(&self.data.values) {
                let col = match e {
                    LinearError::Singular { column } => column,
                    _ => None,
                };
                return Err((format!("singular tangent matrix ({e}): a mechanism, or a limit point (use arc-length)"), col));
            }
            let dx = &mut self.data.correction;
            for (d, r) in dx.iter_mut().zip(&self.data.residual) {
                *d = -r;
            }
            self.data.solver.solve_in_place(dx);
            if let Some(i) = dx.iter().position(|d| !d.is_finite()) {
                return Err(("non-finite Newton correction".into(), Some(i)));
            }
            for k in 0..nd {
                dq[k] += dx[k];
            }
            for (row, slot) in self.data.layout.row_unknown.iter().enumerate() {
                if let Some(k) = slot {
                    self.state.lambda[row] += dx[nd + k] / self.row_scale;
                }
            }
            self.stats.newton_iterations += 1;
            let (err, worst) = weighted_norm(&dx[..nd], &dq, &|_| newton.atol, newton.rtol);
            if err <= 1.0 {
                for i in 0..n {
                    let inc = Vec6::from_column_slice(&dq[6 * i..6 * i + 6]);
                    let mut q = group.integrate(&q0[i], &inc);
                    q.orthonormalize();
                    self.state.q[i] = q;
                }
                self.state.t = lambda;
                load_nodes(&self.state, &mut self.data);
                for node in self.data.nodes.iter_mut() {
                    node.t = Mat6::identity();
                }
                return Ok(Converged {
                    iterations: iteration,
                });
            }
            if iteration >= 4 && err > previous {
                return Err((
                    format!(
                        "Newton diverging (weighted correction {err:.3e} after {previous:.3e})"
                    ),
                    Some(worst),
                ));
            }
            previous = err;
        }
        Err((
            format!("no convergence in {} iterations", newton.max_iterations),
            None,
        ))
    }

    fn run_arc_length(
        &mut self,
        _output: &mut dyn FnMut(&Statics) -> Result<(), String>,
    ) -> Result<(), SolveError> {
        Err(SolveError::Model(
            "arc-length continuation is not available yet".into(),
        ))
    }
}
