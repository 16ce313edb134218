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
