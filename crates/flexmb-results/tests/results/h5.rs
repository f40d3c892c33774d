//! The HDF5 results file: written by a run, read back to the same results as the run in
//! memory, bit for bit.

use flexmb::driver::{run_with, RunOptions};
use flexmb::input::{Analysis, ModelFile};
use flexmb::output::OutputDir;
use flexmb_results::h5::{read, H5Format};
use flexmb_results::Results;
use std::path::{Path, PathBuf};

fn model(name: &str, t_end: f64) -> ModelFile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name);
    let mut file = flexmb::input::read_model_file(&path, &[]).expect("the example reads");
    match &mut file.analysis {
        Analysis::Dynamic(s) => s.t_end = t_end,
        Analysis::Static(s) => s.load_factor = t_end,
    }
    file
}

fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Runs `file` into `dir` with the HDF5 file and reads it back; checks that its solver
/// steps are those the summary counts, the last one at the last output step.
fn written(file: &ModelFile, dir: &Path) -> Results {
    let out = OutputDir::prepare(dir).unwrap();
    let report = run_with(
        file,
        &out,
        RunOptions::default(),
        &[&H5Format],
        &mut |_, _| {},
        None,
    );
    assert!(report.unwritten.is_none());
    let summary = report.summary;
    assert_eq!(
        summary.status,
        flexmb::output::Status::Ok,
        "{:?}",
        summary.error
    );
    let r = read(dir).expect("the results file reads");
    assert_eq!(r.steps.len(), summary.steps);
    let iterations: usize = r.steps.iter().map(|s| s.iterations as usize).sum();
    assert_eq!(iterations, summary.newton_iterations);
    let rejected: usize = r.steps.iter().map(|s| s.rejected as usize).sum();
    assert_eq!(rejected, summary.rejected_steps);
    assert_eq!(r.steps.last().unwrap().at, r.snapshots.last().unwrap().at);
    r
}

#[test]
fn a_dynamic_run_reads_back_as_it_ran() {
    let file = model("heavy_top.toml", 0.05);
    let r = written(&file, &out_dir("h5_heavy_top"));
    let (expected, error) = Results::collect(&file);
    assert!(error.is_none());
    assert_eq!(r.snapshots.len(), 6);
    assert_eq!(r.steps.len(), 500);
    assert_eq!(r, expected);
}

#[test]
fn a_mechanism_and_static_beams_by_load_control_and_arc_length_read_back_as_they_ran() {
    for (name, end) in [
        ("four_bar.toml", 0.02),
        ("bend_45.toml", 0.2),
        ("lee_frame.toml", 3.0),
    ] {
        let file = model(name, end);
        let r = written(&file, &out_dir(&format!("h5_{name}")));
        let (expected, error) = Results::collect(&file);
        assert!(error.is_none());
        assert!(r.snapshots.len() > 1);
        assert_eq!(r.snapshots, expected.snapshots, "{name}");
        assert_eq!(r.steps, expected.steps, "{name}");
        assert_eq!(r.info, expected.info, "{name}");
    }
}
