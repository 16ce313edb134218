//! `trials_tidy.csv`: every trial of every session read, one row each, with the subject and
//! their fields, the session, the trial's place and flags, the condition's parts, the
//! staircase level, the answer, the timing and the report's exclusions; and
//! `datapackage.json`, its data dictionary (a Frictionless Data Package: each column's
//! name, type, description and constraints). Documented in `docs/analysis.md`, "Exports".
//!
//! The sessions are read one at a time and dropped, and whether BT.500 screening rejects a
//! subject is known only once every session is in: each session's rows are encoded by its
//! reader thread before its turn, appended to a spool file in the temporary folder as it is
//! taken, and copied into the export once the analysis is done, the screening's column filled
//! in. Memory holds each row's length, no row. A report killed before it ends leaves its
//! spool (`study-report-<pid>-<n>-trials_tidy.csv`) behind; every other ending removes it.

use std::collections::{BTreeSet, HashMap};
use std::fs::File;
use std::io::{self, BufWriter, Read, Seek, Write};
use std::path::PathBuf;

use analysis::exclusions::SessionExclusion;
use analysis::export::{Column, ColumnType, Resource};
use protocols::manifest::{REFERENCE_CODEC, Stimulus};
use protocols::study::{FieldKind, SubjectField};
use protocols::{Answer, Block, Position, StudyDefinition, TrialRecord};
use results::SessionResults;
use results::store::SessionState;

/// The export's file name.
pub(crate) const TIDY_FILE: &str = "trials_tidy.csv";
/// Its data dictionary's file name.
pub(crate) const PACKAGE_FILE: &str = "datapackage.json";

/// The prefix of a subject field's column (`subject_age`).
const FIELD_PREFIX: &str = "subject_";

fn flag(v: bool) -> &'static str {
    if v { "TRUE" } else { "FALSE" }
}

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

fn state(s: SessionState) -> &'static str {
    match s {
        SessionState::Running => "running",
        SessionState::Interrupted => "interrupted",
        SessionState::Complete => "complete",
        SessionState::TimeLimit => "time_limit",
    }
}

/// Every position's name in files, the MUSHRA panes included.
fn positions() -> Vec<&'static str> {
    [
        Position::Left,
        Position::Right,
        Position::First,
        Position::Second,
        Position::A,
        Position::B,
        Position::Hidden,
        Position::Neither,
    ]
    .into_iter()
    .chain((0..protocols::MAX_PANES).filter_map(Position::pane))
    .map(Position::as_str)
    .collect()
}

/// The column of subject field `f`.
fn field_column(f: &SubjectField) -> Column {
    let name = format!("{FIELD_PREFIX}{}", f.name);
    let what = format!(
        "The subject's answer to \"{}\" (session.json's subject_fields",
        f.label
    );
    match &f.kind {
        FieldKind::Text => Column::new(name, ColumnType::String, format!("{what}; free text).")),
        FieldKind::Number { min, max, integer } => Column::new(
            name,
            if *integer {
                ColumnType::Integer
            } else {
                ColumnType::Number
            },
            format!("{what}; a number; empty when not given or out of range)."),
        )
        .within(*min, *max),
        FieldKind::Choice { .. } | FieldKind::YesNo => Column::new(
            name,
            ColumnType::String,
            format!("{what}; one of its options)."),
        )
        .one_of(f.options()),
    }
}

