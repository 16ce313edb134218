//! Staircase thresholds (thesis §5.4: a two-down-one-up 2AFC staircase on t_L, "the converging
//! point was set as the average of the last three reversal points" (García-Pérez 1998)).
//!
//! A two-down-one-up track converges on the level answered correctly 70.7 % of the time
//! (Levitt 1971: the level where two correct answers in a row are as likely as not,
//! p² = ½). Its reversals alternate between peaks and troughs; the mean of an odd number of
//! the last reversals holds one more of one kind, and sits a fraction of a step off the
//! 70.7 % point (below it when the extra one is a trough: about a sixth to a fifth of a step
//! with the thesis's settings, `analysis/tests/staircase_bias.rs`); an even number holds as
//! many peaks as troughs and centres on it. [`staircase_thresholds`] gives both: the study's k (the seed's 3) and
//! the even k next to it ([`even_k`]), per track, per subject and across subjects, and the
//! threshold to cite per condition ([`CitedThreshold`]).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::confidence::Confidence;
use crate::descriptive::{Summary, summarize};
use crate::error::AnalysisError;
use crate::jnd::LevelGrid;

/// One trial of a staircase.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StaircaseStep {
    /// Stimulus level presented (e.g. the error threshold t_L).
    pub level: f64,
    /// Whether the answer was correct.
    pub correct: bool,
    /// Whether the staircase reversed direction at this trial (as logged by the runner, or
    /// from [`StaircaseTrack::with_detected_reversals`]).
    pub reversal: bool,
}

/// One staircase run by one subject.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StaircaseTrack {
    /// Subject id.
    pub subject: u32,
    /// Label of the staircase (clip or condition), used in plots.
    pub label: String,
    /// Trials in presentation order.
    pub steps: Vec<StaircaseStep>,
    /// A QUEST+ or Psi track (logged without reversals): it has no reversal threshold and is
    /// left out of [`staircase_thresholds`]; the Bayesian fit gives its threshold.
    pub bayesian: bool,
    /// The threshold the session itself computed for this track (`session.json`): the mean
    /// of the last reversals, or a Bayesian track's posterior mean; `None` if not recorded.
    pub logged_threshold: Option<f64>,
}

impl StaircaseTrack {
    /// Marks reversals from the levels alone: trial i is a reversal when the level moves in
    /// the opposite direction after it than the last non-zero move before it. The reversal
    /// level is the level of trial i (the turning point).
    #[must_use]
    #[expect(
        clippy::float_cmp,
        reason = "levels are logged values: a repeat of the same level is exact equality"
    )]
    pub fn with_detected_reversals(mut self) -> Self {
        let mut last_dir = 0.0_f64;
        let n = self.steps.len();
        for i in 0..n {
            self.steps[i].reversal = false;
            if i + 1 < n {
                let dir = (self.steps[i + 1].level - self.steps[i].level).signum();
                let moved = self.steps[i + 1].level != self.steps[i].level;
                if moved {
                    if last_dir != 0.0 && dir != last_dir {
                        self.steps[i].reversal = true;
                    }
                    last_dir = dir;
                }
            }
        }
        self
    }

    /// Levels at the reversals, in order.
    pub fn reversal_levels(&self) -> Vec<f64> {
        self.steps
            .iter()
            .filter(|s| s.reversal)
            .map(|s| s.level)
            .collect()
    }

    /// Threshold estimate: the mean of the last `k` reversal levels; `None` when the track has
    /// fewer than `k` reversals (or k = 0).
    pub fn threshold(&self, k: usize) -> Option<f64> {
        let rev = self.reversal_levels();
        if k == 0 || rev.len() < k {
            return None;
        }
        Some(rev[rev.len() - k..].iter().sum::<f64>() / k as f64)
    }
}

