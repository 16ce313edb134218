//! Dry runs: whole sessions with simulated observers, through the same engines, stimulus
//! sources and session recorder a real subject's session uses.

use std::path::PathBuf;
use std::time::Duration;

use protocols::observer::Observer;
use results::backend::Store;
use results::store::DisplayInfo;
use results::{FolderStore, SessionManifest};
#[cfg(feature = "postgres")]
use results::{ResultsError, backend::Found, pg::PgStore};

#[cfg(feature = "postgres")]
use crate::error::LabError;
use crate::error::{Context as _, Result};
use crate::results_dir::{self, Destination};
use crate::session::{self, Opened};
use crate::source::{self, StimulusSource};
use crate::study::StudyFile;

/// What a simulated run does.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    /// The study file.
    pub study: PathBuf,
    /// Number of simulated subjects (`S001`, `S002`, ...).
    pub subjects: u32,
    /// Seed of the simulated observers (the trial plans derive from the study's own seed).
    pub seed: u64,
    /// Where the sessions go: a results directory to create (never overwritten), or a run of
    /// a database, which several stations may simulate into at once (each takes the next
    /// subject number from the database until `subjects` are given out).
    pub output: Destination,
    /// Pause before each answer (paces trials for kill tests).
    pub trial_delay: Duration,
    /// Continue an interrupted run in an existing results directory (in a database: the
    /// sessions no station holds any more, then new subjects as without it).
    pub resume: bool,
    /// How long a station waits for an unreachable database before it stops (the answer it
    /// holds is then asked again when the session resumes).
    pub patience: Duration,
}

/// The id of simulated subject `index` (0-based): `S001`, `S002`, ...
pub fn subject_id(index: u32) -> String {
    format!("S{:03}", index + 1)
}

/// The index `k` whose [`subject_id`] is `id`, if any.
#[cfg(feature = "postgres")]
fn subject_number(id: &str) -> Option<u32> {
    let k = id.strip_prefix('S')?.parse::<u32>().ok()?.checked_sub(1)?;
    (subject_id(k) == id).then_some(k)
}

/// A simulated subject: the id its session is recorded under and the index its plan and
/// observer derive from.
struct Subject {
    id: String,
    index: u32,
}

impl Subject {
    /// Simulated subject `index` (0-based), [`subject_id`].
    fn numbered(index: u32) -> Self {
        Self {
            id: subject_id(index),
            index,
        }
    }
}

/// One simulated session of the subject `id`, whose plan index is the one `study run
/// --subject ID` and `study serve` derive from that id ([`session::subject_index`] of
/// session 1), into a results folder: what a real subject of that id would have logged had
/// they answered as the simulated observer does (a test gives a browser those answers).
///
/// # Errors
/// A bad subject id, a database destination (subjects there are numbered by the
/// database), and as [`simulate`].
pub fn simulate_subject(
    options: &SimulateOptions,
    id: &str,
    report: &mut dyn FnMut(&str),
) -> Result<()> {
    session::check_subject(id)?;
    // Without the `postgres` feature a folder is the only destination.
    #[cfg_attr(
        not(feature = "postgres"),
        allow(clippy::infallible_destructuring_match)
    )]
    let out = match &options.output {
        Destination::Folder(out) => out,
        #[cfg(feature = "postgres")]
        Destination::Database { .. } => {
            return Err(crate::error::refused(
                "--subject ID simulates into a results folder (-o DIR); a database numbers its subjects",
            ));
        }
    };
    let study = StudyFile::load(&options.study)?;
    let mut stimuli = source::open(&study)?;
    results_dir::open_for_simulation(out, &study, options.seed, 1, options.resume)?;
    let subject = Subject {
        id: id.to_owned(),
        index: session::subject_index(id, 1),
    };
    let mut store = FolderStore::new(out);
    let summary = run_subject(
        &study,
        options,
        &subject,
        &mut store,
        options.resume,
        stimuli.as_mut(),
        report,
    )?;
    report(&summary);
    if let Some(s) = stimuli.summary() {
        report(&s);
    }
    Ok(())
}

/// Runs `options.subjects` complete simulated sessions into a results directory or a
/// database run; `report` gets one line per session as it ends (and a line when the database
/// goes away and comes back).
///
/// # Errors
/// Study file problems, an existing output without resume, a resume whose logged trials the
/// study no longer regenerates, I/O and database errors.
pub fn simulate(options: &SimulateOptions, report: &mut dyn FnMut(&str)) -> Result<()> {
    simulate_with_progress(options, report, &mut |_, _| {})
}

