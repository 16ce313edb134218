//! Pair comparison (ITU-T P.910 PC): two versions of the same motion, the better one chosen;
//! Bradley-Terry scale values in the analysis.

use std::fmt::{self, Write as _};

use super::common::{describe_reference, original_among_versions, presentation_time};
use super::{AnswerKind, AnswerWidget, Method};
use crate::record::{Answer, Arrangement, Protocol, Trial};
use crate::study::{RatingScale, ReferencePlacement, StudyDefinition};
use crate::texts::{PC_QUESTION, Planned};

/// Pair comparison of the study's conditions.
pub(super) struct PairComparison;

impl Method for PairComparison {
    fn protocol(&self) -> Protocol {
        Protocol::PairComparison
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Choice
    }

    fn answer_widget(&self, _study: &StudyDefinition) -> AnswerWidget {
        AnswerWidget::Choice {
            question: PC_QUESTION.to_string(),
        }
    }

    fn instructions(&self, study: &StudyDefinition) -> String {
        let (shows, keys) = if study.presentation.arrangement == Arrangement::Sequential {
            (
                "one after the other, with a grey screen between them",
                "the 1 or 2 key",
            )
        } else {
            ("side by side", "the Left or Right arrow key")
        };
        // The original itself is one of the versions compared (hidden references).
        let original = if original_among_versions(study) {
            "Either of them may be the original motion itself; you are not told which."
        } else {
            "Neither is the original."
        };
        format!(
            "Each trial shows two versions of the same motion {shows}. {original} Choose the one \
             that looks better with {keys} (or click). Answer even when you are unsure."
        )
    }

    fn planned_trials(&self, study: &StudyDefinition) -> Planned {
        Planned::Exactly((study.pairs().len() + study.session.hidden_repeats as usize) as u32)
    }

    fn describe(&self, study: &StudyDefinition, text: &mut String) -> fmt::Result {
        let pairs = study.pairs().len();
        let n = pairs + study.session.hidden_repeats as usize;
        writeln!(
            text,
            "  trials per session: {n} ({pairs} pairs of {} conditions, {} hidden repeats with \
             the sides swapped)",
            study.conditions.len(),
            study.session.hidden_repeats
        )?;
        let anchors = study
            .conditions
            .iter()
            .filter(|c| c.stimulus == c.reference)
            .count();
        if anchors > 0 {
            writeln!(
                text,
                "  originals compared: {anchors} (unlabelled; each clip's scale is anchored at \
                 its original)"
            )?;
        }
        presentation_time(text, study, n)
    }

    fn ordered_items(&self, study: &StudyDefinition) -> usize {
        study.pairs().len()
    }

    fn describe_reference(&self, placement: ReferencePlacement) -> String {
        describe_reference(placement, "per pair")
    }

    fn distinct_answers(&self, trial: &Trial, _scale: &RatingScale) -> Vec<Answer> {
        // The plan does not depend on which stimulus was preferred.
        vec![Answer::Choice(trial.reference_position)]
    }
}
