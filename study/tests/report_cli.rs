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

/// `study simulate examples/EXAMPLE -o OUT ARGS...`, which must succeed.
fn simulate(example: &str, out: &Path, args: &[&str]) {
    let study_file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(example);
    let mut all = vec![
        "simulate".to_owned(),
        study_file.display().to_string(),
        "-o".to_owned(),
        out.display().to_string(),
    ];
    all.extend(args.iter().map(|a| (*a).to_owned()));
    let all: Vec<&str> = all.iter().map(String::as_str).collect();
    let o = study(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn report_finds_the_archived_study_and_manifest() {
    let dir = std::env::temp_dir().join(format!("study-report-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let res = dir.join("res").display().to_string();
    simulate(
        "mos.toml",
        Path::new(&res),
        &["--subjects", "3", "--seed", "5"],
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

/// A folder that is not a results folder, or one with no session yet, is refused with its
/// path and the reason, said once, and no report is written.
#[test]
fn report_names_a_folder_without_results() {
    let dir = std::env::temp_dir().join(format!("study-report-empty-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("empty")).unwrap();
    let refused = |results: &Path, reason: &str| {
        let rep = dir.join("rep");
        let out = study(&[
            "report",
            &results.display().to_string(),
            "-o",
            &rep.display().to_string(),
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        let said = format!("{}{reason}", results.display());
        assert_eq!(err.matches(&said).count(), 1, "{err}");
        assert!(!rep.join("report.md").exists());
    };
    refused(&dir.join("nowhere"), ": no such results folder");
    refused(
        &dir.join("empty"),
        " holds no results: no run.json (make results with `study run`",
    );
    // A run begun and no session recorded: simulate made it, then its sessions are gone.
    let res = dir.join("res");
    simulate("mos.toml", &res, &["--subjects", "1"]);
    std::fs::remove_dir_all(res.join("S001_s1")).unwrap();
    refused(
        &res,
        " holds no sessions yet: no session folder with a session.json",
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Staircase levels lie on an exact grid: the log holds one value per grid point, and no
/// staircase table lists a level twice (accumulated steps once gave 0.0020 twice, and
/// 0.0100 twice with different answers).
#[test]
fn staircase_tables_list_each_level_once() {
    let dir = std::env::temp_dir().join(format!("study-report-grid-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let res = dir.join("res").display().to_string();
    let rep = dir.join("rep");
    simulate(
        "staircase.toml",
        Path::new(&res),
        &["--subjects", "15", "--seed", "1"],
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
        // examples/staircase.toml: 0.004 to 0.040 in steps of 0.006.
        let k = (v - 0.004) / 0.006;
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
    assert!(levels.len() >= 5, "{table}");
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

/// A damaged copy: its name, the edit that damages it, what the error must say, and the line
/// of `S001_s1/trials.csv` it must name.
type Damage = (&'static str, fn(&Path), &'static str, Option<usize>);

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
    let dir = std::env::temp_dir().join(format!("study-report-integrity-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let clean = dir.join("clean");
    simulate("mos.toml", &clean, &["--subjects", "3", "--seed", "5"]);
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
    let cases: [Damage; 7] = [
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
        rows.truncate(rows.len() - 4);
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
    // The tidy export holds every trial there is: the incomplete session's too.
    let tidy = |name: &str| {
        std::fs::read_to_string(dir.join(format!("{name}-report/trials_tidy.csv")))
            .unwrap()
            .lines()
            .count()
            - 1
    };
    assert_eq!(tidy("truncated"), tidy("clean") - 4);
    // Damage is refused even with --allow-incomplete.
    let out = report(
        &dir.join("duplicated"),
        "duplicated-allowed",
        &["--allow-incomplete"],
    );
    assert!(!out.status.success());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Splits one CSV line (RFC 4180 quoting, no line breaks inside fields).
fn csv_fields(line: &str) -> Vec<String> {
    let (mut fields, mut field, mut quoted) = (Vec::new(), String::new(), false);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field)),
            _ => field.push(c),
        }
    }
    fields.push(field);
    fields
}

/// Reads a report table (`tables/NAME.csv`): header and rows.
fn table(dir: &Path, name: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(dir.join(format!("tables/{name}.csv"))).unwrap();
    let mut lines = text.lines().map(csv_fields);
    let header = lines.next().unwrap();
    (header, lines.collect())
}

fn col(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name:?} in {header:?}"))
}

/// Issue 18: one treatment of repeats everywhere (a condition's mean in `mos.csv` is the one
/// `ttests.csv` tests, n = subjects), tests that say their kind and tails, subjects by their
/// ids, DSCQS judged on differences with limits in the scale's units, a constant rater left
/// out of the z-scores with a note instead of stopping the report, and the display section.
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "one study per protocol, each table read"
)]
fn report_tables_agree_and_say_what_they_are() {
    let dir = std::env::temp_dir().join(format!("study-report-agree-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let simulated = |name: &str, subjects: &str| {
        let res = dir.join(format!("{name}-res"));
        simulate(
            &format!("{name}.toml"),
            &res,
            &["--subjects", subjects, "--seed", "7"],
        );
        res
    };
    let report = |res: &Path, name: &str, extra: &[&str]| {
        let rep = dir.join(name);
        let mut args = vec![
            "report".to_owned(),
            res.display().to_string(),
            "-o".to_owned(),
            rep.display().to_string(),
            "--no-png".to_owned(),
        ];
        args.extend(extra.iter().map(|s| (*s).to_owned()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = study(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        rep
    };
    // MOS with 8 hidden repeats: the MOS table's mean of every tested condition is the mean
    // its t-test row prints, and n is the number of subjects.
    let mos_res = simulated("mos", "6");
    let rep = report(&mos_res, "mos-report", &[]);
    let (h, rows) = table(&rep, "mos");
    let (codec, clip, cr, n, mean) = (
        col(&h, "Codec"),
        col(&h, "Clip"),
        col(&h, "CR"),
        col(&h, "n"),
        col(&h, "Mean"),
    );
    let mos: std::collections::HashMap<(String, String, String), String> = rows
        .iter()
        .map(|r| {
            (
                (r[codec].clone(), r[clip].clone(), r[cr].clone()),
                r[mean].clone(),
            )
        })
        .collect();
    assert!(rows.iter().all(|r| r[n] == "6"), "n = subjects: {rows:?}");
    let (h, rows) = table(&rep, "ttests");
    assert!(!rows.is_empty());
    let (tclip, tcr, test) = (col(&h, "Clip"), col(&h, "CR"), col(&h, "Test"));
    for r in &rows {
        for (m, v) in [("Method A", "Mean A"), ("Method B", "Mean B")] {
            let key = (r[col(&h, m)].clone(), r[tclip].clone(), r[tcr].clone());
            assert_eq!(mos[&key], r[col(&h, v)], "{key:?}");
        }
        assert_eq!(r[test], "paired t, two-tailed");
        let p = &r[col(&h, "p")];
        assert!(p == "< 0.001" || p.parse::<f64>().is_ok(), "{p}");
    }
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(md.contains("two-tailed"), "the caption says the tails");
    assert!(md.contains("n = subjects"));
    let (h, rows) = table(&rep, "screening");
    assert!(
        rows.iter().all(|r| r[col(&h, "Subject")].starts_with('S')),
        "{rows:?}"
    );
    let (h, rows) = table(&rep, "display");
    assert_eq!(rows.len(), 6);
    assert!(rows.iter().all(|r| r[col(&h, "Session")].starts_with('S')));
    // Pooled on request, and labelled so: n = ratings where a repeat fell.
    let pooled = report(&mos_res, "mos-pooled", &["--pool-repeats"]);
    let (h, rows) = table(&pooled, "mos");
    assert!(
        rows.iter()
            .any(|r| r[col(&h, "n")].parse::<u32>().unwrap() > 6)
    );
    assert!(
        std::fs::read_to_string(pooled.join("report.md"))
            .unwrap()
            .contains("Repeats pooled")
    );
    // A constant rater: every score of S002 set to 3. --zscore leaves S002 out with a note.
    let trials = mos_res.join("S002_s1/trials.csv");
    let text = std::fs::read_to_string(&trials).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let (response, score) = (
        header.iter().position(|c| *c == "response").unwrap(),
        header.iter().position(|c| *c == "score").unwrap(),
    );
    for line in &mut lines[1..] {
        let mut f: Vec<String> = line.split(',').map(str::to_owned).collect();
        f[response] = "3".into();
        f[score] = "3".into();
        *line = f.join(",");
    }
    std::fs::write(&trials, lines.join("\n") + "\n").unwrap();
    let z = report(&mos_res, "mos-z", &["--zscore"]);
    let md = std::fs::read_to_string(z.join("report.md")).unwrap();
    assert!(
        md.contains("Left out of the z-scores") && md.contains("S002"),
        "{md}"
    );
    // DSCQS on 0-100: limits default to the scale (87.5 and 5), printed with it; the t-tests
    // and the screening are on reference − test differences.
    let dscqs_res = simulated("dscqs", "8");
    let rep = report(&dscqs_res, "dscqs-report", &[]);
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(md.contains("DMOS 5 (scale 0–100)"), "{md}");
    assert!(md.contains("MOS 87.5 (scale 0–100)"), "{md}");
    assert!(md.contains("on the reference − test differences"), "{md}");
    let (h, rows) = table(&rep, "ttests");
    let (h_dmos, dmos_rows) = table(&rep, "dmos_ci");
    let dmos: std::collections::HashMap<(String, String, String), String> = dmos_rows
        .iter()
        .map(|r| {
            (
                (
                    r[col(&h_dmos, "Codec")].clone(),
                    r[col(&h_dmos, "Clip")].clone(),
                    r[col(&h_dmos, "CR")].clone(),
                ),
                r[col(&h_dmos, "Mean")].clone(),
            )
        })
        .collect();
    for r in &rows {
        let key = (
            r[col(&h, "Method A")].clone(),
            r[col(&h, "Clip")].clone(),
            r[col(&h, "CR")].clone(),
        );
        assert_eq!(
            dmos[&key],
            r[col(&h, "Mean A")],
            "DSCQS tests the DMOS: {key:?}"
        );
    }
    let out = study(&[
        "report",
        &dscqs_res.display().to_string(),
        "-o",
        &dir.join("dscqs-bad").display().to_string(),
        "--mos-limit",
        "150",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--mos-limit 150") && err.contains("0-100"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The stimuli of `examples/FILE`'s trial: one pass of a side-by-side trial lasts its
/// reference clip, `Frames` × `Frame Time` of its BVH file, seconds.
fn bvh_seconds(file: &Path) -> f64 {
    let text = std::fs::read_to_string(file).unwrap();
    let value = |key: &str| -> f64 {
        text.lines()
            .find_map(|l| l.trim().strip_prefix(key))
            .unwrap()
            .trim()
            .parse()
            .unwrap()
    };
    value("Frames:") * value("Frame Time:")
}

/// Issue 37: a log whose answers came sooner after the one before than the trial's stimuli
/// play (as a scripted client of an older server wrote them) is flagged by `study report`,
/// naming the session, the trial and both times; `[crowdsourcing] too_fast = "exclude"`
/// leaves such sessions out of every statistic. The three sessions are simulated, then made
/// to look taken by subjects: no observer seed, and answer times rewritten on both clocks:
/// S001 a minute apart, S002 20 ms apart, S003 a minute apart but trial 5 20 ms after trial 4.
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "two runs, each made to look taken by subjects and reported"
)]
fn report_flags_answers_sooner_than_the_stimuli_play_and_the_study_can_exclude_them() {
    let dir = std::env::temp_dir().join(format!("study-report-too-fast-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let excluding = dir.join("mos-excluding.toml");
    let text = std::fs::read_to_string(examples.join("mos.toml"))
        .unwrap()
        .replace(
            "stimuli = \"stimuli.json\"",
            &format!(
                "stimuli = {:?}",
                examples.join("stimuli.json").display().to_string()
            ),
        );
    std::fs::write(
        &excluding,
        text + "\n[crowdsourcing]\ntoo_fast = \"exclude\"\n",
    )
    .unwrap();
    let humanize = |res: &Path| {
        for (subject, gaps) in [
            ("S001", None),
            ("S002", Some(0..usize::MAX)),
            ("S003", Some(5..6)),
        ] {
            let session = res.join(format!("{subject}_s1"));
            let mut m: serde_json::Value =
                serde_json::from_slice(&std::fs::read(session.join("session.json")).unwrap())
                    .unwrap();
            m["observer_seed"] = serde_json::Value::Null;
            let start = m["started_ms"].as_u64().unwrap();
            std::fs::write(session.join("session.json"), m.to_string()).unwrap();
            let text = std::fs::read_to_string(session.join("trials.csv")).unwrap();
            let header = csv_fields(text.lines().next().unwrap());
            let (wall, mono) = (col(&header, "wall_clock_ms"), col(&header, "monotonic_ms"));
            let (mut at_wall, mut at_mono) = (start, 0);
            edit_rows(&session.join("trials.csv"), |rows| {
                for (i, row) in rows.iter_mut().enumerate() {
                    let step = if gaps.as_ref().is_some_and(|g| g.contains(&i)) {
                        20
                    } else {
                        60_000
                    };
                    at_wall += step;
                    at_mono += step;
                    let mut f = csv_fields(row);
                    assert!(f.iter().all(|x| !x.contains([',', '"'])), "{row}");
                    f[wall] = at_wall.to_string();
                    f[mono] = at_mono.to_string();
                    *row = f.join(",");
                }
            });
        }
    };
    let report = |res: &Path, name: &str| {
        let rep = dir.join(name);
        let out = study(&[
            "report",
            res.to_str().unwrap(),
            "-o",
            rep.to_str().unwrap(),
            "--no-png",
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
        let ratings = std::fs::read_to_string(rep.join("ratings.csv"))
            .unwrap()
            .lines()
            .count()
            - 1;
        (rep, md, ratings)
    };
    let flagged = dir.join("flagged");
    simulate("mos.toml", &flagged, &["--subjects", "3", "--seed", "5"]);
    let (_, _, all_ratings) = report(&flagged, "simulated");
    humanize(&flagged);
    let (rep, md, ratings) = report(&flagged, "flagged-report");
    assert!(
        md.contains(
            "2 sessions answered trials sooner after the answer before than their stimuli play"
        ) && md.contains("S002 session 1, S003 session 1")
            && md.contains("they are kept, flagged"),
        "{md}"
    );
    assert_eq!(ratings, all_ratings, "flagged sessions are kept");
    let (header, rows) = table(&rep, "exclusions");
    let fast = col(&header, "Answered too fast");
    let sessions: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(sessions, ["S002 session 1", "S003 session 1"]);
    // S003's trial 5 shows a reference clip whose one pass (side by side, played once) is
    // what it must have played before the answer.
    let s3 = results::read_session(&flagged.join("S003_s1")).unwrap();
    let trial5 = &s3.trials.records[5].trial;
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(examples.join("stimuli.json")).unwrap()).unwrap();
    let file = manifest["stimuli"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == trial5.reference.as_str())
        .unwrap()["file"]
        .as_str()
        .unwrap();
    let need = bvh_seconds(&examples.join(file));
    assert!(need > 1.0, "{need}");
    assert_eq!(rows[1][fast], format!("trial 5 (0.0 s of {need:.1} s)"));
    assert!(
        rows[0][fast].starts_with("trial 0 (0.0 s of ") && rows[0][fast].ends_with(" 11 more"),
        "{:?}",
        rows[0][fast]
    );
    assert!(rows.iter().all(|r| r[col(&header, "Excluded")].is_empty()));

    let excluded = dir.join("excluded");
    let o = study(&[
        "simulate",
        excluding.to_str().unwrap(),
        "-o",
        excluded.to_str().unwrap(),
        "--subjects",
        "3",
        "--seed",
        "5",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    humanize(&excluded);
    let (rep, md, ratings) = report(&excluded, "excluded-report");
    assert!(
        md.contains("left out 2 of 3 sessions (S002 session 1, S003 session 1)")
            && md.contains("they are left out"),
        "{md}"
    );
    assert_eq!(ratings * 3, all_ratings, "only S001's ratings");
    let (header, rows) = table(&rep, "exclusions");
    assert!(rows.iter().all(|r| r[col(&header, "Excluded")] == "yes"));
    std::fs::remove_dir_all(&dir).unwrap();
}
