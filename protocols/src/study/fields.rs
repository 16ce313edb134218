//! `[session] subject_fields`: what the welcome screen asks a subject before the session,
//! each with its kind (free text, a number in a range, one of a list, yes or no). Every front
//! end draws the kind's input and checks an answer with [`SubjectField::check`], so the window,
//! the page and the server accept exactly the same values; the report summarises them by kind.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};
use toml::{Table, Value};

use super::check::{Ctx, type_name};

/// Longest answer to a field, characters.
pub const MAX_FIELD_CHARS: usize = 200;
/// Most options a choice field may list.
pub const MAX_OPTIONS: usize = 50;
/// Most fields a study may ask.
pub const MAX_FIELDS: usize = 50;

/// One question of the welcome screen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "FieldSpec")]
pub struct SubjectField {
    /// The key in `session.json`'s `subject_fields` (letters, digits, `_`).
    pub name: String,
    /// What the subject reads beside the input (default: the name with `_` as spaces).
    pub label: String,
    /// The kind of answer and its bounds.
    #[serde(flatten)]
    pub kind: FieldKind,
}

/// The kind of answer a subject field takes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FieldKind {
    /// Any text up to [`MAX_FIELD_CHARS`] characters.
    Text,
    /// A number in `min..=max`; `integer`: whole numbers only (an age in years).
    Number {
        /// Smallest accepted value.
        min: f64,
        /// Largest accepted value.
        max: f64,
        /// Whole numbers only.
        integer: bool,
    },
    /// One of `options`, as written.
    Choice {
        /// The options, in the order shown.
        options: Vec<String>,
    },
    /// "yes" or "no".
    YesNo,
}

/// What a stored study file or run.json holds: a bare name (a text field, as study files
/// before typed fields wrote it) or the whole field.
#[derive(Deserialize)]
#[serde(untagged)]
enum FieldSpec {
    Name(String),
    Full {
        name: String,
        #[serde(default)]
        label: Option<String>,
        #[serde(flatten)]
        kind: FieldKind,
    },
}

impl From<FieldSpec> for SubjectField {
    fn from(s: FieldSpec) -> SubjectField {
        match s {
            FieldSpec::Name(name) => SubjectField::text(&name),
            FieldSpec::Full { name, label, kind } => SubjectField {
                label: label.unwrap_or_else(|| default_label(&name)),
                name,
                kind,
            },
        }
    }
}

fn default_label(name: &str) -> String {
    name.replace('_', " ")
}

/// `x` as the report and error messages write a bound: no trailing `.0`.
fn number(x: f64) -> String {
    format!("{x}")
}

impl SubjectField {
    /// A free-text field labelled by its name.
    #[must_use]
    pub fn text(name: &str) -> SubjectField {
        SubjectField {
            name: name.to_string(),
            label: default_label(name),
            kind: FieldKind::Text,
        }
    }

    /// The answer `value` as stored (trimmed; a number as written, `yes`/`no` in lower case; a
    /// choice as the study file spells it), or why it is refused, in words a subject reads
    /// ("age: enter a whole number from 18 to 99").
    ///
    /// # Errors
    /// An empty answer, one over [`MAX_FIELD_CHARS`] or with control characters, a number out
    /// of range or not a number, an option the field does not list.
    pub fn check(&self, value: &str) -> Result<String, String> {
        let v = value.trim();
        let refuse = |why: String| Err(format!("{}: {why}", self.label));
        if v.is_empty() {
            return refuse(format!("{} (required)", self.hint()));
        }
        if v.chars().count() > MAX_FIELD_CHARS || v.chars().any(char::is_control) {
            return refuse(format!("at most {MAX_FIELD_CHARS} characters, on one line"));
        }
        match &self.kind {
            FieldKind::Text => Ok(v.to_string()),
            FieldKind::Number { min, max, integer } => match v.parse::<f64>() {
                Ok(x)
                    if x.is_finite()
                        && (!integer || x.fract() == 0.0)
                        && x >= *min
                        && x <= *max =>
                {
                    Ok(v.to_string())
                }
                _ => refuse(self.hint()),
            },
            FieldKind::Choice { options } => options
                .iter()
                .find(|o| o.eq_ignore_ascii_case(v))
                .cloned()
                .map_or_else(|| refuse(self.hint()), Ok),
            FieldKind::YesNo => match v.to_ascii_lowercase().as_str() {
                "yes" | "y" => Ok("yes".into()),
                "no" | "n" => Ok("no".into()),
                _ => refuse(self.hint()),
            },
        }
    }

