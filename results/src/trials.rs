//! `trials.csv` format versions 1 and 2: one row per trial, written and read here.
//!
//! Plain RFC 4180 CSV with a fixed header ([`HEADER`]); the first column repeats the format
//! version on every row so a row taken out of its file still says how to read it. Fields that
//! contain a comma or a quote are quoted; line breaks inside fields are refused, so every row is
//! exactly one line and a row cut short by a power failure is the last line without its `\n`.
//! Version 2 appends three optional columns for stimuli the runner encodes on the fly (live
//! staircase): `codec_params`, `achieved_cr`, `rms_cm`. Version 1 files still read, and a
//! session resumed into a version 1 file keeps appending version 1 rows. Documented in
//! `docs/results-format.md`.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use protocols::{
    Answer, Arrangement, Block, FrameTiming, Outcome, Position, Protocol, Response,
    StimulusEncoding, Trial, TrialRecord,
};

use crate::ResultsError;

/// Version of the `trials.csv` format written by this build.
pub const TRIALS_FORMAT_VERSION: u32 = 2;

/// The oldest `trials.csv` version this build reads (and appends to on resume).
pub const OLDEST_TRIALS_FORMAT_VERSION: u32 = 1;

/// Column names of the current version, in order.
pub const COLUMNS: [&str; 34] = [
    "format_version",
    "study",
    "subject",
    "session",
    "trial_index",
    "block",
    "protocol",
    "condition",
    "stimulus",
    "reference",
    "arrangement",
    "reference_position",
    "break_before",
    "staircase",
    "level",
    "response",
    "response_a",
    "response_b",
    "score",
    "score_reference",
    "score_test",
    "correct",
    "reversal",
    "response_time_ms",
    "replays",
    "dropped_frames",
    "elapsed_ms",
    "wall_clock_ms",
    "monotonic_ms",
    "codec_params",
    "achieved_cr",
    "rms_cm",
    "frames_shown",
    "interval_sd_ms",
];

/// Columns of version 1: the first 29 of [`COLUMNS`].
pub const COLUMNS_V1: usize = 29;

/// The header line, without its line break.
pub const HEADER: &str = "format_version,study,subject,session,trial_index,block,protocol,condition,stimulus,reference,\
arrangement,reference_position,break_before,staircase,level,response,response_a,response_b,score,score_reference,\
score_test,correct,reversal,response_time_ms,replays,dropped_frames,elapsed_ms,wall_clock_ms,monotonic_ms,\
codec_params,achieved_cr,rms_cm,frames_shown,interval_sd_ms";

/// The header line of version 1 (no encoding columns), without its line break.
pub const HEADER_V1: &str = "format_version,study,subject,session,trial_index,block,protocol,condition,stimulus,reference,\
arrangement,reference_position,break_before,staircase,level,response,response_a,response_b,score,score_reference,\
score_test,correct,reversal,response_time_ms,replays,dropped_frames,elapsed_ms,wall_clock_ms,monotonic_ms";

/// The header line of `version`, or `None` for a version this build does not know.
pub fn header_of(version: u32) -> Option<&'static str> {
    match version {
        1 => Some(HEADER_V1),
        2 => Some(HEADER),
        _ => None,
    }
}

fn column_count(version: u32) -> usize {
    if version == 1 {
        COLUMNS_V1
    } else {
        COLUMNS.len()
    }
}

/// Longest row accepted by the reader, bytes.
pub const MAX_ROW_BYTES: usize = 64 * 1024;
/// Largest `trials.csv` accepted by the reader, bytes (checked before reading).
pub const MAX_TRIALS_BYTES: u64 = 1 << 30;

fn push_field(out: &mut String, v: &str) -> Result<(), String> {
    if v.contains(['\n', '\r']) {
        return Err(format!("field {v:?} contains a line break"));
    }
    if v.contains([',', '"']) || v.starts_with(' ') || v.ends_with(' ') {
        out.push('"');
        out.push_str(&v.replace('"', "\"\""));
        out.push('"');
    } else {
        out.push_str(v);
    }
    Ok(())
}

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

fn flag(v: bool) -> String {
    if v { "1".into() } else { "0".into() }
}

