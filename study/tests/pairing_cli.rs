//! One pairing rule for every command that takes clip files: `clip info`, `encode`, `sweep`
//! and `primitives train` read the same AMC with the same ASF, and refuse the same lists.
//!
//! Two generated clips share joint names but not bone lengths (as CMU subjects do), so an AMC
//! read with the other's ASF would load without a word: `zombie` has every bone 1.3 times as
//! long as `backflip`'s.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use motion::Rest;
use motion::synth::{WalkParams, walking_clip};

fn study(args: &[String]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// `backflip.{asf,amc}` and `zombie.{asf,amc}` in `dir`, and a copy of `zombie.amc` alone in
/// `dir/alone`.
fn write_clips(dir: &Path) {
    let backflip = walking_clip(&WalkParams {
        duration_s: 1.0,
        ..WalkParams::default()
    });
    let mut zombie = walking_clip(&WalkParams {
        duration_s: 1.5,
        amplitude: 0.6,
        ..WalkParams::default()
    });
    for j in &mut zombie.skeleton.joints {
        if let Rest::Bone { length, .. } = &mut j.rest {
            *length *= 1.3;
        }
    }
    for (name, clip) in [("backflip", &backflip), ("zombie", &zombie)] {
        motion::io::write_clip(
            clip,
            &dir.join(format!("{name}.amc")),
            Some(&dir.join(format!("{name}.asf"))),
            files::Mode::Replace,
        )
        .unwrap();
    }
    std::fs::create_dir_all(dir.join("alone")).unwrap();
    std::fs::copy(dir.join("zombie.amc"), dir.join("alone/zombie.amc")).unwrap();
}

/// Bone lengths per clip in the output of `study clip info`: clip name (motion file stem) →
/// `name length_cm` lines.
fn bone_lengths(info: &str) -> BTreeMap<String, Vec<String>> {
    let mut out: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut clip = String::new();
    let mut in_bones = false;
    for line in info.lines() {
        if !line.starts_with(' ') {
            clip = Path::new(line)
                .file_stem()
                .unwrap()
                .to_string_lossy()
                .into_owned();
            in_bones = false;
        } else if line.starts_with("  bones") {
            in_bones = true;
        } else if line.starts_with("  ") && !line.starts_with("    ") {
            in_bones = false;
        } else if in_bones {
            let f: Vec<&str> = line.split_whitespace().collect();
            out.entry(clip.clone())
                .or_default()
                .push(format!("{} {}", f[0], f[3]));
        }
    }
    out
}

fn info(files: &[PathBuf], asf: Option<&Path>) -> Output {
    let mut args = vec!["clip".to_string(), "info".to_string()];
    args.extend(files.iter().map(|f| s(f)));
    if let Some(a) = asf {
        args.extend(["--asf".to_string(), s(a)]);
    }
    study(&args)
}

fn ok_text(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// What `clip info` says of the skeletons the other commands wrote: `sweep`'s reference
/// copies and `encode`'s decoded clips carry the skeleton each read its AMC with.
fn lengths_of(files: &[PathBuf]) -> BTreeMap<String, Vec<String>> {
    bone_lengths(&ok_text(&info(files, None)))
}

struct Lists {
    dir: PathBuf,
}

impl Lists {
    fn p(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

/// `head` + `files` + `tail` + `-o out` (+ `--asf`), as strings.
fn command(
    head: &[&str],
    files: &[PathBuf],
    tail: &[&str],
    out: &Path,
    asf: Option<&Path>,
) -> Vec<String> {
    let mut args: Vec<String> = head.iter().map(|a| (*a).to_string()).collect();
    args.extend(files.iter().map(|f| s(f)));
    args.extend(tail.iter().map(|a| (*a).to_string()));
    args.extend(["-o".to_string(), s(out)]);
    if let Some(a) = asf {
        args.extend(["--asf".to_string(), s(a)]);
    }
    args
}

/// `clip info`, `encode`, `sweep` and `primitives train` on `files` (outputs under
/// `out-<tag>`).
fn run_all(l: &Lists, tag: &str, files: &[PathBuf], asf: Option<&Path>) -> [Output; 4] {
    let out = l.p(&format!("out-{tag}"));
    [
        info(files, asf),
        study(&command(
            &["encode"],
            files,
            &["--codec", "spiht", "--cr", "20"],
            &out.join("encode"),
            asf,
        )),
        study(&command(
            &["sweep", "--clips"],
            files,
            &["--codecs", "spiht", "--cr", "20", "--quiet"],
            &out.join("sweep"),
            asf,
        )),
        study(&command(
            &["primitives", "train"],
            files,
            &["--k-max", "5"],
            &out.join("db.mpdb"),
            asf,
        )),
    ]
}

#[test]
fn every_command_pairs_the_same_files_the_same_way() {
    let dir = std::env::temp_dir().join(format!("study-pairing-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    write_clips(&dir);
    let l = Lists { dir: dir.clone() };
    let truth = lengths_of(&[l.p("backflip.amc"), l.p("backflip.asf")]);
    let zombie_truth = lengths_of(&[l.p("zombie.amc"), l.p("zombie.asf")]);
    assert_ne!(
        truth["backflip"], zombie_truth["zombie"],
        "the skeletons differ"
    );

    // The zombie motion among backflip's files: backflip.asf is named after backflip, so
    // zombie has no skeleton, and every command says so and writes nothing.
    let refused = [
        l.p("alone/zombie.amc"),
        l.p("backflip.amc"),
        l.p("backflip.asf"),
    ];
    for (cmd, out) in ["clip info", "encode", "sweep", "primitives train"]
        .iter()
        .zip(run_all(&l, "refused", &refused, None))
    {
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success(),
            "{cmd} accepted zombie with backflip's skeleton"
        );
        assert!(
            err.contains("zombie.amc: no ASF skeleton for this motion")
                && err.contains("backflip.asf"),
            "{cmd}: {err}"
        );
        assert_eq!(err.lines().count(), 1, "{cmd}: {err}");
    }
    assert!(!l.p("out-refused/sweep/stimuli.json").exists());

    // Each motion with its own skeleton, files in any order: every command reads each AMC
    // with the ASF named after it.
    let both = [
        l.p("zombie.asf"),
        l.p("backflip.amc"),
        l.p("zombie.amc"),
        l.p("backflip.asf"),
    ];
    let [info_out, encode, sweep, train] = run_all(&l, "both", &both, None);
    let from_info = bone_lengths(&ok_text(&info_out));
    assert_eq!(from_info["backflip"], truth["backflip"]);
    assert_eq!(from_info["zombie"], zombie_truth["zombie"]);
    // encode takes one clip: two are refused, each one alone agrees with clip info.
    assert!(String::from_utf8_lossy(&encode.stderr).contains("expected one clip"));
    for name in ["backflip", "zombie"] {
        let one = [l.p(&format!("{name}.amc")), l.p(&format!("{name}.asf"))];
        let [_, enc, _, _] = run_all(&l, name, &one, None);
        ok_text(&enc);
        let decoded = l.p(&format!("out-{name}/encode/{name}.spiht"));
        let got = lengths_of(&[
            decoded.with_extension("spiht.amc"),
            decoded.with_extension("spiht.asf"),
        ]);
        assert_eq!(
            got[&format!("{name}.spiht")],
            from_info[name],
            "encode {name}"
        );
    }
    ok_text(&sweep);
    for name in ["backflip", "zombie"] {
        let r = l.p(&format!("out-both/sweep/{name}"));
        let got = lengths_of(&[r.join("reference.amc"), r.join("reference.asf")]);
        assert_eq!(got["reference"], from_info[name], "sweep {name}");
    }
    assert!(
        String::from_utf8_lossy(&train.stderr)
            .contains(&format!("training on 2 clips, {} frames", 120 + 180)),
        "{}",
        String::from_utf8_lossy(&train.stderr)
    );

    // --asf names the skeleton of every motion not named after a file: the zombie motion
    // then really is read with backflip's skeleton, by every command alike.
    let [info_out, encode, sweep, train] = run_all(
        &l,
        "asf",
        &[l.p("alone/zombie.amc")],
        Some(&l.p("backflip.asf")),
    );
    assert_eq!(
        bone_lengths(&ok_text(&info_out))["zombie"],
        truth["backflip"]
    );
    ok_text(&encode);
    let decoded = l.p("out-asf/encode/zombie.spiht");
    let got = lengths_of(&[
        decoded.with_extension("spiht.amc"),
        decoded.with_extension("spiht.asf"),
    ]);
    assert_eq!(got["zombie.spiht"], truth["backflip"]);
    ok_text(&sweep);
    let r = l.p("out-asf/sweep/zombie");
    assert_eq!(
        lengths_of(&[r.join("reference.amc"), r.join("reference.asf")])["reference"],
        truth["backflip"]
    );
    assert!(
        train.status.success(),
        "{}",
        String::from_utf8_lossy(&train.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
