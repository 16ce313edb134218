//! `[scale]`: the rating scale of a MOS, DSCQS, ACR or DCR study, with the protocol's defaults.

use toml::Table;

use super::check::{Ctx, join};
use super::{RatingScale, ScaleKind, ScaleWords};
use crate::record::Protocol;

pub(super) fn parse_scale(
    t: &Table,
    protocol: Option<Protocol>,
    cx: &mut Ctx,
) -> Option<RatingScale> {
    const P: &str = "scale";
    cx.known(t, P, &["kind", "min", "max", "step"]);
    let kind = cx.pick(
        t,
        P,
        "kind",
        &[
            ("categorical", ScaleKind::Categorical),
            ("continuous", ScaleKind::Continuous),
        ],
    );
    let kind = match kind {
        Some(k) => k,
        None if t.contains_key("kind") => return None,
        None if matches!(protocol, Some(Protocol::Dscqs | Protocol::Mushra)) => {
            ScaleKind::Continuous
        }
        None => ScaleKind::Categorical,
    };
    let (dmin, dmax, dstep) = match kind {
        ScaleKind::Categorical => (
            1.0,
            5.0,
            Some(if protocol == Some(Protocol::Mos) {
                0.5
            } else {
                1.0
            }),
        ),
        // BS.1534: a 0-100 slider; whole points keep it keyboard-friendly.
        ScaleKind::Continuous if protocol == Some(Protocol::Mushra) => (0.0, 100.0, Some(1.0)),
        ScaleKind::Continuous => (0.0, 100.0, None),
    };
    let min = cx.float(t, P, "min").unwrap_or(dmin);
    let max = cx.float(t, P, "max").unwrap_or(dmax);
    let step = cx
        .float(t, P, "step")
        .or(if t.contains_key("step") { None } else { dstep });
    if min >= max {
        cx.err(join(P, "max"), format!("max {max} must be above min {min}"));
    }
    if let Some(s) = step {
        if s <= 0.0 {
            cx.err(join(P, "step"), format!("step must be positive, got {s}"));
        } else if min < max {
            let k = (max - min) / s;
            if (k - k.round()).abs() > 1e-9 || k > 10_000.0 {
                cx.err(
                    join(P, "step"),
                    format!("(max - min) / step = {k} must be a whole number up to 10000"),
                );
            }
        }
    } else if kind == ScaleKind::Categorical {
        cx.err(join(P, "step"), "a categorical scale needs a step");
    }
    // P.910 DCR: five impairment categories, 5 (imperceptible) to 1 (very annoying).
    let five_categories = kind == ScaleKind::Categorical
        && [(min, 1.0), (max, 5.0), (step.unwrap_or(0.0), 1.0)]
            .iter()
            .all(|(v, want)| (v - want).abs() < 1e-12);
    if protocol == Some(Protocol::Dcr) && !five_categories {
        cx.err(
            P,
            format!(
                "DCR rates five impairment categories (P.910): use kind = \"categorical\", min = \
                 1, max = 5, step = 1 (or omit [scale]), not {} {min}..{max} step {step:?}",
                if kind == ScaleKind::Categorical {
                    "categorical"
                } else {
                    "continuous"
                }
            ),
        );
    }
    let zero_to_hundred =
        kind == ScaleKind::Continuous && (min - 0.0).abs() < 1e-12 && (max - 100.0).abs() < 1e-12;
    if protocol == Some(Protocol::Mushra) && !zero_to_hundred {
        cx.err(
            P,
            format!(
                "MUSHRA rates on BS.1534's continuous 0-100 scale (its post-screening limits are \
                 on it): use kind = \"continuous\", min = 0, max = 100 (or omit [scale]), not \
                 {min}..{max}"
            ),
        );
    }
    let words = if protocol == Some(Protocol::Dcr) {
        ScaleWords::Impairment
    } else {
        ScaleWords::Quality
    };
    Some(RatingScale {
        kind,
        min,
        max,
        step,
        words,
    })
}
