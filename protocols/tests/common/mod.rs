// Shared by the integration tests: the example study files and their manifest.
#![allow(
    dead_code,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    missing_docs
)]

use std::path::{Path, PathBuf};

use protocols::StudyDefinition;
use protocols::manifest::StimulusManifest;

pub fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

pub fn manifest() -> StimulusManifest {
    let text = std::fs::read_to_string(examples().join("stimuli.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

pub fn example_text(name: &str) -> String {
    std::fs::read_to_string(examples().join(name)).unwrap()
}

pub fn parse(text: &str) -> Result<StudyDefinition, protocols::StudyError> {
    let m = manifest();
    StudyDefinition::parse(text, Path::new("test.toml"), move |_| Ok(m))
}

pub fn example(name: &str) -> StudyDefinition {
    StudyDefinition::load(&examples().join(name)).unwrap()
}

/// A live staircase over the hand-made example manifest (clips `walk` and `dance`).
pub const LIVE: &str = r#"
format_version = 1
name = "live"
protocol = "staircase"
stimuli = "stimuli.json"
seed = 5

[staircase]
param = "cr"
codec = "wavelet-perceptual"
start = 40
step = 4
min = 8
max = 80
stop_reversals = 8
max_trials = 50

[staircase.live]
clips = ["walk", "dance"]
order = "in_turn"
params = { qp = 10, window = 128 }

[simulation]
detection = "error"
threshold = 1.5
slope = 3
"#;
