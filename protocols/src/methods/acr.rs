//! ACR and ACR-HR (ITU-T P.910): one motion at a time, rated on its own; hidden references
//! make it ACR-HR.

use std::fmt;

use super::common::{describe_ratings, practice_sentence, rating_trials, scale_instructions};
use super::{AnswerKind, AnswerWidget, Method};
use crate::record::{Answer, Protocol, Trial};
use crate::study::{RatingScale, StudyDefinition};
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

    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Rating(scale.min)]
    }
}
