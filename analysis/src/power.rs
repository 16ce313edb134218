//! Planning: power of a paired one-tailed t-test and the number of subjects it needs.
//!
//! A paired test on n subjects is a one-sample t-test on the n differences; with true effect
//! d = Δ/σ_diff the statistic follows a noncentral t with n − 1 degrees of freedom and
//! noncentrality d·√n (as in statsmodels' `TTestPower`).

use serde::Serialize;

use crate::dist::{nct_cdf, t_quantile};
use crate::error::AnalysisError;

/// Power of a one-tailed (upper) paired t-test at level `alpha` with `n` subjects and
/// standardised effect `effect_size` = mean difference / SD of the differences.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for alpha outside (0, 1), n < 2 or a non-finite effect.
pub fn paired_one_tailed_power(effect_size: f64, n: f64, alpha: f64) -> Result<f64, AnalysisError> {
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(AnalysisError::InvalidParameter {
            name: "alpha",
            value: alpha,
            reason: "must lie in (0, 1)",
        });
    }
    if !(n >= 2.0 && n.is_finite()) {
        return Err(AnalysisError::InvalidParameter {
            name: "n",
            value: n,
            reason: "must be ≥ 2",
        });
    }
    if !effect_size.is_finite() {
        return Err(AnalysisError::InvalidParameter {
            name: "effect_size",
            value: effect_size,
            reason: "must be finite",
        });
    }
    let df = n - 1.0;
    let crit = t_quantile(1.0 - alpha, df).ok_or(AnalysisError::InvalidParameter {
        name: "n",
        value: n,
        reason: "t quantile undefined",
    })?;
    Ok(1.0 - nct_cdf(crit, df, effect_size * n.sqrt()))
}

/// Sample size for a paired one-tailed t-test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SampleSize {
    /// The (fractional) n at which power equals the target, as statsmodels' `solve_power`.
    pub n_exact: f64,
    /// The smallest whole number of subjects reaching the target power.
    pub n_subjects: usize,
    /// The power achieved with `n_subjects`.
    pub achieved_power: f64,
}

/// Subjects needed to detect a mean difference `mean_difference_score` (e.g. 0.5 MOS points)
/// when the SD of per-subject differences is `sd_difference_score`, at level `alpha` with the
/// given `power`.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for a non-positive difference or SD, alpha or power
/// outside (0, 1), or when more than 100 000 subjects would be needed.
pub fn paired_one_tailed_sample_size(
    mean_difference_score: f64,
    sd_difference_score: f64,
    alpha: f64,
    power: f64,
) -> Result<SampleSize, AnalysisError> {
    const MAX_N: f64 = 100_000.0;
    if !(sd_difference_score > 0.0 && sd_difference_score.is_finite()) {
        return Err(AnalysisError::InvalidParameter {
            name: "sd_difference",
            value: sd_difference_score,
            reason: "must be > 0",
        });
    }
    if !(mean_difference_score > 0.0 && mean_difference_score.is_finite()) {
        return Err(AnalysisError::InvalidParameter {
            name: "mean_difference",
            value: mean_difference_score,
            reason: "must be > 0",
        });
    }
    if !(power > alpha && power < 1.0) {
        return Err(AnalysisError::InvalidParameter {
            name: "power",
            value: power,
            reason: "must lie in (alpha, 1)",
        });
    }
    let d = mean_difference_score / sd_difference_score;
    let f = |n: f64| paired_one_tailed_power(d, n, alpha).map(|p| p - power);
    let mut lo = 2.0;
    if f(lo)? >= 0.0 {
        return Ok(SampleSize {
            n_exact: lo,
            n_subjects: 2,
            achieved_power: f(lo)? + power,
        });
    }
    let mut hi = 4.0;
    while f(hi)? < 0.0 {
        hi *= 2.0;
        if hi > MAX_N {
            return Err(AnalysisError::InvalidParameter {
                name: "mean_difference",
                value: mean_difference_score,
                reason: "needs more than 100000 subjects",
            });
        }
    }
    // Bisection: power is increasing in n; 200 halvings reach machine precision.
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if f(mid)? < 0.0 { lo = mid } else { hi = mid }
    }
    let n_exact = 0.5 * (lo + hi);
    let mut n_subjects = n_exact.ceil() as usize;
    // ceil of a root computed to ~1e-15 can land one below when the root is an integer.
    while f(n_subjects as f64)? < 0.0 {
        n_subjects += 1;
    }
    let achieved_power = f(n_subjects as f64)? + power;
    Ok(SampleSize {
        n_exact,
        n_subjects,
        achieved_power,
    })
}
