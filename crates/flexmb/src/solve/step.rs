//! The Lie group generalized-alpha step as functions over explicit inputs.
//!
//! One step `n -> n+1` of size `h` (Brüls & Cardona 2010, Eqs. (40)-(44); Arnold & Brüls
//! 2007, Eq. (5); stabilized index 2: Arnold, Brüls & Cardona 2015, Sect. 3). Its unknowns
//! are the Newton vector `x = (dq, mu, zeta)` of [`crate::data::Layout`]: the configuration
//! increments, the scaled multipliers `mu = s lambda_{n+1}` of the active rows and, in the
//! stabilized form, one `zeta` per active row. Given the start `s_n = (q_n, v_n, vdot_n, a_n)`
//! the end of the step is
//!
//! ```text
//! q_{n+1}    = q_n exp(dq + B(q_n)^T zeta)                      (B^T zeta: stabilized only)
//! a_{n+1}    = (dq - h v_n - (1/2 - beta) h^2 a_n) / (beta h^2)
//! v_{n+1}    = v_n + (1 - gamma) h a_n + gamma h a_{n+1}
//! vdot_{n+1} = ((1 - alpha_m) a_{n+1} + alpha_m a_n - alpha_f vdot_n) / (1 - alpha_f)
//! ```
//!
//! (the last two affine in `dq`, with `dv/ddq = gamma' = gamma/(beta h)` and
//! `dvdot/ddq = beta' = (1 - alpha_m)/((1 - alpha_f) beta h^2)`), and the step residual is
//!
//! ```text
//! R(x; s_n, p, h) = [ s (r(q, v, vdot, t) + B(q)^T lambda) ]    s = 1/(beta' m)
//!                   [ Phi(q, t)                            ]
//!                   [ (B(q) v + Phi_t) / gamma'            ]    (stabilized only)
//! ```
//!
//! at `t_{n+1}` and the end values above, `m` the largest nodal mass.
//!
//! The Newton iteration of [`super::dynamics`] builds the same relations incrementally
//! ([`predict`], [`correct`], [`finish`]); [`StepFunction`] evaluates them from `x`
//! directly, with the exact Jacobian `dR/dx` and the products of `dR/ds_n` and `dR/dp` with
//! vectors and transposed vectors: what a forward sensitivity, a discrete adjoint and a
//! transcription NLP call.

use super::generalized_alpha::GaParameters;
use super::DynamicSettings;
use crate::assembly::{ConstraintRhs, Scaling};
use crate::data::Layout;
use crate::elements::{Coefficients, NodeState, Vec12};
use crate::state::State;
use flexmb_lie::{Group, Vec6};

/// The fixed numbers of one step: scheme, size, scaling and loading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Start {
    pub params: GaParameters,
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
        Self {
            params,
            h,
            bp,
            gp,
            mass,
            // Equilibrium rows times 1 / (beta' m) with m the largest nodal mass: the mass
            // block is O(1) whatever h and the units of mass, like the constraint block.
            scale: 1.0 / (bp * mass),
            load_factor: settings.load_factor_at(t_new),
            nodal_damping: settings.nodal_damping,
        }
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
            },
            constraint_rhs: ConstraintRhs::Position,
            load_factor: self.load_factor,
            regularization,
            velocity_scale: 1.0 / self.gp,
            nodal_damping: self.nodal_damping,
        }
    }
}

