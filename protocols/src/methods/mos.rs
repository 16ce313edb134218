//! MOS (thesis ch. 3, BT.500 adapted): the original and a compressed version, the compressed
//! one rated on the study's scale.

use super::common::{practice_sentence, scale_instructions};
use super::{AnswerWidget, Method};
use crate::record::{Arrangement, Protocol};
use crate::study::{ScaleKind, StimulusLabels, StudyDefinition};
use crate::texts::scale_words;

/// Mean opinion score of the compressed motion beside (or after) its original.
pub(super) struct Mos;

impl Method for Mos {
    fn protocol(&self) -> Protocol {
        Protocol::Mos
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
            words: scale_words(study),
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
}
