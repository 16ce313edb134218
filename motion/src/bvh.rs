//! BVH (Biovision hierarchy) files.
//!
//! Reading: `HIERARCHY` with `ROOT`/`JOINT` blocks, `OFFSET`, `CHANNELS` in any order and any
//! subset of the six channel names, `End Site` blocks (kept as joints without channels named
//! `<parent>_End`), then `MOTION`, `Frames:`, `Frame Time:` and one line of values per frame.
//! Line endings may be CRLF, LF or mixed; tokens may be separated by any whitespace. The
//! declared frame count is checked against the limits and the bytes present before the matrix
//! is allocated, and must match the lines that follow.
//!
//! Refused, naming the file and line: a value that is not a finite number (`nan`, `inf`,
//! `1e999`), an `OFFSET` component beyond [`MAX_OFFSET_UNITS`], `OFFSET` or `CHANNELS` given
//! twice in one joint.

use std::fmt::Write as _;
use std::path::Path;

use crate::bodymap;
use crate::clip::{Axis, ChannelKind, Clip, Joint, Rest, Skeleton, SkeletonFormat, Units};
use crate::error::{Limits, ParseError, WriteError};
use crate::text::{
    bad_number, fields, fmt_num, lines, number, numbers, parse_finite, push_num, read_text, syntax,
};

/// The largest `OFFSET` component the reader accepts, in the file's length units. The unit is
/// only known once the whole skeleton is read (it is inferred from the skeleton's height), so
/// the bound is in file units and generous for every unit BVH files use: 100 m in a millimetre
/// file, 1 km in a centimetre one. CMU's offsets are under 10 units.
pub const MAX_OFFSET_UNITS: f64 = 1e5;

/// Reads a BVH file with the default [`Limits`].
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_bvh(path: &Path) -> Result<Clip, ParseError> {
    read_bvh_with(path, &Limits::default())
}

/// Reads a BVH file with explicit limits.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_bvh_with(path: &Path, limits: &Limits) -> Result<Clip, ParseError> {
    let text = read_text(path, limits)?;
    parse_bvh(&text, path, limits)
}

struct Tokens<'a> {
    toks: Vec<(usize, &'a str)>,
    pos: usize,
    last_line: usize,
}

impl<'a> Tokens<'a> {
    fn next(&mut self, path: &Path, expected: &str) -> Result<(usize, &'a str), ParseError> {
        let t = self
            .toks
            .get(self.pos)
            .copied()
            .ok_or_else(|| ParseError::Truncated {
                path: path.to_path_buf(),
                line: self.last_line,
                expected: expected.into(),
            })?;
        self.pos += 1;
        Ok(t)
    }

    fn expect(&mut self, path: &Path, word: &str) -> Result<usize, ParseError> {
        let (ln, t) = self.next(path, &format!("`{word}`"))?;
        if t == word {
            Ok(ln)
        } else {
            Err(syntax(
                path,
                ln,
                format!("expected `{word}`, found `{}`", clip_tok(t)),
            ))
        }
    }
}

fn clip_tok(t: &str) -> String {
    t.chars().take(40).collect()
}

fn bvh_channel(path: &Path, line: usize, tok: &str) -> Result<ChannelKind, ParseError> {
    let lower = tok.to_ascii_lowercase();
    let axis = lower.chars().next().and_then(Axis::from_letter);
    match (axis, &lower.get(1..)) {
        (Some(a), Some("position")) => Ok(ChannelKind::Translation(a)),
        (Some(a), Some("rotation")) => Ok(ChannelKind::Rotation(a)),
        _ => Err(ParseError::UnknownChannel {
            path: path.to_path_buf(),
            line,
            name: clip_tok(tok),
        }),
    }
}

fn new_joint(name: String, parent: Option<usize>) -> Joint {
    Joint::new(name, parent, Rest::Offset([0.0; 3]), Vec::new())
}

/// The three values after `OFFSET` in joint `name`'s block, each finite and within
/// [`MAX_OFFSET_UNITS`].
fn offset(t: &mut Tokens<'_>, path: &Path, name: &str) -> Result<[f64; 3], ParseError> {
    let mut off = [0.0; 3];
    let what = format!("OFFSET of {name}");
    for o in &mut off {
        let (l, tok) = t.next(path, "an OFFSET value")?;
        *o = number(path, l, &what, tok)?;
        if o.abs() > MAX_OFFSET_UNITS {
            return Err(syntax(
                path,
                l,
                format!(
                    "{what}: {} is beyond the limit of {} file units",
                    fmt_num(*o),
                    fmt_num(MAX_OFFSET_UNITS)
                ),
            ));
        }
    }
    Ok(off)
}

