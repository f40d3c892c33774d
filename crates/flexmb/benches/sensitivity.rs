//! Sensitivity benchmarks behind BENCHMARKS.md: the cost of the gradients of one criterion
//! relative to one forward run, for 1, 10 and 100 parameters, by direct differentiation and
//! by the discrete adjoint (finite differences cost `2 n_p + 1` runs by construction), and
//! the adjoint's memory with checkpoints under a budget. Release build, one thread
//! (`FLEXMB_THREADS=n` for another count), and the two methods again on two threads.
//!
//! ```text
//! cargo bench -p flexmb --bench sensitivity                  # all cases, each in its own process
//! cargo bench -p flexmb --bench sensitivity -- chain_100     # one case
//! ```

use flexmb::input::read_model_file;
use flexmb::model::{ParamRole, Parameters};
use flexmb::sensitivity::{self, CriteriaSet, Criterion, CriterionKind, Problem};
use std::sync::Arc;
use std::time::Instant;

mod common;
use common::peak_memory_mb;

const CASES: &[&str] = &[
    "right_angle_cantilever",
    "chain_100",
    "memory_256",
    "memory_16",
    "memory_14",
];

/// The example `file` with one criterion `expression` (integral) and the first `n` design
/// parameters of `prefix` (paths starting with it, in registry order).
fn problem(file: &str, set: &[&str], expression: &str, prefix: &str, n: usize) -> Problem {
    problem_on(file, set, expression, prefix, n, thread_count())
}

/// [`problem`] on `threads` threads.
fn problem_on(
    file: &str,
    set: &[&str],
    expression: &str,
    prefix: &str,
    n: usize,
    threads: usize,
) -> Problem {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(file);
    let mut set: Vec<String> = set.iter().map(|s| s.to_string()).collect();
    set.push(format!("solver.threads={threads}"));
    let f = read_model_file(&path, &set).expect("model");
    let model = Arc::new(f.model);
    let params = Parameters::new(&model);
    let design: Vec<_> = params
        .ids()
        .filter(|&id| params.role(id) == ParamRole::Residual && params.path(id).starts_with(prefix))
        .take(n)
        .collect();
    assert_eq!(design.len(), n, "{file}: {n} parameters of '{prefix}'");
    let c =
        Criterion::new(&model, &[], "J", CriterionKind::Integral, expression).expect("criterion");
    let criteria = CriteriaSet::new(&model, Vec::new(), vec![c]);
    Problem::new(model, f.analysis, design, criteria)
}

/// The number of threads of this run: `FLEXMB_THREADS`, else one.
fn thread_count() -> usize {
    std::env::var("FLEXMB_THREADS").map_or(1, |n| n.parse().expect("FLEXMB_THREADS: a number"))
}

/// Seconds of the fastest of `runs` calls of `f`.
fn best<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = None;
    let mut time = f64::INFINITY;
    for _ in 0..runs {
        let t0 = Instant::now();
        let r = f();
        time = time.min(t0.elapsed().as_secs_f64());
        out = Some(r);
    }
    (time, out.expect("one run"))
}

