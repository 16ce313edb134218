//! Cumulative link mixed model (logit link, flexible thresholds) of category ratings, with
//! subject and clip as crossed random intercepts, fitted by the Laplace approximation as R's
//! `ordinal::clmm` fits it by default (Christensen 2019, "A tutorial on fitting cumulative
//! link mixed models with clmm2 from the ordinal package"; the `clmm` code's `getNLA`).
//!
//! P(Y ≤ k) = logit⁻¹(α_k − xᵀβ − τ_s u_subject − τ_c u_clip), u ~ N(0, I). The categories
//! are the distinct scores (a 1-5 scale in half steps has nine). For given parameters
//! (α, β, log τ) the random effects' mode û minimizes h(u) = −Σ log π_i(u) + ½ uᵀu (Newton
//! steps with halving, the exact Hessian H = τZᵀ diag(φ) Zτ + I); the Laplace negative
//! log-likelihood is h(û) + ½ log det H (H is diagonal, and solved as such, when the model
//! has subject intercepts only). It is minimized over the parameters by a quasi-Newton
//! iteration (BFGS, central-difference gradients) and then, from its optimum, damped Newton
//! steps on a central-difference Hessian, usually none: the Hessian is taken once, at the
//! optimum, and its inverse gives the standard errors (as `clmm(Hess = TRUE)` does with
//! numDeriv after ordinal's gradient-based optimiser). The finite differences' evaluations
//! are independent given the warm start û, and run on up to four threads. The
//! likelihood-ratio refits start from the full fit's estimates and need no Hessian.

// Matrix code indexes rows and columns by number, as the equations do.
#![allow(clippy::needless_range_loop)]

use serde::Serialize;

use crate::confidence::Confidence;
use crate::dist::z_quantile;
use crate::linalg::{Cholesky, Matrix};
use crate::mixed::{Design, FixedEffect, FixedTerms, NoModel, TermTest, chisq_sf, model_matrix};

/// Most Newton steps of the random effects' mode per evaluation.
const INNER_STEPS: usize = 100;
/// The mode is found when every gradient element is below this.
const INNER_TOLERANCE: f64 = 1e-10;
/// Most Newton steps over the parameters.
const OUTER_STEPS: usize = 200;
/// A likelihood-ratio refit whose quasi-Newton iteration stalled with its gradient below this
/// is taken as it is (no Newton steps: a refit needs no Hessian).
const REFIT_STALL_GRADIENT: f64 = 1e-3;
/// Most quasi-Newton steps before the Newton iteration takes over.
const BFGS_STEPS: usize = 500;
/// The fit has converged when every element of the (central-difference) gradient is below
/// this.
const GRADIENT_TOLERANCE: f64 = 1e-6;
/// log τ is kept above this: a variance of e⁻³⁰ is zero for every purpose.
const MIN_LOG_TAU: f64 = -15.0;

/// A fitted cumulative link mixed model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClmmFit {
    /// The fixed part.
    pub fixed_terms: FixedTerms,
    /// Clip as a random intercept (three clips or more, as `ordinal::clmm` asks).
    pub clip: bool,
    /// Thresholds `a|b` between adjacent categories, with SEs and Wald intervals.
    pub thresholds: Vec<FixedEffect>,
    /// Fixed effects (no intercept: the thresholds take its place). A positive effect moves
    /// ratings up the scale.
    pub fixed: Vec<FixedEffect>,
    /// Random-intercept variances: (group, variance).
    pub variances: Vec<(String, f64)>,
    /// Laplace log-likelihood.
    pub log_lik: f64,
    /// Parameters: thresholds, fixed effects, variances.
    pub parameters: usize,
    /// AIC.
    pub aic: f64,
    /// Rows.
    pub n: usize,
    /// Categories (the distinct scores).
    pub categories: Vec<f64>,
    /// The outer Newton iteration brought every gradient element below 1e-6 within its step
    /// cap (or stalled there with them below 1e-4).
    pub converged: bool,
}

impl ClmmFit {
    /// The equivalent R call.
    pub fn r_formula(&self) -> String {
        format!(
            "clmm(factor(score, ordered = TRUE) ~ {} + (1 | subject){}, data = d, link = \"logit\")",
            self.fixed_terms.r_terms(),
            if self.clip { " + (1 | clip)" } else { "" }
        )
    }
}