    /// What an answer must be, in a subject's words ("enter a whole number from 18 to 99").
    #[must_use]
    pub fn hint(&self) -> String {
        match &self.kind {
            FieldKind::Text => "enter an answer".into(),
            FieldKind::Number { min, max, integer } => format!(
                "enter a {} from {} to {}",
                if *integer { "whole number" } else { "number" },
                number(*min),
                number(*max)
            ),
            FieldKind::Choice { options } => format!("choose one of: {}", options.join(", ")),
            FieldKind::YesNo => "choose yes or no".into(),
        }
    }

    /// The answers a front end offers as buttons (a choice's options, yes and no); empty for
    /// text and numbers, which are typed.
    #[must_use]
    pub fn options(&self) -> Vec<String> {
        match &self.kind {
            FieldKind::Choice { options } => options.clone(),
            FieldKind::YesNo => vec!["yes".into(), "no".into()],
            FieldKind::Text | FieldKind::Number { .. } => Vec::new(),
        }
    }

    /// A valid answer for a simulated subject `k` (0, 1, 2, ...): numbers spread over the range,
    /// options in turn, "simulated" for text.
    #[must_use]
    pub fn simulated(&self, k: u64) -> String {
        match &self.kind {
            FieldKind::Text => "simulated".into(),
            FieldKind::Number { min, max, integer } => {
                let span = max - min;
                let x = min + span * ((k % 7) as f64 + 0.5) / 7.0;
                if *integer {
                    let r = x.round().clamp(min.ceil(), max.floor());
                    number(r)
                } else {
                    number((x * 100.0).round() / 100.0)
                }
            }
            FieldKind::Choice { .. } | FieldKind::YesNo => {
                let o = self.options();
                o[(k % o.len() as u64) as usize].clone()
            }
        }
    }
}

/// `[session] subject_fields`: names (text fields) or inline tables
/// `{ name = "age", kind = "number", min = 18, max = 99, integer = true, label = "Age (years)" }`,
/// `{ name = "gender", kind = "choice", options = [...] }`, `{ name = "normal_vision", kind = "yes_no" }`.
pub(super) fn parse(t: &Table, path: &str, cx: &mut Ctx) -> Vec<SubjectField> {
    const KEY: &str = "subject_fields";
    let Some(v) = t.get(KEY) else {
        return Vec::new();
    };
    let Value::Array(a) = v else {
        cx.wrong(path, KEY, "an array of names or field tables", v);
        return Vec::new();
    };
    if a.len() > MAX_FIELDS {
        cx.err(
            format!("{path}.{KEY}"),
            format!("{} fields, limit {MAX_FIELDS}", a.len()),
        );
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut seen = BTreeSet::new();
    for (i, v) in a.iter().enumerate() {
        let at = format!("{path}.{KEY}[{i}]");
        let Some(f) = one(v, &at, cx) else { continue };
        if f.name.is_empty()
            || !f
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            cx.err(&at, format!("{:?} must be letters, digits or _", f.name));
        } else if !seen.insert(f.name.clone()) {
            cx.err(&at, format!("{:?} is listed twice", f.name));
        } else {
            out.push(f);
        }
    }
    out
}

