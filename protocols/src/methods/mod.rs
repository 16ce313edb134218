//! The study methods, one module each, behind one trait ([`Method`]) and one registry
//! ([`of`]): what a method says to its subjects (instructions, the answer widget and its
//! words), what a session of it holds (planned trials, `study check`'s lines), what its
//! answers are, and which answers lead to different next trials. Code outside these modules
//! asks the study's method ([`StudyDefinition::method`]) instead of matching on the
//! protocol's name; `study/tests/architecture.rs` counts the matches left.
//!
//! Each method also plans its session (shared planning in `engine`: shuffles, Latin
//! squares, hidden repeats, balanced sides), scores its answers, and answers as a simulated
//! observer (`observer` models the observer; the method says what it answers). Adaptive
//! tracks (staircases, QUEST+, Psi) are the engine's. The study file's checks ask the method
//! what it allows (its sections, arrangements, reference rule, labels, scale), and its
//! analysis is registered the same way in the `analysis` crate (`analysis/src/methods/`).

mod acr;
mod ccr;
pub(crate) mod common;
mod dcr;
mod dscqs;
mod mos;
mod mushra;
mod pair_comparison;
mod staircase;

use std::fmt;

use schemars::JsonSchema;
use serde::Serialize;

use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Outcome, Position, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{Condition, RatingScale, ReferencePlacement, ScaleKind, StudyDefinition};
use crate::texts::Planned;

/// What an answer to a method's trial is (how a result row holds it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnswerKind {
    /// One rating on the study's scale ([`Answer::Rating`]).
    Rating,
    /// A rating of each of two stimuli ([`Answer::Pair`]).
    RatingPair,
    /// A choice of one of two positions ([`Answer::Choice`]).
    Choice,
}

/// The widget a subject answers a trial with, with the words it shows: what every front end
/// draws below the stimuli.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum AnswerWidget {
    /// One rating on the study's scale: grade buttons (categorical) or one vertical scale
    /// (continuous).
    Rating {
        /// The question above it.
        question: String,
        /// What a missing rating names ("Choose a rating for {missing} to continue.").
        missing: String,
        /// The scale's name beside it.
        name: String,
        /// The grades' words, best first ([`crate::texts::scale_words`]).
        words: Vec<String>,
    },
    /// A rating of each of the two stimuli (A and B, or 1 and 2, as the arrangement names
    /// them): two rows of grades or BT.500's pair of vertical scales.
    RatingPair {
        /// The question above them.
        question: String,
        /// What the two stimuli are called ("A" and "B", or "1" and "2"), in the order
        /// the schedule first shows them.
        names: [String; 2],
        /// The grades' words, best first ([`crate::texts::scale_words`]).
        words: Vec<String>,
    },
    /// A choice of one of the buttons.
    Choice {
        /// The question above the buttons.
        question: String,
        /// The buttons, left to right.
        options: Vec<ChoiceOption>,
    },
    /// One slider per lettered pane (a MUSHRA screen), beside the scale's words.
    SliderGrid {
        /// The question above the sliders.
        question: String,
        /// The words of the scale's equal sections, best first (BS.1534's Excellent … Bad,
        /// [`crate::texts::scale_words`]).
        words: Vec<String>,
    },
}

/// One button of a choice: its label, its key, and the answer it gives.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, JsonSchema)]
pub struct ChoiceOption {
    /// What the button says ("Left", "No preference").
    pub label: String,
    /// The key that answers with it, by its name on a keyboard ("ArrowLeft", "1", "A",
    /// "ArrowDown"), as both the window and a browser name keys.
    pub key: String,
    /// The position it answers with.
    pub answer: Position,
}

impl ChoiceOption {
    /// The two positions of `arrangement` (left and right, 1 and 2, or A and B), as buttons
    /// with their keys: what a forced choice between the two stimuli offers.
    pub fn positions(arrangement: Arrangement) -> Vec<ChoiceOption> {
        let (a, b, ka, kb, la, lb) = match arrangement {
            Arrangement::Sequential => (
                Position::First,
                Position::Second,
                "1",
                "2",
                "First",
                "Second",
            ),
            Arrangement::Abab => (Position::A, Position::B, "A", "B", "A", "B"),
            // A choice is never between a single stimulus or a grid's panes (the study file
            // refuses them); they are offered as side by side.
            Arrangement::SideBySide | Arrangement::Single | Arrangement::Grid => (
                Position::Left,
                Position::Right,
                "ArrowLeft",
                "ArrowRight",
                "Left",
                "Right",
            ),
        };
        vec![
            ChoiceOption {
                label: la.to_owned(),
                key: ka.to_owned(),
                answer: a,
            },
            ChoiceOption {
                label: lb.to_owned(),
                key: kb.to_owned(),
                answer: b,
            },
        ]
    }
}

