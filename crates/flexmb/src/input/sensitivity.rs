//! The sections of a sensitivity analysis: `[sensitivity]` (method and settings),
//! `[[design_parameter]]` (parameters by path), `[[reference]]` (signals read from CSV
//! files) and `[[criterion]]` (terminal or integral expressions of sensors).

use super::error::InputError;
use super::reader::Table;
use crate::model::{Model, Parameters};
use crate::sensitivity::{
    CriteriaSet, Criterion, CriterionKind, DesignParameter, Method, Reference, Setup,
    DEFAULT_FD_STEP, DEFAULT_MEMORY_BUDGET, FD_STEP_RANGE, MEMORY_BUDGET_MB_RANGE,
};
use std::collections::HashMap;
use std::path::Path;

type Result<T> = std::result::Result<T, InputError>;

/// Most samples of a reference signal.
const MAX_SAMPLES: usize = 10_000_000;

/// A name that a criterion's table writes into `gradients.csv`: like a sensor's, no commas,
/// quotes or control characters, and not `t` or `pi` (the expressions' built-ins).
fn check_name(t: &Table<'_>, name: &str) -> Result<()> {
    if name.contains([',', '"']) || name.chars().any(char::is_control) {
        return Err(t.key_err(
            "name",
            "must not contain commas, double quotes, line breaks or other control characters (it names a column or row of the result files)",
        ));
    }
    if name == "t" || name == "pi" {
        return Err(t.key_err(
            "name",
            format!(
                "'{name}' is a built-in of the expressions (time, the constant pi); choose another"
            ),
        ));
    }
    Ok(())
}

/// The sensitivity setup of a model file, `None` when it declares no criterion and no
/// design parameter; `file` is the model file's path (reference files are relative to it).
/// A static `analysis` takes terminal criteria and parameters that enter the equations.
pub(super) fn read_sensitivity(
    top: &Table<'_>,
    model: &Model,
    analysis: &super::Analysis,
    file: &str,
) -> Result<Option<Setup>> {
    let statics = matches!(analysis, super::Analysis::Static(_));
    let params_items = top.items("design_parameter")?;
    let criteria_items = top.items("criterion")?;
    let settings = top.field("sensitivity").map(|f| f.table()).transpose()?;
    if params_items.is_empty() && criteria_items.is_empty() && settings.is_none() {
        return Ok(None);
    }
    let mut method = Method::Adjoint;
    let mut fd_step = DEFAULT_FD_STEP;
    let mut memory_budget = DEFAULT_MEMORY_BUDGET;
    if let Some(t) = &settings {
        t.check_keys(&["method", "fd_step", "memory_budget_mb"])?;
        method = match t.opt_choice("method", &["direct", "adjoint", "fd"])? {
            Some("direct") => Method::Direct,
            Some("fd") => Method::Fd,
            _ => Method::Adjoint,
        };
        if let Some(f) = t.field("fd_step") {
            fd_step = f.f64_in(FD_STEP_RANGE.0, FD_STEP_RANGE.1)?;
        }
        if let Some(f) = t.field("memory_budget_mb") {
            let (lo, hi) = MEMORY_BUDGET_MB_RANGE;
            memory_budget = (f.f64_in(lo, hi)? * (1 << 20) as f64) as usize;
        }
    }
    let registry = Parameters::new(model);
    let mut design = Vec::new();
    let mut seen = HashMap::new();
    for t in &params_items {
        t.check_keys(&["path", "scale", "lower", "upper"])?;
        let f = t.req("path")?;
        let path = f.str()?;
        let id = registry.id(path).map_err(|e| f.err(e.to_string()))?;
        if statics && registry.role(id) == crate::model::ParamRole::InitialState {
            return Err(f.err(format!(
                "'{path}' is an initial velocity: a static analysis does not depend on it"
            )));
        }
        if let Some(first) = seen.insert(path.to_string(), t.path.clone()) {
            return Err(f.err(format!("parameter '{path}' is already declared by {first}")));
        }
        let scale = match t.field("scale") {
            Some(f) => f.f64_in(1e-30, 1e30)?,
            None => 1.0,
        };
        let bound = |key| t.field(key).map(|f| f.f64_in(-1e30, 1e30)).transpose();
        let (lower, upper) = (bound("lower")?, bound("upper")?);
        match (lower, upper) {
            (None, None) => {}
            (Some(l), Some(u)) if l > u => {
                return Err(t.key_err(
                    "lower",
                    format!("the bounds are reversed: lower = {l} is above upper = {u}"),
                ))
            }
            (Some(l), Some(u)) if l == u => {
                return Err(t.key_err(
                    "lower",
                    format!("lower and upper are equal ({l}): the optimizer moves a parameter with both bounds between them; leave both out to hold it"),
                ))
            }
            (Some(l), Some(u)) => {
                let value = registry.value(model, id);
                if !(l < value && value < u) {
                    return Err(t.key_err(
                        "lower",
                        format!("the bounds ({l}, {u}) must contain the parameter's value {value} strictly (the optimizer starts there)"),
                    ));
                }
            }
            (Some(_), None) => {
                return Err(t.key_err(
                    "upper",
                    "is required with lower (the optimizer moves parameters with both bounds)",
                ))
            }
            (None, Some(_)) => {
                return Err(t.key_err(
                    "lower",
                    "is required with upper (the optimizer moves parameters with both bounds)",
                ))
            }
        }
        design.push(DesignParameter {
            path: path.to_string(),
            id,
            scale,
            lower,
            upper,
        });
    }
    let mut references = Vec::new();
    let mut names = HashMap::new();
    for t in top.items("reference")? {
        t.check_keys(&["name", "file", "time_column", "column"])?;
        let name = super::fields::read_name(&t, &mut names, "reference")?;
        check_name(&t, &name)?;
        if model.sensors.iter().any(|s| s.name == name) {
            return Err(t.key_err("name", format!("'{name}' is already the name of a sensor")));
        }
        let f = t.req("file")?;
        let base = Path::new(file).parent().unwrap_or(Path::new("."));
        let csv_path = base.join(f.str()?);
        let time_column = t.opt_str("time_column")?.unwrap_or("t");
        let column = t.req("column")?.str()?;
        let (times, values) = read_signal(&csv_path, time_column, column)
            .map_err(|m| f.err(format!("{}: {m}", csv_path.display())))?;
        references.push(Reference {
            name,
            t: times,
            values,
        });
    }
    let mut criteria = Vec::new();
    let mut names = HashMap::new();
    for t in &criteria_items {
        t.check_keys(&["name", "terminal", "integral"])?;
        let name = super::fields::read_name(t, &mut names, "criterion")?;
        check_name(t, &name)?;
        let (kind, key) = match (t.field("terminal"), t.field("integral")) {
            (Some(_), None) => (CriterionKind::Terminal, "terminal"),
            (None, Some(_)) => (CriterionKind::Integral, "integral"),
            (Some(_), Some(_)) => {
                return Err(
                    t.key_name_err("integral", "a criterion is terminal or integral, not both")
                )
            }
            (None, None) => {
                return Err(t.key_err(
                    "terminal",
                    "is required: give terminal = \"...\" or integral = \"...\"",
                ))
            }
        };
        let f = t.req(key)?;
        if statics && kind == CriterionKind::Integral {
            return Err(t.key_name_err(
                "integral",
                "a static analysis has terminal criteria only (its final point): write terminal = \"...\"",
            ));
        }
        let c = Criterion::new(model, &references, &name, kind, f.str()?).map_err(|m| f.err(m))?;
        criteria.push(c);
    }
    Ok(Some(Setup {
        design,
        criteria: CriteriaSet::new(model, references, criteria),
        method,
        fd_step,
        memory_budget,
    }))
}