fn logistic(x: f64) -> f64 {
    if x == f64::INFINITY {
        1.0
    } else if x == f64::NEG_INFINITY {
        0.0
    } else {
        1.0 / (1.0 + (-x).exp())
    }
}

struct Problem {
    n: usize,
    k: usize,
    p: usize,
    q: usize,
    category: Vec<usize>,
    x: Matrix,
    /// Random-effect columns per row: subject, clip (offset by the subjects).
    z: Vec<(usize, Option<usize>)>,
}

struct Inner {
    nll: f64,
    u: Vec<f64>,
}

impl Problem {
    fn taus(&self, par: &[f64]) -> (f64, f64) {
        let base = self.k - 1 + self.p;
        let ts = par[base].max(MIN_LOG_TAU).exp();
        let tc = par.get(base + 1).map_or(0.0, |v| v.max(MIN_LOG_TAU).exp());
        (ts, tc)
    }

    /// xᵀβ per row (the fixed part of the linear predictor, the same for every `u`).
    fn fixed_part(&self, par: &[f64]) -> Vec<f64> {
        let beta = &par[self.k - 1..self.k - 1 + self.p];
        (0..self.n)
            .map(|i| (0..self.p).map(|j| self.x.at(i, j) * beta[j]).sum::<f64>())
            .collect()
    }

    /// Per row: (log π, s = dlogπ/dη, φ = −d²logπ/dη²) at random effects `u`, given the
    /// fixed part `xb` of the linear predictor.
    fn rows(&self, par: &[f64], xb: &[f64], u: &[f64]) -> Option<Vec<(f64, f64, f64)>> {
        let (ts, tc) = self.taus(par);
        let alpha = &par[..self.k - 1];
        let mut out = Vec::with_capacity(self.n);
        for i in 0..self.n {
            let (s, c) = self.z[i];
            let b = ts * u[s] + c.map_or(0.0, |c| tc * u[c]);
            let xb = xb[i] + b;
            let y = self.category[i];
            let e1 = if y + 1 < self.k {
                alpha[y] - xb
            } else {
                f64::INFINITY
            };
            let e2 = if y > 0 {
                alpha[y - 1] - xb
            } else {
                f64::NEG_INFINITY
            };
            let (f1, f2) = (logistic(e1), logistic(e2));
            // π = F(η1) − F(η2), computed on the side that keeps its digits.
            let pi = if e2 > 0.0 {
                logistic(-e2) - logistic(-e1)
            } else {
                f1 - f2
            };
            if pi.is_nan() || pi <= 0.0 {
                return None;
            }
            let d1 = f1 * (1.0 - f1);
            let d2 = f2 * (1.0 - f2);
            let g1 = d1 * (1.0 - 2.0 * f1);
            let g2 = d2 * (1.0 - 2.0 * f2);
            let s = (d1 - d2) / pi;
            out.push((pi.ln(), s, s * s - (g1 - g2) / pi));
        }
        Some(out)
    }

    /// h(u), its gradient and the factor of its Hessian (diagonal when the model has subject
    /// intercepts only: each row then touches one random effect).
    fn h(&self, par: &[f64], xb: &[f64], u: &[f64]) -> Option<(f64, Vec<f64>, Factor)> {
        let rows = self.rows(par, xb, u)?;
        let (ts, tc) = self.taus(par);
        let mut value = 0.5 * u.iter().map(|v| v * v).sum::<f64>();
        let mut grad = u.to_vec();
        if self.z.iter().all(|z| z.1.is_none()) {
            let mut diag = vec![1.0; self.q];
            for (i, &(logpi, s, phi)) in rows.iter().enumerate() {
                value -= logpi;
                let a = self.z[i].0;
                grad[a] += s * ts;
                diag[a] += phi * ts * ts;
            }
            if diag.iter().any(|d| !d.is_finite() || *d <= 0.0) {
                return None;
            }
            return Some((value, grad, Factor::Diagonal(diag)));
        }
        let mut hess = Matrix::zeros(self.q, self.q);
        for i in 0..self.q {
            *hess.at_mut(i, i) = 1.0;
        }
        for (i, &(logpi, s, phi)) in rows.iter().enumerate() {
            value -= logpi;
            let (a, c) = self.z[i];
            grad[a] += s * ts;
            *hess.at_mut(a, a) += phi * ts * ts;
            if let Some(c) = c {
                grad[c] += s * tc;
                *hess.at_mut(a, c) += phi * ts * tc;
                *hess.at_mut(c, a) += phi * tc * ts;
                *hess.at_mut(c, c) += phi * tc * tc;
            }
        }
        Some((value, grad, Factor::Dense(Cholesky::new(&hess)?)))
    }

