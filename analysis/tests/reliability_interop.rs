//! Inter-rater reliability against the outside tools: the six ICCs with their F tests and
//! 95 % CIs against pingouin 0.7.0 (`intraclass_corr`, nan_policy="omit"), and Krippendorff's
//! α (interval and ordinal) against the `krippendorff` package 0.9.0, on data sets simulated
//! by a seeded generator over several seeds (integer scales with ties, repeats, missing
//! subject-condition pairs, continuous scores, signed differences) and on the simulated
//! sessions of three examples (`tests/data/reliability_examples.json`: `study simulate
//! examples/{mos,dscqs,acr-hr}.toml --subjects 8 --seed 3`, the test and hidden-repeat trials,
//! DSCQS as reference − test differences). The expected values come from
//! scripts/reference/reliability_reference.py at test time.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

use analysis::reliability::{self, Metric};
use analysis::{Confidence, Rating};
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use serde_json::{Value, json};

/// How a generated data set looks.
#[derive(Clone, Copy)]
enum Kind {
    /// Integer 1-5 scores, every subject rates every condition twice.
    CompleteIntegers,
    /// Integer 1-5 scores, 1-3 repeats, some subject-condition pairs missing.
    MissingIntegers,
    /// 0-100 scores to one decimal, some pairs missing.
    Continuous,
    /// Signed differences (DSCQS reference − test) on a 0-100 scale, integers.
    Differences,
}

/// A seeded panel: condition quality + subject bias + noise, shaped by `kind`.
fn generate(kind: Kind, seed: u64) -> Vec<Rating> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (subjects, conditions) = match kind {
        Kind::CompleteIntegers => (7, 10),
        Kind::MissingIntegers => (9, 14),
        Kind::Continuous => (12, 9),
        Kind::Differences => (8, 11),
    };
    let quality: Vec<f64> = (0..conditions)
        .map(|_| rng.random_range(0.0..1.0))
        .collect();
    let mut out = Vec::new();
    for s in 0..subjects {
        let bias: f64 = rng.random_range(-0.15..0.15);
        for (c, q) in quality.iter().enumerate() {
            let missing = match kind {
                Kind::CompleteIntegers => false,
                // The first four conditions are rated by everyone, so pingouin keeps targets.
                _ => c >= 4 && rng.random_range(0.0..1.0) < 0.12,
            };
            if missing {
                continue;
            }
            let repeats = match kind {
                Kind::CompleteIntegers => 2,
                Kind::MissingIntegers => rng.random_range(1..=3),
                _ => 1,
            };
            for _ in 0..repeats {
                let noise: f64 = rng.random_range(-0.25..0.25);
                let x: f64 = (q + bias + noise).clamp(0.0, 1.0);
                let score = match kind {
                    Kind::CompleteIntegers | Kind::MissingIntegers => (1.0 + 4.0 * x).round(),
                    Kind::Continuous => (1000.0 * x).round() / 10.0,
                    Kind::Differences => (100.0 * x - 30.0).round(),
                };
                out.push(Rating {
                    subject: s,
                    condition: c as u32,
                    score,
                });
            }
        }
    }
    out
}

/// The example data sets of `tests/data/reliability_examples.json`.
fn examples() -> Vec<(String, Vec<Rating>)> {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/reliability_examples.json"),
    )
    .unwrap();
    let v: Value = serde_json::from_str(&text).unwrap();
    v.as_object()
        .unwrap()
        .iter()
        .map(|(name, rows)| {
            let ratings = rows
                .as_array()
                .unwrap()
                .iter()
                .map(|r| Rating {
                    subject: r[0].as_u64().unwrap() as u32,
                    condition: r[1].as_u64().unwrap() as u32,
                    score: r[2].as_f64().unwrap(),
                })
                .collect();
            (name.clone(), ratings)
        })
        .collect()
}

fn close(ours: f64, theirs: f64, rel: f64, what: &str) {
    let tol = rel * theirs.abs().max(1e-300) + 1e-13;
    assert!(
        (ours - theirs).abs() <= tol,
        "{what}: ours {ours:.15e}, reference {theirs:.15e}"
    );
}

/// Every data set: seeds 1-4 of each generated kind and the three examples.
fn data_sets() -> Vec<(String, Vec<Rating>)> {
    let kinds = [
        ("complete integers", Kind::CompleteIntegers),
        ("missing integers", Kind::MissingIntegers),
        ("continuous", Kind::Continuous),
        ("differences", Kind::Differences),
    ];
    let mut sets = Vec::new();
    for (name, kind) in kinds {
        for seed in 1..=4 {
            sets.push((format!("{name}, seed {seed}"), generate(kind, seed)));
        }
    }
    sets.extend(examples());
    sets
}

