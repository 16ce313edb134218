//! Linear mixed models of rating scores, fitted as lme4 fits them (Bates, Mächler, Bolker &
//! Walker 2015, "Fitting linear mixed-effects models using lme4", J. Stat. Softw. 67(1)).
//!
//! The study's condition factors are fixed: the method ([`ConditionInfo::method`]) and the
//! compression ratio as a factor, with their interaction where every method was shown at every
//! ratio (`method * ratio`), else their sum. Subjects and clips are crossed random intercepts;
//! where every subject saw every method, a random slope of method within subject is tried
//! first (`(1 + method | subject)`), and the model falls back to intercepts when that fit is
//! singular or does not converge. References (conditions without a ratio) are left out of the
//! model: a reference has no method or ratio to be a level of.
//!
//! The fit follows the paper's section 3: the relative covariance factor Λθ, the penalized
//! least-squares system solved by a Cholesky factor, the profiled REML (eq. 41) or ML (eq. 34)
//! deviance, minimized over θ by a bounded Nelder-Mead (θ ≥ 0 for the diagonal elements of
//! Λθ). Fixed effects' covariance is σ² R_X⁻¹ R_X⁻ᵀ at θ̂, as `vcov()` of an lmer fit;
//! likelihood-ratio tests refit by ML (`anova(refit = TRUE)`). The ordinal model for category
//! scales is in [`crate::clmm`].
//!
//! The report's section ([`report_section`]) gives each model's fixed effects as a table and,
//! when figures are drawn, as a forest plot ([`forest_rows`] → [`crate::plots::Figure::Forest`]):
//! one figure per model, since the linear model's effects are on the score scale and the
//! ordinal model's in log odds.

// Matrix code indexes rows and columns by number, as the equations do.
#![allow(clippy::needless_range_loop)]

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use crate::confidence::Confidence;
use crate::descriptive::Rating;
use crate::dist::z_quantile;
use crate::findings::ConditionInfo;
use crate::linalg::{Cholesky, Matrix, nelder_mead};
use crate::report::{Report, Section};
use crate::tables::{Table, fmt_opt, fmt_p};

/// Tolerances of the θ optimizer: simplex values agreeing to 1e-12 (relative) and vertices to
/// 1e-8. The deviance is quadratic near its minimum, so θ̂ is then good to about 1e-6,
/// far inside the 1e-3 the tests allow against lme4.
const THETA_TOLERANCES: (f64, f64) = (1e-12, 1e-8);

/// Most deviance evaluations per fit.
const MAX_EVALUATIONS: usize = 40_000;

/// A θ diagonal element below this is on the boundary: the fit is singular (lme4's
/// `isSingular` tolerance).
pub const SINGULAR_TOLERANCE: f64 = 1e-4;

/// The data of a mixed model: one row per rating of a test condition, with its factors'
/// levels as indices into the sorted level lists.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Design {
    /// Scores.
    pub y: Vec<f64>,
    /// Subject index per row (into [`Self::subjects`]).
    pub subject: Vec<usize>,
    /// Clip index per row.
    pub clip: Vec<usize>,
    /// Method index per row.
    pub method: Vec<usize>,
    /// Ratio index per row.
    pub ratio: Vec<usize>,
    /// Subjects, ascending.
    pub subjects: Vec<u32>,
    /// Clips, in byte order (R: `sort(method = "radix")`).
    pub clips: Vec<String>,
    /// Methods, in byte order; the first is the baseline of the treatment contrasts.
    pub methods: Vec<String>,
    /// Ratios, ascending; the first is the baseline.
    pub ratios: Vec<f64>,
    /// Ratings of references left out.
    pub references_left_out: usize,
}

impl Design {
    /// The ratings of test conditions (known conditions with a ratio). References and
    /// ratings of unknown conditions are left out (references are counted).
    pub fn new(ratings: &[Rating], conditions: &[ConditionInfo]) -> Self {
        // Each test condition's (clip, method, ratio), made once per condition.
        let labels: BTreeMap<u32, (String, String, f64)> = conditions
            .iter()
            .filter_map(|c| {
                let x = c.compression_ratio.filter(|x| x.is_finite())?;
                Some((c.id, (c.clip.clone(), c.method(), x)))
            })
            .collect();
        let known: BTreeSet<u32> = conditions.iter().map(|c| c.id).collect();
        let mut rows: Vec<(u32, u32, f64)> = Vec::with_capacity(ratings.len());
        let mut references_left_out = 0;
        let mut rated: BTreeSet<u32> = BTreeSet::new();
        for r in ratings {
            if labels.contains_key(&r.condition) && r.score.is_finite() {
                rows.push((r.subject, r.condition, r.score));
                rated.insert(r.condition);
            } else if known.contains(&r.condition) {
                references_left_out += 1;
            }
        }
        let rated_labels = || rated.iter().filter_map(|id| labels.get(id));
        let clips: Vec<String> = rated_labels()
            .map(|l| l.0.clone())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let methods: Vec<String> = rated_labels()
            .map(|l| l.1.clone())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let mut ratios: Vec<f64> = rated_labels().map(|l| l.2).collect();
        ratios.sort_by(f64::total_cmp);
        ratios.dedup();
        let index: BTreeMap<u32, (usize, usize, usize)> = rated
            .iter()
            .filter_map(|id| {
                let (c, m, x) = labels.get(id)?;
                Some((
                    *id,
                    (
                        clips.binary_search(c).unwrap_or(0),
                        methods.binary_search(m).unwrap_or(0),
                        ratios.binary_search_by(|v| v.total_cmp(x)).unwrap_or(0),
                    ),
                ))
            })
            .collect();
        let subjects: Vec<u32> = rows
            .iter()
            .map(|r| r.0)
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let at = |id: u32| index.get(&id).copied().unwrap_or_default();
        Self {
            y: rows.iter().map(|r| r.2).collect(),
            subject: rows
                .iter()
                .map(|r| subjects.binary_search(&r.0).unwrap_or(0))
                .collect(),
            clip: rows.iter().map(|r| at(r.1).0).collect(),
            method: rows.iter().map(|r| at(r.1).1).collect(),
            ratio: rows.iter().map(|r| at(r.1).2).collect(),
            subjects,
            clips,
            methods,
            ratios,
            references_left_out,
        }
    }

    /// Number of rows.
    pub fn n(&self) -> usize {
        self.y.len()
    }

    /// Whether every method was shown at every ratio.
    pub fn crossed(&self) -> bool {
        let cells: BTreeSet<(usize, usize)> = self
            .method
            .iter()
            .copied()
            .zip(self.ratio.iter().copied())
            .collect();
        cells.len() == self.methods.len() * self.ratios.len()
    }

