//! Maximum-likelihood psychometric functions for 2AFC data (Weibull and logistic, guess rate
//! 0.5, lapse rate λ) and a parametric bootstrap CI of the threshold at a chosen percent correct.
//!
//! ψ(x) = γ + (1 − γ − λ)·F(x), with F(x) = 1 − exp(−(x/α)^β) (Weibull) or
//! F(x) = 1 / (1 + exp(−β(x − α))) (logistic) (Wichmann & Hill 2001). The thesis (§5.4) only
//! averages staircase reversals; the fit uses every 2AFC trial instead and gives a CI.

use std::collections::BTreeMap;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::confidence::Confidence;
use crate::error::AnalysisError;

/// One two-alternative forced-choice trial.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TwoAfcTrial {
    /// Stimulus level (e.g. t_L); must be > 0 for the Weibull.
    pub level: f64,
    /// Whether the subject picked the correct (original) motion.
    pub correct: bool,
}

/// Shape of F.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[non_exhaustive]
pub enum Shape {
    /// F(x) = 1 − exp(−(x/α)^β), x > 0.
    Weibull,
    /// F(x) = 1 / (1 + exp(−β(x − α))).
    Logistic,
}

/// How the lapse rate λ is treated.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[non_exhaustive]
pub enum Lapse {
    /// λ fixed at the given value.
    Fixed(f64),
    /// λ estimated within [0, max] (Wichmann & Hill use max = 0.06).
    Free {
        /// Upper bound of λ.
        max: f64,
    },
}

/// Options of a psychometric fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitOptions {
    /// Shape of F.
    pub shape: Shape,
    /// Guess rate γ (0.5 for 2AFC).
    pub guess_rate: f64,
    /// Lapse treatment.
    pub lapse: Lapse,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            shape: Shape::Weibull,
            guess_rate: 0.5,
            lapse: Lapse::Free { max: 0.06 },
        }
    }
}

/// Trials grouped by level: (level, trials, correct).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupedTrials {
    /// (level, number of trials, number correct), sorted by level.
    pub levels: Vec<(f64, u32, u32)>,
}

impl GroupedTrials {
    /// Groups trials by exact level.
    pub fn from_trials(trials: &[TwoAfcTrial]) -> Self {
        let mut map: BTreeMap<u64, (f64, u32, u32)> = BTreeMap::new();
        for t in trials {
            // Order-preserving key for non-negative and negative floats alike.
            let bits = t.level.to_bits();
            let key = if t.level.is_sign_negative() {
                !bits
            } else {
                bits | (1 << 63)
            };
            let e = map.entry(key).or_insert((t.level, 0, 0));
            e.1 += 1;
            e.2 += u32::from(t.correct);
        }
        Self {
            levels: map.into_values().collect(),
        }
    }
}

/// A fitted psychometric function.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PsychometricFit {
    /// Shape of F.
    pub shape: Shape,
    /// Location α (the Weibull scale, the logistic midpoint), in level units.
    pub alpha: f64,
    /// Slope β.
    pub beta: f64,
    /// Guess rate γ.
    pub guess_rate: f64,
    /// Lapse rate λ.
    pub lapse: f64,
    /// Log-likelihood at the optimum, Σ k ln ψ + (n − k) ln(1 − ψ) (binomial coefficients
    /// omitted).
    pub log_likelihood: f64,
    /// Number of trials fitted.
    pub trials: usize,
}

fn f_and_complement(shape: Shape, alpha: f64, beta: f64, x: f64) -> (f64, f64) {
    match shape {
        Shape::Weibull => {
            if x <= 0.0 {
                return (0.0, 1.0);
            }
            let e = (-(x / alpha).powf(beta)).exp();
            (1.0 - e, e)
        }
        Shape::Logistic => {
            let z = beta * (x - alpha);
            (1.0 / (1.0 + (-z).exp()), 1.0 / (1.0 + z.exp()))
        }
    }
}

impl PsychometricFit {
    /// Probability correct ψ(x).
    pub fn probability(&self, x: f64) -> f64 {
        let (f, _) = f_and_complement(self.shape, self.alpha, self.beta, x);
        self.guess_rate + (1.0 - self.guess_rate - self.lapse) * f
    }