#[test]
fn icc_and_alpha_match_pingouin_and_krippendorff() {
    let Some(python) = venv_python::STATS.python("pingouin", "reliability interop test") else {
        return;
    };
    let sets = data_sets();
    let cases: Vec<Value> = sets
        .iter()
        .map(|(_, ratings)| {
            json!({"ratings": ratings.iter().map(|r| json!([r.subject, r.condition, r.score])).collect::<Vec<_>>()})
        })
        .collect();
    let expected = venv_python::run_script(
        &python,
        "reference/reliability_reference.py",
        "reliability_interop",
        &Value::Array(cases),
    );
    let mut incomplete = 0;
    for ((name, ratings), want) in sets.iter().zip(expected.as_array().unwrap()) {
        let ours = reliability::analyze(ratings, Confidence::default()).unwrap();
        assert_eq!(
            ours.complete_conditions as u64,
            want["complete"].as_u64().unwrap(),
            "{name}: targets rated by every subject"
        );
        if ours.complete_conditions < ours.conditions {
            incomplete += 1;
        }
        let icc = ours.icc.as_ref().expect("an ICC");
        for (form, w) in icc.forms.iter().zip(want["icc"].as_array().unwrap()) {
            let what = |field: &str| format!("{name}: {} {field}", form.name);
            assert_eq!(form.mcgraw_wong, w["type"].as_str().unwrap(), "{name}");
            close(form.icc, w["icc"].as_f64().unwrap(), 1e-10, &what("ICC"));
            close(form.f, w["f"].as_f64().unwrap(), 1e-10, &what("F"));
            close(form.df1, w["df1"].as_f64().unwrap(), 0.0, &what("df1"));
            close(form.df2, w["df2"].as_f64().unwrap(), 0.0, &what("df2"));
            close(form.p, w["p"].as_f64().unwrap(), 1e-8, &what("p"));
            close(
                form.lower,
                w["lower"].as_f64().unwrap(),
                1e-8,
                &what("CI lower"),
            );
            close(
                form.upper,
                w["upper"].as_f64().unwrap(),
                1e-8,
                &what("CI upper"),
            );
        }
        let alpha = |m: Option<f64>| m.expect("α defined");
        close(
            alpha(ours.alpha_interval),
            want["alpha_interval"].as_f64().unwrap(),
            1e-10,
            &format!("{name}: interval α"),
        );
        close(
            alpha(ours.alpha_ordinal),
            want["alpha_ordinal"].as_f64().unwrap(),
            1e-10,
            &format!("{name}: ordinal α"),
        );
    }
    assert!(
        incomplete >= 8,
        "the missing-value sets drop targets ({incomplete})"
    );
}

#[test]
fn krippendorff_worked_example() {
    // Krippendorff (2011), the example the `krippendorff` package's docs print: interval
    // 0.810845 and (for the second data set) ordinal 0.815.
    let nan = f64::NAN;
    let coders = [
        [
            nan, nan, nan, nan, nan, 3., 4., 1., 2., 1., 1., 3., 3., nan, 3.,
        ],
        [
            1., nan, 2., 1., 3., 3., 4., 3., nan, nan, nan, nan, nan, nan, nan,
        ],
        [
            nan, nan, 2., 1., 3., 4., 4., nan, 2., 1., 1., 3., 3., nan, 4.,
        ],
    ];
    let units: Vec<Vec<f64>> = (0..15)
        .map(|u| {
            coders
                .iter()
                .map(|c| c[u])
                .filter(|v| !v.is_nan())
                .collect()
        })
        .collect();
    let a = reliability::krippendorff_alpha(&units, Metric::Interval).unwrap();
    assert!((a - 0.810_845).abs() < 5e-7, "{a}");
    let coders = [
        [1., 2., 3., 3., 2., 1., 4., 1., 2., nan, nan, nan],
        [1., 2., 3., 3., 2., 2., 4., 1., 2., 5., nan, 3.],
        [nan, 3., 3., 3., 2., 3., 4., 2., 2., 5., 1., nan],
        [1., 2., 3., 3., 2., 4., 4., 1., 2., 5., 1., nan],
    ];
    let units: Vec<Vec<f64>> = (0..12)
        .map(|u| {
            coders
                .iter()
                .map(|c| c[u])
                .filter(|v| !v.is_nan())
                .collect()
        })
        .collect();
    let a = reliability::krippendorff_alpha(&units, Metric::Ordinal).unwrap();
    assert!((a - 0.815).abs() < 5e-4, "{a}");
}

#[test]
fn degenerate_panels_give_none_not_nan() {
    let r = |subject, condition, score| Rating {
        subject,
        condition,
        score,
    };
    // One subject: no ICC, no α (no condition has two raters).
    let one = [r(0, 0, 3.0), r(0, 1, 4.0), r(0, 2, 5.0)];
    let rel = reliability::analyze(&one, Confidence::default()).unwrap();
    assert!(rel.icc.is_none());
    assert!(rel.alpha_interval.is_none() && rel.alpha_ordinal.is_none());
    // Everyone gives 3 to everything: α has no expected disagreement.
    let flat: Vec<Rating> = (0..4)
        .flat_map(|s| (0..5).map(move |c| r(s, c, 3.0)))
        .collect();
    let rel = reliability::analyze(&flat, Confidence::default()).unwrap();
    assert!(rel.alpha_interval.is_none() && rel.alpha_ordinal.is_none());
    // No ratings: no reliability at all.
    assert!(reliability::analyze(&[], Confidence::default()).is_none());
}
