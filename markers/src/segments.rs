//! Segment/marker assignment files, segment frames (seed 003, section 2.5) and the solver
//! that turns a marker set into a BVH [`Clip`].
//!
//! The assignment file is TOML:
//!
//! ```toml
//! hinge_condition = 1000.0   # optional: condition number above which a joint is a hinge
//! still_std_mm = 5.0         # optional: a marker moving less than this is "not moving"
//!
//! [[segment]]
//! name = "pelvis"            # the root: no parent, at least 3 markers
//! markers = ["LASI", "RASI", "SACR"]
//!
//! [[segment]]
//! name = "lfemur"
//! parent = "pelvis"          # parents are listed before their children
//! markers = ["LTHI", "LKNE", "LTHI2"]
//! ```
//!
//! Solving runs root to leaf (section 2.5): the root's frame comes from its markers; for each
//! child segment every marker is expressed in the parent's frame, `x = Mᵀ(x′ − p)` (section
//! 2.3 step 2), and all of them are fitted together by the pooled GDKE
//! ([`gdke_pooled`], eq. 5 summed over markers); for a hinge the
//! centre is the axis point in the plane through the mean of the markers (eq. 6), and a
//! segment may impose `joint = "hinge"` or `"spherical"` instead of the automatic
//! classification. A joint that does not move is reported as such and placed at its markers'
//! centroid. The per-frame
//! centre is `c_jk = x_k + M_k·v_j` with the parent's origin and axes. The child's frame comes
//! from three markers, two markers and the centre, or one marker, the centre and the hinge
//! axis (section 2.5 cases 3, 2, 1); it is then refined each frame by a least-squares rigid fit
//! (Kabsch) of all the segment's visible markers and its centre, so that gaps in one marker do
//! not lose the frame. A frame that still cannot be determined holds the nearest valid one.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};

use super::MarkerError;
use super::data::MarkerSet;
use super::gdke::{GdkeOptions, JointKind, KindHint, gdke_pooled};
use motion::clip::{
    Axis, BodyPart, ChannelKind, Clip, Joint, Rest, Skeleton, SkeletonFormat, Units,
};
use motion::math::{Mat3, to_euler_zyx_deg};

/// One segment of the assignment file.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentSpec {
    /// Segment (and output joint) name.
    pub name: String,
    /// Index of the parent segment, `None` for the root.
    pub parent: Option<usize>,
    /// Names of the markers fixed to the segment.
    pub markers: Vec<String>,
    /// Joint classification: `joint = "auto" | "spherical" | "hinge"` (default auto).
    pub kind: KindHint,
}

/// A parsed assignment file.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentMap {
    /// The file it came from (used in errors).
    pub path: PathBuf,
    /// Segments, parents before children; index 0 is the root.
    pub segments: Vec<SegmentSpec>,
    /// GDKE classification thresholds (`hinge_condition`, `still_std_mm`).
    pub gdke: GdkeOptions,
}

/// Maximum size of an assignment file in bytes.
pub const MAX_SEGMENT_FILE_BYTES: u64 = 1 << 20;

/// Reads an assignment file; see [`parse_segments`].
///
/// # Errors
/// [`MarkerError::Io`], [`MarkerError::Limit`] for a file over 1 MiB, [`MarkerError::Segments`].
pub fn read_segments(path: &Path) -> Result<SegmentMap, MarkerError> {
    let io = |err| MarkerError::Io {
        path: path.to_path_buf(),
        err,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_SEGMENT_FILE_BYTES {
        return Err(MarkerError::Limit {
            path: path.to_path_buf(),
            what: "segment file size in bytes",
            value: len,
            max: MAX_SEGMENT_FILE_BYTES,
        });
    }
    let bytes = std::fs::read(path).map_err(io)?;
    let text = String::from_utf8(bytes).map_err(|_| MarkerError::Segments {
        path: path.to_path_buf(),
        key: "(file)".into(),
        reason: "not valid UTF-8".into(),
    })?;
    parse_segments(&text, path)
}

/// Parses assignment-file text. Errors name the key path, e.g. `segment[2].parent`.
///
/// # Errors
/// [`MarkerError::Segments`] for invalid TOML, unknown keys, wrong types, a missing or
/// duplicated name, an unknown or later-listed parent, no root or more than one, a root with
/// fewer than 3 markers, a segment without markers or a marker on two segments.
pub fn parse_segments(text: &str, path: &Path) -> Result<SegmentMap, MarkerError> {
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| seg_err(path, "(file)", e.message().to_string()))?;
    let (gdke, list) = map_options(&table, path)?;
    let mut segments: Vec<SegmentSpec> = Vec::with_capacity(list.len());
    let mut marker_owner: std::collections::HashMap<String, String> =
        std::collections::HashMap::new();
    for (i, item) in list.iter().enumerate() {
        let fields = segment_fields(i, item, path)?;
        segments.push(fields.resolve(i, &segments, &mut marker_owner, path)?);
    }
    if segments.is_empty() {
        return Err(seg_err(path, "segment", "no segments".into()));
    }
    Ok(SegmentMap {
        path: path.to_path_buf(),
        segments,
        gdke,
    })
}

/// An error of the assignment file at `key`.
fn seg_err(path: &Path, key: &str, reason: String) -> MarkerError {
    MarkerError::Segments {
        path: path.to_path_buf(),
        key: key.to_string(),
        reason,
    }
}