    /// Whether every subject rated every method.
    pub fn every_subject_every_method(&self) -> bool {
        let cells: BTreeSet<(usize, usize)> = self
            .subject
            .iter()
            .copied()
            .zip(self.method.iter().copied())
            .collect();
        cells.len() == self.subjects.len() * self.methods.len()
    }

    /// The fixed terms the design supports.
    pub fn fixed_terms(&self) -> FixedTerms {
        let method = self.methods.len() > 1;
        let ratio = self.ratios.len() > 1;
        FixedTerms {
            method,
            ratio,
            interaction: method && ratio && self.crossed(),
        }
    }
}

/// Which fixed terms a model has (besides the intercept).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct FixedTerms {
    /// Method main effect.
    pub method: bool,
    /// Ratio main effect.
    pub ratio: bool,
    /// Method × ratio interaction.
    pub interaction: bool,
}

impl FixedTerms {
    /// The right-hand side's fixed part in R's syntax (`method * ratio`, `method + ratio`,
    /// `ratio`, `1`).
    pub fn r_terms(self) -> String {
        match (self.method, self.ratio, self.interaction) {
            (true, true, true) => "method * ratio".into(),
            (true, true, false) => "method + ratio".into(),
            (true, false, _) => "method".into(),
            (false, true, _) => "ratio".into(),
            (false, false, _) => "1".into(),
        }
    }

    /// The models each term's likelihood-ratio test compares: (term, reduced model). The
    /// interaction is tested against the additive model; each main effect, in the additive
    /// model, against the model without it (R: `anova(update(m, . ~ . - term), m)` on ML
    /// fits).
    pub fn tests(self) -> Vec<(&'static str, FixedTerms, FixedTerms)> {
        let additive = FixedTerms {
            interaction: false,
            ..self
        };
        let mut out = Vec::new();
        if self.interaction {
            out.push(("method:ratio", self, additive));
        }
        if self.method {
            out.push((
                "method",
                additive,
                FixedTerms {
                    method: false,
                    ..additive
                },
            ));
        }
        if self.ratio {
            out.push((
                "ratio",
                additive,
                FixedTerms {
                    ratio: false,
                    ..additive
                },
            ));
        }
        out
    }
}

/// R's name of a ratio level (`30`, `2.5`).
fn ratio_name(x: f64) -> String {
    format!("{x}")
}

/// The fixed-effects model matrix (treatment contrasts, R's column names and order).
pub(crate) fn model_matrix(
    design: &Design,
    terms: FixedTerms,
    intercept: bool,
) -> (Vec<String>, Matrix) {
    let mut names = Vec::new();
    let mut cols: Vec<Box<dyn Fn(usize) -> f64 + '_>> = Vec::new();
    if intercept {
        names.push("(Intercept)".to_owned());
        cols.push(Box::new(|_| 1.0));
    }
    if terms.method {
        for m in 1..design.methods.len() {
            names.push(format!("method{}", design.methods[m]));
            cols.push(Box::new(move |i| {
                f64::from(u8::from(design.method[i] == m))
            }));
        }
    }
    if terms.ratio {
        for r in 1..design.ratios.len() {
            names.push(format!("ratio{}", ratio_name(design.ratios[r])));
            cols.push(Box::new(move |i| f64::from(u8::from(design.ratio[i] == r))));
        }
    }
    if terms.interaction {
        for r in 1..design.ratios.len() {
            for m in 1..design.methods.len() {
                names.push(format!(
                    "method{}:ratio{}",
                    design.methods[m],
                    ratio_name(design.ratios[r])
                ));
                cols.push(Box::new(move |i| {
                    f64::from(u8::from(design.method[i] == m && design.ratio[i] == r))
                }));
            }
        }
    }
    let mut x = Matrix::zeros(design.n(), cols.len());
    for i in 0..design.n() {
        for (j, c) in cols.iter().enumerate() {
            *x.at_mut(i, j) = c(i);
        }
    }
    (names, x)
}

/// The random part of a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct RandomTerms {
    /// `(1 + method | subject)` instead of `(1 | subject)`.
    pub method_slopes: bool,
    /// `(1 | clip)` (needs two clips or more).
    pub clip: bool,
}

impl RandomTerms {
    /// The random part in R's syntax.
    pub fn r_terms(self) -> String {
        let mut s = if self.method_slopes {
            "(1 + method | subject)".to_owned()
        } else {
            "(1 | subject)".to_owned()
        };
        if self.clip {
            s.push_str(" + (1 | clip)");
        }
        s
    }
}

/// A random-effects term's layout in Z and θ.
#[derive(Debug, Clone)]
struct ReTerm {
    group: &'static str,
    /// Per-level coefficient names.
    names: Vec<String>,
    levels: usize,
    /// First column of Z.
    offset: usize,
    /// First element of θ (lower triangle of T, column by column).
    theta: usize,
}

impl ReTerm {
    fn q(&self) -> usize {
        self.names.len()
    }
    fn thetas(&self) -> usize {
        self.q() * (self.q() + 1) / 2
    }
    /// The lower-triangular T of this term from θ.
    fn t(&self, theta: &[f64]) -> Matrix {
        let q = self.q();
        let mut t = Matrix::zeros(q, q);
        let mut k = self.theta;
        for j in 0..q {
            for i in j..q {
                *t.at_mut(i, j) = theta[k];
                k += 1;
            }
        }
        t
    }
}

/// Everything an evaluation of the deviance needs, computed once per model.
struct Prepared {
    n: usize,
    p: usize,
    q: usize,
    terms: Vec<ReTerm>,
    yty: f64,
    ztz: Matrix,
    ztx: Matrix,
    zty: Vec<f64>,
    xtx: Matrix,
    xty: Vec<f64>,
}

fn random_layout(design: &Design, random: RandomTerms) -> Vec<ReTerm> {
    let mut names = vec!["(Intercept)".to_owned()];
    if random.method_slopes {
        names.extend(design.methods[1..].iter().map(|m| format!("method{m}")));
    }
    let subject = ReTerm {
        group: "subject",
        levels: design.subjects.len(),
        offset: 0,
        theta: 0,
        names,
    };
    let mut terms = vec![subject];
    if random.clip {
        let offset = terms[0].levels * terms[0].q();
        let theta = terms[0].thetas();
        terms.push(ReTerm {
            group: "clip",
            names: vec!["(Intercept)".to_owned()],
            levels: design.clips.len(),
            offset,
            theta,
        });
    }
    terms
}

