//! Per-condition descriptive statistics: n, mean (MOS), SD, standard error, 95 % confidence
//! intervals by Student t and by the normal approximation of ITU-R BT.500, and the median.

use serde::Serialize;

use crate::confidence::Confidence;
use crate::dist::{t_quantile, z_quantile};
use crate::error::{AnalysisError, check_finite};

/// One opinion score: a subject's rating of one test condition.
///
/// `condition` is an id into the study's condition table ([`crate::ConditionInfo`]); the same
/// subject may rate a condition more than once (hidden repeats), in presentation order.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Rating {
    /// Subject (observer) id.
    pub subject: u32,
    /// Condition id (codec × rate × clip, or a reference).
    pub condition: u32,
    /// The score on the study's scale (1-5 for the seeds' ACR / DSCQS studies).
    pub score: f64,
}

/// How a confidence interval of a mean is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[non_exhaustive]
pub enum CiMethod {
    /// Student t with n − 1 degrees of freedom: mean ± t(1 − α/2, n − 1)·S/√n.
    StudentT,
    /// Normal approximation of BT.500 (Annex 2, §2.2.1): mean ± z(1 − α/2)·S/√n, which is
    /// δ = 1.96·S/√N at 95 %.
    NormalZ,
}

/// A two-sided confidence interval of a mean.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Ci {
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// Half width (δ in BT.500), the number the seeds print as "confidence interval".
    pub half_width: f64,
}

/// Descriptive statistics of one sample of scores.
///
/// Statistics that need two or more values (`sd`, `se`, the CIs) are `None` for n = 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Number of values.
    pub n: usize,
    /// Arithmetic mean (the MOS when the values are opinion scores).
    pub mean: f64,
    /// Sample standard deviation (divisor n − 1).
    pub sd: Option<f64>,
    /// Standard error of the mean, S/√n.
    pub se: Option<f64>,
    /// Confidence interval by Student t.
    pub ci_t: Option<Ci>,
    /// Confidence interval by the normal approximation (BT.500).
    pub ci_z: Option<Ci>,
    /// Median (mean of the two middle values for even n); `None` when built from summary
    /// statistics only.
    pub median: Option<f64>,
    /// The confidence level of both intervals, e.g. 0.95.
    pub confidence: Confidence,
}

impl Summary {
    /// The interval computed by `method`.
    pub fn ci(&self, method: CiMethod) -> Option<Ci> {
        match method {
            CiMethod::StudentT => self.ci_t,
            CiMethod::NormalZ => self.ci_z,
        }
    }
}

/// Summarises a sample: n, mean, SD, SE, t and z intervals at `confidence`, median.
///
/// # Errors
/// [`AnalysisError::TooFew`] for an empty sample, [`AnalysisError::NonFinite`] for NaN or
/// infinite values.
pub fn summarize(values: &[f64], confidence: Confidence) -> Result<Summary, AnalysisError> {
    check_finite("summarize", values)?;
    if values.is_empty() {
        return Err(AnalysisError::TooFew {
            what: "summarize",
            needed: 1,
            got: 0,
        });
    }
    let n = values.len();
    let mean = mean_of(values);
    let sd = (n >= 2).then(|| sample_variance(values, mean).sqrt());
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let median = Some(median_of_sorted(&sorted));
    let mut summary = from_summary_statistics(mean, sd, n, confidence)?;
    summary.median = median;
    Ok(summary)
}

/// Builds a [`Summary`] from published summary statistics (mean, SD, n), as labs do when they
/// compare against a paper's table. `sd` may be `None` when n = 1.
///
/// # Errors
/// [`AnalysisError::TooFew`] for n = 0, [`AnalysisError::InvalidParameter`] for a negative or
/// non-finite SD.
pub fn from_summary_statistics(
    mean: f64,
    sd: Option<f64>,
    n: usize,
    confidence: Confidence,
) -> Result<Summary, AnalysisError> {
    if n == 0 {
        return Err(AnalysisError::TooFew {
            what: "summary statistics",
            needed: 1,
            got: 0,
        });
    }
    check_finite("mean", &[mean])?;
    if let Some(s) = sd
        && !(s.is_finite() && s >= 0.0)
    {
        return Err(AnalysisError::InvalidParameter {
            name: "sd",
            value: s,
            reason: "must be finite and ≥ 0",
        });
    }
    let sd = if n >= 2 { sd } else { None };
    let se = sd.map(|s| s / (n as f64).sqrt());
    let upper_p = 1.0 - confidence.alpha() / 2.0;
    let make = |q: Option<f64>| -> Option<Ci> {
        let half_width = q? * se?;
        Some(Ci {
            lower: mean - half_width,
            upper: mean + half_width,
            half_width,
        })
    };
    let ci_t = if n >= 2 {
        make(t_quantile(upper_p, (n - 1) as f64))
    } else {
        None
    };
    let ci_z = make(z_quantile(upper_p));
    Ok(Summary {
        n,
        mean,
        sd,
        se,
        ci_t,
        ci_z,
        median: None,
        confidence,
    })
}

/// The statistics of one condition.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConditionStats {
    /// Condition id.
    pub condition: u32,
    /// Its scores summarised.
    pub summary: Summary,
}

/// Groups ratings by condition and summarises each (the MOS table, Table 3.1 of the thesis).
/// Conditions come back sorted by id.
///
/// # Errors
/// As [`summarize`].
pub fn condition_stats(
    ratings: &[Rating],
    confidence: Confidence,
) -> Result<Vec<ConditionStats>, AnalysisError> {
    let (ids, offsets, scores) = crate::panel::group_by_condition(ratings)?;
    ids.iter()
        .enumerate()
        .map(|(k, &condition)| {
            Ok(ConditionStats {
                condition,
                summary: summarize(&scores[offsets[k]..offsets[k + 1]], confidence)?,
            })
        })
        .collect()
}

/// Mean of a non-empty slice (compensated by a second pass, as NumPy's pairwise sum is not
/// available; the correction term keeps 1e-15 relative agreement on 10⁶ values).
pub(crate) fn mean_of(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    let m = values.iter().sum::<f64>() / n;
    let correction = values.iter().map(|v| v - m).sum::<f64>() / n;
    m + correction
}

/// Sample variance with divisor n − 1 (two-pass, corrected).
pub(crate) fn sample_variance(values: &[f64], mean: f64) -> f64 {
    let n = values.len() as f64;
    let (ss, s) = values.iter().fold((0.0, 0.0), |(ss, s), v| {
        let d = v - mean;
        (ss + d * d, s + d)
    });
    (ss - s * s / n) / (n - 1.0)
}

/// Median of an already sorted, non-empty slice.
pub(crate) fn median_of_sorted(sorted: &[f64]) -> f64 {
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    }
}
