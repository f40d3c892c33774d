//! Typed access to the spanned TOML tree, with errors that carry file, line and field path.

use super::error::{InputError, ItemLabel, Location};
use crate::model::clip;
use crate::model::limits::MAX_ITEMS;
use flexmb_lie::{Mat3, Vec3};
use std::ops::Range;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

pub(crate) type Value<'i> = Spanned<DeValue<'i>>;
pub(crate) type Span = Range<usize>;
pub(crate) type Result<T> = std::result::Result<T, InputError>;

pub(crate) use crate::model::QUOTED;
/// Most characters of a field path, or of an override, in an error.
pub(crate) const PATH: usize = 200;
/// Most characters of an error message: a 10 MB name or value is never echoed whole.
pub(crate) const MESSAGE: usize = 1000;

/// Where the ranges of numbers are documented, for messages.
const RANGES: &str = "see 'Ranges' in docs/model-format.md";

/// The text of the model file, for turning byte offsets into lines and columns.
pub(crate) struct Source<'a> {
    pub file: &'a str,
    text: &'a str,
    line_starts: Vec<usize>,
    /// `(field path, override text)` of every applied `--set`, in order.
    set_by: Vec<(String, String)>,
}

impl<'a> Source<'a> {
    pub fn new(file: &'a str, text: &'a str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Self {
            file,
            text,
            line_starts,
            set_by: Vec::new(),
        }
    }

    /// Line and column (1-based) of a byte offset.
    pub fn location(&self, offset: usize) -> Location {
        let offset = offset.min(self.text.len());
        let line = self.line_starts.partition_point(|&s| s <= offset).max(1);
        let start = self.line_starts[line - 1];
        let column = match self.text.get(start..offset) {
            Some(s) => s.chars().count() + 1,
            None => offset - start + 1,
        };
        Location {
            file: self.file.to_string(),
            line: u32::try_from(line).unwrap_or(u32::MAX),
            column: u32::try_from(column).unwrap_or(u32::MAX),
        }
    }

    /// Records that an override set the value at `path` (`solver.h`, `body[0].mass`).
    pub fn note_override(&mut self, path: String, text: String) {
        self.set_by.push((path, text));
    }

    /// The override that set the value of `field` or of one of its parents, if any.
    pub fn set_by(&self, field: &str) -> Option<String> {
        self.set_by.iter().rev().find_map(|(path, text)| {
            let hit = field == path
                || (field.starts_with(path.as_str())
                    && matches!(field.as_bytes().get(path.len()), Some(b'.' | b'[')));
            hit.then(|| text.clone())
        })
    }

    pub fn field_error(
        &self,
        span: &Span,
        field: &str,
        item: Option<&ItemLabel>,
        message: impl Into<String>,
    ) -> InputError {
        let mut message = clip(&message.into(), MESSAGE);
        if let Some(text) = self.set_by(field) {
            message.push_str(&format!(" (value set by --set '{}')", clip(&text, PATH)));
        }
        InputError::Field {
            location: self.location(span.start),
            field: clip(field, PATH),
            item: item.cloned(),
            message,
        }
    }
}

/// "must be between lo and hi, got v", with where the ranges are documented.
pub(crate) fn out_of_range(v: f64, lo: f64, hi: f64) -> String {
    format!("must be between {lo:e} and {hi:e} ({RANGES}), got {v:e}")
}

/// Short description of a value for "expected X, got Y" messages.
pub(crate) fn describe(v: &DeValue<'_>) -> String {
    match v {
        DeValue::String(s) => {
            let shown: String = s.chars().take(40).collect();
            if shown.len() < s.len() {
                format!("string \"{shown}...\"")
            } else {
                format!("string \"{shown}\"")
            }
        }
        DeValue::Integer(i) => format!("integer {i}"),
        DeValue::Float(f) => format!("float {f}"),
        DeValue::Boolean(b) => format!("boolean {b}"),
        DeValue::Datetime(d) => format!("datetime {d}"),
        DeValue::Array(a) => format!("an array of {} element{}", a.len(), plural(a.len())),
        DeValue::Table(_) => "a table".to_string(),
    }
}

fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// Edit distance, for "did you mean" hints.
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// " (did you mean 'x'?)" when one of `candidates` is close to `word` (none for words or
/// candidates longer than [`QUOTED`]: the edit distance costs the product of the lengths).
pub(crate) fn suggestion<'c>(word: &str, candidates: impl IntoIterator<Item = &'c str>) -> String {
    if word.len() > QUOTED {
        return String::new();
    }
    let score = |c: &str| {
        if c.len() > QUOTED {
            return None;
        }
        let d = distance(word, c);
        let prefix =
            word.len() >= 3 && c.len() >= 3 && (c.starts_with(word) || word.starts_with(c));
        if d <= 2.min(c.len().saturating_sub(1)).max(1) {
            Some(d)
        } else {
            prefix.then_some(3)
        }
    };
    candidates
        .into_iter()
        .filter_map(|c| score(c).map(|d| (d, c)))
        .min_by_key(|&(d, _)| d)
        .map(|(_, c)| format!(" (did you mean '{}'?)", clip(c, QUOTED)))
        .unwrap_or_default()
}

/// `a, b, c` of at most `max` names, then `...`.
pub(crate) fn name_list<'n>(names: impl IntoIterator<Item = &'n str>, max: usize) -> String {
    let names: Vec<&str> = names.into_iter().collect();
    if names.is_empty() {
        return "none".to_string();
    }
    let mut s = names
        .iter()
        .take(max)
        .map(|n| format!("'{}'", clip(n, QUOTED)))
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > max {
        s.push_str(", ...");
    }
    s
}

/// A finite number (integer or float), or the message saying why `v` is not one.
fn number(v: &DeValue<'_>) -> std::result::Result<f64, String> {
    let v = match v {
        DeValue::Integer(i) => match i64::from_str_radix(i.as_str(), i.radix()) {
            Ok(v) => v as f64,
            Err(_) => return Err(format!("integer {i} is out of range")),
        },
        DeValue::Float(f) => match f.as_str().parse::<f64>() {
            Ok(v) => v,
            Err(_) => return Err(format!("cannot read the number {f}")),
        },
        v => return Err(format!("expected a number, got {}", describe(v))),
    };
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("must be a finite number, got {v}"))
    }
}

/// One value of the file with its path, for typed conversions.
#[derive(Clone)]
pub(crate) struct Field<'a> {
    pub src: &'a Source<'a>,
    pub value: &'a Value<'a>,
    pub path: String,
    pub item: Option<ItemLabel>,
}

impl<'a> Field<'a> {
    pub fn err(&self, message: impl Into<String>) -> InputError {
        self.src
            .field_error(&self.value.span(), &self.path, self.item.as_ref(), message)
    }

    fn expected(&self, what: &str) -> InputError {
        self.err(format!(
            "expected {what}, got {}",
            describe(self.value.get_ref())
        ))
    }

    /// A finite number (integer or float).
    pub fn f64(&self) -> Result<f64> {
        number(self.value.get_ref()).map_err(|message| self.err(message))
    }

    /// A number in `[lo, hi]`.
    pub fn f64_in(&self, lo: f64, hi: f64) -> Result<f64> {
        let v = self.f64()?;
        if v >= lo && v <= hi {
            Ok(v)
        } else {
            Err(self.err(out_of_range(v, lo, hi)))
        }
    }

