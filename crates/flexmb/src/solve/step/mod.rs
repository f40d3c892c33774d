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
//! transcription NLP call. For every configuration update: in the Lie algebra updates the
//! Jacobian has, besides the iteration matrix's terms, the derivatives of `M` and `N` with
//! respect to `Theta` (`d(M X)/dTheta`, `d(M Theta'' + N)/dTheta`, `dN/dX`), the start in
//! the chart moves with `v_n` through `N(0, v_n)`, and a start perturbation `q_n exp(d)` is
//! carried by `Ad(C(Theta)^-1)` ([`flexmb_lie::Chart::jacobians`],
//! [`flexmb_lie::Chart::transport`]).
//!
//! As sparse matrices (triplets): `dR/dx` on the positions of a pattern built once per
//! layout ([`StepFunction::jacobian_values`]), `dR/du` of the model's inputs
//! ([`StepFunction::input_jacobian`]), `dR/ds_n` ([`StepFunction::start_jacobian`], columns in
//! the flat order of a [`StateTangent`]) and `dR/dp` ([`StepFunction::parameter_jacobian`]).
//! `dR/ds_n` is built from the partial derivatives directly, in time linear in the size of
//! the model (a start component moves the end of its own node alone, and through `K_zeta`
//! those it shares constraint rows with), and tested against the products; `dR/dp` is the
//! products with unit vectors (one per parameter asked for).

//! The module's files: the scheme's relations here ([`Start`], [`predict`], [`correct`],
//! [`finish`], [`StateTangent`]); the configuration updates in [`updates`]; the step as
//! a function in [`function`]; the positions of its exact Jacobian in [`pattern`].

pub mod function;
pub mod pattern;
pub mod updates;

use super::generalized_alpha::{FirstOrderParameters, GaParameters};
use super::DynamicSettings;
use crate::assembly::{ConstraintRhs, Scaling};
use crate::data::{Block, Layout};
use crate::elements::Coefficients;
use crate::parallel::Threads;
use crate::state::State;
use flexmb_lie::{Chart, Group, Mat6, Vec6};

pub use function::{KeptPartials, StepFunction, Triplets};
pub use pattern::JacobianPattern;
pub use updates::{commutator_correction, kinematics, total_increments};

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

    /// The number of components of a tangent of the states of `layout`: the columns of
    /// `dR/ds_n` ([`StateTangent::flat_mut`] gives their order).
    pub fn flat_len(layout: &Layout) -> usize {
        24 * layout.n_nodes + layout.n_rows + 3 * layout.n_states
    }

    /// Component `j` of the flat order: `q`, `v`, `vdot`, `a` (6 per node each, node after
    /// node), then `lambda`, `x`, `xdot`, `w`.
    pub fn flat_mut(&mut self, j: usize) -> &mut f64 {
        let n6 = 6 * self.q.len();
        if j < 4 * n6 {
            let v = match j / n6 {
                0 => &mut self.q,
                1 => &mut self.v,
                2 => &mut self.vdot,
                _ => &mut self.a,
            };
            let i = j % n6;
            return &mut v[i / 6][i % 6];
        }
        let (nr, ns) = (self.lambda.len(), self.x.len());
        let j = j - 4 * n6;
        if j < nr {
            return &mut self.lambda[j];
        }
        let j = j - nr;
        let v = match j / ns {
            0 => &mut self.x,
            1 => &mut self.xdot,
            _ => &mut self.w,
        };
        &mut v[j % ns]
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

    /// The tangent after an event sets held states, copies `(target, source)` of element
    /// states ([`crate::solve::StepEvent::held`]): each target takes its source's component
    /// as it was before any was set.
    pub fn hold(&mut self, held: &[(usize, usize)]) {
        let sources: Vec<f64> = held.iter().map(|&(_, s)| self.x[s]).collect();
        for (&(target, _), v) in held.iter().zip(sources) {
            self.x[target] = v;
        }
    }

    /// The transpose of [`StateTangent::hold`]: a cotangent of the states after the held
    /// states are set, to the one before.
    pub fn hold_transposed(&mut self, held: &[(usize, usize)]) {
        let targets: Vec<f64> = held.iter().map(|&(t, _)| self.x[t]).collect();
        for &(target, _) in held {
            self.x[target] = 0.0;
        }
        for (&(_, source), v) in held.iter().zip(targets) {
            self.x[source] += v;
        }
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
