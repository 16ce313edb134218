//! Marker trajectories: a markers × frames set of positions in millimetres with gaps, read
//! from and written to C3D ([`crate::c3d`]) and a simple CSV (`frame,marker,x,y,z`).
//!
//! Missing samples are `None`, never zeros: in C3D a negative residual marks a sample invalid,
//! and a sample at exactly (0, 0, 0) is the "zeroed" missing point of seed 003 (section 2.4).

use std::path::Path;

use super::{MarkerError, MarkerLimits};

pub use super::c3d::{parse_c3d, read_c3d, read_c3d_with, write_c3d};

/// Marker positions in millimetres over frames; `None` is a gap.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerSet {
    names: Vec<String>,
    frames: usize,
    /// Frames per second.
    pub frame_rate_hz: f64,
    /// Frame-major samples: `samples[frame * markers + marker]`.
    samples: Vec<Option<[f64; 3]>>,
}

impl MarkerSet {
    /// A set with every sample missing.
    pub fn new(names: Vec<String>, frames: usize, frame_rate_hz: f64) -> MarkerSet {
        let samples = vec![None; names.len() * frames];
        MarkerSet {
            names,
            frames,
            frame_rate_hz,
            samples,
        }
    }

    /// Marker names, in column order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Number of markers.
    pub fn marker_count(&self) -> usize {
        self.names.len()
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Index of the marker called `name`.
    pub fn marker_index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Position of `marker` at `frame` in mm, `None` for a gap or out of range.
    pub fn get(&self, frame: usize, marker: usize) -> Option<[f64; 3]> {
        if marker >= self.names.len() {
            return None;
        }
        self.samples
            .get(frame * self.names.len() + marker)
            .copied()
            .flatten()
    }

    /// Sets (or, with `None`, clears) a sample; out-of-range indices are ignored. A sample
    /// with a non-finite coordinate is stored as a gap.
    pub fn set(&mut self, frame: usize, marker: usize, position_mm: Option<[f64; 3]>) {
        if marker >= self.names.len() {
            return;
        }
        let value = position_mm.filter(|p| p.iter().all(|v| v.is_finite()));
        if let Some(s) = self.samples.get_mut(frame * self.names.len() + marker) {
            *s = value;
        }
    }

    /// Number of gaps.
    pub fn gap_count(&self) -> usize {
        self.samples.iter().filter(|s| s.is_none()).count()
    }
}

pub(crate) fn file_len(path: &Path, limits: &MarkerLimits) -> Result<u64, MarkerError> {
    let len = std::fs::metadata(path)
        .map_err(|err| MarkerError::Io {
            path: path.to_path_buf(),
            err,
        })?
        .len();
    if len > limits.max_file_bytes {
        return Err(MarkerError::Limit {
            path: path.to_path_buf(),
            what: "file size in bytes",
            value: len,
            max: limits.max_file_bytes,
        });
    }
    Ok(len)
}

pub(crate) fn check_shape(
    path: &Path,
    markers: usize,
    frames: usize,
    limits: &MarkerLimits,
) -> Result<(), MarkerError> {
    let lim = |what, value: usize, max: usize| {
        if value > max {
            Err(MarkerError::Limit {
                path: path.to_path_buf(),
                what,
                value: value as u64,
                max: max as u64,
            })
        } else {
            Ok(())
        }
    };
    lim("marker count", markers, limits.max_markers)?;
    lim("frame count", frames, limits.max_frames)?;
    lim(
        "sample count",
        markers.saturating_mul(frames),
        limits.max_samples,
    )
}

/// Reads a CSV marker file with [`MarkerLimits::default`]; see [`parse_csv`].
///
/// # Errors
/// [`MarkerError::Io`], [`MarkerError::Limit`] or [`MarkerError::Csv`].
pub fn read_csv(path: &Path) -> Result<MarkerSet, MarkerError> {
    read_csv_with(path, &MarkerLimits::default())
}

/// Reads a CSV marker file under `limits` (the file size is checked before reading).
///
/// # Errors
/// [`MarkerError::Io`], [`MarkerError::Limit`] or [`MarkerError::Csv`].
pub fn read_csv_with(path: &Path, limits: &MarkerLimits) -> Result<MarkerSet, MarkerError> {
    file_len(path, limits)?;
    let bytes = std::fs::read(path).map_err(|err| MarkerError::Io {
        path: path.to_path_buf(),
        err,
    })?;
    let text = String::from_utf8(bytes).map_err(|e| MarkerError::Csv {
        path: path.to_path_buf(),
        line: 1 + e.as_bytes()[..e.utf8_error().valid_up_to()]
            .split(|&b| b == b'\n')
            .count()
            - 1,
        reason: "not valid UTF-8".into(),
    })?;
    parse_csv(&text, path, limits)
}

/// Parses CSV text: optional `# frame_rate_hz = R` comment lines (default 120 Hz), the header
/// `frame,marker,x,y,z`, then one row per sample with a 0-based frame index, a marker name and
/// coordinates in mm. Samples not listed, or listed with all three coordinates empty, are gaps.
/// Markers are numbered in order of first appearance.
///
/// # Errors
/// [`MarkerError::Csv`] naming the line for a missing header, a wrong field count, a bad
/// number, a duplicated sample; [`MarkerError::Limit`] when the shape exceeds `limits`.
pub fn parse_csv(text: &str, path: &Path, limits: &MarkerLimits) -> Result<MarkerSet, MarkerError> {
    let mut state = CsvReader::new(path, limits);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut record = csv::StringRecord::new();
    loop {
        let more = reader.read_record(&mut record).map_err(|e| {
            let line = e.position().map_or(1, |p| p.line() as usize);
            state.err(line, e.to_string())
        })?;
        if !more {
            break;
        }
        let position = record.position();
        let line_no = position.map_or(1, |p| p.line() as usize);
        // The record's line as written: looked up only for a comment and for the header's
        // message, not for every sample row.
        let line = || {
            position.map_or("", |p| {
                let start = (p.byte() as usize).min(text.len());
                let rest = text.get(start..).unwrap_or("");
                rest.lines().next().unwrap_or("").trim()
            })
        };
        let fields: Vec<&str> = record.iter().collect();
        if fields.iter().all(|f| f.is_empty()) {
            continue;
        }
        // A comment line's first field starts with `#` too (it is the trimmed line's start).
        if fields[0].starts_with('#')
            && let Some(comment) = line().strip_prefix('#')
        {
            state.comment(line_no, comment)?;
            continue;
        }
        if state.header_seen {
            state.sample_row(line_no, &fields)?;
        } else {
            state.header(line_no, line(), &fields)?;
        }
    }
    state.into_set()
}

/// One CSV sample row as read: frame, marker index, position (`None`: a gap), line.
type CsvRow = (usize, usize, Option<[f64; 3]>, usize);

/// The CSV reader's state between lines.
struct CsvReader<'a> {
    path: &'a Path,
    limits: &'a MarkerLimits,
    rate_hz: f64,
    header_seen: bool,
    /// Marker names in order of first appearance, and their indices.
    names: Vec<String>,
    index: std::collections::HashMap<String, usize>,
    rows: Vec<CsvRow>,
    max_frame: Option<usize>,
}

