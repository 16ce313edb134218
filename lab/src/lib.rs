//! What running a perceptual study needs beyond the pure libraries, shared by every front end
//! (the `study` command and its window today, a server tomorrow). It takes plain option
//! structs and returns typed results; it never parses arguments and never draws.
//!
//! - [`catalog`]: the codec registry as study files and commands see it ([`Codecs`]).
//! - [`clips`]: clip sets, paired by the one rule of [`motion::pairing`] and read.
//! - [`stimulus`]: one stimulus made (encode, decode, measure, timings, worst window).
//! - [`bounded`]: the smallest stream within a max joint error (`--max-error-cm`).
//! - [`crowd`]: crowd scenes (thesis 6.5) compressed per character, at a ratio per group
//!   or under one budget shared uniformly, by distance (eq. 6.4-6.5) or by importance.
//! - [`sweep`]: a stimulus set (clips × codecs × parameter variants × rates or error bounds)
//!   with `stimuli.json` and `rd.csv`;
//!   [`generated`] makes one from the generated walk; [`added`] adds clips decoded by a
//!   codec made elsewhere, measured the same way.
//! - [`study`]: a study file as a run uses it (bytes, hash, definition, archived copy).
//! - [`results_dir`]: a study's results directory, created and checked.
//! - [`integrity`]: whether a results directory's logs can be trusted, before any statistic.
//! - [`session`]: one subject's session on disk ([`session::Recorder`]).
//! - [`source`]: where a trial's stimuli come from ([`source::StimulusSource`]): the
//!   manifest's files, or [`live`] encoding per trial with prefetch.
//! - [`preflight`]: every stimulus a plan can show, checked before any subject sees anything.
//! - [`simulate`]: whole sessions with simulated observers.
//! - [`error`]: the crate's error type, [`LabError`].

pub mod added;
pub mod answer_times;
pub mod bounded;
pub mod catalog;
pub mod clips;
pub mod codec_defs;
pub mod crowd;
pub mod error;
pub mod generated;
pub mod integrity;
pub mod live;
pub mod preflight;
pub mod results_dir;
pub mod scene;
pub mod session;
pub mod simulate;
pub mod source;
pub mod stimulus;
pub mod study;
pub mod sweep;

pub use catalog::Codecs;
pub use error::{LabError, Result};
pub use source::{CrowdCharacter, StimulusSource, TrialStimuli};
pub use study::StudyFile;
