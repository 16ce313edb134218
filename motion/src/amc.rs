//! Acclaim AMC motion files.
//!
//! An AMC file lists, per frame, a frame number and one line per bone with that bone's dof
//! values in the ASF `dof` order. Bones without dofs need no line. Frames must be numbered
//! consecutively; every bone with dofs must appear once per frame. `:RADIANS` values are
//! converted to degrees. AMC carries no frame rate; CMU captures at 120 Hz.

use std::fmt::Write as _;
use std::path::Path;

use crate::clip::{Clip, Skeleton, SkeletonFormat};
use crate::error::{Limits, ParseError, WriteError};
use crate::text::{bad_number, fields, fmt_num, lines, parse_finite, push_num, read_text, syntax};

/// The frame rate of CMU AMC files, which do not state one.
pub const CMU_FRAME_RATE_HZ: f64 = 120.0;

/// Reads an AMC file with an explicit frame rate (CMU files: [`CMU_FRAME_RATE_HZ`]) and limits.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_amc_with(
    path: &Path,
    skeleton: &Skeleton,
    frame_rate_hz: f64,
    limits: &Limits,
) -> Result<Clip, ParseError> {
    let text = read_text(path, limits)?;
    parse_amc(&text, path, skeleton, frame_rate_hz, limits)
}

/// Parses AMC text for `skeleton`. `path` is used only in error messages.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason: unknown bone, wrong number of values,
/// a value that is not a finite number (`nan`, `inf`, `1e999`; in `:RADIANS`, one too large
/// for degrees), non-consecutive frame numbers, a frame missing a bone, no frames.
pub fn parse_amc(
    text: &str,
    path: &Path,
    skeleton: &Skeleton,
    frame_rate_hz: f64,
    limits: &Limits,
) -> Result<Clip, ParseError> {
    if skeleton.format != SkeletonFormat::Asf {
        return Err(syntax(path, 0, "an AMC file needs an ASF skeleton"));
    }
    if !(frame_rate_hz.is_finite() && frame_rate_hz > 0.0) {
        return Err(syntax(
            path,
            0,
            format!("frame rate {frame_rate_hz} Hz is not positive"),
        ));
    }
    let mut reader = AmcReader::new(path, skeleton, limits);
    for (ln, raw) in lines(text) {
        reader.last_line = ln;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if let Some(kw) = line.strip_prefix(':') {
            reader.header_keyword(ln, kw)?;
            continue;
        }
        let mut toks = fields(line);
        let first = toks.next().unwrap_or_default();
        // The values of a bone line, kept on the stack (a CMU bone has at most 6 dofs; a
        // longer line is only counted, for the error).
        let mut rest = [""; MAX_LINE_VALUES];
        let mut found = 0;
        for tok in toks {
            if let Some(slot) = rest.get_mut(found) {
                *slot = tok;
            }
            found += 1;
        }
        if found == 0 && first.bytes().all(|b| b.is_ascii_digit()) {
            reader.frame_number_line(ln, first)?;
        } else {
            reader.bone_line(ln, first, &rest[..found.min(MAX_LINE_VALUES)], found)?;
        }
    }
    reader.finish(frame_rate_hz)
}

/// Values of a bone line the reader keeps (a joint has at most six dofs, three rotations
/// and three translations); a line with more is an error whatever they are.
const MAX_LINE_VALUES: usize = 8;

/// The reader's state between the lines of an AMC file.
struct AmcReader<'a> {
    path: &'a Path,
    skeleton: &'a Skeleton,
    limits: &'a Limits,
    /// Offset of each joint's first channel in a frame.
    offsets: Vec<usize>,
    /// Channels per frame.
    n: usize,
    radians: bool,
    /// The frames read so far, frame-major.
    values: Vec<f64>,
    /// The frame being read.
    frame: Vec<f64>,
    /// Which joints the frame being read has given.
    seen: Vec<bool>,
    frames: usize,
    /// Number of the frame being read (`None` before the first).
    frame_number: Option<i64>,
    /// Line of the frame being read's number.
    frame_line: usize,
    last_line: usize,
    /// The joint of each bone line of the first frame, in the order it gave them: later
    /// frames list the bones in the same order, so a name is checked against this guess
    /// before the skeleton is searched.
    order: Vec<usize>,
    /// Bone lines read so far in the frame being read.
    lines_in_frame: usize,
}