/// The count and names after `CHANNELS` (on line `ln`): at most six, none twice.
fn channels(t: &mut Tokens<'_>, path: &Path, ln: usize) -> Result<Vec<ChannelKind>, ParseError> {
    let (l, tok) = t.next(path, "the channel count")?;
    let n: usize = tok.parse().map_err(|_| {
        syntax(
            path,
            l,
            format!("channel count `{}` is not a whole number", clip_tok(tok)),
        )
    })?;
    if n > 6 {
        return Err(ParseError::TooLarge {
            path: path.to_path_buf(),
            line: ln,
            what: "channels of one joint".into(),
            value: n as u64,
            limit: 6,
        });
    }
    let mut dofs = Vec::with_capacity(n);
    for _ in 0..n {
        let (l, tok) = t.next(path, "a channel name")?;
        let ch = bvh_channel(path, l, tok)?;
        if dofs.contains(&ch) {
            return Err(syntax(path, l, format!("channel {tok} listed twice")));
        }
        dofs.push(ch);
    }
    Ok(dofs)
}

/// `key` given again on line `l` in joint `name`'s block, first given on line `first`.
fn twice(path: &Path, l: usize, key: &str, first: usize, name: &str) -> ParseError {
    syntax(
        path,
        l,
        format!("joint {name}: `{key}` given twice (first on line {first})"),
    )
}

/// Parses the block after a joint's name: `{ OFFSET .. CHANNELS .. children }`.
fn parse_joint(
    t: &mut Tokens<'_>,
    path: &Path,
    joints: &mut Vec<Joint>,
    index: usize,
    limits: &Limits,
    depth: usize,
) -> Result<(), ParseError> {
    if depth > limits.max_joints {
        return Err(syntax(path, t.last_line, "hierarchy nested too deeply"));
    }
    t.expect(path, "{")?;
    let offset_line = t.expect(path, "OFFSET")?;
    joints[index].rest = Rest::Offset(offset(t, path, &joints[index].name)?);
    if joints[index].end_site {
        let (l, tok) = t.next(path, "`}`")?;
        return match tok {
            "}" => Ok(()),
            "OFFSET" => Err(twice(path, l, tok, offset_line, &joints[index].name)),
            other => Err(syntax(
                path,
                l,
                format!("expected `}}`, found `{}`", clip_tok(other)),
            )),
        };
    }
    let channels_line = t.expect(path, "CHANNELS")?;
    joints[index].dofs = channels(t, path, channels_line)?;
    loop {
        let (l, tok) = t.next(path, "`JOINT`, `End Site` or `}`")?;
        match tok {
            "}" => return Ok(()),
            "OFFSET" => return Err(twice(path, l, tok, offset_line, &joints[index].name)),
            "CHANNELS" => return Err(twice(path, l, tok, channels_line, &joints[index].name)),
            "JOINT" | "End" => {
                if joints.len() >= limits.max_joints {
                    return Err(ParseError::TooLarge {
                        path: path.to_path_buf(),
                        line: l,
                        what: "number of joints".into(),
                        value: joints.len() as u64 + 1,
                        limit: limits.max_joints as u64,
                    });
                }
                let child = if tok == "End" {
                    t.expect(path, "Site")?;
                    let base = format!("{}_End", joints[index].name);
                    let mut name = base.clone();
                    let mut k = 2;
                    while joints.iter().any(|j| j.name == name) {
                        name = format!("{base}{k}");
                        k += 1;
                    }
                    let mut j = new_joint(name, Some(index));
                    j.end_site = true;
                    j
                } else {
                    let (nl, name) = t.next(path, "a joint name")?;
                    if joints.iter().any(|j| j.name == name) {
                        return Err(syntax(path, nl, format!("joint {name} is defined twice")));
                    }
                    new_joint(name.to_string(), Some(index))
                };
                joints.push(child);
                let k = joints.len() - 1;
                parse_joint(t, path, joints, k, limits, depth + 1)?;
            }
            other => {
                return Err(syntax(
                    path,
                    l,
                    format!(
                        "expected `JOINT`, `End Site` or `}}`, found `{}`",
                        clip_tok(other)
                    ),
                ));
            }
        }
    }
}