    /// The Laplace negative log-likelihood, with the mode found from `start`.
    fn laplace(&self, par: &[f64], start: &[f64]) -> Option<Inner> {
        let xb = self.fixed_part(par);
        let mut u = start.to_vec();
        let (mut value, mut grad, mut chol) = self.h(par, &xb, &u)?;
        for _ in 0..INNER_STEPS {
            if grad.iter().all(|g| g.abs() < INNER_TOLERANCE) {
                break;
            }
            let mut step = grad.clone();
            chol.solve(&mut step);
            // The Newton decrement: what a full step could still gain. Once it is this small
            // the step is taken whole (quadratic convergence), without asking the value to
            // fall: it would fall below its rounding, and û must be exact, as the log
            // determinant depends on it to first order.
            let decrement: f64 = step.iter().zip(&grad).map(|(a, b)| a * b).sum();
            if decrement < 1e-8 {
                let trial: Vec<f64> = u.iter().zip(&step).map(|(a, b)| a - b).collect();
                let Some((v, g, c)) = self.h(par, &xb, &trial) else {
                    break;
                };
                (u, value, grad, chol) = (trial, v, g, c);
                continue;
            }
            let mut factor = 1.0;
            let mut moved = false;
            for _ in 0..50 {
                let trial: Vec<f64> = u.iter().zip(&step).map(|(a, b)| a - factor * b).collect();
                if let Some((v, g, c)) = self.h(par, &xb, &trial)
                    && v <= value
                {
                    (u, value, grad, chol) = (trial, v, g, c);
                    moved = true;
                    break;
                }
                factor /= 2.0;
            }
            if !moved {
                break;
            }
        }
        Some(Inner {
            nll: value + chol.log_det_l(),
            u,
        })
    }
}

/// The factor of the Hessian of h(u): a Cholesky factor, or the diagonal itself.
enum Factor {
    Dense(Cholesky),
    Diagonal(Vec<f64>),
}

impl Factor {
    /// Solves `H x = b` in place.
    fn solve(&self, b: &mut [f64]) {
        match self {
            Self::Dense(c) => c.solve(b),
            Self::Diagonal(d) => {
                for (b, d) in b.iter_mut().zip(d) {
                    *b /= d;
                }
            }
        }
    }

    /// ½ log det H.
    fn log_det_l(&self) -> f64 {
        match self {
            Self::Dense(c) => c.log_det_l(),
            Self::Diagonal(d) => d.iter().map(|v| v.sqrt().ln()).sum(),
        }
    }
}

/// Fits the cumulative link mixed model of the design's scores (as categories) with `fixed`
/// terms and crossed random intercepts (clip when there are three clips or more).
///
/// # Errors
/// [`NoModel`] saying why: fewer than three subjects or two categories, fixed effects not
/// estimable, or no finite likelihood at the start.
pub fn fit_clmm(
    design: &Design,
    fixed: FixedTerms,
    confidence: Confidence,
) -> Result<ClmmFit, NoModel> {
    fit(design, fixed, confidence, None)
}

