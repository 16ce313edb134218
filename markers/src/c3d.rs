//! C3D marker files (<https://www.c3d.org>): the reader, over `c3dio` with sizes checked
//! before it allocates, and the writer, which is this crate's own.
//!
//! The writer follows the C3D specification as the independent readers on PyPI (ezc3d and
//! py-c3d) and `c3dio` parse it, and `markers/tests/c3d_interop.rs` runs both on what it
//! writes:
//! - block 1, the header: parameter block 2, the key byte 0x50, point count, first frame 1,
//!   last frame, `POINT:SCALE`, the data's first block, the frame rate, and word 150 = 0x3039
//!   (4-character event labels, no events);
//! - the parameter section from block 2: the 4-byte section header (0x01, 0x50, its size in
//!   blocks, processor type 84 = Intel, little-endian), then group records (name length,
//!   negative group id, name, offset to the next record, description) each followed by its
//!   parameter records (name length, positive group id, name, offset, element type −1 / 2 / 4,
//!   dimensions, data, description). Every offset points at the next record, and the record
//!   after the last one starts with a zero name length and group id: the end. Groups: `POINT`
//!   (`USED`, `SCALE`, `RATE`, `DATA_START`, `FRAMES`, `UNITS` = `mm`, `LABELS`,
//!   `DESCRIPTIONS`, continued in `LABELS2`, … past 255 points), `ANALOG` (`USED` 0, `RATE` 0:
//!   no analog channels), `MANUFACTURER` (`SOFTWARE`, `VERSION_LABEL`);
//! - the data section from `POINT:DATA_START`: frame by frame, each point as x, y, z and a
//!   fourth word, in 32-bit floats ([`C3dStorage::Float`], `POINT:SCALE` −1) or in 16-bit
//!   integers times `POINT:SCALE` mm ([`C3dStorage::Integer`]). The fourth word is 0 for a
//!   sample (residual 0: computed, not measured, which a synthetic or solved sample is) and −1
//!   for a gap, whose coordinates are 0. Padded to a whole block.

use std::path::Path;

use super::data::{MarkerSet, check_shape, file_len};
use super::quiet::catch_quiet;
use super::{MarkerError, MarkerLimits};

