//! SIGINT, SIGTERM and SIGHUP stop a run cleanly: the rows of every completed output step are
//! in the files, `summary.json` says `interrupted` with the counts of the work done, and the
//! process exits with 128 + the signal number (README.md, "Exit status").

#![cfg(unix)]

use crate::common::{out_dir, rows, send_signal, start_long_run, summary, wait_for};

/// Interrupts a long pendulum run with `signal` and checks what it leaves.
fn interrupted_run_keeps_its_results(name: &str, signal: &str, code: i32) {
    let out = out_dir(name);
    let mut child = start_long_run(&out, 5);
    send_signal(&child, signal);
    let status = wait_for(&mut child);
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(code), "{status}: {stderr}");
    assert!(
        stderr.contains(&format!("interrupted by SIG{signal}")),
        "{stderr}"
    );
    let s = summary(&out);
    assert_eq!(s["status"], "interrupted", "{s}");
    assert!(s.get("error").is_none(), "{s}");
    let steps = s["steps"].as_u64().unwrap();
    let t_reached = s["t_reached"].as_f64().unwrap();
    assert!(steps >= 5 && t_reached > 0.0, "{s}");
    assert!(s["newton_iterations"].as_u64().unwrap() >= steps, "{s}");
    // The pendulum writes every step: one complete row per completed step, the last one at
    // the time reached.
    let sensors = rows(&out.join("sensors.csv"));
    assert_eq!(s["outputs"].as_u64().unwrap() as usize, sensors.len());
    assert_eq!(sensors.len() as u64, steps + 1, "t = 0 and every step");
    assert!(sensors.iter().all(|r| r.len() == 7));
    let last: f64 = sensors.last().unwrap()[0].parse().unwrap();
    // Both are written exactly (shortest round-trip form).
    assert_eq!(last, t_reached);
    let nodes = rows(&out.join("nodes.csv"));
    assert_eq!(nodes.len(), sensors.len(), "one node");
    assert!(nodes.iter().all(|r| r.len() == 9));
}

#[test]
fn sigint_stops_a_run_with_status_interrupted_and_exit_130() {
    interrupted_run_keeps_its_results("sigint", "INT", 130);
}

#[test]
fn sigterm_stops_a_run_with_status_interrupted_and_exit_143() {
    interrupted_run_keeps_its_results("sigterm", "TERM", 143);
}

#[test]
fn sighup_stops_a_run_with_status_interrupted_and_exit_129() {
    interrupted_run_keeps_its_results("sighup", "HUP", 129);
}

/// Two signals in a row (a second Ctrl-C; `timeout -s INT`, which signals the process and
/// then its group; here SIGINT then SIGTERM, which the kernel cannot merge into one) end the
/// run at once, and the summary still tells the truth: `interrupted`, the output steps the
/// files hold and the time of the last (it said `running` and `t_reached` 0 beside the
/// rows written when the second signal took its default action).
#[test]
fn two_signals_in_a_row_end_the_run_with_a_summary_of_what_was_written() {
    let out = out_dir("two-signals");
    let mut child = start_long_run(&out, 5);
    send_signal(&child, "INT");
    send_signal(&child, "TERM");
    let status = wait_for(&mut child);
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(
        matches!(status.code(), Some(130 | 143)),
        "{status}: {stderr}"
    );
    assert!(stderr.contains("interrupted"), "{stderr}");
    let s = summary(&out);
    assert_eq!(s["status"], "interrupted", "{s}");
    let sensors = rows(&out.join("sensors.csv"));
    assert!(sensors.iter().all(|r| r.len() == 7));
    assert_eq!(
        s["outputs"].as_u64().unwrap() as usize,
        sensors.len(),
        "{s}"
    );
    let last: f64 = sensors.last().unwrap()[0].parse().unwrap();
    assert_eq!(s["t_reached"].as_f64().unwrap(), last, "{s}");
    // The pendulum writes every step: the counts are those of the rows.
    assert_eq!(
        s["steps"].as_u64().unwrap() as usize + 1,
        sensors.len(),
        "{s}"
    );
    assert_eq!(rows(&out.join("nodes.csv")).len(), sensors.len());
}
