//! The step as a function (`flexmb::solve::step::StepFunction`): its exact Jacobian
//! `dR/dx` and its products with `dR/ds_n` checked against central finite differences of
//! the step residual, after steps taken through the public API (`Simulation::step`), on the
//! heavy top (SE(3) and R3xSO(3)), the 10-link chain, a flexible beam mechanism, and the
//! stabilized index-2 form. Start perturbations move `q_n` on the manifold (`q_n exp(d)`).

use crate::common;

use flexmb::data::Layout;
use flexmb::model::parameters::{ParamId, ParamRole, Parameters};
use flexmb::solve::step::{StateTangent, StepFunction};
use flexmb::{Data, Simulation, State};
use flexmb_lie::Vec6;

/// A deterministic pseudo-random sequence in [-1, 1].
fn noise(seed: u64) -> impl FnMut() -> f64 {
    let mut lcg = common::Lcg(seed);
    move || lcg.next()
}

/// A simulation of an example file after `steps` steps.
fn simulation(file: &str, overrides: &[&str], steps: usize) -> Simulation {
    let mut sim = common::example_simulation(file, overrides);
    for _ in 0..steps {
        sim.step().expect("step");
    }
    sim
}

/// [`relative_difference`] row block by row block (equilibrium, constraints, velocity-level
/// rows, element states), so that rows of a small scale are not judged against the largest
/// ones.
fn blockwise(a: &[f64], b: &[f64], layout: &Layout, floor: f64) -> f64 {
    let (nd, na, so) = (layout.n_dofs, layout.n_active, layout.state_offset());
    [0..nd, nd..nd + na, nd + na..so, so..a.len()]
        .into_iter()
        .filter(|r| !r.is_empty())
        .map(|r| relative_difference(&a[r.clone()], &b[r], floor))
        .fold(0.0f64, f64::max)
}

/// The central difference `(plus - minus) / (2 eps)`, entry by entry.
fn central(plus: &[f64], minus: &[f64], eps: f64) -> Vec<f64> {
    plus.iter()
        .zip(minus)
        .map(|(a, b)| (a - b) / (2.0 * eps))
        .collect()
}

