//! Observer screening of ITU-R BT.500 Annex 2 §2.3.1 and hidden-repeat consistency.

use std::collections::BTreeSet;

use crate::panel::Panel;

use serde::Serialize;

use crate::descriptive::Rating;
use crate::error::AnalysisError;

/// Moments of one presentation (condition × repetition) across observers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PresentationMoments {
    /// Condition id.
    pub condition: u32,
    /// Repetition index (0 for the first showing of the condition to a subject).
    pub repetition: u32,
    /// Observers who rated it.
    pub n: usize,
    /// Mean score ū.
    pub mean: f64,
    /// Sample SD S (divisor N − 1).
    pub sd: f64,
    /// Kurtosis β2 = m4 / m2² with moments about the mean, divisor N; `None` when m2 = 0.
    pub beta2: Option<f64>,
    /// Whether the distribution counts as normal (2 ≤ β2 ≤ 4): then the ±2S band applies,
    /// otherwise ±√20·S.
    pub normal: bool,
}

/// One observer's screening counts and decision.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ObserverScreening {
    /// Subject id.
    pub subject: u32,
    /// P: scores at or above the upper band.
    pub p: usize,
    /// Q: scores at or below the lower band.
    pub q: usize,
    /// J·K·R: presentations this observer rated.
    pub presentations: usize,
    /// (P + Q) / (J·K·R).
    pub outlier_fraction: f64,
    /// |P − Q| / (P + Q); `None` when P + Q = 0.
    pub asymmetry: Option<f64>,
    /// Rejected: outlier fraction > 0.05 and asymmetry < 0.3.
    pub rejected: bool,
}

/// The screening of a whole panel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScreeningReport {
    /// Per presentation moments.
    pub presentations: Vec<PresentationMoments>,
    /// Per observer, sorted by subject id.
    pub observers: Vec<ObserverScreening>,
}

impl ScreeningReport {
    /// Ids of the rejected observers.
    pub fn rejected(&self) -> BTreeSet<u32> {
        self.observers
            .iter()
            .filter(|o| o.rejected)
            .map(|o| o.subject)
            .collect()
    }
}

/// BT.500 Annex 2 §2.3.1 screening. A presentation is a (condition, repetition) pair, the
/// repetition being the order in which a subject met the condition (hidden repeats get index
/// 1, 2, …). Presentations rated by fewer than two observers are skipped (no S).
///
/// # Errors
/// [`AnalysisError::NonFinite`] for NaN or infinite scores.
pub fn bt500_screening(ratings: &[Rating]) -> Result<ScreeningReport, AnalysisError> {
    Ok(screening_of_panel(ratings, &Panel::new(ratings)?))
}