/// Writes codec parameters as `key=value;key=value` (keys sorted, values in shortest
/// round-trip form), the `codec_params` column.
///
/// # Errors
/// A reason when a key is not 1-32 letters, digits or `_`, or a value is not finite.
pub fn format_codec_params(params: &BTreeMap<String, f64>) -> Result<String, String> {
    let mut out = String::new();
    for (k, v) in params {
        if !valid_param_key(k) {
            return Err(format!(
                "parameter name {k:?} must be 1-32 letters, digits or _"
            ));
        }
        if !v.is_finite() {
            return Err(format!("parameter {k} = {v} is not finite"));
        }
        if !out.is_empty() {
            out.push(';');
        }
        out.push_str(k);
        out.push('=');
        out.push_str(&v.to_string());
    }
    Ok(out)
}

fn valid_param_key(k: &str) -> bool {
    !k.is_empty() && k.len() <= 32 && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Reads the `codec_params` column back ([`format_codec_params`]).
///
/// # Errors
/// A reason naming the entry that is not `key=finite number`, or a key given twice.
pub fn parse_codec_params(text: &str) -> Result<BTreeMap<String, f64>, String> {
    let mut out = BTreeMap::new();
    if text.is_empty() {
        return Ok(out);
    }
    for entry in text.split(';') {
        let Some((k, v)) = entry.split_once('=') else {
            return Err(format!("entry {entry:?} is not key=value"));
        };
        if !valid_param_key(k) {
            return Err(format!(
                "parameter name {k:?} must be 1-32 letters, digits or _"
            ));
        }
        let value: f64 = v
            .parse()
            .ok()
            .filter(|x: &f64| x.is_finite())
            .ok_or_else(|| format!("parameter {k}: {v:?} is not a finite number"))?;
        if out.insert(k.to_string(), value).is_some() {
            return Err(format!("parameter {k} is given twice"));
        }
    }
    Ok(out)
}

/// Encodes one record as a CSV line of the current version, ending in `\n`.
///
/// # Errors
/// [`ResultsError::Unwritable`] when a text field contains a line break or the codec
/// parameters cannot be written.
pub fn encode_row(r: &TrialRecord) -> Result<String, ResultsError> {
    encode_row_as(r, TRIALS_FORMAT_VERSION)
}

/// Columns 30-32 of `r` (empty without an encoding).
fn encoding_fields(
    r: &TrialRecord,
    version: u32,
) -> Result<(String, String, String), ResultsError> {
    Ok(match &r.encoding {
        None => (String::new(), String::new(), String::new()),
        Some(_) if version == 1 => {
            return Err(ResultsError::Unwritable {
                column: "codec_params",
                reason: "a trials.csv of version 1 has no columns for an encoded stimulus".into(),
            });
        }
        Some(e) => {
            for (column, v) in [("achieved_cr", e.achieved_cr), ("rms_cm", e.rms_cm)] {
                if !v.is_finite() {
                    return Err(ResultsError::Unwritable {
                        column,
                        reason: format!("{v} is not finite"),
                    });
                }
            }
            (
                format_codec_params(&e.codec_params).map_err(|reason| {
                    ResultsError::Unwritable {
                        column: "codec_params",
                        reason,
                    }
                })?,
                e.achieved_cr.to_string(),
                e.rms_cm.to_string(),
            )
        }
    })
}

/// Columns 33-34 of `r` (empty without frame timing).
fn timing_fields(r: &TrialRecord, version: u32) -> Result<(String, String), ResultsError> {
    Ok(match &r.timing {
        None => (String::new(), String::new()),
        Some(_) if version == 1 => {
            return Err(ResultsError::Unwritable {
                column: "frames_shown",
                reason: "a trials.csv of version 1 has no columns for frame timing".into(),
            });
        }
        Some(t) if !(t.interval_sd_ms.is_finite() && t.interval_sd_ms >= 0.0) => {
            return Err(ResultsError::Unwritable {
                column: "interval_sd_ms",
                reason: format!("{} is not a standard deviation", t.interval_sd_ms),
            });
        }
        Some(t) => (t.frames_shown.to_string(), t.interval_sd_ms.to_string()),
    })
}

/// Encodes one record as a CSV line of format `version` (1 or 2), ending in `\n`: a session
/// resumed into a version 1 file keeps its layout.
///
/// # Errors
/// [`ResultsError::Unwritable`] as [`encode_row`], for an unknown version, or for a record
/// with an encoding (version 1 has no columns for it).
pub fn encode_row_as(r: &TrialRecord, version: u32) -> Result<String, ResultsError> {
    if header_of(version).is_none() {
        return Err(ResultsError::Unwritable {
            column: "format_version",
            reason: format!("version {version} is not one this build writes"),
        });
    }
    let t = &r.trial;
    let o = &r.outcome;
    let (response, a, b) = match r.response.answer {
        Answer::Rating(v) => (v.to_string(), String::new(), String::new()),
        Answer::Pair { a, b } => (String::new(), a.to_string(), b.to_string()),
        Answer::Choice(p) => (p.to_string(), String::new(), String::new()),
    };
    let (params, cr, rms) = encoding_fields(r, version)?;
    let (frames_shown, interval_sd) = timing_fields(r, version)?;
    let fields: [String; 34] = [
        version.to_string(),
        r.study.clone(),
        r.subject.clone(),
        r.session.to_string(),
        t.index.to_string(),
        t.block.to_string(),
        r.protocol.to_string(),
        t.condition.clone(),
        t.stimulus.clone(),
        t.reference.clone(),
        t.arrangement.to_string(),
        t.reference_position.to_string(),
        flag(t.break_before),
        opt(t.staircase),
        opt(t.level),
        response,
        a,
        b,
        o.score.to_string(),
        opt(o.score_reference),
        opt(o.score_test),
        opt(o.correct.map(flag)),
        opt(o.reversal.map(flag)),
        r.response.response_time_ms.to_string(),
        r.response.replays.to_string(),
        r.response.dropped_frames.to_string(),
        r.elapsed_ms.to_string(),
        r.wall_clock_ms.to_string(),
        r.monotonic_ms.to_string(),
        params,
        cr,
        rms,
        frames_shown,
        interval_sd,
    ];
    let mut line = String::with_capacity(256);
    for (i, f) in fields.iter().take(column_count(version)).enumerate() {
        if i > 0 {
            line.push(',');
        }
        push_field(&mut line, f).map_err(|reason| ResultsError::Unwritable {
            column: COLUMNS[i],
            reason,
        })?;
    }
    line.push('\n');
    Ok(line)
}

/// Splits one CSV line into at most `max` fields, put in `fields` (emptied first; one vector
/// serves every row of a file); `Err((column, message))` with a 1-based column. Fields borrow
/// from `line` unless a doubled quote had to be undone.
fn split_line<'a>(
    line: &'a str,
    max: usize,
    fields: &mut Vec<Cow<'a, str>>,
) -> Result<(), (usize, String)> {
    fields.clear();
    let bytes = line.as_bytes();
    let mut start = 0;
    loop {
        let col = fields.len() + 1;
        if fields.len() == max {
            return Err((col, format!("more than {max} fields")));
        }
        let (field, next) = if bytes.get(start) == Some(&b'"') {
            quoted_field(line, start + 1).map_err(|m| (col, m.into()))?
        } else {
            let rest = &line[start..];
            let end = field_end(rest.as_bytes());
            if rest.as_bytes().get(end) == Some(&b'"') {
                return Err((col, "quote inside an unquoted field".into()));
            }
            (Cow::Borrowed(&rest[..end]), start + end)
        };
        fields.push(field);
        if next >= line.len() {
            return Ok(());
        }
        // `next` is at the comma that ends the field; a comma that ends the line leaves an
        // empty last field, which the next turn reads.
        start = next + 1;
    }
}