    pub fn int(&self) -> Result<i64> {
        match self.value.get_ref() {
            DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix())
                .map_err(|_| self.err(format!("integer {i} is out of range"))),
            _ => Err(self.expected("an integer")),
        }
    }

    pub fn bool(&self) -> Result<bool> {
        match self.value.get_ref() {
            DeValue::Boolean(b) => Ok(*b),
            _ => Err(self.expected("a boolean (true or false)")),
        }
    }

    pub fn str(&self) -> Result<&'a str> {
        match self.value.get_ref() {
            DeValue::String(s) => Ok(s.as_ref()),
            _ => Err(self.expected("a string")),
        }
    }

    /// A string among `allowed`.
    pub fn choice(&self, allowed: &[&'static str]) -> Result<&'static str> {
        let list = || {
            allowed
                .iter()
                .map(|a| format!("\"{a}\""))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let s = match self.value.get_ref() {
            DeValue::String(s) => s.as_ref(),
            _ => return Err(self.expected(&format!("one of {}", list()))),
        };
        allowed.iter().find(|a| **a == s).copied().ok_or_else(|| {
            self.err(format!(
                "must be one of {}, got \"{}\"{}",
                list(),
                clip(s, QUOTED),
                suggestion(s, allowed.iter().copied())
            ))
        })
    }

    pub fn array(&self) -> Result<&'a [Value<'a>]> {
        match self.value.get_ref() {
            DeValue::Array(a) => Ok(a),
            _ => Err(self.expected("an array")),
        }
    }

    pub fn elem(&self, i: usize, value: &'a Value<'a>) -> Field<'a> {
        Field {
            src: self.src,
            value,
            path: format!("{}[{i}]", self.path),
            item: self.item.clone(),
        }
    }

    /// An array of exactly `n` numbers.
    pub fn numbers(&self, n: usize, what: &str) -> Result<Vec<f64>> {
        let a = match self.value.get_ref() {
            DeValue::Array(a) if a.len() == n => a,
            _ => return Err(self.expected(what)),
        };
        // The element's field (its path) is made for an error only.
        a.iter()
            .enumerate()
            .map(|(i, v)| number(v.get_ref()).map_err(|message| self.elem(i, v).err(message)))
            .collect()
    }

    pub fn vec3(&self) -> Result<Vec3> {
        let v = self.numbers(3, "an array of 3 numbers [x, y, z]")?;
        Ok(Vec3::new(v[0], v[1], v[2]))
    }

    /// A vector whose components are at most `max` in magnitude (the error names the
    /// component).
    /// A vector of length at most `max` (a bound on the length holds in every frame the
    /// model later expresses it in); an error names a component that is out of range alone.
    pub fn vec3_within(&self, max: f64) -> Result<Vec3> {
        let v = self.vec3()?;
        let bad = (0..3).find(|&i| v[i].abs() > max);
        if let (Some(i), DeValue::Array(a)) = (bad, self.value.get_ref()) {
            return Err(self.elem(i, &a[i]).err(out_of_range(v[i], -max, max)));
        }
        if v.norm() > max {
            return Err(self.err(format!(
                "has length {:e}, beyond {max:e} (see 'Ranges' in docs/model-format.md)",
                v.norm()
            )));
        }
        Ok(v)
    }

    /// A 3x3 matrix given by rows `[[a, b, c], [d, e, f], [g, h, i]]`.
    pub fn mat3_rows(&self) -> Result<Mat3> {
        let what = "a 3x3 matrix given by rows [[., ., .], [., ., .], [., ., .]]";
        let rows = match self.value.get_ref() {
            DeValue::Array(a) if a.len() == 3 => a,
            _ => return Err(self.expected(what)),
        };
        let mut m = Mat3::zeros();
        for (i, row) in rows.iter().enumerate() {
            let r = self.elem(i, row).numbers(3, "a row of 3 numbers")?;
            for j in 0..3 {
                m[(i, j)] = r[j];
            }
        }
        Ok(m)
    }

    pub fn table(&self) -> Result<Table<'a>> {
        match self.value.get_ref() {
            DeValue::Table(map) => Ok(Table {
                src: self.src,
                map,
                span: self.value.span(),
                path: self.path.clone(),
                item: self.item.clone(),
            }),
            _ => Err(self.expected("a table")),
        }
    }
}

/// One TOML table of the file with its path.
#[derive(Clone)]
pub(crate) struct Table<'a> {
    pub src: &'a Source<'a>,
    pub map: &'a DeTable<'a>,
    pub span: Span,
    pub path: String,
    pub item: Option<ItemLabel>,
}

impl<'a> Table<'a> {
    pub fn child_path(&self, key: &str) -> String {
        // Every field read makes its path: without the formatting machinery.
        let mut path = String::with_capacity(self.path.len() + 1 + key.len());
        if !self.path.is_empty() {
            path.push_str(&self.path);
            path.push('.');
        }
        path.push_str(key);
        path
    }

    pub fn has(&self, key: &str) -> bool {
        self.map.contains_key(key)
    }

