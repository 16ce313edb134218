//! Issue 9, functional calibration: joint centres estimated by GDKE on a synthetic
//! range-of-motion trial of CMU 02_01 and applied to its motion trial (same markers).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::Path;

use common::{assert_survives_a_bvh_round_trip, dist, walk_clip};
use markers::MarkerError;
use markers::calibration::Calibration;
use markers::gdke::{GdkeOptions, JointKind};
use markers::segments::{self, SegmentMap, Solved, parse_segments};
use markers::synth::{
    MarkerPlacement, RomOptions, SynthCapture, SynthOptions, rom_capture, rom_clip, rom_groups,
    segment_map_toml, synth_capture,
};
use motion::clip::SkeletonFormat;
use proptest::prelude::*;

fn map_of(clip: &motion::Clip) -> SegmentMap {
    parse_segments(&segment_map_toml(clip), Path::new("synth.toml")).unwrap()
}

const EXACT: GdkeOptions = GdkeOptions {
    hinge_condition: 1e8,
    still_std: 1e-9,
};

const NOISE_FREE: SynthOptions = SynthOptions {
    noise_mm: 0.0,
    gap_probability: 0.0,
    offset_cm: 6.0,
    seed: 9,
};

/// True for a one-axis joint whose axis runs along its own bone (the CMU wrists, `dof ry`
/// about the forearm line): a twist, whose centre no motion places along the axis.
fn is_twist(clip: &motion::Clip, segment_name: &str) -> bool {
    let sk = &clip.skeleton;
    let Some(j) = sk.joint_index(segment_name) else {
        return false;
    };
    let joint = &sk.joints[j];
    let rot: Vec<_> = joint.dofs.iter().filter(|d| d.is_rotation()).collect();
    if rot.len() != 1 || sk.format != SkeletonFormat::Asf {
        return false;
    }
    let motion::clip::ChannelKind::Rotation(axis) = rot[0] else {
        return false;
    };
    let c = motion::math::euler_fixed(&joint.axis_order, &joint.axis_deg);
    let mut e = [0.0; 3];
    e[axis.index()] = 1.0;
    let a = motion::math::mul_vec(&c, &e);
    let b = joint.rest.vector();
    let bn = dist(b, [0.0; 3]);
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs() > 0.99 * bn
}

struct JointError {
    name: String,
    kind: JointKind,
    twist: bool,
    /// RMS over frames of the distance from the true joint point, mm.
    rms_mm: f64,
    /// The same measured off the solved hinge axis (= `rms_mm` for other kinds), mm.
    rms_off_axis_mm: f64,
    /// Largest distance over frames (off the axis for twist joints), mm.
    max_mm: f64,
    /// Length of the longer bone at the joint (to its parent's or its child's centre), mm.
    bone_mm: f64,
}

impl JointError {
    /// The figure the targets use: the distance from the true point, measured off the axis
    /// for the twist joints only.
    fn counted_mm(&self) -> f64 {
        if self.twist {
            self.rms_off_axis_mm
        } else {
            self.rms_mm
        }
    }
}

