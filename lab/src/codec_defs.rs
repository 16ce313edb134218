//! A lab's own codecs, each defined by an encode and a decode command in a TOML file
//! (`study ... --codec-defs FILE`, or a live staircase's `[staircase.live] codecs`), read
//! into [`codecs::codec::external::Definition`]s. The file's format is in docs/codecs.md:
//!
//! ```toml
//! format_version = 1
//!
//! [codec.quantise]
//! description = "every channel rounded to a multiple of step"
//! encode = ["python3", "quantise.py", "encode", "{input}", "{output}", "{step}"]
//! decode = ["python3", "quantise.py", "decode", "{input}", "{skeleton}", "{output}", "{step}"]
//! timeout_s = 60
//! params = { step = 0.5 }
//! rate = { param = "step", min = 0.001, max = 50, cr = "grows" }
//! ```
//!
//! Every problem comes back at once, each naming the file and the key.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use codecs::codec::external::{Definition, MAX_NAME_LEN, intern};
use codecs::codec::{self, Params, RateControl};
use serde::Deserialize;

use crate::error::{Result, refused};

/// The format version this build reads.
pub const FORMAT_VERSION: u32 = 1;
/// Largest definitions file, bytes.
const MAX_BYTES: u64 = 1 << 20;
/// Most codecs in one file.
const MAX_CODECS: usize = 64;
/// Longest time limit of one command, seconds.
const MAX_TIMEOUT_S: f64 = 3_600.0;
/// The time limit when none is given, seconds.
const DEFAULT_TIMEOUT_S: f64 = 60.0;
/// Placeholders every command may use besides its parameters.
const PLACEHOLDERS: &[&str] = &["input", "output", "skeleton", "frames", "rate"];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    format_version: u32,
    #[serde(default)]
    codec: BTreeMap<String, Entry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    #[serde(default)]
    description: Option<String>,
    encode: Vec<String>,
    decode: Vec<String>,
    #[serde(default)]
    timeout_s: Option<f64>,
    #[serde(default)]
    params: BTreeMap<String, f64>,
    #[serde(default)]
    rate: Option<Rate>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Rate {
    param: String,
    min: f64,
    max: f64,
    cr: Direction,
    #[serde(default)]
    slope: Option<f64>,
}

/// How the CR moves as the rate parameter grows.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Direction {
    /// The CR grows with it (a quantizer step, an error threshold).
    Grows,
    /// The CR falls as it grows (a quality, a kept share).
    Falls,
}

/// Reads the codec definitions at `path`; commands run in the file's folder.
///
/// # Errors
/// The file cannot be read, is not TOML of this format, or has problems (a name taken by a
/// built-in codec, an empty command, an unknown placeholder, a rate parameter the codec does
/// not take, ...): all of them in one message, each with its key.
pub fn read(path: &Path) -> Result<Vec<Arc<Definition>>> {
    let shown = path.display();
    let len = std::fs::metadata(path)
        .map_err(|e| refused(format!("{shown}: {e}")))?
        .len();
    if len > MAX_BYTES {
        return Err(refused(format!(
            "{shown}: {len} bytes; a codec definitions file is at most {MAX_BYTES}"
        )));
    }
    let text = std::fs::read_to_string(path).map_err(|e| refused(format!("{shown}: {e}")))?;
    let file: File = toml::from_str(&text).map_err(|e| refused(format!("{shown}: {e}")))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let dir = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    let mut problems = Vec::new();
    if file.format_version != FORMAT_VERSION {
        problems.push(format!(
            "format_version: {} is not supported (this build reads {FORMAT_VERSION})",
            file.format_version
        ));
    }
    if file.codec.is_empty() {
        problems.push("codec: defines no codec ([codec.NAME] tables)".into());
    }
    if file.codec.len() > MAX_CODECS {
        problems.push(format!(
            "codec: {} codecs, limit {MAX_CODECS}",
            file.codec.len()
        ));
    }
    let mut defs = Vec::new();
    for (name, entry) in file.codec.into_iter().take(MAX_CODECS) {
        let mut say = |key: &str, why: String| problems.push(format!("codec.{name}{key}: {why}"));
        if let Some(def) = definition(&name, entry, &dir, &mut say) {
            defs.push(Arc::new(def));
        }
    }
    if !problems.is_empty() {
        return Err(refused(format!(
            "{shown}: {} problem{}:\n  {}",
            problems.len(),
            if problems.len() == 1 { "" } else { "s" },
            problems.join("\n  ")
        )));
    }
    Ok(defs)
}