fn c3d_err(path: &Path, reason: impl Into<String>) -> MarkerError {
    MarkerError::C3d {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

/// Where a C3D file's sections are and what its header says, once checked.
struct Layout {
    /// Byte where the parameter section starts.
    parameters_at: usize,
    /// Byte where the data section starts.
    data_at: usize,
    /// MIPS: big-endian words.
    big_endian: bool,
    /// Points per frame (header word 2).
    markers: usize,
    /// Analog samples per frame, all channels (header word 3).
    analog_samples: usize,
    /// Float storage: `POINT:SCALE` (header words 7-8) negative or zero, as `c3dio` decides.
    float: bool,
}

/// Whether the header's scale (bytes 12-15) marks float storage: negative or zero. For DEC the
/// sign and exponent sit in the first 16-bit word, as they do in the high word of an IEEE float.
fn float_storage(bytes: &[u8], processor: u8) -> bool {
    let b = [bytes[12], bytes[13], bytes[14], bytes[15]];
    let bits = match processor {
        0x56 => u32::from_be_bytes(b),
        0x55 => u32::from_le_bytes([b[2], b[3], b[0], b[1]]),
        _ => u32::from_le_bytes(b),
    };
    let (negative, zero) = (bits >> 31 == 1, bits << 1 == 0);
    negative || zero
}

/// Checks the 512-byte C3D header against the file length before `c3dio` allocates from it:
/// the header's marker and frame counts must fit in the file.
fn check_c3d_header(
    bytes: &[u8],
    path: &Path,
    limits: &MarkerLimits,
) -> Result<Layout, MarkerError> {
    if bytes.len() < 1024 {
        return Err(c3d_err(
            path,
            format!(
                "{} bytes: shorter than a header and a parameter block",
                bytes.len()
            ),
        ));
    }
    if bytes[1] != 0x50 {
        return Err(c3d_err(
            path,
            format!("header byte 2 is {:#04x}, not 0x50", bytes[1]),
        ));
    }
    let param_block = bytes[0] as usize;
    if param_block < 2 || param_block * 512 > bytes.len() {
        return Err(c3d_err(
            path,
            format!("parameter section starts at block {param_block}, outside the file"),
        ));
    }
    // Processor type: parameter block byte 4 (0x54 Intel, 0x55 DEC, 0x56 MIPS big-endian).
    let processor = bytes[(param_block - 1) * 512 + 3];
    let big = match processor {
        0x54 | 0x55 => false,
        0x56 => true,
        other => {
            return Err(c3d_err(
                path,
                format!("unknown processor type {other:#04x}"),
            ));
        }
    };
    let word = |i: usize| {
        let b = [bytes[i], bytes[i + 1]];
        if big {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    };
    let markers = word(2) as usize;
    let analog = word(4) as usize;
    let (first, last) = (word(6), word(8));
    if last < first {
        return Err(c3d_err(
            path,
            format!("last frame {last} precedes first frame {first}"),
        ));
    }
    let frames = (last - first) as usize + 1;
    check_shape(path, markers, frames, limits)?;
    let data_block = word(16) as usize;
    if data_block < 2 || data_block.saturating_sub(1) * 512 > bytes.len() {
        return Err(c3d_err(
            path,
            format!("data section starts at block {data_block}, outside the file"),
        ));
    }
    // Integer samples are 8 bytes per point and 2 per analog value; anything smaller than
    // that cannot be a valid file.
    let need = frames.saturating_mul(markers.saturating_mul(8).saturating_add(analog * 2));
    let have = bytes.len() - (data_block - 1) * 512;
    if need > have {
        return Err(c3d_err(
            path,
            format!(
                "header claims {markers} markers × {frames} frames, but the data section holds only {have} bytes"
            ),
        ));
    }
    Ok(Layout {
        parameters_at: (param_block - 1) * 512,
        data_at: (data_block - 1) * 512,
        big_endian: big,
        markers,
        analog_samples: analog,
        float: float_storage(bytes, processor),
    })
}

/// The position of the value of parameter `group:name` in `section` (a parameter section from
/// its 4-byte header on) and its element size, if the chain of records from the start reaches
/// it and its first element lies inside the section. Every step moves forward and stays in
/// `section`, so the walk ends on any input.
fn find_parameter(
    section: &[u8],
    big_endian: bool,
    group: &str,
    name: &str,
) -> Option<(i8, usize)> {
    // (id, name, first byte after the offset) of each record.
    let mut records: Vec<(i8, &[u8], usize)> = Vec::new();
    let mut pos = 4;
    while pos + 2 <= section.len() {
        let n = usize::from((section[pos] as i8).unsigned_abs());
        let id = section[pos + 1] as i8;
        if n == 0 || id == 0 {
            break;
        }
        let offset_at = pos + 2 + n;
        let offset = section.get(offset_at..offset_at + 2)?;
        let offset = [offset[0], offset[1]];
        let offset = if big_endian {
            i16::from_be_bytes(offset)
        } else {
            i16::from_le_bytes(offset)
        };
        records.push((id, &section[pos + 2..offset_at], offset_at + 2));
        // 0 marks the last record; a negative offset cannot be followed.
        let Ok(step) = usize::try_from(offset) else {
            break;
        };
        if step == 0 {
            break;
        }
        pos = offset_at + step;
    }
    let (group_id, _, _) = records
        .iter()
        .find(|(id, n, _)| *id < 0 && n.eq_ignore_ascii_case(group.as_bytes()))?;
    let (_, _, body) = records.iter().find(|(id, n, _)| {
        i16::from(*id) == -i16::from(*group_id) && n.eq_ignore_ascii_case(name.as_bytes())
    })?;
    let element = *section.get(*body)? as i8;
    let data = body + 2 + usize::from(*section.get(body + 1)?);
    (data + usize::from(element.unsigned_abs()) <= section.len()).then_some((element, data))
}

/// `bytes` without the analog samples, for `c3dio` to read the points from, or `None` when
/// there are none (or the layout leaves no parameter section to find `ANALOG:USED` in).
///
/// `c3dio` parses the analog channels too and refuses a file whose `ANALOG` group lacks a
/// parameter it wants (py-c3d writes no `ANALOG:UNITS`), though the points are all this reader
/// returns. So it gets the file as if it had no analog channels: header words 3 and 10 zero,
/// `ANALOG:USED` 0, and each frame's analog samples cut from the data section.
fn points_only(bytes: &[u8], layout: &Layout) -> Option<Vec<u8>> {
    if layout.analog_samples == 0 || layout.data_at <= layout.parameters_at {
        return None;
    }
    let (point_bytes, analog_bytes) = if layout.float {
        (16 * layout.markers, 4 * layout.analog_samples)
    } else {
        (8 * layout.markers, 2 * layout.analog_samples)
    };
    let stride = point_bytes + analog_bytes;
    let frames = (bytes.len() - layout.data_at) / stride;
    let mut out = Vec::with_capacity(layout.data_at + frames * point_bytes + 512);
    out.extend_from_slice(&bytes[..layout.data_at]);
    out[4..6].fill(0);
    out[18..20].fill(0);
    let section = &out[layout.parameters_at..layout.data_at];
    if let Some((2, at)) = find_parameter(section, layout.big_endian, "ANALOG", "USED") {
        let at = layout.parameters_at + at;
        out[at..at + 2].fill(0);
    }
    for f in 0..frames {
        let start = layout.data_at + f * stride;
        out.extend_from_slice(&bytes[start..start + point_bytes]);
    }
    out.resize(out.len().div_ceil(512) * 512, 0);
    Some(out)
}

/// Reads a C3D file with [`MarkerLimits::default`]; see [`read_c3d_with`].
///
/// # Errors
/// See [`read_c3d_with`].
pub fn read_c3d(path: &Path) -> Result<MarkerSet, MarkerError> {
    read_c3d_with(path, &MarkerLimits::default())
}

/// Reads the 3-D points of a C3D file: labels from `POINT:LABELS` (continued in `LABELS2`,
/// `LABELS3`, … past 255 points), units from `POINT:UNITS`
/// (`mm`, `cm` or `m`, converted to mm; empty means mm), and a gap wherever the residual is
/// negative, a coordinate is not finite, or the point is exactly (0, 0, 0). Analog channels
/// are skipped, and so is whatever the `ANALOG` group lacks.
///
/// # Errors
/// [`MarkerError::Io`], [`MarkerError::Limit`] (checked on the file size and the header's
/// counts before parsing), or [`MarkerError::C3d`] for a malformed file.
pub fn read_c3d_with(path: &Path, limits: &MarkerLimits) -> Result<MarkerSet, MarkerError> {
    file_len(path, limits)?;
    let bytes = std::fs::read(path).map_err(|err| MarkerError::Io {
        path: path.to_path_buf(),
        err,
    })?;
    parse_c3d(&bytes, path, limits)
}

/// Parses C3D bytes; `path` is only used in errors. See [`read_c3d_with`].
///
/// # Errors
/// [`MarkerError::Limit`] or [`MarkerError::C3d`].
pub fn parse_c3d(
    bytes: &[u8],
    path: &Path,
    limits: &MarkerLimits,
) -> Result<MarkerSet, MarkerError> {
    let layout = check_c3d_header(bytes, path, limits)?;
    let points_only = points_only(bytes, &layout);
    let bytes = points_only.as_deref().unwrap_or(bytes);
    // c3dio indexes its input without bounds checks in places; a malformed file that passes
    // the header checks above must still end as this error, not a crash, and without the
    // panic hook printing c3dio's message next to it.
    let parsed = catch_quiet(|| c3dio::C3d::from_bytes(bytes).map_err(Box::new))
        .map_err(|why| {
            c3d_err(
                path,
                format!("malformed file (the parser stopped on inconsistent data: {why})"),
            )
        })?
        .map_err(|e| c3d_err(path, format!("{e:?}")))?;
    let points = &parsed.points;
    let markers = points.points.cols();
    let frames = points.points.rows();
    check_shape(path, markers, frames, limits)?;
    let unit: String = points
        .units
        .iter()
        .collect::<String>()
        .trim()
        .to_ascii_lowercase();
    let mm_per_unit = match unit.as_str() {
        "" | "mm" => 1.0,
        "cm" => 10.0,
        "m" => 1000.0,
        other => {
            return Err(c3d_err(
                path,
                format!("POINT:UNITS {other:?} is not mm, cm or m"),
            ));
        }
    };
    let labels = point_labels(&parsed);
    let mut names: Vec<String> = (0..markers)
        .map(|m| {
            labels
                .get(m)
                .map(|l| l.trim().to_string())
                .filter(|l| !l.is_empty())
                .unwrap_or_else(|| format!("M{m:03}"))
        })
        .collect();
    // Labels must be unique for the segment file to name them.
    for m in 0..names.len() {
        if names[..m].contains(&names[m]) {
            names[m] = format!("{}#{m}", names[m]);
        }
    }
    let rate = f64::from(points.frame_rate);
    let rate = if rate.is_finite() && rate > 0.0 {
        rate
    } else {
        120.0
    };
    let mut set = MarkerSet::new(names, frames, rate);
    for f in 0..frames {
        for m in 0..markers {
            let Some(p) = points.points.get(f, m) else {
                continue;
            };
            let xyz = [
                f64::from(p.point[0]),
                f64::from(p.point[1]),
                f64::from(p.point[2]),
            ];
            let zeroed = xyz.iter().all(|v| *v == 0.0);
            if p.residual < 0.0 || zeroed {
                continue;
            }
            set.set(f, m, Some(xyz.map(|v| v * mm_per_unit)));
        }
    }
    Ok(set)
}

/// The point labels in order: `POINT:LABELS`, then `LABELS2`, `LABELS3`, … (the C3D
/// convention for more than 255 points, which `c3dio` does not follow by itself).
fn point_labels(parsed: &c3dio::C3d) -> Vec<String> {
    let mut labels = parsed.points.labels.clone();
    for k in 2.. {
        let Some(more) = parsed.parameters.get("POINT", &format!("LABELS{k}")) else {
            break;
        };
        match Vec::<String>::try_from(more) {
            Ok(more) => labels.extend(more),
            Err(_) => break,
        }
    }
    labels
}

/// How [`write_c3d_with`] stores point coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum C3dStorage {
    /// 32-bit IEEE floats (`POINT:SCALE` = −1): each coordinate is the `f32` nearest to the
    /// set's value, so readers return exactly `value as f32`.
    #[default]
    Float,
    /// Signed 16-bit integers times `POINT:SCALE` mm, half the size of [`C3dStorage::Float`].
    /// The scale is the largest |coordinate| of the set over 32 000 (as `f32`), so every
    /// coordinate is within half a scale step of its value.
    Integer,
}

/// Bytes in a C3D block: the header, the parameter section and the data section each start on
/// a block boundary.
const BLOCK: usize = 512;

/// The parameter section's first block (the header is block 1).
const PARAMETER_BLOCK: u8 = 2;

/// The second byte of the header and of the parameter section: the C3D key.
const KEY: u8 = 0x50;

/// Processor type 84 (83 + 1): Intel, little-endian integers and IEEE floats.
const INTEL: u8 = 84;

/// The most labels one `LABELS` parameter holds: its dimensions are bytes.
const LABELS_PER_PARAMETER: usize = 255;

/// The most data bytes one parameter record holds: its offset to the next record is a signed
/// 16-bit integer and counts the record's other bytes too.
const MAX_PARAMETER_DATA: usize = 32_000;

/// The most frames a file holds. The header's last frame is 16-bit, and 65 535 itself is taken:
/// ezc3d reads `POINT:FRAMES` = 0xFFFF as −1, its "count the frames from the data" marker, and
/// py-c3d's `last_frame + 1` wraps to 0 in 16 bits and reads no frames at all.
const MAX_FRAMES: usize = 65_534;

/// The magnitude integer storage maps the largest |coordinate| to (under `i16::MAX`, so that
/// rounding never overflows).
const INTEGER_FULL_SCALE: f64 = 32_000.0;

/// A parameter section under construction: records appended in order, sized when finished.
struct ParameterSection {
    bytes: Vec<u8>,
}

impl ParameterSection {
    fn new() -> ParameterSection {
        // Bytes 1-2 are ignored by readers; 0x01 0x50 is what they hold in an ADTECH parameter
        // file, and what older readers that look at them expect. Byte 3 (the size in blocks)
        // is filled in by `finish`.
        ParameterSection {
            bytes: vec![1, KEY, 0, INTEL],
        }
    }

    /// Appends a record: name length, group id, name, the offset to the next record, `body`.
    /// Returns the position of `body` in the section.
    fn record(&mut self, name: &str, id: i8, body: &[u8]) -> Result<usize, String> {
        debug_assert!(
            !name.is_empty()
                && name.len() <= 127
                && name
                    .bytes()
                    .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b'_')
        );
        // The offset counts from its own first byte to the next record's first byte.
        let offset = i16::try_from(body.len() + 2).map_err(|_| {
            format!(
                "parameter {name} needs {} bytes, more than a C3D parameter record holds",
                body.len()
            )
        })?;
        self.bytes.push(name.len() as u8);
        self.bytes.push(id as u8);
        self.bytes.extend_from_slice(name.as_bytes());
        self.bytes.extend_from_slice(&offset.to_le_bytes());
        let at = self.bytes.len();
        self.bytes.extend_from_slice(body);
        Ok(at)
    }

    /// A group record: its id is stored negated.
    fn group(&mut self, id: i8, name: &str, description: &str) -> Result<(), String> {
        let mut body = Vec::with_capacity(1 + description.len());
        push_description(&mut body, description);
        self.record(name, -id, &body).map(|_| ())
    }

    /// A parameter record of `group`: element size (−1 characters, 1 bytes, 2 16-bit integers,
    /// 4 floats), dimensions (none for a scalar), data, description. Returns the position of
    /// the data in the section.
    fn parameter(
        &mut self,
        group: i8,
        name: &str,
        element: i8,
        dimensions: &[u8],
        data: &[u8],
        description: &str,
    ) -> Result<usize, String> {
        let mut body = Vec::with_capacity(3 + dimensions.len() + data.len() + description.len());
        body.push(element as u8);
        body.push(dimensions.len() as u8);
        body.extend_from_slice(dimensions);
        let data_at = body.len();
        body.extend_from_slice(data);
        push_description(&mut body, description);
        Ok(self.record(name, group, &body)? + data_at)
    }

    fn integer(
        &mut self,
        group: i8,
        name: &str,
        value: i16,
        description: &str,
    ) -> Result<usize, String> {
        self.parameter(group, name, 2, &[], &value.to_le_bytes(), description)
    }

    fn float(
        &mut self,
        group: i8,
        name: &str,
        value: f32,
        description: &str,
    ) -> Result<usize, String> {
        self.parameter(group, name, 4, &[], &value.to_le_bytes(), description)
    }

    /// One string (1 to 255 bytes of ASCII).
    fn text(
        &mut self,
        group: i8,
        name: &str,
        value: &str,
        description: &str,
    ) -> Result<usize, String> {
        self.parameter(
            group,
            name,
            -1,
            &[value.len() as u8],
            value.as_bytes(),
            description,
        )
    }

    /// A column of strings, each padded with spaces to `width` (1 to 255) bytes: dimensions
    /// `[width, count]`.
    fn texts(
        &mut self,
        group: i8,
        name: &str,
        values: &[&str],
        width: usize,
        description: &str,
    ) -> Result<usize, String> {
        let mut data = Vec::with_capacity(width * values.len());
        for v in values {
            data.extend_from_slice(v.as_bytes());
            data.resize(data.len() + width - v.len(), b' ');
        }
        self.parameter(
            group,
            name,
            -1,
            &[width as u8, values.len() as u8],
            &data,
            description,
        )
    }

    /// The section, ended and padded to whole blocks, with its size in byte 3.
    fn finish(mut self) -> Result<Vec<u8>, String> {
        // A record with a zero name length and group id ends the parameters.
        self.bytes.extend_from_slice(&[0, 0]);
        let blocks = self.bytes.len().div_ceil(BLOCK);
        self.bytes[2] = u8::try_from(blocks).map_err(|_| {
            format!(
                "the parameters need {blocks} blocks of 512 bytes, more than the 255 a C3D parameter section holds (too many or too long labels)"
            )
        })?;
        self.bytes.resize(blocks * BLOCK, 0);
        Ok(self.bytes)
    }
}

/// A description: its length byte, then its bytes (at most 255, ASCII).
fn push_description(body: &mut Vec<u8>, description: &str) {
    debug_assert!(description.len() <= 255 && description.is_ascii());
    body.push(description.len() as u8);
    body.extend_from_slice(description.as_bytes());
}

/// Why a label cannot be written as a C3D label, if it cannot.
fn label_problem(label: &str) -> Option<&'static str> {
    if label.is_empty() {
        Some("is empty")
    } else if label.len() > 255 {
        Some("is longer than the 255 bytes a C3D label holds")
    } else if !label.bytes().all(|b| b == b' ' || b.is_ascii_graphic()) {
        Some("is not printable ASCII")
    } else if label.trim() != label {
        Some("starts or ends with a space, which readers strip from C3D labels")
    } else {
        None
    }
}

