//! The configuration updates of a step (the module documentation of [`super`],
//! "Configuration update"): the increment `dq + B(q_n)^T zeta` with the commutator
//! correction `c_n`, and the kinematics `q = q_n exp(total)`, `T(total)` (or the chart's)
//! at an iterate.

use crate::data::Layout;
use crate::elements::{NodeState, Vec12};
use crate::parallel::Threads;
use crate::state::State;
use flexmb_lie::{Group, Mat6, Vec6};

use super::Start;

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
