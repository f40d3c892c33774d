//! The Lie group generalized-alpha step as functions over explicit inputs.
//!
//! One step `n -> n+1` of size `h` (Brüls & Cardona 2010, Eqs. (40)-(44); Arnold & Brüls
//! 2007, Eq. (5); stabilized index 2: Arnold, Brüls & Cardona 2015, Sect. 3). Its unknowns
//! are the Newton vector `x = (dq, mu, zeta, dx)` of [`crate::data::Layout`]: the
//! configuration increments, the scaled multipliers `mu = s lambda_{n+1}` of the active rows,
//! in the stabilized form one `zeta` per active row, and the increments `dx` of the
//! elements' first-order states. Given the start
//! `s_n = (q_n, v_n, vdot_n, a_n, x_n, xdot_n, w_n)` the end of the step is
//!
//! ```text
//! q_{n+1}    = q_n exp(dq + B(q_n)^T zeta + c_n)   (B^T zeta: stabilized only; c_n below)
//! a_{n+1}    = (dq - h v_n - (1/2 - beta) h^2 a_n) / (beta h^2)
//! v_{n+1}    = v_n + (1 - gamma) h a_n + gamma h a_{n+1}
//! vdot_{n+1} = ((1 - alpha_m) a_{n+1} + alpha_m a_n - alpha_f vdot_n) / (1 - alpha_f)
//! x_{n+1}    = x_n + dx
//! w_{n+1}    = (dx - h (1 - gamma_1) w_n) / (h gamma_1)
//! xdot_{n+1} = ((1 - alpha_m1) w_{n+1} + alpha_m1 w_n - alpha_f1 xdot_n) / (1 - alpha_f1)
//! ```
//!
//! (affine in `dq` and `dx`, with `dv/ddq = gamma' = gamma/(beta h)`,
//! `dvdot/ddq = beta' = (1 - alpha_m)/((1 - alpha_f) beta h^2)` and
//! `dxdot/ddx = c_x = (1 - alpha_m1)/((1 - alpha_f1) gamma_1 h)`; the first-order parameters
//! of [`FirstOrderParameters`]), and the step residual is
//!
//! ```text
//! R(x; s_n, p, h) = [ s (r(q, v, vdot, x, xdot, t) + B(q)^T lambda) ]    s = 1/(beta' m)
//!                   [ Phi(q, t)                            ]
//!                   [ (B(q) v + Phi_t) / gamma'            ]    (stabilized only)
//!                   [ h e(q, v, vdot, x, xdot, t)          ]    (element states)
//! ```
//!
//! at `t_{n+1}` and the end values above, `m` the largest nodal mass.
//!
//! **Configuration update** ([`super::LieUpdate`]). Brüls & Cardona (2010, Eqs.
//! (40)-(44)) take `c_n = 0`. The exact flow of `q' = q tilde(v)` over one step is
//! `q(t_n) exp(Theta(h))` with `Theta' = dexp_{-Theta}^{-1} v` (`Theta' = v + 1/2 [Theta, v]
//! + ...`), so that, differentiating three times at `Theta = 0`,
//! `Theta(h) = h v + h^2/2 vdot + h^3/6 (vddot + 1/2 [v, vdot]) + O(h^4)`: the bracket is
//! the second term of the Magnus expansion (Iserles, Munthe-Kaas, Nørsett & Zanna 2000,
//! "Lie-group methods", Acta Numerica 9; its two-term truncation for a linearly
//! interpolated velocity is `h/2 (v_n + v_{n+1}) + h^2/12 [v_n, v_{n+1}]`), and the
//! Brüls-Cardona increment has no such term. (The error analysis of the Lie group scheme
//! is Arnold, Brüls & Cardona 2015, Numer. Math. 129; the expansion above is derived here.)
//! The `commutator` update adds
//!
//! ```text
//! c_n = sigma h^2 [v_n, v_{n+1}]       ([.,.] the algebra's bracket, flexmb_lie::Group::ad)
//! ```
//!
//! (`= sigma h^3 [v_n, vdot] + O(h^4)`): `sigma = 1/12` restores the bracket of the exact
//! flow; a larger `sigma` also cancels part of the scheme's own `h^3 vddot` defect where
//! `vddot` is nearly parallel to `[v, vdot]` (fast-spinning tops). Holzinger, Arnold &
//! Gerstmayr's modified kinematic relations (Exudyn's default Lie group integrator)
//! amount, at convergence, to a term of this form (`BENCHMARKS.md`, "Error constant:
//! variants compared"). The same term with `a_n` in place of `v_{n+1}/h` (a function of the
//! start only) was tried and loses stability for `rho_inf = 0.9`, like Exudyn's variant.
//! `c_n` moves with `dq` through `v_{n+1}`: `d total / d dq = I + E`,
//! `E = sigma h^2 gamma' ad(v_n)`, so the iteration matrix takes `T (I + E)` in place of `T`
//! on the increments' columns, and `dc_n = sigma h^2 (ad(v_n) dv_{n+1} - ad(v_{n+1}) dv_n)`
//! with `dv_{n+1}` from the start at fixed `dq`.
//!
//! **Lie algebra updates** (`lie_algebra`, `lie_algebra_r3xso3`; after Arnold, Cardona &
//! Brüls 2016, "A Lie algebra approach to Lie group time integration of constrained
//! systems", CISM Courses and Lectures 565, Springer; the chapter was not retrieved, so
//! what follows is this module's reading of its idea, derived here). The scheme's
//! relations above are applied to local coordinates `Theta` of the step,
//! `q(t) = q_n o C(Theta(t))`, `Theta(t_n) = 0`, a vector space where generalized-alpha is
//! the linear scheme: the relations' `dq` is `Theta_{n+1}` (plus `B^T zeta`), their `v`
//! and `vdot` are `Theta'_{n+1}` and `Theta''_{n+1}`, and the nodes' follow from the chart
//! ([`flexmb_lie::Chart`]: `C` the group's exponential for `lie_algebra`, R3xSO(3)'s for
//! `lie_algebra_r3xso3`, which on SE(3) reads the translation in the frame of `q_n`):
//!
//! ```text
//! v_{n+1}    = M(Theta) Theta'_{n+1}
//! vdot_{n+1} = M(Theta) Theta''_{n+1} + N(Theta, Theta'_{n+1})
//! ```
//!
//! (exponential chart: `M = T`, `N = (d/ds T(Theta + s X))|_0 X`,
//! [`flexmb_lie::Group::tangent_rate`]). At the start of a step `M(0) = I`, so
//! `Theta'_n = v_n` and `Theta''_n = vdot_n - N(0, v_n)` (`N(0, X) = 0` for the
//! exponential, `(-X_w x X_u, 0)` for R3xSO(3)'s chart on SE(3)). The algorithmic
//! accelerations live in the chart of their step; `a_{n+1}` is kept as
//! `M a_{n+1} + N(Theta, Theta'_{n+1})`, the map of a second derivative, and the next
//! step subtracts its `N(0, v_{n+1})` as it does from `vdot`: both charts read the same
//! `vdot` at `t_{n+1}`, so that `Theta''_new = M Theta''_old + N(Theta, X) - N(0, v)`
//! there, and `a` keeps its `O(h^2)` consistency with it. The predictor takes its
//! `vdot_{n+1}` to the chart, `Theta'' = M^-1 (vdot - N)` at the increment the scheme
//! gives for it (on SE(3) in R3xSO(3)'s chart, the translation part kept at its start
//! value: the body-frame translation acceleration turns with the body, the chart's does
//! not). Newton's node corrections are right-trivialized, `q o C(total) exp(dx)`
//! (`dq += M(total)^-1 dx`), so that the iteration matrix keeps `gamma'`, `beta'` and an
//! identity tangent operator: it omits the derivatives of `M` and `N` (a contraction of
//! order `h^2 |v|^2` on inertia terms and `beta h |v| / (2 gamma)` on damping for the
//! exponential chart, of order `h |v|` on SE(3) in R3xSO(3)'s), and its iterates are
//! accepted on measured rates. Measured (`BENCHMARKS.md`, "The Lie algebra update"): 7 to
//! 9 times less error on the R3xSO(3) heavy and asymmetric tops, as robust as
//! Brüls-Cardona; on SE(3) the exponential chart gains 1.6 to 4 times but a flexible
//! beam turning fast (the spin-up at `h = 0.01 s`, `rho_inf = 0.8`) grows an unstable
//! mode, through the translation-rotation coupling of `T`, while R3xSO(3)'s chart gives
//! the SE(3) tops the R3xSO(3) errors and runs the spin-up smoothly.
//!
//! The Newton iteration of [`super::dynamics`] builds the same relations incrementally
//! ([`predict`], [`correct`], [`finish`]); [`StepFunction`] evaluates them from `x`
//! directly, with the exact Jacobian `dR/dx` and the products of `dR/ds_n` and `dR/dp` with
//! vectors and transposed vectors: what a forward sensitivity, a discrete adjoint and a
//! transcription NLP call.