impl Prepared {
    fn new(design: &Design, x: &Matrix, random: RandomTerms) -> Self {
        let terms = random_layout(design, random);
        let q: usize = terms.iter().map(|t| t.levels * t.q()).sum();
        let n = design.n();
        let p = x.cols;
        let mut z = Vec::with_capacity(n);
        for i in 0..n {
            let mut row = vec![(terms[0].offset + design.subject[i] * terms[0].q(), 1.0)];
            if random.method_slopes && design.method[i] > 0 {
                row.push((
                    terms[0].offset + design.subject[i] * terms[0].q() + design.method[i],
                    1.0,
                ));
            }
            if let Some(c) = terms.get(1) {
                row.push((c.offset + design.clip[i], 1.0));
            }
            z.push(row);
        }
        let mut ztz = Matrix::zeros(q, q);
        let mut ztx = Matrix::zeros(q, p);
        let mut zty = vec![0.0; q];
        let mut xtx = Matrix::zeros(p, p);
        let mut xty = vec![0.0; p];
        let y = design.y.clone();
        for i in 0..n {
            for &(a, va) in &z[i] {
                for &(b, vb) in &z[i] {
                    *ztz.at_mut(a, b) += va * vb;
                }
                for j in 0..p {
                    *ztx.at_mut(a, j) += va * x.at(i, j);
                }
                zty[a] += va * y[i];
            }
            for j in 0..p {
                for k in 0..p {
                    *xtx.at_mut(j, k) += x.at(i, j) * x.at(i, k);
                }
                xty[j] += x.at(i, j) * y[i];
            }
        }
        let yty = y.iter().map(|v| v * v).sum();
        Self {
            n,
            p,
            q,
            terms,
            yty,
            ztz,
            ztx,
            zty,
            xtx,
            xty,
        }
    }

    fn theta_len(&self) -> usize {
        self.terms.iter().map(ReTerm::thetas).sum()
    }

    /// Lower bounds of θ: 0 on T's diagonals, unbounded below it.
    fn lower(&self) -> Vec<f64> {
        let mut lower = Vec::new();
        for t in &self.terms {
            for j in 0..t.q() {
                for i in j..t.q() {
                    lower.push(if i == j { 0.0 } else { f64::NEG_INFINITY });
                }
            }
        }
        lower
    }

    /// Λθ's nonzeros column by column: (row, value).
    fn lambda_columns(&self, theta: &[f64]) -> Vec<Vec<(usize, f64)>> {
        let mut cols = vec![Vec::new(); self.q];
        for term in &self.terms {
            let t = term.t(theta);
            let q = term.q();
            for level in 0..term.levels {
                let base = term.offset + level * q;
                for j in 0..q {
                    for i in j..q {
                        let v = t.at(i, j);
                        if v != 0.0 {
                            cols[base + j].push((base + i, v));
                        }
                    }
                }
            }
        }
        cols
    }

    /// The penalized least-squares solution at θ.
    fn solve(&self, theta: &[f64], reml: bool) -> Option<Solution> {
        let (q, p, n) = (self.q, self.p, self.n);
        let lam = self.lambda_columns(theta);
        // W = ZᵀZ Λ, then A = Λᵀ W + I.
        let mut w = Matrix::zeros(q, q);
        for i in 0..q {
            for (a, col) in lam.iter().enumerate() {
                *w.at_mut(i, a) = col.iter().map(|&(r, v)| self.ztz.at(i, r) * v).sum();
            }
        }
        let mut a = Matrix::zeros(q, q);
        for (ia, ca) in lam.iter().enumerate() {
            for b in 0..=ia {
                let v: f64 = ca.iter().map(|&(r, v)| v * w.at(r, b)).sum();
                *a.at_mut(ia, b) = v;
                *a.at_mut(b, ia) = v;
            }
            *a.at_mut(ia, ia) += 1.0;
        }
        let l = Cholesky::new(&a)?;
        // cu = L⁻¹ Λᵀ Zᵀ y; RZX = L⁻¹ Λᵀ Zᵀ X.
        let lt = |v: &dyn Fn(usize) -> f64| -> Vec<f64> {
            lam.iter()
                .map(|col| col.iter().map(|&(r, x)| x * v(r)).sum())
                .collect()
        };
        let mut cu = lt(&|r| self.zty[r]);
        l.solve_l(&mut cu);
        // RZX stored by column (RZXᵀ, p × q): the products below run along its rows.
        let mut rzx = Matrix::zeros(p, q);
        for j in 0..p {
            let mut c = lt(&|r| self.ztx.at(r, j));
            l.solve_l(&mut c);
            rzx.data[j * q..(j + 1) * q].copy_from_slice(&c);
        }
        // XᵀX − RZXᵀ RZX, its lower triangle only (all the Cholesky factor reads).
        let mut xtx = self.xtx.clone();
        for j in 0..p {
            let cj = &rzx.data[j * q..(j + 1) * q];
            for k in 0..=j {
                let ck = &rzx.data[k * q..(k + 1) * q];
                *xtx.at_mut(j, k) -= cj.iter().zip(ck).map(|(a, b)| a * b).sum::<f64>();
            }
        }
        let rx = Cholesky::new(&xtx)?;
        // cβ = R_X⁻ᵀ (Xᵀy − RZXᵀ cu), β = R_X⁻¹ cβ, and the penalized residual sum of squares
        // r² = yᵀy − ‖cu‖² − ‖cβ‖² (the paper's eq. 25-27): O(q²) per evaluation, not O(n).
        let mut beta: Vec<f64> = (0..p)
            .map(|j| self.xty[j] - (0..q).map(|i| rzx.at(j, i) * cu[i]).sum::<f64>())
            .collect();
        rx.solve_l(&mut beta);
        let r2 = self.yty
            - cu.iter().map(|v| v * v).sum::<f64>()
            - beta.iter().map(|v| v * v).sum::<f64>();
        rx.solve_lt(&mut beta);
        if r2.is_nan() || r2 <= 1e-12 * self.yty {
            return None;
        }
        let log_det_l = l.log_det_l();
        let log_det_rx = rx.log_det_l();
        let tau = std::f64::consts::TAU;
        let dof = if reml { (n - p) as f64 } else { n as f64 };
        let mut deviance = 2.0 * log_det_l + dof * (1.0 + (tau * r2 / dof).ln());
        if reml {
            deviance += 2.0 * log_det_rx;
        }
        Some(Solution {
            deviance,
            beta,
            sigma2: r2 / dof,
            rx,
        })
    }
}

struct Solution {
    deviance: f64,
    beta: Vec<f64>,
    sigma2: f64,
    rx: Cholesky,
}

/// One fixed-effect coefficient.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FixedEffect {
    /// R's coefficient name (`(Intercept)`, `methodwavelet-standard`, `ratio30`,
    /// `methodwavelet-standard:ratio30`; thresholds of an ordinal model `1|2`).
    pub name: String,
    /// Estimate.
    pub estimate: f64,
    /// Standard error.
    pub se: f64,
    /// Wald interval's lower bound at the report's confidence.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
}

