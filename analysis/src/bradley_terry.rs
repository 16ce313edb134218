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
        let n = self.len();
        let reach = |forward: bool| {
            let mut seen = vec![false; n];
            let mut stack = vec![0];
            seen[0] = true;
            while let Some(i) = stack.pop() {
                for (j, s) in seen.iter_mut().enumerate() {
                    let edge = if forward {
                        self.wins[i][j] > 0
                    } else {
                        self.wins[j][i] > 0
                    };
                    if edge && !*s {
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
            return Some((i, "never lost to"));
        }
        if let Some(i) = reach(false).iter().position(|s| !s) {
            return Some((i, "never won against"));
        }
        None
    }
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
    if n < 2 {
        return Err(AnalysisError::TooFew {
            what: "Bradley-Terry items",
            needed: 2,
            got: n,
        });
    }
    if n > MAX_ITEMS {
        return Err(AnalysisError::InvalidParameter {
            name: "Bradley-Terry items",
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

/// One answer of a pair comparison: which condition the subject preferred over which.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PairChoice {
    /// Subject.
    pub subject: u32,
    /// The preferred condition.
    pub winner: u32,
    /// The other condition.
    pub loser: u32,
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
    /// The scale values (the anchor, item 0, at 0).
    pub outcome: BtOutcome,
}

/// Bradley-Terry analysis of a pair comparison study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairComparisonAnalysis {
    /// Answers (scored trials: hidden repeats included, familiarization left out).
    pub choices: usize,
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

/// Fits the choices of every clip, and of all clips pooled (items: method and ratio), with
/// item 0 of each (see [`BtGroup::items`]) as the anchor.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] when a fit has more than [`MAX_ITEMS`] items.
pub fn analyze_pairs(
    conditions: &[crate::findings::ConditionInfo],
    choices: &[PairChoice],
    confidence: Confidence,
) -> Result<PairComparisonAnalysis, AnalysisError> {
    use std::collections::{BTreeMap, BTreeSet};
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
        for c in choices {
            if let (Some(&w), Some(&l)) = (index.get(&c.winner), index.get(&c.loser)) {
                matrix.add(w, l);
            }
        }
        let outcome = fit(&matrix, 0, confidence)?;
        Ok(Some(BtGroup {
            clip: clip.map(str::to_owned),
            items,
            matrix,
            outcome,
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
    let groups: Vec<&BtGroup> = pc.per_clip.iter().chain(&pc.pooled).collect();
    let mut rows = Vec::new();
    for g in &groups {
        let clip = g.clip.clone().unwrap_or_else(|| "all".to_owned());
        for (i, item) in g.items.iter().enumerate() {
            let (scale, se, lo, hi) = match &g.outcome {
                BtOutcome::Fitted(e) => (
                    Some(e.scale[i]),
                    Some(e.se[i]),
                    Some(e.lower[i]),
                    Some(e.upper[i]),
                ),
                BtOutcome::NoFiniteEstimate { .. } => (None, None, None, None),
            };
            rows.push(vec![
                clip.clone(),
                item.method.clone(),
                item.compression_ratio
                    .map_or_else(|| "ref".to_owned(), |cr| format!("{cr}:1")),
                g.matrix.wins_of(i).to_string(),
                g.matrix.comparisons_of(i).to_string(),
                fmt_opt(scale, 6),
                fmt_opt(se, 6),
                fmt_opt(lo, 6),
                fmt_opt(hi, 6),
            ]);
        }
    }
    s.table(Table {
        name: "pc_scale".to_owned(),
        caption: format!(
            "Bradley-Terry scale values per clip and pooled (\"all\"); the first row of each \
             is the anchor; {conf} % CI from the Fisher information"
        ),
        columns: [
            "Clip",
            "Codec",
            "CR",
            "Wins",
            "Comparisons",
            "Scale",
            "SE",
            "Lower",
            "Upper",
        ]
        .map(str::to_owned)
        .to_vec(),
        rows,
    });
    wins_tables(s, &groups);
}

/// Each fit's win matrix (`pc_wins_<k>`), after a note where the fit has no finite scale or
/// did not converge.
fn wins_tables(s: &mut crate::report::Section, groups: &[&BtGroup]) {
    use crate::tables::Table;
    for (k, g) in groups.iter().enumerate() {
        let clip = g.clip.as_deref().unwrap_or("all clips");
        if let BtOutcome::NoFiniteEstimate { item, how } = &g.outcome {
            let name = g.items.get(*item).map(item_label).unwrap_or_default();
            let anchor = g.items.first().map(item_label).unwrap_or_default();
            s.text(format!(
                "{clip}: no finite Bradley-Terry scale: {name} {how} the items connected to \
                 {anchor} (the maximum-likelihood scale value would be infinite); compare more \
                 pairs or more subjects."
            ));
        } else if let BtOutcome::Fitted(e) = &g.outcome
            && !e.converged
        {
            s.text(format!(
                "{clip}: the MM iteration stopped after {} iterations without meeting its \
                 tolerance; the scale values are approximate.",
                e.iterations
            ));
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
            columns,
            rows,
        });
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
}