/// `POINT:SCALE` for integer storage: the largest |coordinate| over [`INTEGER_FULL_SCALE`].
fn integer_scale(set: &MarkerSet) -> f32 {
    let mut max_mm: f64 = 0.0;
    for f in 0..set.frames() {
        for m in 0..set.marker_count() {
            if let Some(p) = set.get(f, m) {
                max_mm = p.iter().fold(max_mm, |a, v| a.max(v.abs()));
            }
        }
    }
    if max_mm == 0.0 {
        return 1.0;
    }
    // Rounded up to the next f32, so that max_mm / scale never exceeds the full scale.
    let scale = (max_mm / INTEGER_FULL_SCALE) as f32;
    let scale = if f64::from(scale) * INTEGER_FULL_SCALE < max_mm {
        f32::from_bits(scale.to_bits() + 1)
    } else {
        scale
    };
    scale.max(f32::MIN_POSITIVE)
}

/// Writes a marker set as a C3D file with float storage; see [`write_c3d_with`].
///
/// # Errors
/// See [`write_c3d_with`].
pub fn write_c3d(set: &MarkerSet, path: &Path, mode: files::Mode) -> Result<(), MarkerError> {
    write_c3d_with(set, path, C3dStorage::Float, mode)
}

/// Writes a marker set as a C3D file (units mm, 1-based frames, no analog channels) with the
/// given storage, whole or not at all ([`files::write`]); an existing file is replaced only
/// with [`files::Mode::Replace`].
///
/// # Errors
/// [`MarkerError::C3d`] as [`format_c3d`] says, [`MarkerError::File`].
pub fn write_c3d_with(
    set: &MarkerSet,
    path: &Path,
    storage: C3dStorage,
    mode: files::Mode,
) -> Result<(), MarkerError> {
    files::check_new(path, mode)?;
    let bytes = format_c3d(set, storage, path)?;
    Ok(files::write(path, bytes, mode)?)
}