/// The index of the first `,` or `"` in `bytes` (its length when there is none), eight bytes
/// at a time: both are ASCII, so no UTF-8 sequence holds them, and a word test per eight
/// bytes is several times faster than a loop over bytes or chars.
fn field_end(bytes: &[u8]) -> usize {
    const ONES: u64 = u64::from_le_bytes([1; 8]);
    const HIGH: u64 = u64::from_le_bytes([0x80; 8]);
    // The high bit of each byte of `word` that equals `b` (and maybe of bytes after the
    // first such byte, never before it).
    let equal = |word: u64, b: u8| {
        let x = word ^ (ONES * u64::from(b));
        x.wrapping_sub(ONES) & !x & HIGH
    };
    let mut words = bytes.chunks_exact(8);
    for (k, chunk) in words.by_ref().enumerate() {
        let mut word = [0; 8];
        word.copy_from_slice(chunk);
        let word = u64::from_le_bytes(word);
        let found = equal(word, b',') | equal(word, b'"');
        if found != 0 {
            return 8 * k + found.trailing_zeros() as usize / 8;
        }
    }
    let tail = words.remainder();
    let done = bytes.len() - tail.len();
    done + tail
        .iter()
        .position(|&b| b == b',' || b == b'"')
        .unwrap_or(tail.len())
}

