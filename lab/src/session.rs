//! One subject's session in a results store (a folder or a database,
//! [`results::backend::Store`]): open or resume it, replay the logged responses into the
//! protocol engine, then commit each new response (fsynced, or committed by the database)
//! before the next trial is asked for. The study window and simulation both use it; it knows
//! nothing of drawing or of observers.
//!
//! An answer the store could not take because the database was unreachable stays in the
//! recorder ([`Recorder::pending`]) and no next trial is given until
//! [`Recorder::commit_pending`] has committed it.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use protocols::{
    Answer, FrameTiming, Outcome, Response, Session, SessionStatus, StimulusEncoding,
    StudyDefinition, Trial, TrialRecord,
};
use results::backend::{Found, SessionWriter, Store};
use results::store::SessionState;
use results::{ResultsError, SessionManifest};

use crate::error::{Context as _, LabError, Result, refused};

/// A subject's plan index: stable for an id and session, different between subjects (FNV-1a
/// of `subject/session`).
pub fn subject_index(subject: &str, session: u32) -> u32 {
    let mut h: u32 = 0x811c_9dc5;
    for b in subject.bytes().chain(format!("/{session}").bytes()) {
        h ^= u32::from(b);
        h = h.wrapping_mul(0x0100_0193);
    }
    h
}

/// Checks a subject id: 1-64 letters, digits, `-` or `_` (it names a folder).
///
/// # Errors
/// Any other id.
pub fn check_subject(id: &str) -> Result<()> {
    if id.is_empty()
        || id.len() > 64
        || !id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(refused(format!(
            "--subject {id:?}: use 1-64 letters, digits, '-' or '_' (it names a folder)"
        )));
    }
    Ok(())
}

/// The folder of `subject`'s session `session` inside a results directory.
pub fn session_dir(results: &Path, subject: &str, session: u32) -> PathBuf {
    results.join(results::backend::session_name(subject, session))
}

/// Runs `f` until it succeeds or fails for another reason than an unreachable database,
/// waiting for the database up to `patience`; `say` gets one line when it goes away and one
/// when it is back.
///
/// # Errors
/// `f`'s error, or the outage when it lasts longer than `patience`.
pub fn retry_outage<T>(
    patience: Duration,
    say: &mut dyn FnMut(&str),
    mut f: impl FnMut() -> Result<T>,
) -> Result<T> {
    let start = Instant::now();
    let mut told = false;
    loop {
        match f() {
            Ok(v) => {
                if told {
                    say(&format!(
                        "the results database is back after {:.1} s; continuing",
                        start.elapsed().as_secs_f64()
                    ));
                }
                return Ok(v);
            }
            Err(e) if is_outage(&e) && start.elapsed() < patience => {
                if !told {
                    say(&format!(
                        "{}; waiting for it (up to {} s)",
                        crate::error::chain(&e),
                        patience.as_secs()
                    ));
                    told = true;
                }
                std::thread::sleep(Duration::from_millis(250));
            }
            Err(e) => return Err(e),
        }
    }
}

/// Per-frame presentation intervals of a window session, beside `trials.csv`.
pub use results::backend::FRAMES_FILE;

/// Whether `e` (or an error it wraps) says that the results database cannot be reached: the
/// answer is kept and can be committed when it is back.
pub fn is_outage(e: &LabError) -> bool {
    match e {
        LabError::Results(ResultsError::Unavailable { .. }) => true,
        LabError::Context { source, .. } => is_outage(source),
        _ => false,
    }
}

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// Who a new session is for: the manifest fields that differ between sessions.
pub struct SessionOf<'a> {
    /// Hash of the study file's bytes.
    pub study_hash: &'a str,
    /// Hash of the stimulus manifest.
    pub manifest_hash: &'a str,
    /// Subject id.
    pub subject: String,
    /// Subject index (the plan's randomisation).
    pub subject_index: u32,
    /// Session number of this subject.
    pub session: u32,
    /// Seed of the simulated observer; `None` for a real subject.
    pub observer_seed: Option<u64>,
    /// The between-subject group the session was assigned ([`assign_group`]); `None` for a
    /// study without groups.
    pub group: Option<String>,
}

