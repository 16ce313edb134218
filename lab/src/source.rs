//! Where a trial's stimuli come from. A runner (the study window, simulation, a server) asks
//! a [`StimulusSource`] for the clips of each trial without knowing whether they are files of
//! the stimulus manifest ([`ManifestStimuli`]) or encoded for the trial by the study's codec
//! ([`crate::live::LiveStimuli`]); [`open`] picks the one a study needs.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};

use motion::Clip;
use protocols::manifest::StimulusManifest;
use protocols::{StimulusEncoding, Trial};

use crate::error::{Context as _, Result};
use crate::live::LiveStimuli;
use crate::study::StudyFile;

/// The two clips of a trial, and how the test clip was made when it was made for this trial.
#[derive(Debug, Clone)]
pub struct TrialStimuli {
    /// The reference (original) clip.
    pub reference: Arc<Clip>,
    /// The test (compressed) clip.
    pub test: Arc<Clip>,
    /// Parameters, compression ratio and error of a test clip encoded for this trial (a live
    /// staircase), logged in the trial's row; `None` for prepared stimuli, whose facts are in
    /// the manifest.
    pub encoding: Option<StimulusEncoding>,
}

/// A study's stimuli, asked for trial by trial.
pub trait StimulusSource: Send {
    /// The clips `trial` shows.
    ///
    /// # Errors
    /// A stimulus the source does not have, a file that cannot be read, or a codec error.
    fn stimuli(&self, trial: &Trial) -> Result<TrialStimuli>;

    /// How `trial`'s test stimulus is made when the source makes it per trial (what
    /// [`TrialStimuli::encoding`] holds), without reading any clip file: a simulation needs no
    /// more. `None` for prepared stimuli.
    ///
    /// # Errors
    /// As [`StimulusSource::stimuli`].
    fn encoding(&self, trial: &Trial) -> Result<Option<StimulusEncoding>>;

    /// Starts preparing the stimuli of trials that may come next (`Session::lookahead`), so
    /// that asking for them later does not wait. Sources with nothing to prepare ignore it.
    fn prepare(&mut self, _upcoming: &[Trial]) {}

    /// Waits until everything [`StimulusSource::prepare`] started has ended.
    fn settle(&mut self) {}

    /// Stimuli ready to show without waiting (files read, levels encoded) so far.
    fn ready(&self) -> usize;

    /// One line on what the source did over a run (levels encoded), if it has something to
    /// say.
    fn summary(&self) -> Option<String> {
        None
    }
}

/// The stimulus source `study` needs: encoded per trial for a live staircase, its manifest's
/// files otherwise.
///
/// # Errors
/// A live staircase whose decoder context or source clips cannot be read (named by file).
pub fn open(study: &StudyFile) -> Result<Box<dyn StimulusSource>> {
    Ok(match LiveStimuli::from_study(study)? {
        Some(live) => Box::new(live),
        None => Box::new(ManifestStimuli::new(study)),
    })
}

/// Stimulus id → clip, read from the files of the study's `stimuli.json` on first use and kept
/// for the session.
pub struct ManifestStimuli {
    base: PathBuf,
    manifest: StimulusManifest,
    clips: Mutex<HashMap<String, Arc<Clip>>>,
}

impl ManifestStimuli {
    /// The stimuli of `study` (manifest paths are relative to the manifest's folder, which the
    /// study file names relative to itself).
    pub fn new(study: &StudyFile) -> ManifestStimuli {
        ManifestStimuli {
            base: study.manifest_dir(),
            manifest: study.definition.manifest.clone(),
            clips: Mutex::default(),
        }
    }

    /// The clip of stimulus `id`.
    ///
    /// # Errors
    /// The id is not in the manifest, or its file cannot be read (named in the message).
    pub fn clip(&self, id: &str) -> Result<Arc<Clip>> {
        if let Some(c) = self.cache().get(id) {
            return Ok(Arc::clone(c));
        }
        let st = self
            .manifest
            .get(id)
            .context(|| format!("stimulus {id:?} is not in the stimulus manifest"))?;
        let file = self.base.join(&st.file);
        let skeleton = st.skeleton.as_ref().map(|s| self.base.join(s));
        let clip = motion::io::read_clip(skeleton.as_deref(), &file)
            .context(|| format!("loading stimulus {id:?}"))?;
        let clip = Arc::new(clip);
        self.cache().insert(id.to_string(), Arc::clone(&clip));
        Ok(clip)
    }

    fn cache(&self) -> std::sync::MutexGuard<'_, HashMap<String, Arc<Clip>>> {
        self.clips.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl StimulusSource for ManifestStimuli {
    fn stimuli(&self, trial: &Trial) -> Result<TrialStimuli> {
        Ok(TrialStimuli {
            reference: self.clip(&trial.reference)?,
            test: self.clip(&trial.stimulus)?,
            encoding: None,
        })
    }

    fn encoding(&self, _trial: &Trial) -> Result<Option<StimulusEncoding>> {
        Ok(None)
    }

    fn ready(&self) -> usize {
        self.cache().len()
    }
}
