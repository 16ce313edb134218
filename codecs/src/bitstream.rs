//! The one container every codec writes (format in `docs/bitstream.md`).
//!
//! ```text
//! offset size  field
//! 0      4     magic "MCZ1"
//! 4      2     format version (u16 LE) = 1
//! 6      1     codec id
//! 7      1     parameter count P (≤ 32)
//! 8      ..    P × { key length u8 (1..=32), key bytes (ASCII), value f64 LE }
//! ..     8     skeleton fingerprint (u64 LE, `Skeleton::fingerprint`)
//! ..     4     channels (u32 LE)
//! ..     4     frames (u32 LE)
//! ..     8     frame rate in Hz (f64 LE)
//! ..     4     payload length L (u32 LE)
//! ..     L     payload (codec specific)
//! ..     4     CRC-32 (IEEE, crc32fast) of every byte before it
//! ```
//!
//! [`Bitstream::from_bytes`] checks the CRC first, then every size against [`StreamLimits`] and
//! against the bytes actually present before it allocates anything; a truncated, extended or
//! altered stream is an error. CRC-32 detects every single-bit flip and every burst of up to
//! 32 bits, which the tests check exhaustively for single bits.

use std::collections::BTreeMap;

/// The four magic bytes.
pub const MAGIC: [u8; 4] = *b"MCZ1";
/// The current format version.
pub const FORMAT_VERSION: u16 = 1;
/// Most parameters a stream may carry.
pub const MAX_PARAMS: usize = 32;
/// Longest parameter key.
pub const MAX_KEY_LEN: usize = 32;

/// Size limits checked before allocating; decoders use them too.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamLimits {
    /// Most channels.
    pub max_channels: u32,
    /// Most frames.
    pub max_frames: u32,
    /// Most channel × frame values a decoder may allocate.
    pub max_values: u64,
    /// Largest payload in bytes.
    pub max_payload: u32,
}

impl Default for StreamLimits {
    fn default() -> Self {
        // 16 M values = 128 MiB of f64: a 62-channel clip of 37 minutes at 120 Hz.
        StreamLimits {
            max_channels: 4096,
            max_frames: 1 << 22,
            max_values: 1 << 24,
            max_payload: 1 << 28,
        }
    }
}

/// A coded clip: header fields and the codec's payload.
#[derive(Debug, Clone, PartialEq)]
pub struct Bitstream {
    /// Codec id (see `codec::registry`).
    pub codec_id: u8,
    /// Codec parameters (keys ASCII, ≤ 32 bytes).
    pub params: BTreeMap<String, f64>,
    /// `Skeleton::fingerprint` of the encoded clip's skeleton.
    pub fingerprint: u64,
    /// Channels of the clip.
    pub channels: u32,
    /// Frames of the clip.
    pub frames: u32,
    /// Frame rate in Hz.
    pub frame_rate_hz: f64,
    /// Codec-specific payload.
    pub payload: Vec<u8>,
}