/// A marker set as the bytes of a C3D file (see the [module docs](self) for the layout);
/// `path` is only used in errors.
///
/// # Errors
/// [`MarkerError::C3d`] when the set does not fit the format: no markers, more than 32 767
/// markers (`POINT:USED` is a signed 16-bit integer), no frames or more than 65 534 (the
/// header's last frame is 16-bit, and readers take 65 535 for something else), a frame rate that is not positive and finite as `f32`, a
/// coordinate beyond the `f32` range, a label that is empty, not printable ASCII, longer than
/// 255 bytes or with a leading or trailing space, or labels too many or too long for the
/// 255-block parameter section.
pub fn format_c3d(
    set: &MarkerSet,
    storage: C3dStorage,
    path: &Path,
) -> Result<Vec<u8>, MarkerError> {
    let err = |reason: String| c3d_err(path, reason);
    let (markers, frames) = (set.marker_count(), set.frames());
    if markers == 0 || markers > i16::MAX as usize || frames == 0 || frames > MAX_FRAMES {
        return Err(err(format!(
            "{markers} markers × {frames} frames: C3D holds 1 to 32 767 markers and 1 to 65 534 frames"
        )));
    }
    let rate_hz = set.frame_rate_hz as f32;
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(err(format!(
            "frame rate {} Hz is not a positive 32-bit float",
            set.frame_rate_hz
        )));
    }
    for name in set.names() {
        if let Some(why) = label_problem(name) {
            return Err(err(format!("marker label {name:?} {why}")));
        }
    }
    let scale = match storage {
        C3dStorage::Float => -1.0,
        C3dStorage::Integer => integer_scale(set),
    };

    let mut params = ParameterSection::new();
    let data_start_at = point_group(&mut params, set, scale, rate_hz).map_err(&err)?;
    other_groups(&mut params).map_err(&err)?;
    let mut params = params.finish().map_err(&err)?;
    let data_start = usize::from(PARAMETER_BLOCK) + params.len() / BLOCK;
    // At most 2 + 255 blocks: always an i16.
    params[data_start_at..data_start_at + 2].copy_from_slice(&(data_start as i16).to_le_bytes());

    let mut bytes = header(
        markers as u16,
        frames as u16,
        scale,
        data_start as u16,
        rate_hz,
    )
    .to_vec();
    bytes.extend_from_slice(&params);
    point_data(set, storage, scale, &mut bytes).map_err(&err)?;
    bytes.resize(bytes.len().div_ceil(BLOCK) * BLOCK, 0);
    Ok(bytes)
}