fn one(v: &Value, at: &str, cx: &mut Ctx) -> Option<SubjectField> {
    let t = match v {
        Value::String(s) => return Some(SubjectField::text(s)),
        Value::Table(t) => t,
        v => {
            cx.err(
                at,
                format!("expected a name or a field table, got {}", type_name(v)),
            );
            return None;
        }
    };
    let kind_name = cx.string(t, at, "kind").unwrap_or_else(|| "text".into());
    let allowed: &[&str] = match kind_name.as_str() {
        "text" | "yes_no" => &["name", "label", "kind"],
        "number" => &["name", "label", "kind", "min", "max", "integer"],
        "choice" => &["name", "label", "kind", "options"],
        other => {
            cx.err(
                format!("{at}.kind"),
                format!("{other:?} is not a field kind (text, number, choice, yes_no)"),
            );
            return None;
        }
    };
    cx.known(t, at, allowed);
    let Some(name) = cx.string(t, at, "name") else {
        cx.err(format!("{at}.name"), "missing");
        return None;
    };
    let label = match cx.string(t, at, "label") {
        Some(l) if l.trim().is_empty() || l.chars().count() > MAX_FIELD_CHARS => {
            cx.err(
                format!("{at}.label"),
                format!("must be 1 to {MAX_FIELD_CHARS} characters"),
            );
            return None;
        }
        Some(l) => l,
        None => default_label(&name),
    };
    let kind = match kind_name.as_str() {
        "text" => FieldKind::Text,
        "yes_no" => FieldKind::YesNo,
        "number" => {
            let (Some(min), Some(max)) = (cx.float(t, at, "min"), cx.float(t, at, "max")) else {
                cx.err(at, "a number field needs min and max");
                return None;
            };
            if min > max {
                cx.err(format!("{at}.min"), format!("{min} is above max {max}"));
                return None;
            }
            let integer = cx.boolean(t, at, "integer").unwrap_or(false);
            if integer && min.ceil() > max.floor() {
                cx.err(at, format!("no whole number lies in {min}..={max}"));
                return None;
            }
            FieldKind::Number { min, max, integer }
        }
        _ => {
            let options = cx.strings(t, at, "options").unwrap_or_default();
            let distinct: BTreeSet<String> =
                options.iter().map(|o| o.trim().to_lowercase()).collect();
            if options.is_empty() || options.len() > MAX_OPTIONS {
                cx.err(
                    format!("{at}.options"),
                    format!("a choice needs 1 to {MAX_OPTIONS} options"),
                );
                return None;
            }
            if distinct.len() != options.len() || distinct.contains("") {
                cx.err(
                    format!("{at}.options"),
                    "options must be distinct and not empty",
                );
                return None;
            }
            if let Some(o) = options.iter().find(|o| o.chars().count() > MAX_FIELD_CHARS) {
                cx.err(
                    format!("{at}.options"),
                    format!("{o:?} is over {MAX_FIELD_CHARS} characters"),
                );
                return None;
            }
            FieldKind::Choice { options }
        }
    };
    Some(SubjectField { name, label, kind })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn age() -> SubjectField {
        SubjectField {
            name: "age".into(),
            label: "age".into(),
            kind: FieldKind::Number {
                min: 18.0,
                max: 99.0,
                integer: true,
            },
        }
    }

    #[test]
    fn a_number_field_takes_whole_numbers_in_its_range_only() {
        let f = age();
        assert_eq!(f.check(" 31 "), Ok("31".into()));
        for bad in ["abc", "17", "100", "31.5", "", "NaN", "inf"] {
            let e = f.check(bad).unwrap_err();
            assert!(e.contains("whole number from 18 to 99"), "{bad}: {e}");
        }
    }

    #[test]
    fn choices_and_yes_no_store_the_study_files_spelling() {
        let g = SubjectField {
            name: "gender".into(),
            label: "gender".into(),
            kind: FieldKind::Choice {
                options: vec!["female".into(), "male".into(), "prefer not to say".into()],
            },
        };
        assert_eq!(g.check("Female"), Ok("female".into()));
        assert!(g.check("f").unwrap_err().contains("female, male"));
        let v = SubjectField {
            kind: FieldKind::YesNo,
            ..SubjectField::text("normal_vision")
        };
        assert_eq!(v.check("Y"), Ok("yes".into()));
        assert!(v.check("maybe").is_err());
        for k in 0..20 {
            assert!(g.check(&g.simulated(k)).is_ok());
            assert!(age().check(&age().simulated(k)).is_ok());
        }
    }

    #[test]
    fn a_bare_name_in_a_stored_definition_reads_as_a_text_field() {
        let f: Vec<SubjectField> = serde_json::from_str(
            r#"["age", {"name":"v","label":"Normal vision","kind":"yes_no"}]"#,
        )
        .unwrap();
        assert_eq!(f[0], SubjectField::text("age"));
        assert_eq!(f[1].kind, FieldKind::YesNo);
        let back: Vec<SubjectField> =
            serde_json::from_str(&serde_json::to_string(&f).unwrap()).unwrap();
        assert_eq!(back, f);
    }
}
