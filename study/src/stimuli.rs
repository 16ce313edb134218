//! The clips behind a study's stimulus ids, loaded on first use and kept for the session.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context as _;
use motion::clip::Clip;
use protocols::StudyDefinition;
use protocols::manifest::StimulusManifest;

/// Stimulus id → decoded clip, from the study's `stimuli.json`.
pub struct StimulusLibrary {
    base: PathBuf,
    manifest: StimulusManifest,
    clips: HashMap<String, Arc<Clip>>,
}

impl StimulusLibrary {
    /// The library of `study`, loaded from `study_path` (manifest paths are relative to the
    /// manifest's folder, which the study file names relative to itself).
    pub fn new(study: &StudyDefinition, study_path: &Path) -> StimulusLibrary {
        let study_dir = study_path.parent().unwrap_or(Path::new("."));
        let manifest_path = study_dir.join(&study.stimuli_path);
        let base = manifest_path
            .parent()
            .map_or_else(|| study_dir.to_path_buf(), Path::to_path_buf);
        StimulusLibrary {
            base,
            manifest: study.manifest.clone(),
            clips: HashMap::new(),
        }
    }

    /// The clip of stimulus `id`.
    ///
    /// # Errors
    /// The id is not in the manifest, or its file cannot be read (named in the message).
    pub fn clip(&mut self, id: &str) -> anyhow::Result<Arc<Clip>> {
        if let Some(c) = self.clips.get(id) {
            return Ok(Arc::clone(c));
        }
        let st = self
            .manifest
            .get(id)
            .with_context(|| format!("stimulus {id:?} is not in the stimulus manifest"))?;
        let file = self.base.join(&st.file);
        let skeleton = st.skeleton.as_ref().map(|s| self.base.join(s));
        let clip = motion::io::read_clip(skeleton.as_deref(), &file)
            .with_context(|| format!("loading stimulus {id:?}"))?;
        let clip = Arc::new(clip);
        self.clips.insert(id.to_string(), Arc::clone(&clip));
        Ok(clip)
    }
}
