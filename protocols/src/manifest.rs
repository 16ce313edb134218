//! The stimulus manifest (`stimuli.json`) written by `study sweep` and read by study files.
//!
//! A stimulus is an id plus what a protocol and an analysis need to know about it: which source
//! clip it shows, which codec and parameters made it, the compression ratio it reached and its
//! objective error. Protocols never open the clip files; the runner does.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::record::StimulusEncoding;

/// Current version of the `stimuli.json` format. Version 2 added a stimulus' `variant`,
/// `target_max_error_cm` and the worst-window fields of its metrics; version 3 the crowd
/// scenes of `study crowd` (a stimulus' `scene`, whose `file` is then empty); version 4 the
/// SHA-256 of each stimulus' file and bitstream. Every one of them is optional, so an older
/// manifest reads as a version-4 one without them.
pub const MANIFEST_VERSION: u32 = 4;

/// The oldest `stimuli.json` version this build reads.
pub const MANIFEST_VERSION_MIN: u32 = 1;

/// The codec name that marks an unprocessed reference clip.
pub const REFERENCE_CODEC: &str = "reference";

/// `Option<T>` that must be present, `null` allowed (serde treats a missing `Option` field
/// as `None` unless it is deserialized by a function of its own).
fn required_nullable<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<T>::deserialize(d)
}

/// The whole `stimuli.json` file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StimulusManifest {
    /// Format version, [`MANIFEST_VERSION`].
    pub version: u32,
    /// Which channels every `achieved_cr` and `target_cr` of the manifest counts (absent:
    /// [`CrBasis::File`]).
    #[serde(default, skip_serializing_if = "CrBasis::is_file")]
    pub cr_basis: CrBasis,
    /// Every stimulus, references included.
    pub stimuli: Vec<Stimulus>,
}

/// Which channels a compression ratio counts (`codecs::basis` counts them): every channel of
/// the clip's file, or the degrees of freedom the seeds count (a CMU skeleton's 56).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CrBasis {
    /// `4 bytes × every channel of the file × frames / bytes`.
    #[default]
    File,
    /// `4 bytes × the seeds' DOF × frames / bytes`.
    Seed,
}

impl CrBasis {
    /// Whether this is the file basis (the default, not written).
    pub fn is_file(&self) -> bool {
        *self == CrBasis::File
    }

    /// How reports name it.
    pub fn words(self) -> &'static str {
        match self {
            CrBasis::File => {
                "file basis: every channel of the clip's file (62 for a CMU AMC clip, 96 for a CMU BVH)"
            }
            CrBasis::Seed => {
                "seed basis: the seeds' 56 DOF of a CMU skeleton (fingers and thumbs left out)"
            }
        }
    }
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
    /// Codec parameters as written by the codec (e.g. `alpha`, `qp`, `window`, `t_l`): every
    /// parameter the stream records, the ones the rate control chose included.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    /// The parameters the sweep was asked to set (`study sweep --param qp=9,11`), which tell
    /// variants of one codec at one target apart; empty when the codec ran with its defaults.
    /// They are part of the id ([`variant_label`]) and of the analysis' condition labels.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub variant: BTreeMap<String, f64>,
    /// Requested compression ratio, if the stimulus was made for a target rate.
    #[serde(default)]
    pub target_cr: Option<f64>,
    /// Requested bound on the largest joint position error, cm, if the stimulus is the
    /// smallest stream found whose max error stays within it (`study sweep --max-error-cm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_max_error_cm: Option<f64>,
    /// Compression ratio reached (4 bytes × channels × frames / bitstream bytes); 1 for a
    /// reference. `null` ("CR unknown") only for a stimulus made elsewhere whose stream size
    /// was not given (`study stimuli add` without `--stream` or `--bytes`): such a stimulus
    /// is shown and rated, but no table, fit or staircase that needs its ratio takes it. The
    /// key is required: a manifest that leaves it out is refused, not read as unknown.
    #[serde(deserialize_with = "required_nullable")]
    pub achieved_cr: Option<f64>,
    /// Bitstream size in bytes (0 for a reference).
    #[serde(default)]
    pub bytes: u64,
    /// Decoded clip file relative to the manifest's folder (the source's copy for a
    /// reference); empty for a crowd scene, whose characters' stimuli have the files.
    #[serde(default)]
    pub file: String,
    /// Skeleton file (ASF) relative to the manifest's folder, when `file` is an AMC.
    #[serde(default)]
    pub skeleton: Option<String>,
    /// Bitstream file relative to the manifest's folder.
    #[serde(default)]
    pub bitstream: Option<String>,
    /// SHA-256 of `file` (64 lowercase hex digits), recorded by the command that wrote the file
    /// (`study sweep`, `study crowd`): every preflight refuses a file whose content differs
    /// (changed, or swapped with another stimulus' file since).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
    /// SHA-256 of `bitstream`, likewise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bitstream_sha256: Option<String>,
    /// Objective error against the reference.
    #[serde(default)]
    pub metrics: Option<StimulusMetrics>,
    /// Encode time in milliseconds.
    #[serde(default)]
    pub encode_ms: Option<f64>,
    /// Decode time in milliseconds.
    #[serde(default)]
    pub decode_ms: Option<f64>,
    /// A crowd scene (thesis 6.5, `study crowd`): several characters, each shown by a
    /// stimulus of this manifest. Its `clip` is the scene's distance level, its `bytes` the
    /// sum of the characters' streams and its `achieved_cr` the scene's ratio (their raw
    /// sizes over those bytes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene: Option<SceneStimulus>,
}