use super::generalized_alpha::{FirstOrderParameters, GaParameters};
use super::DynamicSettings;
use crate::assembly::{ConstraintRhs, Scaling};
use crate::data::{Block, Layout};
use crate::elements::{Coefficients, NodeState, Vec12};
use crate::joints::ConstraintKernel;
use crate::model::Model;
use crate::parallel::Threads;
use crate::state::State;
use flexmb_lie::{Chart, Group, Mat6, Vec6};
use std::cell::RefCell;
use std::sync::Arc;

/// The fixed numbers of one step: scheme, size, scaling and loading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Start {
    pub params: GaParameters,
    /// The first-order scheme of the element states.
    pub first: FirstOrderParameters,
    /// `d xdot / d x` of the states: [`FirstOrderParameters::rate_coefficient`].
    pub cx: f64,
    /// Step size \[s\].
    pub h: f64,
    /// `beta'`, `gamma'` of `h`.
    pub bp: f64,
    pub gp: f64,
    /// Largest nodal mass `m` \[kg\].
    pub mass: f64,
    /// Row scale `s = 1 / (beta' m)`.
    pub scale: f64,
    /// Factor on loads and gravity at `t_{n+1}`.
    pub load_factor: f64,
    /// Nodal viscous damping \[1/s\].
    pub nodal_damping: f64,
    /// The configuration update.
    pub lie_update: super::LieUpdate,
}

impl Start {
    /// The step to `t_new` of size `h`.
    pub fn new(
        params: GaParameters,
        h: f64,
        mass: f64,
        settings: &DynamicSettings,
        t_new: f64,
    ) -> Self {
        let bp = params.beta_prime(h);
        let gp = params.gamma_prime(h);
        let first = FirstOrderParameters::from_rho_inf(
            settings
                .scheme
                .spectral_radius_at_infinity(settings.rho_inf),
        );
        Self {
            params,
            first,
            cx: first.rate_coefficient(h),
            h,
            bp,
            gp,
            mass,
            scale: 0.0,
            load_factor: settings.load_factor_at(t_new),
            nodal_damping: settings.nodal_damping,
            lie_update: settings.lie_update,
        }
        .with_mass(mass)
    }

    /// The step with the row scale of largest nodal mass `mass`: the equilibrium rows times
    /// `1 / (beta' m)`, so that the mass block is O(1) whatever h and the units of mass,
    /// like the constraint block.
    pub fn with_mass(self, mass: f64) -> Self {
        Self {
            mass,
            scale: 1.0 / (self.bp * mass),
            ..self
        }
    }

    /// The weight `sigma h^2` of the configuration update's bracket term `c_n` (0 for the
    /// Brüls-Cardona update).
    pub fn commutator_weight(&self) -> f64 {
        match self.lie_update {
            super::LieUpdate::Commutator { sigma } => sigma * self.h * self.h,
            _ => 0.0,
        }
    }

