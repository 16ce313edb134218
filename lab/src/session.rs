//! One subject's session on disk: open or resume the results folder, replay the logged
//! responses into the protocol engine, then log each new response (fsynced) before the next
//! trial is asked for. The study window and simulation both use it; it knows nothing of
//! drawing or of observers.

use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use protocols::{
    FrameTiming, Outcome, Response, Session, SessionStatus, StimulusEncoding, StudyDefinition,
    Trial, TrialRecord,
};
use results::store::{SessionLock, SessionState, read_manifest};
use results::{SessionLog, SessionManifest};

use crate::error::{Context as _, Result, io_error, refused};

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
    results.join(format!("{subject}_s{session}"))
}

/// Removes session folder `dir` if nothing happened in it: no trial logged and never
/// resumed, what a runner that could not open its window leaves. Returns whether it did; a
/// folder holding anything else is left as it is.
///
/// # Errors
/// The folder's files cannot be read or removed.
pub fn discard_unstarted(dir: &Path) -> Result<bool> {
    use results::store::{LOCK_FILE, SESSION_FILE, TRIALS_FILE};
    let manifest: SessionManifest = read_manifest(&dir.join(SESSION_FILE))?;
    let trials = results::read_trials(&dir.join(TRIALS_FILE))?;
    if manifest.resumes > 0 || !trials.records.is_empty() || trials.torn.is_some() {
        return Ok(false);
    }
    for f in [SESSION_FILE, TRIALS_FILE, LOCK_FILE] {
        match std::fs::remove_file(dir.join(f)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(io_error(dir.join(f))(e));
            }
            _ => {}
        }
    }
    Ok(std::fs::remove_dir(dir).is_ok())
}

/// Per-frame presentation intervals of a window session, beside `trials.csv`.
pub const FRAMES_FILE: &str = "frames.csv";

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
    }
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

/// An open session: the engine, its log and its manifest.
pub struct Recorder {
    engine: Session,
    log: SessionLog,
    manifest: SessionManifest,
    study: String,
    /// Session clock (ms) at which this process took over: the last logged trial's.
    clock_base_ms: u64,
    monotonic_base_ms: u64,
    started: Instant,
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
    /// Opens `dir` for subject `subject_index` of `study`: creates it, or with `resume`
    /// continues an interrupted session there (a torn last row is set aside and reported on
    /// stderr; the logged responses are replayed and must regenerate the logged trials).
    /// `fresh` is the manifest of a new session.
    ///
    /// # Errors
    /// The folder exists without `resume`, a live runner holds it, the log cannot be read,
    /// or the study no longer regenerates the logged trials.
    pub fn open(
        study: &StudyDefinition,
        subject_index: u32,
        dir: &Path,
        resume: bool,
        fresh: SessionManifest,
    ) -> Result<Opened> {
        let mut engine = Session::new(study, subject_index)?;
        let (log, logged, mut manifest) = if resume && dir.exists() {
            let manifest_path = dir.join(results::store::SESSION_FILE);
            let old: Option<SessionManifest> = if manifest_path.exists() {
                Some(read_manifest(&manifest_path)?)
            } else {
                None
            };
            if let Some(m) = &old {
                check_same_session(&manifest_path, m, &fresh)?;
            }
            if let Some(m) = old
                .as_ref()
                .filter(|m| matches!(m.status, SessionState::Complete | SessionState::TimeLimit))
            {
                // A crash after the final manifest write can leave the lock behind: take the
                // stale lock over and release it (refused if a live runner holds it).
                drop(SessionLock::acquire(dir)?);
                return Ok(Opened::Finished(Box::new(m.clone())));
            }
            let resumed = SessionLog::resume(dir)?;
            let mut m = old.unwrap_or(fresh);
            m.resumes += 1;
            m.status = SessionState::Running;
            m.ended_ms = None;
            if let Some((row, aside)) = &resumed.torn {
                let name = aside
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                eprintln!(
                    "warning: {}: line {} was torn ({} bytes, power cut mid-write?); set aside in {name}",
                    dir.join(results::store::TRIALS_FILE).display(),
                    row.line,
                    row.bytes.len()
                );
                m.torn_rows.push(name);
            }
            (resumed.log, resumed.records, m)
        } else {
            if dir.exists() {
                return Err(refused(format!(
                    "{} already exists; results are never overwritten (use --resume to continue)",
                    dir.display()
                )));
            }
            (SessionLog::create(dir)?, Vec::new(), fresh)
        };
        let trials = dir.join(results::store::TRIALS_FILE);
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
        manifest.trials_logged = log.rows();
        log.write_manifest(&manifest)?;
        let last = logged.last();
        Ok(Opened::Ready {
            resumed: logged.len() as u32,
            recorder: Box::new(Recorder {
                engine,
                log,
                study: study.name.clone(),
                manifest,
                clock_base_ms: last.map_or(0, |r| r.elapsed_ms),
                monotonic_base_ms: last.map_or(0, |r| r.monotonic_ms),
                started: Instant::now(),
            }),
        })
    }