/// [`fit_clmm`], started from `from`'s estimates (its thresholds, variances and the fixed
/// effects of the same name) when given, and then without the Hessian (no SEs): the
/// likelihood-ratio refits.
fn fit(
    design: &Design,
    fixed: FixedTerms,
    confidence: Confidence,
    from: Option<&ClmmFit>,
) -> Result<ClmmFit, NoModel> {
    if design.subjects.len() < 2 {
        return Err(NoModel(
            "a subject variance needs two subjects or more".into(),
        ));
    }
    let mut categories = design.y.clone();
    categories.sort_by(f64::total_cmp);
    categories.dedup();
    if categories.len() < 2 {
        return Err(NoModel(
            "every score is the same category: there is nothing to order".into(),
        ));
    }
    let k = categories.len();
    let (names, x) = model_matrix(design, fixed, false);
    let p = x.cols;
    // ordinal's clmm takes a grouping factor of three levels or more; so does this model.
    let clip = design.clips.len() >= 3;
    let subjects = design.subjects.len();
    let problem = Problem {
        n: design.n(),
        k,
        p,
        q: subjects + if clip { design.clips.len() } else { 0 },
        category: design
            .y
            .iter()
            .map(|v| categories.binary_search_by(|c| c.total_cmp(v)).unwrap_or(0))
            .collect(),
        z: (0..design.n())
            .map(|i| (design.subject[i], clip.then(|| subjects + design.clip[i])))
            .collect(),
        x,
    };
    // Start: thresholds at the logits of the cumulative shares, β = 0, τ = 1.
    let mut par = Vec::new();
    let mut cum = 0usize;
    for c in 0..k - 1 {
        cum += problem.category.iter().filter(|&&y| y == c).count();
        let share = cum as f64 / problem.n as f64;
        par.push((share / (1.0 - share)).ln());
    }
    par.extend(std::iter::repeat_n(0.0, p));
    par.extend(std::iter::repeat_n(0.0, if clip { 2 } else { 1 }));
    if let Some(from) = from {
        warm_start(&mut par, from, &names, clip);
    }
    let (par, nll, hessian, converged) = minimize(&problem, par, from.is_none())?;
    let covariance = hessian
        .as_ref()
        .and_then(Cholesky::new)
        .map(|c| c.inverse());
    let z = z_quantile(1.0 - confidence.alpha() / 2.0).unwrap_or(f64::NAN);
    let effect = |name: String, j: usize| {
        let se = covariance.as_ref().map_or(f64::NAN, |c| c.at(j, j).sqrt());
        FixedEffect {
            name,
            estimate: par[j],
            se,
            lower: par[j] - z * se,
            upper: par[j] + z * se,
        }
    };
    let thresholds = (0..k - 1)
        .map(|j| effect(format!("{}|{}", categories[j], categories[j + 1]), j))
        .collect();
    let fixed_effects = names
        .into_iter()
        .enumerate()
        .map(|(j, n)| effect(n, k - 1 + j))
        .collect();
    let (ts, tc) = problem.taus(&par);
    let mut variances = vec![("subject".to_owned(), ts * ts)];
    if clip {
        variances.push(("clip".to_owned(), tc * tc));
    }
    let parameters = par.len();
    Ok(ClmmFit {
        fixed_terms: fixed,
        clip,
        thresholds,
        fixed: fixed_effects,
        variances,
        log_lik: -nll,
        parameters,
        aic: 2.0 * nll + 2.0 * parameters as f64,
        n: problem.n,
        categories,
        converged,
    })
}

/// Moves the start `par` (thresholds, `names`' effects, log τ) to `from`'s estimates: its
/// thresholds, variances and the fixed effects of the same name (the others stay at 0).
fn warm_start(par: &mut [f64], from: &ClmmFit, names: &[String], clip: bool) {
    let k = from.thresholds.len() + 1;
    if from.clip != clip || par.len() != k - 1 + names.len() + from.variances.len() {
        return;
    }
    for (j, t) in from.thresholds.iter().enumerate() {
        par[j] = t.estimate;
    }
    for (j, name) in names.iter().enumerate() {
        if let Some(e) = from.fixed.iter().find(|e| &e.name == name) {
            par[k - 1 + j] = e.estimate;
        }
    }
    for (j, (_, v)) in from.variances.iter().enumerate() {
        par[k - 1 + names.len() + j] = (0.5 * v.ln()).max(MIN_LOG_TAU);
    }
}

/// A cached Laplace evaluation: the last mode is the next evaluation's start.
struct Objective<'a> {
    problem: &'a Problem,
    u: Vec<f64>,
}

