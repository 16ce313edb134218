//! The study file (`STUDY.toml`, format version 1): parsing and validation.
//!
//! Parsing walks the TOML tree by hand rather than through `serde` so that every problem
//! (unknown key, wrong type, a stimulus id missing from the manifest, a zero step, a start
//! outside min/max, a staircase level with no stimulus, a live staircase's codec parameter
//! that the codec does not take) is collected with its key path and reported all at once
//! before any session starts. Codecs are known through a [`CodecCatalog`]. The format is
//! documented in `docs/study-file.md`.

mod check;
mod conditions;
mod crowdsourcing;
mod design;
mod fields;
mod lines;
mod live;
mod mushra;
mod presentation;
mod quest;
mod rendering;
mod scale;
mod scene;
mod session;
mod simulation;
mod staircase;
mod top;
mod viewing;

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use toml::Table;

use crate::catalog::CodecCatalog;
use crate::manifest::StimulusManifest;
use crate::record::{Arrangement, Position, Protocol};
use crate::staircase::StaircaseSettings;
use check::Ctx;
pub use crowdsourcing::{CrowdsourcingSettings, GoldTrial, HiddenRule, TooFastRule};
pub use fields::{FieldKind, MAX_FIELD_CHARS, SubjectField};
pub use mushra::{AnchorRule, MushraSettings, screens as mushra_screens};
pub use quest::domain as quest_domain;
pub use rendering::RenderingSettings;
pub use scene::{
    MAX_CHARACTERS, MAX_LEVELS, Placement, SceneCamera, SceneCharacter, SceneLight, SceneSettings,
};
pub use viewing::{ScreenSize, ViewingDistance, ViewingSettings};

/// Current version of the study file format.
pub const STUDY_FORMAT_VERSION: u32 = 1;
/// Largest study file accepted, bytes (checked before reading it whole).
pub const MAX_STUDY_BYTES: u64 = 1 << 20;
/// Largest stimulus manifest accepted, bytes.
pub const MAX_MANIFEST_BYTES: u64 = 64 << 20;
/// Most conditions (test stimuli) a study may list.
pub const MAX_CONDITIONS: usize = 100_000;
/// Most pairs a pair comparison study may compare (every pair of a clip's conditions is one
/// trial per subject: 10 000 is far beyond a session, and bounds what a plan allocates).
pub const MAX_PAIRS: usize = 10_000;
/// Most staircases a study may interleave.
pub const MAX_TRACKS: usize = 256;

/// One problem in a study file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StudyIssue {
    /// Dotted key path (`staircase.tracks[1].clip`), or `""` for the whole file.
    pub key: String,
    /// What is wrong.
    pub reason: String,
    /// 1-based line of the key in the file (of the table it belongs in when the file lacks
    /// it); `None` when the file does not place it.
    pub line: Option<usize>,
}

impl fmt::Display for StudyIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.key.is_empty() {
            write!(f, "{}", self.reason)
        } else {
            write!(f, "{}: {}", self.key, self.reason)
        }
    }
}

/// Why a study file was rejected.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StudyError {
    /// The file could not be read.
    #[error("{}: cannot read: {cause}", path.display())]
    Io {
        /// File.
        path: PathBuf,
        /// Cause (part of the message, not a separate link of its chain).
        cause: std::io::Error,
    },
    /// The file is larger than [`MAX_STUDY_BYTES`].
    #[error("{}: {bytes} bytes is over the {limit}-byte limit", path.display())]
    TooLarge {
        /// File.
        path: PathBuf,
        /// Its size.
        bytes: u64,
        /// The limit.
        limit: u64,
    },
    /// Not valid TOML.
    #[error("{}:{line}:{column}: {message}", path.display())]
    Syntax {
        /// File.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Parser message.
        message: String,
    },
    /// Valid TOML with study problems, every one listed, each as `FILE:LINE: KEY: REASON`
    /// (`FILE: KEY: REASON` when the file does not place the key).
    #[error("{}: {} problem(s):{}", path.display(), issues.len(), listed(path, issues))]
    Invalid {
        /// File.
        path: PathBuf,
        /// All problems found.
        issues: Vec<StudyIssue>,
    },
}

