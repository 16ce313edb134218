//! Bayesian adaptive procedures for the 2AFC study: QUEST+ (Watson 2017) and Psi (Kontsevich &
//! Tyler 1999), next to the up-down [`crate::staircase`].
//!
//! Both keep a posterior over a grid of psychometric-function parameters (threshold α, slope β,
//! lapse λ; guess rate γ fixed at 1/2 for 2AFC) and put every trial at the level of the
//! stimulus domain whose answer is expected to leave the least entropy in that posterior:
//! for each level x and outcome r ∈ {correct, wrong}, `p(r | x) = Σ_θ post(θ) L(r | x, θ)`,
//! the updated posterior `post(θ) L(r | x, θ) / p(r | x)` and its entropy `H_r(x)`; the next
//! level minimises `E H(x) = Σ_r p(r | x) H_r(x)` (the first such level of the ascending domain
//! on a tie). Psi is this rule over (α, β) with λ fixed (Kontsevich & Tyler's procedure); QUEST+
//! also puts λ (any grid) under the posterior. The likelihood is the observer's own function
//! ([`PsychometricFunction::p_correct`]): `γ + (1 − γ − λ) F(x)`, the Weibull `F = 1 −
//! exp(−(x/α)^β)` being questplus's `weibull` with `stim_scale = "linear"`.
//!
//! Like the staircase the procedure is a pure function of its settings and the answers so far
//! (no randomness at all), so a session replays and resumes exactly, and `Session::lookahead`
//! finds the two levels a correct and a wrong answer lead to by answering a clone. The golden
//! test `tests/questplus_golden.rs` checks the posterior and every chosen level against the
//! `questplus` package from PyPI on fixed answer sequences.
//!
//! The estimate is the posterior mean of each parameter (questplus's `param_estimate` with
//! `mean`), and the threshold's credible interval the equal-tailed interval of its marginal
//! posterior, each grid value standing for the cell between the midpoints to its neighbours
//! (the distribution function interpolated linearly within a cell).

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::observer::PsychometricFunction;
use crate::study::Psychometric;

/// Which Bayesian procedure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QuestMethod {
    /// QUEST+ (Watson 2017): any grid of threshold, slope and lapse.
    QuestPlus,
    /// Psi (Kontsevich & Tyler 1999): threshold and slope, the lapse rate fixed.
    Psi,
}

impl QuestMethod {
    /// The name used in study files.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::QuestPlus => "quest_plus",
            Self::Psi => "psi",
        }
    }
}

/// Settings of one QUEST+ or Psi track: the stimulus domain, the parameter grids with their
/// priors, and when to stop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QuestSettings {
    /// QUEST+ or Psi.
    pub method: QuestMethod,
    /// Family of `F`.
    pub family: Psychometric,
    /// The levels a trial may have (the stimulus domain), ascending.
    pub levels: Vec<f64>,
    /// Threshold grid α, ascending.
    pub thresholds: Vec<f64>,
    /// Slope grid β, ascending.
    pub slopes: Vec<f64>,
    /// Lapse-rate grid λ, ascending (one value for Psi).
    pub lapses: Vec<f64>,
    /// Prior weight of each threshold (any positive scale; normalised with the others).
    pub threshold_prior: Vec<f64>,
    /// Prior weight of each slope.
    pub slope_prior: Vec<f64>,
    /// Prior weight of each lapse rate.
    pub lapse_prior: Vec<f64>,
    /// Stop after this many trials.
    pub max_trials: u32,
    /// Trials before `stop_interval` may stop the track.
    pub min_trials: u32,
    /// Stop as soon as the threshold's credible interval is at most this wide (after
    /// `min_trials`); `None`: run `max_trials`.
    pub stop_interval: Option<f64>,
    /// Probability of the credible interval (e.g. 0.95).
    pub credible: f64,
}

impl QuestSettings {
    /// Settings with uniform priors over the grids `thresholds`, `slopes` and `lapses`,
    /// `max_trials` trials and no interval stop, 95 % intervals.
    pub fn uniform(
        method: QuestMethod,
        family: Psychometric,
        levels: Vec<f64>,
        thresholds: Vec<f64>,
        slopes: Vec<f64>,
        lapses: Vec<f64>,
        max_trials: u32,
    ) -> Self {
        Self {
            method,
            family,
            levels,
            threshold_prior: vec![1.0; thresholds.len()],
            thresholds,
            slope_prior: vec![1.0; slopes.len()],
            slopes,
            lapse_prior: vec![1.0; lapses.len()],
            lapses,
            max_trials,
            min_trials: 0,
            stop_interval: None,
            credible: 0.95,
        }
    }
}

