//! Shared plumbing of the text readers: bounded file reading, lines, numbers.

use std::io::Read;
use std::path::Path;

use crate::error::{Limits, ParseError};

/// Reads a whole file as text, refusing files over `limits.max_file_bytes` before reading.
pub(crate) fn read_text(path: &Path, limits: &Limits) -> Result<String, ParseError> {
    let io = |err| ParseError::Io {
        path: path.to_path_buf(),
        err,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    if len > limits.max_file_bytes {
        return Err(ParseError::TooLarge {
            path: path.to_path_buf(),
            line: 0,
            what: "file size in bytes".into(),
            value: len,
            limit: limits.max_file_bytes,
        });
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(limits.max_file_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    String::from_utf8(bytes).or_else(|e| {
        // Mocap files are ASCII; a stray Latin-1 byte in a comment should not stop a lab.
        let bytes = e.into_bytes();
        Ok(bytes.iter().map(|&b| b as char).collect())
    })
}

/// Lines of a text with 1-based numbers; `\r\n`, `\n` and lone `\r` all end a line.
pub(crate) fn lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.split('\n')
        .flat_map(|l| {
            // A lone '\r' inside a line (old Mac endings) also ends a line.
            let l = l.strip_suffix('\r').unwrap_or(l);
            l.split('\r')
        })
        .enumerate()
        .map(|(i, l)| (i + 1, l))
}

/// Parses one finite number, naming the place on failure.
pub(crate) fn number(path: &Path, line: usize, what: &str, tok: &str) -> Result<f64, ParseError> {
    match tok.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(ParseError::BadNumber {
            path: path.to_path_buf(),
            line,
            what: what.to_string(),
            text: tok.chars().take(40).collect(),
        }),
    }
}

/// Parses exactly `N` finite numbers from `toks`.
pub(crate) fn numbers<const N: usize>(
    path: &Path,
    line: usize,
    what: &str,
    toks: &[&str],
) -> Result<[f64; N], ParseError> {
    if toks.len() != N {
        return Err(ParseError::WrongCount {
            path: path.to_path_buf(),
            line,
            what: what.to_string(),
            expected: N,
            found: toks.len(),
        });
    }
    let mut out = [0.0; N];
    for (o, t) in out.iter_mut().zip(toks) {
        *o = number(path, line, what, t)?;
    }
    Ok(out)
}

/// Formats a number so that parsing the text gives back the same `f64` bit for bit, in the
/// shortest form (`10.4194`, `-1.6201e-14`, `0`).
pub(crate) fn fmt_num(v: f64) -> String {
    if v == 0.0 && v.is_sign_positive() {
        return "0".into();
    }
    let s = format!("{v:?}");
    s.strip_suffix(".0").map_or(s.clone(), str::to_string)
}

/// A syntax error at a line.
pub(crate) fn syntax(path: &Path, line: usize, reason: impl Into<String>) -> ParseError {
    ParseError::Syntax {
        path: path.to_path_buf(),
        line,
        reason: reason.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mixed_line_endings_split_alike() {
        let got: Vec<_> = lines("a\r\nb\nc\rd").map(|(_, l)| l).collect();
        assert_eq!(got, ["a", "b", "c", "d"]);
    }

    #[test]
    fn fmt_num_round_trips() {
        for v in [
            10.4194,
            -1.6201e-14,
            0.0,
            -0.0,
            101.5481,
            1e300,
            5.0,
            -7.125,
            0.1 + 0.2,
        ] {
            let s = fmt_num(v);
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{s}");
        }
        assert_eq!(fmt_num(5.0), "5");
    }
}