/// The manifest of a new, running session of `study`; everything else starts empty.
pub fn new_manifest(study: &StudyDefinition, of: SessionOf<'_>) -> SessionManifest {
    SessionManifest {
        format_version: results::store::MANIFEST_FORMAT_VERSION,
        study: study.name.clone(),
        study_hash: of.study_hash.to_string(),
        manifest_hash: Some(of.manifest_hash.to_string()),
        protocol: study.protocol,
        subject: of.subject,
        subject_index: of.subject_index,
        session: of.session,
        plan_seed: study.seed,
        observer_seed: of.observer_seed,
        software_version: env!("CARGO_PKG_VERSION").into(),
        subject_fields: std::collections::BTreeMap::new(),
        started_ms: now_ms(),
        ended_ms: None,
        status: SessionState::Running,
        trials_logged: 0,
        not_shown: Vec::new(),
        thresholds: Vec::new(),
        resumes: 0,
        torn_rows: Vec::new(),
        display: None,
        browser: None,
        // Unconfirmed until the experimenter confirms the study's viewing conditions.
        viewing: study
            .viewing
            .as_ref()
            .map(|_| results::ViewingRecord::default()),
        group: of.group,
    }
}

/// The between-subject group of a session of `study` (`None` for a study without groups),
/// with the subject index that balances within the group: `subject_index` when given, else
/// the session's place in its group (its k-th session takes row k of a Latin square). The
/// store assigns the group once ([`Store::assign_group`]), so a resumed session, on any
/// station, gets the same; `wanted` asks for one group (refused when it is full).
///
/// # Errors
/// The store's: the wanted group is not the study's or is full, every group is full, or the
/// store cannot be read or written.
pub fn assign_group(
    study: &StudyDefinition,
    store: &mut dyn Store,
    subject: &str,
    session: u32,
    wanted: Option<&str>,
    subject_index: Option<u32>,
) -> Result<(Option<String>, u32)> {
    let fallback = || subject_index.unwrap_or_else(|| self::subject_index(subject, session));
    if study.design.groups.is_empty() {
        if let Some(w) = wanted {
            return Err(refused(format!(
                "--group {w:?}: study {:?} has no between-subject groups ([[design.groups]])",
                study.name
            )));
        }
        return Ok((None, fallback()));
    }
    let groups: Vec<results::backend::GroupQuota<'_>> = study
        .design
        .groups
        .iter()
        .map(|g| results::backend::GroupQuota {
            name: &g.name,
            quota: g.quota,
        })
        .collect();
    let a = store.assign_group(subject, session, &groups, wanted)?;
    if let Some(w) = wanted
        && w != a.group
    {
        return Err(refused(format!(
            "{}: session {session} of {subject:?} was assigned group {:?} before; it stays in it \
             (leave out --group, or give --group {})",
            store.location(),
            a.group,
            a.group
        )));
    }
    Ok((Some(a.group), subject_index.unwrap_or(a.ordinal)))
}

/// Whose session [`open_subject`] opens, and how.
#[derive(Debug, Clone, Copy)]
pub struct SessionFor<'a> {
    /// The subject's id.
    pub subject: &'a str,
    /// The subject's session number.
    pub session: u32,
    /// The between-subject group asked for (`study run --group`); `None`: the store assigns
    /// one in a study with groups.
    pub group: Option<&'a str>,
    /// The plan's subject index when the caller fixes it (`--subject-index`, a participant's
    /// plan group, a simulated subject's number); `None`: the session's place in its group,
    /// or in a study without groups one derived from the id ([`subject_index`]).
    pub subject_index: Option<u32>,
    /// The simulated observer's seed; `None` for a real subject.
    pub observer_seed: Option<u64>,
    /// Continue the session if it was begun (a finished one is returned as such).
    pub resume: bool,
}

/// Opens `who`'s session of `study` in `store`, the one way the window, `study serve` and
/// simulation open a session: the between-subject group assigned ([`assign_group`]), then
/// the session created, or resumed by replay ([`Recorder::open`]). `fill` completes the
/// manifest of a new session (what a simulated subject states). Returns the session and its
/// group.
///
/// # Errors
/// As [`assign_group`] and [`Recorder::open`].
pub fn open_subject(
    study: &crate::StudyFile,
    store: &mut dyn Store,
    who: &SessionFor<'_>,
    fill: &dyn Fn(&mut SessionManifest),
) -> Result<(Opened, Option<String>)> {
    let def = &study.definition;
    let (group, index) = assign_group(
        def,
        store,
        who.subject,
        who.session,
        who.group,
        who.subject_index,
    )?;
    let mut fresh = new_manifest(
        def,
        SessionOf {
            study_hash: &study.hash,
            manifest_hash: &study.manifest_hash,
            subject: who.subject.to_owned(),
            subject_index: index,
            session: who.session,
            observer_seed: who.observer_seed,
            group: group.clone(),
        },
    );
    fill(&mut fresh);
    let opened = Recorder::open(def, index, store, who.resume, fresh)?;
    Ok((opened, group))
}

