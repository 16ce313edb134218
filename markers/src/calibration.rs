//! Functional calibration: joint centres, hinge axes and classifications estimated by GDKE on
//! a range-of-motion (calibration) trial, then applied to a motion trial recorded with the
//! same markers.
//!
//! GDKE finds a joint's centre only from the motion of the child's markers in the parent's
//! frame (seed 003, section 2.3). In a walk the spine, the neck and the clavicles hardly move
//! relative to their parents, and the shoulders swing through short arcs, so their centres
//! are not observable from the walk alone. Labs therefore record a separate range-of-motion
//! trial with the same marker placement, in which every joint is exercised through its range,
//! estimate the centres there, and apply them to the motion trial. [`Calibration::estimate`]
//! runs the solver's root-to-leaf pass ([`segments::solve`](super::segments::solve)) on the
//! calibration trial and keeps, per segment, what defines its frame and its joint: the
//! positions of the markers rigid with the segment in its own frame (the marker template),
//! the centre `v_j` in the parent's frame (eq. 5, or eq. 6 with the hinge axis `n`), the same
//! point `u_j` in the segment's own frame, and the classification. [`Calibration::solve`]
//! then solves another trial with them: root to leaf, the parent's frame gives the joint
//! centre `c_jk = x_k + M_k·v_j` (section 2.5), and the segment's frame is the least-squares
//! rigid fit of its template markers and `u_j` onto the visible markers and `c_jk` (or, for a
//! one-marker hinge segment, section 2.5 case 1 from the marker, the centre and the axis).
//! Since both trials define every frame from the same template, the calibrated `v_j` means
//! the same point in both.
//!
//! ```
//! use std::path::Path;
//! use markers::{calibration::Calibration, segments::parse_segments, synth};
//! let walk = motion::synth::walking_clip(&motion::synth::WalkParams {
//!     duration_s: 2.0,
//!     ..Default::default()
//! });
//! let exact = synth::SynthOptions { noise_mm: 0.0, gap_probability: 0.0, ..Default::default() };
//! let rom = synth::rom_capture(&walk, &synth::RomOptions::default(), &exact).unwrap();
//! let motion = synth::synth_capture(&walk, &exact).unwrap();
//! let map = parse_segments(&synth::segment_map_toml(&walk), Path::new("walk.toml")).unwrap();
//! let calibration = Calibration::estimate(&rom.markers, &map).unwrap();
//! let solved = calibration.solve(&motion.markers).unwrap();
//! assert_eq!(solved.clip.frames(), motion.markers.frames());
//! ```

use nalgebra::Vector3;

use super::MarkerError;
use super::data::MarkerSet;
use super::gdke::JointKind;
use super::segments::{
    Frame, Samples, SegmentMap, SegmentSpec, Solved, SolvedJoint, build_clip, check_order,
    frame_from_axis, hold, pass, rigid_fit, solve_err, v3,
};

/// One segment's frame in every frame of `set` (`None` where it cannot be determined), from
/// its calibrated template (columns `cols` of `set`, positions `template`) and its parent's
/// frames: a rigid fit of the visible template markers and `u_j` onto the markers and
/// `c_jk = x_k + M_k·v_j`, or section 2.5 case 1 for a one-marker hinge segment.
fn segment_frames(
    set: &MarkerSet,
    seg: &SegmentSpec,
    cal: &CalibratedJoint,
    cols: &[usize],
    template: &[Vector3<f64>],
    parent_frames: Option<&[Frame]>,
) -> Result<Vec<Option<Frame>>, MarkerError> {
    let u = v3(cal.centre_own_mm);
    let v = v3(cal.centre_parent_mm);
    let frames = set.frames();
    if seg.markers.len() < 2 {
        // Section 2.5 case 1: the marker, the centre and the hinge axis.
        let (Some(pf), JointKind::Hinge { axis }) = (parent_frames, cal.kind) else {
            return Err(solve_err(
                &seg.name,
                "a segment with one marker needs a calibrated hinge joint (section 2.5 case 1)"
                    .into(),
            ));
        };
        let col = seg.markers.first().and_then(|m| set.marker_index(m));
        return Ok(pf
            .iter()
            .enumerate()
            .map(|(f, pf)| {
                let o = set.get(f, col?)?;
                frame_from_axis(&v3(o), &pf.to_world(&v), &(pf.axes * v3(axis)))
            })
            .collect());
    }
    let mut l = Vec::with_capacity(cols.len() + 1);
    let mut w = Vec::with_capacity(cols.len() + 1);
    Ok((0..frames)
        .map(|f| {
            l.clear();
            w.clear();
            for (t, &col) in template.iter().zip(cols) {
                if let Some(x) = set.get(f, col) {
                    l.push(*t);
                    w.push(v3(x));
                }
            }
            if let Some(pf) = parent_frames {
                l.push(u);
                w.push(pf[f].to_world(&v));
            }
            rigid_fit(&l, &w)
        })
        .collect())
}

