//! Results in memory: what a run collects.

use flexmb_results::Results;
use std::path::Path;

fn model(name: &str) -> flexmb::input::ModelFile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name);
    flexmb::input::read_model_file(&path, &[]).expect("the example reads")
}

#[test]
fn heavy_top_snapshots_hold_every_output_step_and_its_unit_quaternions() {
    let mut file = model("heavy_top.toml");
    file.analysis = match file.analysis {
        flexmb::input::Analysis::Dynamic(mut s) => {
            s.t_end = 0.05;
            flexmb::input::Analysis::Dynamic(s)
        }
        a => a,
    };
    let (r, error) = Results::collect(&file);
    assert!(error.is_none());
    assert_eq!(r.info.nodes.len(), 1);
    assert!(r.snapshots.len() > 2);
    assert!(!r.steps.is_empty());
    for s in &r.snapshots {
        let q = s.orientation[0];
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((n - 1.0).abs() < 1e-12);
        assert_eq!(s.sensors.len(), r.info.sensors.len());
    }
    // The default shape of the top is its inertia box, centred on its centre of mass (the node).
    assert_eq!(r.info.shapes.len(), 1);
    assert_eq!(r.info.shapes[0].position, [0.0, 0.0, 0.0]);
}
