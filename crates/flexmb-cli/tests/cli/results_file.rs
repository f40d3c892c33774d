//! The results file and what is drawn from it through the CLI: a run killed midway leaves a
//! results.h5 that other programs (h5py) and flexmb read, with every output step the writer
//! thread had written, as the run computed it; summary.png, view.html, the Paraview series
//! and plots from a run's directory; `--results none`.

use crate::common::{flexmb, line_count, out_dir, repo, send_signal, wait_for, wait_until};
use flexmb_results::h5::read;
use std::path::Path;

fn run(model: &str, args: &[&str], out: &Path) -> std::process::Output {
    flexmb()
        .args(["run", repo(model).to_str().unwrap(), "--quiet", "--out"])
        .arg(out)
        .args(args)
        .output()
        .expect("runs")
}

/// h5py's view of a results file: the length of `time` and the shape of the node
/// positions (the test fails if python3 or h5py is missing: `scripts/setup --tests`).
fn h5py_shape(path: &Path) -> (usize, Vec<usize>) {
    let python = std::env::var("FLEXMB_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = "import h5py, sys\nf = h5py.File(sys.argv[1], 'r')\nprint(len(f['time']), *f['nodes/position'].shape)";
    let out = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(path)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "{python} does not run ({e}): scripts/setup --tests installs what this test needs"
            )
        });
    assert!(
        out.status.success(),
        "h5py cannot read {} (scripts/setup --tests installs h5py): {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let words: Vec<usize> = String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .map(|w| w.parse().unwrap())
        .collect();
    (words[0], words[1..].to_vec())
}

#[test]
fn a_killed_run_leaves_a_readable_results_file_with_every_completed_step() {
    // The reference: the same model run to its end in memory.
    let model = "examples/chain_10.toml";
    let file =
        flexmb::input::read_model_file(&repo(model), &["solver.t_end=0.3".into()]).expect("reads");
    let (whole, error) = flexmb_results::Results::collect(&file);
    assert!(error.is_none());
    // Killed at three different moments.
    for (k, rows) in [3usize, 9, 17].into_iter().enumerate() {
        let out = out_dir(&format!("killed-{k}"));
        let mut child = flexmb()
            .args(["run", repo(model).to_str().unwrap(), "--quiet", "--out"])
            .arg(&out)
            .args(["--set", "solver.t_end=1000", "--no-plot"])
            .spawn()
            .expect("starts");
        wait_until("output steps", || {
            line_count(&out.join("sensors.csv")) > rows
        });
        // The writer thread flushes the results file after the CSV rows of each batch of
        // output steps: 200 ms later, the file holds at least the steps the CSV files showed.
        std::thread::sleep(std::time::Duration::from_millis(200));
        send_signal(&child, "KILL");
        wait_for(&mut child);
        let r = read(&out).expect("the results file of a killed run reads");
        let n = r.snapshots.len();
        assert!(n >= rows, "{n} output steps, at least {rows} were complete");
        assert_eq!(r.info, whole.info);
        // Every step in the file is the step the run computed, bit for bit.
        let common = n.min(whole.snapshots.len());
        assert_eq!(r.snapshots[..common], whole.snapshots[..common]);
        assert!(r.steps.len() >= 10 * (n - 1));
        assert_eq!(
            r.steps[..r.steps.len().min(whole.steps.len())],
            whole.steps[..r.steps.len().min(whole.steps.len())]
        );
        let (time, shape) = h5py_shape(&out.join("results.h5"));
        assert_eq!(time, n);
        assert_eq!(shape[1..], [10, 3]);
        assert!(shape[0] >= n);
    }
}

#[test]
fn a_run_draws_its_summary_plot_and_animation_and_the_commands_draw_from_its_directory() {
    let out = out_dir("drawn");
    let r = run(
        "examples/four_bar.toml",
        &["--set", "solver.t_end=0.05", "--view"],
        &out,
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(stdout.contains("view.html"), "{stdout}");
    for name in ["results.h5", "summary.png", "view.html"] {
        let len = std::fs::metadata(out.join(name)).map_or(0, |m| m.len());
        assert!(len > 1000, "{name}: {len} bytes");
    }
    let png = std::fs::read(out.join("summary.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    // The commands read the run's directory or its file.
    let plot = out.join("plot.svg");
    let names = read(&out).unwrap().info.sensors;
    let s = flexmb()
        .args(["plot", out.to_str().unwrap(), &names[0].name, "-o"])
        .arg(&plot)
        .output()
        .unwrap();
    assert!(s.status.success(), "{}", String::from_utf8_lossy(&s.stderr));
    assert!(std::fs::read_to_string(&plot)
        .unwrap()
        .contains(&names[0].name));
    let vtk = out.join("vtk");
    let s = flexmb()
        .args(["export-vtk", out.join("results.h5").to_str().unwrap(), "-o"])
        .arg(&vtk)
        .output()
        .unwrap();
    assert!(s.status.success(), "{}", String::from_utf8_lossy(&s.stderr));
    assert!(vtk.join("results.pvd").exists());
    assert!(vtk.join("bodies_000000.vtu").exists());
    let html = out.join("again.html");
    let s = flexmb()
        .args(["view", out.to_str().unwrap(), "-o"])
        .arg(&html)
        .output()
        .unwrap();
    assert!(s.status.success(), "{}", String::from_utf8_lossy(&s.stderr));
    assert!(std::fs::read(&html).unwrap() == std::fs::read(out.join("view.html")).unwrap());
    // A sensor that does not exist is a usage error naming the sensors there are.
    let s = flexmb()
        .args(["plot", out.to_str().unwrap(), "nope", "-o"])
        .arg(&plot)
        .output()
        .unwrap();
    assert_eq!(s.status.code(), Some(64));
    assert!(String::from_utf8_lossy(&s.stderr).contains(&names[0].name));
}

#[test]
fn without_the_results_file_a_run_writes_the_csv_files_only() {
    let out = out_dir("no-results");
    let r = run(
        "examples/pendulum.toml",
        &["--set", "solver.t_end=0.05", "--results", "none", "--view"],
        &out,
    );
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(out.join("sensors.csv").exists());
    for name in ["results.h5", "summary.png", "view.html"] {
        assert!(!out.join(name).exists(), "{name}");
    }
    // The commands say which file is missing.
    let s = flexmb()
        .args(["view", out.to_str().unwrap(), "-o", "x.html"])
        .output()
        .unwrap();
    assert_eq!(s.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&s.stderr).contains("results.h5"));
}