/// The export's columns for `study`, in order: the fixed ones, with one per subject field
/// after `subject`.
#[expect(
    clippy::too_many_lines,
    reason = "one entry per column: the data dictionary"
)]
pub(crate) fn columns(study: &StudyDefinition) -> Vec<Column> {
    use ColumnType::{Boolean, Integer, Number, String};
    let mut c = vec![
        Column::new("study", String, "The study's name.").required(),
        Column::new("subject", String, "Subject id.").required(),
    ];
    c.extend(study.session.subject_fields.iter().map(field_column));
    let groups: Vec<&str> = study
        .design
        .groups
        .iter()
        .map(|g| g.name.as_str())
        .collect();
    let mut group = Column::new(
        "group",
        String,
        "Between-subject group the session was assigned ([[design.groups]]); empty without groups.",
    );
    if !groups.is_empty() {
        group = group.one_of(groups);
    }
    c.extend([
        Column::new("session", Integer, "The subject's session number (1-based).")
            .required()
            .at_least(1.0),
        Column::new(
            "session_status",
            String,
            "How the session ended: complete, time_limit, interrupted or running (an incomplete session is reported with --allow-incomplete).",
        )
        .required()
        .one_of(["complete", "time_limit", "interrupted", "running"]),
        group,
        Column::new("protocol", String, "The study's method.")
            .required()
            .one_of([study.protocol.as_str()]),
        Column::new("trial_index", Integer, "0-based index of the trial in its session.")
            .required()
            .at_least(0.0),
        Column::new(
            "block",
            String,
            "familiarization (practice, not analysed), test, or hidden_repeat (a test trial shown again).",
        )
        .required()
        .one_of(["familiarization", "test", "hidden_repeat"]),
        Column::new("practice", Boolean, "A familiarization (practice) trial.").required(),
        Column::new("hidden_repeat", Boolean, "A hidden repeat of a test trial (a name R can read: `repeat` is reserved).").required(),
        Column::new(
            "catch",
            Boolean,
            "A catch (gold) trial of [crowdsourcing] gold: a test trial of a gold stimulus.",
        )
        .required(),
        Column::new("break_before", Boolean, "A rest break came before the trial.").required(),
        Column::new(
            "condition",
            String,
            "The trial's condition label: the test stimulus id, the staircase's name, or a pair comparison's pair.",
        )
        .required(),
        Column::new(
            "staircase",
            Integer,
            "Staircase track index (0-based); empty outside staircases.",
        )
        .at_least(0.0),
        Column::new(
            "level",
            Number,
            "The staircase level of the trial (the study's staircase parameter); empty outside staircases.",
        ),
        Column::new("stimulus", String, "The test (rated, compared) stimulus id.").required(),
        Column::new(
            "clip",
            String,
            "The stimulus' source clip (a crowd scene: its distance level); empty when the stimulus is not in the manifest.",
        ),
        Column::new(
            "codec",
            String,
            "The stimulus' codec (reference for the unprocessed source); empty when unknown.",
        ),
        Column::new(
            "method",
            String,
            "The codec with its varied parameters (as the report's tables label it); empty when unknown.",
        ),
        Column::new(
            "codec_params",
            String,
            "The stimulus' codec parameters as key=value;key=value (keys sorted): the encoding the runner logged for the trial, else the manifest's.",
        ),
        Column::new("target_cr", Number, "The compression ratio the stimulus was made for, on the stimulus manifest's cr_basis (every channel of the file unless it says seed); empty when none.")
            .at_least(0.0),
        Column::new(
            "compression_ratio",
            Number,
            "Compression ratio reached, x of x:1 (1 for a reference), on the same basis as target_cr (a live staircase's: every channel of the file).",
        )
        .at_least(0.0),
        Column::new(
            "rms_cm",
            Number,
            "Joint position RMS error of the stimulus against its reference, cm.",
        )
        .at_least(0.0),
        Column::new(
            "is_reference",
            Boolean,
            "The test stimulus is the unprocessed reference (a hidden reference); empty when the stimulus is not in the manifest.",
        ),
        Column::new(
            "reference",
            String,
            "The reference stimulus id (a pair comparison: the pair's other stimulus).",
        )
        .required(),
        Column::new("arrangement", String, "How the two stimuli were laid out.")
            .required()
            .one_of(["side_by_side", "sequential", "abab", "single", "grid"]),
        Column::new(
            "reference_position",
            String,
            "Where the reference (or the pair's other stimulus) was shown: the side, interval, DSCQS slot or MUSHRA pane; hidden when not shown.",
        )
        .required()
        .one_of(positions()),
        Column::new("rating", Number, "The rating given (one-rating methods); empty otherwise."),
        Column::new("rating_a", Number, "DSCQS: the rating of slot A (the first stimulus)."),
        Column::new("rating_b", Number, "DSCQS: the rating of slot B (the second stimulus)."),
        Column::new(
            "choice",
            String,
            "The position chosen (2AFC, pair comparison; neither: no preference).",
        )
        .one_of(positions()),
        Column::new(
            "score",
            Number,
            "The engine's score: the rating (MOS, ACR, DCR, MUSHRA, CCR), reference minus test (DSCQS), 1 correct / 0 wrong (staircase), 1 when the stimulus was preferred (pair comparison).",
        )
        .required(),
        Column::new("score_reference", Number, "DSCQS: the reference's rating."),
        Column::new("score_test", Number, "DSCQS: the test stimulus' rating."),
        Column::new("correct", Boolean, "Staircase: the original was picked."),
        Column::new("reversal", Boolean, "Staircase: the trial was a reversal point."),
        Column::new(
            "response_time_ms",
            Integer,
            "Time from the end of the presentation to the answer, ms.",
        )
        .required()
        .at_least(0.0),
        Column::new("replays", Integer, "Times the subject replayed the stimuli.")
            .required()
            .at_least(0.0),
        Column::new("dropped_frames", Integer, "Frames the display dropped during the trial.")
            .required()
            .at_least(0.0),
        Column::new(
            "frames_shown",
            Integer,
            "Frames presented while the trial was on screen (the study window); empty for simulated sessions.",
        )
        .at_least(0.0),
        Column::new(
            "interval_sd_ms",
            Number,
            "Standard deviation of the intervals between the frames shown, ms; empty for simulated sessions.",
        )
        .at_least(0.0),
        Column::new(
            "elapsed_ms",
            Integer,
            "Session clock at the answer (the time limit's), ms.",
        )
        .required()
        .at_least(0.0),
        Column::new("wall_clock_ms", Integer, "Wall-clock time of the answer, ms since the Unix epoch.")
            .required()
            .at_least(0.0),
        Column::new(
            "monotonic_ms",
            Integer,
            "Monotonic clock of the answer, ms since the runner started the session.",
        )
        .required()
        .at_least(0.0),
        Column::new(
            "page_hidden",
            Boolean,
            "study serve: the page was hidden during the trial's stimuli; empty for other sessions.",
        ),
        Column::new(
            "gold_passed",
            Boolean,
            "A catch (gold) trial's verdict: the answer lay in the gold range; empty for other trials.",
        ),
        Column::new(
            "session_excluded",
            Boolean,
            "The session failed more gold trials than [crowdsourcing] allows: left out of every statistic.",
        )
        .required(),
        Column::new(
            "trial_excluded",
            Boolean,
            "The trial is left out of every statistic: its session is excluded, or the page was hidden during it and [crowdsourcing] hidden = \"exclude\".",
        )
        .required(),
        Column::new(
            "screened_out",
            Boolean,
            "BT.500 Annex 2 screening rejected the subject (the report's \"without rejected observers\" tables leave them out); empty where the report ran no screening.",
        ),
    ]);
    c
}

