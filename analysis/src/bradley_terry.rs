//! Bradley-Terry scale values from pair comparisons (ITU-T P.910 PC).
//!
//! Item `i` has a strength `p_i = exp(s_i)`, and it is preferred over `j` with probability
//! `p_i / (p_i + p_j)` (Bradley & Terry 1952). The scale values `s` are fitted by maximum
//! likelihood with Hunter's (2004) MM algorithm,
//! `p_i <- W_i / sum_j n_ij / (p_i + p_j)` (`W_i` the wins of `i`, `n_ij` the comparisons of
//! `i` and `j`), run until no scale value moves by more than [`TOLERANCE`]. The scale is fixed
//! by one item, the anchor, at 0; the others are natural-log odds of being preferred over it.
//!
//! The maximum-likelihood estimate is finite exactly when the directed graph "i was preferred
//! over j at least once" is strongly connected (Ford 1957; Hunter 2004, assumption 1): an item
//! that never lost, or a group of items that never lost to the rest, would have an infinite
//! scale value. [`fit`] checks this first and says which item breaks it instead of reporting a
//! number the iteration happened to stop at.
//!
//! Standard errors come from the observed Fisher information of the log strengths with the
//! anchor's row and column removed (the anchor's value is fixed, so its SE is 0); the interval
//! is `s ± z · SE`. They treat every comparison as independent, which repeated comparisons
//! by the same subject are not quite (the report says so).
//!
//! With "no preference" answers (ties), [`fit_with_ties`] fits Davidson's (1970) extension:
//! `P(i preferred over j) = p_i / (p_i + p_j + ν sqrt(p_i p_j))` and `P(tie) =
//! ν sqrt(p_i p_j) / (p_i + p_j + ν sqrt(p_i p_j))`, by Newton-Raphson on the scale values and
//! `ln ν`, with its own checks for an infinite scale value or tie parameter (the formulas and
//! conditions are at the function). Davidson, R. R. (1970). On extending the Bradley-Terry
//! model to accommodate ties in paired comparison experiments. JASA 65, 317-328.

use serde::Serialize;

use crate::confidence::Confidence;
use crate::dist::z_quantile;
use crate::error::AnalysisError;

/// Largest change of any scale value at which the MM iteration stops.
pub const TOLERANCE: f64 = 1e-12;
/// Most MM iterations (each one pass over the item pairs).
pub const MAX_ITERATIONS: usize = 100_000;

/// Most items one fit takes (the win matrix and the information matrix are `n × n`).
pub const MAX_ITEMS: usize = 2_000;

/// The win counts of `n` items: `wins[i][j]` is how often `i` was preferred over `j`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct WinMatrix {
    /// Row `i`, column `j`: the times `i` won against `j`.
    pub wins: Vec<Vec<u64>>,
}

impl WinMatrix {
    /// `n` items, no comparisons.
    #[must_use]
    pub fn new(n: usize) -> Self {
        Self {
            wins: vec![vec![0; n]; n],
        }
    }

    /// The number of items.
    #[must_use]
    pub fn len(&self) -> usize {
        self.wins.len()
    }

    /// Whether there are no items.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.wins.is_empty()
    }

    /// Counts one comparison `winner` over `loser` (ignored when either is not an item or
    /// they are the same).
    pub fn add(&mut self, winner: usize, loser: usize) {
        if winner != loser
            && let Some(row) = self.wins.get_mut(winner)
            && let Some(w) = row.get_mut(loser)
        {
            *w += 1;
        }
    }

    /// Wins of item `i` over all others.
    #[must_use]
    pub fn wins_of(&self, i: usize) -> u64 {
        self.wins.get(i).map_or(0, |r| r.iter().sum())
    }

    /// Comparisons item `i` took part in.
    #[must_use]
    pub fn comparisons_of(&self, i: usize) -> u64 {
        (0..self.len()).map(|j| self.n(i, j)).sum()
    }

    /// Comparisons between `i` and `j`.
    fn n(&self, i: usize, j: usize) -> u64 {
        if i == j {
            return 0;
        }
        self.wins[i][j] + self.wins[j][i]
    }

    /// The first item (in index order) that cannot be reached from item 0 along "was
    /// preferred over" edges, or that cannot reach item 0, with which it is; `None` when the
    /// win graph is strongly connected.
    fn unconnected(&self) -> Option<(usize, &'static str)> {
        unconnected_by(
            self.len(),
            |i, j| self.wins[i][j] > 0,
            ["never lost to", "never won against"],
        )
    }
}

/// The first item (in index order) that cannot be reached from item 0 along the directed
/// edges `edge(i, j)`, with `how[0]`, or that cannot reach item 0, with `how[1]`; `None` when
/// the graph is strongly connected.
fn unconnected_by(
    n: usize,
    edge: impl Fn(usize, usize) -> bool,
    how: [&'static str; 2],
) -> Option<(usize, &'static str)> {
    let reach = |forward: bool| {
        let mut seen = vec![false; n];
        let mut stack = vec![0];
        seen[0] = true;
        while let Some(i) = stack.pop() {
            for (j, s) in seen.iter_mut().enumerate() {
                let e = if forward { edge(i, j) } else { edge(j, i) };
                if e && !*s {
                    *s = true;
                    stack.push(j);
                }
            }
        }
        seen
    };
    // Forward from 0: items that 0 beat, directly or through others. An item outside it
    // (with the items it beat) never lost to 0's side.
    if let Some(i) = reach(true).iter().position(|s| !s) {
        return Some((i, how[0]));
    }
    if let Some(i) = reach(false).iter().position(|s| !s) {
        return Some((i, how[1]));
    }
    None
}

/// A Bradley-Terry fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BtEstimate {
    /// Scale value of each item, natural-log units, the anchor's 0.
    pub scale: Vec<f64>,
    /// Standard error of each scale value (0 for the anchor).
    pub se: Vec<f64>,
    /// Lower confidence bound of each scale value.
    pub lower: Vec<f64>,
    /// Upper confidence bound of each scale value.
    pub upper: Vec<f64>,
    /// MM iterations run.
    pub iterations: usize,
    /// Whether the iteration met [`TOLERANCE`] within [`MAX_ITERATIONS`].
    pub converged: bool,
    /// Log-likelihood at the estimate.
    pub log_likelihood: f64,
}

/// The outcome of [`fit`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum BtOutcome {
    /// The maximum-likelihood scale values.
    Fitted(BtEstimate),
    /// No finite maximum-likelihood estimate: the reason, naming an item by index.
    NoFiniteEstimate {
        /// The item that breaks the connection.
        item: usize,
        /// How it breaks it ("never lost to" / "never won against" the anchor's side).
        how: &'static str,
    },
}

/// Fits Bradley-Terry scale values to `wins`, item `anchor` fixed at 0, with `confidence`
/// intervals from the Fisher information.
///
/// # Errors
/// [`AnalysisError::TooFew`] for fewer than two items; [`AnalysisError::InvalidParameter`]
/// for an anchor that is not an item or more than [`MAX_ITEMS`] items.
pub fn fit(
    wins: &WinMatrix,
    anchor: usize,
    confidence: Confidence,
) -> Result<BtOutcome, AnalysisError> {
    let n = wins.len();
    check_items("Bradley-Terry items", n, anchor)?;
    if let Some((item, how)) = wins.unconnected() {
        return Ok(BtOutcome::NoFiniteEstimate { item, how });
    }
    let w: Vec<f64> = (0..n).map(|i| wins.wins_of(i) as f64).collect();
    let mut p = vec![1.0_f64; n];
    let mut iterations = 0;
    let converged = loop {
        iterations += 1;
        let mut next = vec![0.0; n];
        for i in 0..n {
            let denominator: f64 = (0..n)
                .filter(|&j| j != i)
                .map(|j| wins.n(i, j) as f64 / (p[i] + p[j]))
                .sum();
            next[i] = w[i] / denominator;
        }
        // Rescale so the anchor's strength is 1 (its scale value 0).
        let a = next[anchor];
        let mut change = 0.0_f64;
        for i in 0..n {
            next[i] /= a;
            change = change.max((next[i].ln() - p[i].ln()).abs());
        }
        p = next;
        if change <= TOLERANCE {
            break true;
        }
        if iterations >= MAX_ITERATIONS {
            break false;
        }
    };
    let scale: Vec<f64> = p.iter().map(|x| x.ln()).collect();
    let mut log_likelihood = 0.0;
    // Fisher information of the log strengths.
    let mut info = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..n {
            if i == j {
                continue;
            }
            let pij = p[i] / (p[i] + p[j]);
            log_likelihood += wins.wins[i][j] as f64 * pij.ln();
            let v = wins.n(i, j) as f64 * pij * (1.0 - pij);
            info[i][i] += v;
            info[i][j] -= v;
        }
    }
    let free: Vec<usize> = (0..n).filter(|&i| i != anchor).collect();
    let reduced: Vec<Vec<f64>> = free
        .iter()
        .map(|&i| free.iter().map(|&j| info[i][j]).collect())
        .collect();
    let inverse = invert(reduced);
    let z = z_quantile(0.5 + confidence.level() / 2.0).unwrap_or(f64::NAN);
    let mut se = vec![0.0; n];
    for (k, &i) in free.iter().enumerate() {
        se[i] = inverse
            .as_ref()
            .and_then(|m| m.get(k).and_then(|r| r.get(k)))
            .map_or(f64::NAN, |v| v.max(0.0).sqrt());
    }
    let lower = scale.iter().zip(&se).map(|(s, e)| s - z * e).collect();
    let upper = scale.iter().zip(&se).map(|(s, e)| s + z * e).collect();
    Ok(BtOutcome::Fitted(BtEstimate {
        scale,
        se,
        lower,
        upper,
        iterations,
        converged,
        log_likelihood,
    }))
}