/// One `[codec.NAME]` table, checked; `None` after saying what is wrong.
fn definition(
    name: &str,
    e: Entry,
    dir: &Path,
    say: &mut impl FnMut(&str, String),
) -> Option<Definition> {
    let before = std::cell::Cell::new(0usize);
    let mut count = |key: &str, why: String| {
        before.set(before.get() + 1);
        say(key, why);
    };
    if name.is_empty()
        || name.len() > MAX_NAME_LEN
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_'))
    {
        count(
            "",
            format!("a name is 1-{MAX_NAME_LEN} letters, digits, '-' or '_'"),
        );
    }
    if codec::by_name(name).is_some() {
        count("", "is a built-in codec's name; choose another".into());
    }
    for (k, v) in &e.params {
        if k == codec::keys::CR {
            count(
                &format!(".params.{k}"),
                "`cr` is the target ratio rate control sets; name the codec's own knob".into(),
            );
        } else if k.is_empty()
            || k.len() > 32
            || !k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            count(
                &format!(".params.{k}"),
                "a parameter name is 1-32 letters, digits or _".into(),
            );
        } else if PLACEHOLDERS.contains(&k.as_str()) {
            count(
                &format!(".params.{k}"),
                format!("{{{k}}} is a file placeholder; name the parameter otherwise"),
            );
        } else if !v.is_finite() {
            count(&format!(".params.{k}"), format!("{v} is not finite"));
        }
    }
    for (key, command) in [("encode", &e.encode), ("decode", &e.decode)] {
        check_command(key, command, &e.params, &mut count);
    }
    let timeout = e.timeout_s.unwrap_or(DEFAULT_TIMEOUT_S);
    if !(timeout > 0.0 && timeout <= MAX_TIMEOUT_S) {
        count(
            ".timeout_s",
            format!("{timeout}: give 0 < seconds ≤ {MAX_TIMEOUT_S}"),
        );
    }
    let rate = match &e.rate {
        None => RateControl::None,
        Some(r) => rate_control(r, &e.params, &mut count),
    };
    if before.get() > 0 {
        return None;
    }
    let mut params: Params = e.params.into_iter().collect();
    if rate != RateControl::None {
        // As for the built-in codecs: rate control sets `cr` (the target) among the
        // parameters; 0 means "none asked".
        params.insert(codec::keys::CR.to_string(), 0.0);
    }
    Some(Definition {
        name: name.to_string(),
        description: e
            .description
            .unwrap_or_else(|| format!("command-defined: {}", e.encode.join(" "))),
        encode: e.encode,
        decode: e.decode,
        dir: dir.to_path_buf(),
        params,
        rate,
        timeout: Duration::from_secs_f64(timeout.clamp(0.001, MAX_TIMEOUT_S)),
    })
}

