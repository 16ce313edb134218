//! What `study` says about a wrong, missing or empty input, from the real binary: every message
//! names its file; a study file's problems (and a crowd scene's) their line and key, a key
//! typo the key it likely meant; the JSON manifest's its line and column. And the progress
//! bars: drawn on a terminal, never on a standard error that is not one.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// A fresh scratch folder for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("study-messages-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

/// The standard error of `study ARGS`, which must fail; a stderr that is not a terminal holds
/// no progress bar (no carriage return, no escape sequence).
fn refused(args: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} succeeded: {err}");
    assert!(err.starts_with("error: "), "{args:?}: {err}");
    assert!(!err.contains(['\r', '\x1b']), "{args:?}: {err:?}");
    err
}

/// The standard error of `study ARGS`, which must succeed, with no progress bar in it.
fn quiet_ok(args: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{args:?}: {err}");
    assert!(!err.contains(['\r', '\x1b']), "{args:?}: {err:?}");
    err
}

/// The 1-based line of `text` that starts with `start`, which must be there once.
fn line_of(text: &str, start: &str) -> usize {
    let lines: Vec<usize> = (1..)
        .zip(text.lines())
        .filter(|(_, l)| l.trim_start().starts_with(start))
        .map(|(n, _)| n)
        .collect();
    assert_eq!(lines.len(), 1, "{start:?} in\n{text}");
    lines[0]
}

/// The one line of `err` that starts with `start` (after its indent).
fn said<'a>(err: &'a str, start: &str) -> &'a str {
    let found: Vec<&str> = err
        .lines()
        .map(str::trim_start)
        .filter(|l| l.starts_with(start))
        .collect();
    assert_eq!(found.len(), 1, "{start:?} in\n{err}");
    found[0]
}

/// `examples/NAME` with each `(from, to)` replaced once and the manifest named by absolute
/// path, written as `dir/file`; returns its path and text.
fn study_file(dir: &Path, name: &str, file: &str, edits: &[(&str, &str)]) -> (String, String) {
    let mut text = std::fs::read_to_string(examples().join(name)).unwrap();
    for (from, to) in edits {
        assert_eq!(text.matches(from).count(), 1, "{from:?} in {name}");
        text = text.replacen(from, to, 1);
    }
    let manifest = examples().join("stimuli.json");
    text = text.replacen(
        "stimuli = \"stimuli.json\"",
        &format!("stimuli = {:?}", manifest.display().to_string()),
        1,
    );
    let path = dir.join(file);
    std::fs::write(&path, &text).unwrap();
    (path.display().to_string(), text)
}