    /// Whether `v` and `vdot` of the iterate are the local coordinates' rates `Theta'` and
    /// `Theta''` (the Lie algebra update), mapped to the nodes' by [`kinematics`] and at
    /// the end of the step by [`finish`].
    pub fn in_chart(&self) -> bool {
        self.lie_update.in_chart()
    }

    /// The local coordinates of the Lie algebra updates on `group` (`None` for the others).
    pub fn chart(&self, group: Group) -> Option<Chart> {
        use super::LieUpdate::{LieAlgebra, LieAlgebraR3xSO3};
        match (self.lie_update, group) {
            (LieAlgebraR3xSO3, Group::SE3) => Some(Chart::TranslationRotation),
            (LieAlgebra | LieAlgebraR3xSO3, _) => Some(Chart::Exponential(group)),
            _ => None,
        }
    }

    /// `I + E`, `E = sigma h^2 gamma' ad(v_n)`: how the total increment moves with `dq`
    /// (`None` for the Brüls-Cardona update, where it is the identity).
    pub fn increment_map(&self, group: Group, v_n: &Vec6) -> Option<Mat6> {
        let w = self.commutator_weight();
        (w != 0.0).then(|| Mat6::identity() + group.ad(v_n) * (w * self.gp))
    }

    /// The scaling of the step's iteration matrix `c_m M + c_c C_t + c_k K_t T` (divided by
    /// `beta' m`) with `-regularization` on the constraint block.
    pub fn scaling(&self, regularization: f64) -> Scaling {
        Scaling {
            row_scale: self.scale,
            coef: Coefficients {
                m: 1.0 / self.mass,
                c: self.gp * self.scale,
                k: self.scale,
                x: self.scale,
                xdot: self.scale * self.cx,
                y: self.scale,
            },
            constraint_rhs: ConstraintRhs::Position,
            load_factor: self.load_factor,
            regularization,
            velocity_scale: 1.0 / self.gp,
            nodal_damping: self.nodal_damping,
            state_scale: self.h,
        }
    }
}

/// Predictor: `vdot_{n+1} = vdot_n` (or its extrapolation from one or two earlier steps
/// when given, [`Extrapolation`]: a closer start saves Newton iterations; the solution does
/// not depend on it), `lambda_{n+1}` likewise, and the `v` and increment
/// that the scheme gives for them. Writes `state.v`, `state.vdot`, `state.lambda` (`state`
/// holds `s_n` on entry) and `dq`; the element states: `xdot_{n+1} = xdot_n` and the `x`
/// the first-order scheme gives for it (`state.x`, `state.xdot`).
///
/// In the Lie algebra updates (`chart` their local coordinates) the predicted `vdot_{n+1}`
/// is taken to the step's chart, `Theta'' = M^-1 (vdot - N)` at the increment and `Theta'`
/// that the scheme gives for it (module documentation).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn predict(
    p: &GaParameters,
    first: &FirstOrderParameters,
    h: f64,
    start: &State,
    extrapolate: Option<&Extrapolation>,
    chart: Option<Chart>,
    state: &mut State,
    dq: &mut Vec<f64>,
) {
    let n = start.q.len();
    dq.clear();
    dq.resize(6 * n, 0.0);
    for i in 0..n {
        let v0 = start.v[i];
        // `vdot_n` and `a_n` in the step's chart (themselves outside the Lie algebra updates)
        let (vd0c, a0) = chart_start(chart, start, i);
        let scheme = |vd1: Vec6| {
            let a1 =
                (vd0c * p.alpha_f + vd1 * (1.0 - p.alpha_f) - a0 * p.alpha_m) / (1.0 - p.alpha_m);
            let v1 = v0 + a0 * (h * (1.0 - p.gamma)) + a1 * (h * p.gamma);
            let inc = v0 * h + a0 * (h * h * (0.5 - p.beta)) + a1 * (h * h * p.beta);
            (v1, inc)
        };
        let vd0 = start.vdot[i];
        let mut vd1 = extrapolate.map_or(vd0, |e| {
            Extrapolation::at(&e.weights[0], vd0, |k| e.vdot[k][i])
        });
        let (mut v1, mut inc) = scheme(vd1);
        if let Some(chart) = chart {
            vd1 = chart.inverse_map(&inc) * (vd1 - chart.rate(&inc, &v1));
            if chart == Chart::TranslationRotation {
                // The body-frame translation acceleration turns with the body; the chart's,
                // the point's acceleration in the frame of `q_n`, does not: predicted
                // constant.
                vd1.fixed_rows_mut::<3>(0)
                    .copy_from(&vd0c.fixed_rows::<3>(0));
            }
            (v1, inc) = scheme(vd1);
        }
        state.vdot[i] = vd1;
        state.v[i] = v1;
        dq[6 * i..6 * i + 6].copy_from_slice(inc.as_slice());
    }
    if let Some(e) = extrapolate {
        for (r, l) in state.lambda.iter_mut().enumerate() {
            *l = Extrapolation::at(&e.weights[1], *l, |k| e.lambda[k][r]);
        }
    }
    for i in 0..start.x.len() {
        let w1 = first.rate(start.xdot[i], start.xdot[i], start.w[i]);
        state.xdot[i] = start.xdot[i];
        state.x[i] = start.x[i] + first.increment(h, start.w[i], w1);
    }
}

/// `Theta''_n` and `a_n` of node `i` in the step's chart: `vdot_n - N(0, v_n)` and
/// `a_n - N(0, v_n)` ([`Chart::rate`]; zero for the exponential chart); `vdot_n` and `a_n`
/// otherwise.
#[inline]
fn chart_start(chart: Option<Chart>, start: &State, i: usize) -> (Vec6, Vec6) {
    let (vd0, a0) = (start.vdot[i], start.a[i]);
    match chart {
        Some(c @ Chart::TranslationRotation) => {
            let n0 = c.rate(&Vec6::zeros(), &start.v[i]);
            (vd0 - n0, a0 - n0)
        }
        _ => (vd0, a0),
    }
}

