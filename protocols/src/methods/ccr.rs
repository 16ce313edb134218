//! CCR (ITU-T P.910 comparison category rating, P.800 Annex E): the original and a
//! compressed version of a motion, in either order and not labelled, the second rated
//! against the first from "Much better" (+3) to "Much worse" (-3). The analysis folds the
//! order (a rating with the compressed version first counts negated) and reports the order
//! effect.

use super::common::{only_categories, original_among_versions, practice_sentence};
use super::{AnswerWidget, Method, ReferenceRule};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Position, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{ScaleKind, StudyDefinition};
use crate::texts::scale_words;

/// The seven categories of P.910's comparison scale, best first (+3 … -3).
const COMPARISON_WORDS: [&str; 7] = [
    "Much better",
    "Better",
    "Slightly better",
    "About the same",
    "Slightly worse",
    "Worse",
    "Much worse",
];

/// Comparison category rating.
pub(super) struct Ccr;

/// The two versions' names as the arrangement shows them: (first, second).
fn order_words(arrangement: Arrangement) -> (&'static str, &'static str) {
    if arrangement == Arrangement::SideBySide {
        ("left", "right")
    } else {
        ("first", "second")
    }
}

impl Method for Ccr {
    fn protocol(&self) -> Protocol {
        Protocol::Ccr
    }

    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        let (first, second) = order_words(study.presentation.arrangement);
        AnswerWidget::Rating {
            question: format!("How does the {second} motion compare with the {first}?"),
            missing: "the comparison".to_string(),
            name: "Comparison".to_string(),
            words: scale_words(study),
        }
    }

    fn instructions(&self, study: &StudyDefinition) -> String {
        let arrangement = study.presentation.arrangement;
        let (first, second) = order_words(arrangement);
        let how = if arrangement == Arrangement::SideBySide {
            "side by side"
        } else {
            "one after the other"
        };
        let same = if original_among_versions(study) {
            " Sometimes both are the original."
        } else {
            ""
        };
        format!(
            "Each trial shows two versions of the same motion {how}: the original and a \
             compressed version, in either order; you are not told which is which.{same} Rate \
             how the {second} compares with the {first}, from “Much better” to “Much worse”, \
             with the mouse or the Up and Down arrow keys, then press Continue (Enter).{}",
            practice_sentence(study, "differences")
        )
    }

    /// P.910 CCR: one after the other (side by side where the study asks).
    fn arrangements(&self) -> &'static [(&'static str, Arrangement)] {
        &[
            ("sequential", Arrangement::Sequential),
            ("side_by_side", Arrangement::SideBySide),
        ]
    }

    /// Both orders, so that the order effect is measured and folded out.
    fn reference_rule(&self) -> ReferenceRule {
        ReferenceRule::NotFixed {
            why: "CCR shows the original first in some trials and second in the others \
                  (P.910), so that the order effect is measured and folded out: give \
                  \"random\" (the default) or \"balanced\" (each subject sees each condition \
                  in both orders equally often)",
        }
    }

    fn labels_hidden(&self) -> Option<&'static str> {
        Some("CCR does not tell which version is the original (P.910): it comes in either order")
    }

    /// A reference compared with itself checks the scale's middle ("About the same").
    fn hidden_references(&self) -> bool {
        true
    }

    fn hidden_reference_use(&self) -> &'static str {
        "the original against itself: its CMOS should be about 0"
    }

    /// -3 … +3.
    fn default_scale_range(&self, kind: ScaleKind) -> (f64, f64) {
        match kind {
            ScaleKind::Categorical => (-3.0, 3.0),
            ScaleKind::Continuous => (-100.0, 100.0),
        }
    }

    /// P.910 CCR: seven categories, -3 (much worse) to +3 (much better).
    fn check_scale(
        &self,
        kind: ScaleKind,
        min: f64,
        max: f64,
        step: Option<f64>,
    ) -> Option<String> {
        only_categories(
            (kind, min, max, step),
            -3.0,
            3.0,
            "CCR rates seven comparison categories",
        )
    }

    fn grade_words(&self) -> &'static [&'static str] {
        &COMPARISON_WORDS
    }

    /// The second version against the first: the difference of the two latent qualities
    /// (the study's scale being -3 … +3, a version's quality runs from -3 to +3 with its
    /// error), the test's minus the reference's when the reference came first and the
    /// reverse when it came second, plus the subject's constant bias (a leaning towards the
    /// second version, which the folded analysis sees as an order effect) and the
    /// judgement's normal noise, snapped to the seven categories.
    fn simulate(
        &self,
        observer: &Observer,
        trial: &Trial,
        test_error: &dyn Fn() -> Result<f64, ObserverError>,
        rng: &mut StudyRng,
    ) -> Result<Answer, ObserverError> {
        let test = observer.quality_of_error(test_error()?);
        let reference = observer.quality_of_error(observer.manifest_error(&trial.reference)?);
        let reference_first = matches!(trial.reference_position, Position::First | Position::Left);
        let second_against_first = if reference_first {
            test - reference
        } else {
            reference - test
        };
        let r = second_against_first + observer.bias() + observer.noise_sd() * rng.normal();
        Ok(Answer::Rating(observer.study().scale.snap(r)))
    }
}
