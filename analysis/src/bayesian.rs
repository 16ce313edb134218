//! Bayesian psychometric fits of 2AFC data with a beta-binomial likelihood, the model and
//! procedure of psignifit 4 (Schütt, Harmeling, Macke & Wichmann 2016, *Vision Research* 122),
//! so that a lab can check them against psignifit itself (`tests/psignifit_interop.rs` runs
//! psignifit 4.3 from PyPI on the same data).
//!
//! ψ(x) = γ + (1 − γ − λ) S(x; m, w), γ = ½ (2AFC); S a sigmoid with threshold m (S(m) = ½)
//! and width w (the distance from S = 0.05 to S = 0.95): a normal, logistic or Gumbel CDF, the
//! Gumbel of ln x being the Weibull. Each level's k correct of n is beta-binomial with mean
//! ψ(x) and overdispersion η (η = 0 is binomial): the blocks' counts may scatter more than a
//! binomial's, as adaptive and pooled data do.
//!
//! Priors (psignifit's defaults, stated in every report): m uniform over the stimulus range
//! [x₀, x₁] with cosine fall-offs to 0 at half the range beyond each end; w uniform between
//! twice the smallest distance of two levels and the range, falling off (cosine) to 0 at that
//! distance and at 3 × the range; λ ~ Beta(1, 10) on [0, ½]; η ~ Beta(1, 10) on [0, 1).
//!
//! The posterior is evaluated on a grid, as psignifit does: a coarse grid over the priors'
//! support (m 30, w 40, λ 10, η 20 values), then a fine grid (40, 40, 20, 20) over the box
//! where the coarse posterior mass is at least 10⁻⁵ (one cell wider each way). The estimate is
//! the posterior mean of each parameter; the credible interval the equal-tailed interval of its
//! marginal, read as psignifit's `percentiles` method does (the marginal's cumulative mass
//! interpolated linearly at α/2 and 1 − α/2).

use serde::Serialize;

use crate::confidence::Confidence;
use crate::error::AnalysisError;
use crate::psychometric::GroupedTrials;

/// The sigmoid S of a Bayesian fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Sigmoid {
    /// Normal CDF (psignifit `norm`).
    Normal,
    /// Logistic (psignifit `logistic`).
    Logistic,
    /// Gumbel of ln x: the Weibull (psignifit `weibull` on log levels). Levels must be > 0;
    /// thresholds and their intervals are reported in level units, widths in ln units.
    Weibull,
}

/// A fitted parameter: posterior mean and equal-tailed credible interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    /// Posterior mean.
    pub mean: f64,
    /// Lower end of the credible interval.
    pub lower: f64,
    /// Upper end.
    pub upper: f64,
}

/// A Bayesian psychometric fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BayesFit {
    /// The sigmoid.
    pub sigmoid: Sigmoid,
    /// Threshold m (S(m) = ½, ψ(m) = ¾ without lapses), in level units.
    pub threshold: Estimate,
    /// Width w (S from 0.05 to 0.95), in level units (ln units for the Weibull).
    pub width: Estimate,
    /// Lapse rate λ.
    pub lapse: Estimate,
    /// Overdispersion η (0: binomial).
    pub eta: Estimate,
    /// Probability of the intervals.
    pub credible: Confidence,
    /// Trials fitted.
    pub trials: u32,
    /// Distinct levels.
    pub levels: usize,
}

/// 2AFC guess rate.
const GUESS: f64 = 0.5;
/// psignifit's `width_alpha`.
const WIDTH_ALPHA: f64 = 0.05;
/// psignifit's `beta_prior` (η ~ Beta(1, 10)).
const ETA_BETA: f64 = 10.0;
/// psignifit's `max_bound_value`.
const MASS_BOUND: f64 = 1e-5;
/// Grid sizes (η, λ, m, w): coarse and fine (psignifit's `steps_moving_bounds`, `grid_steps`
/// for nAFC).
const COARSE: [usize; 4] = [20, 10, 30, 40];
const FINE: [usize; 4] = [20, 20, 40, 40];

/// Standard normal CDF.
fn phi(z: f64) -> f64 {
    0.5 * statrs::function::erf::erfc(-z / std::f64::consts::SQRT_2)
}

/// Standard normal quantile.
fn phi_inv(p: f64) -> f64 {
    -std::f64::consts::SQRT_2 * statrs::function::erf::erfc_inv(2.0 * p)
}