/// A marker's position in its segment's frame, averaged over the calibration trial.
#[derive(Debug, Clone, PartialEq)]
pub struct TemplateMarker {
    /// Marker name.
    pub name: String,
    /// Position in the segment's frame, mm.
    pub local_mm: [f64; 3],
}

/// One segment's joint as calibrated.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibratedJoint {
    /// Segment name.
    pub segment: String,
    /// Classification on the calibration trial; a hinge's axis is in the parent's frame.
    /// The root is `NotMoving` (it has no centre).
    pub kind: JointKind,
    /// Centre `v_j` in the parent's frame, mm; for the root its joint point (the centroid of
    /// its markers) in its own frame.
    pub centre_parent_mm: [f64; 3],
    /// The same centre `u_j` in the segment's own frame, mm (the root: as above).
    pub centre_own_mm: [f64; 3],
    /// Markers rigid with the segment in its frame: its own first (`own_markers` of them),
    /// then, for a joint that does not move, those rigid with its parent. A marker never
    /// seen in the calibration trial has no template and is left out.
    pub markers: Vec<TemplateMarker>,
    /// How many of `markers` are the segment's own.
    pub own_markers: usize,
    /// Markers whose fits made the centre on the calibration trial.
    pub markers_used: usize,
}

/// Joint centres, axes, classifications and marker templates estimated on one trial, to be
/// applied to others recorded with the same markers (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The segment map the calibration was estimated with; a solve uses it too.
    pub map: SegmentMap,
    /// One entry per segment of `map`, in its order.
    pub joints: Vec<CalibratedJoint>,
    /// Frames of the calibration trial.
    pub frames: usize,
}

impl Calibration {
    /// Estimates the calibration on `set` (a range-of-motion trial) with the same
    /// root-to-leaf pass as [`segments::solve`](super::segments::solve).
    ///
    /// # Errors
    /// As [`segments::solve`](super::segments::solve): a marker of the map missing from
    /// `set`, or a segment whose frame or centre cannot be determined.
    pub fn estimate(set: &MarkerSet, map: &SegmentMap) -> Result<Calibration, MarkerError> {
        let p = pass(set, map, Samples::Moving)?;
        let mut joints = Vec::with_capacity(map.segments.len());
        for (s, seg) in map.segments.iter().enumerate() {
            let frames = &p.seg_frames[s];
            let mut markers = Vec::with_capacity(p.rigid_of[s].len());
            let mut own_markers = 0;
            let mut own_sum = Vector3::zeros();
            for (k, &col) in p.rigid_of[s].iter().enumerate() {
                let (mut sum, mut n) = (Vector3::zeros(), 0usize);
                for (f, fr) in frames.iter().enumerate() {
                    if let Some(x) = set.get(f, col) {
                        sum += fr.to_local(&v3(x));
                        n += 1;
                    }
                }
                if n == 0 {
                    continue;
                }
                let local = sum / n as f64;
                if k < seg.markers.len() {
                    own_markers += 1;
                    own_sum += local;
                }
                markers.push(TemplateMarker {
                    name: set.names()[col].clone(),
                    local_mm: [local.x, local.y, local.z],
                });
            }
            let solved = &p.joints[s];
            let (centre_parent_mm, centre_own_mm) = if seg.parent.is_some() {
                let u = p.own_point[s];
                (solved.centre_parent_mm, [u.x, u.y, u.z])
            } else {
                // The root's joint point: its markers' centroid in its (final) frame.
                let c = own_sum / own_markers.max(1) as f64;
                ([c.x, c.y, c.z], [c.x, c.y, c.z])
            };
            joints.push(CalibratedJoint {
                segment: seg.name.clone(),
                kind: solved.kind,
                centre_parent_mm,
                centre_own_mm,
                markers,
                own_markers,
                markers_used: solved.markers_used,
            });
        }
        Ok(Calibration {
            map: map.clone(),
            joints,
            frames: set.frames(),
        })
    }

