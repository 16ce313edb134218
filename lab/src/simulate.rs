//! Dry runs: whole sessions with simulated observers, through the same engines, stimulus
//! sources and session recorder a real subject's session uses.

use std::path::{Path, PathBuf};
use std::time::Duration;

use protocols::observer::Observer;
use results::SessionManifest;
use results::store::DisplayInfo;

use crate::error::{Context as _, Result};
use crate::results_dir;
use crate::session::{self, Opened, Recorder, SessionOf};
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
    /// Results directory to create (never overwritten).
    pub output: PathBuf,
    /// Pause before each answer (paces trials for kill tests).
    pub trial_delay: Duration,
    /// Continue an interrupted run in an existing results directory.
    pub resume: bool,
}

/// The id of simulated subject `index` (0-based): `S001`, `S002`, ...
pub fn subject_id(index: u32) -> String {
    format!("S{:03}", index + 1)
}

/// Runs `options.subjects` complete simulated sessions into a results directory; `report`
/// gets one line per session as it ends.
///
/// # Errors
/// Study file problems, an existing output without resume, a resume whose logged trials the
/// study no longer regenerates, I/O errors.
pub fn simulate(options: &SimulateOptions, report: &mut dyn FnMut(&str)) -> Result<()> {
    let study = StudyFile::load(&options.study)?;
    let out = &options.output;
    results_dir::open_for_simulation(out, &study, options.seed, options.subjects, options.resume)?;
    // One stimulus source (and cache of encoded levels) for every simulated subject.
    let mut stimuli = source::open(&study)?;
    for subject in 0..options.subjects {
        let dir = session::session_dir(out, &subject_id(subject), 1);
        let summary = run_subject(&study, options, subject, &dir, stimuli.as_mut())
            .context(|| format!("session {}", dir.display()))?;
        report(&summary);
    }
    if let Some(s) = stimuli.summary() {
        report(&s);
    }
    Ok(())
}

/// The manifest of a new simulated session.
fn new_manifest(study: &StudyFile, seed: u64, subject: u32) -> SessionManifest {
    let def = &study.definition;
    let mut m = session::new_manifest(
        def,
        SessionOf {
            study_hash: &study.hash,
            manifest_hash: &study.manifest_hash,
            subject: subject_id(subject),
            subject_index: subject,
            session: 1,
            observer_seed: Some(seed),
        },
    );
    m.subject_fields = def
        .session
        .subject_fields
        .iter()
        .map(|f| (f.clone(), "simulated".to_string()))
        .collect();
    m.display = Some(DisplayInfo {
        description: "simulated".into(),
        width_px: 0,
        height_px: 0,
        refresh_hz: 0.0,
    });
    m
}

/// One simulated subject's session in `dir`; returns its one-line summary.
fn run_subject(
    study: &StudyFile,
    options: &SimulateOptions,
    subject: u32,
    dir: &Path,
    stimuli: &mut dyn StimulusSource,
) -> Result<String> {
    let def = &study.definition;
    let fresh = new_manifest(study, options.seed, subject);
    let mut rec = match Recorder::open(def, subject, dir, options.resume, fresh)? {
        Opened::Finished(m) => {
            return Ok(format!(
                "{}: already {:?}, {} trials",
                m.subject, m.status, m.trials_logged
            ));
        }
        Opened::Ready { recorder, .. } => recorder,
    };
    let observer = Observer::new(def, options.seed, subject);
    let mut clock_ms = rec.logged_clock_ms();
    let per_trial_ms = def.trial_presentation_ms();
    while let Some(trial) = rec.next_trial(clock_ms)? {
        // A stimulus made for this trial (live staircase) is made now; the observer sees its
        // measured error. Prepared stimuli carry theirs in the manifest (a crowd scene's row
        // logs its characters' ratios).
        let encoding = stimuli.encoding(&trial)?;
        // A crowd scene's row logs its characters' pooled RMS; the observer weighs each
        // character itself (by size and attention) from the manifest.
        let measured = encoding
            .as_ref()
            .filter(|_| def.scene.is_none())
            .map(|e| e.rms_cm);
        let response = observer.respond_measured(&trial, measured)?;
        if !options.trial_delay.is_zero() {
            std::thread::sleep(options.trial_delay);
        }
        // Simulated session clock: the presentation (again for each replay), the answer and
        // the gap before the next trial; deterministic, so the time limit replays exactly.
        clock_ms += per_trial_ms * (1 + u64::from(response.replays))
            + response.response_time_ms
            + def.presentation.gap_ms;
        rec.record(trial, response, clock_ms, encoding, None)?;
    }
    rec.finish()?;
    Ok(rec.summary())
}