/// Polynomial extrapolation of the accelerations and multipliers to the end of a step
/// from the start and one or two earlier points: `y_{n+1} = w_0 y_n + w_1 y_{n-1} +
/// w_2 y_{n-2}` (Lagrange weights at `t_n + h` through `t_n`, `t_n - h_1`,
/// `t_n - h_1 - h_2`).
pub struct Extrapolation<'a> {
    /// The weights of the accelerations and of the multipliers.
    pub weights: [[f64; 3]; 2],
    /// `vdot` at `t_{n-1}` and `t_{n-2}` (the second unused when its weight is 0).
    pub vdot: [&'a [Vec6]; 2],
    pub lambda: [&'a [f64]; 2],
}

impl Extrapolation<'_> {
    /// Linear through `t_n - h_1` (`h_2 = 0`) or quadratic through `t_n - h_1 - h_2` too.
    pub fn weights(h: f64, h1: f64, h2: f64) -> [f64; 3] {
        if h2 == 0.0 {
            let r = h / h1;
            return [1.0 + r, -r, 0.0];
        }
        let h12 = h1 + h2;
        [
            (h + h1) * (h + h12) / (h1 * h12),
            -h * (h + h12) / (h1 * h2),
            h * (h + h1) / (h12 * h2),
        ]
    }

    /// The value extrapolated with `weights` from `y_n` and the earlier points
    /// `earlier(k)` (the linear one as `y_n + r (y_n - y_{n-1})`, `r = h / h_1`, the
    /// rounding of the linear predictor before the quadratic one existed).
    #[inline]
    pub(crate) fn at<T>(weights: &[f64; 3], y_n: T, earlier: impl Fn(usize) -> T) -> T
    where
        T: Copy
            + std::ops::Mul<f64, Output = T>
            + std::ops::Add<Output = T>
            + std::ops::Sub<Output = T>,
    {
        let [w0, w1, w2] = *weights;
        if w2 == 0.0 {
            y_n + (y_n - earlier(0)) * -w1
        } else {
            y_n * w0 + earlier(0) * w1 + earlier(1) * w2
        }
    }
}

/// The Newton vector `x = (dq, mu, zeta, dx)` of `layout` from the increments, the
/// multipliers (`n_rows`, unscaled: `mu = s lambda` of the active rows), the stabilization
/// unknowns (`n_active`, or empty for zeros; ignored outside the stabilized formulation) and
/// the element states at both ends of the step (`dx = x_{n+1} - x_n`).
pub fn pack_unknowns(
    layout: &Layout,
    scale: f64,
    (dq, lambda, zeta): (&[f64], &[f64], &[f64]),
    (x_n, x_1): (&[f64], &[f64]),
    x: &mut Vec<f64>,
) {
    x.clear();
    x.extend_from_slice(dq);
    x.extend(layout.active_rows.iter().map(|&r| scale * lambda[r]));
    if layout.stabilized {
        x.extend_from_slice(zeta);
        x.resize(layout.state_offset(), 0.0);
    }
    x.extend(x_1.iter().zip(x_n).map(|(b, a)| b - a));
}

/// `dq + B(q_n)^T zeta` into `total` in the stabilized formulation, `dq` otherwise.
#[inline]
pub fn total_increments(
    layout: &Layout,
    dq: &[f64],
    zeta: &[f64],
    b_start: &[Vec12],
    total: &mut Vec<f64>,
) {
    total.clear();
    total.extend_from_slice(dq);
    if layout.stabilized {
        for (n, rows) in layout.node_rows.iter().enumerate() {
            for &(row, slot) in rows {
                let z = zeta[layout.row_unknown[row].expect("active row")];
                for i in 0..6 {
                    total[6 * n + i] += b_start[row][6 * slot + i] * z;
                }
            }
        }
    }
}

/// Adds the configuration update's bracket term `c_n = sigma h^2 [v_n, v_{n+1}]` of each
/// node to `total` (module documentation; nothing for the Brüls-Cardona update); `v_1`
/// holds `v_{n+1}`.
#[inline]
pub fn commutator_correction(
    step: &Start,
    group: Group,
    start: &State,
    v_1: &[Vec6],
    total: &mut [f64],
) {
    let c = step.commutator_weight();
    if c == 0.0 {
        return;
    }
    for (i, (v, v1)) in start.v.iter().zip(v_1).enumerate() {
        let d = group.ad(v) * v1 * c;
        for k in 0..6 {
            total[6 * i + k] += d[k];
        }
    }
}

/// Node kinematics of the iterate: `q = q_n exp(total)`, `v` and `vdot` from `state` and,
/// when `tangents`, the tangent operators `T(total)` (otherwise left as they are); node by
/// node on `threads`.
/// In the Lie algebra updates `state` holds `Theta'` and `Theta''`, and the nodes take
/// `q = q_n o C(total)`, `v = M Theta'` and `vdot = M Theta'' + N` ([`Start::chart`]).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn kinematics(
    step: &Start,
    group: Group,
    start: &State,
    state: &State,
    total: &[f64],
    tangents: bool,
    nodes: &mut [NodeState],
    threads: &Threads,
) {
    let chart = step.chart(group);
    threads.for_each(nodes, |i, node| {
        let inc = Vec6::from_column_slice(&total[6 * i..6 * i + 6]);
        if let Some(chart) = chart {
            // The corrections are right-trivialized (`q exp(total) exp(dx)`, [`correct`]):
            // the tangent operator of the iteration matrix is the identity.
            let m = chart.map(&inc);
            node.q = chart.point(&start.q[i], &inc);
            node.v = m * state.v[i];
            node.vdot = m * state.vdot[i] + chart.rate(&inc, &state.v[i]);
            if tangents {
                node.t = Mat6::identity();
            }
            return;
        }
        node.q = group.integrate(&start.q[i], &inc);
        node.v = state.v[i];
        node.vdot = state.vdot[i];
        if tangents {
            node.t = group.tangent(&inc);
        }
    });
}