/// Predictor: `vdot_{n+1} = vdot_n` (or its linear extrapolation from the previous step
/// `(h_prev, vdot_{n-1}, lambda_{n-1})` when given: a closer start saves Newton iterations;
/// the solution does not depend on it), `lambda_{n+1}` likewise, and the `v` and increment
/// that the scheme gives for them. Writes `state.v`, `state.vdot`, `state.lambda` (`state`
/// holds `s_n` on entry) and `dq`.
pub fn predict(
    p: &GaParameters,
    h: f64,
    start: &State,
    extrapolate: Option<(f64, &[Vec6], &[f64])>,
    state: &mut State,
    dq: &mut Vec<f64>,
) {
    let n = start.q.len();
    dq.clear();
    dq.resize(6 * n, 0.0);
    let ratio = extrapolate.map_or(0.0, |(h_prev, _, _)| h / h_prev);
    for i in 0..n {
        let (v0, vd0, a0) = (start.v[i], start.vdot[i], start.a[i]);
        let vd1 = match extrapolate {
            Some((_, vdot_prev, _)) if ratio > 0.0 => vd0 + (vd0 - vdot_prev[i]) * ratio,
            _ => vd0,
        };
        let a1 = (vd0 * p.alpha_f + vd1 * (1.0 - p.alpha_f) - a0 * p.alpha_m) / (1.0 - p.alpha_m);
        state.vdot[i] = vd1;
        state.v[i] = v0 + a0 * (h * (1.0 - p.gamma)) + a1 * (h * p.gamma);
        let inc = v0 * h + a0 * (h * h * (0.5 - p.beta)) + a1 * (h * h * p.beta);
        dq[6 * i..6 * i + 6].copy_from_slice(inc.as_slice());
    }
    if let Some((_, _, lambda_prev)) = extrapolate.filter(|_| ratio > 0.0) {
        for (k, l) in state.lambda.iter_mut().enumerate() {
            *l += (*l - lambda_prev[k]) * ratio;
        }
    }
}

/// `dq + B(q_n)^T zeta` into `total` in the stabilized formulation, `dq` otherwise.
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

/// Node kinematics of the iterate: `q = q_n exp(total)`, `v` and `vdot` from `state` and,
/// when `tangents`, the tangent operators `T(total)` (otherwise left as they are).
pub fn kinematics(
    group: Group,
    start: &State,
    state: &State,
    total: &[f64],
    tangents: bool,
    nodes: &mut [NodeState],
) {
    for (i, node) in nodes.iter_mut().enumerate() {
        let inc = Vec6::from_column_slice(&total[6 * i..6 * i + 6]);
        node.q = group.integrate(&start.q[i], &inc);
        node.v = state.v[i];
        node.vdot = state.vdot[i];
        if tangents {
            node.t = group.tangent(&inc);
        }
    }
}

/// Applies a Newton correction `dx`: `dq += dx`, `v += gamma' dx`, `vdot += beta' dx`,
/// `lambda += dmu / s`, and `zeta += dzeta` in the stabilized formulation.
pub fn correct(
    layout: &Layout,
    dx: &[f64],
    start: &Start,
    dq: &mut [f64],
    zeta: &mut [f64],
    state: &mut State,
) {
    let nd = layout.n_dofs;
    if layout.stabilized {
        let na = layout.n_active;
        for (z, d) in zeta.iter_mut().zip(&dx[nd + na..]) {
            *z += d;
        }
    }
    for i in 0..layout.n_nodes {
        let d = Vec6::from_column_slice(&dx[6 * i..6 * i + 6]);
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
}

/// End of the step: `q_{n+1} = q_n exp(total)` (re-orthonormalized) and the algorithmic
/// acceleration `a_{n+1} = (alpha_f vdot_n + (1 - alpha_f) vdot_{n+1} - alpha_m a_n) /
/// (1 - alpha_m)`.
pub fn finish(group: Group, p: &GaParameters, start: &State, total: &[f64], state: &mut State) {
    for i in 0..start.q.len() {
        let inc = Vec6::from_column_slice(&total[6 * i..6 * i + 6]);
        let mut q = group.integrate(&start.q[i], &inc);
        q.orthonormalize();
        state.q[i] = q;
        state.a[i] = (start.vdot[i] * p.alpha_f + state.vdot[i] * (1.0 - p.alpha_f)
            - start.a[i] * p.alpha_m)
            / (1.0 - p.alpha_m);
    }
}