/// `issues` one per line, each after the file and its line: `\n  study.toml:3: nmae: ...`.
fn listed(path: &Path, issues: &[StudyIssue]) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    for issue in issues {
        let _ = write!(out, "\n  {}", path.display());
        if let Some(line) = issue.line {
            let _ = write!(out, ":{line}");
        }
        let _ = write!(out, ": {issue}");
    }
    out
}

/// Where the reference goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ReferencePlacement {
    /// Always this position.
    Fixed(Position),
    /// Drawn per trial with probability one half.
    Random,
    /// Counterbalanced (`"balanced"`): each subject sees the reference in each position
    /// equally often (per condition in a rated study, per block of four trials in a
    /// staircase), and the next subject sees the mirror image ([`crate::design`]).
    Balanced,
}

/// The order of a rated study's test conditions (`[design] order`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConditionOrder {
    /// Shuffled per subject from the study seed.
    Random,
    /// A balanced Latin square (Williams design) over the conditions in file order; subject
    /// `k` takes row `k mod rows` ([`crate::design::williams_row`]).
    LatinSquare,
}

/// Design settings (`[design]`): counterbalancing and between-subject groups.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DesignSettings {
    /// The order of the test conditions.
    pub order: ConditionOrder,
    /// Between-subject groups (`[[design.groups]]`): each session is assigned one and sees
    /// only its conditions; empty when every subject sees every condition.
    #[serde(default)]
    pub groups: Vec<SubjectGroup>,
}

impl Default for DesignSettings {
    fn default() -> Self {
        Self {
            order: ConditionOrder::Random,
            groups: Vec::new(),
        }
    }
}

/// A between-subject group (`[[design.groups]]`): a name, the test conditions its subjects
/// see, and how many sessions it takes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SubjectGroup {
    /// Name (1-32 letters, digits, `-` or `_`), recorded in each of its sessions' manifests.
    pub name: String,
    /// Its test conditions' stimulus ids (each one of the study's conditions).
    pub stimuli: Vec<String>,
    /// Most sessions assigned to it; `None`: no limit.
    pub quota: Option<u32>,
}

/// Presentation settings (`[presentation]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PresentationSettings {
    /// Layout (DSCQS is always A B A B).
    pub arrangement: Arrangement,
    /// Where the reference is shown.
    pub reference_position: ReferencePlacement,
    /// How many times each stimulus plays before the subject may answer.
    pub playback_count: u32,
    /// Replays allowed per trial; `None` = unlimited (paper 000: as many as wanted).
    pub max_replays: Option<u32>,
    /// Loop playback until the subject answers.
    pub loop_playback: bool,
    /// Blank gap between trials, ms (shown after each answer, with its acknowledgement).
    pub gap_ms: u64,
    /// Mid-grey field between the intervals of a sequential or DSCQS presentation, ms
    /// (BT.500 DSCQS: about 3 s).
    #[serde(default)]
    pub grey_ms: u64,
    /// The on-screen names of the reference and the test stimulus, where the design tells
    /// the subject which is which (MOS); `None`: no labels (DSCQS and 2AFC by design, or a
    /// MOS study with `labels = false`).
    #[serde(default)]
    pub labels: Option<StimulusLabels>,
    /// Duration of one playback, ms (session time estimates, simulation clock).
    pub stimulus_duration_ms: u64,
    /// Whether the screen offers "no preference" beside the choices (a tie), where the
    /// method takes one ([`crate::methods::Method::offers_no_preference`]).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub no_preference: bool,
}

/// What the reference and the test stimulus are called on screen (`[presentation]
/// reference_label`, `test_label`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StimulusLabels {
    /// The reference's label (default "Original").
    pub reference: String,
    /// The test stimulus' label (default "Compressed").
    pub test: String,
}