/// The inverse of a symmetric positive definite matrix by Gauss-Jordan elimination with
/// partial pivoting; `None` when it is singular.
fn invert(mut a: Vec<Vec<f64>>) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let mut inv: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    for col in 0..n {
        let pivot = (col..n).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, pivot);
        inv.swap(col, pivot);
        let d = a[col][col];
        for j in 0..n {
            a[col][j] /= d;
            inv[col][j] /= d;
        }
        for r in 0..n {
            if r == col {
                continue;
            }
            let f = a[r][col];
            if f == 0.0 {
                continue;
            }
            for j in 0..n {
                a[r][j] -= f * a[col][j];
                inv[r][j] -= f * inv[col][j];
            }
        }
    }
    Some(inv)
}

/// Counts of "no preference" answers among `n` items: `ties[i][j]`, equal to `ties[j][i]`, is
/// how often a subject preferred neither `i` nor `j` (Davidson's model, [`fit_with_ties`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TieMatrix {
    /// Row `i`, column `j`: the ties of `i` and `j` (symmetric, the diagonal 0).
    pub ties: Vec<Vec<u64>>,
}

impl TieMatrix {
    /// `n` items, no ties.
    #[must_use]
    pub fn new(n: usize) -> Self {
        Self {
            ties: vec![vec![0; n]; n],
        }
    }

    /// The number of items.
    #[must_use]
    pub fn len(&self) -> usize {
        self.ties.len()
    }

    /// Whether there are no items.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.ties.is_empty()
    }

    /// Counts one tie of `i` and `j`, in both `ties[i][j]` and `ties[j][i]` (ignored when either
    /// is not an item or they are the same).
    pub fn add(&mut self, i: usize, j: usize) {
        let has = |a: usize, b: usize| self.ties.get(a).is_some_and(|r| b < r.len());
        if i != j && has(i, j) && has(j, i) {
            self.ties[i][j] += 1;
            self.ties[j][i] += 1;
        }
    }

    /// Ties of `i` and `j` (0 when either is not an item or they are the same).
    #[must_use]
    pub fn get(&self, i: usize, j: usize) -> u64 {
        if i == j {
            return 0;
        }
        self.ties
            .get(i)
            .and_then(|r| r.get(j))
            .copied()
            .unwrap_or(0)
    }

    /// Ties of item `i` with all others.
    #[must_use]
    pub fn ties_of(&self, i: usize) -> u64 {
        (0..self.len()).map(|j| self.get(i, j)).sum()
    }

    /// All ties, each pair counted once.
    #[must_use]
    pub fn total(&self) -> u64 {
        (0..self.len())
            .map(|i| (i + 1..self.len()).map(|j| self.get(i, j)).sum::<u64>())
            .sum()
    }
}

/// A fit of Davidson's model ([`fit_with_ties`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TiesEstimate {
    /// Scale value `s_i = ln p_i` of each item, natural-log units, the anchor's 0.
    pub scale: Vec<f64>,
    /// Standard error of each scale value (0 for the anchor).
    pub se: Vec<f64>,
    /// Lower confidence bound of each scale value, `s - z · SE`.
    pub lower: Vec<f64>,
    /// Upper confidence bound of each scale value, `s + z · SE`.
    pub upper: Vec<f64>,
    /// The tie parameter ν: at equal strengths a tie has probability ν / (2 + ν).
    pub tie_parameter: f64,
    /// Standard error of ν by the delta method from ln ν: `ν · SE(ln ν)`.
    pub tie_se: f64,
    /// Lower confidence bound of ν, `exp(ln ν - z · SE(ln ν))` (always positive).
    pub tie_lower: f64,
    /// Upper confidence bound of ν, `exp(ln ν + z · SE(ln ν))`.
    pub tie_upper: f64,
    /// Newton-Raphson iterations run.
    pub iterations: usize,
    /// Whether the iteration met [`TOLERANCE`] within [`MAX_ITERATIONS`] (see
    /// [`fit_with_ties`] for its rounding floor).
    pub converged: bool,
    /// Log-likelihood at the estimate: `sum w_ij ln P(i over j) + sum t_ij ln P(tie)`, no
    /// multinomial constants (as [`BtEstimate::log_likelihood`]).
    pub log_likelihood: f64,
}

/// The outcome of [`fit_with_ties`]. Every variant but `Fitted` says why there is no (or no
/// finite) estimate of the full model; [`TiesOutcome::explanation`] puts it in a sentence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum TiesOutcome {
    /// The maximum-likelihood scale values and tie parameter.
    Fitted(TiesEstimate),
    /// No finite scale value: `item` never lost to or tied with (or never won against or tied
    /// with) the items linked to item 0, counting a tie as a link both ways.
    NoFiniteEstimate {
        /// The item that breaks the connection.
        item: usize,
        /// How it breaks it ("never lost to or tied with" / "never won against or tied with"
        /// the items linked to item 0).
        how: &'static str,
    },
    /// No tie in the data: the likelihood keeps rising as ν falls to 0, where Davidson's
    /// model is Bradley-Terry's, so ν̂ = 0 on the boundary of its range and the scale values
    /// are those of [`fit`] (its outcome, always `Fitted` here, the connection having been
    /// checked already).
    NoTies(BtEstimate),
    /// ν̂ = ∞: the ties outweigh the preferences, and the likelihood rises without bound as ν
    /// grows (with the scale values spreading apart unless `decided` is 0). See
    /// [`fit_with_ties`] for the exact condition.
    TieParameterInfinite {
        /// All ties.
        ties: u64,
        /// All comparisons with a preference.
        decided: u64,
    },
}

impl TiesOutcome {
    /// A sentence for a report on why the outcome is not `Fitted`, the items named by `name`
    /// (by index); `None` for `Fitted`.
    pub fn explanation(&self, name: impl Fn(usize) -> String) -> Option<String> {
        match self {
            Self::Fitted(_) => None,
            Self::NoFiniteEstimate { item, how } => Some(format!(
                "no finite scale values: {} {how} the items linked to {} (a tie counting as \
                 a link both ways), so its maximum-likelihood scale value would be infinite; \
                 compare more pairs or more subjects.",
                name(*item),
                name(0)
            )),
            Self::NoTies(_) => Some(
                "no comparison ended in a tie: the tie parameter's maximum-likelihood \
                 estimate is 0, where Davidson's model is the Bradley-Terry model, whose \
                 scale values are reported."
                    .to_owned(),
            ),
            Self::TieParameterInfinite { ties, decided: 0 } => Some(format!(
                "all {ties} comparisons ended in a tie: the tie parameter's \
                 maximum-likelihood estimate is infinite and the scale values are not \
                 identified."
            )),
            Self::TieParameterInfinite { ties, decided } => Some(format!(
                "the {ties} ties outweigh the {decided} preferences: no pair was decided both \
                 ways and no preferences run in a circle beyond what the ties bridge, so the \
                 likelihood rises without bound as the tie parameter grows and the scale \
                 values spread apart; there is no finite estimate."
            )),
        }
    }
}

/// One compared pair of [`fit_with_ties`]: items `i < j`, the wins of `i` over `j`, of `j`
/// over `i`, and their ties.
#[derive(Debug, Clone, Copy)]
struct TiedPair {
    i: usize,
    j: usize,
    wij: f64,
    wji: f64,
    tij: f64,
}

impl TiedPair {
    fn n(&self) -> f64 {
        self.wij + self.wji + self.tij
    }

    /// `[ln P(i over j), ln P(j over i), ln P(tie)]` at scale values `s` and `theta = ln ν`,
    /// each its log numerator less `ln D` by a log-sum-exp.
    fn log_probs(&self, s: &[f64], theta: f64) -> [f64; 3] {
        let (a, b) = (s[self.i], s[self.j]);
        let c = theta + 0.5 * (a + b);
        let m = a.max(b).max(c);
        let log_d = m + ((a - m).exp() + (b - m).exp() + (c - m).exp()).ln();
        [a - log_d, b - log_d, c - log_d]
    }
}

/// Davidson's log-likelihood.
fn davidson_log_likelihood(pairs: &[TiedPair], s: &[f64], theta: f64) -> f64 {
    pairs
        .iter()
        .map(|p| {
            let [li, lj, lt] = p.log_probs(s, theta);
            p.wij * li + p.wji * lj + p.tij * lt
        })
        .sum()
}

