//! Issue 9: a skeleton solved from markers written as ASF/AMC reproduces the BVH it was solved
//! as, through the files and the project's own forward kinematics.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::{Path, PathBuf};

use common::{dist, walk_clip};
use markers::acclaim::{AsfSolved, bvh_to_asf};
use markers::segments::{self, parse_segments};
use markers::synth::{SynthOptions, segment_map_toml, synth_capture};
use motion::{Clip, Rest, SkeletonFormat};

fn tmp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("markers-asf-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn solve(clip: &Clip, options: &SynthOptions) -> Clip {
    let cap = synth_capture(clip, options).unwrap();
    let map = parse_segments(&segment_map_toml(clip), Path::new("synth.toml")).unwrap();
    segments::solve(&cap.markers, &map).unwrap().clip
}

/// Writes the solved clip as BVH and as ASF/AMC, reads both back and returns the largest FK
/// disagreement relative to the length of the bone ending at the point, and in mm.
fn round_trip(bvh: &Clip, tag: &str) -> (f64, f64) {
    let dir = tmp(tag);
    let (bvh_path, asf_path, amc_path) = (
        dir.join("solved.bvh"),
        dir.join("solved.asf"),
        dir.join("solved.amc"),
    );
    let AsfSolved { clip, asf_point_of } = bvh_to_asf(bvh).unwrap();
    motion::io::write_clip(bvh, &bvh_path, None, files::Mode::Replace).unwrap();
    motion::io::write_clip(&clip, &amc_path, Some(&asf_path), files::Mode::Replace).unwrap();
    let bvh_back = motion::io::read_clip(None, &bvh_path).unwrap();
    let asf_back = motion::io::read_clip(Some(&asf_path), &amc_path).unwrap();
    std::fs::remove_dir_all(&dir).ok();

    // A valid ASF skeleton: root first, bones with unit direction, length, axis and dofs.
    let sk = &asf_back.skeleton;
    assert_eq!(sk.format, SkeletonFormat::Asf);
    assert_eq!(sk.joints[0].name, "root");
    assert_eq!(sk.joints[0].dofs.len(), 6);
    let names =
        |c: &Clip| -> Vec<String> { c.skeleton.joints.iter().map(|j| j.name.clone()).collect() };
    assert_eq!(
        names(&asf_back),
        names(&clip),
        "the ASF reader kept the bone order"
    );
    for j in &sk.joints[1..] {
        let Rest::Bone { direction, length } = j.rest else {
            panic!("{} is not a bone", j.name);
        };
        assert!(length >= 0.0);
        assert!(
            (dist(direction, [0.0; 3]) - 1.0).abs() < 1e-12,
            "{}",
            j.name
        );
        assert!(j.dofs.len() == 3 || j.dofs.is_empty(), "{}", j.name);
    }
    assert_eq!(asf_back.frames(), bvh.frames());
    assert_eq!(asf_back.channel_count(), clip.channel_count());

    let (a, b) = (
        motion::fk::positions(&bvh_back),
        motion::fk::positions(&asf_back),
    );
    assert_eq!(a.joint_count(), bvh.skeleton.joints.len());
    let (mut worst_rel, mut worst_mm) = (0.0f64, 0.0f64);
    for f in 0..a.frames() {
        for (j, joint) in bvh.skeleton.joints.iter().enumerate() {
            let e = dist(a.point(f, j), b.point(f, asf_point_of[j]));
            worst_mm = worst_mm.max(e);
            if joint.parent.is_some() {
                let bone = joint.rest.length();
                assert!(
                    e <= 1e-6 * bone,
                    "frame {f} {}: {e:e} mm off, bone {bone} mm",
                    joint.name
                );
                worst_rel = worst_rel.max(e / bone);
            } else {
                // The root point is the root translation in both files, read as written.
                assert!(e <= 1e-9, "frame {f} root: {e:e} mm");
            }
        }
    }
    (worst_rel, worst_mm)
}

#[test]
fn solved_demo_walk_as_asf_amc_matches_its_bvh() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let (rel, mm) = round_trip(&solve(&clip, &SynthOptions::default()), "demo");
    eprintln!("demo walk: worst FK disagreement {rel:.2e} of bone length, {mm:.2e} mm");
}

#[test]
fn solved_cmu_clip_as_asf_amc_matches_its_bvh() {
    // 2 s of the walk: every joint moves, and the test stays quick.
    let Some((name, clip)) = walk_clip(240) else {
        return;
    };
    let solved = solve(&clip, &SynthOptions::default());
    let (rel, mm) = round_trip(&solved, &name);
    eprintln!("{name}: worst FK disagreement {rel:.2e} of bone length, {mm:.2e} mm");
}

#[test]
fn asf_conversion_keeps_branches_and_end_sites() {
    // A BVH joint with two children and the root's children each need a bone without dofs
    // (a link) so that every BVH point stays an ASF point.
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let solved = solve(&clip, &SynthOptions::default());
    let asf = bvh_to_asf(&solved).unwrap();
    let sk = &asf.clip.skeleton;
    let bvh = &solved.skeleton;
    for (j, joint) in bvh.joints.iter().enumerate() {
        let p = asf.asf_point_of[j];
        if joint.end_site {
            // An end site is the end of its joint's bone.
            let parent = &bvh.joints[joint.parent.unwrap()].name;
            assert_eq!(&sk.joints[p].name, parent);
        }
    }
    let links = sk
        .joints
        .iter()
        .filter(|j| j.name.ends_with("_link"))
        .count();
    let branches: usize = bvh
        .joints
        .iter()
        .enumerate()
        .map(|(i, _)| {
            let kids = bvh.children(i).count();
            if i == 0 { kids } else { kids.saturating_sub(1) }
        })
        .sum();
    assert!(links > 0);
    assert!(links <= branches, "{links} links for {branches} branches");
    for l in sk.joints.iter().filter(|j| j.name.ends_with("_link")) {
        assert!(l.dofs.is_empty(), "{} carries dofs", l.name);
    }
    // An ASF clip is refused: the conversion reads BVH channels.
    let e = bvh_to_asf(&clip).unwrap_err();
    assert!(e.to_string().contains("expects a BVH clip"), "{e}");
}
