//! How long a logged trial's stimuli played before its answers opened, as the window and the
//! page schedule it (`protocols::screen::Schedule` of the trial's casting): what `study report`
//! checks each answer's time against (`analysis::exclusions::too_fast`).

use std::collections::HashMap;
use std::sync::Mutex;

use protocols::TrialRecord;
use protocols::record::{Arrangement, Position};
use protocols::screen::Schedule;

use crate::StudyFile;
use crate::scene::{Casting, View};
use crate::source::StimulusSource;

/// The stimuli of one kind of trial: its layout, test and reference.
type Key = (Arrangement, Position, String, String);

/// Each trial's time before answers open, from the study's stimuli, read on first use (a
/// report of simulated sessions reads none) and kept per test, reference and layout.
pub struct AnswerTimes<'a> {
    study: &'a StudyFile,
    source: Mutex<Option<Box<dyn StimulusSource>>>,
    known: Mutex<HashMap<Key, Option<f64>>>,
    /// The first trial whose stimuli could not be read, and how many could not.
    failed: Mutex<(Option<String>, usize)>,
}

impl<'a> AnswerTimes<'a> {
    /// The answer times of `study`'s trials.
    pub fn new(study: &'a StudyFile) -> Self {
        AnswerTimes {
            study,
            source: Mutex::new(None),
            known: Mutex::default(),
            failed: Mutex::default(),
        }
    }

    /// How long `r`'s stimuli play before answers open, ms (one pass of its schedule); `None`
    /// when its stimuli cannot be read (counted for [`Self::unchecked`]).
    pub fn need_ms(&self, r: &TrialRecord) -> Option<f64> {
        let t = &r.trial;
        let key = (
            t.arrangement,
            t.reference_position,
            t.stimulus.clone(),
            t.reference.clone(),
        );
        if let Some(known) = lock(&self.known).get(&key) {
            return *known;
        }
        let need = self.schedule_ms(r);
        let value = match need {
            Ok(ms) => Some(ms),
            Err(e) => {
                let mut failed = lock(&self.failed);
                failed.0.get_or_insert_with(|| e.to_string());
                failed.1 += 1;
                None
            }
        };
        lock(&self.known).insert(key, value);
        value
    }

    fn schedule_ms(&self, r: &TrialRecord) -> crate::Result<f64> {
        let study = &self.study.definition;
        let mut opened = lock(&self.source);
        let source: &dyn StimulusSource = match &mut *opened {
            Some(s) => &**s,
            slot => &**slot.insert(crate::source::open(self.study)?),
        };
        let shown = source.stimuli(&r.trial)?;
        // What the page and the window cast: a MUSHRA screen's first pane is its reference.
        let clip_s = if r.trial.arrangement == Arrangement::Grid {
            shown.reference.duration_s()
        } else {
            Casting::of(study, &r.trial, &shown, &mut |_, clip| View::framing(clip))?.duration_s()
        };
        Ok(Schedule::of(r.trial.arrangement, &study.presentation, clip_s).answers_open_s * 1e3)
    }

    /// The trials whose stimuli could not be read (so not checked), with the first reason.
    pub fn unchecked(&self) -> Option<(usize, String)> {
        let failed = lock(&self.failed);
        failed.0.clone().map(|why| (failed.1, why))
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