/// The top-level keys: the GDKE thresholds and the `[[segment]]` tables.
fn map_options<'t>(
    table: &'t toml::Table,
    path: &Path,
) -> Result<(GdkeOptions, &'t toml::value::Array), MarkerError> {
    let err = |key: &str, reason: String| seg_err(path, key, reason);
    let mut gdke = GdkeOptions {
        hinge_condition: 1e3,
        still_std: 5.0,
    };
    let mut list = None;
    for (key, value) in table {
        match key.as_str() {
            "hinge_condition" | "still_std_mm" => {
                let v = match value {
                    toml::Value::Float(f) => *f,
                    toml::Value::Integer(i) => *i as f64,
                    _ => return Err(err(key, "expected a number".into())),
                };
                if !(v.is_finite() && v > 0.0) {
                    return Err(err(key, format!("{v} is not a positive number")));
                }
                if key == "hinge_condition" {
                    gdke.hinge_condition = v;
                } else {
                    gdke.still_std = v;
                }
            }
            "segment" => match value {
                toml::Value::Array(a) => list = Some(a),
                _ => {
                    return Err(err(key, "expected an array of tables ([[segment]])".into()));
                }
            },
            other => {
                return Err(err(
                    other,
                    "unknown key (expected hinge_condition, still_std_mm or [[segment]])".into(),
                ));
            }
        }
    }
    let Some(list) = list else {
        return Err(err("segment", "no [[segment]] tables".into()));
    };
    Ok((gdke, list))
}

/// The keys of one `[[segment]]` table as written, before names are resolved.
struct SegmentFields {
    name: Option<String>,
    parent: Option<String>,
    markers: Option<Vec<String>>,
    kind: KindHint,
}

/// Reads the keys of `segment[i]`, each checked for its type.
fn segment_fields(i: usize, item: &toml::Value, path: &Path) -> Result<SegmentFields, MarkerError> {
    let at = |k: &str| format!("segment[{i}]{k}");
    let toml::Value::Table(t) = item else {
        return Err(seg_err(path, &at(""), "expected a table".into()));
    };
    let mut fields = SegmentFields {
        name: None,
        parent: None,
        markers: None,
        kind: KindHint::Auto,
    };
    for (k, v) in t {
        match (k.as_str(), v) {
            ("name", toml::Value::String(s)) => fields.name = Some(s.clone()),
            ("parent", toml::Value::String(s)) => fields.parent = Some(s.clone()),
            ("markers", toml::Value::Array(a)) => {
                fields.markers = Some(marker_names(a, &at, path)?);
            }
            ("joint", toml::Value::String(s)) => {
                fields.kind = match s.as_str() {
                    "auto" => KindHint::Auto,
                    "spherical" => KindHint::Spherical,
                    "hinge" => KindHint::Hinge,
                    other => {
                        return Err(seg_err(
                            path,
                            &at(".joint"),
                            format!("{other:?} is not auto, spherical or hinge"),
                        ));
                    }
                };
            }
            ("name" | "parent" | "joint", _) => {
                return Err(seg_err(
                    path,
                    &at(&format!(".{k}")),
                    "expected a string".into(),
                ));
            }
            ("markers", _) => {
                return Err(seg_err(
                    path,
                    &at(".markers"),
                    "expected an array of marker names".into(),
                ));
            }
            (other, _) => {
                return Err(seg_err(
                    path,
                    &at(&format!(".{other}")),
                    "unknown key (expected name, parent, markers, joint)".into(),
                ));
            }
        }
    }
    Ok(fields)
}

/// The `markers` array of a segment: non-empty strings (`at` names the segment's keys).
fn marker_names(
    a: &[toml::Value],
    at: &dyn Fn(&str) -> String,
    path: &Path,
) -> Result<Vec<String>, MarkerError> {
    let mut names = Vec::with_capacity(a.len());
    for (m, v) in a.iter().enumerate() {
        let toml::Value::String(s) = v else {
            return Err(seg_err(
                path,
                &at(&format!(".markers[{m}]")),
                "expected a string".into(),
            ));
        };
        if s.is_empty() {
            return Err(seg_err(
                path,
                &at(&format!(".markers[{m}]")),
                "empty marker name".into(),
            ));
        }
        names.push(s.clone());
    }
    Ok(names)
}

impl SegmentFields {
    /// The segment `i`: a new name, a parent listed before it (only the root has none), at
    /// least one marker (three on the root), each marker on no other segment (`marker_owner`
    /// records which segment has it).
    fn resolve(
        self,
        i: usize,
        segments: &[SegmentSpec],
        marker_owner: &mut std::collections::HashMap<String, String>,
        path: &Path,
    ) -> Result<SegmentSpec, MarkerError> {
        let at = |k: &str| format!("segment[{i}]{k}");
        let err = |key: &str, reason: String| seg_err(path, key, reason);
        let Some(name) = self.name.filter(|n| !n.trim().is_empty()) else {
            return Err(err(&at(".name"), "missing or empty segment name".into()));
        };
        if segments.iter().any(|s| s.name == name) {
            return Err(err(
                &at(".name"),
                format!("segment {name:?} is listed twice"),
            ));
        }
        let parent = match self.parent {
            None => {
                if i != 0 {
                    return Err(err(
                        &at(".parent"),
                        "missing: only the first segment (the root) has no parent".into(),
                    ));
                }
                None
            }
            Some(p) => {
                if i == 0 {
                    return Err(err(
                        &at(".parent"),
                        "the first segment is the root and has no parent".into(),
                    ));
                }
                let Some(k) = segments.iter().position(|s| s.name == p) else {
                    return Err(err(
                        &at(".parent"),
                        format!("parent {p:?} is not a segment listed before this one"),
                    ));
                };
                Some(k)
            }
        };
        let Some(markers) = self.markers.filter(|m| !m.is_empty()) else {
            return Err(err(&at(".markers"), "missing or empty marker list".into()));
        };
        if parent.is_none() && markers.len() < 3 {
            return Err(err(
                &at(".markers"),
                format!("the root needs at least 3 markers, found {}", markers.len()),
            ));
        }
        for (m, marker) in markers.iter().enumerate() {
            if let Some(owner) = marker_owner.insert(marker.clone(), name.clone()) {
                return Err(err(
                    &at(&format!(".markers[{m}]")),
                    format!("marker {marker:?} is already on segment {owner:?}"),
                ));
            }
        }
        Ok(SegmentSpec {
            name,
            parent,
            markers,
            kind: self.kind,
        })
    }
}

