//! The seeds' codecs and the baselines behind one [`Codec`] trait and a registry by name.
//!
//! | name | id | what |
//! | --- | --- | --- |
//! | `raw-f32` | 1 | the channel matrix as IEEE float32 (the seeds' CR = 1 reference) |
//! | `zstd` | 2 | lossless zstd (level 19) of the float32 channel matrix |
//! | `wavelet-perceptual` | 3 | paper 000 / thesis ch. 3: `A_i = l_i·v_i` |
//! | `wavelet-standard` | 4 | same share α for every channel (the paper's "standard wavelet") |
//! | `wavelet-bone` | 5 | bone length only, `A_i = l_i` |
//! | `spiht` | 6 | thesis ch. 6: 1-D SPIHT, perceptual bit allocation eq. 6.1-6.3 |
//! | `spiht-uniform` | 7 | 1-D SPIHT with equal bit shares (allocation ablation) |
//! | `primitive` | 8 | thesis ch. 5: primitive database + incremental CDF 9/7 differences, knob `t_l` |
//! | `rhythmic` | 9 | thesis ch. 4: whole-body segments as references to the clip's primitives, blended at the joins |
//! | a lab's own | 255 | an encode and a decode command ([`external`]), found through [`CodecContext::external`] |
//!
//! Every lossy codec but `rhythmic` takes either its native parameters or `cr` (a target
//! compression ratio); [`crate::rate::encode_to_cr`] reaches a target within ±2 % where the
//! codec's knob allows. `rhythmic`'s rate follows from how often the clip repeats its moves
//! ([`RateControl::None`]).
//!
//! The `primitive` codec needs a context the others do not: the primitive database its
//! decoder shares with the encoder. [`CodecContext`] carries it; [`by_name_in`],
//! [`by_id_in`], [`decode_any_in`] and [`registry_in`] take one, and [`by_name`], [`by_id`],
//! [`decode_any`] use an empty context (the `primitive` codec is found, but refuses to encode
//! or decode with [`CodecError::NoDatabase`]).

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::bitstream::{Bitstream, BitstreamError, StreamLimits};
use crate::primitives::Database;
use motion::clip::{Clip, ClipError, Skeleton};

pub mod external;
mod prep;
pub mod primitive;
pub mod raw;
pub mod rhythmic;
pub mod spiht;
pub mod wavelet_codec;

pub use prep::{unwrap_degrees, wrap_degrees};
pub use primitive::{Costs, Part, PrimitiveCodec};
pub use rhythmic::RhythmicCodec;
pub use spiht::{SpihtCodec, crowd_budgets};
pub use wavelet_codec::{Selection, TranslationRule, WaveletCodec};

/// Codec parameters by name (`alpha`, `qp`, `window`, `cr`, ...), as the manifest stores them.
/// The names are the constants of [`keys`]; each codec reads its parameters from here once,
/// into a typed settings struct that checks every range.
pub type Params = BTreeMap<String, f64>;