/// What a crowd scene of the manifest shows: its distance level and, per character, the
/// stimulus it shows and how the scene's budget was shared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneStimulus {
    /// The study's distance level the scene was made for (`[scene] levels`).
    pub level: String,
    /// How the bytes were shared between the characters: `reference` (no compression),
    /// `fixed` (a ratio per group), or a total budget shared `uniform`ly, by `distance`
    /// (thesis eq. 6.4-6.5) or by `importance`.
    pub allocation: String,
    /// The total budget in bytes, when one was shared (`B` of eq. 6.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_bytes: Option<f64>,
    /// The characters, in the scene's order.
    pub characters: Vec<SceneMember>,
}

/// One character of a crowd scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneMember {
    /// Character name (`[[scene.characters]] name`).
    pub name: String,
    /// Its group.
    pub group: String,
    /// The stimulus it shows (an entry of this manifest: its compression ratio, bytes and
    /// error are that entry's).
    pub stimulus: String,
    /// Its distance from the camera on this level, cm (`d_C` of eq. 6.4).
    pub distance_cm: f64,
    /// Its share score `S_k` of eq. 6.5 (`d_m / d_k` when shared by distance, its importance,
    /// or 1 when shared uniformly); `None` when no budget was shared.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score: Option<f64>,
    /// Its budget `B_k` in bytes, when a budget was shared.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_bytes: Option<f64>,
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
    /// Joint position RMS error of the worst window (1 s of frames, sliding; see
    /// `docs/codecs.md`), cm: where a clip-wide RMS hides a broken stretch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_window_rms_cm: Option<f64>,
    /// First frame of that window (0-based).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_window_start_frame: Option<u64>,
    /// Frames in that window (the clip's rate rounded, or the whole clip when shorter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_window_frames: Option<u64>,
}

/// The variant part of a stimulus id and of a condition label: `key` then value for every
/// parameter, in key order, joined by `-` (`qp9-window128`); empty for no parameters. Values
/// print as Rust's shortest round-trip decimal (`0.25`, `128`), so a label reads back to the
/// numbers that made it.
pub fn variant_label(params: &BTreeMap<String, f64>) -> String {
    params
        .iter()
        .map(|(k, v)| format!("{k}{v}"))
        .collect::<Vec<_>>()
        .join("-")
}

/// The method a stimulus (or a condition) shows: the codec name, then `/` and its
/// [`variant_label`] when it has a variant (`wavelet-perceptual/qp9-window128`); the codec
/// name alone otherwise, so labels of sweeps without `--param` are what they always were.
pub fn method_label(codec: &str, variant: &BTreeMap<String, f64>) -> String {
    if variant.is_empty() {
        codec.to_string()
    } else {
        format!("{codec}/{}", variant_label(variant))
    }
}

impl Stimulus {
    /// The stimulus' method: codec and variant ([`method_label`]).
    pub fn method(&self) -> String {
        method_label(&self.codec, &self.variant)
    }
}

