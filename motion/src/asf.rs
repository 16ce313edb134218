//! Acclaim ASF skeleton files (as in the CMU database).
//!
//! Reading: sections `:version`, `:name`, `:units`, `:documentation`, `:root`, `:bonedata`,
//! `:hierarchy` (`:skin` is skipped); `#` comments; CRLF, LF or mixed endings; bones without a
//! `dof` line; `limits` spread over several lines; `angle rad` converted to degrees. Joints are
//! returned root first, then bones in file order (reordered only if a child precedes its
//! parent). Writing emits a canonical file that reads back equal.

use std::fmt::Write as _;
use std::path::Path;

use crate::bodymap;
use crate::clip::{Axis, BodyPart, ChannelKind, Joint, Rest, Skeleton, SkeletonFormat, Units};
use crate::error::{Limits, ParseError, WriteError};
use crate::text::{fmt_num, lines, number, numbers, read_text, syntax};

/// Centimetres per inch; ASF `length L` means one unit is `1/L` inch.
const CM_PER_INCH: f64 = 2.54;

/// Reads an ASF file with the default [`Limits`].
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_asf(path: &Path) -> Result<Skeleton, ParseError> {
    read_asf_with(path, &Limits::default())
}

/// Reads an ASF file with explicit limits.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
pub fn read_asf_with(path: &Path, limits: &Limits) -> Result<Skeleton, ParseError> {
    let text = read_text(path, limits)?;
    parse_asf(&text, path, limits)
}

