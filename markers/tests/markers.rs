//! Issue 9: GDKE joint centres, marker files and skeleton solving from synthetic captures.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::Path;

use common::{assert_survives_a_bvh_round_trip, dist, walk_clip};
use markers::c3d::{C3dStorage, format_c3d, write_c3d_with};
use markers::data::{self, MarkerSet};
use markers::gdke::{GdkeOptions, JointKind, LsqOptions, gdke, least_squares_sphere};
use markers::segments::{self, parse_segments};
use markers::synth::{SynthOptions, segment_map_toml, synth_capture};
use markers::{MarkerError, MarkerLimits};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn rot(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let [x, y, z] = axis.map(|v| v / n);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

fn apply(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

const EXACT: GdkeOptions = GdkeOptions {
    hinge_condition: 1e8,
    still_std: 1e-9,
};

#[test]
fn noise_free_spherical_joint_centre_is_exact_and_classified() {
    // A 2-DOF joint (flexion ±60°, abduction ±35°) moving a marker 40 cm from the centre.
    let c0 = [12.0, -30.0, 95.0];
    let arm = [3.0, -40.0, 5.0];
    let bone = dist(arm, [0.0; 3]);
    let mut pts = Vec::new();
    for i in 0..60 {
        let a = (i as f64 * 0.41).sin() * 60f64.to_radians();
        let b = (i as f64 * 0.23).cos() * 35f64.to_radians();
        let r = apply(
            &rot([1.0, 0.0, 0.0], a),
            apply(&rot([0.0, 0.0, 1.0], b), arm),
        );
        pts.push([c0[0] + r[0], c0[1] + r[1], c0[2] + r[2]]);
    }
    let fit = gdke(&pts, &EXACT).unwrap();
    assert_eq!(
        fit.kind,
        JointKind::Spherical,
        "condition {}",
        fit.condition
    );
    assert!(
        dist(fit.centre, c0) < 1e-6 * bone,
        "error {}",
        dist(fit.centre, c0)
    );
    assert!((fit.radius - bone).abs() < 1e-6 * bone);
}

#[test]
fn noise_free_hinge_joint_centre_is_exact_and_classified() {
    // A knee-like hinge about axis n through c0; the marker sits 4 cm along the axis from the
    // joint, so the circle it draws is centred at c0 + 4·n (eq. 6's centre in its plane).
    let c0 = [-5.0, 48.0, 3.0];
    let n = [0.6, 0.0, 0.8];
    let arm = [4.0 * 0.6 + 0.0, -38.0, 4.0 * 0.8];
    let mut pts = Vec::new();
    for i in 0..50 {
        let a = (i as f64 * 0.3).sin() * 70f64.to_radians();
        let r = apply(&rot(n, a), arm);
        pts.push([c0[0] + r[0], c0[1] + r[1], c0[2] + r[2]]);
    }
    let fit = gdke(&pts, &EXACT).unwrap();
    let JointKind::Hinge { axis } = fit.kind else {
        panic!("classified {:?} (condition {})", fit.kind, fit.condition);
    };
    let dot = axis[0] * n[0] + axis[1] * n[1] + axis[2] * n[2];
    assert!((dot.abs() - 1.0).abs() < 1e-9, "axis {axis:?}");
    let truth = [c0[0] + 4.0 * n[0], c0[1] + 4.0 * n[1], c0[2] + 4.0 * n[2]];
    assert!(
        dist(fit.centre, truth) < 1e-6 * 38.0,
        "error {}",
        dist(fit.centre, truth)
    );
    // A joint that does not move is reported as such.
    let still = gdke(&[c0; 8], &EXACT).unwrap();
    assert_eq!(still.kind, JointKind::NotMoving);
}

/// Uniform point on the unit sphere.
fn on_sphere(rng: &mut ChaCha8Rng) -> [f64; 3] {
    let z: f64 = 2.0 * rng.random::<f64>() - 1.0;
    let t: f64 = std::f64::consts::TAU * rng.random::<f64>();
    let s = (1.0 - z * z).sqrt();
    [s * t.cos(), s * t.sin(), z]
}

#[test]
fn monte_carlo_bias_follows_eq_7_and_radius_is_unbiased() {
    // Seed 003, section 2.2: points uniform on a sphere with Gaussian noise; |c − c0| ≈
    // 2.93·σ/√N (eq. 7) for σ < 0.1·R, and the radius unbiased.
    let mut rng = ChaCha8Rng::seed_from_u64(2007);
    let runs = 2000;
    let (mut ratio_sum, mut radius_bias_sum, mut lsq_ratio_sum) = (0.0, 0.0, 0.0);
    for run in 0..runs {
        let n = 20 + (rng.random::<f64>() * 981.0) as usize;
        let r0 = 0.1 + rng.random::<f64>() * 0.5;
        let sigma = r0 * (0.002 + 0.098 * rng.random::<f64>());
        let c0 = [
            0.6 + 0.5 * gaussian(&mut rng),
            -0.2 + 0.5 * gaussian(&mut rng),
            0.9 + 0.5 * gaussian(&mut rng),
        ];
        let pts: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                let u = on_sphere(&mut rng);
                [0, 1, 2].map(|k| c0[k] + r0 * u[k] + sigma * gaussian(&mut rng))
            })
            .collect();
        let fit = gdke(&pts, &GdkeOptions::default()).unwrap();
        assert_eq!(fit.kind, JointKind::Spherical);
        ratio_sum += dist(fit.centre, c0) * (n as f64).sqrt() / sigma;
        radius_bias_sum += (fit.radius - r0) / sigma;
        if run < 300 {
            let l = least_squares_sphere(&pts, None, &LsqOptions::default()).unwrap();
            lsq_ratio_sum += dist(l.centre, c0) * (n as f64).sqrt() / sigma;
        }
    }
    let ratio = ratio_sum / f64::from(runs);
    let radius_bias = radius_bias_sum / f64::from(runs);
    let lsq_ratio = lsq_ratio_sum / 300.0;
    eprintln!(
        "GDKE mean |c−c0|·√N/σ = {ratio:.3} (eq. 7: 2.93); least squares {lsq_ratio:.3}; \
         mean radius bias {radius_bias:.4}·σ"
    );
    assert!((ratio - 2.93).abs() < 0.1 * 2.93, "ratio {ratio}");
    assert!(
        (lsq_ratio - 2.93).abs() < 0.1 * 2.93,
        "least-squares ratio {lsq_ratio}"
    );
    // Unbiased: the mean radius error is a small fraction of σ (its spread is σ·√(1/N)).
    assert!(radius_bias.abs() < 0.15, "radius bias {radius_bias}·σ");
}

