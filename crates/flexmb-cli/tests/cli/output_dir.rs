//! A run owns its output directory's result files (README.md, "Outputs"): it removes those
//! of an earlier run when it starts and leaves other files alone, so a run repeated into the
//! same directory gives the same files whatever ran there before.

use crate::common;

use crate::common::{flexmb, out_dir, repo, send_signal, start_long_run, summary, wait_for};
use std::collections::BTreeMap;
use std::path::Path;

/// `flexmb run MODEL --out DIR [--set ...]`; returns the exit code.
fn run(model: &str, dir: &Path, set: &[&str]) -> i32 {
    let mut c = flexmb();
    c.args(["run", repo(model).to_str().unwrap(), "--out"])
        .arg(dir)
        .arg("--quiet");
    for s in set {
        c.args(["--set", s]);
    }
    c.output().expect("runs").status.code().expect("exit code")
}

/// Every file of a directory by name; `summary.json` without its timings; `results.h5` by
/// its content (its bytes depend on when its batches were written, which follows the wall
/// clock).
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let name = e.unwrap().file_name().into_string().unwrap();
            let mut bytes = std::fs::read(dir.join(&name)).unwrap();
            if name == "summary.json" {
                let mut s = summary(dir);
                let fields = s.as_object_mut().unwrap();
                assert!(fields.remove("wall_seconds").is_some());
                assert!(fields.remove("solve_seconds").is_some());
                bytes = s.to_string().into_bytes();
            }
            if name == "results.h5" {
                let r = flexmb_results::h5::read(dir).expect("results.h5 reads");
                bytes = serde_json::to_vec(&r).unwrap();
            }
            (name, bytes)
        })
        .collect()
}

const PENDULUM: &str = "examples/pendulum.toml";
const ROLL_UP: &str = "examples/roll_up.toml";
const SHORT: &[&str] = &["solver.t_end=0.03"];

#[test]
fn a_failed_run_leaves_no_rows_of_an_earlier_run() {
    let dir = out_dir("stale-rows");
    assert_eq!(run(PENDULUM, &dir, SHORT), 0);
    assert_eq!(common::line_count(&dir.join("sensors.csv")), 1 + 31);
    let code = run(
        "crates/flexmb-cli/tests/data/inconsistent.toml",
        &dir,
        &["body.bob.velocity=[0.0, 1.0, 0.0]"],
    );
    assert_eq!(code, 2);
    assert_eq!(summary(&dir)["error_kind"], "model");
    for gone in ["sensors.csv", "nodes.csv"] {
        assert!(
            !dir.join(gone).exists(),
            "{gone} of the earlier run is left"
        );
    }
}

#[test]
fn a_rigid_run_after_a_beam_run_leaves_no_beams_csv_and_keeps_other_files() {
    let dir = out_dir("stale-beams");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("notes.txt"), "my notes").unwrap();
    assert_eq!(run(ROLL_UP, &dir, &[]), 0);
    assert!(dir.join("beams.csv").exists());
    assert_eq!(run(PENDULUM, &dir, SHORT), 0);
    assert!(!dir.join("beams.csv").exists());
    assert_eq!(
        std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
        "my notes"
    );
}

/// Something that may have run into a directory before.
#[derive(Clone, Copy, Debug)]
enum Earlier {
    /// The same model, longer.
    LongerPendulum,
    /// A beam model (writes beams.csv), completed.
    BeamsOk,
    /// A beam model whose static analysis fails.
    BeamsFailed,
    /// A run stopped by SIGINT.
    Interrupted,
    /// A run killed by SIGKILL (summary left `running`, rows written so far).
    Killed,
    /// A model rejected before its first step.
    Rejected,
    /// A model file that cannot be read.
    Unreadable,
}

impl Earlier {
    const ALL: [Earlier; 7] = [
        Earlier::LongerPendulum,
        Earlier::BeamsOk,
        Earlier::BeamsFailed,
        Earlier::Interrupted,
        Earlier::Killed,
        Earlier::Rejected,
        Earlier::Unreadable,
    ];

    fn run_into(self, dir: &Path) {
        let code = match self {
            Earlier::LongerPendulum => run(PENDULUM, dir, &["solver.t_end=0.06"]),
            Earlier::BeamsOk => run(ROLL_UP, dir, &[]),
            Earlier::BeamsFailed => run(ROLL_UP, dir, &["solver.max_iterations=1"]),
            Earlier::Interrupted | Earlier::Killed => {
                let mut child = start_long_run(dir, 3);
                let signal = if matches!(self, Earlier::Killed) {
                    "KILL"
                } else {
                    "INT"
                };
                send_signal(&child, signal);
                wait_for(&mut child).code().unwrap_or(-1)
            }
            Earlier::Rejected => run(
                "crates/flexmb-cli/tests/data/inconsistent.toml",
                dir,
                &["body.bob.velocity=[0.0, 1.0, 0.0]"],
            ),
            Earlier::Unreadable => run("no/such/model.toml", dir, &[]),
        };
        let expected = match self {
            Earlier::LongerPendulum | Earlier::BeamsOk => 0,
            Earlier::BeamsFailed => 1,
            Earlier::Rejected | Earlier::Unreadable => 2,
            Earlier::Interrupted => 130,
            Earlier::Killed => -1,
        };
        assert_eq!(code, expected, "{self:?}");
    }
}

