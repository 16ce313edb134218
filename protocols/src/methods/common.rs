//! What several methods share: the words of a rating scale in the instructions, the
//! practice sentence, the rating methods' `study check` lines.

use std::fmt::{self, Write as _};

use super::Refusal;
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Outcome, Position, Trial};
use crate::rng::StudyRng;
use crate::study::{RatingScale, ReferencePlacement, ScaleKind, StudyDefinition};
use crate::texts::{Planned, format_rating};

/// How the rating is given, for the instructions.
pub(super) fn scale_instructions(scale: &RatingScale, what: &str) -> String {
    match scale.kind {
        ScaleKind::Categorical => format!(
            "Rate {what} from {} (worst) to {} (best), with the mouse or the number keys \
             (the Up and Down arrow keys move by one step), then press Continue (Enter).",
            format_rating(scale.min),
            format_rating(scale.max)
        ),
        ScaleKind::Continuous => format!(
            "Rate {what} by placing a mark on the scale, from Bad at the bottom to Excellent at \
             the top: click or drag, or press 1 (Bad) to 5 (Excellent) and move the mark with \
             the Up and Down arrow keys (Page Up and Page Down for larger steps). Then press \
             Continue (Enter)."
        ),
    }
}

/// " The first few trials show the range of {what} you will meet." where the session opens
/// with familiarization trials (`[session] familiarization`), else nothing: the
/// instructions promise no practice a study does not give.
pub(super) fn practice_sentence(study: &StudyDefinition, what: &str) -> String {
    if study.familiarization.is_empty() {
        String::new()
    } else {
        format!(" The first few trials show the range of {what} you will meet.")
    }
}

/// Whether the original itself is among the versions a subject compares or rates unlabelled
/// (`[conditions] hidden_reference`: a condition whose stimulus is its reference).
pub(super) fn original_among_versions(study: &StudyDefinition) -> bool {
    study.conditions.iter().any(|c| c.stimulus == c.reference)
}

/// The trials of a rating method's session: familiarization, conditions, hidden repeats.
pub(super) fn rating_trials(study: &StudyDefinition) -> Planned {
    Planned::Exactly(
        (study.familiarization.len()
            + study.conditions.len()
            + study.session.hidden_repeats as usize) as u32,
    )
}

/// The trials of a session of between-subject group `group`.
pub(crate) fn group_trials(study: &StudyDefinition, group: &str) -> Option<u32> {
    let of_group = study.for_group(Some(group)).ok()?;
    of_group.method().planned_trials(&of_group).exact()
}

/// Where the reference goes; a balanced placement balances `per` ("per condition").
pub(super) fn describe_reference(placement: ReferencePlacement, per: &str) -> String {
    match placement {
        ReferencePlacement::Fixed(p) => format!("always {p}"),
        ReferencePlacement::Random => "random per trial".to_string(),
        ReferencePlacement::Balanced => format!("balanced ({per}, mirrored for the next subject)"),
    }
}

/// A rating method's (MOS, DSCQS, ACR, DCR) trials and presentation time.
pub(super) fn describe_ratings(text: &mut String, study: &StudyDefinition) -> fmt::Result {
    let n = study.familiarization.len()
        + study.conditions.len()
        + study.session.hidden_repeats as usize;
    if study.design.groups.is_empty() {
        writeln!(
            text,
            "  trials per session: {n} ({} familiarization, {} conditions, {} hidden repeats)",
            study.familiarization.len(),
            study.conditions.len(),
            study.session.hidden_repeats
        )?;
    } else {
        writeln!(
            text,
            "  conditions: {} in {} between-subject groups (each session sees its group's; \
             {} familiarization, {} hidden repeats)",
            study.conditions.len(),
            study.design.groups.len(),
            study.familiarization.len(),
            study.session.hidden_repeats
        )?;
    }
    let hidden = study
        .conditions
        .iter()
        .filter(|c| c.stimulus == c.reference)
        .count();
    if hidden > 0 {
        writeln!(
            text,
            "  hidden references: {hidden} ({})",
            study.method().hidden_reference_use()
        )?;
    }
    // A session of a between-subject group shows its group's trials: the largest group's.
    let n = if study.design.groups.is_empty() {
        n
    } else {
        study
            .design
            .groups
            .iter()
            .filter_map(|g| group_trials(study, &g.name))
            .max()
            .map_or(n, |t| t as usize)
    };
    presentation_time(text, study, n)
}

/// "presentation time: … min without answers" for `shown` trials (or screens).
pub(super) fn presentation_time(
    text: &mut String,
    study: &StudyDefinition,
    shown: usize,
) -> fmt::Result {
    let est_min = shown as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
    writeln!(
        text,
        "  presentation time: {est_min:.1} min without answers"
    )
}

/// `v` if the study's scale takes it.
pub(super) fn on_scale(v: f64, scale: &RatingScale) -> Result<f64, Refusal> {
    if scale.accepts(v) {
        Ok(v)
    } else {
        Err(Refusal::OffScale(v))
    }
}

/// A one-rating method's outcome: the rating is the score.
pub(super) fn score_rating(answer: Answer, scale: &RatingScale) -> Result<Outcome, Refusal> {
    let Answer::Rating(v) = answer else {
        return Err(Refusal::Expected("a rating"));
    };
    Ok(scored(on_scale(v, scale)?))
}

/// An outcome that is a score and nothing else.
pub(super) fn scored(score: f64) -> Outcome {
    Outcome {
        score,
        score_reference: None,
        score_test: None,
        correct: None,
        reversal: None,
    }
}

/// The position a forced choice picked, if it is one of the trial's arrangement.
pub(super) fn choice(trial: &Trial, answer: Answer) -> Result<Position, Refusal> {
    match answer {
        Answer::Choice(p) if p.fits(trial.arrangement) => Ok(p),
        _ => Err(Refusal::Expected(
            "a choice of a position of this arrangement",
        )),
    }
}

/// A one-rating method's simulated answer: the test stimulus rated on its own (a hidden
/// reference's error is 0, a MUSHRA anchor's the largest).
pub(super) fn simulate_rating(
    observer: &Observer,
    test_error: &dyn Fn() -> Result<f64, ObserverError>,
    rng: &mut StudyRng,
) -> Result<Answer, ObserverError> {
    Ok(Answer::Rating(observer.rate(test_error()?, rng)))
}

/// The check of a method that rates on one categorical scale only, `lowest..=highest` in
/// whole steps (`rates`: "DCR rates five impairment categories"): `None` for that scale,
/// else the refusal naming it.
pub(super) fn only_categories(
    scale: (ScaleKind, f64, f64, Option<f64>),
    lowest: f64,
    highest: f64,
    rates: &str,
) -> Option<String> {
    let (kind, min, max, step) = scale;
    let fits = kind == ScaleKind::Categorical
        && [(min, lowest), (max, highest), (step.unwrap_or(0.0), 1.0)]
            .iter()
            .all(|(v, want)| (v - want).abs() < 1e-12);
    (!fits).then(|| {
        format!(
            "{rates} (P.910): use kind = \"categorical\", min = {lowest}, max = {highest}, step \
             = 1 (or omit [scale]), not {} {min}..{max} step {step:?}",
            if kind == ScaleKind::Categorical {
                "categorical"
            } else {
                "continuous"
            }
        )
    })
}
