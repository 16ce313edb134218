//! Shared plumbing of the text readers: bounded file reading, lines, numbers.

use std::fmt::Write as _;
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
    parse_finite(tok).ok_or_else(|| bad_number(path, line, what, tok))
}

/// `tok` as a finite `f64` (what `str::parse` reads), `None` if it is not one.
///
/// Mocap files hold short decimals (`-27.07`, `2.51125`): those are read here directly as
/// `digits / 10^k`, which is exact, since both are exactly representable (at most 2^53 and
/// 10^22) and one IEEE division rounds correctly (Clinger's fast path, the one `str::parse`
/// also takes first, less its general-purpose scanning). Anything else (exponents, more than
/// 15 digits, `inf`) goes to `str::parse`.
pub(crate) fn parse_finite(tok: &str) -> Option<f64> {
    /// Exact powers of ten of `f64`.
    const POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let b = tok.as_bytes();
    let (negative, digits) = match b.split_first() {
        Some((b'-', rest)) => (true, rest),
        Some((b'+', rest)) => (false, rest),
        _ => (false, b),
    };
    let mut mantissa: u64 = 0;
    let mut count = 0usize;
    let mut fraction: Option<usize> = None;
    let mut fast = !digits.is_empty() && digits.len() <= 16;
    if fast {
        for &c in digits {
            match c {
                b'0'..=b'9' => {
                    mantissa = mantissa * 10 + u64::from(c - b'0');
                    count += 1;
                    if let Some(f) = fraction.as_mut() {
                        *f += 1;
                    }
                }
                b'.' if fraction.is_none() => fraction = Some(0),
                _ => {
                    fast = false;
                    break;
                }
            }
        }
    }
    // At most 16 characters: at most 15 digits with a point, so the mantissa is below 2^53.
    if fast && count > 0 && mantissa < (1 << 53) {
        let v = mantissa as f64 / POW10[fraction.unwrap_or(0)];
        return Some(if negative { -v } else { v });
    }
    match tok.parse::<f64>() {
        Ok(v) if v.is_finite() => Some(v),
        _ => None,
    }
}

/// The whitespace-separated fields of `line`, as `str::split_whitespace` gives them; an ASCII
/// line (every mocap file) is split on its bytes, without decoding characters.
pub(crate) fn fields(line: &str) -> Fields<'_> {
    if line.is_ascii() {
        Fields::Ascii { line, pos: 0 }
    } else {
        Fields::Unicode(line.split_whitespace())
    }
}

/// Iterator of [`fields`].
pub(crate) enum Fields<'a> {
    /// An ASCII line and where the next field may start.
    Ascii { line: &'a str, pos: usize },
    /// Any other line.
    Unicode(std::str::SplitWhitespace<'a>),
}

impl<'a> Iterator for Fields<'a> {
    type Item = &'a str;

    fn next(&mut self) -> Option<&'a str> {
        match self {
            Fields::Unicode(it) => it.next(),
            Fields::Ascii { line, pos } => {
                // `char::is_whitespace` on ASCII: space, \t, \n, vertical tab, form feed, \r.
                let white = |b: u8| matches!(b, b' ' | b'\t' | b'\n' | 0x0B | 0x0C | b'\r');
                let bytes = line.as_bytes();
                let start = *pos + bytes.get(*pos..)?.iter().position(|&b| !white(b))?;
                let end = bytes[start..]
                    .iter()
                    .position(|&b| white(b))
                    .map_or(bytes.len(), |k| start + k);
                *pos = end;
                line.get(start..end)
            }
        }
    }
}