/// Refuses to resume the session recorded in `path` (`old`) as the one `fresh` describes
/// when they are not the same session of the same study: study name and file hash, stimulus
/// manifest hash, protocol, subject, plan and seeds.
fn check_same_session(path: &Path, old: &SessionManifest, fresh: &SessionManifest) -> Result<()> {
    let mut differ = Vec::new();
    let mut field = |name: &str, was: String, now: String| {
        if was != now {
            differ.push(format!("{name} {was} (now {now})"));
        }
    };
    field(
        "study",
        format!("{:?}", old.study),
        format!("{:?}", fresh.study),
    );
    field(
        "study file hash",
        old.study_hash.clone(),
        fresh.study_hash.clone(),
    );
    // Sessions written before the manifest hash was recorded have none to compare.
    if let Some(was) = &old.manifest_hash {
        field(
            "stimulus manifest hash",
            was.clone(),
            fresh.manifest_hash.clone().unwrap_or_default(),
        );
    }
    field(
        "protocol",
        old.protocol.to_string(),
        fresh.protocol.to_string(),
    );
    field(
        "subject",
        format!("{:?}", old.subject),
        format!("{:?}", fresh.subject),
    );
    field(
        "subject index",
        old.subject_index.to_string(),
        fresh.subject_index.to_string(),
    );
    field(
        "session",
        old.session.to_string(),
        fresh.session.to_string(),
    );
    field(
        "study seed",
        old.plan_seed.to_string(),
        fresh.plan_seed.to_string(),
    );
    field(
        "observer seed",
        format!("{:?}", old.observer_seed),
        format!("{:?}", fresh.observer_seed),
    );
    field(
        "group",
        format!("{:?}", old.group),
        format!("{:?}", fresh.group),
    );
    if differ.is_empty() {
        return Ok(());
    }
    Err(refused(format!(
        "{}: cannot resume: recorded with {}; resume with the study file and stimuli the session was started with",
        path.display(),
        differ.join(", ")
    )))
}

/// A logged row must belong to the session being resumed.
pub(crate) fn check_row_identity(
    rec: &TrialRecord,
    m: &SessionManifest,
) -> std::result::Result<(), String> {
    if rec.study != m.study || rec.subject != m.subject || rec.session != m.session {
        return Err(format!(
            "the row is of study {:?}, subject {:?}, session {}; this session is study {:?}, subject {:?}, session {}",
            rec.study, rec.subject, rec.session, m.study, m.subject, m.session
        ));
    }
    if rec.protocol != m.protocol {
        return Err(format!(
            "the row is a {} trial; this session is {}",
            rec.protocol, m.protocol
        ));
    }
    Ok(())
}

/// A live staircase's row must log the codec parameters the study asks for at its level: the
/// fixed ones and the level's own.
pub(crate) fn check_live_params(
    study: &StudyDefinition,
    rec: &TrialRecord,
) -> std::result::Result<(), String> {
    let Some((param, fixed)) = study
        .staircase
        .as_ref()
        .and_then(|s| s.live.as_ref().map(|l| (s.param.as_str(), &l.params)))
    else {
        return Ok(());
    };
    let Some(level) = rec.trial.level else {
        return Ok(());
    };
    let Some(enc) = &rec.encoding else {
        return Err("a live staircase trial without its codec parameters".into());
    };
    let wanted = fixed
        .iter()
        .map(|(k, v)| (k.as_str(), *v))
        .chain(std::iter::once((param, level)));
    for (k, want) in wanted {
        match enc.codec_params.get(k) {
            // Both are the exact values written by the shortest round-trip formatting.
            Some(got) if got.to_bits() == want.to_bits() => {}
            got => {
                return Err(format!(
                    "codec parameter {k:?} logged as {got:?}, the study gives {want}"
                ));
            }
        }
    }
    Ok(())
}