#[test]
fn too_few_samples_is_a_typed_error() {
    let e = gdke(
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &GdkeOptions::default(),
    );
    assert!(matches!(
        e,
        Err(MarkerError::TooFewSamples {
            got: 3,
            needed: 4,
            ..
        })
    ));
    let e = least_squares_sphere(&[[0.0; 3]; 2], None, &LsqOptions::default());
    assert!(matches!(e, Err(MarkerError::TooFewSamples { got: 2, .. })));
}

fn demo_clip() -> motion::Clip {
    motion::synth::walking_clip(&motion::synth::WalkParams::default())
}

struct JointError {
    name: String,
    /// Kind of the parent segment's joint (`None` for the root).
    parent_kind: Option<JointKind>,
    kind: JointKind,
    /// RMS distance of the solved joint point from the truth, mm.
    rms_mm: f64,
    /// RMS distance of the truth from the solved hinge axis (= `rms_mm` for other kinds), mm:
    /// a hinge's centre is only defined up to a slide along its axis (eq. 6).
    rms_off_axis_mm: f64,
    /// Distance to the farthest child centre, mm.
    bone_mm: f64,
}

/// Per-segment RMS errors of solved joint points against the truth, and the RMS over the
/// joints that move.
fn centre_errors(
    clip: &motion::Clip,
    options: &SynthOptions,
    gdke_options: Option<GdkeOptions>,
) -> (Vec<JointError>, f64) {
    let cap = synth_capture(clip, options).unwrap();
    let mut map = parse_segments(&segment_map_toml(clip), Path::new("synth.toml")).unwrap();
    if let Some(g) = gdke_options {
        map.gdke = g;
    }
    let solved = segments::solve(&cap.markers, &map).unwrap();
    let kin = motion::fk::Kinematics::new(&solved.clip.skeleton);
    let (mut values, mut local, mut points, mut rotations) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut out = Vec::new();
    let (mut sum, mut count) = (0.0, 0usize);
    let frames = solved.clip.frames();
    for (s, seg) in cap.segments.iter().enumerate() {
        let Some(tp) = seg.truth_point else { continue };
        let kind = solved.joints[s].kind;
        let j = solved.joint_of_segment[s];
        let pj = solved.joint_of_segment[seg.parent.unwrap()];
        let (mut e2, mut a2) = (0.0, 0.0);
        for f in 0..frames {
            solved.clip.frame_into(f, &mut values);
            kin.local_transforms(&values, &mut local);
            kin.world(&local, &mut points, &mut rotations);
            let t = cap.truth_mm[f][tp];
            let d = [0, 1, 2].map(|k| t[k] - points[j][k]);
            let dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            e2 += dd;
            a2 += if let JointKind::Hinge { axis } = kind {
                let n = apply(&rotations[pj], axis);
                let along = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
                (dd - along * along).max(0.0)
            } else {
                dd
            };
        }
        let bone_mm = cap
            .segments
            .iter()
            .filter(|c| c.parent == Some(s))
            .filter_map(|c| c.truth_point)
            .map(|c| dist(cap.truth_mm[0][c], cap.truth_mm[0][tp]))
            .fold(0.0, f64::max);
        if kind != JointKind::NotMoving {
            sum += e2;
            count += frames;
        }
        let parent_seg = seg.parent.unwrap();
        out.push(JointError {
            name: seg.name.clone(),
            parent_kind: cap.segments[parent_seg]
                .parent
                .map(|_| solved.joints[parent_seg].kind),
            kind,
            rms_mm: (e2 / frames as f64).sqrt(),
            rms_off_axis_mm: (a2 / frames as f64).sqrt(),
            bone_mm,
        });
    }
    (out, (sum / count.max(1) as f64).sqrt())
}

