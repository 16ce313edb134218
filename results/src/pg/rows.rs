//! Trial records as rows of `study_trials`: one column per `trials.csv` column (the answer
//! split by kind: `response` a MOS rating, `response_a`/`response_b` a DSCQS pair, `choice` a
//! 2AFC answer), every value a query parameter.

use std::path::Path;

use postgres::Row;
use postgres::types::ToSql;
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

/// Reads row `i` of a `SELECT` of [`SELECT_COLUMNS`] back into a record; an error names
/// `trials` (the session's path in messages), the line the row has in an exported
/// `trials.csv` and the column.
pub struct Decoder<'a> {
    /// The path naming the session's trials in messages.
    pub trials: &'a Path,
}

type Field<T> = Result<T, (usize, String)>;

fn get<'r, T: postgres::types::FromSql<'r>>(row: &'r Row, i: usize) -> Field<T> {
    row.try_get(i).map_err(|e| (i, e.to_string()))
}

fn unsigned<T: TryFrom<i64>>(row: &Row, i: usize) -> Field<T> {
    let v: i64 = match row.columns()[i].type_() {
        &postgres::types::Type::INT4 => i64::from(get::<i32>(row, i)?),
        _ => get::<i64>(row, i)?,
    };
    T::try_from(v).map_err(|_| (i, format!("{v} is out of range")))
}

fn opt_unsigned(row: &Row, i: usize) -> Field<Option<u32>> {
    get::<Option<i32>>(row, i)?
        .map(|v| u32::try_from(v).map_err(|_| (i, format!("{v} is out of range"))))
        .transpose()
}

fn named<T: std::str::FromStr<Err = String>>(row: &Row, i: usize) -> Field<T> {
    let s: &str = get(row, i)?;
    s.parse().map_err(|e| (i, e))
}

fn finite(row: &Row, i: usize) -> Field<f64> {
    let v: f64 = get(row, i)?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err((i, format!("{v} is not finite")))
    }
}

impl Decoder<'_> {
    /// The record of `row` (a row of [`SELECT_COLUMNS`]).
    ///
    /// # Errors
    /// [`ResultsError::Malformed`] naming the row's line and column.
    pub fn decode(&self, row: &Row) -> Result<TrialRecord, ResultsError> {
        decode(row).map_err(|(i, message)| {
            let line = row
                .try_get::<_, i32>(1)
                .map_or(0, |n| usize::try_from(n).unwrap_or(0) + 2);
            ResultsError::Malformed {
                path: self.trials.to_path_buf(),
                line,
                column: csv_column(i),
                message: format!("{}: {message}", row.columns()[i].name()),
            }
        })
    }
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

fn decode(row: &Row) -> Field<TrialRecord> {
    let protocol: Protocol = named(row, 7)?;
    let answer = match protocol {
        Protocol::Mos | Protocol::Acr | Protocol::Dcr => Answer::Rating(finite(row, 16)?),
        Protocol::Dscqs => Answer::Pair {
            a: finite(row, 17)?,
            b: finite(row, 18)?,
        },
        Protocol::Staircase => Answer::Choice(named(row, 19)?),
    };
    let encoding = match get::<Option<&str>>(row, 31)? {
        None => None,
        Some(params) => Some(StimulusEncoding {
            codec_params: parse_codec_params(params).map_err(|m| (31, m))?,
            achieved_cr: finite(row, 32)?,
            rms_cm: finite(row, 33)?,
        }),
    };
    let timing = match get::<Option<i32>>(row, 34)? {
        None => None,
        Some(_) => Some(FrameTiming {
            frames_shown: unsigned(row, 34)?,
            interval_sd_ms: finite(row, 35)?,
        }),
    };
    let block: Block = named(row, 6)?;
    Ok(TrialRecord {
        study: get::<String>(row, 2)?,
        subject: get::<String>(row, 3)?,
        session: unsigned(row, 4)?,
        protocol,
        trial: Trial {
            index: unsigned(row, 5)?,
            block,
            condition: get(row, 8)?,
            stimulus: get(row, 9)?,
            reference: get(row, 10)?,
            arrangement: named(row, 11)?,
            reference_position: named(row, 12)?,
            break_before: get(row, 13)?,
            staircase: opt_unsigned(row, 14)?,
            level: get(row, 15)?,
        },
        response: Response {
            answer,
            response_time_ms: unsigned(row, 25)?,
            replays: unsigned(row, 26)?,
            dropped_frames: unsigned(row, 27)?,
        },
        outcome: Outcome {
            score: finite(row, 20)?,
            score_reference: get(row, 21)?,
            score_test: get(row, 22)?,
            correct: get(row, 23)?,
            reversal: get(row, 24)?,
        },
        elapsed_ms: unsigned(row, 28)?,
        wall_clock_ms: unsigned(row, 29)?,
        monotonic_ms: unsigned(row, 30)?,
        encoding,
        timing,
    })
}