impl StimulusManifest {
    /// Every value of the manifest that cannot be true, one line each naming the stimulus
    /// (its place and id) and the key: a ratio, size, error, time or target that is not a
    /// finite number in its range, an RMS error above its maximum, a SHA-256 that is not 64
    /// hex digits; and the manifest's own: a version this build does not read, an id listed
    /// twice, a crowd scene named like a clip. A hand-written or damaged manifest would
    /// otherwise change the analysis (a negative RMS error changed simulated ratings).
    pub fn problems(&self) -> Vec<String> {
        /// `v` where it is not finite, or not above 0 (`zero_ok`: not 0 or more).
        fn range(v: f64, zero_ok: bool) -> Option<String> {
            let bad = !v.is_finite() || v < 0.0 || (!zero_ok && v == 0.0);
            let range = if zero_ok { "0 or more" } else { "more than 0" };
            bad.then(|| format!("{v} is not a finite number {range}"))
        }
        let mut out = Vec::new();
        for (i, s) in self.stimuli.iter().enumerate() {
            let mut values = vec![("achieved_cr", s.achieved_cr, false)];
            values.extend([
                ("target_cr", s.target_cr, false),
                ("target_max_error_cm", s.target_max_error_cm, false),
                ("encode_ms", s.encode_ms, true),
                ("decode_ms", s.decode_ms, true),
            ]);
            let mut found: Vec<(&str, String)> = Vec::new();
            if s.achieved_cr.is_none()
                && (s.codec == REFERENCE_CODEC
                    || s.bitstream.is_some()
                    || s.bytes > 0
                    || s.scene.is_some())
            {
                found.push((
                    "achieved_cr",
                    "is null (CR unknown), but a reference's is 1 and a stimulus with a \
                     stream, a size or a scene has one"
                        .into(),
                ));
            }
            if let Some(m) = &s.metrics {
                values.extend([
                    ("metrics.rms_cm", Some(m.rms_cm), true),
                    ("metrics.max_cm", Some(m.max_cm), true),
                    ("metrics.mean_angle_deg", Some(m.mean_angle_deg), true),
                    ("metrics.worst_window_rms_cm", m.worst_window_rms_cm, true),
                ]);
                // A difference (decoded − reference): any sign.
                if let Some(v) = m.foot_slide_cm_s.filter(|v| !v.is_finite()) {
                    found.push((
                        "metrics.foot_slide_cm_s",
                        format!("{v} is not a finite number"),
                    ));
                }
                // The RMS of errors is never above their largest (a little slack for the
                // digits JSON keeps).
                if m.rms_cm.is_finite()
                    && m.max_cm.is_finite()
                    && m.rms_cm > m.max_cm * (1.0 + 1e-9) + 1e-9
                {
                    found.push((
                        "metrics.rms_cm",
                        format!("{} is above metrics.max_cm {}", m.rms_cm, m.max_cm),
                    ));
                }
            }
            for (key, v, zero_ok) in values {
                if let Some(why) = v.and_then(|v| range(v, zero_ok)) {
                    found.push((key, why));
                }
            }
            for (key, hash) in [
                ("sha256", &s.sha256),
                ("bitstream_sha256", &s.bitstream_sha256),
            ] {
                if let Some(h) = hash
                    && !(h.len() == 64 && h.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')))
                {
                    found.push((key, format!("\"{h}\" is not 64 lowercase hex digits")));
                }
            }
            out.extend(
                found
                    .into_iter()
                    .map(|(key, why)| format!("stimuli[{i}] (\"{}\").{key}: {why}", s.id)),
            );
        }
        out.extend(self.whole_problems());
        out
    }

    /// What is wrong with the manifest as a whole: a version this build does not read, an id
    /// listed twice, a crowd scene whose level is also the name of a clip.
    fn whole_problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !(MANIFEST_VERSION_MIN..=MANIFEST_VERSION).contains(&self.version) {
            out.push(format!(
                "manifest version {} is not supported (this build reads \
                 {MANIFEST_VERSION_MIN} to {MANIFEST_VERSION})",
                self.version,
            ));
        }
        let mut seen = std::collections::BTreeSet::new();
        for (i, s) in self.stimuli.iter().enumerate() {
            if !seen.insert(s.id.as_str()) {
                out.push(format!(
                    "stimuli[{i}]: stimulus id {:?} is listed twice",
                    s.id
                ));
            }
        }
        // A crowd scene's clip is its level: a clip of one figure by that name would make the
        // scene's reference ambiguous.
        let plain: std::collections::BTreeSet<&str> = self
            .stimuli
            .iter()
            .filter(|s| s.scene.is_none())
            .map(|s| s.clip.as_str())
            .collect();
        for (i, s) in self.stimuli.iter().enumerate() {
            if s.scene.is_some() && plain.contains(s.clip.as_str()) {
                out.push(format!(
                    "stimuli[{i}]: crowd scene {:?} is of level {:?}, also the name of a clip",
                    s.id, s.clip
                ));
            }
        }
        out
    }

    /// What a trial row logs about crowd scene `id` (`trials.csv` columns 30-32): each
    /// character's compression ratio as `cr_<name>`, the scene's distance level as `level`
    /// (1-based, in the order of `levels`), the scene's ratio, and the root mean square of
    /// the characters' joint RMS errors. `None` for a stimulus that is no compressed scene or
    /// whose characters are not in the manifest.
    pub fn scene_encoding(&self, id: &str, levels: &[String]) -> Option<StimulusEncoding> {
        let s = self.get(id)?;
        let scene = s.scene.as_ref().filter(|_| s.codec != REFERENCE_CODEC)?;
        let level = levels.iter().position(|l| *l == scene.level)?;
        let mut codec_params = BTreeMap::from([("level".to_string(), (level + 1) as f64)]);
        let mut squares = 0.0;
        for c in &scene.characters {
            let m = self.get(&c.stimulus)?;
            codec_params.insert(format!("cr_{}", c.name), m.achieved_cr?);
            squares += m.metrics.map_or(0.0, |x| x.rms_cm * x.rms_cm);
        }
        Some(StimulusEncoding {
            codec_params,
            achieved_cr: s.achieved_cr?,
            rms_cm: (squares / scene.characters.len().max(1) as f64).sqrt(),
        })
    }

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