/// Applies a Newton correction `dx`: `dq += dx`, `v += gamma' dx`, `vdot += beta' dx`,
/// `lambda += dmu / s`, `zeta += dzeta` in the stabilized formulation, and on the element
/// states `x += dx`, `xdot += c_x dx`. In the Lie algebra updates the node corrections are
/// right-trivialized, `q o C(total) exp(dx)`: `dq` moves by `M(total)^-1 dx` and `v`,
/// `vdot` (there `Theta'`, `Theta''`) with it.
#[inline]
pub fn correct(
    layout: &Layout,
    dx: &[f64],
    (start, group, total): (&Start, Group, &[f64]),
    dq: &mut [f64],
    zeta: &mut [f64],
    state: &mut State,
) {
    let chart = start.chart(group);
    let nd = layout.n_dofs;
    if layout.stabilized {
        let na = layout.n_active;
        for (z, d) in zeta.iter_mut().zip(&dx[nd + na..]) {
            *z += d;
        }
    }
    for i in 0..layout.n_nodes {
        let mut d = Vec6::from_column_slice(&dx[6 * i..6 * i + 6]);
        if let Some(chart) = chart {
            d = chart.inverse_map(&Vec6::from_column_slice(&total[6 * i..6 * i + 6])) * d;
        }
        for k in 0..6 {
            dq[6 * i + k] += d[k];
        }
        state.v[i] += d * start.gp;
        state.vdot[i] += d * start.bp;
    }
    for (row, slot) in layout.row_unknown.iter().enumerate() {
        if let Some(k) = slot {
            state.lambda[row] += dx[nd + k] / start.scale;
        }
    }
    let dx_states = &dx[layout.block(Block::States)];
    for (i, d) in dx_states.iter().enumerate() {
        state.x[i] += d;
        state.xdot[i] += start.cx * d;
    }
}

/// End of the step: `q_{n+1} = q_n exp(total)` (re-orthonormalized), the algorithmic
/// acceleration `a_{n+1} = (alpha_f vdot_n + (1 - alpha_f) vdot_{n+1} - alpha_m a_n) /
/// (1 - alpha_m)` and the states' algorithmic rates `w_{n+1}` likewise. In the Lie algebra
/// updates `q_{n+1} = q_n o C(total)`, and `v`, `vdot` and `a` leave the chart
/// (`M X`, `M Theta'' + N`, `M a + N`; module documentation).
#[inline]
pub fn finish(
    step: &Start,
    group: Group,
    start: &State,
    total: &[f64],
    state: &mut State,
    threads: &Threads,
) {
    let p = &step.params;
    for i in 0..start.x.len() {
        state.w[i] = step.first.rate(start.xdot[i], state.xdot[i], start.w[i]);
    }
    let chart = step.chart(group);
    threads.for_each(&mut state.q, |i, q| {
        let inc = Vec6::from_column_slice(&total[6 * i..6 * i + 6]);
        *q = match chart {
            Some(chart) => chart.point(&start.q[i], &inc),
            None => group.integrate(&start.q[i], &inc),
        };
        q.orthonormalize();
    });
    for i in 0..start.q.len() {
        let (vd0, a0) = chart_start(chart, start, i);
        state.a[i] = (vd0 * p.alpha_f + state.vdot[i] * (1.0 - p.alpha_f) - a0 * p.alpha_m)
            / (1.0 - p.alpha_m);
    }
    if let Some(chart) = chart {
        // From the step's chart to the nodes' velocities and the next step's chart: with
        // `X = Theta'_{n+1}` and `N = N(Theta, X)`, `v = M X`, `vdot = M Theta'' + N`, and
        // `a` as a second derivative, `M a + N` (module documentation).
        for i in 0..start.q.len() {
            let inc = Vec6::from_column_slice(&total[6 * i..6 * i + 6]);
            let m = chart.map(&inc);
            let n = chart.rate(&inc, &state.v[i]);
            state.v[i] = m * state.v[i];
            state.vdot[i] = m * state.vdot[i] + n;
            state.a[i] = m * state.a[i] + n;
        }
    }
}

/// A tangent (or, for the transposed products, a cotangent) of a state `s`:
/// right-trivialized perturbations of `q` (`q exp(q)`) and changes of `v`, `vdot`, `a`, one
/// vector of 6 per node each, of the multipliers `lambda` (one per constraint row; they do
/// not enter the step residual, criteria read them), and of the element states `x`, their
/// rates `xdot` and algorithmic rates `w`, one per state each.
#[derive(Clone, Debug, PartialEq)]
pub struct StateTangent {
    pub q: Vec<Vec6>,
    pub v: Vec<Vec6>,
    pub vdot: Vec<Vec6>,
    pub a: Vec<Vec6>,
    pub lambda: Vec<f64>,
    pub x: Vec<f64>,
    pub xdot: Vec<f64>,
    pub w: Vec<f64>,
}

impl StateTangent {
    pub fn zeros(n_nodes: usize, n_rows: usize, n_states: usize) -> Self {
        let z = vec![Vec6::zeros(); n_nodes];
        let zs = vec![0.0; n_states];
        Self {
            q: z.clone(),
            v: z.clone(),
            vdot: z.clone(),
            a: z,
            lambda: vec![0.0; n_rows],
            x: zs.clone(),
            xdot: zs.clone(),
            w: zs,
        }
    }

    /// The zero tangent of the states of `layout`.
    pub fn zeros_of(layout: &Layout) -> Self {
        Self::zeros(layout.n_nodes, layout.n_rows, layout.n_states)
    }

    /// Euclidean inner product of the components.
    pub fn dot(&self, other: &Self) -> f64 {
        let d = |a: &[Vec6], b: &[Vec6]| a.iter().zip(b).map(|(x, y)| x.dot(y)).sum::<f64>();
        let s = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        d(&self.q, &other.q)
            + d(&self.v, &other.v)
            + d(&self.vdot, &other.vdot)
            + d(&self.a, &other.a)
            + s(&self.lambda, &other.lambda)
            + s(&self.x, &other.x)
            + s(&self.xdot, &other.xdot)
            + s(&self.w, &other.w)
    }