/// Runs `model` into a fresh directory and into directories where each earlier run (one
/// each, then all of them in turn) left its files; every result is the fresh one.
fn repeated_runs_give_identical_files(name: &str, model: &str, set: &[&str]) {
    let fresh_dir = out_dir(&format!("{name}-fresh"));
    assert_eq!(run(model, &fresh_dir, set), 0);
    let fresh = snapshot(&fresh_dir);
    assert!(fresh.contains_key("sensors.csv") && fresh.contains_key("summary.json"));
    // The same directory again.
    assert_eq!(run(model, &fresh_dir, set), 0);
    assert_eq!(
        snapshot(&fresh_dir),
        fresh,
        "run repeated into its own directory"
    );
    let mut sequences: Vec<Vec<Earlier>> = Earlier::ALL.iter().map(|e| vec![*e]).collect();
    sequences.push(Earlier::ALL.to_vec());
    sequences.push(Earlier::ALL.iter().rev().copied().collect());
    for (i, earlier) in sequences.iter().enumerate() {
        let dir = out_dir(&format!("{name}-after-{i}"));
        for e in earlier {
            e.run_into(&dir);
        }
        assert_eq!(run(model, &dir, set), 0);
        assert_eq!(snapshot(&dir), fresh, "after {earlier:?}");
    }
}

#[test]
fn rigid_run_repeated_into_a_used_directory_gives_identical_files() {
    repeated_runs_give_identical_files("same-pendulum", PENDULUM, SHORT);
}

#[test]
fn beam_run_repeated_into_a_used_directory_gives_identical_files() {
    repeated_runs_give_identical_files("same-roll-up", ROLL_UP, &[]);
}

/// A tmpfs mounted for a test, unmounted when dropped.
struct Tmpfs(std::path::PathBuf);

impl Tmpfs {
    /// Mounts a tmpfs with `options` on `dir`; `None` where that is not allowed (not root).
    fn mount(dir: &Path, options: &str) -> Option<Self> {
        std::fs::create_dir_all(dir).unwrap();
        let mounted = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", options, "tmpfs"])
            .arg(dir)
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        mounted.then(|| Self(dir.to_path_buf()))
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
    }
}

/// Fills the file system of `dir` with one file, then frees `free` bytes of it.
fn fill(dir: &Path, free: u64) {
    use std::io::Write;
    let path = dir.join("filler");
    let mut f = std::fs::File::create(&path).unwrap();
    let page = [1u8; 4096];
    while f.write_all(&page).is_ok() {}
    let len = f.metadata().unwrap().len();
    f.set_len(len.saturating_sub(free)).unwrap();
}

/// `flexmb run` of the pendulum (`t_end`) into `out`: its exit code and summary.
fn run_pendulum(out: &Path, t_end: &str) -> (i32, serde_json::Value) {
    let code = run(
        "examples/pendulum.toml",
        out,
        &[&format!("solver.t_end={t_end}")],
    );
    (code, summary(out))
}

/// The end of a run is recorded whatever the disk has left, on a real full file system (a
/// tmpfs of 256 KiB mounted for the test; it needs root, and says it is skipped otherwise:
/// tests/cli/exit_codes.rs checks the same with a file size limit, and the output module's
/// tests the room kept for the last summary). The summary said `running` (0 outputs beside
/// the rows written) when the disk filled during the run, or one page was left, or no inode:
/// it now says `failed` (`output`), with the output steps the files hold.
#[cfg(target_os = "linux")]
#[test]
fn a_full_file_system_still_records_the_end_of_the_run() {
    let mnt = out_dir("tmpfs");
    let out = mnt.join("out");
    let failed_on_output = |(code, s): (i32, serde_json::Value)| {
        assert_eq!(code, 3, "{s}");
        assert_eq!(s["status"], "failed", "{s}");
        assert_eq!(s["error_kind"], "output", "{s}");
        let rows = std::fs::read_to_string(out.join("sensors.csv"))
            .map_or(0, |t| t.lines().count().saturating_sub(1));
        assert_eq!(s["outputs"].as_u64().unwrap() as usize, rows, "{s}");
        s
    };
    {
        // The disk fills during the run (the results file included).
        let Some(_fs) = Tmpfs::mount(&mnt, "size=1m") else {
            eprintln!(
                "skipped: cannot mount a tmpfs on {} (needs root)",
                mnt.display()
            );
            return;
        };
        let s = failed_on_output(run_pendulum(&out, "100"));
        // complete up to the last step written (how many fit depends on how far the solver
        // ran ahead of the writer)
        let text = std::fs::read_to_string(out.join("sensors.csv")).unwrap();
        let last = text
            .lines()
            .skip(1)
            .last()
            .map_or(0.0, |l| l.split(',').next().unwrap().parse().unwrap());
        assert_eq!(s["t_reached"].as_f64().unwrap(), last, "{s}");
    }
    {
        // One page left.
        let _fs = Tmpfs::mount(&mnt, "size=256k").unwrap();
        fill(&mnt, 4096);
        let s = failed_on_output(run_pendulum(&out, "1"));
        assert_eq!(s["outputs"], 0);
    }
    {
        // No inode left, the directory holding an earlier run's results.
        let _fs = Tmpfs::mount(&mnt, "size=256k,nr_inodes=16").unwrap();
        assert_eq!(run_pendulum(&out, "0.01").1["status"], "ok");
        let mut k = 0;
        while std::fs::File::create(mnt.join(format!("f{k}"))).is_ok() {
            k += 1;
        }
        failed_on_output(run_pendulum(&out, "1"));
    }
}
