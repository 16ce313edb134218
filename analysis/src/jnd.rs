//! Just-noticeable differences across viewers (thesis ch. 5: "average JND t_L = 0.012, min
//! 0.010, max 0.016 over 20 subjects"), turned into what a codec user asks: at this level, or
//! this compression ratio, what share of viewers would notice?
//!
//! A viewer with staircase threshold `T` notices a stimulus at level `x` when `x ≥ T` (a higher
//! level is a stronger distortion: t_L, or a target compression ratio); `x = T` is decided on
//! the staircase's level grid ([`LevelGrid`]), not by float equality. Over subjects:
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
use crate::dist::z_sf;
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
    /// The modelled share who would notice, `Φ((level − x̄)/s)` = 1 − `model`, computed
    /// without the cancellation of `1 − model` where it is near 0.
    pub notice: Option<f64>,
    /// Its confidence interval (lower, upper) = 1 − `model_ci` (upper, lower), likewise.
    pub notice_ci: Option<(f64, f64)>,
}

/// The grid a staircase steps on, for deciding when a threshold equals a level.
///
/// A threshold is the mean of reversal levels (the last k of each track, averaged over a
/// subject's tracks: `levels_per_threshold` = k × tracks at most), and a level of the JND
/// table is a grid level. On a linear grid of step h, N·(T − x) is then an exact multiple of h
/// for a threshold T averaged from N levels: T and x are equal or at least h/N apart. Float
/// rounding moves a mean of N levels by about N·2⁻⁵² of its size, some 10¹⁰ times less. The
/// comparison therefore counts T as equal to x when |T − x| < h/(2N): half the smallest
/// exact difference, which no true difference falls inside and no rounding reaches. (On a
/// log grid the same tolerance is far above rounding and below any difference a study
/// resolves.)
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LevelGrid {
    /// A level of the grid: the smallest level a track presented.
    pub origin: f64,
    /// The grid's step h: the smallest move between two trials of a track.
    pub step: f64,
    /// The most reversal levels averaged into one subject's threshold (N).
    pub levels_per_threshold: usize,
    /// Whether every level presented is origin + an integer multiple of the step (a linear
    /// grid); a log or dB grid is not.
    pub linear: bool,
}

impl LevelGrid {
    /// The grid of up-down `tracks` whose thresholds are means of their last `k` reversals:
    /// the smallest non-zero move between successive trials, and k × the most tracks one
    /// subject has. `None` without a move (or k = 0).
    #[must_use]
    pub fn of_tracks(tracks: &[crate::staircase::StaircaseTrack], k: usize) -> Option<Self> {
        let up_down = || tracks.iter().filter(|t| !t.bayesian);
        let step = up_down()
            .flat_map(|t| t.steps.windows(2).map(|w| (w[1].level - w[0].level).abs()))
            .filter(|d| d.is_finite() && *d > 0.0)
            .min_by(f64::total_cmp)?;
        let mut per_subject: BTreeMap<u32, usize> = BTreeMap::new();
        for t in up_down() {
            *per_subject.entry(t.subject).or_default() += 1;
        }
        let tracks = per_subject.values().copied().max()?;
        let origin = up_down()
            .flat_map(|t| t.steps.iter().map(|s| s.level))
            .filter(|l| l.is_finite())
            .min_by(f64::total_cmp)?;
        let linear = up_down().flat_map(|t| t.steps.iter()).all(|s| {
            let n = (s.level - origin) / step;
            (n - n.round()).abs() <= 1e-6
        });
        (k > 0).then_some(Self {
            origin,
            linear,
            step,
            levels_per_threshold: k * tracks,
        })
    }

    /// The level of a linear grid nearest to `x`, origin + round((x − origin)/h)·h; `None`
    /// on a grid that is not linear.
    #[must_use]
    pub fn nearest(&self, x: f64) -> Option<f64> {
        self.linear
            .then(|| self.origin + ((x - self.origin) / self.step).round() * self.step)
    }