/// Per-subject thresholds and their across-subject summary ("the average converging threshold
/// was t_L = 0.012, while the smallest was 0.01 and the largest 0.016", thesis §5.4).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ThresholdSummary {
    /// (subject, mean threshold over that subject's converged staircases), sorted by subject.
    pub per_subject: Vec<(u32, f64)>,
    /// Staircases that did not reach k reversals: (subject, label).
    pub unconverged: Vec<(u32, String)>,
    /// Mean, SD, CI of the per-subject thresholds; `None` when no subject converged.
    pub summary: Option<Summary>,
    /// Smallest per-subject threshold.
    pub min: Option<f64>,
    /// Largest per-subject threshold.
    pub max: Option<f64>,
    /// The k used.
    pub last_reversals: usize,
    /// The even k next to it ([`even_k`]): k itself when even, else k + 1.
    pub even_k: usize,
    /// Every up-down track's reversals and both estimates, in the order given.
    pub tracks: Vec<TrackThresholds>,
    /// The threshold to cite per condition (track label), sorted by label, then across all
    /// conditions (each subject's tracks averaged) last.
    pub cited: Vec<CitedThreshold>,
    /// The grid the tracks stepped on, when they moved.
    pub grid: Option<LevelGrid>,
    /// Decimals that print a threshold: the grid's plus one ([`level_decimals`]).
    pub decimals: usize,
}

/// One up-down track's thresholds by both counts of reversals.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrackThresholds {
    /// Subject id.
    pub subject: u32,
    /// The track's label (its condition).
    pub label: String,
    /// Reversals the track reached.
    pub reversals: usize,
    /// The mean of its last k reversals (the study's k), if it reached k.
    pub last_k: Option<f64>,
    /// (the even count used, the mean of that many last reversals): [`ThresholdSummary::even_k`]
    /// when the track reached it, else the largest even count it reached (at least 2).
    pub even: Option<(usize, f64)>,
}

/// The threshold to cite for one condition (or all together): the even-k estimate's mean
/// across subjects with its t interval, the study's k next to it, and the level grid's
/// nearest level.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CitedThreshold {
    /// The condition (track label); `None` for all conditions together.
    pub condition: Option<String>,
    /// Mean, SD and t interval across subjects of the even-k estimates (a subject's tracks of
    /// the condition averaged).
    pub even: Summary,
    /// The mean across subjects of the study's k estimate, over the subjects that reached k.
    pub last_k_mean: Option<f64>,
    /// `even.mean` rounded to the nearest level of the grid (`None` without a linear grid).
    pub on_grid: Option<f64>,
}

/// The even count of reversals next to `k`: k when even, k + 1 when odd (4 for the seed's 3).
#[must_use]
pub fn even_k(k: usize) -> usize {
    if k.is_multiple_of(2) { k } else { k + 1 }
}

/// The mean of a track's last even number of reversals: `even` of them when it has that
/// many, else the largest even count it has (at least 2); with the count used.
fn even_threshold(track: &StaircaseTrack, even: usize) -> Option<(usize, f64)> {
    let n = track.reversal_levels().len();
    let k = if n >= even { even } else { n - n % 2 };
    (k >= 2)
        .then(|| track.threshold(k).map(|t| (k, t)))
        .flatten()
}

/// The decimals that print thresholds on the levels of `tracks`: [`decimals_of_levels`].
#[must_use]
pub fn level_decimals(tracks: &[StaircaseTrack]) -> usize {
    let levels: Vec<f64> = tracks
        .iter()
        .flat_map(|t| t.steps.iter().map(|s| s.level))
        .collect();
    decimals_of_levels(&levels)
}

/// The decimals that print a threshold on a grid of `levels`: those of the grid (the fewest,
/// up to 6, that write every level exactly; for levels that are no short decimals, down to
/// the first significant digit of the smallest gap between two levels) plus one, since a mean
/// of reversals resolves a fraction of a step. 4 without levels.
#[must_use]
pub fn decimals_of_levels(levels: &[f64]) -> usize {
    let mut levels: Vec<f64> = levels.iter().copied().filter(|l| l.is_finite()).collect();
    if levels.is_empty() {
        return 4;
    }
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    let exact = |x: f64, d: i32| {
        let scaled = x * 10_f64.powi(d);
        (scaled - scaled.round()).abs() <= 1e-6 * scaled.abs().max(1e-9)
    };
    let decimals = (0..=6)
        .find(|&d| levels.iter().all(|&x| exact(x, d)))
        .unwrap_or_else(|| {
            let gap = levels
                .windows(2)
                .map(|w| w[1] - w[0])
                .fold(f64::INFINITY, f64::min);
            if gap.is_finite() && gap > 0.0 {
                (-gap.log10().floor()).clamp(0.0, 8.0) as i32
            } else {
                3
            }
        });
    decimals.unsigned_abs() as usize + 1
}