impl<'a> CsvReader<'a> {
    fn new(path: &'a Path, limits: &'a MarkerLimits) -> CsvReader<'a> {
        CsvReader {
            path,
            limits,
            rate_hz: 120.0,
            header_seen: false,
            names: Vec::new(),
            index: std::collections::HashMap::new(),
            rows: Vec::new(),
            max_frame: None,
        }
    }

    fn err(&self, line: usize, reason: String) -> MarkerError {
        MarkerError::Csv {
            path: self.path.to_path_buf(),
            line,
            reason,
        }
    }

    /// A `#` comment line (after the `#`): `frame_rate_hz = R` sets the rate, anything else
    /// is ignored.
    fn comment(&mut self, line_no: usize, comment: &str) -> Result<(), MarkerError> {
        if let Some((k, v)) = comment.split_once('=')
            && k.trim() == "frame_rate_hz"
        {
            self.rate_hz = v
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|r| r.is_finite() && *r > 0.0)
                .ok_or_else(|| {
                    self.err(
                        line_no,
                        format!("frame_rate_hz {:?} is not a positive number", v.trim()),
                    )
                })?;
        }
        Ok(())
    }

    /// The first line that is not a comment: it must be the header.
    fn header(&mut self, line_no: usize, line: &str, fields: &[&str]) -> Result<(), MarkerError> {
        if fields != ["frame", "marker", "x", "y", "z"] {
            return Err(self.err(
                line_no,
                format!("expected the header `frame,marker,x,y,z`, found {line:?}"),
            ));
        }
        self.header_seen = true;
        Ok(())
    }

    /// A sample row `frame,marker,x,y,z`.
    fn sample_row(&mut self, line_no: usize, fields: &[&str]) -> Result<(), MarkerError> {
        if fields.len() != 5 {
            return Err(self.err(
                line_no,
                format!(
                    "expected 5 fields (frame,marker,x,y,z), found {}",
                    fields.len()
                ),
            ));
        }
        let frame: usize = fields[0].parse().map_err(|_| {
            self.err(
                line_no,
                format!("frame {:?} is not a non-negative integer", fields[0]),
            )
        })?;
        if frame >= self.limits.max_frames {
            return Err(MarkerError::Limit {
                path: self.path.to_path_buf(),
                what: "frame count",
                value: frame as u64 + 1,
                max: self.limits.max_frames as u64,
            });
        }
        let name = fields[1];
        if name.is_empty() {
            return Err(self.err(line_no, "empty marker name".into()));
        }
        let marker = self.marker_index(name)?;
        let position = self.position(line_no, &fields[2..])?;
        self.max_frame = Some(self.max_frame.map_or(frame, |m: usize| m.max(frame)));
        self.rows.push((frame, marker, position, line_no));
        Ok(())
    }

    /// The index of marker `name`, numbering a new name within the marker limit.
    fn marker_index(&mut self, name: &str) -> Result<usize, MarkerError> {
        if let Some(&m) = self.index.get(name) {
            return Ok(m);
        }
        if self.names.len() >= self.limits.max_markers {
            return Err(MarkerError::Limit {
                path: self.path.to_path_buf(),
                what: "marker count",
                value: self.names.len() as u64 + 1,
                max: self.limits.max_markers as u64,
            });
        }
        self.index.insert(name.to_string(), self.names.len());
        self.names.push(name.to_string());
        Ok(self.names.len() - 1)
    }

    /// The `x,y,z` fields in mm: a gap when all three are empty.
    fn position(&self, line_no: usize, xyz: &[&str]) -> Result<Option<[f64; 3]>, MarkerError> {
        if xyz.iter().all(|f| f.is_empty()) {
            return Ok(None);
        }
        let mut p = [0.0; 3];
        for (k, f) in xyz.iter().enumerate() {
            p[k] = f
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    self.err(
                        line_no,
                        format!("{} {:?} is not a finite number", ["x", "y", "z"][k], f),
                    )
                })?;
        }
        Ok(Some(p))
    }

    /// The set: its shape checked against the limits, each sample given at most once.
    fn into_set(self) -> Result<MarkerSet, MarkerError> {
        if !self.header_seen {
            return Err(self.err(1, "missing the header `frame,marker,x,y,z`".into()));
        }
        let frames = self.max_frame.map_or(0, |m| m + 1);
        check_shape(self.path, self.names.len(), frames, self.limits)?;
        let mut set = MarkerSet::new(self.names, frames, self.rate_hz);
        let mut seen = vec![false; set.samples.len()];
        let markers = set.marker_count();
        for (frame, marker, position, line_no) in self.rows {
            let k = frame * markers + marker;
            if seen[k] {
                return Err(MarkerError::Csv {
                    path: self.path.to_path_buf(),
                    line: line_no,
                    reason: format!(
                        "marker {:?} appears twice in frame {frame}",
                        set.names[marker]
                    ),
                });
            }
            seen[k] = true;
            set.samples[k] = position;
        }
        Ok(set)
    }
}