/// Kind of rating scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScaleKind {
    /// Discrete categories `min, min+step, ..., max` (paper 000: 1-5 in 0.5 steps).
    Categorical,
    /// Continuous slider (BT.500 DSCQS: 0-100).
    Continuous,
}

/// Rating scale (`[scale]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RatingScale {
    /// Categorical or continuous.
    pub kind: ScaleKind,
    /// Lowest rating (worst).
    pub min: f64,
    /// Highest rating (best).
    pub max: f64,
    /// Category step (categorical) or slider resolution (continuous, optional).
    pub step: Option<f64>,
}

impl RatingScale {
    /// Whether `v` is a rating this scale allows.
    pub fn accepts(&self, v: f64) -> bool {
        if !(v.is_finite() && v >= self.min && v <= self.max) {
            return false;
        }
        match (self.kind, self.step) {
            (ScaleKind::Categorical, Some(step)) => {
                let k = (v - self.min) / step;
                (k - k.round()).abs() < 1e-9
            }
            _ => true,
        }
    }

    /// Rounds `v` to the nearest allowed rating.
    pub fn snap(&self, v: f64) -> f64 {
        let v = v.max(self.min).min(self.max);
        match self.step {
            Some(step) if step > 0.0 => (self.min + ((v - self.min) / step).round() * step)
                .max(self.min)
                .min(self.max),
            _ => v,
        }
    }
}

/// Session settings (`[session]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionSettings {
    /// Session time limit, ms (paper 000: 40 min); `None` = no limit.
    pub time_limit_ms: Option<u64>,
    /// A break every this many trials; `None` = no breaks.
    pub break_every_trials: Option<u32>,
    /// Hidden repeats inserted among the test trials (paper 000: 8).
    pub hidden_repeats: u32,
    /// Subject fields a runner collects before the session, each with its kind.
    pub subject_fields: Vec<SubjectField>,
    /// Consent text the subject must accept before the session (none: no consent step).
    #[serde(default)]
    pub consent: Option<String>,
    /// Instructions shown before the first trial (none: the protocol's default text).
    #[serde(default)]
    pub instructions: Option<String>,
}

/// A test stimulus with its reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Condition {
    /// Test stimulus id.
    pub stimulus: String,
    /// Reference stimulus id (same clip, codec `reference`).
    pub reference: String,
}

/// One staircase of an interleaved set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Track {
    /// Name, logged as the trial's condition.
    pub name: String,
    /// Source clip (empty in a live staircase, whose clips take turns across trials).
    pub clip: String,
    /// Reference stimulus id of that clip (empty in a live staircase).
    pub reference: String,
    /// Settings (shared settings with this track's start).
    pub settings: StaircaseSettings,
    /// Available levels: (parameter value, stimulus id), sorted by value (empty in a live
    /// staircase, where every level is encoded on demand).
    pub levels: Vec<(f64, String)>,
}

impl Track {
    /// The stimulus shown at `level`: the one with the nearest parameter value within
    /// `tolerance`.
    pub fn stimulus_at(&self, level: f64, tolerance: f64) -> Option<&str> {
        let i = self.levels.partition_point(|(v, _)| *v < level);
        let mut best: Option<(f64, &str)> = None;
        for j in [i.wrapping_sub(1), i] {
            if let Some((v, id)) = self.levels.get(j) {
                let d = (v - level).abs();
                if d <= tolerance && best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, id));
                }
            }
        }
        best.map(|(_, id)| id)
    }
}

