//! DCR (ITU-T P.910, BT.500 DSIS): the original, then (or beside) a compressed version,
//! the impairment rated on the five categories.

use std::fmt;

use super::common::{describe_ratings, practice_sentence, rating_trials};
use super::common::{score_rating, simulate_rating};
use super::{AnswerKind, AnswerWidget, Method, ReferenceRule, Refusal};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Outcome, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{RatingScale, ScaleKind, ScaleWords, StudyDefinition};
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
        let five_categories = kind == ScaleKind::Categorical
            && [(min, 1.0), (max, 5.0), (step.unwrap_or(0.0), 1.0)]
                .iter()
                .all(|(v, want)| (v - want).abs() < 1e-12);
        (!five_categories).then(|| {
            format!(
                "DCR rates five impairment categories (P.910): use kind = \"categorical\", min = \
                 1, max = 5, step = 1 (or omit [scale]), not {} {min}..{max} step {step:?}",
                if kind == ScaleKind::Categorical {
                    "categorical"
                } else {
                    "continuous"
                }
            )
        })
    }

    fn scale_words(&self) -> ScaleWords {
        ScaleWords::Impairment
    }

    fn gold_trials(&self) -> bool {
        true
    }

    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Rating(scale.min)]
    }
}