/// Most parameter combinations of a grid.
pub const MAX_PARAMETER_POINTS: usize = 200_000;
/// Most (level, parameter combination) pairs, the size of the likelihood table.
pub const MAX_TABLE: usize = 4_000_000;
/// Most levels of a stimulus domain.
pub const MAX_LEVELS: usize = 1000;

/// Why QUEST+ settings were rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum QuestError {
    /// A setting is out of its range.
    #[error("QUEST+ setting `{key}`: {reason}")]
    BadSetting {
        /// Key as in the study file (`staircase.quest.threshold`).
        key: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A response after the last trial.
    #[error("QUEST+ track already finished after {trials} trials")]
    Finished {
        /// Trials run.
        trials: usize,
    },
}

/// Checks QUEST+ settings, returning every problem.
pub fn check_settings(s: &QuestSettings) -> Vec<QuestError> {
    let mut errs = check_grids(s);
    let mut bad =
        |key: &'static str, reason: String| errs.push(QuestError::BadSetting { key, reason });
    let weibull = s.family == Psychometric::Weibull;
    let ascending = |v: &[f64]| v.windows(2).all(|w| w[0] < w[1]);
    if weibull && s.thresholds.iter().any(|t| *t <= 0.0) {
        bad(
            "staircase.quest.threshold",
            "a Weibull threshold must be > 0".into(),
        );
    }
    if s.slopes.iter().any(|b| *b <= 0.0) {
        bad("staircase.quest.slope", "slopes must be > 0".into());
    }
    if s.lapses.iter().any(|l| !(0.0..0.5).contains(l)) {
        bad(
            "staircase.quest.lapse",
            "lapse rates lie in [0, 0.5)".into(),
        );
    }
    if s.method == QuestMethod::Psi && s.lapses.len() != 1 {
        bad(
            "staircase.quest.lapse",
            format!(
                "Psi (Kontsevich & Tyler) fixes the lapse rate: give one value, not {} (method = \"quest_plus\" puts it under the posterior)",
                s.lapses.len()
            ),
        );
    }
    if s.levels.is_empty() {
        bad("staircase.min", "the stimulus domain has no level".into());
    } else if s.levels.len() > MAX_LEVELS {
        bad(
            "staircase.step",
            format!("{} levels, limit {MAX_LEVELS}", s.levels.len()),
        );
    } else if !ascending(&s.levels) || !s.levels.iter().all(|x| x.is_finite()) {
        bad(
            "staircase.step",
            "levels must be finite and ascending".into(),
        );
    }
    if weibull && s.levels.iter().any(|x| *x <= 0.0) {
        bad("staircase.min", "a Weibull needs levels > 0".into());
    }
    let points = s
        .thresholds
        .len()
        .saturating_mul(s.slopes.len())
        .saturating_mul(s.lapses.len());
    if points > MAX_PARAMETER_POINTS {
        bad(
            "staircase.quest",
            format!("{points} parameter combinations, limit {MAX_PARAMETER_POINTS}"),
        );
    } else if points.saturating_mul(s.levels.len()) > MAX_TABLE {
        bad(
            "staircase.quest",
            format!(
                "{points} parameter combinations × {} levels, limit {MAX_TABLE}",
                s.levels.len()
            ),
        );
    }
    if s.max_trials == 0 {
        bad("staircase.max_trials", "must be at least 1".into());
    }
    if !(s.credible > 0.0 && s.credible < 1.0) {
        bad(
            "staircase.quest.credible",
            format!("must lie in (0, 1), got {}", s.credible),
        );
    }
    if let Some(w) = s.stop_interval
        && !(w.is_finite() && w > 0.0)
    {
        bad(
            "staircase.quest.stop_interval",
            format!("must be a positive width, got {w}"),
        );
    }
    errs
}

/// Each parameter grid: values finite and ascending, one non-negative prior weight per value.
fn check_grids(s: &QuestSettings) -> Vec<QuestError> {
    let mut errs = Vec::new();
    for (key, values, prior) in [
        (
            "staircase.quest.threshold",
            &s.thresholds,
            &s.threshold_prior,
        ),
        ("staircase.quest.slope", &s.slopes, &s.slope_prior),
        ("staircase.quest.lapse", &s.lapses, &s.lapse_prior),
    ] {
        let mut bad = |reason: String| errs.push(QuestError::BadSetting { key, reason });
        if values.is_empty() {
            bad("needs at least one value".into());
        } else if !values.iter().all(|v| v.is_finite()) || !values.windows(2).all(|w| w[0] < w[1]) {
            bad("values must be finite and strictly ascending".into());
        }
        if prior.len() != values.len() {
            bad(format!(
                "{} prior weights for {} values",
                prior.len(),
                values.len()
            ));
        } else if !prior.iter().all(|w| w.is_finite() && *w >= 0.0)
            || !prior.iter().any(|w| *w > 0.0)
        {
            bad("prior weights must be finite, >= 0 and not all 0".into());
        }
    }
    errs
}