/// Why a method refused an answer (the engine names the trial and the protocol).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    /// The answer is not of the kind the method takes; what it takes, in words.
    Expected(&'static str),
    /// A rating that is not on the study's scale.
    OffScale(f64),
}

/// What a study file may say of the reference's position (`[presentation]
/// reference_position`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReferenceRule {
    /// A position of the arrangement, `"random"` (the default) or `"balanced"`.
    Any,
    /// `"random"` or `"balanced"` only: a fixed side or order would confound it with the
    /// condition (two test stimuli), or leave an effect unmeasured (CCR's order).
    NotFixed {
        /// The refusal of a fixed position, naming the method's reason.
        why: &'static str,
    },
    /// The reference is shown first (P.910 DCR), or on the side the study names.
    ShownFirst,
    /// Not the study's to say: `why` refuses the key; the placement is `placement`.
    None {
        /// The refusal, naming the method's reason.
        why: &'static str,
        /// Where the reference goes.
        placement: ReferencePlacement,
    },
}

/// The sections of a study file that describe what a method shows (checked by
/// `study::top`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sections {
    /// `[conditions]` (test conditions, hidden references where the method takes them) and
    /// `[session] familiarization`.
    RatedConditions,
    /// `[conditions]` compared in pairs: every pair of one clip's conditions.
    Pairs,
    /// `[conditions]` grouped in screens, one per clip, and `[mushra]` (anchors, training
    /// screens, post-screening).
    Screens,
    /// `[staircase]`: the tracks and their levels (or a live codec).
    Tracks,
}

/// The `(name, arrangement)` pairs of side by side (the default) or sequential.
pub(crate) const SIDE_BY_SIDE_OR_SEQUENTIAL: &[(&str, Arrangement)] = &[
    ("side_by_side", Arrangement::SideBySide),
    ("sequential", Arrangement::Sequential),
];

/// A study method: one implementation per [`Protocol`], found by [`of`].
///
/// The provided methods are those of a method that rates one stimulus (or one pane) per
/// trial on the study's scale over a plan of the study's conditions, with familiarization
/// and hidden repeats (MOS, ACR, DCR); the others override what differs.
pub trait Method: Sync {
    /// The protocol this method runs (its name in study files and result rows).
    fn protocol(&self) -> Protocol;