    /// The level at which ψ equals `percent_correct` (a fraction, e.g. 0.75); `None` when that
    /// proportion lies outside (γ, 1 − λ).
    pub fn threshold(&self, percent_correct: f64) -> Option<f64> {
        let f = (percent_correct - self.guess_rate) / (1.0 - self.guess_rate - self.lapse);
        if !(f > 0.0 && f < 1.0) {
            return None;
        }
        Some(match self.shape {
            Shape::Weibull => self.alpha * (-(-f).ln_1p()).powf(1.0 / self.beta),
            Shape::Logistic => self.alpha + (f / (1.0 - f)).ln() / self.beta,
        })
    }
}

/// Negative log-likelihood of grouped data.
fn nll(shape: Shape, alpha: f64, beta: f64, gamma: f64, lapse: f64, data: &GroupedTrials) -> f64 {
    let mut total = 0.0;
    for &(x, n, k) in &data.levels {
        let (f, fc) = f_and_complement(shape, alpha, beta, x);
        let p = gamma + (1.0 - gamma - lapse) * f;
        let q = (1.0 - gamma - lapse) * fc + lapse;
        if k > 0 {
            total -= f64::from(k) * p.ln();
        }
        if n > k {
            total -= f64::from(n - k) * q.ln();
        }
    }
    if total.is_nan() { f64::INFINITY } else { total }
}

struct Param {
    shape: Shape,
    gamma: f64,
    lapse: Lapse,
}

impl Param {
    /// Unconstrained vector → (α, β, λ).
    fn decode(&self, v: &[f64]) -> (f64, f64, f64) {
        let alpha = match self.shape {
            Shape::Weibull => v[0].exp(),
            Shape::Logistic => v[0],
        };
        let beta = v[1].exp();
        let lapse = match self.lapse {
            Lapse::Fixed(l) => l,
            // λ = max·(1 + sin u)/2 reaches both bounds exactly, so a boundary optimum is found.
            Lapse::Free { max } => max * 0.5 * (1.0 + v[2].sin()),
        };
        (alpha, beta, lapse)
    }

    fn encode(&self, alpha: f64, beta: f64, lapse: f64) -> Vec<f64> {
        let a = match self.shape {
            Shape::Weibull => alpha.ln(),
            Shape::Logistic => alpha,
        };
        let mut v = vec![a, beta.ln()];
        if let Lapse::Free { max } = self.lapse {
            v.push((2.0 * lapse / max - 1.0).clamp(-1.0, 1.0).asin());
        }
        v
    }
}