    /// `self += c other`.
    pub fn add_scaled(&mut self, c: f64, other: &Self) {
        let d = |a: &mut [Vec6], b: &[Vec6]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y * c);
        let s = |a: &mut [f64], b: &[f64]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y * c);
        d(&mut self.q, &other.q);
        d(&mut self.v, &other.v);
        d(&mut self.vdot, &other.vdot);
        d(&mut self.a, &other.a);
        s(&mut self.lambda, &other.lambda);
        s(&mut self.x, &other.x);
        s(&mut self.xdot, &other.xdot);
        s(&mut self.w, &other.w);
    }
}

/// Sparse matrix entries `(row, column, value)`; duplicates are summed.
pub type Triplets = Vec<(usize, usize, f64)>;

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
    /// Tangent operators `T(total)` of the nodes' increments.
    t: Vec<Mat6>,
    /// `I + E`: how the total increments move with `dq` (module documentation; empty for
    /// the Brüls-Cardona update).
    e: Vec<Mat6>,
    /// Transports `G = Ad(exp(-total))`: `q_n exp(d) exp(total) = q_{n+1} exp(G d)`.
    g: Vec<Mat6>,
    /// The end of the step and its node kinematics (`T = I`): where the parameter
    /// derivatives are taken.
    end: State,
    nodes: Vec<NodeState>,
    /// `K_zeta = d(B(q_n)^T zeta)/dq_n` (stabilized form; empty otherwise).
    k_zeta: Triplets,
}

impl Partials {
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

/// `out` as `n` zeros, its storage reused.
fn zeroed(out: &mut Vec<f64>, n: usize) {
    out.clear();
    out.resize(n, 0.0);
}

/// The positions of the exact step Jacobian of one layout, sorted by row then column
/// without repeats: the iteration matrix's pattern ([`crate::data::Data::pattern`], whose repeated
/// positions are summed) with every node block of a row complete (six columns), plus, in
/// the stabilized form, the columns of `zeta` that `F_q T B(q_n)^T` fills. Built once per
/// [`crate::data::Data`] and kept there: the values of every step's Jacobian go on these
/// positions, so a solver's symbolic analysis is done once.
#[derive(Debug)]
pub struct JacobianPattern {
    /// Unknowns (rows and columns).
    pub n: usize,
    /// `(row, column)`.
    pub positions: Vec<(usize, usize)>,
    /// Positions of the first of the six entries of each node block `(row, 6 n..6 n + 6)`,
    /// with the node.
    blocks: Vec<(usize, usize)>,
    /// Stabilized form: `(block, constraint row, slot, position)` for every block of node
    /// `n` and every active row acting on `n`: where `F_q T B(q_n)^T` puts its entries.
    zeta: Vec<(usize, usize, usize, usize)>,
    /// The layout's groups of unknowns, for the block LU ([`Layout::groups`]).
    pub groups: crate::linear::Groups,
    /// Where each entry of the iteration matrix's pattern goes in each partial derivative
    /// ([`Selection`]): a position, or [`crate::assembly::Selected::NONE`].
    selections: [Vec<u32>; Selection::COUNT],
    /// Positions in the velocity-level rows (stabilized form), which `F_v` divides by
    /// `gamma'`.
    velocity_positions: Vec<u32>,
}

/// The partial derivatives of [`Partials`] taken from an assembly of the iteration matrix,
/// each a selection of its entries by row and column.
#[derive(Clone, Copy)]
enum Selection {
    /// `F_q`: position-level rows (and the element states') against the configuration.
    Configuration,
    /// `F_mu`: the equilibrium rows (and the element states') against the multipliers.
    Multipliers,
    /// `F_v`: every row but the position-level ones against the velocities.
    Velocities,
    /// `F_vd`: equilibrium and element-state rows against the accelerations.
    Accelerations,
    /// `F_x`, `F_xd`: every row against the element states.
    States,
}

impl Selection {
    const COUNT: usize = 5;
    const ALL: [Selection; Self::COUNT] = [
        Selection::Configuration,
        Selection::Multipliers,
        Selection::Velocities,
        Selection::Accelerations,
        Selection::States,
    ];

    /// Whether entry `(i, j)` of the iteration matrix of `layout` belongs to this partial.
    fn takes(self, layout: &Layout, i: usize, j: usize) -> bool {
        let (nd, na, so) = (layout.n_dofs, layout.n_active, layout.state_offset());
        match self {
            Selection::Configuration => j < nd && (i < nd + na || i >= so),
            Selection::Multipliers => (i < nd || i >= so) && (nd..nd + na).contains(&j),
            Selection::Velocities => j < nd && (i < nd || i >= nd + na),
            Selection::Accelerations => (i < nd || i >= so) && j < nd,
            Selection::States => j >= so,
        }
    }
}

impl JacobianPattern {
    fn new(layout: &Layout, pattern: &[(usize, usize)]) -> Self {
        let nd = layout.n_dofs;
        let mut positions: Vec<(usize, usize)> = Vec::with_capacity(pattern.len());
        for &(i, j) in pattern {
            if j < nd {
                positions.extend((0..6).map(|c| (i, 6 * (j / 6) + c)));
            } else {
                positions.push((i, j));
            }
        }
        if layout.stabilized {
            let nodes: Vec<(usize, usize)> =
                positions.iter().filter(|p| p.1 < nd).copied().collect();
            for (i, j) in nodes {
                for &(row, _) in &layout.node_rows[j / 6] {
                    positions.push((i, layout.zeta(layout.row_unknown[row].expect("active row"))));
                }
            }
        }
        positions.sort_unstable();
        positions.dedup();
        let find = |p: &(usize, usize)| {
            positions
                .binary_search(p)
                .expect("a position of the pattern")
        };
        let of_pattern: Vec<usize> = pattern.iter().map(find).collect();
        let mut blocks = Vec::new();
        let mut zeta = Vec::new();
        for (k, &(i, j)) in positions.iter().enumerate() {
            if j < nd && j % 6 == 0 {
                let n = j / 6;
                blocks.push((k, n));
                if layout.stabilized {
                    for &(row, slot) in &layout.node_rows[n] {
                        let z = layout.zeta(layout.row_unknown[row].expect("active row"));
                        zeta.push((k, row, slot, find(&(i, z))));
                    }
                }
            }
        }
        let selections = Selection::ALL.map(|sel| {
            (pattern.iter().zip(&of_pattern))
                .map(|(&(i, j), &k)| match sel.takes(layout, i, j) {
                    true => k as u32,
                    false => crate::assembly::Selected::NONE,
                })
                .collect()
        });
        let so = layout.state_offset();
        let velocity_positions = (positions.iter().enumerate())
            .filter(|(_, &(i, _))| i >= nd + layout.n_active && i < so)
            .map(|(k, _)| k as u32)
            .collect();
        Self {
            n: layout.n_unknowns(),
            positions,
            blocks,
            zeta,
            groups: layout.groups(),
            selections,
            velocity_positions,
        }
    }