/// Why bytes are not a valid container.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BitstreamError {
    /// Fewer bytes than the smallest stream or than a field needs.
    #[error(
        "bitstream truncated: field `{field}` at offset {offset} needs {need} bytes, {have} left"
    )]
    Truncated {
        /// Field being read.
        field: &'static str,
        /// Byte offset of the field.
        offset: usize,
        /// Bytes needed.
        need: usize,
        /// Bytes left.
        have: usize,
    },
    /// Wrong magic bytes.
    #[error("not a motion bitstream (magic {0:02x?})")]
    Magic([u8; 4]),
    /// A format version this build does not read.
    #[error("unsupported bitstream version {0}")]
    Version(u16),
    /// The CRC does not match.
    #[error("CRC mismatch: stored {stored:08x}, computed {computed:08x}")]
    Crc {
        /// CRC in the stream.
        stored: u32,
        /// CRC of the bytes.
        computed: u32,
    },
    /// A size field is beyond its limit.
    #[error("field `{field}` at offset {offset} is {value}, limit {limit}")]
    Limit {
        /// Field.
        field: &'static str,
        /// Byte offset.
        offset: usize,
        /// Value found.
        value: u64,
        /// Limit.
        limit: u64,
    },
    /// A parameter key is not printable ASCII, or a value is not finite.
    #[error("parameter at offset {offset} is malformed: {detail}")]
    Param {
        /// Byte offset.
        offset: usize,
        /// What is wrong.
        detail: String,
    },
    /// Bytes after the CRC.
    #[error("{0} trailing bytes after the CRC")]
    Trailing(usize),
    /// The frame rate is not positive and finite.
    #[error("frame rate {0} is not positive and finite")]
    FrameRate(f64),
    /// The stream was made for another skeleton.
    #[error("skeleton mismatch: stream fingerprint {stream:016x}, skeleton {skeleton:016x}")]
    Skeleton {
        /// Fingerprint in the stream.
        stream: u64,
        /// Fingerprint of the skeleton given.
        skeleton: u64,
    },
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, field: &'static str) -> Result<&'a [u8], BitstreamError> {
        let have = self.data.len() - self.pos;
        if n > have {
            return Err(BitstreamError::Truncated {
                field,
                offset: self.pos,
                need: n,
                have,
            });
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], BitstreamError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, field)?);
        Ok(a)
    }
}

impl Bitstream {
    /// Serializes the container.
    ///
    /// # Errors
    /// [`BitstreamError::Param`] or [`BitstreamError::Limit`] when a parameter key or the
    /// payload does not fit the format.
    pub fn to_bytes(&self) -> Result<Vec<u8>, BitstreamError> {
        if self.params.len() > MAX_PARAMS {
            return Err(BitstreamError::Limit {
                field: "parameter count",
                offset: 7,
                value: self.params.len() as u64,
                limit: MAX_PARAMS as u64,
            });
        }
        let payload_len = u32::try_from(self.payload.len()).map_err(|_| BitstreamError::Limit {
            field: "payload length",
            offset: 0,
            value: self.payload.len() as u64,
            limit: u64::from(u32::MAX),
        })?;
        let mut out = Vec::with_capacity(self.payload.len() + 64 + self.params.len() * 24);
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.push(self.codec_id);
        out.push(self.params.len() as u8);
        for (k, v) in &self.params {
            if k.is_empty() || k.len() > MAX_KEY_LEN || !k.bytes().all(|b| b.is_ascii_graphic()) {
                return Err(BitstreamError::Param {
                    offset: out.len(),
                    detail: format!("key `{k}`"),
                });
            }
            out.push(k.len() as u8);
            out.extend_from_slice(k.as_bytes());
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.fingerprint.to_le_bytes());
        out.extend_from_slice(&self.channels.to_le_bytes());
        out.extend_from_slice(&self.frames.to_le_bytes());
        out.extend_from_slice(&self.frame_rate_hz.to_le_bytes());
        out.extend_from_slice(&payload_len.to_le_bytes());
        out.extend_from_slice(&self.payload);
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        Ok(out)
    }

    /// Size of [`Bitstream::to_bytes`] without building it.
    pub fn byte_len(&self) -> usize {
        4 + 2
            + 2
            + self.params.keys().map(|k| 1 + k.len() + 8).sum::<usize>()
            + 8
            + 4
            + 4
            + 8
            + 4
            + self.payload.len()
            + 4
    }

    /// Parses and validates a container with the default [`StreamLimits`].
    ///
    /// # Errors
    /// Any [`BitstreamError`]: truncation, bad magic, version, CRC, limits, trailing bytes.
    pub fn from_bytes(data: &[u8]) -> Result<Bitstream, BitstreamError> {
        Bitstream::from_bytes_with(data, &StreamLimits::default())
    }

