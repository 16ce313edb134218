//! `study simulate` over a real `study sweep` stimulus set (CMU clip `pirouette`, SPIHT codecs
//! at native target ratios): MOS, DSCQS and a staircase on the `cr` parameter write complete
//! results directories. Skipped only outside CI when the shared clips are absent.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::Command;

use results::store::SessionState;

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("sweep-sim-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn study() -> Command {
    Command::new(env!("CARGO_BIN_EXE_study"))
}

const MOS: &str = r#"
format_version = 1
name = "sweep-mos"
protocol = "mos"
stimuli = "stimuli.json"
seed = 5
[conditions]
clips = ["pirouette"]
codecs = ["spiht", "spiht-uniform"]
target_cr = [10, 20, 30, 40]
[session]
familiarization = 2
hidden_repeats = 2
"#;

const STAIRCASE: &str = r#"
format_version = 1
name = "sweep-staircase"
protocol = "staircase"
stimuli = "stimuli.json"
seed = 6
[staircase]
param = "cr"
codec = "spiht"
start = 30
step = 10
min = 10
max = 40
stop_reversals = 6
max_trials = 40
[[staircase.tracks]]
clip = "pirouette"
[simulation]
threshold = 22
slope = 3
"#;

#[test]
fn simulate_over_a_sweep_manifest() {
    let Some(mocap) = motion::data::mocap_dir() else {
        return;
    };
    let dir = scratch("sweep");
    let sweep = study()
        .arg("sweep")
        .arg("--clips")
        .arg(mocap.join("pirouette.amc"))
        .args([
            "--codecs",
            "spiht,spiht-uniform",
            "--cr",
            "10,20,30,40",
            "--quiet",
            "-o",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        sweep.status.success(),
        "{}",
        String::from_utf8_lossy(&sweep.stderr)
    );
    std::fs::write(dir.join("mos.toml"), MOS).unwrap();
    std::fs::write(
        dir.join("dscqs.toml"),
        MOS.replace("\"mos\"", "\"dscqs\"")
            .replace("sweep-mos", "sweep-dscqs"),
    )
    .unwrap();
    std::fs::write(dir.join("staircase.toml"), STAIRCASE).unwrap();
    for (file, trials) in [
        ("mos.toml", Some(2 + 8 + 2)),
        ("dscqs.toml", Some(2 + 8 + 2)),
        ("staircase.toml", None),
    ] {
        let out = dir.join(format!("results-{file}"));
        let check = study().arg("check").arg(dir.join(file)).output().unwrap();
        assert!(
            check.status.success(),
            "{file}: {}",
            String::from_utf8_lossy(&check.stderr)
        );
        let sim = study()
            .arg("simulate")
            .arg(dir.join(file))
            .args(["--subjects", "2", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            sim.status.success(),
            "{file}: {}",
            String::from_utf8_lossy(&sim.stderr)
        );
        let (_, sessions) = results::read_results_dir(&out).unwrap();
        assert_eq!(sessions.len(), 2);
        for s in sessions {
            assert_eq!(s.manifest.status, SessionState::Complete);
            if let Some(n) = trials {
                assert_eq!(s.trials.records.len(), n, "{file}");
            } else {
                assert!(
                    s.manifest.thresholds[0].1.is_some(),
                    "{file}: staircase threshold"
                );
            }
        }
    }
}