/// One variance component.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VarianceComponent {
    /// Grouping factor (`subject`, `clip`, `Residual`).
    pub group: String,
    /// The coefficient it varies (`(Intercept)`, `methodX`; empty for the residual).
    pub name: String,
    /// Variance.
    pub variance: f64,
    /// Standard deviation.
    pub sd: f64,
}

/// A likelihood-ratio test of one fixed term.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TermTest {
    /// The term (`method`, `ratio`, `method:ratio`).
    pub term: String,
    /// χ² = the drop in −2 log L.
    pub chisq: f64,
    /// Degrees of freedom (parameters dropped).
    pub df: usize,
    /// p value.
    pub p: f64,
}

/// A fitted linear mixed model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LmmFit {
    /// The fixed part.
    pub fixed_terms: FixedTerms,
    /// The random part.
    pub random_terms: RandomTerms,
    /// Fitted by REML (else ML).
    pub reml: bool,
    /// Fixed effects.
    pub fixed: Vec<FixedEffect>,
    /// Variance components, the residual last.
    pub variances: Vec<VarianceComponent>,
    /// Correlations of a term's random effects: (group, first, second, r).
    pub correlations: Vec<(String, String, String, f64)>,
    /// θ̂ (lme4's `getME(m, "theta")`).
    pub theta: Vec<f64>,
    /// The minimized deviance (REML criterion for a REML fit).
    pub deviance: f64,
    /// Log-likelihood (the REML one for a REML fit, as `logLik()` gives).
    pub log_lik: f64,
    /// Parameters: fixed effects, θ and σ.
    pub parameters: usize,
    /// AIC = −2 log L + 2 · parameters.
    pub aic: f64,
    /// Rows.
    pub n: usize,
    /// The optimizer stopped on its tolerances (not on its evaluation cap).
    pub converged: bool,
    /// A θ diagonal element at its bound (below [`SINGULAR_TOLERANCE`]).
    pub singular: bool,
    /// Deviance evaluations.
    pub evaluations: usize,
}

impl LmmFit {
    /// The equivalent R call.
    pub fn r_formula(&self) -> String {
        let reml = if self.reml { "" } else { ", REML = FALSE" };
        format!(
            "lmer(score ~ {} + {}, data = d{reml})",
            self.fixed_terms.r_terms(),
            self.random_terms.r_terms()
        )
    }
}

/// Why a model could not be fitted.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct NoModel(pub String);

/// Fits `score ~ fixed + random` by REML or ML, with Wald intervals at `confidence`.
///
/// # Errors
/// [`NoModel`] saying why: too few subjects, fixed effects not estimable (rank-deficient X),
/// every score equal.
pub fn fit_lmm(
    design: &Design,
    fixed: FixedTerms,
    random: RandomTerms,
    reml: bool,
    confidence: Confidence,
) -> Result<LmmFit, NoModel> {
    if design.subjects.len() < 2 {
        return Err(NoModel(format!(
            "{} subject(s): a subject variance needs two subjects or more",
            design.subjects.len()
        )));
    }
    if random.clip && design.clips.len() < 2 {
        return Err(NoModel("a clip variance needs two clips or more".into()));
    }
    let first = design.y.first().copied().unwrap_or(0.0);
    if design.y.iter().all(|v| v.total_cmp(&first).is_eq()) {
        return Err(NoModel(
            "every score is the same: there is no variance to model".into(),
        ));
    }
    let (names, x) = model_matrix(design, fixed, true);
    if design.n() <= x.cols {
        return Err(NoModel("fewer ratings than fixed effects".into()));
    }
    let prepared = Prepared::new(design, &x, random);
    if Cholesky::new(&prepared.xtx).is_none() {
        return Err(NoModel(
            "the fixed effects are not estimable from this design (rank-deficient)".into(),
        ));
    }
    let lower = prepared.lower();
    let (theta, evaluations, converged) = minimize_theta(&prepared, &lower, reml);
    let Some(sol) = prepared.solve(&theta, reml) else {
        return Err(NoModel(
            "the penalized least-squares system is singular at the optimum".into(),
        ));
    };
    let z = z_quantile(1.0 - confidence.alpha() / 2.0).unwrap_or(f64::NAN);
    let vcov = sol.rx.inverse();
    let fixed_effects = names
        .into_iter()
        .enumerate()
        .map(|(j, name)| {
            let se = (sol.sigma2 * vcov.at(j, j)).sqrt();
            FixedEffect {
                name,
                estimate: sol.beta[j],
                se,
                lower: sol.beta[j] - z * se,
                upper: sol.beta[j] + z * se,
            }
        })
        .collect();
    let (variances, correlations) = components(&prepared.terms, &theta, sol.sigma2);
    let singular = prepared
        .lower()
        .iter()
        .zip(&theta)
        .any(|(lo, t)| *lo == 0.0 && *t < SINGULAR_TOLERANCE);
    let parameters = prepared.p + prepared.theta_len() + 1;
    let log_lik = -sol.deviance / 2.0;
    Ok(LmmFit {
        fixed_terms: fixed,
        random_terms: random,
        reml,
        fixed: fixed_effects,
        variances,
        correlations,
        theta,
        deviance: sol.deviance,
        log_lik,
        parameters,
        aic: -2.0 * log_lik + 2.0 * parameters as f64,
        n: prepared.n,
        converged,
        singular,
        evaluations,
    })
}

/// θ̂: Nelder-Mead from lme4's start (1 on T's diagonals, 0 below them), then from that
/// start with each diagonal element on its bound 0 in turn, and from 0.3 on every diagonal:
/// with a random slope the criterion can have a second local minimum on the boundary, and
/// one start alone may stop there. The lowest is kept; (θ̂, evaluations, whether its run
/// converged).
fn minimize_theta(prepared: &Prepared, lower: &[f64], reml: bool) -> (Vec<f64>, usize, bool) {
    let default: Vec<f64> = lower
        .iter()
        .map(|&lo| if lo == 0.0 { 1.0 } else { 0.0 })
        .collect();
    let mut starts = vec![default.clone()];
    if default.len() > 1 {
        for (i, &lo) in lower.iter().enumerate() {
            if lo == 0.0 {
                let mut s = default.clone();
                s[i] = 0.0;
                starts.push(s);
            }
        }
        starts.push(default.iter().map(|&v| v * 0.3).collect());
    }
    let run = |start: &Vec<f64>| {
        let mut objective = |theta: &[f64]| {
            prepared
                .solve(theta, reml)
                .map_or(f64::INFINITY, |s| s.deviance)
        };
        nelder_mead(
            &mut objective,
            start,
            lower,
            0.2,
            THETA_TOLERANCES,
            MAX_EVALUATIONS,
        )
    };
    // The runs are independent: they share the starts out over two threads (each run is
    // the sequential one, and the best is chosen in the starts' order as before).
    let runs: Vec<_> = if starts.len() > 1 {
        let half = starts.len().div_ceil(2);
        std::thread::scope(|scope| {
            let second = scope.spawn(|| starts[half..].iter().map(run).collect::<Vec<_>>());
            let mut runs: Vec<_> = starts[..half].iter().map(run).collect();
            runs.extend(second.join().unwrap_or_default());
            runs
        })
    } else {
        starts.iter().map(run).collect()
    };
    if runs.len() != starts.len() {
        return (default, 0, false);
    }
    let mut best: Option<(Vec<f64>, f64, bool)> = None;
    let mut evaluations = 0;
    for (theta, value, used, converged) in runs {
        evaluations += used;
        if best.as_ref().is_none_or(|b| value < b.1) {
            best = Some((theta, value, converged));
        }
    }
    let (theta, _, converged) = best.unwrap_or((default, f64::INFINITY, false));
    (theta, evaluations, converged)
}

