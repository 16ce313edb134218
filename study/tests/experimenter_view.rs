//! The experimenter's terminal during `study run` (`window/src/status.rs`): under Xvfb +
//! lavapipe, with keys from a test input script, a 4-trial MOS study (a practice trial, a
//! break after two trials, the experimenter's pause on the second) writes one line per event
//! on standard error, each answer's line matching its row in `trials.csv`; with `--quiet` it
//! writes none of them. And `study run` refuses a study whose stimulus file is missing before
//! any window opens or any folder is made.
//!
//! Needs `Xvfb`, `xdotool`, `import` and a Vulkan driver (`scripts/test` installs them);
//! without them the window tests fail under `CI` and are skipped elsewhere.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{Env, Scripted, setup};
use protocols::Answer::Rating;
use protocols::record::Block;

/// The shared walk stimuli and a MOS study: 1 familiarization + 2 test + 1 hidden-repeat
/// trial, a break before the third.
fn write_study(dir: &Path) -> PathBuf {
    common::write_walk_stimuli(dir);
    let study = dir.join("study.toml");
    std::fs::write(
        &study,
        "format_version = 1\nname = \"view\"\nprotocol = \"mos\"\nstimuli = \"stimuli/stimuli.json\"\n\
         seed = 3\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
         [presentation]\nplayback_count = 1\n\
         [session]\nfamiliarization = 1\nhidden_repeats = 1\nbreak_every_trials = 2\n",
    )
    .unwrap();
    study
}

/// `study run STUDY --subject S01 -o OUT [EXTRA]` with its keys from `script`.
fn run(env: &Env, name: &str, study: &Path, out: &Path, extra: &[&str], script: &str) -> Scripted {
    let mut args: Vec<&OsStr> = vec![
        "run".as_ref(),
        study.as_os_str(),
        "--subject".as_ref(),
        "S01".as_ref(),
        "--window-size".as_ref(),
        "640x480".as_ref(),
        "-o".as_ref(),
        out.as_os_str(),
    ];
    args.extend(extra.iter().map(OsStr::new));
    Scripted::spawn(env, name, &args, script)
}

/// `mm:ss` of a session clock in ms, as the experimenter reads it.
fn mm_ss(ms: u64) -> String {
    format!("{:02}:{:02}", ms / 60_000, ms / 1000 % 60)
}

/// The lines of `stderr` that are the experimenter's view (not the test input's, nor the
/// window's warnings).
fn view_lines(stderr: &str) -> Vec<&str> {
    const STARTS: [&str; 10] = [
        "stimuli checked:",
        "session ",
        "began:",
        "trial ",
        "practice trial ",
        "paused ",
        "resumed ",
        "break ",
        "finished:",
        "interrupted ",
    ];
    stderr
        .lines()
        .filter(|l| STARTS.iter().any(|s| l.starts_with(s)))
        .collect()
}

