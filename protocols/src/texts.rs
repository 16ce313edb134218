//! The words a subject reads, shared by every front end (the study window, the browser page
//! of `study serve`): the BT.500 grade labels, the 2AFC question, the acknowledgement, and
//! the default instructions of each protocol as the study's presentation settings make them.

use crate::record::{Arrangement, Position, Protocol};
use crate::study::{
    RatingScale, ReferencePlacement, ScaleKind, ScaleWords, StimulusLabels, StudyDefinition,
};

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

/// The five grade labels of `scale`, best first.
pub fn grade_labels(scale: &RatingScale) -> [&'static str; 5] {
    match scale.words {
        ScaleWords::Quality => QUALITY_LABELS,
        ScaleWords::Impairment => IMPAIRMENT_LABELS,
    }
}

/// The 2AFC question of thesis ch. 5.
pub const AFC_QUESTION: &str = "Which motion looks more natural?";

/// The question of a pair comparison (P.910 PC): which of two versions is better.
pub const PC_QUESTION: &str = "Which motion looks better?";

/// Shown after an answer was logged, over the blank gap before the next trial.
pub const ANSWER_RECORDED: &str = "Answer recorded";

/// A rating as a subject reads it: `3`, `3.5`.
pub fn format_rating(v: f64) -> String {
    if v.fract().abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

/// Label of an integer rating on a five-grade scale: BT.500's quality grades, or P.910 DCR's
/// impairment categories on a DCR study's scale.
pub fn quality_label(scale: &RatingScale, v: f64) -> Option<&'static str> {
    if (scale.max - scale.min - 4.0).abs() > 1e-9 || v.fract().abs() > 1e-9 {
        return None;
    }
    grade_labels(scale)
        .get((scale.max - v).round() as usize)
        .copied()
}

/// The rating values of a categorical scale, low to high.
pub fn categories(scale: &RatingScale) -> Vec<f64> {
    let step = scale.step.filter(|s| *s > 0.0).unwrap_or(1.0);
    let n = ((scale.max - scale.min) / step).round().clamp(0.0, 200.0) as usize;
    (0..=n).map(|k| scale.min + k as f64 * step).collect()
}

/// How the rating is given, for the instructions.
fn scale_instructions(scale: &RatingScale, what: &str) -> String {
    match scale.kind {
        ScaleKind::Categorical => format!(
            "Rate {what} from {} (worst) to {} (best), with the mouse or the number keys \
             (the Up and Down arrow keys move by one step), then press Continue (Enter).",
            format_rating(scale.min),
            format_rating(scale.max)
        ),
        ScaleKind::Continuous => format!(
            "Rate {what} by placing a mark on the scale, from Bad at the bottom to Excellent at \
             the top: click or drag, or press 1 (Bad) to 5 (Excellent) and move the mark with \
             the Up and Down arrow keys (Page Up and Page Down for larger steps). Then press \
             Continue (Enter)."
        ),
    }
}

/// The default instructions of a MUSHRA study (BS.1534-3 adapted).
const MUSHRA_INSTRUCTIONS: &str = "Each screen shows the original motion, labelled “Reference”, and beside it several \
     versions of it, lettered A, B, C ... One of them is the original itself, hidden \
     among them; rate it 100 when you find it. Rate each lettered motion from 0 (bad) \
     to 100 (excellent) against the reference on its slider: click it, drag, or press \
     Tab to go from slider to slider and the arrow keys to move one (Page Up and Page \
     Down by 10). The sliders open once every motion has played through; Replay shows \
     them again. Press Continue (Enter) when every letter has its rating.";

/// The title subjects see when the study file gives none: the study's `name` is the
/// experimenter's handle (`staircase-thesis-ch5`) and is never shown to a subject.
pub const DEFAULT_TITLE: &str = "Motion study";

/// " The first few trials show the range of {what} you will meet." where the session opens
/// with familiarization trials (`[session] familiarization`), else nothing: the
/// instructions promise no practice a study does not give.
fn practice_sentence(study: &StudyDefinition, what: &str) -> String {
    if study.familiarization.is_empty() {
        String::new()
    } else {
        format!(" The first few trials show the range of {what} you will meet.")
    }
}

/// Whether the original itself is among the versions a subject compares or rates unlabelled
/// (`[conditions] hidden_reference`: a condition whose stimulus is its reference).
fn original_among_versions(study: &StudyDefinition) -> bool {
    study.conditions.iter().any(|c| c.stimulus == c.reference)
}