/// Type alias for the correlations list.
type Correlations = Vec<(String, String, String, f64)>;

/// Variance components σ² T Tᵀ of each term and the residual σ².
fn components(
    terms: &[ReTerm],
    theta: &[f64],
    sigma2: f64,
) -> (Vec<VarianceComponent>, Correlations) {
    let mut variances = Vec::new();
    let mut correlations = Vec::new();
    for term in terms {
        let t = term.t(theta);
        let q = term.q();
        let cov =
            |i: usize, j: usize| sigma2 * (0..q).map(|k| t.at(i, k) * t.at(j, k)).sum::<f64>();
        for i in 0..q {
            let v = cov(i, i);
            variances.push(VarianceComponent {
                group: term.group.to_owned(),
                name: term.names[i].clone(),
                variance: v,
                sd: v.sqrt(),
            });
            for j in 0..i {
                let r = cov(i, j) / (v * cov(j, j)).sqrt();
                correlations.push((
                    term.group.to_owned(),
                    term.names[j].clone(),
                    term.names[i].clone(),
                    r,
                ));
            }
        }
    }
    variances.push(VarianceComponent {
        group: "Residual".into(),
        name: String::new(),
        variance: sigma2,
        sd: sigma2.sqrt(),
    });
    (variances, correlations)
}

/// χ² survival function (p of a likelihood-ratio test); `NaN` for df 0.
pub(crate) fn chisq_sf(x: f64, df: usize) -> f64 {
    ChiSquared::new(df as f64).map_or(f64::NAN, |c| if x <= 0.0 { 1.0 } else { c.sf(x) })
}

/// Likelihood-ratio tests of each fixed term by ML refits with the same random part.
///
/// # Errors
/// [`NoModel`] when a refit fails.
pub fn lmm_term_tests(
    design: &Design,
    fixed: FixedTerms,
    random: RandomTerms,
    confidence: Confidence,
) -> Result<Vec<TermTest>, NoModel> {
    let mut cache: Vec<(FixedTerms, LmmFit)> = Vec::new();
    let mut ml = |terms: FixedTerms| -> Result<LmmFit, NoModel> {
        if let Some((_, f)) = cache.iter().find(|(t, _)| *t == terms) {
            return Ok(f.clone());
        }
        let f = fit_lmm(design, terms, random, false, confidence)?;
        cache.push((terms, f.clone()));
        Ok(f)
    };
    let mut out = Vec::new();
    for (term, full, reduced) in fixed.tests() {
        let f = ml(full)?;
        let r = ml(reduced)?;
        let chisq = (r.deviance - f.deviance).max(0.0);
        let df = f.fixed.len() - r.fixed.len();
        out.push(TermTest {
            term: term.to_owned(),
            chisq,
            df,
            p: chisq_sf(chisq, df),
        });
    }
    Ok(out)
}

/// Most distinct scores a scale may have for the ordinal model: a 1-5 scale in half steps
/// has 9, an 11-grade scale 11; a 0-100 slider has more and is left to the linear model.
pub const MAX_CATEGORIES: usize = 11;

/// The mixed models of a rating study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MixedAnalysis {
    /// Rows modelled (ratings of test conditions).
    pub n: usize,
    /// Subjects.
    pub subjects: usize,
    /// Clips.
    pub clips: usize,
    /// Methods (levels).
    pub methods: Vec<String>,
    /// Ratios (levels).
    pub ratios: Vec<f64>,
    /// Ratings of references left out.
    pub references_left_out: usize,
    /// The linear mixed model (REML), or why there is none.
    pub lmm: Result<LmmFit, NoModel>,
    /// Why its random part is what it is (slopes fitted, or the fallback and its cause).
    pub lmm_choice: String,
    /// Likelihood-ratio tests of its fixed terms (ML refits).
    pub lmm_tests: Result<Vec<TermTest>, NoModel>,
    /// The ML fit of the same model (its log-likelihood and AIC compare across fixed parts).
    pub lmm_ml: Option<LmmFit>,
    /// The ordinal model, for scales of at most [`MAX_CATEGORIES`] distinct scores.
    pub clmm: Option<Result<crate::clmm::ClmmFit, NoModel>>,
    /// Its likelihood-ratio tests.
    pub clmm_tests: Result<Vec<TermTest>, NoModel>,
}

/// Most ratings the report fits mixed models to: each deviance evaluation is O(q³) after an
/// O(n) set-up, but the ordinal model's every evaluation passes over every rating (some
/// thousands of evaluations), so larger sets are left to R on ratings.csv (the report prints
/// the call).
pub const MAX_RATINGS: usize = 50_000;

/// Most random effects (columns of Z) of the dense linear fit: its Cholesky factor is O(q³)
/// per evaluation. 200 holds 45 subjects with a slope of four methods and 20 clips, or 180
/// subjects' intercepts and 20 clips.
pub const MAX_RANDOM_EFFECTS: usize = 200;

/// Most random effects (subjects and clips) and ratings of the ordinal model: each of its
/// evaluations solves for the random effects' mode (O(n + q³) per Newton step), and each
/// outer step takes 2d² evaluations for the Hessian of its d parameters.
pub const MAX_ORDINAL: (usize, usize) = (100, 20_000);

/// Why a design is too large for the dense fits, if it is.
fn too_large(design: &Design) -> Option<NoModel> {
    let q = design.subjects.len() + design.clips.len();
    (design.n() > MAX_RATINGS || q > MAX_RANDOM_EFFECTS).then(|| {
        NoModel(format!(
            "{} ratings and {q} random effects are more than the report's dense fit takes ({MAX_RATINGS} ratings, {MAX_RANDOM_EFFECTS} random effects); fit the model printed here in R on ratings.csv",
            design.n()
        ))
    })
}

