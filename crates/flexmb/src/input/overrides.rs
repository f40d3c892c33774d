//! `--set KEY.PATH=VALUE` overrides, applied to the parsed tree before it is interpreted.
//!
//! A replaced value keeps the span of the value it replaces and an inserted key gets the
//! position of its parent table, so errors about it still point at a meaningful line; the
//! error message then names the override. A table missing on the path is inserted with the
//! rest of the path (the reader checks its keys as it checks the file's).

use super::error::InputError;
use super::reader::{describe, name_list, Source, Span, Value, MESSAGE, PATH, QUOTED};
use crate::model::clip;
use std::borrow::Cow;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

/// Applies `overrides` in order to the document `root` (a table).
pub(crate) fn apply<'i>(
    root: &mut Value<'i>,
    overrides: &'i [String],
    src: &mut Source<'_>,
) -> Result<(), InputError> {
    for text in overrides {
        let path = apply_one(root, text, src)?;
        src.note_override(path, text.clone());
    }
    Ok(())
}

/// The parsed value of the right-hand side: TOML, or a bare word taken as a string.
fn parse_value<'i>(raw: &'i str) -> Result<DeValue<'i>, String> {
    let raw = raw.trim();
    if raw.is_empty() {
        return Err("the value after '=' is empty".to_string());
    }
    match DeValue::parse(raw) {
        Ok(v) => Ok(v.into_inner()),
        Err(e) if raw.starts_with(['[', '{', '"', '\'']) => Err(format!(
            "'{}' is not a valid TOML value: {}",
            clip(raw, QUOTED),
            e.message()
        )),
        Err(_) => Ok(DeValue::String(Cow::Borrowed(raw))),
    }
}

/// Gives a value and everything inside it the span `span`.
fn respan<'i>(value: DeValue<'i>, span: &Span) -> Value<'i> {
    let inner = match value {
        DeValue::Array(a) => DeValue::Array(
            a.into_iter()
                .map(|v| respan(v.into_inner(), span))
                .collect(),
        ),
        DeValue::Table(t) => {
            let mut out = DeTable::new();
            for (k, v) in t {
                out.insert(
                    Spanned::new(span.clone(), k.into_inner()),
                    respan(v.into_inner(), span),
                );
            }
            DeValue::Table(out)
        }
        other => other,
    };
    Spanned::new(span.clone(), inner)
}

/// Index of `seg` in an array: a number, or the `name` of one of its tables.
fn resolve_index(a: &[Value<'_>], seg: &str, path: &str) -> Result<usize, String> {
    if let Ok(i) = seg.parse::<usize>() {
        return if i < a.len() {
            Ok(i)
        } else {
            Err(format!(
                "index {i} is out of range: '{path}' has {} element{}",
                a.len(),
                if a.len() == 1 { "" } else { "s" }
            ))
        };
    }
    let name_of = |v: &Value<'_>| match v.get_ref() {
        DeValue::Table(t) => t
            .get("name")
            .and_then(|n| n.get_ref().as_str().map(str::to_owned)),
        _ => None,
    };
    if let Some(i) = a.iter().position(|v| name_of(v).as_deref() == Some(seg)) {
        return Ok(i);
    }
    let names: Vec<String> = a.iter().filter_map(name_of).collect();
    let seg = clip(seg, QUOTED);
    Err(format!(
        "'{path}' has no item named '{seg}' (names: {}) and '{seg}' is not an index",
        name_list(names.iter().map(String::as_str), 10)
    ))
}

/// Span of the deepest value along a dotted key path that exists, for locating errors.
fn locate(root: &Value<'_>, key: &str) -> Span {
    let mut cur = root;
    for seg in key.split('.').map(str::trim) {
        let next = match cur.get_ref() {
            DeValue::Table(t) => t.get(seg),
            DeValue::Array(a) => resolve_index(a, seg, "").ok().map(|i| &a[i]),
            _ => None,
        };
        match next {
            Some(v) => cur = v,
            None => break,
        }
    }
    cur.span()
}

/// Applies one override; returns the path of the value it set (`body[0].mass`).
fn apply_one<'i>(
    root: &mut Value<'i>,
    text: &'i str,
    src: &Source<'_>,
) -> Result<String, InputError> {
    let fail = |span: &Span, field: &str, message: String| InputError::Override {
        location: src.location(span.start),
        text: clip(text, PATH),
        field: clip(field, PATH),
        message: clip(&message, MESSAGE),
    };
    let Some((key, raw)) = text.split_once('=') else {
        let at = locate(root, text);
        return Err(fail(
            &at,
            text.trim(),
            "expected KEY.PATH=VALUE".to_string(),
        ));
    };
    let segs: Vec<&str> = key.split('.').map(str::trim).collect();
    if segs.iter().any(|s| s.is_empty()) {
        return Err(fail(
            &locate(root, key),
            key.trim(),
            "the key path has an empty part (expected e.g. solver.h or body.top.mass)".to_string(),
        ));
    }
    let mut path = String::new();
    let mut cur: &mut Value<'i> = root;
    for (i, seg) in segs.iter().enumerate() {
        let last = i + 1 == segs.len();
        let here = cur.span();
        let shown = if path.is_empty() {
            seg.to_string()
        } else {
            format!("{path}.{seg}")
        };
        match cur.get_mut() {
            DeValue::Table(t) => {
                if last {
                    let at = t.get(*seg).map_or(here.clone(), |v| v.span());
                    let value = parse_value(raw).map_err(|m| fail(&at, &shown, m))?;
                    match t.get_mut(*seg) {
                        Some(old) => {
                            let span = old.span();
                            *old = respan(value, &span);
                        }
                        None => {
                            let at = here.start..here.start;
                            t.insert(
                                Spanned::new(at.clone(), Cow::Borrowed(*seg)),
                                respan(value, &at),
                            );
                        }
                    }
                    return Ok(shown);
                }
                if !t.contains_key(*seg) {
                    // A table missing on the path is created with the rest of it (an
                    // element's section of a beam: `beam.leg.element.3.section.EI2`); the
                    // reader then checks its keys like any other, naming this override.
                    let at = here.start..here.start;
                    let mut value = respan(
                        parse_value(raw).map_err(|m| fail(&here, key.trim(), m))?,
                        &at,
                    );
                    for inner in segs[i + 1..].iter().rev() {
                        let mut table = DeTable::new();
                        table.insert(Spanned::new(at.clone(), Cow::Borrowed(*inner)), value);
                        value = Spanned::new(at.clone(), DeValue::Table(table));
                    }
                    t.insert(Spanned::new(at.clone(), Cow::Borrowed(*seg)), value);
                    // (errors anywhere in the created table name this override)
                    return Ok(shown);
                }
                cur = t.get_mut(*seg).expect("the key is there");
                path = shown;
            }
            DeValue::Array(a) => {
                let a: &mut [Value<'i>] = a;
                let idx = resolve_index(a, seg, &path).map_err(|m| fail(&here, &shown, m))?;
                path = format!("{path}[{idx}]");
                if last {
                    let value = parse_value(raw).map_err(|m| fail(&a[idx].span(), &path, m))?;
                    let span = a[idx].span();
                    a[idx] = respan(value, &span);
                    return Ok(path);
                }
                cur = &mut a[idx];
            }
            other => {
                return Err(fail(
                    &here,
                    &path,
                    format!(
                        "'{path}' is {}, not a table or an array, so it has no '{seg}'",
                        describe(other)
                    ),
                ));
            }
        }
    }
    // Not reached: `split` yields at least one part and the last part returns.
    Err(fail(&(0..0), key.trim(), "empty key path".to_string()))
}