/// The default instructions for `study` (used when `[session] instructions` is not given),
/// written from the design as it runs: they say which motion is the original where the screen
/// labels it (MOS), that nobody says so where the design hides it (DSCQS, 2AFC), whether the
/// original may be one of the versions compared (a pair comparison with hidden references),
/// and mention practice trials only where the session has them. Hidden repeats are not
/// mentioned: they are hidden by design.
pub fn default_instructions(study: &StudyDefinition) -> String {
    let p = &study.presentation;
    match study.protocol {
        Protocol::Mos => {
            let how = if p.arrangement == Arrangement::Sequential {
                "one after the other"
            } else {
                "side by side"
            };
            let which = match &p.labels {
                Some(StimulusLabels { reference, test }) => format!(
                    "the original motion, labelled “{reference}”, and a compressed version of it, \
                     labelled “{test}”"
                ),
                None => "the original motion and a compressed version of it (they are not \
                         labelled)"
                    .to_string(),
            };
            format!(
                "Each trial shows {which}, {how}. {}{}",
                scale_instructions(&study.scale, "the quality of the compressed motion"),
                practice_sentence(study, "qualities")
            )
        }
        Protocol::Dscqs => {
            let [a, b] = dscqs_names(p.arrangement);
            let keys = if study.scale.kind == ScaleKind::Continuous {
                format!(
                    " The number keys mark {a} first, then {b}; the Left and Right arrow keys \
                     choose which scale the keys move."
                )
            } else {
                format!(
                    " The number keys rate {a} first, then {b}; the Left and Right arrow keys \
                     choose which row the keys change."
                )
            };
            let shows = if p.arrangement == Arrangement::Sequential {
                let which = match p.reference_position {
                    ReferencePlacement::Fixed(Position::First) => {
                        "The first is the original, the second a compressed version of it."
                    }
                    ReferencePlacement::Fixed(_) => {
                        "The second is the original, the first a compressed version of it."
                    }
                    ReferencePlacement::Random | ReferencePlacement::Balanced => {
                        "One of them may be the original; you are not told which."
                    }
                };
                format!(
                    "Each trial shows two motions one after the other, {a} then {b}, with a grey \
                     screen between them. {which} Then rate both."
                )
            } else {
                "Each trial shows two motions, A and B, twice, with a grey screen between them: \
                 A, B, A, B. One of them may be the original; you are not told which. After the \
                 second B, rate both."
                    .to_string()
            };
            format!(
                "{shows} {}{keys}",
                scale_instructions(&study.scale, &format!("the quality of {a} and of {b}"))
            )
        }
        Protocol::Acr => format!(
            "Each trial shows one motion. {} Rate each motion on its own; there is no original \
             to compare it with.{}",
            scale_instructions(&study.scale, "its quality"),
            practice_sentence(study, "qualities")
        ),
        Protocol::Dcr => {
            let label = |l: Option<&str>| l.map_or(String::new(), |l| format!(", labelled “{l}”"));
            let (reference, test) = (
                label(p.labels.as_ref().map(|l| l.reference.as_str())),
                label(p.labels.as_ref().map(|l| l.test.as_str())),
            );
            let how = if p.arrangement == Arrangement::Sequential {
                "then"
            } else {
                "beside"
            };
            format!(
                "Each trial shows the original motion{reference}, {how} a compressed version of \
                 it{test}. Rate how much the compression impairs the motion, from 5 \
                 (imperceptible) to 1 (very annoying), with the mouse or the number keys, then \
                 press Continue (Enter).{}",
                practice_sentence(study, "impairments")
            )
        }
        Protocol::PairComparison => {
            pair_comparison_instructions(p.arrangement, original_among_versions(study))
        }
        Protocol::Mushra => MUSHRA_INSTRUCTIONS.to_string(),
        Protocol::Staircase => staircase_instructions(study),
    }
}

/// The default instructions of a 2AFC staircase, with its practice trials where it has any.
fn staircase_instructions(study: &StudyDefinition) -> String {
    let practice = match study.staircase.as_ref().map_or(0, |s| s.practice_trials) {
        0 => String::new(),
        1 => " The first trial is for practice.".to_string(),
        n => format!(" The first {n} trials are for practice."),
    };
    format!(
        "Each trial shows two motions side by side. Choose the one that looks more natural \
         with the Left or Right arrow key (or click). Answer even when you are unsure.{practice}"
    )
}

/// The default instructions of a pair comparison shown in `arrangement`; `original`: the
/// original itself is one of the versions compared (hidden references).
fn pair_comparison_instructions(arrangement: Arrangement, original: bool) -> String {
    let (shows, keys) = if arrangement == Arrangement::Sequential {
        (
            "one after the other, with a grey screen between them",
            "the 1 or 2 key",
        )
    } else {
        ("side by side", "the Left or Right arrow key")
    };
    let original = if original {
        "Either of them may be the original motion itself; you are not told which."
    } else {
        "Neither is the original."
    };
    format!(
        "Each trial shows two versions of the same motion {shows}. {original} Choose the one \
         that looks better with {keys} (or click). Answer even when you are unsure."
    )
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

/// Total trials of a session: exact when the protocol plans them up front, an upper bound
/// when every interleaved staircase has `max_trials`.
#[must_use]
pub fn planned_trials(study: &StudyDefinition) -> Planned {
    match study.protocol {
        Protocol::Mos | Protocol::Dscqs | Protocol::Acr | Protocol::Dcr => Planned::Exactly(
            (study.familiarization.len()
                + study.conditions.len()
                + study.session.hidden_repeats as usize) as u32,
        ),
        Protocol::PairComparison => {
            Planned::Exactly((study.pairs().len() + study.session.hidden_repeats as usize) as u32)
        }
        // One row per rated pane: each screen's conditions, hidden reference and anchor, the
        // training screens' first.
        Protocol::Mushra => {
            let training = study.mushra.as_ref().map_or(0, |m| m.training_screens) as usize;
            let panes = |s: &(String, Vec<&crate::study::Condition>)| s.1.len() + 2;
            let screens = crate::study::mushra_screens(&study.conditions);
            let test: usize = screens.iter().map(panes).sum();
            let trained: usize = screens.iter().take(training).map(panes).sum();
            Planned::Exactly((test + trained) as u32)
        }
        Protocol::Staircase => study
            .staircase
            .as_ref()
            .and_then(|s| {
                s.tracks
                    .iter()
                    .map(|t| t.settings.max_trials)
                    .sum::<Option<u32>>()
                    .map(|n| n + s.practice_trials)
            })
            .map_or(Planned::Unknown, Planned::AtMost),
    }
}