#[test]
fn noise_free_solve_reproduces_joint_centres() {
    let clip = demo_clip();
    let options = SynthOptions {
        noise_mm: 0.0,
        gap_probability: 0.0,
        ..SynthOptions::default()
    };
    let (joints, _) = centre_errors(&clip, &options, Some(EXACT));
    let mut moving = 0;
    for j in &joints {
        eprintln!(
            "{:<14} {:?} rms {:.3e} mm, off axis {:.3e} mm (bone {:.0} mm)",
            j.name, j.kind, j.rms_mm, j.rms_off_axis_mm, j.bone_mm
        );
        if j.kind != JointKind::NotMoving {
            moving += 1;
            assert!(
                j.rms_off_axis_mm <= 1e-6 * j.bone_mm.max(100.0),
                "{}",
                j.name
            );
        }
    }
    assert!(moving >= 6, "only {moving} moving joints");
}

#[test]
fn solved_cmu_clip_reproduces_joint_positions() {
    // Keep CI time low: 4 s of motion is plenty of samples for every joint.
    let Some((name, clip)) = walk_clip(480) else {
        return;
    };
    let options = SynthOptions::default(); // σ = 2 mm, 0.5 % gaps
    let (joints, rms_mm) = centre_errors(&clip, &options, None);
    for j in &joints {
        eprintln!(
            "{:<14} {:<10} rms {:.2} cm, off axis {:.2} cm",
            j.name,
            format!("{:?}", j.kind).split(' ').next().unwrap_or(""),
            j.rms_mm / 10.0,
            j.rms_off_axis_mm / 10.0
        );
    }
    eprintln!(
        "{}: RMS over all moving joints {:.3} cm at σ = 2 mm",
        name,
        rms_mm / 10.0
    );
    // Joints whose centre the markers determine: moving, with a moving (or root) parent whose
    // frame is not that of a short still bone, hinges measured off their axis (the slide along
    // a hinge axis is not observable, eq. 6).
    let observed: Vec<&JointError> = joints
        .iter()
        .filter(|j| j.kind != JointKind::NotMoving)
        .filter(|j| j.parent_kind != Some(JointKind::NotMoving))
        .collect();
    let rms_cm = (observed
        .iter()
        .map(|j| j.rms_off_axis_mm.powi(2))
        .sum::<f64>()
        / observed.len() as f64)
        .sqrt()
        / 10.0;
    let names: Vec<&str> = observed.iter().map(|j| j.name.as_str()).collect();
    eprintln!(
        "RMS over the {} observed joints {rms_cm:.3} cm: {names:?}",
        observed.len()
    );
    assert!(
        observed.len() >= 10,
        "only {} observed joints",
        observed.len()
    );
    assert!(rms_cm <= 1.0, "RMS {rms_cm} cm");
}