/// Thresholds from the last `k` reversals of every up-down track (QUEST+ and Psi tracks have
/// none and are skipped), averaged per subject, then summarised across subjects at
/// `confidence`.
///
/// # Errors
/// [`AnalysisError::InvalidParameter`] for k = 0;
/// [`AnalysisError::NonFinite`] if a level is not finite.
pub fn staircase_thresholds(
    tracks: &[StaircaseTrack],
    k: usize,
    confidence: Confidence,
) -> Result<ThresholdSummary, AnalysisError> {
    if k == 0 {
        return Err(AnalysisError::InvalidParameter {
            name: "k",
            value: 0.0,
            reason: "need at least one reversal",
        });
    }
    let mut per: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    let mut unconverged = Vec::new();
    for track in tracks.iter().filter(|t| !t.bayesian) {
        for (index, s) in track.steps.iter().enumerate() {
            if !s.level.is_finite() {
                return Err(AnalysisError::NonFinite {
                    what: "staircase level",
                    index,
                    value: s.level,
                });
            }
        }
        match track.threshold(k) {
            Some(t) => per.entry(track.subject).or_default().push(t),
            None => unconverged.push((track.subject, track.label.clone())),
        }
    }
    let per_subject: Vec<(u32, f64)> = per
        .into_iter()
        .map(|(s, v)| (s, v.iter().sum::<f64>() / v.len() as f64))
        .collect();
    let values: Vec<f64> = per_subject.iter().map(|p| p.1).collect();
    let summary = if values.is_empty() {
        None
    } else {
        Some(summarize(&values, confidence)?)
    };
    let min = values.iter().copied().min_by(f64::total_cmp);
    let max = values.iter().copied().max_by(f64::total_cmp);
    let even = even_k(k);
    let grid = LevelGrid::of_tracks(tracks, k.max(even));
    let track_rows: Vec<TrackThresholds> = tracks
        .iter()
        .filter(|t| !t.bayesian)
        .map(|t| TrackThresholds {
            subject: t.subject,
            label: t.label.clone(),
            reversals: t.reversal_levels().len(),
            last_k: t.threshold(k),
            even: even_threshold(t, even),
        })
        .collect();
    let mut labels: Vec<&str> = track_rows.iter().map(|t| t.label.as_str()).collect();
    labels.sort_unstable();
    labels.dedup();
    let mut cited = Vec::new();
    for condition in labels.iter().map(|l| Some(*l)).chain([None]) {
        let rows: Vec<&TrackThresholds> = track_rows
            .iter()
            .filter(|t| condition.is_none_or(|c| t.label == c))
            .collect();
        if let Some(c) = cite(&rows, condition, grid, confidence)? {
            cited.push(c);
        }
    }
    Ok(ThresholdSummary {
        per_subject,
        unconverged,
        summary,
        min,
        max,
        last_reversals: k,
        even_k: even,
        tracks: track_rows,
        cited,
        grid,
        decimals: level_decimals(tracks),
    })
}

/// The threshold to cite over `rows` (one condition's tracks, or all): each subject's
/// even-k estimates averaged, then summarised across subjects; `None` when no track has two
/// reversals.
fn cite(
    rows: &[&TrackThresholds],
    condition: Option<&str>,
    grid: Option<LevelGrid>,
    confidence: Confidence,
) -> Result<Option<CitedThreshold>, AnalysisError> {
    let per_subject = |value: &dyn Fn(&TrackThresholds) -> Option<f64>| -> Vec<f64> {
        let mut per: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
        for t in rows {
            if let Some(v) = value(t) {
                per.entry(t.subject).or_default().push(v);
            }
        }
        per.values()
            .map(|v| v.iter().sum::<f64>() / v.len() as f64)
            .collect()
    };
    let even = per_subject(&|t| t.even.map(|e| e.1));
    if even.is_empty() {
        return Ok(None);
    }
    let last = per_subject(&|t| t.last_k);
    let even = summarize(&even, confidence)?;
    Ok(Some(CitedThreshold {
        condition: condition.map(str::to_owned),
        on_grid: grid.and_then(|g| g.nearest(even.mean)),
        even,
        last_k_mean: (!last.is_empty()).then(|| last.iter().sum::<f64>() / last.len() as f64),
    }))
}
