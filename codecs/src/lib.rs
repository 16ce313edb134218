//! Motion-capture clips and the codecs that compress them.
//!
//! This crate holds everything that works on motion data and knows nothing of studies:
//! - the clip model ([`Skeleton`], [`Clip`]) with readers and writers for Acclaim ASF/AMC and BVH,
//! - forward kinematics ([`fk`]) in `f64`,
//! - the body-part and hierarchy map the perceptual codecs weight channels by ([`bodymap`]),
//! - a procedurally generated walking figure for demos and tests ([`synth`]),
//! - (codec issue) wavelets, the seeds' codecs, the bitstream container and error metrics.
//!
//! ```
//! let clip = codecs::synth::walking_clip(&codecs::synth::WalkParams::default());
//! let positions = codecs::fk::positions(&clip);
//! assert_eq!(positions.frames(), clip.frames());
//! ```

pub mod amc;
pub mod asf;
pub mod bitstream;
pub mod bodymap;
pub mod bvh;
pub mod clip;
pub mod codec;
pub mod convert;
pub mod data;
pub mod entropy;
pub mod error;
pub mod fk;
pub mod io;
pub mod markers;
pub mod math;
pub mod metrics;
pub mod playback;
pub mod primitives;
pub mod quat;
pub mod rate;
pub mod synth;
mod text;
pub mod wavelet;

pub use clip::{
    Axis, BodyPart, Channel, ChannelKind, Clip, ClipError, Joint, Rest, Skeleton, SkeletonFormat,
    Units,
};
pub use error::{Limits, ParseError, WriteError};