/// A session's tidy rows, encoded by a reader thread before its turn ([`Encoder::encode`]):
/// every column but the last (the screening's verdict), each row ending in `\n`.
pub(crate) struct Encoded {
    bytes: Vec<u8>,
    /// Each row's length in `bytes`, its `\n` included.
    rows: Vec<u32>,
    /// The rows' subject.
    subject: String,
    /// Why the rows could not be encoded.
    failed: Option<String>,
}

/// What encodes a session's rows: the study, and the columns of each stimulus of its
/// manifest, made once. Shared by the reader threads.
pub(crate) struct Encoder<'a> {
    study: &'a StudyDefinition,
    stimuli: HashMap<&'a str, [String; 8]>,
    /// Each trial's time before answers open, which its answer is checked against.
    answer_times: &'a lab::answer_times::AnswerTimes<'a>,
}

impl<'a> Encoder<'a> {
    pub(crate) fn new(
        study: &'a StudyDefinition,
        answer_times: &'a lab::answer_times::AnswerTimes<'a>,
    ) -> Self {
        Encoder {
            study,
            answer_times,
            stimuli: study
                .manifest
                .stimuli
                .iter()
                .map(|s| (s.id.as_str(), stimulus_fields(s)))
                .collect(),
        }
    }

    /// What the study's `[crowdsourcing]` rules decide about session `s`, and its rows.
    pub(crate) fn prepare(&self, s: &SessionResults) -> (SessionExclusion, Encoded) {
        let exclusion =
            analysis::exclusions::session_exclusion(s, &self.study.crowdsourcing, &|r| {
                self.answer_times.need_ms(r)
            });
        let rows = self.encode(s, &exclusion);
        (exclusion, rows)
    }

