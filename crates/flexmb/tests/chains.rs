//! N-link pendulum chains (the scaling benchmark): they run for every rho_inf in
//! {0, 0.5, 0.9, 1}, keep the constraints, and lose energy only through the scheme's
//! numerical dissipation (none at rho_inf = 1). The 1000-link chain is a benchmark
//! (BENCHMARKS.md), not a test.

mod common;
use common::run;

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
