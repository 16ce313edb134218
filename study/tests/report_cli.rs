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

/// Copies a results directory (files and one level of session folders).
fn copy_results(from: &Path, to: &Path) {
    let _ = std::fs::remove_dir_all(to);
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let target = to.join(p.file_name().unwrap());
        if p.is_dir() {
            std::fs::create_dir_all(&target).unwrap();
            for f in std::fs::read_dir(&p).unwrap() {
                let f = f.unwrap().path();
                std::fs::copy(&f, target.join(f.file_name().unwrap())).unwrap();
            }
        } else {
            std::fs::copy(&p, &target).unwrap();
        }
    }
}

/// Edits the rows (header excluded) of a session's `trials.csv`.
fn edit_rows(trials: &Path, edit: impl FnOnce(&mut Vec<String>)) {
    let text = std::fs::read_to_string(trials).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut rows = lines.split_off(1);
    edit(&mut rows);
    lines.extend(rows);
    std::fs::write(trials, lines.join("\n") + "\n").unwrap();
}

/// Issue 18: the logs are checked before any statistic. A duplicated, a truncated, a reordered
/// and a foreign-row trials file, a torn row after the end, a session in the wrong folder and
/// a session still running each give one error naming the file (and the row); trials
/// missing at the end are reported with `--allow-incomplete`, which lists them.
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "one damaged copy per case, side by side"
)]
fn report_refuses_logs_it_cannot_trust_naming_file_and_row() {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let dir = std::env::temp_dir().join(format!("study-report-integrity-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let clean = dir.join("clean");
    let out = study(&[
        "simulate",
        &examples.join("mos.toml").display().to_string(),
        "--subjects",
        "3",
        "--seed",
        "5",
        "-o",
        &clean.display().to_string(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = |res: &Path, name: &str, extra: &[&str]| {
        let rep = dir.join(format!("{name}-report")).display().to_string();
        let mut args = vec!["report", res.to_str().unwrap(), "-o", &rep, "--no-png"];
        args.extend_from_slice(extra);
        study(&args)
    };
    let out = report(&clean, "clean", &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ratings = |name: &str| {
        std::fs::read_to_string(dir.join(format!("{name}-report/ratings.csv")))
            .unwrap()
            .lines()
            .count()
            - 1
    };
    let all_ratings = ratings("clean");
    let s1 = "S001_s1";
    // (case, edit of a copy, what the error must say, line it must name)
    type Edit = fn(&Path);
    let cases: [(&str, Edit, &str, Option<usize>); 7] = [
        (
            "duplicated",
            |res| {
                edit_rows(&res.join("S001_s1/trials.csv"), |rows| {
                    let copy = rows.clone();
                    rows.clear();
                    for r in copy {
                        rows.push(r.clone());
                        rows.push(r);
                    }
                });
            },
            "trial 0 is logged twice (first at line 2)",
            Some(3),
        ),
        (
            "reordered",
            |res| edit_rows(&res.join("S001_s1/trials.csv"), |rows| rows.swap(4, 6)),
            "rows out of order: trial 6 is logged before trial 4 (line 8)",
            Some(6),
        ),
        (
            "deleted",
            |res| edit_rows(&res.join("S001_s1/trials.csv"), |rows| drop(rows.remove(3))),
            "trial 3 is missing: this row is trial 4",
            Some(5),
        ),
        (
            "foreign",
            |res| {
                let other = std::fs::read_to_string(res.join("S002_s1/trials.csv")).unwrap();
                let row = other.lines().nth(6).unwrap().to_owned();
                edit_rows(&res.join("S001_s1/trials.csv"), |rows| rows[5] = row);
            },
            "subject \"S002\"",
            Some(7),
        ),
        (
            "torn after the end",
            |res| {
                use std::io::Write as _;
                std::fs::OpenOptions::new()
                    .append(true)
                    .open(res.join("S001_s1/trials.csv"))
                    .unwrap()
                    .write_all(b"mos-example,S001,1,mos,4")
                    .unwrap();
            },
            "a torn row",
            None,
        ),
        (
            "moved",
            |res| std::fs::rename(res.join("S001_s1"), res.join("S009_s1")).unwrap(),
            "whose folder is S001_s1, not S009_s1",
            None,
        ),
        (
            "running",
            |res| {
                let m = res.join("S001_s1/session.json");
                let text = std::fs::read_to_string(&m).unwrap();
                std::fs::write(&m, text.replace("\"complete\"", "\"running\"")).unwrap();
            },
            "the session is running",
            None,
        ),
    ];
    for (name, edit, says, line) in cases {
        let res = dir.join(name);
        copy_results(&clean, &res);
        edit(&res);
        let out = report(&res, name, &[]);
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(!out.status.success(), "{name}: reported: {err}");
        assert!(
            err.contains("trials.csv") || err.contains("session.json"),
            "{name}: {err}"
        );
        assert!(err.contains(says), "{name}: {err}");
        if let Some(line) = line {
            assert!(
                err.contains(&format!("S001_s1/trials.csv: line {line}: ")),
                "{name}: {err}"
            );
        }
        assert_eq!(err.matches(says).count(), 1, "{name}: said once: {err}");
        assert!(
            !dir.join(format!("{name}-report/report.md")).exists(),
            "{name}"
        );
    }
    // Trials missing at the end: refused, then reported with --allow-incomplete, listed.
    let res = dir.join("truncated");
    copy_results(&clean, &res);
    edit_rows(&res.join(format!("{s1}/trials.csv")), |rows| {
        rows.truncate(rows.len() - 4)
    });
    let out = report(&res, "truncated", &[]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success());
    assert!(
        err.contains("S001_s1/trials.csv") && err.contains("are missing"),
        "{err}"
    );
    assert!(err.contains("--allow-incomplete"), "{err}");
    let out = report(&res, "truncated", &["--allow-incomplete"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning: "));
    let md = std::fs::read_to_string(dir.join("truncated-report/report.md")).unwrap();
    assert!(
        md.contains("Incomplete sessions") && md.contains("are missing"),
        "{md}"
    );
    assert!(ratings("truncated") < all_ratings);
    // Damage is refused even with --allow-incomplete.
    let out = report(
        &dir.join("duplicated"),
        "duplicated-allowed",
        &["--allow-incomplete"],
    );
    assert!(!out.status.success());
    std::fs::remove_dir_all(&dir).unwrap();
}