/// The quoted field whose text starts at byte `from` (just after its opening quote), and the
/// index just past its closing quote (the end of the line or a comma).
fn quoted_field(line: &str, from: usize) -> Result<(Cow<'_, str>, usize), &'static str> {
    let mut owned: Option<String> = None;
    let mut pos = from;
    loop {
        let Some(q) = line[pos..].find('"').map(|i| pos + i) else {
            return Err("unterminated quoted field");
        };
        if line.as_bytes().get(q + 1) == Some(&b'"') {
            owned
                .get_or_insert_with(String::new)
                .push_str(&line[pos..=q]);
            pos = q + 2;
            continue;
        }
        if !matches!(line.as_bytes().get(q + 1), None | Some(b',')) {
            return Err("text after a closing quote");
        }
        let field = match owned {
            Some(mut s) => {
                s.push_str(&line[pos..q]);
                Cow::Owned(s)
            }
            None => Cow::Borrowed(&line[from..q]),
        };
        return Ok((field, q + 1));
    }
}

struct Row<'a> {
    fields: &'a [Cow<'a, str>],
}

type FieldResult<T> = Result<T, (usize, String)>;

impl Row<'_> {
    fn text(&self, i: usize) -> &str {
        self.fields.get(i).map_or("", |f| f)
    }
    fn nonempty(&self, i: usize) -> FieldResult<&str> {
        let s = self.text(i);
        if s.is_empty() {
            Err((i + 1, format!("{} is empty", COLUMNS[i])))
        } else {
            Ok(s)
        }
    }
    fn parse<T: std::str::FromStr>(&self, i: usize) -> FieldResult<T> {
        let s = self.nonempty(i)?;
        s.parse().map_err(|_| {
            (
                i + 1,
                format!(
                    "{} {s:?} is not a valid {}",
                    COLUMNS[i],
                    std::any::type_name::<T>()
                ),
            )
        })
    }
    fn float(&self, i: usize) -> FieldResult<f64> {
        let v: f64 = self.parse(i)?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err((i + 1, format!("{} {v} is not finite", COLUMNS[i])))
        }
    }
    fn opt_float(&self, i: usize) -> FieldResult<Option<f64>> {
        if self.text(i).is_empty() {
            Ok(None)
        } else {
            self.float(i).map(Some)
        }
    }
    fn named<T: std::str::FromStr<Err = String>>(&self, i: usize) -> FieldResult<T> {
        let s = self.nonempty(i)?;
        s.parse()
            .map_err(|e| (i + 1, format!("{}: {e}", COLUMNS[i])))
    }
    fn flag(&self, i: usize) -> FieldResult<bool> {
        match self.text(i) {
            "1" => Ok(true),
            "0" => Ok(false),
            s => Err((i + 1, format!("{} must be 0 or 1, got {s:?}", COLUMNS[i]))),
        }
    }
    fn opt_flag(&self, i: usize) -> FieldResult<Option<bool>> {
        if self.text(i).is_empty() {
            Ok(None)
        } else {
            self.flag(i).map(Some)
        }
    }
    /// Columns 30-32: all empty (no encoding) or all set.
    fn encoding(&self) -> FieldResult<Option<StimulusEncoding>> {
        let (p, cr, rms) = (29, 30, 31);
        if [p, cr, rms].iter().all(|&i| self.text(i).is_empty()) {
            return Ok(None);
        }
        let codec_params = parse_codec_params(self.text(p))
            .map_err(|m| (p + 1, format!("{}: {m}", COLUMNS[p])))?;
        let achieved_cr = self.float(cr)?;
        if achieved_cr <= 0.0 {
            return Err((
                cr + 1,
                format!("{} {achieved_cr} must be positive", COLUMNS[cr]),
            ));
        }
        let rms_cm = self.float(rms)?;
        if rms_cm < 0.0 {
            return Err((
                rms + 1,
                format!("{} {rms_cm} must not be negative", COLUMNS[rms]),
            ));
        }
        Ok(Some(StimulusEncoding {
            codec_params,
            achieved_cr,
            rms_cm,
        }))
    }
    /// Columns 33-34: both empty (simulated) or both set.
    fn timing(&self) -> FieldResult<Option<FrameTiming>> {
        let (f, sd) = (32, 33);
        if self.text(f).is_empty() && self.text(sd).is_empty() {
            return Ok(None);
        }
        let frames_shown = self.parse(f)?;
        let interval_sd_ms = self.float(sd)?;
        if interval_sd_ms < 0.0 {
            return Err((
                sd + 1,
                format!("{} {interval_sd_ms} must not be negative", COLUMNS[sd]),
            ));
        }
        Ok(Some(FrameTiming {
            frames_shown,
            interval_sd_ms,
        }))
    }
    fn opt_u32(&self, i: usize) -> FieldResult<Option<u32>> {
        if self.text(i).is_empty() {
            Ok(None)
        } else {
            self.parse(i).map(Some)
        }
    }
}