    /// The entries of `values` (on the iteration matrix's pattern) that `selection` takes,
    /// summed on the Jacobian's positions, into `out` (its storage reused).
    fn select_into(&self, selection: Selection, values: &[f64], out: &mut Vec<f64>) {
        use crate::assembly::Sink;
        zeroed(out, self.positions.len());
        let mut sink = self.sink(selection, out);
        for &v in values {
            sink.entry(0, 0, v);
        }
    }

    /// A sink of the iteration matrix's entries that sums those of `selection` into `out`
    /// (on these positions).
    fn sink<'s>(
        &'s self,
        selection: Selection,
        out: &'s mut [f64],
    ) -> crate::assembly::Selected<'s> {
        crate::assembly::Selected {
            dest: &self.selections[selection as usize],
            out,
            pos: 0,
        }
    }

    /// The position of `(row, column)`.
    fn position(&self, at: (usize, usize)) -> usize {
        self.positions
            .binary_search(&at)
            .expect("a position of the step Jacobian")
    }
}

impl<'a> StepFunction<'a> {
    /// The step of size `h` from `start` (the state `s_n`, with its time `t_n`) of a
    /// simulation with `settings` and the unknowns of `layout`.
    ///
    /// # Panics
    /// With the Lie algebra updates ([`super::LieUpdate::in_chart`]), which this function
    /// does not implement (the sensitivity analyses refuse them with an error first).
    pub fn new(
        model: &'a Model,
        layout: &'a Layout,
        start: &'a State,
        settings: &DynamicSettings,
        h: f64,
    ) -> Self {
        assert!(
            !settings.lie_update.in_chart(),
            "StepFunction implements the bruls_cardona and commutator updates only"
        );
        let params = settings.scheme.parameters(settings.rho_inf);
        let step = Start::new(
            params,
            h,
            super::initial::mass_scale(model),
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
            None,
            &mut state,
            &mut dq,
        );
        let mut x = Vec::new();
        let step = (&dq[..], &self.start.lambda[..], &[][..]);
        let states = (&self.start.x[..], &state.x[..]);
        pack_unknowns(self.layout, self.step.scale, step, states, &mut x);
        x
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
        let p = &self.step.params;
        let h = self.step.h;
        let s0 = self.start;
        let mut end = s0.clone();
        end.t = s0.t + h;
        for i in 0..s0.q.len() {
            let dq = Vec6::from_column_slice(&x[6 * i..6 * i + 6]);
            let a1 = (dq - s0.v[i] * h - s0.a[i] * ((0.5 - p.beta) * h * h)) / (p.beta * h * h);
            end.v[i] = s0.v[i] + s0.a[i] * ((1.0 - p.gamma) * h) + a1 * (p.gamma * h);
            end.vdot[i] = (a1 * (1.0 - p.alpha_m) + s0.a[i] * p.alpha_m - s0.vdot[i] * p.alpha_f)
                / (1.0 - p.alpha_f);
            end.a[i] = a1;
        }
        let total = self.total(x, &end.v);
        for (i, q) in end.q.iter_mut().enumerate() {
            *q = self
                .model
                .group
                .integrate(&s0.q[i], &Vec6::from_column_slice(&total[6 * i..6 * i + 6]));
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
        (end, total)
    }

    /// Node kinematics at the end of the step, with the tangent operators `T(total)`.
    fn end_nodes(&self, x: &[f64]) -> (State, Vec<NodeState>, Vec<f64>) {
        let (end, total) = self.end_state_and_total(x);
        let mut nodes = self.start_nodes.clone();
        let sequential = Threads::sequential();
        kinematics(
            &self.step,
            self.model.group,
            self.start,
            &end,
            &total,
            true,
            &mut nodes,
            &sequential,
        );
        (end, nodes, total)
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
        }
    }

    /// The step residual `R(x; s_n, p, h)` (`n_unknowns`).
    pub fn residual(&self, x: &[f64], data: &mut crate::data::Data) -> Vec<f64> {
        let (end, nodes, _) = self.end_nodes(x);
        self.assemble(data, &nodes, &end, &self.step.scaling(0.0), false);
        data.residual.clone()
    }

