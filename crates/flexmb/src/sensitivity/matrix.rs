//! The exact step Jacobian `dR/dx` of [`crate::solve::step::StepFunction::jacobian`],
//! factorized once per step for the solves of a sensitivity analysis: `n_p` forward solves
//! (direct differentiation) or one transposed solve per criterion (adjoint).

use crate::linear::{Backend, LinearSolver};

/// Unknowns above which the step Jacobian is factorized by the block LU.
const BLOCK_FROM: usize = 40;
use super::SensitivityError;
use crate::solve::step::JacobianPattern;
use std::sync::Arc;

/// A factorized step Jacobian, on the positions of its layout's [`JacobianPattern`]: the
/// solver, with its symbolic analysis, is built once per pattern.
#[derive(Default)]
pub struct StepMatrix {
    pattern: Option<Arc<JacobianPattern>>,
    solver: Option<LinearSolver>,
}

impl StepMatrix {
    /// Factorizes the matrix of `values` on `pattern`; `what` names the step in the error
    /// of a singular matrix.
    pub fn factorize(
        &mut self,
        pattern: &Arc<JacobianPattern>,
        values: &[f64],
        what: &dyn Fn() -> String,
    ) -> Result<(), SensitivityError> {
        let same = self
            .pattern
            .as_ref()
            .is_some_and(|p| Arc::ptr_eq(p, pattern));
        if !same {
            let n = pattern.n;
            // The step Jacobian is factorized once per step, fresh: the block LU pays off on
            // smaller matrices than in the Newton iteration, which mostly reuses its matrix.
            let backend = if n > BLOCK_FROM {
                Backend::Block
            } else {
                Backend::Dense
            };
            let solver = LinearSolver::build(n, &pattern.positions, backend, &pattern.groups)
                .map_err(crate::error::SolveError::from)?;
            self.solver = Some(solver);
            self.pattern = Some(Arc::clone(pattern));
        }
        let solver = self.solver.as_mut().expect("built above");
        solver.factorize(values).map_err(|e| {
            SensitivityError::Singular(format!("the exact step Jacobian of {} ({e})", what()))
        })
    }

    /// `A x = b` in place.
    pub fn solve(&mut self, b: &mut [f64]) {
        self.solver
            .as_mut()
            .expect("factorize first")
            .solve_in_place(b);
    }

    /// `A^T x = b` in place.
    pub fn solve_transpose(&mut self, b: &mut [f64]) {
        self.solver
            .as_mut()
            .expect("factorize first")
            .solve_transpose_in_place(b);
    }
}
