//! `[simulation]`: the simulated observers of `study simulate`.

use toml::Table;

use super::check::{Ctx, join};
use super::{Detection, Metric, Psychometric, SimulationSettings};

pub(super) fn parse_simulation(t: &Table, cx: &mut Ctx) -> SimulationSettings {
    const P: &str = "simulation";
    cx.known(
        t,
        P,
        &[
            "metric",
            "quality_scale",
            "bias_sd",
            "noise_sd",
            "psychometric",
            "detection",
            "threshold",
            "slope",
            "lapse",
            "response_time_ms",
            "attention",
        ],
    );
    let d = SimulationSettings::default();
    let detection = cx.pick(
        t,
        P,
        "detection",
        &[("level", Detection::Level), ("error", Detection::Error)],
    );
    let metric = cx.pick(
        t,
        P,
        "metric",
        &[
            ("rms_cm", Metric::RmsCm),
            ("max_cm", Metric::MaxCm),
            ("mean_angle_deg", Metric::MeanAngleDeg),
        ],
    );
    let psychometric = cx.pick(
        t,
        P,
        "psychometric",
        &[
            ("weibull", Psychometric::Weibull),
            ("logistic", Psychometric::Logistic),
        ],
    );
    let positive = |cx: &mut Ctx, key: &str, default: f64| match cx.float(t, P, key) {
        Some(v) if v > 0.0 => v,
        Some(v) => {
            cx.err(join(P, key), format!("must be positive, got {v}"));
            default
        }
        None => default,
    };
    let quality_scale = positive(cx, "quality_scale", d.quality_scale);
    let slope = positive(cx, "slope", d.slope);
    let threshold = match cx.float(t, P, "threshold") {
        Some(v) => v,
        None => d.threshold,
    };
    let nonneg = |cx: &mut Ctx, key: &str, default: f64, hi: f64| match cx.float(t, P, key) {
        Some(v) if (0.0..=hi).contains(&v) => v,
        Some(v) => {
            cx.err(join(P, key), format!("must be in [0, {hi}], got {v}"));
            default
        }
        None => default,
    };
    let bias_sd = nonneg(cx, "bias_sd", d.bias_sd, 1e6);
    let noise_sd = nonneg(cx, "noise_sd", d.noise_sd, 1e6);
    let lapse = nonneg(cx, "lapse", d.lapse, 0.5);
    let response_time_ms = cx
        .uint(t, P, "response_time_ms", 600_000)
        .map_or(d.response_time_ms, u64::from);
    let mut attention = std::collections::BTreeMap::new();
    if let Some(a) = cx.table(t, P, "attention") {
        for k in a.keys() {
            match cx.float(a, "simulation.attention", k) {
                Some(v) if v >= 0.0 => {
                    attention.insert(k.clone(), v);
                }
                Some(v) => cx.err(
                    format!("{P}.attention.{k}"),
                    format!("must be 0 or more, got {v}"),
                ),
                None => {}
            }
        }
    }
    SimulationSettings {
        metric: metric.unwrap_or(d.metric),
        quality_scale,
        bias_sd,
        noise_sd,
        psychometric: psychometric.unwrap_or(d.psychometric),
        detection: detection.unwrap_or(d.detection),
        threshold,
        slope,
        lapse,
        response_time_ms,
        attention,
    }
}