/// Decodes one CSV line (without its line break) of a file of format `file_version`, its
/// fields split into `fields`; `Err((column, message))`.
fn decode_fields<'a>(
    line: &'a str,
    file_version: u32,
    fields: &mut Vec<Cow<'a, str>>,
) -> FieldResult<TrialRecord> {
    let n = column_count(file_version);
    split_line(line, n, fields)?;
    if fields.len() != n {
        return Err((
            fields.len().min(n),
            format!("{} fields, expected {n}", fields.len()),
        ));
    }
    let r = Row { fields };
    let version: u32 = r.parse(0)?;
    if version != file_version {
        return Err((
            1,
            format!("format_version {version} in a file whose header is version {file_version}"),
        ));
    }
    let encoding = if n > COLUMNS_V1 { r.encoding()? } else { None };
    let timing = if n > COLUMNS_V1 { r.timing()? } else { None };
    let protocol: Protocol = r.named(6)?;
    let arrangement: Arrangement = r.named(10)?;
    let reference_position: Position = r.named(11)?;
    if !reference_position.fits(arrangement) {
        return Err((
            12,
            format!(
                "reference_position {reference_position} does not fit arrangement {arrangement}"
            ),
        ));
    }
    let answer = match protocol {
        Protocol::Mos | Protocol::Acr | Protocol::Dcr | Protocol::Mushra => {
            Answer::Rating(r.float(15)?)
        }
        Protocol::Dscqs => Answer::Pair {
            a: r.float(16)?,
            b: r.float(17)?,
        },
        Protocol::Staircase | Protocol::PairComparison => Answer::Choice(r.named(15)?),
    };
    let trial = Trial {
        index: r.parse(4)?,
        block: r.named::<Block>(5)?,
        condition: r.text(7).to_string(),
        stimulus: r.nonempty(8)?.to_string(),
        reference: r.nonempty(9)?.to_string(),
        arrangement,
        reference_position,
        staircase: r.opt_u32(13)?,
        level: r.opt_float(14)?,
        break_before: r.flag(12)?,
    };
    Ok(TrialRecord {
        study: r.text(1).to_string(),
        subject: r.nonempty(2)?.to_string(),
        session: r.parse(3)?,
        protocol,
        trial,
        response: Response {
            answer,
            response_time_ms: r.parse(23)?,
            replays: r.parse(24)?,
            dropped_frames: r.parse(25)?,
        },
        outcome: Outcome {
            score: r.float(18)?,
            score_reference: r.opt_float(19)?,
            score_test: r.opt_float(20)?,
            correct: r.opt_flag(21)?,
            reversal: r.opt_flag(22)?,
        },
        elapsed_ms: r.parse(26)?,
        wall_clock_ms: r.parse(27)?,
        monotonic_ms: r.parse(28)?,
        encoding,
        timing,
    })
}