/// Staircase study settings (`[staircase]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StaircaseStudy {
    /// Parameter that is the level (thesis ch. 5: `t_l`): a manifest parameter, or in a live
    /// staircase the codec parameter the runner encodes with.
    pub param: String,
    /// Codec whose stimuli give the levels (live: the codec the runner encodes with).
    pub codec: String,
    /// Largest distance between a level and the parameter of the stimulus shown for it
    /// (unused by a live staircase).
    pub level_tolerance: f64,
    /// The interleaved staircases.
    pub tracks: Vec<Track>,
    /// Set when the level is a codec parameter and the runner encodes each trial's stimulus
    /// on the fly (`[staircase.live]`); `None` for stimuli from the manifest.
    pub live: Option<LiveStaircase>,
    /// Set when every track is a QUEST+ or Psi procedure (`method`, `[staircase.quest]`),
    /// shared by the tracks; `None` for up-down staircases.
    #[serde(default)]
    pub quest: Option<crate::quest::QuestSettings>,
    /// Practice trials before the staircases start (`practice_trials`), the tracks in turn,
    /// logged in block `familiarization` and left out of every analysis.
    #[serde(default)]
    pub practice_trials: u32,
    /// The level of every practice trial (`practice_level`); `None`: each track's start.
    #[serde(default)]
    pub practice_level: Option<f64>,
}

/// Prefix of every stimulus id a live staircase derives.
pub const LIVE_ID_PREFIX: &str = "live:";

impl StaircaseStudy {
    /// The derived stimulus id of a live trial: `live:<clip>/<codec>/<param>=<level>`, the
    /// level written in Rust's shortest round-trip form so the id names the exact value.
    pub fn live_stimulus_id(&self, clip: &str, level: f64) -> String {
        format!(
            "{LIVE_ID_PREFIX}{clip}/{}/{}={level}",
            self.codec, self.param
        )
    }
}

/// The order in which a live staircase's clips take turns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClipOrder {
    /// The clips in the order listed, one per trial, over and over (thesis ch. 5: the five
    /// motions were used in turn).
    InTurn,
    /// In turn, in an order drawn per subject from the study seed (counterbalanced).
    Shuffled,
}

/// One source clip of a live staircase.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LiveClip {
    /// Clip name in the manifest.
    pub clip: String,
    /// Its reference stimulus id (the source the runner encodes).
    pub reference: String,
}

/// A codec-in-the-loop staircase (`[staircase.live]`): each trial's distorted stimulus is the
/// reference clip encoded and decoded at the trial's level by the runner; the protocol only
/// names it ([`StaircaseStudy::live_stimulus_id`]) and never encodes anything.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveStaircase {
    /// Clips that alternate between trials.
    pub clips: Vec<LiveClip>,
    /// How they take turns.
    pub order: ClipOrder,
    /// Fixed values of the codec's other parameters.
    pub params: BTreeMap<String, f64>,
    /// Decoder context file (e.g. a primitive database) as written, relative to the study
    /// file.
    pub database: Option<String>,
    /// A file of command-defined codecs (the lab's own encoder and decoder), relative to the
    /// study file: `[staircase] codec` may name one of them.
    pub codecs: Option<String>,
}

/// Psychometric function family of the simulated 2AFC observer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Psychometric {
    /// `1 - exp(-(x/α)^β)`.
    Weibull,
    /// `1 / (1 + exp(-β (x - α)))`.
    Logistic,
}

/// Objective error measure a simulated rating observer bases its quality on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// Joint position RMS error, cm.
    RmsCm,
    /// Largest joint position error, cm.
    MaxCm,
    /// Mean absolute angle error, degrees.
    MeanAngleDeg,
}

/// What a simulated 2AFC observer's psychometric function is a function of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Detection {
    /// The staircase level itself (α in level units).
    Level,
    /// The objective error (`metric`) of the trial's distorted stimulus: measured on the
    /// decoded clip in a live staircase, from the manifest otherwise (α in metric units).
    Error,
}

