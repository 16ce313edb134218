//! Motion primitives (thesis ch. 4-5): segmentation of quaternion tracks and the primitive
//! database the incremental codec encodes against.
//!
//! - [`segment`]: chop each joint's track at zero crossings of its angular acceleration
//!   (eq. 5.1-5.2), at least 15 frames and at most `S_M` frames long, and normalize every
//!   segment to 16 frames by SLERP; or chop the whole body at once by the same rule
//!   ([`segment_body`], the `rhythmic` codec of ch. 4).
//! - [`database`]: k-means++ in quaternion-segment space with the distance of eq. 5.3-5.4,
//!   centres updated by weighted SLERP, K grown from 5 until the clustering error (eq. 5.6)
//!   falls below a bound or K reaches 25; stored in a versioned file with a checksum.

pub mod database;
pub mod segment;

pub use database::{Database, DatabaseError, JointPrimitives, TrainParams};
pub use segment::{NORMALIZED_FRAMES, Segment, SegmentParams, segment_body, segment_track};