/// An open session: the engine, its writer and its manifest.
pub struct Recorder {
    engine: Session,
    log: Box<dyn SessionWriter>,
    manifest: SessionManifest,
    /// An answer scored but not yet committed (the database was unreachable).
    pending: Option<TrialRecord>,
    /// The manifest changed while an answer was pending: written once it is committed.
    manifest_changed: bool,
    /// Frame intervals of answers not yet committed with them.
    pending_frames: Vec<(u32, Vec<f64>, Vec<String>)>,
    study: String,
    /// Session clock (ms) at which this process took over: the last logged trial's.
    clock_base_ms: u64,
    monotonic_base_ms: u64,
    started: Instant,
    /// The trial index and answer of the last row replayed when the session was opened.
    resumed_last: Option<(u32, Answer)>,
}

/// What opening a session found.
pub enum Opened {
    /// Ready for trials; `resumed` trials were replayed from the log.
    Ready {
        /// The session.
        recorder: Box<Recorder>,
        /// Trials replayed from an earlier run.
        resumed: u32,
    },
    /// The session was already finished.
    Finished(Box<SessionManifest>),
}

impl Recorder {
    /// Opens the session `fresh` describes (its subject and session number) in `store` for
    /// subject `subject_index` of `study`: creates it, or with `resume` continues an
    /// interrupted session there (a folder's torn last row is set aside and reported on
    /// stderr; the logged responses are replayed and must regenerate the logged trials).
    /// `fresh` is the manifest of a new session.
    ///
    /// # Errors
    /// The session exists without `resume`, a live runner holds it, the log cannot be read,
    /// or the study no longer regenerates the logged trials.
    pub fn open(
        study: &StudyDefinition,
        subject_index: u32,
        store: &mut dyn Store,
        resume: bool,
        fresh: SessionManifest,
    ) -> Result<Opened> {
        // A session of a between-subject group is planned over its group's conditions.
        let study = study.for_group(fresh.group.as_deref()).map_err(refused)?;
        let study = study.as_ref();
        let mut engine = Session::new(study, subject_index)?;
        let (subject, number) = (fresh.subject.clone(), fresh.session);
        let path = store.session_path(&subject, number);
        let found = store.find_session(&subject, number)?;
        let (log, logged, mut manifest) = match found {
            Found::Present(old) if resume => {
                let manifest_path = path.join(results::store::SESSION_FILE);
                if let Some(m) = &old {
                    check_same_session(&manifest_path, m, &fresh)?;
                }
                if let Some(m) = old.as_ref().filter(|m| {
                    matches!(m.status, SessionState::Complete | SessionState::TimeLimit)
                }) {
                    store.check_not_held(&subject, number)?;
                    return Ok(Opened::Finished(m.clone()));
                }
                let resumed = store.resume_session(&subject, number)?;
                let mut m = old.map_or(fresh, |m| *m);
                m.resumes += 1;
                m.status = SessionState::Running;
                m.ended_ms = None;
                if let Some((row, name)) = &resumed.torn {
                    eprintln!(
                        "warning: {}: line {} was torn ({} bytes, power cut mid-write?); set aside in {name}",
                        path.join(results::store::TRIALS_FILE).display(),
                        row.line,
                        row.bytes.len()
                    );
                    m.torn_rows.push(name.clone());
                }
                (resumed.writer, resumed.records, m)
            }
            Found::Present(_) => {
                return Err(refused(format!(
                    "{} already exists; results are never overwritten (use --resume to continue)",
                    path.display()
                )));
            }
            Found::Absent => (store.create_session(&fresh)?, Vec::new(), fresh),
        };
        let trials = path.join(results::store::TRIALS_FILE);
        for (i, rec) in logged.iter().enumerate() {
            // Line 1 is the header.
            let at = || format!("cannot resume: {} line {}", trials.display(), i + 2);
            check_row_identity(rec, &manifest)
                .and_then(|()| check_live_params(study, rec))
                .map_err(refused)
                .context(at)?;
            engine
                .replay(&rec.trial, &rec.response, &rec.outcome)
                .context(at)?;
        }
        let mut log = log;
        if manifest.resumes > 0 {
            // A new session's manifest was written with it.
            manifest.trials_logged = log.rows();
            log.write_manifest(&manifest)?;
        }
        let last = logged.last();
        Ok(Opened::Ready {
            resumed: logged.len() as u32,
            recorder: Box::new(Recorder {
                engine,
                log,
                study: study.name.clone(),
                manifest,
                pending: None,
                manifest_changed: false,
                pending_frames: Vec::new(),
                clock_base_ms: last.map_or(0, |r| r.elapsed_ms),
                monotonic_base_ms: last.map_or(0, |r| r.monotonic_ms),
                started: Instant::now(),
                resumed_last: last.map(|r| (r.trial.index, r.response.answer)),
            }),
        })
    }

