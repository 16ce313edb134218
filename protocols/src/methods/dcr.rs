//! DCR (ITU-T P.910, BT.500 DSIS): the original, then (or beside) a compressed version,
//! the impairment rated on the five categories.

use super::common::{only_categories, practice_sentence};
use super::{AnswerWidget, Method, ReferenceRule};
use crate::record::{Arrangement, Protocol};
use crate::study::{ScaleKind, StudyDefinition};
use crate::texts::scale_words;

/// Degradation category rating.
pub(super) struct Dcr;

impl Method for Dcr {
    fn protocol(&self) -> Protocol {
        Protocol::Dcr
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
            words: scale_words(study),
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

    /// P.910 DCR: the reference, then the test (or both at once, side by side).
    fn arrangements(&self) -> &'static [(&'static str, Arrangement)] {
        &[
            ("sequential", Arrangement::Sequential),
            ("side_by_side", Arrangement::SideBySide),
        ]
    }

    fn reference_rule(&self) -> ReferenceRule {
        ReferenceRule::ShownFirst
    }

    /// P.910 DCR: five impairment categories, 5 (imperceptible) to 1 (very annoying).
    fn check_scale(
        &self,
        kind: ScaleKind,
        min: f64,
        max: f64,
        step: Option<f64>,
    ) -> Option<String> {
        only_categories(
            (kind, min, max, step),
            1.0,
            5.0,
            "DCR rates five impairment categories",
        )
    }

    fn grade_words(&self) -> &'static [&'static str] {
        &crate::texts::IMPAIRMENT_LABELS
    }

    fn gold_trials(&self) -> bool {
        true
    }
}
