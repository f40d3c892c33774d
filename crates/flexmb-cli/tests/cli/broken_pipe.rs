//! A closed stdout or stderr never makes `flexmb` panic (exit 101): the message is lost, the
//! exit code still says what happened (README.md, "The `flexmb` command").
//!
//! Each child gets a pipe whose reading end is closed before it starts, so its first write
//! fails with EPIPE (Rust ignores SIGPIPE).

use crate::common::{flexmb, out_dir, repo, summary};
use std::process::{Command, Output, Stdio};

/// A pipe with no reader.
fn closed_pipe() -> std::io::PipeWriter {
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    writer
}

fn with_closed_stdout(mut command: Command) -> Output {
    command
        .stdout(closed_pipe())
        .stderr(Stdio::piped())
        .output()
        .expect("runs")
}

fn with_closed_stderr(mut command: Command) -> Output {
    command
        .stdout(Stdio::piped())
        .stderr(closed_pipe())
        .output()
        .expect("runs")
}

fn assert_no_panic(o: &Output) {
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(o.status.code(), Some(101), "{stderr}");
}

#[test]
fn check_with_closed_stdout_exits_0() {
    let mut c = flexmb();
    c.args(["check", repo("examples/pendulum.toml").to_str().unwrap()]);
    let o = with_closed_stdout(c);
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(0));
}

#[test]
fn run_with_closed_stdout_exits_0_and_writes_its_results() {
    let out = out_dir("pipe-run");
    let mut c = flexmb();
    c.args([
        "run",
        repo("examples/pendulum.toml").to_str().unwrap(),
        "--out",
    ])
    .arg(&out)
    .args(["--set", "solver.t_end=0.01"]);
    let o = with_closed_stdout(c);
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(0));
    assert_eq!(summary(&out)["status"], "ok");
}

#[test]
fn help_with_closed_stdout_exits_0() {
    let mut c = flexmb();
    c.arg("--help");
    let o = with_closed_stdout(c);
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(0));
}

#[test]
fn failed_run_with_closed_stderr_keeps_its_exit_code() {
    // Every message of a failed run goes to stderr.
    let out = out_dir("pipe-fail");
    let mut c = flexmb();
    c.args([
        "run",
        repo("crates/flexmb-cli/tests/data/blows_up.toml")
            .to_str()
            .unwrap(),
        "--out",
    ])
    .arg(&out);
    let o = with_closed_stderr(c);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(summary(&out)["status"], "failed");
}

#[test]
fn invalid_model_and_usage_error_with_closed_stderr_keep_their_exit_codes() {
    let mut check = flexmb();
    check.args(["check", "no/such/model.toml"]);
    assert_eq!(with_closed_stderr(check).status.code(), Some(2));
    let mut usage = flexmb();
    usage.arg("run");
    assert_eq!(with_closed_stderr(usage).status.code(), Some(64));
}
