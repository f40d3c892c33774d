//! The `flexmb` command-line contract (README.md): `flexmb run MODEL --out DIR [--set ...]`
//! writes `sensors.csv` (header `time,<sensor names>`, rows as the run goes) and
//! `summary.json`; a failed run keeps its rows, says why and exits 1; a bad model file is
//! reported with file, line and field. Exit codes, signals, broken pipes and the output
//! directory have their own test files.

use crate::common::{flexmb, out_dir, repo, summary};

#[test]
fn run_writes_sensors_and_summary() {
    let out = out_dir("ok");
    let status = flexmb()
        .args([
            "run",
            repo("examples/pendulum.toml").to_str().unwrap(),
            "--out",
        ])
        .arg(&out)
        .args([
            "--set",
            "solver.t_end=0.1",
            "--set",
            "solver.output_interval=0.01",
        ])
        .status()
        .expect("runs");
    assert!(status.success());
    let csv = std::fs::read_to_string(out.join("sensors.csv")).expect("csv");
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("time,x,y,angle,energy,reaction_x,reaction_y")
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 11, "t = 0, 0.01, ..., 0.1");
    // The time column in its shortest exact form.
    assert!(rows[10].starts_with("0.1,"), "{}", rows[10]);
    // The deformed shape: one row per node and output step.
    let nodes = std::fs::read_to_string(out.join("nodes.csv")).expect("nodes.csv");
    assert_eq!(nodes.lines().next(), Some("time,node,x,y,z,qw,qx,qy,qz"));
    assert_eq!(nodes.lines().count(), 1 + 11);
    let s = summary(&out);
    assert_eq!(s["status"], "ok");
    assert_eq!(s["steps"], 100);
    assert!(s["newton_iterations"].as_u64().unwrap() >= 100);
    assert_eq!(s["rejected_steps"], 0);
    assert!(s["wall_seconds"].as_f64().unwrap() > 0.0);
}

