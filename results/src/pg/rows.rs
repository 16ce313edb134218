//! Trial records as rows of `study_trials`: one column per `trials.csv` column (the answer
//! split by kind: `response` a MOS rating, `response_a`/`response_b` a DSCQS pair, `choice` a
//! 2AFC answer), every value a query parameter.

use std::path::Path;

use postgres::types::ToSql;
use protocols::methods::AnswerKind;
use protocols::{
    Answer, Block, FrameTiming, Outcome, Protocol, Response, StimulusEncoding, Trial, TrialRecord,
};

use crate::ResultsError;
use crate::trials::{format_codec_params, parse_codec_params};

/// The columns after `session_id, row_number`, in the order of [`Values`] and of
/// [`SELECT_COLUMNS`].
pub const COLUMNS: &str = "study, subject, session, trial_index, block, protocol, condition, \
    stimulus, reference, arrangement, reference_position, break_before, staircase, level, \
    response, response_a, response_b, choice, score, score_reference, score_test, correct, \
    reversal, response_time_ms, replays, dropped_frames, elapsed_ms, wall_clock_ms, \
    monotonic_ms, codec_params, achieved_cr, rms_cm, frames_shown, interval_sd_ms";

/// The statement that commits one answer: its row (`$1` session id, `$2` row number, then
/// [`COLUMNS`]) and the session's count of rows, in one statement.
pub fn append_sql() -> String {
    format!(
        "WITH row AS (INSERT INTO study_trials (session_id, row_number, {COLUMNS}) VALUES ($1, $2, {})) \
         UPDATE study_sessions SET trials_logged = $2 + 1 WHERE id = $1",
        (3..COLUMN_COUNT + 3)
            .map(|i| format!("${i}"))
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// Columns read back, `session_id` and `row_number` first.
pub const SELECT_COLUMNS: &str = "session_id, row_number, study, subject, session, trial_index, \
    block, protocol, condition, stimulus, reference, arrangement, reference_position, \
    break_before, staircase, level, response, response_a, response_b, choice, score, \
    score_reference, score_test, correct, reversal, response_time_ms, replays, dropped_frames, \
    elapsed_ms, wall_clock_ms, monotonic_ms, codec_params, achieved_cr, rms_cm, frames_shown, \
    interval_sd_ms";

/// Number of columns in [`COLUMNS`].
pub const COLUMN_COUNT: usize = 34;

fn unwritable(column: &'static str, reason: impl Into<String>) -> ResultsError {
    ResultsError::Unwritable {
        column,
        reason: reason.into(),
    }
}

fn int(column: &'static str, v: u64) -> Result<i64, ResultsError> {
    i64::try_from(v).map_err(|_| unwritable(column, format!("{v} is too large")))
}

fn int4(column: &'static str, v: u32) -> Result<i32, ResultsError> {
    i32::try_from(v).map_err(|_| unwritable(column, format!("{v} is too large")))
}

/// One record's values, owned, in the order of [`COLUMNS`].
pub struct Values {
    study: String,
    subject: String,
    session: i32,
    trial_index: i32,
    block: &'static str,
    protocol: &'static str,
    condition: String,
    stimulus: String,
    reference: String,
    arrangement: &'static str,
    reference_position: &'static str,
    break_before: bool,
    staircase: Option<i32>,
    level: Option<f64>,
    response: Option<f64>,
    response_a: Option<f64>,
    response_b: Option<f64>,
    choice: Option<&'static str>,
    score: f64,
    score_reference: Option<f64>,
    score_test: Option<f64>,
    correct: Option<bool>,
    reversal: Option<bool>,
    response_time_ms: i64,
    replays: i32,
    dropped_frames: i32,
    elapsed_ms: i64,
    wall_clock_ms: i64,
    monotonic_ms: i64,
    codec_params: Option<String>,
    achieved_cr: Option<f64>,
    rms_cm: Option<f64>,
    frames_shown: Option<i32>,
    interval_sd_ms: Option<f64>,
}

impl Values {
    /// The values of `r`, checked as `trials.csv` checks them (finite numbers, codec
    /// parameters it can write).
    ///
    /// # Errors
    /// [`ResultsError::Unwritable`] naming the column.
    pub fn of(r: &TrialRecord) -> Result<Self, ResultsError> {
        let t = &r.trial;
        let o = &r.outcome;
        let (response, response_a, response_b, choice) = match r.response.answer {
            Answer::Rating(v) => (Some(v), None, None, None),
            Answer::Pair { a, b } => (None, Some(a), Some(b), None),
            Answer::Choice(p) => (None, None, None, Some(p.as_str())),
        };
        let (codec_params, achieved_cr, rms_cm) = match &r.encoding {
            None => (None, None, None),
            Some(e) => (
                Some(
                    format_codec_params(&e.codec_params)
                        .map_err(|m| unwritable("codec_params", m))?,
                ),
                Some(e.achieved_cr),
                Some(e.rms_cm),
            ),
        };
        let p = Values {
            study: r.study.clone(),
            subject: r.subject.clone(),
            session: int4("session", r.session)?,
            trial_index: int4("trial_index", t.index)?,
            block: t.block.as_str(),
            protocol: r.protocol.as_str(),
            condition: t.condition.clone(),
            stimulus: t.stimulus.clone(),
            reference: t.reference.clone(),
            arrangement: t.arrangement.as_str(),
            reference_position: t.reference_position.as_str(),
            break_before: t.break_before,
            staircase: t.staircase.map(|s| int4("staircase", s)).transpose()?,
            level: t.level,
            response,
            response_a,
            response_b,
            choice,
            score: o.score,
            score_reference: o.score_reference,
            score_test: o.score_test,
            correct: o.correct,
            reversal: o.reversal,
            response_time_ms: int("response_time_ms", r.response.response_time_ms)?,
            replays: int4("replays", r.response.replays)?,
            dropped_frames: int4("dropped_frames", r.response.dropped_frames)?,
            elapsed_ms: int("elapsed_ms", r.elapsed_ms)?,
            wall_clock_ms: int("wall_clock_ms", r.wall_clock_ms)?,
            monotonic_ms: int("monotonic_ms", r.monotonic_ms)?,
            codec_params,
            achieved_cr,
            rms_cm,
            frames_shown: r
                .timing
                .map(|t| int4("frames_shown", t.frames_shown))
                .transpose()?,
            interval_sd_ms: r.timing.map(|t| t.interval_sd_ms),
        };
        for (column, v) in [
            ("level", p.level),
            ("response", p.response),
            ("response_a", p.response_a),
            ("response_b", p.response_b),
            ("score", Some(p.score)),
            ("score_reference", p.score_reference),
            ("score_test", p.score_test),
            ("achieved_cr", p.achieved_cr),
            ("rms_cm", p.rms_cm),
            ("interval_sd_ms", p.interval_sd_ms),
        ] {
            if let Some(v) = v.filter(|v| !v.is_finite()) {
                return Err(unwritable(column, format!("{v} is not finite")));
            }
        }
        Ok(p)
    }

    /// The values as query parameters, in the order of [`COLUMNS`].
    pub fn refs(&self) -> [&(dyn ToSql + Sync); COLUMN_COUNT] {
        [
            &self.study,
            &self.subject,
            &self.session,
            &self.trial_index,
            &self.block,
            &self.protocol,
            &self.condition,
            &self.stimulus,
            &self.reference,
            &self.arrangement,
            &self.reference_position,
            &self.break_before,
            &self.staircase,
            &self.level,
            &self.response,
            &self.response_a,
            &self.response_b,
            &self.choice,
            &self.score,
            &self.score_reference,
            &self.score_test,
            &self.correct,
            &self.reversal,
            &self.response_time_ms,
            &self.replays,
            &self.dropped_frames,
            &self.elapsed_ms,
            &self.wall_clock_ms,
            &self.monotonic_ms,
            &self.codec_params,
            &self.achieved_cr,
            &self.rms_cm,
            &self.frames_shown,
            &self.interval_sd_ms,
        ]
    }
}

/// The Postgres types of [`COLUMNS`], for a binary `COPY`.
pub fn types() -> [postgres::types::Type; COLUMN_COUNT] {
    use postgres::types::Type;
    let (t, i4, i8, f8, b) = (Type::TEXT, Type::INT4, Type::INT8, Type::FLOAT8, Type::BOOL);
    [
        t.clone(),
        t.clone(),
        i4.clone(),
        i4.clone(),
        t.clone(),
        t.clone(),
        t.clone(),
        t.clone(),
        t.clone(),
        t.clone(),
        t.clone(),
        b.clone(),
        i4.clone(),
        f8.clone(),
        f8.clone(),
        f8.clone(),
        f8.clone(),
        t.clone(),
        f8.clone(),
        f8.clone(),
        f8.clone(),
        b.clone(),
        b,
        i8.clone(),
        i4.clone(),
        i4.clone(),
        i8.clone(),
        i8.clone(),
        i8,
        t,
        f8.clone(),
        f8.clone(),
        i4,
        f8,
    ]
}

/// Number of columns in [`SELECT_COLUMNS`].
pub const SELECT_COUNT: usize = COLUMN_COUNT + 2;

/// The start of every binary `COPY` stream: its 11-byte signature (the flags and header
/// extension length follow it).
const COPY_SIGNATURE: &[u8; 11] = b"PGCOPY\n\xff\r\n\0";

/// A binary `COPY` stream of [`SELECT_COLUMNS`] rows, for splitting into sessions and
/// decoding, with no per-row allocation: the server's rows are read straight from the bytes
/// it sent (`COPY ... TO STDOUT (FORMAT binary)`), not through a `Row` per row.
pub struct CopyRows<'a> {
    bytes: &'a [u8],
    at: usize,
}

/// One row of a [`CopyRows`] stream: its fields (`None` for NULL), and where it lies in
/// the stream.
pub struct Tuple<'a> {
    fields: [Option<&'a [u8]>; SELECT_COUNT],
    /// Where the row lies in the bytes it was read from, from its field count to its last
    /// field's end.
    pub span: std::ops::Range<usize>,
}

fn be_i16(b: &[u8]) -> Option<i16> {
    Some(i16::from_be_bytes(b.get(..2)?.try_into().ok()?))
}

fn be_i32(b: &[u8]) -> Option<i32> {
    Some(i32::from_be_bytes(b.get(..4)?.try_into().ok()?))
}

impl<'a> CopyRows<'a> {
    /// The rows of a whole binary `COPY` stream (signature, flags, header extension, rows,
    /// trailer).
    ///
    /// # Errors
    /// A stream that does not start as binary `COPY` output does.
    pub fn stream(bytes: &'a [u8]) -> Result<Self, String> {
        let rest = bytes
            .strip_prefix(COPY_SIGNATURE)
            .ok_or("the server's rows are not a binary COPY stream")?;
        let flags = be_i32(rest).ok_or("the binary COPY header is cut short")?;
        if flags & 0xffff_0000_u32.cast_signed() != 0 {
            return Err(format!(
                "the binary COPY header has unknown flags {flags:#x}"
            ));
        }
        let ext = be_i32(&rest[4..])
            .and_then(|n| usize::try_from(n).ok())
            .ok_or("the binary COPY header is cut short")?;
        let at = COPY_SIGNATURE.len() + 8 + ext;
        if at > bytes.len() {
            return Err("the binary COPY header is cut short".into());
        }
        Ok(CopyRows { bytes, at })
    }

    /// The rows of one session cut from a stream by [`Self::next`] (the rows' bytes back to
    /// back, no header or trailer).
    pub fn rows(bytes: &'a [u8]) -> Self {
        CopyRows { bytes, at: 0 }
    }

    /// The next row, `None` at the stream's trailer or the end of the bytes.
    ///
    /// # Errors
    /// A row with another number of fields than [`SELECT_COLUMNS`], or cut short.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Result<Option<Tuple<'a>>, String> {
        let start = self.at;
        let b = self.bytes;
        if start == b.len() {
            return Ok(None);
        }
        let count = be_i16(&b[start..]).ok_or("a row is cut short")?;
        if count == -1 {
            self.at = b.len();
            return Ok(None);
        }
        if usize::try_from(count).ok() != Some(SELECT_COUNT) {
            return Err(format!(
                "a row has {count} columns, not the {SELECT_COUNT} asked for"
            ));
        }
        let mut at = start + 2;
        let mut fields = [None; SELECT_COUNT];
        for field in &mut fields {
            let len = be_i32(&b[at.min(b.len())..]).ok_or("a row is cut short")?;
            at += 4;
            if len >= 0 {
                let end = at
                    .checked_add(len.unsigned_abs() as usize)
                    .filter(|&e| e <= b.len())
                    .ok_or("a row is cut short")?;
                *field = Some(&b[at..end]);
                at = end;
            } else if len != -1 {
                return Err(format!("a field has length {len}"));
            }
        }
        self.at = at;
        Ok(Some(Tuple {
            fields,
            span: start..at,
        }))
    }
}