/// The score and the information (negative Hessian) of Davidson's log-likelihood in
/// `(s_0, ..., s_{n-1}, θ)`, θ at index `n` (formulas at [`fit_with_ties`]).
fn davidson_score_information(
    pairs: &[TiedPair],
    s: &[f64],
    theta: f64,
) -> (Vec<f64>, Vec<Vec<f64>>) {
    let t = s.len();
    let mut g = vec![0.0; t + 1];
    let mut info = vec![vec![0.0; t + 1]; t + 1];
    for p in pairs {
        let [li, lj, lt] = p.log_probs(s, theta);
        let (pi, pj, pt) = (li.exp(), lj.exp(), lt.exp());
        let (i, j, m) = (p.i, p.j, p.n());
        g[i] += p.wij + 0.5 * p.tij - m * (pi + 0.5 * pt);
        g[j] += p.wji + 0.5 * p.tij - m * (pj + 0.5 * pt);
        g[t] += p.tij - m * pt;
        let ss = m * (pi * pj + 0.25 * pt * (pi + pj));
        info[i][i] += ss;
        info[j][j] += ss;
        info[i][j] -= ss;
        info[j][i] -= ss;
        let st = m * 0.5 * pt * (pj - pi);
        info[i][t] += st;
        info[t][i] += st;
        info[j][t] -= st;
        info[t][j] -= st;
        info[t][t] += m * pt * (pi + pj);
    }
    (g, info)
}

/// The dot product of two equally long slices.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solves `a x = b` for a symmetric positive definite `a` by its Cholesky factor; `None` when
/// `a` is not positive definite to rounding.
fn cholesky_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for k in 0..n {
        let d = a[k][k] - dot(&a[k][..k], &a[k][..k]);
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        let d = d.sqrt();
        a[k][k] = d;
        for i in k + 1..n {
            let v = (a[i][k] - dot(&a[i][..k], &a[k][..k])) / d;
            a[i][k] = v;
        }
    }
    for i in 0..n {
        b[i] = (b[i] - dot(&a[i][..i], &b[..i])) / a[i][i];
    }
    for i in (0..n).rev() {
        let v: f64 = (i + 1..n).map(|m| a[m][i] * b[m]).sum();
        b[i] = (b[i] - v) / a[i][i];
    }
    Some(b)
}

/// Whether ν̂ is infinite: whether scale values `x` exist with `x_i - x_j >= 1` for every
/// pair in which `i` was preferred over `j` and `|x_i - x_j| <= 1` for every tied pair. These
/// are difference constraints, feasible exactly when the graph with an edge `i -> j` of
/// weight -1 for each such preference and edges both ways of weight +1 for each tied pair has
/// no negative cycle (Bellman-Ford from a virtual source at distance 0 to every item).
fn tie_parameter_unbounded(wins: &WinMatrix, ties: &TieMatrix) -> bool {
    let n = wins.len();
    // A pair decided both ways is a cycle of weight -2: the common case, found at once.
    if (0..n).any(|i| (i + 1..n).any(|j| wins.wins[i][j] > 0 && wins.wins[j][i] > 0)) {
        return false;
    }
    let mut edges: Vec<(usize, usize, i64)> = Vec::new();
    for i in 0..n {
        for j in 0..n {
            if wins.wins[i][j] > 0 {
                edges.push((i, j, -1));
            }
            if ties.get(i, j) > 0 {
                edges.push((i, j, 1));
            }
        }
    }
    let mut dist = vec![0_i64; n];
    for _ in 0..=n {
        let mut relaxed = false;
        for &(u, v, w) in &edges {
            if dist[u] + w < dist[v] {
                dist[v] = dist[u] + w;
                relaxed = true;
            }
        }
        if !relaxed {
            return true;
        }
    }
    false
}

/// Newton-steps smaller than this that no longer shrink are at the rounding floor of the
/// score, and end the iteration as converged.
const ROUNDING_FLOOR: f64 = 1e-9;

/// Newton-Raphson with step halving for Davidson's model (see [`fit_with_ties`]): the scale
/// values (the anchor's 0), θ, the iterations run and whether it converged.
fn davidson_newton(
    pairs: &[TiedPair],
    n: usize,
    anchor: usize,
    theta0: f64,
) -> (Vec<f64>, f64, usize, bool) {
    let idx: Vec<usize> = (0..=n).filter(|&i| i != anchor).collect();
    let mut s = vec![0.0; n];
    let mut theta = theta0;
    let mut ll = davidson_log_likelihood(pairs, &s, theta);
    let mut iterations = 0;
    let mut previous = f64::INFINITY;
    let converged = loop {
        iterations += 1;
        let (g, info) = davidson_score_information(pairs, &s, theta);
        let reduced: Vec<Vec<f64>> = idx
            .iter()
            .map(|&a| idx.iter().map(|&b| info[a][b]).collect())
            .collect();
        let Some(step) = cholesky_solve(reduced, idx.iter().map(|&k| g[k]).collect()) else {
            break false;
        };
        let size = step.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let slack = 1e-13 * (1.0 + ll.abs());
        let mut lambda = 1.0;
        let accepted = loop {
            let mut s_new = s.clone();
            let mut theta_new = theta;
            for (&k, d) in idx.iter().zip(&step) {
                if k == n {
                    theta_new += lambda * d;
                } else {
                    s_new[k] += lambda * d;
                }
            }
            let ll_new = davidson_log_likelihood(pairs, &s_new, theta_new);
            if ll_new >= ll - slack {
                break Some((s_new, theta_new, ll_new));
            }
            lambda *= 0.5;
            if lambda < 1e-12 {
                break None;
            }
        };
        let Some((s_new, theta_new, ll_new)) = accepted else {
            break false;
        };
        (s, theta, ll) = (s_new, theta_new, ll_new);
        let change = lambda * size;
        if change <= TOLERANCE || (change <= ROUNDING_FLOOR && change >= previous) {
            break true;
        }
        if iterations >= MAX_ITERATIONS {
            break false;
        }
        previous = change;
    };
    (s, theta, iterations, converged)
}

/// A fit's item count `n` (named `what`) and anchor: 2 to [`MAX_ITEMS`] items, the anchor
/// one of them.
fn check_items(what: &'static str, n: usize, anchor: usize) -> Result<(), AnalysisError> {
    if n < 2 {
        return Err(AnalysisError::TooFew {
            what,
            needed: 2,
            got: n,
        });
    }
    if n > MAX_ITEMS {
        return Err(AnalysisError::InvalidParameter {
            name: what,
            value: n as f64,
            reason: "at most 2000 items per fit",
        });
    }
    if anchor >= n {
        return Err(AnalysisError::InvalidParameter {
            name: "anchor",
            value: anchor as f64,
            reason: "the anchor must be one of the items",
        });
    }
    Ok(())
}

/// The input checks of [`fit_with_ties`] (its errors).
fn check_tied_input(
    wins: &WinMatrix,
    ties: &TieMatrix,
    anchor: usize,
) -> Result<(), AnalysisError> {
    let n = wins.len();
    check_items("Davidson items", n, anchor)?;
    for (what, rows) in [("win matrix", &wins.wins), ("tie matrix", &ties.ties)] {
        if rows.len() != n {
            return Err(AnalysisError::LengthMismatch {
                what,
                left: n,
                right: rows.len(),
            });
        }
        if let Some(r) = rows.iter().find(|r| r.len() != n) {
            return Err(AnalysisError::LengthMismatch {
                what,
                left: n,
                right: r.len(),
            });
        }
    }
    if let Some(i) = (0..n).find(|&i| (0..n).any(|j| ties.ties[i][j] != ties.ties[j][i])) {
        return Err(AnalysisError::InvalidParameter {
            name: "tie matrix row",
            value: i as f64,
            reason: "tie counts must be symmetric (ties[i][j] == ties[j][i])",
        });
    }
    Ok(())
}

