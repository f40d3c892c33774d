//! Flexible slider-crank of B. Simeon (Math. Modelling of Systems 2, 1996; IVP Test Set
//! 'crank'), examples/slider_crank.toml, against the converged reference of
//! tests/reference/slider_crank_reference.md (case U, Timoshenko columns: 64 quadratic
//! Reissner elements, Radau IIA with h = 5e-6 s; its own mesh and step errors are below
//! 1e-8 m, Sect. 4 of that file).

mod common;

use common::{reference, run, History};

/// Reference rows `(t, slider x, rod mid-span deflection)`, Timoshenko beam, case U.
fn reference_case_u() -> Vec<(f64, f64, f64)> {
    let text = std::fs::read_to_string(reference("slider_crank_reference_caseU.csv"))
        .expect("reference file");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (t, x, w) = (
        col("time"),
        col("slider_x_timoshenko"),
        col("rod_mid_deflection_timoshenko"),
    );
    lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|s| s.parse().expect("number")).collect();
            (v[t], v[x], v[w])
        })
        .collect()
}

/// Mid-span deflection from the chord A-B, positive to the left of A -> B.
fn mid_deflection(h: &History, t: f64) -> f64 {
    let (ax, ay) = (h.at("a_x", t), h.at("a_y", t));
    let (bx, by) = (h.at("b_x", t), h.at("b_y", t));
    let (mx, my) = (h.at("mid_x", t), h.at("mid_y", t));
    let (dx, dy) = (bx - ax, by - ay);
    let l = dx.hypot(dy);
    (mx - 0.5 * (ax + bx)) * (-dy / l) + (my - 0.5 * (ay + by)) * (dx / l)
}

/// Largest errors over the 101 reference times: (mid-span deflection, slider x).
fn errors(h: &History, reference: &[(f64, f64, f64)]) -> (f64, f64) {
    reference
        .iter()
        .fold((0.0f64, 0.0f64), |(ew, ex), (t, x, w)| {
            (
                ew.max((mid_deflection(h, *t) - w).abs()),
                ex.max((h.at("slider_x", *t) - x).abs()),
            )
        })
}

#[test]
fn slider_crank_converges_to_the_reference_under_mesh_refinement() {
    let reference = reference_case_u();
    assert_eq!(reference.len(), 101);
    let peak = reference.iter().fold(0.0f64, |m, r| m.max(r.2.abs()));
    assert!((peak - 1.869e-3).abs() < 1e-6, "reference peak {peak}");

    let h16 = run("slider_crank.toml", &[]);
    let h32 = run(
        "slider_crank.toml",
        &[
            "beam.rod.elements=32",
            "joint.slider_pin.node_b=rod.32",
            "sensor.mid_x.node=rod.16",
            "sensor.mid_y.node=rod.16",
            "sensor.rod_axial_force.beam=\"rod[16]\"",
        ],
    );
    let (w16, x16) = errors(&h16, &reference);
    let (w32, x32) = errors(&h32, &reference);
    eprintln!("16 elements: w error {w16:.3e} m, x error {x16:.3e} m");
    eprintln!("32 elements: w error {w32:.3e} m, x error {x32:.3e} m");
    // The deflection error is the bending frequency of the mesh (a phase drift over 20
    // periods), second order in the element length: 3.45 % and 0.89 % of the peak.
    assert!(w16 < 0.035 * peak, "16 elements: {w16:e}");
    assert!(w32 < 0.0095 * peak, "32 elements: {w32:e}");
    let order = (w16 / w32).log2();
    assert!(order > 1.8, "mesh order {order}");
    // The slider position carries the axial vibration of the rod (~2e-5 m, period 0.35 ms),
    // whose phase h = 1e-5 s does not follow over 0.1 s: 3.6e-5 m here, 8e-7 m with
    // h = 1e-6 s and 32 elements (BENCHMARKS.md).
    assert!(x16 < 4e-5 && x32 < 4e-5, "slider x: {x16:e}, {x32:e}");
    // The consistent mass (an option) changes the 16-element error little: the two-node
    // element's stiffness dominates it.
    let consistent = run("slider_crank.toml", &["beam.rod.mass_matrix=consistent"]);
    let (wc, _) = errors(&consistent, &reference);
    eprintln!("16 elements, consistent mass: w error {wc:.3e} m");
    assert!(wc < 0.035 * peak && (wc - w16).abs() < 0.2 * w16);
    // The slider stays on its guide.
    for (t, _, _) in &reference {
        assert!(h16.at("b_y", *t).abs() < 1e-9);
    }
}
