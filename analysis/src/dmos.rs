//! Differential scores: DSCQS difference scores (BT.500; thesis §6.4.1), the ACR-HR differential
//! viewer score of ITU-T P.910, and per-subject z-scoring.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::Serialize;

use crate::confidence::Confidence;
use crate::descriptive::{ConditionStats, Rating, mean_of, sample_variance, summarize};
use crate::error::AnalysisError;
use crate::panel::check_scores;

/// One DSCQS presentation: a subject scored the hidden reference and the test version of a
/// condition.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DscqsPair {
    /// Subject id.
    pub subject: u32,
    /// Condition id of the test (compressed) version.
    pub condition: u32,
    /// Score given to the reference.
    pub reference_score: f64,
    /// Score given to the test version.
    pub test_score: f64,
}

/// DMOS per condition from DSCQS pairs: each subject's difference (reference − test) is averaged
/// over that subject's presentations of the condition, then summarised across subjects
/// ("the average value of this difference would be the DSCQS value", thesis §6.4.1).
///
/// # Errors
/// [`AnalysisError::NonFinite`] for NaN or infinite scores.
pub fn dscqs_dmos(
    pairs: &[DscqsPair],
    confidence: Confidence,
) -> Result<Vec<ConditionStats>, AnalysisError> {
    let mut per: BTreeMap<(u32, u32), (f64, usize)> = BTreeMap::new();
    for (index, p) in pairs.iter().enumerate() {
        let d = p.reference_score - p.test_score;
        if !d.is_finite() {
            return Err(AnalysisError::NonFinite {
                what: "DSCQS score",
                index,
                value: d,
            });
        }
        let e = per.entry((p.condition, p.subject)).or_insert((0.0, 0));
        e.0 += d;
        e.1 += 1;
    }
    summarize_subject_means(
        per.into_iter().map(|((c, _), (s, k))| (c, s / k as f64)),
        confidence,
    )
}

fn summarize_subject_means(
    values: impl Iterator<Item = (u32, f64)>,
    confidence: Confidence,
) -> Result<Vec<ConditionStats>, AnalysisError> {
    let mut groups: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for (c, v) in values {
        groups.entry(c).or_default().push(v);
    }
    groups
        .into_iter()
        .map(|(condition, v)| {
            Ok(ConditionStats {
                condition,
                summary: summarize(&v, confidence)?,
            })
        })
        .collect()
}

/// ACR-HR differential MOS (ITU-T P.910, hidden reference removal): for every rating of a test
/// condition, DV = V(test) − V(reference) + 5, where V(reference) is the same subject's score of
/// the hidden reference of that condition (averaged if the subject rated it more than once).
/// A subject's DVs of a condition (hidden repeats) are averaged first, then the subjects'
/// means summarised per condition (as the MOS and the DSCQS DMOS are: one value per subject).
///
/// `reference_of` maps test condition ids to the id of their hidden reference; ratings of
/// conditions not in the map (the references themselves) are skipped. P.910 notes that DV above
/// 5 is possible (a test version rated above its reference); it is kept, not clipped, so the
/// mean stays unbiased.
///
/// # Errors
/// [`AnalysisError::MissingReference`] when a subject rated a test condition but never its
/// reference; [`AnalysisError::NonFinite`] for bad scores.
pub fn acr_hr_dmos<S: std::hash::BuildHasher>(
    ratings: &[Rating],
    reference_of: &HashMap<u32, u32, S>,
    confidence: Confidence,
) -> Result<Vec<ConditionStats>, AnalysisError> {
    let references: std::collections::HashSet<u32> = reference_of.values().copied().collect();
    let mut ref_scores: HashMap<(u32, u32), (f64, usize)> = HashMap::new();
    check_scores(ratings)?;
    for r in ratings {
        if references.contains(&r.condition) {
            let e = ref_scores
                .entry((r.subject, r.condition))
                .or_insert((0.0, 0));
            e.0 += r.score;
            e.1 += 1;
        }
    }
    let mut per: BTreeMap<(u32, u32), (f64, usize)> = BTreeMap::new();
    for r in ratings {
        let Some(&reference) = reference_of.get(&r.condition) else {
            continue;
        };
        let Some(&(sum, k)) = ref_scores.get(&(r.subject, reference)) else {
            return Err(AnalysisError::MissingReference {
                subject: r.subject,
                condition: r.condition,
                reference,
            });
        };
        let e = per.entry((r.condition, r.subject)).or_insert((0.0, 0));
        e.0 += r.score - sum / k as f64 + 5.0;
        e.1 += 1;
    }
    summarize_subject_means(
        per.into_iter().map(|((c, _), (s, k))| (c, s / k as f64)),
        confidence,
    )
}

/// Replaces each score by its per-subject z-score, (x − mean_s)/SD_s with the sample SD
/// (divisor n − 1), removing each subject's offset and scale use (BT.500 Annex 2 §2.2 notes).
///
/// # Errors
/// [`AnalysisError::UndefinedZScore`] when a subject has fewer than two ratings or gives every
/// stimulus the same score; [`AnalysisError::NonFinite`] for bad scores.
pub fn zscore_by_subject(ratings: &[Rating]) -> Result<Vec<Rating>, AnalysisError> {
    let params = zscore_params(ratings)?;
    if let Some((&subject, _)) = params.iter().find(|(_, p)| p.is_none()) {
        return Err(AnalysisError::UndefinedZScore { subject });
    }
    Ok(apply_zscores(ratings, &params))
}

/// As [`zscore_by_subject`], but a subject without a z-score (fewer than two ratings, or the
/// same score for everything) is left out instead of refusing the whole set; returns the
/// z-scores of the others and who was left out.
///
/// # Errors
/// [`AnalysisError::NonFinite`] for bad scores.
pub fn zscore_screened(ratings: &[Rating]) -> Result<(Vec<Rating>, BTreeSet<u32>), AnalysisError> {
    let params = zscore_params(ratings)?;
    let excluded: BTreeSet<u32> = params
        .iter()
        .filter(|(_, p)| p.is_none())
        .map(|(&s, _)| s)
        .collect();
    Ok((apply_zscores(ratings, &params), excluded))
}

/// Each subject's (mean, SD), `None` where the z-score is undefined.
fn zscore_params(ratings: &[Rating]) -> Result<HashMap<u32, Option<(f64, f64)>>, AnalysisError> {
    check_scores(ratings)?;
    let mut by_subject: HashMap<u32, Vec<f64>> = HashMap::new();
    for r in ratings {
        by_subject.entry(r.subject).or_default().push(r.score);
    }
    Ok(by_subject
        .into_iter()
        .map(|(subject, scores)| {
            let m = mean_of(&scores);
            let sd = if scores.len() < 2 {
                f64::NAN
            } else {
                sample_variance(&scores, m).max(0.0).sqrt()
            };
            (subject, (sd.is_finite() && sd > 0.0).then_some((m, sd)))
        })
        .collect())
}

/// The z-scores of the subjects that have parameters; the others' ratings are dropped.
fn apply_zscores(ratings: &[Rating], params: &HashMap<u32, Option<(f64, f64)>>) -> Vec<Rating> {
    ratings
        .iter()
        .filter_map(|r| {
            let (m, sd) = params.get(&r.subject).copied().flatten()?;
            Some(Rating {
                score: (r.score - m) / sd,
                ..*r
            })
        })
        .collect()
}