fn costs(case: &str, file: &str, counts: &[usize], expression: &str, prefix: &str) {
    println!("| case | n_p | forward [ms] | direct [ms] | direct / forward | adjoint [ms] | adjoint / forward | adjoint, workspace kept / forward | direct, 2 threads / forward | adjoint, 2 threads / forward | fd / forward | direct-adjoint |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    // `FLEXMB_NP=n` measures one count only (for profiling).
    let only: Option<usize> = std::env::var("FLEXMB_NP")
        .ok()
        .map(|v| v.parse().expect("FLEXMB_NP"));
    for &n in counts.iter().filter(|&&n| only.is_none_or(|o| o == n)) {
        let p = problem(file, &[], expression, prefix, n);
        let (forward, _) = best(3, || sensitivity::criteria_values(&p).expect("run"));
        // `FLEXMB_METHOD=direct|adjoint|adjoint_kept` runs that method only (for
        // profiling; `adjoint_kept`: the second of two calls with one workspace).
        if let Ok(method) = std::env::var("FLEXMB_METHOD") {
            let mut workspace = sensitivity::Workspace::default();
            let adjoint = |w: &mut sensitivity::Workspace| {
                sensitivity::adjoint_in(&p, w, &mut |_, _| {}).expect("adjoint")
            };
            if method == "adjoint_kept" {
                adjoint(&mut workspace);
            }
            let t0 = Instant::now();
            let stats = match method.as_str() {
                "direct" => sensitivity::direct(&p).expect("direct").stats,
                "adjoint" | "adjoint_kept" => adjoint(&mut workspace).stats,
                _ => panic!("FLEXMB_METHOD: direct, adjoint or adjoint_kept"),
            };
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            println!(
                "{case}, {n} parameters, {method}: {ms:.1} ms ({:.2} forward runs; forward run {:.2}, sweep {:.2})",
                ms / (forward * 1e3),
                stats.forward_seconds / forward,
                stats.sweep_seconds / forward,
            );
            continue;
        }
        let (direct, d) = best(3, || sensitivity::direct(&p).expect("direct"));
        let (adjoint, a) = best(3, || {
            sensitivity::adjoint(&p, &mut |_, _| {}).expect("adjoint")
        });
        // An optimizer's repeated calls: the workspace (scratch, symbolic analysis,
        // trajectory storage) kept from the first call.
        let mut workspace = sensitivity::Workspace::default();
        let (kept, _) = best(4, || {
            sensitivity::adjoint_in(&p, &mut workspace, &mut |_, _| {}).expect("adjoint")
        });
        // The same on two threads (the steps' Jacobians prepared ahead of the chain), against
        // the same forward run (on one thread: a model this size gains nothing from more).
        let p2 = problem_on(file, &[], expression, prefix, n, 2);
        let (direct2, d2) = best(3, || sensitivity::direct(&p2).expect("direct"));
        let (adjoint2, a2) = best(3, || {
            sensitivity::adjoint(&p2, &mut |_, _| {}).expect("adjoint")
        });
        assert_eq!(d2.gradients, d.gradients, "the same bits on two threads");
        assert_eq!(a2.gradients, a.gradients, "the same bits on two threads");
        let scale = d.gradients[0].iter().fold(1e-300f64, |m, v| m.max(v.abs()));
        let agree = d.gradients[0]
            .iter()
            .zip(&a.gradients[0])
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs() / scale));
        println!(
            "| {case} | {n} | {:.1} | {:.1} | {:.2} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {agree:.1e} |",
            forward * 1e3,
            direct * 1e3,
            direct / forward,
            adjoint * 1e3,
            adjoint / forward,
            kept / forward,
            direct2 / forward,
            adjoint2 / forward,
            2 * n + 1
        );
    }
}

fn run_case(case: &str) {
    match case {
        "right_angle_cantilever" => costs(
            case,
            "right_angle_cantilever.toml",
            &[1, 10, 75],
            "sq(tip_w)",
            "",
        ),
        "chain_100" => costs(case, "chain_100.toml", &[1, 10, 100], "sq(tip_x)", "body."),
        _ if case.starts_with("memory_") => {
            let budget: f64 = case["memory_".len()..].parse().expect("MB");
            if budget == 256.0 {
                println!("| case | budget [MB] | checkpoints | trajectory kept [MB] | peak memory [MB] | adjoint [ms] |");
                println!("|---|---|---|---|---|---|");
            }
            let mut p = problem("chain_100.toml", &[], "sq(tip_x)", "body.", 10);
            p.memory_budget = (budget * (1 << 20) as f64) as usize;
            let t0 = Instant::now();
            let a = sensitivity::adjoint(&p, &mut |_, _| {}).expect("adjoint");
            println!(
                "| chain_100, 1000 steps, 10 parameters | {budget} | {} | {:.2} | {:.1} | {:.1} |",
                a.stats.checkpoints,
                a.stats.trajectory_bytes as f64 / (1 << 20) as f64,
                peak_memory_mb(),
                t0.elapsed().as_secs_f64() * 1e3
            );
        }
        _ => panic!("unknown case {case}"),
    }
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    if let Some(case) = args.first() {
        run_case(case);
        return;
    }
    let exe = std::env::current_exe().expect("exe");
    for case in CASES {
        let status = std::process::Command::new(&exe)
            .arg(case)
            .status()
            .expect("child");
        assert!(status.success(), "{case}");
    }
}
