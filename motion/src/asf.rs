//! Acclaim ASF skeleton files (as in the CMU database).
//!
//! Reading: sections `:version`, `:name`, `:units`, `:documentation`, `:root`, `:bonedata`,
//! `:hierarchy` (`:skin` is skipped); `#` comments; CRLF, LF or mixed endings; bones without a
//! `dof` line; `limits` spread over several lines; `angle rad` converted to degrees. Joints are
//! returned root first, then bones in file order (reordered only if a child precedes its
//! parent). Writing emits a canonical file that reads back equal.
//!
//! What the reader refuses, naming the file and line: a number that is not finite (the one
//! exception is `inf` in `limits`, an unbounded range), a bone direction that is zero or whose
//! length is outside [`DIRECTION_NORMALISED_RANGE`], a bone length over
//! [`MAX_BONE_LENGTH_CM`], a key given twice in one bone block. A direction off unit length by
//! more than [`DIRECTION_UNIT_TOLERANCE`] but inside the range is normalised, with a
//! [`ReadWarning`] ([`parse_asf_with_warnings`]).

use std::fmt::Write as _;
use std::path::Path;

use crate::bodymap;
use crate::clip::{Axis, BodyPart, ChannelKind, Joint, Rest, Skeleton, SkeletonFormat, Units};
use crate::error::{Limits, ParseError, ReadWarning, WriteError};
use crate::text::{fmt_num, lines, number, numbers, read_text, syntax};

/// Centimetres per inch; ASF `length L` means one unit is `1/L` inch.
const CM_PER_INCH: f64 = 2.54;

/// The longest bone the reader accepts, in centimetres (the file's `length` times the
/// `:units length` scale): 100 m is far beyond any capture volume, and far below lengths whose
/// sums in forward kinematics could overflow to `inf`. CMU bones are at most about 45 cm.
pub const MAX_BONE_LENGTH_CM: f64 = 1e4;

/// How far the length of a bone `direction` may be from 1 and still be taken as written. CMU
/// files print six significant digits, so their directions are off by up to 6e-7; a reader that
/// "corrected" them would change every real skeleton for nothing.
pub const DIRECTION_UNIT_TOLERANCE: f64 = 1e-4;

/// The lengths of a bone `direction` that are normalised (with a warning) when off unit length;
/// outside this range the direction is refused. A direction written loosely (`1 1 0`, length
/// 1.41) is still a direction; one of length 1000 or 1e-9 most likely carries the bone's length
/// or a corruption, and guessing which would be a silently wrong skeleton.
pub const DIRECTION_NORMALISED_RANGE: std::ops::RangeInclusive<f64> = 0.5..=2.0;

/// Reads an ASF file with the default [`Limits`], dropping the reader's warnings (see
/// [`read_asf_with_warnings`] to show them).
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_asf(path: &Path) -> Result<Skeleton, ParseError> {
    read_asf_with(path, &Limits::default())
}

/// Reads an ASF file with explicit limits, dropping the reader's warnings (see
/// [`read_asf_with_warnings`] to show them).
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_asf_with(path: &Path, limits: &Limits) -> Result<Skeleton, ParseError> {
    read_asf_with_warnings(path, limits).map(|(skeleton, _)| skeleton)
}

/// Reads an ASF file with explicit limits, with what the reader changed (directions
/// normalised), in file order.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_asf_with_warnings(
    path: &Path,
    limits: &Limits,
) -> Result<(Skeleton, Vec<ReadWarning>), ParseError> {
    let text = read_text(path, limits)?;
    parse_asf_with_warnings(&text, path, limits)
}

#[derive(Clone, Copy, PartialEq, Default)]
enum Section {
    #[default]
    None,
    Header,
    Units,
    Documentation,
    Root,
    BoneData,
    Hierarchy,
    Skip,
}

