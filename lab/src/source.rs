//! Where a trial's stimuli come from. A runner (the study window, simulation, a server) asks
//! a [`StimulusSource`] for the clips of each trial without knowing whether they are files of
//! the stimulus manifest ([`ManifestStimuli`]) or encoded for the trial by the study's codec
//! ([`crate::live::LiveStimuli`]); [`open`] picks the one a study needs.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};

use motion::Clip;
use protocols::manifest::StimulusManifest;
use protocols::study::{Placement, SceneSettings};
use protocols::{StimulusEncoding, Trial};

use crate::error::{Context as _, Result};
use crate::live::LiveStimuli;
use crate::study::StudyFile;

/// The two clips of a trial, and how the test clip was made when it was made for this trial.
#[derive(Debug, Clone)]
pub struct TrialStimuli {
    /// The reference (original) clip (a crowd scene's: its first character's).
    pub reference: Arc<Clip>,
    /// The test (compressed) clip (a crowd scene's: its first character's).
    pub test: Arc<Clip>,
    /// Parameters, compression ratio and error of a test clip encoded for this trial (a live
    /// staircase), or a crowd scene's characters' ratios and level, logged in the trial's
    /// row; `None` for other prepared stimuli, whose facts are in the manifest.
    pub encoding: Option<StimulusEncoding>,
    /// A crowd scene's characters (thesis 6.5), in the `[scene]`'s order; empty for one
    /// figure per pane.
    pub crowd: Vec<CrowdCharacter>,
}

/// One character of a crowd trial: where it stands and what it shows in the reference and in
/// the compressed scene.
#[derive(Debug, Clone)]
pub struct CrowdCharacter {
    /// Its name in the `[scene]`.
    pub name: String,
    /// Where it stands on the trial's level.
    pub placement: Placement,
    /// Its clip in the reference scene.
    pub reference: Arc<Clip>,
    /// Its clip in the compressed scene.
    pub test: Arc<Clip>,
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

    /// Keeps `clips`, already read by id (a server passes what its preflight read,
    /// [`crate::preflight::verify_keeping`]), so that no trial waits for a file; returns how
    /// many it kept. Sources that make stimuli per trial keep none.
    fn keep(&self, _clips: &[(String, Arc<Clip>)]) -> usize {
        0
    }

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
    scene: Option<SceneSettings>,
    clips: Mutex<HashMap<String, Arc<Clip>>>,
}

impl ManifestStimuli {
    /// The stimuli of `study` (manifest paths are relative to the manifest's folder, which the
    /// study file names relative to itself).
    pub fn new(study: &StudyFile) -> ManifestStimuli {
        ManifestStimuli {
            base: study.manifest_dir(),
            manifest: study.definition.manifest.clone(),
            scene: study.definition.scene.clone(),
            clips: Mutex::default(),
        }
    }

    /// The stimuli of `manifest`, its file paths relative to `base` (its folder), without a
    /// study: no crowd scene can be drawn ([`Self::crowd_pair`] needs the study's `[scene]`).
    pub fn of_manifest(base: PathBuf, manifest: StimulusManifest) -> ManifestStimuli {
        ManifestStimuli {
            base,
            manifest,
            scene: None,
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
        if st.scene.is_some() {
            return Err(crate::error::refused(format!(
                "stimulus {id:?} is a crowd scene, not one clip"
            )));
        }
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

    /// The characters of crowd trial `trial` (empty for a trial of one figure per pane).
    fn crowd(&self, trial: &Trial) -> Result<Vec<CrowdCharacter>> {
        let is_scene = |id: &str| self.manifest.get(id).is_some_and(|s| s.scene.is_some());
        if is_scene(&trial.stimulus) && is_scene(&trial.reference) {
            self.crowd_pair(&trial.stimulus, &trial.reference)
        } else {
            Ok(Vec::new())
        }
    }

    /// The characters of crowd scene `test` beside those of scene `reference` (both of the
    /// same level of the study's `[scene]`): where each stands and its clip in each.
    ///
    /// # Errors
    /// A scene the manifest or the study's `[scene]` does not know, or a clip that cannot be
    /// read.
    pub fn crowd_pair(&self, test: &str, reference: &str) -> Result<Vec<CrowdCharacter>> {
        let scene_of = |id: &str| {
            self.manifest
                .get(id)
                .and_then(|s| s.scene.as_ref())
                .context(|| format!("{id:?} is not a crowd scene of the stimulus manifest"))
        };
        let (t, r) = (scene_of(test)?, scene_of(reference)?);
        let settings = self
            .scene
            .as_ref()
            .context(|| format!("{test:?} is a crowd scene and the study has no [scene]"))?;
        let level = settings
            .level_index(&t.level)
            .filter(|_| t.level == r.level)
            .context(|| {
                format!(
                    "crowd scenes {test:?} and {reference:?}: levels {:?} and {:?}, the study's \
                     are {}",
                    t.level,
                    r.level,
                    settings.levels.join(", ")
                )
            })?;
        t.characters
            .iter()
            .zip(&r.characters)
            .map(|(tc, rc)| {
                let c = settings
                    .character(&tc.name)
                    .filter(|_| tc.name == rc.name)
                    .context(|| {
                        format!(
                            "crowd scene {test:?}: character {:?} is not the study's or its \
                             reference's",
                            tc.name
                        )
                    })?;
                Ok(CrowdCharacter {
                    name: tc.name.clone(),
                    placement: settings.placement(c, level),
                    reference: self.clip(&rc.stimulus)?,
                    test: self.clip(&tc.stimulus)?,
                })
            })
            .collect()
    }

    /// The stimulus manifest.
    pub fn manifest(&self) -> &StimulusManifest {
        &self.manifest
    }

    /// What a crowd trial's row logs about its scene.
    fn scene_encoding(&self, trial: &Trial) -> Option<StimulusEncoding> {
        let levels = &self.scene.as_ref()?.levels;
        self.manifest.scene_encoding(&trial.stimulus, levels)
    }
}

impl StimulusSource for ManifestStimuli {
    fn stimuli(&self, trial: &Trial) -> Result<TrialStimuli> {
        let crowd = self.crowd(trial)?;
        let (reference, test) = match crowd.first() {
            Some(c) => (Arc::clone(&c.reference), Arc::clone(&c.test)),
            None => (self.clip(&trial.reference)?, self.clip(&trial.stimulus)?),
        };
        Ok(TrialStimuli {
            reference,
            test,
            encoding: self.scene_encoding(trial),
            crowd,
        })
    }

    fn encoding(&self, trial: &Trial) -> Result<Option<StimulusEncoding>> {
        Ok(self.scene_encoding(trial))
    }

    fn keep(&self, clips: &[(String, Arc<Clip>)]) -> usize {
        let mut cache = self.cache();
        for (id, clip) in clips {
            cache.insert(id.clone(), Arc::clone(clip));
        }
        clips.len()
    }

    fn ready(&self) -> usize {
        self.cache().len()
    }
}