/// The REML fit with the random part the design supports: a slope of method within subject
/// where every subject rated every method (and the fit converges and is not singular), else
/// intercepts; (random part, fit, why).
fn choose_lmm(
    design: &Design,
    fixed: FixedTerms,
    clip: bool,
    confidence: Confidence,
) -> (RandomTerms, Result<LmmFit, NoModel>, String) {
    let intercepts = RandomTerms {
        method_slopes: false,
        clip,
    };
    let k = design.methods.len();
    let (random, lmm, lmm_choice) = if k < 2 {
        let fit = fit_lmm(design, fixed, intercepts, true, confidence);
        (
            intercepts,
            fit,
            "One method: random intercepts of subject and clip.".to_owned(),
        )
    } else if !design.every_subject_every_method() {
        let fit = fit_lmm(design, fixed, intercepts, true, confidence);
        (intercepts, fit, "Not every subject rated every method, so a slope of method within subject is not estimable: random intercepts only.".to_owned())
    } else if design.subjects.len() * k + design.clips.len() > MAX_RANDOM_EFFECTS {
        let fit = fit_lmm(design, fixed, intercepts, true, confidence);
        (
            intercepts,
            fit,
            format!(
                "A slope of method within subject would make {} random effects, more than the dense fit's {MAX_RANDOM_EFFECTS}: random intercepts only.",
                design.subjects.len() * k + design.clips.len()
            ),
        )
    } else if design.subjects.len() <= k {
        let fit = fit_lmm(design, fixed, intercepts, true, confidence);
        (
            intercepts,
            fit,
            format!(
                "{} subjects cannot support a {k}-by-{k} covariance of method within subject: random intercepts only.",
                design.subjects.len()
            ),
        )
    } else {
        let slopes = RandomTerms {
            method_slopes: true,
            clip,
        };
        match fit_lmm(design, fixed, slopes, true, confidence) {
            Ok(f) if f.converged && !f.singular => (slopes, Ok(f), "Every subject rated every method: a random slope of method within subject was fitted (it converged and is not singular).".to_owned()),
            other => {
                let why = match other {
                    Ok(f) if !f.converged => "did not converge".to_owned(),
                    Ok(_) => format!("was singular (a θ diagonal element below {SINGULAR_TOLERANCE}: a variance at zero or a correlation at ±1)"),
                    Err(NoModel(e)) => format!("could not be fitted ({e})"),
                };
                let fit = fit_lmm(design, fixed, intercepts, true, confidence);
                (intercepts, fit, format!("Every subject rated every method, but the model with a random slope of method within subject {why}; the fallback, random intercepts only, was fitted."))
            }
        }
    };
    (random, lmm, lmm_choice)
}

/// Fits the study's mixed models (`None` without ratings of test conditions).
pub fn analyze(
    ratings: &[Rating],
    conditions: &[ConditionInfo],
    confidence: Confidence,
) -> Option<MixedAnalysis> {
    let design = Design::new(ratings, conditions);
    if design.n() == 0 {
        return None;
    }
    let fixed = design.fixed_terms();
    let clip = design.clips.len() >= 2;
    let mut categories = design.y.clone();
    categories.sort_by(f64::total_cmp);
    categories.dedup();
    let ordinal = categories.len() <= MAX_CATEGORIES;
    if let Some(why) = too_large(&design) {
        let random = RandomTerms {
            method_slopes: false,
            clip,
        };
        return Some(MixedAnalysis {
            n: design.n(),
            subjects: design.subjects.len(),
            clips: design.clips.len(),
            methods: design.methods.clone(),
            ratios: design.ratios.clone(),
            references_left_out: design.references_left_out,
            lmm: Err(NoModel(format!(
                "{}: lmer(score ~ {} + {}, data = d)",
                why.0,
                fixed.r_terms(),
                random.r_terms()
            ))),
            lmm_choice: String::new(),
            lmm_tests: Ok(Vec::new()),
            lmm_ml: None,
            clmm: ordinal.then(|| Err(why.clone())),
            clmm_tests: Ok(Vec::new()),
        });
    }
    let (random, lmm, lmm_choice) = choose_lmm(&design, fixed, clip, confidence);
    let lmm_tests = if lmm.is_ok() {
        lmm_term_tests(&design, fixed, random, confidence)
    } else {
        Ok(Vec::new())
    };
    let lmm_ml = lmm
        .as_ref()
        .ok()
        .and_then(|_| fit_lmm(&design, fixed, random, false, confidence).ok());
    let q = design.subjects.len() + design.clips.len();
    let clmm = if ordinal && (q > MAX_ORDINAL.0 || design.n() > MAX_ORDINAL.1) {
        Some(Err(NoModel(format!(
            "{} ratings and {q} random effects are more than the report's ordinal fit takes ({} ratings, {} random effects); fit the model in R on ratings.csv: clmm(factor(score, ordered = TRUE) ~ {} + (1 | subject) + (1 | clip), data = d)",
            design.n(),
            MAX_ORDINAL.1,
            MAX_ORDINAL.0,
            fixed.r_terms()
        ))))
    } else {
        ordinal.then(|| crate::clmm::fit_clmm(&design, fixed, confidence))
    };
    let clmm_tests = match &clmm {
        Some(Ok(c)) => crate::clmm::clmm_term_tests(&design, fixed, c, confidence),
        _ => Ok(Vec::new()),
    };
    Some(MixedAnalysis {
        n: design.n(),
        subjects: design.subjects.len(),
        clips: design.clips.len(),
        methods: design.methods.clone(),
        ratios: design.ratios.clone(),
        references_left_out: design.references_left_out,
        lmm,
        lmm_choice,
        lmm_tests,
        lmm_ml,
        clmm,
        clmm_tests,
    })
}

/// The rows of a forest plot of the fixed effects (intercept and thresholds left out): the
/// linear model's, then the ordinal model's (its names prefixed `clmm: `), each as (name,
/// estimate, lower, upper) at the report's confidence.
pub fn forest_rows(m: &MixedAnalysis) -> Vec<(String, f64, f64, f64)> {
    let mut rows: Vec<(String, f64, f64, f64)> = Vec::new();
    if let Ok(fit) = &m.lmm {
        rows.extend(
            fit.fixed
                .iter()
                .filter(|e| e.name != "(Intercept)")
                .map(|e| (e.name.clone(), e.estimate, e.lower, e.upper)),
        );
    }
    if let Some(Ok(c)) = &m.clmm {
        rows.extend(
            c.fixed
                .iter()
                .map(|e| (format!("clmm: {}", e.name), e.estimate, e.lower, e.upper)),
        );
    }
    rows
}

fn effects_table(
    name: &str,
    caption: &str,
    effects: &[FixedEffect],
    confidence: Confidence,
) -> Table {
    let conf = format!("{:.0} %", confidence.percent());
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: vec![
            "Term".into(),
            "Estimate".into(),
            "SE".into(),
            format!("{conf} CI lower"),
            format!("{conf} CI upper"),
        ],
        rows: effects
            .iter()
            .map(|e| {
                vec![
                    e.name.clone(),
                    fmt_opt(Some(e.estimate), 3),
                    fmt_opt(Some(e.se), 3),
                    fmt_opt(Some(e.lower), 3),
                    fmt_opt(Some(e.upper), 3),
                ]
            })
            .collect(),
    }
}