#[derive(Default)]
struct BoneDraft {
    line: usize,
    id: Option<u32>,
    name: Option<String>,
    direction: Option<[f64; 3]>,
    length: Option<f64>,
    axis: Option<([f64; 3], [Axis; 3])>,
    dofs: Vec<ChannelKind>,
    limits: Vec<(f64, f64)>,
    limit_values: Vec<f64>,
    /// The line of each of `limit_values` (`limits` may span several lines).
    limit_lines: Vec<usize>,
    /// Every key given so far in the block, with its line: a key given twice is refused, and
    /// a value's problem found after `end` still names the value's line.
    keys: Vec<(&'static str, usize)>,
}

/// The keys a bone block may give once each (`bodymass` and `cofmass` are skipped).
const BONE_KEYS: [&str; 7] = ["id", "name", "direction", "length", "axis", "dof", "limits"];

/// The `:root` section as read.
struct RootDraft {
    order: Option<Vec<ChannelKind>>,
    axis: [Axis; 3],
    position: [f64; 3],
    orientation: [f64; 3],
    /// Line of `orientation` (0 when absent), for an angle too large to convert.
    orientation_line: usize,
}

impl Default for RootDraft {
    fn default() -> Self {
        RootDraft {
            order: None,
            axis: [Axis::X, Axis::Y, Axis::Z],
            position: [0.0; 3],
            orientation: [0.0; 3],
            orientation_line: 0,
        }
    }
}

/// What the lines of an ASF file have said so far: the reader's state between lines.
#[derive(Default)]
struct AsfDraft {
    section: Section,
    name: String,
    units: Units,
    angle_rad: bool,
    documentation: Vec<String>,
    root: RootDraft,
    bones: Vec<BoneDraft>,
    /// The bone block between `begin` and `end`, if one is open.
    current: Option<BoneDraft>,
    /// The last bone field was `limits`: a line starting with `(` continues it.
    in_limits: bool,
    hierarchy: HierarchyDraft,
    seen_root: bool,
}

/// The `:hierarchy` section as read.
#[derive(Default)]
struct HierarchyDraft {
    /// Line number, parent, children.
    lines: Vec<(usize, String, Vec<String>)>,
    /// Inside `begin` ... `end`.
    open: bool,
    /// An `end` has been seen.
    closed: bool,
}

fn axis_order(path: &Path, line: usize, tok: &str) -> Result<[Axis; 3], ParseError> {
    let axes: Vec<Axis> = tok.chars().filter_map(Axis::from_letter).collect();
    if tok.len() != 3
        || axes.len() != 3
        || axes[0] == axes[1]
        || axes[1] == axes[2]
        || axes[0] == axes[2]
    {
        return Err(syntax(
            path,
            line,
            format!("`{tok}` is not an axis order such as XYZ"),
        ));
    }
    Ok([axes[0], axes[1], axes[2]])
}

fn channel(path: &Path, line: usize, tok: &str) -> Result<ChannelKind, ParseError> {
    let lower = tok.to_ascii_lowercase();
    let mut cs = lower.chars();
    let kind = cs.next();
    let axis = cs.next().and_then(Axis::from_letter);
    match (kind, axis, cs.next()) {
        (Some('r'), Some(a), None) => Ok(ChannelKind::Rotation(a)),
        (Some('t'), Some(a), None) => Ok(ChannelKind::Translation(a)),
        _ => Err(ParseError::UnknownChannel {
            path: path.to_path_buf(),
            line,
            name: tok.into(),
        }),
    }
}

fn limit_pairs(
    path: &Path,
    line: usize,
    values: &[f64],
    dofs: usize,
) -> Result<Vec<(f64, f64)>, ParseError> {
    if values.len() != 2 * dofs {
        return Err(ParseError::WrongCount {
            path: path.to_path_buf(),
            line,
            what: "limits (two per dof)".into(),
            expected: 2 * dofs,
            found: values.len(),
        });
    }
    Ok(values.chunks_exact(2).map(|p| (p[0], p[1])).collect())
}

/// Parses ASF text, dropping the reader's warnings (see [`parse_asf_with_warnings`]). `path`
/// is used only in error messages.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn parse_asf(text: &str, path: &Path, limits: &Limits) -> Result<Skeleton, ParseError> {
    parse_asf_with_warnings(text, path, limits).map(|(skeleton, _)| skeleton)
}

/// Parses ASF text, with what the reader changed (a bone direction off unit length,
/// normalised), in file order. `path` is used only in messages.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn parse_asf_with_warnings(
    text: &str,
    path: &Path,
    limits: &Limits,
) -> Result<(Skeleton, Vec<ReadWarning>), ParseError> {
    let mut draft = AsfDraft::default();
    let mut last_line = 0;
    for (ln, raw) in lines(text) {
        last_line = ln;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let toks: Vec<&str> = line.split_whitespace().collect();
        if let Some(kw) = toks[0].strip_prefix(':') {
            draft.start_section(path, ln, kw, &toks)?;
        } else {
            draft.section_line(path, ln, line, &toks, limits)?;
        }
    }
    draft.check_complete(path, last_line)?;
    draft.into_skeleton(path)
}

