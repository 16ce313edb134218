//! Nobody writes outside their folder, nothing is taken over, nothing of another study is
//! resumed: the study name is a safe folder name, `study run -o` refuses a folder holding
//! anything but this study's results, `--resume` refuses another study, another version of
//! the study file, and logs whose rows belong to another session, each naming what it found.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use results::trials::{encode_row_as, read_trials};

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("safety-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `examples/<name>` and the stimulus manifest it names, copied into `dir` (its files linked).
fn copy_example(dir: &Path, name: &str) -> PathBuf {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    std::fs::copy(examples.join("stimuli.json"), dir.join("stimuli.json")).unwrap();
    // The manifest's files (a second example in the same folder finds the link there).
    let _ = std::os::unix::fs::symlink(examples.join("stimuli"), dir.join("stimuli"));
    let to = dir.join(name);
    std::fs::copy(examples.join(name), &to).unwrap();
    to
}

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        // The refusals must come before any window is opened.
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Marks a finished session as interrupted (so `--resume` replays it).
fn mark_running(session: &Path) {
    let manifest = session.join("session.json");
    let m = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(&manifest, m.replace("\"complete\"", "\"running\"")).unwrap();
}

/// Rewrites `trials` with its first `keep` rows, `edit` applied to row `row`; returns the text.
fn rewrite_rows(
    trials: &Path,
    keep: usize,
    row: usize,
    edit: impl FnOnce(&mut protocols::TrialRecord),
) -> String {
    let file = read_trials(trials).unwrap();
    let header = std::fs::read_to_string(trials).unwrap();
    let mut text = format!("{}\n", header.lines().next().unwrap());
    let mut edit = Some(edit);
    for (i, rec) in file.records.iter().take(keep).enumerate() {
        let mut rec = rec.clone();
        if i == row {
            (edit.take().unwrap())(&mut rec);
        }
        text.push_str(&encode_row_as(&rec, file.format_version).unwrap());
    }
    std::fs::write(trials, &text).unwrap();
    text
}

fn set_name(study: &Path, name: &str) {
    let text = std::fs::read_to_string(study).unwrap();
    let line = text.lines().find(|l| l.starts_with("name = ")).unwrap();
    std::fs::write(study, text.replacen(line, &format!("name = {name:?}"), 1)).unwrap();
}

#[test]
fn study_names_that_are_not_safe_folder_names_are_refused_by_check() {
    let dir = scratch("names");
    let file = copy_example(&dir, "mos.toml");
    for bad in [
        "x/../../../ESCAPED",
        "..",
        "a/b",
        ".hidden",
        "a b",
        "ü",
        &"n".repeat(65),
    ] {
        set_name(&file, bad);
        let o = study(&["check", p(&file)]);
        let err = stderr(&o);
        assert!(!o.status.success(), "{bad:?} accepted");
        assert!(
            err.contains("mos.toml") && err.contains("name"),
            "{bad:?}: {err}"
        );
        assert!(err.contains("letters, digits"), "{bad:?}: {err}");
        // Said once.
        assert_eq!(err.matches("letters, digits").count(), 1, "{err}");
    }
    for good in ["mos-paper-000", "a", "Study_2.v1", &"n".repeat(64)] {
        set_name(&file, good);
        let o = study(&["check", p(&file)]);
        assert!(o.status.success(), "{good:?}: {}", stderr(&o));
    }
    assert!(!dir.join("../../../ESCAPED").exists());
}

#[test]
fn run_refuses_a_folder_that_holds_other_files_unless_forced() {
    let dir = scratch("run-o");
    let file = copy_example(&dir, "mos.toml");
    let out = dir.join("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("thesis.tex"), "x").unwrap();
    std::fs::write(out.join("study.toml"), "name = \"someone else's\"\n").unwrap();
    let o = study(&["run", p(&file), "--subject", "S01", "-o", p(&out)]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("thesis.tex") && err.contains("--force"),
        "{err}"
    );
    assert!(err.contains(p(&out)), "{err}");
    assert!(
        !out.join("run.json").exists(),
        "nothing written into the refused folder"
    );
    // With --force the folder is accepted (and the run goes on to need a display).
    let o = study(&[
        "run",
        p(&file),
        "--subject",
        "S01",
        "-o",
        p(&out),
        "--force",
    ]);
    assert!(stderr(&o).contains("no display"), "{}", stderr(&o));
    // A session folder of a study is results, not foreign: a folder holding only a simulated
    // run of this study is taken without --force.
    let sim = dir.join("sim");
    let o = study(&[
        "simulate",
        p(&file),
        "--subjects",
        "2",
        "--seed",
        "1",
        "-o",
        p(&sim),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = study(&["run", p(&file), "--subject", "S01", "-o", p(&sim)]);
    assert!(stderr(&o).contains("no display"), "{}", stderr(&o));
}

#[test]
fn resuming_another_study_or_another_version_of_it_is_refused() {
    let dir = scratch("identity");
    let mos = copy_example(&dir, "mos.toml");
    let dscqs = copy_example(&dir, "dscqs.toml");
    let out = dir.join("results");
    let sim = |file: &Path, resume: bool| {
        let mut a = vec![
            "simulate",
            p(file),
            "--subjects",
            "2",
            "--seed",
            "4",
            "-o",
            p(&out),
        ];
        if resume {
            a.push("--resume");
        }
        study(&a)
    };
    let o = sim(&mos, false);
    assert!(o.status.success(), "{}", stderr(&o));
    // Another study into the folder: refused, naming both.
    let o = sim(&dscqs, true);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("mos-paper-000") && err.contains("dscqs-thesis-ch6"),
        "{err}"
    );
    // `study run` into it likewise.
    let o = study(&["run", p(&dscqs), "--subject", "S01", "-o", p(&out)]);
    let err = stderr(&o);
    assert!(
        err.contains("mos-paper-000") && err.contains("dscqs-thesis-ch6"),
        "{err}"
    );
    // The same study, edited: refused, naming the file and both hashes.
    let text = std::fs::read_to_string(&mos).unwrap();
    std::fs::write(&mos, format!("{text}\n# edited\n")).unwrap();
    let o = sim(&mos, true);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("mos.toml") && err.contains("another version"),
        "{err}"
    );
    std::fs::write(&mos, &text).unwrap();
    let o = sim(&mos, true);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn resume_refuses_rows_of_another_session_naming_file_and_line() {
    let dir = scratch("rows");
    let mos = copy_example(&dir, "mos.toml");
    let out = dir.join("results");
    let o = study(&[
        "simulate",
        p(&mos),
        "--subjects",
        "1",
        "--seed",
        "4",
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let session = out.join("S001_s1");
    // Interrupt the session after its rows, then put a row of another subject in its log.
    mark_running(&session);
    rewrite_rows(&session.join("trials.csv"), 6, 4, |rec| {
        rec.subject = "S777".into();
    });
    let o = study(&[
        "simulate",
        p(&mos),
        "--subjects",
        "1",
        "--seed",
        "4",
        "-o",
        p(&out),
        "--resume",
    ]);
    let err = stderr(&o);
    assert!(!o.status.success());
    // Row 5 is on line 6 (line 1 is the header).
    assert!(
        err.contains("trials.csv line 6") && err.contains("S777"),
        "{err}"
    );
}

#[test]
fn resume_refuses_a_live_row_whose_codec_parameters_the_study_does_not_give() {
    let dir = scratch("live");
    let study_file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/live-staircase.toml");
    let out = dir.join("results");
    let args = |resume: bool| {
        let mut a = vec![
            "simulate",
            p(&study_file),
            "--subjects",
            "1",
            "--seed",
            "2",
            "-o",
            p(&out),
        ];
        if resume {
            a.push("--resume");
        }
        a
    };
    let o = study(&args(false));
    assert!(o.status.success(), "{}", stderr(&o));
    let session = out.join("S001_s1");
    mark_running(&session);
    let trials = session.join("trials.csv");
    let text = rewrite_rows(&trials, 5, 2, |rec| {
        let enc = rec.encoding.as_mut().unwrap();
        *enc.codec_params.get_mut("window").unwrap() = 256.0;
    });
    let o = study(&args(true));
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("trials.csv line 4") && err.contains("\"window\""),
        "{err}"
    );
    // The rows before it resume.
    let good: String = text.lines().take(3).flat_map(|l| [l, "\n"]).collect();
    std::fs::write(&trials, good).unwrap();
    let o = study(&args(true));
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn messages_name_their_file_and_say_their_cause_once() {
    let dir = scratch("messages");
    let mos = copy_example(&dir, "mos.toml");
    // A stimulus manifest's own problem names the manifest, not only the study file.
    let manifest = dir.join("stimuli.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let first = json["stimuli"][0]["id"].clone();
    json["stimuli"][1]["id"] = first;
    std::fs::write(&manifest, json.to_string()).unwrap();
    let o = study(&["check", p(&mos)]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("stimuli.json: stimuli[1]") && err.contains("listed twice"),
        "{err}"
    );
    // A missing file: its path and the OS's reason, once.
    std::fs::remove_file(&manifest).unwrap();
    let o = study(&["check", p(&mos)]);
    let err = stderr(&o);
    assert!(err.contains("stimuli.json"), "{err}");
    assert_eq!(err.matches("No such file or directory").count(), 1, "{err}");
    // A results folder that is not there: its path and the reason, once.
    let o = study(&["report", p(&dir.join("nowhere")), "-o", p(&dir.join("r"))]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert_eq!(
        err.matches("nowhere: no such results folder").count(),
        1,
        "{err}"
    );
}

/// A level edited to 0 (which the Weibull fit could not take either) is not what the study
/// plans there: the log check refuses it before any fit, naming the file, the line and both
/// levels.
#[test]
fn report_names_the_row_of_an_edited_level() {
    let dir = scratch("level");
    let file = copy_example(&dir, "staircase.toml");
    let out = dir.join("results");
    let o = study(&[
        "simulate",
        p(&file),
        "--subjects",
        "2",
        "--seed",
        "3",
        "-o",
        p(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    rewrite_rows(
        &out.join("S002_s1").join("trials.csv"),
        usize::MAX,
        7,
        |rec| {
            rec.trial.level = Some(0.0);
        },
    );
    let o = study(&["report", p(&out), "-o", p(&dir.join("report"))]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("S002_s1")
            && err.contains("trials.csv: line 9")
            && err.contains("logged level \"Some(0.0)\""),
        "{err}"
    );
}

#[test]
fn clip_commands_refuse_a_zero_direction_and_warn_of_a_normalised_one() {
    let dir = scratch("asf");
    let walk = motion::synth::WalkParams {
        duration_s: 0.5,
        ..motion::synth::WalkParams::default()
    };
    lab::generated::walk_stimuli(&dir, &walk, &["spiht"], &[10.0]).unwrap();
    let asf = dir.join("clips/walk.asf");
    let amc = dir.join("clips/walk.amc");
    let text = std::fs::read_to_string(&asf).unwrap();
    let (n, line) = text
        .lines()
        .enumerate()
        .find(|(_, l)| l.trim_start().starts_with("direction"))
        .unwrap();
    let with = |direction: &str| {
        std::fs::write(
            &asf,
            text.replacen(line, &format!("  direction {direction}"), 1),
        )
        .unwrap();
        study(&["clip", "info", "--asf", p(&asf), "--amc", p(&amc)])
    };
    let o = with("0 0 0");
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(err.contains(&format!("walk.asf:{}", n + 1)), "{err}");
    assert!(err.contains("zero"), "{err}");
    let o = with("0 -1000 0");
    assert!(!o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("walk.asf:{}", n + 1)),
        "{}",
        stderr(&o)
    );
    // Twice the unit length: read, normalised, and said once.
    let o = with("0 2 0");
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("warning: ").count(), 1, "{err}");
    assert!(err.contains(&format!("walk.asf:{}", n + 1)), "{err}");
}