#[derive(Clone, Copy, PartialEq)]
enum Section {
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

/// Parses ASF text. `path` is used only in error messages.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason.
#[expect(
    clippy::too_many_lines,
    reason = "one state machine over the file's sections"
)]
pub fn parse_asf(text: &str, path: &Path, limits: &Limits) -> Result<Skeleton, ParseError> {
    let mut section = Section::None;
    let mut name = String::new();
    let mut units = Units::default();
    let mut angle_rad = false;
    let mut documentation = Vec::new();
    let mut root_order: Option<Vec<ChannelKind>> = None;
    let mut root_axis = [Axis::X, Axis::Y, Axis::Z];
    let mut root_position = [0.0; 3];
    let mut root_orientation = [0.0; 3];
    let mut bones: Vec<BoneDraft> = Vec::new();
    let mut current: Option<BoneDraft> = None;
    let mut in_limits = false;
    let mut hierarchy: Vec<(usize, String, Vec<String>)> = Vec::new();
    let mut hierarchy_open = false;
    let mut hierarchy_closed = false;
    let mut seen_root = false;
    let mut last_line = 0;

    for (ln, raw) in lines(text) {
        last_line = ln;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let toks: Vec<&str> = line.split_whitespace().collect();
        if let Some(kw) = toks[0].strip_prefix(':') {
            if current.is_some() {
                return Err(syntax(path, ln, "bone block not closed with `end`"));
            }
            in_limits = false;
            section = match kw.to_ascii_lowercase().as_str() {
                "version" => Section::Header,
                "name" => {
                    name = toks[1..].join(" ");
                    Section::Header
                }
                "units" => Section::Units,
                "documentation" => Section::Documentation,
                "root" => {
                    seen_root = true;
                    Section::Root
                }
                "bonedata" => Section::BoneData,
                "hierarchy" => Section::Hierarchy,
                "skin" => Section::Skip,
                other => return Err(syntax(path, ln, format!("unknown section `:{other}`"))),
            };
            continue;
        }
        match section {
            Section::None => {
                return Err(syntax(path, ln, "text before the first `:` section"));
            }
            Section::Header | Section::Skip => {}
            Section::Documentation => documentation.push(line.to_string()),
            Section::Units => {
                let what = format!("units {}", toks[0]);
                match toks[0] {
                    "mass" => units.asf_mass = numbers::<1>(path, ln, &what, &toks[1..])?[0],
                    "length" => {
                        let l = numbers::<1>(path, ln, &what, &toks[1..])?[0];
                        if l <= 0.0 {
                            return Err(syntax(path, ln, "units length must be positive"));
                        }
                        units.asf_length = l;
                        units.cm_per_unit = CM_PER_INCH / l;
                        units.declared = true;
                    }
                    "angle" => match toks.get(1).map(|t| t.to_ascii_lowercase()).as_deref() {
                        Some("deg") => angle_rad = false,
                        Some("rad") => angle_rad = true,
                        _ => return Err(syntax(path, ln, "units angle must be `deg` or `rad`")),
                    },
                    other => return Err(syntax(path, ln, format!("unknown unit `{other}`"))),
                }
            }
            Section::Root => match toks[0] {
                "order" => {
                    let order = toks[1..]
                        .iter()
                        .map(|t| channel(path, ln, t))
                        .collect::<Result<Vec<_>, _>>()?;
                    if order.len() > 6 {
                        return Err(syntax(path, ln, "root order lists more than 6 channels"));
                    }
                    root_order = Some(order);
                }
                "axis" => {
                    let tok = toks.get(1).copied().unwrap_or("");
                    root_axis = axis_order(path, ln, tok)?;
                }
                "position" => root_position = numbers::<3>(path, ln, "root position", &toks[1..])?,
                "orientation" => {
                    root_orientation = numbers::<3>(path, ln, "root orientation", &toks[1..])?;
                }
                other => return Err(syntax(path, ln, format!("unknown root field `{other}`"))),
            },
            Section::BoneData => {
                if toks[0] == "begin" {
                    if current.is_some() {
                        return Err(syntax(path, ln, "`begin` inside a bone block"));
                    }
                    if bones.len() + 1 >= limits.max_joints {
                        return Err(ParseError::TooLarge {
                            path: path.to_path_buf(),
                            line: ln,
                            what: "number of bones".into(),
                            value: bones.len() as u64 + 1,
                            limit: limits.max_joints as u64,
                        });
                    }
                    current = Some(BoneDraft {
                        line: ln,
                        ..BoneDraft::default()
                    });
                    in_limits = false;
                    continue;
                }
                let Some(bone) = current.as_mut() else {
                    return Err(syntax(
                        path,
                        ln,
                        format!("`{}` outside a begin/end block", toks[0]),
                    ));
                };
                if in_limits && toks[0].starts_with('(') {
                    push_limits(path, ln, line, &mut bone.limit_values)?;
                    continue;
                }
                in_limits = false;
                let bone_name = bone.name.clone().unwrap_or_else(|| "?".into());
                match toks[0] {
                    "end" => {
                        let mut bone = current.take().unwrap_or_default();
                        bone.limits = if bone.limit_values.is_empty() {
                            Vec::new()
                        } else {
                            limit_pairs(path, ln, &bone.limit_values, bone.dofs.len())?
                        };
                        bones.push(bone);
                    }
                    "id" => {
                        let id = toks.get(1).and_then(|t| t.parse::<u32>().ok());
                        if id.is_none() || toks.len() != 2 {
                            return Err(syntax(path, ln, "bone id must be one whole number"));
                        }
                        bone.id = id;
                    }
                    "name" => {
                        if toks.len() != 2 {
                            return Err(syntax(path, ln, "bone name must be one word"));
                        }
                        bone.name = Some(toks[1].to_string());
                    }
                    "direction" => {
                        let what = format!("direction of bone {bone_name}");
                        bone.direction = Some(numbers::<3>(path, ln, &what, &toks[1..])?);
                    }
                    "length" => {
                        let what = format!("length of bone {bone_name}");
                        let l = numbers::<1>(path, ln, &what, &toks[1..])?[0];
                        if l < 0.0 {
                            return Err(syntax(path, ln, "bone length is negative"));
                        }
                        bone.length = Some(l);
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
                        bone.axis = Some((a, axis_order(path, ln, toks[4])?));
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
                                format!(
                                    "bone {bone_name}: only rx, ry, rz dofs are supported on bones"
                                ),
                            ));
                        }
                        bone.dofs = dofs;
                    }
                    "limits" => {
                        in_limits = true;
                        push_limits(path, ln, &line["limits".len()..], &mut bone.limit_values)?;
                    }
                    "bodymass" | "cofmass" => {}
                    other => {
                        return Err(syntax(path, ln, format!("unknown bone field `{other}`")));
                    }
                }
            }
            Section::Hierarchy => match toks[0] {
                "begin" => hierarchy_open = true,
                "end" => {
                    hierarchy_open = false;
                    hierarchy_closed = true;
                }
                parent => {
                    if !hierarchy_open {
                        return Err(syntax(path, ln, "hierarchy line outside begin/end"));
                    }
                    let children = toks[1..].iter().map(|s| (*s).to_string()).collect();
                    hierarchy.push((ln, parent.to_string(), children));
                }
            },
        }
    }
    if current.is_some() {
        return Err(ParseError::Truncated {
            path: path.to_path_buf(),
            line: last_line,
            expected: "`end` of a bone block".into(),
        });
    }
    if !seen_root {
        return Err(ParseError::Truncated {
            path: path.to_path_buf(),
            line: last_line,
            expected: "a `:root` section".into(),
        });
    }
    if !hierarchy_closed {
        return Err(ParseError::Truncated {
            path: path.to_path_buf(),
            line: last_line,
            expected: "a complete `:hierarchy` section".into(),
        });
    }
    let to_deg = |v: f64| if angle_rad { v.to_degrees() } else { v };

    let root = Joint {
        name: "root".into(),
        parent: None,
        rest: Rest::Offset(root_position),
        dofs: root_order.unwrap_or_default(),
        axis_deg: root_orientation.map(to_deg),
        axis_order: root_axis,
        limits: Vec::new(),
        id: None,
        end_site: false,
        body_part: BodyPart::Torso,
        chain_depth: 0,
    };
    let mut drafts: Vec<(Joint, usize)> = Vec::with_capacity(bones.len());
    for b in bones {
        let Some(bname) = b.name else {
            return Err(syntax(path, b.line, "bone block without a name"));
        };
        let direction = b
            .direction
            .ok_or_else(|| syntax(path, b.line, format!("bone {bname} has no direction")))?;
        let length = b
            .length
            .ok_or_else(|| syntax(path, b.line, format!("bone {bname} has no length")))?;
        let (axis, order) = b.axis.unwrap_or(([0.0; 3], [Axis::X, Axis::Y, Axis::Z]));
        if drafts.iter().any(|(j, _)| j.name == bname) || bname == "root" {
            return Err(syntax(
                path,
                b.line,
                format!("bone {bname} is defined twice"),
            ));
        }
        drafts.push((
            Joint {
                name: bname,
                parent: None,
                rest: Rest::Bone { direction, length },
                dofs: b.dofs,
                axis_deg: axis.map(to_deg),
                axis_order: order,
                limits: b
                    .limits
                    .into_iter()
                    .map(|(lo, hi)| (to_deg(lo), to_deg(hi)))
                    .collect(),
                id: b.id,
                end_site: false,
                body_part: BodyPart::Torso,
                chain_depth: 0,
            },
            b.line,
        ));
    }
    let joints = order_by_hierarchy(path, root, &drafts, &hierarchy)?;
    let mut skeleton = Skeleton {
        name,
        format: SkeletonFormat::Asf,
        units,
        joints,
        documentation,
    };
    bodymap::assign(&mut skeleton);
    Ok(skeleton)
}

fn push_limits(path: &Path, ln: usize, text: &str, out: &mut Vec<f64>) -> Result<(), ParseError> {
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
        if out.len() >= 6 {
            return Err(syntax(path, ln, "more than three limit pairs"));
        }
        out.push(v);
    }
    Ok(())
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
