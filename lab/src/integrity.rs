//! Whether a results directory's logs can be trusted, checked before any statistic is drawn
//! from them (`study report`).
//!
//! Every session is replayed through the protocol engine from the study file it ran, the way
//! `study run --resume` replays it: the logged trials must be the ones the plan (and, for a
//! staircase, the logged answers) leads to, in order, each once. That one rule catches rows
//! duplicated, deleted, reordered or copied in from another subject's log; the checks around
//! it name what went wrong in words a lab can act on. A problem is one of two kinds:
//! - [`Kind::Damage`]: the logs contradict themselves or the study (a row twice, a row out of
//!   order or of another session, a manifest that disagrees with its log or its folder, a
//!   torn row in a session marked complete). Nothing computed from them can be trusted.
//! - [`Kind::Incomplete`]: trials are missing at the end (a session still running or
//!   interrupted, or a log shorter than its manifest says). The rows that are there are
//!   sound; a report may use them when asked to (`--allow-incomplete`), and lists what is
//!   missing.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

use protocols::StudyDefinition;
use protocols::engine::{Session, SessionStatus};
use results::store::{SESSION_FILE, SessionState, TRIALS_FILE};
use results::{RunManifest, SessionResults};

use crate::StudyFile;
use crate::session::{check_live_params, check_row_identity, session_dir};

/// What kind of problem a log has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The logs contradict themselves or the study.
    Damage,
    /// Trials are missing at the end; the logged rows are sound.
    Incomplete,
}

/// One problem of one session's logs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// The file at fault (`trials.csv` or `session.json` of the session).
    pub path: PathBuf,
    /// The 1-based line of `trials.csv`, when a row is at fault.
    pub line: Option<usize>,
    /// Damage or missing trials.
    pub kind: Kind,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ": line {line}")?;
        }
        write!(f, ": {}", self.message)
    }
}

/// Checks the sessions of a results directory one at a time (as [`results::read_session`]
/// reads them) against the study file they ran: at most one replay problem per session (the
/// rows after the first bad one follow from it), and a session recorded twice. Shared by
/// reference between threads: [`Self::check_alone`] on any of them, [`Self::check_repeat`]
/// in session order.
pub struct Checker<'a> {
    study: &'a StudyFile,
    run: &'a RunManifest,
    archived: bool,
    seen: Mutex<HashMap<(String, u32), PathBuf>>,
}

impl<'a> Checker<'a> {
    /// A checker of the sessions of `results` against `study` and the run manifest `run`.
    #[must_use]
    pub fn new(results: &Path, study: &'a StudyFile, run: &'a RunManifest) -> Self {
        // The archived copy points at absolute stimulus paths, so neither its own hash nor
        // its manifest's is the original's: sessions are held to the run's hashes then.
        Self::with_archived(
            study,
            run,
            same_file(&results.join(&run.study_file), &study.path),
        )
    }

    /// A checker of sessions against `study`, which is the run's archived copy when
    /// `archived` (a database run's copy, written out for the report): sessions are then held
    /// to the run's hashes.
    #[must_use]
    pub fn with_archived(study: &'a StudyFile, run: &'a RunManifest, archived: bool) -> Self {
        Self {
            study,
            run,
            archived,
            seen: Mutex::new(HashMap::new()),
        }
    }

    /// The problems of one session (and of it against the sessions checked before).
    pub fn check(&self, s: &SessionResults) -> Vec<Problem> {
        match self.check_repeat(s) {
            Some(p) => vec![p],
            None => self.check_alone(s),
        }
    }

    /// A session recorded again (the same subject and session as one checked before); the
    /// first time, notes it.
    pub fn check_repeat(&self, s: &SessionResults) -> Option<Problem> {
        let m = &s.manifest;
        let key = (m.subject.clone(), m.session);
        // A panic elsewhere while this was held leaves the map whole (one insert at a time).
        let mut seen = self.seen.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(first) = seen.get(&key) {
            return Some(Problem {
                path: s.dir.join(SESSION_FILE),
                line: None,
                kind: Kind::Damage,
                message: format!(
                    "subject {:?} session {} is also recorded in {} (a session copied twice?)",
                    m.subject,
                    m.session,
                    first.display()
                ),
            });
        }
        seen.insert(key, s.dir.clone());
        None
    }