/// A command: a program, no unknown placeholder, and `{input}` and `{output}` somewhere.
fn check_command(
    key: &str,
    command: &[String],
    params: &BTreeMap<String, f64>,
    say: &mut impl FnMut(&str, String),
) {
    if command.first().is_none_or(|p| p.trim().is_empty()) {
        say(
            &format!(".{key}"),
            "give the program and its arguments, e.g. [\"python3\", \"codec.py\", \"{input}\", \"{output}\"]".into(),
        );
        return;
    }
    for (i, arg) in command.iter().enumerate() {
        let mut rest = arg.as_str();
        while let Some(open) = rest.find('{') {
            let Some(close) = rest[open..].find('}') else {
                break;
            };
            let name = &rest[open + 1..open + close];
            if !PLACEHOLDERS.contains(&name) && !params.contains_key(name) {
                say(
                    &format!(".{key}[{i}]"),
                    format!(
                        "unknown placeholder {{{name}}}; known: {}, and the codec's params",
                        PLACEHOLDERS
                            .iter()
                            .map(|p| format!("{{{p}}}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                );
            }
            rest = &rest[open + close + 1..];
        }
    }
    for needed in ["{input}", "{output}"] {
        if !command.iter().any(|a| a.contains(needed)) {
            say(&format!(".{key}"), format!("never names {needed}"));
        }
    }
}

/// `rate`: the knob rate control searches.
fn rate_control(
    r: &Rate,
    params: &BTreeMap<String, f64>,
    say: &mut impl FnMut(&str, String),
) -> RateControl {
    let Some(&default) = params.get(&r.param) else {
        say(
            ".rate.param",
            format!("{:?} is not one of the codec's params", r.param),
        );
        return RateControl::None;
    };
    if !(r.min > 0.0 && r.min < r.max && r.max.is_finite()) {
        say(
            ".rate",
            format!(
                "min {} and max {}: give 0 < min < max (the search runs on a log scale)",
                r.min, r.max
            ),
        );
        return RateControl::None;
    }
    if !(r.min..=r.max).contains(&default) {
        say(
            &format!(".params.{}", r.param),
            format!(
                "its default {default} is outside the rate range [{}, {}]",
                r.min, r.max
            ),
        );
    }
    let slope = r.slope.unwrap_or(1.0);
    if !(slope > 0.0 && slope.is_finite()) {
        say(".rate.slope", format!("{slope}: give a positive number"));
    }
    // The rate search names its knob as `&'static str` (the built-in codecs' keys); a
    // definition's knob is interned once per distinct name.
    let key = intern(&r.param);
    match r.cr {
        Direction::Grows => RateControl::SearchIncreasing {
            key,
            min: r.min,
            max: r.max,
            slope,
        },
        Direction::Falls => RateControl::Search {
            key,
            min: r.min,
            max: r.max,
            slope,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("codec-defs-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("codecs.toml");
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_definition_is_read_with_its_rate_knob() {
        let p = write(
            "ok",
            r#"format_version = 1
[codec.q]
encode = ["python3", "q.py", "{input}", "{output}", "{step}"]
decode = ["python3", "q.py", "-d", "{input}", "{skeleton}", "{output}"]
params = { step = 0.5, bits = 8 }
rate = { param = "step", min = 0.001, max = 10, cr = "grows" }
"#,
        );
        let defs = read(&p).unwrap();
        assert_eq!(defs.len(), 1);
        assert_eq!(defs[0].name, "q");
        assert_eq!(defs[0].timeout, Duration::from_secs(60));
        assert_eq!(
            defs[0].rate,
            RateControl::SearchIncreasing {
                key: "step",
                min: 0.001,
                max: 10.0,
                slope: 1.0
            }
        );
        // Rate control sets `cr` among the parameters, as for the built-in codecs.
        assert_eq!(defs[0].params.get("cr"), Some(&0.0));
    }

    #[test]
    fn every_problem_is_named_by_its_key() {
        let p = write(
            "bad",
            r#"format_version = 1
[codec.spiht]
encode = ["x", "{input}", "{output}"]
decode = ["x", "{input}", "{output}"]
[codec."a b"]
encode = []
decode = ["x", "{input}", "{out}"]
timeout_s = 0
params = { cr = 3, input = 1 }
rate = { param = "q", min = 1, max = 2, cr = "falls" }
"#,
        );
        let e = read(&p).unwrap_err().to_string();
        for needle in [
            "codec.spiht: is a built-in codec's name",
            "codec.a b: a name is 1-32",
            "codec.a b.encode: give the program",
            "codec.a b.decode[2]: unknown placeholder {out}",
            "codec.a b.decode: never names {output}",
            "codec.a b.timeout_s: 0",
            "codec.a b.params.cr:",
            "codec.a b.params.input: {input} is a file placeholder",
            "codec.a b.rate.param: \"q\" is not one",
            "9 problems",
        ] {
            assert!(e.contains(needle), "{needle:?} not in {e}");
        }
        let p = write(
            "key",
            "format_version = 1\n[codec.q]\nencode = [\"a\"]\ndecode = [\"b\"]\nshell = true\n",
        );
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("codecs.toml") && e.contains("shell"), "{e}");
    }
}