/// Per-joint errors of every segment's joint point (all 28 of the CMU skeleton: every joint
/// with rotation channels but the root) against the FK points of the clip.
fn errors(clip: &motion::Clip, cap: &SynthCapture, solved: &Solved) -> Vec<JointError> {
    let kin = motion::fk::Kinematics::new(&solved.clip.skeleton);
    let (mut values, mut local, mut points, mut rotations) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let frames = solved.clip.frames();
    assert_eq!(frames, cap.truth_mm.len());
    let mut out = Vec::new();
    for (s, seg) in cap.segments.iter().enumerate() {
        let Some(tp) = seg.truth_point else { continue };
        let kind = solved.joints[s].kind;
        let twist = is_twist(clip, &seg.name);
        let j = solved.joint_of_segment[s];
        let p = seg.parent.unwrap();
        let pj = solved.joint_of_segment[p];
        let (mut e2, mut a2, mut max) = (0.0, 0.0, 0.0f64);
        for f in 0..frames {
            solved.clip.frame_into(f, &mut values);
            kin.local_transforms(&values, &mut local);
            kin.world(&local, &mut points, &mut rotations);
            let t = cap.truth_mm[f][tp];
            let d = [0, 1, 2].map(|k| t[k] - points[j][k]);
            let dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            let off = if let JointKind::Hinge { axis } = kind {
                let n = motion::math::mul_vec(&rotations[pj], &axis);
                let along = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
                (dd - along * along).max(0.0)
            } else {
                dd
            };
            e2 += dd;
            a2 += off;
            max = max.max(if twist { off.sqrt() } else { dd.sqrt() });
        }
        let parent_point = cap.segments[p].truth_point.unwrap_or(0);
        let up = dist(cap.truth_mm[0][tp], cap.truth_mm[0][parent_point]);
        let down = cap
            .segments
            .iter()
            .filter(|c| c.parent == Some(s))
            .filter_map(|c| c.truth_point)
            .map(|c| dist(cap.truth_mm[0][c], cap.truth_mm[0][tp]))
            .fold(0.0, f64::max);
        out.push(JointError {
            name: seg.name.clone(),
            kind,
            twist,
            rms_mm: (e2 / frames as f64).sqrt(),
            rms_off_axis_mm: (a2 / frames as f64).sqrt(),
            max_mm: max,
            bone_mm: up.max(down),
        });
    }
    out
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in values {
        s += v * v;
        n += 1;
    }
    (s / n.max(1) as f64).sqrt()
}

fn kind_name(k: JointKind) -> &'static str {
    match k {
        JointKind::Spherical => "spherical",
        JointKind::Hinge { .. } => "hinge",
        JointKind::NotMoving => "not moving",
    }
}

#[test]
fn rom_trial_carries_the_motion_trial_markers() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let options = SynthOptions::default();
    let motion = synth_capture(&clip, &options).unwrap();
    let rom = rom_capture(&clip, &RomOptions::default(), &options).unwrap();
    assert_eq!(motion.markers.names(), rom.markers.names());
    assert_eq!(motion.segments, rom.segments);
    // Same placement: every noise-free marker sits at the same offset in its bone's frame in
    // both trials (from the placement, independently of the generator).
    let placement = MarkerPlacement::new(&clip.skeleton, options.offset_cm).unwrap();
    let trial = rom_clip(&clip, &RomOptions::default()).unwrap();
    let mm = clip.skeleton.units.cm_per_unit * 10.0;
    for (c, cap) in [(&clip, &motion), (&trial, &rom)] {
        let kin = motion::fk::Kinematics::new(&c.skeleton);
        let (mut values, mut local, mut points, mut rotations) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for f in (0..c.frames()).step_by(37) {
            c.frame_into(f, &mut values);
            kin.local_transforms(&values, &mut local);
            kin.world(&local, &mut points, &mut rotations);
            for (m, pm) in placement.markers.iter().enumerate() {
                let x = cap.exact.get(f, m).unwrap();
                let r = rotations[pm.joint];
                let d = [0, 1, 2].map(|k| x[k] / mm - points[pm.anchor_point][k]);
                // Rᵀ·d: the marker in its bone's frame.
                let local_off = [0, 1, 2].map(|k| r[0][k] * d[0] + r[1][k] * d[1] + r[2][k] * d[2]);
                assert!(dist(local_off, pm.offset) < 1e-9, "frame {f} {}", pm.name);
            }
        }
    }
    // The seed reproduces both trials; the two trials' noise is independent.
    let again = rom_capture(&clip, &RomOptions::default(), &options).unwrap();
    assert_eq!(again.markers, rom.markers);
    let noise = |cap: &SynthCapture| {
        let (a, b) = (cap.markers.get(0, 0).unwrap(), cap.exact.get(0, 0).unwrap());
        [0, 1, 2].map(|k| a[k] - b[k])
    };
    assert!(dist(noise(&motion), noise(&rom)) > 1e-6);
}

