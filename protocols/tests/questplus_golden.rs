//! QUEST+ against the `questplus` package from PyPI (issue 24): on fixed answer sequences,
//! `protocols::quest::QuestPlus` must choose the level questplus chooses on every trial and
//! hold the same posterior after every answer.
//!
//! `scripts/golden/questplus_golden.py` runs questplus (Weibull, `stim_scale = "linear"`,
//! `min_entropy`) on the cases this test writes: uniform and non-uniform priors (log-normal
//! threshold, beta lapse as in `examples/quest.toml`), a Psi grid with the lapse fixed, and a
//! subject who is always right. The answers come from a simulated observer at the levels the
//! engine chose, so they are a realistic sequence; questplus gets them as a fixed list and has
//! to arrive at the same levels by itself.
//!
//! The Python is `$BAYES_PYTHON`, which `scripts/test` points at the venv it makes
//! (`target/bayes-env`, pins in `scripts/reference/bayes-requirements.txt`), or without the
//! variable that venv itself. Under `CI` a missing interpreter or package fails the test;
//! elsewhere it skips with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use protocols::observer::PsychometricFunction;
use protocols::quest::{QuestMethod, QuestPlus, QuestSettings};
use protocols::rng::StudyRng;
use protocols::study::Psychometric;
use serde_json::{Value, json};

/// Largest difference allowed between two posteriors (probabilities summing to 1) computed
/// with the same formula in a different order of floating-point operations.
const POSTERIOR_TOL: f64 = 1e-10;

#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

fn python() -> Option<std::path::PathBuf> {
    venv_python::BAYES.python("questplus", "questplus golden test")
}

fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64))
        .collect()
}

fn settings(method: QuestMethod, levels: Vec<f64>, lapses: Vec<f64>, trials: u32) -> QuestSettings {
    QuestSettings::uniform(
        method,
        Psychometric::Weibull,
        levels,
        log_grid(0.002, 0.06, 30),
        vec![1.5, 2.0, 3.0, 4.0, 6.0],
        lapses,
        trials,
    )
}

/// The engine's run: its levels, its posteriors after every trial, and the answers a
/// simulated observer (`None`: always right) gave at those levels.
struct Run {
    levels: Vec<f64>,
    posteriors: Vec<Vec<f64>>,
    answers: Vec<bool>,
    engine: QuestPlus,
}

fn run(s: &QuestSettings, observer: Option<(PsychometricFunction, u64)>) -> Run {
    let mut q = QuestPlus::new(s.clone()).unwrap();
    let mut out = Run {
        levels: Vec::new(),
        posteriors: Vec::new(),
        answers: Vec::new(),
        engine: q.clone(),
    };
    let mut i = 0;
    while let Some(x) = q.next_level() {
        let correct =
            observer.is_none_or(|(f, seed)| StudyRng::new(seed, &[i]).unit_f64() < f.p_correct(x));
        q.add_response(correct).unwrap();
        out.levels.push(x);
        out.answers.push(correct);
        out.posteriors.push(q.posterior().to_vec());
        i += 1;
    }
    out.engine = q;
    out
}

