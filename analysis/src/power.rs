//! Planning: power of a paired t-test (one- or two-sided), the number of subjects it needs,
//! and the number of subjects that keeps a mean's t-based confidence interval within a
//! half-width.
//!
//! A paired test on n subjects is a one-sample t-test on the n differences; with true effect
//! d = Δ/σ_diff (Cohen's d_z) the statistic follows a noncentral t with n − 1 degrees of
//! freedom and noncentrality d·√n. Power is computed as statsmodels' `TTestPower` does: a
//! one-sided test (`alternative="larger"`) rejects above t₁₋α, a two-sided one above t₁₋α/₂ or
//! below t_α/₂, and both tails count.

use serde::Serialize;

use crate::confidence::Confidence;
use crate::dist::{nct_cdf, t_quantile};
use crate::error::AnalysisError;

/// Most subjects a plan may ask for; a smaller effect is refused rather than searched for.
pub const MAX_SUBJECTS: f64 = 100_000.0;

/// Which side(s) of the null a paired test rejects on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Sides {
    /// One-sided in the direction of the effect (statsmodels `alternative="larger"`).
    One,
    /// Two-sided (statsmodels `alternative="two-sided"`).
    Two,
}

impl Sides {
    /// `one-sided` or `two-sided`.
    pub fn label(self) -> &'static str {
        match self {
            Sides::One => "one-sided",
            Sides::Two => "two-sided",
        }
    }
}

fn invalid(name: &'static str, value: f64, reason: &'static str) -> AnalysisError {
    AnalysisError::InvalidParameter {
        name,
        value,
        reason,
    }
}

fn check_alpha(alpha: f64) -> Result<(), AnalysisError> {
    if alpha > 0.0 && alpha < 1.0 {
        Ok(())
    } else {
        Err(invalid("alpha", alpha, "must lie in (0, 1)"))
    }
}

/// Power of a paired t-test at level `alpha` with `n` subjects (fractional n allowed, as in
/// statsmodels) and standardised effect `effect_size` = mean difference / SD of the
/// differences; one-sided tests look for a positive effect.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for alpha outside (0, 1), n < 2 or a non-finite effect.
pub fn paired_power(
    effect_size: f64,
    n: f64,
    alpha: f64,
    sides: Sides,
) -> Result<f64, AnalysisError> {
    check_alpha(alpha)?;
    if !(n >= 2.0 && n.is_finite()) {
        return Err(invalid("n", n, "must be ≥ 2"));
    }
    if !effect_size.is_finite() {
        return Err(invalid("effect_size", effect_size, "must be finite"));
    }
    let df = n - 1.0;
    let tail = match sides {
        Sides::One => alpha,
        Sides::Two => alpha / 2.0,
    };
    let crit = t_quantile(1.0 - tail, df).ok_or(invalid("n", n, "t quantile undefined"))?;
    let delta = effect_size * n.sqrt();
    let upper = 1.0 - nct_cdf(crit, df, delta);
    Ok(match sides {
        Sides::One => upper,
        Sides::Two => upper + nct_cdf(-crit, df, delta),
    })
}

/// Power of a one-tailed (upper) paired t-test: [`paired_power`] with [`Sides::One`].
///
/// # Errors
/// As [`paired_power`].
pub fn paired_one_tailed_power(effect_size: f64, n: f64, alpha: f64) -> Result<f64, AnalysisError> {
    paired_power(effect_size, n, alpha, Sides::One)
}

/// Sample size for a paired t-test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SampleSize {
    /// The (fractional) n at which power equals the target, as statsmodels' `solve_power`.
    pub n_exact: f64,
    /// The smallest whole number of subjects reaching the target power.
    pub n_subjects: usize,
    /// The power achieved with `n_subjects`.
    pub achieved_power: f64,
}

/// The smallest n ≥ 2 (fractional, to about 1e-13 relative) at which `gap(n)` ≥ 0, for a
/// `gap` increasing in n, and the smallest whole n where it holds; `None` beyond
/// [`MAX_SUBJECTS`]. The root is bracketed by doubling, then found by regula falsi with the
/// Illinois modification (a handful of evaluations where bisection takes fifty).
fn solve_n(
    gap: impl Fn(f64) -> Result<f64, AnalysisError>,
) -> Result<Option<(f64, usize)>, AnalysisError> {
    let (mut lo, mut g_lo) = (2.0, gap(2.0)?);
    if g_lo >= 0.0 {
        return Ok(Some((2.0, 2)));
    }
    let (mut hi, mut g_hi) = (4.0, gap(4.0)?);
    while g_hi < 0.0 {
        (lo, g_lo) = (hi, g_hi);
        hi *= 2.0;
        if hi > 2.0 * MAX_SUBJECTS {
            return Ok(None);
        }
        g_hi = gap(hi)?;
    }
    // Which end moved last (−1: lo, 1: hi), for the Illinois halving.
    let mut last = 0;
    let mut exact = None;
    for _ in 0..200 {
        if hi - lo <= 1e-13 * hi {
            break;
        }
        let mut mid = (lo * g_hi - hi * g_lo) / (g_hi - g_lo);
        if !(mid > lo && mid < hi) {
            mid = 0.5 * (lo + hi);
        }
        let g = gap(mid)?;
        if g < 0.0 {
            (lo, g_lo) = (mid, g);
            if last == -1 {
                g_hi /= 2.0;
            }
            last = -1;
        } else {
            (hi, g_hi) = (mid, g);
            if last == 1 {
                g_lo /= 2.0;
            }
            last = 1;
        }
        if g.abs() <= 1e-15 {
            exact = Some(mid);
            break;
        }
    }
    let n_exact = exact.unwrap_or(0.5 * (lo + hi));
    let mut whole = (n_exact.ceil() as usize).max(2);
    // The ceiling of a root computed to ~1e-13 can land one below when the root is whole.
    while gap(whole as f64)? < 0.0 {
        whole += 1;
    }
    if whole as f64 > MAX_SUBJECTS {
        return Ok(None);
    }
    Ok(Some((n_exact, whole)))
}

