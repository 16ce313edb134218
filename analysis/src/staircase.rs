//! Staircase thresholds (thesis §5.4: a two-down-one-up 2AFC staircase on t_L, "the converging
//! point was set as the average of the last three reversal points" (García-Pérez 1998)).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::confidence::Confidence;
use crate::descriptive::{Summary, summarize};
use crate::error::AnalysisError;

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
    Ok(ThresholdSummary {
        per_subject,
        unconverged,
        summary,
        min,
        max,
        last_reversals: k,
    })
}