impl Objective<'_> {
    fn value(&self, par: &[f64]) -> f64 {
        match self.problem.laplace(par, &self.u) {
            Some(inner) if inner.nll.is_finite() => inner.nll,
            _ => f64::INFINITY,
        }
    }

    /// Moves the warm start to the mode at `par`.
    fn settle(&mut self, par: &[f64]) {
        if let Some(inner) = self.problem.laplace(par, &self.u) {
            self.u = inner.u;
        }
    }

    /// The values at `par` moved by each of `moves` ((coordinate, step) pairs). Every
    /// evaluation starts from the same mode, so they are independent and run on up to four
    /// threads; the results do not depend on how they are shared out.
    fn values(&self, par: &[f64], moves: &[Vec<(usize, f64)>]) -> Vec<f64> {
        let at = |steps: &Vec<(usize, f64)>| {
            let mut x = par.to_vec();
            for &(i, s) in steps {
                x[i] += s;
            }
            self.value(&x)
        };
        let threads = std::thread::available_parallelism()
            .map_or(1, usize::from)
            .clamp(1, 4);
        if threads == 1 || moves.len() < 8 {
            return moves.iter().map(at).collect();
        }
        let chunk = moves.len().div_ceil(threads);
        std::thread::scope(|scope| {
            let handles: Vec<_> = moves
                .chunks(chunk)
                .map(|part| scope.spawn(move || part.iter().map(at).collect::<Vec<f64>>()))
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_default())
                .collect()
        })
    }

    /// Central-difference gradient at `par` (step 1e-3, as [`Self::derivatives`]).
    fn gradient(&self, par: &[f64]) -> Vec<f64> {
        let d = par.len();
        let h = 1e-3;
        let moves: Vec<Vec<(usize, f64)>> =
            (0..d).flat_map(|i| [vec![(i, h)], vec![(i, -h)]]).collect();
        let v = self.values(par, &moves);
        (0..d)
            .map(|i| (v[2 * i] - v[2 * i + 1]) / (2.0 * h))
            .collect()
    }

    /// Central-difference gradient and Hessian at `par` (step 1e-3 per coordinate: the
    /// value is exact to about 1e-13, so the Hessian's rounding error is about 1e-7 and its
    /// truncation error about h² = 1e-6 relative).
    fn derivatives(&self, par: &[f64], f0: f64) -> (Vec<f64>, Matrix) {
        let d = par.len();
        let h = 1e-3;
        let mut moves = Vec::with_capacity(2 * d * d);
        for i in 0..d {
            moves.push(vec![(i, h)]);
            moves.push(vec![(i, -h)]);
            for j in 0..i {
                moves.push(vec![(i, h), (j, h)]);
                moves.push(vec![(i, h), (j, -h)]);
                moves.push(vec![(i, -h), (j, h)]);
                moves.push(vec![(i, -h), (j, -h)]);
            }
        }
        let v = self.values(par, &moves);
        let mut grad = vec![0.0; d];
        let mut hess = Matrix::zeros(d, d);
        let mut next = 0;
        for i in 0..d {
            let (fp, fm) = (v[next], v[next + 1]);
            next += 2;
            grad[i] = (fp - fm) / (2.0 * h);
            *hess.at_mut(i, i) = (fp - 2.0 * f0 + fm) / (h * h);
            for j in 0..i {
                let w = (v[next] - v[next + 1] - v[next + 2] + v[next + 3]) / (4.0 * h * h);
                next += 4;
                *hess.at_mut(i, j) = w;
                *hess.at_mut(j, i) = w;
            }
        }
        (grad, hess)
    }
}

/// The largest gradient element of a parameter not held at the τ floor.
fn max_free_gradient(par: &[f64], grad: &[f64], tau_start: usize) -> f64 {
    grad.iter()
        .enumerate()
        .filter(|&(i, g)| i < tau_start || par[i] > MIN_LOG_TAU + 1e-9 || *g < 0.0)
        .map(|(_, g)| g.abs())
        .fold(0.0, f64::max)
}