/// The names of codec parameters: the keys of [`Params`], of the stimulus manifest and of the
/// bitstream header. Which codec takes which key is its [`Codec::default_params`].
pub mod keys {
    /// Target compression ratio (every lossy codec; [`crate::rate::encode_to_cr`] sets it).
    /// Native to SPIHT (0.1..=10 000); the others search their knob for it and do not record
    /// it in the stream.
    pub const CR: &str = "cr";
    /// Wavelet codecs: the kept fraction α of the coefficients (0..=1), their rate knob.
    pub const ALPHA: &str = "alpha";
    /// Wavelet codecs: quantization bits QP (4..=16).
    pub const QP: &str = "qp";
    /// Wavelet and SPIHT codecs: slice (segment) length in frames (8..=4096).
    pub const WINDOW: &str = "window";
    /// Wavelet codecs: the minimum `C` of kept coefficients per channel and slice (0..=4096).
    pub const C_MIN: &str = "c";
    /// Wavelet and SPIHT codecs: the wavelet, by [`crate::wavelet::Wavelet::id`].
    pub const WAVELET: &str = "wavelet";
    /// Wavelet codecs: how root translations enter the allocation (0 comparable, 1 literal).
    pub const TRANSLATION: &str = "translation";
    /// `wavelet-perceptual` and SPIHT: 0 position-aware allocation, 1 the rule as printed.
    pub const ALLOCATION: &str = "allocation";
    /// SPIHT: body-part score `S` of the legs (0..=1).
    pub const SCORE_LEGS: &str = "score_legs";
    /// SPIHT: body-part score `S` of the arms (0..=1).
    pub const SCORE_ARMS: &str = "score_arms";
    /// SPIHT: body-part score `S` of the torso (0..=1).
    pub const SCORE_TORSO: &str = "score_torso";
    /// SPIHT: body-part score `S` of the head (0..=1).
    pub const SCORE_HEAD: &str = "score_head";
    /// `primitive`: the leg joints' error threshold `t_L` in radians (1e-4..=1), its rate knob.
    pub const T_L: &str = "t_l";
    /// `primitive`: `t_U / t_L`, the other joints' threshold over the legs' (1..=10).
    pub const UPPER_RATIO: &str = "upper_ratio";
    /// `primitive`: frames smoothed each side of a segment join (0..=16).
    pub const SMOOTH: &str = "smooth";
    /// `primitive`: the coarsest quantizer step as a fraction of the threshold (0..=4).
    pub const STEP_FLOOR: &str = "step_floor";
    /// `primitive`: the fingerprint of the primitive database.
    pub const DB: &str = "db";
    /// `primitive`: 1 to code a difference on the 16 normalized frames where that meets the
    /// threshold, 0 always at the segment's own length.
    pub const NORMALIZED: &str = "normalized";
    /// `rhythmic`: the most primitives of the clip's database (1..=256).
    pub const K: &str = "k";
    /// `rhythmic`: the longest segment `S_M` in frames (15..=256).
    pub const S_M: &str = "s_m";
    /// `rhythmic`: the share of each segment searched for blend points (0..=0.5, 0 = none).
    pub const BLEND: &str = "blend";
    /// `rhythmic`: 1 to send every segment's position and heading, 0 for the first only.
    pub const ANCHOR: &str = "anchor";
    /// `rhythmic`: the compression ratio of the database section (1..=100).
    pub const DB_CR: &str = "db_cr";
}

/// `pairs` as [`Params`].
pub(crate) fn params_of(pairs: &[(&str, f64)]) -> Params {
    pairs.iter().map(|&(k, v)| (k.to_string(), v)).collect()
}

/// Why a clip could not be encoded or a stream decoded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CodecError {
    /// The container is invalid or made for another skeleton.
    #[error(transparent)]
    Bitstream(#[from] BitstreamError),
    /// The decoded matrix does not fit the skeleton.
    #[error(transparent)]
    Clip(#[from] ClipError),
    /// A parameter is unknown or out of range.
    #[error("codec `{codec}`: parameter `{key}` = {value}: {detail}")]
    Param {
        /// Codec name.
        codec: &'static str,
        /// Parameter.
        key: String,
        /// Value given.
        value: f64,
        /// What is allowed.
        detail: String,
    },
    /// The stream names another codec.
    #[error("stream is coded with codec id {found}, not `{codec}` (id {expected})")]
    WrongCodec {
        /// This codec.
        codec: &'static str,
        /// Its id.
        expected: u8,
        /// Id in the stream.
        found: u8,
    },
    /// The payload is malformed.
    #[error("codec `{codec}`: corrupt payload at byte {offset}: {detail}")]
    Payload {
        /// Codec name.
        codec: &'static str,
        /// Byte offset in the payload (approximate for entropy-coded data).
        offset: usize,
        /// What is wrong.
        detail: String,
    },
    /// The clip is too large for the format.
    #[error("clip of {channels} channels × {frames} frames exceeds the format's limits")]
    TooLarge {
        /// Channels.
        channels: usize,
        /// Frames.
        frames: usize,
    },
    /// The codec needs a primitive database and none was given.
    #[error(
        "codec `{codec}` needs a primitive database (CodecContext::primitives; in `study`: --db FILE)"
    )]
    NoDatabase {
        /// Codec name.
        codec: &'static str,
    },
    /// The stream (or the `db` parameter) names another primitive database than the one given.
    #[error(
        "codec `{codec}`: the stream was coded with primitive database {stream:08x}, but the database given has fingerprint {given:08x}"
    )]
    DatabaseMismatch {
        /// Codec name.
        codec: &'static str,
        /// Fingerprint recorded in the stream or parameters.
        stream: u32,
        /// Fingerprint of the database in the context.
        given: u32,
    },
    /// The stream was made by a command-defined codec ([`external`]) the context does not
    /// define.
    #[error(
        "the stream was made by the command-defined codec `{name}`, which is not defined here (in `study`: --codec-defs FILE)"
    )]
    Undefined {
        /// The codec's name, as the stream carries it.
        name: String,
    },
    /// A command of a command-defined codec ([`external`]) failed.
    #[error("codec `{codec}`: command `{command}`: {detail}")]
    External {
        /// Codec name.
        codec: &'static str,
        /// The command line, placeholders replaced.
        command: String,
        /// What went wrong (its exit status and the end of its standard error).
        detail: String,
    },
    /// A target compression ratio cannot be reached.
    #[error("codec `{codec}`: target CR {target} not reachable (closest {closest:.3})")]
    Rate {
        /// Codec name.
        codec: &'static str,
        /// Target.
        target: f64,
        /// Closest CR reached.
        closest: f64,
    },
}