/// Parses BVH text. `path` is used only in error messages.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn parse_bvh(text: &str, path: &Path, limits: &Limits) -> Result<Clip, ParseError> {
    let (joints, motion_line) = parse_hierarchy(text, path, limits)?;
    let n: usize = joints.iter().map(|j| j.dofs.len()).sum();
    let mut rest = lines(text)
        .skip(motion_line)
        .filter(|(_, l)| !l.trim().is_empty());
    let header = motion_header(&mut rest, path, motion_line)?;
    check_declared_size(&header, n, text.len(), path, limits)?;
    let data = read_frames(rest, &header, n, path)?;
    let name = joints[0].name.clone();
    let mut skeleton = Skeleton {
        name,
        format: SkeletonFormat::Bvh,
        units: Units::default(),
        joints,
        documentation: Vec::new(),
    };
    skeleton.units = bodymap::infer_bvh_units(&skeleton);
    bodymap::assign(&mut skeleton);
    Clip::new(skeleton, 1.0 / header.frame_time_s, header.declared, data)
        .map_err(|e| syntax(path, header.time_line, e.to_string()))
}

/// The joints of the `HIERARCHY` section and the line of `MOTION`.
fn parse_hierarchy(
    text: &str,
    path: &Path,
    limits: &Limits,
) -> Result<(Vec<Joint>, usize), ParseError> {
    // Split into hierarchy tokens (up to MOTION) and motion lines.
    let mut toks = Vec::new();
    let mut motion_start = None;
    let mut last_line = 0;
    for (ln, line) in lines(text) {
        last_line = ln;
        if line.trim() == "MOTION" {
            motion_start = Some(ln);
            break;
        }
        toks.extend(line.split_whitespace().map(|t| (ln, t)));
    }
    let mut t = Tokens {
        toks,
        pos: 0,
        last_line,
    };
    t.expect(path, "HIERARCHY")?;
    t.expect(path, "ROOT")?;
    let (_, root_name) = t.next(path, "the root's name")?;
    let mut joints = vec![new_joint(root_name.to_string(), None)];
    parse_joint(&mut t, path, &mut joints, 0, limits, 0)?;
    if let Some(&(ln, extra)) = t.toks.get(t.pos) {
        return Err(syntax(
            path,
            ln,
            format!("unexpected `{}` after the hierarchy", clip_tok(extra)),
        ));
    }
    let Some(motion_line) = motion_start else {
        return Err(ParseError::Truncated {
            path: path.to_path_buf(),
            line: last_line,
            expected: "`MOTION`".into(),
        });
    };
    Ok((joints, motion_line))
}

/// The `Frames:` and `Frame Time:` lines after `MOTION`.
struct MotionHeader {
    /// Frames declared.
    declared: usize,
    /// Line of `Frames:`.
    frames_line: usize,
    /// Line of `Frame Time:`.
    time_line: usize,
    frame_time_s: f64,
}

/// Reads the two header lines after `MOTION` from `rest` (the non-blank lines after it).
fn motion_header<'t>(
    rest: &mut impl Iterator<Item = (usize, &'t str)>,
    path: &Path,
    motion_line: usize,
) -> Result<MotionHeader, ParseError> {
    let (fl, frames_line) = rest.next().ok_or_else(|| ParseError::Truncated {
        path: path.to_path_buf(),
        line: motion_line,
        expected: "`Frames:`".into(),
    })?;
    let declared: usize = frames_line
        .trim()
        .strip_prefix("Frames:")
        .and_then(|v| v.trim().parse().ok())
        .ok_or_else(|| syntax(path, fl, "expected `Frames: N`"))?;
    let (tl, time_line) = rest.next().ok_or_else(|| ParseError::Truncated {
        path: path.to_path_buf(),
        line: fl,
        expected: "`Frame Time:`".into(),
    })?;
    let time_tok = time_line
        .trim()
        .strip_prefix("Frame Time:")
        .ok_or_else(|| syntax(path, tl, "expected `Frame Time: seconds`"))?;
    let frame_time_s = numbers::<1>(
        path,
        tl,
        "Frame Time",
        &time_tok.split_whitespace().collect::<Vec<_>>(),
    )?[0];
    if frame_time_s <= 0.0 {
        return Err(syntax(path, tl, "Frame Time must be positive"));
    }
    Ok(MotionHeader {
        declared,
        frames_line: fl,
        time_line: tl,
        frame_time_s,
    })
}