    pub fn field(&self, key: &str) -> Option<Field<'a>> {
        self.map.get(key).map(|value| Field {
            src: self.src,
            value,
            path: self.child_path(key),
            item: self.item.clone(),
        })
    }

    /// Error about `key`, at its value (or at the table when the key is absent).
    pub fn key_err(&self, key: &str, message: impl Into<String>) -> InputError {
        let span = self.map.get(key).map_or(self.span.clone(), |v| v.span());
        self.src
            .field_error(&span, &self.child_path(key), self.item.as_ref(), message)
    }

    pub fn req(&self, key: &str) -> Result<Field<'a>> {
        self.field(key)
            .ok_or_else(|| self.key_err(key, "is required but missing"))
    }

    /// Span of the key itself (not its value).
    fn key_span(&self, key: &str) -> Span {
        self.map
            .get_key_value(key)
            .map_or(self.span.clone(), |(k, _)| k.span())
    }

    /// Fails on the first key (in file order) that is not in `allowed`.
    pub fn check_keys(&self, allowed: &[&str]) -> Result<()> {
        let unknown = self
            .map
            .iter()
            .filter(|(k, _)| !allowed.contains(&k.get_ref().as_ref()))
            .min_by_key(|(k, _)| k.span().start);
        match unknown {
            None => Ok(()),
            Some((k, _)) => {
                let key: &str = k.get_ref();
                Err(self.src.field_error(
                    &k.span(),
                    &self.child_path(key),
                    self.item.as_ref(),
                    format!(
                        "unknown key '{}'{}; allowed keys here: {}",
                        clip(key, QUOTED),
                        suggestion(key, allowed.iter().copied()),
                        allowed.join(", ")
                    ),
                ))
            }
        }
    }

    /// Error about `key`, at the key itself (for a key that should not be there).
    pub fn key_name_err(&self, key: &str, message: impl Into<String>) -> InputError {
        self.src.field_error(
            &self.key_span(key),
            &self.child_path(key),
            self.item.as_ref(),
            message,
        )
    }

    /// The first (in file order) of `keys` present in the table.
    pub fn first_key_of(&self, keys: &[&str]) -> Option<&'a str> {
        self.map
            .iter()
            .filter(|(k, _)| keys.contains(&k.get_ref().as_ref()))
            .min_by_key(|(k, _)| k.span().start)
            .map(|(k, _)| k.get_ref().as_ref())
    }

    /// Fails if `key` is present: it is not meaningful in this context.
    pub fn forbid(&self, key: &str, why: &str) -> Result<()> {
        if self.has(key) {
            Err(self.src.field_error(
                &self.key_span(key),
                &self.child_path(key),
                self.item.as_ref(),
                format!("is not allowed {why}"),
            ))
        } else {
            Ok(())
        }
    }

    pub fn opt_str(&self, key: &str) -> Result<Option<&'a str>> {
        self.field(key).map(|f| f.str()).transpose()
    }

    pub fn opt_choice(&self, key: &str, allowed: &[&'static str]) -> Result<Option<&'static str>> {
        self.field(key).map(|f| f.choice(allowed)).transpose()
    }

    /// The items of an array of tables (`[[body]]`), each with path `key[i]` and labelled
    /// with its `name` when that is a string. Absent means none.
    pub fn items(&self, key: &'static str) -> Result<Vec<Table<'a>>> {
        let Some(f) = self.field(key) else {
            return Ok(Vec::new());
        };
        let what = format!("an array of tables ([[{key}]])");
        let arr = match f.value.get_ref() {
            DeValue::Array(a) => a,
            _ => {
                return Err(f.err(format!(
                    "expected {what}, got {}",
                    describe(f.value.get_ref())
                )))
            }
        };
        if arr.len() > MAX_ITEMS {
            return Err(f.err(format!(
                "has {} items; a model has at most {MAX_ITEMS} of a kind",
                arr.len()
            )));
        }
        let mut out = Vec::with_capacity(arr.len());
        for (i, v) in arr.iter().enumerate() {
            let DeValue::Table(map) = v.get_ref() else {
                return Err(f.elem(i, v).err(format!(
                    "expected a table ([[{key}]]), got {}",
                    describe(v.get_ref())
                )));
            };
            let item = match map.get("name").map(|n| n.get_ref()) {
                Some(DeValue::String(name)) => Some(ItemLabel {
                    table: key,
                    name: clip(name, QUOTED),
                }),
                _ => None,
            };
            out.push(Table {
                src: self.src,
                map,
                span: v.span(),
                path: format!("{key}[{i}]"),
                item,
            });
        }
        Ok(out)
    }

    /// Value spans of every key, for mapping later errors back to the file.
    pub fn spans(&self) -> Vec<(String, Span)> {
        self.map
            .iter()
            .map(|(k, v)| (k.get_ref().to_string(), v.span()))
            .collect()
    }
}