impl AsfDraft {
    /// A `:keyword` line: the section that the following lines belong to.
    fn start_section(
        &mut self,
        path: &Path,
        ln: usize,
        kw: &str,
        toks: &[&str],
    ) -> Result<(), ParseError> {
        if self.current.is_some() {
            return Err(syntax(path, ln, "bone block not closed with `end`"));
        }
        self.in_limits = false;
        self.section = match kw.to_ascii_lowercase().as_str() {
            "version" => Section::Header,
            "name" => {
                self.name = toks[1..].join(" ");
                Section::Header
            }
            "units" => Section::Units,
            "documentation" => Section::Documentation,
            "root" => {
                self.seen_root = true;
                Section::Root
            }
            "bonedata" => Section::BoneData,
            "hierarchy" => Section::Hierarchy,
            "skin" => Section::Skip,
            other => return Err(syntax(path, ln, format!("unknown section `:{other}`"))),
        };
        Ok(())
    }

    /// A line inside the current section (`line` trimmed, `toks` its words).
    fn section_line(
        &mut self,
        path: &Path,
        ln: usize,
        line: &str,
        toks: &[&str],
        limits: &Limits,
    ) -> Result<(), ParseError> {
        match self.section {
            Section::None => Err(syntax(path, ln, "text before the first `:` section")),
            Section::Header | Section::Skip => Ok(()),
            Section::Documentation => {
                self.documentation.push(line.to_string());
                Ok(())
            }
            Section::Units => self.units_line(path, ln, toks),
            Section::Root => self.root_line(path, ln, toks),
            Section::BoneData => self.bone_data_line(path, ln, line, toks, limits),
            Section::Hierarchy => self.hierarchy_line(path, ln, toks),
        }
    }

    /// `mass M`, `length L` or `angle deg|rad` under `:units`.
    fn units_line(&mut self, path: &Path, ln: usize, toks: &[&str]) -> Result<(), ParseError> {
        let what = format!("units {}", toks[0]);
        match toks[0] {
            "mass" => self.units.asf_mass = numbers::<1>(path, ln, &what, &toks[1..])?[0],
            "length" => {
                let l = numbers::<1>(path, ln, &what, &toks[1..])?[0];
                if l <= 0.0 {
                    return Err(syntax(path, ln, "units length must be positive"));
                }
                let cm_per_unit = CM_PER_INCH / l;
                // A subnormal `l` makes a unit `inf` cm, a huge one 0 cm: every length then
                // reads as `inf` or 0.
                if !cm_per_unit.is_normal() {
                    return Err(syntax(
                        path,
                        ln,
                        format!(
                            "units length {} makes one unit {} cm, which no length can be measured in",
                            fmt_num(l),
                            fmt_num(cm_per_unit)
                        ),
                    ));
                }
                self.units.asf_length = l;
                self.units.cm_per_unit = cm_per_unit;
                self.units.declared = true;
            }
            "angle" => match toks.get(1).map(|t| t.to_ascii_lowercase()).as_deref() {
                Some("deg") => self.angle_rad = false,
                Some("rad") => self.angle_rad = true,
                _ => return Err(syntax(path, ln, "units angle must be `deg` or `rad`")),
            },
            other => return Err(syntax(path, ln, format!("unknown unit `{other}`"))),
        }
        Ok(())
    }

    /// `order`, `axis`, `position` or `orientation` under `:root`.
    fn root_line(&mut self, path: &Path, ln: usize, toks: &[&str]) -> Result<(), ParseError> {
        match toks[0] {
            "order" => {
                let order = toks[1..]
                    .iter()
                    .map(|t| channel(path, ln, t))
                    .collect::<Result<Vec<_>, _>>()?;
                if order.len() > 6 {
                    return Err(syntax(path, ln, "root order lists more than 6 channels"));
                }
                self.root.order = Some(order);
            }
            "axis" => {
                let tok = toks.get(1).copied().unwrap_or("");
                self.root.axis = axis_order(path, ln, tok)?;
            }
            "position" => {
                self.root.position = numbers::<3>(path, ln, "root position", &toks[1..])?;
            }
            "orientation" => {
                self.root.orientation = numbers::<3>(path, ln, "root orientation", &toks[1..])?;
                self.root.orientation_line = ln;
            }
            other => return Err(syntax(path, ln, format!("unknown root field `{other}`"))),
        }
        Ok(())
    }