fn small_set() -> MarkerSet {
    let mut set = MarkerSet::new(vec!["A".into(), "B".into(), "C".into()], 5, 100.0);
    for f in 0..5 {
        for m in 0..3 {
            if (f + m) % 4 != 3 {
                set.set(
                    f,
                    m,
                    Some([f as f64 * 1.5 + 0.25, m as f64 - 7.5, 1000.0 + f as f64]),
                );
            }
        }
    }
    set
}

#[test]
fn csv_round_trips_with_gaps() {
    let set = small_set();
    let text = data::format_csv(&set);
    let back = data::parse_csv(&text, Path::new("x.csv"), &MarkerLimits::default()).unwrap();
    assert_eq!(back, set);
    assert!(set.gap_count() > 0);
}

#[test]
fn csv_round_trips_marker_names_with_commas_and_quotes() {
    // C3D labels are free text; the CSV writer quotes what needs it and the reader undoes it.
    let mut set = data::MarkerSet::new(
        vec!["L,ASIS".into(), "say \"hi\"".into(), "RKNE".into()],
        2,
        100.0,
    );
    set.set(0, 0, Some([1.0, 2.0, 3.0]));
    set.set(1, 1, Some([-4.5, 0.0, 1e-3]));
    set.set(1, 2, Some([7.0, 8.0, 9.0]));
    let text = data::format_csv(&set);
    assert!(text.contains("0,\"L,ASIS\",1,2,3\n"), "{text}");
    assert!(
        text.contains("1,\"say \"\"hi\"\"\",-4.5,0,0.001\n"),
        "{text}"
    );
    let back = data::parse_csv(&text, Path::new("x.csv"), &MarkerLimits::default()).unwrap();
    assert_eq!(back, set);
}

