//! Gradient-based design: the criteria and their adjoint gradients as a function of the
//! design parameters' values ([`Evaluator`], what an optimizer calls), and a bounded
//! quasi-Newton loop on one criterion ([`optimize`], L-BFGS of the argmin crate with a
//! More-Thuente line search).
//!
//! Bounds are kept by a change of variables: a parameter with both bounds `l <= p <= u` is
//! `p = l + (u - l) / (1 + exp(-z))` in the optimizer's variable `z`, so every point the
//! line search tries is feasible; `dp/dz = (p - l)(u - p)/(u - l)`. Parameters without both
//! bounds are held at their values (their gradients are still reported).

use super::adjoint::{adjoint_in, Workspace};
use super::{DesignParameter, Problem, SensitivityError};
use argmin::core::{CostFunction, Error, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use std::cell::RefCell;

/// The criteria of a problem and their gradients at any values of its design parameters,
/// by the discrete adjoint, with the scratch of the adjoint (the step Jacobian's positions
/// and symbolic factorization, the layout's data) kept between calls.
pub struct Evaluator {
    problem: Problem,
    workspace: Workspace,
    /// Forward runs so far.
    pub runs: usize,
}

impl Evaluator {
    pub fn new(problem: Problem) -> Self {
        Self {
            problem,
            workspace: Workspace::default(),
            runs: 0,
        }
    }

    /// The problem at its nominal values.
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// The criteria `f` and `df/dp` (`[criterion][parameter]`) with the design parameters
    /// at `values`.
    pub fn criteria_and_gradients(
        &mut self,
        values: &[f64],
    ) -> Result<(Vec<f64>, Vec<Vec<f64>>), SensitivityError> {
        let problem = self.problem.with_values(values);
        let g = adjoint_in(&problem, &mut self.workspace, &mut |_, _| {})?;
        self.runs += 1;
        Ok((g.values, g.gradients))
    }
}

/// One iteration of [`optimize`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Iteration {
    pub iteration: usize,
    /// The criterion at the iteration's best point.
    pub criterion: f64,
    /// The design parameters there.
    pub values: Vec<f64>,
    /// `df/dp` there.
    pub gradient: Vec<f64>,
}

/// The outcome of [`optimize`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Optimum {
    pub history: Vec<Iteration>,
    /// Why the loop stopped (argmin's termination status).
    pub status: String,
    /// Forward and adjoint runs.
    pub runs: usize,
}

/// The map between the free parameters' values and the optimizer's variables.
struct Variables {
    /// Index in the design and bounds of each free parameter.
    free: Vec<(usize, f64, f64)>,
    nominal: Vec<f64>,
}

impl Variables {
    fn values(&self, z: &[f64]) -> Vec<f64> {
        let mut p = self.nominal.clone();
        for (&(k, l, u), &zk) in self.free.iter().zip(z) {
            p[k] = l + (u - l) / (1.0 + (-zk).exp());
        }
        p
    }

    fn variables(&self, p: &[f64]) -> Vec<f64> {
        self.free
            .iter()
            .map(|&(k, l, u)| {
                let s = ((p[k] - l) / (u - l)).clamp(1e-12, 1.0 - 1e-12);
                (s / (1.0 - s)).ln()
            })
            .collect()
    }

    /// `df/dz` from `df/dp` at `p`.
    fn gradient(&self, p: &[f64], g: &[f64]) -> Vec<f64> {
        self.free
            .iter()
            .map(|&(k, l, u)| g[k] * (p[k] - l) * (u - p[k]) / (u - l))
            .collect()
    }
}

/// A point the optimizer tried: the criterion, the parameters' values, `df/dp`.
type Tried = (f64, Vec<f64>, Vec<f64>);

/// The cost of argmin: criterion `c` of the evaluator at `z`, both cost and gradient from
/// one adjoint run (kept for the gradient call at the same point), every run recorded.
struct Cost<'a> {
    evaluator: RefCell<&'a mut Evaluator>,
    variables: Variables,
    criterion: usize,
    /// The last point asked for (`z`) and its cost and `df/dz`.
    last: RefCell<Option<(Vec<f64>, Tried)>>,
    tried: RefCell<Vec<Tried>>,
}