/// Fits Davidson's (1970) model for pair comparisons with ties ("no preference" answers),
/// item `anchor` fixed at 0, with `confidence` intervals from the observed information.
///
/// # The model
/// Item `i` has strength `p_i = exp(s_i)`; with the tie parameter `ν = exp(θ) > 0` one
/// comparison of `i` and `j` ends
///
/// - `i` preferred with `π_i = p_i / D_ij`, `j` preferred with `π_j = p_j / D_ij`,
/// - a tie with `π_t = ν sqrt(p_i p_j) / D_ij`, where `D_ij = p_i + p_j + ν sqrt(p_i p_j)`.
///
/// At `ν = 0` it is the Bradley-Terry model of [`fit`]; at equal strengths a tie has
/// probability `ν / (2 + ν)`. With `w_ij` the times `i` was preferred over `j`, `t_ij` the
/// ties and `n_ij = w_ij + w_ji + t_ij`, the log-likelihood is
///
/// `ℓ = Σ_{i<j} [w_ij s_i + w_ji s_j + t_ij (θ + (s_i + s_j)/2) − n_ij ln D_ij]`,
///
/// `ln D_ij` a log-sum-exp of `s_i`, `s_j`, `θ + (s_i + s_j)/2`, so `ℓ` is concave in
/// `(s, θ)`. Its score, with `∂ ln D_ij / ∂s_i = π_i + π_t/2` and `∂ ln D_ij / ∂θ = π_t`:
///
/// - `∂ℓ/∂s_i = Σ_j [w_ij + t_ij/2 − n_ij (π_i + π_t/2)]`,
/// - `∂ℓ/∂θ = Σ_{i<j} (t_ij − n_ij π_t)`;
///
/// its information `I = −∇²ℓ` sums over the pairs (the covariance of `n_ij` trinomial
/// outcomes, so observed and expected information agree):
///
/// - `I_ii += n_ij (π_i π_j + π_t (π_i + π_j)/4)`, the same to `I_jj`, its negative to `I_ij`,
/// - `I_iθ += n_ij π_t (π_j − π_i)/2`, its negative to `I_jθ`,
/// - `I_θθ += n_ij π_t (π_i + π_j)`.
///
/// # The estimate
/// Newton-Raphson on `(s` without the anchor's, `θ)` from `s = 0` and `ν = 2f/(1 − f)` (`f`
/// the share of ties: the ν whose tie probability at equal strengths is `f`), each step
/// `I⁻¹ ∇ℓ` (Cholesky) halved until `ℓ` does not fall (beyond 1e-13 of `|ℓ|`, its rounding),
/// until no parameter moves by more than [`TOLERANCE`], or at most [`MAX_ITERATIONS`] steps.
/// Steps that stop shrinking while below 1e-9 are the rounding floor of the score and count
/// as converged too. `ℓ` being concave and, under the conditions below, strictly so with a
/// finite maximum, the maximum is unique and Newton with step halving reaches it.
///
/// Standard errors: `I` at the estimate with the anchor's row and column removed, in
/// `(s_free, θ)`, inverted (its `s` block is the same in `(s_free, ν)`: reparametrising `θ`
/// alone does not change it); `SE(s_i)` the root of its diagonal, the interval
/// `s ± z · SE`; `SE(ν) = ν · SE(θ)` by the delta method from `ln ν`, and the interval of `ν`
/// `exp(θ ± z · SE(θ))`. Like [`fit`] they count every comparison as independent.
///
/// # When there is no finite estimate
/// The maximum is finite exactly when no direction of the parameters keeps every observed
/// outcome among the most probable of its pair (the concave `ℓ` then rises, or stays, along
/// it for ever). Checked in this order:
///
/// 1. Counting a tie of `i` and `j` as if each had beaten the other once, the graph "`i` was
///    preferred over or tied with `j`" must be strongly connected, as in [`fit`] (Ford 1957,
///    Hunter 2004 for Bradley-Terry): with ν fixed, `π_t → 0` both as `p_i/p_j → 0` and as
///    `p_i/p_j → ∞`, so an observed tie holds the ratio back from both sides, as a win each
///    way does, and an item or group that never lost to or tied with the rest would have an
///    infinite scale value: [`TiesOutcome::NoFiniteEstimate`].
/// 2. Without any tie, `ℓ` rises as `ν → 0`: [`TiesOutcome::NoTies`] with the Bradley-Terry
///    fit, the maximum on that boundary.
/// 3. `ν̂ = ∞` when scale values `x` exist with `x_i − x_j ≥ 1` for every pair where `i` was
///    preferred over `j` and `|x_i − x_j| ≤ 1` for every tied pair: moving `s` along `x` while
///    `θ` rises by 1/2 per unit keeps every observed outcome most probable (only ties; or two
///    items with ties and preferences one way only, where `ν̂ = t/sqrt(w_12 w_21)` has a zero
///    below). Found as a system of difference constraints (Bellman-Ford); a pair decided
///    both ways, or preferences around a cycle, rule it out:
///    [`TiesOutcome::TieParameterInfinite`].
///
/// Otherwise no such direction exists (step 1 rules out those with `θ` fixed, the ties those
/// with `θ` falling, step 3 those with `θ` rising) and the estimate is finite.
///
/// # Errors
/// [`AnalysisError::TooFew`] for fewer than two items; [`AnalysisError::InvalidParameter`]
/// for an anchor that is not an item, more than [`MAX_ITEMS`] items or a tie matrix that is
/// not symmetric; [`AnalysisError::LengthMismatch`] when the matrices are not both `n × n`.
pub fn fit_with_ties(
    wins: &WinMatrix,
    ties: &TieMatrix,
    anchor: usize,
    confidence: Confidence,
) -> Result<TiesOutcome, AnalysisError> {
    check_tied_input(wins, ties, anchor)?;
    let n = wins.len();
    if let Some((item, how)) = unconnected_by(
        n,
        |i, j| wins.wins[i][j] > 0 || ties.get(i, j) > 0,
        [
            "never lost to or tied with",
            "never won against or tied with",
        ],
    ) {
        return Ok(TiesOutcome::NoFiniteEstimate { item, how });
    }
    let total_ties = ties.total();
    if total_ties == 0 {
        return Ok(match fit(wins, anchor, confidence)? {
            BtOutcome::Fitted(e) => TiesOutcome::NoTies(e),
            BtOutcome::NoFiniteEstimate { item, how } => {
                TiesOutcome::NoFiniteEstimate { item, how }
            }
        });
    }
    if tie_parameter_unbounded(wins, ties) {
        let decided = (0..n).map(|i| wins.wins_of(i)).sum();
        return Ok(TiesOutcome::TieParameterInfinite {
            ties: total_ties,
            decided,
        });
    }
    let pairs: Vec<TiedPair> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .map(|(i, j)| TiedPair {
            i,
            j,
            wij: wins.wins[i][j] as f64,
            wji: wins.wins[j][i] as f64,
            tij: ties.get(i, j) as f64,
        })
        .filter(|p| p.n() > 0.0)
        .collect();
    let all: f64 = pairs.iter().map(TiedPair::n).sum();
    let f = total_ties as f64 / all;
    let (scale, theta, iterations, converged) =
        davidson_newton(&pairs, n, anchor, (2.0 * f / (1.0 - f)).ln());
    let log_likelihood = davidson_log_likelihood(&pairs, &scale, theta);
    let (_, info) = davidson_score_information(&pairs, &scale, theta);
    let idx: Vec<usize> = (0..=n).filter(|&i| i != anchor).collect();
    let reduced: Vec<Vec<f64>> = idx
        .iter()
        .map(|&a| idx.iter().map(|&b| info[a][b]).collect())
        .collect();
    let inverse = invert(reduced);
    let sd = |k: usize| {
        inverse
            .as_ref()
            .and_then(|m| m.get(k).and_then(|r| r.get(k)))
            .map_or(f64::NAN, |v| v.max(0.0).sqrt())
    };
    let z = z_quantile(0.5 + confidence.level() / 2.0).unwrap_or(f64::NAN);
    let mut se = vec![0.0; n];
    for (k, &i) in idx.iter().enumerate() {
        if i < n {
            se[i] = sd(k);
        }
    }
    let se_theta = sd(idx.len() - 1);
    let nu = theta.exp();
    let lower = scale.iter().zip(&se).map(|(s, e)| s - z * e).collect();
    let upper = scale.iter().zip(&se).map(|(s, e)| s + z * e).collect();
    Ok(TiesOutcome::Fitted(TiesEstimate {
        scale,
        se,
        lower,
        upper,
        tie_parameter: nu,
        tie_se: nu * se_theta,
        tie_lower: (theta - z * se_theta).exp(),
        tie_upper: (theta + z * se_theta).exp(),
        iterations,
        converged,
        log_likelihood,
    }))
}

/// One answer of a pair comparison: which condition the subject preferred over which, or
/// that it preferred neither.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PairChoice {
    /// Subject.
    pub subject: u32,
    /// The preferred condition (with `tie`, one of the two).
    pub winner: u32,
    /// The other condition.
    pub loser: u32,
    /// No preference: the two tied (a screen with "No preference").
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub tie: bool,
}

/// One item of a fit: a condition of a clip, or in the pooled fit a method at a ratio over
/// every clip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BtItem {
    /// The method (codec and varied parameters), `reference` for the original.
    pub method: String,
    /// Compression ratio x of x:1; `None` for the original.
    pub compression_ratio: Option<f64>,
    /// The condition ids it stands for.
    pub conditions: Vec<u32>,
}

/// The fit of one clip's comparisons, or of all clips pooled.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BtGroup {
    /// The clip; `None` for all clips pooled.
    pub clip: Option<String>,
    /// The items, the anchor first: the original when it was compared, else the lowest
    /// compression ratio (then the method name).
    pub items: Vec<BtItem>,
    /// Who was preferred over whom.
    pub matrix: WinMatrix,
    /// The scale values (the anchor, item 0, at 0) of the preferences, ties left out.
    pub outcome: BtOutcome,
    /// Where the study offered "no preference": the ties and Davidson's fit of preferences
    /// and ties together, which the report gives instead.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ties: Option<TiedFit>,
}

/// Davidson's fit of one group's preferences and ties ([`fit_with_ties`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TiedFit {
    /// Who tied with whom.
    pub matrix: TieMatrix,
    /// The scale values and the tie parameter.
    pub outcome: TiesOutcome,
}

