//! Sensitivities of a static equilibrium: the final point of a static analysis (load
//! control, arc length or pseudo-dynamic), at its load factor `lambda`.
//!
//! The equilibrium `R(q, mu, x; p) = [r(q, x; p) - lambda g_ext(q; p) + B^T mu; Phi(q; p);
//! e(q, x; p)] = 0` (multipliers `mu`, element states `x` at zero rates) defines the solution
//! as a function of the parameters at fixed `lambda`. With configuration tangents in the
//! algebra (`dq/dp = q tilde(w)`) and `K = dR/d(w, mu, x)` the static iteration matrix
//! `[[K_t + K_c, B^T], [B, 0]]` (with the state rows and columns) at the solution (`T = I`):
//!
//! ```text
//! direct:   K d(w, mu, x)/dp = -dR/dp                      one solve per parameter
//! adjoint:  K^T a = dG/d(w, mu, x),  dG/dp = G_p - a . dR/dp  one solve per criterion
//! ```
//!
//! for terminal criteria `G(s, p)` of the final state (an integral over the load factor is
//! not a static criterion). An arc-length run's final load factor is held fixed: its
//! criteria are differentiated at that load.

use super::criteria::{CriterionKind, History};
use super::{Gradients, Problem, SensitivityError, Stats};
use crate::assembly::{assemble, Iterate};
use crate::data::{Block, Data};
use crate::model::ParamId;
use crate::parameter_derivatives::{
    residual_derivative, residual_derivative_transpose_for, Columns, Point, Weights,
};
use crate::solve::step::StateTangent;
use crate::solve::{StaticSettings, Statics};
use std::sync::Arc;

/// Runs the static analysis of `problem` and records its criteria's sensors at the final
/// point.
pub(super) fn solve(
    problem: &Problem,
    settings: &StaticSettings,
) -> Result<(Statics, History), SensitivityError> {
    if let Some(c) = problem
        .criteria
        .criteria
        .iter()
        .find(|c| c.kind == CriterionKind::Integral)
    {
        return Err(SensitivityError::Unsupported(format!(
            "criterion '{}' is an integral: a static analysis has terminal criteria only (its final point)",
            c.name
        )));
    }
    let mut statics = Statics::new(Arc::clone(&problem.model), *settings)?;
    statics.run(&mut |_: &crate::solve::observe::Sample| Ok(()))?;
    let mut history = History::default();
    let layout = statics.data.layout.clone();
    problem
        .criteria
        .record(&problem.model, &layout, &statics.state, &mut history);
    Ok((statics, history))
}