    /// Half the smallest exact difference between a threshold and a level, h/(2N).
    #[must_use]
    pub fn tie_tolerance(&self) -> f64 {
        self.step / (2.0 * self.levels_per_threshold.max(1) as f64)
    }
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
    unnoticed_share_on(thresholds, level, None, confidence)
}

/// [`unnoticed_share`] with ties decided on the level `grid`: a threshold within
/// [`LevelGrid::tie_tolerance`] of `level` equals it and notices it (a mean of reversal
/// levels that is 0.010 in exact arithmetic may come out as 0.010000000000000002). Without a
/// grid, thresholds are compared as they are.
///
/// # Errors
/// As [`unnoticed_share`].
pub fn unnoticed_share_on(
    thresholds: &[f64],
    level: f64,
    grid: Option<LevelGrid>,
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
    let tie = grid.map_or(0.0, |g| g.tie_tolerance());
    let above = thresholds.iter().filter(|&&t| t > level + tie).count() as f64;
    let empirical = above / n;
    let Some((mean, sd)) = normal_model(thresholds) else {
        return Ok(UnnoticedShare {
            level,
            empirical,
            model: None,
            model_ci: None,
            notice: None,
            notice_ci: None,
        });
    };
    let model = phi((mean - level) / sd);
    let root_n = n.sqrt();
    let t_obs = root_n * (mean - level) / sd;
    let df = n - 1.0;
    let alpha = confidence.alpha();
    // P(T ≤ t_obs | δ) falls from 1 to 0 as δ grows: the lower bound of δ puts t_obs at the
    // upper α/2 point, the upper bound at the lower α/2 point.
    let lower = solve_delta(t_obs, df, alpha / 2.0, true);
    let upper = solve_delta(t_obs, df, alpha / 2.0, false);
    Ok(UnnoticedShare {
        level,
        empirical,
        model: Some(model),
        model_ci: Some((phi(lower / root_n), phi(upper / root_n))),
        notice: Some(phi((level - mean) / sd)),
        notice_ci: Some((phi(-upper / root_n), phi(-lower / root_n))),
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

/// `ln Φ(u)`, accurate to the far lower tail: `Φ` itself below `u = −30`, where it is
/// about 1e-198, would soon underflow; there the Mills ratio's continued fraction
/// `Φ(u) = φ(u) / (x + 1/(x + 2/(x + 3/(x + …))))`, `x = −u`, gives its logarithm (40 terms:
/// relative error below 1e-16 for x ≥ 30).
fn ln_phi(u: f64) -> f64 {
    if u > -30.0 {
        return phi(u).ln();
    }
    let x = -u;
    let mut tail = x;
    for k in (1..=40).rev() {
        tail = x + f64::from(k) / tail;
    }
    -0.5 * x * x - 0.5 * (2.0 * std::f64::consts::PI).ln() - tail.ln()
}

/// `ln P(T ≤ t)` for the noncentral t with `df` degrees of freedom and noncentrality
/// `delta`, by integration over the chi distribution of the denominator:
/// `P(T ≤ t) = ∫₀^∞ Φ(t·s − δ) g(s) ds`, where `s = √(V/df)`, `V ~ χ²(df)` and
/// `ln g(s) = ln 2 + (df/2) ln(df/2) − ln Γ(df/2) + (df − 1) ln s − df·s²/2`.
///
/// The integrand is log-concave in `s` (for df ≥ 1): its peak is found by bisection on the
/// derivative of its logarithm, the integral is taken over the span where it is within
/// e⁻⁴⁵ of the peak, relative to the peak, by Romberg's method to 1e-13, and the peak's
/// logarithm is added back. So the result holds its relative accuracy however small it is
/// (until `ln` itself leaves f64, far below 1e-300), at any df and δ; the series of
/// AS 243 (`dist::nct_cdf`) starts from `exp(−δ²/2)`, which underflows beyond |δ| ≈ 38.
fn ln_nct_lower(t: f64, df: f64, delta: f64) -> f64 {
    const SPAN: f64 = 45.0;
    // (df − 1)·ln s, 0 for df = 1 (also at s = 0).
    let power = |s: f64| if df > 1.0 { (df - 1.0) * s.ln() } else { 0.0 };
    let h = |s: f64| ln_phi(t * s - delta) + power(s) - 0.5 * df * s * s;
    // d/ds of h; φ/Φ at u by logs (it is ≈ −u far in the lower tail).
    let dh = |s: f64| {
        let u = t * s - delta;
        let mills = (-0.5 * u * u - 0.5 * (2.0 * std::f64::consts::PI).ln() - ln_phi(u)).exp();
        t * mills + (df - 1.0) / s - df * s
    };
    // The peak: h' falls from +∞ (or, for df = 1, from its value at 0) through 0.
    let mut hi = 1.0;
    while dh(hi) > 0.0 && hi < 1e300 {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if dh(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let peak = 0.5 * (lo + hi);
    let top = if peak > 0.0 {
        h(peak)
    } else {
        h(f64::MIN_POSITIVE)
    };
    // Where h falls to top − SPAN on either side (or 0 on the left, for df = 1).
    let left = if df > 1.0 || h(0.0) < top - SPAN {
        let (mut a, mut b) = (0.0, peak);
        for _ in 0..200 {
            let mid = 0.5 * (a + b);
            if mid <= a || mid >= b {
                break;
            }
            if h(mid) < top - SPAN {
                a = mid;
            } else {
                b = mid;
            }
        }
        a
    } else {
        0.0
    };
    let mut step = peak.max(1e-3);
    while h(peak + step) > top - SPAN && step < 1e300 {
        step *= 2.0;
    }
    let (mut a, mut b) = (peak, peak + step);
    for _ in 0..200 {
        let mid = 0.5 * (a + b);
        if mid <= a || mid >= b {
            break;
        }
        if h(mid) < top - SPAN {
            b = mid;
        } else {
            a = mid;
        }
    }
    let right = b;
    let f = |s: f64| {
        if s <= 0.0 && df > 1.0 {
            0.0
        } else {
            (h(s) - top).exp()
        }
    };
    let integral = romberg(&f, left, right);
    let ln_norm = std::f64::consts::LN_2 + 0.5 * df * (0.5 * df).ln()
        - statrs::function::gamma::ln_gamma(0.5 * df);
    ln_norm + top + integral.ln()
}

/// Romberg integration of `f` over `[a, b]`: trapezoid sums on 2, 4, 8, … panels with
/// Richardson extrapolation, until two diagonal values agree to 1e-13 relative (at most
/// 2¹⁶ panels).
fn romberg(f: &impl Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    const LEVELS: usize = 17;
    let mut previous: Vec<f64> = vec![0.5 * (b - a) * (f(a) + f(b))];
    let mut best = previous[0];
    for level in 1..LEVELS {
        let panels = 1_u32 << level;
        let width = (b - a) / f64::from(panels);
        let new_points: f64 = (0..panels / 2)
            .map(|i| f(a + width * f64::from(2 * i + 1)))
            .sum();
        let mut row = vec![0.5 * previous[0] + width * new_points];
        let mut factor = 1.0;
        for j in 1..=level {
            factor *= 4.0;
            let r = row[j - 1] + (row[j - 1] - previous[j - 1]) / (factor - 1.0);
            row.push(r);
        }
        let estimate = row[level];
        let converged = level >= 4 && (estimate - best).abs() <= 1e-13 * estimate.abs();
        best = estimate;
        previous = row;
        if converged {
            break;
        }
    }
    best
}

/// `P(T ≤ t)` for the noncentral t with `df` (≥ 1) degrees of freedom and noncentrality
/// `delta`, to a relative accuracy of about 1e-12 in both tails: the smaller of the CDF and
/// its complement is integrated (`P(T > t) = P(−T < −t)`, `−T` having noncentrality `−δ`),
/// the other is one minus it. Checked against SciPy's `scipy.stats.nct` at df = 1, 9, 199
/// and 1999 to 1e-6 relative wherever it exceeds 1e-300 (`analysis/tests/jnd.rs`; measured
/// worst 9e-11).
#[must_use]
pub fn noncentral_t_cdf(t: f64, df: f64, delta: f64) -> f64 {
    let lower = ln_nct_lower(t, df, delta);
    if lower < -std::f64::consts::LN_2 {
        lower.exp()
    } else {
        -(ln_nct_lower(-t, df, -delta)).exp_m1()
    }
}

/// `P(T > t)` for the noncentral t, with the same relative accuracy as [`noncentral_t_cdf`]
/// in the upper tail.
#[must_use]
pub fn noncentral_t_sf(t: f64, df: f64, delta: f64) -> f64 {
    noncentral_t_cdf(-t, df, -delta)
}

/// The noncentrality δ with `P(T ≤ t | df, δ) = p` (`upper` false) or `P(T > t | df, δ) = p`
/// (`upper` true), for a small tail probability `p` (< ½): the CDF falls monotonically in δ.
/// The logarithm of the tail probability is matched, by the Illinois variant of regula falsi
/// in a bracket around `t` that widens (without bound) until it holds the root, to 1e-14
/// relative in δ. Any n: the tails are integrated, not summed ([`noncentral_t_cdf`]).
fn solve_delta(t: f64, df: f64, p: f64, upper: bool) -> f64 {
    let target = p.ln();
    // Decreasing in δ for the lower tail, increasing for the upper: g rises with δ.
    let g = |d: f64| {
        if upper {
            ln_nct_lower(-t, df, -d) - target
        } else {
            target - ln_nct_lower(t, df, d)
        }
    };
    // The spread of T about δ: √(1 + t²/(2 df)) (normal approximation of the noncentral t).
    let scale = (1.0 + t * t / (2.0 * df)).sqrt();
    let mut half = 12.0 * scale;
    let (mut lo, mut hi) = (t - half, t + half);
    let (mut glo, mut ghi) = (g(lo), g(hi));
    for _ in 0..60 {
        if glo < 0.0 {
            break;
        }
        half *= 2.0;
        lo = t - half;
        glo = g(lo);
    }
    for _ in 0..60 {
        if ghi > 0.0 {
            break;
        }
        half *= 2.0;
        hi = t + half;
        ghi = g(hi);
    }
    let mut side = 0;
    for _ in 0..200 {
        if hi - lo <= 1e-14 * (1.0 + lo.abs().max(hi.abs())) {
            break;
        }
        let mut mid = (lo * ghi - hi * glo) / (ghi - glo);
        if !(mid > lo && mid < hi) {
            mid = 0.5 * (lo + hi);
        }
        let gm = g(mid);
        if gm < 0.0 {
            lo = mid;
            glo = gm;
            if side == -1 {
                ghi *= 0.5;
            }
            side = -1;
        } else {
            hi = mid;
            ghi = gm;
            if side == 1 {
                glo *= 0.5;
            }
            side = 1;
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
    /// The level grid ties were decided on, when the tracks had one.
    pub grid: Option<LevelGrid>,
}

/// Most levels tabulated; more distinct levels are thinned evenly.
const MAX_ROWS: usize = 24;

/// The JND analysis: the distribution of `thresholds` and, at every encoded level (thinned to
/// at most 24, plus the levels of the thresholds' range when nothing was encoded), the share
/// of viewers who would not notice (ties decided on the level `grid`, see [`LevelGrid`]) and
/// the compression ratio per clip.
///
/// # Errors
/// As [`unnoticed_share`] and [`summarize`].
pub fn jnd_analysis(
    thresholds: &[(u32, f64)],
    encoded: &[EncodedLevel],
    grid: Option<LevelGrid>,
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
                share: unnoticed_share_on(&values, level, grid, confidence)?,
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
        grid,
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
                let (l, u) = s.notice_ci?;
                Some((x, s.notice?, l, u))
            })
            .collect()
    }
}