/// Subjects a paired t-test needs to detect a standardised effect `effect_size` (Cohen's
/// d_z = mean difference / SD of the differences, > 0) at level `alpha` with the given
/// `power`.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for a non-positive or non-finite effect, alpha or
/// power outside (0, 1) or power ≤ alpha, or when more than [`MAX_SUBJECTS`] subjects would
/// be needed.
pub fn paired_sample_size(
    effect_size: f64,
    alpha: f64,
    power: f64,
    sides: Sides,
) -> Result<SampleSize, AnalysisError> {
    check_alpha(alpha)?;
    if !(effect_size > 0.0 && effect_size.is_finite()) {
        return Err(invalid("effect_size", effect_size, "must be > 0"));
    }
    if !(power > alpha && power < 1.0) {
        return Err(invalid("power", power, "must lie in (alpha, 1)"));
    }
    let gap = |n: f64| paired_power(effect_size, n, alpha, sides).map(|p| p - power);
    let Some((n_exact, n_subjects)) = solve_n(gap)? else {
        return Err(invalid(
            "effect_size",
            effect_size,
            "needs more than 100000 subjects",
        ));
    };
    Ok(SampleSize {
        n_exact,
        n_subjects,
        achieved_power: paired_power(effect_size, n_subjects as f64, alpha, sides)?,
    })
}

/// Subjects needed to detect a mean difference `mean_difference_score` (e.g. 0.5 MOS points)
/// when the SD of per-subject differences is `sd_difference_score`, one-tailed at level
/// `alpha` with the given `power` ([`paired_sample_size`] with d_z = difference / SD).
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
    if !(sd_difference_score > 0.0 && sd_difference_score.is_finite()) {
        return Err(invalid("sd_difference", sd_difference_score, "must be > 0"));
    }
    if !(mean_difference_score > 0.0 && mean_difference_score.is_finite()) {
        return Err(invalid(
            "mean_difference",
            mean_difference_score,
            "must be > 0",
        ));
    }
    paired_sample_size(
        mean_difference_score / sd_difference_score,
        alpha,
        power,
        Sides::One,
    )
}

/// Subjects that keep a mean's confidence interval within a half-width.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CiSampleSize {
    /// The (fractional) n at which t₁₋α/₂,ₙ₋₁ · SD / √n equals the half-width.
    pub n_exact: f64,
    /// The smallest whole number of subjects (≥ 2) whose half-width is at most the target.
    pub n_subjects: usize,
    /// The half-width with `n_subjects`.
    pub half_width: f64,
}

/// Half-width t₁₋α/₂,ₙ₋₁ · `sd` / √n of the Student-t interval of a mean of `n` values.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for n < 2 or a negative or non-finite SD.
pub fn ci_half_width(sd: f64, n: f64, confidence: Confidence) -> Result<f64, AnalysisError> {
    if !(sd >= 0.0 && sd.is_finite()) {
        return Err(invalid("sd", sd, "must be ≥ 0 and finite"));
    }
    if !(n >= 2.0 && n.is_finite()) {
        return Err(invalid("n", n, "must be ≥ 2"));
    }
    let t = t_quantile(1.0 - confidence.alpha() / 2.0, n - 1.0).ok_or(invalid(
        "n",
        n,
        "t quantile undefined",
    ))?;
    Ok(t * sd / n.sqrt())
}

/// Subjects needed for the `confidence` Student-t interval of a mean (a threshold, a MOS) to
/// have a half-width of at most `half_width` when the values' SD is `sd`.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for a non-positive SD or half-width, or when more than
/// [`MAX_SUBJECTS`] subjects would be needed.
pub fn ci_sample_size(
    sd: f64,
    half_width: f64,
    confidence: Confidence,
) -> Result<CiSampleSize, AnalysisError> {
    if !(sd > 0.0 && sd.is_finite()) {
        return Err(invalid("sd", sd, "must be > 0"));
    }
    if !(half_width > 0.0 && half_width.is_finite()) {
        return Err(invalid("half_width", half_width, "must be > 0"));
    }
    let gap = |n: f64| ci_half_width(sd, n, confidence).map(|w| half_width - w);
    let Some((n_exact, n_subjects)) = solve_n(gap)? else {
        return Err(invalid(
            "half_width",
            half_width,
            "needs more than 100000 subjects",
        ));
    };
    Ok(CiSampleSize {
        n_exact,
        n_subjects,
        half_width: ci_half_width(sd, n_subjects as f64, confidence)?,
    })
}
