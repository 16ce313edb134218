//! MOS (thesis ch. 3, BT.500 adapted): the original and a compressed version, the compressed
//! one rated on the study's scale.

use std::fmt;

use super::common::{describe_ratings, practice_sentence, rating_trials, scale_instructions};
use super::common::{score_rating, simulate_rating};
use super::{AnswerKind, AnswerWidget, Method, Refusal};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Outcome, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{RatingScale, ScaleKind, StimulusLabels, StudyDefinition};
use crate::texts::Planned;

/// Mean opinion score of the compressed motion beside (or after) its original.
pub(super) struct Mos;

impl Method for Mos {
    fn protocol(&self) -> Protocol {
        Protocol::Mos
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Rating
    }

    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        // The compressed motion, named by its label where labels are shown.
        let labels = study.presentation.labels.as_ref();
        let (question, missing) = match labels {
            Some(l) => (
                format!("Rate the quality of the motion labelled “{}”", l.test),
                format!("“{}”", l.test),
            ),
            None => (
                "Rate the quality of the compressed motion".to_string(),
                "the compressed motion".to_string(),
            ),
        };
        AnswerWidget::Rating {
            question,
            missing,
            name: labels.map_or("Quality", |l| l.test.as_str()).to_string(),
        }
    }

    fn instructions(&self, study: &StudyDefinition) -> String {
        let p = &study.presentation;
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

    /// Paper 000's 1-5 in half steps.
    fn default_scale_step(&self, kind: ScaleKind) -> Option<f64> {
        match kind {
            ScaleKind::Categorical => Some(0.5),
            ScaleKind::Continuous => None,
        }
    }

    fn gold_trials(&self) -> bool {
        true
    }

    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Rating(scale.min)]
    }
}
