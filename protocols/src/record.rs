//! Trials, responses and the per-trial record that the results store writes.
//!
//! These types are the contract between an engine, a runner (window or simulated observer) and
//! the results store: the engine emits a [`Trial`], the runner returns a [`Response`], the engine
//! scores it into an [`Outcome`], and the store logs all three as one [`TrialRecord`].

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Which protocol a study runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Protocol {
    /// Mean opinion score, test beside reference, one rating (paper 000 section IV).
    Mos,
    /// Double stimulus continuous quality scale (ITU-R BT.500, thesis ch. 6.4).
    Dscqs,
    /// Two-alternative forced choice with adaptive staircases (thesis ch. 5).
    Staircase,
    /// Absolute category rating (ITU-T P.910 ACR): one stimulus at a time, rated on the
    /// five-grade quality scale without a reference; with the clips' references among the
    /// conditions (hidden reference) it is ACR-HR.
    Acr,
    /// Degradation category rating (ITU-T P.910 DCR, ITU-R BT.500 DSIS): the labelled
    /// reference, then the test stimulus, rated on the five impairment categories.
    Dcr,
    /// Pair comparison (ITU-T P.910 PC): two test stimuli of the same source clip, side by
    /// side or one after the other, and the subject picks the better one (forced choice);
    /// analysed with Bradley-Terry scale values.
    PairComparison,
    /// MUSHRA-style multi-stimulus rating (ITU-R BS.1534-3 adapted to motion): one screen per
    /// clip with the labelled reference and, unlabelled in a shuffled grid, every test
    /// condition of the clip, a hidden reference and a low anchor, each rated 0-100. One row
    /// per rated stimulus.
    Mushra,
    /// Comparison category rating (ITU-T P.910 CCR): the reference and a test stimulus in
    /// either order, unlabelled, the second rated against the first on seven categories from
    /// +3 (much better) to -3 (much worse); analysed with the order folded out.
    Ccr,
}

/// Which part of a session a trial belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Block {
    /// Familiarization trial: shown first, not scored in analyses.
    Familiarization,
    /// Scored test trial.
    Test,
    /// Hidden repeat of a test trial (consistency check), scored.
    HiddenRepeat,
}

/// Where something is shown: a side of the screen, an interval, or a DSCQS slot.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Position {
    /// Left half of a side-by-side display.
    Left,
    /// Right half of a side-by-side display.
    Right,
    /// First interval of a sequential display.
    First,
    /// Second interval of a sequential display.
    Second,
    /// DSCQS slot A (shown first and third).
    A,
    /// DSCQS slot B (shown second and fourth).
    B,
    /// Not shown: the reference of a single-stimulus trial (ACR), which the subject never
    /// sees.
    Hidden,
    /// MUSHRA: the pane of the grid the rated stimulus was shown in, 0 = the pane lettered A
    /// (below [`MAX_PANES`]); the labelled reference has a pane of its own.
    Pane(u8),
    /// No position: the answer "no preference" where the screen offers it (a pair
    /// comparison with ties); never where a stimulus is shown.
    Neither,
}

/// Most unlabelled panes (rated stimuli) a MUSHRA screen may show, lettered A to L.
pub const MAX_PANES: usize = 12;

/// The file names of the MUSHRA panes, `pane_a` ... `pane_l`.
const PANE_NAMES: [&str; MAX_PANES] = [
    "pane_a", "pane_b", "pane_c", "pane_d", "pane_e", "pane_f", "pane_g", "pane_h", "pane_i",
    "pane_j", "pane_k", "pane_l",
];

/// How the two stimuli of a trial are laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Arrangement {
    /// Both at once, side by side.
    SideBySide,
    /// One after the other.
    Sequential,
    /// DSCQS: A B A B.
    Abab,
    /// The test stimulus alone (ACR); the reference is not shown.
    Single,
    /// MUSHRA: the labelled reference and the rated stimuli at once, in a grid of panes.
    Grid,
}

macro_rules! text_enum {
    ($ty:ty, $($variant:path => $text:literal),+ $(,)?) => {
        impl $ty {
            /// The name used in files.
            pub fn as_str(self) -> &'static str {
                match self { $($variant => $text),+ }
            }
        }
        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }
        impl FromStr for $ty {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                match s {
                    $($text => Ok($variant),)+
                    _ => Err(format!("expected one of {}, got {s:?}", [$($text),+].join(", "))),
                }
            }
        }
    };
}