impl Sigmoid {
    /// S(x; m, w).
    fn value(self, x: f64, m: f64, w: f64) -> f64 {
        match self {
            Self::Normal => {
                let scale = w / (phi_inv(1.0 - WIDTH_ALPHA) - phi_inv(WIDTH_ALPHA));
                phi((x - m) / scale)
            }
            Self::Logistic => {
                let scale = w / (2.0 * (1.0 / WIDTH_ALPHA - 1.0).ln());
                1.0 / (1.0 + (-(x - m) / scale).exp())
            }
            Self::Weibull => {
                // scipy's gumbel_l: cdf 1 − exp(−exp((x − loc)/scale)), ppf(½) = ln ln 2.
                let scale = w / ((-WIDTH_ALPHA.ln()).ln() - (-(1.0 - WIDTH_ALPHA).ln()).ln());
                let loc = m - 2_f64.ln().ln() * scale;
                -(-((x - loc) / scale).exp()).exp_m1()
            }
        }
    }
}

/// ln Γ(a + k) − ln Γ(a) = Σ_{i<k} ln(a + i), as the logarithm of products of as many terms
/// as stay below 10³⁰⁰ (64 while a + k < 10³, 32 while < 10⁹, else 16).
fn ln_rising(a: f64, k: u32) -> f64 {
    let top = a + f64::from(k);
    let chunk = if top < 1e3 {
        64
    } else if top < 1e9 {
        32
    } else {
        16
    };
    let mut total = 0.0;
    let mut i = 0;
    while i < k {
        let end = (i + chunk).min(k);
        let mut prod = 1.0;
        for j in i..end {
            prod *= a + f64::from(j);
        }
        total += prod.ln();
        i = end;
    }
    total
}

/// psignifit's threshold prior: 1 inside (x₀, x₁), cosine fall-off to 0 at half the range
/// outside.
fn threshold_prior(m: f64, lo: f64, hi: f64) -> f64 {
    let sp = hi - lo;
    if lo < m && m < hi {
        1.0
    } else if lo - sp / 2.0 <= m && m <= lo {
        0.5 + 0.5 * (2.0 * std::f64::consts::PI * (lo - m) / sp).cos()
    } else if hi <= m && m <= hi + sp / 2.0 {
        0.5 + 0.5 * (2.0 * std::f64::consts::PI * (m - hi) / sp).cos()
    } else {
        0.0
    }
}

/// psignifit's width prior (with `width_alpha` 0.05 the width is its own y).
///
/// psignifit assigns the three pieces in turn, each over the last: the flat part on
/// (2·wmin, wmax), the rising cosine on [wmin, 2·wmin], the falling cosine on
/// [wmax, 3·wmax]. Where the fall-offs overlap (2·wmin > wmax: a track that tested only two
/// levels, whose smallest gap is the whole range) the falling one wins, and the flat part is
/// empty: the prior is 0 below wmax and falls from 1 at wmax to 0 at 3·wmax. The order of the
/// tests below is that precedence.
fn width_prior(w: f64, wmin: f64, wmax: f64) -> f64 {
    use std::f64::consts::PI;
    if wmax <= w && w <= 3.0 * wmax {
        0.5 + 0.5 * (PI / 2.0 * (w - wmax) / wmax).cos()
    } else if wmin <= w && w <= 2.0 * wmin {
        (1.0 - (PI * (w - wmin) / wmin).cos()) / 2.0
    } else if 2.0 * wmin < w && w < wmax {
        1.0
    } else {
        0.0
    }
}

/// Beta(1, b) density.
fn beta1(x: f64, b: f64) -> f64 {
    if (0.0..=1.0).contains(&x) {
        b * (1.0 - x).powf(b - 1.0)
    } else {
        0.0
    }
}

/// numpy's `linspace` (the last value exactly the upper bound), one value where the bounds
/// are `isclose`.
fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if (lo - hi).abs() <= 1e-8 + 1e-5 * hi.abs() {
        return vec![lo];
    }
    let step = (hi - lo) / (n - 1) as f64;
    (0..n)
        .map(|i| if i + 1 == n { hi } else { lo + i as f64 * step })
        .collect()
}

/// Trapezoid weights of one axis (1 for a single value).
fn trapezoid(grid: &[f64]) -> Vec<f64> {
    let n = grid.len();
    if n <= 1 {
        return vec![1.0; n];
    }
    let mut d = vec![0.0; n];
    for i in 1..n {
        d[i] = grid[i] - grid[i - 1];
    }
    d[0] = d[1] / 2.0;
    d[n - 1] /= 2.0;
    d
}