fn tests_table(name: &str, caption: &str, tests: &[TermTest]) -> Table {
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: vec!["Term".into(), "χ²".into(), "df".into(), "p".into()],
        rows: tests
            .iter()
            .map(|t| {
                vec![
                    t.term.clone(),
                    fmt_opt(Some(t.chisq), 2),
                    t.df.to_string(),
                    fmt_p(Some(t.p)),
                ]
            })
            .collect(),
    }
}

/// The "Mixed models" section: the data modelled, the linear mixed model (its R call, why
/// its random part, fixed effects, tests, variance components, fit) and the ordinal model for
/// a category scale. With `figures`, each fitted model's fixed effects (intercept and
/// thresholds left out, [`forest_rows`]) are drawn as a forest plot
/// ([`crate::plots::Figure::Forest`]), one figure per model, `mixed_forest_lmm` on the score
/// scale and `mixed_forest_clmm` on the log-odds scale: the two scales never share an axis.
pub fn report_section(
    report: &mut Report,
    m: Option<&MixedAnalysis>,
    confidence: Confidence,
    figures: bool,
) {
    let Some(m) = m else {
        return;
    };
    let s = report.section("Mixed models");
    s.text(format!(
        "{} ratings of test conditions from {} subjects on {} clip(s): method ({}) and compression ratio ({}) are fixed factors (treatment contrasts, the first level the baseline), subject and clip crossed random effects. {} Every rating is a row (hidden repeats included, no observer rejected); the models are fitted as R's lme4 and ordinal fit them, and each table gives the call that reproduces it on ratings.csv (method = codec, ratio = factor(compression_ratio)).",
        m.n,
        m.subjects,
        m.clips,
        m.methods.join(", "),
        m.ratios.iter().map(|r| format!("{r}:1")).collect::<Vec<_>>().join(", "),
        if m.references_left_out > 0 {
            format!("The {} ratings of references are left out: a reference has no method or ratio to be a level of.", m.references_left_out)
        } else {
            String::new()
        }
    ));
    match &m.lmm {
        Err(NoModel(why)) => {
            s.text(format!("No linear mixed model: {why}."));
        }
        Ok(fit) => lmm_blocks(s, m, fit, confidence),
    }
    match &m.clmm {
        None => {
            s.text(format!("No ordinal model: the scores take more than {MAX_CATEGORIES} distinct values, so they are treated as a continuous scale."));
        }
        Some(Err(NoModel(why))) => {
            s.text(format!("No cumulative link mixed model: {why}."));
        }
        Some(Ok(c)) => clmm_blocks(s, m, c, confidence),
    }
    if figures {
        forest_figures(s, m, confidence);
    }
}

/// The forest plots of the two models' fixed effects, one figure each (none for a model
/// without a fit or without effects besides the intercept).
fn forest_figures(s: &mut Section, m: &MixedAnalysis, confidence: Confidence) {
    let (mut lmm, mut clmm) = (Vec::new(), Vec::new());
    for (name, estimate, lower, upper) in forest_rows(m) {
        match name.strip_prefix("clmm: ") {
            Some(effect) => clmm.push((effect.to_owned(), estimate, lower, upper)),
            None => lmm.push((name, estimate, lower, upper)),
        }
    }
    let conf = confidence.percent();
    let figures = [
        (
            "mixed_forest_lmm",
            "Fixed effects of the linear mixed model",
            format!("Effect on the score (estimate, Wald {conf:.0} % CI)"),
            lmm,
        ),
        (
            "mixed_forest_clmm",
            "Fixed effects of the cumulative link mixed model",
            format!("Effect in log odds of a higher rating (estimate, Wald {conf:.0} % CI)"),
            clmm,
        ),
    ];
    for (name, title, x_label, rows) in figures {
        if !rows.is_empty() {
            s.figure(
                name,
                crate::plots::Figure::Forest {
                    title: title.to_owned(),
                    x_label,
                    rows,
                },
            );
        }
    }
}

fn lmm_blocks(s: &mut Section, m: &MixedAnalysis, fit: &LmmFit, confidence: Confidence) {
    s.text(format!(
        "Linear mixed model, REML: {}. {} {}",
        fit.r_formula(),
        m.lmm_choice,
        if fit.converged {
            format!("The optimizer (bounded Nelder-Mead on θ) converged in {} evaluations.", fit.evaluations)
        } else {
            format!("The optimizer did NOT converge within {} evaluations: read the estimates with care.", fit.evaluations)
        }
    ));
    s.table(effects_table(
        "mixed_lmm_fixed",
        &format!(
            "Fixed effects of the linear mixed model (Wald {:.0} % intervals)",
            confidence.percent()
        ),
        &fit.fixed,
        confidence,
    ));
    match &m.lmm_tests {
        Ok(t) if !t.is_empty() => {
            s.table(tests_table(
                "mixed_lmm_tests",
                "Likelihood-ratio tests of the fixed terms (ML refits: the interaction against the additive model, each main effect within the additive model)",
                t,
            ));
        }
        Ok(_) => {}
        Err(NoModel(why)) => {
            s.text(format!("No likelihood-ratio tests: {why}."));
        }
    }
    let mut rows: Vec<Vec<String>> = fit
        .variances
        .iter()
        .map(|v| {
            vec![
                v.group.clone(),
                v.name.clone(),
                fmt_opt(Some(v.variance), 4),
                fmt_opt(Some(v.sd), 4),
            ]
        })
        .collect();
    for (g, a, b, r) in &fit.correlations {
        rows.push(vec![
            g.clone(),
            format!("corr({a}, {b})"),
            String::new(),
            fmt_opt(Some(*r), 3),
        ]);
    }
    s.table(Table {
        name: "mixed_lmm_variance".into(),
        caption: "Variance components of the linear mixed model (REML)".into(),
        columns: vec![
            "Group".into(),
            "Coefficient".into(),
            "Variance".into(),
            "SD".into(),
        ],
        rows,
    });
    s.text(format!(
        "REML criterion {:.2}, log-likelihood (REML) {:.2}, AIC (REML) {:.2}{}; {} parameters, {} ratings{}.",
        fit.deviance,
        fit.log_lik,
        fit.aic,
        m.lmm_ml.as_ref().map_or_else(String::new, |ml| format!("; ML log-likelihood {:.2}, AIC {:.2}", ml.log_lik, ml.aic)),
        fit.parameters,
        fit.n,
        if fit.singular { "; the fit is singular (a variance at zero)" } else { "" }
    ));
}

