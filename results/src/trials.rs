//! `trials.csv` format versions 1 and 2: one row per trial, written and read here.
//!
//! Plain RFC 4180 CSV with a fixed header ([`HEADER`]), written and read with the `csv` crate;
//! the first column repeats the format version on every row so a row taken out of its file
//! still says how to read it. Fields that contain a comma or a quote are quoted (rows written
//! before the csv crate also quoted a field that starts or ends with a space; both read the
//! same); line breaks inside fields are refused, so every row is exactly one line
//! and a row cut short by a power failure is the last line without its `\n`. A stray quote is
//! refused on reading, naming its column.
//! Version 2 appends three optional columns for stimuli the runner encodes on the fly (live
//! staircase): `codec_params`, `achieved_cr`, `rms_cm`. Version 1 files still read, and a
//! session resumed into a version 1 file keeps appending version 1 rows. Documented in
//! `docs/results-format.md`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use protocols::methods::AnswerKind;
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

/// Refuses a line break in a field: every row stays one line, so a row cut short by a power
/// failure is the last line without its `\n`.
fn check_field(v: &str) -> Result<(), String> {
    if v.contains(['\n', '\r']) {
        return Err(format!("field {v:?} contains a line break"));
    }
    Ok(())
}

/// A CSV writer into memory with lines ending in `\n` alone.
fn csv_writer(style: csv::QuoteStyle) -> csv::Writer<Vec<u8>> {
    csv::WriterBuilder::new()
        .quote_style(style)
        .terminator(csv::Terminator::Any(b'\n'))
        .buffer_capacity(1024)
        .from_writer(Vec::with_capacity(256))
}

/// The bytes a CSV writer holds, its records written.
fn written(w: csv::Writer<Vec<u8>>) -> Result<Vec<u8>, String> {
    w.into_inner().map_err(|e| e.error().to_string())
}

/// One row of `fields` (free of line breaks) with its `\n`, written by the csv crate: a field
/// with a comma or a quote is quoted, a quote in it doubled (`QuoteStyle::Necessary`).
fn write_row<S: AsRef<str>>(fields: &[S]) -> Result<String, String> {
    let mut w = csv_writer(csv::QuoteStyle::Necessary);
    w.write_record(fields.iter().map(AsRef::as_ref))
        .map_err(|e| e.to_string())?;
    String::from_utf8(written(w)?).map_err(|e| e.to_string())
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
    let fields = &fields[..column_count(version)];
    for (i, f) in fields.iter().enumerate() {
        check_field(f).map_err(|reason| ResultsError::Unwritable {
            column: COLUMNS[i],
            reason,
        })?;
    }
    write_row(fields).map_err(|reason| ResultsError::Unwritable {
        column: "row",
        reason,
    })
}

/// A row's fields, read by the csv crate.
struct Row<'a> {
    fields: &'a csv::StringRecord,
}

type FieldResult<T> = Result<T, (usize, String)>;

