//! Subject bias and inconsistency by maximum likelihood (Li & Bampis 2017, "Recover subjective
//! quality scores from noisy measurements"; Netflix sureal's `MaximumLikelihoodEstimationModel`).
//!
//! Every rating is modelled as X_esr = ψ_e + Δ_s + ν_s·Z + a_c(e)·Z', Z, Z' standard normal:
//! ψ_e the true quality of stimulus e, Δ_s subject s's bias, ν_s its inconsistency, a_c the
//! ambiguity of content (clip) c. The likelihood is maximised by sureal's own iteration (its
//! default "simplified" gradient method): from ψ = the pooled MOS, Δ = 0, ν_s and a_c the SDs of
//! the residuals per subject and per content, each pass updates Δ (weighted mean residual), ν
//! and a (one Newton step each on their score equations, clipped at 0) and ψ (weighted mean),
//! every update mixed in at 10 % (sureal's refresh rate), until ψ moves less than 10⁻⁸
//! (Euclidean norm) in a pass or after 10,000 passes; then the biases are shifted to mean 0
//! (and ψ by the same). Standard errors are the inverse square roots of the information
//! sums sureal uses; the inconsistency's 95 % interval is sureal's χ² interval on the subject's
//! number of ratings. `tests/sureal_interop.rs` compares the result with sureal 0.9.0's.

use std::collections::BTreeMap;

use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use crate::descriptive::Rating;
use crate::error::AnalysisError;
use crate::findings::ConditionInfo;

/// sureal's refresh rate: the share of each update mixed into the estimate.
const REFRESH: f64 = 0.1;
/// sureal's `delta_thr`.
const DELTA: f64 = 1e-8;
/// sureal's `MAX_ITR`.
const MAX_PASSES: usize = 10_000;
/// sureal's 95 % normal quantile.
const Z95: f64 = 1.95996;

/// One subject's estimates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SubjectEstimate {
    /// Subject.
    pub subject: u32,
    /// Bias Δ_s (scale units; the biases have mean 0).
    pub bias: f64,
    /// Half-width of Δ_s's 95 % interval (1.96 standard errors).
    pub bias_ci: f64,
    /// Inconsistency ν_s (an SD, scale units).
    pub inconsistency: f64,
    /// ν_s's 95 % interval (χ² on the subject's ratings).
    pub inconsistency_ci: (f64, f64),
    /// Ratings of the subject.
    pub ratings: usize,
}

/// The fitted model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SubjectModel {
    /// (condition, quality ψ_e, half-width of its 95 % interval), in condition order.
    pub quality: Vec<(u32, f64, f64)>,
    /// Per subject, in subject order.
    pub subjects: Vec<SubjectEstimate>,
    /// (content = clip, ambiguity a_c), in order of first appearance among the conditions.
    pub contents: Vec<(String, f64)>,
    /// Passes run.
    pub passes: usize,
}

/// One rating, indexed.
struct Obs {
    e: usize,
    s: usize,
    c: usize,
    x: f64,
}

