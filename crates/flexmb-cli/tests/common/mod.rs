//! Helpers of the CLI tests: the binary, the repository's files, fresh output directories,
//! reading results, and waiting for a child process with a deadline.

#![allow(dead_code)] // each test file uses its own part

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// The `flexmb` binary under test.
pub fn flexmb() -> Command {
    Command::new(env!("CARGO_BIN_EXE_flexmb"))
}

/// A file of the repository, e.g. `examples/pendulum.toml`.
pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(path)
}

/// A fresh (absent) directory for one test, unique per test process and name.
pub fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("flexmb-cli-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// `summary.json` of a directory, parsed.
pub fn summary(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("summary.json is not JSON ({e}): {text}"))
}

/// The data rows of a CSV file (without its header), each split at commas.
pub fn rows(path: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

/// Lines of a file so far (0 if it does not exist yet).
pub fn line_count(path: &Path) -> usize {
    std::fs::read_to_string(path).map_or(0, |t| t.lines().count())
}

/// Waits until `ready()` holds, panicking after a minute.
pub fn wait_until(what: &str, mut ready: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(60);
    while !ready() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits for the child to end, killing it and panicking after a minute.
pub fn wait_for(child: &mut Child) -> ExitStatus {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(status) = child.try_wait().expect("child status") {
            return status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("the child did not end within a minute");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Sends a signal (`INT`, `TERM`, `HUP`, `KILL`) to a process with the `kill` command.
pub fn send_signal(child: &Child, name: &str) {
    let status = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(child.id().to_string())
        .status()
        .expect("kill runs");
    assert!(status.success(), "kill -{name} failed");
}

/// Starts `flexmb run` of the pendulum for over 1000 s into `dir` (far longer than any test
/// waits) and returns once it has written `rows` rows to `sensors.csv`. Each call gets its
/// own `t_end`, by which its summary is told from one an earlier run left in `dir`.
pub fn start_long_run(dir: &Path, rows: usize) -> Child {
    static STARTS: AtomicUsize = AtomicUsize::new(0);
    let t_end = 1000 + STARTS.fetch_add(1, Ordering::Relaxed);
    let mut child = flexmb()
        .args([
            "run",
            repo("examples/pendulum.toml").to_str().unwrap(),
            "--out",
        ])
        .arg(dir)
        .args(["--set", &format!("solver.t_end={t_end}"), "--quiet"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("flexmb starts");
    let ours = || {
        std::fs::read_to_string(dir.join("summary.json")).is_ok_and(|text| {
            serde_json::from_str::<serde_json::Value>(&text)
                .is_ok_and(|s| s["t_end"].as_f64() == Some(t_end as f64))
        })
    };
    let sensors = dir.join("sensors.csv");
    wait_until("rows in sensors.csv", || {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("the long run ended early: {status}");
        }
        // The run wrote its summary (so it removed earlier results and handles signals).
        ours() && line_count(&sensors) > rows
    });
    child
}
