//! `study demo` from nothing: stimuli, three studies, three reports; without a display with
//! simulated observers only (and saying so), with one (Xvfb + lavapipe) also your session of
//! each study in the window, driven here by a test input script.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::process::Command;

#[test]
fn demo_runs_every_protocol_and_says_observers_are_simulated() {
    let dir = std::env::temp_dir().join(format!("study-demo-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let run = || {
        Command::new(env!("CARGO_BIN_EXE_study"))
            .args(["demo", "--subjects", "3"])
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .current_dir(&dir)
            .output()
            .unwrap()
    };
    let out = run();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("No display") && text.contains("simulated observers"),
        "{text}"
    );
    assert!(text.contains("## Mean opinion scores") && text.contains("## Staircase thresholds"));
    // A summary, not the reports: each step numbered once and in order, no heading printed
    // without its table, and the end names every report.
    let steps: Vec<&str> = text
        .lines()
        .filter_map(|l| l.strip_prefix('[')?.split(']').next())
        .collect();
    assert_eq!(steps, ["1/5", "2/5", "3/5", "4/5", "5/5"], "{text}");
    assert!(text.lines().count() < 100, "{text}");
    let lines: Vec<&str> = text.lines().collect();
    for (i, l) in lines.iter().enumerate() {
        if l.starts_with('#') {
            assert!(
                lines.get(i + 1).is_some_and(|n| n.starts_with('|')),
                "heading {l:?} without its table:\n{text}"
            );
        }
    }
    let tail = lines[lines.len() - 3..].join("\n");
    for p in ["mos", "dscqs", "staircase"] {
        assert!(tail.contains(&format!("report-{p}/report.html")), "{tail}");
    }
    for p in ["mos", "dscqs", "staircase"] {
        assert!(
            dir.join(format!("study-demo/report-{p}/report.html"))
                .is_file(),
            "{p}"
        );
        let (_, sessions) =
            results::read_results_dir(&dir.join(format!("study-demo/results-{p}"))).unwrap();
        assert_eq!(sessions.len(), 3, "{p}");
    }
    // A second run never touches the first one's results.
    let out = run();
    assert!(out.status.success());
    assert!(dir.join("study-demo-2/report-mos/report.md").is_file());
}

#[test]
fn demo_with_a_display_adds_your_session_of_each_study_in_the_window() {
    let Some(env) = common::setup("demo-window") else {
        return;
    };
    // One script answers every window of the demo (each window reads it anew): Enter
    // begins; once a trial's answers open, 4 4 Enter rates MOS (4) and DSCQS (A 4, B 4) and
    // Left answers 2AFC (keys a screen does not take are ignored; the rest of a rule is
    // dropped once the answer has moved the screen on); Enter closes the end screen.
    let demo = env.dir.join("demo");
    let run = common::Scripted::spawn(
        &env,
        "demo",
        &[
            "demo".as_ref(),
            "--subjects".as_ref(),
            "2".as_ref(),
            "-o".as_ref(),
            demo.as_os_str(),
        ],
        "welcome/ready: Enter\ntrial/open: 4 4 Enter Left\nend/ready: Enter\n",
    );
    let (status, text, stderr) = run.wait_exit();
    assert!(status.success(), "{text}\n{stderr}");
    assert_eq!(
        stderr.matches("test input: screen end/ready").count(),
        3,
        "three windows closed by their end screens: {stderr}"
    );
    assert!(text.contains("A display is available"), "{text}");
    for p in ["mos", "dscqs", "staircase"] {
        let (_, sessions) =
            results::read_results_dir(&env.dir.join(format!("demo/results-{p}"))).unwrap();
        let yours = sessions
            .iter()
            .find(|s| s.manifest.subject == "you")
            .unwrap_or_else(|| panic!("{p}: no session of yours"));
        assert_eq!(
            yours.manifest.status,
            results::store::SessionState::Complete,
            "{p}"
        );
        assert!(
            yours.manifest.observer_seed.is_none(),
            "{p}: a real session"
        );
        assert!(!yours.trials.records.is_empty(), "{p}");
        for r in &yours.trials.records {
            assert!(r.timing.is_some(), "{p}: window rows carry frame timing");
        }
        assert!(
            env.dir
                .join(format!("demo/report-{p}/report.html"))
                .is_file()
        );
    }
}