/// What stays fixed while a track runs: the settings and the likelihood table.
#[derive(Debug)]
struct Model {
    settings: QuestSettings,
    /// `ln p(correct | x, θ)`, level-major (`x · n_θ + θ`).
    ln_correct: Vec<f64>,
    /// `ln p(wrong | x, θ)` (−∞ where the answer is impossible).
    ln_wrong: Vec<f64>,
    /// `p(correct | x, θ)`.
    correct: Vec<f64>,
    /// Number of parameter combinations, threshold-major then slope then lapse.
    points: usize,
}

/// A summary of one parameter's marginal posterior.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Marginal {
    /// Posterior mean.
    pub mean: f64,
    /// Lower end of the equal-tailed credible interval.
    pub lower: f64,
    /// Upper end.
    pub upper: f64,
}

/// A running QUEST+ or Psi track.
#[derive(Debug, Clone)]
pub struct QuestPlus {
    model: Arc<Model>,
    /// Normalised posterior over the parameter grid.
    posterior: Vec<f64>,
    /// Index into the domain of the next level; `None` once finished.
    next: Option<usize>,
    /// Levels of the trials run.
    levels: Vec<f64>,
    /// Answers so far.
    answers: Vec<bool>,
}

impl QuestPlus {
    /// A track before its first trial: the prior, and the level it puts the first trial at.
    ///
    /// # Errors
    /// The first problem [`check_settings`] finds.
    pub fn new(settings: QuestSettings) -> Result<Self, QuestError> {
        if let Some(e) = check_settings(&settings).into_iter().next() {
            return Err(e);
        }
        let points = settings.thresholds.len() * settings.slopes.len() * settings.lapses.len();
        let mut correct = Vec::with_capacity(points * settings.levels.len());
        for &x in &settings.levels {
            for &alpha in &settings.thresholds {
                for &beta in &settings.slopes {
                    for &lapse in &settings.lapses {
                        let f = PsychometricFunction {
                            family: settings.family,
                            threshold: alpha,
                            slope: beta,
                            lapse,
                        };
                        correct.push(f.p_correct(x));
                    }
                }
            }
        }
        let ln_correct = correct.iter().map(|p| p.ln()).collect();
        let ln_wrong = correct.iter().map(|p| (1.0 - p).ln()).collect();
        let mut prior = Vec::with_capacity(points);
        for wa in &settings.threshold_prior {
            for wb in &settings.slope_prior {
                for wl in &settings.lapse_prior {
                    prior.push(wa * wb * wl);
                }
            }
        }
        normalise(&mut prior);
        let mut q = Self {
            model: Arc::new(Model {
                settings,
                ln_correct,
                ln_wrong,
                correct,
                points,
            }),
            posterior: prior,
            next: None,
            levels: Vec::new(),
            answers: Vec::new(),
        };
        q.next = Some(q.best_level());
        Ok(q)
    }

    /// The settings.
    pub fn settings(&self) -> &QuestSettings {
        &self.model.settings
    }

    /// Level of the next trial, or `None` once finished.
    pub fn next_level(&self) -> Option<f64> {
        self.next.map(|i| self.model.settings.levels[i])
    }

    /// Whether the stop rule has fired.
    pub fn is_finished(&self) -> bool {
        self.next.is_none()
    }

    /// Levels of the trials run so far.
    pub fn levels(&self) -> &[f64] {
        &self.levels
    }

    /// The posterior over the grid, threshold-major, then slope, then lapse (questplus's
    /// `posterior` array, flattened in C order).
    pub fn posterior(&self) -> &[f64] {
        &self.posterior
    }