/// Simulated observer settings (`[simulation]`), used by `study simulate` only.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationSettings {
    /// Error measure behind the latent quality.
    pub metric: Metric,
    /// Metric value at which latent quality has fallen to 1/e of the scale range.
    pub quality_scale: f64,
    /// SD of a subject's constant bias, scale units.
    pub bias_sd: f64,
    /// SD of trial-to-trial rating noise, scale units.
    pub noise_sd: f64,
    /// Psychometric family of the 2AFC observer.
    pub psychometric: Psychometric,
    /// Input of the 2AFC observer's psychometric function.
    pub detection: Detection,
    /// Level at which detection is 63 % (Weibull α) or 50 % (logistic α) of the way from guess
    /// rate to 1.
    pub threshold: f64,
    /// Slope β.
    pub slope: f64,
    /// Lapse rate λ (wrong guesses at any level).
    pub lapse: f64,
    /// Mean response time, ms.
    pub response_time_ms: u64,
    /// Crowd scenes: how much the simulated observer attends to each group (or character) of
    /// the `[scene]`, by name; 1 for those not named. A scene's error is the
    /// attention-weighted mean of its characters' errors, each scaled by its apparent size
    /// (the nearest character's distance over its own), see [`crate::observer`].
    #[serde(default)]
    pub attention: BTreeMap<String, f64>,
}

impl Default for SimulationSettings {
    fn default() -> Self {
        Self {
            metric: Metric::RmsCm,
            quality_scale: 2.0,
            bias_sd: 0.25,
            noise_sd: 0.35,
            psychometric: Psychometric::Weibull,
            detection: Detection::Level,
            threshold: 0.012,
            slope: 3.5,
            lapse: 0.02,
            response_time_ms: 1500,
            attention: BTreeMap::new(),
        }
    }
}

/// A validated study: everything an engine needs, stimulus ids checked against the manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyDefinition {
    /// Format version of the file ([`STUDY_FORMAT_VERSION`]).
    pub format_version: u32,
    /// Study name.
    pub name: String,
    /// The title subjects see (`title`); `None`: the name.
    pub title: Option<String>,
    /// Protocol.
    pub protocol: Protocol,
    /// Manifest path as written in the file (relative to the study file).
    pub stimuli_path: String,
    /// Randomization seed of the trial plans (subject k's plan derives from it and k).
    pub seed: u64,
    /// Test conditions (MOS, DSCQS).
    pub conditions: Vec<Condition>,
    /// Familiarization stimuli, spanning the quality range (MOS, DSCQS).
    pub familiarization: Vec<Condition>,
    /// Presentation.
    pub presentation: PresentationSettings,
    /// Rating scale (MOS, DSCQS).
    pub scale: RatingScale,
    /// Session settings.
    pub session: SessionSettings,
    /// Staircases (staircase protocol).
    pub staircase: Option<StaircaseStudy>,
    /// Simulated observers.
    pub simulation: SimulationSettings,
    /// How the runner draws the figures (`[rendering]`).
    pub rendering: RenderingSettings,
    /// What a study served to browsers needs (`[crowdsourcing]`).
    pub crowdsourcing: CrowdsourcingSettings,
    /// Counterbalancing (`[design]`).
    pub design: DesignSettings,
    /// The viewing conditions the experimenter confirms before each session (`[viewing]`);
    /// `None`: the study states none.
    pub viewing: Option<ViewingSettings>,
    /// Several characters per pane (`[scene]`, thesis 6.5): the conditions are crowd scenes
    /// of the manifest, drawn with this camera and light; `None` for one figure per pane.
    pub scene: Option<SceneSettings>,
    /// A MUSHRA study's anchors and post-screening rules (`[mushra]`); `None` for other
    /// protocols.
    pub mushra: Option<MushraSettings>,
    /// The stimulus manifest.
    pub manifest: StimulusManifest,
}

/// The conditions of each clip (by reference), as indices into `conditions`, the clips in
/// the order their first condition is listed.
pub(crate) fn conditions_by_clip(conditions: &[Condition]) -> Vec<Vec<usize>> {
    let mut slot: BTreeMap<&str, usize> = BTreeMap::new();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (i, c) in conditions.iter().enumerate() {
        let k = *slot.entry(c.reference.as_str()).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[k].push(i);
    }
    groups
}

/// How many pairs [`pairs_of`] gives, without making them.
pub(crate) fn pair_count(conditions: &[Condition]) -> usize {
    conditions_by_clip(conditions)
        .iter()
        .map(|m| m.len().saturating_mul(m.len().saturating_sub(1)) / 2)
        .fold(0, usize::saturating_add)
}

