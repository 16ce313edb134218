//! Live (codec-in-the-loop) staircase stimuli: each trial's distorted clip is the reference
//! encoded and decoded at the trial's level, on demand, cached by (clip, level).
//!
//! The protocol engine only names a live trial's stimulus (`live:<clip>/<codec>/<param>=<level>`,
//! see `protocols::StaircaseStudy::live_stimulus_id`); this module turns that name into clips:
//! it loads each source clip once from the manifest's reference stimulus (ASF + AMC or BVH),
//! encodes it with the study's codec at `param = level` (other parameters fixed by
//! `[staircase.live] params`), decodes it, and measures the compression ratio reached and the
//! joint-position RMS error. Both `study simulate` and the subject window call it, and both log
//! the exact parameters, CR and error in the trial's row.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context as _, anyhow, bail};
use codecs::clip::Clip;
use codecs::codec::CodecContext;
use codecs::codec::{Codec, Params, RateControl};
use codecs::primitives::Database;
use protocols::{StaircaseStudy, StimulusEncoding, StudyDefinition, Trial};

/// The stimuli of one live staircase study: its codec, source clips and a cache of encoded
/// levels.
pub struct LiveStimuli {
    staircase: StaircaseStudy,
    codec: Box<dyn Codec>,
    fixed: Params,
    /// (clip name, reference stimulus id, the source clip).
    clips: Vec<(String, String, Arc<Clip>)>,
    cache: HashMap<(usize, u64), LiveStimulus>,
}

/// One trial's stimulus pair with how the distorted clip was made.
#[derive(Debug, Clone)]
pub struct LiveStimulus {
    /// The source clip (shown as the original).
    pub reference: Arc<Clip>,
    /// The decoded clip at the trial's level.
    pub test: Arc<Clip>,
    /// Exact codec parameters of the bitstream, the level's parameter included.
    pub params: BTreeMap<String, f64>,
    /// Compression ratio reached (4 bytes × channels × frames / bitstream bytes).
    pub achieved_cr: f64,
    /// Joint position RMS error of `test` against `reference`, cm.
    pub rms_cm: f64,
}

impl LiveStimulus {
    /// What a trial row logs about this stimulus (`codec_params`, `achieved_cr`, `rms_cm`).
    pub fn encoding(&self) -> StimulusEncoding {
        StimulusEncoding {
            codec_params: self.params.clone(),
            achieved_cr: self.achieved_cr,
            rms_cm: self.rms_cm,
        }
    }
}

/// The codec called `name`, with the decoder context loaded from the study (the primitive
/// codec's database).
fn codec_named(name: &str, database: Option<Arc<Database>>) -> anyhow::Result<Box<dyn Codec>> {
    let ctx = CodecContext {
        primitives: database,
    };
    codecs::codec::by_name_in(name, &ctx).ok_or_else(|| {
        let known: Vec<&str> = codecs::codec::registry_in(&ctx)
            .iter()
            .map(|c| c.name())
            .collect();
        anyhow!(
            "unknown codec {name:?} (known: {}; `study codecs` lists them)",
            known.join(", ")
        )
    })
}

