//! A TOML reader that keeps spans and collects every problem, so a mission
//! file gets one diagnostic per mistake (raw TOML → checked values).

use std::ops::Range;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::diagnostics::{Diagnostic, Source};

/// A value with the byte span it came from.
pub type At<T> = Spanned<T>;

/// Collects diagnostics while reading one file.
#[derive(Debug)]
pub struct Reader<'s> {
    /// The file being read.
    pub source: &'s Source,
    /// Problems found so far.
    pub problems: Vec<Diagnostic>,
}

/// One table of the document and the keys read from it.
#[derive(Debug)]
pub struct Table<'d, 'i> {
    table: Option<&'d DeTable<'i>>,
    span: Range<usize>,
    path: String,
    read: Vec<&'static str>,
    /// The value under this name is not a table (already reported).
    broken: bool,
}

fn kind(v: &DeValue<'_>) -> &'static str {
    match v {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a float",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a datetime",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

impl<'s> Reader<'s> {
    /// Starts reading `source`.
    pub fn new(source: &'s Source) -> Self {
        Self { source, problems: Vec::new() }
    }

    /// Records a problem at `span`.
    pub fn problem(&mut self, span: &Range<usize>, field: &str, message: impl Into<String>) {
        let d = self.source.diagnostic(span, field, message);
        self.problems.push(d);
    }

    /// Reads a number (float or integer) as f64, rejecting NaN and infinities.
    pub fn number(&mut self, v: &Spanned<DeValue<'_>>, field: &str) -> Option<At<f64>> {
        let parsed = match v.get_ref() {
            DeValue::Float(f) => f.as_str().parse::<f64>().ok(),
            DeValue::Integer(i) => match i64::from_str_radix(i.as_str(), i.radix()) {
                Ok(i) => Some(i as f64),
                Err(_) => {
                    // A number, but beyond any range a key has (not "not finite").
                    let message = format!("value {} is out of range: beyond a 64-bit integer", i.as_str());
                    self.problem(&v.span(), field, message);
                    return None;
                }
            },
            other => {
                self.problem(&v.span(), field, format!("expected a number, found {}", kind(other)));
                return None;
            }
        };
        match parsed {
            Some(x) if x.is_finite() => Some(Spanned::new(v.span(), x)),
            _ => {
                self.problem(&v.span(), field, "expected a finite number (not nan or inf)");
                None
            }
        }
    }

    /// Reads a number and checks it lies above `min` (inclusive or not) and
    /// at most `max`.
    pub fn number_in(
        &mut self,
        v: &Spanned<DeValue<'_>>,
        field: &str,
        min: f64,
        min_inclusive: bool,
        max: Option<f64>,
    ) -> Option<At<f64>> {
        let x = self.number(v, field)?;
        check_range(self, &x, field, min, min_inclusive, max)?;
        Some(x)
    }

    /// Reads a whole number in `min ..= max`.
    pub fn integer_in(&mut self, v: &Spanned<DeValue<'_>>, field: &str, min: u64, max: u64) -> Option<u64> {
        let x = self.number_in(v, field, min as f64, true, Some(max as f64))?;
        if x.get_ref().fract() != 0.0 {
            self.problem(&v.span(), field, format!("value {} is not a whole number; expected an integer", x.get_ref()));
            return None;
        }
        Some(*x.get_ref() as u64)
    }

    /// Reads one of `choices` (strings).
    pub fn choice(&mut self, v: &Spanned<DeValue<'_>>, field: &str, choices: &[&str]) -> Option<At<String>> {
        let s = self.string(v, field)?;
        if choices.contains(&s.get_ref().as_str()) {
            return Some(s);
        }
        let list = choices.iter().map(|c| format!("\"{c}\"")).collect::<Vec<_>>().join(", ");
        self.problem(&s.span(), field, format!("unknown value \"{}\"; expected one of {list}", s.get_ref()));
        None
    }

    /// Reads an array, each element through `item`.
    pub fn array<T>(
        &mut self,
        v: &Spanned<DeValue<'_>>,
        field: &str,
        mut item: impl FnMut(&mut Self, &Spanned<DeValue<'_>>, &str) -> Option<T>,
    ) -> Option<Vec<T>> {
        let DeValue::Array(items) = v.get_ref() else {
            self.problem(&v.span(), field, format!("expected an array, found {}", kind(v.get_ref())));
            return None;
        };
        let mut out = Vec::with_capacity(items.len());
        let mut ok = true;
        for (k, e) in items.iter().enumerate() {
            match item(self, e, &format!("{field}[{k}]")) {
                Some(x) => out.push(x),
                None => ok = false,
            }
        }
        ok.then_some(out)
    }

    /// Reads `[x, y, z]` (numbers, metres).
    pub fn point3(&mut self, v: &Spanned<DeValue<'_>>, field: &str) -> Option<At<[f64; 3]>> {
        let xs = self.array(v, field, |r, e, f| r.number(e, f))?;
        if xs.len() != 3 {
            self.problem(&v.span(), field, format!("expected 3 numbers [x, y, z], found {}", xs.len()));
            return None;
        }
        // (Issue 34, U1: a route at 3e14 m validated, then stopped the run.)
        if let Some(x) = xs.iter().find(|x| x.get_ref().abs() > cps::MAX_COORDINATE_M) {
            let message = format!(
                "{} m is beyond ±{:e} m: expected coordinates of a survey on Earth",
                x.get_ref(),
                cps::MAX_COORDINATE_M
            );
            self.problem(&x.span(), field, message);
            return None;
        }
        Some(Spanned::new(v.span(), [*xs[0].get_ref(), *xs[1].get_ref(), *xs[2].get_ref()]))
    }

    /// Reads a boolean.
    pub fn boolean(&mut self, v: &Spanned<DeValue<'_>>, field: &str) -> Option<bool> {
        match v.get_ref() {
            DeValue::Boolean(b) => Some(*b),
            other => {
                self.problem(&v.span(), field, format!("expected true or false, found {}", kind(other)));
                None
            }
        }
    }

    /// Reads a string.
    pub fn string(&mut self, v: &Spanned<DeValue<'_>>, field: &str) -> Option<At<String>> {
        match v.get_ref() {
            DeValue::String(s) => Some(Spanned::new(v.span(), s.to_string())),
            other => {
                self.problem(&v.span(), field, format!("expected a string, found {}", kind(other)));
                None
            }
        }
    }
}

impl<'d, 'i> Table<'d, 'i> {
    /// The document's root table.
    pub fn root(doc: &'d Spanned<DeTable<'i>>) -> Self {
        Self { table: Some(doc.get_ref()), span: doc.span(), path: String::new(), read: Vec::new(), broken: false }
    }

    /// A table found inside an array (`[[control]]`), named `path` in
    /// diagnostics.
    pub fn element(table: &'d DeTable<'i>, span: Range<usize>, path: String) -> Self {
        Self { table: Some(table), span, path, read: Vec::new(), broken: false }
    }

    fn field(&self, key: &str) -> String {
        if self.path.is_empty() { key.to_string() } else { format!("{}.{key}", self.path) }
    }

    /// Span of the table (its header), for problems about missing keys.
    pub fn span(&self) -> Range<usize> {
        self.span.clone()
    }

    /// The raw value under `key`, marking the key as known.
    pub fn get(&mut self, key: &'static str) -> Option<&'d Spanned<DeValue<'i>>> {
        self.read.push(key);
        self.table.and_then(|t| t.get(key))
    }

    /// A sub-table; a missing one reads as empty (its keys then report as missing).
    pub fn table(&mut self, r: &mut Reader<'_>, key: &'static str) -> Table<'d, 'i> {
        let path = self.field(key);
        match self.get(key) {
            Some(v) => match v.get_ref() {
                DeValue::Table(t) => Table { table: Some(t), span: v.span(), path, read: Vec::new(), broken: false },
                other => {
                    r.problem(&v.span(), &path, format!("expected a table, found {}", kind(other)));
                    Table { table: None, span: v.span(), path, read: vec![], broken: true }
                }
            },
            None => Table { table: None, span: self.span.clone(), path, read: vec![], broken: self.broken },
        }
    }

    /// Whether `key` is present.
    pub fn has(&self, key: &str) -> bool {
        self.table.is_some_and(|t| t.get(key).is_some())
    }

    /// A required value read with `f`; missing → a problem naming `expected`.
    pub fn required<T>(
        &mut self,
        r: &mut Reader<'_>,
        key: &'static str,
        expected: &str,
        f: impl FnOnce(&mut Reader<'_>, &Spanned<DeValue<'i>>, &str) -> Option<T>,
    ) -> Option<T> {
        let field = self.field(key);
        match self.get(key) {
            Some(v) => f(r, v, &field),
            None if self.broken => None,
            None => {
                let what = if self.path.is_empty() { "the file".to_string() } else { format!("[{}]", self.path) };
                r.problem(&self.span, &field, format!("missing key `{key}` in {what}; expected {expected}"));
                None
            }
        }
    }

    /// An optional value read with `f`.
    pub fn optional<T>(
        &mut self,
        r: &mut Reader<'_>,
        key: &'static str,
        f: impl FnOnce(&mut Reader<'_>, &Spanned<DeValue<'i>>, &str) -> Option<T>,
    ) -> Option<Option<T>> {
        let field = self.field(key);
        match self.get(key) {
            Some(v) => f(r, v, &field).map(Some),
            None => Some(None),
        }
    }

    /// Reports every key that was never asked for, naming the known ones.
    pub fn finish(self, r: &mut Reader<'_>) {
        let Some(t) = self.table else { return };
        for (k, _) in t.iter() {
            if !self.read.contains(&k.get_ref().as_ref()) {
                let mut known = self.read.clone();
                known.sort_unstable();
                known.dedup();
                let field = self.field(k.get_ref());
                r.problem(
                    &k.span(),
                    &field,
                    format!("unknown key `{}`; expected one of: {}", k.get_ref(), known.join(", ")),
                );
            }
        }
    }
}

/// Checks `value` against an inclusive/exclusive lower bound and an optional
/// upper bound, recording a problem that names the field and the range.
pub fn check_range(
    r: &mut Reader<'_>,
    value: &At<f64>,
    field: &str,
    min: f64,
    min_inclusive: bool,
    max: Option<f64>,
) -> Option<f64> {
    let v = *value.get_ref();
    let low_ok = if min_inclusive { v >= min } else { v > min };
    let high_ok = max.is_none_or(|m| v <= m);
    if low_ok && high_ok {
        return Some(v);
    }
    let lo = if min_inclusive { format!("≥ {min}") } else { format!("> {min}") };
    let expected = match max {
        Some(m) => format!("{lo} and ≤ {m}"),
        None => lo,
    };
    r.problem(&value.span(), field, format!("value {v} is out of range; expected {expected}"));
    None
}
