//! `[scale]`: the rating scale of a MOS, DSCQS, ACR or DCR study, with the protocol's defaults.

use toml::Table;

use super::check::{Ctx, join};
use super::{RatingScale, ScaleKind};
use crate::methods::Method;
use crate::record::Protocol;

pub(super) fn parse_scale(
    t: &Table,
    protocol: Option<Protocol>,
    cx: &mut Ctx,
) -> Option<RatingScale> {
    const P: &str = "scale";
    let method = protocol.map(crate::methods::of);
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
        None => method.map_or(ScaleKind::Categorical, Method::default_scale_kind),
    };
    let (dmin, dmax) = match method {
        Some(m) => m.default_scale_range(kind),
        None if kind == ScaleKind::Categorical => (1.0, 5.0),
        None => (0.0, 100.0),
    };
    let dstep = match method {
        Some(m) => m.default_scale_step(kind),
        None => (kind == ScaleKind::Categorical).then_some(1.0),
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
    if let Some(problem) = method.and_then(|m| m.check_scale(kind, min, max, step)) {
        cx.err(P, problem);
    }
    Some(RatingScale {
        kind,
        min,
        max,
        step,
    })
}