/// Largest entry of `a - b` relative to the largest entry of `b` (and at least `floor`).
fn relative_difference(a: &[f64], b: &[f64], floor: f64) -> f64 {
    let scale = b.iter().fold(floor, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// Checks `dR/dx` column by column, `dR/ds_n` along random tangents, and the transposed
/// product against the direct one, at the predictor of the next step moved by a random
/// perturbation (a point away from the solution, with non-zero multipliers and zeta).
fn check(name: &str, sim: &Simulation) {
    check_end_state(name, sim);
    let h = sim.settings.h;
    let f = sim.step_function(h);
    let layout = sim.data.layout.clone();
    let mut data = Data::new(&sim.model, layout.clone()).expect("data");
    let nu = layout.n_unknowns();
    let mut rand = noise(7);
    let mut x = f.predict();
    let x_scale = x.iter().fold(1e-3f64, |m, v| m.max(v.abs()));
    for v in &mut x {
        *v += 0.05 * x_scale * rand();
    }
    // dR/dx along directions that each move one kind of unknown (translations, rotations,
    // multipliers, stabilization) and all of them: a product compared with a central
    // difference of the residual, relative to its size, so that round-off in rows that sum
    // large forces does not pass for an error and a small block is not hidden by a large one.
    let jacobian = f.jacobian(&x, &mut data);
    // The partial derivatives are kept for the last x only: another point recomputes them,
    // and coming back gives the same matrix.
    let other: Vec<f64> = x.iter().map(|v| v * 1.01 + 1e-4).collect();
    assert_ne!(
        f.jacobian(&other, &mut data),
        jacobian,
        "{name}: another point"
    );
    assert_eq!(
        f.jacobian(&x, &mut data),
        jacobian,
        "{name}: the same point again"
    );
    // ... and a changed step (here its row scale) recomputes them too.
    let mut g = sim.step_function(h);
    assert_eq!(g.jacobian(&x, &mut data), jacobian);
    g.step = g.step.with_mass(2.0 * g.step.mass);
    assert_ne!(
        g.jacobian(&x, &mut data),
        jacobian,
        "{name}: the step changed"
    );
    let (nd, na, so) = (layout.n_dofs, layout.n_active, layout.state_offset());
    type Selection<'a> = Box<dyn Fn(usize) -> bool + 'a>;
    let kinds: [(&str, Selection); 6] = [
        ("translations", Box::new(move |i| i < nd && i % 6 < 3)),
        ("rotations", Box::new(move |i| i < nd && i % 6 >= 3)),
        ("multipliers", Box::new(move |i| (nd..nd + na).contains(&i))),
        (
            "stabilization",
            Box::new(move |i| (nd + na..so).contains(&i)),
        ),
        ("element states", Box::new(move |i| i >= so)),
        ("all unknowns", Box::new(|_| true)),
    ];
    for (kind, selected) in kinds {
        if !(0..nu).any(&selected) {
            continue;
        }
        for trial in 0..2 {
            let u: Vec<f64> = (0..nu)
                .map(|i| if selected(i) { rand() } else { 0.0 })
                .collect();
            let mut ju = vec![0.0; nu];
            for &(i, j, v) in &jacobian {
                ju[i] += v * u[j];
            }
            let eps = 1e-5 * x_scale;
            let along = |sign: f64| -> Vec<f64> {
                let xs: Vec<f64> = x.iter().zip(&u).map(|(a, b)| a + sign * eps * b).collect();
                f.residual(
                    &xs,
                    &mut Data::new(&sim.model, layout.clone()).expect("data"),
                )
            };
            let (rp, rm) = (along(1.0), along(-1.0));
            let fd = central(&rp, &rm, eps);
            let d = blockwise(&ju, &fd, &layout, 1e-12);
            assert!(
                d < 1e-6,
                "{name}: dR/dx along the {kind} (trial {trial}) differs from finite differences by {d:e}"
            );
        }
    }
    // dR/ds_n along random tangents.
    let n = sim.state.q.len();
    let ns = sim.state.x.len();
    let n_rows = sim.state.lambda.len();
    let tangent = |rand: &mut dyn FnMut() -> f64| StateTangent {
        q: (0..n).map(|_| Vec6::from_fn(|_, _| rand())).collect(),
        v: (0..n).map(|_| Vec6::from_fn(|_, _| rand())).collect(),
        vdot: (0..n).map(|_| Vec6::from_fn(|_, _| rand())).collect(),
        a: (0..n).map(|_| Vec6::from_fn(|_, _| rand())).collect(),
        lambda: (0..n_rows).map(|_| rand()).collect(),
        x: (0..ns).map(|_| rand()).collect(),
        xdot: (0..ns).map(|_| rand()).collect(),
        w: (0..ns).map(|_| rand()).collect(),
    };
    for trial in 0..3 {
        let ds = tangent(&mut rand);
        let jv = f.start_jvp(&x, &ds, &mut data);
        let eps = 1e-6;
        let moved = |sign: f64| moved_state(sim, &ds, sign * eps);
        let (sp, sm) = (moved(1.0), moved(-1.0));
        let rp =
            StepFunction::new(&sim.model, &layout, &sp, &sim.settings, h).residual(&x, &mut data);
        let rm =
            StepFunction::new(&sim.model, &layout, &sm, &sim.settings, h).residual(&x, &mut data);
        let fd = central(&rp, &rm, eps);
        let d = blockwise(&jv, &fd, &layout, 1e-6);
        assert!(d < 1e-5, "{name}: dR/ds_n (trial {trial}) differs by {d:e}");
        // <w, J ds> = <J^T w, ds>
        let w: Vec<f64> = (0..nu).map(|_| rand()).collect();
        let left: f64 = w.iter().zip(&jv).map(|(a, b)| a * b).sum();
        let right = f.start_vjp(&x, &w, &mut data).dot(&ds);
        assert!(
            (left - right).abs() <= 1e-10 * left.abs().max(right.abs()).max(1e-12),
            "{name}: transposed product {right:e} against {left:e}"
        );
    }
}

/// The simulation's state moved by `c ds` (configurations on the group: `q exp(c ds.q)`;
/// the multipliers stay, they do not enter the step).
fn moved_state(sim: &Simulation, ds: &StateTangent, c: f64) -> State {
    let mut s: State = sim.state.clone();
    for i in 0..s.q.len() {
        s.q[i] = sim.model.group.integrate(&s.q[i], &(ds.q[i] * c));
        s.v[i] += ds.v[i] * c;
        s.vdot[i] += ds.vdot[i] * c;
        s.a[i] += ds.a[i] * c;
    }
    for i in 0..s.x.len() {
        s.x[i] += ds.x[i] * c;
        s.xdot[i] += ds.xdot[i] * c;
        s.w[i] += ds.w[i] * c;
    }
    s
}

/// The components of a state tangent, one vector per kind (compared kind by kind: their
/// scales differ by powers of h).
fn components(t: &StateTangent) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = [&t.q, &t.v, &t.vdot, &t.a]
        .into_iter()
        .map(|v| v.iter().flat_map(|x| x.iter().copied()).collect())
        .collect();
    out.extend([&t.lambda, &t.x, &t.xdot, &t.w].map(|v| v.clone()));
    out
}

/// The end state `s_{n+1}(x, s_n)` of the step: its tangent `end_jvp` along random
/// `(dx, ds_n)` against central differences (configurations compared on the group), and
/// `end_vjp` as its transpose.
fn check_end_state(name: &str, sim: &Simulation) {
    let h = sim.settings.h;
    let f = sim.step_function(h);
    let layout = sim.data.layout.clone();
    let mut data = Data::new(&sim.model, layout.clone()).expect("data");
    let mut rand = noise(5);
    let mut x = f.predict();
    let x_scale = x.iter().fold(1e-3f64, |m, v| m.max(v.abs()));
    for v in &mut x {
        *v += 0.05 * x_scale * rand();
    }
    let group = sim.model.group;
    let (n, ns, n_rows) = (layout.n_nodes, layout.n_states, layout.n_rows);
    let mut ds = StateTangent::zeros_of(&layout);
    for i in 0..n {
        ds.q[i] = Vec6::from_fn(|_, _| rand());
        ds.v[i] = Vec6::from_fn(|_, _| rand());
        ds.vdot[i] = Vec6::from_fn(|_, _| rand());
        ds.a[i] = Vec6::from_fn(|_, _| rand());
    }
    for i in 0..ns {
        (ds.x[i], ds.xdot[i], ds.w[i]) = (rand(), rand(), rand());
    }
    let dx: Vec<f64> = (0..x.len()).map(|_| rand() * x_scale).collect();
    let jv = f.end_jvp(&x, &dx, &ds, None, &mut data);
    let eps = 1e-6;
    let end = f.end_state(&x);
    let moved = |sign: f64| {
        let s = moved_state(sim, &ds, sign * eps);
        let xm: Vec<f64> = x.iter().zip(&dx).map(|(a, b)| a + sign * eps * b).collect();
        StepFunction::new(&sim.model, &layout, &s, &sim.settings, h).end_state(&xm)
    };
    let (ep, em) = (moved(1.0), moved(-1.0));
    let mut fd = StateTangent::zeros(n, n_rows, ns);
    for i in 0..n {
        let (dp, dm) = (
            group.difference(&end.q[i], &ep.q[i]),
            group.difference(&end.q[i], &em.q[i]),
        );
        fd.q[i] = (dp - dm) / (2.0 * eps);
        fd.v[i] = (ep.v[i] - em.v[i]) / (2.0 * eps);
        fd.vdot[i] = (ep.vdot[i] - em.vdot[i]) / (2.0 * eps);
        fd.a[i] = (ep.a[i] - em.a[i]) / (2.0 * eps);
    }
    let diff = |a: &[f64], b: &[f64]| central(a, b, eps);
    fd.lambda = diff(&ep.lambda, &em.lambda);
    fd.x = diff(&ep.x, &em.x);
    fd.xdot = diff(&ep.xdot, &em.xdot);
    fd.w = diff(&ep.w, &em.w);
    let d = components(&jv)
        .iter()
        .zip(&components(&fd))
        .map(|(a, b)| relative_difference(a, b, 1e-8))
        .fold(0.0f64, f64::max);
    assert!(
        d < 1e-6,
        "{name}: ds_(n+1) differs from central differences by {d:e}"
    );
    // The stabilized update q_n exp(dq + B(q_n; p)^T zeta) along a joint's position.
    if layout.stabilized && !sim.model.joints.is_empty() {
        let params = Parameters::new(&sim.model);
        let id = params
            .id(&format!("joint.{}.position.1", sim.model.joints[0].name))
            .expect("joint position");
        let mut dp = vec![0.0; params.len()];
        dp[id.0 as usize] = 1.0;
        let zero = StateTangent::zeros_of(&layout);
        let dx0 = vec![0.0; x.len()];
        let jp = f.end_jvp(&x, &dx0, &zero, Some((&params, &dp)), &mut data);
        let value = params.value(&sim.model, id);
        let eps = 1e-6;
        let end_of = |v: f64| {
            let mut m = (*sim.model).clone();
            params.set(&mut m, id, v);
            let l = Layout::with_rows(&m, true, &layout.redundant_rows());
            StepFunction::new(&m, &l, &sim.state, &sim.settings, h).end_state(&x)
        };
        let (ep, em) = (end_of(value + eps), end_of(value - eps));
        let mut worst = 0.0f64;
        let scale = jp.q.iter().fold(1e-12f64, |m, q| m.max(q.abs().max()));
        for i in 0..n {
            let fd = (group.difference(&end.q[i], &ep.q[i])
                - group.difference(&end.q[i], &em.q[i]))
                / (2.0 * eps);
            worst = worst.max((fd - jp.q[i]).abs().max() / scale);
        }
        assert!(
            worst < 1e-6,
            "{name}: dq_(n+1)/dp of a joint position differs by {worst:e}"
        );
        assert!(scale > 1e-9, "{name}: zeta moves the configuration");
        let all: Vec<_> = params.ids().collect();
        let (_, _, pbar) = f.end_vjp(&x, &jv, Some((&params, &all)), &mut data);
        let left = jv.dot(&jp);
        assert!(
            (left - pbar[id.0 as usize]).abs() <= 1e-10 * left.abs().max(1e-300),
            "{name}: end_vjp's parameter part {} against {left:e}",
            pbar[id.0 as usize]
        );
    }
    // <bar, J (dx, ds)> = <J_x^T bar, dx> + <J_s^T bar, ds>
    let mut bar = StateTangent::zeros_of(&layout);
    bar.add_scaled(1.0, &fd);
    for v in bar.q.iter_mut().chain(bar.v.iter_mut()) {
        *v = Vec6::from_fn(|_, _| rand());
    }
    let (xbar, sbar, _) = f.end_vjp(&x, &bar, None, &mut data);
    let left = bar.dot(&jv);
    let right = xbar.iter().zip(&dx).map(|(a, b)| a * b).sum::<f64>() + sbar.dot(&ds);
    assert!(
        (left - right).abs() <= 1e-10 * left.abs().max(right.abs()),
        "{name}: end_vjp {right:e} against end_jvp {left:e}"
    );
}

/// `dR/dp` (products with a vector and a transposed vector) against central differences of
/// the step residual of the model with one parameter moved (through `Parameters::set`, at
/// the same row scale), for every parameter that enters the residual, or every k-th of them
/// to keep it to about `most` of them; returns the paths checked.
fn check_parameters(name: &str, sim: &Simulation, most: usize) -> Vec<String> {
    let h = sim.settings.h;
    let layout = sim.data.layout.clone();
    let redundant = layout.redundant_rows();
    let f = sim.step_function(h);
    let mass = f.step.mass;
    let mut data = Data::new(&sim.model, layout.clone()).expect("data");
    let params = Parameters::new(&sim.model);
    let mut rand = noise(11);
    let mut x = f.predict();
    let x_scale = x.iter().fold(1e-3f64, |m, v| m.max(v.abs()));
    for v in &mut x {
        *v += 0.05 * x_scale * rand();
    }
    let residual_of = |model: &flexmb::Model| {
        let l = Layout::with_rows(model, layout.stabilized, &redundant);
        let mut d = Data::new(model, l.clone()).expect("data");
        StepFunction::new(model, &l, &sim.state, &sim.settings, h)
            .with_mass_scale(mass)
            .residual(&x, &mut d)
    };
    let ids: Vec<ParamId> = params
        .ids()
        .filter(|&id| params.role(id) == ParamRole::Residual)
        .collect();
    let stride = ids.len().div_ceil(most).max(1);
    let mut picked: Vec<ParamId> = ids.iter().step_by(stride).copied().collect();
    // and every kind at least once: a model of many beam elements has hundreds of section
    // parameters, among which a stride alone skips the rarer kinds
    let mut covered = kinds(
        &picked
            .iter()
            .map(|&id| params.path(id).to_string())
            .collect::<Vec<_>>(),
    );
    for &id in &ids {
        let kind = kinds(&[params.path(id).to_string()]);
        if !kind.is_subset(&covered) {
            covered.extend(kind);
            picked.push(id);
        }
    }
    let mut checked = Vec::new();
    for &id in &picked {
        let mut dp = vec![0.0; params.len()];
        dp[id.0 as usize] = 1.0;
        let jv = f.parameter_jvp(&x, &params, &dp, &mut data);
        let value = params.value(&sim.model, id);
        let eps = 1e-5 * value.abs().max(1.0);
        let moved = |sign: f64| {
            let mut m = (*sim.model).clone();
            params.set(&mut m, id, value + sign * eps);
            residual_of(&m)
        };
        // Damping coefficients are not negative: at 0 the derivative is the one from above
        // (the residual is linear in them), taken by a forward difference.
        let one_sided = value == 0.0 && params.path(id).contains(".damping.");
        let (rp, rm) = if one_sided {
            (moved(1.0), moved(0.0))
        } else {
            (moved(1.0), moved(-1.0))
        };
        let width = if one_sided { eps } else { 2.0 * eps };
        let fd: Vec<f64> = rp.iter().zip(&rm).map(|(a, b)| (a - b) / width).collect();
        let scale = fd.iter().chain(&jv).fold(0.0f64, |m, v| m.max(v.abs()));
        let d = jv
            .iter()
            .zip(&fd)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        // Round-off of the differenced residual: a derivative far below the residual's size
        // (a gravity component times the row scale) is compared to that floor.
        let r_max = rp.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let floor = 100.0 * f64::EPSILON * r_max / eps;
        // Joint positions and spring points are themselves differenced (the listed
        // finite-difference default, `parameter_derivatives`) in rows that subtract node
        // positions of metres: their round-off is about 1e-6 of the derivative.
        let path = params.path(id);
        let differenced = path.contains(".position.") || path.contains(".point_");
        let relative = if differenced { 1e-5 } else { 1e-6 };
        assert!(
            d <= relative * scale + floor,
            "{name}: dR/d {} differs from finite differences by {d:e} (scale {scale:e})",
            params.path(id)
        );
        checked.push(params.path(id).to_string());
    }
    // <w, J_p dp> = <J_p^T w, dp>
    let nu = layout.n_unknowns();
    let w: Vec<f64> = (0..nu).map(|_| rand()).collect();
    let dp: Vec<f64> = (0..params.len()).map(|_| rand()).collect();
    let left: f64 = w
        .iter()
        .zip(f.parameter_jvp(&x, &params, &dp, &mut data))
        .map(|(a, b)| a * b)
        .sum();
    let right: f64 = f
        .parameter_vjp(&x, &params, &w, &mut data)
        .iter()
        .zip(&dp)
        .map(|(a, b)| a * b)
        .sum();
    assert!(
        (left - right).abs() <= 1e-10 * left.abs().max(right.abs()),
        "{name}: transposed parameter product {right:e} against {left:e}"
    );
    checked
}

/// The kinds of parameters the checks above cover (a path without its item name and
/// component), so that a kind cannot drop out unnoticed.
fn kinds(paths: &[String]) -> std::collections::BTreeSet<String> {
    paths
        .iter()
        .map(|p| {
            let parts: Vec<&str> = p.split('.').collect();
            // `model.gravity.k` has no item name; the others are `kind.name.field...`.
            let skip = if parts[0] == "model" { 1 } else { 2 };
            let mut k = vec![parts[0]];
            k.extend(
                parts
                    .iter()
                    .skip(skip)
                    .filter(|s| s.parse::<usize>().is_err()),
            );
            k.join(".")
        })
        .collect()
}

#[test]
fn step_parameter_derivatives_match_finite_differences() {
    let mut paths = Vec::new();
    for (file, overrides) in [
        ("heavy_top.toml", &[][..]),
        ("heavy_top_r3so3.toml", &[][..]),
        ("chain_10.toml", &[][..]),
        ("flexible_four_bar.toml", &[][..]),
        ("heavy_top.toml", &["solver.formulation=index2"][..]),
        ("slider_crank.toml", &[][..]),
    ] {
        let sim = simulation(file, overrides, 3);
        paths.extend(check_parameters(file, &sim, 40));
    }
    for stabilized in [false, true] {
        let sim = viscoelastic_pair(flexmb_lie::Group::SE3, stabilized);
        paths.extend(check_parameters("viscoelastic pair", &sim, usize::MAX));
    }
    // The nodal damping alpha D v of pseudo-dynamic statics: D depends on the masses and
    // inertias of bodies and beams.
    for file in ["heavy_top.toml", "flexible_four_bar.toml"] {
        let mut sim = simulation(file, &[], 3);
        sim.settings.nodal_damping = 7.0;
        let name = format!("{file} with nodal damping");
        paths.extend(check_parameters(&name, &sim, usize::MAX));
    }
    let covered = kinds(&paths);
    for kind in [
        "body.mass",
        "body.inertia",
        "body.com",
        "joint.position",
        "joint.drive.slope",
        "model.gravity",
        "beam.section.EA",
        "beam.section.rhoA",
        "beam.element.section.EI2",
        "beam.element.section.rhoA",
        "beam.damping.stiffness",
        "spring.stiffness",
        "spring.rest_length",
        "spring.relaxation_stiffness",
        "spring.relaxation_damping",
        "rope.stiffness",
        "rope.damping",
        "rope.rest_length",
        "rope.points.point",
    ] {
        assert!(covered.contains(kind), "{kind} not covered: {covered:?}");
    }
}

#[test]
fn heavy_top_step_jacobians_match_finite_differences_on_both_groups() {
    check("heavy top SE(3)", &simulation("heavy_top.toml", &[], 5));
    check(
        "heavy top R3xSO(3)",
        &simulation("heavy_top_r3so3.toml", &[], 5),
    );
}

#[test]
fn commutator_update_step_jacobians_match_finite_differences() {
    // The configuration update q_n exp(dq + sigma h^3 [v_n, a_n]) moves with v_n and a_n;
    // a large sigma makes that dependence visible in the differences.
    let set = [
        "solver.lie_update=commutator",
        "solver.lie_update_sigma=0.9",
    ];
    for file in ["heavy_top.toml", "heavy_top_r3so3.toml"] {
        let sim = simulation(file, &set, 5);
        check(&format!("{file}, commutator update"), &sim);
    }
    let mut with_index2 = set.to_vec();
    with_index2.push("solver.formulation=index2");
    let sim = simulation("chain_10.toml", &with_index2, 5);
    check("chain_10, commutator update, stabilized index 2", &sim);
}

#[test]
fn lie_algebra_update_step_jacobians_match_finite_differences() {
    // q_{n+1} = q_n o C(Theta), v = M(Theta) Theta', vdot = M Theta'' + N(Theta, Theta'):
    // the velocities and accelerations move with the configuration's unknowns, and, in
    // R3xSO(3)'s chart on SE(3), the start in the chart with v_n.
    for update in ["lie_algebra", "lie_algebra_r3xso3"] {
        let set = format!("solver.lie_update={update}");
        for file in ["heavy_top.toml", "heavy_top_r3so3.toml"] {
            let sim = simulation(file, &[&set], 5);
            check(&format!("{file}, {update} update"), &sim);
        }
        let sim = simulation("chain_10.toml", &[&set, "solver.formulation=index2"], 5);
        check(
            &format!("chain_10, {update} update, stabilized index 2"),
            &sim,
        );
        let sim = simulation("flexible_four_bar.toml", &[&set], 3);
        check(&format!("flexible four-bar, {update} update"), &sim);
    }
}

#[test]
fn chain_step_jacobians_match_finite_differences() {
    check("chain_10", &simulation("chain_10.toml", &[], 5));
}

#[test]
fn beam_step_jacobians_match_finite_differences() {
    check(
        "flexible four-bar",
        &simulation("flexible_four_bar.toml", &[], 3),
    );
}

#[test]
fn stabilized_step_jacobians_match_finite_differences() {
    let sim = simulation("heavy_top.toml", &["solver.formulation=index2"], 5);
    assert!(sim.data.layout.stabilized);
    check("heavy top, stabilized index 2", &sim);
    let sim = simulation("chain_10.toml", &["solver.formulation=index2"], 5);
    check("chain_10, stabilized index 2", &sim);
    // A driven revolute joint turning (the spin-up's hub): Phi_t depends on q.
    let sim = simulation("spin_up.toml", &["solver.formulation=index2"], 1000);
    check("spin-up, stabilized index 2", &sim);
}

/// Two bodies on SE(3) or R3xSO(3), the first on a spherical joint to the ground, joined by a
/// spring-damper with a Maxwell branch between offset points and tied to the ground by a
/// second one (two element states, of two elements), and held by a rope from the ground over
/// a, b and a again back to the ground (an element on five slots, one node on two of them),
/// under gravity: the element-state block of the step and an element on more than two
/// slots.
fn viscoelastic_pair(group: flexmb_lie::Group, stabilized: bool) -> Simulation {
    use flexmb::model::{JointKind, Model, Relaxation, SpringDamper};
    use flexmb_lie::{Frame, Mat3, Vec3};
    let mut m = Model::new(group);
    m.gravity = Vec3::new(0.0, 0.0, -9.81);
    let a = m.add_node("a", Frame::new(Vec3::new(0.5, 0.0, 0.0), Mat3::identity()));
    let b = m.add_node("b", Frame::new(Vec3::new(1.2, 0.3, -0.2), Mat3::identity()));
    let inertia = Mat3::new(0.3, 0.01, 0.0, 0.01, 0.2, 0.02, 0.0, 0.02, 0.25);
    m.add_body("a", a, 2.0, Vec3::new(0.05, 0.0, 0.0), inertia);
    m.add_body("b", b, 1.0, Vec3::zeros(), inertia * 0.5);
    m.add_joint(
        "pivot",
        JointKind::Spherical,
        None,
        Some(a),
        Vec3::zeros(),
        Mat3::identity(),
        None,
    );
    m.springs.push(SpringDamper {
        name: "mount".into(),
        node_a: Some(a),
        node_b: Some(b),
        point_a: Vec3::new(0.1, 0.05, 0.0),
        point_b: Vec3::new(-0.05, 0.0, 0.1),
        stiffness: 300.0,
        damping: 2.0,
        rest_length: 0.6,
        relaxation: Some(Relaxation {
            stiffness: 500.0,
            damping: 20.0,
        }),
    });
    let at = |node, point| flexmb::model::RopePoint { node, point };
    m.ropes.push(flexmb::model::Rope {
        name: "sling".into(),
        points: vec![
            at(None, Vec3::new(0.3, 0.5, 1.0)),
            at(Some(a), Vec3::new(0.1, 0.1, 0.0)),
            at(Some(b), Vec3::new(0.0, 0.1, 0.05)),
            at(Some(a), Vec3::new(-0.1, 0.0, 0.1)),
            at(None, Vec3::new(1.5, 0.2, 1.0)),
        ],
        stiffness: 400.0,
        damping: 3.0,
        rest_length: 3.0,
    });
    m.springs.push(SpringDamper {
        name: "tie".into(),
        node_a: None,
        node_b: Some(a),
        point_a: Vec3::new(0.4, -0.6, 0.2),
        point_b: Vec3::new(0.0, -0.1, 0.0),
        stiffness: 50.0,
        damping: 0.0,
        rest_length: 0.5,
        relaxation: Some(Relaxation {
            stiffness: 120.0,
            damping: 6.0,
        }),
    });
    let mut s = flexmb::DynamicSettings::new(1.0, 1e-3);
    if stabilized {
        s.formulation = flexmb::solve::Formulation::StabilizedIndex2;
    }
    let mut sim = Simulation::new(&m, s).expect("starts");
    for _ in 0..20 {
        sim.step().expect("step");
    }
    sim
}

#[test]
fn element_state_step_jacobians_match_finite_differences() {
    for group in [flexmb_lie::Group::SE3, flexmb_lie::Group::R3xSO3] {
        for stabilized in [false, true] {
            let sim = viscoelastic_pair(group, stabilized);
            assert_eq!(sim.data.layout.n_states, 2);
            let name = format!("viscoelastic pair on {group:?}, stabilized {stabilized}");
            check(&name, &sim);
        }
    }
}

/// The heavy top with two inputs ([`flexmb::model::Input`]): a follower torque and a dead
/// force at its node, `u(t)` a sine each in a run.
fn heavy_top_with_inputs() -> Simulation {
    use flexmb::model::{Input, Load, LoadFrame, TimeFunction};
    let mf = flexmb::input::read_model_file(&common::example("heavy_top.toml"), &[]).unwrap();
    let flexmb::input::Analysis::Dynamic(settings) = mf.analysis else {
        panic!("dynamic")
    };
    let mut model = mf.model;
    let node = model.bodies[0].node;
    let sine = |amplitude| TimeFunction::Sine {
        amplitude,
        frequency: 3.0,
        phase: 0.2,
        offset: 0.1,
    };
    let actuators = [
        (
            "spin",
            flexmb_lie::Vec3::zeros(),
            flexmb_lie::Vec3::new(0.1, -0.2, 1.0),
            LoadFrame::Body,
        ),
        (
            "push",
            flexmb_lie::Vec3::new(2.0, 0.5, -1.0),
            flexmb_lie::Vec3::zeros(),
            LoadFrame::Inertial,
        ),
    ];
    for (k, (name, force, torque, frame)) in actuators.into_iter().enumerate() {
        model.inputs.push(Input {
            name: name.into(),
            load: model.loads.len(),
        });
        model.loads.push(Load {
            name: name.into(),
            node,
            force,
            torque,
            frame,
            function: sine(0.5 + k as f64),
            input: Some(k),
        });
    }
    let mut sim = Simulation::new(model, settings).expect("starts");
    for _ in 0..5 {
        sim.step().expect("step");
    }
    sim
}

#[test]
fn input_jacobian_matches_finite_differences() {
    // R(x; s_n, u_{n+1}, p) is linear in u: dR/du against central differences of the
    // residual with the inputs given, its products against it, and a step given its own
    // functions' values against a step that reads them.
    let sim = heavy_top_with_inputs();
    let h = sim.settings.h;
    let layout = sim.data.layout.clone();
    let mut data = Data::new(&sim.model, layout.clone()).expect("data");
    let reading = sim.step_function(h);
    let u_run = reading.input_values();
    assert_eq!(u_run.len(), 2);
    let mut rand = noise(11);
    let mut x = reading.predict();
    for v in &mut x {
        *v += 1e-3 * rand();
    }
    let given = sim.step_function(h).with_inputs(&u_run);
    assert_eq!(
        given.residual(&x, &mut data),
        reading.residual(&x, &mut data),
        "the functions' values given: the same residual"
    );
    let u = [0.7, -1.3];
    let f = sim.step_function(h).with_inputs(&u);
    let jacobian = f.input_jacobian(&x);
    let nu = layout.n_unknowns();
    for k in 0..2 {
        let mut column = vec![0.0; nu];
        for &(i, j, v) in &jacobian {
            if j == k {
                column[i] += v;
            }
        }
        // (linear: a large step has no truncation error, and less round-off)
        let eps = 1.0;
        let along = |sign: f64| {
            let mut us = u;
            us[k] += sign * eps;
            sim.step_function(h)
                .with_inputs(&us)
                .residual(&x, &mut Data::new(&sim.model, layout.clone()).unwrap())
        };
        let (rp, rm) = (along(1.0), along(-1.0));
        let fd = central(&rp, &rm, eps);
        let d = blockwise(&column, &fd, &layout, 1e-12);
        assert!(
            d < 1e-9,
            "dR/du_{k} differs from central differences by {d:e}"
        );
        let s = f.step.scale;
        assert!(column.iter().any(|v| v.abs() > 0.1 * s), "input {k} acts");
    }
    // <w, J du> = <J^T w, du>
    let du = [rand(), rand()];
    let w: Vec<f64> = (0..nu).map(|_| rand()).collect();
    let left: f64 = w.iter().zip(f.input_jvp(&x, &du)).map(|(a, b)| a * b).sum();
    let right: f64 = f.input_vjp(&x, &w).iter().zip(du).map(|(a, b)| a * b).sum();
    assert!((left - right).abs() <= 1e-12 * left.abs().max(1e-300));
    // The inputs' parameters at given inputs: the force per unit of input scales with u, its
    // function's amplitude no longer enters.
    let params = Parameters::new(&sim.model);
    for (path, moves) in [
        ("input.push.force.0", true),
        ("input.push.function.amplitude", false),
    ] {
        let id = params.id(path).unwrap();
        let mut dp = vec![0.0; params.len()];
        dp[id.0 as usize] = 1.0;
        let jp = f.parameter_jvp(&x, &params, &dp, &mut data);
        let value = params.value(&sim.model, id);
        let residual_at = |v: f64| {
            let mut m = (*sim.model).clone();
            params.set(&mut m, id, v);
            StepFunction::new(&m, &layout, &sim.state, &sim.settings, h)
                .with_mass_scale(f.step.mass)
                .with_inputs(&u)
                .residual(&x, &mut Data::new(&m, layout.clone()).unwrap())
        };
        let eps = 1.0; // (linear in both)
        let (rp, rm) = (residual_at(value + eps), residual_at(value - eps));
        let fd = central(&rp, &rm, eps);
        let size = fd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert_eq!(size > 1e-3 * f.step.scale, moves, "{path}: {size:e}");
        let d = blockwise(&jp, &fd, &layout, 1e-12);
        assert!(d < 1e-8, "{path}: dR/dp differs by {d:e}");
    }
}

#[test]
fn sparse_step_matrices_are_the_products() {
    // dR/ds_n and dR/dp as triplets (what a transcription assembles) against the products
    // checked against central differences above, along random directions. (dR/ds_n is built
    // from the partials directly, not from the products.)
    let sims = [
        ("heavy top with inputs", heavy_top_with_inputs()),
        (
            "heavy top R3xSO(3), Lie algebra update",
            simulation(
                "heavy_top_r3so3.toml",
                &["solver.lie_update=lie_algebra"],
                3,
            ),
        ),
        (
            "flexible four-bar, commutator",
            simulation(
                "flexible_four_bar.toml",
                &["solver.lie_update=commutator"],
                3,
            ),
        ),
        (
            "chain_10, stabilized",
            simulation("chain_10.toml", &["solver.formulation=index2"], 3),
        ),
        (
            "viscoelastic pair",
            viscoelastic_pair(flexmb_lie::Group::SE3, false),
        ),
    ];
    for (name, sim) in sims {
        let h = sim.settings.h;
        let layout = sim.data.layout.clone();
        let mut data = Data::new(&sim.model, layout.clone()).expect("data");
        let f = sim.step_function(h);
        let mut rand = noise(13);
        let mut x = f.predict();
        for v in &mut x {
            *v += 1e-3 * rand();
        }
        let nu = layout.n_unknowns();
        let product = |triplets: &[(usize, usize, f64)], d: &[f64]| {
            let mut out = vec![0.0; nu];
            for &(i, j, v) in triplets {
                out[i] += v * d[j];
            }
            out
        };
        let js = f.start_jacobian(&x, &mut data);
        let mut ds = StateTangent::zeros_of(&layout);
        let flat: Vec<f64> = (0..StateTangent::flat_len(&layout))
            .map(|_| rand())
            .collect();
        for (j, v) in flat.iter().enumerate() {
            *ds.flat_mut(j) = *v;
        }
        let d = blockwise(
            &product(&js, &flat),
            &f.start_jvp(&x, &ds, &mut data),
            &layout,
            1e-300,
        );
        assert!(
            d < 1e-12,
            "{name}: dR/ds_n as triplets differs from the product by {d:e}"
        );
        let params = Parameters::new(&sim.model);
        let ids: Vec<_> = params.ids().step_by(3).collect();
        let jp = f.parameter_jacobian(&x, &params, &ids, &mut data);
        let dp_ids: Vec<f64> = ids.iter().map(|_| rand()).collect();
        let mut dp = vec![0.0; params.len()];
        for (id, v) in ids.iter().zip(&dp_ids) {
            dp[id.0 as usize] = *v;
        }
        let expected = f.parameter_jvp(&x, &params, &dp, &mut data);
        let d = blockwise(&product(&jp, &dp_ids), &expected, &layout, 1e-300);
        assert!(
            d < 1e-12,
            "{name}: dR/dp as triplets differs from the product by {d:e}"
        );
    }
}
