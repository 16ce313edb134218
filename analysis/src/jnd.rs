//! Just-noticeable differences across viewers (thesis ch. 5: "average JND t_L = 0.012, min
//! 0.010, max 0.016 over 20 subjects"), turned into what a codec user asks: at this level, or
//! this compression ratio, what share of viewers would notice?
//!
//! A viewer with staircase threshold `T` notices a stimulus at level `x` when `x ≥ T` (a higher
//! level is a stronger distortion: t_L, or a target compression ratio). Over subjects:
//! - empirical: the share who would not notice is `#{T_i > x} / n` (one minus the empirical
//!   CDF of the thresholds);
//! - normal model: `T ~ N(μ, σ²)`, share not noticing `Φ((μ − x)/σ)`, estimated by
//!   `Φ((x̄ − x)/s)`, with the exact normal-theory confidence interval: `√n (x̄ − x)/s` follows
//!   a noncentral t with `n − 1` degrees of freedom and noncentrality `√n (μ − x)/σ`, which is
//!   inverted for the noncentrality and mapped back through `Φ(δ/√n)` (the interval behind
//!   one-sided normal tolerance limits; checked against SciPy's `nct`).
//!
//! The compression ratio a codec reaches at a level on each clip comes from the logged
//! achieved ratios (live staircase rows) or the manifest (staircases over prepared stimuli).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::confidence::Confidence;
use crate::descriptive::{Summary, summarize};
use crate::dist::{nct_cdf, z_sf};
use crate::error::{AnalysisError, check_finite};

/// The compression ratio and error a codec reached at one level on one clip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EncodedLevel {
    /// Clip name.
    pub clip: String,
    /// Staircase level (the codec parameter's value).
    pub level: f64,
    /// Compression ratio reached.
    pub achieved_cr: f64,
    /// Joint position RMS error of the decoded clip, cm, when known.
    pub rms_cm: Option<f64>,
}

/// Share of viewers who would not notice a level, empirical and modelled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct UnnoticedShare {
    /// The level.
    pub level: f64,
    /// `#{T_i > level} / n`.
    pub empirical: f64,
    /// `Φ((x̄ − level)/s)` under the normal model; `None` with fewer than 2 thresholds or no
    /// spread.
    pub model: Option<f64>,
    /// Exact normal-theory confidence interval of the modelled share (lower, upper).
    pub model_ci: Option<(f64, f64)>,
}

/// `Φ(x)` without cancellation in either tail.
fn phi(x: f64) -> f64 {
    z_sf(-x)
}

/// Share of viewers whose threshold lies above `level` (who would not notice it), from the
/// per-viewer `thresholds`, with a `confidence` interval of the normal model.
///
/// # Errors
/// [`AnalysisError::TooFew`] without thresholds; [`AnalysisError::NonFinite`] for a
/// non-finite threshold or level.
pub fn unnoticed_share(
    thresholds: &[f64],
    level: f64,
    confidence: Confidence,
) -> Result<UnnoticedShare, AnalysisError> {
    if thresholds.is_empty() {
        return Err(AnalysisError::TooFew {
            what: "thresholds",
            needed: 1,
            got: 0,
        });
    }
    check_finite("threshold", thresholds)?;
    check_finite("level", &[level])?;
    let n = thresholds.len() as f64;
    let above = thresholds.iter().filter(|&&t| t > level).count() as f64;
    let empirical = above / n;
    let Some((mean, sd)) = normal_model(thresholds) else {
        return Ok(UnnoticedShare {
            level,
            empirical,
            model: None,
            model_ci: None,
        });
    };
    let model = phi((mean - level) / sd);
    let root_n = n.sqrt();
    let t_obs = root_n * (mean - level) / sd;
    let df = n - 1.0;
    let alpha = confidence.alpha();
    // P(T ≤ t_obs | δ) falls from 1 to 0 as δ grows: the lower bound of δ puts t_obs at the
    // upper α/2 point, the upper bound at the lower α/2 point.
    let lower = solve_delta(t_obs, df, 1.0 - alpha / 2.0);
    let upper = solve_delta(t_obs, df, alpha / 2.0);
    Ok(UnnoticedShare {
        level,
        empirical,
        model: Some(model),
        model_ci: Some((phi(lower / root_n), phi(upper / root_n))),
    })
}