    /// A line under `:bonedata`: `begin`, `end`, a field of the open bone block, or a
    /// continuation of its `limits`.
    fn bone_data_line(
        &mut self,
        path: &Path,
        ln: usize,
        line: &str,
        toks: &[&str],
        limits: &Limits,
    ) -> Result<(), ParseError> {
        if toks[0] == "begin" {
            return self.begin_bone(path, ln, limits);
        }
        let Some(bone) = self.current.as_mut() else {
            return Err(syntax(
                path,
                ln,
                format!("`{}` outside a begin/end block", toks[0]),
            ));
        };
        if self.in_limits && toks[0].starts_with('(') {
            return bone.push_limits(path, ln, line);
        }
        self.in_limits = false;
        match toks[0] {
            "end" => self.end_bone(path, ln),
            "limits" => {
                bone.key(path, ln, "limits")?;
                self.in_limits = true;
                bone.push_limits(path, ln, &line["limits".len()..])
            }
            _ => bone.field(path, ln, toks),
        }
    }

    /// `begin`: opens a bone block, within the joint limit.
    fn begin_bone(&mut self, path: &Path, ln: usize, limits: &Limits) -> Result<(), ParseError> {
        if self.current.is_some() {
            return Err(syntax(path, ln, "`begin` inside a bone block"));
        }
        if self.bones.len() + 1 >= limits.max_joints {
            return Err(ParseError::TooLarge {
                path: path.to_path_buf(),
                line: ln,
                what: "number of bones".into(),
                value: self.bones.len() as u64 + 1,
                limit: limits.max_joints as u64,
            });
        }
        self.current = Some(BoneDraft {
            line: ln,
            ..BoneDraft::default()
        });
        self.in_limits = false;
        Ok(())
    }

    /// `end`: closes the open bone block, pairing its limit values per dof.
    fn end_bone(&mut self, path: &Path, ln: usize) -> Result<(), ParseError> {
        let mut bone = self.current.take().unwrap_or_default();
        bone.limits = if bone.limit_values.is_empty() {
            Vec::new()
        } else {
            limit_pairs(path, ln, &bone.limit_values, bone.dofs.len())?
        };
        self.bones.push(bone);
        Ok(())
    }

    /// `begin`, `end` or `parent child...` under `:hierarchy`.
    fn hierarchy_line(&mut self, path: &Path, ln: usize, toks: &[&str]) -> Result<(), ParseError> {
        match toks[0] {
            "begin" => self.hierarchy.open = true,
            "end" => {
                self.hierarchy.open = false;
                self.hierarchy.closed = true;
            }
            parent => {
                if !self.hierarchy.open {
                    return Err(syntax(path, ln, "hierarchy line outside begin/end"));
                }
                let children = toks[1..].iter().map(|s| (*s).to_string()).collect();
                self.hierarchy
                    .lines
                    .push((ln, parent.to_string(), children));
            }
        }
        Ok(())
    }

    /// At the end of the text: no open bone block, a root and a closed hierarchy.
    fn check_complete(&self, path: &Path, last_line: usize) -> Result<(), ParseError> {
        let missing = |expected: &str| ParseError::Truncated {
            path: path.to_path_buf(),
            line: last_line,
            expected: expected.into(),
        };
        if self.current.is_some() {
            return Err(missing("`end` of a bone block"));
        }
        if !self.seen_root {
            return Err(missing("a `:root` section"));
        }
        if !self.hierarchy.closed {
            return Err(missing("a complete `:hierarchy` section"));
        }
        Ok(())
    }

    /// The file's angle `v` (of `what`, on `line`) in degrees. An infinite `v` (an unbounded
    /// `limits` range) stays as it is; a finite one too large for degrees is refused.
    fn to_deg(&self, path: &Path, line: usize, what: &str, v: f64) -> Result<f64, ParseError> {
        if !self.angle_rad || v.is_infinite() {
            return Ok(v);
        }
        let deg = v.to_degrees();
        if deg.is_finite() {
            Ok(deg)
        } else {
            Err(syntax(
                path,
                line,
                format!("{what}: {} rad is too large to hold in degrees", fmt_num(v)),
            ))
        }
    }

