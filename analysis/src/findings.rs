//! Rate findings: MOS or DMOS against compression ratio per codec and clip, and the highest
//! ratio whose confidence bound stays on the good side of a limit ("the codec can compress to
//! X:1 before viewers notice": DMOS < 0.2 in thesis §6.4.3, MOS ≥ 4.5 in §3.3).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::descriptive::{CiMethod, ConditionStats, Summary};

/// What a test condition is: codec and its varied parameters, clip and compression ratio (x
/// in x:1).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConditionInfo {
    /// Condition id (as in [`crate::Rating::condition`]).
    pub id: u32,
    /// Codec name (or method / weighting label).
    pub codec: String,
    /// The codec parameters the stimulus' sweep varied (the manifest's `variant`): two
    /// variants of a codec at one ratio are two methods ([`ConditionInfo::method`]). Empty
    /// when nothing was varied.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub params: BTreeMap<String, f64>,
    /// Clip name, e.g. "2_2".
    pub clip: String,
    /// Compression ratio x of x:1; `None` for references.
    pub compression_ratio: Option<f64>,
}

impl ConditionInfo {
    /// The label of the condition's method in every table, test and plot: the codec, with
    /// its varied parameters when it has any (`wavelet-perceptual/qp9-window128`, as in the
    /// stimulus id); the codec alone otherwise.
    pub fn method(&self) -> String {
        protocols::manifest::method_label(&self.codec, &self.params)
    }
}

/// The limit a finding is checked against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[non_exhaustive]
pub enum Limit {
    /// DMOS (an impairment) must stay below this value: the CI's upper bound is checked.
    DmosBelow(f64),
    /// MOS (a quality) must stay at or above this value: the CI's lower bound is checked.
    MosAtLeast(f64),
}

/// One point of a rate curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RatePoint {
    /// Compression ratio.
    pub compression_ratio: f64,
    /// Condition id.
    pub condition: u32,
    /// Statistics of the scores at this ratio.
    pub summary: Summary,
}

/// A rate curve and its finding for one method (codec and variant) and clip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RateFinding {
    /// The method ([`ConditionInfo::method`]): the codec, with its varied parameters.
    pub codec: String,
    /// Clip.
    pub clip: String,
    /// Points sorted by compression ratio.
    pub points: Vec<RatePoint>,
    /// The highest ratio such that it and every lower tested ratio pass the limit; `None` when
    /// already the lowest fails (or its CI is undefined).
    pub highest_passing_ratio: Option<f64>,
}

fn passes(summary: &Summary, limit: Limit, method: CiMethod) -> bool {
    let Some(ci) = summary.ci(method) else {
        return false;
    };
    match limit {
        Limit::DmosBelow(l) => ci.upper < l,
        Limit::MosAtLeast(l) => ci.lower >= l,
    }
}

/// Builds rate curves per (method, clip) from condition statistics and finds, for each, the
/// highest compression ratio whose CI bound (by `method`) stays within `limit`. The run must be
/// unbroken from the lowest ratio: a pass at 60:1 after a failure at 50:1 is noise, not a
/// finding. Conditions without a ratio (references) are skipped.
pub fn rate_findings(
    conditions: &[ConditionInfo],
    stats: &[ConditionStats],
    limit: Limit,
    method: CiMethod,
) -> Vec<RateFinding> {
    let by_id: BTreeMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
    let mut curves: BTreeMap<(String, String), Vec<RatePoint>> = BTreeMap::new();
    for s in stats {
        let Some(info) = by_id.get(&s.condition) else {
            continue;
        };
        let Some(cr) = info.compression_ratio else {
            continue;
        };
        curves
            .entry((info.method(), info.clip.clone()))
            .or_default()
            .push(RatePoint {
                compression_ratio: cr,
                condition: s.condition,
                summary: s.summary,
            });
    }
    curves
        .into_iter()
        .map(|((codec, clip), mut points)| {
            points.sort_by(|a, b| a.compression_ratio.total_cmp(&b.compression_ratio));
            let highest_passing_ratio = points
                .iter()
                .take_while(|p| passes(&p.summary, limit, method))
                .last()
                .map(|p| p.compression_ratio);
            RateFinding {
                codec,
                clip,
                points,
                highest_passing_ratio,
            }
        })
        .collect()
}