    /// The session clock of the last logged trial (0 for a new session), ms.
    pub fn logged_clock_ms(&self) -> u64 {
        self.clock_base_ms
    }

    /// The session clock: time already logged plus this process's running time, ms.
    pub fn elapsed_ms(&self) -> u64 {
        self.clock_base_ms + self.started.elapsed().as_millis() as u64
    }

    /// Trials answered so far (including replayed ones).
    pub fn answered(&self) -> u32 {
        self.engine.answered()
    }

    /// The manifest as it stands.
    pub fn manifest(&self) -> &SessionManifest {
        &self.manifest
    }

    /// Updates the manifest (display information, ...) and writes it.
    ///
    /// # Errors
    /// The manifest cannot be written.
    pub fn update_manifest(&mut self, change: impl FnOnce(&mut SessionManifest)) -> Result<()> {
        change(&mut self.manifest);
        self.log.write_manifest(&self.manifest)?;
        Ok(())
    }

    /// The next trial at session clock `elapsed_ms`, or `None` when the session is over.
    ///
    /// # Errors
    /// Engine errors (a staircase level without a stimulus).
    pub fn next_trial(&mut self, elapsed_ms: u64) -> Result<Option<Trial>> {
        Ok(self.engine.next_trial(elapsed_ms)?)
    }

    /// The trials that can follow the pending one (one per answer that leads somewhere
    /// different; see `protocols::Session::lookahead`), for preparing their stimuli early.
    pub fn lookahead(&self, elapsed_ms: u64) -> Vec<Trial> {
        self.engine.lookahead(elapsed_ms)
    }

    /// Scores `response` to the pending `trial` and appends the row (flushed and fsynced)
    /// before returning: nothing can show the next stimulus before the answer is on disk.
    /// `encoding` describes a stimulus encoded for this trial (live staircase), `timing` how
    /// the window's display kept time during it.
    ///
    /// # Errors
    /// The engine refuses the response, or the row cannot be written.
    pub fn record(
        &mut self,
        trial: Trial,
        response: Response,
        elapsed_ms: u64,
        encoding: Option<StimulusEncoding>,
        timing: Option<FrameTiming>,
    ) -> Result<Outcome> {
        let outcome = self.engine.respond(&response)?;
        let record = TrialRecord {
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
        };
        self.log.append(&record)?;
        // The manifest's count follows every row, so a session stopped at any point (but a
        // kill between these two writes) reads as many trials in both files.
        self.manifest.trials_logged = self.log.rows();
        self.log.write_manifest(&self.manifest)?;
        Ok(outcome)
    }

    /// Appends the presentation intervals of trial `index` to `frames.csv` beside the trial
    /// log (`trial_index,interval_ms,phase`, one row per presented frame, `phases[k]` what
    /// frame `k` showed: `a`, `b`, `grey`, `both`, `answer`, ...), so every frame's timing
    /// is kept, not only the per-trial summary. Flushed, not fsynced: the answer itself is
    /// already on disk.
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn append_frame_intervals(
        &mut self,
        index: u32,
        intervals: &[f64],
        phases: &[&str],
    ) -> Result<()> {
        use std::fmt::Write as _;
        use std::io::Write as _;
        let path = self.log.dir().join(FRAMES_FILE);
        // A session begun before the phase column keeps its two columns when resumed.
        let phased = match std::fs::File::open(&path) {
            Ok(f) => {
                use std::io::Read as _;
                let mut head = Vec::with_capacity(64);
                f.take(64).read_to_end(&mut head).map_err(io_error(&path))?;
                head.split(|b| *b == b'\n')
                    .next()
                    .is_some_and(|h| h.ends_with(b",phase"))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => true,
            Err(e) => return Err(io_error(&path)(e)),
        };
        let new = !path.exists();
        let mut text = String::with_capacity(intervals.len() * 20 + 40);
        if new {
            text.push_str("trial_index,interval_ms,phase\n");
        }
        for (k, ms) in intervals.iter().enumerate() {
            if phased {
                let phase = phases.get(k).copied().unwrap_or("");
                let _ = writeln!(text, "{index},{ms:.3},{phase}");
            } else {
                let _ = writeln!(text, "{index},{ms:.3}");
            }
        }
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io_error(&path))?;
        f.write_all(text.as_bytes())
            .and_then(|()| f.flush())
            .map_err(io_error(&path))?;
        Ok(())
    }

    /// Marks the session interrupted (stopped on purpose before its end, resumable) and
    /// writes the manifest with the rows on disk.
    ///
    /// # Errors
    /// The manifest cannot be written.
    pub fn interrupt(&mut self) -> Result<()> {
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