/// Every unordered pair of `conditions` that share a reference (a clip), `(i, j)` with
/// `i < j`, grouped by clip in the order clips first appear. A validated study has at most
/// [`MAX_PAIRS`] of them.
pub(crate) fn pairs_of(conditions: &[Condition]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for members in conditions_by_clip(conditions) {
        for (k, &i) in members.iter().enumerate() {
            for &j in &members[k + 1..] {
                out.push((i, j));
            }
        }
    }
    out
}

/// 64-bit FNV-1a of `bytes`, hex: identifies a study file in session manifests (not a
/// cryptographic hash).
pub fn content_hash(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

impl StudyDefinition {
    /// The pairs of a pair comparison (P.910 PC): every unordered pair of conditions of the
    /// same source clip (the same reference), as indices into [`Self::conditions`], `(i, j)`
    /// with `i < j`; the clips in the order their first condition is listed, a clip's pairs
    /// in lexicographic order.
    pub fn pairs(&self) -> Vec<(usize, usize)> {
        pairs_of(&self.conditions)
    }

    /// The title shown to subjects: `title` from the study file, or else
    /// [`crate::texts::DEFAULT_TITLE`] (never the study's `name`, the experimenter's handle).
    pub fn title(&self) -> &str {
        self.title.as_deref().unwrap_or(crate::texts::DEFAULT_TITLE)
    }

    /// The study as a session of between-subject group `group` runs it: the test conditions
    /// are the group's and the catch trials' (every session gets the catch trials), in the
    /// order `[conditions]` lists them, so a Latin square runs over the group's conditions.
    /// Without groups the study is itself (and `group` must be `None`).
    ///
    /// # Errors
    /// A group given to a study without groups, none given to a study with groups, or a
    /// name the study does not have.
    pub fn for_group(&self, group: Option<&str>) -> Result<std::borrow::Cow<'_, Self>, String> {
        let groups = &self.design.groups;
        match group {
            None if groups.is_empty() => Ok(std::borrow::Cow::Borrowed(self)),
            None => Err(format!(
                "study {:?} assigns every session to one of its groups ({}); none was given",
                self.name,
                self.group_names()
            )),
            Some(g) if groups.is_empty() => Err(format!(
                "study {:?} has no between-subject groups ([[design.groups]]), but the session \
                 is in group {g:?}",
                self.name
            )),
            Some(g) => {
                let Some(group) = groups.iter().find(|x| x.name == g) else {
                    return Err(format!(
                        "study {:?} has no group {g:?} (its groups: {})",
                        self.name,
                        self.group_names()
                    ));
                };
                let keep = |c: &Condition| {
                    group.stimuli.contains(&c.stimulus)
                        || self
                            .crowdsourcing
                            .gold
                            .iter()
                            .any(|t| t.stimulus == c.stimulus)
                };
                let mut study = self.clone();
                study.conditions.retain(keep);
                Ok(std::borrow::Cow::Owned(study))
            }
        }
    }

    /// The between-subject groups' names, comma-separated, for messages.
    fn group_names(&self) -> String {
        let names: Vec<&str> = self.design.groups.iter().map(|g| g.name.as_str()).collect();
        names.join(", ")
    }

    /// Reads and validates a study file and its stimulus manifest; a live staircase's codec
    /// settings are checked against `codecs` (see [`crate::catalog`]).
    ///
    /// # Errors
    /// [`StudyError`] with every problem found.
    pub fn load(path: &Path, codecs: &dyn CodecCatalog) -> Result<Self, StudyError> {
        Self::load_text(path, codecs).map(|(study, _)| study)
    }

    /// As [`StudyDefinition::load`], also returning the text the definition was read from (a
    /// runner hashes and archives exactly those bytes, read once).
    ///
    /// # Errors
    /// [`StudyError`] with every problem found.
    pub fn load_text(path: &Path, codecs: &dyn CodecCatalog) -> Result<(Self, String), StudyError> {
        let text = read_limited(path, MAX_STUDY_BYTES)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let manifest = |rel: &str| {
            let p = base.join(rel);
            let t = read_limited(&p, MAX_MANIFEST_BYTES).map_err(|e| e.to_string())?;
            serde_json::from_str::<StimulusManifest>(&t).map_err(|e| json_error(&p, &e))
        };
        let study = Self::parse(&text, path, manifest, codecs)?;
        Ok((study, text))
    }

    /// Validates study `text` (named `path` in errors); `manifest` loads the manifest named by
    /// the `stimuli` key, and `codecs` tells what a live staircase's codec accepts.
    ///
    /// # Errors
    /// [`StudyError::Syntax`] or [`StudyError::Invalid`] with every problem found.
    pub fn parse(
        text: &str,
        path: &Path,
        manifest: impl FnOnce(&str) -> Result<StimulusManifest, String>,
        codecs: &dyn CodecCatalog,
    ) -> Result<Self, StudyError> {
        let table = parse_toml(text, path)?;
        let mut cx = Ctx::default();
        let def = top::parse_table(&table, &mut cx, manifest, codecs);
        finish(def, cx, path, text, "study file is invalid")
    }

    /// Sessions' time estimate per trial, ms (playbacks, gaps).
    pub fn trial_presentation_ms(&self) -> u64 {
        let p = &self.presentation;
        let shows = match p.arrangement {
            Arrangement::SideBySide | Arrangement::Single | Arrangement::Grid => 1,
            Arrangement::Sequential => 2,
            Arrangement::Abab => 4,
        };
        let n = u64::from(p.playback_count.max(1)) * shows;
        n * p.stimulus_duration_ms + n.saturating_sub(1) * p.gap_ms
    }
}

