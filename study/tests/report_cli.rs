//! A results directory is self-contained: `study report RESULTS` needs no other file.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::Path;
use std::process::{Command, Output};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn report_finds_the_archived_study_and_manifest() {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let dir = std::env::temp_dir().join(format!("study-report-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let res = dir.join("res").display().to_string();
    let out = study(&[
        "simulate",
        &examples.join("mos.toml").display().to_string(),
        "--subjects",
        "3",
        "--seed",
        "5",
        "-o",
        &res,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The copy's manifest names the clip files by absolute path, so they still resolve.
    let copy: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("res/stimuli.json")).unwrap()).unwrap();
    let file = copy["stimuli"][0]["file"].as_str().unwrap();
    assert!(Path::new(file).is_absolute(), "{file}");
    let rep = dir.join("rep").display().to_string();
    let out = study(&["report", &res, "-o", &rep, "--no-png"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("rep/report.md").is_file());
}

/// Staircase levels lie on an exact grid: the log holds one value per grid point, and no
/// staircase table lists a level twice (accumulated steps once gave 0.0020 twice, and
/// 0.0100 twice with different answers).
#[test]
fn staircase_tables_list_each_level_once() {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let dir = std::env::temp_dir().join(format!("study-report-grid-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let res = dir.join("res").display().to_string();
    let rep = dir.join("rep");
    let out = study(&[
        "simulate",
        &examples.join("staircase.toml").display().to_string(),
        "--subjects",
        "15",
        "--seed",
        "1",
        "-o",
        &res,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = study(&["report", &res, "-o", &rep.display().to_string()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Every level in the logs is the decimal the study's start and step make.
    let mut logged = std::collections::BTreeSet::new();
    for entry in std::fs::read_dir(&res).unwrap() {
        let p = entry.unwrap().path().join("trials.csv");
        if let Ok(t) = results::read_trials(&p) {
            for r in t.records {
                logged.insert(r.trial.level.unwrap().to_bits());
            }
        }
    }
    for bits in &logged {
        let v = f64::from_bits(*bits);
        let k = (v - 0.002) / 0.002;
        assert!((k - k.round()).abs() < 1e-9, "{v} is off the grid");
        assert!(format!("{v}").len() <= 6, "{v} is not a short decimal");
    }
    let table = std::fs::read_to_string(rep.join("tables/jnd_notice.csv")).unwrap();
    let levels: Vec<&str> = table
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    let unique: std::collections::BTreeSet<&&str> = levels.iter().collect();
    assert!(levels.len() >= 10, "{table}");
    assert_eq!(unique.len(), levels.len(), "a level listed twice:\n{table}");
    std::fs::remove_dir_all(&dir).unwrap();
}