    /// What an answer to one of its trials is.
    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Rating
    }

    /// The widget a subject answers with, and its words, for `study` as run.
    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget;

    /// The default instructions (used when `[session] instructions` is not given), written
    /// from the design as it runs: what is shown, whether the original may be among the
    /// versions, practice only where the session has it.
    fn instructions(&self, study: &StudyDefinition) -> String;

    /// How many trials a session has, as far as the subject can be told.
    fn planned_trials(&self, study: &StudyDefinition) -> Planned {
        common::rating_trials(study)
    }

    /// `study check`'s lines about a session: its trials (or screens, or staircases) and
    /// presentation time.
    ///
    /// # Errors
    /// Only the formatter's (never, into a `String`).
    fn describe(&self, study: &StudyDefinition, text: &mut String) -> fmt::Result {
        common::describe_ratings(text, study)
    }

    /// How many items a balanced Latin square orders over `conditions`: the conditions,
    /// unless the method orders something else (pairs, screens).
    fn ordered_items(&self, conditions: &[Condition]) -> usize {
        conditions.len()
    }

    /// The study file's sections that say what the method shows.
    fn sections(&self) -> Sections {
        Sections::RatedConditions
    }

    /// What a balanced Latin square orders, in the report's words.
    fn ordered_item_name(&self) -> &'static str {
        "conditions"
    }

    /// The arrangements a study file may ask for (`[presentation] arrangement`), by name;
    /// the first is the default.
    fn arrangements(&self) -> &'static [(&'static str, Arrangement)] {
        SIDE_BY_SIDE_OR_SEQUENTIAL
    }

    /// What a study file may say of the reference's position.
    fn reference_rule(&self) -> ReferenceRule {
        ReferenceRule::Any
    }

    /// Why the stimuli cannot carry labels naming the reference and the test, where the
    /// design hides which is which (`None`: they are shown unless the study says no).
    fn labels_hidden(&self) -> Option<&'static str> {
        None
    }

    /// The rating scale's kind when the study file does not name one.
    fn default_scale_kind(&self) -> ScaleKind {
        ScaleKind::Categorical
    }

    /// The default range of a scale of `kind` (categorical 1-5, continuous 0-100).
    fn default_scale_range(&self, kind: ScaleKind) -> (f64, f64) {
        match kind {
            ScaleKind::Categorical => (1.0, 5.0),
            ScaleKind::Continuous => (0.0, 100.0),
        }
    }

    /// The default step of a scale of `kind` (categorical 1-5, continuous 0-100).
    fn default_scale_step(&self, kind: ScaleKind) -> Option<f64> {
        match kind {
            ScaleKind::Categorical => Some(1.0),
            ScaleKind::Continuous => None,
        }
    }

    /// A scale the method cannot rate on, said as the study file's problem (`None`: fine).
    fn check_scale(
        &self,
        _kind: ScaleKind,
        _min: f64,
        _max: f64,
        _step: Option<f64>,
    ) -> Option<String> {
        None
    }

    /// The words of its grades, best first (BT.500's five quality grades unless the method
    /// names others): beside a categorical scale's whole numbers from the top, or naming the
    /// equal sections of a continuous scale ([`crate::texts::scale_words`]).
    fn grade_words(&self) -> &'static [&'static str] {
        &crate::texts::QUALITY_LABELS
    }

    /// Whether its screen may offer a "no preference" answer ([`crate::Position::Neither`])
    /// beside its choices, where the study asks for one (`[presentation] no_preference`).
    fn offers_no_preference(&self) -> bool {
        false
    }

    /// Whether a condition may be its own reference (`[conditions] hidden_reference`: ACR-HR,
    /// a pair comparison's anchor).
    fn hidden_references(&self) -> bool {
        false
    }

    /// What its analysis makes of a hidden reference, for `study check`.
    fn hidden_reference_use(&self) -> &'static str {
        "ACR-HR: DMOS = test - hidden reference + 5"
    }

    /// Whether it takes catch (gold) trials: rated conditions of one-stimulus screens.
    fn gold_trials(&self) -> bool {
        false
    }

    /// Where the reference goes, for `study check`.
    fn describe_reference(&self, placement: ReferencePlacement) -> String {
        common::describe_reference(placement, "per condition")
    }

    /// The trials of subject `subject`'s session (0-based), planned up front from the
    /// study's seed; none for an adaptive method, whose tracks pick each trial (`engine`).
    fn plan(&self, study: &StudyDefinition, subject: u32) -> Vec<Trial> {
        crate::engine::plan_rated_conditions(study, subject)
    }

    /// Scores `answer` to `trial` on `scale`: the outcome its row logs. An adaptive method's
    /// `correct` moves its track, which adds the reversal.
    ///
    /// # Errors
    /// An answer of another kind, or a rating off the scale.
    fn score(
        &self,
        _trial: &Trial,
        answer: Answer,
        scale: &RatingScale,
    ) -> Result<Outcome, Refusal> {
        common::score_rating(answer, scale)
    }

    /// A simulated observer's answer to `trial`: `test_error` gives the objective error of
    /// the trial's test stimulus (measured, or the manifest's), `rng` the trial's draws.
    ///
    /// # Errors
    /// A stimulus without the error the observer needs.
    fn simulate(
        &self,
        observer: &Observer,
        _trial: &Trial,
        test_error: &dyn Fn() -> Result<f64, ObserverError>,
        rng: &mut StudyRng,
    ) -> Result<Answer, ObserverError> {
        common::simulate_rating(observer, test_error, rng)
    }

    /// Whether its trials come in screens shown whole (a MUSHRA screen's panes, one trial
    /// each): the time limit and breaks fall between screens.
    fn screens(&self) -> bool {
        false
    }

    /// Whether the next trial depends on the answers (an adaptive track), so that a session
    /// has no fixed plan to count against.
    fn adaptive(&self) -> bool {
        false
    }

    /// The answers to `trial` that can lead to different next trials (a runner prepares
    /// each one's next stimulus while the subject watches): one when the plan does not
    /// depend on the answer.
    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Rating(scale.min)]
    }
}

/// The method of `protocol`: the one place a protocol's name picks its code.
pub fn of(protocol: Protocol) -> &'static dyn Method {
    match protocol {
        Protocol::Mos => &mos::Mos,
        Protocol::Dscqs => &dscqs::Dscqs,
        Protocol::Acr => &acr::Acr,
        Protocol::Dcr => &dcr::Dcr,
        Protocol::PairComparison => &pair_comparison::PairComparison,
        Protocol::Mushra => &mushra::Mushra,
        Protocol::Staircase => &staircase::Staircase,
        Protocol::Ccr => &ccr::Ccr,
    }
}

impl StudyDefinition {
    /// The study's method ([`of`] its protocol).
    pub fn method(&self) -> &'static dyn Method {
        of(self.protocol)
    }
}

#[cfg(test)]
mod tests {
    use super::of;
    use crate::record::Protocol;

    #[test]
    fn every_protocol_has_its_own_method() {
        for p in [
            Protocol::Mos,
            Protocol::Dscqs,
            Protocol::Acr,
            Protocol::Dcr,
            Protocol::PairComparison,
            Protocol::Mushra,
            Protocol::Staircase,
            Protocol::Ccr,
        ] {
            assert_eq!(of(p).protocol(), p);
        }
    }
}