/// A last row cut short (power cut mid-write): kept aside, never silently dropped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TornRow {
    /// 1-based line number of the torn row.
    pub line: usize,
    /// Byte offset where it starts.
    pub offset: u64,
    /// Its bytes.
    pub bytes: Vec<u8>,
}

/// A parsed `trials.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialsFile {
    /// Format version named by the header (rows appended on resume keep it).
    pub format_version: u32,
    /// Complete rows, in file order.
    pub records: Vec<TrialRecord>,
    /// Byte length of the complete part (header and complete rows).
    pub complete_bytes: u64,
    /// A torn last row, if any.
    pub torn: Option<TornRow>,
}

/// Parses the bytes of a `trials.csv` (named `path` in errors).
///
/// The last line counts as torn when it lacks its line break or holds NUL bytes (what a
/// power cut leaves); any other bad row is an error naming line and column.
///
/// # Errors
/// [`ResultsError::Malformed`] with file, line and column.
pub fn parse_trials(bytes: &[u8], path: &Path) -> Result<TrialsFile, ResultsError> {
    let bad = |line: usize, column: usize, message: String| ResultsError::Malformed {
        path: path.to_path_buf(),
        line,
        column,
        message,
    };
    let mut records = Vec::new();
    let mut fields = Vec::with_capacity(COLUMNS.len());
    let mut offset = 0_usize;
    let mut line_no = 0_usize;
    let mut torn = None;
    let mut version = TRIALS_FORMAT_VERSION;
    // A file that is UTF-8 as a whole (any but a damaged one) is cut at its line ends by the
    // string search, which is several times faster than a byte loop, and each line needs no
    // check of its own.
    let whole = std::str::from_utf8(bytes).ok();
    while offset < bytes.len() {
        line_no += 1;
        let rest = &bytes[offset..];
        let line_end = match whole {
            Some(text) => text[offset..].find('\n'),
            None => rest.iter().position(|&b| b == b'\n'),
        };
        let (raw, complete) = match line_end {
            Some(n) => (&rest[..n], true),
            None => (rest, false),
        };
        let is_last = !complete || offset + raw.len() + 1 == bytes.len();
        if !complete || (is_last && raw.contains(&0)) {
            if line_no == 1 {
                return Err(bad(1, 1, "header line is incomplete".into()));
            }
            torn = Some(TornRow {
                line: line_no,
                offset: offset as u64,
                bytes: rest.to_vec(),
            });
            break;
        }
        if raw.len() > MAX_ROW_BYTES {
            return Err(bad(
                line_no,
                1,
                format!(
                    "row of {} bytes is over the {MAX_ROW_BYTES}-byte limit",
                    raw.len()
                ),
            ));
        }
        let text = match whole {
            Some(text) => Ok(&text[offset..offset + raw.len()]),
            None => std::str::from_utf8(raw),
        }
        .map_err(|e| {
            let col = std::str::from_utf8(&raw[..e.valid_up_to()])
                .map_or(1, |s| s.matches(',').count() + 1);
            bad(
                line_no,
                col,
                format!("invalid UTF-8 at byte {}", e.valid_up_to()),
            )
        })?;
        let text = text.strip_suffix('\r').unwrap_or(text);
        if line_no == 1 {
            if text == HEADER {
                version = TRIALS_FORMAT_VERSION;
            } else if text == HEADER_V1 {
                version = 1;
            } else {
                let col = text
                    .split(',')
                    .zip(COLUMNS)
                    .position(|(a, b)| a != b)
                    .map_or(COLUMNS_V1 + 1, |i| i + 1);
                return Err(bad(
                    1,
                    col,
                    format!(
                        "header is not a trials.csv header (versions {OLDEST_TRIALS_FORMAT_VERSION} to {TRIALS_FORMAT_VERSION})"
                    ),
                ));
            }
        } else {
            let rec = decode_fields(text, version, &mut fields)
                .map_err(|(col, msg)| bad(line_no, col, msg))?;
            records.push(rec);
        }
        offset += raw.len() + 1;
    }
    if line_no == 0 {
        return Err(bad(1, 1, "file is empty (no header)".into()));
    }
    let complete_bytes = torn.as_ref().map_or(bytes.len() as u64, |t| t.offset);
    Ok(TrialsFile {
        format_version: version,
        records,
        complete_bytes,
        torn,
    })
}