    /// Session `s`'s rows, with what the study's `[crowdsourcing]` rules decided about it
    /// (`exclusion`).
    fn encode(&self, s: &SessionResults, exclusion: &SessionExclusion) -> Encoded {
        let session = session_fields(self.study, s);
        let mut row = Row {
            out: csv::WriterBuilder::new()
                .has_headers(false)
                .terminator(csv::Terminator::Any(b'\n'))
                .from_writer(Vec::with_capacity(400 * s.trials.records.len())),
            scratch: String::new(),
        };
        let mut rows = Vec::with_capacity(s.trials.records.len());
        let mut end = 0;
        let mut failed = None;
        for r in &s.trials.records {
            let hidden = s
                .manifest
                .browser
                .as_ref()
                .map(|b| b.hidden_trials.contains(&r.trial.index));
            let written = (|| -> csv::Result<usize> {
                for f in &session {
                    row.text(f)?;
                }
                trial_fields(&mut row, self.study, &self.stimuli, r)?;
                row.flag(hidden)?;
                row.flag(
                    self.study
                        .crowdsourcing
                        .gold_verdict(r)
                        .map(|(_, passed)| passed),
                )?;
                row.flag(Some(exclusion.excluded))?;
                row.flag(Some(
                    exclusion.excluded || exclusion.hidden_trials.contains(&r.trial.index),
                ))?;
                row.out.write_record(None::<&[u8]>)?;
                row.out.flush()?;
                Ok(row.out.get_ref().len())
            })();
            match written.map(|at| (at, u32::try_from(at - end))) {
                Ok((at, Ok(len))) => {
                    rows.push(len);
                    end = at;
                }
                Ok((_, Err(_))) => {
                    failed = Some(format!("{}: a row over 4 GB", s.dir.display()));
                    break;
                }
                Err(e) => {
                    failed = Some(format!("{}: {e}", s.dir.display()));
                    break;
                }
            }
        }
        let bytes = row.out.into_inner().unwrap_or_default();
        Encoded {
            bytes,
            rows,
            subject: s.manifest.subject.clone(),
            failed,
        }
    }
}

/// The tidy rows of the sessions taken so far, in session order, in a spool file (removed on
/// drop); in memory only each row's length and each session's subject.
pub(crate) struct Spool {
    path: PathBuf,
    file: Option<BufWriter<File>>,
    /// Each session's subject and row count, in order.
    sessions: Vec<(String, usize)>,
    /// Every row's length, in order.
    rows: Vec<u32>,
    /// The first error encoding or writing the spool; every later session is skipped.
    failed: Option<io::Error>,
}

impl Drop for Spool {
    fn drop(&mut self) {
        self.file = None;
        let _ = std::fs::remove_file(&self.path);
    }
}

/// A spool's name of its own in the temporary folder.
fn spool_path() -> PathBuf {
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    std::env::temp_dir().join(format!(
        "study-report-{}-{n}-{TIDY_FILE}",
        std::process::id()
    ))
}