    /// Records the answer to a trial at [`Self::next_level`], updates the posterior and
    /// chooses the next level.
    ///
    /// # Errors
    /// [`QuestError::Finished`] once the track has stopped.
    pub fn add_response(&mut self, correct: bool) -> Result<f64, QuestError> {
        let Some(i) = self.next else {
            return Err(QuestError::Finished {
                trials: self.levels.len(),
            });
        };
        let m = &self.model;
        let row = &m.correct[i * m.points..(i + 1) * m.points];
        for (p, c) in self.posterior.iter_mut().zip(row) {
            *p *= if correct { *c } else { 1.0 - c };
        }
        normalise(&mut self.posterior);
        let level = m.settings.levels[i];
        self.levels.push(level);
        self.answers.push(correct);
        let s = &m.settings;
        let n = self.levels.len();
        let narrow = s.stop_interval.is_some_and(|w| {
            n >= s.min_trials as usize && {
                let t = self.threshold();
                t.upper - t.lower <= w
            }
        });
        self.next = if n >= s.max_trials as usize || narrow {
            None
        } else {
            Some(self.best_level())
        };
        Ok(level)
    }

    /// The index of the level with the least expected posterior entropy (the first on a tie).
    fn best_level(&self) -> usize {
        let m = &self.model;
        let ln_post: Vec<f64> = self.posterior.iter().map(|p| p.ln()).collect();
        let mut best = (0, f64::INFINITY);
        for x in 0..m.settings.levels.len() {
            let range = x * m.points..(x + 1) * m.points;
            let (mut pc, mut pw, mut sc, mut sw) = (0.0, 0.0, 0.0, 0.0);
            for (((&post, &lp), &c), (&lc, &lw)) in self
                .posterior
                .iter()
                .zip(&ln_post)
                .zip(&m.correct[range.clone()])
                .zip(m.ln_correct[range.clone()].iter().zip(&m.ln_wrong[range]))
            {
                if post == 0.0 {
                    continue;
                }
                let a = post * c;
                let b = post * (1.0 - c);
                pc += a;
                pw += b;
                // a ln a, with 0 ln 0 = 0 (questplus skips the NaN that makes).
                if a > 0.0 {
                    sc += a * (lp + lc);
                }
                if b > 0.0 {
                    sw += b * (lp + lw);
                }
            }
            // Σ_r p_r H_r = −Σ a ln(a / p_c) − Σ b ln(b / p_w).
            let mut eh = 0.0;
            if pc > 0.0 {
                eh += pc * pc.ln() - sc;
            }
            if pw > 0.0 {
                eh += pw * pw.ln() - sw;
            }
            if eh < best.1 {
                best = (x, eh);
            }
        }
        best.0
    }

    /// Marginal posterior of the threshold (one weight per grid value, summing to 1).
    pub fn threshold_marginal(&self) -> Vec<f64> {
        self.marginal(0)
    }

    /// Marginal posterior of parameter `axis` (0 threshold, 1 slope, 2 lapse).
    fn marginal(&self, axis: usize) -> Vec<f64> {
        let s = &self.model.settings;
        let (nb, nl) = (s.slopes.len(), s.lapses.len());
        let len = [s.thresholds.len(), nb, nl][axis];
        let mut out = vec![0.0; len];
        for (k, p) in self.posterior.iter().enumerate() {
            let i = match axis {
                0 => k / (nb * nl),
                1 => (k / nl) % nb,
                _ => k % nl,
            };
            out[i] += p;
        }
        out
    }

    /// The threshold's posterior mean and credible interval.
    pub fn threshold(&self) -> Marginal {
        self.summary(0)
    }

    /// The slope's posterior mean and credible interval.
    pub fn slope(&self) -> Marginal {
        self.summary(1)
    }

    /// The lapse rate's posterior mean and credible interval.
    pub fn lapse(&self) -> Marginal {
        self.summary(2)
    }

    fn summary(&self, axis: usize) -> Marginal {
        let s = &self.model.settings;
        let grid = [&s.thresholds, &s.slopes, &s.lapses][axis];
        let weights = self.marginal(axis);
        let (lower, upper) = credible_interval(grid, &weights, s.credible);
        Marginal {
            mean: grid.iter().zip(&weights).map(|(v, w)| v * w).sum(),
            lower,
            upper,
        }
    }

    /// The posterior mean of the level at which the observer answers correctly with
    /// probability `p`, over the parameter combinations that reach `p` (renormalised over
    /// them); `None` when none does.
    pub fn level_for(&self, p: f64) -> Option<f64> {
        let s = &self.model.settings;
        let (mut sum, mut mass) = (0.0, 0.0);
        let mut k = 0;
        for &alpha in &s.thresholds {
            for &beta in &s.slopes {
                for &lapse in &s.lapses {
                    let w = self.posterior[k];
                    k += 1;
                    if w == 0.0 {
                        continue;
                    }
                    let f = PsychometricFunction {
                        family: s.family,
                        threshold: alpha,
                        slope: beta,
                        lapse,
                    };
                    if let Some(x) = f.level_for(p) {
                        sum += w * x;
                        mass += w;
                    }
                }
            }
        }
        (mass > 0.0).then(|| sum / mass)
    }
}

