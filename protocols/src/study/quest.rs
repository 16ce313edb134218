//! `[staircase] method = "quest_plus"` or `"psi"` and its `[staircase.quest]` table: the
//! stimulus domain (the level grid of `min`, `max`, `step`, `step_type`), the parameter grids
//! of threshold, slope and lapse rate with their priors, the credible level and the optional
//! interval stop.

use toml::{Table, Value};

use super::check::{Ctx, join, type_name};
use super::{Psychometric, Track};
use crate::quest::{QuestMethod, QuestSettings, check_settings};
use crate::staircase::{StaircaseSettings, StepType, canonical_level};

const P: &str = "staircase.quest";

/// Keys of `[staircase]` that only an up-down staircase uses.
const UP_DOWN_KEYS: &[&str] = &[
    "start",
    "down_up_ratio",
    "n_up",
    "n_down",
    "apply_initial_rule",
    "stop_reversals",
    "threshold_reversals",
];

/// Most values of one parameter grid.
const MAX_GRID: usize = 10_000;

/// `staircase.method`: `None` for the up-down staircase (the default), else the Bayesian
/// procedure; a `[staircase.quest]` table without a Bayesian method is refused.
pub(super) fn parse_method(t: &Table, cx: &mut Ctx) -> Option<QuestMethod> {
    let method = cx.pick(
        t,
        "staircase",
        "method",
        &[
            ("up_down", None),
            ("quest_plus", Some(QuestMethod::QuestPlus)),
            ("psi", Some(QuestMethod::Psi)),
        ],
    );
    let method = method.flatten();
    if method.is_none() && t.contains_key("quest") {
        cx.err(
            "staircase.quest",
            "only method = \"quest_plus\" or \"psi\" takes a [staircase.quest] table",
        );
    }
    if let Some(m) = method {
        for k in UP_DOWN_KEYS.iter().filter(|k| t.contains_key(**k)) {
            cx.err(
                join("staircase", k),
                format!(
                    "an up-down staircase setting; method = {:?} chooses every level itself (remove it)",
                    m.as_str()
                ),
            );
        }
        if !t.contains_key("max_trials") {
            cx.err(
                "staircase.max_trials",
                format!(
                    "missing: method = {:?} runs a fixed number of trials",
                    m.as_str()
                ),
            );
        }
    }
    method
}

/// The levels a Bayesian track may put a trial at: `min`, then a step at a time (linear,
/// log10 or dB, as a staircase steps) up to `max`, each the decimal the study file's numbers
/// make (12 significant digits, as staircase levels). Empty when the settings give none or
/// over [`crate::quest::MAX_LEVELS`] + 1.
pub fn domain(s: &StaircaseSettings) -> Vec<f64> {
    let (Some(lo), Some(hi)) = (s.min, s.max) else {
        return Vec::new();
    };
    if !(s.step > 0.0 && lo.is_finite() && hi.is_finite() && lo <= hi) {
        return Vec::new();
    }
    if s.step_type != StepType::Linear && lo <= 0.0 {
        return Vec::new();
    }
    let mut out = Vec::new();
    for k in 0..=crate::quest::MAX_LEVELS {
        let k = k as f64;
        let x = canonical_level(match s.step_type {
            StepType::Linear => lo + k * s.step,
            StepType::Log => lo * 10_f64.powf(k * s.step),
            StepType::Db => lo * 10_f64.powf(k * s.step / 20.0),
        });
        if x > hi + 1e-9 * (hi - lo).abs().max(s.step) {
            break;
        }
        out.push(x);
    }
    out
}