/// Quasi-Newton (BFGS on the inverse Hessian, central-difference gradients, backtracking
/// line search with the Armijo condition) from `par`, until the free gradient is below
/// [`GRADIENT_TOLERANCE`] or no step lowers the value. `par` and `f` are moved to the best
/// point found; returns the largest free gradient element there.
fn bfgs(obj: &mut Objective, par: &mut Vec<f64>, f: &mut f64, tau_start: usize) -> f64 {
    let d = par.len();
    let identity = || {
        let mut m = Matrix::zeros(d, d);
        for i in 0..d {
            *m.at_mut(i, i) = 1.0;
        }
        m
    };
    let mut hinv = identity();
    let mut fresh = true;
    let mut grad = obj.gradient(par);
    // The values of the last steps: when ten steps together gain less than 1e-11 relative,
    // the gradient's finite differences are at their noise and the Newton steps take over.
    let mut recent = vec![*f];
    for _ in 0..BFGS_STEPS {
        let largest = max_free_gradient(par, &grad, tau_start);
        if largest < GRADIENT_TOLERANCE
            || recent.len() > 10 && recent[recent.len() - 11] - *f < 1e-11 * (1.0 + f.abs())
        {
            return largest;
        }
        let mut dir: Vec<f64> = (0..d)
            .map(|i| -(0..d).map(|j| hinv.at(i, j) * grad[j]).sum::<f64>())
            .collect();
        let mut slope: f64 = dir.iter().zip(&grad).map(|(a, b)| a * b).sum();
        if slope >= 0.0 {
            hinv = identity();
            fresh = true;
            dir = grad.iter().map(|g| -g).collect();
            slope = -grad.iter().map(|g| g * g).sum::<f64>();
        }
        // No coordinate moves by more than 1 in one step (the parameters are logits and log
        // SDs): the first steepest-descent step would otherwise leave the data far behind.
        let longest = dir.iter().fold(0.0, |m: f64, v| m.max(v.abs()));
        let mut t = if longest > 1.0 { 1.0 / longest } else { 1.0 };
        let mut accepted = None;
        for _ in 0..40 {
            let mut trial: Vec<f64> = par.iter().zip(&dir).map(|(a, b)| a + t * b).collect();
            for v in &mut trial[tau_start..] {
                *v = v.max(MIN_LOG_TAU);
            }
            let ft = obj.value(&trial);
            if ft <= *f + 1e-4 * t * slope {
                accepted = Some((trial, ft));
                break;
            }
            t /= 2.0;
        }
        let Some((trial, ft)) = accepted else {
            if fresh {
                return largest;
            }
            hinv = identity();
            fresh = true;
            continue;
        };
        obj.settle(&trial);
        let new_grad = obj.gradient(&trial);
        let s: Vec<f64> = trial.iter().zip(par.iter()).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = new_grad.iter().zip(&grad).map(|(a, b)| a - b).collect();
        let sy: f64 = s.iter().zip(&y).map(|(a, b)| a * b).sum();
        let yy: f64 = y.iter().map(|v| v * v).sum();
        if sy > 1e-12 * yy.sqrt() * s.iter().map(|v| v * v).sum::<f64>().sqrt() {
            if fresh {
                // Scale the first inverse Hessian to the curvature along the step.
                for v in &mut hinv.data {
                    *v *= sy / yy;
                }
            }
            let rho = 1.0 / sy;
            let hy: Vec<f64> = (0..d)
                .map(|i| (0..d).map(|j| hinv.at(i, j) * y[j]).sum::<f64>())
                .collect();
            let yhy: f64 = y.iter().zip(&hy).map(|(a, b)| a * b).sum();
            for i in 0..d {
                for j in 0..d {
                    *hinv.at_mut(i, j) += -rho * (hy[i] * s[j] + s[i] * hy[j])
                        + (rho * rho * yhy + rho) * s[i] * s[j];
                }
            }
            fresh = false;
        }
        *par = trial;
        *f = ft;
        recent.push(ft);
        grad = new_grad;
    }
    max_free_gradient(par, &grad, tau_start)
}

