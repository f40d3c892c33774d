//! The step residual `R(x; s_n, p, h)` as a function of explicit inputs ([`super`]), with
//! its exact Jacobian and the products of its partial derivatives with vectors.

use crate::assembly::Scaling;
use crate::data::{Block, Layout};
use crate::elements::{Coefficients, NodeState, Vec12};
use crate::joints::ConstraintKernel;
use crate::model::Model;
use crate::parallel::Threads;
use crate::solve::DynamicSettings;
use crate::state::State;
use flexmb_lie::{Chart, Mat6, Vec6};
use std::cell::RefCell;
use std::sync::Arc;

use super::pattern::{zeroed, JacobianPattern, Selection};
use super::updates::{commutator_correction, kinematics, total_increments};
use super::{chart_start, pack_unknowns, predict, Start, StateTangent};

/// Sparse matrix entries `(row, column, value)`; duplicates are summed.
pub type Triplets = Vec<(usize, usize, f64)>;

/// The triplets `t` with each position once (by column, then row), their values summed,
/// without the zeros.
fn merge_triplets(mut t: Triplets) -> Triplets {
    t.sort_unstable_by_key(|&(i, j, _)| (j, i));
    let mut out: Triplets = Vec::with_capacity(t.len());
    for (i, j, v) in t {
        match out.last_mut() {
            Some(last) if (last.0, last.1) == (i, j) => last.2 += v,
            _ => out.push((i, j, v)),
        }
    }
    out.retain(|e| e.2 != 0.0);
    out
}

/// The nonzero entries of the dense column `values` as column `j` of `out`.
fn push_column(out: &mut Triplets, j: usize, values: &[f64]) {
    let nonzero = values.iter().enumerate().filter(|(_, v)| **v != 0.0);
    out.extend(nonzero.map(|(i, &v)| (i, j, v)));
}

/// The step residual `R(x; s_n, p, h)` as a function (see the module documentation), with
/// its exact Jacobian `dR/dx` and the products of `dR/ds_n` with a tangent and with a
/// transposed vector. Every evaluation takes its inputs explicitly; `data` is scratch (a
/// [`crate::data::Data`] of the same layout). The partial derivatives at the last `x` asked for
/// are kept: `jacobian`, `start_jvp`, `start_vjp` and the parameter products at the same
/// `x` (what an adjoint step calls) assemble them once.
pub struct StepFunction<'a> {
    model: &'a Model,
    layout: &'a Layout,
    start: &'a State,
    /// The fixed numbers of the step.
    pub step: Start,
    /// Rows of `B(q_n)` (`n_rows`).
    b_start: Vec<Vec12>,
    /// Node kinematics of `s_n` (`T = I`).
    start_nodes: Vec<NodeState>,
    /// The input vector `u_{n+1}` given to the step ([`crate::model::Input`]), or `None`:
    /// each input's function at `t_{n+1}`, as in a run.
    inputs: Option<Vec<f64>>,
    /// The partial derivatives at the last `x` (see [`StepFunction::partials`]).
    cache: RefCell<Option<Cached>>,
}

/// The partial derivatives a [`StepFunction`] keeps, taken out of it
/// ([`StepFunction::take_partials`]) to be handed to a step function of the same step made
/// elsewhere ([`StepFunction::with_partials`]): a sensitivity analysis prepares its steps'
/// Jacobians on other threads.
#[derive(Default)]
pub struct KeptPartials(Option<Cached>);

/// Partial derivatives and where they were taken: the unknowns and the step's numbers.
struct Cached {
    x: Vec<f64>,
    step: Start,
    inputs: Option<Vec<f64>>,
    partials: Arc<Partials>,
}

/// Partial derivatives of the residual at the end of the step with respect to its
/// arguments, each as values on the positions of the step's [`JacobianPattern`]: the
/// right-trivialized configuration `q_{n+1}` (all rows, node columns), the velocities, the
/// accelerations (node columns) and the multipliers (equilibrium rows).
struct Partials {
    pattern: Arc<JacobianPattern>,
    f_q: Vec<f64>,
    f_v: Vec<f64>,
    f_vd: Vec<f64>,
    f_mu: Vec<f64>,
    /// The element states `x_{n+1}` and their rates `xdot_{n+1}` (all rows, state columns).
    f_x: Vec<f64>,
    f_xd: Vec<f64>,
    /// Tangent operators `T(total)` of the nodes' increments (`M(total)` of the chart in
    /// the Lie algebra updates).
    t: Vec<Mat6>,
    /// `I + E`: how the total increments move with `dq` (module documentation; empty for
    /// the Brüls-Cardona update).
    e: Vec<Mat6>,
    /// Transports `G = Ad(exp(-total))`: `q_n exp(d) exp(total) = q_{n+1} exp(G d)` (the
    /// Lie algebra updates: `Ad(C(total)^-1)`, [`Chart::transport`]).
    g: Vec<Mat6>,
    /// The Lie algebra updates' derivatives of the nodes' velocities, accelerations and
    /// algorithmic accelerations in the chart (empty for the other updates).
    chart: Vec<ChartNode>,
    /// The end of the step and its node kinematics (`T = I`): where the parameter
    /// derivatives are taken.
    end: State,
    nodes: Vec<NodeState>,
    /// `K_zeta = d(B(q_n)^T zeta)/dq_n` (stabilized form; empty otherwise).
    k_zeta: Triplets,
}

/// One node's derivatives of the end of a step in the Lie algebra updates (module
/// documentation, "Lie algebra updates"): with `Theta = total` and the chart's rates
/// `X = Theta'_{n+1}`, `Y = Theta''_{n+1}`, `A` (the algorithmic acceleration in the chart),
/// `v = M X`, `vdot = M Y + N(Theta, X)`, `a = M A + N(Theta, X)`.
struct ChartNode {
    /// `d v / d Theta`, `d vdot / d Theta`, `d a / d Theta` at fixed rates.
    v_theta: Mat6,
    vdot_theta: Mat6,
    a_theta: Mat6,
    /// `dN(Theta, X)/dX`.
    n_x: Mat6,
    /// `dN(0, v_n)/dv_n`: the start in the chart, `vdot_n - N(0, v_n)`, `a_n - N(0, v_n)`.
    n0_x: Mat6,
}

/// Changes of one node's end of the step: the configuration (right-trivialized, without the
/// transport of the start's) and the velocities, accelerations and algorithmic
/// accelerations.
type NodeMove = [Vec6; 4];

/// The scheme's relations of one node at fixed start (module documentation): the end's
/// rates `[v, vdot, a]` (in the step's coordinates: the chart's `X`, `Y`, `A` in the Lie
/// algebra updates) from the start's `(v_n, vdot_n, a_n)` and the increment `dq`, all linear.
struct Relations {
    /// `[c1, c2, c3, c4, c5]` of [`StepFunction::start_coefficients`].
    c: [f64; 5],
    gp: f64,
    bp: f64,
    h: f64,
    beta: f64,
}

impl Relations {
    /// The end's rates for changes `[dv_n, dvdot_n, da_n]` of the start and `ddq`.
    fn forward(&self, [v, vd, a]: [Vec6; 3], ddq: &Vec6) -> [Vec6; 3] {
        let ([c1, c2, c3, c4, c5], h, beta) = (self.c, self.h, self.beta);
        [
            v * c1 + a * c2 + ddq * self.gp,
            v * c3 + a * c4 + vd * c5 + ddq * self.bp,
            (ddq - v * h - a * ((0.5 - beta) * h * h)) / (beta * h * h),
        ]
    }

    /// The transpose of [`Relations::forward`]: the cotangents of the start
    /// `[v_n, vdot_n, a_n]` and of `dq` for those of the end's rates.
    fn transposed(&self, [x, y, a]: [Vec6; 3]) -> ([Vec6; 3], Vec6) {
        let ([c1, c2, c3, c4, c5], h, beta) = (self.c, self.h, self.beta);
        let bh2 = beta * h * h;
        let start = [
            x * c1 + y * c3 - a * (h / bh2),
            y * c5,
            x * c2 + y * c4 - a * ((0.5 - beta) / beta),
        ];
        (start, x * self.gp + y * self.bp + a / bh2)
    }
}

impl Partials {
    /// How node `i`'s end moves with its total increment `d_theta` and its rates in the
    /// step's coordinates (`dv`, `dvdot`, `da`: the nodes' own outside the Lie algebra
    /// updates, the chart's `dX`, `dY`, `dA` in them).
    fn node_move(&self, i: usize, d_theta: &Vec6, rates: &[Vec6; 3]) -> NodeMove {
        let q = self.t[i] * d_theta;
        let Some(c) = self.chart.get(i) else {
            return [q, rates[0], rates[1], rates[2]];
        };
        let (m, nx) = (&self.t[i], c.n_x * rates[0]);
        [
            q,
            c.v_theta * d_theta + m * rates[0],
            c.vdot_theta * d_theta + nx + m * rates[1],
            c.a_theta * d_theta + nx + m * rates[2],
        ]
    }

