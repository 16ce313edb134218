//! Study definitions and the protocol engines that decide what a subject sees next.
//!
//! Holds: the versioned study file ([`study`], TOML), the trial and record types ([`record`]),
//! the MOS, DSCQS and 2AFC engines (up-down staircases, QUEST+ and Psi, [`quest`]) as
//! deterministic state machines ([`engine`]: the
//! study, its seed and the responses so far fix the next trial), the PsychoPy-compatible
//! [`staircase`], and
//! simulated observers for dry runs ([`observer`]). It knows stimuli only as ids and parameters
//! from the [`manifest`], and codecs only through the [`catalog`] the binary implements over
//! the codec registry; it never draws anything and never touches result files.
//!
//! ```
//! use protocols::{Staircase, StaircaseSettings};
//!
//! // Thesis ch. 5: start t_L = 0.024, step 0.002, two-down-one-up.
//! let mut s = Staircase::new(StaircaseSettings::default())?;
//! s.add_response(true)?;
//! s.add_response(true)?; // two correct in a row: one step down
//! assert!((s.next_level().unwrap_or(0.0) - 0.022).abs() < 1e-12);
//! # Ok::<(), protocols::staircase::StaircaseError>(())
//! ```

pub mod catalog;
pub mod describe;
pub mod design;
pub mod engine;
pub mod manifest;
pub mod methods;
pub mod observer;
pub mod quest;
pub mod record;
pub mod rng;
pub mod screen;
pub mod staircase;
pub mod study;
pub mod texts;

pub use catalog::{CodecCatalog, CodecInfo};
pub use engine::{EngineError, Session, SessionStatus};
pub use quest::{QuestMethod, QuestPlus, QuestSettings};
pub use record::{
    Answer, Arrangement, Block, FrameTiming, MAX_PANES, Outcome, Position, Protocol, Response,
    StimulusEncoding, Trial, TrialRecord,
};
pub use staircase::{Staircase, StaircaseSettings, StepType};
pub use study::{
    ClipOrder, Detection, LiveClip, LiveStaircase, StaircaseStudy, StudyDefinition, StudyError,
    StudyIssue,
};
