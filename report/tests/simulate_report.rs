//! Simulated sessions of the three example studies reported: every table and figure is
//! written; a score edited outside the scale is an error naming file and line.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use lab::results_dir::Destination;

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

fn simulate(study: &Path, output: &Path) {
    let options = lab::simulate::SimulateOptions {
        study: study.to_path_buf(),
        subjects: 6,
        seed: 2,
        output: Destination::Folder(output.to_path_buf()),
        trial_delay: Duration::ZERO,
        resume: false,
        patience: Duration::from_secs(1),
    };
    lab::simulate::simulate(&options, &mut |_| {}).unwrap();
}

fn request(results: &Path, study: &Path, output: &Path) -> report::Request {
    report::Request {
        results: Destination::Folder(results.to_path_buf()),
        study: Some(study.to_path_buf()),
        output: output.to_path_buf(),
        mode: files::Mode::New,
        allow_incomplete: false,
        png: false,
        settings: report::Settings {
            bootstrap: 50,
            ..report::Settings::default()
        },
    }
}

/// A folder of its own for a test.
fn fresh_root(test: &str) -> PathBuf {
    let root = std::env::temp_dir().join(format!("report-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    root
}

#[test]
fn simulated_sessions_give_every_table_and_figure() {
    let root = fresh_root("tables");
    let expected: [(&str, &[&str], &[&str]); 3] = [
        (
            "mos",
            &["mos", "ttests", "screening", "mos_findings"],
            &["mos_vs_cr", "score_distributions"],
        ),
        (
            "dscqs",
            &["mos", "dmos", "dmos_ci", "dmos_findings", "ttests"],
            &["dmos_vs_cr", "mos_vs_cr"],
        ),
        (
            "staircase",
            &["thresholds", "jnd_thresholds", "jnd_notice"],
            &["staircases", "psychometric", "jnd"],
        ),
    ];
    for (name, tables, figures) in expected {
        let study = examples().join(format!("{name}.toml"));
        let results = root.join(format!("{name}-results"));
        let out = root.join(format!("{name}-report"));
        simulate(&study, &results);
        let mut warnings = Vec::new();
        let summary = report::report(&request(&results, &study, &out), &mut |w| {
            warnings.push(w.to_owned());
        })
        .unwrap();
        assert!(warnings.is_empty(), "{name}: {warnings:?}");
        assert_eq!(summary.output, out);
        for t in tables {
            for ext in ["csv", "md", "tex"] {
                assert!(
                    out.join("tables").join(format!("{t}.{ext}")).is_file(),
                    "{name}: {t}.{ext}"
                );
            }
        }
        for f in figures {
            assert!(
                out.join("figures").join(format!("{f}.svg")).is_file(),
                "{name}: {f}.svg"
            );
            assert!(!out.join("figures").join(format!("{f}.png")).exists());
        }
        for f in [
            "report.md",
            "report.html",
            "ratings.csv",
            "trials_tidy.csv",
            "datapackage.json",
            "sureal_dataset.py",
        ] {
            assert!(out.join(f).is_file(), "{name}: {f}");
        }
        // Every file the summary counts is in the output folder.
        let on_disk = ["", "tables", "figures"]
            .iter()
            .map(|d| {
                std::fs::read_dir(out.join(d))
                    .unwrap()
                    .filter(|e| e.as_ref().unwrap().path().is_file())
                    .count()
            })
            .sum::<usize>();
        assert_eq!(summary.files, on_disk, "{name}");
        // A second report into the same folder is refused without replacing.
        let again = report::report(&request(&results, &study, &out), &mut |_| {});
        assert!(again.is_err(), "{name}: an existing report was overwritten");
    }
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn a_score_outside_the_scale_is_named_by_file_and_line() {
    let root = fresh_root("bad-score");
    let results = root.join("mos-results");
    simulate(&examples().join("mos.toml"), &results);
    // Corrupt one MOS rating: 9 on a 1-5 scale.
    let session = std::fs::read_dir(&results)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.join("trials.csv").is_file())
        .unwrap();
    let trials = session.join("trials.csv");
    let text = std::fs::read_to_string(&trials).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let (response, score) = (
        header.iter().position(|c| *c == "response").unwrap(),
        header.iter().position(|c| *c == "score").unwrap(),
    );
    let row = lines.iter().position(|l| l.contains(",test,")).unwrap();
    let mut fields: Vec<String> = lines[row].split(',').map(str::to_owned).collect();
    fields[response] = "9".into();
    fields[score] = "9".into();
    lines[row] = fields.join(",");
    std::fs::write(&trials, lines.join("\n") + "\n").unwrap();
    let err = report::report(
        &request(
            &results,
            &examples().join("mos.toml"),
            &root.join("bad-report"),
        ),
        &mut |_| {},
    )
    .unwrap_err();
    let err = format!("{err:#}");
    assert!(
        err.contains("trials.csv") && err.contains(&format!("line {}", row + 1)),
        "{err}"
    );
    assert!(
        !root.join("bad-report").exists(),
        "a refused report wrote its folder"
    );
    std::fs::remove_dir_all(&root).unwrap();
}
