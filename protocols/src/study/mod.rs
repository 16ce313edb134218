//! The study file (`STUDY.toml`, format version 1): parsing and validation.
//!
//! Parsing walks the TOML tree by hand rather than through `serde` so that every problem
//! (unknown key, wrong type, a stimulus id missing from the manifest, a zero step, a start
//! outside min/max, a staircase level with no stimulus) is collected with its key path and
//! reported all at once before any session starts. The format is documented in
//! `docs/study-file.md`.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use toml::{Table, Value};

use crate::manifest::{REFERENCE_CODEC, StimulusManifest};
use crate::record::{Arrangement, Position, Protocol};
use crate::staircase::{StaircaseSettings, StepType, check_settings};

/// Current version of the study file format.
pub const STUDY_FORMAT_VERSION: u32 = 1;
/// Largest study file accepted, bytes (checked before reading it whole).
pub const MAX_STUDY_BYTES: u64 = 1 << 20;
/// Largest stimulus manifest accepted, bytes.
pub const MAX_MANIFEST_BYTES: u64 = 64 << 20;
/// Most conditions (test stimuli) a study may list.
pub const MAX_CONDITIONS: usize = 100_000;
/// Most staircases a study may interleave.
pub const MAX_TRACKS: usize = 256;
/// Most levels enumerated when checking that every staircase level has a stimulus.
const MAX_ENUMERATED_LEVELS: usize = 4096;

/// One problem in a study file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StudyIssue {
    /// Dotted key path (`staircase.tracks[1].clip`), or `""` for the whole file.
    pub key: String,
    /// What is wrong.
    pub reason: String,
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
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
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
    #[error("{}: line {line}, column {column}: {message}", path.display())]
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
    /// Valid TOML with study problems, every one listed.
    #[error("{}: {} problem(s):\n  {}", path.display(), issues.len(),
        issues.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n  "))]
    Invalid {
        /// File.
        path: PathBuf,
        /// All problems found.
        issues: Vec<StudyIssue>,
    },
}

/// Where the reference goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ReferencePlacement {
    /// Always this position.
    Fixed(Position),
    /// Drawn per trial with probability one half.
    Random,
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
    /// Gap between sequential stimuli, ms.
    pub gap_ms: u64,
    /// Duration of one playback, ms (session time estimates, simulation clock).
    pub stimulus_duration_ms: u64,
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
    /// Subject fields a runner collects before the session.
    pub subject_fields: Vec<String>,
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
    /// The stimulus manifest.
    pub manifest: StimulusManifest,
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
    /// Reads and validates a study file and its stimulus manifest.
    ///
    /// # Errors
    /// [`StudyError`] with every problem found.
    pub fn load(path: &Path) -> Result<Self, StudyError> {
        let text = read_limited(path, MAX_STUDY_BYTES)?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::parse(&text, path, |rel| {
            let p = base.join(rel);
            let t = read_limited(&p, MAX_MANIFEST_BYTES).map_err(|e| e.to_string())?;
            serde_json::from_str::<StimulusManifest>(&t)
                .map_err(|e| format!("{}: {e}", p.display()))
        })
    }

    /// Validates study `text` (named `path` in errors); `manifest` loads the manifest named by
    /// the `stimuli` key.
    ///
    /// # Errors
    /// [`StudyError::Syntax`] or [`StudyError::Invalid`] with every problem found.
    pub fn parse(
        text: &str,
        path: &Path,
        manifest: impl FnOnce(&str) -> Result<StimulusManifest, String>,
    ) -> Result<Self, StudyError> {
        let table: Table = text.parse().map_err(|e: toml::de::Error| {
            let (line, column) = e.span().map_or((0, 0), |s| line_col(text, s.start));
            StudyError::Syntax {
                path: path.to_path_buf(),
                line,
                column,
                message: e.message().to_string(),
            }
        })?;
        let mut cx = Ctx::default();
        let def = parse_table(&table, &mut cx, manifest);
        match def {
            Some(d) if cx.issues.is_empty() => Ok(d),
            _ => {
                if cx.issues.is_empty() {
                    cx.err("", "study file is invalid");
                }
                Err(StudyError::Invalid {
                    path: path.to_path_buf(),
                    issues: cx.issues,
                })
            }
        }
    }

    /// Sessions' time estimate per trial, ms (playbacks, gaps).
    pub fn trial_presentation_ms(&self) -> u64 {
        let p = &self.presentation;
        let shows = match p.arrangement {
            Arrangement::SideBySide => 1,
            Arrangement::Sequential => 2,
            Arrangement::Abab => 4,
        };
        let n = u64::from(p.playback_count.max(1)) * shows;
        n * p.stimulus_duration_ms + n.saturating_sub(1) * p.gap_ms
    }
}