/// What the rate controller may search over to reach a target compression ratio.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RateControl {
    /// The codec takes `cr` natively and reaches it exactly.
    Native,
    /// Search this parameter (CR decreases as it grows) in `[min, max]`, on a log scale
    /// ([`crate::rate`]).
    Search {
        /// Parameter name (one of [`keys`]).
        key: &'static str,
        /// Smallest value.
        min: f64,
        /// Largest value.
        max: f64,
        /// Typical `|d ln CR / d ln value|`: the size of the search's first step.
        slope: f64,
    },
    /// Search this parameter (CR increases as it grows, e.g. an error threshold) in
    /// `[min, max]`, on a log scale ([`crate::rate`]).
    SearchIncreasing {
        /// Parameter name (one of [`keys`]).
        key: &'static str,
        /// Smallest value.
        min: f64,
        /// Largest value.
        max: f64,
        /// Typical `|d ln CR / d ln value|`: the size of the search's first step.
        slope: f64,
    },
    /// Lossless or fixed-rate: no target can be asked for.
    None,
}

/// A motion codec.
pub trait Codec: Send + Sync {
    /// Registry name (`wavelet-perceptual`, ...).
    fn name(&self) -> &'static str;
    /// Bitstream id.
    fn id(&self) -> u8;
    /// One line for `study codecs`.
    fn description(&self) -> &'static str;
    /// Default parameters (every key the codec accepts).
    fn default_params(&self) -> Params;
    /// How a target CR is reached.
    fn rate_control(&self) -> RateControl;
    /// Encodes a clip.
    ///
    /// # Errors
    /// [`CodecError::Param`] for a bad parameter, [`CodecError::TooLarge`] for a clip beyond
    /// the format.
    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError>;
    /// Decodes a stream for `skeleton`.
    ///
    /// # Errors
    /// Any [`CodecError`]; never panics on malformed input.
    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError>;
    /// The encoder of `clip` a rate search ([`crate::rate`]) calls once per value of the
    /// searched parameter it tries, the other parameters unchanged. The default calls
    /// [`Codec::encode`]; a codec with costly work that does not depend on that parameter
    /// does it here, once per search.
    ///
    /// # Errors
    /// As [`Codec::encode`].
    fn rate_encoder<'a>(&'a self, clip: &'a Clip) -> Result<RateEncoder<'a>, CodecError> {
        Ok(Box::new(move |p: &Params| self.encode(clip, p)))
    }
}

/// What [`Codec::rate_encoder`] returns: an encode of one clip with the parameters given.
pub type RateEncoder<'a> = Box<dyn FnMut(&Params) -> Result<Bitstream, CodecError> + 'a>;

/// What a codec may need besides the stream: the primitive database of the `primitive`
/// codec (thesis ch. 5), shared by encoder and decoder, and a lab's command-defined codecs
/// ([`external`]). `Default` is an empty context.
#[derive(Debug, Clone, Default)]
pub struct CodecContext {
    /// The primitive database, if one is loaded.
    pub primitives: Option<Arc<Database>>,
    /// Command-defined codecs, found by name beside the built-in ones.
    pub external: Vec<Arc<external::Definition>>,
}

impl CodecContext {
    /// A context holding a primitive database.
    pub fn with_primitives(db: Arc<Database>) -> CodecContext {
        CodecContext {
            primitives: Some(db),
            external: Vec::new(),
        }
    }

    /// The command-defined codec called `name`.
    fn external_codec(&self, name: &str) -> Option<Box<dyn Codec>> {
        self.external
            .iter()
            .find(|d| d.name == name)
            .map(|d| Box::new(external::ExternalCodec::new(Arc::clone(d))) as Box<dyn Codec>)
    }
}