    /// Parses and validates a container.
    ///
    /// # Errors
    /// As [`Bitstream::from_bytes`].
    pub fn from_bytes_with(
        data: &[u8],
        limits: &StreamLimits,
    ) -> Result<Bitstream, BitstreamError> {
        let (body, pos) = checked_body(data)?;
        let r = &mut Reader { data: body, pos };
        let version = u16::from_le_bytes(r.array("version")?);
        if version != FORMAT_VERSION {
            return Err(BitstreamError::Version(version));
        }
        let [codec_id] = r.array::<1>("codec id")?;
        let params = read_params(r)?;
        let fingerprint = u64::from_le_bytes(r.array("fingerprint")?);
        let (channels, frames) = read_shape(r, limits)?;
        let frame_rate_hz = f64::from_le_bytes(r.array("frame rate")?);
        if !(frame_rate_hz.is_finite() && frame_rate_hz > 0.0) {
            return Err(BitstreamError::FrameRate(frame_rate_hz));
        }
        let payload = read_payload(r, limits)?;
        let trailing = body.len() - r.pos;
        if trailing != 0 {
            return Err(BitstreamError::Trailing(trailing));
        }
        Ok(Bitstream {
            codec_id,
            params,
            fingerprint,
            channels,
            frames,
            frame_rate_hz,
            payload,
        })
    }

    /// Compression ratio as the seeds define it: `4 × channels × frames / bytes`, counting the
    /// whole container.
    pub fn compression_ratio(&self) -> f64 {
        4.0 * f64::from(self.channels) * f64::from(self.frames) / self.byte_len() as f64
    }

    /// Checks the stream was made for `skeleton`.
    ///
    /// # Errors
    /// [`BitstreamError::Skeleton`] when fingerprints or channel counts differ.
    pub fn check_skeleton(&self, skeleton: &motion::Skeleton) -> Result<(), BitstreamError> {
        let fp = skeleton.fingerprint();
        if fp != self.fingerprint || skeleton.channel_count() != self.channels as usize {
            return Err(BitstreamError::Skeleton {
                stream: self.fingerprint,
                skeleton: fp,
            });
        }
        Ok(())
    }
}

/// The bytes before the CRC once the length, the magic and the CRC are checked, and the
/// offset after the magic. The CRC is checked before anything else is interpreted: an
/// altered stream stops here.
fn checked_body(data: &[u8]) -> Result<(&[u8], usize), BitstreamError> {
    const MIN_LEN: usize = 4 + 2 + 2 + 8 + 4 + 4 + 8 + 4 + 4;
    if data.len() < MIN_LEN {
        return Err(BitstreamError::Truncated {
            field: "header",
            offset: 0,
            need: MIN_LEN,
            have: data.len(),
        });
    }
    let mut r = Reader { data, pos: 0 };
    let magic: [u8; 4] = r.array("magic")?;
    if magic != MAGIC {
        return Err(BitstreamError::Magic(magic));
    }
    let body = &data[..data.len() - 4];
    let mut stored_bytes = [0u8; 4];
    stored_bytes.copy_from_slice(&data[data.len() - 4..]);
    let stored = u32::from_le_bytes(stored_bytes);
    let computed = crc32fast::hash(body);
    if stored != computed {
        return Err(BitstreamError::Crc { stored, computed });
    }
    Ok((body, r.pos))
}

