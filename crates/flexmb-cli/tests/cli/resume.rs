//! `--checkpoint-interval` and `--resume`: a run continued from its checkpoint writes the
//! same result files, byte for byte, as a run that was never stopped; a checkpoint of
//! another model is refused.

use crate::common;

use crate::common::{flexmb, out_dir, repo, rows, summary};
use std::path::Path;

fn run(args: &[&str], out: &Path) -> std::process::Output {
    flexmb()
        .args([
            "run",
            repo("examples/heavy_top.toml").to_str().unwrap(),
            "--quiet",
        ])
        .args(args)
        .arg(out)
        .output()
        .expect("runs")
}

fn read(dir: &Path, name: &str) -> String {
    std::fs::read_to_string(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn a_run_resumed_from_its_checkpoint_writes_the_files_of_an_uninterrupted_run() {
    let whole = out_dir("resume-whole");
    let r = run(&["--set", "solver.t_end=0.4", "--out"], &whole);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // The same run to mid-time, with checkpoints (the last one at its end)...
    let part = out_dir("resume-part");
    let r = run(
        &[
            "--set",
            "solver.t_end=0.2",
            "--checkpoint-interval",
            "0.1",
            "--out",
        ],
        &part,
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(part.join("checkpoint.json").exists());
    // ... resumed to the end.
    let r = run(&["--set", "solver.t_end=0.4", "--resume"], &part);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    for name in ["sensors.csv", "nodes.csv"] {
        assert!(read(&part, name) == read(&whole, name), "{name} differs");
    }
    // The results file is cut back to the checkpoint and continued too.
    let results = |d: &Path| flexmb_results::h5::read(d).expect("results.h5 reads");
    let (a, b) = (results(&whole), results(&part));
    assert_eq!(a.snapshots.len(), 41);
    assert_eq!(a.steps.len(), 4000);
    assert!(a == b, "results.h5 differs");
    let (a, b) = (summary(&whole), summary(&part));
    for key in [
        "status",
        "steps",
        "newton_iterations",
        "rejected_steps",
        "outputs",
        "t_reached",
    ] {
        assert_eq!(a[key], b[key], "{key}");
    }
}

#[test]
fn an_interrupted_run_resumes_to_the_results_of_an_uninterrupted_one() {
    let out = out_dir("resume-signal");
    let mut child = common::start_long_run(&out, 20);
    common::send_signal(&child, "INT");
    common::wait_for(&mut child);
    assert!(
        out.join("checkpoint.json").exists(),
        "an interrupted run writes a checkpoint"
    );
    let t_reached = summary(&out)["t_reached"].as_f64().unwrap();
    let t_end = format!("solver.t_end={}", t_reached + 0.25);
    let pendulum = repo("examples/pendulum.toml");
    let resumed = flexmb()
        .args([
            "run",
            pendulum.to_str().unwrap(),
            "--quiet",
            "--set",
            &t_end,
            "--resume",
        ])
        .arg(&out)
        .output()
        .expect("runs");
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let whole = out_dir("resume-signal-whole");
    let r = flexmb()
        .args([
            "run",
            pendulum.to_str().unwrap(),
            "--quiet",
            "--set",
            &t_end,
            "--out",
        ])
        .arg(&whole)
        .output()
        .expect("runs");
    assert!(r.status.success());
    assert_eq!(
        rows(&out.join("sensors.csv")),
        rows(&whole.join("sensors.csv"))
    );
    assert_eq!(rows(&out.join("nodes.csv")), rows(&whole.join("nodes.csv")));
}

#[test]
fn resume_refuses_the_checkpoint_of_another_model() {
    let part = out_dir("resume-other");
    let r = run(
        &[
            "--set",
            "solver.t_end=0.05",
            "--checkpoint-interval",
            "0.05",
            "--out",
        ],
        &part,
    );
    assert!(r.status.success());
    let r = run(
        &[
            "--set",
            "solver.t_end=0.1",
            "--set",
            "body.top.mass=20",
            "--resume",
        ],
        &part,
    );
    assert_eq!(r.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(stderr.contains("the model differs"), "{stderr}");
}

/// A resumed run says what the run it continues said about the model (here the redundant
/// rows of the Bricard mechanism's closed loop).
#[test]
fn a_resumed_run_keeps_the_notes_on_the_model() {
    let bricard = repo("examples/bricard.toml");
    let go = |args: &[&str], dir: &Path| {
        let r = flexmb()
            .args(["run", bricard.to_str().unwrap(), "--quiet"])
            .args(args)
            .arg(dir)
            .output()
            .expect("runs");
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    };
    let whole = out_dir("resume-notes-whole");
    go(&["--set", "solver.t_end=0.2", "--out"], &whole);
    let part = out_dir("resume-notes-part");
    go(
        &[
            "--set",
            "solver.t_end=0.1",
            "--checkpoint-interval",
            "0.1",
            "--out",
        ],
        &part,
    );
    go(&["--set", "solver.t_end=0.2", "--resume"], &part);
    let notes = summary(&whole)["notes"].clone();
    assert!(notes.as_array().is_some_and(|w| !w.is_empty()));
    assert_eq!(summary(&part)["notes"], notes);
}
