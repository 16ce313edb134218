//! The Bayesian psychometric fit (`analysis::bayesian`) against psignifit 4 from PyPI
//! (issue 24): on the same 2AFC data `scripts/golden/psignifit_golden.py` fits psignifit 4.3
//! with its defaults for a 2AFC experiment, and the threshold, the width, the lapse rate and
//! the overdispersion, their posterior means and 95 % credible intervals, must agree.
//!
//! Both evaluate the same posterior on the same two grids, so they differ only by floating-
//! point rounding (and scipy's special functions against statrs'): the tolerance is 1e-6 of
//! the fitted quantity's scale (the stimulus range for threshold and width, 1 for λ and η).
//! Cases: a full method-of-constant-stimuli data set (logistic), one subject's QUEST+ track on
//! `examples/quest.toml`'s levels (Weibull, psignifit on ln level), four tracks that tested
//! only two levels (Weibull, logistic, normal: the width prior's fall-offs overlap there) and a
//! normal fit of data with more scatter than a binomial's.
//!
//! The Python is `$BAYES_PYTHON` (`scripts/test` points it at `target/bayes-env`), or that
//! venv itself; under `CI` a missing interpreter or package fails the test, elsewhere it
//! skips.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use analysis::Confidence;
use analysis::bayesian::{BayesFit, Sigmoid, fit};
use analysis::psychometric::GroupedTrials;
use serde_json::{Value, json};

const TOL: f64 = 1e-6;

#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

fn python() -> Option<std::path::PathBuf> {
    venv_python::BAYES.python("psignifit", "psignifit interop test")
}

fn close(name: &str, what: &str, mine: f64, theirs: f64, scale: f64) {
    assert!(
        (mine - theirs).abs() <= TOL * scale,
        "{name}: {what}: {mine} here, {theirs} in psignifit (tolerance {})",
        TOL * scale
    );
}

/// (name, sigmoid, blocks of (level, trials, correct)).
type Case = (&'static str, Sigmoid, Vec<(f64, u32, u32)>);

fn cases() -> Vec<Case> {
    vec![
        (
            "constant stimuli, logistic",
            Sigmoid::Logistic,
            vec![
                (-2.0, 40, 22),
                (-1.0, 40, 24),
                (-0.5, 40, 27),
                (0.0, 40, 30),
                (0.5, 40, 33),
                (1.0, 40, 36),
                (2.0, 40, 39),
            ],
        ),
        (
            "a QUEST+ track, Weibull",
            Sigmoid::Weibull,
            vec![
                (0.004, 2, 1),
                (0.01, 24, 17),
                (0.016, 10, 9),
                (0.022, 3, 3),
                (0.04, 1, 1),
            ],
        ),
        // Tracks that tested only two levels (12 of 33 QUEST+ fits of the examples did): the
        // smallest gap is the whole range, the width prior's two fall-offs overlap and
        // psignifit keeps the falling one (issue 39).
        (
            "two levels, a QUEST+ track, Weibull",
            Sigmoid::Weibull,
            vec![(0.01, 30, 22), (0.016, 10, 9)],
        ),
        (
            "two levels, far apart, Weibull",
            Sigmoid::Weibull,
            vec![(0.004, 6, 4), (0.04, 14, 14)],
        ),
        (
            "two levels, logistic",
            Sigmoid::Logistic,
            vec![(1.0, 20, 12), (2.0, 20, 17)],
        ),
        (
            "two levels, all correct at the top, normal",
            Sigmoid::Normal,
            vec![(0.022, 25, 15), (0.028, 15, 15)],
        ),
        (
            "overdispersed, normal",
            Sigmoid::Normal,
            vec![
                (1.0, 30, 14),
                (2.0, 30, 25),
                (3.0, 30, 16),
                (4.0, 30, 29),
                (5.0, 30, 23),
                (6.0, 30, 30),
            ],
        ),
    ]
}

#[test]
fn posterior_means_and_intervals_equal_psignifit() {
    let Some(python) = python() else { return };
    let cases = cases();
    let input: Vec<Value> = cases
        .iter()
        .map(|(_, s, d)| {
            json!({
                "sigmoid": match s {
                    Sigmoid::Normal => "norm",
                    Sigmoid::Logistic => "logistic",
                    Sigmoid::Weibull => "weibull",
                },
                "confidence": 0.95,
                "data": d.iter().map(|&(x, n, k)| json!([x, k, n])).collect::<Vec<_>>(),
            })
        })
        .collect();
    let golden = venv_python::run_script(
        &python,
        "golden/psignifit_golden.py",
        "psignifit_interop",
        &Value::from(input),
    );
    for ((name, sigmoid, data), g) in cases.iter().zip(golden["cases"].as_array().unwrap()) {
        let f: BayesFit = fit(
            &GroupedTrials {
                levels: data.clone(),
            },
            *sigmoid,
            Confidence::default(),
        )
        .unwrap();
        let ln = |v: f64| {
            if *sigmoid == Sigmoid::Weibull {
                v.ln()
            } else {
                v
            }
        };
        let xs: Vec<f64> = data.iter().map(|d| ln(d.0)).collect();
        let range = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - xs.iter().copied().fold(f64::INFINITY, f64::min);
        let m = &g["mean"];
        let iv = |p: &str, i: usize| g["interval"][p][i].as_f64().unwrap();
        for (what, est, key, scale, log) in [
            ("threshold", f.threshold, "threshold", range, true),
            ("width", f.width, "width", range, false),
            ("lapse", f.lapse, "lambda", 1.0, false),
            ("eta", f.eta, "eta", 1.0, false),
        ] {
            let back = |v: f64| if log { ln(v) } else { v };
            close(
                name,
                &format!("{what} mean"),
                back(est.mean),
                m[key].as_f64().unwrap(),
                scale,
            );
            close(
                name,
                &format!("{what} lower"),
                back(est.lower),
                iv(key, 0),
                scale,
            );
            close(
                name,
                &format!("{what} upper"),
                back(est.upper),
                iv(key, 1),
                scale,
            );
        }
    }
}