    /// The skeleton: the root, then the bones ordered by the hierarchy; and what was changed.
    fn into_skeleton(self, path: &Path) -> Result<(Skeleton, Vec<ReadWarning>), ParseError> {
        let mut axis_deg = [0.0; 3];
        for (d, &v) in axis_deg.iter_mut().zip(&self.root.orientation) {
            *d = self.to_deg(path, self.root.orientation_line, "root orientation", v)?;
        }
        let root = Joint {
            name: "root".into(),
            parent: None,
            rest: Rest::Offset(self.root.position),
            dofs: self.root.order.clone().unwrap_or_default(),
            axis_deg,
            axis_order: self.root.axis,
            limits: Vec::new(),
            id: None,
            end_site: false,
            body_part: BodyPart::Torso,
            chain_depth: 0,
        };
        let mut warnings = Vec::new();
        let drafts = self.bone_joints(path, &mut warnings)?;
        let joints = order_by_hierarchy(path, root, &drafts, &self.hierarchy.lines)?;
        let mut skeleton = Skeleton {
            name: self.name,
            format: SkeletonFormat::Asf,
            units: self.units,
            joints,
            documentation: self.documentation,
        };
        bodymap::assign(&mut skeleton);
        Ok((skeleton, warnings))
    }

    /// Every bone block as a joint (no parent yet) with its `begin` line, in file order;
    /// directions normalised are added to `warnings`.
    fn bone_joints(
        &self,
        path: &Path,
        warnings: &mut Vec<ReadWarning>,
    ) -> Result<Vec<(Joint, usize)>, ParseError> {
        let mut drafts: Vec<(Joint, usize)> = Vec::with_capacity(self.bones.len());
        for b in &self.bones {
            let joint = self.bone_joint(path, b, warnings)?;
            if drafts.iter().any(|(j, _)| j.name == joint.name) || joint.name == "root" {
                return Err(syntax(
                    path,
                    b.line,
                    format!("bone {} is defined twice", joint.name),
                ));
            }
            drafts.push((joint, b.line));
        }
        Ok(drafts)
    }
}

impl BoneDraft {
    /// A field line of a bone block other than `begin`, `end` and `limits`.
    fn field(&mut self, path: &Path, ln: usize, toks: &[&str]) -> Result<(), ParseError> {
        if let Some(key) = BONE_KEYS.iter().find(|k| **k == toks[0]) {
            self.key(path, ln, key)?;
        }
        let bone_name = self.name.clone().unwrap_or_else(|| "?".into());
        match toks[0] {
            "id" => {
                let id = toks.get(1).and_then(|t| t.parse::<u32>().ok());
                if id.is_none() || toks.len() != 2 {
                    return Err(syntax(path, ln, "bone id must be one whole number"));
                }
                self.id = id;
            }
            "name" => {
                if toks.len() != 2 {
                    return Err(syntax(path, ln, "bone name must be one word"));
                }
                self.name = Some(toks[1].to_string());
            }
            "direction" => {
                let what = format!("direction of bone {bone_name}");
                self.direction = Some(numbers::<3>(path, ln, &what, &toks[1..])?);
            }
            "length" => {
                let what = format!("length of bone {bone_name}");
                let l = numbers::<1>(path, ln, &what, &toks[1..])?[0];
                if l < 0.0 {
                    return Err(syntax(path, ln, "bone length is negative"));
                }
                self.length = Some(l);
            }
            "axis" => {
                if toks.len() != 5 {
                    return Err(ParseError::WrongCount {
                        path: path.to_path_buf(),
                        line: ln,
                        what: format!("axis of bone {bone_name} (3 angles and an order)"),
                        expected: 4,
                        found: toks.len() - 1,
                    });
                }
                let what = format!("axis of bone {bone_name}");
                let a = numbers::<3>(path, ln, &what, &toks[1..4])?;
                self.axis = Some((a, axis_order(path, ln, toks[4])?));
            }
            "dof" => {
                let dofs = toks[1..]
                    .iter()
                    .map(|t| channel(path, ln, t))
                    .collect::<Result<Vec<_>, _>>()?;
                if dofs.len() > 3 || dofs.iter().any(|d| !d.is_rotation()) {
                    return Err(syntax(
                        path,
                        ln,
                        format!("bone {bone_name}: only rx, ry, rz dofs are supported on bones"),
                    ));
                }
                self.dofs = dofs;
            }
            "bodymass" | "cofmass" => {}
            other => {
                return Err(syntax(path, ln, format!("unknown bone field `{other}`")));
            }
        }
        Ok(())
    }