type Field<T> = Result<T, (usize, String)>;

fn null(i: usize) -> (usize, String) {
    (i, "NULL where a value is required".into())
}

impl<'a> Tuple<'a> {
    fn fixed<const N: usize>(&self, i: usize) -> Field<Option<[u8; N]>> {
        self.fields[i]
            .map(|b| {
                b.try_into()
                    .map_err(|_| (i, format!("{} bytes where {N} are expected", b.len())))
            })
            .transpose()
    }

    /// Column `i` as an `integer`.
    pub fn opt_int4(&self, i: usize) -> Field<Option<i32>> {
        Ok(self.fixed::<4>(i)?.map(i32::from_be_bytes))
    }

    /// Column `i` as a non-null `integer`.
    pub fn int4(&self, i: usize) -> Field<i32> {
        self.opt_int4(i)?.ok_or_else(|| null(i))
    }

    fn int8(&self, i: usize) -> Field<i64> {
        Ok(i64::from_be_bytes(
            self.fixed::<8>(i)?.ok_or_else(|| null(i))?,
        ))
    }

    fn opt_f64(&self, i: usize) -> Field<Option<f64>> {
        Ok(self.fixed::<8>(i)?.map(f64::from_be_bytes))
    }

    fn finite(&self, i: usize) -> Field<f64> {
        let v = self.opt_f64(i)?.ok_or_else(|| null(i))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err((i, format!("{v} is not finite")))
        }
    }

    fn opt_bool(&self, i: usize) -> Field<Option<bool>> {
        match self.fixed::<1>(i)? {
            None => Ok(None),
            Some([0]) => Ok(Some(false)),
            Some([1]) => Ok(Some(true)),
            Some([b]) => Err((i, format!("{b} is not a boolean"))),
        }
    }

    fn opt_str(&self, i: usize) -> Field<Option<&'a str>> {
        self.fields[i]
            .map(|b| std::str::from_utf8(b).map_err(|e| (i, format!("not UTF-8: {e}"))))
            .transpose()
    }

    fn str(&self, i: usize) -> Field<&'a str> {
        self.opt_str(i)?.ok_or_else(|| null(i))
    }

    fn string(&self, i: usize) -> Field<String> {
        self.str(i).map(str::to_owned)
    }

    fn named<T: std::str::FromStr<Err = String>>(&self, i: usize) -> Field<T> {
        self.str(i)?.parse().map_err(|e| (i, e))
    }

    fn unsigned<T: TryFrom<i64>>(&self, i: usize, wide: bool) -> Field<T> {
        let v = if wide {
            self.int8(i)?
        } else {
            i64::from(self.int4(i)?)
        };
        T::try_from(v).map_err(|_| (i, format!("{v} is out of range")))
    }

    fn opt_unsigned(&self, i: usize) -> Field<Option<u32>> {
        self.opt_int4(i)?
            .map(|v| u32::try_from(v).map_err(|_| (i, format!("{v} is out of range"))))
            .transpose()
    }
}

