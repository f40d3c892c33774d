//! The files of `flexmb sensitivity`: `gradients.json`, `gradients.csv` and, with
//! `--check`, `gradient_check.csv`.

use super::{DesignParameter, Gradients, Method, Setup, Stats};
use crate::output::push_number;
use serde::Serialize;
use std::fmt::Write as _;

#[derive(Serialize)]
struct Parameter<'a> {
    path: &'a str,
    value: f64,
    scale: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    fd_step: Option<f64>,
}

#[derive(Serialize)]
struct CriterionOut<'a> {
    name: &'a str,
    kind: super::CriterionKind,
    expression: &'a str,
    value: f64,
    /// `dJ/dp` by parameter path.
    gradient: serde_json::Map<String, serde_json::Value>,
}

#[derive(Serialize)]
struct Report<'a> {
    method: Method,
    parameters: Vec<Parameter<'a>>,
    criteria: Vec<CriterionOut<'a>>,
    stats: Stats,
    wall_seconds: f64,
}

/// `gradients.json`: the method, the parameters (path, value, scale, finite-difference
/// step), each criterion with its value and `dJ/dp` by path, the statistics.
pub fn json(setup: &Setup, values: &[f64], method: Method, g: &Gradients, wall: f64) -> String {
    let parameters = setup
        .design
        .iter()
        .zip(values)
        .enumerate()
        .map(|(k, (d, &value))| Parameter {
            path: &d.path,
            value,
            scale: d.scale,
            fd_step: g.fd_steps.as_ref().map(|s| s[k]),
        })
        .collect();
    let criteria = setup
        .criteria
        .criteria
        .iter()
        .enumerate()
        .map(|(c, crit)| CriterionOut {
            name: &crit.name,
            kind: crit.kind,
            expression: &crit.text,
            value: g.values[c],
            gradient: setup
                .design
                .iter()
                .zip(&g.gradients[c])
                .map(|(d, &v)| (d.path.clone(), serde_json::json!(v)))
                .collect(),
        })
        .collect();
    let report = Report {
        method,
        parameters,
        criteria,
        stats: g.stats,
        wall_seconds: wall,
    };
    let mut text = serde_json::to_string_pretty(&report).expect("numbers and strings");
    text.push('\n');
    text
}

/// `gradients.csv`: `criterion,parameter,value,gradient,scaled_gradient,fd_step`, one row
/// per criterion and parameter (`value` the criterion's, `scaled_gradient = scale dJ/dp`,
/// `fd_step` empty unless by finite differences).
pub fn csv(setup: &Setup, g: &Gradients) -> String {
    let mut out = String::from("criterion,parameter,value,gradient,scaled_gradient,fd_step\n");
    for (c, crit) in setup.criteria.criteria.iter().enumerate() {
        for (k, d) in setup.design.iter().enumerate() {
            let _ = write!(out, "{},{},", crit.name, d.path);
            push_number(&mut out, g.values[c]);
            out.push(',');
            push_number(&mut out, g.gradients[c][k]);
            out.push(',');
            push_number(&mut out, d.scale * g.gradients[c][k]);
            out.push(',');
            if let Some(s) = &g.fd_steps {
                push_number(&mut out, s[k]);
            }
            out.push('\n');
        }
    }
    out
}

/// Relative difference of two gradients, `|a - b| / max(|a|, |b|, floor)`.
pub fn relative_difference(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(floor)
}

/// The relative differences of two sets of gradients, `[criterion][parameter]`, compared as
/// `scale dJ/dp` (`scales`: the design parameters', each in its typical magnitude, so that
/// the gradient of a parameter with large units is not measured against its neighbours'
/// unscaled gradients), with the floor `1e-8` times the criterion's largest `|scale dJ/dp|`
/// in `a`.
pub fn differences(scales: &[f64], a: &Gradients, b: &Gradients) -> Vec<Vec<f64>> {
    a.gradients
        .iter()
        .zip(&b.gradients)
        .map(|(ga, gb)| {
            let floor = 1e-8
                * ga.iter()
                    .zip(scales)
                    .fold(f64::MIN_POSITIVE, |m, (v, s)| m.max((s * v).abs()));
            ga.iter()
                .zip(gb)
                .zip(scales)
                .map(|((x, y), s)| relative_difference(s * x, s * y, floor))
                .collect()
        })
        .collect()
}

