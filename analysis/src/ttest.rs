//! Paired, Welch and pooled (Student) t-tests, one- and two-tailed, with effect sizes, and
//! Holm's step-down correction across a family of comparisons.
//!
//! The seeds compare methods with one-tailed tests ("method A scores higher than B", thesis
//! Tables 3.2 and 3.3); use [`Alternative::Greater`] with A as the first sample.

use serde::Serialize;

use crate::descriptive::{mean_of, sample_variance};
use crate::dist::{t_cdf, t_sf};
use crate::error::{AnalysisError, check_finite};

/// The alternative hypothesis about the mean difference (first − second).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[non_exhaustive]
pub enum Alternative {
    /// The means differ (two-tailed).
    TwoSided,
    /// The first mean is greater (one-tailed, upper).
    Greater,
    /// The first mean is smaller (one-tailed, lower).
    Less,
}

/// Why a statistic could not be computed for the data (not an input error: reported as such in
/// tables, never as NaN).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, thiserror::Error)]
#[non_exhaustive]
pub enum Undefined {
    /// Too few observations (a t-test needs n ≥ 2 per sample, or ≥ 2 pairs).
    #[error("undefined: need at least {needed} observations, got {got}")]
    TooFewObservations {
        /// Minimum needed.
        needed: usize,
        /// Number given.
        got: usize,
    },
    /// The standard error is zero, so t is ±∞ or 0/0.
    #[error("undefined: zero variance")]
    ZeroVariance,
}

/// The result of a t-test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TTest {
    /// The t statistic.
    pub t: f64,
    /// Degrees of freedom (fractional for Welch).
    pub df: f64,
    /// p value under the chosen alternative.
    pub p: f64,
    /// Mean difference (first − second), in score units.
    pub mean_difference: f64,
    /// Standardised effect: d_z = mean difference / SD of differences for a paired test;
    /// Cohen's d with the pooled SD for the two-sample tests.
    pub effect_size: f64,
    /// The alternative the p value refers to.
    pub alternative: Alternative,
}

/// A t-test outcome: computed, or undefined for the data.
pub type TTestOutcome = Result<TTest, Undefined>;

fn p_value(t: f64, df: f64, alternative: Alternative) -> f64 {
    let p = match alternative {
        Alternative::Greater => t_sf(t, df),
        Alternative::Less => t_cdf(t, df),
        Alternative::TwoSided => t_sf(t.abs(), df).map(|p| (2.0 * p).min(1.0)),
    };
    p.unwrap_or(f64::NAN)
}

/// Paired t-test on `first[i] − second[i]` (scipy.stats.ttest_rel).
///
/// # Errors
/// [`AnalysisError::LengthMismatch`] when the samples differ in length,
/// [`AnalysisError::NonFinite`] for NaN or infinite scores. Too few pairs or zero variance of the
/// differences come back as `Ok(Err(Undefined))`.
pub fn paired(
    first: &[f64],
    second: &[f64],
    alternative: Alternative,
) -> Result<TTestOutcome, AnalysisError> {
    if first.len() != second.len() {
        return Err(AnalysisError::LengthMismatch {
            what: "paired t-test",
            left: first.len(),
            right: second.len(),
        });
    }
    check_finite("paired t-test first sample", first)?;
    check_finite("paired t-test second sample", second)?;
    let diffs: Vec<f64> = first.iter().zip(second).map(|(a, b)| a - b).collect();
    if diffs.len() < 2 {
        return Ok(Err(Undefined::TooFewObservations {
            needed: 2,
            got: diffs.len(),
        }));
    }
    let mean = mean_of(&diffs);
    let sd = sample_variance(&diffs, mean).max(0.0).sqrt();
    Ok(paired_from_summary(mean, sd, diffs.len(), alternative))
}

/// Paired t-test from the mean and SD of the differences and the number of pairs.
///
/// # Errors
/// [`Undefined`] for fewer than two pairs or a zero SD.
pub fn paired_from_summary(
    mean_difference: f64,
    sd_difference: f64,
    n: usize,
    alternative: Alternative,
) -> TTestOutcome {
    if n < 2 {
        return Err(Undefined::TooFewObservations { needed: 2, got: n });
    }
    if sd_difference.is_nan() || sd_difference <= 0.0 {
        return Err(Undefined::ZeroVariance);
    }
    let nf = n as f64;
    let t = mean_difference / (sd_difference / nf.sqrt());
    let df = nf - 1.0;
    Ok(TTest {
        t,
        df,
        p: p_value(t, df, alternative),
        mean_difference,
        effect_size: mean_difference / sd_difference,
        alternative,
    })
}

/// Mean, sample SD and n of one group, as published in a table.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GroupStats {
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (divisor n − 1).
    pub sd: f64,
    /// Number of observations.
    pub n: usize,
}

impl GroupStats {
    /// Mean, SD and n of a sample, or `None` when it has fewer than two values.
    pub fn of(values: &[f64]) -> Option<Self> {
        (values.len() >= 2).then(|| {
            let mean = mean_of(values);
            Self {
                mean,
                sd: sample_variance(values, mean).max(0.0).sqrt(),
                n: values.len(),
            }
        })
    }
}