#[test]
fn rom_clip_swings_each_rotation_axis_alone_within_limits() {
    let Some((_, clip)) = walk_clip(10) else {
        return;
    };
    let options = RomOptions::default();
    let trial = rom_clip(&clip, &options).unwrap();
    let sk = &trial.skeleton;
    let groups = rom_groups(sk);
    let ancestor = |a: usize, mut j: usize| {
        while let Some(p) = sk.joints[j].parent {
            if p == a {
                return true;
            }
            j = p;
        }
        false
    };
    let mut seen = vec![0usize; sk.joints.len()];
    for g in &groups {
        for &a in g {
            seen[a] += 1;
            assert!(
                g.iter().all(|&b| !ancestor(a, b)),
                "{} with a descendant",
                sk.joints[a].name
            );
        }
    }
    for (j, joint) in sk.joints.iter().enumerate() {
        let rotates = joint.parent.is_some() && joint.dofs.iter().any(|d| d.is_rotation());
        assert_eq!(seen[j], usize::from(rotates), "{}", joint.name);
    }
    let mut base = Vec::new();
    clip.frame_into(0, &mut base);
    let channels = trial.channels();
    let mut values = Vec::new();
    let mut moved = vec![0.0f64; channels.len()];
    for f in 0..trial.frames() {
        trial.frame_into(f, &mut values);
        let mut moving_joints: Vec<usize> = Vec::new();
        for (c, ch) in channels.iter().enumerate() {
            let d = values[c] - base[c];
            if d.abs() < 1e-9 {
                continue;
            }
            moved[c] = moved[c].max(d.abs());
            assert!(ch.kind.is_rotation() && sk.joints[ch.joint].parent.is_some());
            assert!(d.abs() <= options.amplitude_deg + 1e-9);
            // Within the limits, unless the base pose was already past them.
            let joint = &sk.joints[ch.joint];
            if let Some(&(lo, hi)) = joint
                .dofs
                .iter()
                .position(|x| *x == ch.kind)
                .and_then(|k| joint.limits.get(k))
            {
                assert!(values[c] >= lo.min(base[c]) - 1e-9 && values[c] <= hi.max(base[c]) + 1e-9);
            }
            // One axis of a joint at a time.
            assert!(
                !moving_joints.contains(&ch.joint),
                "frame {f}: {} moves two axes",
                joint.name
            );
            moving_joints.push(ch.joint);
        }
        for &a in &moving_joints {
            assert!(moving_joints.iter().all(|&b| !ancestor(a, b)), "frame {f}");
        }
    }
    // Every rotation axis of every joint swings by at least 10° (the CMU limits leave some
    // axes one side only).
    for (c, ch) in channels.iter().enumerate() {
        if ch.kind.is_rotation() && sk.joints[ch.joint].parent.is_some() {
            assert!(
                moved[c] >= 10.0,
                "{} swings {}°",
                trial.channel_name(c),
                moved[c]
            );
        }
    }
    let rate = clip.frame_rate_hz;
    let longest: usize = groups
        .iter()
        .map(|g| g.iter().map(|&j| sk.joints[j].dofs.len()).max().unwrap())
        .sum();
    assert_eq!(
        trial.frames(),
        longest * (options.seconds_per_axis * rate) as usize
    );
    eprintln!(
        "range-of-motion trial: {} groups, {} frames ({:.0} s)",
        groups.len(),
        trial.frames(),
        trial.duration_s()
    );
}