/// Formats a marker set as CSV (gaps are omitted rows; a marker name is quoted by the `csv`
/// crate where it needs it); [`parse_csv`] reads it back exactly.
pub fn format_csv(set: &MarkerSet) -> String {
    let mut w = csv::Writer::from_writer(Vec::with_capacity(32 * set.samples.len() + 64));
    // Writing into memory cannot fail.
    let _ = w.write_record(["frame", "marker", "x", "y", "z"]);
    for f in 0..set.frames {
        for (m, name) in set.names.iter().enumerate() {
            if let Some([x, y, z]) = set.get(f, m) {
                let _ = w.write_record([
                    &f.to_string(),
                    name,
                    &x.to_string(),
                    &y.to_string(),
                    &z.to_string(),
                ]);
            }
        }
    }
    let rows = String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default();
    format!("# frame_rate_hz = {}\n{rows}", set.frame_rate_hz)
}

/// Writes a marker set as CSV, whole or not at all ([`files::write`]); an existing file is
/// replaced only with [`files::Mode::Replace`].
///
/// # Errors
/// [`MarkerError::File`].
pub fn write_csv(set: &MarkerSet, path: &Path, mode: files::Mode) -> Result<(), MarkerError> {
    Ok(files::write(path, format_csv(set), mode)?)
}

/// Reads a marker file by extension: `.c3d` or `.csv`.
///
/// # Errors
/// As [`read_c3d`] / [`read_csv`]; [`MarkerError::Csv`] at line 0 for another extension.
pub fn read_markers(path: &Path) -> Result<MarkerSet, MarkerError> {
    match ext(path).as_deref() {
        Some("c3d") => read_c3d(path),
        Some("csv") => read_csv(path),
        _ => Err(MarkerError::Csv {
            path: path.to_path_buf(),
            line: 0,
            reason: "unknown marker file type: expected .c3d or .csv".into(),
        }),
    }
}

/// Writes a marker file by extension: `.c3d` or `.csv`.
///
/// # Errors
/// As [`write_c3d`] / [`write_csv`]; [`MarkerError::Csv`] at line 0 for another extension.
pub fn write_markers(set: &MarkerSet, path: &Path, mode: files::Mode) -> Result<(), MarkerError> {
    match ext(path).as_deref() {
        Some("c3d") => write_c3d(set, path, mode),
        Some("csv") => write_csv(set, path, mode),
        _ => Err(MarkerError::Csv {
            path: path.to_path_buf(),
            line: 0,
            reason: "unknown marker file type: expected .c3d or .csv".into(),
        }),
    }
}

fn ext(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}