fn read_limited(path: &Path, limit: u64) -> Result<String, StudyError> {
    let meta = std::fs::metadata(path).map_err(|source| StudyError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if meta.len() > limit {
        return Err(StudyError::TooLarge {
            path: path.to_path_buf(),
            bytes: meta.len(),
            limit,
        });
    }
    std::fs::read_to_string(path).map_err(|source| StudyError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// 1-based line and column of byte offset `at` in `text`.
pub fn line_col(text: &str, at: usize) -> (usize, usize) {
    let at = at.min(text.len());
    let before = text.get(..at).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

#[derive(Default)]
struct Ctx {
    issues: Vec<StudyIssue>,
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

fn type_name(v: &Value) -> &'static str {
    match v {
        Value::String(_) => "a string",
        Value::Integer(_) => "an integer",
        Value::Float(_) => "a float",
        Value::Boolean(_) => "a boolean",
        Value::Datetime(_) => "a date-time",
        Value::Array(_) => "an array",
        Value::Table(_) => "a table",
    }
}

impl Ctx {
    fn err(&mut self, key: impl Into<String>, reason: impl Into<String>) {
        self.issues.push(StudyIssue {
            key: key.into(),
            reason: reason.into(),
        });
    }

    fn known(&mut self, t: &Table, path: &str, allowed: &[&str]) {
        for k in t.keys() {
            if !allowed.contains(&k.as_str()) {
                self.err(
                    join(path, k),
                    format!("unknown key (allowed: {})", allowed.join(", ")),
                );
            }
        }
    }

    fn wrong(&mut self, path: &str, key: &str, want: &str, v: &Value) {
        self.err(
            join(path, key),
            format!("expected {want}, got {}", type_name(v)),
        );
    }

    fn table<'a>(&mut self, t: &'a Table, path: &str, key: &str) -> Option<&'a Table> {
        match t.get(key)? {
            Value::Table(x) => Some(x),
            v => {
                self.wrong(path, key, "a table", v);
                None
            }
        }
    }

    fn string(&mut self, t: &Table, path: &str, key: &str) -> Option<String> {
        match t.get(key)? {
            Value::String(s) => Some(s.clone()),
            v => {
                self.wrong(path, key, "a string", v);
                None
            }
        }
    }

    fn boolean(&mut self, t: &Table, path: &str, key: &str) -> Option<bool> {
        match t.get(key)? {
            Value::Boolean(b) => Some(*b),
            v => {
                self.wrong(path, key, "true or false", v);
                None
            }
        }
    }

    fn int(&mut self, t: &Table, path: &str, key: &str, lo: i64, hi: i64) -> Option<i64> {
        match t.get(key)? {
            Value::Integer(i) if (lo..=hi).contains(i) => Some(*i),
            Value::Integer(i) => {
                self.err(join(path, key), format!("{i} is outside {lo}..={hi}"));
                None
            }
            v => {
                self.wrong(path, key, "an integer", v);
                None
            }
        }
    }

    fn uint(&mut self, t: &Table, path: &str, key: &str, hi: u32) -> Option<u32> {
        self.int(t, path, key, 0, i64::from(hi)).map(|v| v as u32)
    }

    fn float(&mut self, t: &Table, path: &str, key: &str) -> Option<f64> {
        match t.get(key)? {
            Value::Float(f) if f.is_finite() => Some(*f),
            Value::Float(f) => {
                self.err(join(path, key), format!("{f} is not a finite number"));
                None
            }
            Value::Integer(i) => Some(*i as f64),
            v => {
                self.wrong(path, key, "a number", v);
                None
            }
        }
    }

    fn strings(&mut self, t: &Table, path: &str, key: &str) -> Option<Vec<String>> {
        match t.get(key)? {
            Value::Array(a) => {
                let mut out = Vec::with_capacity(a.len().min(MAX_CONDITIONS));
                if a.len() > MAX_CONDITIONS {
                    self.err(
                        join(path, key),
                        format!("{} entries, limit {MAX_CONDITIONS}", a.len()),
                    );
                    return None;
                }
                for (i, v) in a.iter().enumerate() {
                    match v {
                        Value::String(s) => out.push(s.clone()),
                        v => self.wrong(path, &format!("{key}[{i}]"), "a string", v),
                    }
                }
                Some(out)
            }
            v => {
                self.wrong(path, key, "an array of strings", v);
                None
            }
        }
    }

    fn floats(&mut self, t: &Table, path: &str, key: &str) -> Option<Vec<f64>> {
        match t.get(key)? {
            Value::Array(a) if a.len() <= MAX_CONDITIONS => {
                let mut out = Vec::with_capacity(a.len());
                for (i, v) in a.iter().enumerate() {
                    match v {
                        Value::Float(f) if f.is_finite() => out.push(*f),
                        Value::Integer(n) => out.push(*n as f64),
                        v => self.wrong(path, &format!("{key}[{i}]"), "a finite number", v),
                    }
                }
                Some(out)
            }
            v => {
                self.wrong(path, key, "an array of numbers (at most 100000)", v);
                None
            }
        }
    }

    fn parse_enum<T: std::str::FromStr<Err = String>>(
        &mut self,
        t: &Table,
        path: &str,
        key: &str,
    ) -> Option<T> {
        let s = self.string(t, path, key)?;
        match s.parse() {
            Ok(v) => Some(v),
            Err(e) => {
                self.err(join(path, key), e);
                None
            }
        }
    }

    fn pick<T: Copy>(
        &mut self,
        t: &Table,
        path: &str,
        key: &str,
        options: &[(&str, T)],
    ) -> Option<T> {
        let s = self.string(t, path, key)?;
        if let Some((_, v)) = options.iter().find(|(n, _)| *n == s) {
            return Some(*v);
        }
        let names: Vec<&str> = options.iter().map(|(n, _)| *n).collect();
        self.err(
            join(path, key),
            format!("expected one of {}, got {s:?}", names.join(", ")),
        );
        None
    }

    fn required<T>(&mut self, v: Option<T>, t: &Table, path: &str, key: &str) -> Option<T> {
        if v.is_none() && !t.contains_key(key) {
            self.err(join(path, key), "missing");
        }
        v
    }
}

const TOP_KEYS: &[&str] = &[
    "format_version",
    "name",
    "protocol",
    "stimuli",
    "seed",
    "conditions",
    "presentation",
    "scale",
    "session",
    "staircase",
    "simulation",
];

#[expect(
    clippy::too_many_lines,
    reason = "one pass over the top-level keys, kept together so the order of checks reads like the file"
)]
fn parse_table(
    t: &Table,
    cx: &mut Ctx,
    load_manifest: impl FnOnce(&str) -> Result<StimulusManifest, String>,
) -> Option<StudyDefinition> {
    cx.known(t, "", TOP_KEYS);
    let version = cx.int(t, "", "format_version", 0, i64::from(u32::MAX));
    let version = cx.required(version, t, "", "format_version");
    if let Some(v) = version
        && v != i64::from(STUDY_FORMAT_VERSION)
    {
        cx.err(
            "format_version",
            format!("version {v} is not supported (this build reads {STUDY_FORMAT_VERSION})"),
        );
    }
    let name = cx.string(t, "", "name");
    let name = cx.required(name, t, "", "name");
    if name
        .as_deref()
        .is_some_and(|n| n.trim().is_empty() || n.len() > 200 || n.chars().any(char::is_control))
    {
        cx.err("name", "must be 1-200 printable characters");
    }
    let protocol: Option<Protocol> = cx.parse_enum(t, "", "protocol");
    let protocol = cx.required(protocol, t, "", "protocol");
    let stimuli_path = cx.string(t, "", "stimuli");
    let stimuli_path = cx.required(stimuli_path, t, "", "stimuli");
    let seed = cx.int(t, "", "seed", 0, i64::MAX);
    let seed = cx.required(seed, t, "", "seed");

    let manifest = match &stimuli_path {
        Some(p) => match load_manifest(p) {
            Ok(m) => {
                check_manifest(&m, cx);
                Some(m)
            }
            Err(e) => {
                cx.err("stimuli", format!("cannot load the stimulus manifest: {e}"));
                None
            }
        },
        None => None,
    };

    let empty = Table::new();
    let pres_t = cx.table(t, "", "presentation").unwrap_or(&empty);
    let presentation = parse_presentation(pres_t, protocol, cx);
    let scale_t = cx.table(t, "", "scale");
    let scale = parse_scale(scale_t.unwrap_or(&empty), protocol, cx);
    let session_t = cx.table(t, "", "session").unwrap_or(&empty);
    let (session, familiarization_spec) = parse_session(session_t, cx);
    let sim_t = cx.table(t, "", "simulation").unwrap_or(&empty);
    let simulation = parse_simulation(sim_t, cx);

    let mut conditions = Vec::new();
    let mut familiarization = Vec::new();
    let mut staircase = None;
    match protocol {
        Some(Protocol::Mos | Protocol::Dscqs) => {
            if t.contains_key("staircase") {
                cx.err(
                    "staircase",
                    "only a staircase study may have a [staircase] table",
                );
            }
            match cx.table(t, "", "conditions") {
                Some(ct) => {
                    if let Some(m) = &manifest {
                        conditions = parse_conditions(ct, m, cx);
                        familiarization =
                            resolve_familiarization(familiarization_spec, &conditions, m, cx);
                    } else {
                        cx.known(
                            ct,
                            "conditions",
                            &["stimuli", "clips", "codecs", "target_cr"],
                        );
                    }
                }
                None if !t.contains_key("conditions") => cx.err("conditions", "missing"),
                None => {}
            }
            if session.hidden_repeats as usize > conditions.len() && manifest.is_some() {
                cx.err(
                    "session.hidden_repeats",
                    format!(
                        "{} repeats but only {} conditions",
                        session.hidden_repeats,
                        conditions.len()
                    ),
                );
            }
        }
        Some(Protocol::Staircase) => {
            if t.contains_key("conditions") {
                cx.err(
                    "conditions",
                    "a staircase study takes its stimuli from [staircase]; remove [conditions]",
                );
            }
            if !matches!(familiarization_spec, FamSpec::None) {
                cx.err(
                    "session.familiarization",
                    "familiarization trials are not supported in a staircase study",
                );
            }
            if session.hidden_repeats > 0 {
                cx.err(
                    "session.hidden_repeats",
                    "hidden repeats are not supported in a staircase study",
                );
            }
            if scale_t.is_some() {
                cx.err("scale", "a staircase study has no rating scale");
            }
            match cx.table(t, "", "staircase") {
                Some(st) => staircase = parse_staircase(st, manifest.as_ref(), cx),
                None if !t.contains_key("staircase") => cx.err("staircase", "missing"),
                None => {}
            }
        }
        None => {}
    }

    Some(StudyDefinition {
        format_version: version? as u32,
        name: name?,
        protocol: protocol?,
        stimuli_path: stimuli_path?,
        seed: seed? as u64,
        conditions,
        familiarization,
        presentation: presentation?,
        scale: scale?,
        session,
        staircase,
        simulation,
        manifest: manifest?,
    })
}

