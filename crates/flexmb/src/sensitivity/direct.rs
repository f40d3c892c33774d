//! Direct differentiation: the tangents `ds_n/dp_k` carried along the run, one linear solve
//! per parameter and step (module documentation of [`super`]).

use super::criteria::{CriterionKind, History};
use super::matrix::StepMatrix;
use super::pipeline::{self, Prepared, Spare};
use super::{EventWatch, Gradients, Problem, SensitivityError, Stats};
use crate::data::Data;
use crate::data::Layout;
use crate::model::Model;
use crate::solve::observe::{Observer, Sample, StepRecord};
use crate::solve::step::{StateTangent, StepFunction};
use crate::solve::trajectory::TrajectoryStep;
use crate::solve::Simulation;
use crate::state::State;
use std::borrow::Borrow;
use std::sync::mpsc::{sync_channel, SyncSender};

/// The direct method's observer of a run.
struct Direct<'a> {
    problem: &'a Problem,
    layout: &'a Layout,
    data: Data,
    /// The storage of the last step's factorization, partial derivatives and Jacobian
    /// values, reused.
    spare: Spare,
    values: Vec<f64>,
    /// `ds_n/dp_k`.
    tangents: Vec<StateTangent>,
    history: History,
    /// `df_c/dp_k` at the last point, unweighted: `[criterion][parameter]`.
    last: Vec<Vec<f64>>,
    /// The gradients so far.
    gradients: Vec<Vec<f64>>,
    /// Scratch: one entry per parameter of the registry.
    dp: Vec<f64>,
    scratch: Model,
    steps: usize,
    /// The rows left out as redundant at the start (a run that changes them is refused).
    redundant: Vec<usize>,
    /// The run's first event, which stops it (the run's thread watches it when the tangents
    /// are carried on another: [`Handover`]).
    events: EventWatch,
    /// Weight 1 for every criterion; the index in the design of each registry parameter.
    ones: Vec<f64>,
    index: Vec<Option<usize>>,
}

impl Direct<'_> {
    /// The criteria's derivatives at a point (unweighted), and the trapezoidal sum.
    fn point(&mut self, state: &State) {
        let p = self.problem;
        let criteria = &p.criteria;
        criteria.record(&p.model, self.layout, state, &mut self.history);
        let n = self.history.t.len() - 1;
        let values = &self.history.values[n];
        let (ones, index) = (&self.ones, &self.index);
        let mut now = vec![vec![0.0; p.design.len()]; criteria.len()];
        let grads = criteria.point_gradients(
            &p.model,
            self.layout,
            state,
            values,
            ones,
            (&p.params, &p.design, &mut self.scratch),
        );
        for (g, coef) in &grads {
            for (k, ds) in self.tangents.iter().enumerate() {
                let d = g.dot(ds);
                for (c, &cc) in coef.iter().enumerate() {
                    now[c][k] += cc * d;
                }
            }
            for &(id, d) in &g.params {
                if let Some(k) = index[id.0 as usize] {
                    for (c, &cc) in coef.iter().enumerate() {
                        now[c][k] += cc * d;
                    }
                }
            }
        }
        if n > 0 {
            let h = self.history.t[n] - self.history.t[n - 1];
            for (c, crit) in criteria.criteria.iter().enumerate() {
                if crit.kind == CriterionKind::Integral {
                    for k in 0..p.design.len() {
                        self.gradients[c][k] += 0.5 * h * (self.last[c][k] + now[c][k]);
                    }
                }
            }
        }
        self.last = now;
    }

    /// Step `n` on the run's thread: its Jacobian prepared here, then [`Direct::advance`].
    fn step(&mut self, record: &StepRecord) -> Result<(), String> {
        self.check(record.redundant_rows, record.start.t)?;
        let held = self.events.step(record)?;
        let p = self.problem;
        let spare = std::mem::take(&mut self.spare);
        let at = (record.index, record.start, record.info.h, record.unknowns);
        let settings = &record.simulation.settings;
        let (data, values) = (&mut self.data, &mut self.values);
        let (f, mut matrix) =
            pipeline::prepare_function(&p.model, self.layout, settings, at, data, spare, values)?;
        self.advance(&f, record.unknowns, &mut matrix, record.end, &held);
        self.spare = Spare::after(matrix, &f);
        Ok(())
    }

    /// A run that changes the rows left out as redundant is refused.
    fn check(&self, redundant: &[usize], t: f64) -> Result<(), String> {
        if redundant != self.redundant.as_slice() {
            return Err(super::reselected(t));
        }
        Ok(())
    }

    /// The tangents carried through step `f` with its Jacobian factorized in `matrix`, and
    /// the criteria's derivatives at its `end`.
    fn advance(
        &mut self,
        f: &StepFunction,
        x: &[f64],
        matrix: &mut StepMatrix,
        end: &State,
        held: &[(usize, usize)],
    ) {
        let p = self.problem;
        let starts = f.start_jvp_many(x, &self.tangents, &mut self.data);
        for ((k, &id), mut rhs) in p.design.iter().enumerate().zip(starts) {
            let ds = &self.tangents[k];
            self.dp[id.0 as usize] = 1.0;
            let dr = f.parameter_jvp(x, &p.params, &self.dp, &mut self.data);
            for (a, b) in rhs.iter_mut().zip(&dr) {
                *a = -(*a + b);
            }
            matrix.solve(&mut rhs);
            let mut next = f.end_jvp(x, &rhs, ds, Some((&p.params, &self.dp)), &mut self.data);
            self.dp[id.0 as usize] = 0.0;
            next.hold(held);
            self.tangents[k] = next;
        }
        self.steps += 1;
        self.point(end);
    }
}

