//! N-link pendulum chains (the scaling benchmark): they run for every rho_inf in
//! {0, 0.5, 0.9, 1}, keep the constraints, and lose energy only through the scheme's
//! numerical dissipation (none at rho_inf = 1). The 1000-link chain is a benchmark
//! (BENCHMARKS.md), not a test; what a chain costs to set up grows linearly with its links.

use crate::common::run;
use flexmb::model::{JointKind, Model};
use flexmb::{DynamicSettings, Simulation};
use flexmb_lie::{Frame, Group, Mat3, Vec3};

#[test]
fn chain_runs_for_every_rho_inf() {
    for rho in ["0.0", "0.5", "0.9", "1.0"] {
        let run = run("chain_10.toml", &[&format!("solver.rho_inf={rho}")]);
        assert_eq!(run.stats.steps, 1000, "rho_inf = {rho}");
        let e = run.series("energy");
        let e0 = e[0].1;
        assert!(e0.abs() < 1e-12, "straight horizontal chain at rest: E = 0");
        // Energy never grows (beyond round-off) and, at rho_inf = 1, stays within 1e-3 J.
        let max = e.iter().fold(f64::MIN, |m, (_, v)| m.max(*v));
        assert!(max < 1e-6, "rho_inf = {rho}: energy grew to {max}");
        let loss = -e.last().expect("rows").1;
        if rho == "1.0" {
            assert!(loss.abs() < 2e-2, "rho_inf = 1: energy change {loss}");
        }
        assert!(
            run.series("violation").iter().all(|(_, v)| *v < 1e-9),
            "rho_inf = {rho}"
        );
        // The tip falls (gravity along -y).
        assert!(run.last("tip_y") < -1.0, "rho_inf = {rho}");
    }
}

#[test]
fn chain_of_100_links_runs() {
    let run = run("chain_100.toml", &["solver.t_end=0.1"]);
    assert_eq!(run.stats.steps, 100);
    assert!(run.series("violation").iter().all(|(_, v)| *v < 1e-9));
}

/// The chain of `examples/chain_*.toml` with `n` links: 1 m x 0.1 m x 0.1 m boxes of 1 kg
/// end to end along x, revolute joints about z, the first to the ground.
fn chain(n: usize) -> Model {
    let mut model = Model::new(Group::SE3);
    model.gravity = Vec3::new(0.0, -9.81, 0.0);
    let inertia = Mat3::from_diagonal(&Vec3::new(0.02, 1.01, 1.01)) / 12.0;
    let mut parent = None;
    for i in 0..n {
        let x = i as f64;
        let centre = Frame::new(Vec3::new(x + 0.5, 0.0, 0.0), Mat3::identity());
        let node = model.add_node(&format!("link{i}"), centre);
        model.add_body(&format!("link{i}"), node, 1.0, Vec3::zeros(), inertia);
        model.add_joint(
            &format!("j{i}"),
            JointKind::Revolute,
            parent,
            Some(node),
            Vec3::new(x, 0.0, 0.0),
            Mat3::identity(),
            None,
        );
        parent = Some(node);
    }
    model
}

/// What `flexmb check` sets up for a chain (layout, the iteration matrix's pattern, the
/// block LU's structure, the consistent initial accelerations) at 2000 and 8000 links: the
/// structures grow 4 times and the smallest pivot's margin to the singularity rule does not
/// shrink. It shrank as `n^-3` (a joint's multiplier pivots against their column of `A`,
/// against the articulated inertia of the links beyond it), so that from 31 000 links on
/// the block LU handed the matrix to the general sparse LU: twice the set-up's time and
/// memory (11 kB per link), and time growing faster than the chain.
#[test]
fn chain_set_up_grows_linearly_with_its_links() {
    let set_up = |n: usize| {
        let sim = Simulation::new(chain(n), DynamicSettings::new(1.0, 1e-3)).expect("starts");
        let solver = &sim.data.solver;
        (
            sim.data.values.len() as f64,
            solver.nnz() as f64,
            solver.pivot_margin().expect("factorized"),
        )
    };
    let (pattern, stored, margin) = set_up(2000);
    let (pattern_4, stored_4, margin_4) = set_up(8000);
    assert!(pattern_4 <= 4.01 * pattern, "{pattern} -> {pattern_4}");
    assert!(stored_4 <= 4.01 * stored, "{stored} -> {stored_4}");
    assert!(
        margin_4 >= 0.5 * margin,
        "pivot margin {margin:e} -> {margin_4:e}"
    );
}