/// A segment's pose in one frame: origin `x_k` and axes `M_k` (columns).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Origin in world coordinates (mm).
    pub origin: Vector3<f64>,
    /// Axes as columns; a rotation matrix.
    pub axes: Matrix3<f64>,
}

impl Frame {
    /// `Mᵀ(x′ − p)`: a world point in this frame (seed 003, section 2.3 step 2).
    pub fn to_local(&self, world: &Vector3<f64>) -> Vector3<f64> {
        self.axes.transpose() * (world - self.origin)
    }

    /// `p + M·v`: a local point in world coordinates (section 2.5, `c_jk = x_jk + M_jk·v_j`).
    pub fn to_world(&self, local: &Vector3<f64>) -> Vector3<f64> {
        self.origin + self.axes * local
    }
}

/// Section 2.5 axes from an origin `o` and two further points `p1`, `p2` (cases 2 and 3):
/// `x̂ = (p2 − o)×(p1 − o)` normalised, `ẑ = (p1 − o)×x̂` normalised, `ŷ = ẑ×x̂`.
/// `None` when the points are (nearly) collinear.
pub fn frame_from_points(o: &Vector3<f64>, p1: &Vector3<f64>, p2: &Vector3<f64>) -> Option<Frame> {
    let a = p1 - o;
    let b = p2 - o;
    let x = b.cross(&a);
    let scale = a.norm() * b.norm();
    if scale.is_nan() || scale <= 0.0 || x.norm() <= 1e-9 * scale {
        return None;
    }
    axes_from(o, &a, &x.normalize())
}

/// Section 2.5 case 1: one marker `o`, the joint centre `c` and the hinge axis `n` (world):
/// `x̂ = n̂`, `ẑ = (c − o)×x̂` normalised, `ŷ = ẑ×x̂`.
pub fn frame_from_axis(o: &Vector3<f64>, c: &Vector3<f64>, n: &Vector3<f64>) -> Option<Frame> {
    let norm = n.norm();
    if norm.is_nan() || norm <= 0.0 {
        return None;
    }
    axes_from(o, &(c - o), &(n / norm))
}

fn axes_from(o: &Vector3<f64>, a: &Vector3<f64>, x: &Vector3<f64>) -> Option<Frame> {
    let z = a.cross(x);
    let zn = z.norm();
    if zn.is_nan() || zn <= 1e-9 * a.norm() {
        return None;
    }
    let z = z / zn;
    let y = z.cross(x);
    Some(Frame {
        origin: *o,
        axes: Matrix3::from_columns(&[*x, y, z]),
    })
}