    /// Where the session is, for messages (its folder, or its name in the database).
    pub fn path(&self) -> PathBuf {
        self.log.path()
    }

    /// Whether an answer is waiting to be committed (the database was unreachable): no next
    /// trial is given until [`Self::commit_pending`] has committed it.
    pub fn pending(&self) -> bool {
        self.pending.is_some()
    }

    /// Commits the answer (and its frame intervals) kept after an outage, if any.
    ///
    /// # Errors
    /// The database is still unreachable ([`is_outage`]; the answer stays kept), or the
    /// store refused it.
    pub fn commit_pending(&mut self) -> Result<()> {
        if let Some(record) = &self.pending {
            match self.log.append(record) {
                Ok(()) => {}
                Err(e @ ResultsError::Unavailable { .. }) => return Err(e.into()),
                Err(e) => {
                    // Refused, not unreachable: the session stops here (resumable). A folder
                    // may hold the row already, so it is never written twice.
                    self.pending = None;
                    return Err(e.into());
                }
            }
            // The row is the record; the manifest file keeps the count of its last write.
            self.manifest.trials_logged = self.log.rows();
            self.pending = None;
        }
        if self.manifest_changed {
            self.manifest.trials_logged = self.log.rows();
            self.log.write_manifest(&self.manifest)?;
            self.manifest_changed = false;
        }
        while let Some((index, intervals, phases)) = self.pending_frames.first() {
            let phases: Vec<&str> = phases.iter().map(String::as_str).collect();
            self.log.append_frames(*index, intervals, &phases)?;
            self.pending_frames.remove(0);
        }
        Ok(())
    }

    /// [`Self::commit_pending`] until it succeeds, as long as the database stays unreachable
    /// for less than `patience`; `say` gets one line when the outage starts and one when it
    /// ends (a simulated station's stderr).
    ///
    /// # Errors
    /// The store refused the answer, or the database stayed away longer than `patience` (the
    /// answer is lost with this process; the session resumes where its committed answers
    /// end).
    pub fn commit_waiting(&mut self, patience: Duration, say: &mut dyn FnMut(&str)) -> Result<()> {
        say(&format!(
            "{}: the answer is kept and is committed when the results database is back",
            self.path().display()
        ));
        retry_outage(patience, say, || self.commit_pending())
    }

    /// The session clock of the last logged trial (0 for a new session), ms.
    pub fn logged_clock_ms(&self) -> u64 {
        self.clock_base_ms
    }

    /// The session clock: time already logged plus this process's running time, ms.
    pub fn elapsed_ms(&self) -> u64 {
        self.clock_base_ms + self.started.elapsed().as_millis() as u64
    }

    /// Rows committed (replayed ones included).
    pub fn rows(&self) -> u32 {
        self.log.rows()
    }

    /// The trial index and answer of the last row the session held when it was opened
    /// (`None` for a new session): a repeated post of that answer is known again after a
    /// resume.
    pub fn resumed_last(&self) -> Option<(u32, Answer)> {
        self.resumed_last
    }

    /// Trials answered so far (including replayed ones).
    pub fn answered(&self) -> u32 {
        self.engine.answered()
    }

    /// The manifest as it stands (its `trials_logged` counts the rows committed so far,
    /// though the file is rewritten only when the session's state changes).
    pub fn manifest(&self) -> &SessionManifest {
        &self.manifest
    }

    /// Updates the manifest (display information, ...) and writes it (once the pending
    /// answer is committed, if one is waiting).
    ///
    /// # Errors
    /// The manifest cannot be written.
    pub fn update_manifest(&mut self, change: impl FnOnce(&mut SessionManifest)) -> Result<()> {
        change(&mut self.manifest);
        if self.pending.is_some() {
            self.manifest_changed = true;
            return Ok(());
        }
        self.manifest.trials_logged = self.log.rows();
        self.log.write_manifest(&self.manifest)?;
        self.manifest_changed = false;
        Ok(())
    }

