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
