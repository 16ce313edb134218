//! DCR (ITU-T P.910, BT.500 DSIS): the original, then (or beside) a compressed version,
//! the impairment rated on the five categories.

use std::fmt;

use super::common::{describe_ratings, practice_sentence, rating_trials};
use super::common::{score_rating, simulate_rating};
use super::{AnswerKind, AnswerWidget, Method, Refusal};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Outcome, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{RatingScale, StudyDefinition};
use crate::texts::Planned;

/// Degradation category rating.
pub(super) struct Dcr;

impl Method for Dcr {
    fn protocol(&self) -> Protocol {
        Protocol::Dcr
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Rating
    }

    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        let question = match &study.presentation.labels {
            Some(l) => format!(
                "How impaired is “{}” compared with “{}”?",
                l.test, l.reference
            ),
            None => "How impaired is the compressed motion compared with the original?".to_string(),
        };
        AnswerWidget::Rating {
            question,
            missing: "the impairment".to_string(),
            name: "Impairment".to_string(),
        }
    }

    fn instructions(&self, study: &StudyDefinition) -> String {
        let p = &study.presentation;
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
        // The test's impairment, on the same latent quality, with the reference shown.
        simulate_rating(observer, test_error, rng)
    }

    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Rating(scale.min)]
    }
}