/// Every event of a session in order on standard error: the stimulus check, the session
/// opened, the subject beginning, each answer as logged (its value, response time, dropped
/// frames and session clock, a practice trial marked), the pause and the resume, the break,
/// and the end with the frames dropped in all.
#[test]
fn the_experimenter_sees_each_event_of_the_session_as_a_line() {
    let Some(env) = setup("view-lines") else {
        return;
    };
    let study = write_study(&env.dir);
    let out = env.dir.join("results");
    // Trial 1 rated 2; trial 2 paused by the experimenter as soon as its answers open,
    // resumed (Tab to Resume, Enter), then rated 4.5 (4, Up); the break; trials 3 and 4
    // rated 3 and 5; the end screen closed.
    let script = "welcome/ready: Enter\n\
                  trial/open once: 2 Enter\n\
                  trial/open once: Ctrl+Shift+P\n\
                  paused once: Tab Enter\n\
                  trial/open once: 4 Up Enter\n\
                  break: Enter\n\
                  trial/open once: 3 Enter\n\
                  trial/open once: 5 Enter\n\
                  end/ready: Enter\n";
    let session = run(&env, "lines", &study, &out, &[], script);
    let (status, stdout, stderr) = session.wait_exit();
    assert!(status.success(), "{stdout}\n{stderr}");
    let rows = results::trials::read_trials(&out.join("S01_s1/trials.csv"))
        .unwrap()
        .records;
    let ratings: Vec<protocols::Answer> = rows.iter().map(|r| r.response.answer).collect();
    assert_eq!(
        ratings,
        [Rating(2.0), Rating(4.5), Rating(3.0), Rating(5.0)]
    );

    let lines = view_lines(&stderr);
    eprintln!("the experimenter's view:\n{}", lines.join("\n"));
    // Each answer's line, as its row logged it.
    let answered: Vec<String> = rows
        .iter()
        .map(|r| {
            let v = match r.response.answer {
                Rating(v) => protocols::texts::format_rating(v),
                other => panic!("{other:?}"),
            };
            let dropped = r.response.dropped_frames;
            format!(
                "{}trial {}/4 answered {v} in {:.2} s, {dropped} frame{} dropped, {} elapsed",
                if r.trial.block == Block::Familiarization {
                    "practice "
                } else {
                    ""
                },
                r.trial.index + 1,
                r.response.response_time_ms as f64 / 1e3,
                if dropped == 1 { "" } else { "s" },
                mm_ss(r.elapsed_ms)
            )
        })
        .collect();
    assert!(answered[0].starts_with("practice trial 1/4 answered 2 in "));
    let dropped: u32 = rows.iter().map(|r| r.response.dropped_frames).sum();
    let expected: Vec<&str> = vec![
        "stimuli checked:",
        "session S01 s1 opened: 0 of 4 trials done, 00:",
        "began: trial 1/4, ",
        &answered[0],
        "paused by the experimenter, ",
        "resumed after a pause of ",
        &answered[1],
        "break after 2 of 4 trials, ",
        "break over after ",
        &answered[2],
        &answered[3],
    ];
    assert_eq!(lines.len(), expected.len() + 1, "{lines:#?}");
    for (line, want) in lines.iter().zip(&expected) {
        assert!(
            line.starts_with(want),
            "{line:?} should start with {want:?}"
        );
    }
    let last = lines.last().unwrap();
    let plural = if dropped == 1 { "" } else { "s" };
    let finished = format!("finished: 4 of 4 trials, {dropped} frame{plural} dropped, ");
    assert!(last.starts_with(&finished), "{last:?}: {finished:?}");
    assert!(lines[2].ends_with(" elapsed") && lines[5].ends_with(" s (the trial starts again)"));
    // The summary still goes to standard output, after the view's last line.
    assert!(stdout.contains("S01: Complete, 4 trials"), "{stdout}");
}

/// `--quiet`: the same session writes none of the view's lines (the test input's lines show
/// that standard error was read all along), and its answers are recorded as ever; a signal
/// stops it as before.
#[test]
fn quiet_runs_without_the_experimenters_view() {
    let Some(env) = setup("view-quiet") else {
        return;
    };
    let study = write_study(&env.dir);
    let out = env.dir.join("results");
    let script = "welcome/ready: Enter\ntrial/open once: 2 Enter\n";
    let mut session = run(&env, "quiet", &study, &out, &["--quiet"], script);
    session.wait_line("done 2");
    let (stdout, stderr) = session.interrupt();
    assert!(
        stderr.contains("test input: screen trial/open #0"),
        "{stderr}"
    );
    assert_eq!(view_lines(&stderr), Vec::<&str>::new(), "{stderr}");
    assert!(
        stdout.contains("interrupted by a signal after 1 trials"),
        "{stdout}"
    );
    let rows = results::trials::read_trials(&out.join("S01_s1/trials.csv")).unwrap();
    assert_eq!(rows.records.len(), 1);
}

/// A study whose stimulus file is missing is refused before the window opens (the test input
/// script is never read) and before anything is written: the error names the study file and
/// the missing file, and no results folder appears. `study run --help` names every method.
#[test]
fn a_missing_stimulus_is_refused_before_the_window_and_writes_nothing() {
    let Some(env) = setup("view-missing") else {
        return;
    };
    let study = write_study(&env.dir);
    // A compressed stimulus's file, as the manifest names it.
    let manifest = env.dir.join("stimuli/stimuli.json");
    let manifest: protocols::manifest::StimulusManifest =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    let last = manifest.stimuli.last().unwrap();
    let gone = env.dir.join("stimuli").join(&last.file);
    assert!(gone.is_file(), "{}", gone.display());
    std::fs::remove_file(&gone).unwrap();
    let out = env.dir.join("results");
    let session = run(&env, "missing", &study, &out, &[], "welcome/ready: Enter\n");
    let (status, stdout, stderr) = session.wait_exit();
    assert!(!status.success(), "{stdout}{stderr}");
    let first = stderr.lines().find(|l| l.starts_with("error:")).unwrap();
    assert!(
        first.contains(&study.display().to_string()) && stderr.contains("nothing was written"),
        "{stderr}"
    );
    assert!(stderr.contains(&gone.display().to_string()), "{stderr}");
    assert!(
        !stderr.contains("STUDY_TEST_INPUT"),
        "the window opened: {stderr}"
    );
    assert!(!out.exists(), "{} was made", out.display());

    let help = Command::new(env!("CARGO_BIN_EXE_study"))
        .args(["run", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("any method a study file can name"), "{help}");
    assert!(
        help.contains("--quiet") && !help.contains("2AFC staircase"),
        "{help}"
    );
}