fn check_manifest(m: &StimulusManifest, cx: &mut Ctx) {
    if m.version != crate::manifest::MANIFEST_VERSION {
        cx.err(
            "stimuli",
            format!("manifest version {} is not supported", m.version),
        );
    }
    let mut seen = BTreeSet::new();
    for s in &m.stimuli {
        if !seen.insert(s.id.as_str()) {
            cx.err(
                "stimuli",
                format!("manifest lists stimulus id {:?} twice", s.id),
            );
        }
    }
}

fn parse_presentation(
    t: &Table,
    protocol: Option<Protocol>,
    cx: &mut Ctx,
) -> Option<PresentationSettings> {
    const P: &str = "presentation";
    cx.known(
        t,
        P,
        &[
            "arrangement",
            "reference_position",
            "playback_count",
            "max_replays",
            "loop",
            "gap_ms",
            "stimulus_duration_ms",
        ],
    );
    let arrangement = if protocol == Some(Protocol::Dscqs) {
        match cx.pick(t, P, "arrangement", &[("abab", Arrangement::Abab)]) {
            Some(a) => a,
            None if t.contains_key("arrangement") => return None,
            None => Arrangement::Abab,
        }
    } else {
        match cx.pick(
            t,
            P,
            "arrangement",
            &[
                ("side_by_side", Arrangement::SideBySide),
                ("sequential", Arrangement::Sequential),
            ],
        ) {
            Some(a) => a,
            None if t.contains_key("arrangement") => return None,
            None => Arrangement::SideBySide,
        }
    };
    let reference_position = match cx.string(t, P, "reference_position").as_deref() {
        None | Some("random") => ReferencePlacement::Random,
        Some(s) => match s.parse::<Position>() {
            Ok(p) if p.fits(arrangement) => ReferencePlacement::Fixed(p),
            Ok(p) => {
                cx.err(
                    join(P, "reference_position"),
                    format!("{p} does not fit arrangement {arrangement}"),
                );
                ReferencePlacement::Random
            }
            Err(e) => {
                cx.err(join(P, "reference_position"), format!("{e} or \"random\""));
                ReferencePlacement::Random
            }
        },
    };
    let playback_count = cx.uint(t, P, "playback_count", 100).unwrap_or(1);
    if playback_count == 0 {
        cx.err(join(P, "playback_count"), "must be at least 1");
    }
    let max_replays = cx.uint(t, P, "max_replays", 1000);
    let loop_playback = cx.boolean(t, P, "loop").unwrap_or(false);
    let gap_ms = cx.uint(t, P, "gap_ms", 600_000).unwrap_or(500);
    let stimulus_duration_ms = cx
        .uint(t, P, "stimulus_duration_ms", 3_600_000)
        .unwrap_or(5000);
    Some(PresentationSettings {
        arrangement,
        reference_position,
        playback_count,
        max_replays,
        loop_playback,
        gap_ms: u64::from(gap_ms),
        stimulus_duration_ms: u64::from(stimulus_duration_ms),
    })
}