    /// Checks that the calibration is complete and consistent with its map.
    fn check(&self) -> Result<(), MarkerError> {
        let bad = |reason: String| Err(MarkerError::Calibration { reason });
        check_order(&self.map)?;
        if self.joints.len() != self.map.segments.len() {
            return bad(format!(
                "{} calibrated joints for {} segments",
                self.joints.len(),
                self.map.segments.len()
            ));
        }
        for (j, seg) in self.joints.iter().zip(&self.map.segments) {
            if j.segment != seg.name {
                return bad(format!(
                    "joint {:?} where the map has segment {:?}",
                    j.segment, seg.name
                ));
            }
            // Finite and within 10⁹ mm (1000 km), so that products of positions stay finite.
            let finite = |p: &[f64; 3]| p.iter().all(|v| v.is_finite() && v.abs() <= 1e9);
            if !(finite(&j.centre_parent_mm)
                && finite(&j.centre_own_mm)
                && j.markers.iter().all(|m| finite(&m.local_mm)))
            {
                return bad(format!(
                    "segment {}: a position is not a finite number of mm within 10⁹",
                    seg.name
                ));
            }
            if let JointKind::Hinge { axis } = j.kind
                && !(axis.iter().all(|v| v.is_finite()) && v3(axis).norm() > 1e-12)
            {
                return bad(format!(
                    "segment {}: the hinge axis is not a direction",
                    seg.name
                ));
            }
            if j.own_markers > j.markers.len() {
                return bad(format!(
                    "segment {}: {} own markers of {}",
                    seg.name,
                    j.own_markers,
                    j.markers.len()
                ));
            }
        }
        Ok(())
    }

    /// Solves `set` (a motion trial with the calibration trial's markers) with this
    /// calibration's centres, axes and templates (see the module docs) into a BVH clip.
    ///
    /// # Errors
    /// [`MarkerError::MissingMarker`] naming the first marker of the map or of a template that
    /// `set` lacks; [`MarkerError::Calibration`] when the calibration does not fit its map;
    /// [`MarkerError::Solve`] when `set` has no frames or a segment's frame cannot be
    /// determined in any frame.
    pub fn solve(&self, set: &MarkerSet) -> Result<Solved, MarkerError> {
        self.check()?;
        let map = &self.map;
        let frames = set.frames();
        if frames == 0 {
            return Err(solve_err(
                &map.segments[0].name,
                "the marker set has no frames".into(),
            ));
        }
        let column = |name: &str, segment: &str| {
            set.marker_index(name)
                .ok_or_else(|| MarkerError::MissingMarker {
                    marker: name.to_string(),
                    segment: segment.to_string(),
                })
        };
        // Every marker named anywhere must be present before any work is done.
        let mut template_cols: Vec<Vec<usize>> = Vec::with_capacity(self.joints.len());
        for (seg, cal) in map.segments.iter().zip(&self.joints) {
            for m in &seg.markers {
                column(m, &seg.name)?;
            }
            template_cols.push(
                cal.markers
                    .iter()
                    .map(|m| column(&m.name, &seg.name))
                    .collect::<Result<_, _>>()?,
            );
        }
        let n_seg = map.segments.len();
        let mut seg_frames: Vec<Vec<Frame>> = Vec::with_capacity(n_seg);
        let mut joints = Vec::with_capacity(n_seg);
        let mut own_point = Vec::with_capacity(n_seg);
        let mut centroids = Vec::with_capacity(n_seg);
        for (s, (seg, cal)) in map.segments.iter().zip(&self.joints).enumerate() {
            let cols = &template_cols[s];
            let template: Vec<Vector3<f64>> = cal.markers.iter().map(|m| v3(m.local_mm)).collect();
            let u = v3(cal.centre_own_mm);
            let parent_frames = seg.parent.map(|p| seg_frames[p].as_slice());
            let mut fitted = segment_frames(set, seg, cal, cols, &template, parent_frames)?;
            let Some(held) = hold(&mut fitted) else {
                return Err(solve_err(
                    &seg.name,
                    "its frame cannot be determined in any frame (markers missing or collinear)"
                        .into(),
                ));
            };
            seg_frames.push(fitted.into_iter().flatten().collect());
            let own = &template[..cal.own_markers];
            centroids.push(if own.is_empty() {
                u
            } else {
                own.iter().sum::<Vector3<f64>>() / own.len() as f64
            });
            own_point.push(u);
            joints.push(SolvedJoint {
                segment: seg.name.clone(),
                kind: cal.kind,
                centre_parent_mm: cal.centre_parent_mm,
                markers_used: cal.markers_used,
                held_frames: held,
            });
        }
        build_clip(set, map, &seg_frames, &joints, &own_point, &centroids)
    }
}