fn clmm_blocks(
    s: &mut Section,
    m: &MixedAnalysis,
    c: &crate::clmm::ClmmFit,
    confidence: Confidence,
) {
    s.text(format!(
        "Cumulative link mixed model (logit link, flexible thresholds, Laplace approximation) of the {} categories {}: {}. A positive effect moves ratings up the scale.{} {}",
        c.categories.len(),
        c.categories.iter().map(|v| format!("{v}")).collect::<Vec<_>>().join(", "),
        c.r_formula(),
        if c.clip {
            ""
        } else {
            " With fewer than three clips there is no clip intercept (ordinal's clmm takes a grouping factor of three levels or more)."
        },
        if c.converged { "The fit converged." } else { "The fit did NOT converge: read the estimates with care." }
    ));
    s.table(effects_table(
        "mixed_clmm_thresholds",
        "Thresholds of the cumulative link mixed model",
        &c.thresholds,
        confidence,
    ));
    s.table(effects_table(
        "mixed_clmm_fixed",
        &format!(
            "Fixed effects of the cumulative link mixed model (log odds, Wald {:.0} % intervals)",
            confidence.percent()
        ),
        &c.fixed,
        confidence,
    ));
    match &m.clmm_tests {
        Ok(t) if !t.is_empty() => {
            s.table(tests_table(
                "mixed_clmm_tests",
                "Likelihood-ratio tests of the ordinal model's fixed terms",
                t,
            ));
        }
        Ok(_) => {}
        Err(NoModel(why)) => {
            s.text(format!(
                "No likelihood-ratio tests of the ordinal model: {why}."
            ));
        }
    }
    s.text(format!(
        "Random intercepts: {}. Log-likelihood (Laplace) {:.2}, AIC {:.2}; {} parameters, {} ratings.",
        c.variances.iter().map(|(g, v)| format!("{g} variance {v:.4} (SD {:.4})", v.sqrt())).collect::<Vec<_>>().join(", "),
        c.log_lik,
        c.aic,
        c.parameters,
        c.n
    ));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn condition(id: u32, codec: &str, clip: &str, ratio: Option<f64>) -> ConditionInfo {
        ConditionInfo {
            id,
            codec: codec.into(),
            params: BTreeMap::new(),
            clip: clip.into(),
            compression_ratio: ratio,
        }
    }

    fn rating(subject: u32, condition: u32, score: f64) -> Rating {
        Rating {
            subject,
            condition,
            score,
        }
    }

    /// A balanced one-way design (subjects only: one clip, method and ratio) has REML's
    /// closed form: σ² = MSW, σ²_subject = (MSB − MSW) / m when positive.
    #[test]
    fn balanced_one_way_reml_is_the_anova_estimate() {
        let conditions = [condition(0, "a", "walk", Some(10.0))];
        let scores = [
            [3.0, 3.5, 4.0, 3.0],
            [4.5, 4.0, 5.0, 4.5],
            [2.0, 2.5, 3.0, 2.0],
        ];
        let ratings: Vec<Rating> = scores
            .iter()
            .enumerate()
            .flat_map(|(s, row)| row.iter().map(move |&v| rating(s as u32, 0, v)))
            .collect();
        let design = Design::new(&ratings, &conditions);
        let random = RandomTerms {
            method_slopes: false,
            clip: false,
        };
        let fit = fit_lmm(
            &design,
            design.fixed_terms(),
            random,
            true,
            Confidence::default(),
        )
        .unwrap();
        let means: Vec<f64> = scores.iter().map(|r| r.iter().sum::<f64>() / 4.0).collect();
        let grand = means.iter().sum::<f64>() / 3.0;
        let msb = 4.0 * means.iter().map(|m| (m - grand).powi(2)).sum::<f64>() / 2.0;
        let msw = scores
            .iter()
            .zip(&means)
            .map(|(r, m)| r.iter().map(|v| (v - m).powi(2)).sum::<f64>())
            .sum::<f64>()
            / 9.0;
        assert!(
            (fit.variances[1].variance - msw).abs() < 1e-7 * msw,
            "{fit:?}"
        );
        let subject = (msb - msw) / 4.0;
        assert!(
            (fit.variances[0].variance - subject).abs() < 1e-6 * subject,
            "{fit:?}"
        );
        assert!((fit.fixed[0].estimate - grand).abs() < 1e-9);
        // SE of the grand mean: √(MSB / (subjects · m)).
        assert!((fit.fixed[0].se - (msb / 12.0).sqrt()).abs() < 1e-6);
        assert!(fit.converged && !fit.singular);
    }

    #[test]
    fn degenerate_designs_give_reasons_not_models() {
        let conditions = [
            condition(0, "a", "walk", Some(10.0)),
            condition(1, "b", "walk", Some(10.0)),
            condition(2, "ref", "walk", None),
        ];
        // One subject.
        let one = [rating(0, 0, 3.0), rating(0, 1, 4.0), rating(0, 2, 5.0)];
        let m = analyze(&one, &conditions, Confidence::default()).unwrap();
        assert!(m.lmm.is_err() && matches!(m.clmm, Some(Err(_))));
        assert_eq!(m.references_left_out, 1);
        let mut report = Report::new("t");
        report_section(&mut report, Some(&m), Confidence::default(), false);
        assert_eq!(report.sections.len(), 1);
        // Every score the same.
        let same: Vec<Rating> = (0..4)
            .flat_map(|s| [rating(s, 0, 4.0), rating(s, 1, 4.0)])
            .collect();
        let m = analyze(&same, &conditions, Confidence::default()).unwrap();
        assert!(m.lmm.unwrap_err().0.contains("same"));
        // Only references: no model at all.
        assert!(analyze(&[rating(0, 2, 5.0)], &conditions, Confidence::default()).is_none());
        // One clip: the clip term is left out, the rest is fitted.
        let varied: Vec<Rating> = (0..5)
            .flat_map(|s| {
                let s_f = f64::from(s);
                [
                    rating(s, 0, 3.0 + 0.25 * s_f),
                    rating(s, 1, 2.0 + 0.5 * (s_f % 2.0)),
                    rating(s, 0, 3.5),
                    rating(s, 1, 2.5 + 0.25 * (s_f % 3.0)),
                ]
            })
            .collect();
        let m = analyze(&varied, &conditions, Confidence::default()).unwrap();
        let fit = m.lmm.as_ref().unwrap();
        assert!(!fit.random_terms.clip);
        assert_eq!(fit.fixed.len(), 2);
        assert!(fit.r_formula().starts_with("lmer(score ~ method + "));
        let forest = forest_rows(&m);
        assert_eq!(forest[0].0, "methodb");
        assert!(forest[0].2 < forest[0].1 && forest[0].1 < forest[0].3);
    }
}