/// The `POINT` group (id 1); returns where `DATA_START`'s value is, to fill in once the
/// section's size is known.
fn point_group(
    params: &mut ParameterSection,
    set: &MarkerSet,
    scale: f32,
    rate_hz: f32,
) -> Result<usize, String> {
    const POINT: i8 = 1;
    params.group(POINT, "POINT", "3-D point parameters")?;
    params.integer(
        POINT,
        "USED",
        set.marker_count() as i16,
        "Number of 3-D points",
    )?;
    params.float(
        POINT,
        "SCALE",
        scale,
        "Integer data to mm (negative: float data)",
    )?;
    params.float(POINT, "RATE", rate_hz, "Frames per second")?;
    let data_start_at = params.integer(POINT, "DATA_START", 0, "First block of the data")?;
    // Read as unsigned past 32 767, as the header's 16-bit frame numbers are.
    params.integer(
        POINT,
        "FRAMES",
        set.frames() as u16 as i16,
        "Number of frames",
    )?;
    params.text(POINT, "UNITS", "mm", "Units of the 3-D points")?;
    let names: Vec<&str> = set.names().iter().map(String::as_str).collect();
    let width = names.iter().map(|n| n.len()).max().unwrap_or(1);
    let per_parameter = LABELS_PER_PARAMETER.min(MAX_PARAMETER_DATA / width);
    let blanks = vec![" "; per_parameter];
    for (k, chunk) in names.chunks(per_parameter).enumerate() {
        let suffix = if k == 0 {
            String::new()
        } else {
            (k + 1).to_string()
        };
        params.texts(
            POINT,
            &format!("LABELS{suffix}"),
            chunk,
            width,
            "Point labels",
        )?;
        params.texts(
            POINT,
            &format!("DESCRIPTIONS{suffix}"),
            &blanks[..chunk.len()],
            1,
            "Point descriptions",
        )?;
    }
    Ok(data_start_at)
}