/// Reads and parses a `trials.csv`.
///
/// # Errors
/// [`ResultsError::Io`], [`ResultsError::TooLarge`] or [`ResultsError::Malformed`].
pub fn read_trials(path: &Path) -> Result<TrialsFile, ResultsError> {
    let bytes = crate::store::read_limited(path, MAX_TRIALS_BYTES)?;
    parse_trials(&bytes, path)
}

/// The path of a set-aside torn row: `trials.csv.torn-<n>` with the first unused `n`.
pub fn torn_path(trials: &Path) -> PathBuf {
    let mut n = 1;
    loop {
        let p = trials.with_file_name(format!("trials.csv.torn-{n}"));
        if !p.exists() {
            return p;
        }
        n += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::split_line;

    fn split(line: &str, max: usize) -> Result<Vec<String>, (usize, String)> {
        let mut fields = Vec::new();
        split_line(line, max, &mut fields).map(|()| {
            fields
                .into_iter()
                .map(std::borrow::Cow::into_owned)
                .collect()
        })
    }

    #[test]
    fn splits_plain_quoted_and_empty_fields() {
        assert_eq!(split("", 3).unwrap(), [""]);
        assert_eq!(split("a,,b", 3).unwrap(), ["a", "", "b"]);
        assert_eq!(split("a,", 3).unwrap(), ["a", ""]);
        assert_eq!(split(",", 3).unwrap(), ["", ""]);
        assert_eq!(
            split(r#""x, ""y""",z,"""""#, 3).unwrap(),
            [r#"x, "y""#, "z", "\""]
        );
        assert_eq!(split(r#""",a"#, 3).unwrap(), ["", "a"]);
        assert_eq!(split("é,ü", 2).unwrap(), ["é", "ü"]);
    }

    /// The word test finds the first comma or quote at every place in a word and across
    /// words, bytes above 0x80 (UTF-8) and bytes just below and above the two included.
    #[test]
    fn field_end_finds_the_first_comma_or_quote() {
        let filler = [
            b'a', b'+', b'-', b'!', b'#', 0xC3, 0xA9, 0x80, 0xFF, 0x00, 0x2B, 0x21,
        ];
        for len in 0..40 {
            for at in 0..=len {
                for mark in [b',', b'"'] {
                    let mut bytes: Vec<u8> = (0..len)
                        .map(|i| filler[(i * 7 + len) % filler.len()])
                        .collect();
                    if at < len {
                        bytes[at] = mark;
                        // A second mark later must not be the one found.
                        if at + 3 < len {
                            bytes[at + 3] = b',';
                        }
                    }
                    let want = bytes
                        .iter()
                        .position(|&b| b == b',' || b == b'"')
                        .unwrap_or(len);
                    assert_eq!(super::field_end(&bytes), want, "{bytes:?}");
                }
            }
        }
    }

    #[test]
    fn refuses_bad_quotes_and_extra_fields_naming_the_column() {
        assert_eq!(split("a,b,c", 2).unwrap_err().0, 3);
        assert_eq!(split("a,b,", 2).unwrap_err().0, 3);
        let (col, msg) = split(r#"a,b"c"#, 3).unwrap_err();
        assert_eq!((col, msg.as_str()), (2, "quote inside an unquoted field"));
        let (col, msg) = split(r#"a,"b"c"#, 3).unwrap_err();
        assert_eq!((col, msg.as_str()), (2, "text after a closing quote"));
        let (col, msg) = split(r#"a,"b,c"#, 3).unwrap_err();
        assert_eq!((col, msg.as_str()), (2, "unterminated quoted field"));
    }
}
