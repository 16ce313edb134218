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
    if let Some(clip) = parse_in_halves(text, path, skeleton, frame_rate_hz, limits) {
        return Ok(clip);
    }
    let mut reader = AmcReader::new(path, skeleton, limits);
    reader.values.reserve(text.len() / 4);
    read_lines(&mut reader, text)?;
    reader.finish(frame_rate_hz)
}

/// Texts from this size on are read in two halves on two threads (a 60 s CMU clip is 5.5
/// MB, whose reading was a quarter of `study encode`).
const TWO_THREADS_FROM_BYTES: usize = 1 << 20;

/// Reads a large AMC text as two halves on two threads: the text is cut at a frame number
/// line near its middle, each half is read as a file of its own (the second with the
/// header's `:RADIANS`/`:DEGREES`), and the halves' frames are joined if the second half
/// numbers on from the first. `None` (the caller then reads the text in one pass, which
/// also names any error's place exactly) for a small text, a text with no such cut, any
/// error in a half, or halves that do not join within the limits.
fn parse_in_halves(
    text: &str,
    path: &Path,
    skeleton: &Skeleton,
    frame_rate_hz: f64,
    limits: &Limits,
) -> Option<Clip> {
    if text.len() < TWO_THREADS_FROM_BYTES {
        return None;
    }
    let radians = header_radians(text)?;
    let cut = frame_line_after(text, text.len() / 2)?;
    let (head, tail) = text.split_at(cut);
    let half = |part: &str| {
        let mut r = AmcReader::new(path, skeleton, limits);
        r.radians = radians;
        r.values.reserve(part.len() / 4);
        read_lines(&mut r, part).ok()?;
        r.into_frames().ok()
    };
    let (first, second) = std::thread::scope(|s| {
        let late = s.spawn(|| half(tail));
        (half(head), late.join())
    });
    let (mut values, frames_a, _, last_a) = first?;
    let (values_b, frames_b, first_b, _) = second.ok()??;
    let n: usize = skeleton.joints.iter().map(|j| j.dofs.len()).sum();
    let frames = frames_a + frames_b;
    if first_b != last_a.checked_add(1)?
        || frames > limits.max_frames
        || frames.saturating_mul(n) > limits.max_values
    {
        return None;
    }
    values.extend_from_slice(&values_b);
    let data = channel_major(&values, frames, n);
    Clip::new(skeleton.clone(), frame_rate_hz, frames, data).ok()
}

/// The `:DEGREES`/`:RADIANS` state the header of `text` leaves (lines before the first
/// frame), or `None` if the header has a line the reader would refuse.
fn header_radians(text: &str) -> Option<bool> {
    let mut radians = false;
    for (_, raw) in lines(text) {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let Some(kw) = line.strip_prefix(':') else {
            return Some(radians);
        };
        match kw.trim().to_ascii_uppercase().as_str() {
            "FULLY-SPECIFIED" => {}
            "DEGREES" => radians = false,
            "RADIANS" => radians = true,
            _ => return None,
        }
    }
    Some(radians)
}

/// The offset of the first line at or after byte `from` that holds a frame number alone
/// (digits, ended by `\n` or `\r\n`), within 1 MB.
fn frame_line_after(text: &str, from: usize) -> Option<usize> {
    let bytes = text.as_bytes();
    let mut at = from;
    while at < bytes.len() && at < from + (1 << 20) {
        let start = at + bytes[at..].iter().position(|&b| b == b'\n')? + 1;
        let len = bytes[start..]
            .iter()
            .position(|&b| !b.is_ascii_digit())
            .unwrap_or(bytes.len() - start);
        let after = bytes.get(start + len..start + len + 2);
        let ends = matches!(after, Some([b'\n', ..] | [b'\r', b'\n']) | None);
        if len > 0 && ends && start + len < bytes.len() {
            return Some(start);
        }
        at = start;
    }
    None
}

/// Frame-major values (`frames × n`) as a channel-major matrix.
fn channel_major(values: &[f64], frames: usize, n: usize) -> Vec<f64> {
    let mut data = vec![0.0; values.len()];
    for f in 0..frames {
        for c in 0..n {
            data[c * frames + f] = values[f * n + c];
        }
    }
    data
}