/// `ANALOG` (id 2: no channels, rate 0 so that readers derive 0 samples per frame) and
/// `MANUFACTURER` (id 3: what wrote the file).
fn other_groups(params: &mut ParameterSection) -> Result<(), String> {
    const ANALOG: i8 = 2;
    const MANUFACTURER: i8 = 3;
    params.group(ANALOG, "ANALOG", "Analog channels (none)")?;
    params.integer(ANALOG, "USED", 0, "Number of analog channels")?;
    params.float(ANALOG, "RATE", 0.0, "Analog samples per second")?;
    params.group(
        MANUFACTURER,
        "MANUFACTURER",
        "The software that wrote the file",
    )?;
    params.text(MANUFACTURER, "SOFTWARE", "mocap-study markers", "")?;
    params.text(MANUFACTURER, "VERSION_LABEL", env!("CARGO_PKG_VERSION"), "")?;
    Ok(())
}

/// The 512-byte header (16-bit words numbered from 1 in the specification).
fn header(markers: u16, frames: u16, scale: f32, data_start: u16, rate_hz: f32) -> [u8; BLOCK] {
    let mut h = [0u8; BLOCK];
    let mut word = |n: usize, v: u16| h[2 * (n - 1)..2 * n].copy_from_slice(&v.to_le_bytes());
    word(2, markers);
    word(3, 0); // analog samples per frame, all channels
    word(4, 1); // first frame
    word(5, frames); // last frame
    word(6, 0); // maximum interpolation gap
    word(9, data_start);
    word(10, 0); // analog samples per frame and channel
    word(150, 0x3039); // events have 4-character labels (there are none)
    h[0] = PARAMETER_BLOCK;
    h[1] = KEY;
    h[12..16].copy_from_slice(&scale.to_le_bytes());
    h[20..24].copy_from_slice(&rate_hz.to_le_bytes());
    h
}