/// Reads rows of [`SELECT_COLUMNS`] back into records; an error names `trials` (the
/// session's path in messages), the line the row has in an exported `trials.csv` and the
/// column.
pub struct Decoder<'a> {
    /// The path naming the session's trials in messages.
    pub trials: &'a Path,
}

impl Decoder<'_> {
    /// The record of `row`.
    ///
    /// # Errors
    /// [`ResultsError::Malformed`] naming the row's line and column.
    pub fn decode(&self, row: &Tuple<'_>) -> Result<TrialRecord, ResultsError> {
        decode(row).map_err(|(i, message)| {
            let line = row
                .int4(1)
                .map_or(0, |n| usize::try_from(n).unwrap_or(0) + 2);
            ResultsError::Malformed {
                path: self.trials.to_path_buf(),
                line,
                column: csv_column(i),
                message: format!("{}: {message}", column_name(i)),
            }
        })
    }
}

/// The name of select column `i`.
pub fn column_name(i: usize) -> &'static str {
    SELECT_COLUMNS.split(", ").nth(i).unwrap_or("?")
}

/// The 1-based `trials.csv` column of select column `i` (the CSV's `response` holds a rating
/// or a 2AFC choice, which the table keeps apart).
fn csv_column(i: usize) -> usize {
    match i {
        0..=18 => i.max(1),
        19 => 16,
        _ => i - 1,
    }
}