/// Least-squares rigid fit (Kabsch): the frame that best maps `local` points onto `world`
/// points. `None` with fewer than 3 pairs or (nearly) collinear points.
pub fn rigid_fit(local: &[Vector3<f64>], world: &[Vector3<f64>]) -> Option<Frame> {
    let n = local.len();
    if n < 3 || world.len() != n {
        return None;
    }
    let lc = local.iter().sum::<Vector3<f64>>() / n as f64;
    let wc = world.iter().sum::<Vector3<f64>>() / n as f64;
    let mut h = Matrix3::zeros();
    for (l, w) in local.iter().zip(world) {
        h += (l - lc) * (w - wc).transpose();
    }
    // nalgebra's 3×3 SVD iterates without a bound: never hand it NaN or infinity.
    if !h.iter().all(|v| v.is_finite()) {
        return None;
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut s = svd.singular_values;
    s.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    if s[1].is_nan() || s[1] <= 1e-9 * s[0].max(f64::MIN_POSITIVE) {
        return None;
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    Some(Frame {
        origin: wc - r * lc,
        axes: r,
    })
}

/// What the solver found for one segment's joint.
#[derive(Debug, Clone, PartialEq)]
pub struct SolvedJoint {
    /// Segment name.
    pub segment: String,
    /// Joint classification (the root is reported as `NotMoving`: it has no centre).
    pub kind: JointKind,
    /// Centre `v_j` in the parent's frame (mm); the root's joint point in its own frame.
    pub centre_parent_mm: [f64; 3],
    /// Markers whose fits made the centre.
    pub markers_used: usize,
    /// Frames where the segment's frame had to be held from a neighbour.
    pub held_frames: usize,
}

/// A solved capture: the BVH clip (units mm) and what each joint turned out to be.
#[derive(Debug, Clone)]
pub struct Solved {
    /// Skeleton and joint rotations; one BVH joint per segment plus an end site per leaf.
    pub clip: Clip,
    /// One entry per segment, in segment order.
    pub joints: Vec<SolvedJoint>,
    /// Index of each segment's joint in `clip.skeleton.joints`.
    pub joint_of_segment: Vec<usize>,
}

pub(super) fn v3(p: [f64; 3]) -> Vector3<f64> {
    Vector3::new(p[0], p[1], p[2])
}

pub(super) fn solve_err(segment: &str, reason: String) -> MarkerError {
    MarkerError::Solve {
        segment: segment.to_string(),
        reason,
    }
}

/// Fills `None` frames with the nearest earlier (else later) valid frame; returns how many
/// were filled, or `None` when no frame is valid.
pub(super) fn hold(frames: &mut [Option<Frame>]) -> Option<usize> {
    let first = frames.iter().position(Option::is_some)?;
    let mut held = 0;
    let mut last = frames[first];
    for f in frames.iter_mut() {
        if f.is_none() {
            *f = last;
            held += 1;
        } else {
            last = *f;
        }
    }
    Some(held)
}

struct Canon {
    /// Canonical frame per frame (section 2.5), before the rigid refinement.
    frames: Vec<Option<Frame>>,
}

/// Solves a marker set with an assignment map into a BVH clip (see the module docs).
///
/// # Errors
/// [`MarkerError::Segments`] when the map names a marker the set lacks;
/// [`MarkerError::Solve`] when a segment's frame can never be determined (markers always
/// missing or collinear), or a one-marker segment is not a hinge.
pub fn solve(set: &MarkerSet, map: &SegmentMap) -> Result<Solved, MarkerError> {
    let p = pass(set, map, Samples::All)?;
    build_clip(
        set,
        map,
        &p.seg_frames,
        &p.joints,
        &p.own_point,
        &p.centroids,
    )
}

/// What one root-to-leaf pass over a trial finds.
pub(super) struct Pass {
    /// Each segment's frame in every frame.
    pub(super) seg_frames: Vec<Vec<Frame>>,
    /// Each segment's joint.
    pub(super) joints: Vec<SolvedJoint>,
    /// Joint point of each segment in its own frame (`u_j`; the root: its markers' centroid).
    pub(super) own_point: Vec<Vector3<f64>>,
    /// Centroid of each segment's own markers in its frame.
    pub(super) centroids: Vec<Vector3<f64>>,
    /// Marker columns rigid with each segment (its own first).
    pub(super) rigid_of: Vec<Vec<usize>>,
}

/// Which frames of a trial a joint's GDKE fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Samples {
    /// Every frame where a marker is seen (a motion trial: [`solve`]).
    All,
    /// Only the frames in which the segment moves relative to its parent (a range-of-motion
    /// trial, where each joint holds still most of the time; see [`moving_frames`]).
    Moving,
}

/// Half-width of the window over which [`moving_frames`] looks for motion, seconds.
const MOTION_WINDOW_S: f64 = 0.25;

/// Detection threshold of [`moving_frames`] in units of the estimated noise σ: the distance
/// between two noisy positions is Maxwell-distributed with scale σ·√2, and exceeds 8σ with
/// probability about 10⁻⁶.
const MOTION_THRESHOLD_SIGMA: f64 = 8.0;

/// The frames in which a segment moves relative to its parent, from its markers' positions
/// in the parent's frame (`local[marker][frame]`), or `None` when fewer than
/// [`MIN_SAMPLES`](super::gdke::MIN_SAMPLES) frames move (the fit then uses every frame and
/// classifies the joint as it finds it).
///
/// GDKE's algebraic fit weights every sample alike, so in a range-of-motion trial, where a
/// joint rests in the base pose while the others are exercised, thousands of samples of one
/// noisy point pull the fitted centre towards that point (by about `σ²·r/λ` times the ratio
/// of still to moving samples, where `λ` is the arc's radial variance): centimetres at σ = 2
/// mm. Seed 003 analyses "the frames of data … during joint motion" (section 2.5), and so does
/// this: the noise σ of the relative positions is estimated robustly from second differences
/// (`x[f+1] − 2x[f] + x[f−1]` has standard deviation `√6·σ` per coordinate for white noise and
/// is negligible for smooth motion at capture rates; σ = median|Δ²x| / (0.6745·√6)); a frame
/// moves when some marker is more than 8σ away from where it was [`MOTION_WINDOW_S`]
/// earlier or will be as long after; and every frame within that window of a moving frame
/// counts as moving too, so the slow turning points of a swing are kept.
pub(super) fn moving_frames(
    local: &[Vec<Option<Vector3<f64>>>],
    rate_hz: f64,
) -> Option<Vec<bool>> {
    let frames = local.first().map_or(0, Vec::len);
    let w = ((MOTION_WINDOW_S * rate_hz).round() as usize).max(2);
    let mut second: Vec<f64> = Vec::new();
    for t in local {
        for f in 1..frames.saturating_sub(1) {
            if let (Some(a), Some(b), Some(c)) = (t[f - 1], t[f], t[f + 1]) {
                second.extend((a - 2.0 * b + c).iter().map(|v| v.abs()));
            }
        }
    }
    if second.is_empty() {
        return None;
    }
    let mid = second.len() / 2;
    let (_, median, _) = second.select_nth_unstable_by(mid, f64::total_cmp);
    let sigma = *median / (0.674_49 * 6f64.sqrt());
    let threshold = MOTION_THRESHOLD_SIGMA * sigma;
    let mut moved = vec![false; frames];
    for t in local {
        for (f, m) in moved.iter_mut().enumerate() {
            let Some(x) = t[f] else { continue };
            let far = |g: usize| t[g].is_some_and(|y| (y - x).norm() > threshold);
            if (f >= w && far(f - w)) || (f + w < frames && far(f + w)) {
                *m = true;
            }
        }
    }
    // Dilate by the window: frame f moves when any frame within w of it does.
    let mut keep = vec![false; frames];
    let mut last: Option<usize> = None;
    for f in 0..frames {
        if moved[f] {
            last = Some(f);
        }
        keep[f] = last.is_some_and(|l| f - l <= w);
    }
    let mut next: Option<usize> = None;
    for f in (0..frames).rev() {
        if moved[f] {
            next = Some(f);
        }
        keep[f] |= next.is_some_and(|n| n - f <= w);
    }
    (keep.iter().filter(|&&k| k).count() >= super::gdke::MIN_SAMPLES).then_some(keep)
}

/// Checks that the map's first segment is the root and parents precede children.
pub(super) fn check_order(map: &SegmentMap) -> Result<(), MarkerError> {
    let Some(root) = map.segments.first() else {
        return Err(MarkerError::Segments {
            path: map.path.clone(),
            key: "segment".into(),
            reason: "no segments".into(),
        });
    };
    if root.parent.is_some()
        || map
            .segments
            .iter()
            .enumerate()
            .any(|(i, s)| s.parent.is_some_and(|p| p >= i))
    {
        return Err(MarkerError::Segments {
            path: map.path.clone(),
            key: "segment".into(),
            reason: "the first segment must be the root and parents must precede children".into(),
        });
    }
    Ok(())
}

/// The root-to-leaf pass (section 2.5) over a trial: each segment's joint from its markers in
/// its parent's frame, then its own frames, in map order.
pub(super) fn pass(
    set: &MarkerSet,
    map: &SegmentMap,
    samples: Samples,
) -> Result<Pass, MarkerError> {
    let frames = set.frames();
    check_order(map)?;
    if frames == 0 {
        return Err(solve_err(
            &map.segments[0].name,
            "the marker set has no frames".into(),
        ));
    }
    let marker_ix = marker_columns(set, map)?;
    let n_seg = map.segments.len();
    let mut pass = Pass {
        seg_frames: Vec::with_capacity(n_seg),
        joints: Vec::with_capacity(n_seg),
        own_point: Vec::with_capacity(n_seg),
        centroids: Vec::with_capacity(n_seg),
        rigid_of: Vec::with_capacity(n_seg),
    };
    for (si, seg) in map.segments.iter().enumerate() {
        let solved = solve_segment(set, map, seg, &marker_ix[si], samples, &pass)?;
        pass.own_point.push(solved.own_point);
        pass.rigid_of.push(solved.rigid);
        pass.centroids.push(solved.centroid);
        pass.seg_frames.push(solved.frames);
        pass.joints.push(solved.joint);
    }
    Ok(pass)
}

/// Each segment's marker columns in `set`, in the map's order.
fn marker_columns(set: &MarkerSet, map: &SegmentMap) -> Result<Vec<Vec<usize>>, MarkerError> {
    let mut marker_ix: Vec<Vec<usize>> = Vec::with_capacity(map.segments.len());
    for (i, s) in map.segments.iter().enumerate() {
        let mut ix = Vec::with_capacity(s.markers.len());
        for (m, name) in s.markers.iter().enumerate() {
            let Some(k) = set.marker_index(name) else {
                return Err(MarkerError::Segments {
                    path: map.path.clone(),
                    key: format!("segment[{i}].markers[{m}]"),
                    reason: format!("marker {name:?} is not in the marker data"),
                });
            };
            ix.push(k);
        }
        marker_ix.push(ix);
    }
    Ok(marker_ix)
}

/// Position of marker column `columns[k]` at frame `f`, if seen.
fn marker_at(set: &MarkerSet, columns: &[usize], f: usize, k: usize) -> Option<Vector3<f64>> {
    set.get(f, columns[k]).map(v3)
}

/// What [`pass`] finds for one segment (see the fields of [`Pass`]).
struct SolvedSegment {
    frames: Vec<Frame>,
    joint: SolvedJoint,
    own_point: Vector3<f64>,
    centroid: Vector3<f64>,
    rigid: Vec<usize>,
}

/// The joint centre (and hinge axis) of a segment in world coordinates, per frame.
struct Centres {
    world: Vec<Option<Vector3<f64>>>,
    axis_world: Vec<Option<Vector3<f64>>>,
}

/// One step of the root-to-leaf pass: the segment's joint, its frames and its points, given
/// the segments before it (`done`).
fn solve_segment(
    set: &MarkerSet,
    map: &SegmentMap,
    seg: &SegmentSpec,
    mk: &[usize],
    samples: Samples,
    done: &Pass,
) -> Result<SolvedSegment, MarkerError> {
    let frames = set.frames();
    let mut solved = SolvedJoint {
        segment: seg.name.clone(),
        kind: JointKind::NotMoving,
        centre_parent_mm: [0.0; 3],
        markers_used: 0,
        held_frames: 0,
    };
    let centres = match seg.parent {
        Some(p) => joint_centre(set, map, seg, mk, &done.seg_frames[p], samples, &mut solved)?,
        None => Centres {
            world: vec![None; frames],
            axis_world: vec![None; frames],
        },
    };
    let canon = canonical_frames(set, mk, &centres);
    if mk.len() == 1 && !matches!(solved.kind, JointKind::Hinge { .. }) {
        return Err(solve_err(
            &seg.name,
            "a segment with one marker needs a hinge joint (section 2.5 case 1), but this joint is not one".into(),
        ));
    }
    // Markers rigid with this segment: its own, plus, when its joint does not move, those
    // rigid with its parent (a still joint makes one rigid body, and more markers spread
    // wider give a steadier frame).
    let mut rigid: Vec<usize> = mk.to_vec();
    if solved.kind == JointKind::NotMoving
        && let Some(p) = seg.parent
    {
        rigid.extend(done.rigid_of[p].iter().copied());
    }
    let template = marker_templates(set, &rigid, &canon, &centres.world);
    let mut fitted = fitted_frames(set, &rigid, mk.len(), &template, &canon, &centres.world);
    let Some(held) = hold(&mut fitted) else {
        return Err(solve_err(
            &seg.name,
            "its frame cannot be determined in any frame (markers missing or collinear)".into(),
        ));
    };
    solved.held_frames = held;
    let fitted: Vec<Frame> = fitted.into_iter().flatten().collect();
    // Marker centroid in the segment's frame (end sites, root point).
    let present: Vec<Vector3<f64>> = template[..mk.len()].iter().flatten().copied().collect();
    let centroid = present.iter().sum::<Vector3<f64>>() / present.len().max(1) as f64;
    let own_point = if seg.parent.is_some() {
        // u_j: the joint centre in the segment's own frame, averaged over frames.
        let mut s = Vector3::zeros();
        for (f, fr) in fitted.iter().enumerate() {
            if let Some(c) = centres.world[f] {
                s += fr.to_local(&c);
            }
        }
        s / frames as f64
    } else {
        solved.centre_parent_mm = [centroid.x, centroid.y, centroid.z];
        centroid
    };
    Ok(SolvedSegment {
        frames: fitted,
        joint: solved,
        own_point,
        centroid,
        rigid,
    })
}

/// The joint centre of a child segment relative to its parent (frames `pf`), by the pooled
/// GDKE of its markers in the parent's frame; records the fit in `solved` and returns the
/// centre (and a hinge's axis) in world coordinates per frame.
fn joint_centre(
    set: &MarkerSet,
    map: &SegmentMap,
    seg: &SegmentSpec,
    mk: &[usize],
    pf: &[Frame],
    samples: Samples,
    solved: &mut SolvedJoint,
) -> Result<Centres, MarkerError> {
    let frames = set.frames();
    let local: Vec<Vec<Option<Vector3<f64>>>> = (0..mk.len())
        .map(|k| {
            (0..frames)
                .map(|f| marker_at(set, mk, f, k).map(|x| pf[f].to_local(&x)))
                .collect()
        })
        .collect();
    let keep = match samples {
        Samples::All => None,
        Samples::Moving => moving_frames(&local, set.frame_rate_hz),
    };
    let tracks: Vec<Vec<[f64; 3]>> = local
        .iter()
        .map(|t| {
            t.iter()
                .enumerate()
                .filter(|(f, _)| keep.as_ref().is_none_or(|k| k[*f]))
                .filter_map(|(_, x)| x.map(|v| [v.x, v.y, v.z]))
                .collect()
        })
        .collect();
    let refs: Vec<&[[f64; 3]]> = tracks.iter().map(Vec::as_slice).collect();
    let fit = match gdke_pooled(&refs, &map.gdke, seg.kind) {
        Ok(fit) => fit,
        Err(MarkerError::TooFewSamples { got, .. }) => {
            return Err(solve_err(
                &seg.name,
                format!("its markers are seen in at most {got} frames, at least 4 needed"),
            ));
        }
        Err(e) => return Err(e),
    };
    let (centre, kind, used) = (
        v3(fit.centre),
        fit.kind,
        tracks.iter().filter(|t| t.len() >= 4).count(),
    );
    solved.kind = kind;
    solved.centre_parent_mm = [centre.x, centre.y, centre.z];
    solved.markers_used = used;
    Ok(Centres {
        world: (0..frames).map(|f| Some(pf[f].to_world(&centre))).collect(),
        axis_world: (0..frames)
            .map(|f| match kind {
                JointKind::Hinge { axis } => Some(pf[f].axes * v3(axis)),
                _ => None,
            })
            .collect(),
    })
}

/// Section 2.5's canonical frame of a segment with markers `mk` in every frame: from three
/// markers, two and the centre, or one, the centre and the hinge axis.
fn canonical_frames(set: &MarkerSet, mk: &[usize], centres: &Centres) -> Canon {
    let pos = |f: usize, k: usize| marker_at(set, mk, f, k);
    Canon {
        frames: (0..set.frames())
            .map(|f| match mk.len() {
                0 => None,
                1 => {
                    let (o, c, n) = (pos(f, 0)?, centres.world[f]?, centres.axis_world[f]?);
                    frame_from_axis(&o, &c, &n)
                }
                2 => frame_from_points(&pos(f, 0)?, &pos(f, 1)?, &centres.world[f]?),
                _ => frame_from_points(&pos(f, 0)?, &pos(f, 1)?, &pos(f, 2)?),
            })
            .collect(),
    }
}

/// Templates: the mean local position of each `rigid` marker, then of the joint centre, over
/// the canonical frames (`None` where never seen).
fn marker_templates(
    set: &MarkerSet,
    rigid: &[usize],
    canon: &Canon,
    centre_world: &[Option<Vector3<f64>>],
) -> Vec<Option<Vector3<f64>>> {
    let nr = rigid.len();
    let mut sums = vec![(Vector3::zeros(), 0usize); nr + 1];
    for (f, cf) in canon.frames.iter().enumerate() {
        let Some(cf) = cf else { continue };
        for (k, s) in sums.iter_mut().enumerate().take(nr) {
            if let Some(x) = marker_at(set, rigid, f, k) {
                s.0 += cf.to_local(&x);
                s.1 += 1;
            }
        }
        if let Some(c) = centre_world[f] {
            sums[nr].0 += cf.to_local(&c);
            sums[nr].1 += 1;
        }
    }
    sums.iter()
        .map(|(s, n)| (*n > 0).then(|| s / *n as f64))
        .collect()
}

/// Final frames: a rigid fit of the visible `rigid` markers and the centre to their
/// templates (a segment with at least two own markers), else the canonical frame.
fn fitted_frames(
    set: &MarkerSet,
    rigid: &[usize],
    own_markers: usize,
    template: &[Option<Vector3<f64>>],
    canon: &Canon,
    centre_world: &[Option<Vector3<f64>>],
) -> Vec<Option<Frame>> {
    let nr = rigid.len();
    (0..set.frames())
        .map(|f| {
            if own_markers >= 2 {
                let mut l = Vec::with_capacity(nr + 1);
                let mut w = Vec::with_capacity(nr + 1);
                for (k, t) in template.iter().enumerate().take(nr) {
                    if let (Some(t), Some(x)) = (*t, marker_at(set, rigid, f, k)) {
                        l.push(t);
                        w.push(x);
                    }
                }
                if let (Some(t), Some(c)) = (template[nr], centre_world[f]) {
                    l.push(t);
                    w.push(c);
                }
                rigid_fit(&l, &w).or(canon.frames[f])
            } else {
                canon.frames[f]
            }
        })
        .collect()
}

/// The solved clip from a pass's frames and joints: skeleton and channel matrix.
pub(super) fn build_clip(
    set: &MarkerSet,
    map: &SegmentMap,
    seg_frames: &[Vec<Frame>],
    joints: &[SolvedJoint],
    own_point: &[Vector3<f64>],
    centroids: &[Vector3<f64>],
) -> Result<Solved, MarkerError> {
    // Depth-first pre-order, so that the BVH hierarchy and the channel order agree.
    let order = depth_first_order(map);
    let (skeleton, joint_of_segment) = solved_skeleton(map, &order, joints, own_point, centroids);
    let data = channel_matrix(
        map,
        &order,
        seg_frames,
        own_point,
        skeleton.channel_count(),
        set.frames(),
    );
    let clip = Clip::new(skeleton, set.frame_rate_hz, set.frames(), data)
        .map_err(|e| solve_err(&map.segments[0].name, format!("cannot build the clip: {e}")))?;
    Ok(Solved {
        clip,
        joints: joints.to_vec(),
        joint_of_segment,
    })
}

/// The segments in depth-first pre-order from the root, children in map order.
fn depth_first_order(map: &SegmentMap) -> Vec<usize> {
    let n_seg = map.segments.len();
    let mut order = Vec::with_capacity(n_seg);
    let mut stack = vec![0usize];
    while let Some(s) = stack.pop() {
        order.push(s);
        let kids: Vec<usize> = (0..n_seg)
            .filter(|&k| map.segments[k].parent == Some(s))
            .collect();
        stack.extend(kids.into_iter().rev());
    }
    order
}

/// The ZYX rotation channels every solved joint has.
const ZYX: [ChannelKind; 3] = [
    ChannelKind::Rotation(Axis::Z),
    ChannelKind::Rotation(Axis::Y),
    ChannelKind::Rotation(Axis::X),
];

/// A BVH joint of the solved skeleton (body part and depth are assigned later).
fn bvh_joint(
    name: String,
    parent: Option<usize>,
    offset: Vector3<f64>,
    dofs: Vec<ChannelKind>,
    end: bool,
) -> Joint {
    Joint {
        name,
        parent,
        rest: Rest::Offset([offset.x, offset.y, offset.z]),
        dofs,
        axis_deg: [0.0; 3],
        axis_order: [Axis::X, Axis::Y, Axis::Z],
        limits: Vec::new(),
        id: None,
        end_site: end,
        body_part: BodyPart::Torso,
        chain_depth: 0,
    }
}

/// The BVH skeleton (units mm) in `order`: one joint per segment at its centre, the root
/// with translations, an end site at each leaf's marker centroid; and each segment's joint.
fn solved_skeleton(
    map: &SegmentMap,
    order: &[usize],
    joints: &[SolvedJoint],
    own_point: &[Vector3<f64>],
    centroids: &[Vector3<f64>],
) -> (Skeleton, Vec<usize>) {
    let n_seg = map.segments.len();
    let mut skel_joints: Vec<Joint> = Vec::with_capacity(2 * n_seg);
    let mut joint_of_segment = vec![0usize; n_seg];
    for &s in order {
        let seg = &map.segments[s];
        let (parent, offset, dofs) = match seg.parent {
            None => {
                let mut d = vec![
                    ChannelKind::Translation(Axis::X),
                    ChannelKind::Translation(Axis::Y),
                    ChannelKind::Translation(Axis::Z),
                ];
                d.extend(ZYX);
                (None, Vector3::zeros(), d)
            }
            Some(p) => (
                Some(joint_of_segment[p]),
                v3(joints[s].centre_parent_mm) - own_point[p],
                ZYX.to_vec(),
            ),
        };
        joint_of_segment[s] = skel_joints.len();
        skel_joints.push(bvh_joint(seg.name.clone(), parent, offset, dofs, false));
        let leaf = !map.segments.iter().any(|c| c.parent == Some(s));
        if leaf {
            let mut off = centroids[s] - own_point[s];
            if off.norm() < 1e-6 {
                off = Vector3::new(0.0, 1.0, 0.0);
            }
            skel_joints.push(bvh_joint(
                format!("{}_End", seg.name),
                Some(joint_of_segment[s]),
                off,
                Vec::new(),
                true,
            ));
        }
    }
    let mut skeleton = Skeleton {
        name: map.segments[0].name.clone(),
        format: SkeletonFormat::Bvh,
        units: Units {
            cm_per_unit: 0.1,
            asf_length: 1.0,
            asf_mass: 1.0,
            declared: true,
        },
        joints: skel_joints,
        documentation: vec!["solved from markers by GDKE (seed 003)".into()],
    };
    motion::bodymap::assign(&mut skeleton);
    (skeleton, joint_of_segment)
}

/// The channel matrix in `order`: the root's joint point, then every segment's rotation
/// relative to its parent as ZYX Euler angles in degrees.
fn channel_matrix(
    map: &SegmentMap,
    order: &[usize],
    seg_frames: &[Vec<Frame>],
    own_point: &[Vector3<f64>],
    channels: usize,
    frames: usize,
) -> Vec<f64> {
    let mut data = vec![0.0; channels * frames];
    let mut c = 0;
    for &s in order {
        let seg = &map.segments[s];
        for f in 0..frames {
            let fr = &seg_frames[s][f];
            let local = match seg.parent {
                None => {
                    let p = fr.to_world(&own_point[s]);
                    for k in 0..3 {
                        data[(c + k) * frames + f] = p[k];
                    }
                    fr.axes
                }
                Some(p) => seg_frames[p][f].axes.transpose() * fr.axes,
            };
            let m: Mat3 = [
                [local[(0, 0)], local[(0, 1)], local[(0, 2)]],
                [local[(1, 0)], local[(1, 1)], local[(1, 2)]],
                [local[(2, 0)], local[(2, 1)], local[(2, 2)]],
            ];
            let zyx = to_euler_zyx_deg(&m);
            let base = if seg.parent.is_none() { c + 3 } else { c };
            for k in 0..3 {
                data[(base + k) * frames + f] = zyx[k];
            }
        }
        c += if seg.parent.is_none() { 6 } else { 3 };
    }
    data
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::gdke::GdkeOptions;

    /// One marker 250 mm from a centre at the origin: still for 4 s, one ±40° swing over 2 s,
    /// still for 12 s (120 Hz, as a joint of a range-of-motion trial in 9 groups), with
    /// Gaussian noise σ on each coordinate.
    fn rom_track(sigma: f64, seed: u64) -> (Vec<Option<Vector3<f64>>>, std::ops::Range<usize>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut gauss = || {
            let u1: f64 = 1.0 - rng.random::<f64>();
            let u2: f64 = rng.random::<f64>();
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        let swing = 480..720;
        let track = (0..2160)
            .map(|f| {
                let a = if swing.contains(&f) {
                    let t = (f - swing.start) as f64 / swing.len() as f64;
                    40f64.to_radians() * (std::f64::consts::TAU * t).sin()
                } else {
                    0.0
                };
                let p = Vector3::new(250.0 * a.sin(), -250.0 * a.cos(), 0.0);
                Some(p + sigma * Vector3::new(gauss(), gauss(), gauss()))
            })
            .collect();
        (track, swing)
    }

    #[test]
    fn moving_frames_keep_the_swing_and_drop_the_rest() {
        let (track, swing) = rom_track(2.0, 1);
        let keep = moving_frames(std::slice::from_ref(&track), 120.0).unwrap();
        let w = (MOTION_WINDOW_S * 120.0).round() as usize;
        for (f, k) in keep.iter().enumerate() {
            if swing.contains(&f) {
                assert!(k, "frame {f} of the swing dropped");
            } else if f + 2 * w < swing.start || f > swing.end + 2 * w {
                assert!(!k, "still frame {f} kept");
            }
        }
        // Noise-free: nothing is lost either.
        let (exact, _) = rom_track(0.0, 1);
        let all = moving_frames(std::slice::from_ref(&exact), 120.0).unwrap();
        assert!(swing.clone().all(|f| all[f]));
    }

    #[test]
    fn still_samples_pull_the_gdke_centre_and_the_selection_removes_the_pull() {
        // The reason for `Samples::Moving`: with eight still seconds for every moving one the
        // centre of one marker's ±40° arc is 7-8 mm off at σ = 2 mm (mean of 8 runs), with
        // the moving frames alone 2-3 mm (the algebraic fit's own bias on a short arc).
        let opts = GdkeOptions {
            hinge_condition: 1e12,
            still_std: 1e-9,
        };
        let (mut all_err, mut moving_err) = (0.0f64, 0.0f64);
        for seed in 0..8 {
            let (track, _) = rom_track(2.0, seed);
            let keep = moving_frames(std::slice::from_ref(&track), 120.0).unwrap();
            let pts = |sel: &dyn Fn(usize) -> bool| -> Vec<[f64; 3]> {
                track
                    .iter()
                    .enumerate()
                    .filter(|(f, _)| sel(*f))
                    .filter_map(|(_, p)| p.map(|p| [p.x, p.y, p.z]))
                    .collect()
            };
            // The motion is planar: the centre in the plane (eq. 6) is the one to compare.
            let err = |p: &[[f64; 3]]| {
                let fit = gdke_pooled(&[p], &opts, KindHint::Hinge).unwrap();
                (fit.centre[0].powi(2) + fit.centre[1].powi(2)).sqrt()
            };
            all_err += err(&pts(&|_| true)) / 8.0;
            moving_err += err(&pts(&|f| keep[f])) / 8.0;
        }
        eprintln!(
            "mean centre error over 8 runs: all frames {all_err:.1} mm, moving frames \
             {moving_err:.1} mm"
        );
        assert!(all_err > 5.0, "all frames: {all_err} mm");
        assert!(moving_err < all_err / 2.5, "moving frames: {moving_err} mm");
    }
}