/// As [`simulate`]; `progress(done, total)` is called as each session ends: `done` of the
/// `options.subjects` sessions (into a database run: subject numbers given out, by any
/// station).
///
/// # Errors
/// As [`simulate`].
pub fn simulate_with_progress(
    options: &SimulateOptions,
    report: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(usize, usize),
) -> Result<()> {
    let study = StudyFile::load(&options.study)?;
    // One stimulus source (and cache of encoded levels) for every simulated subject.
    let mut stimuli = source::open(&study)?;
    match &options.output {
        Destination::Folder(out) => {
            results_dir::open_for_simulation(
                out,
                &study,
                options.seed,
                options.subjects,
                options.resume,
            )?;
            let mut store = FolderStore::new(out);
            for subject in 0..options.subjects {
                let summary = run_subject(
                    &study,
                    options,
                    &Subject::numbered(subject),
                    &mut store,
                    options.resume,
                    stimuli.as_mut(),
                    report,
                )?;
                report(&summary);
                progress(subject as usize + 1, options.subjects as usize);
            }
        }
        #[cfg(feature = "postgres")]
        Destination::Database { db, run } => {
            let mut store = results_dir::open_database_for_simulation(
                db,
                run.as_deref(),
                &study,
                options.seed,
                options.subjects,
            )?;
            simulate_into_database(
                &study,
                options,
                &mut store,
                stimuli.as_mut(),
                report,
                progress,
            )?;
        }
    }
    if let Some(s) = stimuli.summary() {
        report(&s);
    }
    Ok(())
}

/// Simulated sessions into a database run: with `resume` first the sessions no station holds
/// any more, then new subjects numbered by the database until the run's count is given out.
#[cfg(feature = "postgres")]
fn simulate_into_database(
    study: &StudyFile,
    options: &SimulateOptions,
    store: &mut PgStore,
    stimuli: &mut dyn StimulusSource,
    report: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(usize, usize),
) -> Result<()> {
    let wait = options.patience;
    if options.resume {
        resume_in_database(study, options, store, stimuli, report)?;
    } else {
        let left = session::retry_outage(wait, report, || Ok(store.abandoned()?))?.len();
        let unclaimed = session::retry_outage(wait, report, || Ok(store.unclaimed_numbers()?))?
            .iter()
            .filter(|u| u.observer_seed == Some(options.seed))
            .count();
        if left > 0 || unclaimed > 0 {
            report(&format!(
                "note: {left} sessions of {} were left unfinished by a station and {unclaimed} \
                 subject numbers taken without a session; `--resume` continues and creates them",
                store.location()
            ));
        }
    }
    let id_of = |n: u32| subject_id(n - 1);
    while let Some((number, id)) = session::retry_outage(wait, report, || {
        Ok(store.take_subject_number(Some(options.subjects), &id_of, Some(options.seed))?)
    })? {
        let index = number - 1;
        let found = session::retry_outage(wait, report, || Ok(store.find_session(&id, 1)?))?;
        if found != Found::Absent {
            // Recorded already (imported under this id): the number is spent, take the next.
            continue;
        }
        // A resuming station may have found the number before this one created the session.
        let said = match run_unless_taken(study, options, index, store, false, stimuli, report)? {
            Some(summary) => summary,
            None => format!("{id}: created by another station"),
        };
        report(&said);
        progress(number as usize, options.subjects as usize);
    }
    Ok(())
}

/// `study simulate --resume` into a database run: the run's simulated sessions no station
/// holds, continued, then the sessions of the numbers this simulation took whose station
/// stopped before creating them.
#[cfg(feature = "postgres")]
fn resume_in_database(
    study: &StudyFile,
    options: &SimulateOptions,
    store: &mut PgStore,
    stimuli: &mut dyn StimulusSource,
    report: &mut dyn FnMut(&str),
) -> Result<()> {
    let wait = options.patience;
    let abandoned = session::retry_outage(wait, report, || Ok(store.abandoned()?))?;
    for m in abandoned {
        // Only this simulation's sessions: not a real subject's in the same run. A
        // simulated subject's plan index is its number, or in a study with groups its
        // place in its group.
        let Some(index) = subject_number(&m.subject) else {
            continue;
        };
        if m.session != 1
            || m.observer_seed != Some(options.seed)
            || (m.group.is_none() && m.subject_index != index)
        {
            continue;
        }
        let said = match run_unless_taken(study, options, index, store, true, stimuli, report)? {
            Some(summary) => summary,
            None => format!("{}: taken over by another station", m.subject),
        };
        report(&said);
    }
    // Numbers this simulation took whose station stopped before creating the session.
    let unclaimed = session::retry_outage(wait, report, || Ok(store.unclaimed_numbers()?))?;
    for u in unclaimed {
        if u.observer_seed != Some(options.seed)
            || subject_number(&u.subject) != Some(u.number - 1)
            || u.number > options.subjects
        {
            continue;
        }
        let index = u.number - 1;
        let said = match run_unless_taken(study, options, index, store, false, stimuli, report)? {
            Some(summary) => format!(
                "{summary} (number {} was taken by {} without a session)",
                u.number, u.station
            ),
            None => format!("{}: created by another station", u.subject),
        };
        report(&said);
    }
    Ok(())
}