/// Welch's unequal-variance t-test (scipy.stats.ttest_ind(equal_var=False)).
///
/// # Errors
/// [`AnalysisError::NonFinite`] for NaN or infinite scores.
pub fn welch(
    first: &[f64],
    second: &[f64],
    alternative: Alternative,
) -> Result<TTestOutcome, AnalysisError> {
    two_sample(first, second, alternative, welch_from_summary)
}

/// Student's pooled-variance two-sample t-test (scipy.stats.ttest_ind(equal_var=True)).
///
/// # Errors
/// [`AnalysisError::NonFinite`] for NaN or infinite scores.
pub fn student(
    first: &[f64],
    second: &[f64],
    alternative: Alternative,
) -> Result<TTestOutcome, AnalysisError> {
    two_sample(first, second, alternative, student_from_summary)
}

fn two_sample(
    first: &[f64],
    second: &[f64],
    alternative: Alternative,
    test: fn(GroupStats, GroupStats, Alternative) -> TTestOutcome,
) -> Result<TTestOutcome, AnalysisError> {
    check_finite("t-test first sample", first)?;
    check_finite("t-test second sample", second)?;
    let (Some(a), Some(b)) = (GroupStats::of(first), GroupStats::of(second)) else {
        return Ok(Err(Undefined::TooFewObservations {
            needed: 2,
            got: first.len().min(second.len()),
        }));
    };
    Ok(test(a, b, alternative))
}

fn pooled_sd(a: GroupStats, b: GroupStats) -> f64 {
    let (na, nb) = (a.n as f64, b.n as f64);
    (((na - 1.0) * a.sd * a.sd + (nb - 1.0) * b.sd * b.sd) / (na + nb - 2.0)).sqrt()
}

/// Welch's t-test from published summary statistics (scipy.stats.ttest_ind_from_stats with
/// equal_var=False). df by Welch–Satterthwaite; effect size is Cohen's d with the pooled SD.
///
/// # Errors
/// [`Undefined`] for a group with fewer than two values or zero standard error.
pub fn welch_from_summary(a: GroupStats, b: GroupStats, alternative: Alternative) -> TTestOutcome {
    check_groups(a, b)?;
    let (na, nb) = (a.n as f64, b.n as f64);
    let va = a.sd * a.sd / na;
    let vb = b.sd * b.sd / nb;
    let se2 = va + vb;
    if se2.is_nan() || se2 <= 0.0 {
        return Err(Undefined::ZeroVariance);
    }
    let t = (a.mean - b.mean) / se2.sqrt();
    let df = se2 * se2 / (va * va / (na - 1.0) + vb * vb / (nb - 1.0));
    Ok(finish(a, b, t, df, alternative))
}

/// Student's pooled t-test from summary statistics (ttest_ind_from_stats, equal_var=True).
///
/// # Errors
/// [`Undefined`] for a group with fewer than two values or a zero pooled SD.
pub fn student_from_summary(
    a: GroupStats,
    b: GroupStats,
    alternative: Alternative,
) -> TTestOutcome {
    check_groups(a, b)?;
    let (na, nb) = (a.n as f64, b.n as f64);
    let sp = pooled_sd(a, b);
    if sp.is_nan() || sp <= 0.0 {
        return Err(Undefined::ZeroVariance);
    }
    let t = (a.mean - b.mean) / (sp * (1.0 / na + 1.0 / nb).sqrt());
    Ok(finish(a, b, t, na + nb - 2.0, alternative))
}

fn check_groups(a: GroupStats, b: GroupStats) -> Result<(), Undefined> {
    if a.n < 2 || b.n < 2 {
        return Err(Undefined::TooFewObservations {
            needed: 2,
            got: a.n.min(b.n),
        });
    }
    Ok(())
}

fn finish(a: GroupStats, b: GroupStats, t: f64, df: f64, alternative: Alternative) -> TTest {
    let sp = pooled_sd(a, b);
    let mean_difference = a.mean - b.mean;
    // Cohen's d is undefined for a zero pooled SD; the t-test guards already excluded se = 0,
    // and sp = 0 implies se = 0, so the division is safe here.
    TTest {
        t,
        df,
        p: p_value(t, df, alternative),
        mean_difference,
        effect_size: mean_difference / sp,
        alternative,
    }
}

/// Holm's step-down adjustment of a family of p values (statsmodels multipletests, "holm").
///
/// Returns the adjusted p values in input order. NaN or out-of-range inputs are rejected.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for a p value outside [0, 1].
pub fn holm(p_values: &[f64]) -> Result<Vec<f64>, AnalysisError> {
    if let Some(&p) = p_values.iter().find(|p| !(**p >= 0.0 && **p <= 1.0)) {
        return Err(AnalysisError::InvalidParameter {
            name: "p value",
            value: p,
            reason: "must lie in [0, 1]",
        });
    }
    let m = p_values.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&i, &j| p_values[i].total_cmp(&p_values[j]));
    let mut adjusted = vec![0.0; m];
    let mut running = 0.0_f64;
    for (rank, &i) in order.iter().enumerate() {
        let candidate = ((m - rank) as f64 * p_values[i]).min(1.0);
        running = running.max(candidate);
        adjusted[i] = running;
    }
    Ok(adjusted)
}
