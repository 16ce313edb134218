//! Dense indexing of a rating panel: subject and condition ids mapped to 0..S and 0..C, rows
//! ordered by (subject, condition, presentation) with two stable counting sorts. Every
//! per-subject and per-condition statistic then runs as a linear pass over flat arrays instead
//! of hash-map lookups per row, which keeps a million-row report well under a second.

use crate::descriptive::Rating;
use crate::error::AnalysisError;

/// Most rating rows accepted (checked before allocating the index).
pub const MAX_ROWS: usize = 200_000_000;

/// Largest id for which a direct lookup table is used instead of binary search (4 MiB table).
const TABLE_LIMIT: u32 = 1 << 20;

/// Sorted unique ids and, per row, the index of the row's id among them. Small ids use a
/// presence table (linear time); large ones a sort and binary search.
pub(crate) fn dense(ids: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let max = ids.iter().copied().max().unwrap_or(0);
    if max < TABLE_LIMIT {
        let mut table = vec![u32::MAX; max as usize + 1];
        for id in ids {
            table[*id as usize] = 0;
        }
        let mut unique = Vec::new();
        for (id, slot) in table.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = unique.len() as u32;
                unique.push(id as u32);
            }
        }
        let index = ids.iter().map(|id| table[*id as usize]).collect();
        return (unique, index);
    }
    let mut unique = ids.to_vec();
    unique.sort_unstable();
    unique.dedup();
    let index = ids
        .iter()
        .map(|id| unique.binary_search(id).map_or(0, |i| i as u32))
        .collect();
    (unique, index)
}

/// Stable counting sort of `rows` by `key[row]` (keys < `buckets`).
pub(crate) fn counting_sort(rows: &[u32], key: &[u32], buckets: usize) -> Vec<u32> {
    let mut start = vec![0usize; buckets + 1];
    for &r in rows {
        start[key[r as usize] as usize + 1] += 1;
    }
    for k in 0..buckets {
        start[k + 1] += start[k];
    }
    let mut out = vec![0u32; rows.len()];
    for &r in rows {
        let slot = &mut start[key[r as usize] as usize];
        out[*slot] = r;
        *slot += 1;
    }
    out
}

/// The dense index of a set of ratings.
#[derive(Debug, Clone)]
pub(crate) struct Panel {
    /// Sorted unique subject ids.
    pub subjects: Vec<u32>,
    /// Sorted unique condition ids.
    pub conditions: Vec<u32>,
    /// Per row: subject index.
    pub s: Vec<u32>,
    /// Per row: condition index.
    pub c: Vec<u32>,
    /// Row numbers sorted by (subject, condition, row).
    pub order: Vec<u32>,
    /// Per row: how many earlier rows have the same subject and condition (0 = first showing).
    pub rep: Vec<u32>,
    /// Largest repetition index + 1.
    pub reps: u32,
}

/// Refuses more rating rows than [`MAX_ROWS`].
pub(crate) fn check_row_count(ratings: &[Rating]) -> Result<(), AnalysisError> {
    if ratings.len() > MAX_ROWS {
        return Err(AnalysisError::TooLarge {
            what: "rating rows",
            count: ratings.len(),
            limit: MAX_ROWS,
        });
    }
    Ok(())
}

/// Refuses the first rating whose score is not finite, naming its row.
pub(crate) fn check_scores(ratings: &[Rating]) -> Result<(), AnalysisError> {
    match ratings.iter().position(|r| !r.score.is_finite()) {
        Some(index) => Err(AnalysisError::NonFinite {
            what: "rating score",
            index,
            value: ratings[index].score,
        }),
        None => Ok(()),
    }
}

impl Panel {
    /// Indexes `ratings`, checking every score is finite.
    pub fn new(ratings: &[Rating]) -> Result<Self, AnalysisError> {
        check_row_count(ratings)?;
        check_scores(ratings)?;
        let (subjects, s) = dense(&ratings.iter().map(|r| r.subject).collect::<Vec<_>>());
        let (conditions, c) = dense(&ratings.iter().map(|r| r.condition).collect::<Vec<_>>());
        // Two stable counting sorts (by condition, then by subject) order the rows by
        // (subject, condition, row) in linear time.
        let rows: Vec<u32> = (0..ratings.len() as u32).collect();
        let by_condition = counting_sort(&rows, &c, conditions.len());
        let order = counting_sort(&by_condition, &s, subjects.len());
        let mut rep = vec![0u32; ratings.len()];
        let mut reps = u32::from(!ratings.is_empty());
        for w in 1..order.len() {
            let (prev, row) = (order[w - 1] as usize, order[w] as usize);
            if s[row] == s[prev] && c[row] == c[prev] {
                rep[row] = rep[prev] + 1;
                reps = reps.max(rep[row] + 1);
            }
        }
        Ok(Self {
            subjects,
            conditions,
            s,
            c,
            order,
            rep,
            reps,
        })
    }

    /// One rating per (subject, condition) cell: the subject's mean over its repeats, in
    /// (subject, condition) order. `ratings` must be the rows this panel indexes.
    pub(crate) fn subject_means(&self, ratings: &[Rating]) -> Vec<Rating> {
        self.cells()
            .map(|(start, end)| {
                let first = &ratings[self.order[start] as usize];
                let sum: f64 = self.order[start..end]
                    .iter()
                    .map(|&r| ratings[r as usize].score)
                    .sum();
                Rating {
                    subject: first.subject,
                    condition: first.condition,
                    score: sum / (end - start) as f64,
                }
            })
            .collect()
    }

    /// Runs of `order` sharing (subject, condition): (start, end) into `order`.
    pub fn cells(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let mut start = 0;
        std::iter::from_fn(move || {
            if start >= self.order.len() {
                return None;
            }
            let first = self.order[start] as usize;
            let mut end = start + 1;
            while end < self.order.len() {
                let r = self.order[end] as usize;
                if self.s[r] != self.s[first] || self.c[r] != self.c[first] {
                    break;
                }
                end += 1;
            }
            let run = (start, end);
            start = end;
            Some(run)
        })
    }
}

/// (condition ids, offsets, scores) of [`group_by_condition`].
pub(crate) type Grouped = (Vec<u32>, Vec<usize>, Vec<f64>);

/// Scores grouped by condition with one counting pass: (condition ids, offsets, scores) where
/// the scores of condition `ids[k]` are `scores[offsets[k]..offsets[k + 1]]` in row order.
pub(crate) fn group_by_condition(ratings: &[Rating]) -> Result<Grouped, AnalysisError> {
    check_row_count(ratings)?;
    check_scores(ratings)?;
    let (ids, c) = dense(&ratings.iter().map(|r| r.condition).collect::<Vec<_>>());
    let mut offsets = vec![0usize; ids.len() + 1];
    for k in &c {
        offsets[*k as usize + 1] += 1;
    }
    for k in 0..ids.len() {
        offsets[k + 1] += offsets[k];
    }
    let mut fill = offsets.clone();
    let mut scores = vec![0.0; ratings.len()];
    for (r, k) in ratings.iter().zip(&c) {
        scores[fill[*k as usize]] = r.score;
        fill[*k as usize] += 1;
    }
    Ok((ids, offsets, scores))
}