/// Every codec that needs no context (ids 1-7 and 9), in id order. The `primitive` codec is
/// left out because it cannot encode without a database; [`registry_in`] lists every codec.
pub fn registry() -> Vec<Box<dyn Codec>> {
    vec![
        Box::new(raw::RawF32),
        Box::new(raw::ZstdLossless),
        Box::new(WaveletCodec::new(Selection::Perceptual)),
        Box::new(WaveletCodec::new(Selection::Standard)),
        Box::new(WaveletCodec::new(Selection::BoneLength)),
        Box::new(SpihtCodec::new(true)),
        Box::new(SpihtCodec::new(false)),
        Box::new(RhythmicCodec::new()),
    ]
}

/// Every codec, in id order, with `ctx` (the `primitive` codec is listed with or without a
/// database; without one it refuses to encode and decode), then the context's
/// command-defined codecs in their order.
pub fn registry_in(ctx: &CodecContext) -> Vec<Box<dyn Codec>> {
    let mut r = registry();
    r.push(primitive_in(ctx));
    r.sort_by_key(|c| c.id());
    r.extend(
        ctx.external
            .iter()
            .filter_map(|d| ctx.external_codec(&d.name)),
    );
    r
}

/// The `primitive` codec of a context (built only when asked for: it fingerprints and
/// renormalizes the database).
fn primitive_in(ctx: &CodecContext) -> Box<dyn Codec> {
    Box::new(match &ctx.primitives {
        Some(db) => PrimitiveCodec::new(Arc::clone(db)),
        None => PrimitiveCodec::without_database(),
    })
}

/// The codec called `name` (empty context).
pub fn by_name(name: &str) -> Option<Box<dyn Codec>> {
    by_name_in(name, &CodecContext::default())
}

/// The codec called `name`, with `ctx`.
pub fn by_name_in(name: &str, ctx: &CodecContext) -> Option<Box<dyn Codec>> {
    if name == primitive::NAME {
        return Some(primitive_in(ctx));
    }
    registry()
        .into_iter()
        .find(|c| c.name() == name)
        .or_else(|| ctx.external_codec(name))
}

/// The codec with bitstream id `id` (empty context; a command-defined codec's stream,
/// [`external::ID`], is found by [`decode_any_in`] by the name it carries).
pub fn by_id(id: u8) -> Option<Box<dyn Codec>> {
    by_id_in(id, &CodecContext::default())
}

/// The codec with bitstream id `id`, with `ctx`.
pub fn by_id_in(id: u8, ctx: &CodecContext) -> Option<Box<dyn Codec>> {
    if id == primitive::ID {
        return Some(primitive_in(ctx));
    }
    registry().into_iter().find(|c| c.id() == id)
}

/// Decodes any stream with the codec its header names (empty context).
///
/// # Errors
/// [`CodecError::WrongCodec`] for an unknown id, otherwise as [`Codec::decode`].
pub fn decode_any(stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
    decode_any_in(stream, skeleton, &CodecContext::default())
}

/// Decodes any stream with the codec its header names, with `ctx`.
///
/// # Errors
/// [`CodecError::WrongCodec`] for an unknown id, otherwise as [`Codec::decode`]
/// ([`CodecError::NoDatabase`] and [`CodecError::DatabaseMismatch`] for `primitive` streams).
pub fn decode_any_in(
    stream: &Bitstream,
    skeleton: &Skeleton,
    ctx: &CodecContext,
) -> Result<Clip, CodecError> {
    let codec = if stream.codec_id == external::ID {
        let name = external::stream_codec_name(stream).unwrap_or_default();
        ctx.external_codec(&name)
            .ok_or(CodecError::Undefined { name })?
    } else {
        by_id_in(stream.codec_id, ctx).ok_or(CodecError::WrongCodec {
            codec: "any",
            expected: 0,
            found: stream.codec_id,
        })?
    };
    codec.decode(stream, skeleton)
}

