//! Helpers shared by the marker test files.
#![allow(dead_code, reason = "each test file uses its own part")]

/// Euclidean distance between two points.
pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Writes `clip` as BVH (under the temp folder, in a directory named after `tag`), reads it
/// back and asserts that every joint of every frame lands within 1e-3 units of where it was.
pub fn assert_survives_a_bvh_round_trip(clip: &motion::Clip, tag: &str) {
    let dir = std::env::temp_dir().join(format!("{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("solved.bvh");
    motion::io::write_clip(clip, &path, None, files::Mode::Replace).unwrap();
    let back = motion::io::read_clip(None, &path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let (a, b) = (motion::fk::positions(clip), motion::fk::positions(&back));
    assert_eq!(a.names, b.names);
    for f in 0..a.frames() {
        for j in 0..a.joint_count() {
            assert!(
                dist(a.point(f, j), b.point(f, j)) < 1e-3,
                "frame {f} joint {j}"
            );
        }
    }
}

/// The first `frames` frames of CMU 02_01 (a walk), or of the first shared clip where a
/// `MOCAP_DATA` folder lacks it, with the clip's name; `None` outside CI without the data
/// (under `CI` a missing folder fails the test).
pub fn walk_clip(frames: usize) -> Option<(String, motion::Clip)> {
    let clips = motion::data::shared_clips();
    let Some(files) = clips.iter().find(|c| c.name == "02_01").or(clips.first()) else {
        eprintln!("shared clips not found: skipped outside CI");
        return None;
    };
    let clip = motion::io::read_clip(files.asf.as_deref(), &files.motion).unwrap();
    Some((files.name.clone(), clip.excerpt(0..frames)))
}