#[test]
fn c3d_round_trips_with_gaps() {
    let dir = std::env::temp_dir().join(format!("markers-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("small.c3d");
    let set = small_set();
    data::write_c3d(&set, &path, files::Mode::Replace).unwrap();
    let back = data::read_c3d(&path).unwrap();
    assert_eq!(back.names(), set.names());
    assert_eq!(back.frames(), set.frames());
    assert!((back.frame_rate_hz - 100.0).abs() < 1e-9);
    for f in 0..set.frames() {
        for m in 0..set.marker_count() {
            match (set.get(f, m), back.get(f, m)) {
                (Some(a), Some(b)) => assert!(dist(a, b) < 1e-3, "{a:?} {b:?}"),
                (None, None) => {}
                (a, b) => panic!("frame {f} marker {m}: {a:?} vs {b:?}"),
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn c3d_integer_storage_round_trips_within_half_a_step() {
    let dir = std::env::temp_dir().join(format!("markers-int-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("small.c3d");
    let set = small_set();
    write_c3d_with(&set, &path, C3dStorage::Integer, files::Mode::Replace).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // Header words 7-8: POINT:SCALE, positive for integer storage; the largest |coordinate|
    // (1004 mm) maps to at most 32 000 steps.
    let scale = f64::from(f32::from_le_bytes(bytes[12..16].try_into().unwrap()));
    assert!(
        scale > 0.0 && 1004.0 / scale <= 32_000.0 && 1004.0 / scale > 31_999.0,
        "{scale}"
    );
    // 8 bytes per point: 15 samples in one block after header and parameters.
    assert_eq!(bytes.len() % 512, 0);
    let back = data::read_c3d(&path).unwrap();
    assert_eq!(back.names(), set.names());
    for f in 0..set.frames() {
        for m in 0..set.marker_count() {
            match (set.get(f, m), back.get(f, m)) {
                (Some(a), Some(b)) => {
                    for k in 0..3 {
                        assert!((a[k] - b[k]).abs() <= scale * 0.5 + 1e-4, "{a:?} {b:?}");
                    }
                }
                (None, None) => {}
                (a, b) => panic!("frame {f} marker {m}: {a:?} vs {b:?}"),
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A file with analog samples between the frames and an `ANALOG` group that names none of
/// LABELS, SCALE, OFFSET, UNITS (py-c3d writes no UNITS, which `c3dio` insists on): the
/// points still read, exactly.
#[test]
fn c3d_points_read_past_analog_samples_and_an_incomplete_analog_group() {
    let set = small_set();
    let bytes = format_c3d(&set, C3dStorage::Float, Path::new("a.c3d")).unwrap();
    let word = |b: &[u8], i: usize| usize::from(u16::from_le_bytes([b[i], b[i + 1]]));
    let data_at = (word(&bytes, 16) - 1) * 512;
    let mut with_analog = bytes[..data_at].to_vec();
    // One channel at twice the point rate: 2 samples per frame in all (word 3), 2 per channel
    // (word 10), ANALOG:USED 1 (its value follows name, offset, type and dimension count).
    with_analog[4..6].copy_from_slice(&2u16.to_le_bytes());
    with_analog[18..20].copy_from_slice(&2u16.to_le_bytes());
    let find = |hay: &[u8], needle: &[u8]| hay.windows(needle.len()).position(|w| w == needle);
    let analog = find(&with_analog, b"ANALOG").unwrap();
    let used = analog + find(&with_analog[analog..], b"USED").unwrap();
    assert_eq!(word(&with_analog, used + 8), 0);
    with_analog[used + 8..used + 10].copy_from_slice(&1i16.to_le_bytes());
    let point_bytes = 16 * set.marker_count();
    for f in 0..set.frames() {
        let frame = data_at + f * point_bytes;
        with_analog.extend_from_slice(&bytes[frame..frame + point_bytes]);
        for k in 0..2 {
            with_analog.extend_from_slice(&(f as f32 * 10.0 + k as f32).to_le_bytes());
        }
    }
    with_analog.resize(with_analog.len().div_ceil(512) * 512, 0);
    let back = data::parse_c3d(&with_analog, Path::new("a.c3d"), &MarkerLimits::default()).unwrap();
    assert_eq!(back, set);
}

#[test]
fn c3d_writer_refuses_sets_c3d_cannot_hold() {
    let p = Path::new("out.c3d");
    let refused = |set: &MarkerSet, needle: &str| {
        let e = format_c3d(set, C3dStorage::Float, p).unwrap_err();
        assert!(matches!(e, MarkerError::C3d { .. }), "{e}");
        assert!(e.to_string().starts_with("out.c3d: C3D: "), "{e}");
        assert!(e.to_string().contains(needle), "{e}");
    };
    refused(&MarkerSet::new(Vec::new(), 3, 100.0), "1 to 32 767 markers");
    // 65 535 frames would be FRAMES = 0xFFFF, which ezc3d and py-c3d misread.
    refused(
        &MarkerSet::new(vec!["A".into()], 65_535, 100.0),
        "65 534 frames",
    );
    assert!(
        format_c3d(
            &MarkerSet::new(vec!["A".into()], 65_534, 100.0),
            C3dStorage::Float,
            p
        )
        .is_ok()
    );
    refused(&MarkerSet::new(vec!["A".into()], 3, 0.0), "frame rate");
    refused(&MarkerSet::new(vec!["A".into()], 3, f64::NAN), "frame rate");
    refused(&MarkerSet::new(vec!["A ".into()], 3, 100.0), "space");
    refused(&MarkerSet::new(vec!["Kn\u{e4}e".into()], 3, 100.0), "ASCII");
    refused(
        &MarkerSet::new(vec!["x".repeat(256)], 3, 100.0),
        "255 bytes",
    );
    // 2 000 labels of 80 characters: 160 kB, more than the 255-block parameter section.
    let long: Vec<String> = (0..2000).map(|i| format!("{i:080}")).collect();
    refused(
        &MarkerSet::new(long, 3, 100.0),
        "255 a C3D parameter section holds",
    );
    let mut huge = MarkerSet::new(vec!["A".into()], 1, 100.0);
    huge.set(0, 0, Some([1e39, 0.0, 0.0]));
    refused(&huge, "32-bit float range");
}

#[test]
fn malformed_files_give_clear_errors() {
    let lim = MarkerLimits::default();
    let p = Path::new("bad.csv");
    let e = data::parse_csv("frame,marker,x,y\n", p, &lim).unwrap_err();
    assert!(e.to_string().contains("bad.csv:1"), "{e}");
    let e = data::parse_csv("frame,marker,x,y,z\n0,A,1,2\n", p, &lim).unwrap_err();
    assert!(
        e.to_string().contains("bad.csv:2") && e.to_string().contains("5 fields"),
        "{e}"
    );
    let e = data::parse_csv("frame,marker,x,y,z\n0,A,1,2,3\n0,A,1,2,3\n", p, &lim).unwrap_err();
    assert!(
        e.to_string().contains(":3") && e.to_string().contains("twice"),
        "{e}"
    );
    let e = data::parse_csv("frame,marker,x,y,z\n0,A,1,nan,3\n", p, &lim).unwrap_err();
    assert!(e.to_string().contains("y \"nan\""), "{e}");
    let small = MarkerLimits {
        max_frames: 10,
        ..lim
    };
    let e = data::parse_csv("frame,marker,x,y,z\n99,A,1,2,3\n", p, &small).unwrap_err();
    assert!(matches!(e, MarkerError::Limit { .. }), "{e}");

    let e = data::parse_c3d(&[0u8; 100], Path::new("bad.c3d"), &lim).unwrap_err();
    assert!(e.to_string().contains("bad.c3d: C3D"), "{e}");
    // A header that claims 60 000 markers × 60 000 frames is refused before allocation.
    let mut bytes = vec![0u8; 2048];
    bytes[0] = 2;
    bytes[1] = 0x50;
    bytes[512 + 3] = 0x54;
    bytes[2..4].copy_from_slice(&60_000u16.to_le_bytes());
    bytes[6..8].copy_from_slice(&1u16.to_le_bytes());
    bytes[8..10].copy_from_slice(&60_000u16.to_le_bytes());
    bytes[16..18].copy_from_slice(&3u16.to_le_bytes());
    let e = data::parse_c3d(&bytes, Path::new("bomb.c3d"), &lim).unwrap_err();
    assert!(
        matches!(e, MarkerError::Limit { .. } | MarkerError::C3d { .. }),
        "{e}"
    );

    let s = Path::new("seg.toml");
    let e = parse_segments("[[segment]]\nname = \"a\"\nmarkers = [\"x\", \"y\"]\n", s).unwrap_err();
    assert!(
        e.to_string().contains("segment[0].markers") && e.to_string().contains("3 markers"),
        "{e}"
    );
    let text = "[[segment]]\nname = \"a\"\nmarkers = [\"x\", \"y\", \"z\"]\n\
                [[segment]]\nname = \"b\"\nparent = \"c\"\nmarkers = [\"w\"]\n";
    let e = parse_segments(text, s).unwrap_err();
    assert!(e.to_string().contains("segment[1].parent"), "{e}");
    let e = parse_segments("[[segment]]\nname = 3\n", s).unwrap_err();
    assert!(e.to_string().contains("segment[0].name"), "{e}");
    let e = parse_segments("segment = [", s).unwrap_err();
    assert!(e.to_string().starts_with("seg.toml: (file)"), "{e}");
    let text = "[[segment]]\nname = \"a\"\nmarkers = [\"x\", \"y\", \"z\"]\n\
                [[segment]]\nname = \"b\"\nparent = \"a\"\nmarkers = [\"x\"]\n";
    let e = parse_segments(text, s).unwrap_err();
    assert!(
        e.to_string().contains("segment[1].markers[0]") && e.to_string().contains("already"),
        "{e}"
    );
}

fn written_c3d() -> Vec<u8> {
    let dir = std::env::temp_dir().join(format!("markers-prop-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("p.c3d");
    data::write_c3d(&small_set(), &path, files::Mode::Replace).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn mutated_c3d_never_panics(pos in 0usize..4096, val in any::<u8>(), cut in 0usize..4096) {
        let mut bytes = written_c3d();
        let n = bytes.len();
        bytes[pos % n] = val;
        bytes.truncate(n - cut % n);
        match data::parse_c3d(&bytes, Path::new("m.c3d"), &MarkerLimits::default()) {
            // Whatever the header claims, what was allocated fits in the file.
            Ok(set) => prop_assert!(set.marker_count() * set.frames() * 8 <= bytes.len()),
            Err(e) => prop_assert!(e.to_string().starts_with("m.c3d")),
        }
    }

    #[test]
    fn mutated_csv_errors_name_a_line(pos in 0usize..400, ch in prop::sample::select(vec![',', 'x', '-', '\n', '9', ' ', '.'])) {
        let mut text: Vec<char> = data::format_csv(&small_set()).chars().collect();
        let n = text.len();
        text[pos % n] = ch;
        let text: String = text.into_iter().collect();
        let lines = text.lines().count();
        if let Err(e) = data::parse_csv(&text, Path::new("m.csv"), &MarkerLimits::default()) {
            match e {
                MarkerError::Csv { line, .. } => prop_assert!(line >= 1 && line <= lines),
                other => prop_assert!(false, "unexpected {other}"),
            }
        }
    }

    #[test]
    fn mutated_segment_files_error_with_key_paths(pos in 0usize..2000, ch in prop::sample::select(vec!['"', '[', ']', '=', 'x', '\n', ','])) {
        let base = segment_map_toml(&demo_clip());
        let mut text: Vec<char> = base.chars().collect();
        let n = text.len();
        text[pos % n] = ch;
        let text: String = text.into_iter().collect();
        if let Err(e) = parse_segments(&text, Path::new("m.toml")) {
            match e {
                MarkerError::Segments { key, reason, .. } => {
                    prop_assert!(!key.is_empty() && !reason.is_empty());
                }
                other => prop_assert!(false, "unexpected {other}"),
            }
        }
    }
}

#[test]
fn solved_clip_survives_a_bvh_round_trip() {
    let clip = demo_clip();
    let cap = synth_capture(&clip, &SynthOptions::default()).unwrap();
    let map = parse_segments(&segment_map_toml(&clip), Path::new("s.toml")).unwrap();
    let solved = segments::solve(&cap.markers, &map).unwrap();
    assert_survives_a_bvh_round_trip(&solved.clip, "markers-bvh");
}

#[test]
fn one_and_two_marker_segments_use_section_2_5_frames() {
    // Section 2.5 cases 1 and 2 on noise-free markers: the thigh keeps two of its markers
    // (frame from two markers and the hip centre), the shank one (frame from the marker, the
    // knee centre and the hinge axis). The ankle below then still finds its centre.
    let clip = demo_clip();
    let options = SynthOptions {
        noise_mm: 0.0,
        gap_probability: 0.0,
        ..SynthOptions::default()
    };
    let cap = synth_capture(&clip, &options).unwrap();
    let mut map = parse_segments(&segment_map_toml(&clip), Path::new("s.toml")).unwrap();
    map.gdke = EXACT;
    let femur = map
        .segments
        .iter()
        .position(|s| s.name == "lfemur")
        .unwrap();
    let tibia = map
        .segments
        .iter()
        .position(|s| s.name == "ltibia")
        .unwrap();
    map.segments[femur].markers.truncate(2);
    map.segments[tibia].markers.truncate(1);
    let solved = segments::solve(&cap.markers, &map).unwrap();
    assert!(matches!(solved.joints[tibia].kind, JointKind::Hinge { .. }));
    let pos = motion::fk::positions(&solved.clip);
    let foot = map.segments.iter().position(|s| s.name == "lfoot").unwrap();
    for s in [femur, tibia, foot] {
        let tp = cap.segments[s].truth_point.unwrap();
        let j = solved.joint_of_segment[s];
        if s == tibia {
            continue; // a hinge centre slides along its axis; checked through the foot below
        }
        for f in 0..pos.frames() {
            let e = dist(pos.point(f, j), cap.truth_mm[f][tp]);
            assert!(
                e < 1e-3 * 400.0,
                "{}: frame {f}: {e} mm",
                map.segments[s].name
            );
        }
    }
    // A one-marker segment on a ball joint is refused with a clear error.
    let hip_one = {
        let mut m = map.clone();
        m.segments[tibia].markers = vec!["ltibia_1".into(), "ltibia_2".into()];
        m.segments[femur].markers.truncate(1);
        m.segments[femur].kind = markers::gdke::KindHint::Spherical;
        m
    };
    let e = segments::solve(&cap.markers, &hip_one).unwrap_err();
    assert!(
        e.to_string().contains("lfemur") && e.to_string().contains("hinge"),
        "{e}"
    );
}
