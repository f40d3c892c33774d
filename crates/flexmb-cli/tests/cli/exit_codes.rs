//! One exit code per class of outcome (README.md, "Exit status"), and one message per cause:
//! 0 success, 1 failed analysis (tests/cli/cli.rs), 2 invalid model (the same for `check` and
//! `run`, and for `sensitivity` and `optimize` before their first step), 3 results that
//! cannot be written, 4 an analysis stopped at a limit of its settings before its end, 64 a
//! wrong command line; signals in tests/cli/signals.rs.

use crate::common::{flexmb, out_dir, repo, rows, summary};
use std::path::Path;
use std::process::Output;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn run_pendulum(out: &Path) -> Output {
    flexmb()
        .args([
            "run",
            repo("examples/pendulum.toml").to_str().unwrap(),
            "--out",
        ])
        .arg(out)
        .args(["--set", "solver.t_end=0.05"])
        .output()
        .expect("runs")
}

#[test]
fn usage_errors_exit_64_and_help_exits_0() {
    let missing = flexmb().arg("run").output().unwrap();
    assert_eq!(missing.status.code(), Some(64), "{}", stderr(&missing));
    assert!(stderr(&missing).contains("<MODEL>"), "{}", stderr(&missing));
    let unknown = flexmb().args(["check", "--frobnicate"]).output().unwrap();
    assert_eq!(unknown.status.code(), Some(64));
    let help = flexmb().arg("--help").output().unwrap();
    assert_eq!(help.status.code(), Some(0));
    let text = String::from_utf8_lossy(&help.stdout);
    for code in ["0 ", "1 ", "2 ", "3 ", "4 ", "64 ", "128+n", "130 SIGINT"] {
        assert!(text.contains(code), "--help lists exit code {code}: {text}");
    }
    assert_eq!(
        flexmb().arg("--version").output().unwrap().status.code(),
        Some(0)
    );
}

