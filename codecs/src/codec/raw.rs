//! Baselines: the float32 channel matrix (the seeds' CR reference) and lossless zstd of it.

use super::{Codec, CodecError, Params, RateControl, check_stream, header, merged};
use crate::bitstream::Bitstream;
use motion::clip::{Clip, Skeleton};

/// zstd level for the lossless baseline.
const ZSTD_LEVEL: i32 = 19;

fn f32_matrix(clip: &Clip) -> Vec<u8> {
    let mut out = Vec::with_capacity(clip.data().len() * 4);
    for &v in clip.data() {
        out.extend_from_slice(&(v as f32).to_le_bytes());
    }
    out
}

fn from_f32(
    codec: &'static str,
    bytes: &[u8],
    stream: &Bitstream,
    skeleton: &Skeleton,
) -> Result<Clip, CodecError> {
    let values = stream.channels as usize * stream.frames as usize;
    if bytes.len() != values * 4 {
        return Err(CodecError::Payload {
            codec,
            offset: bytes.len().min(values * 4),
            detail: format!(
                "{} bytes, expected {} (4 × {values})",
                bytes.len(),
                values * 4
            ),
        });
    }
    let data: Vec<f64> = bytes
        .chunks_exact(4)
        .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
        .collect();
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(CodecError::Payload {
            codec,
            offset: i * 4,
            detail: "non-finite value".into(),
        });
    }
    Ok(Clip::new(
        skeleton.clone(),
        stream.frame_rate_hz,
        stream.frames as usize,
        data,
    )?)
}

/// The channel matrix as little-endian float32: CR ≈ 1.
#[derive(Debug, Clone, Copy, Default)]
pub struct RawF32;

impl Codec for RawF32 {
    fn name(&self) -> &'static str {
        "raw-f32"
    }
    fn id(&self) -> u8 {
        1
    }
    fn description(&self) -> &'static str {
        "float32 channel matrix, CR ≈ 1 (the seeds' reference size)"
    }
    fn default_params(&self) -> Params {
        Params::new()
    }
    fn rate_control(&self) -> RateControl {
        RateControl::None
    }
    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError> {
        let p = merged(self, params)?;
        header(self, clip, p, f32_matrix(clip))
    }
    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
        check_stream(self, stream, skeleton)?;
        from_f32(self.name(), &stream.payload, stream, skeleton)
    }
}

/// Lossless zstd of the float32 channel matrix (channel-major, so each channel's bytes are
/// contiguous).
#[derive(Debug, Clone, Copy, Default)]
pub struct ZstdLossless;

impl Codec for ZstdLossless {
    fn name(&self) -> &'static str {
        "zstd"
    }
    fn id(&self) -> u8 {
        2
    }
    fn description(&self) -> &'static str {
        "lossless zstd (level 19) of the float32 channel matrix"
    }
    fn default_params(&self) -> Params {
        Params::new()
    }
    fn rate_control(&self) -> RateControl {
        RateControl::None
    }
    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError> {
        let p = merged(self, params)?;
        let raw = f32_matrix(clip);
        let payload = zstd::bulk::compress(&raw, ZSTD_LEVEL).map_err(|e| CodecError::Payload {
            codec: self.name(),
            offset: 0,
            detail: e.to_string(),
        })?;
        header(self, clip, p, payload)
    }
    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
        check_stream(self, stream, skeleton)?;
        let values = stream.channels as usize * stream.frames as usize;
        // `decompress` refuses output beyond the capacity given: memory stays bounded.
        let raw = zstd::bulk::decompress(&stream.payload, values * 4).map_err(|e| {
            CodecError::Payload {
                codec: self.name(),
                offset: 0,
                detail: e.to_string(),
            }
        })?;
        from_f32(self.name(), &raw, stream, skeleton)
    }
}