/// Nelder–Mead simplex minimiser (standard coefficients 1, 2, ½, ½).
fn nelder_mead(
    f: &dyn Fn(&[f64]) -> f64,
    start: &[f64],
    steps: &[f64],
    max_iter: usize,
    ftol: f64,
) -> (Vec<f64>, f64) {
    let dim = start.len();
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(dim + 1);
    simplex.push((start.to_vec(), f(start)));
    for i in 0..dim {
        let mut p = start.to_vec();
        p[i] += steps[i];
        let v = f(&p);
        simplex.push((p, v));
    }
    for _ in 0..max_iter {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let best = simplex[0].1;
        let worst = simplex[dim].1;
        let spread = simplex
            .iter()
            .skip(1)
            .flat_map(|(p, _)| p.iter().zip(&simplex[0].0).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max);
        if (worst - best).abs() <= ftol * (best.abs() + 1e-300) && spread < 1e2 * ftol {
            break;
        }
        let centroid: Vec<f64> = (0..dim)
            .map(|j| simplex[..dim].iter().map(|(p, _)| p[j]).sum::<f64>() / dim as f64)
            .collect();
        let along = |t: f64| -> Vec<f64> {
            centroid
                .iter()
                .zip(&simplex[dim].0)
                .map(|(c, w)| c + t * (c - w))
                .collect()
        };
        let reflected = along(1.0);
        let fr = f(&reflected);
        if fr < simplex[0].1 {
            let expanded = along(2.0);
            let fe = f(&expanded);
            simplex[dim] = if fe < fr {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
        } else if fr < simplex[dim - 1].1 {
            simplex[dim] = (reflected, fr);
        } else {
            let (contracted, fc) = if fr < worst {
                let c = along(0.5);
                let v = f(&c);
                (c, v)
            } else {
                let c = along(-0.5);
                let v = f(&c);
                (c, v)
            };
            if fc < worst.min(fr) {
                simplex[dim] = (contracted, fc);
            } else {
                let best_point = simplex[0].0.clone();
                for entry in simplex.iter_mut().skip(1) {
                    let p: Vec<f64> = best_point
                        .iter()
                        .zip(&entry.0)
                        .map(|(b, x)| b + 0.5 * (x - b))
                        .collect();
                    let v = f(&p);
                    *entry = (p, v);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (p, v) = simplex.swap_remove(0);
    (p, v)
}

fn check_options(options: &FitOptions) -> Result<(), AnalysisError> {
    if !(options.guess_rate >= 0.0 && options.guess_rate < 1.0) {
        return Err(AnalysisError::InvalidParameter {
            name: "guess_rate",
            value: options.guess_rate,
            reason: "must lie in [0, 1)",
        });
    }
    let (name, value) = match options.lapse {
        Lapse::Fixed(l) => ("lapse", l),
        Lapse::Free { max } => ("lapse max", max),
    };
    if !(value >= 0.0 && value < 1.0 - options.guess_rate) {
        return Err(AnalysisError::InvalidParameter {
            name,
            value,
            reason: "must lie in [0, 1 − guess rate)",
        });
    }
    if matches!(options.lapse, Lapse::Free { max } if max <= 0.0) {
        return Err(AnalysisError::InvalidParameter {
            name,
            value,
            reason: "a free lapse needs max > 0",
        });
    }
    Ok(())
}

fn check_data(data: &GroupedTrials, shape: Shape) -> Result<(), AnalysisError> {
    for (index, &(x, _, _)) in data.levels.iter().enumerate() {
        if !x.is_finite() {
            return Err(AnalysisError::NonFinite {
                what: "2AFC level",
                index,
                value: x,
            });
        }
        if shape == Shape::Weibull && x <= 0.0 {
            return Err(AnalysisError::InvalidParameter {
                name: "2AFC level",
                value: x,
                reason: "the Weibull needs levels > 0",
            });
        }
    }
    if data.levels.len() < 2 {
        return Err(AnalysisError::TooFew {
            what: "psychometric fit (distinct levels)",
            needed: 2,
            got: data.levels.len(),
        });
    }
    Ok(())
}

/// Minimises the negative log-likelihood from several starts. `ftol` is the relative spread of
/// the simplex values at which Nelder–Mead stops: 1e-13 for a reported fit, looser for
/// bootstrap replicates whose thresholds only enter percentiles.
fn minimise(
    data: &GroupedTrials,
    options: &FitOptions,
    starts: &[Vec<f64>],
    ftol: f64,
) -> (Vec<f64>, f64) {
    let param = Param {
        shape: options.shape,
        gamma: options.guess_rate,
        lapse: options.lapse,
    };
    let objective = |v: &[f64]| {
        let (a, b, l) = param.decode(v);
        nll(param.shape, a, b, param.gamma, l, data)
    };
    let steps: Vec<f64> = match (options.shape, options.lapse) {
        (_, Lapse::Fixed(_)) => vec![0.2, 0.3],
        (_, Lapse::Free { .. }) => vec![0.2, 0.3, 0.5],
    };
    let mut best: Option<(Vec<f64>, f64)> = None;
    for s in starts {
        let r = nelder_mead(&objective, s, &steps, 4000, ftol);
        if best.as_ref().is_none_or(|b| r.1 < b.1) {
            best = Some(r);
        }
    }
    let (mut point, mut value) =
        best.unwrap_or_else(|| (starts.first().cloned().unwrap_or_default(), f64::INFINITY));
    // Restarts from the best vertex: Nelder–Mead can stall on a collapsed simplex.
    for _ in 0..3 {
        let small: Vec<f64> = steps.iter().map(|s| s * 0.1).collect();
        let r = nelder_mead(&objective, &point, &small, 4000, ftol);
        if r.1 < value {
            point = r.0;
            value = r.1;
        } else {
            break;
        }
    }
    (point, value)
}

/// Fits ψ by maximum likelihood to grouped 2AFC data.
///
/// # Errors
/// [`AnalysisError::TooFew`] for fewer than two distinct levels, invalid options or levels, or
/// when no finite likelihood was found.
pub fn fit_grouped(
    data: &GroupedTrials,
    options: &FitOptions,
) -> Result<PsychometricFit, AnalysisError> {
    check_options(options)?;
    check_data(data, options.shape)?;
    let param = Param {
        shape: options.shape,
        gamma: options.guess_rate,
        lapse: options.lapse,
    };
    let xs: Vec<f64> = data.levels.iter().map(|l| l.0).collect();
    let (lo, hi) = (xs[0], xs[xs.len() - 1]);
    let range = (hi - lo).max(f64::EPSILON);
    let start_lapse = match options.lapse {
        Lapse::Fixed(l) => l,
        Lapse::Free { max } => 0.25 * max,
    };
    let mut starts = Vec::new();
    for frac in [0.25, 0.5, 0.75] {
        let alpha = lo + frac * range;
        let betas: [f64; 3] = match options.shape {
            Shape::Weibull => [1.0, 3.0, 8.0],
            Shape::Logistic => [2.0 / range, 6.0 / range, 20.0 / range],
        };
        for beta in betas {
            starts.push(param.encode(alpha, beta, start_lapse));
        }
    }
    let (point, value) = minimise(data, options, &starts, 1e-13);
    finish_fit(&param, &point, value, data)
}

fn finish_fit(
    param: &Param,
    point: &[f64],
    value: f64,
    data: &GroupedTrials,
) -> Result<PsychometricFit, AnalysisError> {
    if !value.is_finite() {
        return Err(AnalysisError::TooFew {
            what: "psychometric fit (finite likelihood)",
            needed: 1,
            got: 0,
        });
    }
    let (alpha, beta, lapse) = param.decode(point);
    let trials = data.levels.iter().map(|l| l.1 as usize).sum();
    Ok(PsychometricFit {
        shape: param.shape,
        alpha,
        beta,
        guess_rate: param.gamma,
        lapse,
        log_likelihood: -value,
        trials,
    })
}

/// Fits ψ to individual trials (grouped by level first).
///
/// # Errors
/// As [`fit_grouped`].
pub fn fit(trials: &[TwoAfcTrial], options: &FitOptions) -> Result<PsychometricFit, AnalysisError> {
    fit_grouped(&GroupedTrials::from_trials(trials), options)
}

/// A bootstrap confidence interval of a threshold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BootstrapCi {
    /// Threshold of the fit to the data.
    pub threshold: f64,
    /// Lower percentile bound.
    pub lower: f64,
    /// Upper percentile bound.
    pub upper: f64,
    /// Replicates whose threshold was defined.
    pub replicates: usize,
    /// Replicates whose fit failed or whose threshold was undefined.
    pub failed: usize,
    /// Confidence level.
    pub confidence: Confidence,
    /// The RNG seed (ChaCha8), logged so the interval can be reproduced.
    pub seed: u64,
}

/// Options of the parametric bootstrap.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BootstrapOptions {
    /// Number of simulated data sets.
    pub replicates: usize,
    /// Confidence level of the percentile interval.
    pub confidence: Confidence,
    /// Seed of the ChaCha8 generator.
    pub seed: u64,
}

impl Default for BootstrapOptions {
    fn default() -> Self {
        Self {
            replicates: 1000,
            confidence: Confidence::default(),
            seed: 0x5EED,
        }
    }
}

/// Parametric bootstrap of the threshold at `percent_correct`: simulates binomial data at the
/// observed levels and trial counts from the fitted ψ, refits each, and takes percentiles of
/// the thresholds (linear interpolation, as numpy.percentile).
///
/// # Errors
/// As [`fit_grouped`]; [`AnalysisError::InvalidParameter`] when the fitted threshold at
/// `percent_correct` is undefined or fewer than two replicates are asked for.
pub fn bootstrap_threshold(
    data: &GroupedTrials,
    options: &FitOptions,
    percent_correct: f64,
    boot: &BootstrapOptions,
) -> Result<(PsychometricFit, BootstrapCi), AnalysisError> {
    const MAX_REPLICATES: usize = 1_000_000;
    if boot.replicates < 2 || boot.replicates > MAX_REPLICATES {
        return Err(AnalysisError::InvalidParameter {
            name: "replicates",
            value: boot.replicates as f64,
            reason: "must lie in [2, 1e6]",
        });
    }
    let fitted = fit_grouped(data, options)?;
    let threshold = fitted
        .threshold(percent_correct)
        .ok_or(AnalysisError::InvalidParameter {
            name: "percent_correct",
            value: percent_correct,
            reason: "outside (guess rate, 1 − lapse) of the fit",
        })?;
    let mut thresholds = Vec::with_capacity(boot.replicates);
    let mut failed = 0;
    for replicate in replicate_fits(data, options, &fitted, boot) {
        match replicate.and_then(|f| f.threshold(percent_correct)) {
            Some(t) if t.is_finite() => thresholds.push(t),
            _ => failed += 1,
        }
    }
    if thresholds.len() < 2 {
        return Err(AnalysisError::TooFew {
            what: "bootstrap replicates with a threshold",
            needed: 2,
            got: thresholds.len(),
        });
    }
    thresholds.sort_by(f64::total_cmp);
    let tail = boot.confidence.alpha() / 2.0;
    let ci = BootstrapCi {
        threshold,
        lower: percentile(&thresholds, tail),
        upper: percentile(&thresholds, 1.0 - tail),
        replicates: thresholds.len(),
        failed,
        confidence: boot.confidence,
        seed: boot.seed,
    };
    Ok((fitted, ci))
}

/// The parametric bootstrap's refits: `boot.replicates` binomial data sets simulated at the
/// observed levels and trial counts from `fitted`, each refitted from `fitted`'s parameters
/// (`None` where a refit failed). The same seed gives the same replicates, so the threshold
/// interval and the curve band of one seed come from one set of fits.
fn replicate_fits(
    data: &GroupedTrials,
    options: &FitOptions,
    fitted: &PsychometricFit,
    boot: &BootstrapOptions,
) -> Vec<Option<PsychometricFit>> {
    let param = Param {
        shape: options.shape,
        gamma: options.guess_rate,
        lapse: options.lapse,
    };
    let start = param.encode(
        fitted.alpha,
        fitted.beta,
        match options.lapse {
            Lapse::Fixed(l) => l,
            // Start inside the bounds so the simplex can move in both directions.
            Lapse::Free { max } => fitted.lapse.clamp(0.05 * max, 0.95 * max),
        },
    );
    let probabilities: Vec<f64> = data
        .levels
        .iter()
        .map(|l| fitted.probability(l.0))
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(boot.seed);
    let mut sim = data.clone();
    (0..boot.replicates)
        .map(|_| {
            for (level, p) in sim.levels.iter_mut().zip(&probabilities) {
                level.2 = (0..level.1)
                    .map(|_| u32::from(rng.random::<f64>() < *p))
                    .sum();
            }
            let (point, value) = minimise(&sim, options, std::slice::from_ref(&start), 1e-9);
            finish_fit(&param, &point, value, &sim).ok()
        })
        .collect()
}

/// A pointwise confidence band of the fitted psychometric function.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurveBand {
    /// Confidence level of the band.
    pub confidence: Confidence,
    /// (level, lower ψ, upper ψ), in increasing level.
    pub points: Vec<(f64, f64, f64)>,
}

/// Pointwise parametric-bootstrap band of ψ at each of `levels`: the percentiles (as
/// [`bootstrap_threshold`]'s) of ψ(x) over the replicate fits. With the same `boot` it refits
/// the very replicates that [`bootstrap_threshold`] does, so the band and the threshold
/// interval agree.
///
/// # Errors
/// As [`bootstrap_threshold`].
pub fn bootstrap_band(
    data: &GroupedTrials,
    options: &FitOptions,
    boot: &BootstrapOptions,
    levels: &[f64],
) -> Result<CurveBand, AnalysisError> {
    if boot.replicates < 2 || boot.replicates > 1_000_000 {
        return Err(AnalysisError::InvalidParameter {
            name: "replicates",
            value: boot.replicates as f64,
            reason: "must lie in [2, 1e6]",
        });
    }
    let fitted = fit_grouped(data, options)?;
    let fits: Vec<PsychometricFit> = replicate_fits(data, options, &fitted, boot)
        .into_iter()
        .flatten()
        .collect();
    if fits.len() < 2 {
        return Err(AnalysisError::TooFew {
            what: "bootstrap replicates with a fit",
            needed: 2,
            got: fits.len(),
        });
    }
    let tail = boot.confidence.alpha() / 2.0;
    let mut column = Vec::with_capacity(fits.len());
    let points = levels
        .iter()
        .map(|&x| {
            column.clear();
            column.extend(fits.iter().map(|f| f.probability(x)));
            column.sort_by(f64::total_cmp);
            (
                x,
                percentile(&column, tail),
                percentile(&column, 1.0 - tail),
            )
        })
        .collect();
    Ok(CurveBand {
        confidence: boot.confidence,
        points,
    })
}

/// numpy.percentile with linear interpolation on sorted data, q in [0, 1].
pub(crate) fn percentile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let i = pos.floor() as usize;
    let frac = pos - i as f64;
    if i + 1 < sorted.len() {
        sorted[i] + frac * (sorted[i + 1] - sorted[i])
    } else {
        sorted[sorted.len() - 1]
    }
}
