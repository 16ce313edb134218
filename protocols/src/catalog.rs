//! The codecs a study file may name, as the study check sees them.
//!
//! A live staircase (`[staircase.live]`) names a codec, the parameter its level sets and fixed
//! values of the others; whether those exist is known only to the codec suite. Protocols never
//! depends on the `codecs` crate (ARCHITECTURE.md), so the binary implements [`CodecCatalog`]
//! over its codec registry and passes it to [`StudyDefinition::load`]. The codec problems then
//! land in the same [`StudyError::Invalid`] list as every other problem of the file.
//!
//! ```
//! use std::path::Path;
//! use protocols::{CodecCatalog, CodecInfo, StudyDefinition, StudyError};
//!
//! /// One codec with rate control.
//! struct OneCodec;
//!
//! impl CodecCatalog for OneCodec {
//!     fn codec(&self, name: &str) -> Option<CodecInfo> {
//!         (name == "spiht").then(|| CodecInfo {
//!             params: vec!["cr".into(), "window".into()],
//!             target_cr: true,
//!             needs_database: false,
//!         })
//!     }
//!     fn names(&self) -> Vec<String> {
//!         vec!["spiht".into()]
//!     }
//! }
//!
//! let text = r#"
//! format_version = 1
//! name = "live"
//! protocol = "staircase"
//! stimuli = "stimuli.json"
//! seed = 1
//! [staircase]
//! param = "cr"
//! codec = "spihtt"
//! start = 40
//! step = 4
//! min = 8
//! max = 80
//! max_trials = 50
//! [staircase.live]
//! clips = ["walk"]
//! "#;
//! let no_manifest = |_: &str| Err("not in this example".to_string());
//! let err = StudyDefinition::parse(text, Path::new("live.toml"), no_manifest, &OneCodec);
//! let Err(StudyError::Invalid { issues, .. }) = err else {
//!     panic!("expected problems");
//! };
//! // The missing manifest and the misspelt codec, in one list.
//! assert!(issues.iter().any(|i| i.key == "stimuli"));
//! assert!(issues.iter().any(|i| i.key == "staircase.codec"
//!     && i.reason.starts_with("unknown codec \"spihtt\" (known: spiht;")));
//! ```
//!
//! [`StudyDefinition::load`]: crate::StudyDefinition::load
//! [`StudyError::Invalid`]: crate::StudyError::Invalid

/// The codec parameter that is a target compression ratio: a live staircase whose level is
/// this parameter asks the codec's rate control for each level's ratio.
pub const TARGET_CR_PARAM: &str = "cr";

/// What the codec suite says about one codec, for checking a study file.
#[derive(Debug, Clone, PartialEq)]
pub struct CodecInfo {
    /// Every parameter the codec accepts (the keys of its defaults), sorted.
    pub params: Vec<String>,
    /// Whether a target compression ratio (`cr`) can be asked for (the codec has rate control).
    pub target_cr: bool,
    /// Whether encoding needs a decoder context file (the primitive codec's database).
    pub needs_database: bool,
}

/// The codecs a study file may name (implemented by the binary's codec registry; protocols
/// never depends on the codecs crate).
pub trait CodecCatalog {
    /// The codec called `name`, if there is one.
    fn codec(&self, name: &str) -> Option<CodecInfo>;
    /// Every codec name, for messages.
    fn names(&self) -> Vec<String>;
}