/// `text` as a TOML table, or its syntax error with line and column (the file named `path`).
fn parse_toml(text: &str, path: &Path) -> Result<Table, StudyError> {
    text.parse().map_err(|e: toml::de::Error| {
        let (line, column) = e.span().map_or((0, 0), |s| line_col(text, s.start));
        StudyError::Syntax {
            path: path.to_path_buf(),
            line,
            column,
            message: e.message().to_string(),
        }
    })
}

/// What a parse of the file at `path` with `text` gave: the value when no problem was found,
/// else every problem, each with its line (`fallback` when the parse gave nothing and said
/// nothing).
fn finish<T>(
    value: Option<T>,
    mut cx: Ctx,
    path: &Path,
    text: &str,
    fallback: &str,
) -> Result<T, StudyError> {
    match value {
        Some(v) if cx.issues.is_empty() => Ok(v),
        _ => {
            if cx.issues.is_empty() {
                cx.err("", fallback);
            }
            lines::locate(&mut cx.issues, text);
            Err(StudyError::Invalid {
                path: path.to_path_buf(),
                issues: cx.issues,
            })
        }
    }
}

fn read_limited(path: &Path, limit: u64) -> Result<String, StudyError> {
    let meta = std::fs::metadata(path).map_err(|cause| StudyError::Io {
        path: path.to_path_buf(),
        cause,
    })?;
    if meta.len() > limit {
        return Err(StudyError::TooLarge {
            path: path.to_path_buf(),
            bytes: meta.len(),
            limit,
        });
    }
    std::fs::read_to_string(path).map_err(|cause| StudyError::Io {
        path: path.to_path_buf(),
        cause,
    })
}

/// A JSON file's error as `FILE:LINE:COLUMN: what` (serde_json says where after what).
fn json_error(path: &Path, e: &serde_json::Error) -> String {
    let text = e.to_string();
    let at = format!(" at line {} column {}", e.line(), e.column());
    match text.strip_suffix(&at) {
        Some(what) if e.line() > 0 => {
            format!("{}:{}:{}: {what}", path.display(), e.line(), e.column())
        }
        _ => format!("{}: {text}", path.display()),
    }
}

/// 1-based line and column of byte offset `at` in `text`.
pub fn line_col(text: &str, at: usize) -> (usize, usize) {
    let at = at.min(text.len());
    let before = text.get(..at).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}