/// [`run_subject`] for simulated subject `index` in a database run; `None` where another
/// station created the session, or holds it, first (not an error: that station runs it).
#[cfg(feature = "postgres")]
fn run_unless_taken(
    study: &StudyFile,
    options: &SimulateOptions,
    index: u32,
    store: &mut PgStore,
    resume: bool,
    stimuli: &mut dyn StimulusSource,
    report: &mut dyn FnMut(&str),
) -> Result<Option<String>> {
    match run_subject(
        study,
        options,
        &Subject::numbered(index),
        store,
        resume,
        stimuli,
        report,
    ) {
        Ok(summary) => Ok(Some(summary)),
        Err(LabError::Context { source, .. })
            if matches!(
                *source,
                LabError::Results(ResultsError::SessionBusy { .. } | ResultsError::Exists { .. })
            ) =>
        {
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// What a simulated subject states in a new session's manifest: a valid answer to every
/// subject field ("simulated" for free text, numbers and options spread over the subjects)
/// and "simulated" for the display.
fn simulated(def: &protocols::StudyDefinition, m: &mut SessionManifest) {
    let k = u64::from(m.subject_index);
    m.subject_fields = def
        .session
        .subject_fields
        .iter()
        .map(|f| (f.name.clone(), f.simulated(k)))
        .collect();
    m.display = Some(DisplayInfo {
        description: "simulated".into(),
        width_px: 0,
        height_px: 0,
        refresh_hz: 0.0,
    });
}

/// One simulated subject's session in `store`; returns its one-line summary.
fn run_subject(
    study: &StudyFile,
    options: &SimulateOptions,
    subject: &Subject,
    store: &mut dyn Store,
    resume: bool,
    stimuli: &mut dyn StimulusSource,
    report: &mut dyn FnMut(&str),
) -> Result<String> {
    let path = store.session_path(&subject.id, 1);
    let at = || format!("session {}", path.display());
    let def = &study.definition;
    // In a study with between-subject groups the store assigns the group (the one with the
    // fewest sessions), and the plan index is the session's place in it, so each group's
    // Latin square fills in turn; the observer stays the subject's. Assigning again after an
    // outage gives the same group.
    let who = session::SessionFor {
        subject: &subject.id,
        session: 1,
        group: None,
        subject_index: def.design.groups.is_empty().then_some(subject.index),
        observer_seed: Some(options.seed),
        resume,
    };
    let (opened, _) = session::retry_outage(options.patience, report, || {
        session::open_subject(study, &mut *store, &who, &|m| simulated(def, m))
    })
    .context(at)?;
    let mut rec = match opened {
        Opened::Finished(m) => {
            return Ok(format!(
                "{}: already {:?}, {} trials",
                m.subject, m.status, m.trials_logged
            ));
        }
        Opened::Ready { recorder, .. } => recorder,
    };
    let observer = Observer::new(def, options.seed, subject.index);
    let mut clock_ms = rec.logged_clock_ms();
    let per_trial_ms = def.trial_presentation_ms();
    while let Some(trial) = rec.next_trial(clock_ms).context(at)? {
        // A stimulus made for this trial (live staircase) is made now; the observer sees its
        // measured error. Prepared stimuli carry theirs in the manifest (a crowd scene's row
        // logs its characters' ratios).
        let encoding = stimuli.encoding(&trial).context(at)?;
        // A crowd scene's row logs its characters' pooled RMS; the observer weighs each
        // character itself (by size and attention) from the manifest.
        let measured = encoding
            .as_ref()
            .filter(|_| def.scene.is_none())
            .map(|e| e.rms_cm);
        let response = observer.respond_measured(&trial, measured).context(at)?;
        if !options.trial_delay.is_zero() {
            std::thread::sleep(options.trial_delay);
        }
        // Simulated session clock: the presentation (again for each replay), the answer and
        // the gap before the next trial; deterministic, so the time limit replays exactly.
        clock_ms += per_trial_ms * (1 + u64::from(response.replays))
            + response.response_time_ms
            + def.presentation.gap_ms;
        if let Err(e) = rec.record(trial, response, clock_ms, encoding, None) {
            if !session::is_outage(&e) {
                return Err(e).context(at);
            }
            // The answer is kept: committed when the database is back, before the next trial.
            rec.commit_waiting(options.patience, report).context(at)?;
        }
    }
    session::retry_outage(options.patience, report, || rec.finish()).context(at)?;
    Ok(rec.summary())
}
