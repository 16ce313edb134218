#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]
//! The report's tables on a small hand-made study, against values computed independently by
//! `scripts/golden/report_tables.py` (SciPy `ttest_rel` / `t.ppf`, statsmodels `multipletests`
//! Holm, NumPy) into `tests/data/report_tables_golden.json`: every printed cell of the MOS,
//! t-test and staircase-threshold tables, and the numbers behind them (n, MOS, SD, CI
//! half-width and bounds, t, df, p, Holm p, effect size, thresholds) to 1e-12 relative.
//!
//! The data set has a hidden repeat (subject 1 rates A at 10:1 twice: averaged into one score
//! of subject 1 in the MOS and in the paired test alike), a missing rating (subject 6 never rated B at
//! 20:1: that test has 5 pairs), and a staircase short of 3 reversals (subject 3, `walk`:
//! unconverged, and subject 3's threshold is its `run` track alone).

use std::collections::HashMap;

use analysis::study::{ReportOptions, StudyData, analyze};
use analysis::tables::Table;
use analysis::{ConditionInfo, Rating, StaircaseStep, StaircaseTrack};
use serde_json::Value;

fn golden() -> Value {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/report_tables_golden.json"
    ))
    .unwrap();
    serde_json::from_str(&text).unwrap()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

fn close(actual: f64, expected: f64, what: &str) {
    assert!(
        (actual - expected).abs() <= 1e-12 * expected.abs().max(1e-300),
        "{what}: {actual} vs expected {expected}"
    );
}

fn data(g: &Value) -> StudyData {
    let conditions = g["conditions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| ConditionInfo {
            id: c["id"].as_u64().unwrap() as u32,
            codec: c["codec"].as_str().unwrap().to_owned(),
            params: std::collections::BTreeMap::new(),
            clip: c["clip"].as_str().unwrap().to_owned(),
            compression_ratio: Some(f(&c["compression_ratio"])),
        })
        .collect();
    let ratings = g["ratings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| Rating {
            subject: r["subject"].as_u64().unwrap() as u32,
            condition: r["condition"].as_u64().unwrap() as u32,
            score: f(&r["score"]),
        })
        .collect();
    let staircases = g["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            let levels: Vec<f64> = t["levels"].as_array().unwrap().iter().map(f).collect();
            StaircaseTrack {
                bayesian: false,
                logged_threshold: None,
                subject: t["subject"].as_u64().unwrap() as u32,
                label: t["label"].as_str().unwrap().to_owned(),
                steps: levels
                    .iter()
                    .enumerate()
                    .map(|(i, &level)| StaircaseStep {
                        level,
                        // Not used by the thresholds: correct when the level goes down next.
                        correct: levels.get(i + 1).is_some_and(|n| *n < level),
                        reversal: false,
                    })
                    .collect(),
            }
            .with_detected_reversals()
        })
        .collect();
    StudyData {
        conditions,
        ratings,
        staircases,
        ..StudyData::default()
    }
}

fn options(g: &Value, baseline: Option<&str>) -> ReportOptions {
    assert!((f(&g["confidence"]) - 0.95).abs() < 1e-15);
    ReportOptions {
        baseline_codec: baseline.map(str::to_owned),
        last_reversals: g["last_reversals"].as_u64().unwrap() as usize,
        figures: false,
        ..ReportOptions::default()
    }
}

/// The report's tables by name, each once.
fn tables(data: &StudyData, options: &ReportOptions) -> HashMap<String, Table> {
    let a = analyze(data, options).unwrap();
    assert!(
        a.mos_screened.is_none(),
        "BT.500 rejects nobody in this panel: {:?}",
        a.screening
    );
    let report = a.to_report(data, options, "Golden");
    let mut out = HashMap::new();
    for t in report.tables() {
        assert!(
            out.insert(t.name.clone(), t.clone()).is_none(),
            "table {} twice",
            t.name
        );
    }
    out
}

fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap().to_owned())
        .collect()
}

fn check_cells(table: &Table, expected: &[Value]) {
    assert_eq!(table.rows.len(), expected.len(), "{}: rows", table.name);
    for (i, (row, e)) in table.rows.iter().zip(expected).enumerate() {
        assert_eq!(row.len(), table.columns.len(), "{} row {i}", table.name);
        assert_eq!(*row, strings(&e["cells"]), "{} row {i}", table.name);
    }
}

#[test]
fn mos_table_matches_scipy() {
    let g = golden();
    let data = data(&g);
    let opts = options(&g, None);
    let t = tables(&data, &opts);
    let expected = g["mos"].as_array().unwrap();
    assert_eq!(
        t["mos"].columns,
        [
            "Codec",
            "Clip",
            "CR",
            "n",
            "Mean",
            "SD",
            "CI ± (t)",
            "Lower",
            "Upper"
        ]
    );
    check_cells(&t["mos"], expected);
    let stats = analyze(&data, &opts).unwrap().mos;
    assert_eq!(stats.len(), expected.len());
    for e in expected {
        let id = e["condition"].as_u64().unwrap() as u32;
        let s = &stats.iter().find(|s| s.condition == id).unwrap().summary;
        let n = &e["numbers"];
        let what = format!("condition {id}");
        assert_eq!(s.n as u64, n["n"].as_u64().unwrap(), "{what}: n");
        close(s.mean, f(&n["mean"]), &format!("{what}: MOS"));
        close(s.sd.unwrap(), f(&n["sd"]), &format!("{what}: SD"));
        let ci = s.ci_t.unwrap();
        close(ci.half_width, f(&n["half_width"]), &format!("{what}: CI ±"));
        close(ci.lower, f(&n["lower"]), &format!("{what}: lower"));
        close(ci.upper, f(&n["upper"]), &format!("{what}: upper"));
    }
    // The hidden repeat is averaged into its subject's score: 7 ratings of condition 1 by 6
    // subjects, n = 6.
    assert_eq!(data.ratings.iter().filter(|r| r.condition == 1).count(), 7);
    assert_eq!(t["mos"].rows[0][3], "6");
}

