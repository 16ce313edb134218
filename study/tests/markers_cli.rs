//! `study markers ...` end to end, as a user runs it (issue 9): a solve written as ASF/AMC
//! agrees with the same solve written as BVH, and malformed C3D input ends in exactly one
//! `error:` line, with no panic message from the C3D parser.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use markers::data::{self, MarkerSet};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) {
    let out = study(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn tmp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("study-markers-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Synthesises markers from `clip_args`, solves them to BVH and to ASF/AMC through the CLI,
/// reads both back and checks every BVH point against its ASF point over all frames.
fn solve_both_ways(tag: &str, clip_args: &[&str]) {
    let dir = tmp(tag);
    let (c3d, seg) = (dir.join("m.c3d"), dir.join("s.toml"));
    let (bvh, asf, amc) = (dir.join("o.bvh"), dir.join("o.asf"), dir.join("o.amc"));
    let mut synth = vec!["markers", "synth"];
    synth.extend_from_slice(clip_args);
    synth.extend_from_slice(&["-o", s(&c3d), "--segments-out", s(&seg)]);
    ok(&synth);
    let solve = |out: &[&str]| {
        let mut a = vec!["markers", "solve", s(&c3d), "--segments", s(&seg)];
        a.extend_from_slice(out);
        ok(&a);
    };
    solve(&["-o", s(&bvh)]);
    solve(&["-o", s(&amc), "--out-asf", s(&asf)]);
    let bvh_back = motion::io::read_clip(None, &bvh).unwrap();
    let asf_back = motion::io::read_clip(Some(&asf), &amc).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    // The point map depends only on the skeleton's structure; the ASF read back must have
    // the bones the conversion of the BVH read back names, in the same order.
    let map = markers::acclaim::bvh_to_asf(&bvh_back).unwrap();
    let names = |c: &motion::Clip| -> Vec<String> {
        c.skeleton.joints.iter().map(|j| j.name.clone()).collect()
    };
    assert_eq!(names(&asf_back), names(&map.clip));
    let (a, b) = (
        motion::fk::positions(&bvh_back),
        motion::fk::positions(&asf_back),
    );
    assert_eq!(a.frames(), b.frames());
    let mut worst = 0.0f64;
    for f in 0..a.frames() {
        for (j, joint) in bvh_back.skeleton.joints.iter().enumerate() {
            let e = dist(a.point(f, j), b.point(f, map.asf_point_of[j]));
            let bone = joint.rest.length();
            if joint.parent.is_some() {
                assert!(e <= 1e-6 * bone, "frame {f} {}: {e:e} mm", joint.name);
                worst = worst.max(e / bone);
            } else {
                assert!(e <= 1e-9, "frame {f} root: {e:e} mm");
            }
        }
    }
    eprintln!("{tag}: worst disagreement {worst:.2e} of bone length");
}

#[test]
fn solve_as_asf_amc_matches_solve_as_bvh() {
    solve_both_ways("demo", &["--demo"]);
    if let Some(dir) = motion::data::mocap_dir() {
        let (asf, amc) = (dir.join("12.asf"), dir.join("02_01.amc"));
        solve_both_ways("cmu", &["--asf", s(&asf), "--amc", s(&amc)]);
    } else {
        eprintln!("shared clips not found: CMU part skipped outside CI");
    }
}

#[test]
fn solve_output_arguments_are_checked() {
    let dir = tmp("args");
    let (c3d, seg) = (dir.join("m.c3d"), dir.join("s.toml"));
    ok(&[
        "markers",
        "synth",
        "--demo",
        "-o",
        s(&c3d),
        "--segments-out",
        s(&seg),
    ]);
    let run = |out: &[&str]| {
        let mut a = vec!["markers", "solve", s(&c3d), "--segments", s(&seg)];
        a.extend_from_slice(out);
        let o = study(&a);
        assert!(!o.status.success(), "{out:?}");
        String::from_utf8(o.stderr).unwrap()
    };
    let amc = dir.join("o.amc");
    assert!(run(&["-o", s(&amc)]).contains("needs --out-asf"));
    let bvh = dir.join("o.bvh");
    assert!(run(&["-o", s(&bvh), "--out-asf", s(&dir.join("o.asf"))]).contains("own skeleton"));
    assert!(run(&["-o", s(&amc), "--out-asf", s(&dir.join("o.txt"))]).contains(".asf"));
    assert!(run(&["-o", s(&dir.join("o.csv"))]).contains(".bvh or .amc"));
    assert!(!amc.exists() && !bvh.exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// SplitMix64: the mutations below are reproducible from the seed printed on failure.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn small_c3d(dir: &Path) -> Vec<u8> {
    let mut set = MarkerSet::new(vec!["A".into(), "B".into(), "C".into()], 5, 100.0);
    for f in 0..5 {
        for m in 0..3 {
            if (f + m) % 4 != 3 {
                set.set(f, m, Some([f as f64 * 1.5 + 0.25, m as f64 - 7.5, 1000.0]));
            }
        }
    }
    let path = dir.join("base.c3d");
    data::write_c3d(&set, &path, files::Mode::Replace).unwrap();
    std::fs::read(&path).unwrap()
}

/// Runs `solve` on mutated bytes; returns whether the C3D parser panicked (as the error
/// says), after checking that stderr is exactly one `error:` line.
fn solve_mutated(dir: &Path, bytes: &[u8], what: &str) -> bool {
    let c3d = dir.join("m.c3d");
    std::fs::write(&c3d, bytes).unwrap();
    // Marker Z is in no file: a C3D that still parses ends at the segment check, so every
    // run ends in exactly one error.
    let seg = dir.join("s.toml");
    let out = dir.join("o.bvh");
    let o = study(&[
        "markers",
        "solve",
        s(&c3d),
        "--segments",
        s(&seg),
        "-o",
        s(&out),
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert!(!o.status.success(), "{what}: succeeded");
    assert!(
        lines.len() == 1 && lines[0].starts_with("error: "),
        "{what}: stderr is not one error line:\n{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{what}:\n{stderr}");
    assert!(
        lines[0].contains("m.c3d"),
        "{what}: names no file:\n{stderr}"
    );
    lines[0].contains("the parser stopped")
}

#[test]
fn malformed_c3d_prints_one_error_line_and_no_panic_message() {
    let dir = tmp("c3d");
    let base = small_c3d(&dir);
    std::fs::write(
        dir.join("s.toml"),
        "[[segment]]\nname = \"root\"\nmarkers = [\"A\", \"B\", \"Z\"]\n",
    )
    .unwrap();
    // Every parameter-section byte set to 0x80 (a negative signed count or length there is
    // where c3dio indexes past its input), then random multi-byte mutations and cuts.
    let mut panicked = 0;
    for pos in (512..1024.min(base.len())).step_by(2) {
        let mut b = base.clone();
        b[pos] = 0x80;
        panicked += usize::from(solve_mutated(&dir, &b, &format!("byte {pos} = 0x80")));
    }
    let seed = 0x00C3_D5EE_D009;
    let mut rng = SplitMix(seed);
    for case in 0..64 {
        let mut b = base.clone();
        let n = b.len();
        for _ in 0..=rng.below(3) {
            let pos = 512 + rng.below(n - 512);
            b[pos] = (rng.next() & 0xFF) as u8;
        }
        if rng.below(4) == 0 {
            b.truncate(n - rng.below(n / 2));
        }
        let what = format!("seed {seed:#x} case {case}");
        panicked += usize::from(solve_mutated(&dir, &b, &what));
    }
    std::fs::remove_dir_all(&dir).ok();
    eprintln!("{panicked} of the mutated files made the C3D parser panic");
    // Without at least a few parser panics this test would not test the hook at all.
    assert!(panicked >= 10, "only {panicked} parser panics");
}

/// `markers synth --demo` into `dir` with a range-of-motion trial (0.5 s per axis): the
/// motion trial, the calibration trial, the segment map and what the command printed.
fn synth_with_calibration(dir: &Path) -> (PathBuf, PathBuf, PathBuf, String) {
    let (c3d, rom, seg) = (dir.join("m.c3d"), dir.join("rom.c3d"), dir.join("s.toml"));
    let out = study(&[
        "markers",
        "synth",
        "--demo",
        "-o",
        s(&c3d),
        "--segments-out",
        s(&seg),
        "--calibration-out",
        s(&rom),
        "--rom-seconds-per-axis",
        "0.5",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    (c3d, rom, seg, stderr)
}

/// `synth --calibration-out` writes a range-of-motion trial with the motion trial's markers;
/// `solve --calibration` solves the motion trial with the centres estimated on it, exactly as
/// the library does, and differently from a solve of the motion trial alone.
#[test]
fn solve_with_a_calibration_trial() {
    let dir = tmp("cal");
    let (c3d, rom, seg, stderr) = synth_with_calibration(&dir);
    assert!(stderr.contains("range-of-motion trial"), "{stderr}");
    let (cal_bvh, plain_bvh) = (dir.join("cal.bvh"), dir.join("plain.bvh"));
    let solve = |out: &Path, extra: &[&str]| {
        let mut a = vec![
            "markers",
            "solve",
            s(&c3d),
            "--segments",
            s(&seg),
            "-o",
            s(out),
        ];
        a.extend_from_slice(extra);
        let o = study(&a);
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{stderr}");
        stderr
    };
    let stderr = solve(&cal_bvh, &["--calibration", s(&rom)]);
    assert!(stderr.contains("calibrated on"), "{stderr}");
    solve(&plain_bvh, &[]);
    // The library on the files the CLI wrote.
    let motion = data::read_markers(&c3d).unwrap();
    let rom_set = data::read_markers(&rom).unwrap();
    assert_eq!(motion.names(), rom_set.names());
    assert!(rom_set.frames() > motion.frames());
    let map = markers::segments::read_segments(&seg).unwrap();
    let cal = markers::calibration::Calibration::estimate(&rom_set, &map).unwrap();
    let expected = motion::fk::positions(&cal.solve(&motion).unwrap().clip);
    let cal_back = motion::fk::positions(&motion::io::read_clip(None, &cal_bvh).unwrap());
    let plain_back = motion::fk::positions(&motion::io::read_clip(None, &plain_bvh).unwrap());
    std::fs::remove_dir_all(&dir).ok();
    let (mut same, mut differ) = (0.0f64, 0.0f64);
    for f in 0..expected.frames() {
        for j in 0..expected.joint_count() {
            same = same.max(dist(expected.point(f, j), cal_back.point(f, j)));
            differ = differ.max(dist(expected.point(f, j), plain_back.point(f, j)));
        }
    }
    assert!(same < 1e-6, "CLI and library differ by {same} mm");
    assert!(
        differ > 1.0,
        "the calibration changed nothing ({differ} mm)"
    );
}

/// A calibration trial and a motion trial with different marker sets: one `error:` line
/// naming the file and the marker, and no output written.
#[test]
fn mismatched_calibration_trial_names_the_file_and_marker() {
    let dir = tmp("calbad");
    let (c3d, rom, seg, _) = synth_with_calibration(&dir);
    // Copies of both trials without one marker, as CSV.
    let without = |from: &Path, to: &Path, gone: &str| {
        let set = data::read_markers(from).unwrap();
        let keep: Vec<usize> = (0..set.marker_count())
            .filter(|&m| set.names()[m] != gone)
            .collect();
        assert_eq!(keep.len() + 1, set.marker_count());
        let names = keep.iter().map(|&m| set.names()[m].clone()).collect();
        let mut out = MarkerSet::new(names, set.frames(), set.frame_rate_hz);
        for f in 0..set.frames() {
            for (i, &m) in keep.iter().enumerate() {
                out.set(f, i, set.get(f, m));
            }
        }
        data::write_csv(&out, to, files::Mode::Replace).unwrap();
    };
    let gone = data::read_markers(&c3d).unwrap().names()[7].clone();
    let (rom_less, motion_less) = (dir.join("rom-less.csv"), dir.join("motion-less.csv"));
    without(&rom, &rom_less, &gone);
    without(&c3d, &motion_less, &gone);
    let out = dir.join("o.bvh");
    let fail = |motion: &Path, rom: &Path| {
        let o = study(&[
            "markers",
            "solve",
            s(motion),
            "--segments",
            s(&seg),
            "--calibration",
            s(rom),
            "-o",
            s(&out),
        ]);
        assert!(!o.status.success());
        let stderr = String::from_utf8(o.stderr).unwrap();
        let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
        assert!(
            lines.len() == 1 && lines[0].starts_with("error: "),
            "not one error line:\n{stderr}"
        );
        lines[0].to_string()
    };
    // The calibration trial lacks the marker.
    let e = fail(&c3d, &rom_less);
    assert!(
        e.contains(s(&rom_less)) && e.contains(&format!("{gone:?}")),
        "{e}"
    );
    // The motion trial lacks it.
    let e = fail(&motion_less, &rom);
    assert!(
        e.contains(s(&motion_less)) && e.contains(&format!("{gone:?}")) && e.contains(s(&rom)),
        "{e}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).ok();
}
