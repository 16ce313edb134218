//! ACR and ACR-HR (ITU-T P.910): one motion at a time, rated on its own; hidden references
//! make it ACR-HR.

use std::fmt;

use super::common::{describe_ratings, practice_sentence, rating_trials, scale_instructions};
use super::common::{score_rating, simulate_rating};
use super::{AnswerKind, AnswerWidget, Method, ReferenceRule, Refusal};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Outcome, Position, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{RatingScale, ReferencePlacement, StudyDefinition};
use crate::texts::Planned;

/// Absolute category rating.
pub(super) struct Acr;

impl Method for Acr {
    fn protocol(&self) -> Protocol {
        Protocol::Acr
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Rating
    }

    fn answer_widget(&self, _study: &StudyDefinition) -> AnswerWidget {
        AnswerWidget::Rating {
            question: "Rate the quality of the motion".to_string(),
            missing: "the motion".to_string(),
            name: "Quality".to_string(),
        }
    }

    fn instructions(&self, study: &StudyDefinition) -> String {
        format!(
            "Each trial shows one motion. {} Rate each motion on its own; there is no original \
             to compare it with.{}",
            scale_instructions(&study.scale, "its quality"),
            practice_sentence(study, "qualities")
        )
    }

    fn planned_trials(&self, study: &StudyDefinition) -> Planned {
        rating_trials(study)
    }

    fn describe(&self, study: &StudyDefinition, text: &mut String) -> fmt::Result {
        describe_ratings(text, study)
    }

    fn plan(&self, study: &StudyDefinition, subject: u32) -> Vec<Trial> {
        crate::engine::plan_rated_conditions(study, subject)
    }

    fn score(
        &self,
        _trial: &Trial,
        answer: Answer,
        scale: &RatingScale,
    ) -> Result<Outcome, Refusal> {
        score_rating(answer, scale)
    }

    fn simulate(
        &self,
        observer: &Observer,
        _trial: &Trial,
        test_error: &dyn Fn() -> Result<f64, ObserverError>,
        rng: &mut StudyRng,
    ) -> Result<Answer, ObserverError> {
        simulate_rating(observer, test_error, rng)
    }

    /// P.910 ACR: one stimulus at a time.
    fn arrangements(&self) -> &'static [(&'static str, Arrangement)] {
        &[("single", Arrangement::Single)]
    }

    fn reference_rule(&self) -> ReferenceRule {
        ReferenceRule::None {
            why: "ACR shows no reference (P.910 single stimulus): remove it",
            placement: ReferencePlacement::Fixed(Position::Hidden),
        }
    }

    fn labels_hidden(&self) -> Option<&'static str> {
        Some("ACR shows one motion and no reference (ITU-T P.910)")
    }

    fn hidden_references(&self) -> bool {
        true
    }

    fn gold_trials(&self) -> bool {
        true
    }

    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Rating(scale.min)]
    }
}