/// Quasi-Newton ([`bfgs`]) over the parameters, then damped Newton (Levenberg) steps on the
/// central-difference Hessian from there until its gradient is below the tolerance (usually
/// at once: the Hessian is then taken once, at the optimum, for the SEs, as ordinal does).
/// Without `hessian` a converged quasi-Newton fit is returned as it is (the likelihood-ratio
/// refits need no SEs). Returns (optimum, its value, Hessian there, converged).
fn minimize(
    problem: &Problem,
    mut par: Vec<f64>,
    hessian_wanted: bool,
) -> Result<(Vec<f64>, f64, Option<Matrix>, bool), NoModel> {
    let mut obj = Objective {
        problem,
        u: vec![0.0; problem.q],
    };
    let mut f = obj.value(&par);
    if !f.is_finite() {
        return Err(NoModel(
            "the likelihood is not finite at the starting values".into(),
        ));
    }
    let tau_start = problem.k - 1 + problem.p;
    let gradient = bfgs(&mut obj, &mut par, &mut f, tau_start);
    if !hessian_wanted && gradient < REFIT_STALL_GRADIENT {
        // Converged, or stalled: ten steps gained less than 1e-11 relative, so the value is
        // at its minimum to far below what the likelihood-ratio test prints (the Newton
        // steps would stall at the same value, as they do on this data); the converged flag
        // is the one the Newton iteration gives a stall.
        return Ok((par, f, None, gradient < 1e-4));
    }
    let mut lambda = 1e-3;
    let mut stalled = 0;
    let mut converged = false;
    let mut hessian = None;
    for _ in 0..OUTER_STEPS {
        obj.settle(&par);
        let (grad, hess) = obj.derivatives(&par, f);
        // Parameters held at the τ floor do not count towards convergence.
        let max_free_gradient = max_free_gradient(&par, &grad, tau_start);
        let done = max_free_gradient < GRADIENT_TOLERANCE;
        hessian = Some(hess.clone());
        if done {
            converged = true;
            break;
        }
        let mut stepped = false;
        for _ in 0..30 {
            let mut damped = hess.clone();
            for i in 0..par.len() {
                *damped.at_mut(i, i) += lambda * (1.0 + hess.at(i, i).abs());
            }
            if let Some(c) = Cholesky::new(&damped) {
                let mut step = grad.clone();
                c.solve(&mut step);
                let mut trial: Vec<f64> = par.iter().zip(&step).map(|(a, b)| a - b).collect();
                for v in &mut trial[tau_start..] {
                    *v = v.max(MIN_LOG_TAU);
                }
                let ft = obj.value(&trial);
                if ft <= f {
                    stalled = if f - ft < 1e-13 * (1.0 + f.abs()) {
                        stalled + 1
                    } else {
                        0
                    };
                    par = trial;
                    f = ft;
                    lambda = (lambda / 10.0).max(1e-12);
                    stepped = true;
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !stepped || stalled >= 3 {
            // No step lowers the value further: the gradient's finite differences are at
            // their noise. Call that converged when the gradient is small all the same.
            converged = max_free_gradient < 1e-4;
            break;
        }
    }
    // The Hessian for the standard errors, at the optimum (the τ rows of a variance at its
    // floor are dropped by the caller's inversion failing there only through the τ block).
    Ok((par, f, hessian, converged))
}

/// Likelihood-ratio tests of each fixed term of the ordinal model (refits by Laplace).
///
/// # Errors
/// [`NoModel`] when a refit fails.
pub fn clmm_term_tests(
    design: &Design,
    fixed: FixedTerms,
    full: &ClmmFit,
    confidence: Confidence,
) -> Result<Vec<TermTest>, NoModel> {
    let mut fits: Vec<(FixedTerms, f64, usize)> = vec![(fixed, full.log_lik, full.parameters)];
    let mut out = Vec::new();
    for (term, big, small) in fixed.tests() {
        let mut get = |t: FixedTerms| -> Result<(f64, usize), NoModel> {
            if let Some(&(_, l, p)) = fits.iter().find(|f| f.0 == t) {
                return Ok((l, p));
            }
            let f = fit(design, t, confidence, Some(full))?;
            fits.push((t, f.log_lik, f.parameters));
            Ok((f.log_lik, f.parameters))
        };
        let (lb, pb) = get(big)?;
        let (ls, ps) = get(small)?;
        let chisq = (2.0 * (lb - ls)).max(0.0);
        let df = pb - ps;
        out.push(TermTest {
            term: term.to_owned(),
            chisq,
            df,
            p: chisq_sf(chisq, df),
        });
    }
    Ok(out)
}