/// [`bt500_screening`] over an already built index.
pub(crate) fn screening_of_panel(ratings: &[Rating], panel: &Panel) -> ScreeningReport {
    // Presentation g = condition index × R + repetition; three linear passes: sums, central
    // moments, then P / Q per observer.
    let reps = panel.reps.max(1) as usize;
    let groups = panel.conditions.len() * reps;
    let group = |i: usize| panel.c[i] as usize * reps + panel.rep[i] as usize;
    let mut n = vec![0usize; groups];
    let mut sum = vec![0.0; groups];
    for (i, r) in ratings.iter().enumerate() {
        n[group(i)] += 1;
        sum[group(i)] += r.score;
    }
    let mean: Vec<f64> = sum
        .iter()
        .zip(&n)
        .map(|(s, &k)| if k > 0 { s / k as f64 } else { 0.0 })
        .collect();
    let mut m2 = vec![0.0; groups];
    let mut m4 = vec![0.0; groups];
    for (i, r) in ratings.iter().enumerate() {
        let g = group(i);
        let d2 = (r.score - mean[g]) * (r.score - mean[g]);
        m2[g] += d2;
        m4[g] += d2 * d2;
    }
    let mut presentations = Vec::new();
    // (lower, upper) band per presentation; None when it has fewer than two observers or S = 0.
    let mut band: Vec<Option<(f64, f64)>> = vec![None; groups];
    for g in 0..groups {
        if n[g] < 2 {
            continue;
        }
        let nf = n[g] as f64;
        let sd = (m2[g] / (nf - 1.0)).sqrt();
        let (c2, c4) = (m2[g] / nf, m4[g] / nf);
        let beta2 = (c2 > 0.0).then(|| c4 / (c2 * c2));
        // With no spread nobody lies outside any band; treat as normal (bands of width 0 would
        // flag everyone, which the standard does not intend).
        let normal = beta2.is_none_or(|b| (2.0..=4.0).contains(&b));
        let width = if normal { 2.0 * sd } else { 20f64.sqrt() * sd };
        if sd > 0.0 {
            band[g] = Some((mean[g] - width, mean[g] + width));
        }
        presentations.push(PresentationMoments {
            condition: panel.conditions[g / reps],
            repetition: (g % reps) as u32,
            n: n[g],
            mean: mean[g],
            sd,
            beta2,
            normal,
        });
    }
    let subjects = panel.subjects.len();
    let (mut p, mut q, mut count) = (
        vec![0usize; subjects],
        vec![0usize; subjects],
        vec![0usize; subjects],
    );
    for (i, r) in ratings.iter().enumerate() {
        let subject = panel.s[i] as usize;
        count[subject] += 1;
        if let Some((lower, upper)) = band[group(i)] {
            if r.score >= upper {
                p[subject] += 1;
            }
            if r.score <= lower {
                q[subject] += 1;
            }
        }
    }
    let observers = (0..subjects)
        .map(|k| {
            let (p, q, presentations) = (p[k], q[k], count[k]);
            let outlier_fraction = (p + q) as f64 / presentations as f64;
            let asymmetry = (p + q > 0).then(|| (p as f64 - q as f64).abs() / (p + q) as f64);
            let rejected = outlier_fraction > 0.05 && asymmetry.is_some_and(|a| a < 0.3);
            ObserverScreening {
                subject: panel.subjects[k],
                p,
                q,
                presentations,
                outlier_fraction,
                asymmetry,
                rejected,
            }
        })
        .collect();
    ScreeningReport {
        presentations,
        observers,
    }
}

/// Keeps only the ratings of subjects not in `rejected`.
pub fn without_subjects(ratings: &[Rating], rejected: &BTreeSet<u32>) -> Vec<Rating> {
    ratings
        .iter()
        .filter(|r| !rejected.contains(&r.subject))
        .copied()
        .collect()
}

/// How consistently a subject scored hidden repeats.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RepeatConsistency {
    /// Subject id.
    pub subject: u32,
    /// Number of (first showing, repeat) pairs found.
    pub pairs: usize,
    /// Mean |score(repeat) − score(first showing)| in score units; `None` without repeats.
    pub mean_abs_difference: Option<f64>,
}

/// Hidden-repeat consistency (the seeds show 8 stimuli twice): for each subject, the mean
/// absolute difference between each repeat and the first showing of the same condition.
///
/// # Errors
/// [`AnalysisError::NonFinite`] for NaN or infinite scores.
pub fn repeat_consistency(ratings: &[Rating]) -> Result<Vec<RepeatConsistency>, AnalysisError> {
    Ok(repeats_of_panel(ratings, &Panel::new(ratings)?))
}

/// [`repeat_consistency`] over an already built index.
pub(crate) fn repeats_of_panel(ratings: &[Rating], panel: &Panel) -> Vec<RepeatConsistency> {
    let mut acc = vec![(0.0, 0usize); panel.subjects.len()];
    for (start, end) in panel.cells() {
        let first = ratings[panel.order[start] as usize].score;
        let subject = panel.s[panel.order[start] as usize] as usize;
        for &row in &panel.order[start + 1..end] {
            acc[subject].0 += (ratings[row as usize].score - first).abs();
            acc[subject].1 += 1;
        }
    }
    acc.into_iter()
        .zip(&panel.subjects)
        .map(|((sum, pairs), &subject)| RepeatConsistency {
            subject,
            pairs,
            mean_abs_difference: (pairs > 0).then(|| sum / pairs as f64),
        })
        .collect()
}