/// The data on the fit's axis: (x, n, k) with x = ln level for the Weibull.
struct Blocks {
    x: Vec<f64>,
    n: Vec<u32>,
    k: Vec<u32>,
}

/// The posterior mass on a grid (η, λ, m, w), η-major.
struct Posterior {
    axes: [Vec<f64>; 4],
    mass: Vec<f64>,
}

fn posterior(
    data: &Blocks,
    sigmoid: Sigmoid,
    axes: [Vec<f64>; 4],
    range: (f64, f64),
    wmin: f64,
) -> Posterior {
    let [eta, lambda, m, w] = &axes;
    let (nm, nw, nl) = (m.len(), w.len(), lambda.len());
    // S per (m, w, level).
    let levels = data.x.len();
    let mut s = vec![0.0; nm * nw * levels];
    for (i, &mi) in m.iter().enumerate() {
        for (j, &wj) in w.iter().enumerate() {
            for (b, &x) in data.x.iter().enumerate() {
                s[(i * nw + j) * levels + b] = sigmoid.value(x, mi, wj);
            }
        }
    }
    // Log prior of (λ, m, w); η's is added per η.
    let ln_prior_m: Vec<f64> = m
        .iter()
        .map(|&v| threshold_prior(v, range.0, range.1).ln())
        .collect();
    let ln_prior_w: Vec<f64> = w
        .iter()
        .map(|&v| width_prior(v, wmin, range.1 - range.0).ln())
        .collect();
    let ln_prior_l: Vec<f64> = lambda.iter().map(|&v| beta1(v, 10.0).ln()).collect();
    // Per η: whether it is binomial, ν = 1/η² − 1, its log prior and −Σ ln Γ(n + ν) − ln Γ(ν).
    let etas: Vec<(bool, f64, f64, f64)> = eta
        .iter()
        .map(|&eta_std| {
            let variance = eta_std * eta_std;
            let binomial = variance <= 1e-9;
            let nu = 1.0 / variance - 1.0;
            let norm = if binomial {
                0.0
            } else {
                data.n.iter().map(|&n| -ln_rising(nu, n)).sum()
            };
            (binomial, nu, beta1(eta_std, ETA_BETA).ln(), norm)
        })
        .collect();
    let mut lp = vec![f64::NEG_INFINITY; eta.len() * nl * nm * nw];
    let mut psi = vec![0.0; levels];
    for (l, &lam) in lambda.iter().enumerate() {
        for i in 0..nm {
            for j in 0..nw {
                let cell = (i * nw + j) * levels;
                for (b, p) in psi.iter_mut().enumerate() {
                    *p = GUESS + (1.0 - lam - GUESS) * s[cell + b];
                }
                let prior = ln_prior_l[l] + ln_prior_m[i] + ln_prior_w[j];
                for (e, &(binomial, nu, ln_prior_e, norm)) in etas.iter().enumerate() {
                    let mut ll = norm;
                    for ((&n, &k), &p) in data.n.iter().zip(&data.k).zip(&psi) {
                        if binomial {
                            if k > 0 {
                                ll += f64::from(k) * p.ln();
                            }
                            if n > k {
                                ll += f64::from(n - k) * (1.0 - p).ln();
                            }
                        } else {
                            ll += ln_rising(p * nu, k) + ln_rising((1.0 - p) * nu, n - k);
                        }
                    }
                    let v = ll + ln_prior_e + prior;
                    lp[((e * nl + l) * nm + i) * nw + j] =
                        if v.is_nan() { f64::NEG_INFINITY } else { v };
                }
            }
        }
    }
    let max = lp.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let weights: Vec<Vec<f64>> = axes.iter().map(|a| trapezoid(a)).collect();
    let mut mass = Vec::with_capacity(lp.len());
    let mut k = 0;
    for we in &weights[0] {
        for wl in &weights[1] {
            for wm in &weights[2] {
                for ww in &weights[3] {
                    mass.push((lp[k] - max).exp() * we * wl * wm * ww);
                    k += 1;
                }
            }
        }
    }
    let total: f64 = mass.iter().sum();
    for v in &mut mass {
        *v /= total;
    }
    Posterior { axes, mass }
}