    /// The next trial at session clock `elapsed_ms`, or `None` when the session is over.
    ///
    /// # Errors
    /// Engine errors (a staircase level without a stimulus).
    pub fn next_trial(&mut self, elapsed_ms: u64) -> Result<Option<Trial>> {
        if self.pending.is_some() {
            return Err(refused(format!(
                "{}: the last answer is not committed yet; no next trial before it is",
                self.path().display()
            )));
        }
        Ok(self.engine.next_trial(elapsed_ms)?)
    }

    /// The rest of the pending trial's MUSHRA screen, in pane order (the pending trial first;
    /// see `protocols::Session::screen`): what the window shows together.
    pub fn screen(&self) -> Vec<Trial> {
        self.engine.screen()
    }

    /// The trials that can follow the pending one (one per answer that leads somewhere
    /// different; see `protocols::Session::lookahead`), for preparing their stimuli early.
    pub fn lookahead(&self, elapsed_ms: u64) -> Vec<Trial> {
        self.engine.lookahead(elapsed_ms)
    }

    /// Scores `response` to the pending `trial` and commits the row (flushed and fsynced, or
    /// committed by the database) before returning: nothing can show the next stimulus before
    /// the answer is durable. The row is the record: `session.json` is not rewritten per
    /// answer (its `trials_logged` is the count at its last write; readers count the rows).
    /// `encoding` describes a stimulus encoded for this trial (live staircase), `timing` how
    /// the window's display kept time during it. When the database
    /// cannot be reached the answer is kept ([`Self::pending`]) and the error says so
    /// ([`is_outage`]).
    ///
    /// # Errors
    /// The engine refuses the response, an earlier answer is still pending, or the row cannot
    /// be committed.
    pub fn record(
        &mut self,
        trial: Trial,
        response: Response,
        elapsed_ms: u64,
        encoding: Option<StimulusEncoding>,
        timing: Option<FrameTiming>,
    ) -> Result<Outcome> {
        if self.pending.is_some() {
            return Err(refused(format!(
                "{}: the last answer is not committed yet",
                self.path().display()
            )));
        }
        let outcome = self.engine.respond(&response)?;
        self.pending = Some(TrialRecord {
            study: self.study.clone(),
            subject: self.manifest.subject.clone(),
            session: self.manifest.session,
            protocol: self.engine.protocol(),
            trial,
            response,
            outcome,
            elapsed_ms,
            wall_clock_ms: now_ms(),
            monotonic_ms: self.monotonic_base_ms + self.started.elapsed().as_millis() as u64,
            encoding,
            timing,
        });
        self.commit_pending()?;
        Ok(outcome)
    }

    /// Appends the presentation intervals of trial `index` to `frames.csv` of the session
    /// (`trial_index,interval_ms,phase`, one row per presented frame, `phases[k]` what frame
    /// `k` showed: `a`, `b`, `grey`, `both`, `answer`, ...), so every frame's timing is kept,
    /// not only the per-trial summary. A folder flushes without fsync: the answer itself is
    /// already on disk. While the answer is pending, they wait with it.
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn append_frame_intervals(
        &mut self,
        index: u32,
        intervals: &[f64],
        phases: &[&str],
    ) -> Result<()> {
        if self.pending.is_some() || !self.pending_frames.is_empty() {
            self.pending_frames.push((
                index,
                intervals.to_vec(),
                phases.iter().map(|p| (*p).to_owned()).collect(),
            ));
            return Ok(());
        }
        self.log.append_frames(index, intervals, phases)?;
        Ok(())
    }

    /// Marks the session interrupted (stopped on purpose before its end, resumable) and
    /// writes the manifest with the rows on disk.
    ///
    /// # Errors
    /// The manifest cannot be written.
    pub fn interrupt(&mut self) -> Result<()> {
        self.commit_pending()?;
        self.manifest.status = SessionState::Interrupted;
        self.manifest.trials_logged = self.log.rows();
        self.manifest.ended_ms = Some(now_ms());
        self.log.write_manifest(&self.manifest)?;
        Ok(())
    }

    /// Writes the final manifest once the engine says the session is over.
    ///
    /// # Errors
    /// The manifest cannot be written.
    pub fn finish(&mut self) -> Result<SessionState> {
        self.manifest.status = match self.engine.status() {
            SessionStatus::TimeLimit => SessionState::TimeLimit,
            SessionStatus::Complete | SessionStatus::Running => SessionState::Complete,
        };
        self.manifest.trials_logged = self.log.rows();
        self.manifest.ended_ms = Some(now_ms());
        self.manifest.not_shown = self
            .engine
            .not_shown()
            .into_iter()
            .map(|t| t.stimulus)
            .collect();
        self.manifest.thresholds = self.engine.thresholds();
        self.log.write_manifest(&self.manifest)?;
        Ok(self.manifest.status)
    }

