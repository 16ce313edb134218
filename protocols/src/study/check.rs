//! The generic walker of a study file's TOML tree: [`Ctx`] collects every problem with its
//! dotted key path, and its typed getters read one key each, report a wrong type or range, and
//! return `None` so that parsing goes on and finds the next problem.

use toml::{Table, Value};

use super::{MAX_CONDITIONS, StudyIssue};

/// The problems found so far in one study file.
#[derive(Default)]
pub(super) struct Ctx {
    /// Every problem found so far, in the order found.
    pub(super) issues: Vec<StudyIssue>,
}

/// The dotted key path of `key` inside the table at `path` (`""`: the top level).
pub(super) fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

/// What a value is, for "expected X, got Y" messages.
pub(super) fn type_name(v: &Value) -> &'static str {
    match v {
        Value::String(_) => "a string",
        Value::Integer(_) => "an integer",
        Value::Float(_) => "a float",
        Value::Boolean(_) => "a boolean",
        Value::Datetime(_) => "a date-time",
        Value::Array(_) => "an array",
        Value::Table(_) => "a table",
    }
}

impl Ctx {
    pub(super) fn err(&mut self, key: impl Into<String>, reason: impl Into<String>) {
        self.issues.push(StudyIssue {
            key: key.into(),
            reason: reason.into(),
        });
    }

    pub(super) fn known(&mut self, t: &Table, path: &str, allowed: &[&str]) {
        for k in t.keys() {
            if !allowed.contains(&k.as_str()) {
                self.err(
                    join(path, k),
                    format!("unknown key (allowed: {})", allowed.join(", ")),
                );
            }
        }
    }

    pub(super) fn wrong(&mut self, path: &str, key: &str, want: &str, v: &Value) {
        self.err(
            join(path, key),
            format!("expected {want}, got {}", type_name(v)),
        );
    }

    pub(super) fn table<'a>(&mut self, t: &'a Table, path: &str, key: &str) -> Option<&'a Table> {
        match t.get(key)? {
            Value::Table(x) => Some(x),
            v => {
                self.wrong(path, key, "a table", v);
                None
            }
        }
    }

    pub(super) fn string(&mut self, t: &Table, path: &str, key: &str) -> Option<String> {
        match t.get(key)? {
            Value::String(s) => Some(s.clone()),
            v => {
                self.wrong(path, key, "a string", v);
                None
            }
        }
    }

    pub(super) fn boolean(&mut self, t: &Table, path: &str, key: &str) -> Option<bool> {
        match t.get(key)? {
            Value::Boolean(b) => Some(*b),
            v => {
                self.wrong(path, key, "true or false", v);
                None
            }
        }
    }

    pub(super) fn int(
        &mut self,
        t: &Table,
        path: &str,
        key: &str,
        lo: i64,
        hi: i64,
    ) -> Option<i64> {
        match t.get(key)? {
            Value::Integer(i) if (lo..=hi).contains(i) => Some(*i),
            Value::Integer(i) => {
                self.err(join(path, key), format!("{i} is outside {lo}..={hi}"));
                None
            }
            v => {
                self.wrong(path, key, "an integer", v);
                None
            }
        }
    }

    pub(super) fn uint(&mut self, t: &Table, path: &str, key: &str, hi: u32) -> Option<u32> {
        self.int(t, path, key, 0, i64::from(hi)).map(|v| v as u32)
    }

    pub(super) fn float(&mut self, t: &Table, path: &str, key: &str) -> Option<f64> {
        match t.get(key)? {
            Value::Float(f) if f.is_finite() => Some(*f),
            Value::Float(f) => {
                self.err(join(path, key), format!("{f} is not a finite number"));
                None
            }
            Value::Integer(i) => Some(*i as f64),
            v => {
                self.wrong(path, key, "a number", v);
                None
            }
        }
    }

    pub(super) fn strings(&mut self, t: &Table, path: &str, key: &str) -> Option<Vec<String>> {
        match t.get(key)? {
            Value::Array(a) => {
                let mut out = Vec::with_capacity(a.len().min(MAX_CONDITIONS));
                if a.len() > MAX_CONDITIONS {
                    self.err(
                        join(path, key),
                        format!("{} entries, limit {MAX_CONDITIONS}", a.len()),
                    );
                    return None;
                }
                for (i, v) in a.iter().enumerate() {
                    match v {
                        Value::String(s) => out.push(s.clone()),
                        v => self.wrong(path, &format!("{key}[{i}]"), "a string", v),
                    }
                }
                Some(out)
            }
            v => {
                self.wrong(path, key, "an array of strings", v);
                None
            }
        }
    }

    pub(super) fn floats(&mut self, t: &Table, path: &str, key: &str) -> Option<Vec<f64>> {
        match t.get(key)? {
            Value::Array(a) if a.len() <= MAX_CONDITIONS => {
                let mut out = Vec::with_capacity(a.len());
                for (i, v) in a.iter().enumerate() {
                    match v {
                        Value::Float(f) if f.is_finite() => out.push(*f),
                        Value::Integer(n) => out.push(*n as f64),
                        v => self.wrong(path, &format!("{key}[{i}]"), "a finite number", v),
                    }
                }
                Some(out)
            }
            v => {
                self.wrong(path, key, "an array of numbers (at most 100000)", v);
                None
            }
        }
    }

    pub(super) fn parse_enum<T: std::str::FromStr<Err = String>>(
        &mut self,
        t: &Table,
        path: &str,
        key: &str,
    ) -> Option<T> {
        let s = self.string(t, path, key)?;
        match s.parse() {
            Ok(v) => Some(v),
            Err(e) => {
                self.err(join(path, key), e);
                None
            }
        }
    }

    pub(super) fn pick<T: Copy>(
        &mut self,
        t: &Table,
        path: &str,
        key: &str,
        options: &[(&str, T)],
    ) -> Option<T> {
        let s = self.string(t, path, key)?;
        if let Some((_, v)) = options.iter().find(|(n, _)| *n == s) {
            return Some(*v);
        }
        let names: Vec<&str> = options.iter().map(|(n, _)| *n).collect();
        self.err(
            join(path, key),
            format!("expected one of {}, got {s:?}", names.join(", ")),
        );
        None
    }

    pub(super) fn required<T>(
        &mut self,
        v: Option<T>,
        t: &Table,
        path: &str,
        key: &str,
    ) -> Option<T> {
        if v.is_none() && !t.contains_key(key) {
            self.err(join(path, key), "missing");
        }
        v
    }
}
