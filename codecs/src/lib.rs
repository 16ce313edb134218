//! The seeds' motion codecs and what they are measured with.
//!
//! This crate compresses [`motion::Clip`]s and knows nothing of studies:
//! - wavelets ([`wavelet`]) and entropy coding ([`entropy`]),
//! - every codec behind one [`codec::Codec`] trait and a registry by name ([`codec`]): the
//!   perceptual wavelet codec and its baselines, 1-D SPIHT with perceptual bit allocation, the
//!   primitive codec, raw and zstd references,
//! - the CRC-checked bitstream container ([`bitstream`]) and rate control to a target
//!   compression ratio ([`rate`]),
//! - objective error metrics through forward kinematics ([`metrics`]),
//! - the motion-primitive database of the incremental codec ([`primitives`]).
//!
//! ```
//! use codecs::codec;
//! let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
//! let spiht = codec::by_name("spiht").ok_or("no spiht")?;
//! let stream = codecs::rate::encode_to_cr(spiht.as_ref(), &clip, &codec::Params::new(), 20.0)?;
//! let decoded = spiht.decode(&stream, &clip.skeleton)?;
//! assert!(codecs::metrics::compare(&clip, &decoded)?.rms_cm < 2.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod basis;
pub mod bitstream;
pub mod codec;
pub mod entropy;
pub mod metrics;
pub mod primitives;
pub mod rate;
pub mod wavelet;
