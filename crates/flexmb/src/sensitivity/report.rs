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

/// `gradient_check.csv`: `criterion,parameter,exact,fd,fd_step,relative_difference` with
/// the exact gradient (`exact`, adjoint) against central differences (`fd`). The floor of
/// the relative difference is `1e-8` times the largest gradient of the criterion.
pub fn check_csv(setup: &Setup, exact: &Gradients, fd: &Gradients) -> (String, f64) {
    let mut out = String::from("criterion,parameter,exact,fd,fd_step,relative_difference\n");
    let mut worst = 0.0f64;
    for (c, crit) in setup.criteria.criteria.iter().enumerate() {
        let floor = 1e-8
            * exact.gradients[c]
                .iter()
                .fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
        for (k, d) in setup.design.iter().enumerate() {
            let (a, b) = (exact.gradients[c][k], fd.gradients[c][k]);
            let r = relative_difference(a, b, floor);
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

/// `optimization.csv`: `evaluation,criterion,<path>...,d/d <path>...`, one row per
/// improvement (the starting point first, the best point last).
pub fn optimization_csv(design: &[DesignParameter], optimum: &super::optimize::Optimum) -> String {
    let mut out = String::from("evaluation,criterion");
    for d in design {
        let _ = write!(out, ",{}", d.path);
    }
    for d in design {
        let _ = write!(out, ",d/d {}", d.path);
    }
    out.push('\n');
    for it in &optimum.history {
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