text_enum!(Protocol, Protocol::Mos => "mos", Protocol::Dscqs => "dscqs", Protocol::Staircase => "staircase",
    Protocol::Acr => "acr", Protocol::Dcr => "dcr", Protocol::PairComparison => "pair_comparison",
    Protocol::Mushra => "mushra", Protocol::Ccr => "ccr");
text_enum!(Block, Block::Familiarization => "familiarization", Block::Test => "test", Block::HiddenRepeat => "hidden_repeat");
text_enum!(Arrangement, Arrangement::SideBySide => "side_by_side", Arrangement::Sequential => "sequential",
    Arrangement::Abab => "abab", Arrangement::Single => "single", Arrangement::Grid => "grid");

/// The fixed names of [`Position`] (the panes are `pane_a` ... `pane_l`).
const POSITION_NAMES: [(Position, &str); 8] = [
    (Position::Left, "left"),
    (Position::Right, "right"),
    (Position::First, "first"),
    (Position::Second, "second"),
    (Position::A, "a"),
    (Position::B, "b"),
    (Position::Hidden, "hidden"),
    (Position::Neither, "neither"),
];

impl Position {
    /// The name used in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Pane(i) => PANE_NAMES.get(usize::from(i)).copied().unwrap_or("pane_?"),
            p => POSITION_NAMES
                .iter()
                .find(|(q, _)| *q == p)
                .map_or("?", |(_, n)| n),
        }
    }

    /// MUSHRA pane `i` (0 = A), or `None` past [`MAX_PANES`].
    pub fn pane(i: usize) -> Option<Self> {
        (i < MAX_PANES).then_some(Self::Pane(i as u8))
    }

    /// The letter a subject sees on a MUSHRA pane (`A` for pane 0); `None` for other
    /// positions.
    pub fn pane_letter(self) -> Option<char> {
        match self {
            Self::Pane(i) if usize::from(i) < MAX_PANES => Some(char::from(b'A' + i)),
            _ => None,
        }
    }
}

impl fmt::Display for Position {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Position {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if let Some((p, _)) = POSITION_NAMES.iter().find(|(_, n)| *n == s) {
            return Ok(*p);
        }
        if let Some(i) = PANE_NAMES.iter().position(|n| *n == s) {
            return Ok(Self::Pane(i as u8));
        }
        let names: Vec<&str> = POSITION_NAMES.iter().map(|(_, n)| *n).collect();
        Err(format!(
            "expected one of {}, pane_a ... pane_l, got {s:?}",
            names.join(", ")
        ))
    }
}

impl Position {
    /// The other position of the same arrangement.
    #[must_use]
    pub fn other(self) -> Self {
        match self {
            Self::Left => Self::Right,
            Self::Right => Self::Left,
            Self::First => Self::Second,
            Self::Second => Self::First,
            Self::A => Self::B,
            Self::B => Self::A,
            Self::Hidden => Self::Hidden,
            Self::Pane(i) => Self::Pane(i),
            Self::Neither => Self::Neither,
        }
    }

    /// Whether this position belongs to `arrangement` ([`Position::Neither`] belongs to
    /// none).
    pub fn fits(self, arrangement: Arrangement) -> bool {
        matches!(
            (arrangement, self),
            (Arrangement::SideBySide, Self::Left | Self::Right)
                | (Arrangement::Sequential, Self::First | Self::Second)
                | (Arrangement::Abab, Self::A | Self::B)
                | (Arrangement::Single, Self::Hidden)
        ) || matches!((arrangement, self), (Arrangement::Grid, Self::Pane(i)) if usize::from(i) < MAX_PANES)
    }
}

