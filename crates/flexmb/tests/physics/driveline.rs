//! The worm gear's friction in a Torsen (type I) differential: the torque bias ratio
//! against the analytic one of `flexmb::elements::worm_gear`, and the driveline example
//! (motor, two-stage gearbox on flexible shafts, the differential, two loaded output shafts)
//! through the driver that `flexmb run` calls.

use flexmb::elements::worm_gear::torque_bias_ratio;
use flexmb::input::read_model_file;

use crate::common::{example, run};

/// Ratio `T_right / T_left` of the output torques, averaged over the last 10 ms (after the
/// input torque's 20 ms ramp and the mesh transient), its analytic value and the sum of
/// the output torques.
fn bias_ratio(mu: f64, washer_radius: f64) -> (f64, f64, f64) {
    let set = [
        format!("worm_gear.left.friction={mu}"),
        format!("worm_gear.right.friction={mu}"),
        format!("worm_gear.left.washer_radius={washer_radius}"),
        format!("worm_gear.right.washer_radius={washer_radius}"),
    ];
    let file = read_model_file(&example("torsen.toml"), &set).expect("model");
    let analytic = torque_bias_ratio(&file.model.worm_gears[0]);
    let h = run(
        "torsen.toml",
        &set.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    // the shafts' reactions: the torque delivered to a shaft is minus its reaction
    let late = |name: &str| {
        let s: Vec<f64> = h
            .series(name)
            .iter()
            .filter(|(t, _)| *t >= 0.03 - 1e-9)
            .map(|(_, v)| -v)
            .collect();
        s.iter().sum::<f64>() / s.len() as f64
    };
    let (left, right) = (late("torque_left"), late("torque_right"));
    (right / left, analytic, left + right)
}

#[test]
fn torsen_torque_bias_ratio_matches_the_worm_gear_friction_model() {
    // The side shafts are driven at 12 and 8 rad/s (the right one is the slow one), so both
    // meshes and washers slide at 40 times the stiction velocity: Coulomb's law holds
    // exactly, and the quasi-static balance of the module documentation is the steady
    // state. What the formula leaves out is the mesh deflection (F / k ~ 1e-5 m against
    // radii of 1e-2 m, entering the geometry to second order) and the decaying transient:
    // 1e-5 covers both with a margin; the results agree to about 1e-8. Near locking (mu = 0.15 with washers: TBR 16, the fast
    // side's torque the small difference eta' - w) the ratio is most sensitive to the
    // friction torques, and still agrees.
    let mut table = vec![];
    for (mu, r_w) in [
        (0.0, 0.0095),
        (0.05, 0.0095),
        (0.1, 0.0095),
        (0.15, 0.0095),
        (0.1, 0.0),
    ] {
        let (computed, analytic, sum) = bias_ratio(mu, r_w);
        table.push(format!(
            "mu {mu:5.2} washer {r_w:6.4} m: TBR computed {computed:9.5} analytic {analytic:9.5} (relative difference {:.1e})",
            computed / analytic - 1.0
        ));
        assert!(
            (computed / analytic - 1.0).abs() < 1e-5,
            "mu {mu}, washer radius {r_w}: TBR {computed} vs {analytic}"
        );
        // the input torque (200 N m) reaches the shafts
        assert!(
            (sum - 200.0).abs() < 0.2,
            "mu {mu}: output torques add up to {sum}"
        );
        if mu == 0.0 {
            // the ideal (open) differential
            assert!((computed - 1.0).abs() < 1e-6, "mu = 0: TBR {computed}");
        } else {
            assert!(
                computed > 1.5,
                "mu {mu}: the friction biases the torque: {computed}"
            );
        }
    }
    println!("{}", table.join("\n"));
}

#[test]
fn driveline_runs_through_the_driver_and_biases_the_torque() {
    // `flexmb run examples/driveline.toml`: the driver writes sensors.csv; at the steady
    // state (after the 50 ms ramp of the motor torque) the differential slips and the loads'
    // torques are in the bias ratio, the gearbox reduces the speed 9 times, and the motor
    // torque times 9 reaches the loads.
    let file = read_model_file(&example("driveline.toml"), &[]).expect("model");
    let out = std::env::temp_dir().join(format!("flexmb-driveline-{}", std::process::id()));
    let dir = flexmb::output::OutputDir::prepare(&out).expect("output directory");
    let report = flexmb::driver::run(&file, &dir, Default::default(), &mut |_, _| {}, None);
    assert_eq!(
        report.summary.status,
        flexmb::output::Status::Ok,
        "{:?}",
        report.summary
    );
    let text = std::fs::read_to_string(out.join("sensors.csv")).expect("sensors.csv");
    let _ = std::fs::remove_dir_all(&out);
    let header: Vec<&str> = text.lines().next().expect("header").split(',').collect();
    let last: Vec<f64> = text
        .lines()
        .last()
        .expect("rows")
        .split(',')
        .map(|v| v.parse().expect("number"))
        .collect();
    let value = |name: &str| last[header.iter().position(|h| *h == name).expect(name)];
    assert!((value("time") - 0.12).abs() < 1e-12);
    let (left, right) = (value("load_left"), value("load_right"));
    let tbr = torque_bias_ratio(&file.model.worm_gears[0]);
    // slipping (the left side faster), the ratio is the bias ratio (not the loads' 10:1)
    assert!(value("omega_left") > value("omega_right") + 5.0);
    assert!(
        (right / left / tbr - 1.0).abs() < 1e-4,
        "TDR {} vs TBR {tbr}",
        right / left
    );
    assert!((left + right - 180.0).abs() < 0.1, "{left} + {right}");
    // the axles carry the loads' torques
    assert!((value("axle_left").abs() / left - 1.0).abs() < 1e-3);
    assert!((value("axle_right").abs() / right - 1.0).abs() < 1e-3);
    assert!((value("omega_motor") / value("omega_case") - 9.0).abs() < 1e-3);
}