#[test]
fn failed_run_keeps_its_rows_and_says_why() {
    let out = out_dir("fail");
    let result = flexmb()
        .args([
            "run",
            repo("crates/flexmb-cli/tests/data/blows_up.toml")
                .to_str()
                .unwrap(),
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("runs");
    assert_eq!(result.status.code(), Some(1), "the analysis failed");
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("Newton failed at step"), "{stderr}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert_eq!(s["error_kind"], "analysis");
    let error = s["error"].as_str().unwrap();
    let t: f64 = error
        .split("t = ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .expect("time in the diagnosis");
    assert!((0.054..=0.055).contains(&t), "{error}");
    assert!(error.contains("worst equation"), "{error}");
    assert!(
        error.contains("node 'bob'") || error.contains("joint 'pivot'"),
        "{error}"
    );
    assert!(
        s["rejected_steps"].as_u64().unwrap() > 0,
        "step-size reduction was tried"
    );
    let csv = std::fs::read_to_string(out.join("sensors.csv")).expect("csv");
    // t = 0, 0.01, ..., 0.05 were completed before the blow-up.
    assert_eq!(csv.lines().count(), 1 + 6, "{csv}");
    assert_eq!(s["outputs"], 6);
    // The results file has them too: the run waits for its writer thread.
    let r = flexmb_results::h5::read(&out).expect("the results file of a failed run reads");
    assert_eq!(r.snapshots.len(), 6);
    assert!(
        s["steps"].as_u64().unwrap() >= 50,
        "the counts of the work done"
    );
}

#[test]
fn bad_model_file_names_file_line_and_field() {
    let dir = out_dir("bad");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("bad.toml");
    std::fs::write(
        &file,
        "flexmb = 1\n[model]\ngroup = \"SE3\"\n[solver]\nanalysis = \"dynamic\"\nt_end = 1.0\nh = 1e-3\n[[body]]\nname = \"b\"\nmass = -2.0\ninertia = [1.0, 1.0, 1.0]\n",
    )
    .unwrap();
    let result = flexmb()
        .args(["run", file.to_str().unwrap(), "--out"])
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert_eq!(result.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("bad.toml:10:"), "{stderr}");
    assert!(stderr.contains("mass"), "{stderr}");
    // The output directory describes the rejected run.
    let s = summary(&dir.join("out"));
    assert_eq!(s["status"], "failed");
    assert_eq!(s["error_kind"], "model");
    assert!(s["error"].as_str().unwrap().contains("bad.toml:10:"), "{s}");
}

#[test]
fn inconsistent_initial_conditions_are_reported() {
    let out = out_dir("inconsistent");
    let model = repo("crates/flexmb-cli/tests/data/inconsistent.toml");
    // Consistent as written; a velocity of the pinned node violates the joint.
    let ok = flexmb()
        .args(["check", model.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let result = flexmb()
        .args(["run", model.to_str().unwrap(), "--out"])
        .arg(&out)
        .args(["--set", "body.bob.velocity=[0.0, 1.0, 0.0]"])
        .output()
        .unwrap();
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("inconsistent initial conditions") && stderr.contains("'pivot'"),
        "{stderr}"
    );
    assert!(stderr.contains("velocit"), "{stderr}");
}

/// `--verify` re-checks every accepted step with a fresh matrix and reports the largest
/// estimated error (in units of the Newton tolerance) on the closing line and in
/// summary.json; the free body of the trust issue (reused matrix by default) passes it.
#[test]
fn verify_reports_the_largest_error_of_an_accepted_step() {
    let out = out_dir("verify");
    let result = flexmb()
        .args([
            "run",
            repo("crates/flexmb-cli/tests/data/free_body.toml")
                .to_str()
                .unwrap(),
            "--verify",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("runs");
    assert!(result.status.success());
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(stdout.contains("verify: 400 steps re-checked"), "{stdout}");
    let s = summary(&out);
    let v = &s["verify"];
    assert_eq!(v["steps"], 400);
    let max = v["max_error"].as_f64().expect("a number");
    assert!(max > 0.0 && max <= 1.0, "{v}");
    assert!(
        v["worst_equation"].as_str().unwrap().contains("node 'b'"),
        "{v}"
    );
    // Without the flag there is no verify entry.
    let plain = out_dir("verify-off");
    let status = flexmb()
        .args([
            "run",
            repo("crates/flexmb-cli/tests/data/free_body.toml")
                .to_str()
                .unwrap(),
            "--out",
        ])
        .arg(&plain)
        .status()
        .expect("runs");
    assert!(status.success());
    assert!(summary(&plain).get("verify").is_none());
}

#[test]
fn run_threads_write_the_same_bytes() {
    // 150 + 150 beam elements: above the size below which a model stays sequential.
    let run = |threads: &str| {
        let out = out_dir(&format!("threads_{threads}"));
        let status = flexmb()
            .args([
                "run",
                repo("examples/right_angle_cantilever.toml")
                    .to_str()
                    .unwrap(),
                "--out",
            ])
            .arg(&out)
            .args([
                "--set",
                "beam.0.elements=150",
                "--set",
                "beam.1.elements=150",
                "--set",
                "solver.t_end=1.5",
                "--threads",
                threads,
            ])
            .status()
            .expect("runs");
        assert!(status.success());
        ["sensors.csv", "nodes.csv", "beams.csv"]
            .map(|f| std::fs::read(out.join(f)).expect("result file"))
    };
    assert!(run("1") == run("2"), "the result files differ");
    let status = flexmb()
        .args(["run", repo("examples/pendulum.toml").to_str().unwrap()])
        .args(["--threads", "2000"])
        .status()
        .expect("runs");
    assert_eq!(
        status.code(),
        Some(64),
        "a thread count out of range is a usage error"
    );
}

/// Runs `flexmb run MODEL ARGS --out OUT`, which must succeed without a warning and say one
/// note, on stdout and in summary.json; returns the note.
fn the_one_note_of_a_run(model: &str, args: &[&str], out: &std::path::Path) -> String {
    let r = flexmb()
        .args(["run", repo(model).to_str().unwrap()])
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("runs");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&r.stdout),
        String::from_utf8_lossy(&r.stderr),
    );
    assert!(r.status.success(), "{stderr}");
    assert!(!stderr.contains("warning:"), "{stderr}");
    let notes: Vec<&str> = stdout
        .lines()
        .filter_map(|l| l.strip_prefix("note: "))
        .collect();
    assert_eq!(notes.len(), 1, "{stdout}");
    let s = summary(out);
    assert_eq!(s["status"], "ok");
    assert!(s.get("warnings").is_none(), "{s}");
    assert_eq!(s["notes"], serde_json::json!(notes));
    notes[0].to_string()
}

/// Redundant constraint rows are expected of closed loops built with spatial joints: one
/// note per run naming them, no warning (Andrews' mechanism printed 9 warning lines, one
/// per row left out).
#[test]
fn redundant_constraints_are_one_note_not_warnings() {
    let note = the_one_note_of_a_run(
        "examples/andrews.toml",
        &["--set", "solver.t_end=0.001", "--no-plot"],
        &out_dir("andrews-notes"),
    );
    assert!(
        note.contains("9 of the 50 constraint rows are redundant"),
        "{note}"
    );
    assert!(note.contains("revolute joint 'E_K2_K3', row 4"), "{note}");
}

/// A run that succeeds without writing its summary plot says why, on the terminal and in
/// summary.json (a single body without sensors wrote no summary.png and said so only on the
/// terminal).
#[test]
fn run_without_sensors_says_why_it_draws_no_summary_plot() {
    let out = out_dir("no-sensors");
    let note = the_one_note_of_a_run("crates/flexmb-cli/tests/data/falling_body.toml", &[], &out);
    assert!(!out.join("summary.png").exists());
    assert!(
        note.contains("no sensors") && note.contains("no summary.png"),
        "{note}"
    );
}
