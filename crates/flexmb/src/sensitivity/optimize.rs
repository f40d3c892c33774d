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
use argmin::core::{CostFunction, Error, Executor, Gradient, State, TerminationReason};
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
        let g = match problem.analysis {
            crate::solve::Analysis::Dynamic(_) => {
                adjoint_in(&problem, &mut self.workspace, &mut |_, _| {})?
            }
            crate::solve::Analysis::Static(_) => super::statics::gradients(&problem, false)?,
        };
        self.runs += 1;
        Ok((g.values, g.gradients))
    }
}

/// A point of [`optimize`] that lowered the criterion below every earlier one (the
/// starting point first): the accepted iterates and the line search's better trials.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Improvement {
    /// Which evaluation (forward and adjoint run) it was, from 1.
    pub evaluation: usize,
    /// The criterion there.
    pub criterion: f64,
    /// The design parameters there.
    pub values: Vec<f64>,
    /// `df/dp` there.
    pub gradient: Vec<f64>,
}

/// The outcome of [`optimize`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Optimum {
    /// The improvements, in order: the last is the best point.
    pub history: Vec<Improvement>,
    /// Why the loop stopped (argmin's termination status).
    pub status: String,
    /// The loop stopped at its most iterations before a convergence test held: the last
    /// point is the best found, not an optimum.
    pub iteration_limit: bool,
    /// L-BFGS iterations.
    pub iterations: u64,
    /// Evaluations (forward and adjoint runs).
    pub runs: usize,
}

/// An [`optimize`] that stopped on an error: the error, and the improvements found before
/// it (none when the first evaluation failed), which are the optimization's results so far.
#[derive(Debug)]
pub struct Stopped {
    pub error: SensitivityError,
    pub history: Vec<Improvement>,
    /// Evaluations (forward and adjoint runs), the one that failed included.
    pub runs: usize,
}

/// The map between the free parameters' values and the optimizer's variables.
struct Variables {
    /// Index in the design and bounds of each free parameter.
    free: Vec<(usize, f64, f64)>,
    nominal: Vec<f64>,
    /// The variables of the nominal values (which map back to them exactly).
    z0: Vec<f64>,
}

impl Variables {
    fn new(free: Vec<(usize, f64, f64)>, nominal: Vec<f64>) -> Self {
        let mut v = Self {
            free,
            nominal,
            z0: Vec::new(),
        };
        v.z0 = v.variables(&v.nominal);
        v
    }

    fn values(&self, z: &[f64]) -> Vec<f64> {
        if z == self.z0.as_slice() {
            return self.nominal.clone();
        }
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

/// A point asked for: `z`, the cost there and `df/dz`.
type Evaluated = (Vec<f64>, f64, Vec<f64>);

/// The cost of argmin: criterion `c` of the evaluator at `z`, both cost and gradient from
/// one adjoint run (kept for the gradient call at the same point); every improvement is
/// recorded and reported as it is found.
struct Cost<'a, 'r> {
    evaluator: RefCell<&'a mut Evaluator>,
    variables: Variables,
    criterion: usize,
    /// The last point asked for (`z`), its cost and `df/dz`.
    last: RefCell<Option<Evaluated>>,
    history: RefCell<Vec<Improvement>>,
    report: RefCell<&'r mut dyn FnMut(&Improvement)>,
    /// The error of an evaluation, which stops the optimizer (argmin keeps only its text).
    failed: RefCell<Option<SensitivityError>>,
}

impl Cost<'_, '_> {
    fn evaluate(&self, z: &[f64]) -> Result<(f64, Vec<f64>), Error> {
        if let Some((at, f, g)) = &*self.last.borrow() {
            if at.as_slice() == z {
                return Ok((*f, g.clone()));
            }
        }
        let p = self.variables.values(z);
        let mut evaluator = self.evaluator.borrow_mut();
        let (f, g) = evaluator.criteria_and_gradients(&p).map_err(|e| {
            let text = e.to_string();
            *self.failed.borrow_mut() = Some(e);
            Error::msg(text)
        })?;
        let (f, g) = (f[self.criterion], g[self.criterion].clone());
        let gz = self.variables.gradient(&p, &g);
        let mut history = self.history.borrow_mut();
        if history.last().is_none_or(|best| f < best.criterion) {
            let it = Improvement {
                evaluation: evaluator.runs,
                criterion: f,
                values: p,
                gradient: g,
            };
            (self.report.borrow_mut())(&it);
            history.push(it);
        }
        *self.last.borrow_mut() = Some((z.to_vec(), f, gz.clone()));
        Ok((f, gz))
    }
}

/// The cost as argmin holds it (by value), borrowed so that the runs stay readable after.
struct Shared<'c, 'a, 'r>(&'c Cost<'a, 'r>);

impl CostFunction for Shared<'_, '_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, z: &Vec<f64>) -> Result<f64, Error> {
        self.0.evaluate(z).map(|r| r.0)
    }
}

impl Gradient for Shared<'_, '_, '_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, z: &Vec<f64>) -> Result<Vec<f64>, Error> {
        self.0.evaluate(z).map(|r| r.1)
    }
}

/// Lowers criterion `criterion` of the evaluator's problem over the design parameters that
/// have both bounds (`design`: the problem's design parameters with their bounds), at most
/// `max_iterations` L-BFGS iterations; `report` is told each improvement as it is found. An
/// evaluation that fails (a run that does not converge, an event in the run: the adjoint
/// refuses it) stops the optimization with the improvements found so far.
pub fn optimize(
    evaluator: &mut Evaluator,
    design: &[DesignParameter],
    criterion: usize,
    max_iterations: u64,
    report: &mut dyn FnMut(&Improvement),
) -> Result<Optimum, Box<Stopped>> {
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
        return Err(Box::new(Stopped {
            error: SensitivityError::Unsupported(
                "no design parameter has both a lower and an upper bound: nothing to optimize"
                    .into(),
            ),
            history: Vec::new(),
            runs: 0,
        }));
    }
    let variables = Variables::new(free, nominal);
    let z0 = variables.z0.clone();
    let cost = Cost {
        evaluator: RefCell::new(evaluator),
        variables,
        criterion,
        last: RefCell::new(None),
        history: RefCell::new(Vec::new()),
        report: RefCell::new(report),
        failed: RefCell::new(None),
    };
    let solver = LBFGS::new(MoreThuenteLineSearch::new(), 7);
    let result = Executor::new(Shared(&cost), solver)
        .configure(|s| s.param(z0).max_iters(max_iterations))
        .run();
    let runs = cost.evaluator.borrow().runs;
    // An evaluation that failed stops the optimization, also when the line search took its
    // error for its own end (argmin then reports a termination status); the evaluator did
    // not count it.
    let stopped = |error, runs| {
        Box::new(Stopped {
            error,
            history: cost.history.take(),
            runs,
        })
    };
    let result = match (result, cost.failed.take()) {
        (_, Some(error)) => return Err(stopped(error, runs + 1)),
        (Err(e), None) => {
            return Err(stopped(SensitivityError::Optimization(e.to_string()), runs));
        }
        (Ok(result), None) => result,
    };
    let state = result.state();
    let (status, iterations) = (state.get_termination_status().to_string(), state.get_iter());
    let iteration_limit = matches!(
        state.get_termination_reason(),
        Some(TerminationReason::MaxItersReached)
    );
    Ok(Optimum {
        history: cost.history.into_inner(),
        status,
        iteration_limit,
        iterations,
        runs,
    })
}