/// Bradley-Terry analysis of a pair comparison study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairComparisonAnalysis {
    /// Answers (scored trials: hidden repeats included, familiarization left out).
    pub choices: usize,
    /// Of them, "no preference" answers (0 where the study offered none).
    #[serde(skip_serializing_if = "is_zero")]
    pub ties: usize,
    /// Subjects who answered.
    pub subjects: usize,
    /// One fit per clip, in clip order.
    pub per_clip: Vec<BtGroup>,
    /// All clips pooled, items being a method at a ratio (only with two or more clips).
    pub pooled: Option<BtGroup>,
}

/// The anchor-first order of items: the original, then by ratio, then by method.
fn item_order(a: &BtItem, b: &BtItem) -> std::cmp::Ordering {
    let cr = |i: &BtItem| i.compression_ratio.unwrap_or(f64::NEG_INFINITY);
    cr(a)
        .total_cmp(&cr(b))
        .then_with(|| a.method.cmp(&b.method))
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a reference
fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Fits the choices of every clip, and of all clips pooled (items: method and ratio), with
/// item 0 of each (see [`BtGroup::items`]) as the anchor; where any answer was "no
/// preference", Davidson's model of the preferences and the ties of every group as well.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] when a fit has more than [`MAX_ITEMS`] items.
pub fn analyze_pairs(
    conditions: &[crate::findings::ConditionInfo],
    choices: &[PairChoice],
    confidence: Confidence,
) -> Result<PairComparisonAnalysis, AnalysisError> {
    use std::collections::{BTreeMap, BTreeSet};
    let with_ties = choices.iter().any(|c| c.tie);
    let info: BTreeMap<u32, &crate::findings::ConditionInfo> =
        conditions.iter().map(|c| (c.id, c)).collect();
    let key = |id: u32| {
        info.get(&id)
            .map(|c| (c.method(), c.compression_ratio.map(f64::to_bits)))
    };
    let group = |clip: Option<&str>| -> Result<Option<BtGroup>, AnalysisError> {
        let in_group = |id: u32| clip.is_none_or(|c| info.get(&id).is_some_and(|i| i.clip == c));
        let mut items: Vec<BtItem> = Vec::new();
        let mut slot: BTreeMap<(String, Option<u64>), usize> = BTreeMap::new();
        let used: BTreeSet<u32> = choices
            .iter()
            .filter(|c| in_group(c.winner) && in_group(c.loser))
            .flat_map(|c| [c.winner, c.loser])
            .collect();
        for id in used {
            let Some(k) = key(id) else { continue };
            let at = *slot.entry(k.clone()).or_insert_with(|| {
                items.push(BtItem {
                    method: k.0.clone(),
                    compression_ratio: k.1.map(f64::from_bits),
                    conditions: Vec::new(),
                });
                items.len() - 1
            });
            items[at].conditions.push(id);
        }
        if items.len() < 2 {
            return Ok(None);
        }
        items.sort_by(item_order);
        let index: BTreeMap<u32, usize> = items
            .iter()
            .enumerate()
            .flat_map(|(i, it)| it.conditions.iter().map(move |&c| (c, i)))
            .collect();
        let mut matrix = WinMatrix::new(items.len());
        let mut tie_matrix = TieMatrix::new(items.len());
        for c in choices {
            if let (Some(&w), Some(&l)) = (index.get(&c.winner), index.get(&c.loser)) {
                if c.tie {
                    tie_matrix.add(w, l);
                } else {
                    matrix.add(w, l);
                }
            }
        }
        let outcome = fit(&matrix, 0, confidence)?;
        let ties = if with_ties {
            let outcome = fit_with_ties(&matrix, &tie_matrix, 0, confidence)?;
            Some(TiedFit {
                matrix: tie_matrix,
                outcome,
            })
        } else {
            None
        };
        Ok(Some(BtGroup {
            clip: clip.map(str::to_owned),
            items,
            matrix,
            outcome,
            ties,
        }))
    };
    let mut clips: Vec<&str> = Vec::new();
    for c in choices {
        if let Some(i) = info.get(&c.winner)
            && !clips.contains(&i.clip.as_str())
        {
            clips.push(&i.clip);
        }
    }
    clips.sort_unstable();
    let mut per_clip = Vec::new();
    for clip in &clips {
        per_clip.extend(group(Some(clip))?);
    }
    let pooled = if clips.len() > 1 { group(None)? } else { None };
    let subjects: BTreeSet<u32> = choices.iter().map(|c| c.subject).collect();
    Ok(PairComparisonAnalysis {
        choices: choices.len(),
        ties: choices.iter().filter(|c| c.tie).count(),
        subjects: subjects.len(),
        per_clip,
        pooled,
    })
}

/// How a table names an item: `wavelet-perceptual 30:1`, or `reference`.
fn item_label(item: &BtItem) -> String {
    match item.compression_ratio {
        Some(cr) => format!("{} {cr}:1", item.method),
        None => item.method.clone(),
    }
}

/// The report's pair comparison section: the method in words, the scale values of every clip
/// and of all clips pooled (`pc_scale`), and each fit's win counts (`pc_wins_<k>`).
pub fn report_section(
    report: &mut crate::report::Report,
    pc: &PairComparisonAnalysis,
    confidence: Confidence,
) {
    use crate::tables::{Table, fmt_opt};
    let conf = format!("{}", confidence.percent());
    let s = report.section("Pair comparison (Bradley-Terry)");
    s.text(format!(
        "{} choices from {} subjects (ITU-T P.910 pair comparison: two versions of one clip, \
         the better one picked). Bradley-Terry scale values by maximum likelihood (Hunter's \
         MM algorithm, to a change below {TOLERANCE:e}): P(i preferred over j) = 1 / (1 + \
         exp(s_j - s_i)), natural-log units. Each fit's anchor, at 0, is the original where it \
         was compared, else the condition of the lowest compression ratio; the others read \
         as log odds of being preferred over it. {conf} % intervals s ± z·SE, the SE from the \
         Fisher information with the anchor fixed, counting every choice as independent \
         (repeated choices of one subject are not quite). The pooled fit treats a method at \
         a ratio as one item across clips.",
        pc.choices, pc.subjects
    ));
    let with_ties = pc.ties > 0;
    if with_ties {
        s.text(format!(
            "{} of the choices were \"no preference\" (ties). With ties the scale values are \
             Davidson's (1970) by maximum likelihood (Newton-Raphson on the scale values and \
             ln ν): P(i over j) = p_i / (p_i + p_j + ν √(p_i p_j)), P(tie) = ν √(p_i p_j) / \
             (p_i + p_j + ν √(p_i p_j)), s = ln p; at equal strengths a tie has probability \
             ν / (2 + ν). Comparisons counts preferences and ties; {conf} % intervals of ν are \
             exp(ln ν ± z·SE(ln ν)).",
            pc.ties
        ));
    }
    let groups: Vec<&BtGroup> = pc.per_clip.iter().chain(&pc.pooled).collect();
    let mut rows = Vec::new();
    for g in &groups {
        let clip = g.clip.clone().unwrap_or_else(|| "all".to_owned());
        let estimate = group_estimate(g);
        for (i, item) in g.items.iter().enumerate() {
            let at = |v: Option<&Vec<f64>>| v.and_then(|v| v.get(i).copied());
            let tied = g.ties.as_ref().map_or(0, |t| t.matrix.ties_of(i));
            let mut row = vec![
                clip.clone(),
                item.method.clone(),
                item.compression_ratio
                    .map_or_else(|| "ref".to_owned(), |cr| format!("{cr}:1")),
                g.matrix.wins_of(i).to_string(),
            ];
            if with_ties {
                row.push(tied.to_string());
            }
            row.extend([
                (g.matrix.comparisons_of(i) + tied).to_string(),
                fmt_opt(at(estimate.map(|e| e.0)), 6),
                fmt_opt(at(estimate.map(|e| e.1)), 6),
                fmt_opt(at(estimate.map(|e| e.2)), 6),
                fmt_opt(at(estimate.map(|e| e.3)), 6),
            ]);
            rows.push(row);
        }
    }
    let mut columns = vec!["Clip", "Codec", "CR", "Wins"];
    if with_ties {
        columns.push("Ties");
    }
    columns.extend(["Comparisons", "Scale", "SE", "Lower", "Upper"]);
    let model = if with_ties {
        "Davidson (Bradley-Terry with ties)"
    } else {
        "Bradley-Terry"
    };
    s.table(Table {
        name: "pc_scale".to_owned(),
        caption: format!(
            "{model} scale values per clip and pooled (\"all\"); the first row of each is the \
             anchor; {conf} % CI from the Fisher information"
        ),
        columns: columns.into_iter().map(str::to_owned).collect(),
        rows,
    });
    if with_ties {
        tie_parameter_table(s, &groups, &conf);
    }
    wins_tables(s, &groups);
}

/// The scale values the report gives for a group (scale, SE, lower, upper): Davidson's where
/// the group was fitted with ties and that fit has a finite estimate (Bradley-Terry's where
/// it had no tie), else Bradley-Terry's; `None` when there is no finite estimate.
#[allow(clippy::type_complexity)]
fn group_estimate(g: &BtGroup) -> Option<(&Vec<f64>, &Vec<f64>, &Vec<f64>, &Vec<f64>)> {
    match (&g.ties, &g.outcome) {
        (Some(t), _) => match &t.outcome {
            TiesOutcome::Fitted(e) => Some((&e.scale, &e.se, &e.lower, &e.upper)),
            TiesOutcome::NoTies(e) => Some((&e.scale, &e.se, &e.lower, &e.upper)),
            TiesOutcome::NoFiniteEstimate { .. } | TiesOutcome::TieParameterInfinite { .. } => None,
        },
        (None, BtOutcome::Fitted(e)) => Some((&e.scale, &e.se, &e.lower, &e.upper)),
        (None, BtOutcome::NoFiniteEstimate { .. }) => None,
    }
}

/// Davidson's tie parameter of each group (`pc_tie_parameter`), after a sentence for each
/// group without a full estimate.
fn tie_parameter_table(s: &mut crate::report::Section, groups: &[&BtGroup], conf: &str) {
    use crate::tables::{Table, fmt_opt};
    let mut rows = Vec::new();
    for g in groups {
        let Some(t) = &g.ties else { continue };
        let clip = g.clip.clone().unwrap_or_else(|| "all".to_owned());
        if let Some(why) = t
            .outcome
            .explanation(|i| g.items.get(i).map(item_label).unwrap_or_default())
        {
            s.text(format!("{clip}: {why}"));
        }
        let e = match &t.outcome {
            TiesOutcome::Fitted(e) => Some(e),
            _ => None,
        };
        if let Some(e) = e.filter(|e| !e.converged) {
            s.text(format!(
                "{clip}: the Newton iteration stopped after {} iterations without meeting its \
                 tolerance; the estimates are approximate.",
                e.iterations
            ));
        }
        rows.push(vec![
            clip,
            t.matrix.total().to_string(),
            fmt_opt(e.map(|e| e.tie_parameter), 6),
            fmt_opt(e.map(|e| e.tie_se), 6),
            fmt_opt(e.map(|e| e.tie_lower), 6),
            fmt_opt(e.map(|e| e.tie_upper), 6),
            fmt_opt(e.map(|e| e.tie_parameter / (2.0 + e.tie_parameter)), 6),
        ]);
    }
    s.table(Table {
        name: "pc_tie_parameter".to_owned(),
        caption: format!(
            "Davidson's tie parameter ν per clip and pooled (\"all\"), {conf} % CI; P(tie) at \
             equal strengths is ν / (2 + ν)"
        ),
        columns: [
            "Clip",
            "Ties",
            "ν",
            "SE",
            "Lower",
            "Upper",
            "P(tie | equal)",
        ]
        .map(str::to_owned)
        .to_vec(),
        rows,
    });
}

/// Each fit's win matrix (`pc_wins_<k>`), after a note where the fit has no finite scale or
/// did not converge.
fn wins_tables(s: &mut crate::report::Section, groups: &[&BtGroup]) {
    use crate::tables::Table;
    for (k, g) in groups.iter().enumerate() {
        let clip = g.clip.as_deref().unwrap_or("all clips");
        // With ties the report gives Davidson's fit, whose notes come with its table.
        match (&g.ties, &g.outcome) {
            (None, BtOutcome::NoFiniteEstimate { item, how }) => {
                let name = g.items.get(*item).map(item_label).unwrap_or_default();
                let anchor = g.items.first().map(item_label).unwrap_or_default();
                s.text(format!(
                    "{clip}: no finite Bradley-Terry scale: {name} {how} the items connected \
                     to {anchor} (the maximum-likelihood scale value would be infinite); \
                     compare more pairs or more subjects."
                ));
            }
            (None, BtOutcome::Fitted(e)) if !e.converged => {
                s.text(format!(
                    "{clip}: the MM iteration stopped after {} iterations without meeting its \
                     tolerance; the scale values are approximate.",
                    e.iterations
                ));
            }
            _ => {}
        }
        let labels: Vec<String> = g.items.iter().map(item_label).collect();
        let mut columns = vec!["Preferred over".to_owned()];
        columns.extend(labels.iter().cloned());
        let rows = g
            .matrix
            .wins
            .iter()
            .zip(&labels)
            .map(|(row, l)| {
                let mut r = vec![l.clone()];
                r.extend(row.iter().map(u64::to_string));
                r
            })
            .collect();
        s.table(Table {
            name: format!("pc_wins_{}", k + 1),
            caption: format!(
                "Pair comparison wins, {clip}: how often the row's version was preferred over \
                 the column's"
            ),
            columns: columns.clone(),
            rows,
        });
        if let Some(t) = &g.ties {
            let rows = t
                .matrix
                .ties
                .iter()
                .zip(&labels)
                .map(|(row, l)| {
                    let mut r = vec![l.clone()];
                    r.extend(row.iter().map(u64::to_string));
                    r
                })
                .collect();
            let mut columns = columns;
            if let Some(first) = columns.first_mut() {
                "Tied with".clone_into(first);
            }
            s.table(Table {
                name: format!("pc_ties_{}", k + 1),
                caption: format!(
                    "Pair comparison ties, {clip}: how often the row's and the column's \
                     versions were answered \"no preference\""
                ),
                columns,
                rows,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    fn fitted(o: BtOutcome) -> BtEstimate {
        match o {
            BtOutcome::Fitted(e) => e,
            BtOutcome::NoFiniteEstimate { item, how } => panic!("item {item} {how}"),
        }
    }

    /// Two items: the MLE of p = w / (w + l) is the share of wins, so s = ln(w / l); the
    /// Fisher information of s is n p (1 - p), so SE = 1 / sqrt(n p (1 - p)).
    #[test]
    fn two_items_are_the_log_odds_of_the_share_of_wins() {
        let mut m = WinMatrix::new(2);
        for _ in 0..7 {
            m.add(1, 0);
        }
        for _ in 0..3 {
            m.add(0, 1);
        }
        let e = fitted(fit(&m, 0, Confidence::default()).unwrap());
        assert_eq!(e.scale[0].to_bits(), 0.0_f64.to_bits());
        assert!((e.scale[1] - (7.0_f64 / 3.0).ln()).abs() < 1e-12, "{e:?}");
        let se = 1.0 / (10.0_f64 * 0.7 * 0.3).sqrt();
        assert!((e.se[1] - se).abs() < 1e-9, "{e:?}");
        assert!((e.upper[1] - e.scale[1] - 1.959_963_984_540_054 * se).abs() < 1e-9);
        let ll = 7.0 * 0.7_f64.ln() + 3.0 * 0.3_f64.ln();
        assert!((e.log_likelihood - ll).abs() < 1e-9);
        // The anchor on the other item mirrors the scale.
        let e = fitted(fit(&m, 1, Confidence::default()).unwrap());
        assert!((e.scale[0] + (7.0_f64 / 3.0).ln()).abs() < 1e-12);
    }

    /// Three items in a circle with equal counts each way: every strength equal, s = 0.
    /// Three with wins a>b 2:1, b>c 2:1, a>c 4:1 satisfy the likelihood equations
    /// W_i = sum_j n_ij p_i / (p_i + p_j) at p = (4, 2, 1) exactly.
    #[test]
    fn three_items_solve_the_likelihood_equations() {
        let mut m = WinMatrix::new(3);
        let mut add = |w: usize, l: usize, k: usize| {
            for _ in 0..k {
                m.add(w, l);
            }
        };
        add(0, 1, 2);
        add(1, 0, 1);
        add(1, 2, 2);
        add(2, 1, 1);
        add(0, 2, 4);
        add(2, 0, 1);
        let e = fitted(fit(&m, 2, Confidence::default()).unwrap());
        assert!((e.scale[0] - 4.0_f64.ln()).abs() < 1e-10, "{e:?}");
        assert!((e.scale[1] - 2.0_f64.ln()).abs() < 1e-10, "{e:?}");
        assert_eq!(e.scale[2].to_bits(), 0.0_f64.to_bits());
        assert!(e.se[0] > 0.0 && e.se[1] > 0.0 && e.se[2].to_bits() == 0.0_f64.to_bits());
    }

    /// The Fisher-information interval covers the true scale value at about its nominal
    /// rate: 600 simulated studies of four items with known Bradley-Terry values (every pair
    /// compared 30 times), each from its own seed, 1,800 intervals at 95 %. The count must lie
    /// within 4 binomial standard errors of 95 % (1,710 ± 37).
    #[test]
    fn fisher_intervals_cover_the_true_values_at_their_nominal_rate() {
        let truth: [f64; 4] = [0.0, -0.5, 0.4, -1.2];
        let (mut covered, mut intervals, mut unfit) = (0_u32, 0_u32, 0_u32);
        for seed in 0..600_u64 {
            let mut rng = protocols::rng::StudyRng::new(seed, &[0x6274]);
            let mut m = WinMatrix::new(4);
            for i in 0..4 {
                for j in i + 1..4 {
                    let p = 1.0 / (1.0 + (truth[j] - truth[i]).exp());
                    for _ in 0..30 {
                        if rng.unit_f64() < p {
                            m.add(i, j);
                        } else {
                            m.add(j, i);
                        }
                    }
                }
            }
            match fit(&m, 0, Confidence::default()).unwrap() {
                BtOutcome::Fitted(e) => {
                    for (i, t) in truth.iter().enumerate().skip(1) {
                        intervals += 1;
                        covered += u32::from(e.lower[i] <= *t && *t <= e.upper[i]);
                    }
                }
                BtOutcome::NoFiniteEstimate { .. } => unfit += 1,
            }
        }
        assert_eq!(unfit, 0);
        eprintln!("Bradley-Terry Fisher intervals: {covered} of {intervals} covered");
        let expected = 0.95 * f64::from(intervals);
        let sd = (f64::from(intervals) * 0.95 * 0.05).sqrt();
        assert!(
            (f64::from(covered) - expected).abs() <= 4.0 * sd,
            "{covered} of {intervals} covered"
        );
    }

    #[test]
    fn an_item_that_never_lost_has_no_finite_scale_value() {
        let mut m = WinMatrix::new(3);
        m.add(0, 1);
        m.add(1, 0);
        m.add(2, 0);
        m.add(2, 1);
        match fit(&m, 0, Confidence::default()).unwrap() {
            BtOutcome::NoFiniteEstimate { item, how } => {
                assert_eq!((item, how), (2, "never lost to"));
            }
            BtOutcome::Fitted(e) => panic!("{e:?}"),
        }
        // An item that never won.
        let mut m = WinMatrix::new(3);
        m.add(0, 1);
        m.add(1, 0);
        m.add(0, 2);
        match fit(&m, 0, Confidence::default()).unwrap() {
            BtOutcome::NoFiniteEstimate { item, how } => {
                assert_eq!((item, how), (2, "never won against"));
            }
            BtOutcome::Fitted(e) => panic!("{e:?}"),
        }
        assert!(fit(&WinMatrix::new(1), 0, Confidence::default()).is_err());
        assert!(fit(&m, 3, Confidence::default()).is_err());
    }

    fn fitted_ties(o: TiesOutcome) -> TiesEstimate {
        match o {
            TiesOutcome::Fitted(e) => e,
            other => panic!("{other:?}"),
        }
    }

    /// `(wins, ties)` from `(winner, loser, count)` and `(i, j, count)` lists.
    fn tied_data(
        n: usize,
        w: &[(usize, usize, u64)],
        t: &[(usize, usize, u64)],
    ) -> (WinMatrix, TieMatrix) {
        let mut wins = WinMatrix::new(n);
        let mut ties = TieMatrix::new(n);
        for &(a, b, k) in w {
            for _ in 0..k {
                wins.add(a, b);
            }
        }
        for &(a, b, k) in t {
            for _ in 0..k {
                ties.add(a, b);
            }
        }
        (wins, ties)
    }

    /// Davidson's log-likelihood straight from the probabilities, in `(s, ν)`, for checking
    /// the fit's score and information independently of its formulas.
    fn direct_log_likelihood(wins: &WinMatrix, ties: &TieMatrix, s: &[f64], nu: f64) -> f64 {
        let n = wins.len();
        let mut ll = 0.0;
        for i in 0..n {
            for j in 0..n {
                if i == j {
                    continue;
                }
                let (pi, pj) = (s[i].exp(), s[j].exp());
                let d = pi + pj + nu * (pi * pj).sqrt();
                ll += wins.wins[i][j] as f64 * (pi / d).ln();
                if i < j {
                    ll += ties.get(i, j) as f64 * (nu * (pi * pj).sqrt() / d).ln();
                }
            }
        }
        ll
    }

    #[test]
    fn tie_matrix_counts_ties_symmetrically() {
        let mut t = TieMatrix::new(3);
        t.add(0, 2);
        t.add(2, 0);
        t.add(1, 1);
        t.add(1, 5);
        assert_eq!(
            (t.get(0, 2), t.get(2, 0), t.get(1, 1), t.get(1, 5)),
            (2, 2, 0, 0)
        );
        assert_eq!(
            (t.total(), t.ties_of(0), t.ties_of(1), t.len()),
            (2, 2, 0, 3)
        );
    }

    /// Without ties ν̂ = 0, on the boundary, where the model is Bradley-Terry's: the outcome
    /// is `NoTies` with exactly `fit`'s estimate.
    #[test]
    fn without_ties_the_fit_is_bradley_terrys() {
        let (w, t) = tied_data(
            3,
            &[
                (0, 1, 2),
                (1, 0, 1),
                (1, 2, 2),
                (2, 1, 1),
                (0, 2, 4),
                (2, 0, 1),
            ],
            &[],
        );
        let bt = fitted(fit(&w, 2, Confidence::default()).unwrap());
        match fit_with_ties(&w, &t, 2, Confidence::default()).unwrap() {
            TiesOutcome::NoTies(e) => assert_eq!(e, bt),
            other => panic!("{other:?}"),
        }
        let o = fit_with_ties(&w, &t, 2, Confidence::default()).unwrap();
        assert!(
            o.explanation(|i| format!("#{i}"))
                .unwrap()
                .contains("no comparison ended in a tie")
        );
    }

    /// Two items: the model is saturated (two free parameters, three outcome cells), so the
    /// estimate reproduces the observed shares: π_1 / π_0 = p_1 / p_0 = w_10 / w_01, so
    /// s_1 = ln(w_10 / w_01), and π_t / π_0 = ν sqrt(p_1 / p_0) = t / w_01, so
    /// ν = t / sqrt(w_10 w_01). By the delta method on the multinomial log shares,
    /// Var(s_1) = 1/w_10 + 1/w_01 and Var(ln ν) = Var(ln π_t − (ln π_0 + ln π_1)/2) =
    /// 1/t + 1/(4 w_10) + 1/(4 w_01); the log-likelihood is Σ c ln(c / n).
    #[test]
    fn two_items_reproduce_the_observed_shares() {
        let (w, t) = tied_data(2, &[(1, 0, 7), (0, 1, 3)], &[(0, 1, 4)]);
        let e = fitted_ties(fit_with_ties(&w, &t, 0, Confidence::default()).unwrap());
        assert!(e.converged, "{e:?}");
        assert_eq!(e.scale[0].to_bits(), 0.0_f64.to_bits());
        assert_eq!(e.se[0].to_bits(), 0.0_f64.to_bits());
        assert!((e.scale[1] - (7.0_f64 / 3.0).ln()).abs() < 1e-12, "{e:?}");
        let nu = 4.0 / 21.0_f64.sqrt();
        assert!((e.tie_parameter - nu).abs() < 1e-12, "{e:?}");
        let se = (1.0_f64 / 7.0 + 1.0 / 3.0).sqrt();
        assert!((e.se[1] - se).abs() < 1e-10, "{e:?}");
        let se_theta = (0.25_f64 + 1.0 / 28.0 + 1.0 / 12.0).sqrt();
        assert!((e.tie_se - nu * se_theta).abs() < 1e-10, "{e:?}");
        let z = 1.959_963_984_540_054;
        assert!((e.upper[1] - e.scale[1] - z * se).abs() < 1e-9);
        assert!((e.tie_lower - (nu.ln() - z * se_theta).exp()).abs() < 1e-9);
        assert!((e.tie_upper - (nu.ln() + z * se_theta).exp()).abs() < 1e-9);
        let ll: f64 = [7.0_f64, 3.0, 4.0]
            .iter()
            .map(|c| c * (c / 14.0).ln())
            .sum();
        assert!((e.log_likelihood - ll).abs() < 1e-10, "{e:?}");
        // The anchor on the other item mirrors the scale.
        let e = fitted_ties(fit_with_ties(&w, &t, 1, Confidence::default()).unwrap());
        assert!((e.scale[0] + (7.0_f64 / 3.0).ln()).abs() < 1e-12);
        assert!((e.tie_parameter - nu).abs() < 1e-12);
    }

    /// Four items, unbalanced: at the estimate the score of the likelihood written straight
    /// from the probabilities, in `(s, ν)`, by central differences, vanishes; and the SEs equal
    /// those from the inverse of its numerical negative Hessian in `(s_free, ln ν)`.
    #[test]
    fn four_items_solve_the_score_equations() {
        let (w, t) = tied_data(
            4,
            &[
                (0, 1, 6),
                (1, 0, 3),
                (0, 2, 9),
                (2, 0, 1),
                (0, 3, 4),
                (3, 0, 5),
                (1, 2, 5),
                (2, 1, 2),
                (1, 3, 2),
                (3, 1, 4),
                (2, 3, 3),
                (3, 2, 6),
            ],
            &[(0, 1, 3), (0, 2, 1), (1, 2, 4), (1, 3, 2), (0, 3, 2)],
        );
        let anchor = 1;
        let e = fitted_ties(fit_with_ties(&w, &t, anchor, Confidence::default()).unwrap());
        assert!(e.converged && e.iterations < 50, "{e:?}");
        // Parameters (s without the anchor's, ln ν).
        let free: Vec<usize> = (0..4).filter(|&i| i != anchor).collect();
        let point = |x: &[f64]| {
            let mut s = vec![0.0; 4];
            for (k, &i) in free.iter().enumerate() {
                s[i] = x[k];
            }
            (s, x[3].exp())
        };
        let ll = |x: &[f64]| {
            let (s, nu) = point(x);
            direct_log_likelihood(&w, &t, &s, nu)
        };
        let mut x: Vec<f64> = free.iter().map(|&i| e.scale[i]).collect();
        x.push(e.tie_parameter.ln());
        assert!((ll(&x) - e.log_likelihood).abs() < 1e-10);
        let h = 1e-6;
        for k in 0..4 {
            let (mut up, mut down) = (x.clone(), x.clone());
            up[k] += h;
            down[k] -= h;
            let g = (ll(&up) - ll(&down)) / (2.0 * h);
            assert!(g.abs() < 1e-6, "score {k}: {g}");
        }
        let h = 1e-4;
        let mut info = vec![vec![0.0; 4]; 4];
        for a in 0..4 {
            for b in 0..4 {
                let at = |da: f64, db: f64| {
                    let mut y = x.clone();
                    y[a] += da;
                    y[b] += db;
                    ll(&y)
                };
                info[a][b] = -(at(h, h) - at(h, -h) - at(-h, h) + at(-h, -h)) / (4.0 * h * h);
            }
        }
        let cov = invert(info).unwrap();
        for (k, &i) in free.iter().enumerate() {
            let se = cov[k][k].sqrt();
            assert!(
                (e.se[i] - se).abs() < 1e-5 * se,
                "item {i}: {} vs {se}",
                e.se[i]
            );
        }
        let se_theta = cov[3][3].sqrt();
        assert!((e.tie_se - e.tie_parameter * se_theta).abs() < 1e-5 * e.tie_se);
    }

    /// An item that only lost and never tied has scale value −∞; one that only won, +∞. A
    /// single tie links it back.
    #[test]
    fn an_item_that_only_lost_and_never_tied_has_no_finite_scale_value() {
        let core = [
            (0, 1, 2),
            (1, 0, 1),
            (1, 2, 2),
            (2, 1, 2),
            (0, 2, 1),
            (2, 0, 3),
        ];
        let lost: Vec<_> = core
            .iter()
            .copied()
            .chain([(0, 3, 2), (1, 3, 1), (2, 3, 4)])
            .collect();
        let (w, t) = tied_data(4, &lost, &[(0, 1, 2), (1, 2, 1)]);
        let o = fit_with_ties(&w, &t, 0, Confidence::default()).unwrap();
        assert_eq!(
            o,
            TiesOutcome::NoFiniteEstimate {
                item: 3,
                how: "never won against or tied with"
            }
        );
        let text = o.explanation(|i| format!("item {i}")).unwrap();
        assert!(
            text.contains("item 3 never won against or tied with the items linked to item 0"),
            "{text}"
        );
        let won: Vec<_> = core.iter().copied().chain([(3, 0, 2), (3, 2, 1)]).collect();
        let (w2, t2) = tied_data(4, &won, &[(0, 1, 2)]);
        assert_eq!(
            fit_with_ties(&w2, &t2, 0, Confidence::default()).unwrap(),
            TiesOutcome::NoFiniteEstimate {
                item: 3,
                how: "never lost to or tied with"
            }
        );
        // One tie with item 0 bounds item 3's scale value from above.
        let (w, t) = tied_data(4, &lost, &[(0, 1, 2), (1, 2, 1), (0, 3, 1)]);
        let e = fitted_ties(fit_with_ties(&w, &t, 0, Confidence::default()).unwrap());
        assert!(
            e.converged && e.scale[3] < e.scale[1].min(e.scale[2]),
            "{e:?}"
        );
        // Errors as `fit`'s, and for matrices that do not fit together.
        let c = Confidence::default();
        assert!(fit_with_ties(&WinMatrix::new(1), &TieMatrix::new(1), 0, c).is_err());
        assert!(fit_with_ties(&w, &t, 4, c).is_err());
        assert!(fit_with_ties(&w, &TieMatrix::new(3), 0, c).is_err());
        let mut skew = t.clone();
        skew.ties[0][2] = 1;
        assert!(fit_with_ties(&w, &skew, 0, c).is_err());
    }

    /// ν̂ = ∞: only ties; two items with ties and preferences one way only; three items
    /// where `x = (0, −1, −1/2)` keeps every preference a unit downhill and every tie within
    /// one unit, along which the likelihood keeps rising. Preferences around a cycle that the
    /// ties do not bridge give a finite estimate.
    #[test]
    fn ties_that_outweigh_the_preferences_have_no_finite_tie_parameter() {
        let c = Confidence::default();
        let (w, t) = tied_data(3, &[], &[(0, 1, 2), (1, 2, 1), (0, 2, 1)]);
        let o = fit_with_ties(&w, &t, 0, c).unwrap();
        assert_eq!(
            o,
            TiesOutcome::TieParameterInfinite {
                ties: 4,
                decided: 0
            }
        );
        assert!(
            o.explanation(|i| i.to_string())
                .unwrap()
                .starts_with("all 4 comparisons")
        );
        let (w, t) = tied_data(2, &[(1, 0, 3)], &[(0, 1, 2)]);
        assert_eq!(
            fit_with_ties(&w, &t, 0, c).unwrap(),
            TiesOutcome::TieParameterInfinite {
                ties: 2,
                decided: 3
            }
        );
        let (w, t) = tied_data(3, &[(0, 1, 2)], &[(1, 2, 1), (0, 2, 3)]);
        assert_eq!(
            fit_with_ties(&w, &t, 0, c).unwrap(),
            TiesOutcome::TieParameterInfinite {
                ties: 4,
                decided: 2
            }
        );
        let x = [0.0, -1.0, -0.5];
        let along = |r: f64| {
            let s: Vec<f64> = x.iter().map(|v| r * v).collect();
            direct_log_likelihood(&w, &t, &s, (r / 2.0).exp())
        };
        let lls: Vec<f64> = [0.0, 2.0, 5.0, 10.0, 20.0]
            .iter()
            .map(|&r| along(r))
            .collect();
        assert!(lls.windows(2).all(|p| p[1] > p[0]), "{lls:?}");
        // 0 over 1, 1 over 2, and a tie of 0 and 2: x_0 − x_2 ≥ 2 and ≤ 1 at once.
        let (w, t) = tied_data(3, &[(0, 1, 1), (1, 2, 1)], &[(0, 2, 1)]);
        let e = fitted_ties(fit_with_ties(&w, &t, 0, c).unwrap());
        assert!(
            e.converged && e.tie_parameter.is_finite() && e.scale[2] < e.scale[1],
            "{e:?}"
        );
    }

    /// Every 3-item data set with at most one of each outcome (2^9): where the checks let it
    /// through, Newton converges to a finite point with a zero score; where they find ν̂ = ∞,
    /// Newton without the checks runs away (or stalls) instead of converging nearby.
    #[test]
    fn the_existence_checks_agree_with_newton_on_every_small_data_set() {
        let cells = [(0, 1), (1, 0), (0, 2), (2, 0), (1, 2), (2, 1)];
        let tie_pairs = [(0, 1), (0, 2), (1, 2)];
        let mut counts = [0_u32; 4];
        for bits in 0..512_u32 {
            let w: Vec<_> = cells
                .iter()
                .enumerate()
                .filter(|(k, _)| bits >> k & 1 == 1)
                .map(|(_, &(a, b))| (a, b, 1))
                .collect();
            let t: Vec<_> = tie_pairs
                .iter()
                .enumerate()
                .filter(|(k, _)| bits >> (k + 6) & 1 == 1)
                .map(|(_, &(a, b))| (a, b, 1))
                .collect();
            let (wins, ties) = tied_data(3, &w, &t);
            let pairs: Vec<TiedPair> = [(0, 1), (0, 2), (1, 2)]
                .iter()
                .map(|&(i, j)| TiedPair {
                    i,
                    j,
                    wij: wins.wins[i][j] as f64,
                    wji: wins.wins[j][i] as f64,
                    tij: ties.get(i, j) as f64,
                })
                .collect();
            match fit_with_ties(&wins, &ties, 0, Confidence::default()).unwrap() {
                TiesOutcome::Fitted(e) => {
                    counts[0] += 1;
                    assert!(e.converged, "{bits}: {e:?}");
                    let (g, _) = davidson_score_information(&pairs, &e.scale, e.tie_parameter.ln());
                    assert!(g.iter().skip(1).all(|v| v.abs() < 1e-9), "{bits}: {g:?}");
                }
                TiesOutcome::TieParameterInfinite { .. } => {
                    counts[1] += 1;
                    let (s, theta, _, converged) = davidson_newton(&pairs, 3, 0, 0.0);
                    let far = s.iter().chain([&theta]).any(|v| v.abs() > 10.0);
                    assert!(far || !converged, "{bits}: {s:?} {theta}");
                }
                TiesOutcome::NoTies(_) => counts[2] += 1,
                TiesOutcome::NoFiniteEstimate { .. } => counts[3] += 1,
            }
        }
        eprintln!("fitted, ν̂ = ∞, no ties, unconnected: {counts:?}");
        assert!(counts.iter().all(|&c| c > 0), "{counts:?}");
    }
}