fn parse_scale(t: &Table, protocol: Option<Protocol>, cx: &mut Ctx) -> Option<RatingScale> {
    const P: &str = "scale";
    cx.known(t, P, &["kind", "min", "max", "step"]);
    let kind = cx.pick(
        t,
        P,
        "kind",
        &[
            ("categorical", ScaleKind::Categorical),
            ("continuous", ScaleKind::Continuous),
        ],
    );
    let kind = match kind {
        Some(k) => k,
        None if t.contains_key("kind") => return None,
        None if protocol == Some(Protocol::Dscqs) => ScaleKind::Continuous,
        None => ScaleKind::Categorical,
    };
    let (dmin, dmax, dstep) = match kind {
        ScaleKind::Categorical => (
            1.0,
            5.0,
            Some(if protocol == Some(Protocol::Mos) {
                0.5
            } else {
                1.0
            }),
        ),
        ScaleKind::Continuous => (0.0, 100.0, None),
    };
    let min = cx.float(t, P, "min").unwrap_or(dmin);
    let max = cx.float(t, P, "max").unwrap_or(dmax);
    let step = cx
        .float(t, P, "step")
        .or(if t.contains_key("step") { None } else { dstep });
    if min >= max {
        cx.err(join(P, "max"), format!("max {max} must be above min {min}"));
    }
    if let Some(s) = step {
        if s <= 0.0 {
            cx.err(join(P, "step"), format!("step must be positive, got {s}"));
        } else if min < max {
            let k = (max - min) / s;
            if (k - k.round()).abs() > 1e-9 || k > 10_000.0 {
                cx.err(
                    join(P, "step"),
                    format!("(max - min) / step = {k} must be a whole number up to 10000"),
                );
            }
        }
    } else if kind == ScaleKind::Categorical {
        cx.err(join(P, "step"), "a categorical scale needs a step");
    }
    Some(RatingScale {
        kind,
        min,
        max,
        step,
    })
}

enum FamSpec {
    None,
    Count(u32),
    Stimuli(Vec<String>),
}

fn parse_session(t: &Table, cx: &mut Ctx) -> (SessionSettings, FamSpec) {
    const P: &str = "session";
    cx.known(
        t,
        P,
        &[
            "time_limit_min",
            "break_every_trials",
            "familiarization",
            "familiarization_stimuli",
            "hidden_repeats",
            "subject_fields",
            "consent",
            "instructions",
        ],
    );
    let time_limit_ms = cx.float(t, P, "time_limit_min").and_then(|m| {
        if m > 0.0 && m <= 24.0 * 60.0 {
            Some((m * 60_000.0).round() as u64)
        } else {
            cx.err(
                join(P, "time_limit_min"),
                format!("{m} must be in (0, 1440] minutes"),
            );
            None
        }
    });
    let break_every_trials = cx.uint(t, P, "break_every_trials", 100_000);
    if break_every_trials == Some(0) {
        cx.err(
            join(P, "break_every_trials"),
            "must be at least 1 (omit it for no breaks)",
        );
    }
    let hidden_repeats = cx.uint(t, P, "hidden_repeats", 100_000).unwrap_or(0);
    let subject_fields = cx.strings(t, P, "subject_fields").unwrap_or_default();
    let mut seen = BTreeSet::new();
    for (i, f) in subject_fields.iter().enumerate() {
        if f.is_empty() || !f.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            cx.err(
                format!("{P}.subject_fields[{i}]"),
                format!("{f:?} must be letters, digits or _"),
            );
        }
        if !seen.insert(f) {
            cx.err(
                format!("{P}.subject_fields[{i}]"),
                format!("{f:?} is listed twice"),
            );
        }
    }
    let mut text = |key: &str| {
        let v = cx.string(t, P, key)?;
        if v.trim().is_empty() {
            cx.err(join(P, key), "is empty (omit it instead)");
            None
        } else if v.len() > 16 * 1024 {
            cx.err(
                join(P, key),
                format!("{} bytes is over the 16 KiB limit", v.len()),
            );
            None
        } else {
            Some(v)
        }
    };
    let consent = text("consent");
    let instructions = text("instructions");
    let count = cx.uint(t, P, "familiarization", 10_000);
    let list = cx.strings(t, P, "familiarization_stimuli");
    let fam = match (count, list) {
        (Some(_), Some(_)) => {
            cx.err(
                join(P, "familiarization"),
                "give either familiarization (a count) or familiarization_stimuli, not both",
            );
            FamSpec::None
        }
        (Some(0) | None, None) => FamSpec::None,
        (Some(n), None) => FamSpec::Count(n),
        (None, Some(l)) => FamSpec::Stimuli(l),
    };
    (
        SessionSettings {
            time_limit_ms,
            break_every_trials,
            hidden_repeats,
            subject_fields,
            consent,
            instructions,
        },
        fam,
    )
}

