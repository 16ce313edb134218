//! `study demo` from nothing: stimuli, three studies, three reports; without a display with
//! simulated observers only (and saying so), with one (Xvfb + lavapipe) also your session of
//! each study in the window, driven here by `xdotool`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

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
    let mut child = env
        .cmd(env!("CARGO_BIN_EXE_study"))
        .args(["demo", "--subjects", "2", "-o"])
        .arg(env.dir.join("demo"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // One key sequence answers every screen: Enter begins, 4 4 Enter rates MOS (4) and DSCQS
    // (A 4, B 4), Left answers 2AFC; keys a screen does not take are ignored.
    let deadline = Instant::now() + Duration::from_secs(600);
    let mut windows = 0;
    while child.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "the demo did not finish");
        let id = env.xdotool(&["search", "--name", "study: demo-"]);
        if let Some(wid) = id.lines().next().filter(|l| !l.is_empty()) {
            windows += 1;
            common::press(&env, wid, &["Return", "4", "4", "Return", "Left"]);
        }
        std::thread::sleep(Duration::from_millis(400));
    }
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(windows > 0);
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