    /// One line on how the session ended.
    pub fn summary(&self) -> String {
        let m = &self.manifest;
        let thresholds: Vec<String> = m
            .thresholds
            .iter()
            .map(|(n, t)| {
                format!(
                    "{n}={}",
                    t.map_or_else(|| "n/a".to_string(), |v| format!("{v:.4}"))
                )
            })
            .collect();
        format!(
            "{}: {:?}, {} trials{}{}",
            m.subject,
            m.status,
            m.trials_logged,
            if m.not_shown.is_empty() {
                String::new()
            } else {
                format!(", {} not shown", m.not_shown.len())
            },
            if thresholds.is_empty() {
                String::new()
            } else {
                format!(", thresholds {}", thresholds.join(" "))
            }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fsynced rows are the record: the manifest file is not rewritten per answer (its
    /// count is the one of its last write), the recorder's manifest counts every row, a
    /// display change writes the count, and a resume after a kill recounts the rows.
    #[test]
    fn the_rows_are_the_record_and_resume_recounts_them() {
        use protocols::Answer;
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/mos.toml");
        let study = crate::StudyFile::load(&path).unwrap();
        let d = &study.definition;
        let dir = std::env::temp_dir().join(format!("lab-session-rows-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let fresh = || {
            new_manifest(
                d,
                SessionOf {
                    study_hash: &study.hash,
                    manifest_hash: &study.manifest_hash,
                    subject: "S01".into(),
                    subject_index: 7,
                    session: 1,
                    observer_seed: None,
                    group: None,
                },
            )
        };
        let on_disk = || -> SessionManifest {
            results::store::read_manifest(&dir.join("S01_s1").join(results::store::SESSION_FILE))
                .unwrap()
        };
        let answer = |rec: &mut Recorder| {
            let trial = rec.next_trial(0).unwrap().unwrap();
            let response = protocols::Response {
                answer: Answer::Rating(d.scale.max),
                response_time_ms: 1,
                replays: 0,
                dropped_frames: 0,
            };
            rec.record(trial, response, 0, None, None).unwrap();
        };
        let mut store = results::FolderStore::new(&dir);
        let Opened::Ready { mut recorder, .. } =
            Recorder::open(d, 7, &mut store, false, fresh()).unwrap()
        else {
            panic!("a new session")
        };
        for _ in 0..3 {
            answer(&mut recorder);
        }
        assert_eq!(recorder.manifest().trials_logged, 3);
        assert_eq!(on_disk().trials_logged, 0, "not rewritten per row");
        recorder
            .update_manifest(|m| {
                m.subject_fields.insert("age".into(), "31".into());
            })
            .unwrap();
        assert_eq!(
            (on_disk().trials_logged, on_disk().subject_fields.len()),
            (3, 1)
        );
        answer(&mut recorder);
        assert_eq!(on_disk().trials_logged, 3);
        // Killed here: the lock goes with the process, the fourth row is on disk.
        drop(recorder);
        let Opened::Ready { recorder, resumed } =
            Recorder::open(d, 7, &mut store, true, fresh()).unwrap()
        else {
            panic!("an unfinished session")
        };
        assert_eq!((resumed, recorder.manifest().trials_logged), (4, 4));
        let m = on_disk();
        assert_eq!(
            (m.trials_logged, m.resumes, m.status),
            (4, 1, SessionState::Running)
        );
        drop(recorder);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn subject_ids_are_checked_and_indexed() {
        assert!(check_subject("S01_a-b").is_ok());
        for bad in ["", "../x", "a b", "s/1"] {
            assert!(check_subject(bad).is_err(), "{bad:?}");
        }
        // Stable across builds, not only within one: a resumed session replays the plan this
        // index seeded. FNV-1a 32 of "S01/1", computed independently in Python:
        // h = 0x811c9dc5; for b in b"S01/1": h = ((h ^ b) * 0x01000193) & 0xffffffff
        assert_eq!(subject_index("S01", 1), 0x12a5_671d);
        assert_ne!(subject_index("S01", 1), subject_index("S02", 1));
        assert_ne!(subject_index("S01", 1), subject_index("S01", 2));
    }
}