impl Spool {
    /// An empty spool, a new file in the temporary folder.
    pub(crate) fn new() -> Self {
        let path = spool_path();
        let opened = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path);
        let (file, failed) = match opened {
            Ok(file) => (Some(BufWriter::with_capacity(1 << 16, file)), None),
            Err(e) => (
                None,
                Some(io::Error::new(
                    e.kind(),
                    format!("{}: create: {e}", path.display()),
                )),
            ),
        };
        Spool {
            path,
            file,
            sessions: Vec::new(),
            rows: Vec::new(),
            failed,
        }
    }

    /// Adds a session's rows, the next in session order.
    pub(crate) fn add(&mut self, encoded: Encoded) {
        if self.failed.is_some() {
            return;
        }
        if let Some(why) = encoded.failed {
            self.failed = Some(io::Error::other(why));
            return;
        }
        let Some(file) = self.file.as_mut() else {
            return;
        };
        if let Err(e) = file.write_all(&encoded.bytes) {
            self.failed = Some(io::Error::new(
                e.kind(),
                format!("{}: write: {e}", self.path.display()),
            ));
            return;
        }
        self.sessions.push((encoded.subject, encoded.rows.len()));
        self.rows.extend(encoded.rows);
    }

    /// Writes the export of `study`'s sessions to `out`: the header and every spooled row,
    /// its last column the screening's verdict on its subject (`screened`: the rejected
    /// subjects' ids; `None` where no screening ran).
    ///
    /// # Errors
    /// The first error encoding, writing or reading the spool, or writing `out`.
    pub(crate) fn write(
        mut self,
        out: impl Write,
        study: &StudyDefinition,
        screened: Option<&BTreeSet<String>>,
    ) -> io::Result<()> {
        if let Some(e) = self.failed.take() {
            return Err(e);
        }
        let Some(file) = self.file.take() else {
            return Err(io::Error::other("the tidy spool is gone"));
        };
        let mut file = file.into_inner().map_err(io::IntoInnerError::into_error)?;
        file.rewind()?;
        let mut spool = io::BufReader::with_capacity(1 << 16, file);
        let mut out = BufWriter::with_capacity(1 << 16, out);
        let mut header = csv::WriterBuilder::new()
            .terminator(csv::Terminator::Any(b'\n'))
            .from_writer(Vec::new());
        header.write_record(columns(study).iter().map(|c| c.name.as_str()))?;
        header.flush()?;
        out.write_all(header.get_ref())?;
        let mut rows = self.rows.iter();
        let mut row = Vec::new();
        for (subject, n) in &self.sessions {
            // The last column, and the row's end.
            let last: &[u8] = match screened.map(|rejected| rejected.contains(subject)) {
                Some(true) => b",TRUE\n",
                Some(false) => b",FALSE\n",
                None => b",\n",
            };
            for len in rows.by_ref().take(*n) {
                row.resize(*len as usize, 0);
                spool.read_exact(&mut row)?;
                out.write_all(&row[..row.len() - 1])?;
                out.write_all(last)?;
            }
        }
        out.flush()
    }
}

/// A spool row being written, a field at a time, the fields borrowed or formatted into one
/// reused string.
struct Row {
    out: csv::Writer<Vec<u8>>,
    scratch: String,
}

impl Row {
    fn text(&mut self, v: &str) -> csv::Result<()> {
        self.out.write_field(v)
    }
    fn value(&mut self, v: impl std::fmt::Display) -> csv::Result<()> {
        use std::fmt::Write as _;
        self.scratch.clear();
        let _ = write!(self.scratch, "{v}");
        self.out.write_field(&self.scratch)
    }
    fn opt(&mut self, v: Option<impl std::fmt::Display>) -> csv::Result<()> {
        match v {
            Some(v) => self.value(v),
            None => self.text(""),
        }
    }
    fn flag(&mut self, v: Option<bool>) -> csv::Result<()> {
        self.text(v.map_or("", flag))
    }
}

/// The columns from `study` to `protocol` of every row of session `s`.
fn session_fields(study: &StudyDefinition, s: &SessionResults) -> Vec<String> {
    let m = &s.manifest;
    let mut row = vec![m.study.clone(), m.subject.clone()];
    for f in &study.session.subject_fields {
        // A value as the field stores it; one that does not pass the field's check (a
        // session recorded under another version of the study) is missing.
        row.push(
            m.subject_fields
                .get(&f.name)
                .and_then(|v| f.check(v).ok())
                .unwrap_or_default(),
        );
    }
    row.extend([
        m.session.to_string(),
        state(m.status).to_owned(),
        m.group.clone().unwrap_or_default(),
        m.protocol.as_str().to_owned(),
    ]);
    row
}

