//! The exact step Jacobian `dR/dx` of [`crate::solve::step::StepFunction::jacobian`],
//! factorized once per step for the solves of a sensitivity analysis: `n_p` forward solves
//! (direct differentiation) or one transposed solve per criterion (adjoint).

use crate::solve::linear::LinearSolver;
use crate::solve::step::Triplets;
use crate::SolveError;

/// A factorized step Jacobian. The triplets' positions change little from step to step (an
/// entry is left out where it is exactly zero), so the solver, with its symbolic analysis,
/// is built again only when they change.
#[derive(Default)]
pub struct StepMatrix {
    positions: Vec<(usize, usize)>,
    values: Vec<f64>,
    solver: Option<LinearSolver>,
}

impl StepMatrix {
    /// Factorizes the `n x n` matrix of `triplets` (duplicates summed); `what` names the
    /// step in the error of a singular matrix.
    pub fn factorize(
        &mut self,
        n: usize,
        triplets: &Triplets,
        what: &dyn Fn() -> String,
    ) -> Result<(), SolveError> {
        let same = self.solver.as_ref().is_some_and(|s| s.n() == n)
            && self.positions.len() == triplets.len()
            && self
                .positions
                .iter()
                .zip(triplets)
                .all(|(&(i, j), &(a, b, _))| i == a && j == b);
        if !same {
            self.positions = triplets.iter().map(|&(i, j, _)| (i, j)).collect();
            self.solver = Some(LinearSolver::new(n, &self.positions)?);
        }
        self.values.clear();
        self.values.extend(triplets.iter().map(|t| t.2));
        let solver = self.solver.as_mut().expect("built above");
        solver.factorize(&self.values).map_err(|e| {
            SolveError::Output(format!(
                "sensitivity: the exact step Jacobian of {} cannot be factorized ({e}); the derivatives of the step are not defined there",
                what()
            ))
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

    /// Numeric factorizations so far.
    pub fn factorizations(&self) -> usize {
        self.solver.as_ref().map_or(0, |s| s.factorizations())
    }
}
