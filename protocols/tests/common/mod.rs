// Shared by the integration tests: the test study files, their manifest, and a codec
// catalog standing in for the binary's codec registry.
#![allow(
    dead_code,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    missing_docs
)]

use std::path::{Path, PathBuf};

use protocols::manifest::StimulusManifest;
use protocols::{CodecCatalog, CodecInfo, StudyDefinition};

/// The codecs the test study files may name, shaped like the real registry's: `spiht` and
/// `wavelet-perceptual` reach a target compression ratio, `primitive` also needs its database,
/// `raw-f32` takes no parameters and has no rate control.
pub struct TestCodecs;

impl CodecCatalog for TestCodecs {
    fn codec(&self, name: &str) -> Option<CodecInfo> {
        let info = |params: &[&str], target_cr: bool, needs_database: bool| CodecInfo {
            params: params.iter().map(|p| (*p).to_string()).collect(),
            target_cr,
            needs_database,
        };
        match name {
            "spiht" => Some(info(&["cr", "window"], true, false)),
            "wavelet-perceptual" => Some(info(
                &["alpha", "c", "cr", "qp", "translation", "wavelet", "window"],
                true,
                false,
            )),
            "primitive" => Some(info(&["cr", "t_l"], true, true)),
            "raw-f32" => Some(info(&[], false, false)),
            _ => None,
        }
    }

    fn names(&self) -> Vec<String> {
        ["raw-f32", "wavelet-perceptual", "spiht", "primitive"]
            .map(String::from)
            .to_vec()
    }
}

/// The study files these tests read: paper 000's MOS design (42 conditions), BT.500 DSCQS,
/// the thesis's staircases and a live staircase, over a hand-made manifest of clips `walk` and
/// `dance` (the protocols never read the clip files). Kept here, not in `examples/`, whose
/// studies are smaller so that their generated stimuli fit in the repository.
pub fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/studies")
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
    StudyDefinition::parse(text, Path::new("test.toml"), move |_| Ok(m), &TestCodecs)
}

/// The (key, reason) of every problem of a study file that must be invalid.
pub fn invalid(parsed: Result<StudyDefinition, protocols::StudyError>) -> Vec<(String, String)> {
    match parsed {
        Err(protocols::StudyError::Invalid { issues, .. }) => {
            issues.into_iter().map(|i| (i.key, i.reason)).collect()
        }
        other => panic!("expected Invalid, got {other:?}"),
    }
}

/// The (key, reason) of every problem of study file `text`, which must be invalid.
pub fn issues(text: &str) -> Vec<(String, String)> {
    invalid(parse(text))
}

/// Whether `got` has a problem at `key` whose reason contains `words`.
pub fn has(got: &[(String, String)], key: &str, words: &str) -> bool {
    got.iter().any(|(k, r)| k == key && r.contains(words))
}

pub fn example(name: &str) -> StudyDefinition {
    StudyDefinition::load(&examples().join(name), &TestCodecs).unwrap()
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

/// A QUEST+ study of two tracks over the hand-made example manifest (primitive codec, `t_l`).
pub const QUEST: &str = r#"
format_version = 1
name = "quest"
protocol = "staircase"
stimuli = "stimuli.json"
seed = 11

[staircase]
method = "quest_plus"
param = "t_l"
codec = "primitive"
min = 0.002
max = 0.040
step = 0.002
max_trials = 24

[staircase.quest]
threshold = { min = 0.002, max = 0.06, count = 30, spacing = "log", prior = { kind = "log_normal", mean = -1.9, sd = 0.4 } }
slope = [1.5, 2.5, 3.5, 5]
lapse = { values = [0, 0.02, 0.04], prior = { kind = "beta", a = 1, b = 10 } }

[[staircase.tracks]]
name = "walk"
clip = "walk"

[[staircase.tracks]]
name = "dance"
clip = "dance"
"#;
