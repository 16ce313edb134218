//! Real clips: parsing, round trips, conversion and a lab's plausibility check of FK.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::PathBuf;

use motion::BodyPart::{Head, LeftArm, LeftLeg, RightArm, RightLeg, Torso};
use motion::data::shared_clips;
use motion::pairing::ClipSource;
use motion::{Clip, SkeletonFormat, asf, bvh, convert, fk, io};

fn clips() -> Vec<ClipSource> {
    let c = shared_clips();
    if std::env::var_os("CI").is_some() {
        assert!(
            c.len() >= 5,
            "expected the 5 shared clips, found {}",
            c.len()
        );
    }
    c
}

fn load(c: &ClipSource) -> Clip {
    io::read_clip(c.asf.as_deref(), &c.motion).unwrap_or_else(|e| panic!("{e}"))
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("codecs-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn every_shared_clip_parses_with_the_documented_shape() {
    for c in clips() {
        let clip = load(&c);
        match clip.skeleton.format {
            SkeletonFormat::Asf => {
                assert_eq!(clip.skeleton.joints.len(), 31, "{}", c.name);
                assert_eq!(clip.channel_count(), 62, "{}", c.name);
                assert!((clip.frame_rate_hz - 120.0).abs() < 1e-12);
                assert!((clip.skeleton.units.cm_per_unit - 2.54 / 0.45).abs() < 1e-12);
            }
            SkeletonFormat::Bvh => {
                assert_eq!(clip.channel_count(), 96, "{}", c.name);
                assert!((clip.frame_rate_hz - 1.0 / 0.008_333_3).abs() < 1e-9);
                // CMU's BVH keeps the ASF unit; the inference must find it.
                assert!((clip.skeleton.units.cm_per_unit - 2.54 / 0.45).abs() < 1e-12);
            }
        }
        let expected = match c.name.as_str() {
            "02_01" => 343,
            "charleston1" => 506,
            "lambada" => 2180,
            "pirouette" => 591,
            "131_01" => 994,
            _ => clip.frames(),
        };
        assert_eq!(clip.frames(), expected, "{}", c.name);
        assert!(clip.data().iter().all(|v| v.is_finite()));
    }
}

fn assert_same_values(a: &Clip, b: &Clip, what: &str) {
    assert_eq!(a.frames(), b.frames(), "{what}");
    assert_eq!(a.channel_count(), b.channel_count(), "{what}");
    for (i, (x, y)) in a.data().iter().zip(b.data()).enumerate() {
        assert_eq!(x.to_bits(), y.to_bits(), "{what}: value {i}: {x} vs {y}");
    }
}

#[test]
fn writers_round_trip_every_value_bit_for_bit() {
    for c in clips() {
        let clip = load(&c);
        match clip.skeleton.format {
            SkeletonFormat::Asf => {
                let (a, m) = (
                    tmp(&format!("{}.asf", c.name)),
                    tmp(&format!("{}.amc", c.name)),
                );
                io::write_clip(&clip, &m, Some(&a), files::Mode::Replace).unwrap();
                let back = io::read_clip(Some(&a), &m).unwrap();
                assert_eq!(back.skeleton, clip.skeleton, "{}", c.name);
                assert_same_values(&clip, &back, &c.name);
                // Twice: the writer's output is a fixed point.
                let text1 = std::fs::read_to_string(&m).unwrap();
                io::write_clip(&back, &m, Some(&a), files::Mode::Replace).unwrap();
                assert_eq!(text1, std::fs::read_to_string(&m).unwrap());
            }
            SkeletonFormat::Bvh => {
                let b = tmp(&format!("{}.bvh", c.name));
                io::write_clip(&clip, &b, None, files::Mode::Replace).unwrap();
                let back = io::read_clip(None, &b).unwrap();
                assert_eq!(back.skeleton, clip.skeleton, "{}", c.name);
                assert_same_values(&clip, &back, &c.name);
                assert!((back.frame_rate_hz - clip.frame_rate_hz).abs() < 1e-9);
            }
        }
    }
}

#[test]
fn asf_to_bvh_conversion_keeps_every_joint_position() {
    for c in clips().into_iter().filter(|c| c.asf.is_some()) {
        let clip = load(&c);
        let conv = convert::asf_to_bvh(&clip).unwrap();
        // Through a file, as a user would do it.
        let path = tmp(&format!("{}-conv.bvh", c.name));
        io::write_clip(&clip, &path, None, files::Mode::Replace).unwrap();
        let read = bvh::read_bvh(&path).unwrap();
        assert_eq!(read.skeleton.joints.len(), conv.skeleton.joints.len());
        let pa = fk::positions(&clip);
        let pb = fk::positions(&read);
        let mut worst: f64 = 0.0;
        for (ai, name) in pa.names.iter().enumerate() {
            // ASF point of bone j (its end) = BVH point of j's first child or end site.
            let bj = read.skeleton.joint_index(name).unwrap();
            let bi = if ai == 0 {
                bj
            } else {
                read.skeleton.children(bj).next().unwrap()
            };
            for f in 0..pa.frames() {
                let (p, q) = (pa.point(f, ai), pb.point(f, bi));
                for k in 0..3 {
                    worst = worst.max((p[k] - q[k]).abs());
                }
            }
        }
        assert!(
            worst < 1e-6,
            "{}: conversion moved a joint by {worst} units",
            c.name
        );
    }
}

/// A lab's check of the FK conventions: while a foot is planted its toe must not slide.
/// On the dance clips (matching skeletons) the lowest toe's horizontal speed over frames where
/// it is within 1 unit (5.6 cm) of the clip's floor is a few units/s at most; a wrong rotation
/// order or a missing `C·M·Cᵀ` makes it tens of units/s.
#[test]
fn planted_toes_do_not_slide() {
    for c in clips()
        .into_iter()
        .filter(|c| c.asf.is_some() && c.name != "02_01")
    {
        let clip = load(&c);
        let speed = planted_toe_speed(&clip);
        eprintln!("{}: median planted toe speed {speed:.2} units/s", c.name);
        assert!(
            speed < 4.0,
            "{}: median planted toe speed {speed} units/s",
            c.name
        );
    }
}

fn planted_toe_speed(clip: &Clip) -> f64 {
    let p = fk::positions(clip);
    let toes: Vec<usize> = ["ltoes", "rtoes"]
        .iter()
        .filter_map(|n| clip.skeleton.joint_index(n))
        .collect();
    let floor = (0..p.frames())
        .flat_map(|f| toes.iter().map(move |&t| (f, t)))
        .map(|(f, t)| p.point(f, t)[1])
        .fold(f64::INFINITY, f64::min);
    let mut speeds = Vec::new();
    for f in 1..p.frames() {
        let t = *toes
            .iter()
            .min_by(|&&a, &&b| p.point(f, a)[1].total_cmp(&p.point(f, b)[1]))
            .unwrap();
        let (a, b) = (p.point(f - 1, t), p.point(f, t));
        if b[1] - floor < 1.0 {
            let d = ((b[0] - a[0]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
            speeds.push(d * clip.frame_rate_hz);
        }
    }
    assert!(speeds.len() > 20, "too few contact frames");
    speeds.sort_by(f64::total_cmp);
    speeds[speeds.len() / 2]
}

#[test]
fn asf_body_parts_and_chain_depths_match_the_cmu_names() {
    for c in clips().into_iter().filter(|c| c.asf.is_some()).take(1) {
        let sk = asf::read_asf(c.asf.as_deref().unwrap()).unwrap();
        let part = |n: &str| sk.joints[sk.joint_index(n).unwrap()].body_part;
        let depth = |n: &str| sk.joints[sk.joint_index(n).unwrap()].chain_depth;
        assert_eq!(part("ltoes"), LeftLeg);
        assert_eq!(part("rfemur"), RightLeg);
        assert_eq!(part("lowerback"), Torso);
        assert_eq!(part("lowerneck"), Head);
        assert_eq!(part("lthumb"), LeftArm);
        assert_eq!(part("rclavicle"), RightArm);
        assert_eq!(depth("lhipjoint"), 0);
        assert_eq!(depth("ltoes"), 4);
        assert_eq!(depth("thorax"), 3);
        assert_eq!(depth("head"), 2);
        assert_eq!(sk.chain_height(LeftLeg), Some(4));
    }
}

#[test]
fn bvh_body_parts_by_name_agree_with_topology() {
    for c in clips().into_iter().filter(|c| c.asf.is_none()) {
        let clip = load(&c);
        let sk = &clip.skeleton;
        let by_name: Vec<_> = sk.joints.iter().map(|j| j.body_part).collect();
        // Rename every joint so that names say nothing, forcing the topology fallback.
        let mut anon = sk.clone();
        for (i, j) in anon.joints.iter_mut().enumerate() {
            j.name = format!("j{i}");
        }
        motion::bodymap::assign(&mut anon);
        let by_topo: Vec<_> = anon.joints.iter().map(|j| j.body_part).collect();
        let agree = by_name.iter().zip(&by_topo).filter(|(a, b)| a == b).count();
        assert_eq!(
            agree,
            by_name.len(),
            "{}: {by_name:?} vs {by_topo:?}",
            c.name
        );
        let hips = sk.joint_index("Hips").unwrap();
        assert_eq!(sk.joints[hips].body_part, motion::BodyPart::Torso);
        let toe = sk.joint_index("LeftToe").unwrap();
        assert_eq!(sk.joints[toe].body_part, motion::BodyPart::LeftLeg);
    }
}

#[test]
fn synthetic_walk_is_a_valid_clip_that_walks_forward() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    assert_eq!(clip.frames(), 480);
    let p = fk::positions(&clip);
    let z0 = p.point(0, 0)[2];
    let z1 = p.point(p.frames() - 1, 0)[2];
    let metres = (z1 - z0) * clip.skeleton.units.cm_per_unit / 100.0;
    assert!((metres - 4.0 * 1.2).abs() < 0.1, "walked {metres} m");
    // Feet stay below the hips and above a floor near zero.
    let ltoe = clip.skeleton.joint_index("ltoes").unwrap();
    for f in 0..p.frames() {
        assert!(p.point(f, ltoe)[1] < p.point(f, 0)[1]);
    }
    // Round trip through files, like a real clip.
    let (a, m) = (tmp("walk.asf"), tmp("walk.amc"));
    io::write_clip(&clip, &m, Some(&a), files::Mode::Replace).unwrap();
    let back = io::read_clip(Some(&a), &m).unwrap();
    assert_same_values(&clip, &back, "walk");
}

#[test]
fn excerpt_keeps_the_frames_asked_for_and_cuts_at_the_end() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let n = clip.frames();
    let part = clip.excerpt(100..130);
    assert_eq!(part.frames(), 30);
    assert_eq!(part.skeleton, clip.skeleton);
    assert_eq!(part.frame_rate_hz.to_bits(), clip.frame_rate_hz.to_bits());
    for c in 0..clip.channel_count() {
        assert_eq!(part.channel(c), &clip.channel(c)[100..130], "channel {c}");
    }
    let tail = clip.excerpt(n - 5..n + 50);
    assert_eq!(tail.frames(), 5);
    assert_eq!(tail.value(3, 4).to_bits(), clip.value(3, n - 1).to_bits());
    assert_eq!(clip.excerpt(n + 1..n + 9).frames(), 0);
    assert_eq!(clip.excerpt(0..n), clip);
}

/// Thesis ch. 5 works on quaternions: Euler → quaternion → Euler must keep every joint where
/// it was (≤ 1e-6 of the skeleton's scale), including across Euler wraps.
#[test]
fn quaternion_round_trip_keeps_every_joint_position() {
    let mut all = clips().into_iter().map(|c| load(&c)).collect::<Vec<_>>();
    all.push(motion::synth::walking_clip(
        &motion::synth::WalkParams::default(),
    ));
    for clip in all {
        let back = motion::quat::from_quaternions(&motion::quat::to_quaternions(&clip));
        let (a, b) = (fk::positions(&clip), fk::positions(&back));
        let scale = clip
            .skeleton
            .joints
            .iter()
            .map(|j| j.rest.length())
            .fold(0.0, f64::max);
        let mut worst: f64 = 0.0;
        for f in 0..a.frames() {
            for j in 0..a.joint_count() {
                let (p, q) = (a.point(f, j), b.point(f, j));
                for k in 0..3 {
                    worst = worst.max((p[k] - q[k]).abs());
                }
            }
        }
        assert!(
            worst <= 1e-6 * scale,
            "{}: moved by {worst}",
            clip.skeleton.name
        );
        // Unwrapping keeps channels continuous: no new jumps over 180 degrees.
        for c in 0..clip.channel_count() {
            let jumps = |x: &Clip| {
                x.channel(c)
                    .windows(2)
                    .filter(|w| (w[1] - w[0]).abs() > 180.0)
                    .count()
            };
            assert!(jumps(&back) <= jumps(&clip), "{}", clip.channel_name(c));
        }
    }
}