/// The gradients of the criteria of a static `problem` at its final point, by the adjoint
/// or, with `direct`, by direct differentiation.
pub(super) fn gradients(problem: &Problem, direct: bool) -> Result<Gradients, SensitivityError> {
    let crate::solve::Analysis::Static(settings) = &problem.analysis else {
        return Err(SensitivityError::Unsupported(
            "not a static analysis".into(),
        ));
    };
    let (statics, history) = solve(problem, settings)?;
    let model = &problem.model;
    let state = &statics.state;
    let lambda = statics.load_factor;
    let layout = statics.data.layout.clone();
    let mut data = Data::new(model, layout.clone()).map_err(crate::error::SolveError::from)?;
    // The equilibrium's point: no velocities or accelerations (a pseudo-dynamic run ends
    // with small ones), loads at the state's time, where the analysis evaluated them (the
    // load factor; a pseudo-dynamic run's end time, with the load factor as scale).
    let mut nodes = crate::sensors::node_states(state);
    for n in &mut nodes {
        n.v = flexmb_lie::Vec6::zeros();
        n.vdot = flexmb_lie::Vec6::zeros();
    }
    let t = state.t;
    let rates = vec![0.0; layout.n_states];
    let it = Iterate {
        nodes: &nodes,
        t,
        lambda: &state.lambda,
        b_start: &[],
        x: &state.x,
        xdot: &rates,
        inputs: None,
    };
    // Rows scaled as the static solver scales them, by 1 / max diag K_t (multiplier
    // unknowns s lambda), so that the pivot test sees the constraint block at the scale of
    // the stiffness block.
    assemble(
        model,
        &mut data,
        &it,
        &crate::solve::statics::scaling(1.0, lambda),
        true,
    );
    let nd = layout.n_dofs;
    let s = crate::solve::statics::stiffness_row_scale(&data).unwrap_or(1.0);
    assemble(
        model,
        &mut data,
        &it,
        &crate::solve::statics::scaling(s, lambda),
        true,
    );
    let values = data.values.clone();
    data.solver.factorize(&values).map_err(|e| {
        SensitivityError::Singular(format!(
            "the static tangent at the final load factor {lambda} ({e})"
        ))
    })?;
    check_equilibrium(&mut data, state, settings)?;
    let point = Point {
        nodes: &nodes,
        x: &state.x,
        xdot: &rates,
        t,
        lambda: &state.lambda,
        load_factor: lambda,
        inputs: None,
    };
    let so = layout.state_offset();
    let n_c = problem.criteria.len();
    let n_p = problem.design.len();
    // The criteria's derivatives at the final point (weight 1: terminal).
    let mut scratch = (**model).clone();
    let ones = vec![1.0; n_c];
    let grads = problem.criteria.point_gradients(
        model,
        &layout,
        state,
        &history.values[0],
        &ones,
        (&problem.params, &problem.design, &mut scratch),
    );
    let index = problem.design_index();
    let mut gradients = vec![vec![0.0; n_p]; n_c];
    let mut bars = vec![StateTangent::zeros_of(&layout); n_c];
    for (g, coef) in &grads {
        for (c, &cc) in coef.iter().enumerate() {
            g.add_to(cc, &mut bars[c]);
            for &(id, d) in &g.params {
                if let Some(k) = index[id.0 as usize] {
                    gradients[c][k] += cc * d;
                }
            }
        }
    }
    // A state tangent as an unknown vector of the static system and back.
    let to_unknowns = |t: &StateTangent| {
        let mut u = vec![0.0; layout.n_unknowns()];
        for (i, q) in t.q.iter().enumerate() {
            u[6 * i..6 * i + 6].copy_from_slice(q.as_slice());
        }
        for (k, &row) in layout.active_rows.iter().enumerate() {
            u[nd + k] = t.lambda[row] / s;
        }
        u[layout.block(Block::States)].copy_from_slice(&t.x);
        u
    };
    if direct {
        let mut dr = vec![0.0; nd];
        let (mut dphi, mut de) = (vec![0.0; layout.n_rows], vec![0.0; layout.n_states]);
        for (k, &id) in problem.design.iter().enumerate() {
            let columns = Columns {
                dr: &mut dr,
                dphi: &mut dphi,
                dpsi: &mut [],
                de: &mut de,
            };
            residual_derivative(model, &problem.params, id, &point, columns);
            let mut rhs = vec![0.0; layout.n_unknowns()];
            rhs[..nd].iter_mut().zip(&dr).for_each(|(a, b)| *a = -s * b);
            for (j, &row) in layout.active_rows.iter().enumerate() {
                rhs[nd + j] = -dphi[row];
            }
            rhs[so..].iter_mut().zip(&de).for_each(|(a, b)| *a = -s * b);
            data.solver.solve_in_place(&mut rhs);
            let mut ds = StateTangent::zeros_of(&layout);
            for (i, q) in ds.q.iter_mut().enumerate() {
                q.copy_from_slice(&rhs[6 * i..6 * i + 6]);
            }
            for (j, &row) in layout.active_rows.iter().enumerate() {
                ds.lambda[row] = rhs[nd + j] / s;
            }
            ds.x.copy_from_slice(&rhs[layout.block(Block::States)]);
            for (c, g) in gradients.iter_mut().enumerate() {
                g[k] += bars[c].dot(&ds);
            }
        }
    } else {
        let ids: Vec<ParamId> = problem.design.clone();
        for (c, bar) in bars.iter().enumerate() {
            let mut a = to_unknowns(bar);
            data.solver.solve_transpose_in_place(&mut a);
            let mut w_phi = vec![0.0; layout.n_rows];
            for (j, &row) in layout.active_rows.iter().enumerate() {
                w_phi[row] = a[nd + j];
            }
            let w_r: Vec<f64> = a[..nd].iter().map(|v| s * v).collect();
            let w_e: Vec<f64> = a[so..].iter().map(|v| s * v).collect();
            let weights = Weights {
                r: &w_r,
                phi: &w_phi,
                psi: &[],
                e: &w_e,
            };
            let mut full = vec![0.0; problem.params.len()];
            residual_derivative_transpose_for(
                model,
                &problem.params,
                &ids,
                &point,
                weights,
                &mut full,
            );
            for (k, id) in ids.iter().enumerate() {
                gradients[c][k] -= full[id.0 as usize];
            }
        }
    }
    Ok(Gradients {
        values: problem.criteria.values(&history),
        gradients,
        fd_steps: None,
        stats: Stats {
            forward_runs: 1,
            steps: statics.stats.steps,
            ..Stats::default()
        },
        warnings: statics.warnings.clone(),
    })
}

/// The derivatives of a static solution hold at an equilibrium: one Newton correction from
/// the final point (`data` holds the residual and the factorized tangent there) must stay
/// within ten times the Newton tolerance, else the point (e.g. a pseudo-dynamic run that
/// has not settled) is refused.
fn check_equilibrium(
    data: &mut Data,
    state: &crate::state::State,
    settings: &StaticSettings,
) -> Result<(), SensitivityError> {
    let mut dx = data.residual.clone();
    data.solver.solve_in_place(&mut dx);
    let nd = data.layout.n_dofs;
    let size = state.q.iter().fold(1.0f64, |m, q| m.max(q.x.norm()));
    let tolerance = 10.0 * (settings.newton.atol + settings.newton.rtol * size);
    let moved = dx[..nd].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if moved > tolerance {
        return Err(SensitivityError::Unconverged(format!(
            "the final point of the static analysis is not an equilibrium: one Newton correction from it moves the configuration by {moved:.3e} (tolerance {tolerance:.3e}); a pseudo-dynamic run has not settled: increase pseudo_time or pseudo_damping, or use load_control"
        )));
    }
    Ok(())
}