    /// Records that `key` is given on line `ln`, refusing a key the block has given before.
    fn key(&mut self, path: &Path, ln: usize, key: &'static str) -> Result<(), ParseError> {
        if let Some(&(_, first)) = self.keys.iter().find(|(k, _)| *k == key) {
            let bone = self
                .name
                .as_ref()
                .map_or_else(String::new, |n| format!("bone {n}: "));
            return Err(syntax(
                path,
                ln,
                format!("{bone}`{key}` given twice in one bone block (first on line {first})"),
            ));
        }
        self.keys.push((key, ln));
        Ok(())
    }

    /// The line `key` was given on, or the block's `begin` line when it was not.
    fn line_of(&self, key: &str) -> usize {
        self.keys
            .iter()
            .find(|(k, _)| *k == key)
            .map_or(self.line, |&(_, ln)| ln)
    }

    /// The limit values of one `limits` line (or of a line continuing it).
    fn push_limits(&mut self, path: &Path, ln: usize, text: &str) -> Result<(), ParseError> {
        let cleaned: String = text
            .chars()
            .map(|c| if c == '(' || c == ')' { ' ' } else { c })
            .collect();
        for tok in cleaned.split_whitespace() {
            // Limits may be unbounded (`inf`); values elsewhere must be finite.
            let v = match tok.to_ascii_lowercase().as_str() {
                "inf" | "+inf" => f64::INFINITY,
                "-inf" => f64::NEG_INFINITY,
                _ => number(path, ln, "limits", tok)?,
            };
            if self.limit_values.len() >= 6 {
                return Err(syntax(path, ln, "more than three limit pairs"));
            }
            self.limit_values.push(v);
            self.limit_lines.push(ln);
        }
        Ok(())
    }
}

impl AsfDraft {
    /// The closed block `b` as a joint (no parent yet): direction a unit vector, length within
    /// [`MAX_BONE_LENGTH_CM`], angles in degrees.
    fn bone_joint(
        &self,
        path: &Path,
        b: &BoneDraft,
        warnings: &mut Vec<ReadWarning>,
    ) -> Result<Joint, ParseError> {
        let Some(bname) = b.name.clone() else {
            return Err(syntax(path, b.line, "bone block without a name"));
        };
        let direction = b
            .direction
            .ok_or_else(|| syntax(path, b.line, format!("bone {bname} has no direction")))?;
        let direction = unit_direction(path, b.line_of("direction"), &bname, direction, warnings)?;
        let length = b
            .length
            .ok_or_else(|| syntax(path, b.line, format!("bone {bname} has no length")))?;
        let length_cm = length * self.units.cm_per_unit;
        if length_cm > MAX_BONE_LENGTH_CM {
            return Err(syntax(
                path,
                b.line_of("length"),
                format!(
                    "length of bone {bname} is {} cm, over the limit of {} cm",
                    fmt_num(length_cm),
                    fmt_num(MAX_BONE_LENGTH_CM)
                ),
            ));
        }
        let (axis, order) = b.axis.unwrap_or(([0.0; 3], [Axis::X, Axis::Y, Axis::Z]));
        let what = format!("axis of bone {bname}");
        let mut axis_deg = [0.0; 3];
        for (d, v) in axis_deg.iter_mut().zip(axis) {
            *d = self.to_deg(path, b.line_of("axis"), &what, v)?;
        }
        let what = format!("limits of bone {bname}");
        let line_of_limit = |k: usize| b.limit_lines.get(k).copied().unwrap_or(b.line);
        let limits = b
            .limits
            .iter()
            .enumerate()
            .map(|(k, &(lo, hi))| {
                Ok((
                    self.to_deg(path, line_of_limit(2 * k), &what, lo)?,
                    self.to_deg(path, line_of_limit(2 * k + 1), &what, hi)?,
                ))
            })
            .collect::<Result<Vec<_>, ParseError>>()?;
        Ok(Joint {
            name: bname,
            parent: None,
            rest: Rest::Bone { direction, length },
            dofs: b.dofs.clone(),
            axis_deg,
            axis_order: order,
            limits,
            id: b.id,
            end_site: false,
            body_part: BodyPart::Torso,
            chain_depth: 0,
        })
    }
}