    /// The problems of one session on its own: its manifest against the run, the study and
    /// its folder, its rows replayed. Needs no other session, so sessions can be checked on
    /// several threads; [`Self::check_repeat`] then runs on them in order.
    #[must_use]
    pub fn check_alone(&self, s: &SessionResults) -> Vec<Problem> {
        let mut problems = Vec::new();
        check_session(self.study, self.archived, self.run, s, &mut problems);
        problems
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// The manifest's own fields against the run, the study and the folder it is in.
fn manifest_problem(
    study: &StudyFile,
    archived: bool,
    run: &RunManifest,
    s: &SessionResults,
) -> Option<String> {
    let m = &s.manifest;
    let folder = s.dir.file_name().map(|n| n.to_string_lossy().into_owned());
    let expected = session_dir(Path::new(""), &m.subject, m.session);
    if folder.as_deref() != expected.to_str() {
        return Some(format!(
            "records subject {:?} session {}, whose folder is {}, not {}",
            m.subject,
            m.session,
            expected.display(),
            folder.unwrap_or_default()
        ));
    }
    if m.study != run.study || m.study != study.definition.name {
        return Some(format!(
            "is a session of study {:?}; the results directory is of {:?} and the study file of {:?}",
            m.study, run.study, study.definition.name
        ));
    }
    let (study_hash, manifest_hash, against) = if archived {
        (
            &run.study_hash,
            run.manifest_hash.as_ref(),
            "the run (run.json)",
        )
    } else {
        (&study.hash, Some(&study.manifest_hash), "the study file")
    };
    if m.study_hash != *study_hash {
        return Some(format!(
            "was recorded with study file {}, {against} has {study_hash} ({}): report with the study file the session ran",
            m.study_hash,
            study.path.display()
        ));
    }
    if let (Some(h), Some(want)) = (&m.manifest_hash, manifest_hash)
        && h != want
    {
        return Some(format!(
            "was recorded with stimulus manifest {h}, {against} has {want} (stimuli re-made since?)"
        ));
    }
    if m.plan_seed != study.definition.seed {
        return Some(format!(
            "was planned with seed {}, the study file gives {}",
            m.plan_seed, study.definition.seed
        ));
    }
    None
}

fn check_session(
    study: &StudyFile,
    archived: bool,
    run: &RunManifest,
    s: &SessionResults,
    problems: &mut Vec<Problem>,
) {
    let m = &s.manifest;
    let trials = s.dir.join(TRIALS_FILE);
    let manifest = s.dir.join(SESSION_FILE);
    let mut push = |path: &Path, line: Option<usize>, kind: Kind, message: String| {
        problems.push(Problem {
            path: path.to_path_buf(),
            line,
            kind,
            message,
        });
    };
    if let Some(message) = manifest_problem(study, archived, run, s) {
        push(&manifest, None, Kind::Damage, message);
        return;
    }
    let rows = s.trials.records.len();
    let finished = matches!(m.status, SessionState::Complete | SessionState::TimeLimit);
    if let Some(torn) = &s.trials.torn {
        if finished {
            push(
                &trials,
                Some(torn.line),
                Kind::Damage,
                format!(
                    "a torn row ({} bytes without a line end) after the session was marked {}",
                    torn.bytes.len(),
                    state_name(m.status)
                ),
            );
            return;
        }
        push(
            &trials,
            Some(torn.line),
            Kind::Incomplete,
            format!(
                "the last row is torn ({} bytes, the session stopped mid-write); `study run --resume` sets it aside",
                torn.bytes.len()
            ),
        );
    }
    let mut engine = match replayed(&study.definition, s) {
        Ok(engine) => engine,
        Err((line, message)) => {
            push(&trials, Some(line), Kind::Damage, message);
            return;
        }
    };
    let logged = m.trials_logged as usize;
    // The rows are the record. A running session's manifest counts the rows at its last
    // write (open, resume, a display change; before manifest version 4, after every row), so
    // its log may hold more; an interrupted or finished session's manifest counts them all
    // (an unfinished one of an earlier version may lack the row a kill cut it off from).
    let consistent = rows == logged
        || (!finished && rows == logged + 1)
        || (m.status == SessionState::Running && rows > logged);
    if rows > logged && !consistent {
        push(
            &manifest,
            None,
            Kind::Damage,
            format!("records {logged} trials logged, but trials.csv holds {rows} rows"),
        );
        return;
    }
    if rows < logged {
        push(
            &trials,
            Some(rows + 2),
            Kind::Incomplete,
            format!(
                "ends after {rows} rows; session.json records {logged} trials logged: trials {} to {logged} are missing (the file was cut short)",
                rows + 1
            ),
        );
        return;
    }
    match m.status {
        SessionState::Running | SessionState::Interrupted => {
            let left = remaining(&study.definition, s, &engine);
            push(
                &manifest,
                None,
                Kind::Incomplete,
                format!(
                    "the session is {} with {rows} trials logged{left}; finish it with `study run --resume` (or `study simulate --resume`)",
                    state_name(m.status)
                ),
            );
        }
        SessionState::Complete => {
            if let Some(left) = unfinished_plan(&study.definition, &mut engine) {
                push(
                    &trials,
                    Some(rows + 2),
                    Kind::Incomplete,
                    format!(
                        "ends after {rows} rows, but the session is marked complete and the study plans {left}: rows missing at the end"
                    ),
                );
            }
        }
        SessionState::TimeLimit => {}
    }
}

fn state_name(state: SessionState) -> &'static str {
    match state {
        SessionState::Running => "running",
        SessionState::Interrupted => "interrupted",
        SessionState::Complete => "complete",
        SessionState::TimeLimit => "ended by the time limit",
    }
}

/// The engine after replaying a session's rows, or the first row that does not follow from the
/// plan and the answers before it, with why.
///
/// A sound log takes [`replayed_sound`], which asks the engine the same questions
/// [`Session::replay`] does but compares the answers in place; any doubt about a row (or a
/// level logged before the exact grid, which `replay` accepts within rounding) replays the
/// session again from the start with [`replayed_in_full`], which finds and words the problem.
fn replayed(study: &StudyDefinition, s: &SessionResults) -> Result<Session, (usize, String)> {
    // A session of a between-subject group was planned over its group's conditions.
    let study = study
        .for_group(s.manifest.group.as_deref())
        .map_err(|e| (1, format!("the study cannot plan this session: {e}")))?;
    let study = study.as_ref();
    match replayed_sound(study, s) {
        Some(engine) => Ok(engine),
        None => replayed_in_full(study, s),
    }
}

/// The engine after replaying a session whose every row is the one the plan gives at its
/// place (trial index = row number, the row's identity the manifest's, the trial the engine's
/// next one field for field as [`Session::replay`] compares them, the outcome the engine's
/// scoring of the response), else `None`. Accepts only what [`replayed_in_full`] accepts,
/// leaving the engine in the same state, without the text `replay` makes of every field.
fn replayed_sound(study: &StudyDefinition, s: &SessionResults) -> Option<Session> {
    let m = &s.manifest;
    let mut engine = Session::new(study, m.subject_index).ok()?;
    for (i, rec) in s.trials.records.iter().enumerate() {
        let logged = &rec.trial;
        let sound = logged.index as usize == i
            && check_row_identity(rec, m).is_ok()
            && check_live_params(study, rec).is_ok();
        if !sound {
            return None;
        }
        let planned = engine.next_trial(0).ok()??;
        // `replay`'s fields, `break_before` not among them; the level exactly.
        let same = planned.index == logged.index
            && planned.block == logged.block
            && planned.condition == logged.condition
            && planned.stimulus == logged.stimulus
            && planned.reference == logged.reference
            && planned.arrangement == logged.arrangement
            && planned.reference_position == logged.reference_position
            && planned.staircase == logged.staircase
            && planned.level == logged.level;
        if !same || engine.respond(&rec.response).ok()? != rec.outcome {
            return None;
        }
    }
    Some(engine)
}

/// [`replayed`], row by row through [`Session::replay`], naming the first row at fault.
fn replayed_in_full(
    study: &StudyDefinition,
    s: &SessionResults,
) -> Result<Session, (usize, String)> {
    let m = &s.manifest;
    let mut engine = match Session::new(study, m.subject_index) {
        Ok(e) => e,
        Err(e) => return Err((1, format!("the study cannot plan this session: {e}"))),
    };
    let mut first_line: HashMap<u32, usize> = HashMap::new();
    for (i, rec) in s.trials.records.iter().enumerate() {
        // Line 1 is the header.
        let line = i + 2;
        if let Err(e) = check_row_identity(rec, m) {
            return Err((line, format!("{e} (a row of another log?)")));
        }
        let index = rec.trial.index;
        if let Some(first) = first_line.get(&index) {
            return Err((
                line,
                format!("trial {index} is logged twice (first at line {first})"),
            ));
        }
        first_line.insert(index, line);
        let due = i as u32;
        if index > due
            && let Some(later) = s.trials.records[i + 1..]
                .iter()
                .position(|r| r.trial.index == due)
        {
            return Err((
                line,
                format!(
                    "rows out of order: trial {index} is logged before trial {due} (line {})",
                    line + 1 + later
                ),
            ));
        }
        if index > due {
            return Err((
                line,
                if index == due + 1 {
                    format!("trial {due} is missing: this row is trial {index}")
                } else {
                    format!(
                        "trials {due} to {} are missing: this row is trial {index}",
                        index - 1
                    )
                },
            ));
        }
        if index < due {
            return Err((
                line,
                format!(
                    "trial {index} comes after trial {} (rows out of order)",
                    due - 1
                ),
            ));
        }
        if let Err(e) = check_live_params(study, rec) {
            return Err((line, e));
        }
        if let Err(e) = engine.replay(&rec.trial, &rec.response, &rec.outcome) {
            return Err((
                line,
                format!("the row is not what the study plans for this subject here: {e}"),
            ));
        }
    }
    Ok(engine)
}

/// How many trials the plan still holds after the logged rows, as words (" of N planned"),
/// or "" when the plan has no fixed length (a staircase).
fn remaining(study: &StudyDefinition, s: &SessionResults, engine: &Session) -> String {
    if study.method().adaptive() {
        return String::new();
    }
    let left = engine.not_shown().len();
    format!(
        " of {} planned ({left} not shown)",
        s.trials.records.len() + left
    )
}

/// What the plan still holds after the rows of a session marked complete, if anything.
fn unfinished_plan(study: &StudyDefinition, engine: &mut Session) -> Option<String> {
    match engine.next_trial(0) {
        Ok(Some(t)) => Some(if study.method().adaptive() {
            format!("more staircase trials (trial {} is due)", t.index)
        } else {
            format!("{} more trials", engine.not_shown().len() + 1)
        }),
        _ => (engine.status() == SessionStatus::Running).then(|| "more trials".to_owned()),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use std::collections::BTreeMap;
    use std::path::Path;

    use protocols::methods::AnswerKind;
    use protocols::{Answer, Arrangement, Block, Position, Response, Session, TrialRecord};
    use results::store::{SessionManifest, SessionState};
    use results::{SessionResults, TrialsFile};

    use super::{replayed, replayed_in_full, replayed_sound};
    use crate::StudyFile;

    /// An example study and two complete sessions of it, answered in memory (the two ends of
    /// the scale in turn; a staircase right twice, then wrong).
    fn sessions(name: &str) -> (StudyFile, Vec<SessionResults>) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../examples/{name}.toml"));
        let study = StudyFile::load(&path).unwrap();
        let d = &study.definition;
        let sessions = (0..2)
            .map(|subject_index| {
                let subject = format!("S{subject_index}");
                let mut engine = Session::new(d, subject_index).unwrap();
                let mut records = Vec::new();
                while let Some(trial) = engine.next_trial(0).unwrap() {
                    let k = records.len();
                    let end = if k % 2 == 0 { d.scale.min } else { d.scale.max };
                    let answer = match d.method().answer_kind() {
                        AnswerKind::Rating => Answer::Rating(end),
                        AnswerKind::RatingPair => Answer::Pair {
                            a: end,
                            b: d.scale.max,
                        },
                        AnswerKind::Choice if k % 3 == 2 => {
                            Answer::Choice(flip(trial.reference_position))
                        }
                        AnswerKind::Choice => Answer::Choice(trial.reference_position),
                    };
                    let response = Response {
                        answer,
                        response_time_ms: 900,
                        replays: 0,
                        dropped_frames: 0,
                    };
                    let outcome = engine.respond(&response).unwrap();
                    records.push(TrialRecord {
                        study: d.name.clone(),
                        subject: subject.clone(),
                        session: 1,
                        protocol: d.protocol,
                        trial,
                        response,
                        outcome,
                        elapsed_ms: 0,
                        wall_clock_ms: 0,
                        monotonic_ms: 0,
                        encoding: None,
                        timing: None,
                    });
                }
                let manifest = SessionManifest {
                    format_version: 2,
                    study: d.name.clone(),
                    study_hash: study.hash.clone(),
                    manifest_hash: Some(study.manifest_hash.clone()),
                    protocol: d.protocol,
                    subject,
                    subject_index,
                    session: 1,
                    plan_seed: d.seed,
                    observer_seed: None,
                    software_version: String::new(),
                    subject_fields: BTreeMap::new(),
                    started_ms: 0,
                    ended_ms: Some(0),
                    status: SessionState::Complete,
                    trials_logged: records.len() as u32,
                    not_shown: Vec::new(),
                    thresholds: Vec::new(),
                    resumes: 0,
                    torn_rows: Vec::new(),
                    display: None,
                    browser: None,
                    viewing: None,
                    group: None,
                };
                SessionResults {
                    dir: Path::new("results").join(format!("S{subject_index}_s1")),
                    manifest,
                    trials: TrialsFile {
                        format_version: 2,
                        records,
                        complete_bytes: 0,
                        torn: None,
                    },
                }
            })
            .collect();
        (study, sessions)
    }

    /// The other side, interval or slot (a side for no preference).
    fn flip(p: Position) -> Position {
        match p {
            Position::Left => Position::Right,
            Position::Right | Position::Neither => Position::Left,
            Position::First => Position::Second,
            Position::Second => Position::First,
            Position::A => Position::B,
            Position::B => Position::A,
            Position::Hidden => Position::Hidden,
            Position::Pane(i) => Position::Pane((i + 1) % protocols::MAX_PANES as u8),
        }
    }

    /// Every way a row can differ from what the plan holds, one at a time, at row `i` (the
    /// first, second, middle and last rows are tried).
    fn edits(s: &SessionResults, i: usize) -> Vec<(&'static str, SessionResults)> {
        let n = s.trials.records.len();
        let other = (i + 1) % n;
        let mut out = Vec::new();
        let mut edit = |what, f: &dyn Fn(&mut SessionResults)| {
            let mut e = s.clone();
            f(&mut e);
            out.push((what, e));
        };
        edit("swap", &|e| e.trials.records.swap(i, other));
        edit("twice", &|e| {
            let r = e.trials.records[i].clone();
            e.trials.records.insert(i, r);
        });
        edit("deleted", &|e| drop(e.trials.records.remove(i)));
        edit("cut", &|e| e.trials.records.truncate(i));
        edit("index", &|e| e.trials.records[i].trial.index += 1);
        edit("block", &|e| {
            let b = &mut e.trials.records[i].trial.block;
            *b = if *b == Block::Test {
                Block::Familiarization
            } else {
                Block::Test
            };
        });
        edit("stimulus", &|e| {
            e.trials.records[i].trial.stimulus = s.trials.records[other].trial.stimulus.clone();
        });
        edit("condition", &|e| {
            e.trials.records[i].trial.condition.push('x');
        });
        edit("reference", &|e| {
            e.trials.records[i].trial.reference.push('x');
        });
        edit("arrangement", &|e| {
            e.trials.records[i].trial.arrangement = Arrangement::Sequential;
        });
        edit("position", &|e| {
            let p = &mut e.trials.records[i].trial.reference_position;
            *p = flip(*p);
        });
        edit("staircase", &|e| {
            let t = &mut e.trials.records[i].trial.staircase;
            *t = Some(t.map_or(0, |k| k + 1));
        });
        // Within rounding (a log from before the exact grid) and not.
        edit("level rounding", &|e| {
            if let Some(l) = &mut e.trials.records[i].trial.level {
                *l *= 1.0 + 1e-12;
            }
        });
        edit("level", &|e| {
            let l = &mut e.trials.records[i].trial.level;
            *l = Some(l.map_or(1.0, |l| l * 1.5));
        });
        edit("break", &|e| {
            let b = &mut e.trials.records[i].trial.break_before;
            *b = !*b;
        });
        edit("answer", &|e| {
            let a = &mut e.trials.records[i].response.answer;
            *a = match *a {
                Answer::Rating(v) => Answer::Rating(if v > 2.0 { v - 1.0 } else { v + 1.0 }),
                Answer::Pair { a, b } => Answer::Pair { a: b, b: a + 1.0 },
                Answer::Choice(p) => Answer::Choice(flip(p)),
            };
        });
        edit("off scale", &|e| {
            e.trials.records[i].response.answer = Answer::Rating(99.0);
        });
        edit("replays", &|e| e.trials.records[i].response.replays += 50);
        edit("score", &|e| e.trials.records[i].outcome.score += 0.5);
        edit("reversal", &|e| {
            let r = &mut e.trials.records[i].outcome.reversal;
            *r = Some(!r.unwrap_or(false));
        });
        edit("subject", &|e| e.trials.records[i].subject.push('x'));
        edit("study", &|e| e.trials.records[i].study.push('x'));
        edit("session", &|e| e.trials.records[i].session += 1);
        edit("subject index", &|e| e.manifest.subject_index += 1);
        out
    }

    /// The rows are the record of how many trials were logged: a running session whose
    /// manifest was last written at open or resume (fewer trials than its log holds) is
    /// incomplete, not damaged; a manifest of an interrupted or finished session must count
    /// every row, and a log shorter than any manifest's count is cut short.
    #[test]
    fn the_trial_count_comes_from_the_rows() {
        use super::{Checker, Kind};
        let (study, read) = sessions("mos");
        let d = &study.definition;
        let run = results::RunManifest {
            format_version: 3,
            study: d.name.clone(),
            study_hash: study.hash.clone(),
            manifest_hash: Some(study.manifest_hash.clone()),
            study_file: "study.toml".into(),
            plan_seed: d.seed,
            observer_seed: None,
            subjects: 2,
            software_version: String::new(),
            created_ms: 0,
        };
        let checker = Checker::with_archived(&study, &run, false);
        let kinds = |status: SessionState, logged: usize, rows: usize| -> Vec<Kind> {
            let mut s = read[0].clone();
            s.trials.records.truncate(rows);
            s.manifest.status = status;
            s.manifest.trials_logged = logged as u32;
            checker.check_alone(&s).iter().map(|p| p.kind).collect()
        };
        let n = read[0].trials.records.len();
        assert!(n > 6, "{n} rows");
        assert_eq!(kinds(SessionState::Complete, n, n), []);
        // Written at open (0) or at a resume after 2 rows, then 5 more rows logged.
        for logged in [0, 2, 5] {
            assert_eq!(kinds(SessionState::Running, logged, 5), [Kind::Incomplete]);
        }
        assert_eq!(kinds(SessionState::Interrupted, 5, 5), [Kind::Incomplete]);
        // Version 3 and before: a kill between the row and the manifest write.
        assert_eq!(kinds(SessionState::Interrupted, 4, 5), [Kind::Incomplete]);
        assert_eq!(kinds(SessionState::Interrupted, 2, 5), [Kind::Damage]);
        assert_eq!(kinds(SessionState::Complete, n - 2, n), [Kind::Damage]);
        for status in [SessionState::Running, SessionState::Complete] {
            assert_eq!(kinds(status, 6, 5), [Kind::Incomplete], "{status:?}");
        }
    }

    /// The quick replay of sound logs gives what the replay row by row gives: the same
    /// engine for every log it accepts (it accepts every untouched one), and for any edited
    /// row the full replay's verdict, naming the same line with the same words.
    #[test]
    fn the_quick_replay_agrees_with_the_full_one() {
        for name in ["mos", "dscqs", "staircase", "pc", "mushra"] {
            let (study, read) = sessions(name);
            let definition = &study.definition;
            for s in &read {
                let quick = replayed_sound(definition, s).map(|e| format!("{e:?}"));
                let full = replayed_in_full(definition, s).map(|e| format!("{e:?}"));
                assert_eq!(quick.as_ref(), full.as_ref().ok(), "{name}: untouched log");
                let n = s.trials.records.len();
                for i in [0, 1, n / 2, n - 1] {
                    for (what, edited) in edits(s, i) {
                        let full = replayed_in_full(definition, &edited).map(|e| format!("{e:?}"));
                        let got = replayed(definition, &edited).map(|e| format!("{e:?}"));
                        assert_eq!(got, full, "{name}: {what} at row {i}");
                        if let Some(quick) = replayed_sound(definition, &edited) {
                            assert_eq!(
                                Ok(format!("{quick:?}")),
                                full,
                                "{name}: {what} at row {i} passed the quick replay"
                            );
                        }
                    }
                }
            }
        }
    }
}
