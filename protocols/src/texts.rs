//! The words a subject reads, shared by every front end (the study window, the browser page
//! of `study serve`): the BT.500 grade labels, the 2AFC question, the acknowledgement, and
//! the default instructions of each protocol as the study's presentation settings make them.

use crate::record::Arrangement;
use crate::study::{RatingScale, ScaleKind, StudyDefinition};

/// The BT.500 five-grade quality labels, best first.
pub const QUALITY_LABELS: [&str; 5] = ["Excellent", "Good", "Fair", "Poor", "Bad"];

/// The five impairment categories of ITU-T P.910 DCR (ITU-R BT.500 DSIS), least impaired
/// (5) first.
pub const IMPAIRMENT_LABELS: [&str; 5] = [
    "Imperceptible",
    "Perceptible but not annoying",
    "Slightly annoying",
    "Annoying",
    "Very annoying",
];

/// The 2AFC question of thesis ch. 5.
pub const AFC_QUESTION: &str = "Which motion looks more natural?";

/// The question of a pair comparison (P.910 PC): which of two versions is better.
pub const PC_QUESTION: &str = "Which motion looks better?";

/// Shown after an answer was logged, over the blank gap before the next trial.
pub const ANSWER_RECORDED: &str = "Answer recorded";

/// The label above a MUSHRA screen's open reference (BS.1534).
pub const MUSHRA_REFERENCE: &str = "Reference";

/// A rating as a subject reads it: `3`, `3.5`.
pub fn format_rating(v: f64) -> String {
    if v.fract().abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

/// The word of rating `v` on `scale`, where its method names the grades with `words` (best
/// first: BT.500's quality grades, P.910 DCR's impairment categories, P.910 CCR's
/// comparison words): the scale's whole numbers, one word each, from `max` down. `None`
/// between grades (MOS's half steps) or where the scale has another number of grades than
/// words.
pub fn grade_word<'a, S: AsRef<str>>(
    words: &'a [S],
    scale: &RatingScale,
    v: f64,
) -> Option<&'a str> {
    let span = words.len().checked_sub(1)? as f64;
    if (scale.max - scale.min - span).abs() > 1e-9 || v.fract().abs() > 1e-9 {
        return None;
    }
    words
        .get((scale.max - v).round() as usize)
        .map(AsRef::as_ref)
}

/// The words of `study`'s grades, best first ([`crate::methods::Method::grade_words`]): on
/// a continuous scale every word, each naming an equal section (BT.500's quality scale); on a
/// categorical one where it has one whole-number grade per word, else none (a 1-10 scale).
pub fn scale_words(study: &StudyDefinition) -> Vec<String> {
    let words = study.method().grade_words();
    let s = &study.scale;
    let fits = (s.max - s.min - words.len().saturating_sub(1) as f64).abs() < 1e-9;
    if s.kind == ScaleKind::Categorical && !fits {
        return Vec::new();
    }
    words.iter().map(|w| (*w).to_owned()).collect()
}

/// The rating values of a categorical scale, low to high.
pub fn categories(scale: &RatingScale) -> Vec<f64> {
    let step = scale.step.filter(|s| *s > 0.0).unwrap_or(1.0);
    let n = ((scale.max - scale.min) / step).round().clamp(0.0, 200.0) as usize;
    (0..=n).map(|k| scale.min + k as f64 * step).collect()
}

/// The title subjects see when the study file gives none: the study's `name` is the
/// experimenter's handle (`staircase-thesis-ch5`) and is never shown to a subject.
pub const DEFAULT_TITLE: &str = "Motion study";

/// The default instructions for `study` (used when `[session] instructions` is not given):
/// its method's ([`crate::methods::Method::instructions`]), written from the design as it
/// runs.
pub fn default_instructions(study: &StudyDefinition) -> String {
    study.method().instructions(study)
}

/// The instructions subjects read: `[session] instructions` where the study gives them, else
/// [`default_instructions`].
pub fn instructions(study: &StudyDefinition) -> String {
    study
        .session
        .instructions
        .clone()
        .unwrap_or_else(|| default_instructions(study))
}

/// What the two stimuli of a DSCQS trial are called on screen: A and B (BT.500's A B A B),
/// or 1 and 2 (one after the other, thesis 6.5), as the presentation labels them.
pub fn dscqs_names(arrangement: Arrangement) -> [&'static str; 2] {
    if arrangement == Arrangement::Sequential {
        ["1", "2"]
    } else {
        ["A", "B"]
    }
}

/// How many trials a session has, as far as the subject can be told.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Planned {
    /// Exactly this many (MOS, DSCQS: planned up front).
    Exactly(u32),
    /// At most this many (staircases capped by `max_trials`; they may stop earlier).
    AtMost(u32),
    /// Not known (a staircase that stops on reversals only).
    Unknown,
}

impl Planned {
    /// "Trial k of n", "Trial k of at most n" or "Trial k".
    #[must_use]
    pub fn trial_text(self, k: u32) -> String {
        match self {
            Planned::Exactly(n) => format!("Trial {k} of {n}"),
            Planned::AtMost(n) => format!("Trial {k} of at most {n}"),
            Planned::Unknown => format!("Trial {k}"),
        }
    }

    /// "k of n trials done", and so on.
    #[must_use]
    pub fn done_text(self, done: u32) -> String {
        match self {
            Planned::Exactly(n) => format!("Trials done: {done} of {n}."),
            Planned::AtMost(n) => format!("Trials done: {done} (at most {n})."),
            Planned::Unknown => format!("Trials done: {done}."),
        }
    }

    /// The number a progress bar runs to (exact plans only).
    #[must_use]
    pub fn exact(self) -> Option<u32> {
        match self {
            Planned::Exactly(n) if n > 0 => Some(n),
            _ => None,
        }
    }
}

/// Total trials of a session ([`crate::methods::Method::planned_trials`]): exact when the
/// method plans them up front, an upper bound when every interleaved staircase has
/// `max_trials`.
#[must_use]
pub fn planned_trials(study: &StudyDefinition) -> Planned {
    study.method().planned_trials(study)
}