#[test]
fn inconsistent_initial_velocity_exits_2_from_check_and_run() {
    let model = repo("crates/flexmb-cli/tests/data/inconsistent.toml");
    let velocity = "body.bob.velocity=[0.0, 1.0, 0.0]";
    let check = flexmb()
        .args(["check", model.to_str().unwrap(), "--set", velocity])
        .output()
        .unwrap();
    let out = out_dir("inconsistent-run");
    let run = flexmb()
        .args(["run", model.to_str().unwrap(), "--set", velocity, "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(check.status.code(), Some(2), "{}", stderr(&check));
    assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
    assert_eq!(stderr(&check), stderr(&run), "the same message");
    assert_eq!(stderr(&run).lines().count(), 1, "{}", stderr(&run));
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert_eq!(s["error_kind"], "model");
    assert!(!out.join("sensors.csv").exists(), "nothing was solved");
}

/// `flexmb COMMAND MODEL --out DIR ARGS...` of a model of the repository.
fn command(command: &str, model: &str, out: &Path, args: &[&str]) -> Output {
    flexmb()
        .args([command, repo(model).to_str().unwrap(), "--out"])
        .arg(out)
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn problems_before_the_first_step_exit_2_from_sensitivity_and_optimize_as_from_run() {
    // Before: exit 1 ("ran and failed") without the model file's name; the memory budget
    // in bytes.
    // Initial velocities that violate a joint: the heavy top's pivot, the half car's plane.
    let cases = [
        (
            "sensitivity",
            "examples/heavy_top_sensitivity.toml",
            "body.top.velocity=[0.0, 1.0, 0.0]",
        ),
        (
            "optimize",
            "examples/half_car.toml",
            "body.chassis.velocity=[0.0, 1.0, 0.0]",
        ),
    ];
    for (cmd, model, velocity) in cases {
        let set = ["--set", velocity, "--set", "solver.t_end=0.01"];
        let run = command(
            "run",
            model,
            &out_dir("ic-run"),
            &[&set[..], &["--no-plot"]].concat(),
        );
        assert_eq!(run.status.code(), Some(2), "{}", stderr(&run));
        assert!(
            stderr(&run).contains(".toml: inconsistent initial conditions"),
            "{}",
            stderr(&run)
        );
        let o = command(cmd, model, &out_dir("ic"), &set);
        assert_eq!(o.status.code(), Some(2), "{cmd}: {}", stderr(&o));
        assert_eq!(stderr(&o), stderr(&run), "{cmd}: the message of run");
    }
    // A memory budget too small (in MiB), no parameter with both bounds: one line naming
    // the model file.
    let top = "examples/heavy_top_sensitivity.toml";
    let cases: [(&str, &str, &[&str], &[&str]); 2] = [
        (
            "sensitivity",
            "examples/right_angle_cantilever_sensitivity.toml",
            &["--memory-mb", "1", "--set", "solver.h=1e-4"],
            &[
                "right_angle_cantilever_sensitivity.toml: sensitivity: the memory budget of 1 MiB",
                "it needs at least 11.6 MiB",
            ],
        ),
        (
            "optimize",
            top,
            &["--set", "solver.t_end=0.01"],
            &["heavy_top_sensitivity.toml: sensitivity: no design parameter has both"],
        ),
    ];
    for (cmd, model, args, expected) in cases {
        let o = command(cmd, model, &out_dir("refused"), args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{cmd} {args:?}: {err}");
        assert!(err.starts_with("error: "), "{err}");
        assert!(expected.iter().all(|x| err.contains(x)), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    // Every configuration update has exact gradients (the Lie algebra updates were refused
    // before their step had a Jacobian).
    let set = [
        "--set",
        "solver.lie_update=lie_algebra",
        "--set",
        "solver.t_end=0.01",
    ];
    let o = command("sensitivity", top, &out_dir("lie-algebra"), &set);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn unreadable_model_file_exits_2_and_states_its_cause_once() {
    let out = out_dir("no-model");
    let result = flexmb()
        .args(["run", "no/such/model.toml", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(result.status.code(), Some(2));
    let err = stderr(&result);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("no/such/model.toml: cannot read the model file"),
        "{err}"
    );
    let os_cause = "No such file or directory";
    assert_eq!(
        err.matches(os_cause).count(),
        1,
        "cause printed once: {err}"
    );
    let check = flexmb()
        .args(["check", "no/such/model.toml"])
        .output()
        .unwrap();
    assert_eq!(check.status.code(), Some(2));
    assert_eq!(
        stderr(&check).matches(os_cause).count(),
        1,
        "{}",
        stderr(&check)
    );
    let s = summary(&out);
    assert_eq!(s["error_kind"], "model");
}

#[test]
fn output_path_that_is_a_file_exits_3_not_a_directory() {
    let dir = out_dir("out-is-file");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("results");
    std::fs::write(&file, "mine").unwrap();
    let result = run_pendulum(&file);
    assert_eq!(result.status.code(), Some(3));
    let err = stderr(&result);
    assert_eq!(
        err.trim(),
        format!("error: {}: not a directory", file.display())
    );
    assert_eq!(
        std::fs::read_to_string(&file).unwrap(),
        "mine",
        "the file is untouched"
    );
}

#[test]
fn earlier_result_that_cannot_be_removed_exits_3() {
    let out = out_dir("unremovable");
    // A directory where the run's sensors.csv goes.
    std::fs::create_dir_all(out.join("sensors.csv/keep")).unwrap();
    let result = run_pendulum(&out);
    assert_eq!(result.status.code(), Some(3));
    let err = stderr(&result);
    assert!(
        err.contains("sensors.csv: cannot remove the earlier result"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
}

/// Runs the pendulum with the size of every file the process writes limited to `blocks`
/// 512-byte blocks (`ulimit -f` of sh, SIGXFSZ ignored so that writes past it fail with
/// EFBIG like on a full disk). At least 8 blocks hold the room a run keeps for its last
/// summary (4096 bytes).
#[cfg(unix)]
fn run_with_file_size_limit(out: &Path, blocks: u32) -> Output {
    run_model_with_file_size_limit(
        "examples/pendulum.toml",
        &["solver.t_end=0.05"],
        out,
        blocks,
    )
}

/// Runs a model of the repository with `--set` overrides and the size of every file the
/// process writes limited to `blocks` 512-byte blocks.
#[cfg(unix)]
fn run_model_with_file_size_limit(model: &str, set: &[&str], out: &Path, blocks: u32) -> Output {
    run_limited(model, &["--results", "none"], set, out, blocks)
}

/// [`run_model_with_file_size_limit`] with more arguments of `flexmb run` (`args`) and the
/// results file unless they say otherwise.
#[cfg(unix)]
fn run_limited(model: &str, args: &[&str], set: &[&str], out: &Path, blocks: u32) -> Output {
    std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f {blocks} || exit 99; exec \"$0\" \"$@\""
        ))
        .arg(env!("CARGO_BIN_EXE_flexmb"))
        .args(["run", repo(model).to_str().unwrap(), "--out"])
        .arg(out)
        .args(args)
        .args(set.iter().flat_map(|s| ["--set", s]))
        .output()
        .expect("sh runs")
}

/// An output step goes to every result file or to none: here nodes.csv (10 nodes a step)
/// reaches the size limit while sensors.csv has room for more rows, and sensors.csv is cut
/// back to the steps that nodes.csv holds (it kept one row more before).
#[cfg(unix)]
#[test]
fn full_disk_keeps_the_same_steps_in_every_result_file() {
    let out = out_dir("fsize-steps");
    let result = run_model_with_file_size_limit(
        "examples/chain_10.toml",
        &["solver.output_interval=0", "solver.t_end=0.01"],
        &out,
        8,
    );
    assert_eq!(result.status.code(), Some(3), "{}", stderr(&result));
    assert!(
        stderr(&result).contains("nodes.csv: cannot write"),
        "{}",
        stderr(&result)
    );
    let sensors = rows(&out.join("sensors.csv"));
    let nodes = rows(&out.join("nodes.csv"));
    assert!(!sensors.is_empty());
    assert_eq!(
        nodes.len(),
        10 * sensors.len(),
        "{} sensor rows",
        sensors.len()
    );
    let s = summary(&out);
    assert_eq!(s["outputs"].as_u64().unwrap() as usize, sensors.len());
    // complete up to the last step written (the solver had gone further)
    let last: f64 = sensors[sensors.len() - 1][0].parse().unwrap();
    assert_eq!(s["t_reached"].as_f64().unwrap(), last, "{s}");
}

/// A results file that cannot be written (here: created) ends the run with exit status 3
/// and one line naming it, as a CSV file would.
#[cfg(unix)]
#[test]
fn full_disk_on_the_results_file_exits_3_and_names_it() {
    let out = out_dir("fsize-h5");
    let result = run_limited("examples/pendulum.toml", &["--no-plot"], &[], &out, 8);
    assert_eq!(result.status.code(), Some(3), "{}", stderr(&result));
    let err = stderr(&result);
    assert!(err.contains("results.h5: cannot create"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert_eq!(s["error_kind"], "output");
}

#[cfg(unix)]
#[test]
fn full_disk_exits_3_keeps_complete_rows_and_says_so_in_the_summary() {
    let out = out_dir("fsize");
    let result = run_with_file_size_limit(&out, 8);
    assert_eq!(result.status.code(), Some(3), "{}", stderr(&result));
    let err = stderr(&result);
    assert!(err.contains("sensors.csv: cannot write"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert_eq!(s["error_kind"], "output");
    // Every row is complete (a partly written step is cut back), and the summary counts the
    // steps written to every file.
    let rows = rows(&out.join("sensors.csv"));
    assert!(!rows.is_empty());
    assert!(rows.iter().all(|r| r.len() == 7), "{rows:?}");
    assert!(std::fs::read_to_string(out.join("sensors.csv"))
        .unwrap()
        .ends_with('\n'));
    assert_eq!(s["outputs"].as_u64().unwrap() as usize, rows.len());
    // complete up to the last step written, not to the step the solver had reached
    let last: f64 = rows[rows.len() - 1][0].parse().unwrap();
    assert_eq!(s["t_reached"].as_f64().unwrap(), last, "{s}");
}

/// A run records its end in room kept for it when it starts: one that cannot keep that
/// room (here: files of at most one 512-byte block, under the 4096 bytes of the room) does
/// not start. It says why on one line and leaves nothing in the directory: no result file,
/// no partial summary (the failure itself, naming this long directory twice, does not fit
/// in a block either), no temporary file.
#[cfg(unix)]
#[test]
fn a_run_that_cannot_keep_room_for_its_last_summary_does_not_start() {
    let out = out_dir(&format!("fsize-summary-{}", "long-name-".repeat(12)));
    let result = run_with_file_size_limit(&out, 1);
    assert_eq!(result.status.code(), Some(3), "{}", stderr(&result));
    let err = stderr(&result);
    assert!(
        err.contains(".summary.json.room: cannot keep room for the last summary"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    let entries: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(entries.is_empty(), "{entries:?}");
}

/// A static analysis that has taken `max_steps` load steps before its final load factor
/// stops there, whatever its method: status `incomplete` (not `ok`, not `failed`), exit
/// status 4, a warning that names the limit and the setting to raise, and every converged
/// step in the files (arc length: examples/lee_frame.toml; load control:
/// examples/roll_up.toml).
#[test]
fn a_static_analysis_stopped_by_max_steps_exits_4_with_status_incomplete() {
    for (model, method) in [
        ("examples/lee_frame.toml", "arc-length continuation"),
        ("examples/roll_up.toml", "load control"),
    ] {
        let out = out_dir(&format!("incomplete-{method}").replace(' ', "-"));
        let result = flexmb()
            .args(["run", repo(model).to_str().unwrap(), "--out"])
            .arg(&out)
            .args(["--set", "solver.max_steps=3", "--results", "none"])
            .output()
            .expect("runs");
        let err = stderr(&result);
        assert_eq!(result.status.code(), Some(4), "{model}: {err}");
        let s = summary(&out);
        assert_eq!(s["status"], "incomplete", "{s}");
        assert!(s.get("error").is_none(), "{s}");
        assert_eq!(s["steps"], 3, "{s}");
        let warning = s["warnings"][0].as_str().unwrap();
        for part in [method, "max_steps = 3", "raise solver.max_steps"] {
            assert!(warning.contains(part), "{model}: {warning}");
        }
        assert!(err.contains(warning), "{err}");
        assert!(
            err.contains("incomplete: results up to load factor"),
            "{err}"
        );
        // The start and the three converged steps, the last at the load factor reached,
        // short of the final one.
        let sensors = rows(&out.join("sensors.csv"));
        assert_eq!(sensors.len(), 4, "{model}");
        assert_eq!(s["outputs"], 4);
        let last: f64 = sensors[3][0].parse().unwrap();
        assert_eq!(last, s["t_reached"].as_f64().unwrap());
        assert!(last < s["t_end"].as_f64().unwrap(), "{s}");
    }
}