#[test]
fn noise_free_calibrated_solve_of_cmu_is_exact() {
    let Some((_, clip)) = walk_clip(300) else {
        return;
    };
    let mut map = map_of(&clip);
    map.gdke = EXACT;
    let rom = rom_capture(&clip, &RomOptions::default(), &NOISE_FREE).unwrap();
    let motion = synth_capture(&clip, &NOISE_FREE).unwrap();
    let cal = Calibration::estimate(&rom.markers, &map).unwrap();
    let solved = cal.solve(&motion.markers).unwrap();
    let errs = errors(&clip, &motion, &solved);
    assert_eq!(errs.len(), 28);
    let mut twists = Vec::new();
    for e in &errs {
        eprintln!(
            "{:<10} {:<9} worst {:.2e} of the bone ({:.0} mm), along a twist axis {:.1} mm",
            e.name,
            kind_name(e.kind),
            e.max_mm / e.bone_mm,
            e.bone_mm,
            if e.twist { e.rms_mm } else { 0.0 }
        );
        // Every joint is exercised in the calibration trial, the spine, neck, clavicles and
        // shoulders included: none is "not moving", each has its skeleton's kind.
        let seg = motion.segments.iter().find(|s| s.name == e.name).unwrap();
        let expected = if seg.hinge { "hinge" } else { "spherical" };
        assert_eq!(kind_name(e.kind), expected, "{}", e.name);
        assert!(e.max_mm <= 1e-6 * e.bone_mm, "{}: {} mm", e.name, e.max_mm);
        if e.twist {
            twists.push(e.name.as_str());
        }
    }
    assert_eq!(twists, ["lwrist", "rwrist"]);
    // The solved clip's FK reproduces the clip's points of every joint: the points above are
    // the solved clip's own FK points; the same holds after a BVH round trip.
    assert_survives_a_bvh_round_trip(&solved.clip, "markers-cal");
}

#[test]
fn calibrated_solve_of_cmu_reaches_1_cm_at_2_mm() {
    let Some((_, clip)) = walk_clip(480) else {
        return;
    };
    let options = SynthOptions::default(); // σ = 2 mm, 0.5 % gaps
    let map = map_of(&clip);
    let rom = rom_capture(&clip, &RomOptions::default(), &options).unwrap();
    let motion = synth_capture(&clip, &options).unwrap();
    assert!(rom.markers.gap_count() > 0 && motion.markers.gap_count() > 0);
    let cal = Calibration::estimate(&rom.markers, &map).unwrap();
    let calibrated = errors(&clip, &motion, &cal.solve(&motion.markers).unwrap());
    let plain = errors(
        &clip,
        &motion,
        &segments::solve(&motion.markers, &map).unwrap(),
    );
    assert_eq!(calibrated.len(), plain.len(), "the same joints both ways");
    eprintln!("joint      calibrated                 without calibration");
    for (c, p) in calibrated.iter().zip(&plain) {
        eprintln!(
            "{:<10} {:<9} {:5.2} cm (max {:5.2})  {:<10} {:5.2} cm{}",
            c.name,
            kind_name(c.kind),
            c.counted_mm() / 10.0,
            c.max_mm / 10.0,
            kind_name(p.kind),
            p.counted_mm() / 10.0,
            if c.twist {
                format!(
                    "  (off the twist axis; with the slide along it {:.2} / {:.2} cm)",
                    c.rms_mm / 10.0,
                    p.rms_mm / 10.0
                )
            } else {
                String::new()
            }
        );
    }
    let all_cal = rms(calibrated.iter().map(JointError::counted_mm)) / 10.0;
    let all_plain = rms(plain.iter().map(JointError::counted_mm)) / 10.0;
    let slide_cal = rms(calibrated.iter().map(|e| e.rms_mm)) / 10.0;
    let slide_plain = rms(plain.iter().map(|e| e.rms_mm)) / 10.0;
    eprintln!(
        "RMS over all {} joints (wrists off their twist axis): calibrated {all_cal:.3} cm, \
         without calibration {all_plain:.3} cm; with the wrists' slide along the axis \
         {slide_cal:.3} / {slide_plain:.3} cm",
        calibrated.len()
    );
    assert_eq!(calibrated.len(), 28);
    assert!(
        calibrated.iter().all(|e| e.kind != JointKind::NotMoving),
        "a joint was not exercised"
    );
    assert!(all_cal <= 1.0, "calibrated RMS {all_cal} cm");
    // The walk alone does not place the still joints: without calibration it is worse.
    assert!(
        all_plain > 2.0 * all_cal,
        "without calibration {all_plain} cm"
    );
}