/// Appends the data section: frame by frame, each point's x, y, z and fourth word.
fn point_data(
    set: &MarkerSet,
    storage: C3dStorage,
    scale: f32,
    bytes: &mut Vec<u8>,
) -> Result<(), String> {
    let per_point = match storage {
        C3dStorage::Float => 16,
        C3dStorage::Integer => 8,
    };
    bytes.reserve(set.frames() * set.marker_count() * per_point + BLOCK);
    for f in 0..set.frames() {
        for m in 0..set.marker_count() {
            let sample = set.get(f, m);
            match storage {
                C3dStorage::Float => {
                    let (xyz, word) = match sample {
                        Some(p) => (p.map(|v| v as f32), 0.0f32),
                        None => ([0.0; 3], -1.0),
                    };
                    if xyz.iter().any(|v| v.is_infinite()) {
                        return Err(format!(
                            "frame {f} marker {:?}: {:?} mm is beyond the 32-bit float range",
                            set.names()[m],
                            sample
                        ));
                    }
                    for v in xyz.into_iter().chain([word]) {
                        bytes.extend_from_slice(&v.to_le_bytes());
                    }
                }
                C3dStorage::Integer => {
                    // |v| / scale ≤ 32 000 by the choice of scale: the casts cannot saturate.
                    let (xyz, word) = match sample {
                        Some(p) => (p.map(|v| (v / f64::from(scale)).round() as i16), 0i16),
                        None => ([0; 3], -1),
                    };
                    for v in xyz.into_iter().chain([word]) {
                        bytes.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
        }
    }
    Ok(())
}
