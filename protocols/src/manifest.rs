//! The stimulus manifest (`stimuli.json`) written by `study sweep` and read by study files.
//!
//! A stimulus is an id plus what a protocol and an analysis need to know about it: which source
//! clip it shows, which codec and parameters made it, the compression ratio it reached and its
//! objective error. Protocols never open the clip files; the runner does.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// Current version of the `stimuli.json` format.
pub const MANIFEST_VERSION: u32 = 1;

/// The codec name that marks an unprocessed reference clip.
pub const REFERENCE_CODEC: &str = "reference";

/// The whole `stimuli.json` file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StimulusManifest {
    /// Format version, [`MANIFEST_VERSION`].
    pub version: u32,
    /// Every stimulus, references included.
    pub stimuli: Vec<Stimulus>,
}

/// One stimulus: a clip file a subject can be shown.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stimulus {
    /// Unique id within the manifest (e.g. `walk/wavelet-perceptual/cr20`).
    pub id: String,
    /// Name of the source clip; a reference and its compressed versions share it.
    pub clip: String,
    /// Codec name, or [`REFERENCE_CODEC`] for the source itself.
    pub codec: String,
    /// Codec parameters as written by the codec (e.g. `alpha`, `qp`, `window`, `t_l`).
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    /// Requested compression ratio, if the stimulus was made for a target rate.
    #[serde(default)]
    pub target_cr: Option<f64>,
    /// Compression ratio reached (4 bytes × channels × frames / bitstream bytes); 1 for a
    /// reference.
    pub achieved_cr: f64,
    /// Bitstream size in bytes (0 for a reference).
    #[serde(default)]
    pub bytes: u64,
    /// Decoded clip file relative to the manifest's folder (the source's copy for a reference).
    pub file: String,
    /// Skeleton file (ASF) relative to the manifest's folder, when `file` is an AMC.
    #[serde(default)]
    pub skeleton: Option<String>,
    /// Bitstream file relative to the manifest's folder.
    #[serde(default)]
    pub bitstream: Option<String>,
    /// Objective error against the reference.
    #[serde(default)]
    pub metrics: Option<StimulusMetrics>,
    /// Encode time in milliseconds.
    #[serde(default)]
    pub encode_ms: Option<f64>,
    /// Decode time in milliseconds.
    #[serde(default)]
    pub decode_ms: Option<f64>,
}

/// Objective error of a stimulus against its reference, via forward kinematics.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StimulusMetrics {
    /// Joint position RMS error over all joints and frames, cm.
    pub rms_cm: f64,
    /// Largest joint position error, cm.
    pub max_cm: f64,
    /// Mean absolute angle error over rotation channels, degrees.
    pub mean_angle_deg: f64,
    /// Difference in mean horizontal foot speed while in contact, cm/s.
    #[serde(default)]
    pub foot_slide_cm_s: Option<f64>,
}

impl StimulusManifest {
    /// The stimulus with id `id`.
    pub fn get(&self, id: &str) -> Option<&Stimulus> {
        self.stimuli.iter().find(|s| s.id == id)
    }

    /// The reference stimulus of clip `clip`.
    pub fn reference_of(&self, clip: &str) -> Option<&Stimulus> {
        self.stimuli
            .iter()
            .find(|s| s.clip == clip && s.codec == REFERENCE_CODEC)
    }
}