    /// The transpose of [`Partials::node_move`]: the cotangents of the total increment and
    /// of the three rates for a cotangent of node `i`'s end.
    fn node_move_transposed(&self, i: usize, bar: &NodeMove) -> (Vec6, [Vec6; 3]) {
        let theta = self.t[i].tr_mul(&bar[0]);
        let Some(c) = self.chart.get(i) else {
            return (theta, [bar[1], bar[2], bar[3]]);
        };
        let m = &self.t[i];
        let theta = theta
            + c.v_theta.tr_mul(&bar[1])
            + c.vdot_theta.tr_mul(&bar[2])
            + c.a_theta.tr_mul(&bar[3]);
        let x = m.tr_mul(&bar[1]) + c.n_x.tr_mul(&(bar[2] + bar[3]));
        (theta, [x, m.tr_mul(&bar[2]), m.tr_mul(&bar[3])])
    }

    /// The start's velocity, acceleration and algorithmic acceleration changes in the
    /// step's coordinates: `(dv_n, dvdot_n - N0' dv_n, da_n - N0' dv_n)` in the Lie algebra
    /// updates, themselves otherwise.
    fn start_in_chart(&self, i: usize, dv: &Vec6, dvdot: &Vec6, da: &Vec6) -> [Vec6; 3] {
        match self.chart.get(i) {
            Some(c) => {
                let n0 = c.n0_x * dv;
                [*dv, dvdot - n0, da - n0]
            }
            None => [*dv, *dvdot, *da],
        }
    }

    /// The transpose of [`Partials::start_in_chart`]: `(vbar, vdotbar, abar)` of the start.
    fn start_in_chart_transposed(&self, i: usize, bar: [Vec6; 3]) -> [Vec6; 3] {
        match self.chart.get(i) {
            Some(c) => [bar[0] - c.n0_x.tr_mul(&(bar[1] + bar[2])), bar[1], bar[2]],
            None => bar,
        }
    }

    /// The partial derivatives that a move of the total increments reaches, with their
    /// index in a [`NodeMove`]: `F_q`, and in the Lie algebra updates `F_v` and `F_vd` too.
    fn configuration_partials(&self) -> impl Iterator<Item = (usize, &Vec<f64>)> {
        let kinds = if self.chart.is_empty() { 1 } else { 3 };
        [&self.f_q, &self.f_v, &self.f_vd]
            .into_iter()
            .enumerate()
            .take(kinds)
    }

    /// The nonzero entries `(row, column, value)` of one partial derivative.
    fn entries<'p>(&'p self, values: &'p [f64]) -> impl Iterator<Item = (usize, usize, f64)> + 'p {
        self.pattern
            .positions
            .iter()
            .zip(values)
            .filter(|(_, &v)| v != 0.0)
            .map(|(&(i, j), &v)| (i, j, v))
    }
}

impl<'a> StepFunction<'a> {
    /// The step of size `h` from `start` (the state `s_n`, with its time `t_n`) of a
    /// simulation with `settings` and the unknowns of `layout`.
    pub fn new(
        model: &'a Model,
        layout: &'a Layout,
        start: &'a State,
        settings: &DynamicSettings,
        h: f64,
    ) -> Self {
        let params = settings.scheme.parameters(settings.rho_inf);
        let step = Start::new(
            params,
            h,
            crate::solve::initial::mass_scale(model),
            settings,
            start.t + h,
        );
        let start_nodes = crate::sensors::node_states(start);
        let mut b_start = vec![Vec12::zeros(); layout.n_rows];
        if layout.stabilized {
            crate::assembly::constraint_rows(model, layout, &start_nodes, start.t, &mut b_start);
        }
        Self {
            model,
            layout,
            start,
            step,
            b_start,
            start_nodes,
            inputs: None,
            cache: RefCell::new(None),
        }
    }

    /// The same step with the row scale of a model whose largest nodal mass is `mass`. The
    /// row scale `s = 1/(beta' m)` is a constant of the step function (the simulation's:
    /// the nominal model's), not a function of the parameters: derivatives with respect to
    /// the parameters are taken at fixed `s`, as the unknowns `mu = s lambda` are.
    pub fn with_mass_scale(mut self, mass: f64) -> Self {
        self.step = self.step.with_mass(mass);
        self
    }

    /// The same step with the input vector `u_{n+1}` given (one value per
    /// [`crate::model::Input`] of the model, in its order) in place of the inputs'
    /// functions: what a transcription sets at each step. (The initial state `s_0`, its
    /// consistent accelerations, takes the inputs' functions at `t_0`: `u_0` is not an
    /// argument yet.)
    ///
    /// # Panics
    /// If `u` does not have one value per input.
    pub fn with_inputs(mut self, u: &[f64]) -> Self {
        assert_eq!(u.len(), self.model.inputs.len(), "one value per input");
        self.inputs = Some(u.to_vec());
        self
    }

    /// The input vector of the step: the given one, or each input's function at `t_{n+1}`.
    pub fn input_values(&self) -> Vec<f64> {
        match &self.inputs {
            Some(u) => u.clone(),
            None => {
                let ctx = crate::elements::Context::at(self.model, self.start.t + self.step.h, 1.0);
                (0..self.model.inputs.len()).map(|k| ctx.input(k)).collect()
            }
        }
    }

    /// `dR/du` at `x`: the sparse columns `s dr/du_k` of the equilibrium rows, one per input
    /// (the residual is linear in the inputs; [`crate::parameter_derivatives::input_derivative`]).
    pub fn input_jacobian(&self, x: &[f64]) -> Triplets {
        // at the end of the step, tangent operators identity (a parameter derivative's point)
        let (end, mut nodes, ..) = self.end_nodes(x);
        nodes.iter_mut().for_each(|n| n.t = Mat6::identity());
        let point = self.derivative_point(&end, &nodes);
        let mut dr = vec![0.0; self.layout.n_dofs];
        let mut out = Triplets::new();
        for k in 0..self.model.inputs.len() {
            crate::parameter_derivatives::input_derivative(self.model, &point, k, &mut dr);
            dr.iter_mut().for_each(|v| *v *= self.step.scale);
            push_column(&mut out, k, &dr);
        }
        out
    }

    /// `(dR/du) du` at `x`.
    pub fn input_jvp(&self, x: &[f64], du: &[f64]) -> Vec<f64> {
        assert_eq!(du.len(), self.model.inputs.len(), "one value per input");
        let mut out = vec![0.0; self.layout.n_unknowns()];
        for (i, k, v) in self.input_jacobian(x) {
            out[i] += v * du[k];
        }
        out
    }

    /// `(dR/du)^T w` at `x`: one entry per input.
    pub fn input_vjp(&self, x: &[f64], w: &[f64]) -> Vec<f64> {
        assert_eq!(w.len(), self.layout.n_unknowns(), "one weight per unknown");
        let mut out = vec![0.0; self.model.inputs.len()];
        for (i, k, v) in self.input_jacobian(x) {
            out[k] += v * w[i];
        }
        out
    }

    /// The partial derivatives kept at the last unknowns asked for, taken out.
    pub fn take_partials(&self) -> KeptPartials {
        KeptPartials(self.cache.borrow_mut().take())
    }

    /// This step function with the partial derivatives `kept` of another of the same step
    /// (used where they were taken: at the same unknowns and step numbers; elsewhere their
    /// storage takes the new ones).
    pub fn with_partials(self, kept: KeptPartials) -> Self {
        *self.cache.borrow_mut() = kept.0;
        self
    }

    /// The predictor of the step (no extrapolation): `vdot_{n+1} = vdot_n`,
    /// `mu = s lambda_n`, `zeta = 0`.
    pub fn predict(&self) -> Vec<f64> {
        let mut state = self.start.clone();
        let mut dq = Vec::new();
        predict(
            &self.step.params,
            &self.step.first,
            self.step.h,
            self.start,
            None,
            self.chart(),
            &mut state,
            &mut dq,
        );
        let mut x = Vec::new();
        let step = (&dq[..], &self.start.lambda[..], &[][..]);
        let states = (&self.start.x[..], &state.x[..]);
        pack_unknowns(self.layout, self.step.scale, step, states, &mut x);
        x
    }

    /// The local coordinates of the Lie algebra updates (`None` for the others).
    fn chart(&self) -> Option<Chart> {
        self.step.chart(self.model.group)
    }

