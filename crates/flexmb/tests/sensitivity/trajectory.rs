//! The trajectory store for a backward sweep: checkpoints every k steps and the steps in
//! between recomputed give exactly (bit for bit) the steps a store of every step keeps, in
//! reverse order; and each stored step is consistent with the step as a function (its
//! unknowns solve the step residual and give the next step's start, the run's last state
//! for the last step).

use crate::common;

use flexmb::data::Layout;
use flexmb::observe::Observers;
use flexmb::solve::linear::LinearSolver;
use flexmb::solve::step::StepFunction;
use flexmb::solve::trajectory::{Trajectory, TrajectoryStep};
use flexmb::Data;

fn backward(t: &Trajectory) -> Vec<TrajectoryStep> {
    let mut out = Vec::new();
    t.backward(&mut |s| {
        out.push(s.clone());
        Ok(())
    })
    .expect("recomputes");
    out
}

fn check(file: &str, overrides: &[&str]) {
    check_simulation(file, common::example_simulation(file, overrides));
}

/// Returns how many times the redundant rows changed along the run.
fn check_simulation(file: &str, mut sim: flexmb::Simulation) -> usize {
    let mut all = Trajectory::new(&sim, 1);
    let mut sparse = Trajectory::new(&sim, 7);
    sim.run(&mut Observers(vec![&mut all, &mut sparse]))
        .expect("runs");
    let n = sim.stats.steps;
    assert_eq!(all.len(), n);
    assert_eq!(
        sparse.checkpoints(),
        n / 7 + 1,
        "{file}: memory bounded by n / k"
    );
    let (a, b) = (backward(&all), backward(&sparse));
    assert_eq!(a.len(), n);
    assert_eq!(a, b, "{file}: recomputed steps differ from stored ones");
    let indices: Vec<usize> = a.iter().map(|s| s.index).collect();
    assert_eq!(indices, (1..=n).rev().collect::<Vec<_>>());
    // Each step against the step function, in the layout of its own redundant rows.
    let rows_changed: Vec<&TrajectoryStep> = a
        .windows(2)
        .filter(|w| w[0].redundant_rows != w[1].redundant_rows)
        .map(|w| &w[0])
        .collect();
    let changes = rows_changed.len();
    // The end of a step is the next one's start (the run's last state for the last).
    let end_of = |s: &TrajectoryStep| {
        let n = a.len() - s.index;
        if n == 0 {
            sim.state.clone()
        } else {
            a[n - 1].start.clone()
        }
    };
    for s in a.iter().step_by(5).chain(rows_changed) {
        let recorded = end_of(s);
        let stabilized = sim.settings.stabilized();
        let layout = Layout::with_rows(&sim.model, stabilized, &s.redundant_rows);
        let mut data = Data::new(&sim.model, layout.clone()).expect("data");
        let f = StepFunction::new(&sim.model, &layout, &s.start, &sim.settings, s.h);
        let end = f.end_state(&s.unknowns);
        for (p, q) in end.q.iter().zip(&recorded.q) {
            assert!(
                (p.x - q.x).norm() < 1e-12 * (1.0 + q.x.norm()),
                "{file}: step {}",
                s.index
            );
        }
        for (p, q) in end.v.iter().zip(&recorded.v) {
            assert!(
                (p - q).norm() < 1e-9 * (1.0 + q.norm()),
                "{file}: step {}",
                s.index
            );
        }
        // The Newton correction from the stored unknowns with the exact Jacobian is within
        // the tolerance: the unknowns solve the step.
        let r = f.residual(&s.unknowns, &mut data);
        let jacobian = f.jacobian(&s.unknowns, &mut data);
        let pattern: Vec<(usize, usize)> = jacobian.iter().map(|&(i, j, _)| (i, j)).collect();
        let values: Vec<f64> = jacobian.iter().map(|&(_, _, v)| v).collect();
        let mut solver = LinearSolver::new(r.len(), &pattern).expect("pattern");
        solver.factorize(&values).expect("regular");
        let mut dx: Vec<f64> = r.iter().map(|v| -v).collect();
        solver.solve_in_place(&mut dx);
        let nd = layout.n_dofs;
        let dq = dx[..nd].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let q = s.unknowns[..nd].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let rtol = sim.settings.newton.rtol;
        assert!(
            dq <= rtol * q,
            "{file}: step {}: correction {dq:e} of {q:e}",
            s.index
        );
    }
    changes
}

#[test]
fn checkpointed_trajectory_replays_the_heavy_top_steps_exactly() {
    check("heavy_top.toml", &["solver.t_end=0.1"]);
}

#[test]
fn checkpointed_trajectory_replays_a_stabilized_chain_exactly() {
    check(
        "chain_10.toml",
        &["solver.t_end=0.1", "solver.formulation=index2"],
    );
}

/// The Lie algebra updates: the run's Newton iteration (right-trivialized corrections in the
/// step's chart) and the step function (closed form) reach the same end from the same
/// unknowns, and the unknowns solve the step function's residual.
#[test]
fn lie_algebra_updates_run_the_steps_of_the_step_function() {
    for update in ["lie_algebra", "lie_algebra_r3xso3"] {
        let set = format!("solver.lie_update={update}");
        check("heavy_top.toml", &["solver.t_end=0.1", &set]);
        check("heavy_top_r3so3.toml", &["solver.t_end=0.1", &set]);
        check(
            "chain_10.toml",
            &["solver.t_end=0.1", "solver.formulation=index2", &set],
        );
    }
}

/// The Bricard mechanism with each rod's node at its first joint chooses its redundant rows
/// again at t = 1.152 s: the steps around it keep the layout they were taken in.
#[test]
fn checkpointed_trajectory_replays_steps_across_a_change_of_redundant_rows() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/bricard_nodes_at_joints.toml");
    let mf = flexmb::input::read_model_file(&path, &["solver.t_end=1.2".to_string()])
        .expect("model file");
    let flexmb::input::Analysis::Dynamic(settings) = mf.analysis else {
        unreachable!()
    };
    let sim = flexmb::Simulation::new(mf.model, settings).expect("starts");
    let changes = check_simulation("bricard_nodes_at_joints.toml", sim);
    assert_eq!(
        changes, 1,
        "the rows are chosen again once before t = 1.2 s"
    );
}
