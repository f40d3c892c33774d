//! Restart: a run interrupted at mid-time, written to a checkpoint (through JSON) and
//! resumed in a new simulation, gives bit for bit the states of the uninterrupted run at
//! every output time after the checkpoint (the checkpoint keeps the integrator's memory,
//! the step-size control and the factorized matrix that later steps reuse).

use crate::common;

use flexmb::observe::Sample;
use flexmb::solve::dynamics::Checkpoint;
use flexmb::{Simulation, SolveError, State};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The states at the output times of a whole run.
fn outputs(sim: &mut Simulation) -> Vec<State> {
    let mut out = Vec::new();
    sim.run(&mut |s: &Sample| {
        out.push(s.state.clone());
        Ok(())
    })
    .expect("runs");
    out
}

fn check(file: &str, overrides: &[&str]) {
    let whole = outputs(&mut common::example_simulation(file, overrides));
    let t_end = whole.last().expect("outputs").t;
    let mid = 0.5 * t_end;
    // Interrupted once an output at or after mid-time is written.
    let mut sim = common::example_simulation(file, overrides);
    let flag = Arc::new(AtomicBool::new(false));
    sim.interrupt = Some(flag.clone());
    let mut first = Vec::new();
    let result = sim.run(&mut |s: &Sample| {
        first.push(s.state.clone());
        if s.state.t >= mid {
            flag.store(true, Ordering::Relaxed);
        }
        Ok(())
    });
    assert!(
        matches!(result, Err(SolveError::Interrupted { .. })),
        "{file}: {result:?}"
    );
    let json = serde_json::to_string(&sim.checkpoint()).expect("serializes");
    drop(sim);
    let checkpoint: Checkpoint = serde_json::from_str(&json).expect("reads back");
    let mut resumed = Simulation::resume(checkpoint, t_end).expect("resumes");
    let second = outputs(&mut resumed);
    let joined: Vec<State> = first.into_iter().chain(second).collect();
    let times = |v: &[State]| v.iter().map(|s| s.t).collect::<Vec<_>>();
    assert_eq!(times(&joined), times(&whole), "{file}: output times");
    for (a, b) in joined.iter().zip(&whole) {
        assert_eq!(a, b, "{file}: state at t = {} differs", b.t);
    }
}

#[test]
fn resumed_heavy_top_matches_the_uninterrupted_run() {
    check("heavy_top.toml", &["solver.t_end=0.5"]);
}

#[test]
fn resumed_stabilized_run_matches_the_uninterrupted_run() {
    check(
        "heavy_top_r3so3.toml",
        &["solver.t_end=0.5", "solver.formulation=index2"],
    );
}

#[test]
fn resumed_closed_loop_with_redundant_rows_matches_the_uninterrupted_run() {
    check("bricard.toml", &["solver.t_end=2"]);
}

#[test]
fn resumed_beam_run_matches_the_uninterrupted_run() {
    check("spin_up.toml", &["solver.t_end=2"]);
}

#[test]
fn resumed_run_with_element_states_and_a_rope_matches_the_uninterrupted_run() {
    // The Maxwell branch's state, its rate and algorithmic rate go through the checkpoint.
    check("viscoelastic_mount.toml", &["solver.t_end=2"]);
    check("block_and_tackle.toml", &["solver.t_end=0.3"]);
}

/// A run extended past an end that is not an output time goes on to the next output time
/// (none is skipped).
#[test]
fn extended_run_keeps_every_output_time() {
    let mut sim = common::example_simulation("heavy_top.toml", &["solver.t_end=0.255"]);
    outputs(&mut sim);
    assert_eq!(sim.state.t, 0.255);
    let mut resumed = Simulation::resume(sim.checkpoint(), 0.3).expect("resumes");
    let times: Vec<f64> = outputs(&mut resumed).iter().map(|s| s.t).collect();
    assert_eq!(times.len(), 5, "{times:?}");
    assert!(
        (times[0] - 0.26).abs() < 1e-12 && times[4] == 0.3,
        "{times:?}"
    );
}

/// A checkpoint whose element states do not fit the model (a damaged or edited file; serde
/// reads missing vectors as empty) is refused, not taken for a run that would panic later.
#[test]
fn restore_refuses_element_states_that_do_not_fit() {
    let mut sim = common::example_simulation("viscoelastic_mount.toml", &["solver.t_end=0.1"]);
    sim.step().expect("step");
    for damage in 0..3 {
        let mut memory = sim.memory();
        match damage {
            0 => memory.state.x.clear(),
            1 => memory.state.xdot.push(0.0),
            _ => memory.state.w.clear(),
        }
        let result = Simulation::restore(sim.model.clone(), sim.settings, memory);
        assert!(
            matches!(&result, Err(SolveError::Checkpoint(m)) if m.contains("does not fit")),
            "damage {damage}: {:?}",
            result.err()
        );
    }
}
