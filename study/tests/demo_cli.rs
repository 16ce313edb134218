//! `study demo` from nothing: stimuli, three simulated studies, three reports.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::process::Command;

#[test]
fn demo_runs_every_protocol_and_says_observers_are_simulated() {
    let dir = std::env::temp_dir().join(format!("study-demo-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let run = || {
        Command::new(env!("CARGO_BIN_EXE_study"))
            .args(["demo", "--subjects", "3"])
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
    assert!(text.contains("simulated observers"), "{text}");
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
