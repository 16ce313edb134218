//! The study methods, one module each, behind one trait ([`Method`]) and one registry
//! ([`of`]): what a method says to its subjects (instructions, the answer widget and its
//! words), what a session of it holds (planned trials, `study check`'s lines), what its
//! answers are, and which answers lead to different next trials. Code outside these modules
//! asks the study's method ([`StudyDefinition::method`]) instead of matching on the
//! protocol's name; `study/tests/architecture.rs` counts the matches left.
//!
//! A method's trial plan and answer scoring are still `engine`'s, its simulated observer
//! `observer`'s and its analysis `analysis`'s: they move behind this trait next.

mod acr;
pub(crate) mod common;
mod dcr;
mod dscqs;
mod mos;
mod mushra;
mod pair_comparison;
mod staircase;

use std::fmt;

use serde::Serialize;

use crate::record::{Answer, Protocol, Trial};
use crate::study::{RatingScale, ReferencePlacement, StudyDefinition};
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
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
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
    },
    /// A rating of each of the two stimuli (A and B, or 1 and 2, as the arrangement names
    /// them): two rows of grades or BT.500's pair of vertical scales.
    RatingPair,
    /// A forced choice between the two positions shown.
    Choice {
        /// The question above the two buttons.
        question: String,
    },
    /// One slider per lettered pane (a MUSHRA screen).
    SliderGrid {
        /// The question above the sliders.
        question: String,
    },
}

/// A study method: one implementation per [`Protocol`], found by [`of`].
pub trait Method: Sync {
    /// The protocol this method runs (its name in study files and result rows).
    fn protocol(&self) -> Protocol;

    /// What an answer to one of its trials is.
    fn answer_kind(&self) -> AnswerKind;

    /// The widget a subject answers with, and its words, for `study` as run.
    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget;

    /// The default instructions (used when `[session] instructions` is not given), written
    /// from the design as it runs: what is shown, whether the original may be among the
    /// versions, practice only where the session has it.
    fn instructions(&self, study: &StudyDefinition) -> String;

    /// How many trials a session has, as far as the subject can be told.
    fn planned_trials(&self, study: &StudyDefinition) -> Planned;

    /// `study check`'s lines about a session: its trials (or screens, or staircases) and
    /// presentation time.
    ///
    /// # Errors
    /// Only the formatter's (never, into a `String`).
    fn describe(&self, study: &StudyDefinition, text: &mut String) -> fmt::Result;

    /// How many items a balanced Latin square orders: the conditions, unless the method
    /// orders something else (pairs, screens).
    fn ordered_items(&self, study: &StudyDefinition) -> usize {
        study.conditions.len()
    }

    /// Where the reference goes, for `study check`.
    fn describe_reference(&self, placement: ReferencePlacement) -> String {
        common::describe_reference(placement, "per condition")
    }

    /// Whether the next trial depends on the answers (an adaptive track), so that a session
    /// has no fixed plan to count against.
    fn adaptive(&self) -> bool {
        false
    }

    /// The answers to `trial` that can lead to different next trials (a runner prepares
    /// each one's next stimulus while the subject watches): one when the plan does not
    /// depend on the answer.
    fn distinct_answers(&self, trial: &Trial, scale: &RatingScale) -> Vec<Answer>;
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
        ] {
            assert_eq!(of(p).protocol(), p);
        }
    }
}
