//! ACR and ACR-HR (ITU-T P.910): one motion at a time, rated on its own; hidden references
//! make it ACR-HR.

use super::common::{practice_sentence, scale_instructions};
use super::{AnswerWidget, Method, ReferenceRule};
use crate::record::{Arrangement, Position, Protocol};
use crate::study::{ReferencePlacement, StudyDefinition};
use crate::texts::scale_words;

/// Absolute category rating.
pub(super) struct Acr;

impl Method for Acr {
    fn protocol(&self) -> Protocol {
        Protocol::Acr
    }

    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        AnswerWidget::Rating {
            question: "Rate the quality of the motion".to_string(),
            missing: "the motion".to_string(),
            name: "Quality".to_string(),
            words: scale_words(study),
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
}