/// One trial as an engine plans it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trial {
    /// 0-based index within the session.
    pub index: u32,
    /// Familiarization, test or hidden repeat.
    pub block: Block,
    /// Condition label: the test stimulus id (MOS, DSCQS, ACR, DCR), the staircase name, or
    /// in a pair comparison the pair, `<stimulus> vs <reference>`.
    pub condition: String,
    /// Test (compressed / distorted) stimulus id; in ACR-HR the clip's reference itself for
    /// a hidden-reference trial.
    pub stimulus: String,
    /// Reference stimulus id (of the same clip; not shown in ACR). In a pair comparison the
    /// pair's other test stimulus (of the same clip), shown at `reference_position`.
    pub reference: String,
    /// Layout of the two stimuli.
    pub arrangement: Arrangement,
    /// Where the reference is (hidden from the subject).
    pub reference_position: Position,
    /// Staircase index (staircase protocol only).
    pub staircase: Option<u32>,
    /// Staircase level of this trial (staircase protocol only).
    pub level: Option<f64>,
    /// A rest break is due before this trial.
    pub break_before: bool,
}

/// What the subject answered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Answer {
    /// One rating of the test stimulus (MOS, ACR, DCR).
    Rating(f64),
    /// Ratings of slot A and slot B (DSCQS), or of the first and the second stimulus of a
    /// sequential DSCQS (thesis 6.5).
    Pair {
        /// Rating of slot A (the first stimulus).
        a: f64,
        /// Rating of slot B (the second stimulus).
        b: f64,
    },
    /// The position the subject picked as more natural and smooth (2AFC), or as the better
    /// of the two (pair comparison).
    Choice(Position),
}

/// A subject's response to one trial.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Response {
    /// The answer.
    pub answer: Answer,
    /// Time from the end of the presentation to the answer, ms.
    pub response_time_ms: u64,
    /// How many times the subject replayed the stimuli.
    pub replays: u32,
    /// Frames the display dropped during this trial.
    pub dropped_frames: u32,
}

/// The engine's scoring of a response.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// MOS, ACR, DCR: the rating; DSCQS: reference score minus test score (BT.500 difference);
    /// staircase: 1 correct, 0 wrong; pair comparison: 1 when the subject preferred the
    /// trial's `stimulus`, 0 when the other (`reference` column) one.
    pub score: f64,
    /// DSCQS: rating of the reference.
    pub score_reference: Option<f64>,
    /// DSCQS: rating of the test stimulus.
    pub score_test: Option<f64>,
    /// Staircase: the subject picked the original.
    pub correct: Option<bool>,
    /// Staircase: this trial was a reversal point.
    pub reversal: Option<bool>,
}

/// One row of `trials.csv`: a trial, its response, its scoring and when it happened.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialRecord {
    /// Study name.
    pub study: String,
    /// Subject id.
    pub subject: String,
    /// Session number of this subject (1-based).
    pub session: u32,
    /// Protocol.
    pub protocol: Protocol,
    /// The trial.
    pub trial: Trial,
    /// The response.
    pub response: Response,
    /// The scoring.
    pub outcome: Outcome,
    /// Session clock the engine used for the time limit when the trial was answered, ms.
    pub elapsed_ms: u64,
    /// Wall-clock time of the answer, ms since the Unix epoch.
    pub wall_clock_ms: u64,
    /// Monotonic clock of the answer, ms since this runner process started the session.
    pub monotonic_ms: u64,
    /// How the distorted stimulus was made, when the runner encoded it for this trial (live
    /// staircase); `None` for stimuli from the manifest.
    #[serde(default)]
    pub encoding: Option<StimulusEncoding>,
    /// How the display kept time while the trial was shown (the study window); `None` for a
    /// simulated session.
    #[serde(default)]
    pub timing: Option<FrameTiming>,
}

/// Frame timing of one trial in the study window. The dropped frames are in
/// [`Response::dropped_frames`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameTiming {
    /// Frames presented while the trial was on screen.
    pub frames_shown: u32,
    /// Sample standard deviation of the intervals between them, ms.
    pub interval_sd_ms: f64,
}

/// What the runner logged about a stimulus it encoded and decoded for one trial (live
/// staircase): the exact codec parameters, the compression ratio reached and the error of the
/// decoded clip. A crowd scene's trial logs its characters' ratios and its level here
/// ([`crate::manifest::StimulusManifest::scene_encoding`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StimulusEncoding {
    /// Codec parameters of the bitstream (the level's parameter included), exact values.
    pub codec_params: BTreeMap<String, f64>,
    /// Compression ratio reached (4 bytes × channels × frames / bitstream bytes).
    pub achieved_cr: f64,
    /// Joint position RMS error of the decoded clip against the reference, cm.
    pub rms_cm: f64,
}
