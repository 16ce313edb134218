//! Motion-capture clips: the skeleton and channel model, the files they come in, and the
//! kinematics every other crate builds on.
//!
//! This crate knows nothing of codecs or studies:
//! - the clip model ([`Skeleton`], [`Clip`]) with readers and writers for Acclaim ASF/AMC and
//!   BVH ([`asf`], [`amc`], [`bvh`], [`io`]) and ASF → BVH conversion ([`convert`]),
//! - which skeleton an AMC motion is read with, one rule for every command ([`pairing`]),
//! - forward kinematics ([`fk`]) in `f64`, rotation helpers ([`math`]) and quaternions
//!   ([`quat`]),
//! - the body-part and hierarchy map the perceptual codecs weight channels by ([`bodymap`]),
//! - playback by time ([`playback`]) and a generated walking figure for demos and tests
//!   ([`synth`]),
//! - where tests find the shared real clips ([`data`]).
//!
//! ```
//! let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
//! let positions = motion::fk::positions(&clip);
//! assert_eq!(positions.frames(), clip.frames());
//! ```

pub mod amc;
pub mod asf;
pub mod bodymap;
pub mod bvh;
pub mod clip;
pub mod convert;
pub mod data;
pub mod error;
pub mod fk;
pub mod info;
pub mod io;
pub mod math;
pub mod pairing;
pub mod playback;
pub mod quat;
pub mod synth;
mod text;

pub use clip::{
    Axis, BodyPart, Channel, ChannelKind, Clip, ClipError, Joint, Rest, Skeleton, SkeletonFormat,
    Units,
};
pub use error::{Limits, ParseError, ReadWarning, WriteError};
