//! DSCQS (ITU-R BT.500; thesis 6.5 shows the two one after the other): two motions, one of
//! them possibly the original, both rated; the score is reference minus test.

use super::common::{on_scale, scale_instructions};
use super::{AnswerKind, AnswerWidget, Method, Refusal};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Outcome, Position, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{RatingScale, ReferencePlacement, ScaleKind, StudyDefinition};
use crate::texts::{dscqs_names, scale_words};

/// Double-stimulus continuous quality scale.
pub(super) struct Dscqs;

impl Method for Dscqs {
    fn protocol(&self) -> Protocol {
        Protocol::Dscqs
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::RatingPair
    }

    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        let [a, b] = dscqs_names(study.presentation.arrangement);
        AnswerWidget::RatingPair {
            question: format!("Rate the quality of {a} and of {b}"),
            names: [a.to_owned(), b.to_owned()],
            words: scale_words(study),
        }
    }

    fn instructions(&self, study: &StudyDefinition) -> String {
        let p = &study.presentation;
        let [a, b] = dscqs_names(p.arrangement);
        let keys = if study.scale.kind == ScaleKind::Continuous {
            format!(
                " The number keys mark {a} first, then {b}; the Left and Right arrow keys \
                 choose which scale the keys move."
            )
        } else {
            format!(
                " The number keys rate {a} first, then {b}; the Left and Right arrow keys \
                 choose which row the keys change."
            )
        };
        let shows = if p.arrangement == Arrangement::Sequential {
            let which = match p.reference_position {
                ReferencePlacement::Fixed(Position::First) => {
                    "The first is the original, the second a compressed version of it."
                }
                ReferencePlacement::Fixed(_) => {
                    "The second is the original, the first a compressed version of it."
                }
                ReferencePlacement::Random | ReferencePlacement::Balanced => {
                    "One of them may be the original; you are not told which."
                }
            };
            format!(
                "Each trial shows two motions one after the other, {a} then {b}, with a grey \
                 screen between them. {which} Then rate both."
            )
        } else {
            "Each trial shows two motions, A and B, twice, with a grey screen between them: \
             A, B, A, B. One of them may be the original; you are not told which. After the \
             second B, rate both."
                .to_string()
        };
        format!(
            "{shows} {}{keys}",
            scale_instructions(&study.scale, &format!("the quality of {a} and of {b}"))
        )
    }

    /// BT.500 DSCQS: the difference reference minus test is the trial's score.
    fn score(
        &self,
        trial: &Trial,
        answer: Answer,
        scale: &RatingScale,
    ) -> Result<Outcome, Refusal> {
        let Answer::Pair { a, b } = answer else {
            return Err(Refusal::Expected("ratings of both stimuli"));
        };
        let (a, b) = (on_scale(a, scale)?, on_scale(b, scale)?);
        // `a` rates what was shown first: slot A, or the first interval.
        let (r, t) = if matches!(trial.reference_position, Position::A | Position::First) {
            (a, b)
        } else {
            (b, a)
        };
        Ok(Outcome {
            score: r - t,
            score_reference: Some(r),
            score_test: Some(t),
            correct: None,
            reversal: None,
        })
    }

    /// Both stimuli rated, each on its own latent quality.
    fn simulate(
        &self,
        observer: &Observer,
        trial: &Trial,
        test_error: &dyn Fn() -> Result<f64, ObserverError>,
        rng: &mut StudyRng,
    ) -> Result<Answer, ObserverError> {
        let r = observer.rate(observer.manifest_error(&trial.reference)?, rng);
        let t = observer.rate(test_error()?, rng);
        Ok(
            if matches!(trial.reference_position, Position::A | Position::First) {
                Answer::Pair { a: r, b: t }
            } else {
                Answer::Pair { a: t, b: r }
            },
        )
    }

    /// BT.500's A B A B, or thesis 6.5's reference then test, once each.
    fn arrangements(&self) -> &'static [(&'static str, Arrangement)] {
        &[
            ("abab", Arrangement::Abab),
            ("sequential", Arrangement::Sequential),
        ]
    }

    fn labels_hidden(&self) -> Option<&'static str> {
        Some("DSCQS does not tell the subject which of A and B is the reference (ITU-R BT.500)")
    }

    fn default_scale_kind(&self) -> ScaleKind {
        ScaleKind::Continuous
    }

    fn gold_trials(&self) -> bool {
        true
    }

    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Pair {
            a: scale.min,
            b: scale.min,
        }]
    }
}
