//! Issue 24, item 1: the P.910 rating methods and the MUSHRA-style method end to end. The ACR-HR and DCR examples are
//! simulated (`study simulate`), reported (`study report`), and the report's MOS and ACR-HR
//! DMOS tables are compared cell for cell with `scripts/golden/rating_methods.py`, which reads
//! the same results folder with Python's csv module and computes the tables with NumPy and
//! SciPy (subject means, `ddof = 1`, `scipy.stats.t.ppf`), none of the project's code.
//!
//! The Python is `$SUREAL_PYTHON` (the venv `scripts/test` makes for sureal, which has NumPy
//! and SciPy at the pins of `scripts/reference/sureal-requirements.txt`), or without the
//! variable that venv itself. Under `CI` a missing interpreter fails the tests; elsewhere they
//! skip with a message.
//!
//! The pair comparison example is simulated and reported the same way, and the report's
//! Bradley-Terry scale values, CIs and win counts are compared with
//! `scripts/golden/pair_comparison.py`, which fits with choix (`ilsr_pairwise`, alpha = 0) in
//! `$BAYES_PYTHON` (pinned in `scripts/reference/bayes-requirements.txt`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;
#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::study_ok;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The Python with NumPy and SciPy, or `None` (outside CI only) to skip.
fn python() -> Option<PathBuf> {
    let ci = std::env::var_os("CI").is_some();
    let venv = repo().join("target/sureal-env/bin/python");
    let python = match std::env::var_os("SUREAL_PYTHON") {
        Some(p) => PathBuf::from(p),
        None if venv.exists() => venv,
        None if ci => panic!(
            "neither SUREAL_PYTHON nor {} is there: under CI these tests need the venv \
             scripts/test makes",
            venv.display()
        ),
        None => {
            eprintln!("rating methods golden skipped: no SUREAL_PYTHON and no target/sureal-env");
            return None;
        }
    };
    let probe = Command::new(&python)
        .args(["-c", "import numpy, scipy"])
        .output();
    match probe {
        Ok(o) if o.status.success() => Some(python),
        _ if ci => panic!("{} cannot import numpy and scipy", python.display()),
        _ => {
            eprintln!(
                "rating methods golden skipped: {} lacks scipy",
                python.display()
            );
            None
        }
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("rating-methods-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Simulates the study file `study` (an example's name, or a path) with `subjects` subjects
/// and `seed`, reports it, and returns the results folder and the report folder.
fn simulate_and_report(dir: &Path, study: &str, subjects: u32, seed: u64) -> (PathBuf, PathBuf) {
    let path = repo().join("examples").join(study);
    let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
    let results = dir.join(format!("results-{stem}-{seed}"));
    let report = dir.join(format!("report-{stem}-{seed}"));
    study_ok(&[
        "simulate".as_ref(),
        path.as_os_str(),
        "--subjects".as_ref(),
        subjects.to_string().as_ref(),
        "--seed".as_ref(),
        seed.to_string().as_ref(),
        "-o".as_ref(),
        results.as_os_str(),
    ]);
    study_ok(&[
        "report".as_ref(),
        results.as_os_str(),
        "--no-png".as_ref(),
        "-o".as_ref(),
        report.as_os_str(),
    ]);
    (results, report)
}

/// The golden script's rows for `results`: ("mos", "dmos") → CSV lines.
fn golden(python: &Path, results: &Path) -> serde_json::Value {
    run_golden(python, "rating_methods.py", results)
}

/// The data rows of a report table, as lines.
fn table_rows(report: &Path, name: &str) -> Vec<String> {
    let text = std::fs::read_to_string(report.join("tables").join(name)).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("Codec,Clip,CR,n,Mean,SD,CI ± (t),Lower,Upper"),
        "{name}"
    );
    let mut rows: Vec<String> = lines.map(str::to_owned).collect();
    rows.sort();
    rows
}

fn golden_rows(g: &serde_json::Value, key: &str) -> Vec<String> {
    let mut rows = golden_lines(g, key);
    rows.sort();
    rows
}

/// ACR-HR: two simulated panels of 12 subjects (hidden repeats make subjects rate some
/// conditions twice, so the per-subject averaging is exercised); the report's MOS of every
/// condition (the two hidden references included) and its DMOS = test − hidden reference + 5
/// of every test condition equal SciPy's, every printed digit.
#[test]
fn acr_hr_report_equals_scipy() {
    let Some(python) = python() else { return };
    let dir = scratch("acr-hr");
    for seed in [3, 8] {
        let (results, report) = simulate_and_report(&dir, "acr-hr.toml", 12, seed);
        let g = golden(&python, &results);
        let mos = table_rows(&report, "mos.csv");
        assert_eq!(mos.len(), 10, "8 tests and 2 hidden references");
        assert_eq!(mos, golden_rows(&g, "mos"), "seed {seed}: MOS");
        let dmos = table_rows(&report, "dmos_ci.csv");
        assert_eq!(dmos.len(), 8, "a DMOS per test condition");
        assert_eq!(dmos, golden_rows(&g, "dmos"), "seed {seed}: ACR-HR DMOS");
        // Every row is one subject's: n = subjects, though repeats were rated twice.
        assert!(dmos.iter().all(|r| r.split(',').nth(3) == Some("12")));
        let md = std::fs::read_to_string(report.join("report.md")).unwrap();
        assert!(md.contains("P.910 ACR-HR"), "the method is named");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// DCR: the report's mean impairment category per condition equals SciPy's; no DMOS (no
/// hidden reference in a DCR study).
#[test]
fn dcr_report_equals_scipy() {
    let Some(python) = python() else { return };
    let dir = scratch("dcr");
    let (results, report) = simulate_and_report(&dir, "dcr.toml", 10, 5);
    let g = golden(&python, &results);
    let mos = table_rows(&report, "mos.csv");
    assert_eq!(mos.len(), 8);
    assert_eq!(mos, golden_rows(&g, "mos"));
    assert!(g["dmos"].as_array().unwrap().is_empty());
    assert!(!report.join("tables/dmos_ci.csv").exists());
    let trials = results::trials::read_trials(&results.join("S001_s1/trials.csv")).unwrap();
    for r in &trials.records {
        assert_eq!(r.protocol, protocols::Protocol::Dcr);
        assert_eq!(r.trial.reference_position, protocols::Position::First);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The rows of a report table as CSV lines, after checking its header.
fn table_with_header(report: &Path, name: &str, header: &str) -> Vec<String> {
    let text = std::fs::read_to_string(report.join("tables").join(name)).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(header), "{name}");
    lines.map(str::to_owned).collect()
}

/// The golden script's rows of `key` as CSV lines, in its order.
fn golden_lines(g: &serde_json::Value, key: &str) -> Vec<String> {
    g[key]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_str().unwrap())
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect()
}

/// MUSHRA (BS.1534-3 adapted): simulated panels of the example, reported; the report's
/// post-screening of every assessor and its table of every stimulus over the assessors kept
/// (tests, hidden references, anchors) equal `scripts/golden/mushra.py` (csv, tomllib and
/// `scipy.stats.t`) row for row and cell for cell, in the same order. The anchor rule is
/// tried both ways: listed only (the example), and excluding (a copy of the study with the
/// anchor limit lowered so that assessors trip it). The example's training screen counts in
/// neither, and the Method section states it.
#[test]
fn mushra_report_equals_scipy() {
    let Some(python) = python() else { return };
    let dir = scratch("mushra");
    let example = std::fs::read_to_string(repo().join("examples/mushra.toml")).unwrap();
    let strict = example
        .replace(
            "stimuli = \"stimuli.json\"",
            &format!(
                "stimuli = {:?}",
                repo().join("examples/stimuli.json").canonicalize().unwrap()
            ),
        )
        .replace("anchor_above = 90", "anchor_above = 15")
        .replace("anchor_rule = \"report\"", "anchor_rule = \"exclude\"");
    std::fs::write(dir.join("mushra-strict.toml"), strict).unwrap();
    let mut excluded = 0;
    let mut by_anchor = 0;
    for (study, seed) in [
        (repo().join("examples/mushra.toml"), 2),
        (dir.join("mushra-strict.toml"), 5),
    ] {
        let (results, report) = simulate_and_report(&dir, study.to_str().unwrap(), 12, seed);
        let out = Command::new(&python)
            .arg(repo().join("scripts/golden/mushra.py"))
            .arg(&results)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let g: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let screening = table_with_header(
            &report,
            "mushra_screening.csv",
            "Subject,Screens,Hidden reference low,Anchor high,Excluded",
        );
        assert_eq!(screening.len(), 12);
        // Two test screens each: the example's training screen is not screened.
        assert!(
            screening.iter().all(|r| r.split(',').nth(1) == Some("2")),
            "{screening:?}"
        );
        assert_eq!(
            screening,
            golden_lines(&g, "screening"),
            "seed {seed}: screening"
        );
        excluded += screening.iter().filter(|r| r.contains(",yes: ")).count();
        by_anchor += screening
            .iter()
            .filter(|r| r.ends_with(",yes: anchor"))
            .count();
        let table = table_with_header(
            &report,
            "mushra.csv",
            "Stimulus,Clip,Role,n,Mean,SD,CI ± (t),Lower,Upper",
        );
        assert_eq!(table.len(), 10, "6 tests, 2 hidden references, 2 anchors");
        assert_eq!(
            table,
            golden_lines(&g, "conditions"),
            "seed {seed}: conditions"
        );
        let md = std::fs::read_to_string(report.join("report.md")).unwrap();
        assert!(md.contains("BS.1534-3"), "the post-screening is named");
        assert!(
            md.contains("1 training screen(s) first (BS.1534-3's training phase), not analysed"),
            "the Method section states the training"
        );
    }
    // The screening excluded someone, and the excluding anchor rule did too: both paths ran.
    assert!(
        excluded > by_anchor && by_anchor > 0,
        "{excluded} {by_anchor}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The report's `pc_scale.csv` rows and the golden script's agree: clip, codec, ratio, wins
/// (ties) and comparisons exactly, scale value, SE and bounds to 2e-6 (the table prints six
/// decimals; choix iterates to 1e-12, the Davidson reference to a gradient below 1e-9).
fn assert_pc_equal(report: &Path, g: &serde_json::Value, ties: bool) {
    let text = std::fs::read_to_string(report.join("tables/pc_scale.csv")).unwrap();
    let mut lines = text.lines();
    let (header, counts) = if ties {
        (
            "Clip,Codec,CR,Wins,Ties,Comparisons,Scale,SE,Lower,Upper",
            3..6,
        )
    } else {
        ("Clip,Codec,CR,Wins,Comparisons,Scale,SE,Lower,Upper", 3..5)
    };
    assert_eq!(lines.next(), Some(header));
    let ours: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let theirs = g["rows"].as_array().unwrap();
    assert_eq!(ours.len(), theirs.len());
    for (o, t) in ours.iter().zip(theirs) {
        let t = t.as_array().unwrap();
        assert_eq!(o.len(), t.len(), "{o:?} vs {t:?}");
        for k in 0..3 {
            assert_eq!(o[k], t[k].as_str().unwrap(), "{o:?} vs {t:?}");
        }
        for k in counts.clone() {
            assert_eq!(o[k], t[k].as_u64().unwrap().to_string(), "{o:?} vs {t:?}");
        }
        for k in counts.end..o.len() {
            let (a, b): (f64, f64) = (o[k].parse().unwrap(), t[k].as_f64().unwrap());
            assert!((a - b).abs() < 2e-6, "column {k}: {o:?} vs {t:?}");
        }
    }
}

/// The JSON that `scripts/golden/<script>` prints for the results folder `results` (and the
/// examples' manifest).
fn run_golden(python: &Path, script: &str, results: &Path) -> serde_json::Value {
    let out = Command::new(python)
        .arg(repo().join("scripts/golden").join(script))
        .arg(results)
        .arg(repo().join("examples/stimuli.json"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{script}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The report's square count table `tables/<name>.csv` (first column the row's name).
fn count_table(report: &Path, name: &str) -> Vec<Vec<u64>> {
    std::fs::read_to_string(report.join(format!("tables/{name}.csv")))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(1).map(|c| c.parse().unwrap()).collect())
        .collect()
}

/// Pair comparison (P.910 PC): two simulated panels of 16; every clip's fit and the pooled
/// one equal choix's maximum-likelihood Bradley-Terry scale (the same anchor), their Fisher
/// information intervals equal NumPy's, the win matrices equal the script's counts; and the
/// simulated Thurstone observer's clearly worst version (standard wavelet at 30:1, by far
/// the largest error) has the lowest scale value of its clip.
#[test]
fn pair_comparison_report_equals_choix() {
    let Some(python) = venv_python::BAYES.python("choix", "pair comparison golden") else {
        return;
    };
    let dir = scratch("pc");
    for seed in [3, 8] {
        let (results, report) = simulate_and_report(&dir, "pc.toml", 16, seed);
        let g = run_golden(&python, "pair_comparison.py", &results);
        assert_pc_equal(&report, &g, false);
        // Two clips of five conditions and the pool: fifteen rows, anchored at the originals.
        let rows = g["rows"].as_array().unwrap();
        assert_eq!(rows.len(), 15);
        for (k, clip) in ["march", "walk", "all"].iter().enumerate() {
            let group = &rows[5 * k..5 * k + 5];
            assert_eq!(group[0][0], *clip);
            assert_eq!(group[0][2], "ref", "the original is the anchor");
            let worst = group
                .iter()
                .min_by(|a, b| a[5].as_f64().unwrap().total_cmp(&b[5].as_f64().unwrap()))
                .unwrap();
            assert_eq!(
                (worst[1].as_str(), worst[2].as_str()),
                (Some("wavelet-standard"), Some("30:1")),
                "seed {seed}, {clip}"
            );
            // The win matrix as the report writes it.
            let counts = count_table(&report, &format!("pc_wins_{}", k + 1));
            let want: Vec<Vec<u64>> = serde_json::from_value(g["wins"][*clip].clone()).unwrap();
            assert_eq!(counts, want, "seed {seed}, {clip}");
        }
        let md = std::fs::read_to_string(report.join("report.md")).unwrap();
        assert!(md.contains("Pair comparison (Bradley-Terry)"));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Pair comparison with ties (`examples/pc-ties.toml`: a "No preference" button): two
/// simulated panels of 16; every clip's Davidson fit and the pooled one equal the SciPy fit
/// of scripts/reference/davidson_reference.py on the counts scripts/golden/pair_comparison.py
/// reads from the rows itself (scale values, SEs and bounds to 2e-6; the tie parameter ν, its
/// SE and interval to 2e-6), the win and tie matrices equal its counts, and the ties are a
/// share the simulated observer's indifference band gives (a tie when two versions' perceived
/// qualities differ by less than half the noise SD: between 15 % and 45 % of the choices).
#[test]
fn pair_comparison_with_ties_report_equals_scipy_davidson() {
    let Some(python) = venv_python::BAYES.python("choix", "pair comparison golden") else {
        return;
    };
    let dir = scratch("pc-ties");
    for seed in [3, 8] {
        let (results, report) = simulate_and_report(&dir, "pc-ties.toml", 16, seed);
        let g = run_golden(&python, "pair_comparison.py", &results);
        assert_pc_equal(&report, &g, true);
        for (k, clip) in ["march", "walk", "all"].iter().enumerate() {
            let wins = count_table(&report, &format!("pc_wins_{}", k + 1));
            let want: Vec<Vec<u64>> = serde_json::from_value(g["wins"][*clip].clone()).unwrap();
            assert_eq!(wins, want, "seed {seed}, {clip}");
            let ties = count_table(&report, &format!("pc_ties_{}", k + 1));
            let want: Vec<Vec<u64>> = serde_json::from_value(g["ties"][*clip].clone()).unwrap();
            assert_eq!(ties, want, "seed {seed}, {clip}");
        }
        let nu = std::fs::read_to_string(report.join("tables/pc_tie_parameter.csv")).unwrap();
        let mut lines = nu.lines();
        assert_eq!(
            lines.next(),
            Some("Clip,Ties,ν,SE,Lower,Upper,P(tie | equal)")
        );
        let mut ties_all = 0;
        for line in lines {
            let o: Vec<&str> = line.split(',').collect();
            let t = g["nu"][o[0]].as_array().unwrap();
            assert_eq!(o[1], t[0].as_u64().unwrap().to_string(), "{line}");
            for k in 2..6 {
                let (a, b): (f64, f64) = (o[k].parse().unwrap(), t[k - 1].as_f64().unwrap());
                assert!((a - b).abs() < 2e-6, "column {k}: {line} vs {t:?}");
            }
            if o[0] == "all" {
                ties_all = t[0].as_u64().unwrap();
            }
        }
        // 16 subjects x 22 trials.
        let share = ties_all as f64 / 352.0;
        assert!((0.15..0.45).contains(&share), "seed {seed}: {share}");
        let md = std::fs::read_to_string(report.join("report.md")).unwrap();
        assert!(md.contains("Davidson (Bradley-Terry with ties)"));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The report's CSV table `name` as rows of cells, the header checked against `columns`.
fn csv_rows(report: &Path, name: &str, columns: &str) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(report.join(format!("tables/{name}.csv"))).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(columns), "{name}");
    lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

/// Our row `o` against the script's `t`: the first `labels` cells as text, the rest as
/// numbers (integers exactly, the others to 2e-6: the tables print six decimals), "n/a"
/// for the script's null.
fn assert_row(o: &[String], t: &serde_json::Value, labels: usize, what: &str) {
    let t = t.as_array().unwrap();
    assert_eq!(o.len(), t.len(), "{what}: {o:?} vs {t:?}");
    for (k, (o, t)) in o.iter().zip(t).enumerate() {
        if k < labels {
            assert_eq!(o, t.as_str().unwrap(), "{what}");
        } else if t.is_null() {
            assert_eq!(o, "n/a", "{what} column {k}");
        } else if let Some(n) = t.as_u64() {
            assert_eq!(o, &n.to_string(), "{what} column {k}");
        } else {
            let (a, b): (f64, f64) = (o.parse().unwrap(), t.as_f64().unwrap());
            assert!((a - b).abs() < 2e-6, "{what} column {k}: {o} vs {b}");
        }
    }
}

/// CCR (P.910 comparison category rating, `examples/ccr.toml`): two simulated panels of 16;
/// the report's CMOS per condition (folded order, mean of subject means, t interval), the
/// folded means by order and the order effect's paired t-test equal scripts/golden/ccr.py,
/// which reads the rows itself and computes with NumPy and SciPy (scipy.stats.ttest_rel).
/// The simulated observer's clearly worst version (standard wavelet at 30:1, by far the
/// largest error) has the lowest CMOS of its clip, below 0 with its whole interval.
#[test]
fn ccr_report_equals_scipy() {
    let Some(python) = venv_python::BAYES.python("scipy", "CCR golden") else {
        return;
    };
    let dir = scratch("ccr");
    for seed in [3, 8] {
        let (results, report) = simulate_and_report(&dir, "ccr.toml", 16, seed);
        let g = run_golden(&python, "ccr.py", &results);
        let cmos = csv_rows(
            &report,
            "ccr_cmos",
            "Clip,Codec,CR,Subjects,Ratings,CMOS,SD,Lower,Upper",
        );
        let want = g["cmos"].as_array().unwrap();
        assert_eq!(cmos.len(), 10, "two clips of four codecs and the original");
        assert_eq!(cmos.len(), want.len());
        for (o, t) in cmos.iter().zip(want) {
            assert_row(o, t, 3, &format!("seed {seed} ccr_cmos"));
        }
        let order = csv_rows(
            &report,
            "ccr_order",
            "Clip,Codec,CR,Original first,Mean,Original second,Mean,Difference",
        );
        let want = g["order"].as_array().unwrap();
        assert_eq!(order.len(), want.len());
        for (o, t) in order.iter().zip(want) {
            assert_row(o, t, 3, &format!("seed {seed} ccr_order"));
        }
        let effect = csv_rows(
            &report,
            "ccr_order_effect",
            "Subjects,Difference,SD,Lower,Upper,t,df,p",
        );
        assert_eq!(effect.len(), 1);
        assert_row(
            &effect[0],
            &g["order_effect"],
            0,
            &format!("seed {seed} order effect"),
        );
        for clip in ["march", "walk"] {
            let rows: Vec<&Vec<String>> = cmos.iter().filter(|r| r[0] == clip).collect();
            let worst = rows
                .iter()
                .min_by(|a, b| {
                    let v = |r: &Vec<String>| r[5].parse::<f64>().unwrap();
                    v(a).total_cmp(&v(b))
                })
                .unwrap();
            assert_eq!(
                (worst[1].as_str(), worst[2].as_str()),
                ("wavelet-standard", "30:1"),
                "seed {seed}, {clip}"
            );
            assert!(
                worst[8].parse::<f64>().unwrap() < 0.0,
                "seed {seed}: {worst:?}"
            );
        }
        let md = std::fs::read_to_string(report.join("report.md")).unwrap();
        assert!(md.contains("Comparison category rating (CCR)"));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