/// Scales `v` to sum to 1 (left alone when it sums to 0).
fn normalise(v: &mut [f64]) {
    let total: f64 = v.iter().sum();
    if total > 0.0 {
        for x in v {
            *x /= total;
        }
    }
}

/// The equal-tailed `credible` interval of a distribution given as `weights` on the ascending
/// `grid`: each grid value holds its weight spread evenly over its cell (from the midpoint to
/// the neighbour below to the midpoint to the one above; the end cells as wide as their inner
/// half twice), and the quantiles are read from that piecewise-linear distribution function.
/// A grid of one value is that value.
pub fn credible_interval(grid: &[f64], weights: &[f64], credible: f64) -> (f64, f64) {
    let n = grid.len().min(weights.len());
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    if n == 1 {
        return (grid[0], grid[0]);
    }
    let edge = |i: usize| -> f64 {
        // Edge i lies below grid value i (edge n above the last).
        if i == 0 {
            grid[0] - (grid[1] - grid[0]) / 2.0
        } else if i == n {
            grid[n - 1] + (grid[n - 1] - grid[n - 2]) / 2.0
        } else {
            f64::midpoint(grid[i - 1], grid[i])
        }
    };
    let total: f64 = weights[..n].iter().sum();
    let quantile = |q: f64| -> f64 {
        let target = q * total;
        let mut below = 0.0;
        for (i, &w) in weights[..n].iter().enumerate() {
            if below + w >= target && w > 0.0 {
                let frac = ((target - below) / w).clamp(0.0, 1.0);
                return edge(i) + frac * (edge(i + 1) - edge(i));
            }
            below += w;
        }
        edge(n)
    };
    let tail = (1.0 - credible) / 2.0;
    (quantile(tail), quantile(1.0 - tail))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> QuestSettings {
        QuestSettings::uniform(
            QuestMethod::QuestPlus,
            Psychometric::Weibull,
            (1..=10).map(|i| f64::from(i) * 0.004).collect(),
            (1..=20).map(|i| f64::from(i) * 0.002).collect(),
            vec![2.0, 3.5, 5.0],
            vec![0.0, 0.02],
            30,
        )
    }

    #[test]
    fn same_answers_same_levels_and_the_track_stops() {
        let mut a = QuestPlus::new(settings()).unwrap();
        let mut b = QuestPlus::new(settings()).unwrap();
        let mut n = 0;
        while let Some(x) = a.next_level() {
            assert_eq!(Some(x), b.next_level());
            let correct = n % 4 != 3;
            a.add_response(correct).unwrap();
            b.add_response(correct).unwrap();
            n += 1;
        }
        assert_eq!(n, 30);
        assert!(matches!(
            a.add_response(true),
            Err(QuestError::Finished { trials: 30 })
        ));
        assert!((a.posterior().iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_narrow_interval_stops_early() {
        let mut s = settings();
        s.stop_interval = Some(0.03);
        s.min_trials = 5;
        let mut q = QuestPlus::new(s).unwrap();
        let mut n = 0;
        while q.next_level().is_some() {
            q.add_response(true).unwrap();
            n += 1;
        }
        let t = q.threshold();
        assert!((5..30).contains(&n), "{n}");
        assert!(t.upper - t.lower <= 0.03);
    }

    #[test]
    fn credible_interval_of_a_uniform_grid_is_its_quantiles() {
        let grid: Vec<f64> = (0..10).map(f64::from).collect();
        let (lo, hi) = credible_interval(&grid, &[1.0; 10], 0.8);
        // Cells [-0.5, 9.5]: the 10 % and 90 % points.
        assert!(
            (lo - 0.5).abs() < 1e-12 && (hi - 8.5).abs() < 1e-12,
            "{lo} {hi}"
        );
        assert_eq!(credible_interval(&[3.0], &[1.0], 0.95), (3.0, 3.0));
    }

    #[test]
    fn every_bad_setting_is_reported() {
        let mut s = settings();
        s.method = QuestMethod::Psi;
        s.slopes = vec![0.0, 1.0];
        s.thresholds[3] = s.thresholds[2];
        s.credible = 1.0;
        assert_eq!(check_settings(&s).len(), 5, "{:?}", check_settings(&s));
    }
}