    /// `dq + B(q_n)^T zeta + c_n` of the unknowns `x` (`v_1` the end velocities of `x`).
    fn total(&self, x: &[f64], v_1: &[Vec6]) -> Vec<f64> {
        let layout = self.layout;
        let zeta = &x[layout.block(Block::Stabilization)];
        let mut total = Vec::new();
        let dq = &x[layout.block(Block::NodeIncrements)];
        total_increments(layout, dq, zeta, &self.b_start, &mut total);
        commutator_correction(&self.step, self.model.group, self.start, v_1, &mut total);
        total
    }

    /// The end of the step `s_{n+1}` for the unknowns `x` (the scheme's relations in the
    /// module documentation; multipliers `lambda = mu / s`, redundant rows 0).
    pub fn end_state(&self, x: &[f64]) -> State {
        self.end_state_and_total(x).0
    }

    /// [`StepFunction::end_state`] and the total increments `dq + B(q_n)^T zeta`.
    fn end_state_and_total(&self, x: &[f64]) -> (State, Vec<f64>) {
        let (end, total, _) = self.end_state_in_chart(x);
        (end, total)
    }

    /// [`StepFunction::end_state_and_total`] and, in the Lie algebra updates, each node's
    /// rates in the step's chart `[X, Y, A]` (`Theta'`, `Theta''` and the algorithmic
    /// acceleration; empty for the other updates): the scheme's relations hold for them,
    /// and the nodes' end values are `M X`, `M Y + N`, `M A + N` (module documentation).
    fn end_state_in_chart(&self, x: &[f64]) -> (State, Vec<f64>, Vec<[Vec6; 3]>) {
        let p = &self.step.params;
        let h = self.step.h;
        let s0 = self.start;
        let chart = self.chart();
        let mut end = s0.clone();
        end.t = s0.t + h;
        for i in 0..s0.q.len() {
            let dq = Vec6::from_column_slice(&x[6 * i..6 * i + 6]);
            let (vd0, a0) = chart_start(chart, s0, i);
            let a1 = (dq - s0.v[i] * h - a0 * ((0.5 - p.beta) * h * h)) / (p.beta * h * h);
            end.v[i] = s0.v[i] + a0 * ((1.0 - p.gamma) * h) + a1 * (p.gamma * h);
            end.vdot[i] =
                (a1 * (1.0 - p.alpha_m) + a0 * p.alpha_m - vd0 * p.alpha_f) / (1.0 - p.alpha_f);
            end.a[i] = a1;
        }
        let total = self.total(x, &end.v);
        let inc = |i: usize| Vec6::from_column_slice(&total[6 * i..6 * i + 6]);
        for (i, q) in end.q.iter_mut().enumerate() {
            *q = match chart {
                Some(chart) => chart.point(&s0.q[i], &inc(i)),
                None => self.model.group.integrate(&s0.q[i], &inc(i)),
            };
        }
        let mut rates = Vec::new();
        if let Some(chart) = chart {
            for i in 0..s0.q.len() {
                let (m, n) = (chart.map(&inc(i)), chart.rate(&inc(i), &end.v[i]));
                rates.push([end.v[i], end.vdot[i], end.a[i]]);
                end.v[i] = m * end.v[i];
                end.vdot[i] = m * end.vdot[i] + n;
                end.a[i] = m * end.a[i] + n;
            }
        }
        end.lambda.iter_mut().for_each(|l| *l = 0.0);
        for (k, &row) in self.layout.active_rows.iter().enumerate() {
            end.lambda[row] = x[self.layout.n_dofs + k] / self.step.scale;
        }
        let first = &self.step.first;
        let dx = &x[self.layout.block(Block::States)];
        for (i, d) in dx.iter().enumerate() {
            let w1 = first.rate_of_increment(h, *d, s0.w[i]);
            end.x[i] = s0.x[i] + d;
            end.xdot[i] = first.rate_from(s0.xdot[i], s0.w[i], w1);
            end.w[i] = w1;
        }
        (end, total, rates)
    }

    /// Node kinematics at the end of the step (the Newton iteration's, [`kinematics`]),
    /// with the tangent operators `T(total)` (`M(total)` in the Lie algebra updates), and
    /// the chart's rates of [`StepFunction::end_state_in_chart`].
    fn end_nodes(&self, x: &[f64]) -> (State, Vec<NodeState>, Vec<f64>, Vec<[Vec6; 3]>) {
        let (end, total, rates) = self.end_state_in_chart(x);
        let mut nodes = self.start_nodes.clone();
        let sequential = Threads::sequential();
        // The Newton iterate of the Lie algebra updates holds the chart's rates.
        let mut in_chart = None;
        if !rates.is_empty() {
            let mut s = end.clone();
            for (i, [v, vdot, _]) in rates.iter().enumerate() {
                (s.v[i], s.vdot[i]) = (*v, *vdot);
            }
            in_chart = Some(s);
        }
        let (step, group) = (&self.step, self.model.group);
        let iterate = in_chart.as_ref().unwrap_or(&end);
        kinematics(
            step,
            group,
            self.start,
            iterate,
            &total,
            true,
            &mut nodes,
            &sequential,
        );
        if let Some(chart) = self.chart() {
            for (i, n) in nodes.iter_mut().enumerate() {
                n.t = chart.map(&Vec6::from_column_slice(&total[6 * i..6 * i + 6]));
            }
        }
        (end, nodes, total, rates)
    }

    fn assemble(
        &self,
        data: &mut crate::data::Data,
        nodes: &[NodeState],
        end: &State,
        sc: &Scaling,
        matrix: bool,
    ) {
        assert!(
            data.layout.active_rows == self.layout.active_rows
                && data.layout.stabilized == self.layout.stabilized,
            "the data must be built for the step function's layout"
        );
        let it = self.iterate(nodes, end);
        crate::assembly::assemble(self.model, data, &it, sc, matrix);
    }