#[test]
fn a_key_typo_is_named_with_its_file_line_and_the_key_it_likely_meant() {
    let dir = scratch("typo");
    let (p, text) = study_file(
        &dir,
        "mos.toml",
        "typo.toml",
        &[
            ("\nname = ", "\nnmae = "),
            ("gap_ms = 500", "gap_mss = 500"),
            ("[presentation]\n", "[presentation]\ncolour = \"red\"\n"),
            (
                "arrangement = \"side_by_side\"",
                "arrangement = \"side_by_sid\"",
            ),
        ],
    );
    for command in ["check", "simulate"] {
        let mut args = vec![command, p.as_str()];
        let out = dir.join("out").display().to_string();
        if command == "simulate" {
            args.extend(["-o", &out]);
        }
        let err = refused(&args);
        assert_eq!(
            err.matches(&format!("{p}: 5 problem(s):")).count(),
            1,
            "{err}"
        );
        assert!(
            said(&err, &format!("{p}:{}: nmae: ", line_of(&text, "nmae ="))).starts_with(&format!(
                "{p}:{}: nmae: unknown key, did you mean \"name\"? (allowed: format_version, \
                     name, title,",
                line_of(&text, "nmae =")
            )),
            "{err}"
        );
        // A missing key at the top level has no line to point at.
        assert_eq!(
            said(&err, &format!("{p}: name: ")),
            format!("{p}: name: missing")
        );
        let gap = said(&err, &format!("{p}:{}: ", line_of(&text, "gap_mss =")));
        assert!(
            gap.contains("presentation.gap_mss: unknown key, did you mean \"gap_ms\"? (allowed: "),
            "{err}"
        );
        // Nothing allowed is close to `colour`: no guess, only the list.
        let colour = said(&err, &format!("{p}:{}: ", line_of(&text, "colour =")));
        assert!(
            colour.starts_with(&format!(
                "{p}:{}: presentation.colour: unknown key (allowed: arrangement,",
                line_of(&text, "colour =")
            )),
            "{err}"
        );
        let arrangement = said(&err, &format!("{p}:{}: ", line_of(&text, "arrangement =")));
        assert!(
            arrangement.contains("presentation.arrangement: expected one of ")
                && arrangement.ends_with("got \"side_by_sid\", did you mean \"side_by_side\"?"),
            "{err}"
        );
        assert!(!dir.join("out").exists());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Keys in arrays of tables, array elements and dotted keys are found in the file too.
#[test]
fn problems_in_arrays_of_tables_elements_and_dotted_keys_have_lines() {
    let dir = scratch("nested");
    let (p, text) = study_file(
        &dir,
        "groups.toml",
        "nested.toml",
        &[
            (
                "subject_fields = [\"age\"]",
                "subject_fields = [\n  \"age\",\n  3,\n]",
            ),
            (
                "quota = 12\n\n[[design.groups]]",
                "quota = 12\n\n[[design.groups]]\ncolour = 1",
            ),
            (
                "[conditions]\n",
                "rendering.ground_shadw = false\n\n[conditions]\n",
            ),
        ],
    );
    let err = refused(&["check", &p]);
    let element = line_of(&text, "3,");
    assert_eq!(
        said(&err, &format!("{p}:{element}: ")),
        format!(
            "{p}:{element}: session.subject_fields[1]: expected a name or a field table, got an \
             integer"
        )
    );
    let colour = line_of(&text, "colour = 1");
    assert!(
        said(&err, &format!("{p}:{colour}: ")).starts_with(&format!(
            "{p}:{colour}: design.groups[1].colour: unknown key (allowed: "
        )),
        "{err}"
    );
    let dotted = line_of(&text, "rendering.ground_shadw");
    assert!(
        said(&err, &format!("{p}:{dotted}: ")).starts_with(&format!(
            "{p}:{dotted}: rendering.ground_shadw: unknown key, did you mean \"ground_shadow\"?"
        )),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `study crowd` reads only a file's `[scene]`: its problems have lines too, an inline
/// table's keys and a missing key of an array of tables' entry (the entry's header).
#[test]
fn a_crowd_scene_problem_has_its_line() {
    let dir = scratch("scene");
    let mut text = std::fs::read_to_string(examples().join("crowd-run1.toml")).unwrap();
    text = text
        .replacen("fov_deg = 40 }", "fov_dg = 40 }", 1)
        .replacen("x_cm = -260", "x_cn = -260", 1)
        .replacen("name = \"back_left\"\n", "", 1);
    let p = dir.join("scene.toml").display().to_string();
    std::fs::write(&p, &text).unwrap();
    let march = examples().join("stimuli/march/reference.bvh");
    std::fs::copy(&march, dir.join("march.bvh")).unwrap();
    let out = dir.join("out").display().to_string();
    let clip = dir.join("march.bvh").display().to_string();
    let err = refused(&[
        "crowd",
        &p,
        "--clips",
        &clip,
        "--budget-cr",
        "20",
        "-o",
        &out,
    ]);
    let camera = line_of(&text, "camera = {");
    assert!(
        said(&err, &format!("{p}:{camera}: ")).starts_with(&format!(
            "{p}:{camera}: scene.camera.fov_dg: unknown key, did you mean \"fov_deg\"?"
        )),
        "{err}"
    );
    let typo = line_of(&text, "x_cn =");
    assert!(
        said(&err, &format!("{p}:{typo}: ")).starts_with(&format!(
            "{p}:{typo}: scene.characters[1].x_cn: unknown key, did you mean \"x_cm\"?"
        )),
        "{err}"
    );
    // The second character's entry lacks its name: the line of its `[[scene.characters]]`.
    let header = (1..)
        .zip(text.lines())
        .filter(|(_, l)| *l == "[[scene.characters]]")
        .nth(1)
        .unwrap()
        .0;
    assert_eq!(
        said(&err, &format!("{p}:{header}: ")),
        format!("{p}:{header}: scene.characters[1].name: missing")
    );
    assert!(!dir.join("out").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Syntax errors: a study file's with line and column; a stimulus manifest's with its own
/// file, line and column, under the study file's line of `stimuli`.
#[test]
fn syntax_errors_name_file_line_and_column() {
    let dir = scratch("syntax");
    let (p, text) = study_file(
        &dir,
        "mos.toml",
        "broken.toml",
        &[("seed = 20110512", "seed = = 1")],
    );
    let line = line_of(&text, "seed =");
    let err = refused(&["check", &p]);
    assert!(err.starts_with(&format!("error: {p}:{line}:")), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");

    let manifest = dir.join("stimuli.json");
    std::fs::write(
        &manifest,
        "{\"version\": 1,\n \"stimuli\": [\n  {\"id\": 1}\n]}",
    )
    .unwrap();
    let text = std::fs::read_to_string(examples().join("mos.toml")).unwrap();
    let p = dir.join("study.toml").display().to_string();
    std::fs::write(&p, &text).unwrap();
    let err = refused(&["check", &p]);
    let stimuli = line_of(&text, "stimuli =");
    assert_eq!(
        said(&err, &format!("{p}:{stimuli}: ")),
        format!(
            "{p}:{stimuli}: stimuli: cannot load the stimulus manifest: {}:3:10: invalid type: \
             integer `1`, expected a string",
            manifest.display()
        )
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `study report` on a folder that is not results, has no sessions, or is not there, and
/// with a `--study` that is not there: the path once, and what is wrong in words.
#[test]
fn report_says_what_a_folder_lacks() {
    let dir = scratch("report");
    let out = dir.join("rep").display().to_string();
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let e = empty.display().to_string();
    let err = refused(&["report", &e, "-o", &out]);
    assert_eq!(
        err.trim_end(),
        format!(
            "error: {e} holds no results: no run.json (make results with `study run`, `study \
             simulate` or `study serve`)"
        )
    );
    let gone = dir.join("gone").display().to_string();
    let err = refused(&["report", &gone, "-o", &out]);
    assert_eq!(
        err.trim_end(),
        format!("error: {gone}: no such results folder")
    );

    let res = dir.join("res");
    let r = res.display().to_string();
    let mos = examples().join("mos.toml").display().to_string();
    quiet_ok(&["simulate", &mos, "-o", &r]);
    let missing = dir.join("missing.toml").display().to_string();
    let err = refused(&["report", &r, "--study", &missing, "-o", &out]);
    assert_eq!(err.matches(&missing).count(), 1, "{err}");
    assert!(
        err.starts_with(&format!("error: {missing}: cannot read: ")),
        "{err}"
    );

    std::fs::remove_dir_all(res.join("S001_s1")).unwrap();
    let err = refused(&["report", &r, "-o", &out]);
    assert_eq!(
        err.trim_end(),
        format!(
            "error: {r} holds no sessions yet: no session folder with a session.json (nothing to \
             report)"
        )
    );
    assert!(!dir.join("rep/report.md").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every command given a file that is not there names it, once.
#[test]
fn every_command_names_the_file_it_cannot_read() {
    let dir = scratch("missing");
    let nope = |name: &str| dir.join(name).display().to_string();
    let (toml, bvh, mcz, asf, db) = (
        nope("a.toml"),
        nope("a.bvh"),
        nope("a.mcz"),
        nope("a.asf"),
        nope("a.db"),
    );
    let out = nope("out");
    let bitstream = examples()
        .join("stimuli/walk/wavelet-perceptual-cr10.mcz")
        .display()
        .to_string();
    let reference = examples()
        .join("stimuli/walk/reference.bvh")
        .display()
        .to_string();
    let png = nope("a.png");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["check", &toml], &toml),
        (vec!["simulate", &toml, "-o", &out], &toml),
        (vec!["serve", &toml, "-o", &out], &toml),
        (
            vec![
                "sweep", "--clips", &bvh, "--codecs", "spiht", "--cr", "10", "-o", &out,
            ],
            &bvh,
        ),
        (
            vec![
                "crowd",
                &toml,
                "--clips",
                &bvh,
                "--budget-cr",
                "10",
                "-o",
                &out,
            ],
            &toml,
        ),
        (vec!["encode", &bvh, "--codec", "spiht", "-o", &out], &bvh),
        (
            vec![
                "encode", &reference, "--codec", "spiht", "--db", &db, "-o", &out,
            ],
            &db,
        ),
        (
            vec!["decode", &mcz, "--skeleton", &reference, "-o", &out],
            &mcz,
        ),
        (
            vec!["decode", &bitstream, "--skeleton", &asf, "-o", &out],
            &asf,
        ),
        (vec!["clip", "info", &bvh], &bvh),
        (
            vec!["clip", "render", &bvh, "--times", "0", "-o", &png],
            &bvh,
        ),
    ];
    for (args, file) in cases {
        let err = refused(&args);
        assert_eq!(err.matches(file).count(), 1, "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The long commands draw a progress bar on a terminal (under `script`, which gives the
/// command one) and none on a captured standard error, where their lines still arrive.
#[test]
fn progress_bars_show_on_a_terminal_only() {
    let dir = scratch("bars");
    let d = |name: &str| dir.join(name).display().to_string();
    let mos = examples().join("mos.toml").display().to_string();
    let march = examples().join("stimuli/march/reference.bvh");
    std::fs::copy(&march, dir.join("march.bvh")).unwrap();
    let crowd = examples().join("crowd-run1.toml").display().to_string();
    let clip = d("march.bvh");
    let err = quiet_ok(&["simulate", &mos, "-o", &d("sim"), "--subjects", "3"]);
    assert_eq!(
        err.lines()
            .filter(|l| l.ends_with(": Complete, 14 trials"))
            .count(),
        3,
        "{err}"
    );
    quiet_ok(&["report", &d("sim"), "-o", &d("rep")]);
    quiet_ok(&[
        "sweep",
        "--clips",
        &clip,
        "--codecs",
        "spiht",
        "--cr",
        "10,20",
        "-o",
        &d("sweep"),
    ]);
    quiet_ok(&[
        "crowd",
        &crowd,
        "--clips",
        &clip,
        "--cr",
        "front=40",
        "--cr",
        "back=20",
        "-o",
        &d("crowd"),
    ]);
    quiet_ok(&["check", &mos]);

    // On a terminal: `script` runs the command on a pseudo-terminal and logs what it drew.
    if !common::have("script") {
        assert!(
            std::env::var_os("CI").is_none(),
            "`script` (util-linux) is needed under CI"
        );
        eprintln!("skipped the terminal half: no `script`");
        return;
    }
    let command = format!(
        "{} simulate {mos} -o {} --subjects 3",
        env!("CARGO_BIN_EXE_study"),
        d("tty")
    );
    let tty = Command::new("script")
        .args(["-qec", &command, &d("typescript")])
        .output()
        .unwrap();
    assert!(tty.status.success(), "{tty:?}");
    let drawn = String::from_utf8_lossy(&std::fs::read(d("typescript")).unwrap()).into_owned();
    assert!(
        drawn.contains("/3 sessions") && drawn.contains('\r'),
        "{drawn:?}"
    );
    assert!(drawn.contains("stimuli checked"), "{drawn:?}");
    assert!(drawn.contains("S003: Complete, 14 trials"), "{drawn:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}