/// The columns `time_column` and `column` of a CSV file with a header: times increasing,
/// every value finite (`[[reference]]`, and a `[[block]]` source's `file`).
pub(super) fn read_signal(
    path: &Path,
    time_column: &str,
    column: &str,
) -> std::result::Result<(Vec<f64>, Vec<f64>), String> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_path(path)
        .map_err(|e| e.to_string())?;
    let headers = reader.headers().map_err(|e| e.to_string())?.clone();
    let find = |name: &str| {
        headers.iter().position(|h| h == name).ok_or_else(|| {
            format!(
                "no column '{name}' (columns: {})",
                headers.iter().collect::<Vec<_>>().join(", ")
            )
        })
    };
    let (it, iv) = (find(time_column)?, find(column)?);
    let (mut t, mut v) = (Vec::new(), Vec::new());
    for (line, record) in reader.records().enumerate() {
        let record = record.map_err(|e| e.to_string())?;
        let number = |i: usize| -> std::result::Result<f64, String> {
            let text = record.get(i).unwrap_or("");
            match text.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(format!("row {}: '{text}' is not a finite number", line + 2)),
            }
        };
        let (ti, vi) = (number(it)?, number(iv)?);
        if t.last().is_some_and(|&last| ti <= last) {
            return Err(format!("row {}: the times must increase", line + 2));
        }
        t.push(ti);
        v.push(vi);
        if t.len() > MAX_SAMPLES {
            return Err(format!("more than {MAX_SAMPLES} rows"));
        }
    }
    if t.is_empty() {
        return Err("no rows".into());
    }
    Ok((t, v))
}