    /// The partial derivatives at the end of the step (see [`Partials`]), kept for the next
    /// call at the same `x` with the same [`StepFunction::step`].
    fn partials(&self, x: &[f64], data: &mut crate::data::Data) -> Arc<Partials> {
        if let Some(c) = &*self.cache.borrow() {
            if c.x.as_slice() == x && c.step == self.step {
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
        let (end, mut nodes, total) = self.end_nodes(x);
        let group = self.model.group;
        let t: Vec<Mat6> = nodes.iter().map(|n| n.t).collect();
        let g: Vec<Mat6> = (0..nodes.len())
            .map(|i| group.adjoint(&group.exp(&-Vec6::from_column_slice(&total[6 * i..6 * i + 6]))))
            .collect();
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
            end,
            nodes,
            k_zeta: self.start_constraint_stiffness(x),
        }
    }

    /// The step Jacobian's positions for `data`'s layout, built on first use and kept in
    /// `data`.
    fn pattern(&self, data: &mut crate::data::Data) -> Arc<JacobianPattern> {
        let (layout, positions) = (self.layout, &data.pattern);
        Arc::clone(
            data.derived
                .get_or_insert_with(|| Arc::new(JacobianPattern::new(layout, positions))),
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
        out.clear();
        out.extend(
            (p.f_v.iter().zip(&p.f_vd).zip(&p.f_mu)).map(|((v, vd), mu)| v * gp + vd * bp + mu),
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
        // The increments' columns take F_q T (I + E) (module documentation).
        for &(k, n) in &pattern.blocks {
            let row = p.t[n].tr_mul(&Vec6::from_column_slice(&p.f_q[k..k + 6]));
            let columns = p.e.get(n).map_or(row, |e| e.tr_mul(&row));
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
        &self,
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
            let p = self.partials(x, data);
            for (i, j, v) in p.entries(&p.f_q) {
                let (n, c) = (j / 6, j % 6);
                let moved = p.t[n]
                    .row(c)
                    .transpose()
                    .dot(&Vec6::from_column_slice(&dtotal[6 * n..6 * n + 6]));
                out[i] += v * moved;
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
            // u = (F_q T)^T w, then u . d(B(q_n)^T zeta)/dp for the joint parameters.
            let mut g = vec![0.0; nd];
            for (i, j, v) in partials.entries(&partials.f_q) {
                g[j] += v * w[i];
            }
            let u: Vec<f64> = (0..nd / 6)
                .flat_map(|n| {
                    let t = partials.t[n].transpose();
                    let un = t * Vec6::from_column_slice(&g[6 * n..6 * n + 6]);
                    un.iter().copied().collect::<Vec<_>>()
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
        let [c1, c2, c3, c4, c5] = self.start_coefficients();
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
                let dc = self.commutator_jvp(i, &p.end.v[i], &ds.v[i], &ds.a[i]);
                let wi = p.g[i] * ds.q[i] + p.t[i] * (kz[i] + dc);
                let dvi = ds.v[i] * c1 + ds.a[i] * c2;
                let dvdi = ds.v[i] * c3 + ds.a[i] * c4 + ds.vdot[i] * c5;
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
        let [c1, c2, c3, c4, c5] = self.start_coefficients();
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
        let tg: Vec<Vec6> = (0..n).map(|i| p.t[i].tr_mul(&gq[i])).collect();
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
        StateTangent {
            q,
            v: (0..n)
                .map(|i| gv[i] * c1 + gvd[i] * c3 + commutator[i].0)
                .collect(),
            vdot: (0..n).map(|i| gvd[i] * c5).collect(),
            a: (0..n)
                .map(|i| gv[i] * c2 + gvd[i] * c4 + commutator[i].1)
                .collect(),
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
        let [c1, c2, c3, c4, c5] = self.start_coefficients();
        let ga = &self.step.params;
        let h = self.step.h;
        let mut out = StateTangent::zeros_of(layout);
        for i in 0..n {
            let ddq = Vec6::from_column_slice(&dx[6 * i..6 * i + 6]);
            let mut dt = Vec6::from_column_slice(&dtotal[6 * i..6 * i + 6])
                + self.commutator_jvp(i, &p.end.v[i], &ds.v[i], &ds.a[i]);
            if let Some(e) = p.e.get(i) {
                dt += (e - Mat6::identity()) * ddq;
            }
            out.q[i] = p.g[i] * ds.q[i] + p.t[i] * dt;
            out.v[i] = ds.v[i] * c1 + ds.a[i] * c2 + ddq * self.step.gp;
            out.vdot[i] = ds.v[i] * c3 + ds.a[i] * c4 + ds.vdot[i] * c5 + ddq * self.step.bp;
            out.a[i] =
                (ddq - ds.v[i] * h - ds.a[i] * ((0.5 - ga.beta) * h * h)) / (ga.beta * h * h);
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
        let [c1, c2, c3, c4, c5] = self.start_coefficients();
        let ga = &self.step.params;
        let h = self.step.h;
        let bh2 = ga.beta * h * h;
        let mut xbar = vec![0.0; layout.n_unknowns()];
        let mut start = StateTangent::zeros_of(layout);
        // The cotangent of the total increments, T^T qbar_{n+1}.
        let mut tbar = vec![0.0; nd];
        for i in 0..n {
            let t = p.t[i].tr_mul(&bar.q[i]);
            tbar[6 * i..6 * i + 6].copy_from_slice(t.as_slice());
            let a = bar.a[i];
            let moved = p.e.get(i).map_or(t, |e| e.tr_mul(&t));
            let dq = moved + bar.v[i] * self.step.gp + bar.vdot[i] * self.step.bp + a / bh2;
            xbar[6 * i..6 * i + 6].copy_from_slice(dq.as_slice());
            start.q[i] = p.g[i].tr_mul(&bar.q[i]);
            start.v[i] = bar.v[i] * c1 + bar.vdot[i] * c3 - a * (h / bh2);
            start.a[i] = bar.v[i] * c2 + bar.vdot[i] * c4 - a * ((0.5 - ga.beta) / ga.beta);
            start.vdot[i] = bar.vdot[i] * c5;
            let (vbar, abar) = self.commutator_vjp(i, &p.end.v[i], &t);
            start.v[i] += vbar;
            start.a[i] += abar;
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
            xbar[so + i] = bx + bw / (h * f.gamma) + self.step.cx * bxd;
            start.x[i] = bx;
            start.w[i] = -bw * (1.0 - f.gamma) / f.gamma + d_w * bxd;
            start.xdot[i] = d_xd * bxd;
        }
        (xbar, start, pbar)
    }
}
