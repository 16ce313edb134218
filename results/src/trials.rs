//! `trials.csv` format version 1: one row per trial, written and read here.
//!
//! Plain RFC 4180 CSV with a fixed header ([`HEADER`]); the first column repeats the format
//! version on every row so a row taken out of its file still says how to read it. Fields that
//! contain a comma or a quote are quoted; line breaks inside fields are refused, so every row is
//! exactly one line and a row cut short by a power failure is the last line without its `\n`.
//! Documented in `docs/results-format.md`.

use std::path::{Path, PathBuf};

use protocols::{
    Answer, Arrangement, Block, Outcome, Position, Protocol, Response, Trial, TrialRecord,
};

use crate::ResultsError;

/// Version of the `trials.csv` format written by this build.
pub const TRIALS_FORMAT_VERSION: u32 = 1;

/// Column names, in order.
pub const COLUMNS: [&str; 29] = [
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
];

/// The header line, without its line break.
pub const HEADER: &str = "format_version,study,subject,session,trial_index,block,protocol,condition,stimulus,reference,\
arrangement,reference_position,break_before,staircase,level,response,response_a,response_b,score,score_reference,\
score_test,correct,reversal,response_time_ms,replays,dropped_frames,elapsed_ms,wall_clock_ms,monotonic_ms";

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

/// Encodes one record as a CSV line ending in `\n`.
///
/// # Errors
/// [`ResultsError::Unwritable`] when a text field contains a line break.
pub fn encode_row(r: &TrialRecord) -> Result<String, ResultsError> {
    let t = &r.trial;
    let o = &r.outcome;
    let (response, a, b) = match r.response.answer {
        Answer::Rating(v) => (v.to_string(), String::new(), String::new()),
        Answer::Pair { a, b } => (String::new(), a.to_string(), b.to_string()),
        Answer::Choice(p) => (p.to_string(), String::new(), String::new()),
    };
    let fields: [String; 29] = [
        TRIALS_FORMAT_VERSION.to_string(),
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
    ];
    let mut line = String::with_capacity(256);
    for (i, f) in fields.iter().enumerate() {
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

/// Splits one CSV line into fields; `Err((column, message))` with a 1-based column.
fn split_line(line: &str) -> Result<Vec<String>, (usize, String)> {
    let mut fields = Vec::with_capacity(COLUMNS.len());
    let mut cur = String::new();
    let mut chars = line.chars().peekable();
    let mut quoted = false;
    let mut at_start = true;
    loop {
        let col = fields.len() + 1;
        match chars.next() {
            None => {
                if quoted {
                    return Err((col, "unterminated quoted field".into()));
                }
                fields.push(std::mem::take(&mut cur));
                return Ok(fields);
            }
            Some('"') if at_start && !quoted => {
                quoted = true;
                at_start = false;
            }
            Some('"') if quoted => {
                if chars.peek() == Some(&'"') {
                    chars.next();
                    cur.push('"');
                } else {
                    quoted = false;
                    if !matches!(chars.peek(), None | Some(',')) {
                        return Err((col, "text after a closing quote".into()));
                    }
                }
            }
            Some('"') => return Err((col, "quote inside an unquoted field".into())),
            Some(',') if !quoted => {
                fields.push(std::mem::take(&mut cur));
                at_start = true;
                if fields.len() > COLUMNS.len() {
                    return Err((fields.len(), format!("more than {} fields", COLUMNS.len())));
                }
            }
            Some(c) => {
                cur.push(c);
                at_start = false;
            }
        }
    }
}

struct Row<'a> {
    fields: &'a [String],
}

type FieldResult<T> = Result<T, (usize, String)>;

impl Row<'_> {
    fn text(&self, i: usize) -> &str {
        self.fields.get(i).map_or("", String::as_str)
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
    fn opt_u32(&self, i: usize) -> FieldResult<Option<u32>> {
        if self.text(i).is_empty() {
            Ok(None)
        } else {
            self.parse(i).map(Some)
        }
    }
}

/// Decodes one CSV line (without its line break); `Err((column, message))`.
fn decode_fields(line: &str) -> FieldResult<TrialRecord> {
    let fields = split_line(line)?;
    if fields.len() != COLUMNS.len() {
        return Err((
            fields.len().min(COLUMNS.len()),
            format!("{} fields, expected {}", fields.len(), COLUMNS.len()),
        ));
    }
    let r = Row { fields: &fields };
    let version: u32 = r.parse(0)?;
    if version != TRIALS_FORMAT_VERSION {
        return Err((
            1,
            format!(
                "format_version {version} is not supported (this build reads {TRIALS_FORMAT_VERSION})"
            ),
        ));
    }
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
        Protocol::Mos => Answer::Rating(r.float(15)?),
        Protocol::Dscqs => Answer::Pair {
            a: r.float(16)?,
            b: r.float(17)?,
        },
        Protocol::Staircase => Answer::Choice(r.named(15)?),
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
    let mut offset = 0_usize;
    let mut line_no = 0_usize;
    let mut torn = None;
    while offset < bytes.len() {
        line_no += 1;
        let rest = &bytes[offset..];
        let (raw, complete) = match rest.iter().position(|&b| b == b'\n') {
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
        let text = std::str::from_utf8(raw).map_err(|e| {
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
            if text != HEADER {
                let col = text
                    .split(',')
                    .zip(COLUMNS)
                    .position(|(a, b)| a != b)
                    .map_or(1, |i| i + 1);
                return Err(bad(
                    1,
                    col,
                    format!("header is not the trials.csv v{TRIALS_FORMAT_VERSION} header"),
                ));
            }
        } else {
            let rec = decode_fields(text).map_err(|(col, msg)| bad(line_no, col, msg))?;
            records.push(rec);
        }
        offset += raw.len() + 1;
    }
    if line_no == 0 {
        return Err(bad(1, 1, "file is empty (no header)".into()));
    }
    let complete_bytes = torn.as_ref().map_or(bytes.len() as u64, |t| t.offset);
    Ok(TrialsFile {
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
