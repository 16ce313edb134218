// A report's tidy export read by outside readers, shared by the tests that simulate and report
// the examples (study/tests/simulate_protocols.rs, live_staircase.rs and examples_window.rs
// include this file with `#[path]`, beside scripts/golden/venv_python.rs): `trials_tidy.csv` read with pandas (`$STATS_PYTHON`,
// scripts/reference/tidy_read.py) and with R's read.csv (`Rscript`,
// scripts/reference/tidy_read.R), its columns and their inferred types checked against
// `datapackage.json`, its rows against the sessions' own trial rows.

use std::path::Path;
use std::process::Command;

/// The tidy resource's columns in `datapackage.json`: (name, type).
fn documented(report: &Path) -> Vec<(String, String)> {
    let text = std::fs::read_to_string(report.join("datapackage.json")).unwrap();
    let package: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(package["profile"], "tabular-data-package");
    let tidy = package["resources"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["path"] == "trials_tidy.csv")
        .expect("datapackage.json describes trials_tidy.csv");
    tidy["schema"]["fields"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            assert!(
                !f["description"].as_str().unwrap_or_default().is_empty(),
                "{f}: no description"
            );
            (
                f["name"].as_str().unwrap().to_owned(),
                f["type"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

/// Whether a column of Table Schema type `kind` that pandas read as `dtype`, `missing` of
/// `rows` values missing, was read as its type.
fn pandas_reads_as(kind: &str, dtype: &str, missing: u64, rows: u64) -> bool {
    if missing == rows {
        // Nothing to infer from: pandas makes an empty column float64.
        return true;
    }
    match kind {
        "integer" => dtype == "int64" || (missing > 0 && dtype == "float64"),
        "number" => dtype == "float64" || dtype == "int64",
        "boolean" => dtype == "bool" || (missing > 0 && dtype == "object"),
        "string" => dtype == "object" || dtype == "str" || dtype == "string",
        _ => false,
    }
}

/// Whether a column of Table Schema type `kind` that R read as class `class` was read as its
/// type (R reads a whole number past 2³¹ as a double).
fn r_reads_as(kind: &str, class: &str, missing: u64, rows: u64) -> bool {
    if missing == rows {
        return class == "logical";
    }
    match kind {
        "integer" => class == "integer" || class == "numeric",
        "number" => class == "numeric" || class == "integer",
        "boolean" => class == "logical",
        "string" => class == "character",
        _ => false,
    }
}

fn run(mut command: Command, what: &str) -> String {
    let out = command
        .output()
        .unwrap_or_else(|e| panic!("cannot run {what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn script(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scripts/reference")
        .join(name)
}

/// `Rscript`, or `None` after saying why the check skips; under `CI` a missing R fails.
fn rscript(what: &str) -> Option<&'static str> {
    match Command::new("Rscript").arg("--version").output() {
        Ok(o) if o.status.success() => Some("Rscript"),
        _ if std::env::var_os("CI").is_some() => {
            panic!("under CI the {what} needs Rscript (scripts/test installs r-base-core)")
        }
        _ => {
            eprintln!("{what} skipped: no Rscript");
            None
        }
    }
}

/// Checks `report`'s `trials_tidy.csv` (of the results folder `results`, `name` in messages)
/// with pandas and R: the columns and their order as `datapackage.json` documents them,
/// each read as its documented type, one row per trial row of the sessions, and the
/// subject, session, trial, stimulus, score, response time, practice flag, level, group and
/// subject fields of every row equal to the sessions' (pandas), the subject, trial, score and
/// response time (R); a catch trial's verdict on catch trials alone. Under `CI` a missing
/// pandas or R fails.
pub fn check_tidy(results: &Path, report: &Path, name: &str) {
    let csv = report.join("trials_tidy.csv");
    let columns = documented(report);
    let (_, sessions) = results::read_results_dir(results).unwrap();
    let rows: Vec<TrialRow<'_>> = sessions
        .iter()
        .flat_map(|s| s.trials.records.iter().map(move |r| (s, r)))
        .collect();
    assert!(!rows.is_empty(), "{name}: no trials");
    if let Some(python) = crate::venv_python::STATS.python("pandas", "tidy export check (pandas)") {
        check_pandas(&python, &csv, &columns, &rows, name);
    }
    if let Some(rscript) = rscript("tidy export check (R)") {
        check_r(rscript, &csv, &columns, &rows, name);
    }
}

/// A session's trial row.
type TrialRow<'s> = (&'s results::SessionResults, &'s protocols::TrialRecord);

/// `csv` read by pandas: the documented `columns` with their types, `rows` and their values.
fn check_pandas(
    python: &Path,
    csv: &Path,
    columns: &[(String, String)],
    rows: &[TrialRow<'_>],
    name: &str,
) {
    let names: Vec<&str> = columns.iter().map(|c| c.0.as_str()).collect();
    let mut command = Command::new(python);
    command.arg(script("tidy_read.py")).arg(csv);
    let read: serde_json::Value = serde_json::from_str(&run(command, "tidy_read.py")).unwrap();
    let read_names: Vec<&str> = read["columns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    assert_eq!(read_names, names, "{name}: pandas' columns");
    let n = read["rows"].as_u64().unwrap();
    assert_eq!(n as usize, rows.len(), "{name}: pandas' rows");
    for (column, kind) in columns {
        let dtype = read["dtypes"][column].as_str().unwrap();
        let missing = read["missing"][column].as_u64().unwrap();
        assert!(
            pandas_reads_as(kind, dtype, missing, n),
            "{name}: pandas reads {column} ({kind}) as {dtype}"
        );
    }
    let v = &read["values"];
    for (i, (s, r)) in rows.iter().enumerate() {
        let at = |c: &str| &v[c][i];
        assert_eq!(
            at("subject"),
            s.manifest.subject.as_str(),
            "{name}: row {i}"
        );
        assert_eq!(at("session"), s.manifest.session, "{name}: row {i}");
        assert_eq!(at("trial_index"), r.trial.index, "{name}: row {i}");
        assert_eq!(at("stimulus"), r.trial.stimulus.as_str(), "{name}: row {i}");
        assert_eq!(
            at("score").as_f64(),
            Some(r.outcome.score),
            "{name}: row {i}"
        );
        assert_eq!(
            at("response_time_ms"),
            r.response.response_time_ms,
            "{name}: row {i}"
        );
        assert_eq!(
            at("practice").as_bool(),
            Some(r.trial.block == protocols::Block::Familiarization),
            "{name}: row {i}"
        );
        assert_eq!(at("level").as_f64(), r.trial.level, "{name}: row {i}");
        assert_eq!(
            at("group").as_str(),
            s.manifest.group.as_deref(),
            "{name}: row {i}"
        );
        for (field, value) in &s.manifest.subject_fields {
            let read = at(&format!("subject_{field}"));
            let read = read
                .as_str()
                .map_or_else(|| read.to_string(), str::to_owned);
            assert_eq!(&read, value, "{name}: row {i}: subject field {field}");
        }
        // A catch trial's verdict is there, and only there.
        assert_eq!(
            at("catch").as_bool().unwrap(),
            !at("gold_passed").is_null(),
            "{name}: row {i}"
        );
    }
}

/// `csv` read by R's `read.csv`: the documented `columns` with their types, `rows` and the
/// subject, trial, score and response time of each.
#[expect(
    clippy::float_cmp,
    reason = "R prints 17 significant digits: the same double or a bug"
)]
fn check_r(
    rscript: &str,
    csv: &Path,
    columns: &[(String, String)],
    rows: &[TrialRow<'_>],
    name: &str,
) {
    let names: Vec<&str> = columns.iter().map(|c| c.0.as_str()).collect();
    let mut command = Command::new(rscript);
    command.arg(script("tidy_read.R")).arg(csv);
    let out = run(command, "tidy_read.R");
    let lines: Vec<Vec<&str>> = out.lines().map(|l| l.split('\t').collect()).collect();
    let n: u64 = lines
        .iter()
        .find(|l| l[0] == "rows")
        .map(|l| l[1].parse().unwrap())
        .unwrap();
    assert_eq!(n as usize, rows.len(), "{name}: R's rows");
    let read: Vec<&Vec<&str>> = lines.iter().take_while(|l| l[0] != "rows").collect();
    assert_eq!(
        read.iter().map(|l| l[0]).collect::<Vec<_>>(),
        names,
        "{name}: R's columns"
    );
    for (l, (column, kind)) in read.iter().zip(columns) {
        let missing: u64 = l[2].parse().unwrap();
        assert!(
            r_reads_as(kind, l[1], missing, n),
            "{name}: R reads {column} ({kind}) as {}",
            l[1]
        );
    }
    let values = |column: &str| -> Vec<&str> {
        lines
            .iter()
            .find(|l| l[0] == "value" && l[1] == column)
            .map(|l| l[2..].to_vec())
            .unwrap()
    };
    let (subject, trial, score, time) = (
        values("subject"),
        values("trial_index"),
        values("score"),
        values("response_time_ms"),
    );
    for (i, (s, r)) in rows.iter().enumerate() {
        assert_eq!(subject[i], s.manifest.subject, "{name}: R row {i}");
        assert_eq!(
            trial[i].parse::<f64>().unwrap(),
            f64::from(r.trial.index),
            "{name}: R row {i}"
        );
        assert_eq!(
            score[i].parse::<f64>().unwrap(),
            r.outcome.score,
            "{name}: R row {i}"
        );
        assert_eq!(
            time[i].parse::<f64>().unwrap(),
            r.response.response_time_ms as f64,
            "{name}: R row {i}"
        );
    }
}