/// The error of [`number`] for `tok`.
pub(crate) fn bad_number(path: &Path, line: usize, what: &str, tok: &str) -> ParseError {
    ParseError::BadNumber {
        path: path.to_path_buf(),
        line,
        what: what.to_string(),
        text: tok.chars().take(40).collect(),
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
    let mut s = String::new();
    push_num(&mut s, v);
    s
}

/// Appends [`fmt_num`]`(v)` to `out` without allocating.
///
/// The text is the one `format!("{v:?}")` writes less a trailing `.0` (what the writers wrote
/// before): plain decimals for `1e-4 <= |v| < 1e16`, `d.ddde±x` outside, `-0` for negative
/// zero. The shortest digits come from `zmij` (Schubfach), which the std `Debug` path took
/// about ten times as long to find (29 % of `study encode` went to number formatting); the
/// layout is ours, so written clips do not change. (Above 1e13, where a double can lie exactly
/// halfway between two shortest candidates, zmij rounds that tie to even and `Debug` up: the
/// last digit may differ, and both read back to the same `f64`.)
pub(crate) fn push_num(out: &mut String, v: f64) {
    if v == 0.0 {
        out.push_str(if v.is_sign_negative() { "-0" } else { "0" });
        return;
    }
    if !v.is_finite() {
        // Never in a clip (the readers and `Clip` refuse them); written as `Debug` does.
        let _ = write!(out, "{v:?}");
        return;
    }
    let mut buf = zmij::Buffer::new();
    let text = buf.format_finite(v);
    // Inside `Debug`'s decimal range zmij writes plain decimals too, `Debug`'s text but for
    // the trailing `.0` of integers.
    if (1e-4..1e16).contains(&v.abs()) && !text.contains('e') {
        out.push_str(text.strip_suffix(".0").unwrap_or(text));
        return;
    }
    // Elsewhere zmij's layout is its own (`1e+300`, `0.00001`): take its digits and decimal
    // exponent.
    let text = text.as_bytes();
    let (negative, text) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, text),
    };
    let (mantissa, exp10) = match text.iter().position(|&b| b == b'e' || b == b'E') {
        Some(i) => (
            &text[..i],
            std::str::from_utf8(&text[i + 1..])
                .ok()
                .and_then(|e| e.parse::<i32>().ok())
                .unwrap_or(0),
        ),
        None => (text, 0),
    };
    let mut digits = [0u8; 40];
    let mut n = 0usize;
    // Digits before the decimal point, counted before leading zeros are dropped.
    let mut int_digits: i32 = 0;
    let mut seen_point = false;
    for &b in mantissa {
        if b == b'.' {
            seen_point = true;
        } else if b.is_ascii_digit() {
            if !seen_point {
                int_digits += 1;
            }
            if n == 0 && b == b'0' {
                // A leading zero: one integer digit fewer.
                int_digits -= 1;
            } else if n < digits.len() {
                digits[n] = b;
                n += 1;
            }
        }
    }
    while n > 1 && digits[n - 1] == b'0' {
        n -= 1;
    }
    let digits = &digits[..n];
    // v = d.ddd × 10^e
    let e = int_digits - 1 + exp10;
    if negative {
        out.push('-');
    }
    if (-4..16).contains(&e) {
        if e >= 0 {
            let int_len = e as usize + 1;
            if n <= int_len {
                out.push_str(ascii(digits));
                out.extend(std::iter::repeat_n('0', int_len - n));
            } else {
                out.push_str(ascii(&digits[..int_len]));
                out.push('.');
                out.push_str(ascii(&digits[int_len..]));
            }
        } else {
            out.push_str("0.");
            out.extend(std::iter::repeat_n('0', (-e - 1) as usize));
            out.push_str(ascii(digits));
        }
    } else {
        out.push_str(ascii(&digits[..1]));
        if n > 1 {
            out.push('.');
            out.push_str(ascii(&digits[1..]));
        }
        let _ = write!(out, "e{e}");
    }
}

