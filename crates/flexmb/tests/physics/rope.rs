//! A rope on more than two node slots: the block and tackle of
//! `examples/block_and_tackle.toml` (a mass on a rope with two falls, four points, two on the
//! same body) against its exact solution, dynamic and static; and a rope that goes slack
//! pulls nothing.

use crate::common;

use flexmb::input::{read_model_file, Analysis};
use flexmb::sensors::SensorEvaluator;
use flexmb::solve::{StaticSettings, Statics};
use flexmb::Simulation;

const M: f64 = 2.0;
const G: f64 = 9.81;
const K: f64 = 1000.0;
const E0: f64 = 0.004;

fn example() -> flexmb::input::ModelFile {
    read_model_file(&common::example("block_and_tackle.toml"), &[]).expect("reads")
}

/// The equilibrium drop `(m g / (2 k) - e0) / 2`.
fn equilibrium() -> f64 {
    (M * G / (2.0 * K) - E0) / 2.0
}

/// The exact drop `u_eq (1 - cos(omega t))` and tension `k (e0 + 2 u)`.
fn exact(t: f64) -> (f64, f64) {
    let u_eq = equilibrium();
    let omega = (4.0 * K / M).sqrt();
    let u = u_eq * (1.0 - (omega * t).cos());
    (u, K * (E0 + 2.0 * u))
}

#[test]
fn block_and_tackle_oscillates_with_the_stiffness_of_two_falls() {
    let file = example();
    let Analysis::Dynamic(settings) = file.analysis else {
        panic!("a dynamic analysis")
    };
    let mut sim = Simulation::new(file.model.clone(), settings).expect("starts");
    let mut sensors = SensorEvaluator::new(&file.model);
    let (mut worst_u, mut worst_t, mut outputs) = (0.0f64, 0.0f64, 0);
    let u_eq = equilibrium();
    sim.run(&mut |s: &flexmb::observe::Sample| {
        let values = sensors.evaluate(s.model, s.data, s.state);
        let (u, tension) = exact(s.state.t);
        worst_u = worst_u.max((-values[0] - u).abs() / u_eq);
        worst_t = worst_t.max((values[1] - tension).abs() / (K * E0));
        outputs += 1;
        Ok(())
    })
    .expect("runs");
    println!("{outputs} outputs: drop within {worst_u:.2e} of u_eq, tension within {worst_t:.2e}");
    assert_eq!(outputs, 201);
    assert!(worst_u < 2e-3 && worst_t < 2e-3, "{worst_u:e} {worst_t:e}");
}

#[test]
fn block_and_tackle_static_equilibrium() {
    let file = example();
    let mut statics = Statics::new(file.model, StaticSettings::default()).expect("starts");
    statics
        .run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("converges");
    let u = -statics.state.q[0].x.y;
    let u_eq = equilibrium();
    assert!(
        (u - u_eq).abs() < 1e-9 * u_eq.max(1.0),
        "{u} against {u_eq}"
    );
}

#[test]
fn a_slack_rope_pulls_nothing() {
    // The same mass on a rope 0.1 m longer than the path (slack): in 0.05 s it falls
    // g t^2 / 2 = 12 mm, which lengthens the path by 25 mm only; the rope pulls exactly
    // nothing and the fall is free.
    let file = read_model_file(
        &common::example("block_and_tackle.toml"),
        &["rope.rope.rest_length=4.3".to_string()],
    )
    .expect("reads");
    let Analysis::Dynamic(mut settings) = file.analysis else {
        panic!("a dynamic analysis")
    };
    settings.t_end = 0.05;
    let mut sim = Simulation::new(file.model.clone(), settings).expect("starts");
    let mut sensors = SensorEvaluator::new(&file.model);
    sim.run(&mut |s: &flexmb::observe::Sample| {
        let values = sensors.evaluate(s.model, s.data, s.state);
        let t = s.state.t;
        assert_eq!(values[1], 0.0, "tension at t = {t}");
        let free_fall = 0.5 * G * t * t;
        assert!(
            (-values[0] - free_fall).abs() < 1e-9,
            "drop {} against {free_fall} at t = {t}",
            -values[0]
        );
        Ok(())
    })
    .expect("runs");
}