fn check_ttests(baseline: Option<&str>, key: &str) {
    let g = golden();
    let data = data(&g);
    let opts = options(&g, baseline);
    let t = tables(&data, &opts);
    let expected = g[key].as_array().unwrap();
    check_cells(&t["ttests"], expected);
    let rows = analyze(&data, &opts).unwrap().comparisons;
    assert_eq!(rows.len(), expected.len());
    for (i, (r, e)) in rows.iter().zip(expected).enumerate() {
        let what = format!("{key} row {i}");
        assert_eq!(
            (r.first.0.as_str(), r.second.0.as_str()),
            (e["first"].as_str().unwrap(), e["second"].as_str().unwrap()),
            "{what}"
        );
        close(r.first.1, f(&e["mean_first"]), &format!("{what}: mean A"));
        close(r.second.1, f(&e["mean_second"]), &format!("{what}: mean B"));
        let test = r.test.as_ref().unwrap();
        close(test.t, f(&e["t"]), &format!("{what}: t"));
        // df = pairs − 1: 6 subjects rated both at 10:1, 5 at 20:1.
        close(test.df, f(&e["df"]), &format!("{what}: df"));
        assert_eq!(
            test.df as u64 + 1,
            e["n"].as_u64().unwrap(),
            "{what}: pairs"
        );
        close(test.p, f(&e["p"]), &format!("{what}: p"));
        close(
            r.p_holm.unwrap(),
            f(&e["p_holm"]),
            &format!("{what}: Holm p"),
        );
        close(
            test.effect_size,
            f(&e["effect_size"]),
            &format!("{what}: effect size"),
        );
    }
}

#[test]
fn two_sided_ttest_table_matches_scipy_and_statsmodels() {
    check_ttests(None, "ttests_two_sided");
}

#[test]
fn one_sided_ttest_table_against_a_baseline_matches_scipy_and_statsmodels() {
    check_ttests(Some("B"), "ttests_baseline_b");
}

#[test]
fn threshold_table_matches_numpy_and_scipy() {
    let g = golden();
    let data = data(&g);
    let opts = options(&g, None);
    let t = tables(&data, &opts);
    let e = &g["thresholds"];
    check_cells(&t["thresholds"], std::slice::from_ref(e));
    let th = analyze(&data, &opts).unwrap().thresholds.unwrap();
    let per: Vec<(u32, f64)> = e["per_subject"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p[0].as_u64().unwrap() as u32, f(&p[1])))
        .collect();
    assert_eq!(th.per_subject.len(), per.len());
    for ((s, v), (es, ev)) in th.per_subject.iter().zip(&per) {
        assert_eq!(s, es);
        close(*v, *ev, &format!("subject {s} threshold"));
    }
    assert_eq!(th.unconverged, vec![(3, "walk".to_owned())]);
    let n = &e["numbers"];
    let s = th.summary.unwrap();
    assert_eq!(s.n as u64, n["n"].as_u64().unwrap());
    close(s.mean, f(&n["mean"]), "threshold mean");
    close(s.sd.unwrap(), f(&n["sd"]), "threshold SD");
    close(th.min.unwrap(), f(&n["min"]), "threshold min");
    close(th.max.unwrap(), f(&n["max"]), "threshold max");
    let ci = s.ci_t.unwrap();
    close(ci.half_width, f(&n["half_width"]), "threshold CI ±");
    close(ci.lower, f(&n["lower"]), "threshold CI lower");
    close(ci.upper, f(&n["upper"]), "threshold CI upper");
}

/// Issue 39: the staircase report gives the thesis's last-3 estimate and the even-count
/// (last-4) estimate side by side per track, and the threshold to cite per condition and
/// over all (the even-count means across subjects, their t interval and the nearest grid
/// level), every cell as `scripts/golden/report_tables.py` computes it with NumPy/SciPy.
#[test]
fn staircase_estimates_and_threshold_to_cite_match_numpy_and_scipy() {
    let g = golden();
    let data = data(&g);
    let opts = options(&g, None);
    let t = tables(&data, &opts);
    check_cells(
        &t["staircase_tracks"],
        g["staircase_tracks"].as_array().unwrap(),
    );
    let cite = g["threshold_to_cite"].as_array().unwrap();
    check_cells(&t["threshold_to_cite"], cite);
    let th = analyze(&data, &opts).unwrap().thresholds.unwrap();
    assert_eq!(th.even_k, 4);
    for (c, e) in th.cited.iter().zip(cite) {
        close(c.even.mean, f(&e["mean"]), "threshold to cite");
    }
}