fn condition_of(id: &str, m: &StimulusManifest, key: &str, cx: &mut Ctx) -> Option<Condition> {
    let Some(s) = m.get(id) else {
        cx.err(key, format!("stimulus {id:?} is not in the manifest"));
        return None;
    };
    if s.codec == REFERENCE_CODEC {
        cx.err(
            key,
            format!("stimulus {id:?} is a reference, not a test stimulus"),
        );
        return None;
    }
    let Some(r) = m.reference_of(&s.clip) else {
        cx.err(
            key,
            format!(
                "clip {:?} of stimulus {id:?} has no reference in the manifest",
                s.clip
            ),
        );
        return None;
    };
    Some(Condition {
        stimulus: s.id.clone(),
        reference: r.id.clone(),
    })
}

fn parse_conditions(t: &Table, m: &StimulusManifest, cx: &mut Ctx) -> Vec<Condition> {
    const P: &str = "conditions";
    cx.known(t, P, &["stimuli", "clips", "codecs", "target_cr"]);
    let mut out = Vec::new();
    let list = cx.strings(t, P, "stimuli");
    let grid_keys = ["clips", "codecs", "target_cr"]
        .iter()
        .any(|k| t.contains_key(*k));
    if let Some(list) = list {
        if grid_keys {
            cx.err(
                P,
                "give either stimuli or a clips x codecs x target_cr grid, not both",
            );
        }
        let mut seen = BTreeSet::new();
        for (i, id) in list.iter().enumerate() {
            let key = format!("{P}.stimuli[{i}]");
            if !seen.insert(id.as_str()) {
                cx.err(
                    &key,
                    format!(
                        "stimulus {id:?} is listed twice (use session.hidden_repeats for repeats)"
                    ),
                );
                continue;
            }
            if let Some(c) = condition_of(id, m, &key, cx) {
                out.push(c);
            }
        }
    } else if grid_keys {
        let clips = cx.strings(t, P, "clips");
        let clips = cx.required(clips, t, P, "clips").unwrap_or_default();
        let codecs = cx.strings(t, P, "codecs");
        let codecs = cx.required(codecs, t, P, "codecs").unwrap_or_default();
        let crs = cx.floats(t, P, "target_cr");
        for (ci, clip) in clips.iter().enumerate() {
            for (di, codec) in codecs.iter().enumerate() {
                let matching: Vec<_> = m
                    .stimuli
                    .iter()
                    .filter(|s| &s.clip == clip && &s.codec == codec)
                    .collect();
                match &crs {
                    None if matching.is_empty() => {
                        cx.err(
                            format!("{P}.codecs[{di}]"),
                            format!(
                                "no stimulus of clip {clip:?} (clips[{ci}]) with codec {codec:?}"
                            ),
                        );
                    }
                    None => {
                        for s in matching {
                            out.extend(condition_of(&s.id, m, &format!("{P}.codecs[{di}]"), cx));
                        }
                    }
                    Some(crs) => {
                        for (ri, cr) in crs.iter().enumerate() {
                            let hit: Vec<_> = matching
                                .iter()
                                .filter(|s| {
                                    s.target_cr
                                        .is_some_and(|t| (t - cr).abs() <= 1e-9 * cr.abs().max(1.0))
                                })
                                .collect();
                            if hit.is_empty() {
                                cx.err(format!("{P}.target_cr[{ri}]"), format!("no stimulus of clip {clip:?} with codec {codec:?} at target_cr {cr}"));
                            }
                            for s in hit {
                                out.extend(condition_of(
                                    &s.id,
                                    m,
                                    &format!("{P}.target_cr[{ri}]"),
                                    cx,
                                ));
                            }
                        }
                    }
                }
            }
        }
    } else {
        cx.err(P, "give stimuli = [...] or clips, codecs (and target_cr)");
    }
    if out.is_empty() && cx.issues.is_empty() {
        cx.err(P, "no test stimulus selected");
    }
    out
}