/// ASCII digits as text (they are always valid UTF-8, so nothing is ever dropped).
fn ascii(digits: &[u8]) -> &str {
    std::str::from_utf8(digits).unwrap_or_default()
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
    fn fields_split_as_split_whitespace_does() {
        for line in [
            "root 1 2  3",
            "  lead\tand trail \x0b\x0c ",
            "",
            "   ",
            "one",
            "caf\u{e9} 1\u{a0}2 3",
        ] {
            let got: Vec<&str> = fields(line).collect();
            let want: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(got, want, "{line:?}");
        }
    }

    /// The fast path reads what `str::parse` reads, bit for bit, and leaves the rest to it.
    #[test]
    fn parse_finite_reads_what_parse_reads() {
        let mut toks: Vec<String> = [
            "0",
            "-0",
            "+0",
            "0.0",
            "-0.000",
            "1",
            "-27.07",
            "2.51125",
            "17.2554",
            ".5",
            "5.",
            "-.5",
            "123456789012345",
            "1234567890123456",
            "12345678901234567",
            "0.1",
            "9007199254740993",
            "1e3",
            "1E-3",
            "inf",
            "-inf",
            "nan",
            "1e999",
            "",
            "-",
            "+",
            ".",
            "1.2.3",
            "1-2",
            "--1",
            "0x10",
            " 1",
            "1 ",
            "١",
        ]
        .iter()
        .map(|s| (*s).to_string())
        .collect();
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        for _ in 0..50_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let digits = (x % 10_000_000_000) as i64 - 5_000_000_000;
            let k = ((x >> 40) % 16) as usize;
            let s = digits.abs().to_string();
            let s = if k < s.len() {
                format!("{}.{}", &s[..s.len() - k], &s[s.len() - k..])
            } else {
                format!("0.{}{s}", "0".repeat(k - s.len()))
            };
            toks.push(if digits < 0 { format!("-{s}") } else { s });
        }
        for t in &toks {
            let want = t.parse::<f64>().ok().filter(|v| v.is_finite());
            assert_eq!(
                parse_finite(t).map(f64::to_bits),
                want.map(f64::to_bits),
                "{t:?}"
            );
        }
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

    /// What the writers wrote before `push_num`: the `Debug` text less a trailing `.0`.
    fn debug_text(v: f64) -> String {
        if v == 0.0 && v.is_sign_positive() {
            return "0".into();
        }
        let s = format!("{v:?}");
        s.strip_suffix(".0").map_or(s.clone(), str::to_string)
    }

    /// Bit-exact round trips, and the same text as before below 1e13 (every value a clip
    /// holds), over the edges of the layout and 200 000 pseudo-random bit patterns
    /// (xorshift64, fixed seed) spread over every exponent.
    #[test]
    fn push_num_writes_what_debug_wrote() {
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            1e-4,
            -1e-4,
            9.999_999_999_999_999e-5,
            1e-5,
            1.5e-7,
            1e15,
            9_999_999_999_999_998.0,
            1e16,
            1.234_567_890_123_456_7e16,
            123_456_789.0,
            f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            -27.069_999_999_999_997,
            2.51125,
            100.0,
            1e21,
            1e22,
            1e23,
        ];
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for i in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let v = f64::from_bits(x);
            if v.is_finite() {
                values.push(v);
            }
            // Values a clip holds: angles and lengths with a few decimals, and their
            // decoded neighbours.
            let short = ((x % 4_000_000) as f64 - 2_000_000.0) / 10f64.powi(i % 7);
            values.push(short);
            values.push(f64::from_bits(short.to_bits().wrapping_add(1)));
        }
        let mut s = String::new();
        for v in values {
            s.clear();
            push_num(&mut s, v);
            let before = debug_text(v);
            if v.abs() < 1e13 {
                assert_eq!(s, before, "{v:e}");
            } else {
                // Where a double's exact value has few decimals it can fall halfway between
                // two shortest candidates (1658206780088562.25): zmij rounds the tie to even,
                // `Debug` up; both read back to `v`.
                assert_eq!(s.len(), before.len(), "{v:e}: {s} vs {before}");
            }
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{s}");
        }
    }
}