impl Cost<'_> {
    fn evaluate(&self, z: &[f64]) -> Result<(f64, Vec<f64>), Error> {
        if let Some((at, (f, _, g))) = &*self.last.borrow() {
            if at.as_slice() == z {
                return Ok((*f, g.clone()));
            }
        }
        let p = self.variables.values(z);
        let (f, g) = self.evaluator.borrow_mut().criteria_and_gradients(&p)?;
        let (f, g) = (f[self.criterion], g[self.criterion].clone());
        let gz = self.variables.gradient(&p, &g);
        self.tried.borrow_mut().push((f, p.clone(), g));
        *self.last.borrow_mut() = Some((z.to_vec(), (f, p, gz.clone())));
        Ok((f, gz))
    }
}

/// The cost as argmin holds it (by value), borrowed so that the runs stay readable after.
struct Shared<'c, 'a>(&'c Cost<'a>);

impl CostFunction for Shared<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, z: &Vec<f64>) -> Result<f64, Error> {
        self.0.evaluate(z).map(|r| r.0)
    }
}

impl Gradient for Shared<'_, '_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, z: &Vec<f64>) -> Result<Vec<f64>, Error> {
        self.0.evaluate(z).map(|r| r.1)
    }
}

/// Lowers criterion `criterion` of the evaluator's problem over the design parameters that
/// have both bounds (`design`: the problem's design parameters with their bounds), at most
/// `max_iterations` L-BFGS iterations; `report` is told each iteration.
pub fn optimize(
    evaluator: &mut Evaluator,
    design: &[DesignParameter],
    criterion: usize,
    max_iterations: u64,
    report: &mut dyn FnMut(&Iteration),
) -> Result<Optimum, SensitivityError> {
    let nominal = evaluator.problem().values();
    let free: Vec<(usize, f64, f64)> = design
        .iter()
        .enumerate()
        .filter_map(|(k, d)| match (d.lower, d.upper) {
            (Some(l), Some(u)) if u > l => Some((k, l, u)),
            _ => None,
        })
        .collect();
    if free.is_empty() {
        return Err(SensitivityError::Unsupported(
            "no design parameter has both a lower and an upper bound: nothing to optimize".into(),
        ));
    }
    let variables = Variables { free, nominal };
    let z0 = variables.variables(&variables.nominal);
    let cost = Cost {
        evaluator: RefCell::new(evaluator),
        variables,
        criterion,
        last: RefCell::new(None),
        tried: RefCell::new(Vec::new()),
    };
    // The starting point, reported as iteration 0.
    cost.evaluate(&z0)
        .map_err(|e| SensitivityError::Unsupported(format!("optimization: {e}")))?;
    let mut history = Vec::new();
    let first = cost.tried.borrow()[0].clone();
    let record = |history: &mut Vec<Iteration>,
                  (f, p, g): (f64, Vec<f64>, Vec<f64>),
                  report: &mut dyn FnMut(&Iteration)| {
        let it = Iteration {
            iteration: history.len(),
            criterion: f,
            values: p,
            gradient: g,
        };
        report(&it);
        history.push(it);
    };
    record(&mut history, first, report);
    let solver = LBFGS::new(MoreThuenteLineSearch::new(), 7);
    let result = Executor::new(Shared(&cost), solver)
        .configure(|s| s.param(z0).max_iters(max_iterations))
        .run()
        .map_err(|e| SensitivityError::Unsupported(format!("optimization: {e}")))?;
    // Each accepted iterate: the best point tried so far after each line search, in order.
    let mut best = history[0].criterion;
    for (f, p, g) in cost.tried.borrow().iter().skip(1) {
        if *f < best {
            best = *f;
            record(&mut history, (*f, p.clone(), g.clone()), report);
        }
    }
    let status = result.state().get_termination_status().to_string();
    let runs = cost.evaluator.borrow().runs;
    Ok(Optimum {
        history,
        status,
        runs,
    })
}
