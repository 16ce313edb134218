//! Issue 18, item 6: a sureal export that the real tool reads unchanged. The dataset file that
//! `study report` writes (`analysis::export::SurealDataset`) is run through Netflix sureal
//! (from PyPI) by `scripts/reference/sureal_reference.py`: `MosModel`, `SubjrejMosModel`,
//! `MaximumLikelihoodEstimationModel` and `DmosModel`, on a MOS study with hidden references
//! and hidden repeats (subjects repeat different conditions a different number of times) and
//! on a DSCQS study, and their MOS and DMOS are compared with the report's.
//!
//! What each side computes: sureal's `MosModel` averages every rating of a stimulus, a
//! subject's repeats pooled with everyone's (a subject who rated it three times counts three
//! times); `DmosModel` is that MOS + `ref_score` − the same MOS of the content's reference
//! entry. The report's MOS table and its DSCQS DMOS (mean over subjects of each subject's mean
//! reference − test difference, `dmos::dscqs_dmos`) weigh subjects, not ratings, where a
//! subject's repeats are averaged first. So wherever every subject rated a condition equally
//! often the two must agree exactly (sureal's DSCQS DMOS being `ref_score` − the report's);
//! elsewhere sureal is checked against its own definition, computed here, and the report's
//! MOS against the mean of subject means (and shown to differ from the pooled mean there).
//!
//! The Python is `$SUREAL_PYTHON`, which `scripts/test` points at the venv it makes
//! (`target/sureal-env`, pins in `scripts/reference/sureal-requirements.txt`), or without the
//! variable that venv itself. Under `CI` a missing interpreter or sureal fails the tests;
//! elsewhere they skip with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use analysis::export::SurealDataset;
use analysis::study::{ReportOptions, StudyAnalysis, StudyData, analyze};
use analysis::synthetic::standard_normal;
use analysis::{ConditionInfo, DscqsPair, Rating};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;

/// Agreement asked of two means of the same scores summed in a different order.
const TOL: f64 = 1e-9;

/// The Python that has sureal: `$SUREAL_PYTHON`, else the venv scripts/test makes
/// (`target/sureal-env`), or `None` (outside CI only) to skip.
fn python() -> Option<PathBuf> {
    let ci = std::env::var_os("CI").is_some();
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/sureal-env/bin/python");
    let python = match std::env::var_os("SUREAL_PYTHON") {
        Some(p) => PathBuf::from(p),
        None if venv.exists() => venv,
        None if ci => panic!(
            "neither SUREAL_PYTHON nor {} is there: under CI the sureal interop tests need \
             the venv with sureal that scripts/test makes",
            venv.display()
        ),
        None => {
            eprintln!(
                "sureal interop skipped: no SUREAL_PYTHON and no target/sureal-env (scripts/test \
                 makes it: a venv with sureal from scripts/reference/sureal-requirements.txt)"
            );
            return None;
        }
    };
    let probe = Command::new(&python)
        .args(["-c", "import sureal.subjective_model"])
        .output();
    match probe {
        Ok(o) if o.status.success() => Some(python),
        Ok(o) if ci => panic!(
            "{} cannot import sureal:\n{}",
            python.display(),
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) if ci => panic!("cannot run {}: {e}", python.display()),
        _ => {
            eprintln!("sureal interop skipped: {} lacks sureal", python.display());
            None
        }
    }
}

/// Writes the export to a fresh folder and runs the reference script on it.
fn run_sureal(python: &Path, tag: &str, dataset: &SurealDataset<'_>, dmos: bool) -> Value {
    let dir = std::env::temp_dir().join(format!("sureal_interop_{}_{tag}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("sureal_dataset.py");
    std::fs::write(&file, dataset.to_python()).unwrap();
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/reference/sureal_reference.py");
    let mut cmd = Command::new(python);
    cmd.arg(&script).arg(&file);
    if dmos {
        cmd.arg("--dmos");
    }
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "sureal_reference.py failed on {}:\n{}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "sureal_reference.py printed no JSON ({e}):\n{}",
            String::from_utf8_lossy(&out.stdout)
        )
    });
    for (name, result) in v["models"].as_object().unwrap() {
        assert!(
            result.get("error").is_none(),
            "sureal's {name} failed on {}:\n{}",
            file.display(),
            result["error"].as_str().unwrap_or_default()
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
    v
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap_or(f64::NAN))
        .collect()
}

fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().to_owned())
        .collect()
}

fn u32s(v: &Value) -> Vec<u32> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| u32::try_from(x.as_u64().unwrap()).unwrap())
        .collect()
}

/// Subject names in an order that sorts differently from their ids, as sureal sorts them.
fn subject_names(n: usize) -> Vec<String> {
    [
        "S034", "S005", "S021", "S012", "S003", "S055", "S008", "S040", "S013", "S041",
    ][..n]
        .iter()
        .map(|s| (*s).to_owned())
        .collect()
}

/// Scores of each condition by subject, in order.
fn by_condition(
    scores: impl Iterator<Item = (u32, u32, f64)>,
) -> BTreeMap<u32, BTreeMap<u32, Vec<f64>>> {
    let mut m: BTreeMap<u32, BTreeMap<u32, Vec<f64>>> = BTreeMap::new();
    for (condition, subject, score) in scores {
        m.entry(condition)
            .or_default()
            .entry(subject)
            .or_default()
            .push(score);
    }
    m
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// sureal's mean: every rating of every subject pooled.
fn pooled(by_subject: &BTreeMap<u32, Vec<f64>>) -> f64 {
    let all: Vec<f64> = by_subject.values().flatten().copied().collect();
    mean(&all)
}

/// Each subject's repeats averaged first, then the mean over subjects.
fn per_subject_first(by_subject: &BTreeMap<u32, Vec<f64>>) -> f64 {
    let means: Vec<f64> = by_subject.values().map(|v| mean(v)).collect();
    mean(&means)
}

/// Every subject who rated the condition rated it equally often.
fn balanced(by_subject: &BTreeMap<u32, Vec<f64>>) -> bool {
    by_subject
        .values()
        .map(Vec::len)
        .collect::<BTreeSet<_>>()
        .len()
        == 1
}

fn conditions(with_references: bool) -> Vec<ConditionInfo> {
    let mut out = Vec::new();
    for clip in ["2_2", "49_14"] {
        for codec in ["perceptual", "wavelet"] {
            for cr in [20.0, 30.0, 40.0] {
                out.push(ConditionInfo {
                    id: out.len() as u32,
                    codec: codec.to_owned(),
                    params: BTreeMap::new(),
                    clip: clip.to_owned(),
                    compression_ratio: Some(cr),
                });
            }
        }
        if with_references {
            out.push(ConditionInfo {
                id: out.len() as u32,
                codec: "reference".to_owned(),
                params: BTreeMap::new(),
                clip: clip.to_owned(),
                compression_ratio: None,
            });
        }
    }
    out
}

fn truth(c: &ConditionInfo) -> f64 {
    let loss = if c.codec == "wavelet" { 0.6 } else { 0.35 };
    c.compression_ratio
        .map_or(5.0, |cr| (5.0 - loss * (cr - 10.0) / 10.0).clamp(1.0, 5.0))
}

/// The conditions a subject repeats: every subject repeats condition 1 once (balanced, with
/// repeats), and subject `s` repeats `(s + 1) % modulus` others picked at random, subject 0
/// its one twice (three ratings).
fn repeats(rng: &mut ChaCha8Rng, subject: u32, modulus: u32, n: u32) -> Vec<u32> {
    let mut out = vec![1];
    for _ in 0..(subject + 1) % modulus {
        let c = loop {
            let c = rng.random_range(0..n);
            if c != 1 {
                break c;
            }
        };
        out.push(c);
        if subject == 0 {
            out.push(c);
        }
    }
    out
}

/// A MOS (ACR-HR) study: 10 subjects, 12 test conditions and a hidden reference per clip,
/// scores 1-5 in steps of 0.5; hidden repeats of different number per subject; subject 4
/// answers 1 or 5 at random; subject 9 never rated condition 5.
fn mos_study() -> (StudyData, Vec<String>) {
    let names = subject_names(10);
    let conditions = conditions(true);
    let n = conditions.len() as u32;
    let mut rng = ChaCha8Rng::seed_from_u64(186);
    let mut ratings = Vec::new();
    for subject in 0..names.len() as u32 {
        let bias = 0.2 * standard_normal(&mut rng);
        let mut shown: Vec<u32> = (0..n).filter(|&c| !(subject == 9 && c == 5)).collect();
        shown.extend(repeats(&mut rng, subject, 4, n - 2));
        for c in shown {
            let raw = if subject == 4 {
                if rng.random::<bool>() { 1.0 } else { 5.0 }
            } else {
                truth(&conditions[c as usize]) + bias + 0.45 * standard_normal(&mut rng)
            };
            ratings.push(Rating {
                subject,
                condition: c,
                score: ((raw * 2.0).round() / 2.0).clamp(1.0, 5.0),
            });
        }
    }
    let mut data = StudyData {
        conditions,
        ratings,
        ..StudyData::default()
    };
    for c in &data.conditions {
        if c.compression_ratio.is_some() {
            let reference = data
                .conditions
                .iter()
                .find(|r| r.clip == c.clip && r.compression_ratio.is_none())
                .unwrap();
            data.reference_of.insert(c.id, reference.id);
        }
    }
    (data, names)
}

/// A DSCQS study: 9 subjects, 12 conditions, scores 0-100 in whole points; each subject sees
/// every condition, condition 1 twice, and `(s + 1) % 3` others once more.
fn dscqs_study() -> (StudyData, Vec<String>) {
    let names = subject_names(9);
    let conditions = conditions(false);
    let n = conditions.len() as u32;
    let mut rng = ChaCha8Rng::seed_from_u64(1861);
    let mut dscqs = Vec::new();
    let score = |x: f64| x.round().clamp(0.0, 100.0);
    for subject in 0..names.len() as u32 {
        let bias = 4.0 * standard_normal(&mut rng);
        let mut shown: Vec<u32> = (0..n).collect();
        shown.extend(repeats(&mut rng, subject, 3, n));
        for c in shown {
            let t = 20.0 * truth(&conditions[c as usize]);
            dscqs.push(DscqsPair {
                subject,
                condition: c,
                reference_score: score(92.0 + bias + 5.0 * standard_normal(&mut rng)),
                test_score: score(t + bias + 8.0 * standard_normal(&mut rng)),
            });
        }
    }
    // As from_results: the test scores also fill the MOS table.
    let ratings = dscqs
        .iter()
        .map(|p| Rating {
            subject: p.subject,
            condition: p.condition,
            score: p.test_score,
        })
        .collect();
    (
        StudyData {
            conditions,
            ratings,
            dscqs,
            ..StudyData::default()
        },
        names,
    )
}

fn options() -> ReportOptions {
    ReportOptions {
        figures: false,
        ..ReportOptions::default()
    }
}

/// The MLE model ran and gave a finite bias and inconsistency for every subject of the export,
/// under the export's names, and a finite quality for every entry.
fn check_mle(v: &Value, names: &[String], entries: usize) -> Vec<f64> {
    let mle = &v["models"]["MaximumLikelihoodEstimationModel"];
    let mut sorted = names.to_vec();
    sorted.sort();
    assert_eq!(strings(&mle["observers"]), sorted);
    for key in ["observer_bias", "observer_inconsistency"] {
        let x = floats(&mle[key]);
        assert_eq!(x.len(), names.len(), "{key}");
        assert!(x.iter().all(|x| x.is_finite()), "{key}: {x:?}");
    }
    let q = floats(&mle["quality_scores"]);
    assert_eq!(q.len(), entries);
    assert!(q.iter().all(|x| x.is_finite()), "MLE quality: {q:?}");
    eprintln!(
        "MLE: bias {:?}, inconsistency {:?}",
        floats(&mle["observer_bias"]),
        floats(&mle["observer_inconsistency"])
    );
    q
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let (ma, mb) = (mean(a), mean(b));
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

/// `SubjrejMosModel`: sureal's MOS over the subjects it kept; prints both rejections.
fn check_subjrej(
    v: &Value,
    names: &[String],
    scores: &BTreeMap<u32, BTreeMap<u32, Vec<f64>>>,
    assets: &[u32],
    report: &StudyAnalysis,
) {
    let mut sorted = names.to_vec();
    sorted.sort();
    let sr = &v["models"]["SubjrejMosModel"];
    let rejected: Vec<bool> = sr["observer_rejected"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_bool().unwrap())
        .collect();
    let rejected_names: BTreeSet<&str> = sorted
        .iter()
        .zip(&rejected)
        .filter(|(_, r)| **r)
        .map(|(n, _)| n.as_str())
        .collect();
    let kept: BTreeSet<u32> = (0..names.len() as u32)
        .filter(|&s| !rejected_names.contains(names[s as usize].as_str()))
        .collect();
    for (&c, &m) in assets.iter().zip(&floats(&sr["quality_scores"])) {
        let s: BTreeMap<u32, Vec<f64>> = scores[&c]
            .iter()
            .filter(|(s, _)| kept.contains(s))
            .map(|(s, v)| (*s, v.clone()))
            .collect();
        let expected = pooled(&s);
        assert!(
            (m - expected).abs() < TOL,
            "condition {c}: sureal SR-MOS {m}, pooled mean of the kept subjects {expected}"
        );
    }
    let ours: BTreeSet<&str> = report
        .screening
        .as_ref()
        .map(|s| {
            s.rejected()
                .iter()
                .map(|&i| names[i as usize].as_str())
                .collect()
        })
        .unwrap_or_default();
    eprintln!("rejected: sureal {rejected_names:?}, report (BT.500 per presentation) {ours:?}");
}

/// `DmosModel` finds the hidden references (same path as the clip's reference).
fn check_hidden_reference_dmos(
    v: &Value,
    data: &StudyData,
    scores: &BTreeMap<u32, BTreeMap<u32, Vec<f64>>>,
    assets: &[u32],
) {
    let dmos = floats(&v["models"]["DmosModel"]["quality_scores"]);
    for (&c, &d) in assets.iter().zip(&dmos) {
        let info = &data.conditions[c as usize];
        let reference = data
            .conditions
            .iter()
            .find(|r| r.clip == info.clip && r.compression_ratio.is_none())
            .unwrap();
        let expected = pooled(&scores[&c]) + 5.0 - pooled(&scores[&reference.id]);
        assert!(
            (d - expected).abs() < TOL,
            "condition {c}: sureal DMOS {d}, MOS + 5 − reference MOS {expected}"
        );
    }
}

#[test]
fn sureal_reads_a_mos_study_with_hidden_repeats_and_references() {
    let Some(python) = python() else {
        return;
    };
    let (data, names) = mos_study();
    let dataset = SurealDataset {
        name: "mos_hidden_repeats",
        subjects: &names,
        ratings: &data.ratings,
        dscqs: &data.dscqs,
        conditions: &data.conditions,
        ref_score: 5.0,
    };
    let v = run_sureal(&python, "mos", &dataset, true);
    eprintln!("sureal versions: {}", v["versions"]);
    let assets = u32s(&v["asset_ids"]);
    assert_eq!(
        assets,
        data.conditions.iter().map(|c| c.id).collect::<Vec<_>>(),
        "one entry per condition, asset id = condition id"
    );
    let scores = by_condition(
        data.ratings
            .iter()
            .map(|r| (r.condition, r.subject, r.score)),
    );
    assert!(
        scores.values().filter(|s| !balanced(s)).count() >= 3,
        "the data must have conditions that subjects repeated unequally"
    );
    let report = analyze(&data, &options()).unwrap();
    let report_mos: BTreeMap<u32, f64> = report
        .mos
        .iter()
        .map(|s| (s.condition, s.summary.mean))
        .collect();

    let mos = floats(&v["models"]["MosModel"]["quality_scores"]);
    let mut sorted = names.clone();
    sorted.sort();
    assert_eq!(strings(&v["models"]["MosModel"]["observers"]), sorted);
    let (mut worst_def, mut worst_report) = (0.0_f64, 0.0_f64);
    for (&c, &m) in assets.iter().zip(&mos) {
        let s = &scores[&c];
        let expected = pooled(s);
        assert!(
            (m - expected).abs() < TOL,
            "condition {c}: sureal MOS {m}, pooled mean of its ratings {expected}"
        );
        worst_def = worst_def.max((m - expected).abs());
        let r = report_mos[&c];
        if balanced(s) {
            assert!(
                (m - r).abs() < TOL,
                "condition {c} (balanced): sureal MOS {m}, report {r}"
            );
            worst_report = worst_report.max((m - r).abs());
        } else {
            let per_subject = per_subject_first(s);
            assert!(
                (r - per_subject).abs() < TOL,
                "condition {c}: report MOS {r} is not the mean of subject means {per_subject} \
                 (the pooled mean is {expected})"
            );
            eprintln!(
                "condition {c} (unequal repeats): sureal {m:.6}, report {r:.6}, mean of \
                 subject means {per_subject:.6}"
            );
        }
    }
    eprintln!(
        "MOS: sureal vs its definition max |diff| {worst_def:.3e}; vs the report where \
         balanced {worst_report:.3e}"
    );

    check_subjrej(&v, &names, &scores, &assets, &report);
    check_hidden_reference_dmos(&v, &data, &scores, &assets);
    let q = check_mle(&v, &names, assets.len());
    let r = pearson(&q, &mos);
    assert!(r > 0.9, "MLE quality vs MOS: r = {r}");
    check_report_mle(&v, &names, &assets, &report);
}

/// Agreement asked of the report's subject model with sureal's MLE: both run sureal's
/// iteration to the same stopping rule, so they differ by floating-point rounding.
const MLE_TOL: f64 = 1e-6;

/// The report's own maximum-likelihood subject model (`analysis::mle`) equals sureal's
/// `MaximumLikelihoodEstimationModel`: every subject's bias and inconsistency, every
/// stimulus's quality and every clip's ambiguity.
fn check_report_mle(v: &Value, names: &[String], assets: &[u32], report: &StudyAnalysis) {
    let mle = &v["models"]["MaximumLikelihoodEstimationModel"];
    let model = report
        .subject_model
        .as_ref()
        .expect("the report fits the subject model");
    let observers = strings(&mle["observers"]);
    let (bias, inconsistency) = (
        floats(&mle["observer_bias"]),
        floats(&mle["observer_inconsistency"]),
    );
    assert_eq!(model.subjects.len(), observers.len());
    let mut worst = 0.0_f64;
    for e in &model.subjects {
        let name = &names[e.subject as usize];
        let i = observers.iter().position(|o| o == name).unwrap();
        for (what, mine, theirs) in [
            ("bias", e.bias, bias[i]),
            ("inconsistency", e.inconsistency, inconsistency[i]),
        ] {
            assert!(
                (mine - theirs).abs() < MLE_TOL,
                "{name}: {what} {mine} in the report, {theirs} in sureal"
            );
            worst = worst.max((mine - theirs).abs());
        }
    }
    let quality = floats(&mle["quality_scores"]);
    for (asset, theirs) in assets.iter().zip(&quality) {
        let (_, mine, _) = model.quality.iter().find(|q| q.0 == *asset).unwrap();
        assert!(
            (mine - theirs).abs() < MLE_TOL,
            "condition {asset}: quality {mine} in the report, {theirs} in sureal"
        );
        worst = worst.max((mine - theirs).abs());
    }
    let ambiguity = floats(&mle["content_ambiguity"]);
    for ((clip, mine), theirs) in model.contents.iter().zip(&ambiguity) {
        assert!(
            (mine - theirs).abs() < MLE_TOL,
            "{clip}: ambiguity {mine} in the report, {theirs} in sureal"
        );
    }
    eprintln!(
        "subject model: report vs sureal max |diff| {worst:.3e} ({} passes)",
        model.passes
    );
}

#[test]
fn sureal_reads_a_dscqs_study_and_its_references() {
    let Some(python) = python() else {
        return;
    };
    let (data, names) = dscqs_study();
    let dataset = SurealDataset {
        name: "dscqs",
        subjects: &names,
        ratings: &data.ratings,
        dscqs: &data.dscqs,
        conditions: &data.conditions,
        ref_score: 100.0,
    };
    let v = run_sureal(&python, "dscqs", &dataset, true);
    let assets = u32s(&v["asset_ids"]);
    let contents = u32s(&v["content_ids"]);
    let n = data.conditions.len();
    assert_eq!(
        assets.len(),
        2 * n,
        "a test and a reference entry per condition"
    );
    let tests = by_condition(
        data.dscqs
            .iter()
            .map(|p| (p.condition, p.subject, p.test_score)),
    );
    let references = by_condition(
        data.dscqs
            .iter()
            .map(|p| (p.condition, p.subject, p.reference_score)),
    );
    assert!(tests.values().filter(|s| !balanced(s)).count() >= 3);
    // The reference entry of each condition is the other entry of its content.
    let mut condition_of_content = BTreeMap::new();
    for (&a, &k) in assets.iter().zip(&contents) {
        if (a as usize) < n {
            assert!(condition_of_content.insert(k, a).is_none());
        }
    }
    let report = analyze(&data, &options()).unwrap();
    let report_mos: BTreeMap<u32, f64> = report
        .mos
        .iter()
        .map(|s| (s.condition, s.summary.mean))
        .collect();
    let report_dmos: BTreeMap<u32, f64> = report
        .dmos
        .iter()
        .map(|s| (s.condition, s.summary.mean))
        .collect();

    let mos = floats(&v["models"]["MosModel"]["quality_scores"]);
    let dmos = floats(&v["models"]["DmosModel"]["quality_scores"]);
    let (mut worst_mos, mut worst_dmos) = (0.0_f64, 0.0_f64);
    for ((&a, &k), (&m, &d)) in assets.iter().zip(&contents).zip(mos.iter().zip(&dmos)) {
        let c = condition_of_content[&k];
        if a as usize >= n {
            // The reference of condition c's pairs: its DMOS is ref_score by definition.
            let expected = pooled(&references[&c]);
            assert!(
                (m - expected).abs() < TOL,
                "reference of {c}: {m} vs {expected}"
            );
            assert!((d - 100.0).abs() < TOL, "reference of {c}: DMOS {d}");
            continue;
        }
        let (t, r) = (&tests[&c], &references[&c]);
        assert!((m - pooled(t)).abs() < TOL, "condition {c}: MOS {m}");
        let expected = pooled(t) + 100.0 - pooled(r);
        assert!(
            (d - expected).abs() < TOL,
            "condition {c}: sureal DMOS {d}, pooled test + 100 − pooled reference {expected}"
        );
        // The report's DSCQS DMOS is reference − test: sureal's is ref_score minus it.
        let ours = report_dmos[&c];
        if balanced(t) {
            assert!(
                (100.0 - d - ours).abs() < TOL,
                "condition {c} (balanced): 100 − sureal DMOS {}, report DMOS {ours}",
                100.0 - d
            );
            assert!((m - report_mos[&c]).abs() < TOL);
            worst_dmos = worst_dmos.max((100.0 - d - ours).abs());
            worst_mos = worst_mos.max((m - report_mos[&c]).abs());
        } else {
            eprintln!(
                "condition {c} (unequal repeats): 100 − sureal DMOS {:.6}, report DMOS {ours:.6}",
                100.0 - d
            );
        }
    }
    eprintln!("DSCQS, balanced conditions: MOS max |diff| {worst_mos:.3e}, DMOS {worst_dmos:.3e}");
    let sr = floats(&v["models"]["SubjrejMosModel"]["quality_scores"]);
    assert!(sr.iter().all(|x| x.is_finite()));
    check_mle(&v, &names, assets.len());
}