impl Row<'_> {
    fn text(&self, i: usize) -> &str {
        self.fields.get(i).unwrap_or("")
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

/// Checks the quotes of a row that holds one, in field order, up to field `max`: the csv
/// crate reads a stray quote as text (`a"b`, `"a"b`), where this format refuses it, naming the
/// field; `Err((column, message))`. A row that passes reads as RFC 4180 says.
fn check_quotes(line: &[u8], max: usize) -> FieldResult<()> {
    let mut at = 0;
    let mut col = 1;
    loop {
        if col > max {
            return Err((col, format!("more than {max} fields")));
        }
        if line.get(at) == Some(&b'"') {
            // A quoted field: quotes doubled inside, then a comma or the end of the line.
            at += 1;
            loop {
                let Some(q) = line[at..].iter().position(|&b| b == b'"') else {
                    return Err((col, "unterminated quoted field".into()));
                };
                at += q + 1;
                if line.get(at) != Some(&b'"') {
                    break;
                }
                at += 1;
            }
            match line.get(at) {
                None => return Ok(()),
                Some(b',') => at += 1,
                Some(_) => return Err((col, "text after a closing quote".into())),
            }
        } else {
            match line[at..].iter().position(|&b| b == b',' || b == b'"') {
                None => return Ok(()),
                Some(k) if line[at + k] == b',' => at += k + 1,
                Some(_) => return Err((col, "quote inside an unquoted field".into())),
            }
        }
        col += 1;
    }
}

/// Reads the row `line` (without its line end; `cr`: that was `\r\n`) from `reader`, which
/// stands at its start, into `fields`; `max` fields are expected. `Err((column, message))`.
///
/// The reader takes only `\n` as a line end, so that a `\r` inside a field is text as in
/// any other place; a row's fields never hold a line break (the writer refuses them), so the
/// row read is exactly `line` once its quotes are checked.
fn read_fields(
    reader: &mut csv::Reader<&[u8]>,
    line: &str,
    cr: bool,
    max: usize,
    fields: &mut csv::StringRecord,
) -> FieldResult<()> {
    if line.as_bytes().contains(&b'"') {
        check_quotes(line.as_bytes(), max)?;
    }
    // The reader skips an empty line; here it is a row of one empty field.
    if line.is_empty() {
        return Err((1, format!("1 fields, expected {max}")));
    }
    match reader.read_record(fields) {
        Ok(true) => {}
        Ok(false) => return Err((1, "the CSV reader found no row here".into())),
        Err(e) => return Err((1, e.to_string())),
    }
    if cr && let Some(last) = fields.iter().next_back() {
        // The last field ends with the `\r` that is no part of it.
        let last = last.strip_suffix('\r').unwrap_or(last).to_string();
        fields.truncate(fields.len() - 1);
        fields.push_field(&last);
    }
    let n = fields.len();
    if n > max {
        return Err((max + 1, format!("more than {max} fields")));
    }
    if n < max {
        return Err((n, format!("{n} fields, expected {max}")));
    }
    Ok(())
}

/// Decodes one row of a file of format `file_version`, its fields read; `Err((column,
/// message))`.
fn decode_fields(fields: &csv::StringRecord, file_version: u32) -> FieldResult<TrialRecord> {
    let n = column_count(file_version);
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
    let answer = match protocols::methods::of(protocol).answer_kind() {
        AnswerKind::Rating => Answer::Rating(r.float(15)?),
        AnswerKind::RatingPair => Answer::Pair {
            a: r.float(16)?,
            b: r.float(17)?,
        },
        AnswerKind::Choice => Answer::Choice(r.named(15)?),
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

/// The format version whose header `text` is; `Err((column, message))` naming the first
/// column that differs.
fn header_version(text: &str) -> FieldResult<u32> {
    if text == HEADER {
        Ok(TRIALS_FORMAT_VERSION)
    } else if text == HEADER_V1 {
        Ok(1)
    } else {
        let col = text
            .split(',')
            .zip(COLUMNS)
            .position(|(a, b)| a != b)
            .map_or(COLUMNS_V1 + 1, |i| i + 1);
        Err((
            col,
            format!(
                "header is not a trials.csv header (versions {OLDEST_TRIALS_FORMAT_VERSION} to {TRIALS_FORMAT_VERSION})"
            ),
        ))
    }
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
    // One reader over the file, a row read each time the loop below has checked its line
    // (a check that fails ends the read, so the two never part), and one record for all.
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .terminator(csv::Terminator::Any(b'\n'))
        .from_reader(bytes);
    let mut fields = csv::StringRecord::with_capacity(256, COLUMNS.len());
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
        let (text, cr) = match text.strip_suffix('\r') {
            Some(t) => (t, true),
            None => (text, false),
        };
        if line_no == 1 {
            version = header_version(text).map_err(|(col, msg)| bad(1, col, msg))?;
            // The reader passes the header by.
            read_fields(&mut reader, text, cr, column_count(version), &mut fields)
                .map_err(|(col, msg)| bad(1, col, msg))?;
        } else {
            let rec = read_fields(&mut reader, text, cr, column_count(version), &mut fields)
                .and_then(|()| decode_fields(&fields, version))
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
    use std::path::Path;

    use protocols::{
        Answer, Arrangement, Block, FrameTiming, Outcome, Position, Protocol, Response, Trial,
        TrialRecord,
    };

    use super::{HEADER, HEADER_V1, TrialsFile, encode_row, encode_row_as, parse_trials};
    use crate::ResultsError;

    /// A MOS row whose text columns hold placeholders (`STUDYX`, `SUBJX`, `CONDX`, `STIMX`,
    /// `REFX`) that a test swaps for the text it needs, raw or quoted.
    fn sample() -> TrialRecord {
        TrialRecord {
            study: "STUDYX".into(),
            subject: "SUBJX".into(),
            session: 1,
            protocol: Protocol::Mos,
            trial: Trial {
                index: 3,
                block: Block::Test,
                condition: "CONDX".into(),
                stimulus: "STIMX".into(),
                reference: "REFX".into(),
                arrangement: Arrangement::SideBySide,
                reference_position: Position::Left,
                staircase: None,
                level: None,
                break_before: false,
            },
            response: Response {
                answer: Answer::Rating(4.5),
                response_time_ms: 1200,
                replays: 0,
                dropped_frames: 0,
            },
            outcome: Outcome {
                score: 4.5,
                score_reference: None,
                score_test: None,
                correct: None,
                reversal: None,
            },
            elapsed_ms: 5000,
            wall_clock_ms: 1_795_000_000_000,
            monotonic_ms: 4999,
            encoding: None,
            timing: None,
        }
    }

    /// The sample row (without its `\n`) with `STUDYX` replaced by `raw`, as it would stand
    /// in the file.
    fn row_with_study(raw: &str) -> String {
        let line = encode_row(&sample()).unwrap();
        line.trim_end_matches('\n').replacen("STUDYX", raw, 1)
    }

    fn parse(text: &str) -> Result<TrialsFile, ResultsError> {
        parse_trials(text.as_bytes(), Path::new("s/trials.csv"))
    }

    /// The records of a file holding the header and `rows` (each without its `\n`).
    fn parse_rows(rows: &[&str]) -> Vec<TrialRecord> {
        let mut text = format!("{HEADER}\n");
        for r in rows {
            text.push_str(r);
            text.push('\n');
        }
        parse(&text).unwrap_or_else(|e| panic!("{e}")).records
    }

    /// `(line, column, message)` of the error a file of the header and `rows` gives.
    fn error_of(rows: &[&str]) -> (usize, usize, String) {
        let mut text = format!("{HEADER}\n");
        for r in rows {
            text.push_str(r);
            text.push('\n');
        }
        match parse(&text) {
            Err(ResultsError::Malformed {
                path,
                line,
                column,
                message,
            }) => {
                assert_eq!(path, Path::new("s/trials.csv"));
                (line, column, message)
            }
            other => panic!("{other:?}"),
        }
    }

    /// RFC 4180's quoting, written out independently of the csv crate: a field with a comma
    /// or a quote is quoted, its quotes doubled.
    fn quoted(v: &str) -> String {
        if v.contains([',', '"']) {
            format!("\"{}\"", v.replace('"', "\"\""))
        } else {
            v.to_string()
        }
    }

    /// Every text column, alone and together, written with the format's quoting rule (the
    /// same bytes as ever) and read back unchanged, version 2 and version 1.
    #[test]
    fn rows_are_written_with_the_formats_quoting_and_read_back() {
        let texts = [
            "a", "", " a", "a ", " ", "a b", "a,b", "a\"b", "\"", "\"\"", ",", " a,b ", "x, \"y\"",
            "é ü,ß", "a\tb", "k=1;q=2", "'a'",
        ];
        let plain = encode_row(&sample()).unwrap();
        let plain_v1 = encode_row_as(&sample(), 1).unwrap();
        for (k, &t) in texts.iter().enumerate() {
            // The same text in study, then four different ones at once (a spaced field
            // beside others that need quotes or none).
            let others = [texts[(k + 3) % texts.len()], texts[(k + 7) % texts.len()]];
            let mut r = sample();
            r.study = t.into();
            r.subject = format!("S{}", others[0]);
            r.trial.condition = others[1].into();
            r.trial.stimulus = format!("{t}/x");
            r.trial.reference = "walk".into();
            for (version, plain) in [(2, &plain), (1, &plain_v1)] {
                let want = plain
                    .replacen("STUDYX", &quoted(&r.study), 1)
                    .replacen("SUBJX", &quoted(&r.subject), 1)
                    .replacen("CONDX", &quoted(&r.trial.condition), 1)
                    .replacen("STIMX", &quoted(&r.trial.stimulus), 1)
                    .replacen("REFX", "walk", 1);
                let line = encode_row_as(&r, version).unwrap();
                assert_eq!(line, want, "{t:?}");
                let header = if version == 1 { HEADER_V1 } else { HEADER };
                let file = parse(&format!("{header}\n{line}")).unwrap();
                assert_eq!(file.format_version, version);
                assert_eq!(file.records, [r.clone()], "{t:?}");
            }
        }
    }

    #[test]
    fn a_line_break_in_a_field_is_refused_naming_its_column() {
        for (text, column) in [("a\nb", "study"), ("\r", "condition")] {
            let mut r = sample();
            if column == "study" {
                r.study = text.into();
            } else {
                r.trial.condition = text.into();
            }
            match encode_row(&r) {
                Err(ResultsError::Unwritable { column: c, reason }) => {
                    assert_eq!(c, column);
                    assert!(reason.contains("line break"), "{reason}");
                }
                other => panic!("{other:?}"),
            }
        }
    }

    /// Quoted fields lose their quotes and their doubled quotes; empty fields, quoted or
    /// not, are empty; text beyond ASCII is kept.
    #[test]
    fn reads_plain_quoted_and_empty_fields() {
        let row = encode_row(&sample()).unwrap();
        let row = row.trim_end_matches('\n');
        let cases = [
            (r#""x, ""y""""#, r#"x, "y""#),
            (r#""""""#, "\""),
            (r#""""#, ""),
            (r#""a""#, "a"),
            ("é", "é"),
            ("", ""),
            // A field with spaces at its ends, quoted (as rows were once written) or not.
            (r#"" a ""#, " a "),
            (" a ", " a "),
        ];
        for (raw, want) in cases {
            let line = row
                .replacen("STUDYX", raw, 1)
                .replacen("CONDX", raw, 1)
                .replacen("SUBJX", "ü", 1);
            let records = parse_rows(&[&line]);
            assert_eq!(records[0].study, want, "{raw}");
            assert_eq!(records[0].trial.condition, want, "{raw}");
            assert_eq!(records[0].subject, "ü");
        }
        // An empty last field (no frame timing), and the same quoted.
        assert!(row.ends_with(','), "{row}");
        assert_eq!(
            parse_rows(&[row, &format!("{row}\"\"")]),
            [sample(), sample()]
        );
    }

    /// A comma or a quote at every place of a field, beside text of one to three bytes a
    /// character, is found: the row reads back as written, and a stray quote in an unquoted
    /// field is refused at its column.
    #[test]
    fn a_comma_or_quote_anywhere_in_a_field_is_found() {
        let filler = ['a', '+', '-', 'é', '€', '#', '\t', '\u{7f}', 'ÿ'];
        for len in 0..20 {
            for at in 0..=len {
                for mark in [',', '"'] {
                    let mut chars: Vec<char> = (0..len)
                        .map(|i| filler[(i * 7 + len) % filler.len()])
                        .collect();
                    if at < len {
                        chars[at] = mark;
                        if at + 3 < len {
                            chars[at + 3] = ',';
                        }
                    }
                    let text: String = chars.iter().collect();
                    let mut r = sample();
                    r.study.clone_from(&text);
                    let file = parse(&format!("{HEADER}\n{}", encode_row(&r).unwrap())).unwrap();
                    assert_eq!(file.records, [r], "{text:?}");
                    if at > 0 && at < len && mark == '"' && !text.contains(',') {
                        // Written as it is, unquoted (not at its start, which opens a quoted
                        // field): the quote is refused.
                        let (line, col, msg) = error_of(&[&row_with_study(&text)]);
                        assert_eq!(
                            (line, col, msg.as_str()),
                            (2, 2, "quote inside an unquoted field")
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn refuses_bad_quotes_and_extra_or_missing_fields_naming_the_column() {
        let row = encode_row(&sample()).unwrap();
        let row = row.trim_end_matches('\n');
        let cases: [(String, usize, &str); 10] = [
            (format!("{row},x"), 35, "more than 34 fields"),
            (format!("{row},"), 35, "more than 34 fields"),
            (format!("{row},\"x\""), 35, "more than 34 fields"),
            // The quotes of a field past the last are not looked at.
            (format!("{row},x\"y"), 35, "more than 34 fields"),
            (row_with_study("a\"b"), 2, "quote inside an unquoted field"),
            (row_with_study("\"b\"c"), 2, "text after a closing quote"),
            (row_with_study("\"b,c"), 2, "unterminated quoted field"),
            (row_with_study("\"b\"\""), 2, "unterminated quoted field"),
            (
                row[..row.len() - 1].to_string(),
                33,
                "33 fields, expected 34",
            ),
            (String::new(), 1, "1 fields, expected 34"),
        ];
        for (line, col, msg) in cases {
            assert_eq!(error_of(&[row, &line]), (3, col, msg.to_string()), "{line}");
        }
        // A row of version 2 in a version 1 file has too many fields.
        let text = format!("{HEADER_V1}\n{row}\n");
        match parse(&text) {
            Err(ResultsError::Malformed {
                line: 2,
                column: 30,
                message,
                ..
            }) => assert_eq!(message, "more than 29 fields"),
            other => panic!("{other:?}"),
        }
    }

    /// Lines that end in `\r\n` read as those ending in `\n`; a `\r` inside a line is text.
    #[test]
    fn crlf_line_ends_and_a_carriage_return_inside_a_field() {
        let row = encode_row(&sample()).unwrap();
        let row = row.trim_end_matches('\n');
        let lf = parse(&format!("{HEADER}\n{row}\n{row}\n")).unwrap();
        let crlf = parse(&format!("{HEADER}\r\n{row}\r\n{row}\r\n")).unwrap();
        assert_eq!(lf.records, crlf.records);
        assert_eq!(crlf.records.len(), 2);
        let quoted_cr = row_with_study("\"a\r\"");
        let records = parse_rows(&[&row_with_study("a\rb"), &quoted_cr]);
        assert_eq!(records[0].study, "a\rb");
        assert_eq!(records[1].study, "a\r");
        // The last field (frame timing's interval_sd_ms) ends before a `\r\n`, quoted or
        // not; a `\r` inside its quotes is its own.
        let mut timed = sample();
        timed.timing = Some(FrameTiming {
            frames_shown: 120,
            interval_sd_ms: 0.25,
        });
        let row = encode_row(&timed).unwrap();
        let row = row.trim_end_matches('\n');
        assert!(row.ends_with(",120,0.25"), "{row}");
        let quoted = row.replace(",0.25", ",\"0.25\"");
        let text = format!("{HEADER}\r\n{row}\r\n{quoted}\r\n{row}\n");
        assert_eq!(
            parse(&text).unwrap().records,
            [timed.clone(), timed.clone(), timed]
        );
        let cr_inside = row.replace(",0.25", ",\"0.25\r\"");
        let (line, col, msg) = error_of(&[&cr_inside]);
        assert_eq!((line, col), (2, 34));
        assert!(msg.contains("interval_sd_ms \"0.25\\r\""), "{msg}");
    }

    /// A last line without its `\n`, or holding NUL bytes, is torn: kept aside with its line
    /// and offset, and the rows before it read.
    #[test]
    fn a_torn_last_row_is_kept_aside() {
        let row = encode_row(&sample()).unwrap();
        let head = format!("{HEADER}\n{row}");
        for (tail, torn) in [
            (&row[..40], &row[..40]),
            ("2,\"a,b", "2,\"a,b"),
            ("\0\0\0\n", "\0\0\0\n"),
            ("", ""),
        ] {
            let text = format!("{head}{tail}");
            let f = parse(&text).unwrap();
            assert_eq!(f.records.len(), 1);
            assert_eq!(f.complete_bytes, head.len() as u64);
            match &f.torn {
                None => assert!(torn.is_empty()),
                Some(t) => {
                    assert_eq!(t.line, 3);
                    assert_eq!(t.offset, head.len() as u64);
                    assert_eq!(t.bytes, torn.as_bytes());
                }
            }
        }
        match parse(&HEADER[..20]) {
            Err(ResultsError::Malformed {
                line: 1,
                column: 1,
                message,
                ..
            }) => assert_eq!(message, "header line is incomplete"),
            other => panic!("{other:?}"),
        }
    }
}
