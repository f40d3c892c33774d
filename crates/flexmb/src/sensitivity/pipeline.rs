//! The steps' exact Jacobians prepared ahead on worker threads and handed over in order.
//!
//! Both methods need, at every step, the exact step Jacobian `J_x = dR/dx` at the converged
//! unknowns, factorized, and then a chain of products that runs step after step (the direct
//! method's tangents forward, the adjoint's cotangents backward). The Jacobian of a step
//! depends on that step alone (its start `s_{n-1}`, its unknowns `x_n`), not on the chain:
//! `W` workers prepare the steps `k = w, w + W, ...` of the sequence (step function, partial
//! derivatives, factorization), each with its own scratch [`Data`] and factorizations, at
//! most [`AHEAD`] steps ahead of the chain; the calling thread takes them in order and runs
//! the chain. The operations on each step are those of the sequential code, so the results
//! are the same, bit for bit (`tests/sensitivity/sensitivity.rs`).

use super::matrix::StepMatrix;
use crate::data::Data;
use crate::data::Layout;
use crate::model::Model;
use crate::solve::step::{KeptPartials, StepFunction};
use crate::solve::trajectory::TrajectoryStep;
use crate::solve::DynamicSettings;
use crate::state::State;
use std::borrow::Borrow;
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Steps a worker prepares ahead of the chain (each holds the step's partial derivatives
/// and factorization: about 1 MB for chain_100).
pub const AHEAD: usize = 2;

/// Unknowns from which the steps are prepared on several threads when the setting allows
/// them (below, a step's Jacobian costs little against the hand-over between threads;
/// BENCHMARKS.md, "Sensitivity analysis").
pub const PARALLEL_FROM: usize = 100;

/// A step made ready for the chain: the step, its exact Jacobian's partial derivatives at
/// the converged unknowns (for [`StepFunction::with_partials`]) and the Jacobian factorized.
pub struct Prepared<S> {
    pub step: S,
    pub partials: KeptPartials,
    pub matrix: StepMatrix,
}

/// What the preparation of a step reuses from an earlier step's: the factorization's storage
/// (with its symbolic analysis) and the partial derivatives' storage.
#[derive(Default)]
pub struct Spare {
    pub matrix: StepMatrix,
    pub partials: KeptPartials,
}

impl Spare {
    /// What the next steps reuse of a step done with: its factorization `matrix` and the
    /// partial derivatives kept in its step function `f`.
    pub fn after(matrix: StepMatrix, f: &StepFunction) -> Self {
        Spare {
            matrix,
            partials: f.take_partials(),
        }
    }
}

/// Prepares `step` with the scratch `data`, the storage of `spare` and `values` (the
/// Jacobian's values, scratch).
pub fn prepare<S: Borrow<TrajectoryStep>>(
    model: &Model,
    layout: &Layout,
    settings: &DynamicSettings,
    step: S,
    data: &mut Data,
    spare: Spare,
    values: &mut Vec<f64>,
) -> Result<Prepared<S>, String> {
    let s: &TrajectoryStep = step.borrow();
    let at = (s.index, &s.start, s.h, &s.unknowns[..]);
    let (f, matrix) = prepare_function(model, layout, settings, at, data, spare, values)?;
    let partials = f.take_partials();
    Ok(Prepared {
        step,
        partials,
        matrix,
    })
}

/// [`prepare`] where the step is used: the step function of the step `index` of size `h`
/// from `start` (its partial derivatives at `unknowns` kept) and its Jacobian factorized.
pub fn prepare_function<'s>(
    model: &'s Model,
    layout: &'s Layout,
    settings: &DynamicSettings,
    (index, start, h, unknowns): (usize, &'s State, f64, &[f64]),
    data: &mut Data,
    spare: Spare,
    values: &mut Vec<f64>,
) -> Result<(StepFunction<'s>, StepMatrix), String> {
    let f = StepFunction::new(model, layout, start, settings, h).with_partials(spare.partials);
    let pattern = f.jacobian_values(unknowns, data, values);
    let t = start.t + h;
    let mut matrix = spare.matrix;
    matrix
        .factorize(&pattern, values, &|| {
            format!("step {index} (t = {t:.6e} s)")
        })
        .map_err(|e| e.to_string())?;
    Ok((f, matrix))
}

/// Runs `chain` on every step of `steps` in order, the steps prepared on as many workers as
/// `scratch` has scratch data (at least two), worker `w` with the storage of `spares[w]`.
/// `chain` gives back the storage of the step's preparation, which goes back to the
/// worker's `spares` (for its next steps, and for the next call). The first error stops
/// everything and is returned.
pub fn run<S, I>(
    model: &Model,
    layout: &Layout,
    settings: &DynamicSettings,
    scratch: Vec<&mut Data>,
    spares: &[Mutex<Vec<Spare>>],
    steps: I,
    chain: &mut dyn FnMut(Prepared<S>) -> Result<Spare, String>,
) -> Result<(), String>
where
    S: Borrow<TrajectoryStep> + Send,
    I: Iterator<Item = S> + Send,
{
    let workers = scratch.len();
    std::thread::scope(|scope| {
        let mut ready: Vec<Receiver<Result<Prepared<S>, String>>> = Vec::with_capacity(workers);
        let mut inputs = Vec::with_capacity(workers);
        for (data, spares) in scratch.into_iter().zip(spares) {
            let (input, steps_in) = sync_channel::<S>(AHEAD);
            let (tx, rx) = sync_channel(AHEAD);
            inputs.push(input);
            ready.push(rx);
            scope.spawn(move || {
                let mut values = Vec::new();
                for step in steps_in {
                    let spare = lock(spares).pop().unwrap_or_default();
                    let prepared = prepare(model, layout, settings, step, data, spare, &mut values);
                    let failed = prepared.is_err();
                    // The chain stopped (an error): nothing more to prepare.
                    if tx.send(prepared).is_err() || failed {
                        return;
                    }
                }
            });
        }
        // Step `k` of the sequence goes to worker `k % workers`.
        scope.spawn(move || {
            for (k, step) in steps.enumerate() {
                if inputs[k % workers].send(step).is_err() {
                    return;
                }
            }
        });
        // A worker without a step `k` has closed its channel: the sequence has ended.
        let mut k = 0;
        while let Ok(prepared) = ready[k % workers].recv() {
            let done = chain(prepared?)?;
            lock(&spares[k % workers]).push(done);
            k += 1;
        }
        Ok(())
    })
}

/// The storage of a worker (a thread that panicked left it as it was: still storage).
fn lock(spares: &Mutex<Vec<Spare>>) -> MutexGuard<'_, Vec<Spare>> {
    spares.lock().unwrap_or_else(PoisonError::into_inner)
}