/// Merges `given` over the defaults, refusing unknown keys.
pub(crate) fn merged(codec: &dyn Codec, given: &Params) -> Result<Params, CodecError> {
    let mut p = codec.default_params();
    for (k, &v) in given {
        if !p.contains_key(k) {
            return Err(CodecError::Param {
                codec: codec.name(),
                key: k.clone(),
                value: v,
                detail: format!(
                    "unknown; accepted: {}",
                    p.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            });
        }
        if !v.is_finite() {
            return Err(CodecError::Param {
                codec: codec.name(),
                key: k.clone(),
                value: v,
                detail: "not finite".into(),
            });
        }
        p.insert(k.clone(), v);
    }
    Ok(p)
}

/// Reads an integer parameter within `[lo, hi]`.
pub(crate) fn int_param(
    codec: &'static str,
    p: &Params,
    key: &str,
    lo: i64,
    hi: i64,
) -> Result<i64, CodecError> {
    let v = p.get(key).copied().unwrap_or(f64::NAN);
    if v.fract() != 0.0 || !(lo as f64..=hi as f64).contains(&v) {
        return Err(CodecError::Param {
            codec,
            key: key.to_string(),
            value: v,
            detail: format!("must be an integer in {lo}..={hi}"),
        });
    }
    Ok(v as i64)
}

/// Reads a real parameter within `[lo, hi]`.
pub(crate) fn real_param(
    codec: &'static str,
    p: &Params,
    key: &str,
    lo: f64,
    hi: f64,
) -> Result<f64, CodecError> {
    let v = p.get(key).copied().unwrap_or(f64::NAN);
    if !(lo..=hi).contains(&v) {
        return Err(CodecError::Param {
            codec,
            key: key.to_string(),
            value: v,
            detail: format!("must be in {lo}..={hi}"),
        });
    }
    Ok(v)
}

/// Header fields shared by every codec; checks the clip fits the format.
pub(crate) fn header(
    codec: &dyn Codec,
    clip: &Clip,
    params: Params,
    payload: Vec<u8>,
) -> Result<Bitstream, CodecError> {
    let limits = StreamLimits::default();
    let too_large = || CodecError::TooLarge {
        channels: clip.channel_count(),
        frames: clip.frames(),
    };
    let channels = u32::try_from(clip.channel_count()).map_err(|_| too_large())?;
    let frames = u32::try_from(clip.frames()).map_err(|_| too_large())?;
    if channels > limits.max_channels
        || frames > limits.max_frames
        || u64::from(channels) * u64::from(frames) > limits.max_values
    {
        return Err(too_large());
    }
    Ok(Bitstream {
        codec_id: codec.id(),
        params,
        fingerprint: clip.skeleton.fingerprint(),
        channels,
        frames,
        frame_rate_hz: clip.frame_rate_hz,
        payload,
    })
}

/// Whether a decoder splits its work over two threads (the wavelet codec's lanes, SPIHT's
/// channels): once the clip holds [`PARALLEL_MIN_VALUES`] values or the payload
/// [`PARALLEL_MIN_BYTES`] bytes. Below both, a thread costs more than it saves.
pub(crate) fn decode_on_two_threads(stream: &Bitstream) -> bool {
    let values = (stream.channels as usize).saturating_mul(stream.frames as usize);
    stream.channels > 1
        && (values >= PARALLEL_MIN_VALUES || stream.payload.len() >= PARALLEL_MIN_BYTES)
}

/// Clip values (channels × frames) from which a decoder uses two threads whatever the rate:
/// per-frame work (inverse transforms, range decoding of the zero runs) pays for the thread.
/// On the project's 2-core machine a second thread costs time on 02_01 cut to 64 frames
/// (4 000 values) and saves 16-30 % on all its 343 frames (21 000 values), at 20:1 to 100:1.
const PARALLEL_MIN_VALUES: usize = 16 * 1024;
/// Payload size from which a decoder uses two threads however short the clip.
const PARALLEL_MIN_BYTES: usize = 16 * 1024;

/// Checks the stream belongs to `codec` and `skeleton`.
pub(crate) fn check_stream(
    codec: &dyn Codec,
    stream: &Bitstream,
    skeleton: &Skeleton,
) -> Result<(), CodecError> {
    if stream.codec_id != codec.id() {
        return Err(CodecError::WrongCodec {
            codec: codec.name(),
            expected: codec.id(),
            found: stream.codec_id,
        });
    }
    stream.check_skeleton(skeleton)?;
    let limits = StreamLimits::default();
    if stream.frames > limits.max_frames
        || u64::from(stream.channels) * u64::from(stream.frames) > limits.max_values
    {
        return Err(CodecError::TooLarge {
            channels: stream.channels as usize,
            frames: stream.frames as usize,
        });
    }
    Ok(())
}