fn resolve_familiarization(
    spec: FamSpec,
    conditions: &[Condition],
    m: &StimulusManifest,
    cx: &mut Ctx,
) -> Vec<Condition> {
    match spec {
        FamSpec::None => Vec::new(),
        FamSpec::Stimuli(list) => list
            .iter()
            .enumerate()
            .filter_map(|(i, id)| {
                condition_of(id, m, &format!("session.familiarization_stimuli[{i}]"), cx)
            })
            .collect(),
        FamSpec::Count(n) => {
            let n = n as usize;
            if n > conditions.len() {
                cx.err(
                    "session.familiarization",
                    format!(
                        "{n} familiarization trials but only {} conditions",
                        conditions.len()
                    ),
                );
                return Vec::new();
            }
            // Paper 000: familiarization spans the range of compression ratios (10:1 to 70:1);
            // pick evenly spaced ranks of the achieved ratio.
            let mut ranked: Vec<&Condition> = conditions.iter().collect();
            ranked.sort_by(|a, b| {
                let cr = |c: &Condition| m.get(&c.stimulus).map_or(0.0, |s| s.achieved_cr);
                cr(a)
                    .total_cmp(&cr(b))
                    .then_with(|| a.stimulus.cmp(&b.stimulus))
            });
            (0..n)
                .map(|i| {
                    if n == 1 {
                        ranked.len() / 2
                    } else {
                        (i * (ranked.len() - 1) + (n - 1) / 2) / (n - 1)
                    }
                })
                .filter_map(|i| ranked.get(i).map(|c| (*c).clone()))
                .collect()
        }
    }
}

fn parse_simulation(t: &Table, cx: &mut Ctx) -> SimulationSettings {
    const P: &str = "simulation";
    cx.known(
        t,
        P,
        &[
            "metric",
            "quality_scale",
            "bias_sd",
            "noise_sd",
            "psychometric",
            "detection",
            "threshold",
            "slope",
            "lapse",
            "response_time_ms",
        ],
    );
    let d = SimulationSettings::default();
    let detection = cx.pick(
        t,
        P,
        "detection",
        &[("level", Detection::Level), ("error", Detection::Error)],
    );
    let metric = cx.pick(
        t,
        P,
        "metric",
        &[
            ("rms_cm", Metric::RmsCm),
            ("max_cm", Metric::MaxCm),
            ("mean_angle_deg", Metric::MeanAngleDeg),
        ],
    );
    let psychometric = cx.pick(
        t,
        P,
        "psychometric",
        &[
            ("weibull", Psychometric::Weibull),
            ("logistic", Psychometric::Logistic),
        ],
    );
    let positive = |cx: &mut Ctx, key: &str, default: f64| match cx.float(t, P, key) {
        Some(v) if v > 0.0 => v,
        Some(v) => {
            cx.err(join(P, key), format!("must be positive, got {v}"));
            default
        }
        None => default,
    };
    let quality_scale = positive(cx, "quality_scale", d.quality_scale);
    let slope = positive(cx, "slope", d.slope);
    let threshold = match cx.float(t, P, "threshold") {
        Some(v) => v,
        None => d.threshold,
    };
    let nonneg = |cx: &mut Ctx, key: &str, default: f64, hi: f64| match cx.float(t, P, key) {
        Some(v) if (0.0..=hi).contains(&v) => v,
        Some(v) => {
            cx.err(join(P, key), format!("must be in [0, {hi}], got {v}"));
            default
        }
        None => default,
    };
    let bias_sd = nonneg(cx, "bias_sd", d.bias_sd, 1e6);
    let noise_sd = nonneg(cx, "noise_sd", d.noise_sd, 1e6);
    let lapse = nonneg(cx, "lapse", d.lapse, 0.5);
    let response_time_ms = cx
        .uint(t, P, "response_time_ms", 600_000)
        .map_or(d.response_time_ms, u64::from);
    SimulationSettings {
        metric: metric.unwrap_or(d.metric),
        quality_scale,
        bias_sd,
        noise_sd,
        psychometric: psychometric.unwrap_or(d.psychometric),
        detection: detection.unwrap_or(d.detection),
        threshold,
        slope,
        lapse,
        response_time_ms,
    }
}

const STAIR_KEYS: &[&str] = &[
    "param",
    "codec",
    "level_tolerance",
    "start",
    "step",
    "step_type",
    "down_up_ratio",
    "min",
    "max",
    "n_up",
    "n_down",
    "apply_initial_rule",
    "stop_reversals",
    "min_trials",
    "max_trials",
    "threshold_reversals",
    "tracks",
    "live",
];

/// Most clips a live staircase may alternate, and most fixed codec parameters.
const MAX_LIVE_CLIPS: usize = 256;
const MAX_LIVE_PARAMS: usize = 32;