impl<'a> AmcReader<'a> {
    fn new(path: &'a Path, skeleton: &'a Skeleton, limits: &'a Limits) -> AmcReader<'a> {
        let mut offsets = Vec::with_capacity(skeleton.joints.len());
        let mut n = 0;
        for j in &skeleton.joints {
            offsets.push(n);
            n += j.dofs.len();
        }
        AmcReader {
            path,
            skeleton,
            limits,
            offsets,
            n,
            radians: false,
            values: Vec::new(),
            frame: vec![0.0; n],
            seen: vec![false; skeleton.joints.len()],
            frames: 0,
            frame_number: None,
            frame_line: 0,
            last_line: 0,
            order: Vec::new(),
            lines_in_frame: 0,
        }
    }

    /// A `:KEYWORD` header line, allowed only before the first frame.
    fn header_keyword(&mut self, ln: usize, kw: &str) -> Result<(), ParseError> {
        if self.frame_number.is_some() {
            return Err(syntax(
                self.path,
                ln,
                "header keyword after the first frame",
            ));
        }
        match kw.trim().to_ascii_uppercase().as_str() {
            "FULLY-SPECIFIED" => {}
            "DEGREES" => self.radians = false,
            "RADIANS" => self.radians = true,
            other => return Err(syntax(self.path, ln, format!("unknown header `:{other}`"))),
        }
        Ok(())
    }

    /// A frame number: ends the frame before it (which must follow on), starts a new one
    /// within the limits.
    fn frame_number_line(&mut self, ln: usize, first: &str) -> Result<(), ParseError> {
        let path = self.path;
        let num: i64 = first
            .parse()
            .map_err(|_| syntax(path, ln, "frame number too large"))?;
        if let Some(prev) = self.frame_number {
            self.end_frame(ln)?;
            if num != prev + 1 {
                return Err(ParseError::FrameCount {
                    path: path.to_path_buf(),
                    line: ln,
                    detail: format!("frame {num} follows frame {prev}"),
                });
            }
        }
        self.frames += 1;
        let (frames, n, limits) = (self.frames, self.n, self.limits);
        if frames > limits.max_frames || frames.saturating_mul(n) > limits.max_values {
            return Err(ParseError::TooLarge {
                path: path.to_path_buf(),
                line: ln,
                what: "number of frames".into(),
                value: frames as u64,
                limit: limits.max_frames.min(limits.max_values / n.max(1)) as u64,
            });
        }
        self.frame_number = Some(num);
        self.frame_line = ln;
        self.lines_in_frame = 0;
        Ok(())
    }

    /// The joint named `name`: the one the first frame gave at this line, else found by
    /// name (and remembered for the next frames).
    fn joint_named(&mut self, name: &str) -> Option<usize> {
        let k = self.lines_in_frame;
        self.lines_in_frame += 1;
        if let Some(&j) = self.order.get(k)
            && self.skeleton.joints[j].name == name
        {
            return Some(j);
        }
        let j = self.skeleton.joint_index(name)?;
        if let Some(slot) = self.order.get_mut(k) {
            *slot = j;
        } else {
            self.order.push(j);
        }
        Some(j)
    }

    /// `bone v1 v2 ...`: one bone's values in the frame being read; `rest` holds the first
    /// values of the `found` the line has.
    fn bone_line(
        &mut self,
        ln: usize,
        first: &str,
        rest: &[&str],
        found: usize,
    ) -> Result<(), ParseError> {
        let path = self.path;
        if self.frame_number.is_none() {
            return Err(syntax(
                path,
                ln,
                format!("bone line `{first}` before the first frame number"),
            ));
        }
        let Some(j) = self.joint_named(first) else {
            return Err(ParseError::UnknownBone {
                path: path.to_path_buf(),
                line: ln,
                name: first.into(),
            });
        };
        let joint = &self.skeleton.joints[j];
        if self.seen[j] {
            return Err(syntax(
                path,
                ln,
                format!("bone {first} appears twice in frame {}", self.frames),
            ));
        }
        if found != joint.dofs.len() || rest.len() != found {
            return Err(ParseError::WrongCount {
                path: path.to_path_buf(),
                line: ln,
                what: format!("bone {first}"),
                expected: joint.dofs.len(),
                found,
            });
        }
        for (k, tok) in rest.iter().enumerate() {
            // The error's text is built only when there is an error (one `format!` per line
            // was a sixth of the reader's time).
            let v = parse_finite(tok)
                .ok_or_else(|| bad_number(path, ln, &format!("bone {first}"), tok))?;
            let v = if self.radians && joint.dofs[k].is_rotation() {
                // A finite angle over ~3e306 rad is `inf` in degrees.
                let deg = v.to_degrees();
                if !deg.is_finite() {
                    return Err(syntax(
                        path,
                        ln,
                        format!(
                            "bone {first}: {} rad is too large to hold in degrees",
                            fmt_num(v)
                        ),
                    ));
                }
                deg
            } else {
                v
            };
            self.frame[self.offsets[j] + k] = v;
        }
        self.seen[j] = true;
        Ok(())
    }

    /// Ends the frame being read: every bone with dofs must have been given.
    fn end_frame(&mut self, line: usize) -> Result<(), ParseError> {
        for (j, joint) in self.skeleton.joints.iter().enumerate() {
            if !joint.dofs.is_empty() && !self.seen[j] {
                return Err(ParseError::MissingBone {
                    path: self.path.to_path_buf(),
                    line,
                    frame: self.frames,
                    name: joint.name.clone(),
                });
            }
        }
        self.values.extend_from_slice(&self.frame);
        self.seen.fill(false);
        Ok(())
    }

    /// Ends the last frame and builds the clip (channel-major).
    fn finish(mut self, frame_rate_hz: f64) -> Result<Clip, ParseError> {
        let (path, last_line) = (self.path, self.last_line);
        if self.frame_number.is_none() {
            return Err(ParseError::Truncated {
                path: path.to_path_buf(),
                line: last_line,
                expected: "at least one frame".into(),
            });
        }
        self.end_frame(last_line.max(self.frame_line))?;
        let (frames, n) = (self.frames, self.n);
        // frame-major -> channel-major
        let mut data = vec![0.0; self.values.len()];
        for f in 0..frames {
            for c in 0..n {
                data[c * frames + f] = self.values[f * n + c];
            }
        }
        Clip::new(self.skeleton.clone(), frame_rate_hz, frames, data)
            .map_err(|e| syntax(path, last_line, e.to_string()))
    }
}

/// Writes a clip as AMC text (`:FULLY-SPECIFIED`, `:DEGREES`, frames numbered from 1, bones in
/// skeleton order, shortest exact number format).
///
/// # Errors
/// [`WriteError::Unsupported`] when the clip's skeleton is not an ASF skeleton.
pub fn write_amc(clip: &Clip, path: &Path) -> Result<String, WriteError> {
    let sk = &clip.skeleton;
    if sk.format != SkeletonFormat::Asf {
        return Err(WriteError::Unsupported {
            path: path.to_path_buf(),
            reason: "AMC needs an ASF skeleton; write BVH or convert the clip".into(),
        });
    }
    // Decoded values take up to 17 significant digits (about 20 bytes each), plus a bone
    // name per line: reserve that once instead of growing a 10 MB string step by step.
    let named: usize = sk
        .joints
        .iter()
        .filter(|j| !j.dofs.is_empty())
        .map(|j| j.name.len() + 1)
        .sum();
    let mut s = String::with_capacity(clip.frames() * (clip.channel_count() * 20 + named + 8));
    let _ = writeln!(s, "# AMC written by study {}", env!("CARGO_PKG_VERSION"));
    let _ = writeln!(s, ":FULLY-SPECIFIED");
    let _ = writeln!(s, ":DEGREES");
    for f in 0..clip.frames() {
        let _ = writeln!(s, "{}", f + 1);
        let mut c = 0;
        for j in &sk.joints {
            if j.dofs.is_empty() {
                continue;
            }
            s.push_str(&j.name);
            for _ in &j.dofs {
                s.push(' ');
                push_num(&mut s, clip.value(c, f));
                c += 1;
            }
            s.push('\n');
        }
    }
    Ok(s)
}