impl LiveStimuli {
    /// The live stimuli of `study` (read from `study_path`), or `None` when the study has no
    /// live staircase. Checks the codec and its parameters and loads every source clip and
    /// the decoder context, so a bad setting stops the session before its first trial.
    ///
    /// # Errors
    /// Unknown codec or parameter, a level range the codec cannot encode, an unreadable clip
    /// or database (named by file).
    pub fn from_study(
        study: &StudyDefinition,
        study_path: &Path,
    ) -> anyhow::Result<Option<LiveStimuli>> {
        let Some(sc) = &study.staircase else {
            return Ok(None);
        };
        let Some(live) = &sc.live else {
            return Ok(None);
        };
        let where_ = || format!("{}: staircase.live", study_path.display());
        let base = study_path.parent().unwrap_or(Path::new("."));
        let database = match &live.database {
            Some(db) => {
                let path = base.join(db);
                let d = Database::read(&path).with_context(|| {
                    format!("{}: staircase.live.database", study_path.display())
                })?;
                Some(Arc::new(d))
            }
            None => None,
        };
        let codec = codec_named(&sc.codec, database)
            .with_context(|| format!("{}: staircase.codec", study_path.display()))?;
        let accepted = codec.default_params();
        let list = || accepted.keys().cloned().collect::<Vec<_>>().join(", ");
        if !accepted.contains_key(&sc.param) {
            bail!(
                "{}: staircase.param: codec {:?} has no parameter {:?} (accepted: {})",
                study_path.display(),
                sc.codec,
                sc.param,
                list()
            );
        }
        for k in live.params.keys() {
            if !accepted.contains_key(k) {
                bail!(
                    "{}.params.{k}: codec {:?} has no such parameter (accepted: {})",
                    where_(),
                    sc.codec,
                    list()
                );
            }
        }
        if sc.param == "cr" {
            if codec.rate_control() == RateControl::None {
                bail!(
                    "{}: staircase.param: codec {:?} takes no target compression ratio",
                    study_path.display(),
                    sc.codec
                );
            }
            for t in &sc.tracks {
                if t.settings.min.is_none_or(|m| m <= 0.0) {
                    bail!(
                        "{}: staircase.min: a compression ratio level needs min > 0",
                        study_path.display()
                    );
                }
            }
        }
        let manifest_path = base.join(&study.stimuli_path);
        let manifest_dir = manifest_path.parent().unwrap_or(Path::new("."));
        let mut clips = Vec::with_capacity(live.clips.len());
        for c in &live.clips {
            let s = study.manifest.get(&c.reference).ok_or_else(|| {
                anyhow!(
                    "{}: reference {:?} is not in the manifest",
                    where_(),
                    c.reference
                )
            })?;
            let file: PathBuf = manifest_dir.join(&s.file);
            let skeleton = s.skeleton.as_deref().map(|k| manifest_dir.join(k));
            let clip = codecs::io::read_clip(skeleton.as_deref(), &file).with_context(|| {
                format!(
                    "loading the source of live clip {:?} (stimulus {:?} in {})",
                    c.clip,
                    c.reference,
                    manifest_path.display()
                )
            })?;
            clips.push((c.clip.clone(), c.reference.clone(), Arc::new(clip)));
        }
        Ok(Some(LiveStimuli {
            staircase: sc.clone(),
            codec,
            fixed: live.params.clone(),
            clips,
            cache: HashMap::new(),
        }))
    }

    /// The codec's name.
    pub fn codec_name(&self) -> &'static str {
        self.codec.name()
    }

    /// Levels encoded so far (distinct clip × level pairs).
    pub fn cached(&self) -> usize {
        self.cache.len()
    }

    /// The clips in the study's order: (clip name, reference stimulus id).
    pub fn clips(&self) -> impl Iterator<Item = (&str, &str)> {
        self.clips.iter().map(|(c, r, _)| (c.as_str(), r.as_str()))
    }

    /// Encodes+decodes (cached) the trial's distorted stimulus.
    ///
    /// # Errors
    /// A trial that is not one of this study's live trials (unknown reference, no level, a
    /// stimulus id that does not name this codec and level), or a codec error at that level.
    pub fn resolve(&mut self, trial: &Trial) -> anyhow::Result<LiveStimulus> {
        let idx = self
            .clips
            .iter()
            .position(|(_, r, _)| *r == trial.reference)
            .ok_or_else(|| {
                anyhow!(
                    "trial {}: reference {:?} is not a clip of this live staircase",
                    trial.index,
                    trial.reference
                )
            })?;
        let level = trial
            .level
            .filter(|l| l.is_finite())
            .ok_or_else(|| anyhow!("trial {}: no finite staircase level", trial.index))?;
        let (name, _, source) = &self.clips[idx];
        let expected = self.staircase.live_stimulus_id(name, level);
        if trial.stimulus != expected {
            bail!(
                "trial {}: stimulus {:?} is not the live stimulus {expected:?} of this study",
                trial.index,
                trial.stimulus
            );
        }
        let key = (idx, level.to_bits());
        if let Some(hit) = self.cache.get(&key) {
            return Ok(hit.clone());
        }
        let mut requested = self.fixed.clone();
        requested.insert(self.staircase.param.clone(), level);
        let stream = self.codec.encode(source, &requested).with_context(|| {
            format!(
                "encoding clip {name:?} with {} at {} = {level}",
                self.codec.name(),
                self.staircase.param
            )
        })?;
        let decoded = self
            .codec
            .decode(&stream, &source.skeleton)
            .with_context(|| {
                format!(
                    "decoding clip {name:?} at {} = {level}",
                    self.staircase.param
                )
            })?;
        let metrics = codecs::metrics::compare(source, &decoded).with_context(|| {
            format!(
                "measuring clip {name:?} at {} = {level}",
                self.staircase.param
            )
        })?;
        // The stream's parameters are what the encoder really used (e.g. the α a rate search
        // found); the requested ones fill in what it does not store (a target `cr`).
        let mut params = stream.params.clone();
        for (k, v) in requested {
            params.entry(k).or_insert(v);
        }
        let out = LiveStimulus {
            reference: Arc::clone(source),
            test: Arc::new(decoded),
            params,
            achieved_cr: stream.compression_ratio(),
            rms_cm: metrics.rms_cm,
        };
        self.cache.insert(key, out.clone());
        Ok(out)
    }
}