/// `[staircase.quest]` with the level grid of `settings`: the procedure's settings, or `None`
/// with every problem reported.
pub(super) fn parse_quest(
    t: Option<&Table>,
    method: QuestMethod,
    settings: &StaircaseSettings,
    cx: &mut Ctx,
) -> Option<QuestSettings> {
    let empty = Table::new();
    let q = if let Some(q) = t {
        q
    } else {
        cx.err(
            P,
            "missing: a QUEST+ or Psi study needs [staircase.quest] with at least `threshold`",
        );
        &empty
    };
    cx.known(
        q,
        P,
        &[
            "psychometric",
            "threshold",
            "slope",
            "lapse",
            "credible",
            "stop_interval",
        ],
    );
    let family = cx
        .pick(
            q,
            P,
            "psychometric",
            &[
                ("weibull", Psychometric::Weibull),
                ("logistic", Psychometric::Logistic),
            ],
        )
        .unwrap_or(Psychometric::Weibull);
    let threshold = if let Some(v) = q.get("threshold") {
        grid(v, "threshold", cx)
    } else {
        if t.is_some() {
            cx.err(join(P, "threshold"), "missing");
        }
        None
    };
    let slope = match q.get("slope") {
        Some(v) => grid(v, "slope", cx),
        None => Some(Grid::uniform(vec![1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0])),
    };
    let lapse = match q.get("lapse") {
        Some(v) => grid(v, "lapse", cx),
        None if method == QuestMethod::Psi => Some(Grid::uniform(vec![0.02])),
        None => Some(Grid::uniform(vec![0.0, 0.01, 0.02, 0.03, 0.04])),
    };
    let credible = cx.float(q, P, "credible").unwrap_or(0.95);
    let stop_interval = cx.float(q, P, "stop_interval");
    let levels = domain(settings);
    if levels.is_empty() {
        cx.err(
            "staircase.min",
            "min, max and step give no level (min ≤ max, step > 0, and min > 0 for log or dB steps)",
        );
    }
    let (threshold, slope, lapse) = (threshold?, slope?, lapse?);
    let s = QuestSettings {
        method,
        family,
        levels,
        thresholds: threshold.values,
        slopes: slope.values,
        lapses: lapse.values,
        threshold_prior: threshold.weights,
        slope_prior: slope.weights,
        lapse_prior: lapse.weights,
        max_trials: settings.max_trials.unwrap_or(0),
        min_trials: settings.min_trials,
        stop_interval,
        credible,
    };
    let problems = check_settings(&s);
    for e in &problems {
        if let crate::quest::QuestError::BadSetting { key, reason } = e
            && !cx
                .issues
                .iter()
                .any(|i| i.key == *key && i.reason == *reason)
        {
            cx.err(*key, reason.clone());
        }
    }
    problems.is_empty().then_some(s)
}

/// One parameter's grid and prior weights.
struct Grid {
    values: Vec<f64>,
    weights: Vec<f64>,
}

impl Grid {
    fn uniform(values: Vec<f64>) -> Self {
        Self {
            weights: vec![1.0; values.len()],
            values,
        }
    }
}

/// A parameter grid as the study file gives it: a number (a fixed value), an array of
/// numbers, or a table with `values` or `min`/`max`/`count`/`spacing`, and `prior` or
/// `weights`.
fn grid(v: &Value, name: &str, cx: &mut Ctx) -> Option<Grid> {
    let path = join(P, name);
    match v {
        Value::Integer(i) => Some(Grid::uniform(vec![*i as f64])),
        Value::Float(f) if f.is_finite() => Some(Grid::uniform(vec![*f])),
        Value::Array(_) => {
            let mut t = Table::new();
            t.insert("values".into(), v.clone());
            grid_table(&t, &path, cx)
        }
        Value::Table(t) => grid_table(t, &path, cx),
        v => {
            cx.err(
                &path,
                format!(
                    "expected a number, an array of numbers or a table, got {}",
                    type_name(v)
                ),
            );
            None
        }
    }
}

fn grid_table(t: &Table, path: &str, cx: &mut Ctx) -> Option<Grid> {
    cx.known(
        t,
        path,
        &[
            "values", "min", "max", "count", "spacing", "prior", "weights",
        ],
    );
    let values = if t.contains_key("values") {
        for k in ["min", "max", "count", "spacing"] {
            if t.contains_key(k) {
                cx.err(join(path, k), "give either `values` or min/max/count");
            }
        }
        let v = cx.floats(t, path, "values")?;
        if v.len() > MAX_GRID {
            cx.err(
                join(path, "values"),
                format!("{} values, limit {MAX_GRID}", v.len()),
            );
            return None;
        }
        v
    } else {
        let lo = cx.float(t, path, "min");
        let lo = cx.required(lo, t, path, "min");
        let hi = cx.float(t, path, "max");
        let hi = cx.required(hi, t, path, "max");
        let n = cx.uint(t, path, "count", MAX_GRID as u32);
        let n = cx.required(n, t, path, "count");
        let log = cx
            .pick(t, path, "spacing", &[("linear", false), ("log", true)])
            .unwrap_or(false);
        let (lo, hi, n) = (lo?, hi?, n? as usize);
        if n == 0 || (n == 1 && (lo - hi).abs() > 0.0) || lo > hi {
            cx.err(
                path,
                format!("min {lo}, max {hi}, count {n}: need min < max and count ≥ 2 (or min = max and count 1)"),
            );
            return None;
        }
        if log && lo <= 0.0 {
            cx.err(join(path, "min"), "log spacing needs min > 0");
            return None;
        }
        (0..n)
            .map(|i| {
                let f = if n == 1 {
                    0.0
                } else {
                    i as f64 / (n - 1) as f64
                };
                if i + 1 == n {
                    hi
                } else if log {
                    lo * (hi / lo).powf(f)
                } else {
                    lo + f * (hi - lo)
                }
            })
            .collect()
    };
    if t.contains_key("weights") && t.contains_key("prior") {
        cx.err(join(path, "weights"), "give either `prior` or `weights`");
        return None;
    }
    let weights = if t.contains_key("weights") {
        let w = cx.floats(t, path, "weights")?;
        if w.len() != values.len() {
            cx.err(
                join(path, "weights"),
                format!("{} weights for {} values", w.len(), values.len()),
            );
            return None;
        }
        w
    } else {
        prior(t.get("prior"), &values, &join(path, "prior"), cx)?
    };
    Some(Grid { values, weights })
}

