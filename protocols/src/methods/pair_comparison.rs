//! Pair comparison (ITU-T P.910 PC): two versions of the same motion, the better one chosen
//! (or, with `[presentation] no_preference`, neither: a tie); Bradley-Terry scale values in
//! the analysis, Davidson's model where there are ties.

use std::fmt::{self, Write as _};

use super::common::{
    choice, describe_reference, original_among_versions, presentation_time, scored,
};
use super::{AnswerKind, AnswerWidget, ChoiceOption, Method, ReferenceRule, Refusal, Sections};
use crate::engine::{PlanItem, plan_trials};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Arrangement, Outcome, Position, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{Condition, RatingScale, ReferencePlacement, StudyDefinition};
use crate::texts::{PC_QUESTION, Planned};

/// The key of the "No preference" button.
const NO_PREFERENCE_KEY: &str = "N";

/// The simulated observer's indifference band, in units of its noise SD: a perceived quality
/// difference below it is answered "no preference" where the screen offers that.
const INDIFFERENCE: f64 = 0.5;

/// Pair comparison of the study's conditions.
pub(super) struct PairComparison;

impl Method for PairComparison {
    fn protocol(&self) -> Protocol {
        Protocol::PairComparison
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Choice
    }

    /// The two positions' buttons, and "No preference" (key N) between them where the study
    /// offers it.
    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        let mut options = ChoiceOption::positions(study.presentation.arrangement);
        if study.presentation.no_preference {
            options.insert(
                1,
                ChoiceOption {
                    label: "No preference".to_owned(),
                    key: NO_PREFERENCE_KEY.to_owned(),
                    answer: Position::Neither,
                },
            );
        }
        AnswerWidget::Choice {
            question: PC_QUESTION.to_string(),
            options,
        }
    }

    fn offers_no_preference(&self) -> bool {
        true
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
        let answer = if study.presentation.no_preference {
            "If neither looks better to you, answer \"No preference\" with the N key."
        } else {
            "Answer even when you are unsure."
        };
        format!(
            "Each trial shows two versions of the same motion {shows}. {original} Choose the one \
             that looks better with {keys} (or click). {answer}"
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

    fn ordered_item_name(&self) -> &'static str {
        "pairs (every pair of a clip's conditions)"
    }

    fn ordered_items(&self, conditions: &[Condition]) -> usize {
        crate::study::pair_count(conditions)
    }

    fn describe_reference(&self, placement: ReferencePlacement) -> String {
        describe_reference(placement, "per pair")
    }

    /// Each pair of the study's pairs a trial ([`crate::engine::plan_trials`]), no
    /// familiarization.
    fn plan(&self, study: &StudyDefinition, subject: u32) -> Vec<Trial> {
        let pairs: Vec<PlanItem> = study
            .pairs()
            .into_iter()
            .filter_map(|(i, j)| {
                Some(PlanItem::pair(
                    study.conditions.get(i)?,
                    study.conditions.get(j)?,
                ))
            })
            .collect();
        plan_trials(
            study,
            &[],
            &pairs,
            subject,
            study.presentation.arrangement,
            study.presentation.reference_position,
        )
    }

    /// The `reference` column holds the pair's other test stimulus, shown at the reference
    /// position: picking the other position prefers `stimulus` (score 1), picking the reference
    /// position the other (0); no preference scores 1/2 (the engine takes it only where the
    /// screen offered it).
    fn score(
        &self,
        trial: &Trial,
        answer: Answer,
        _scale: &RatingScale,
    ) -> Result<Outcome, Refusal> {
        if answer == Answer::Choice(Position::Neither) {
            return Ok(scored(0.5));
        }
        let preferred_stimulus = choice(trial, answer)? != trial.reference_position;
        Ok(scored(if preferred_stimulus { 1.0 } else { 0.0 }))
    }

    /// A Thurstone case V observer: each stimulus' latent quality plus its own normal noise
    /// (`noise_sd` σ), the better-looking one picked; the subject's bias shifts both alike and
    /// cancels. P(stimulus preferred) = Φ((q_s - q_r) / (σ√2)). Where the screen offers no
    /// preference, a perceived difference below σ/2 is answered with it (an indifference
    /// band: P(tie) = Φ((σ/2 - Δ) / (σ√2)) - Φ((-σ/2 - Δ) / (σ√2)), Δ = q_s - q_r).
    fn simulate(
        &self,
        observer: &Observer,
        trial: &Trial,
        test_error: &dyn Fn() -> Result<f64, ObserverError>,
        rng: &mut StudyRng,
    ) -> Result<Answer, ObserverError> {
        let q = |e: f64, rng: &mut StudyRng| {
            observer.quality_of_error(e) + observer.noise_sd() * rng.normal()
        };
        let qs = q(test_error()?, rng);
        let qr = q(observer.manifest_error(&trial.reference)?, rng);
        if observer.study().presentation.no_preference
            && (qs - qr).abs() < INDIFFERENCE * observer.noise_sd()
        {
            return Ok(Answer::Choice(Position::Neither));
        }
        Ok(Answer::Choice(if qs > qr {
            trial.reference_position.other()
        } else {
            trial.reference_position
        }))
    }

    /// A pair comparison places each pair's two test stimuli; a fixed side would put one
    /// condition of every pair on one side and confound the side with the condition.
    fn reference_rule(&self) -> ReferenceRule {
        ReferenceRule::NotFixed {
            why: "a pair comparison places each pair's two motions by \"random\" (the default) \
                  or \"balanced\" (each subject sees each condition of a pair on each side \
                  equally often), never on a fixed side",
        }
    }

    fn labels_hidden(&self) -> Option<&'static str> {
        Some("a pair comparison shows two test motions and no labelled reference (ITU-T P.910)")
    }

    /// An original among the versions anchors each clip's scale.
    fn hidden_references(&self) -> bool {
        true
    }

    fn sections(&self) -> Sections {
        Sections::Pairs
    }

    fn distinct_answers(&self, trial: &Trial, _scale: &RatingScale) -> Vec<Answer> {
        // The plan does not depend on which stimulus was preferred.
        vec![Answer::Choice(trial.reference_position)]
    }
}
