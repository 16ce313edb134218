//! Issue 38, item 4: which channels a compression ratio counts. On every shared CMU AMC clip
//! the seeds' basis counts 56 of the file's 62 channels, so a stream's seed-basis CR × 62/56
//! is its file-basis CR (4 bytes × 62 × frames / its bytes, counted here from the file's
//! size). `study encode --cr-basis seed` aims its target at the seeds' raw size; a sweep
//! records the basis in the manifest and rd.csv, the preflight checks each ratio on it, and
//! the report says which basis its ratios use. A skeleton the seeds do not describe is
//! refused on the seed basis, naming a joint.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = study(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("cr-basis-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The number after `CR ` in a `study encode` line.
fn cr_of(line: &str) -> f64 {
    let rest = &line[line.find("CR ").unwrap() + 3..];
    rest[..rest.find([' ', ',']).unwrap()].parse().unwrap()
}

/// `(asf, amc, frames)` of every shared AMC clip.
fn amc_clips() -> Vec<(PathBuf, PathBuf, usize)> {
    let Some(dir) = motion::data::mocap_dir() else {
        return Vec::new();
    };
    let clips: Vec<_> = motion::data::shared_clips()
        .into_iter()
        .filter_map(|c| c.asf.map(|a| (a, c.motion)))
        .map(|(asf, amc)| {
            let frames = motion::io::read_clip(Some(&asf), &amc).unwrap().frames();
            (asf, amc, frames)
        })
        .collect();
    assert_eq!(clips.len(), 4, "the shared AMC clips in {}", dir.display());
    clips
}

#[test]
fn on_every_cmu_amc_clip_the_seed_basis_is_56_of_62_channels() {
    let dir = scratch("encode");
    for (asf, amc, frames) in amc_clips() {
        for codec in ["wavelet-perceptual", "spiht"] {
            let out = dir.join(format!(
                "{}-{codec}",
                amc.file_stem().unwrap().to_string_lossy()
            ));
            let said = ok(&[
                "encode",
                s(&asf),
                s(&amc),
                "--codec",
                codec,
                "--cr",
                "20",
                "--cr-basis",
                "seed",
                "-o",
                s(&out),
            ]);
            assert!(said.contains("seed basis: 56 of 62 channels"), "{said}");
            let seed = cr_of(&said);
            assert!((seed / 20.0 - 1.0).abs() <= 0.02, "{said}");
            let mcz = std::fs::read_dir(&out)
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|p| p.extension().is_some_and(|e| e == "mcz"))
                .unwrap();
            let bytes = std::fs::metadata(&mcz).unwrap().len() as f64;
            let file = 4.0 * 62.0 * frames as f64 / bytes;
            // The printed ratio has two decimals.
            assert!(
                (seed * 62.0 / 56.0 - file).abs() <= 0.006 * 62.0 / 56.0,
                "{}: seed {seed} × 62/56 against file {file}",
                amc.display()
            );
        }
    }
}

#[test]
fn a_sweep_records_its_basis_and_the_report_names_it() {
    let dir = scratch("sweep");
    let clips = amc_clips();
    let (asf, amc, frames) = &clips[0];
    let set = dir.join("set");
    ok(&[
        "sweep",
        "--clips",
        s(asf),
        s(amc),
        "--codecs",
        "spiht",
        "--cr",
        "15,30",
        "--cr-basis",
        "seed",
        "--quiet",
        "-o",
        s(&set),
    ]);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(set.join("stimuli.json")).unwrap()).unwrap();
    assert_eq!(manifest["cr_basis"], "seed");
    let mut coded = Vec::new();
    for st in manifest["stimuli"].as_array().unwrap() {
        if st["codec"] == "reference" {
            continue;
        }
        let (cr, bytes) = (
            st["achieved_cr"].as_f64().unwrap(),
            st["bytes"].as_f64().unwrap(),
        );
        assert!(
            (cr - 4.0 * 56.0 * *frames as f64 / bytes).abs() < 1e-9 * cr,
            "{st}"
        );
        let target = st["target_cr"].as_f64().unwrap();
        assert!((cr / target - 1.0).abs() <= 0.02, "{st}");
        coded.push(st["id"].as_str().unwrap().to_string());
    }
    assert_eq!(coded.len(), 2);
    let rd = std::fs::read_to_string(set.join("rd.csv")).unwrap();
    assert!(rd.lines().next().unwrap().ends_with(",cr_basis"), "{rd}");
    assert_eq!(
        rd.lines().skip(1).filter(|l| l.ends_with(",seed")).count(),
        2,
        "{rd}"
    );

    // A study over the set: the preflight checks each ratio on the seed basis, and the
    // report says which basis its ratios count.
    let toml = dir.join("mos.toml");
    std::fs::write(
        &toml,
        format!(
            "format_version = 1\nname = \"seed-basis\"\nprotocol = \"mos\"\n\
             stimuli = \"set/stimuli.json\"\nseed = 3\n[conditions]\nstimuli = {coded:?}\n"
        ),
    )
    .unwrap();
    ok(&["check", s(&toml)]);
    let res = dir.join("res");
    ok(&["simulate", s(&toml), "--subjects", "3", "-o", s(&res)]);
    let rep = dir.join("rep");
    ok(&[
        "report",
        s(&res),
        "--bootstrap",
        "50",
        "--no-png",
        "-o",
        s(&rep),
    ]);
    let report = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(report.contains("on the seed basis"), "{report}");

    // The same manifest claiming the file basis no longer matches its streams: refused,
    // naming the stimulus and the key.
    let path = set.join("stimuli.json");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replace("\"cr_basis\": \"seed\",", "")).unwrap();
    let out = study(&["check", s(&toml)]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "a wrong basis passed");
    assert!(e.contains("achieved_cr") && e.contains(&coded[0]), "{e}");
}

#[test]
fn a_skeleton_the_seeds_do_not_describe_is_refused_on_their_basis() {
    let dir = scratch("refuse");
    let walk = dir.join("walk.bvh");
    ok(&["clip", "convert", "--demo", "-o", s(&walk)]);
    let out = study(&[
        "encode",
        s(&walk),
        "--codec",
        "spiht",
        "--cr",
        "20",
        "--cr-basis",
        "seed",
        "-o",
        s(&dir.join("out")),
    ]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(e.contains("CMU") && e.contains("joint \"root\""), "{e}");
    // The CMU BVH conversion counts the ASF's degrees of freedom: 56 of its 96 channels.
    if let Some(data) = motion::data::mocap_dir() {
        let said = ok(&[
            "encode",
            s(&data.join("131_01.bvh")),
            "--codec",
            "spiht",
            "--cr",
            "20",
            "--cr-basis",
            "seed",
            "-o",
            s(&dir.join("bvh")),
        ]);
        assert!(said.contains("seed basis: 56 of 96 channels"), "{said}");
    }
}