/// Bone `bone`'s `direction` (given on `line`) as a unit vector: as written within
/// [`DIRECTION_UNIT_TOLERANCE`] of unit length, normalised with a warning within
/// [`DIRECTION_NORMALISED_RANGE`], refused otherwise (and when zero).
fn unit_direction(
    path: &Path,
    line: usize,
    bone: &str,
    d: [f64; 3],
    warnings: &mut Vec<ReadWarning>,
) -> Result<[f64; 3], ParseError> {
    let written = d.map(fmt_num).join(" ");
    // Scaled by the largest component, so that neither 1e200 nor 1e-200 over- or underflows
    // when squared.
    let scale = d.iter().fold(0.0_f64, |m, c| m.max(c.abs()));
    if scale <= 0.0 {
        return Err(syntax(
            path,
            line,
            format!("direction of bone {bone} is {written}: a zero vector points nowhere"),
        ));
    }
    let norm = scale * d.iter().map(|c| (c / scale).powi(2)).sum::<f64>().sqrt();
    if (norm - 1.0).abs() <= DIRECTION_UNIT_TOLERANCE {
        return Ok(d);
    }
    if !DIRECTION_NORMALISED_RANGE.contains(&norm) {
        return Err(syntax(
            path,
            line,
            format!(
                "direction of bone {bone} is {written}, of length {}: not a unit vector, and too far from one to normalise (lengths {} to {} are)",
                fmt_num(norm),
                fmt_num(*DIRECTION_NORMALISED_RANGE.start()),
                fmt_num(*DIRECTION_NORMALISED_RANGE.end()),
            ),
        ));
    }
    let unit = d.map(|c| c / norm);
    warnings.push(ReadWarning {
        path: path.to_path_buf(),
        line,
        message: format!(
            "direction of bone {bone} is {written}, of length {}: normalised to {}",
            fmt_num(norm),
            unit.map(fmt_num).join(" ")
        ),
    });
    Ok(unit)
}

/// Assigns parents from `:hierarchy` and orders joints so that every parent precedes its
/// children, keeping file order where it already does.
fn order_by_hierarchy(
    path: &Path,
    root: Joint,
    drafts: &[(Joint, usize)],
    hierarchy: &[(usize, String, Vec<String>)],
) -> Result<Vec<Joint>, ParseError> {
    // parent name per bone, from the hierarchy section
    let mut parent_of: Vec<Option<String>> = vec![None; drafts.len()];
    for (ln, parent, children) in hierarchy {
        if parent != "root" && !drafts.iter().any(|(j, _)| &j.name == parent) {
            return Err(ParseError::UnknownBone {
                path: path.to_path_buf(),
                line: *ln,
                name: parent.clone(),
            });
        }
        for child in children {
            let Some(k) = drafts.iter().position(|(j, _)| &j.name == child) else {
                return Err(ParseError::UnknownBone {
                    path: path.to_path_buf(),
                    line: *ln,
                    name: child.clone(),
                });
            };
            if parent_of[k].is_some() {
                return Err(syntax(
                    path,
                    *ln,
                    format!("bone {child} is given two parents"),
                ));
            }
            parent_of[k] = Some(parent.clone());
        }
    }
    let mut joints = vec![root];
    let mut placed = vec![false; drafts.len()];
    // Each pass places every bone whose parent is placed; n passes suffice for any tree.
    loop {
        let mut progress = false;
        for (k, (joint, _)) in drafts.iter().enumerate() {
            if placed[k] {
                continue;
            }
            let Some(pname) = &parent_of[k] else { continue };
            if let Some(p) = joints.iter().position(|j| &j.name == pname) {
                let mut j = joint.clone();
                j.parent = Some(p);
                joints.push(j);
                placed[k] = true;
                progress = true;
            }
        }
        if !progress {
            break;
        }
    }
    if let Some(k) = placed.iter().position(|p| !p) {
        let (j, ln) = &drafts[k];
        let why = if parent_of[k].is_none() {
            format!("bone {} is not attached in :hierarchy", j.name)
        } else {
            format!("bone {} is in a cycle of the hierarchy", j.name)
        };
        return Err(syntax(path, *ln, why));
    }
    Ok(joints)
}