impl Posterior {
    /// Marginal mass of axis `a`.
    fn marginal(&self, a: usize) -> Vec<f64> {
        let lens: Vec<usize> = self.axes.iter().map(Vec::len).collect();
        let stride: usize = lens[a + 1..].iter().product();
        let mut out = vec![0.0; lens[a]];
        for (k, v) in self.mass.iter().enumerate() {
            out[(k / stride) % lens[a]] += v;
        }
        out
    }

    /// psignifit's `masked_parameter_bounds`: per axis the first and last value where any
    /// mass ≥ `bound`, widened by one value each way.
    fn tighter_bounds(&self, bound: f64) -> [(f64, f64); 4] {
        let lens: Vec<usize> = self.axes.iter().map(Vec::len).collect();
        let mut lo = [usize::MAX; 4];
        let mut hi = [0_usize; 4];
        for (k, v) in self.mass.iter().enumerate() {
            if *v < bound {
                continue;
            }
            let mut rest = k;
            for a in (0..4).rev() {
                let i = rest % lens[a];
                rest /= lens[a];
                lo[a] = lo[a].min(i);
                hi[a] = hi[a].max(i);
            }
        }
        std::array::from_fn(|a| {
            let (l, h) = if lo[a] == usize::MAX {
                (0, lens[a] - 1)
            } else {
                (lo[a].saturating_sub(1), (hi[a] + 1).min(lens[a] - 1))
            };
            (self.axes[a][l], self.axes[a][h])
        })
    }

    /// Posterior mean and percentile interval of axis `a`.
    fn estimate(&self, a: usize, credible: Confidence) -> Estimate {
        let grid = &self.axes[a];
        let m = self.marginal(a);
        let mean = grid.iter().zip(&m).map(|(g, p)| g * p).sum();
        let tail = credible.alpha() / 2.0;
        let mut cum = Vec::with_capacity(m.len());
        let mut acc = 0.0;
        for p in &m {
            acc += p;
            cum.push(acc);
        }
        Estimate {
            mean,
            lower: interp(tail, &cum, grid),
            upper: interp(1.0 - tail, &cum, grid),
        }
    }
}

