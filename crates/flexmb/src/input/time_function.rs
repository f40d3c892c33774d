//! Time functions in the model file (`amplitude = ...` of loads, drives, sources): a
//! constant, a table or a named function, nested up to a depth limit.

use super::fields::positive_step;
use super::reader::{Field, Result};
use crate::model::limits::{
    MAX_ANGLE, MAX_FUNCTION_DEPTH, MAX_FUNCTION_TERMS, MAX_KINEMATIC, MAX_PHYSICAL, MAX_TIME,
    MIN_STEP,
};
use crate::model::TimeFunction;

pub(super) fn read_function(f: &Field<'_>) -> Result<TimeFunction> {
    read_nested_function(f, 1, 1.0)
}

/// A time function at nesting level `level` (1 for the outermost), inside scaled functions
/// whose factors multiply to `scale` (in magnitude).
pub(super) fn read_nested_function(
    f: &Field<'_>,
    level: usize,
    scale: f64,
) -> Result<TimeFunction> {
    if level > MAX_FUNCTION_DEPTH {
        return Err(f.err(format!(
            "functions are nested more than {MAX_FUNCTION_DEPTH} levels deep (see 'Time functions' in docs/model-format.md)"
        )));
    }
    let t = f.table()?;
    let kind = t.req("type")?.choice(&[
        "constant",
        "linear",
        "ramp",
        "step",
        "sine",
        "chirp",
        "table",
        "spin_up",
        "bump",
        "smooth_step",
        "delay",
        "window",
        "sum",
        "scaled",
    ])?;
    let keys: &[&str] = match kind {
        "constant" => &["type", "value"],
        "linear" => &["type", "slope", "start", "offset"],
        "ramp" => &["type", "t0", "t1", "value"],
        "step" => &["type", "t0", "value"],
        "sine" => &["type", "amplitude", "frequency", "phase", "offset"],
        "chirp" => &["type", "amplitude", "f0", "f1", "duration", "offset"],
        "table" => &["type", "points"],
        "bump" => &["type", "height", "start", "duration"],
        "smooth_step" => &["type", "value", "start", "duration"],
        "delay" => &["type", "delay", "function"],
        "window" => &["type", "start", "end", "function"],
        "sum" => &["type", "functions"],
        "scaled" => &["type", "factor", "function"],
        _ => &["type", "omega", "duration"],
    };
    t.check_keys(keys)?;
    let inner = |scale: f64| read_nested_function(&t.req("function")?, level + 1, scale);
    // Values (a factor, or rad or m), times, rates and angles, each in its range.
    let num = |k: &str| t.req(k)?.f64_in(-MAX_PHYSICAL, MAX_PHYSICAL);
    let num_or = |k: &str, d: f64| {
        t.field(k)
            .map_or(Ok(d), |f| f.f64_in(-MAX_PHYSICAL, MAX_PHYSICAL))
    };
    let time = |k: &str| t.req(k)?.f64_in(-MAX_TIME, MAX_TIME);
    let time_or = |k: &str, d: f64| t.field(k).map_or(Ok(d), |f| f.f64_in(-MAX_TIME, MAX_TIME));
    Ok(match kind {
        "constant" => TimeFunction::Constant {
            value: num("value")?,
        },
        "linear" => TimeFunction::Linear {
            slope: num("slope")?,
            start: match t.field("start") {
                Some(f) => f.f64_in(-MAX_TIME, MAX_TIME)?,
                None => 0.0,
            },
            offset: num_or("offset", 0.0)?,
        },
        "ramp" => {
            let (t0, t1) = (time("t0")?, time("t1")?);
            if t1 - t0 < MIN_STEP {
                return Err(t.key_err(
                    "t1",
                    format!("must exceed t0 = {t0} by at least {MIN_STEP:e}, got {t1}"),
                ));
            }
            TimeFunction::Ramp {
                t0,
                t1,
                value: num("value")?,
            }
        }
        "step" => TimeFunction::Step {
            t0: time("t0")?,
            value: num("value")?,
        },
        "sine" => TimeFunction::Sine {
            amplitude: num("amplitude")?,
            frequency: t.req("frequency")?.f64_in(-MAX_KINEMATIC, MAX_KINEMATIC)?,
            phase: match t.field("phase") {
                Some(f) => f.f64_in(-MAX_ANGLE, MAX_ANGLE)?,
                None => 0.0,
            },
            offset: num_or("offset", 0.0)?,
        },
        "chirp" => TimeFunction::Chirp {
            amplitude: num("amplitude")?,
            f0: t.req("f0")?.f64_in(-MAX_KINEMATIC, MAX_KINEMATIC)?,
            f1: t.req("f1")?.f64_in(-MAX_KINEMATIC, MAX_KINEMATIC)?,
            duration: positive_step(&t.req("duration")?)?,
            offset: num_or("offset", 0.0)?,
        },
        "table" => {
            let pf = t.req("points")?;
            let arr = pf.array()?;
            if arr.is_empty() {
                return Err(pf.err("needs at least one [t, value] point"));
            }
            let mut points = Vec::with_capacity(arr.len());
            for (i, v) in arr.iter().enumerate() {
                let e = pf.elem(i, v);
                let p = e.numbers(2, "a point [t, value]")?;
                if let toml::de::DeValue::Array(tv) = v.get_ref() {
                    e.elem(0, &tv[0]).f64_in(-MAX_TIME, MAX_TIME)?;
                    e.elem(1, &tv[1]).f64_in(-MAX_PHYSICAL, MAX_PHYSICAL)?;
                }
                if let Some(&(prev, _)) = points.last() {
                    if p[0] - prev < MIN_STEP {
                        return Err(e.err(format!(
                            "times must be strictly increasing (by at least {MIN_STEP:e}), got t = {} after t = {prev}",
                            p[0]
                        )));
                    }
                }
                points.push((p[0], p[1]));
            }
            TimeFunction::Table { points }
        }
        "bump" => TimeFunction::Bump {
            height: num("height")?,
            start: time_or("start", 0.0)?,
            duration: positive_step(&t.req("duration")?)?,
        },
        "smooth_step" => TimeFunction::SmoothStep {
            value: num("value")?,
            start: time_or("start", 0.0)?,
            duration: positive_step(&t.req("duration")?)?,
        },
        "delay" => TimeFunction::Delay {
            delay: time("delay")?,
            function: Box::new(inner(scale)?),
        },
        "window" => {
            let (start, end) = (time("start")?, time("end")?);
            if end - start < MIN_STEP {
                return Err(t.key_err(
                    "end",
                    format!("must exceed start = {start} by at least {MIN_STEP:e}, got {end}"),
                ));
            }
            TimeFunction::Window {
                start,
                end,
                function: Box::new(inner(scale)?),
            }
        }
        "sum" => {
            let ff = t.req("functions")?;
            let arr = ff.array()?;
            if arr.is_empty() || arr.len() > MAX_FUNCTION_TERMS {
                return Err(ff.err(format!(
                    "must hold 1 to {MAX_FUNCTION_TERMS} functions, got {}",
                    arr.len()
                )));
            }
            let functions = arr
                .iter()
                .enumerate()
                .map(|(i, v)| read_nested_function(&ff.elem(i, v), level + 1, scale))
                .collect::<Result<Vec<_>>>()?;
            TimeFunction::Sum { functions }
        }
        "scaled" => {
            let factor = num("factor")?;
            let scale = scale * factor.abs();
            if scale > MAX_PHYSICAL {
                return Err(t.key_err(
                    "factor",
                    format!(
                        "the factors of the nested scaled functions multiply to {scale:e}, beyond {MAX_PHYSICAL:e} (see 'Ranges' in docs/model-format.md)"
                    ),
                ));
            }
            TimeFunction::Scaled {
                factor,
                function: Box::new(inner(scale)?),
            }
        }
        _ => TimeFunction::SpinUp {
            omega: t.req("omega")?.f64_in(-MAX_KINEMATIC, MAX_KINEMATIC)?,
            duration: positive_step(&t.req("duration")?)?,
        },
    })
}