/// Limits before allocation: the declared count against the limits and the bytes of the
/// text (every value needs at least two bytes: a digit and a separator).
fn check_declared_size(
    header: &MotionHeader,
    n: usize,
    bytes_left: usize,
    path: &Path,
    limits: &Limits,
) -> Result<(), ParseError> {
    let declared = header.declared;
    let values = declared.saturating_mul(n);
    if declared > limits.max_frames || values > limits.max_values || values / 2 > bytes_left {
        return Err(ParseError::TooLarge {
            path: path.to_path_buf(),
            line: header.frames_line,
            what: "declared frames × channels".into(),
            value: values as u64,
            limit: (limits.max_values.min(bytes_left / 2)) as u64,
        });
    }
    Ok(())
}

/// The channel-major matrix of the frame lines: exactly the declared count, `n` values each.
fn read_frames<'t>(
    rest: impl Iterator<Item = (usize, &'t str)>,
    header: &MotionHeader,
    n: usize,
    path: &Path,
) -> Result<Vec<f64>, ParseError> {
    let declared = header.declared;
    let mut data = vec![0.0; declared.saturating_mul(n)];
    let mut f = 0;
    let mut line_of_last = header.time_line;
    for (ln, line) in rest {
        line_of_last = ln;
        if f == declared {
            return Err(ParseError::FrameCount {
                path: path.to_path_buf(),
                line: ln,
                detail: format!("`Frames: {declared}` but more frame lines follow"),
            });
        }
        let mut count = 0;
        for (c, tok) in fields(line).enumerate() {
            count += 1;
            if c < n {
                // The error's text is built only when there is one.
                data[c * declared + f] = parse_finite(tok)
                    .ok_or_else(|| bad_number(path, ln, &format!("frame {}", f + 1), tok))?;
            }
        }
        if count != n {
            return Err(ParseError::WrongCount {
                path: path.to_path_buf(),
                line: ln,
                what: format!("frame {}", f + 1),
                expected: n,
                found: count,
            });
        }
        f += 1;
    }
    if f != declared {
        return Err(ParseError::FrameCount {
            path: path.to_path_buf(),
            line: line_of_last,
            detail: format!("`Frames: {declared}` but {f} frame lines"),
        });
    }
    if declared == 0 {
        return Err(ParseError::FrameCount {
            path: path.to_path_buf(),
            line: header.frames_line,
            detail: "no frames".into(),
        });
    }
    Ok(data)
}

/// Writes a BVH clip (tabs for nesting, shortest exact numbers).
///
/// # Errors
/// [`WriteError::Unsupported`] when the clip has an ASF skeleton; convert it with
/// [`crate::convert::asf_to_bvh`] first.
pub fn write_bvh(clip: &Clip, path: &Path) -> Result<String, WriteError> {
    let sk = &clip.skeleton;
    if sk.format != SkeletonFormat::Bvh {
        return Err(WriteError::Unsupported {
            path: path.to_path_buf(),
            reason: "the clip has an ASF skeleton: convert it to BVH first".into(),
        });
    }
    // Decoded values take up to 17 significant digits: about 20 bytes each.
    let mut s = String::with_capacity(clip.frames() * clip.channel_count() * 20 + 4096);
    s.push_str("HIERARCHY\n");
    write_joint(&mut s, sk, 0, 0);
    s.push_str("MOTION\n");
    let _ = writeln!(s, "Frames: {}", clip.frames());
    let _ = writeln!(s, "Frame Time: {}", fmt_num(1.0 / clip.frame_rate_hz));
    for f in 0..clip.frames() {
        for c in 0..clip.channel_count() {
            if c > 0 {
                s.push(' ');
            }
            push_num(&mut s, clip.value(c, f));
        }
        s.push('\n');
    }
    Ok(s)
}

fn write_joint(s: &mut String, sk: &Skeleton, i: usize, depth: usize) {
    let tabs = "\t".repeat(depth);
    let j = &sk.joints[i];
    if j.parent.is_none() {
        let _ = writeln!(s, "{tabs}ROOT {}", j.name);
    } else if j.end_site {
        let _ = writeln!(s, "{tabs}End Site");
    } else {
        let _ = writeln!(s, "{tabs}JOINT {}", j.name);
    }
    let _ = writeln!(s, "{tabs}{{");
    let _ = writeln!(
        s,
        "{tabs}\tOFFSET {}",
        j.rest.vector().map(fmt_num).join(" ")
    );
    if !j.end_site {
        let names: Vec<String> = j.dofs.iter().map(|d| d.bvh_name()).collect();
        let _ = writeln!(s, "{tabs}\tCHANNELS {} {}", names.len(), names.join(" "));
        for c in sk.children(i).collect::<Vec<_>>() {
            write_joint(s, sk, c, depth + 1);
        }
    }
    let _ = writeln!(s, "{tabs}}}");
}