/// Feeds every line of `text` to `reader`.
fn read_lines(reader: &mut AmcReader<'_>, text: &str) -> Result<(), ParseError> {
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
    Ok(())
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
    /// Number of the first frame.
    first_number: Option<i64>,
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
            first_number: None,
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
        self.first_number.get_or_insert(num);
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

    /// Ends the last frame; the frames read (frame-major), their count and the numbers of
    /// the first and the last.
    fn into_frames(mut self) -> Result<(Vec<f64>, usize, i64, i64), ParseError> {
        let last_line = self.last_line;
        let (Some(first), Some(last)) = (self.first_number, self.frame_number) else {
            return Err(ParseError::Truncated {
                path: self.path.to_path_buf(),
                line: last_line,
                expected: "at least one frame".into(),
            });
        };
        self.end_frame(last_line.max(self.frame_line))?;
        Ok((self.values, self.frames, first, last))
    }

    /// Ends the last frame and builds the clip (channel-major).
    fn finish(self, frame_rate_hz: f64) -> Result<Clip, ParseError> {
        let (path, last_line, skeleton, n) = (self.path, self.last_line, self.skeleton, self.n);
        let (values, frames, _, _) = self.into_frames()?;
        Clip::new(
            skeleton.clone(),
            frame_rate_hz,
            frames,
            channel_major(&values, frames, n),
        )
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{WalkParams, walking_clip};

    /// One pass over the whole text: what `parse_amc` falls back to.
    fn sequential(text: &str, skeleton: &Skeleton) -> Result<Clip, ParseError> {
        let limits = Limits::default();
        let mut reader = AmcReader::new(Path::new("t.amc"), skeleton, &limits);
        read_lines(&mut reader, text)?;
        reader.finish(120.0)
    }

    fn parse(text: &str, skeleton: &Skeleton) -> Result<Clip, ParseError> {
        parse_amc(
            text,
            Path::new("t.amc"),
            skeleton,
            120.0,
            &Limits::default(),
        )
    }

    /// A walk long enough to be read in two halves, as written, with CRLF endings too.
    fn long_text() -> (Clip, String) {
        let clip = walking_clip(&WalkParams {
            duration_s: 40.0,
            ..WalkParams::default()
        });
        let text = write_amc(&clip, Path::new("t.amc")).unwrap();
        assert!(text.len() >= TWO_THREADS_FROM_BYTES, "{}", text.len());
        (clip, text)
    }

    #[test]
    fn two_halves_read_what_one_pass_reads() {
        let (clip, text) = long_text();
        let sk = &clip.skeleton;
        assert!(
            parse_in_halves(&text, Path::new("t.amc"), sk, 120.0, &Limits::default()).is_some()
        );
        let got = parse(&text, sk).unwrap();
        assert_eq!(got, sequential(&text, sk).unwrap());
        assert_eq!(got.data(), clip.data());
        let crlf = text.replace('\n', "\r\n");
        assert_eq!(parse(&crlf, sk).unwrap(), got);
        let radians = text
            .replacen(":DEGREES", ":RADIANS", 1)
            .replacen("# AMC", "# an AMC", 1);
        assert_eq!(
            parse(&radians, sk).unwrap(),
            sequential(&radians, sk).unwrap()
        );
    }

    /// Any error in either half, or halves that do not join, gives the one-pass error with
    /// its line.
    #[test]
    fn errors_in_a_long_text_are_the_one_pass_errors() {
        let (clip, text) = long_text();
        let sk = &clip.skeleton;
        let cut = frame_line_after(&text, text.len() / 2).unwrap();
        let line_at = |offset: usize| text[..offset].matches('\n').count() + 1;
        let number_at_cut: usize = text[cut..].lines().next().unwrap().parse().unwrap();
        let late = cut + text[cut..].find("\nlfemur ").unwrap() + 1;
        let early = text[..cut].rfind("\nlfemur ").unwrap() + 1;
        let mutants = [
            // a bad number late, and early
            format!("{}lfemur x{}", &text[..late], &text[late + 7..]),
            format!("{}lfemur x{}", &text[..early], &text[early + 7..]),
            // the frame at the cut numbered wrongly
            format!(
                "{}{}{}",
                &text[..cut],
                number_at_cut + 5,
                &text[cut + number_at_cut.to_string().len()..]
            ),
            // a header keyword after the first frame, in the second half
            format!("{}:RADIANS\n{}", &text[..late], &text[late..]),
            // a bone line missing in the second half
            format!(
                "{}{}",
                &text[..late],
                &text[text[late..].find('\n').unwrap() + late + 1..]
            ),
        ];
        for (k, m) in mutants.iter().enumerate() {
            let want = sequential(m, sk).unwrap_err();
            assert_eq!(
                parse(m, sk).unwrap_err().to_string(),
                want.to_string(),
                "mutant {k}"
            );
        }
        assert!(line_at(late) > line_at(cut));
    }
}