/// numpy's `interp(x, xp, fp)`: fp[0] below xp[0], fp[-1] above xp[-1], linear between.
fn interp(x: f64, xp: &[f64], fp: &[f64]) -> f64 {
    let n = xp.len();
    if n == 0 {
        return f64::NAN;
    }
    if x <= xp[0] {
        return fp[0];
    }
    if x >= xp[n - 1] {
        return fp[n - 1];
    }
    // numpy finds the last xp[j] <= x.
    let j = xp.partition_point(|v| *v <= x) - 1;
    if xp[j + 1] <= xp[j] {
        return fp[j];
    }
    fp[j] + (x - xp[j]) * (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
}

/// Fits ψ to grouped 2AFC data by psignifit 4's procedure (see the module documentation);
/// `credible` is the probability of the intervals.
///
/// # Errors
/// [`AnalysisError::TooFew`] for fewer than two distinct levels or no trial;
/// [`AnalysisError::InvalidParameter`] for a level ≤ 0 with the Weibull or a non-finite
/// level, or counts where more are correct than shown.
pub fn fit(
    data: &GroupedTrials,
    sigmoid: Sigmoid,
    credible: Confidence,
) -> Result<BayesFit, AnalysisError> {
    let mut blocks = Blocks {
        x: Vec::new(),
        n: Vec::new(),
        k: Vec::new(),
    };
    for &(level, n, k) in &data.levels {
        if !level.is_finite() || (sigmoid == Sigmoid::Weibull && level <= 0.0) {
            return Err(AnalysisError::InvalidParameter {
                name: "2AFC level",
                value: level,
                reason: "a Bayesian fit needs finite levels (> 0 for the Weibull)",
            });
        }
        if k > n {
            return Err(AnalysisError::InvalidParameter {
                name: "correct trials",
                value: f64::from(k),
                reason: "more correct than shown at one level",
            });
        }
        if n > 0 {
            blocks.x.push(if sigmoid == Sigmoid::Weibull {
                level.ln()
            } else {
                level
            });
            blocks.n.push(n);
            blocks.k.push(k);
        }
    }
    let trials: u32 = blocks.n.iter().sum();
    if blocks.x.len() < 2 {
        return Err(AnalysisError::TooFew {
            what: "Bayesian psychometric fit (distinct levels)",
            needed: 2,
            got: blocks.x.len(),
        });
    }
    // Grouped levels come sorted; psignifit takes the data's range and the smallest gap.
    let mut xs = blocks.x.clone();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    let range = (xs[0], xs[xs.len() - 1]);
    let wmin = xs
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    let spread = range.1 - range.0;
    let width_spread = spread
        / ((phi_inv(0.95) - phi_inv(0.05)) / (phi_inv(1.0 - WIDTH_ALPHA) - phi_inv(WIDTH_ALPHA)));
    let bounds = [
        (0.0, 1.0 - 1e-10),
        (0.0, 0.5),
        (range.0 - spread / 2.0, range.1 + spread / 2.0),
        (wmin, 3.0 * width_spread),
    ];
    let grid = |b: [(f64, f64); 4], steps: [usize; 4]| -> [Vec<f64>; 4] {
        std::array::from_fn(|a| linspace(b[a].0, b[a].1, steps[a]))
    };
    let coarse = posterior(&blocks, sigmoid, grid(bounds, COARSE), range, wmin);
    let fine = posterior(
        &blocks,
        sigmoid,
        grid(coarse.tighter_bounds(MASS_BOUND), FINE),
        range,
        wmin,
    );
    let mut threshold = fine.estimate(2, credible);
    if sigmoid == Sigmoid::Weibull {
        // The threshold's interval is read on ln x; its ends map back exactly, its mean is
        // reported as exp of the mean of ln m (the posterior's geometric mean).
        threshold = Estimate {
            mean: threshold.mean.exp(),
            lower: threshold.lower.exp(),
            upper: threshold.upper.exp(),
        };
    }
    Ok(BayesFit {
        sigmoid,
        threshold,
        width: fine.estimate(3, credible),
        lapse: fine.estimate(1, credible),
        eta: fine.estimate(0, credible),
        credible,
        trials,
        levels: blocks.x.len(),
    })
}

/// The priors of [`fit`], in words, for a report's method section.
pub const PRIORS: &str = "threshold uniform over the tested range with cosine fall-offs to 0 at half the range beyond each end; width uniform between twice the smallest gap between two levels and the range, falling off to 0 at that gap and at three times the range (with two levels tested, where the gap is the range, 0 below the range and falling from 1 at the range to 0 at three times it, as psignifit has it); lapse rate Beta(1, 10) on [0, 0.5]; overdispersion η Beta(1, 10) (psignifit 4's defaults)";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rising_factorial_equals_log_gamma_differences() {
        for (a, k) in [(0.3, 0_u32), (0.3, 1), (2.5, 7), (361.0, 40), (4.0e4, 100)] {
            let want = statrs::function::gamma::ln_gamma(a + f64::from(k))
                - statrs::function::gamma::ln_gamma(a);
            assert!(
                (ln_rising(a, k) - want).abs() < 1e-9 * want.abs().max(1.0),
                "{a} {k}"
            );
        }
    }

    #[test]
    fn sigmoids_have_their_threshold_and_width() {
        for s in [Sigmoid::Normal, Sigmoid::Logistic, Sigmoid::Weibull] {
            assert!((s.value(1.0, 1.0, 2.0) - 0.5).abs() < 1e-12, "{s:?}");
            // Width 2 around threshold 1: S runs from 0.05 to 0.95 over some 2-wide span.
            let lo = (0..=2000)
                .map(|i| -1.0 + f64::from(i) * 0.002)
                .find(|x| s.value(*x, 1.0, 2.0) >= 0.05)
                .unwrap();
            assert!((s.value(lo + 2.0, 1.0, 2.0) - 0.95).abs() < 2e-3, "{s:?}");
        }
    }

    #[test]
    fn a_clear_psychometric_function_is_recovered() {
        // 40 trials at each of 6 levels from ψ with m = 0, w = 2, λ = 0 (logistic).
        let levels: Vec<(f64, u32, u32)> = [-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0]
            .iter()
            .map(|&x: &f64| {
                let p = GUESS + (1.0 - GUESS) * Sigmoid::Logistic.value(x, 0.0, 2.0);
                (x, 40, (40.0 * p).round() as u32)
            })
            .collect();
        let f = fit(
            &GroupedTrials { levels },
            Sigmoid::Logistic,
            Confidence::default(),
        )
        .unwrap();
        assert!(f.threshold.lower < 0.0 && 0.0 < f.threshold.upper, "{f:?}");
        assert!(f.threshold.mean.abs() < 0.3, "{f:?}");
        assert!(f.width.lower < 2.0 && 2.0 < f.width.upper, "{f:?}");
    }
}