/// The columns from `clip` to `is_reference` of a stimulus of the manifest, made once per
/// stimulus.
fn stimulus_fields(s: &Stimulus) -> [String; 8] {
    [
        s.clip.clone(),
        s.codec.clone(),
        s.method(),
        results::trials::format_codec_params(&s.params).unwrap_or_default(),
        opt(s.target_cr),
        opt(s.achieved_cr),
        opt(s.metrics.map(|m| m.rms_cm)),
        flag(s.codec == REFERENCE_CODEC).to_owned(),
    ]
}

/// The columns from `trial_index` to `monotonic_ms` of trial row `r`; `stimuli` holds each
/// manifest stimulus' columns.
fn trial_fields(
    row: &mut Row,
    study: &StudyDefinition,
    stimuli: &HashMap<&str, [String; 8]>,
    r: &TrialRecord,
) -> csv::Result<()> {
    let t = &r.trial;
    let o = &r.outcome;
    let catch =
        t.block != Block::Familiarization && study.crowdsourcing.gold_of(&t.stimulus).is_some();
    row.value(t.index)?;
    row.text(t.block.as_str())?;
    row.flag(Some(t.block == Block::Familiarization))?;
    row.flag(Some(t.block == Block::HiddenRepeat))?;
    row.flag(Some(catch))?;
    row.flag(Some(t.break_before))?;
    row.text(&t.condition)?;
    row.opt(t.staircase)?;
    row.opt(t.level)?;
    row.text(&t.stimulus)?;
    let known = stimuli.get(t.stimulus.as_str());
    let field = |i: usize| known.map_or("", |f| f[i].as_str());
    match &r.encoding {
        None => {
            for i in 0..8 {
                row.text(field(i))?;
            }
        }
        // What the runner logged for the trial (a live staircase, a crowd scene) comes
        // first.
        Some(e) => {
            for i in 0..3 {
                row.text(field(i))?;
            }
            row.text(&results::trials::format_codec_params(&e.codec_params).unwrap_or_default())?;
            row.text(field(4))?;
            row.value(e.achieved_cr)?;
            row.value(e.rms_cm)?;
            row.text(field(7))?;
        }
    }
    row.text(&t.reference)?;
    row.text(t.arrangement.as_str())?;
    row.text(t.reference_position.as_str())?;
    let (rating, a, b, choice) = match r.response.answer {
        Answer::Rating(v) => (Some(v), None, None, None),
        Answer::Pair { a, b } => (None, Some(a), Some(b), None),
        Answer::Choice(p) => (None, None, None, Some(p.as_str())),
    };
    row.opt(rating)?;
    row.opt(a)?;
    row.opt(b)?;
    row.text(choice.unwrap_or_default())?;
    row.value(o.score)?;
    row.opt(o.score_reference)?;
    row.opt(o.score_test)?;
    row.flag(o.correct)?;
    row.flag(o.reversal)?;
    row.value(r.response.response_time_ms)?;
    row.value(r.response.replays)?;
    row.value(r.response.dropped_frames)?;
    row.opt(r.timing.map(|x| x.frames_shown))?;
    row.opt(r.timing.map(|x| x.interval_sd_ms))?;
    row.value(r.elapsed_ms)?;
    row.value(r.wall_clock_ms)?;
    row.value(r.monotonic_ms)
}

/// `datapackage.json` for `study`'s exports: `ratings.csv` and the tidy trials.
pub(crate) fn data_package(study: &StudyDefinition) -> String {
    let tidy = columns(study);
    let ratings = analysis::export::ratings_columns();
    analysis::export::data_package(
        &study.name,
        &format!("Study {}: trials and ratings", study.name),
        &[
            Resource {
                path: TIDY_FILE,
                description: "One row per trial of every session reported, practice trials and excluded sessions included, with the subject's fields, the condition's parts, the answer, its timing and the report's exclusions.",
                columns: &tidy,
            },
            Resource {
                path: "ratings.csv",
                description: "One row per rating the analysis takes (MOS-style ratings; excluded sessions and trials left out).",
                columns: &ratings,
            },
        ],
    )
}