/// The largest of [`differences`] for the design parameters of `setup`.
pub fn largest_difference(setup: &Setup, a: &Gradients, b: &Gradients) -> f64 {
    differences(&scales(setup), a, b)
        .iter()
        .flatten()
        .fold(0.0, |m, &r| m.max(r))
}

/// `gradient_check.csv`: `criterion,parameter,exact,fd,fd_step,relative_difference` with
/// the exact gradient (`exact`, adjoint) against central differences (`fd`), and their
/// relative difference ([`differences`]: of `scale dJ/dp`); and the largest.
pub fn check_csv(setup: &Setup, exact: &Gradients, fd: &Gradients) -> (String, f64) {
    let mut out = String::from("criterion,parameter,exact,fd,fd_step,relative_difference\n");
    let differences = differences(&scales(setup), exact, fd);
    let mut worst = 0.0f64;
    for (c, crit) in setup.criteria.criteria.iter().enumerate() {
        for (k, d) in setup.design.iter().enumerate() {
            let (a, b) = (exact.gradients[c][k], fd.gradients[c][k]);
            let r = differences[c][k];
            worst = worst.max(r);
            let _ = write!(out, "{},{},", crit.name, d.path);
            for x in [a, b, fd.fd_steps.as_ref().map_or(f64::NAN, |s| s[k]), r] {
                push_number(&mut out, x);
                out.push(',');
            }
            out.pop();
            out.push('\n');
        }
    }
    (out, worst)
}

/// The scales of the design parameters of `setup`.
fn scales(setup: &Setup) -> Vec<f64> {
    setup.design.iter().map(|d| d.scale).collect()
}

/// `optimization.csv`: `evaluation,criterion,<path>...,d/d <path>...`, one row per
/// improvement of `history` (the starting point first, the best point last).
pub fn optimization_csv(
    design: &[DesignParameter],
    history: &[super::optimize::Improvement],
) -> String {
    let mut out = String::from("evaluation,criterion");
    for d in design {
        let _ = write!(out, ",{}", d.path);
    }
    for d in design {
        let _ = write!(out, ",d/d {}", d.path);
    }
    out.push('\n');
    for it in history {
        let _ = write!(out, "{},", it.evaluation);
        push_number(&mut out, it.criterion);
        for x in it.values.iter().chain(&it.gradient) {
            out.push(',');
            push_number(&mut out, *x);
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{differences, Gradients};

    fn gradients(g: &[f64]) -> Gradients {
        Gradients {
            values: vec![0.0],
            gradients: vec![g.to_vec()],
            fd_steps: None,
            stats: Default::default(),
            warnings: Vec::new(),
        }
    }

    #[test]
    fn check_differences_compare_scaled_gradients() {
        // A parameter in large units (scale 1e9, say a modulus) has a small unscaled
        // gradient; 60-fold apart from its finite difference beside a neighbour of gradient
        // 1: the floor of 1e-8 times the largest unscaled gradient read 2.5e-4; in scale
        // dJ/dp the difference is 59/60.
        let (exact, fd) = (
            gradients(&[1.0, 4.2e-14]),
            gradients(&[1.0, 60.0 * 4.2e-14]),
        );
        let d = differences(&[1.0, 1e9], &exact, &fd);
        assert_eq!(d[0][0], 0.0);
        assert!((d[0][1] - 59.0 / 60.0).abs() < 1e-12, "{:?}", d);
        // Unscaled (every scale 1) the floor hides it.
        let unscaled = differences(&[1.0, 1.0], &exact, &fd);
        assert!(
            (unscaled[0][1] - 59.0 * 4.2e-14 / 1e-8).abs() < 1e-12,
            "{unscaled:?}"
        );
    }
}
