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

/// Edit distance between `a` and `b` in characters: insertions, deletions, substitutions and
/// swaps of two neighbours each count one (optimal string alignment).
fn distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    // Rows i - 2, i - 1 and i of the table of distances between prefixes.
    let mut before: Vec<usize> = Vec::new();
    let mut last: Vec<usize> = (0..=b.len()).collect();
    for i in 1..=a.len() {
        let mut row = vec![i; b.len() + 1];
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            row[j] = (last[j] + 1).min(row[j - 1] + 1).min(last[j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                row[j] = row[j].min(before[j - 2] + 1);
            }
        }
        before = std::mem::replace(&mut last, row);
    }
    last[b.len()]
}

/// `, did you mean "name"?` when one of `allowed` is close enough to `given` to be what was
/// meant (at most one edit per three characters, and at least one), else nothing; the
/// closest wins, the first listed among equals.
pub(super) fn did_you_mean(given: &str, allowed: &[&str]) -> String {
    let limit = (given.chars().count() / 3).max(1);
    allowed
        .iter()
        .map(|a| (distance(given, a), *a))
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, a)| format!(", did you mean {a:?}?"))
        .unwrap_or_default()
}

impl Ctx {
    pub(super) fn err(&mut self, key: impl Into<String>, reason: impl Into<String>) {
        self.issues.push(StudyIssue {
            key: key.into(),
            reason: reason.into(),
            line: None,
        });
    }

    /// An error for every key of `t` not in `allowed`, suggesting the allowed key it is a
    /// likely typo of.
    pub(super) fn known(&mut self, t: &Table, path: &str, allowed: &[&str]) {
        for k in t.keys() {
            if !allowed.contains(&k.as_str()) {
                self.err(
                    join(path, k),
                    format!(
                        "unknown key{} (allowed: {})",
                        did_you_mean(k, allowed),
                        allowed.join(", ")
                    ),
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
            format!(
                "expected one of {}, got {s:?}{}",
                names.join(", "),
                did_you_mean(&s, &names)
            ),
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

#[cfg(test)]
mod tests {
    use super::{did_you_mean, distance};

    #[test]
    fn distance_counts_edits_and_swaps() {
        assert_eq!(distance("name", "name"), 0);
        assert_eq!(distance("nmae", "name"), 1);
        assert_eq!(distance("gap_mss", "gap_ms"), 1);
        assert_eq!(distance("nam", "name"), 1);
        assert_eq!(distance("kitten", "sitting"), 3);
        assert_eq!(distance("", "abc"), 3);
        assert_eq!(distance("abc", ""), 3);
        assert_eq!(distance("ca", "abc"), 3);
    }

    #[test]
    fn a_close_key_is_suggested_a_far_one_is_not() {
        let allowed = ["format_version", "name", "title", "seed", "stimuli"];
        assert_eq!(did_you_mean("nmae", &allowed), ", did you mean \"name\"?");
        assert_eq!(
            did_you_mean("stimulus", &allowed),
            ", did you mean \"stimuli\"?"
        );
        assert_eq!(
            did_you_mean("fromat_version", &allowed),
            ", did you mean \"format_version\"?"
        );
        assert_eq!(did_you_mean("colour", &allowed), "");
        assert_eq!(did_you_mean("x", &allowed), "");
        // The first listed among equally close keys.
        assert_eq!(
            did_you_mean("sead", &["seed", "read"]),
            ", did you mean \"seed\"?"
        );
    }
}