#[test]
fn calibration_applied_to_other_markers_names_the_missing_one() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 1.0,
        ..Default::default()
    });
    let map = map_of(&clip);
    let options = SynthOptions::default();
    let rom = rom_capture(
        &clip,
        &RomOptions {
            seconds_per_axis: 0.5,
            ..RomOptions::default()
        },
        &options,
    )
    .unwrap();
    let cal = Calibration::estimate(&rom.markers, &map).unwrap();
    let motion = synth_capture(&clip, &options).unwrap();
    assert!(cal.solve(&motion.markers).is_ok());
    // A motion trial without one of the markers.
    let names = motion.markers.names();
    let gone = names.len() / 2;
    let kept: Vec<String> = names
        .iter()
        .enumerate()
        .filter(|&(i, _)| i != gone)
        .map(|(_, n)| n.clone())
        .collect();
    let mut fewer =
        markers::data::MarkerSet::new(kept, motion.markers.frames(), motion.markers.frame_rate_hz);
    for f in 0..motion.markers.frames() {
        for (i, m) in (0..names.len()).filter(|&i| i != gone).enumerate() {
            fewer.set(f, i, motion.markers.get(f, m));
        }
    }
    let e = cal.solve(&fewer).unwrap_err();
    match &e {
        MarkerError::MissingMarker { marker, .. } => assert_eq!(marker, &names[gone]),
        other => panic!("{other}"),
    }
    assert!(e.to_string().contains(&names[gone]), "{e}");
    // The same marker missing from the calibration trial: the estimate names it.
    let e = Calibration::estimate(&fewer, &map).unwrap_err();
    assert!(e.to_string().contains(&names[gone]), "{e}");
    // A calibration that does not fit its map.
    let mut short = cal.clone();
    short.joints.pop();
    assert!(matches!(
        short.solve(&motion.markers),
        Err(MarkerError::Calibration { .. })
    ));
    let mut renamed = cal.clone();
    renamed.joints[2].segment = "elsewhere".into();
    let e = renamed.solve(&motion.markers).unwrap_err();
    assert!(e.to_string().contains("elsewhere"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A calibration is plain data a caller may build or change: any value in any field
    /// gives a solve or a typed error, never a panic.
    #[test]
    fn mutated_calibrations_never_panic(
        joint in 0usize..64,
        field in 0usize..7,
        value in prop::sample::select(vec![f64::NAN, f64::INFINITY, -1e300, 0.0, 1e-300, 5.0, 1e12]),
    ) {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
            duration_s: 0.5,
            ..Default::default()
        });
        let map = map_of(&clip);
        let exact = rom_capture(&clip, &RomOptions { seconds_per_axis: 0.25, ..RomOptions::default() }, &NOISE_FREE).unwrap();
        let mut cal = Calibration::estimate(&exact.markers, &map).unwrap();
        let motion = synth_capture(&clip, &NOISE_FREE).unwrap();
        let n = cal.joints.len();
        let j = &mut cal.joints[joint % n];
        match field {
            0 => j.centre_parent_mm[joint % 3] = value,
            1 => j.centre_own_mm[joint % 3] = value,
            2 => if let Some(m) = j.markers.first_mut() { m.local_mm[joint % 3] = value },
            3 => j.kind = JointKind::Hinge { axis: [value, 0.0, 0.0] },
            4 => j.markers.clear(),
            5 => j.own_markers = (value.abs().min(1e6)) as usize,
            _ => j.markers.iter_mut().for_each(|m| m.local_mm = [value; 3]),
        }
        match cal.solve(&motion.markers) {
            Ok(s) => prop_assert_eq!(s.clip.frames(), motion.markers.frames()),
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }
}