    /// The assembly's iterate at the end of the step with `nodes`' kinematics.
    fn iterate<'i>(
        &'i self,
        nodes: &'i [NodeState],
        end: &'i State,
    ) -> crate::assembly::Iterate<'i> {
        crate::assembly::Iterate {
            nodes,
            t: end.t,
            lambda: &end.lambda,
            b_start: &self.b_start,
            x: &end.x,
            xdot: &end.xdot,
            inputs: self.inputs.as_deref(),
        }
    }

    /// The step residual `R(x; s_n, p, h)` (`n_unknowns`).
    pub fn residual(&self, x: &[f64], data: &mut crate::data::Data) -> Vec<f64> {
        let (end, nodes, ..) = self.end_nodes(x);
        self.assemble(data, &nodes, &end, &self.step.scaling(0.0), false);
        data.residual.clone()
    }

    /// The partial derivatives at the end of the step (see [`Partials`]), kept for the next
    /// call at the same `x` with the same [`StepFunction::step`].
    fn partials(&self, x: &[f64], data: &mut crate::data::Data) -> Arc<Partials> {
        if let Some(c) = &*self.cache.borrow() {
            if c.x.as_slice() == x && c.step == self.step && c.inputs == self.inputs {
                return Arc::clone(&c.partials);
            }
        }
        // The storage of partial derivatives taken elsewhere (no one else holds them) is
        // reused for these.
        let stale = (self.cache.borrow_mut().take()).and_then(|c| Arc::try_unwrap(c.partials).ok());
        let partials = Arc::new(self.compute_partials(x, data, stale));
        *self.cache.borrow_mut() = Some(Cached {
            x: x.to_vec(),
            step: self.step,
            inputs: self.inputs.clone(),
            partials: Arc::clone(&partials),
        });
        partials
    }

    /// [`StepFunction::partials`], assembled: the iteration matrix with the stiffness
    /// coefficient alone (`F_q`, `F_mu`), then the elements alone once per other coefficient
    /// (velocities, accelerations, and the element states' two): the joints have no terms
    /// there but their rows `B`, which the tail takes from the first assembly.
    fn compute_partials(
        &self,
        x: &[f64],
        data: &mut crate::data::Data,
        spare: Option<Partials>,
    ) -> Partials {
        let [mut f_q, mut f_mu, f_v, f_vd, f_x, f_xd] = spare.map_or_else(Default::default, |p| {
            [p.f_q, p.f_mu, p.f_v, p.f_vd, p.f_x, p.f_xd]
        });
        let (end, mut nodes, total, rates) = self.end_nodes(x);
        let group = self.model.group;
        let t: Vec<Mat6> = nodes.iter().map(|n| n.t).collect();
        let inc = |i: usize| Vec6::from_column_slice(&total[6 * i..6 * i + 6]);
        let chart = self.chart();
        let g: Vec<Mat6> = (0..nodes.len())
            .map(|i| match chart {
                Some(chart) => chart.transport(group, &inc(i)),
                None => group.adjoint(&group.exp(&-inc(i))),
            })
            .collect();
        let chart_nodes = chart.map_or_else(Vec::new, |chart| {
            (rates.iter().enumerate())
                .map(|(i, r)| {
                    let j = chart.jacobians(&inc(i), &r[0], r);
                    ChartNode {
                        v_theta: j.m_theta[0],
                        vdot_theta: j.m_theta[1] + j.n_theta,
                        a_theta: j.m_theta[2] + j.n_theta,
                        n_x: j.n_x,
                        n0_x: chart.start_rate_derivative(&self.start.v[i]),
                    }
                })
                .collect()
        });
        for n in &mut nodes {
            n.t = Mat6::identity();
        }
        let layout = self.layout;
        let s = self.step.scale;
        let pattern = self.pattern(data);
        let mut sc = self.step.scaling(0.0);
        let coef = |m, c, k| Coefficients {
            m,
            c,
            k,
            x: 0.0,
            xdot: 0.0,
            y: 0.0,
        };
        // Position-level rows against the configuration: s (K_t + K_c) and B; the
        // multipliers' columns B^T of the same assembly (they carry no coefficient; the
        // element states' rows too: a control block measuring a constraint force).
        sc.coef = coef(0.0, 0.0, s);
        self.assemble(data, &nodes, &end, &sc, true);
        pattern.select_into(Selection::Configuration, &data.values, &mut f_q);
        pattern.select_into(Selection::Multipliers, &data.values, &mut f_mu);
        // The other partials have no joint terms: the elements alone, once per coefficient
        // set (sequential), or full assemblies on the threads.
        let mut sets = vec![coef(0.0, s, 0.0), coef(s, 0.0, 0.0)];
        if layout.n_states > 0 {
            let x = Coefficients {
                x: s,
                y: s,
                ..coef(0.0, 0.0, 0.0)
            };
            let xd = Coefficients {
                xdot: s,
                ..coef(0.0, 0.0, 0.0)
            };
            sets.extend([x, xd]);
        }
        let which = [
            Selection::Velocities,
            Selection::Accelerations,
            Selection::States,
            Selection::States,
        ];
        let mut out = [f_v, f_vd, f_x, f_xd];
        for (k, o) in out.iter_mut().enumerate() {
            zeroed(
                o,
                if k < sets.len() {
                    pattern.positions.len()
                } else {
                    0
                },
            );
        }
        if data.threads.pool().is_some() {
            for ((coef, o), &w) in sets.iter().zip(out.iter_mut()).zip(&which) {
                sc.coef = *coef;
                self.assemble(data, &nodes, &end, &sc, true);
                pattern.select_into(w, &data.values, o);
            }
        } else {
            let it = self.iterate(&nodes, &end);
            let mut sinks: Vec<_> = (out.iter_mut().zip(&which).take(sets.len()))
                .map(|(o, &w)| pattern.sink(w, o))
                .collect();
            crate::assembly::assemble_elements(self.model, data, &it, &sc, &sets, &mut sinks);
        }
        let [mut f_v, f_vd, f_x, f_xd] = out;
        // Velocities: s C_t (and the nodal damping) and, on the velocity-level rows,
        // B / gamma'.
        for &k in &pattern.velocity_positions {
            f_v[k as usize] /= self.step.gp;
        }
        if layout.stabilized {
            self.velocity_rows_configuration(&nodes, &end, &pattern, &mut f_q);
        }
        Partials {
            pattern,
            f_q,
            f_v,
            f_vd,
            f_mu,
            f_x,
            f_xd,
            e: (0..nodes.len())
                .filter_map(|i| self.step.increment_map(group, &self.start.v[i]))
                .collect(),
            t,
            g,
            chart: chart_nodes,
            end,
            nodes,
            k_zeta: self.start_constraint_stiffness(x),
        }
    }

    /// The step Jacobian's positions for `data`'s layout, built on first use and kept in
    /// `data`.
    fn pattern(&self, data: &mut crate::data::Data) -> Arc<JacobianPattern> {
        let (layout, solver) = (self.layout, &data.solver);
        Arc::clone(
            data.derived
                .get_or_insert_with(|| Arc::new(JacobianPattern::new(layout, &solver.pattern()))),
        )
    }

    /// `d((B(q) v + Phi_t) / gamma')/dq` of the velocity-level rows: for row `r`,
    /// `v^T dB_r^T/dq` (the joint's `K_c` with the unit multiplier on that row) plus
    /// `dPhi_t/dq = dB_r/dt` (nonzero for a driven angle).
    fn velocity_rows_configuration(
        &self,
        nodes: &[NodeState],
        end: &State,
        pattern: &JacobianPattern,
        f_q: &mut [f64],
    ) {
        let layout = self.layout;
        let ground = NodeState::ground(Default::default());
        for (j, joint) in self.model.joints.iter().enumerate() {
            let slots = [joint.node_a, joint.node_b];
            let pair = slots.map(|s| s.map_or(ground, |n| nodes[n.0]));
            let rows = &layout.joint_rows[j];
            let start = layout.joint_row_start[j];
            let mut vloc = Vec12::zeros();
            for (ka, n) in slots.iter().enumerate() {
                if let Some(n) = n {
                    vloc.fixed_rows_mut::<6>(6 * ka).copy_from(&end.v[n.0]);
                }
            }
            for r in 0..rows.len() {
                let Some(k) = layout.row_unknown[start + r] else {
                    continue;
                };
                let mut unit = [0.0; crate::joints::MAX_ROWS];
                unit[r] = 1.0;
                let mut kr = crate::elements::Mat12::zeros();
                joint.evaluate(
                    self.model.group,
                    rows,
                    &pair,
                    end.t,
                    &unit[..rows.len()],
                    Some(&mut kr),
                );
                // d(Phi_t)/dq = dB/dt (a driven angle's Phi_t moves with q).
                let b_t =
                    crate::joints::evaluate_row(self.model.group, joint, rows[r], &pair, end.t).b_t;
                let row = (kr.transpose() * vloc + b_t) / self.step.gp;
                for (ka, n) in slots.iter().enumerate() {
                    if let Some(n) = n {
                        for c in 0..6 {
                            let at = pattern.position((layout.zeta(k), 6 * n.0 + c));
                            f_q[at] += row[6 * ka + c];
                        }
                    }
                }
            }
        }
    }

    /// `d(B(q_n)^T zeta)/dq_n` (node rows and columns; stabilized formulation).
    fn start_constraint_stiffness(&self, x: &[f64]) -> Triplets {
        let layout = self.layout;
        let mut out = Triplets::new();
        if !layout.stabilized {
            return out;
        }
        let zeta = &x[layout.block(Block::Stabilization)];
        let ground = NodeState::ground(Default::default());
        for (j, joint) in self.model.joints.iter().enumerate() {
            let slots = [joint.node_a, joint.node_b];
            let pair = slots.map(|s| s.map_or(ground, |n| self.start_nodes[n.0]));
            let rows = &layout.joint_rows[j];
            let start = layout.joint_row_start[j];
            let mut lam = [0.0; crate::joints::MAX_ROWS];
            for (r, l) in lam.iter_mut().enumerate().take(rows.len()) {
                *l = layout.row_unknown[start + r].map_or(0.0, |k| zeta[k]);
            }
            let mut k = crate::elements::Mat12::zeros();
            joint.evaluate(
                self.model.group,
                rows,
                &pair,
                self.start.t,
                &lam[..rows.len()],
                Some(&mut k),
            );
            for (ka, a) in slots.iter().enumerate() {
                for (kb, b) in slots.iter().enumerate() {
                    if let (Some(a), Some(b)) = (a, b) {
                        for r in 0..6 {
                            for c in 0..6 {
                                out.push((6 * a.0 + r, 6 * b.0 + c, k[(6 * ka + r, 6 * kb + c)]));
                            }
                        }
                    }
                }
            }
        }
        out
    }

    /// The exact Jacobian `dR/dx` at `x`, built fresh (no regularization):
    /// `[F_q T + gamma' F_v + beta' F_vd | F_mu | F_q T B(q_n)^T]`.
    pub fn jacobian(&self, x: &[f64], data: &mut crate::data::Data) -> Triplets {
        let mut values = Vec::new();
        let pattern = self.jacobian_values(x, data, &mut values);
        pattern
            .positions
            .iter()
            .zip(&values)
            .map(|(&(i, j), &v)| (i, j, v))
            .collect()
    }

    /// The exact Jacobian `dR/dx` at `x` as values on the positions of the layout's
    /// [`JacobianPattern`] (the same positions at every step of a layout), into `out` (its
    /// storage reused); the pattern is returned.
    pub fn jacobian_values(
        &self,
        x: &[f64],
        data: &mut crate::data::Data,
        out: &mut Vec<f64>,
    ) -> Arc<JacobianPattern> {
        let p = self.partials(x, data);
        let pattern = &p.pattern;
        let step = &self.step;
        let (gp, bp, cx) = (step.gp, step.bp, step.cx);
        // In the Lie algebra updates the velocities and accelerations also move with the
        // configuration (the node blocks below).
        let in_chart = !p.chart.is_empty();
        let (vp, ap) = if in_chart { (0.0, 0.0) } else { (gp, bp) };
        out.clear();
        out.extend(
            (p.f_v.iter().zip(&p.f_vd).zip(&p.f_mu)).map(|((v, vd), mu)| v * vp + vd * ap + mu),
        );
        if self.layout.n_states > 0 {
            for ((o, x), xd) in out.iter_mut().zip(&p.f_x).zip(&p.f_xd) {
                *o += x + xd * cx;
            }
        }
        // F_q T, node block by node block of each row: (F_q T)_k = sum_c F_q,c T(c, k); the
        // stabilized form keeps them for its zeta columns.
        let stabilized = !pattern.zeta.is_empty();
        let mut fqt = Vec::with_capacity(if stabilized { pattern.blocks.len() } else { 0 });
        // The increments' columns take F_q T (I + E) (module documentation); in the Lie
        // algebra updates F_q M + F_v dv/dTheta + F_vd dvdot/dTheta (the zeta columns'), plus
        // the rates' gamma' (F_v M + F_vd N_X) + beta' F_vd M.
        let at = |f: &[f64], k: usize| Vec6::from_column_slice(&f[k..k + 6]);
        for &(k, n) in &pattern.blocks {
            let (row, columns) = if in_chart {
                let bar = [at(&p.f_q, k), at(&p.f_v, k), at(&p.f_vd, k), Vec6::zeros()];
                let (theta, [x, y, _]) = p.node_move_transposed(n, &bar);
                (theta, theta + x * gp + y * bp)
            } else {
                let row = p.t[n].tr_mul(&at(&p.f_q, k));
                (row, p.e.get(n).map_or(row, |e| e.tr_mul(&row)))
            };
            for c in 0..6 {
                out[k + c] += columns[c];
            }
            if stabilized {
                fqt.push(row);
            }
        }
        // Stabilized: F_q T B(q_n)^T on the zeta columns.
        let mut block = 0;
        for &(k, row, slot, at) in &pattern.zeta {
            while pattern.blocks[block].0 != k {
                block += 1;
            }
            out[at] += fqt[block].dot(&self.b_start[row].fixed_rows::<6>(6 * slot));
        }
        Arc::clone(pattern)
    }

    /// `alpha dD/dp` of the nodal damping `alpha D v` (pseudo-dynamic statics; none without
    /// it), per node.
    fn nodal_damping_derivative(
        &self,
        params: &crate::model::parameters::Parameters,
        id: crate::model::ParamId,
    ) -> Vec<(crate::model::NodeId, Vec6)> {
        if self.step.nodal_damping == 0.0 {
            return Vec::new();
        }
        let alpha = self.step.nodal_damping;
        crate::parameter_derivatives::nodal_mass_derivative(self.model, params, id)
            .into_iter()
            .map(|(n, d)| (n, d * alpha))
            .collect()
    }

    /// The [`crate::parameter_derivatives::Point`] of the end of the step.
    fn derivative_point<'p>(
        &'p self,
        end: &'p State,
        nodes: &'p [NodeState],
    ) -> crate::parameter_derivatives::Point<'p> {
        crate::parameter_derivatives::Point {
            nodes,
            x: &end.x,
            xdot: &end.xdot,
            t: end.t,
            lambda: &end.lambda,
            load_factor: self.step.load_factor,
            inputs: self.inputs.as_deref(),
        }
    }

    /// The stabilization unknowns of `x` as one weight per constraint row (0 for the rows
    /// left out).
    fn zeta_rows(&self, x: &[f64]) -> Vec<f64> {
        let layout = self.layout;
        let mut w = vec![0.0; layout.n_rows];
        let zeta = &x[layout.block(Block::Stabilization)];
        for (&row, &z) in layout.active_rows.iter().zip(zeta) {
            w[row] = z;
        }
        w
    }

    /// `(dR/dp) dp` at `x`, `dp` one entry per parameter of `params` (a
    /// [`crate::model::parameters::Parameters`] of this model): `s dr/dp` on the
    /// equilibrium rows, `dPhi/dp` on the constraint rows and `dpsi/dp / gamma'` on the
    /// velocity-level rows, `h de/dp` on the element states' rows, `s alpha dD/dp v` of the
    /// nodal damping of pseudo-dynamic statics (with `r + B^T lambda`,
    /// `Phi`, `psi = B v + Phi_t` and `e` at the end of the step,
    /// [`crate::parameter_derivatives`]), and in the stabilized form the move of
    /// `q_{n+1} = q_n exp(dq + B(q_n; p)^T zeta)`: `F_q T d(B(q_n)^T zeta)/dp`.
    pub fn parameter_jvp(
        &self,
        x: &[f64],
        params: &crate::model::parameters::Parameters,
        dp: &[f64],
        data: &mut crate::data::Data,
    ) -> Vec<f64> {
        use crate::parameter_derivatives::{residual_derivative, Columns};
        let layout = self.layout;
        let (nd, na, so) = (layout.n_dofs, layout.n_active, layout.state_offset());
        let partials = self.partials(x, data);
        let (end, nodes) = (&partials.end, &partials.nodes);
        let point = self.derivative_point(end, nodes);
        let mut dr = vec![0.0; nd];
        let mut dphi = vec![0.0; layout.n_rows];
        let mut dpsi = vec![0.0; if layout.stabilized { layout.n_rows } else { 0 }];
        let mut de = vec![0.0; layout.n_states];
        let mut out = vec![0.0; layout.n_unknowns()];
        for (id, &d) in params.ids().zip(dp) {
            if d == 0.0 {
                continue;
            }
            let columns = Columns {
                dr: &mut dr,
                dphi: &mut dphi,
                dpsi: &mut dpsi,
                de: &mut de,
            };
            residual_derivative(self.model, params, id, &point, columns);
            for i in 0..nd {
                out[i] += d * self.step.scale * dr[i];
            }
            for (node, dd) in self.nodal_damping_derivative(params, id) {
                let damping = dd.component_mul(&end.v[node.0]) * (self.step.scale * d);
                for k in 0..6 {
                    out[6 * node.0 + k] += damping[k];
                }
            }
            for (k, e) in de.iter().enumerate() {
                out[so + k] += d * self.step.h * e;
            }
            for (k, &row) in layout.active_rows.iter().enumerate() {
                out[nd + k] += d * dphi[row];
                if layout.stabilized {
                    out[nd + na + k] += d * dpsi[row] / self.step.gp;
                }
            }
        }
        if let Some(dtotal) = self.stabilization_parameter_move(x, params, dp) {
            // F_q T dtotal (and, in the Lie algebra updates, the velocities' and
            // accelerations' moves with the configuration).
            let p = self.partials(x, data);
            let moves: Vec<NodeMove> = (0..layout.n_nodes)
                .map(|n| {
                    let d = Vec6::from_column_slice(&dtotal[6 * n..6 * n + 6]);
                    p.node_move(n, &d, &[Vec6::zeros(); 3])
                })
                .collect();
            for (kind, f) in p.configuration_partials() {
                for (i, j, v) in p.entries(f) {
                    out[i] += v * moves[j / 6][kind][j % 6];
                }
            }
        }
        out
    }

    /// `(dR/dp)^T w` at `x`: one entry per parameter of `params` (see
    /// [`StepFunction::parameter_jvp`]).
    pub fn parameter_vjp(
        &self,
        x: &[f64],
        params: &crate::model::parameters::Parameters,
        w: &[f64],
        data: &mut crate::data::Data,
    ) -> Vec<f64> {
        let ids: Vec<_> = params.ids().collect();
        self.parameter_vjp_for(x, params, &ids, w, data)
    }

    /// [`StepFunction::parameter_vjp`] for the parameters `ids` only (the other entries 0):
    /// what an adjoint with a few design parameters needs.
    pub fn parameter_vjp_for(
        &self,
        x: &[f64],
        params: &crate::model::parameters::Parameters,
        ids: &[crate::model::ParamId],
        w: &[f64],
        data: &mut crate::data::Data,
    ) -> Vec<f64> {
        use crate::parameter_derivatives::{
            constraint_force_derivative, residual_derivative_transpose_for, Weights,
        };
        let layout = self.layout;
        let (nd, na) = (layout.n_dofs, layout.n_active);
        let partials = self.partials(x, data);
        let (end, nodes) = (&partials.end, &partials.nodes);
        let point = self.derivative_point(end, nodes);
        let w_r: Vec<f64> = w[..nd].iter().map(|v| v * self.step.scale).collect();
        let w_e: Vec<f64> = w[layout.block(Block::States)]
            .iter()
            .map(|v| v * self.step.h)
            .collect();
        let mut w_phi = vec![0.0; layout.n_rows];
        let mut w_psi = vec![0.0; if layout.stabilized { layout.n_rows } else { 0 }];
        for (k, &row) in layout.active_rows.iter().enumerate() {
            w_phi[row] = w[nd + k];
            if layout.stabilized {
                w_psi[row] = w[nd + na + k] / self.step.gp;
            }
        }
        let mut grad = vec![0.0; params.len()];
        let weights = Weights {
            r: &w_r,
            phi: &w_phi,
            psi: &w_psi,
            e: &w_e,
        };
        residual_derivative_transpose_for(self.model, params, ids, &point, weights, &mut grad);
        if self.step.nodal_damping > 0.0 {
            for &id in ids {
                for (node, dd) in self.nodal_damping_derivative(params, id) {
                    let damping = dd.component_mul(&end.v[node.0]);
                    let w_node = &w_r[6 * node.0..6 * node.0 + 6];
                    grad[id.0 as usize] +=
                        damping.iter().zip(w_node).map(|(a, b)| a * b).sum::<f64>();
                }
            }
        }
        if layout.stabilized {
            // u = (F_q T)^T w (in the Lie algebra updates with the velocities' and
            // accelerations' moves), then u . d(B(q_n)^T zeta)/dp for the joint parameters.
            let p = &partials;
            let mut g = vec![[Vec6::zeros(); 4]; nd / 6];
            for (kind, f) in p.configuration_partials() {
                for (i, j, v) in p.entries(f) {
                    g[j / 6][kind][j % 6] += v * w[i];
                }
            }
            let u: Vec<f64> = (g.iter().enumerate())
                .flat_map(|(n, bar)| {
                    p.node_move_transposed(n, bar)
                        .0
                        .iter()
                        .copied()
                        .collect::<Vec<_>>()
                })
                .collect();
            let zeta = self.zeta_rows(x);
            let mut dforce = vec![0.0; nd];
            for &id in ids {
                let model = self.model;
                let (start_nodes, t) = (&self.start_nodes, self.start.t);
                constraint_force_derivative(model, params, id, start_nodes, t, &zeta, &mut dforce);
                grad[id.0 as usize] += u.iter().zip(&dforce).map(|(a, b)| a * b).sum::<f64>();
            }
        }
        grad
    }

    /// How the end of node `i` moves, `(w, dv, dvd)`, with its start `[dq, dv, dvdot, da]`
    /// (a tangent of `s_n`) and the move `kz` of its configuration increment by the others'
    /// start (`K_zeta dq_n` of the stabilized form), at fixed unknowns: what
    /// [`StepFunction::start_jvp_many`] and [`StepFunction::start_jacobian`] apply.
    fn start_move(
        &self,
        p: &Partials,
        relations: &Relations,
        i: usize,
        kz: &Vec6,
        [dq, dv, dvdot, da]: [&Vec6; 4],
    ) -> [Vec6; 3] {
        let dc = self.commutator_jvp(i, &p.end.v[i], dv, da);
        let start = p.start_in_chart(i, dv, dvdot, da);
        let rates = relations.forward(start, &Vec6::zeros());
        let [w, dv, dvd, _] = p.node_move(i, &(kz + dc), &rates);
        [p.g[i] * dq + w, dv, dvd]
    }

    /// `dc_n = sigma h^2 (ad(v_n) dv_{n+1} - ad(v_{n+1}) dv_n)` of node `i` at fixed `dq`,
    /// `dv_{n+1} = c1 dv_n + c2 da_n`: how the bracket term of the configuration update
    /// moves with the start (module documentation); `v_1` is `v_{n+1}`.
    fn commutator_jvp(&self, i: usize, v_1: &Vec6, dv: &Vec6, da: &Vec6) -> Vec6 {
        let w = self.step.commutator_weight();
        if w == 0.0 {
            return Vec6::zeros();
        }
        let [c1, c2, ..] = self.start_coefficients();
        let g = self.model.group;
        (g.ad(&self.start.v[i]) * (dv * c1 + da * c2) - g.ad(v_1) * dv) * w
    }

    /// The transpose of [`StepFunction::commutator_jvp`]: the cotangents `(vbar, abar)`
    /// of `v_n` and `a_n` for a cotangent `cbar` of `c_n`.
    fn commutator_vjp(&self, i: usize, v_1: &Vec6, cbar: &Vec6) -> (Vec6, Vec6) {
        let w = self.step.commutator_weight();
        if w == 0.0 {
            return (Vec6::zeros(), Vec6::zeros());
        }
        let [c1, c2, ..] = self.start_coefficients();
        let g = self.model.group;
        let u = g.ad(&self.start.v[i]).transpose() * cbar;
        ((u * c1 - g.ad(v_1).transpose() * cbar) * w, u * (c2 * w))
    }

    /// The scheme's relations of the step ([`Relations`]).
    fn relations(&self) -> Relations {
        Relations {
            c: self.start_coefficients(),
            gp: self.step.gp,
            bp: self.step.bp,
            h: self.step.h,
            beta: self.step.params.beta,
        }
    }

    /// Coefficients of `v_{n+1}` and `vdot_{n+1}` in `(v_n, a_n, vdot_n)` at fixed `dq`.
    fn start_coefficients(&self) -> [f64; 5] {
        let p = &self.step.params;
        let h = self.step.h;
        let c1 = 1.0 - p.gamma / p.beta;
        let c2 = h * (1.0 - p.gamma / (2.0 * p.beta));
        let c3 = -self.step.bp * h;
        let c4 = (p.alpha_m - (1.0 - p.alpha_m) * (0.5 - p.beta) / p.beta) / (1.0 - p.alpha_f);
        let c5 = -p.alpha_f / (1.0 - p.alpha_f);
        [c1, c2, c3, c4, c5]
    }

    /// `(dR/ds_n) ds` at `x`.
    pub fn start_jvp(
        &self,
        x: &[f64],
        ds: &StateTangent,
        data: &mut crate::data::Data,
    ) -> Vec<f64> {
        self.start_jvp_many(x, std::slice::from_ref(ds), data)
            .pop()
            .expect("one product")
    }

    /// [`StepFunction::start_jvp`] for several tangents at once: the partial derivatives are
    /// read once for all of them (the direct method's `n_p` right-hand sides of a step).
    pub fn start_jvp_many(
        &self,
        x: &[f64],
        ds: &[StateTangent],
        data: &mut crate::data::Data,
    ) -> Vec<Vec<f64>> {
        let p = self.partials(x, data);
        let relations = self.relations();
        let (n, np, nd) = (self.start.q.len(), ds.len(), self.layout.n_dofs);
        // The moves of the end of the step, unknown by unknown with the tangents contiguous
        // (`w[j np + k]`): the configuration G dq_n + T (d(B_n^T zeta)/dq_n dq_n + dc_n),
        // the velocities and the accelerations.
        let (mut w, mut dv, mut dvd) = (vec![0.0; nd * np], vec![0.0; nd * np], vec![0.0; nd * np]);
        let mut kz = vec![Vec6::zeros(); n];
        for (k, ds) in ds.iter().enumerate() {
            kz.iter_mut().for_each(|v| *v = Vec6::zeros());
            for &(i, j, v) in &p.k_zeta {
                kz[i / 6][i % 6] += v * ds.q[j / 6][j % 6];
            }
            for i in 0..n {
                let tangent = [&ds.q[i], &ds.v[i], &ds.vdot[i], &ds.a[i]];
                let [wi, dvi, dvdi] = self.start_move(&p, &relations, i, &kz[i], tangent);
                for c in 0..6 {
                    let at = (6 * i + c) * np + k;
                    (w[at], dv[at], dvd[at]) = (wi[c], dvi[c], dvdi[c]);
                }
            }
        }
        // F_q w + F_v dv + F_vd dvd in one pass over the node columns
        let mut out = vec![0.0; self.layout.n_unknowns() * np];
        for (k, &(i, j)) in p.pattern.positions.iter().enumerate() {
            let (fq, fv, fvd) = (p.f_q[k], p.f_v[k], p.f_vd[k]);
            if j < nd && (fq != 0.0 || fv != 0.0 || fvd != 0.0) {
                let o = &mut out[i * np..(i + 1) * np];
                let (a, b, c) = (&w[j * np..], &dv[j * np..], &dvd[j * np..]);
                for t in 0..np {
                    o[t] += fq * a[t] + fv * b[t] + fvd * c[t];
                }
            }
        }
        // States: x_{n+1} = x_n + dx; xdot_{n+1} = d_w w_n + d_xd xdot_n at fixed dx.
        let (d_w, d_xd) = self.state_start_coefficients();
        let so = self.layout.state_offset();
        for (t, ds) in ds.iter().enumerate() {
            for (i, j, v) in p.entries(&p.f_x) {
                out[i * np + t] += v * ds.x[j - so];
            }
            for (i, j, v) in p.entries(&p.f_xd) {
                out[i * np + t] += v * (d_w * ds.w[j - so] + d_xd * ds.xdot[j - so]);
            }
        }
        (0..np)
            .map(|t| out.iter().skip(t).step_by(np).copied().collect())
            .collect()
    }

    /// `dR/ds_n` at `x` as sparse triplets (each position once), the columns in the flat
    /// order of a [`StateTangent`] ([`StateTangent::flat_mut`], [`StateTangent::flat_len`]
    /// of them). Built from the partial derivatives directly, in time linear in the size of
    /// the model: a start component of node `i` moves only the end of node `i` (and, through
    /// `K_zeta` of the stabilized form, the nodes whose rows it shares), so its column is
    /// `F_q w + F_v dv + F_vd dvd` over node `i`'s columns of the partials, with the move
    /// `(w, dv, dvd)` that [`StepFunction::start_jvp_many`] makes of a unit tangent; the
    /// states' columns are those of `F_x` and `F_xd`. The start multipliers do not enter.
    /// (`tests/derivatives`: against the products, which are against central differences.)
    pub fn start_jacobian(&self, x: &[f64], data: &mut crate::data::Data) -> Triplets {
        let p = self.partials(x, data);
        let relations = self.relations();
        let (n, nd) = (self.start.q.len(), self.layout.n_dofs);
        let n6 = 6 * n;
        // The end's moves per unit start component: (column, node moved, (w, dv, dvd)).
        let mut moves = Vec::with_capacity(24 * n + p.k_zeta.len());
        for i in 0..n {
            for (kind, c) in (0..4).flat_map(|kind| (0..6).map(move |c| (kind, c))) {
                let mut unit = [Vec6::zeros(); 4];
                unit[kind][c] = 1.0;
                let [dq, dv, dvdot, da] = &unit;
                let end = self.start_move(&p, &relations, i, &Vec6::zeros(), [dq, dv, dvdot, da]);
                moves.push((kind * n6 + 6 * i + c, i, end));
            }
        }
        for &(a, b, v) in &p.k_zeta {
            // `q_n` of the node of `b` moves the configuration increment of the node of `a`
            let (mut theta, zero) = (Vec6::zeros(), Vec6::zeros());
            theta[a % 6] = v;
            let end = self.start_move(&p, &relations, a / 6, &theta, [&zero; 4]);
            moves.push((b, a / 6, end));
        }
        // The partials' entries in each node's columns.
        let mut by_node = vec![Vec::new(); n];
        for (k, &(_, j)) in p.pattern.positions.iter().enumerate() {
            if j < nd {
                by_node[j / 6].push(k);
            }
        }
        let mut out = Triplets::new();
        for (column, i, [w, dv, dvd]) in moves {
            for &k in &by_node[i] {
                let (r, c) = (p.pattern.positions[k].0, p.pattern.positions[k].1 % 6);
                out.push((
                    r,
                    column,
                    p.f_q[k] * w[c] + p.f_v[k] * dv[c] + p.f_vd[k] * dvd[c],
                ));
            }
        }
        // States: x_{n+1} = x_n + dx; xdot_{n+1} = d_w w_n + d_xd xdot_n at fixed dx.
        let (d_w, d_xd) = self.state_start_coefficients();
        let (so, ns) = (self.layout.state_offset(), self.layout.n_states);
        let x0 = 4 * n6 + self.layout.n_rows;
        out.extend(p.entries(&p.f_x).map(|(i, j, v)| (i, x0 + j - so, v)));
        for (i, j, v) in p.entries(&p.f_xd) {
            out.push((i, x0 + ns + j - so, d_xd * v));
            out.push((i, x0 + 2 * ns + j - so, d_w * v));
        }
        merge_triplets(out)
    }

    /// `dR/dp` at `x` for the parameters `ids` of `params` as sparse triplets, column `k`
    /// for `ids[k]` ([`StepFunction::parameter_jvp`] with each unit vector).
    pub fn parameter_jacobian(
        &self,
        x: &[f64],
        params: &crate::model::parameters::Parameters,
        ids: &[crate::model::ParamId],
        data: &mut crate::data::Data,
    ) -> Triplets {
        let mut out = Triplets::new();
        let mut dp = vec![0.0; params.len()];
        for (k, id) in ids.iter().enumerate() {
            dp[id.0 as usize] = 1.0;
            push_column(&mut out, k, &self.parameter_jvp(x, params, &dp, data));
            dp[id.0 as usize] = 0.0;
        }
        out
    }

    /// Coefficients of `xdot_{n+1}` in `w_n` and `xdot_n` at fixed `dx = x_{n+1} - x_n`:
    /// `w_{n+1} = (dx - h (1 - gamma) w_n) / (h gamma)` into
    /// [`FirstOrderParameters::rate_from`].
    fn state_start_coefficients(&self) -> (f64, f64) {
        let f = &self.step.first;
        let dw1 = -(1.0 - f.gamma) / f.gamma;
        let d_w = ((1.0 - f.alpha_m) * dw1 + f.alpha_m) / (1.0 - f.alpha_f);
        (d_w, -f.alpha_f / (1.0 - f.alpha_f))
    }

    /// `(dR/ds_n)^T w` at `x`.
    pub fn start_vjp(&self, x: &[f64], w: &[f64], data: &mut crate::data::Data) -> StateTangent {
        let p = self.partials(x, data);
        let n = self.start.q.len();
        // F_q^T w, F_v^T w and F_vd^T w in one pass (the three share the node columns)
        let (mut gq, mut gv, mut gvd) = (
            vec![Vec6::zeros(); n],
            vec![Vec6::zeros(); n],
            vec![Vec6::zeros(); n],
        );
        // Node block by node block (every node column is in one).
        for &(k, node) in &p.pattern.blocks {
            let wi = w[p.pattern.positions[k].0];
            if wi != 0.0 {
                let at = |f: &[f64]| Vec6::from_column_slice(&f[k..k + 6]) * wi;
                gq[node] += at(&p.f_q);
                gv[node] += at(&p.f_v);
                gvd[node] += at(&p.f_vd);
            }
        }
        // The cotangents of the total increments and of the rates in the step's coordinates.
        let (tg, rates): (Vec<Vec6>, Vec<[Vec6; 3]>) = (0..n)
            .map(|i| p.node_move_transposed(i, &[gq[i], gv[i], gvd[i], Vec6::zeros()]))
            .unzip();
        let mut q: Vec<Vec6> = (0..n).map(|i| p.g[i].tr_mul(&gq[i])).collect();
        for &(i, j, v) in &p.k_zeta {
            q[j / 6][j % 6] += v * tg[i / 6][i % 6];
        }
        let commutator: Vec<(Vec6, Vec6)> = (0..n)
            .map(|i| self.commutator_vjp(i, &p.end.v[i], &tg[i]))
            .collect();
        let ns = self.layout.n_states;
        let so = self.layout.state_offset();
        let (d_w, d_xd) = self.state_start_coefficients();
        let (mut gx, mut gxd) = (vec![0.0; ns], vec![0.0; ns]);
        for (i, j, v) in p.entries(&p.f_x) {
            gx[j - so] += v * w[i];
        }
        for (i, j, v) in p.entries(&p.f_xd) {
            gxd[j - so] += v * w[i];
        }
        let (mut v, mut vdot, mut a) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        let relations = self.relations();
        for (i, &[x, y, _]) in rates.iter().enumerate() {
            let ([v_n, vd_n, a_n], _) = relations.transposed([x, y, Vec6::zeros()]);
            let bar = [v_n + commutator[i].0, vd_n, a_n + commutator[i].1];
            let [vi, vdi, ai] = p.start_in_chart_transposed(i, bar);
            v.push(vi);
            vdot.push(vdi);
            a.push(ai);
        }
        StateTangent {
            q,
            v,
            vdot,
            a,
            lambda: vec![0.0; self.layout.n_rows],
            x: gx,
            xdot: gxd.iter().map(|g| g * d_xd).collect(),
            w: gxd.iter().map(|g| g * d_w).collect(),
        }
    }

    /// `(dp_{n+1}/dp) dp` of the configuration update: `d(B(q_n; p)^T zeta)/dp dp` (6 per
    /// node) of the stabilized step, `None` outside it or when no joint parameter moves.
    fn stabilization_parameter_move(
        &self,
        x: &[f64],
        params: &crate::model::parameters::Parameters,
        dp: &[f64],
    ) -> Option<Vec<f64>> {
        if !self.layout.stabilized {
            return None;
        }
        let zeta = self.zeta_rows(x);
        let nd = self.layout.n_dofs;
        let (mut dtotal, mut dforce) = (vec![0.0; nd], vec![0.0; nd]);
        let mut moved = false;
        for (id, &d) in params.ids().zip(dp) {
            if d == 0.0 || !matches!(params.kind(id), crate::model::ParamKind::Joint(..)) {
                continue;
            }
            let (start_nodes, t) = (&self.start_nodes, self.start.t);
            crate::parameter_derivatives::constraint_force_derivative(
                self.model,
                params,
                id,
                start_nodes,
                t,
                &zeta,
                &mut dforce,
            );
            for (a, b) in dtotal.iter_mut().zip(&dforce) {
                *a += d * b;
            }
            moved = true;
        }
        moved.then_some(dtotal)
    }

    /// The tangent of the end of the step `ds_{n+1}` for changes `dx` of the unknowns, `ds`
    /// of the start and `dp` of the parameters (`params` with one entry per parameter, or
    /// `None`): the derivative of the relations of the module documentation,
    ///
    /// ```text
    /// dq_{n+1}    = G dq_n + T ((I + E) ddq + B(q_n)^T dzeta + K_zeta dq_n
    ///                            + d(B_n^T zeta)/dp dp + dc_n)
    /// dv_{n+1}    = c1 dv_n + c2 da_n + gamma' ddq
    /// dvdot_{n+1} = c3 dv_n + c4 da_n + c5 dvdot_n + beta' ddq
    /// da_{n+1}    = (ddq - h dv_n - (1/2 - beta) h^2 da_n) / (beta h^2)
    /// dlambda     = dmu / s
    /// dx_{n+1} = dx_n + ddx,  dw_{n+1} = (ddx - h (1 - gamma_1) dw_n) / (h gamma_1),
    /// dxdot_{n+1} = d_w dw_n + d_xd dxdot_n + c_x ddx
    /// ```
    ///
    /// with `G = Ad(exp(-total))`, `T = T(total)`, `K_zeta = d(B(q_n)^T zeta)/dq_n` (the
    /// terms in `zeta` in the stabilized form only), and `E` and `dc_n` of the bracket term
    /// of the configuration update (module documentation; 0 for Brüls-Cardona).
    pub fn end_jvp(
        &self,
        x: &[f64],
        dx: &[f64],
        ds: &StateTangent,
        dp: Option<(&crate::model::parameters::Parameters, &[f64])>,
        data: &mut crate::data::Data,
    ) -> StateTangent {
        let p = self.partials(x, data);
        let layout = self.layout;
        let n = layout.n_nodes;
        let mut dtotal = dx[..layout.n_dofs].to_vec();
        if layout.stabilized {
            let dzeta = &dx[layout.block(Block::Stabilization)];
            for (node, rows) in layout.node_rows.iter().enumerate() {
                for &(row, slot) in rows {
                    let z = dzeta[layout.row_unknown[row].expect("active row")];
                    for i in 0..6 {
                        dtotal[6 * node + i] += self.b_start[row][6 * slot + i] * z;
                    }
                }
            }
            for &(i, j, v) in &p.k_zeta {
                dtotal[i] += v * ds.q[j / 6][j % 6];
            }
            if let Some(moved) =
                dp.and_then(|(params, dp)| self.stabilization_parameter_move(x, params, dp))
            {
                dtotal.iter_mut().zip(&moved).for_each(|(a, b)| *a += b);
            }
        }
        let relations = self.relations();
        let h = self.step.h;
        let mut out = StateTangent::zeros_of(layout);
        for i in 0..n {
            let ddq = Vec6::from_column_slice(&dx[6 * i..6 * i + 6]);
            let mut dt = Vec6::from_column_slice(&dtotal[6 * i..6 * i + 6])
                + self.commutator_jvp(i, &p.end.v[i], &ds.v[i], &ds.a[i]);
            if let Some(e) = p.e.get(i) {
                dt += (e - Mat6::identity()) * ddq;
            }
            let start = p.start_in_chart(i, &ds.v[i], &ds.vdot[i], &ds.a[i]);
            let rates = relations.forward(start, &ddq);
            let [q, v, vdot, a] = p.node_move(i, &dt, &rates);
            out.q[i] = p.g[i] * ds.q[i] + q;
            (out.v[i], out.vdot[i], out.a[i]) = (v, vdot, a);
        }
        for (k, &row) in layout.active_rows.iter().enumerate() {
            out.lambda[row] = dx[layout.n_dofs + k] / self.step.scale;
        }
        let f = &self.step.first;
        let (d_w, d_xd) = self.state_start_coefficients();
        let so = layout.state_offset();
        for i in 0..layout.n_states {
            let d = dx[so + i];
            out.x[i] = ds.x[i] + d;
            out.w[i] = (d - h * (1.0 - f.gamma) * ds.w[i]) / (h * f.gamma);
            out.xdot[i] = d_w * ds.w[i] + d_xd * ds.xdot[i] + self.step.cx * d;
        }
        out
    }

    /// The transpose of [`StepFunction::end_jvp`]: for a cotangent `bar` of `s_{n+1}`, the
    /// cotangents of the unknowns (`n_unknowns`), of the start `s_n`, and, when `params` is
    /// given with the ids wanted, of those parameters (the stabilized form's
    /// `d(B(q_n; p)^T zeta)/dp`; one entry per parameter of the registry, or empty).
    pub fn end_vjp(
        &self,
        x: &[f64],
        bar: &StateTangent,
        params: Option<(
            &crate::model::parameters::Parameters,
            &[crate::model::ParamId],
        )>,
        data: &mut crate::data::Data,
    ) -> (Vec<f64>, StateTangent, Vec<f64>) {
        let p = self.partials(x, data);
        let layout = self.layout;
        let (n, nd) = (layout.n_nodes, layout.n_dofs);
        let relations = self.relations();
        let mut xbar = vec![0.0; layout.n_unknowns()];
        let mut start = StateTangent::zeros_of(layout);
        // The cotangent of the total increments, T^T qbar_{n+1} (and the rates' in the Lie
        // algebra updates).
        let mut tbar = vec![0.0; nd];
        for i in 0..n {
            let node = [bar.q[i], bar.v[i], bar.vdot[i], bar.a[i]];
            let (t, [xb, yb, a]) = p.node_move_transposed(i, &node);
            tbar[6 * i..6 * i + 6].copy_from_slice(t.as_slice());
            let moved = p.e.get(i).map_or(t, |e| e.tr_mul(&t));
            let ([v_n, vd_n, a_n], dq) = relations.transposed([xb, yb, a]);
            xbar[6 * i..6 * i + 6].copy_from_slice((moved + dq).as_slice());
            start.q[i] = p.g[i].tr_mul(&bar.q[i]);
            let (vbar, abar) = self.commutator_vjp(i, &p.end.v[i], &t);
            let in_chart = [v_n + vbar, vd_n, a_n + abar];
            [start.v[i], start.vdot[i], start.a[i]] = p.start_in_chart_transposed(i, in_chart);
        }
        let mut pbar = Vec::new();
        if layout.stabilized {
            for (node, rows) in layout.node_rows.iter().enumerate() {
                for &(row, slot) in rows {
                    let z = layout.zeta(layout.row_unknown[row].expect("active row"));
                    for i in 0..6 {
                        xbar[z] += self.b_start[row][6 * slot + i] * tbar[6 * node + i];
                    }
                }
            }
            for &(i, j, v) in &p.k_zeta {
                start.q[j / 6][j % 6] += v * tbar[i];
            }
            if let Some((params, ids)) = params {
                pbar = vec![0.0; params.len()];
                let mut unit = vec![0.0; params.len()];
                for &id in ids {
                    let k = id.0 as usize;
                    if !matches!(params.kind(id), crate::model::ParamKind::Joint(..)) {
                        continue;
                    }
                    unit[k] = 1.0;
                    if let Some(moved) = self.stabilization_parameter_move(x, params, &unit) {
                        pbar[k] = moved.iter().zip(&tbar).map(|(a, b)| a * b).sum();
                    }
                    unit[k] = 0.0;
                }
            }
        }
        for (k, &row) in layout.active_rows.iter().enumerate() {
            xbar[nd + k] += bar.lambda[row] / self.step.scale;
        }
        let f = &self.step.first;
        let (d_w, d_xd) = self.state_start_coefficients();
        let so = layout.state_offset();
        for i in 0..layout.n_states {
            let (bx, bw, bxd) = (bar.x[i], bar.w[i], bar.xdot[i]);
            xbar[so + i] = bx + bw / (self.step.h * f.gamma) + self.step.cx * bxd;
            start.x[i] = bx;
            start.w[i] = -bw * (1.0 - f.gamma) / f.gamma + d_w * bxd;
            start.xdot[i] = d_xd * bxd;
        }
        (xbar, start, pbar)
    }
}
