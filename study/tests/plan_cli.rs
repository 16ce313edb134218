//! `study plan`: subjects from stated effect sizes (the numbers are statsmodels' and SciPy's,
//! written out below), from a pilot folder made by `study simulate` of an example (the same
//! table as the pilot's report's "Sample size" section), and one clear error line for bad
//! input, naming the flag or the folder.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout.clone()).unwrap()
}

/// A fresh folder of this test's own.
fn root(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("study-plan-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `study simulate examples/EXAMPLE --subjects N --seed 3 -o OUT`.
fn simulate(example: &str, out: &Path, subjects: &str) {
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(example);
    let out = out.display().to_string();
    let o = study(&[
        "simulate",
        &file.display().to_string(),
        "--subjects",
        subjects,
        "--seed",
        "3",
        "-o",
        &out,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn stated_effects_give_statsmodels_sample_sizes() {
    // TTestPower().solve_power(0.5, alpha=0.05, power=0.8, alternative="two-sided") =
    // 33.36713118; power(0.5, 34, 0.05) = 0.80778.
    let out = stdout(&study(&["plan", "--difference", "0.5", "--sd", "1"]));
    assert!(
        out.contains("34 subjects (power 0.808; exact n 33.37"),
        "{out}"
    );
    assert!(out.contains("two-sided"), "{out}");
    // solve_power(0.3, alpha=0.05, power=0.9, alternative="larger") = 96.52287351;
    // power at 97 = 0.90128. SciPy: t.ppf(0.975, 98) / sqrt(99) = 0.19945 ≤ 0.2 <
    // t.ppf(0.975, 97) / sqrt(98) = 0.20049.
    let out = stdout(&study(&[
        "plan",
        "--dz",
        "0.3",
        "--one-sided",
        "--power",
        "0.9",
        "--ci-width",
        "0.2",
        "--sd",
        "1",
    ]));
    assert!(
        out.contains("97 subjects (power 0.901; exact n 96.52"),
        "{out}"
    );
    assert!(
        out.contains("half-width ≤ 0.2: 99 subjects (half-width 0.1994"),
        "{out}"
    );
    // A negative difference is the same effect: solve_power(0.4/1.5, alpha=0.01, power=0.8)
    // = 167.56.
    let out = stdout(&study(&[
        "plan",
        "--difference=-0.4",
        "--sd",
        "1.5",
        "--alpha",
        "0.01",
    ]));
    assert!(out.contains("168 subjects"), "{out}");
    assert!(out.contains("exact n 167.56"), "{out}");
}

#[test]
fn a_pilot_folder_gives_its_reports_sample_size_table() {
    let dir = root("pilot");
    let pilot = dir.join("pilot");
    simulate("mos.toml", &pilot, "8");
    let pilot_s = pilot.display().to_string();
    let out = stdout(&study(&["plan", &pilot_s, "--ci-width", "0.5"]));
    assert!(out.contains("Pilot "), "{out}");
    assert!(out.contains("n for power 0.8"), "{out}");
    assert!(out.contains("n for CI ±0.5"), "{out}");
    let rows: Vec<&str> = out
        .lines()
        .filter(|l| l.contains(" vs ") && !l.contains("A vs B"))
        .collect();
    assert_eq!(rows.len(), 4, "one row per comparison:\n{out}");
    // The pilot's report prints the same rows (without the CI column) in "Sample size".
    let rep = dir.join("rep");
    let rep_s = rep.display().to_string();
    stdout(&study(&[
        "report",
        &pilot_s,
        "-o",
        &rep_s,
        "--no-png",
        "--bootstrap",
        "20",
    ]));
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(md.contains("## Sample size"), "no Sample size section");
    assert!(
        md.contains("## Inter-rater reliability"),
        "no reliability section"
    );
    let table = std::fs::read_to_string(rep.join("tables/sample_size_comparisons.md")).unwrap();
    let plain = stdout(&study(&["plan", &pilot_s]));
    for row in plain
        .lines()
        .filter(|l| l.contains(" vs ") && !l.contains("A vs B"))
    {
        assert!(
            table.contains(row),
            "{row} not in the report's table:\n{table}"
        );
    }
    // A pilot of one subject: every row says why it has no number; no NaN anywhere, in the
    // plan or in the report's reliability section.
    let one = dir.join("one");
    simulate("mos.toml", &one, "1");
    let one_s = one.display().to_string();
    let out = stdout(&study(&["plan", &one_s]));
    assert!(out.contains("n/a (test undefined)"), "{out}");
    assert!(!out.contains("NaN"), "{out}");
    let rep1 = dir.join("rep1").display().to_string();
    stdout(&study(&[
        "report",
        &one_s,
        "-o",
        &rep1,
        "--no-png",
        "--bootstrap",
        "20",
    ]));
    let md = std::fs::read_to_string(dir.join("rep1/report.md")).unwrap();
    assert!(
        md.contains("No ICC: it needs at least two subjects"),
        "{md}"
    );
    assert!(!md.contains("NaN"), "NaN in the one-subject report");
    // A staircase pilot: one row per track and one over all tracks.
    let stairs = dir.join("stairs");
    simulate("staircase.toml", &stairs, "5");
    let out = stdout(&study(&["plan", &stairs.display().to_string()]));
    assert!(out.contains("| all tracks | 5 |"), "{out}");
    assert!(out.contains("10 % of the pilot's mean"), "{out}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_input_is_one_line_naming_the_flag_or_file() {
    let cases: [(&[&str], &str); 9] = [
        (&["plan"], "nothing to plan"),
        (&["plan", "--difference", "0.5"], "--difference needs --sd"),
        (&["plan", "--dz", "0.5", "--alpha", "1.5"], "--alpha 1.5"),
        (&["plan", "--dz", "0.5", "--power", "0.01"], "--power 0.01"),
        (&["plan", "--difference", "0.5", "--sd", "0"], "--sd 0"),
        (&["plan", "--dz", "0"], "--dz 0"),
        (&["plan", "--ci-width", "0.1"], "--ci-width needs --sd"),
        (&["plan", "--dz", "0.001"], "more than 100000 subjects"),
        (
            &["plan", "--sd", "1"],
            "--sd needs --difference or --ci-width",
        ),
    ];
    for (args, expected) in cases {
        let o = study(args);
        assert!(!o.status.success(), "{args:?} succeeded");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.starts_with("error: ") && err.contains(expected),
            "{args:?}: {err}"
        );
    }
    let missing = root("missing").join("no-such-pilot");
    let m = missing.display().to_string();
    let o = study(&["plan", &m]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains(&m), "{err}");
}