/// A step of the run with its end, copied for the thread of the tangents.
struct OwnedStep {
    step: TrajectoryStep,
    end: State,
}

impl Borrow<TrajectoryStep> for OwnedStep {
    fn borrow(&self) -> &TrajectoryStep {
        &self.step
    }
}

/// The run's observer when the tangents are carried on other threads: each step is copied
/// to them, up to the run's first event.
struct Handover(SyncSender<OwnedStep>, EventWatch);

impl Observer for Handover {
    fn output(&mut self, _: &Sample) -> Result<(), String> {
        Ok(())
    }
    fn wants_steps(&self) -> bool {
        true
    }
    fn step(&mut self, record: &StepRecord) -> Result<(), String> {
        let held = self.1.step(record)?;
        let step = OwnedStep {
            step: TrajectoryStep {
                index: record.index,
                h: record.info.h,
                start: record.start.clone(),
                unknowns: record.unknowns.to_vec(),
                redundant_rows: record.redundant_rows.to_vec(),
                held,
            },
            end: record.end.clone(),
        };
        // The tangents' thread stopped on an error, which is the one reported.
        self.0
            .send(step)
            .map_err(|_| "the sensitivity analysis stopped".to_string())
    }
}

impl Observer for Direct<'_> {
    fn output(&mut self, _: &Sample) -> Result<(), String> {
        Ok(())
    }
    fn wants_steps(&self) -> bool {
        true
    }
    fn step(&mut self, record: &StepRecord) -> Result<(), String> {
        Direct::step(self, record)
    }
}

/// The criteria of `problem` and their gradients by direct differentiation.
pub fn direct(problem: &Problem) -> Result<Gradients, SensitivityError> {
    let (mut sim, tangents) = super::start(problem)?;
    let layout = sim.data.layout.clone();
    let n_c = problem.criteria.len();
    let mut obs = Direct {
        problem,
        data: Data::new(&problem.model, layout.clone())
            .map_err(crate::error::SolveError::from)?
            .with_threads(sim.data.threads.clone()),
        layout: &layout,
        spare: Spare::default(),
        values: Vec::new(),
        tangents,
        history: History::default(),
        last: Vec::new(),
        gradients: vec![vec![0.0; problem.design.len()]; n_c],
        dp: vec![0.0; problem.params.len()],
        scratch: (*problem.model).clone(),
        steps: 0,
        redundant: sim.data.layout.redundant_rows(),
        events: EventWatch::default(),
        ones: vec![1.0; n_c],
        index: problem.design_index(),
    };
    obs.point(&sim.state.clone());
    let workers = crate::parallel::resolve(sim.settings.threads);
    let jacobian_threads = if workers > 1 && obs.layout.n_unknowns() >= pipeline::PARALLEL_FROM {
        obs = on_threads(&mut sim, obs, workers)?;
        workers
    } else {
        let run = sim.run(&mut obs);
        std::mem::take(&mut obs.events).outcome(run)?;
        1
    };
    for (c, crit) in problem.criteria.criteria.iter().enumerate() {
        if crit.kind == CriterionKind::Terminal {
            obs.gradients[c].clone_from(&obs.last[c]);
        }
    }
    Ok(Gradients {
        values: problem.criteria.values(&obs.history),
        gradients: obs.gradients,
        fd_steps: None,
        stats: Stats {
            forward_runs: 1,
            steps: obs.steps,
            jacobian_threads,
            ..Stats::default()
        },
        warnings: sim.warnings,
    })
}

/// Runs `sim` with the tangents of `obs` carried on another thread, the steps' Jacobians
/// prepared on `workers` more ([`pipeline`]); gives `obs` back at the end of the run.
fn on_threads<'a>(
    sim: &mut Simulation,
    mut obs: Direct<'a>,
    workers: usize,
) -> Result<Direct<'a>, SensitivityError> {
    let (p, layout) = (obs.problem, obs.layout);
    let settings = sim.settings;
    let mut scratch = Vec::with_capacity(workers);
    for _ in 0..workers {
        scratch.push(Data::new(&p.model, layout.clone()).map_err(crate::error::SolveError::from)?);
    }
    let spares: Vec<_> = (0..workers).map(|_| Default::default()).collect();
    let (tx, rx) = sync_channel::<OwnedStep>(pipeline::AHEAD);
    std::thread::scope(|scope| {
        let chain = scope.spawn(|| {
            let scratch = scratch.iter_mut().collect();
            let done = pipeline::run(
                &p.model,
                layout,
                &settings,
                scratch,
                &spares,
                rx.into_iter(),
                &mut |prepared| {
                    let Prepared {
                        step,
                        partials,
                        mut matrix,
                    } = prepared;
                    let s = &step.step;
                    obs.check(&s.redundant_rows, s.start.t)?;
                    let f = StepFunction::new(&p.model, layout, &s.start, &settings, s.h)
                        .with_partials(partials);
                    obs.advance(&f, &s.unknowns, &mut matrix, &step.end, &s.held);
                    Ok(Spare::after(matrix, &f))
                },
            );
            done.map(|()| obs)
        });
        let mut handover = Handover(tx, EventWatch::default());
        let run = sim.run(&mut handover);
        // The end of the steps: the tangents' thread finishes those it has.
        let Handover(tx, events) = handover;
        drop(tx);
        let run = events.outcome(run);
        let chain = chain.join().expect("the tangents' thread does not panic");
        match (run, chain) {
            (_, Err(e)) => Err(SensitivityError::from(crate::error::SolveError::Output(e))),
            (Err(e), _) => Err(e),
            (Ok(_), Ok(obs)) => Ok(obs),
        }
    })
}