fn axis_order_text(order: [Axis; 3]) -> String {
    order.iter().map(|a| a.letter()).collect()
}

/// Writes a skeleton as ASF text (degrees; the file's length unit).
///
/// # Errors
/// [`WriteError::Unsupported`] when the skeleton is not an ASF skeleton (a BVH skeleton has no
/// bone directions; convert the clip instead).
pub fn write_asf(skeleton: &Skeleton, path: &Path) -> Result<String, WriteError> {
    if skeleton.format != SkeletonFormat::Asf {
        return Err(WriteError::Unsupported {
            path: path.to_path_buf(),
            reason: "a BVH skeleton cannot be written as ASF".into(),
        });
    }
    let root = &skeleton.joints[0];
    let mut s = String::new();
    let num3 = |v: [f64; 3]| v.map(fmt_num).join(" ");
    let _ = writeln!(s, "# ASF written by study {}", env!("CARGO_PKG_VERSION"));
    let _ = writeln!(s, ":version 1.10");
    let _ = writeln!(s, ":name {}", skeleton.name);
    let _ = writeln!(s, ":units");
    let _ = writeln!(s, "  mass {}", fmt_num(skeleton.units.asf_mass));
    let _ = writeln!(s, "  length {}", fmt_num(skeleton.units.asf_length));
    let _ = writeln!(s, "  angle deg");
    if !skeleton.documentation.is_empty() {
        let _ = writeln!(s, ":documentation");
        for d in &skeleton.documentation {
            let _ = writeln!(s, "  {d}");
        }
    }
    let _ = writeln!(s, ":root");
    let order: Vec<String> = root
        .dofs
        .iter()
        .map(|d| d.asf_name().to_ascii_uppercase())
        .collect();
    let _ = writeln!(s, "  order {}", order.join(" "));
    let _ = writeln!(s, "  axis {}", axis_order_text(root.axis_order));
    let _ = writeln!(s, "  position {}", num3(root.rest.vector()));
    let _ = writeln!(s, "  orientation {}", num3(root.axis_deg));
    let _ = writeln!(s, ":bonedata");
    for j in &skeleton.joints[1..] {
        let _ = writeln!(s, "  begin");
        if let Some(id) = j.id {
            let _ = writeln!(s, "    id {id}");
        }
        let _ = writeln!(s, "    name {}", j.name);
        let (direction, length) = match &j.rest {
            Rest::Bone { direction, length } => (*direction, *length),
            Rest::Offset(v) => {
                let l = j.rest.length();
                let d = if l > 0.0 {
                    [v[0] / l, v[1] / l, v[2] / l]
                } else {
                    [0.0; 3]
                };
                (d, l)
            }
        };
        let _ = writeln!(s, "    direction {}", num3(direction));
        let _ = writeln!(s, "    length {}", fmt_num(length));
        let _ = writeln!(
            s,
            "    axis {} {}",
            num3(j.axis_deg),
            axis_order_text(j.axis_order)
        );
        if !j.dofs.is_empty() {
            let dofs: Vec<String> = j.dofs.iter().map(|d| d.asf_name()).collect();
            let _ = writeln!(s, "    dof {}", dofs.join(" "));
        }
        for (k, (lo, hi)) in j.limits.iter().enumerate() {
            let lead = if k == 0 { "    limits" } else { "          " };
            let _ = writeln!(s, "{lead} ({} {})", fmt_limit(*lo), fmt_limit(*hi));
        }
        let _ = writeln!(s, "  end");
    }
    let _ = writeln!(s, ":hierarchy");
    let _ = writeln!(s, "  begin");
    for (i, j) in skeleton.joints.iter().enumerate() {
        let children: Vec<&str> = skeleton
            .children(i)
            .map(|c| skeleton.joints[c].name.as_str())
            .collect();
        if !children.is_empty() {
            let _ = writeln!(s, "    {} {}", j.name, children.join(" "));
        }
    }
    let _ = writeln!(s, "  end");
    Ok(s)
}

fn fmt_limit(v: f64) -> String {
    if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        fmt_num(v)
    }
}