/// `[staircase.live]`: clips, their order, fixed codec parameters, decoder context.
fn parse_live(
    t: &Table,
    param: Option<&str>,
    m: Option<&StimulusManifest>,
    cx: &mut Ctx,
) -> Option<LiveStaircase> {
    const P: &str = "staircase.live";
    cx.known(t, P, &["clips", "order", "params", "database"]);
    let names = cx.strings(t, P, "clips");
    let names = cx.required(names, t, P, "clips");
    let mut clips = Vec::new();
    if let Some(names) = &names {
        if names.is_empty() {
            cx.err(join(P, "clips"), "needs at least one clip");
        } else if names.len() > MAX_LIVE_CLIPS {
            cx.err(
                join(P, "clips"),
                format!("{} clips, limit {MAX_LIVE_CLIPS}", names.len()),
            );
        }
        let mut seen = BTreeSet::new();
        for (i, clip) in names.iter().take(MAX_LIVE_CLIPS).enumerate() {
            let key = format!("{P}.clips[{i}]");
            if !seen.insert(clip.as_str()) {
                cx.err(&key, format!("clip {clip:?} is listed twice"));
                continue;
            }
            let Some(m) = m else { continue };
            match m.reference_of(clip) {
                Some(r) => clips.push(LiveClip {
                    clip: clip.clone(),
                    reference: r.id.clone(),
                }),
                None => cx.err(
                    &key,
                    format!(
                        "clip {clip:?} has no reference stimulus in the manifest (a live staircase encodes the reference)"
                    ),
                ),
            }
        }
    }
    let order = cx
        .pick(
            t,
            P,
            "order",
            &[
                ("in_turn", ClipOrder::InTurn),
                ("shuffled", ClipOrder::Shuffled),
            ],
        )
        .unwrap_or(ClipOrder::InTurn);
    let mut params = BTreeMap::new();
    match t.get("params") {
        None => {}
        Some(Value::Table(pt)) => {
            if pt.len() > MAX_LIVE_PARAMS {
                cx.err(
                    join(P, "params"),
                    format!("{} parameters, limit {MAX_LIVE_PARAMS}", pt.len()),
                );
            }
            for (k, v) in pt.iter().take(MAX_LIVE_PARAMS) {
                let key = format!("{P}.params.{k}");
                if k.is_empty()
                    || k.len() > 32
                    || !k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                {
                    cx.err(&key, "a parameter name is 1-32 letters, digits or _");
                    continue;
                }
                if Some(k.as_str()) == param {
                    cx.err(
                        &key,
                        format!("{k:?} is the staircase's level; it cannot also be fixed"),
                    );
                    continue;
                }
                match v {
                    Value::Float(f) if f.is_finite() => {
                        params.insert(k.clone(), *f);
                    }
                    Value::Integer(i) => {
                        params.insert(k.clone(), *i as f64);
                    }
                    v => cx.err(
                        &key,
                        format!("expected a finite number, got {}", type_name(v)),
                    ),
                }
            }
        }
        Some(v) => cx.wrong(P, "params", "a table of numbers", v),
    }
    let database = cx.string(t, P, "database");
    if database.as_deref().is_some_and(|d| d.trim().is_empty()) {
        cx.err(join(P, "database"), "must name a file");
    }
    names?;
    Some(LiveStaircase {
        clips,
        order,
        params,
        database,
    })
}

#[expect(
    clippy::too_many_lines,
    reason = "one pass over the [staircase] keys and tracks"
)]
fn parse_staircase(
    t: &Table,
    m: Option<&StimulusManifest>,
    cx: &mut Ctx,
) -> Option<StaircaseStudy> {
    const P: &str = "staircase";
    cx.known(t, P, STAIR_KEYS);
    let d = StaircaseSettings::default();
    let param = cx.string(t, P, "param");
    let param = cx.required(param, t, P, "param");
    let codec = cx.string(t, P, "codec");
    let codec = cx.required(codec, t, P, "codec");
    let start = cx.float(t, P, "start");
    let step = cx.float(t, P, "step");
    let step = cx.required(step, t, P, "step");
    let step_type = cx.pick(
        t,
        P,
        "step_type",
        &[
            ("linear", StepType::Linear),
            ("log", StepType::Log),
            ("db", StepType::Db),
        ],
    );
    let min = cx.float(t, P, "min");
    let min = cx.required(min, t, P, "min");
    let max = cx.float(t, P, "max");
    let max = cx.required(max, t, P, "max");
    let opt_u = |cx: &mut Ctx, key: &str| cx.uint(t, P, key, 100_000);
    let settings = StaircaseSettings {
        start: start.unwrap_or(d.start),
        step: step.unwrap_or(d.step),
        step_type: step_type.unwrap_or(StepType::Linear),
        down_up_ratio: cx.float(t, P, "down_up_ratio").unwrap_or(1.0),
        min,
        max,
        n_up: opt_u(cx, "n_up").unwrap_or(1),
        n_down: opt_u(cx, "n_down").unwrap_or(2),
        apply_initial_rule: cx.boolean(t, P, "apply_initial_rule").unwrap_or(false),
        stop_reversals: opt_u(cx, "stop_reversals"),
        min_trials: opt_u(cx, "min_trials").unwrap_or(0),
        max_trials: opt_u(cx, "max_trials"),
        threshold_reversals: opt_u(cx, "threshold_reversals").unwrap_or(3),
    };
    let live_t = cx.table(t, P, "live");
    let live_asked = t.contains_key("live");
    let live = live_t.and_then(|lt| parse_live(lt, param.as_deref(), m, cx));
    if live_asked && t.contains_key("level_tolerance") {
        cx.err(
            join(P, "level_tolerance"),
            "a live staircase encodes every level exactly; remove level_tolerance",
        );
    }
    let tolerance = match cx.float(t, P, "level_tolerance") {
        Some(v) if v >= 0.0 => v,
        Some(v) => {
            cx.err(join(P, "level_tolerance"), format!("must be >= 0, got {v}"));
            0.0
        }
        None => 1e-9 * settings.step.abs().max(f64::MIN_POSITIVE),
    };
    // A live staircase without [[staircase.tracks]] runs one staircase named "live".
    let default_track = [Value::Table(Table::from_iter([(
        "name".to_string(),
        Value::String("live".into()),
    )]))];
    let tracks_v = match t.get("tracks") {
        Some(Value::Array(a)) => a.as_slice(),
        Some(v) => {
            cx.wrong(P, "tracks", "an array of tables ([[staircase.tracks]])", v);
            &[]
        }
        None if live_asked => &default_track[..],
        None => {
            cx.err(
                join(P, "tracks"),
                "missing: add at least one [[staircase.tracks]]",
            );
            &[]
        }
    };
    if tracks_v.len() > MAX_TRACKS {
        cx.err(
            join(P, "tracks"),
            format!("{} tracks, limit {MAX_TRACKS}", tracks_v.len()),
        );
        return None;
    }
    if t.contains_key("tracks") && tracks_v.is_empty() {
        cx.err(join(P, "tracks"), "needs at least one track");
    }
    let mut tracks = Vec::new();
    let mut names = BTreeSet::new();
    for (i, tv) in tracks_v.iter().enumerate() {
        let tp = format!("{P}.tracks[{i}]");
        let Value::Table(tt) = tv else {
            cx.err(&tp, format!("expected a table, got {}", type_name(tv)));
            continue;
        };
        let clip = if live_asked {
            let mut others = tt.clone();
            if others.remove("clip").is_some() {
                cx.err(
                    join(&tp, "clip"),
                    "a live staircase takes its clips from staircase.live.clips",
                );
            }
            cx.known(&others, &tp, &["name", "start"]);
            None
        } else {
            cx.known(tt, &tp, &["name", "clip", "start"]);
            let clip = cx.string(tt, &tp, "clip");
            cx.required(clip, tt, &tp, "clip")
        };
        let name = cx
            .string(tt, &tp, "name")
            .or_else(|| clip.clone())
            .unwrap_or_else(|| {
                if live_asked {
                    "live".into()
                } else {
                    String::new()
                }
            });
        if !names.insert(name.clone()) {
            cx.err(
                join(&tp, "name"),
                format!("track name {name:?} is used twice"),
            );
        }
        let mut s = settings.clone();
        if let Some(st) = cx.float(tt, &tp, "start") {
            s.start = st;
        } else if start.is_none() {
            cx.err(
                join(&tp, "start"),
                "missing (set staircase.start or a start per track)",
            );
        }
        for e in check_settings(&s) {
            if let crate::staircase::StaircaseError::BadSetting { key, reason } = e {
                let at = if key == "start" && tt.contains_key("start") {
                    join(&tp, "start")
                } else {
                    join(P, key)
                };
                if !cx.issues.iter().any(|x| x.key == at && x.reason == reason) {
                    cx.err(at, reason);
                }
            }
        }
        if live_asked {
            tracks.push(Track {
                name,
                clip: String::new(),
                reference: String::new(),
                settings: s,
                levels: Vec::new(),
            });
            continue;
        }
        let (Some(clip), Some(m), Some(param), Some(codec)) = (clip, m, &param, &codec) else {
            continue;
        };
        let Some(reference) = m.reference_of(&clip) else {
            cx.err(
                join(&tp, "clip"),
                format!("clip {clip:?} has no reference stimulus in the manifest"),
            );
            continue;
        };
        let mut levels: Vec<(f64, String)> = m
            .stimuli
            .iter()
            .filter(|x| x.clip == clip && &x.codec == codec)
            .filter_map(|x| {
                x.params
                    .get(param)
                    .filter(|v| v.is_finite())
                    .map(|v| (*v, x.id.clone()))
            })
            .collect();
        levels.sort_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(&b.1)));
        if levels.is_empty() {
            cx.err(
                join(&tp, "clip"),
                format!(
                    "no stimulus of clip {clip:?} with codec {codec:?} has parameter {param:?}"
                ),
            );
            continue;
        }
        let track = Track {
            name,
            clip,
            reference: reference.id.clone(),
            settings: s,
            levels,
        };
        if check_settings(&track.settings).is_empty() {
            check_levels(&track, tolerance, &tp, cx);
        }
        tracks.push(track);
    }
    if live_asked && live.is_none() {
        return None;
    }
    Some(StaircaseStudy {
        param: param?,
        codec: codec?,
        level_tolerance: tolerance,
        tracks,
        live,
    })
}