fn decode(row: &Tuple<'_>) -> Field<TrialRecord> {
    let protocol: Protocol = row.named(7)?;
    let answer = match protocols::methods::of(protocol).answer_kind() {
        AnswerKind::Rating => Answer::Rating(row.finite(16)?),
        AnswerKind::RatingPair => Answer::Pair {
            a: row.finite(17)?,
            b: row.finite(18)?,
        },
        AnswerKind::Choice => Answer::Choice(row.named(19)?),
    };
    let encoding = match row.opt_str(31)? {
        None => None,
        Some(params) => Some(StimulusEncoding {
            codec_params: parse_codec_params(params).map_err(|m| (31, m))?,
            achieved_cr: row.finite(32)?,
            rms_cm: row.finite(33)?,
        }),
    };
    let timing = match row.opt_unsigned(34)? {
        None => None,
        Some(frames_shown) => Some(FrameTiming {
            frames_shown,
            interval_sd_ms: row.finite(35)?,
        }),
    };
    let block: Block = row.named(6)?;
    Ok(TrialRecord {
        study: row.string(2)?,
        subject: row.string(3)?,
        session: row.unsigned(4, false)?,
        protocol,
        trial: Trial {
            index: row.unsigned(5, false)?,
            block,
            condition: row.string(8)?,
            stimulus: row.string(9)?,
            reference: row.string(10)?,
            arrangement: row.named(11)?,
            reference_position: row.named(12)?,
            break_before: row.opt_bool(13)?.ok_or_else(|| null(13))?,
            staircase: row.opt_unsigned(14)?,
            level: row.opt_f64(15)?,
        },
        response: Response {
            answer,
            response_time_ms: row.unsigned(25, true)?,
            replays: row.unsigned(26, false)?,
            dropped_frames: row.unsigned(27, false)?,
        },
        outcome: Outcome {
            score: row.finite(20)?,
            score_reference: row.opt_f64(21)?,
            score_test: row.opt_f64(22)?,
            correct: row.opt_bool(23)?,
            reversal: row.opt_bool(24)?,
        },
        elapsed_ms: row.unsigned(28, true)?,
        wall_clock_ms: row.unsigned(29, true)?,
        monotonic_ms: row.unsigned(30, true)?,
        encoding,
        timing,
    })
}