/// The parameter count and the parameters: printable ASCII keys of 1 to [`MAX_KEY_LEN`]
/// bytes, each once, with finite values.
fn read_params(r: &mut Reader<'_>) -> Result<BTreeMap<String, f64>, BitstreamError> {
    let [n_params] = r.array::<1>("parameter count")?;
    if usize::from(n_params) > MAX_PARAMS {
        return Err(BitstreamError::Limit {
            field: "parameter count",
            offset: 7,
            value: u64::from(n_params),
            limit: MAX_PARAMS as u64,
        });
    }
    let mut params = BTreeMap::new();
    for _ in 0..n_params {
        let offset = r.pos;
        let [klen] = r.array::<1>("parameter key length")?;
        if klen == 0 || usize::from(klen) > MAX_KEY_LEN {
            return Err(BitstreamError::Param {
                offset,
                detail: format!("key length {klen}"),
            });
        }
        let key = r.take(usize::from(klen), "parameter key")?;
        if !key.iter().all(u8::is_ascii_graphic) {
            return Err(BitstreamError::Param {
                offset,
                detail: "key is not printable ASCII".into(),
            });
        }
        let value = f64::from_le_bytes(r.array("parameter value")?);
        if !value.is_finite() {
            return Err(BitstreamError::Param {
                offset,
                detail: format!("value {value}"),
            });
        }
        let key = String::from_utf8_lossy(key).into_owned();
        if params.insert(key.clone(), value).is_some() {
            return Err(BitstreamError::Param {
                offset,
                detail: format!("duplicate key `{key}`"),
            });
        }
    }
    Ok(params)
}

/// [`BitstreamError::Limit`] when `value` exceeds `limit`.
fn check_limit(
    field: &'static str,
    offset: usize,
    value: u64,
    limit: u64,
) -> Result<(), BitstreamError> {
    if value > limit {
        Err(BitstreamError::Limit {
            field,
            offset,
            value,
            limit,
        })
    } else {
        Ok(())
    }
}

/// Channels and frames, each and their product within `limits`.
fn read_shape(r: &mut Reader<'_>, limits: &StreamLimits) -> Result<(u32, u32), BitstreamError> {
    let ch_off = r.pos;
    let channels = u32::from_le_bytes(r.array("channels")?);
    let frames = u32::from_le_bytes(r.array("frames")?);
    check_limit(
        "channels",
        ch_off,
        u64::from(channels),
        u64::from(limits.max_channels),
    )?;
    check_limit(
        "frames",
        ch_off + 4,
        u64::from(frames),
        u64::from(limits.max_frames),
    )?;
    check_limit(
        "values",
        ch_off,
        u64::from(channels) * u64::from(frames),
        limits.max_values,
    )?;
    Ok((channels, frames))
}

/// The payload length, within `limits` and the bytes present, and the payload.
fn read_payload(r: &mut Reader<'_>, limits: &StreamLimits) -> Result<Vec<u8>, BitstreamError> {
    let pl_off = r.pos;
    let payload_len = u32::from_le_bytes(r.array("payload length")?);
    check_limit(
        "payload length",
        pl_off,
        u64::from(payload_len),
        u64::from(limits.max_payload),
    )?;
    Ok(r.take(payload_len as usize, "payload")?.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Bitstream {
        let mut params = BTreeMap::new();
        params.insert(crate::codec::keys::ALPHA.to_string(), 0.05);
        params.insert(crate::codec::keys::QP.to_string(), 9.0);
        Bitstream {
            codec_id: 3,
            params,
            fingerprint: 0x1234_5678_9abc_def0,
            channels: 62,
            frames: 343,
            frame_rate_hz: 120.0,
            payload: (0..200u32).map(|i| (i * 31 % 256) as u8).collect(),
        }
    }

    #[test]
    fn round_trip_and_length() {
        let s = sample();
        let bytes = s.to_bytes().unwrap();
        assert_eq!(bytes.len(), s.byte_len());
        assert_eq!(Bitstream::from_bytes(&bytes).unwrap(), s);
    }

    #[test]
    fn every_single_bit_flip_is_detected() {
        let bytes = sample().to_bytes().unwrap();
        for bit in 0..bytes.len() * 8 {
            let mut b = bytes.clone();
            b[bit / 8] ^= 1 << (bit % 8);
            assert!(
                Bitstream::from_bytes(&b).is_err(),
                "flip of bit {bit} accepted"
            );
        }
    }

    #[test]
    fn every_truncation_is_detected() {
        let bytes = sample().to_bytes().unwrap();
        for n in 0..bytes.len() {
            assert!(
                Bitstream::from_bytes(&bytes[..n]).is_err(),
                "prefix {n} accepted"
            );
        }
    }
}