/// Every level the staircase can reach must have a stimulus within the tolerance. Reachable
/// levels are enumerated when they form a small set (equal linear steps); otherwise the
/// stimuli's tolerance intervals must cover [min, max].
fn check_levels(track: &Track, tol: f64, path: &str, cx: &mut Ctx) {
    let s = &track.settings;
    let (Some(lo), Some(hi)) = (s.min, s.max) else {
        return;
    };
    let key = |v: f64| format!("{v:.12e}");
    let mut seen: BTreeMap<String, f64> = BTreeMap::new();
    let mut queue = vec![s.start];
    let mut bounded = true;
    while let Some(v) = queue.pop() {
        if seen.insert(key(v), v).is_some() {
            continue;
        }
        if seen.len() > MAX_ENUMERATED_LEVELS {
            bounded = false;
            break;
        }
        for up in [true, false] {
            let mut x = v;
            let st = if up { s.step } else { s.step * s.down_up_ratio };
            let sign = if up { 1.0 } else { -1.0 };
            match s.step_type {
                StepType::Linear => x += sign * st,
                StepType::Log => x *= 10_f64.powf(sign * st),
                StepType::Db => x *= 10_f64.powf(sign * st / 20.0),
            }
            x = x.max(lo).min(hi);
            if !seen.contains_key(&key(x)) {
                queue.push(x);
            }
        }
    }
    if bounded {
        let mut missing: Vec<f64> = seen
            .values()
            .copied()
            .filter(|v| track.stimulus_at(*v, tol).is_none())
            .collect();
        missing.sort_by(f64::total_cmp);
        if !missing.is_empty() {
            let shown: Vec<String> = missing.iter().take(8).map(|v| format!("{v}")).collect();
            cx.err(
                join(path, "clip"),
                format!(
                    "{} reachable level(s) have no stimulus of clip {:?} within {tol}: {}{}",
                    missing.len(),
                    track.clip,
                    shown.join(", "),
                    if missing.len() > 8 { ", ..." } else { "" }
                ),
            );
        }
    } else {
        let mut covered = lo;
        for (v, _) in &track.levels {
            if v - tol > covered {
                break;
            }
            covered = covered.max(v + tol);
        }
        if covered < hi {
            cx.err(
                join(path, "clip"),
                format!(
                    "levels form no finite grid, and stimuli within level_tolerance {tol} cover [{lo}, {covered}] but not up to max {hi}"
                ),
            );
        }
    }
}