/// The normal model of the thresholds, (x̄, s) with the sample SD (divisor n − 1); `None`
/// with fewer than two thresholds or no spread, where the model is undefined.
fn normal_model(thresholds: &[f64]) -> Option<(f64, f64)> {
    if thresholds.len() < 2 {
        return None;
    }
    let n = thresholds.len() as f64;
    // Plain two-pass sums rather than descriptive::mean_of's compensated mean: switching would
    // move the last digits of the published JND tables for no gain at a study's sample sizes.
    let mean = thresholds.iter().sum::<f64>() / n;
    let sd = (thresholds.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    // sd is finite (finite inputs); zero spread leaves the model undefined.
    if sd <= 0.0 { None } else { Some((mean, sd)) }
}

/// The noncentrality δ with `P(T ≤ t | df, δ) = target`, by bisection (the CDF falls
/// monotonically in δ) in a bracket around `t` that widens until it holds the root. A root
/// beyond |δ| = 60 (a share within 1e-15 of 0 or 1 for a study's sample sizes) is returned at
/// the bracket's end.
fn solve_delta(t: f64, df: f64, target: f64) -> f64 {
    const LIMIT: f64 = 60.0;
    let f = |d: f64| nct_cdf(t, df, d) - target;
    let mut half = 12.0;
    let (mut lo, mut hi) = (t - half, t + half);
    while f(lo) <= 0.0 && lo > -LIMIT {
        half *= 2.0;
        lo = (t - half).max(-LIMIT);
    }
    while f(hi) >= 0.0 && hi < LIMIT {
        half *= 2.0;
        hi = (t + half).min(LIMIT);
    }
    if f(lo) <= 0.0 {
        return lo;
    }
    if f(hi) >= 0.0 {
        return hi;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-14 * (1.0 + mid.abs()) {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// One row of the JND table: a level, who would notice it, and what it compresses to.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JndRow {
    /// Share of viewers who would not notice.
    pub share: UnnoticedShare,
    /// Mean compression ratio reached at this level, per clip (in [`JndAnalysis::clips`]
    /// order); `None` where the level was never encoded for that clip.
    pub cr_per_clip: Vec<Option<f64>>,
}

/// The JND report of a staircase study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JndAnalysis {
    /// Per-subject thresholds (subject, threshold), as [`crate::staircase::staircase_thresholds`]
    /// gives them.
    pub thresholds: Vec<(u32, f64)>,
    /// Mean, SD, CI of the thresholds.
    pub summary: Summary,
    /// Smallest threshold.
    pub min: f64,
    /// Largest threshold.
    pub max: f64,
    /// Clips with logged encodings, sorted.
    pub clips: Vec<String>,
    /// One row per tabulated level, ascending.
    pub rows: Vec<JndRow>,
    /// Confidence level of the intervals.
    pub confidence: Confidence,
}

/// Most levels tabulated; more distinct levels are thinned evenly.
const MAX_ROWS: usize = 24;

/// The JND analysis: the distribution of `thresholds` and, at every encoded level (thinned to
/// at most 24, plus the levels of the thresholds' range when nothing was encoded), the share
/// of viewers who would not notice and the compression ratio per clip.
///
/// # Errors
/// As [`unnoticed_share`] and [`summarize`].
pub fn jnd_analysis(
    thresholds: &[(u32, f64)],
    encoded: &[EncodedLevel],
    confidence: Confidence,
) -> Result<JndAnalysis, AnalysisError> {
    let values: Vec<f64> = thresholds.iter().map(|t| t.1).collect();
    let summary = summarize(&values, confidence)?;
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // (clip, level bits) -> (sum of CR, count)
    let mut per: BTreeMap<(String, u64), (f64, u32)> = BTreeMap::new();
    let mut levels: Vec<f64> = Vec::new();
    for e in encoded {
        if !(e.level.is_finite() && e.achieved_cr.is_finite()) {
            continue;
        }
        let cell = per.entry((e.clip.clone(), e.level.to_bits())).or_default();
        cell.0 += e.achieved_cr;
        cell.1 += 1;
        levels.push(e.level);
    }
    let mut clips: Vec<String> = per.keys().map(|k| k.0.clone()).collect();
    clips.dedup();
    if levels.is_empty() {
        levels.extend([min, summary.mean, max]);
    }
    levels.sort_by(f64::total_cmp);
    levels.dedup_by(|a, b| a.to_bits() == b.to_bits());
    if levels.len() > MAX_ROWS {
        let k = levels.len();
        levels = (0..MAX_ROWS)
            .map(|i| levels[i * (k - 1) / (MAX_ROWS - 1)])
            .collect();
    }
    let rows = levels
        .iter()
        .map(|&level| {
            Ok(JndRow {
                share: unnoticed_share(&values, level, confidence)?,
                cr_per_clip: clips
                    .iter()
                    .map(|c| {
                        per.get(&(c.clone(), level.to_bits()))
                            .map(|(s, n)| s / f64::from(*n))
                    })
                    .collect(),
            })
        })
        .collect::<Result<Vec<_>, AnalysisError>>()?;
    Ok(JndAnalysis {
        thresholds: thresholds.to_vec(),
        summary,
        min,
        max,
        clips,
        rows,
        confidence,
    })
}

impl JndAnalysis {
    /// Points of the modelled share of viewers who would NOTICE, `1 − Φ((x̄ − x)/s)`, with its
    /// CI, over `points` levels spanning the thresholds ± 3 SD: (level, share, lower, upper).
    pub fn notice_curve(&self, points: usize) -> Vec<(f64, f64, f64, f64)> {
        let values: Vec<f64> = self.thresholds.iter().map(|t| t.1).collect();
        let sd = self.summary.sd.unwrap_or(0.0);
        let (lo, hi) = (self.min - 3.0 * sd, self.max + 3.0 * sd);
        let points = points.max(2);
        (0..points)
            .filter_map(|i| {
                let x = lo + (hi - lo) * i as f64 / (points - 1) as f64;
                let s = unnoticed_share(&values, x, self.confidence).ok()?;
                let (l, u) = s.model_ci?;
                Some((x, 1.0 - s.model?, 1.0 - u, 1.0 - l))
            })
            .collect()
    }
}