fn population_sd(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// Fits the model to `ratings`; a condition's content is its clip (`conditions`).
///
/// # Errors
/// [`AnalysisError::TooFew`] without ratings; [`AnalysisError::NonFinite`] for a score that is
/// not finite; [`AnalysisError::InvalidParameter`] for a rating of a condition not in
/// `conditions`.
pub fn fit(
    ratings: &[Rating],
    conditions: &[ConditionInfo],
) -> Result<SubjectModel, AnalysisError> {
    if ratings.is_empty() {
        return Err(AnalysisError::TooFew {
            what: "ratings for the subject model",
            needed: 1,
            got: 0,
        });
    }
    let (obs, stimuli, subjects, content_names) = index(ratings, conditions)?;
    let (ne, ns, nc) = (stimuli.len(), subjects.len(), content_names.len());
    // Initial values: the pooled MOS, residual SDs per subject and per content.
    let mut sum = vec![0.0; ne];
    let mut count = vec![0.0; ne];
    for o in &obs {
        sum[o.e] += o.x;
        count[o.e] += 1.0;
    }
    let mut x_e: Vec<f64> = sum.iter().zip(&count).map(|(s, n)| s / n).collect();
    let mut per_s: Vec<Vec<f64>> = vec![Vec::new(); ns];
    let mut per_c: Vec<Vec<f64>> = vec![Vec::new(); nc];
    for o in &obs {
        per_s[o.s].push(o.x - x_e[o.e]);
        per_c[o.c].push(o.x - x_e[o.e]);
    }
    let mut v_s: Vec<f64> = per_s.iter().map(|v| population_sd(v)).collect();
    let mut a_c: Vec<f64> = per_c.iter().map(|v| population_sd(v)).collect();
    // A content nobody rated keeps sureal's NaN out of every sum (it has no observation).
    for a in &mut a_c {
        if a.is_nan() {
            *a = 0.0;
        }
    }
    let mut b_s = vec![0.0; ns];
    let (x_std, b_std, passes) = iterate(&obs, &mut x_e, &mut b_s, &mut v_s, &mut a_c);
    let mean_b = b_s.iter().sum::<f64>() / ns as f64;
    for b in &mut b_s {
        *b -= mean_b;
    }
    for x in &mut x_e {
        *x += mean_b;
    }
    let subjects_out = subjects
        .iter()
        .enumerate()
        .map(|(s, &id)| {
            let n = per_s[s].len();
            let k = n as f64;
            let ci = ChiSquared::new(k).map_or((f64::NAN, f64::NAN), |chi| {
                (
                    v_s[s] * (k / chi.inverse_cdf(0.975)).sqrt(),
                    v_s[s] * (k / chi.inverse_cdf(0.025)).sqrt(),
                )
            });
            SubjectEstimate {
                subject: id,
                bias: b_s[s],
                bias_ci: Z95 * b_std[s],
                inconsistency: v_s[s],
                inconsistency_ci: ci,
                ratings: n,
            }
        })
        .collect();
    Ok(SubjectModel {
        quality: stimuli
            .iter()
            .enumerate()
            .map(|(e, &id)| (id, x_e[e], Z95 * x_std[e]))
            .collect(),
        subjects: subjects_out,
        contents: content_names.into_iter().zip(a_c).collect(),
        passes,
    })
}

/// sureal's passes from the initial values in `x_e`, `b_s`, `v_s`, `a_c` until ψ settles:
/// the standard errors of ψ and Δ of the last pass, and the passes run.
fn iterate(
    obs: &[Obs],
    x_e: &mut [f64],
    b_s: &mut [f64],
    v_s: &mut [f64],
    a_c: &mut [f64],
) -> (Vec<f64>, Vec<f64>, usize) {
    let (ne, ns, nc) = (x_e.len(), b_s.len(), a_c.len());
    let (mut x_std, mut b_std) = (vec![0.0; ne], vec![0.0; ns]);
    let mut passes = 0;
    loop {
        let x_prev = x_e.to_vec();
        // Δ_s.
        let (mut num, mut den) = (vec![0.0; ns], vec![0.0; ns]);
        for o in obs {
            let w = v_s[o.s].powi(2) + a_c[o.c].powi(2);
            num[o.s] += (o.x - x_e[o.e]) / w;
            den[o.s] += 1.0 / w;
        }
        for s in 0..ns {
            b_s[s] = b_s[s] * (1.0 - REFRESH) + num[s] / den[s] * REFRESH;
            b_std[s] = 1.0 / den[s].max(0.0).sqrt();
        }
        // ν_s.
        let (mut num, mut den) = (vec![0.0; ns], vec![0.0; ns]);
        for o in obs {
            let (v, a) = (v_s[o.s], a_c[o.c]);
            let r = o.x - x_e[o.e] - b_s[o.s];
            let add = v * v + a * a;
            let sub = v * v - a * a;
            num[o.s] += -v / add + v * r * r / (add * add);
            let poly = a.powi(4) - 3.0 * v.powi(4) - 2.0 * v * v * a * a;
            den[o.s] += sub / (add * add) + r * r * poly / add.powi(4);
        }
        for s in 0..ns {
            let new = v_s[s] - num[s] / den[s];
            v_s[s] = (v_s[s] * (1.0 - REFRESH) + new * REFRESH).max(0.0);
        }
        // a_c.
        let (mut num, mut den) = (vec![0.0; nc], vec![0.0; nc]);
        for o in obs {
            let (v, a) = (v_s[o.s], a_c[o.c]);
            let r = o.x - x_e[o.e] - b_s[o.s];
            let add = v * v + a * a;
            let sub = v * v - a * a;
            num[o.c] += -a / add + a * r * r / (add * add);
            let poly = v.powi(4) - 3.0 * a.powi(4) - 2.0 * v * v * a * a;
            den[o.c] += -sub / (add * add) + r * r * poly / add.powi(4);
        }
        for c in 0..nc {
            let new = a_c[c] - num[c] / den[c];
            a_c[c] = (a_c[c] * (1.0 - REFRESH) + new * REFRESH).max(0.0);
        }
        // ψ_e.
        let (mut num, mut den) = (vec![0.0; ne], vec![0.0; ne]);
        for o in obs {
            let w = v_s[o.s].powi(2) + a_c[o.c].powi(2);
            num[o.e] += (o.x - b_s[o.s]) / w;
            den[o.e] += 1.0 / w;
        }
        for e in 0..ne {
            x_e[e] = x_e[e] * (1.0 - REFRESH) + num[e] / den[e] * REFRESH;
            x_std[e] = 1.0 / den[e].max(0.0).sqrt();
        }
        passes += 1;
        let delta = x_prev
            .iter()
            .zip(x_e.iter())
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        // A NaN (a zero variance somewhere) ends the loop as sureal's comparison would not.
        if delta.is_nan() || delta < DELTA || passes >= MAX_PASSES {
            break;
        }
    }
    (x_std, b_std, passes)
}

/// The ratings as observations indexed by stimulus, subject and content; the stimuli's and
/// subjects' ids in index order, and the contents' names.
type Indexed = (Vec<Obs>, Vec<u32>, Vec<u32>, Vec<String>);

fn index(ratings: &[Rating], conditions: &[ConditionInfo]) -> Result<Indexed, AnalysisError> {
    let mut content_names: Vec<String> = Vec::new();
    let mut content_of: BTreeMap<u32, usize> = BTreeMap::new();
    for c in conditions {
        let idx = if let Some(i) = content_names.iter().position(|n| *n == c.clip) {
            i
        } else {
            content_names.push(c.clip.clone());
            content_names.len() - 1
        };
        content_of.insert(c.id, idx);
    }
    let stimuli: Vec<u32> = {
        let mut v: Vec<u32> = ratings.iter().map(|r| r.condition).collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    let subjects: Vec<u32> = {
        let mut v: Vec<u32> = ratings.iter().map(|r| r.subject).collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    let mut obs = Vec::with_capacity(ratings.len());
    for (index, r) in ratings.iter().enumerate() {
        if !r.score.is_finite() {
            return Err(AnalysisError::NonFinite {
                what: "rating",
                index,
                value: r.score,
            });
        }
        let c = *content_of
            .get(&r.condition)
            .ok_or(AnalysisError::InvalidParameter {
                name: "condition",
                value: f64::from(r.condition),
                reason: "rated but not among the conditions",
            })?;
        obs.push(Obs {
            e: stimuli.binary_search(&r.condition).unwrap_or(0),
            s: subjects.binary_search(&r.subject).unwrap_or(0),
            c,
            x: r.score,
        });
    }
    Ok((obs, stimuli, subjects, content_names))
}
