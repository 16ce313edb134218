//! Counterbalancing: balanced Latin squares (Williams designs) over a study's conditions, and
//! the balanced placement of the reference.
//!
//! A Williams design (Williams 1949) orders `n` conditions so that, over a complete block of
//! subjects, every condition appears at every position equally often and every condition
//! immediately follows every other equally often (first-order carryover balance). For an even
//! `n` one square of `n` rows does it, each ordered pair adjacent exactly once; for an odd `n`
//! the square and its mirror image (`2n` rows), each ordered pair adjacent exactly twice.
//! Subject `k` takes row `k mod rows`, so the ordering is a pure function of the subject index
//! (resume replays it). Rows are computed one at a time; no square is stored.

use crate::record::{Arrangement, Position};
use crate::rng::{StudyRng, purpose};

/// Rows of the Williams design over `n` conditions: `n` for an even `n`, `2n` for an odd one
/// (1 for `n <= 1`). A complete block of subjects is this many.
pub fn williams_rows(n: usize) -> usize {
    if n <= 1 {
        1
    } else if n.is_multiple_of(2) {
        n
    } else {
        2 * n
    }
}

/// Row `row` (taken modulo [`williams_rows`]) of the Williams design over conditions
/// `0..n`: the order in which that row's subject sees them.
///
/// The first row is `0, 1, n-1, 2, n-2, ...`; row `r < n` adds `r` modulo `n` to every entry;
/// for an odd `n`, rows `n..2n` are rows `0..n` reversed.
pub fn williams_row(n: usize, row: usize) -> Vec<usize> {
    if n == 0 {
        return Vec::new();
    }
    let row = row % williams_rows(n);
    let shift = row % n;
    let mut out: Vec<usize> = (0..n)
        .map(|j| {
            let first = if j == 0 {
                0
            } else if j % 2 == 1 {
                j.div_ceil(2)
            } else {
                n - j / 2
            };
            (first + shift) % n
        })
        .collect();
    if row >= n {
        out.reverse();
    }
    out
}

/// The position that shows the reference first in `arrangement` (left, first interval, A).
pub fn first_position(arrangement: Arrangement) -> Position {
    match arrangement {
        Arrangement::SideBySide => Position::Left,
        Arrangement::Sequential => Position::First,
        Arrangement::Abab => Position::A,
        // One stimulus (ACR): the reference is not shown.
        Arrangement::Single => Position::Hidden,
        // MUSHRA: the first pane (its plan places every stimulus itself).
        Arrangement::Grid => Position::Pane(0),
    }
}

/// Balanced reference sides for `n` items (conditions, or trials of a block) of subject
/// `subject`: exactly half of the items (one more or less when `n` is odd) get the first
/// position, which half is drawn from `seed` per pair of subjects, and the odd subject of a
/// pair (1, 3, 5, ...) gets the mirror image. So each subject sees the reference on each side
/// equally often, and across every two consecutive subjects each item shows it on each side
/// once. `tags` separate independent draws (e.g. the block of a staircase session).
pub fn balanced_sides(
    seed: u64,
    subject: u32,
    tags: &[u64],
    n: usize,
    arrangement: Arrangement,
) -> Vec<Position> {
    let first = first_position(arrangement);
    let mut mix = vec![u64::from(subject / 2), purpose::SIDES];
    mix.extend_from_slice(tags);
    let mut rng = StudyRng::new(seed, &mix);
    // Which of the two sides gets the odd item out alternates between pairs of subjects.
    let mut sides: Vec<bool> = (0..n)
        .map(|i| {
            if n % 2 == 1 && i == n - 1 {
                (subject / 2).is_multiple_of(2)
            } else {
                i % 2 == 0
            }
        })
        .collect();
    rng.shuffle(&mut sides);
    let flip = subject % 2 == 1;
    sides
        .into_iter()
        .map(|s| if s == flip { first.other() } else { first })
        .collect()
}

/// Trials per block of a staircase session's balanced sides: each run of this many trials
/// shows the reference on each side equally often, in an order the subject cannot predict.
pub const SIDE_BLOCK: u32 = 4;

/// The balanced reference position of trial `index` of a staircase session (trials are
/// decided one at a time): [`balanced_sides`] over blocks of [`SIDE_BLOCK`] trials.
pub fn balanced_side_of_trial(
    seed: u64,
    subject: u32,
    index: u32,
    arrangement: Arrangement,
) -> Position {
    let block = index / SIDE_BLOCK;
    let sides = balanced_sides(
        seed,
        subject,
        &[u64::from(block)],
        SIDE_BLOCK as usize,
        arrangement,
    );
    sides[(index % SIDE_BLOCK) as usize]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_rows_are_the_textbook_ones() {
        // Williams (1949) / Bradley (1958): 0 1 n-1 2 n-2 ...
        assert_eq!(williams_row(4, 0), vec![0, 1, 3, 2]);
        assert_eq!(williams_row(4, 1), vec![1, 2, 0, 3]);
        assert_eq!(williams_row(6, 0), vec![0, 1, 5, 2, 4, 3]);
        assert_eq!(williams_row(3, 0), vec![0, 1, 2]);
        assert_eq!(williams_row(3, 3), vec![2, 1, 0]);
        assert_eq!(williams_row(1, 7), vec![0]);
    }
}