fn case_json(s: &QuestSettings, answers: &[bool]) -> Value {
    json!({
        "levels": s.levels, "thresholds": s.thresholds, "slopes": s.slopes, "lapses": s.lapses,
        "threshold_prior": s.threshold_prior, "slope_prior": s.slope_prior,
        "lapse_prior": s.lapse_prior, "answers": answers,
    })
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// (name, settings, the observer answering and its seed; `None`: always right).
type Case = (
    &'static str,
    QuestSettings,
    Option<(PsychometricFunction, u64)>,
);

/// Uniform priors, `examples/quest.toml`'s priors, Psi, and a subject who is always right.
fn cases() -> Vec<Case> {
    let observer = PsychometricFunction {
        family: Psychometric::Weibull,
        threshold: 0.012,
        slope: 3.5,
        lapse: 0.02,
    };
    let fine: Vec<f64> = (2..=40).step_by(2).map(|k| f64::from(k) / 1000.0).collect();
    let example: Vec<f64> = (0..7).map(|k| 0.004 + 0.006 * f64::from(k)).collect();
    let mut informed = settings(
        QuestMethod::QuestPlus,
        example,
        vec![0.0, 0.01, 0.02, 0.03, 0.04],
        30,
    );
    // examples/quest.toml's priors: log-normal threshold (log10 mean -1.92, sd 0.3), Beta(1, 10)
    // lapse.
    informed.threshold_prior = informed
        .thresholds
        .iter()
        .map(|x| (-0.5 * ((x.log10() + 1.92) / 0.3).powi(2)).exp() / x)
        .collect();
    informed.lapse_prior = informed
        .lapses
        .iter()
        .map(|l: &f64| (1.0 - l).powi(9))
        .collect();
    vec![
        (
            "uniform priors",
            settings(
                QuestMethod::QuestPlus,
                fine.clone(),
                vec![0.0, 0.02, 0.04],
                30,
            ),
            Some((observer, 1)),
        ),
        ("example priors", informed, Some((observer, 2))),
        (
            "psi",
            settings(QuestMethod::Psi, fine.clone(), vec![0.02], 25),
            Some((observer, 3)),
        ),
        (
            "always right",
            settings(QuestMethod::QuestPlus, fine, vec![0.0, 0.02, 0.04], 12),
            None,
        ),
    ]
}

#[test]
fn levels_and_posteriors_equal_questplus() {
    let Some(python) = python() else { return };
    let cases = cases();
    let runs: Vec<Run> = cases.iter().map(|(_, s, o)| run(s, *o)).collect();
    let input: Vec<Value> = cases
        .iter()
        .zip(&runs)
        .map(|((_, s, _), r)| case_json(s, &r.answers))
        .collect();
    let golden = venv_python::run_script(
        &python,
        "golden/questplus_golden.py",
        "questplus_golden",
        &Value::from(input),
    );
    for (((name, s, _), r), g) in cases
        .iter()
        .zip(&runs)
        .zip(golden["cases"].as_array().unwrap())
    {
        let levels = floats(&g["levels"]);
        assert_eq!(levels.len(), r.levels.len(), "{name}");
        for (i, (a, b)) in r.levels.iter().zip(&levels).enumerate() {
            assert!(
                (a - b).abs() <= 1e-12 * a.abs(),
                "{name}: trial {i}: the engine chose {a}, questplus {b}"
            );
        }
        for (i, (mine, theirs)) in r
            .posteriors
            .iter()
            .zip(g["posteriors"].as_array().unwrap())
            .enumerate()
        {
            let theirs = floats(theirs);
            assert_eq!(mine.len(), theirs.len(), "{name}");
            let worst = mine
                .iter()
                .zip(&theirs)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                worst <= POSTERIOR_TOL,
                "{name}: trial {i}: posteriors differ by {worst}"
            );
        }
        let t = r.engine.threshold();
        let est = &g["estimate"];
        for (what, mine, theirs) in [
            ("threshold", t.mean, est["threshold"].as_f64().unwrap()),
            (
                "slope",
                r.engine.slope().mean,
                est["slope"].as_f64().unwrap(),
            ),
            (
                "lapse",
                r.engine.lapse().mean,
                est["lapse_rate"].as_f64().unwrap(),
            ),
        ] {
            assert!(
                (mine - theirs).abs() <= 1e-9 * theirs.abs().max(1e-3),
                "{name}: {what} {mine} vs questplus {theirs}"
            );
        }
        let marginal = floats(&g["threshold_marginal"]);
        for (a, b) in r.engine.threshold_marginal().iter().zip(&marginal) {
            assert!((a - b).abs() <= POSTERIOR_TOL, "{name}: threshold marginal");
        }
        assert_eq!(marginal.len(), s.thresholds.len());
    }
}
