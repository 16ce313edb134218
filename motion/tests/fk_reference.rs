//! Forward kinematics against an independent implementation (scripts/reference/fk_reference.py,
//! standard-library Python written separately from the Rust code), on every shared clip and on
//! the generated walk: every joint of every frame within 1e-4 file units.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::Command;

use motion::{Clip, fk, io};

fn reference(args: &[&Path]) -> Vec<(usize, String, [f64; 3])> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/reference/fk_reference.py");
    let out = Command::new("python3")
        .arg(&script)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!("python3 is needed for the FK reference (scripts/test installs it): {e}")
        });
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[0].parse().unwrap(),
                f[1].to_string(),
                [
                    f[2].parse().unwrap(),
                    f[3].parse().unwrap(),
                    f[4].parse().unwrap(),
                ],
            )
        })
        .collect()
}

fn compare(clip: &Clip, args: &[&Path], what: &str) {
    let ours = fk::positions(clip);
    let theirs = reference(args);
    assert_eq!(
        theirs.len(),
        ours.frames() * ours.joint_count(),
        "{what}: point count"
    );
    let mut worst: f64 = 0.0;
    for (k, (f, name, p)) in theirs.iter().enumerate() {
        let j = k % ours.joint_count();
        assert_eq!(*f, k / ours.joint_count(), "{what}");
        assert_eq!(name, &ours.names[j], "{what}: joint order");
        let q = ours.point(*f, j);
        for a in 0..3 {
            worst = worst.max((p[a] - q[a]).abs());
        }
    }
    assert!(
        worst <= 1e-4,
        "{what}: FK differs from the reference by {worst} units"
    );
}

#[test]
fn fk_matches_the_independent_reference_on_every_shared_clip() {
    let clips = motion::data::shared_clips();
    for c in &clips {
        let clip = io::read_clip(c.asf.as_deref(), &c.motion).unwrap();
        let args: Vec<&Path> = c
            .asf
            .iter()
            .map(PathBuf::as_path)
            .chain([c.motion.as_path()])
            .collect();
        compare(&clip, &args, &c.name);
    }
}

#[test]
fn fk_matches_the_independent_reference_on_generated_and_converted_motion() {
    let dir = std::env::temp_dir().join(format!("fkref-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let walk = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 1.0,
        amplitude: 2.5,
        ..Default::default()
    });
    let (a, m, b) = (dir.join("w.asf"), dir.join("w.amc"), dir.join("w.bvh"));
    io::write_clip(&walk, &m, Some(&a), files::Mode::Replace).unwrap();
    compare(&walk, &[&a, &m], "walk (ASF/AMC)");
    io::write_clip(&walk, &b, None, files::Mode::Replace).unwrap();
    let conv = io::read_clip(None, &b).unwrap();
    compare(&conv, &[&b], "walk converted to BVH");
}