/// The prior weights of `values`: `"uniform"` (the default), or a table `{ kind = "normal",
/// mean, sd }`, `{ kind = "log_normal", mean, sd }` (of log10 of the value) or `{ kind =
/// "beta", a, b }`, each its density at the grid values.
fn prior(v: Option<&Value>, values: &[f64], path: &str, cx: &mut Ctx) -> Option<Vec<f64>> {
    let t = match v {
        None => return Some(vec![1.0; values.len()]),
        Some(Value::String(s)) if s == "uniform" => return Some(vec![1.0; values.len()]),
        Some(Value::Table(t)) => t,
        Some(v) => {
            cx.err(
                path,
                format!(
                    "expected \"uniform\" or a table with kind = \"normal\", \"log_normal\" or \"beta\", got {}",
                    match v {
                        Value::String(s) => format!("{s:?}"),
                        v => type_name(v).to_string(),
                    }
                ),
            );
            return None;
        }
    };
    let kind = cx.pick(
        t,
        path,
        "kind",
        &[
            ("uniform", 0_u8),
            ("normal", 1),
            ("log_normal", 2),
            ("beta", 3),
        ],
    );
    let kind = cx.required(kind, t, path, "kind")?;
    let (ka, kb, names): (&str, &str, &[&str]) = match kind {
        0 => {
            cx.known(t, path, &["kind"]);
            return Some(vec![1.0; values.len()]);
        }
        1 | 2 => ("mean", "sd", &["kind", "mean", "sd"]),
        _ => ("a", "b", &["kind", "a", "b"]),
    };
    cx.known(t, path, names);
    let a = cx.float(t, path, ka);
    let a = cx.required(a, t, path, ka);
    let b = cx.float(t, path, kb);
    let b = cx.required(b, t, path, kb);
    let (a, b) = (a?, b?);
    if !(b > 0.0 && (kind != 3 || a > 0.0)) {
        cx.err(
            path,
            format!(
                "{ka} = {a}, {kb} = {b}: the parameters must be > 0 (the mean may be any number)"
            ),
        );
        return None;
    }
    let w: Vec<f64> = values
        .iter()
        .map(|&x| match kind {
            1 => (-0.5 * ((x - a) / b).powi(2)).exp(),
            2 if x > 0.0 => (-0.5 * ((x.log10() - a) / b).powi(2)).exp() / x,
            3 if x > 0.0 && x < 1.0 => x.powf(a - 1.0) * (1.0 - x).powf(b - 1.0),
            3 if x <= 0.0 && (a - 1.0).abs() < 1e-12 => 1.0,
            _ => 0.0,
        })
        .collect();
    if !w.iter().any(|x| *x > 0.0) {
        cx.err(path, "the prior is 0 at every grid value");
        return None;
    }
    Some(w)
}

/// Every level of the domain must have a stimulus of the track's clip within `tol`; the
/// track keeps only those stimuli (the ones a session can show).
pub(super) fn check_domain(track: &mut Track, levels: &[f64], tol: f64, path: &str, cx: &mut Ctx) {
    let mut missing = Vec::new();
    let mut shown = Vec::new();
    for &x in levels {
        match track.stimulus_at(x, tol) {
            Some(id) => shown.push((x, id.to_string())),
            None => missing.push(format!("{x}")),
        }
    }
    if !missing.is_empty() {
        let n = missing.len();
        missing.truncate(8);
        cx.err(
            join(path, "clip"),
            format!(
                "{n} level(s) of the stimulus domain have no stimulus of clip {:?} within {tol}: {}{}",
                track.clip,
                missing.join(", "),
                if n > 8 { ", ..." } else { "" }
            ),
        );
    }
    shown.sort_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(&b.1)));
    shown.dedup_by(|a, b| a.1 == b.1);
    track.levels = shown;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_domain_is_the_decimal_grid() {
        let s = StaircaseSettings {
            min: Some(0.004),
            max: Some(0.040),
            step: 0.006,
            ..StaircaseSettings::default()
        };
        assert_eq!(
            domain(&s),
            vec![0.004, 0.01, 0.016, 0.022, 0.028, 0.034, 0.04]
        );
        let log = StaircaseSettings {
            min: Some(1.0),
            max: Some(100.0),
            step: 0.5,
            step_type: StepType::Log,
            ..StaircaseSettings::default()
        };
        assert_eq!(domain(&log).len(), 5);
    }
}
