//! A sweep on the shared clips: every stimulus file exists, reaches its target within ±2 %,
//! and its bitstream decodes with the reference skeleton.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};

use codecs::bitstream::Bitstream;
use codecs::codec;
use lab::clips::ClipOptions;
use lab::sweep::{SweepOptions, sweep};
use protocols::manifest::{REFERENCE_CODEC, StimulusManifest};

#[test]
fn sweep_two_shared_clips_three_codecs_four_rates() {
    let Some(dir) = motion::data::mocap_dir() else {
        return;
    };
    let out = std::env::temp_dir().join(format!("lab-sweep-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let options = SweepOptions {
        clips: vec![
            dir.join("02_01.amc"),
            dir.join("12.asf"),
            dir.join("131_01.bvh"),
        ],
        clip_options: ClipOptions::default(),
        codecs: vec![
            "wavelet-perceptual".into(),
            "wavelet-bone".into(),
            "spiht".into(),
        ],
        targets: vec![15.0, 20.0, 30.0, 40.0],
        max_errors_cm: Vec::new(),
        params: Vec::new(),
        output: out.clone(),
        jobs: 2,
        database: None,
        codec_defs: None,
        cr_basis: codecs::basis::CrBasis::File,
        force: false,
    };
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let summary = sweep(&options, &|done, total| {
        assert!(done <= total && total == 24);
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    })
    .unwrap();
    assert_eq!(calls.into_inner(), 24);
    assert_eq!(summary.references, 2);
    let text = std::fs::read_to_string(out.join("stimuli.json")).unwrap();
    let manifest: StimulusManifest = serde_json::from_str(&text).unwrap();
    assert_eq!(manifest, summary.manifest);
    assert_eq!(manifest.stimuli.len(), 2 + 2 * 3 * 4);
    for s in &manifest.stimuli {
        assert!(out.join(&s.file).is_file(), "{}", s.file);
        if let Some(k) = &s.skeleton {
            assert!(out.join(k).is_file(), "{k}");
        }
        if s.codec != REFERENCE_CODEC {
            let t = s.target_cr.unwrap();
            assert!(
                (s.achieved_cr.unwrap() / t - 1.0).abs() <= 0.02,
                "{}: {}",
                s.id,
                s.achieved_cr.unwrap()
            );
            let m = s.metrics.unwrap();
            assert!(m.rms_cm.is_finite() && m.rms_cm > 0.0);
            // The bitstream on disk decodes with the reference skeleton to the stimulus file.
            let bytes = std::fs::read(out.join(s.bitstream.as_ref().unwrap())).unwrap();
            assert_eq!(bytes.len() as u64, s.bytes);
            let reference = manifest.reference_of(&s.clip).unwrap();
            let skeleton = match &reference.skeleton {
                Some(asf) => motion::asf::read_asf(&out.join(asf)).unwrap(),
                None => {
                    motion::io::read_clip(None, &out.join(&reference.file))
                        .unwrap()
                        .skeleton
                }
            };
            let decoded =
                codec::decode_any(&Bitstream::from_bytes(&bytes).unwrap(), &skeleton).unwrap();
            let file = motion::io::read_clip(
                reference.skeleton.as_ref().map(|a| out.join(a)).as_deref(),
                &out.join(&s.file),
            )
            .unwrap();
            assert_eq!(decoded.frames(), file.frames(), "{}", s.id);
        }
    }
    let csv = std::fs::read_to_string(out.join("rd.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 24);
    std::fs::remove_dir_all(&out).unwrap();
}

/// A fresh scratch folder holding a one-second generated walk as `clips/walk.{asf,amc}`.
fn walk_dir(name: &str) -> (PathBuf, Vec<PathBuf>) {
    let dir = std::env::temp_dir().join(format!("lab-sweep-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("clips")).unwrap();
    let walk = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 1.0,
        ..motion::synth::WalkParams::default()
    });
    let (asf, amc) = (dir.join("clips/walk.asf"), dir.join("clips/walk.amc"));
    motion::io::write_clip(&walk, &amc, Some(&asf), files::Mode::New).unwrap();
    (dir, vec![amc, asf])
}

fn walk_sweep(clips: &[PathBuf], out: &Path, force: bool) -> lab::Result<lab::sweep::SweepSummary> {
    let options = SweepOptions {
        clips: clips.to_vec(),
        clip_options: ClipOptions::default(),
        codecs: vec!["spiht".into()],
        targets: vec![10.0],
        max_errors_cm: Vec::new(),
        params: Vec::new(),
        output: out.to_path_buf(),
        jobs: 1,
        database: None,
        codec_defs: None,
        cr_basis: codecs::basis::CrBasis::File,
        force,
    };
    sweep(&options, &|_, _| {})
}

/// Every file under `dir`, relative, sorted.
fn tree(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out.sort();
    out
}

#[test]
fn a_sweep_into_a_folder_holding_files_is_refused_unless_forced() {
    let (dir, clips) = walk_dir("refuse");
    let out = dir.join("stimuli");
    // An existing empty folder is fine.
    std::fs::create_dir_all(&out).unwrap();
    walk_sweep(&clips, &out, false).unwrap();
    let first = tree(&out);
    assert_eq!(
        first,
        [
            "rd.csv",
            "stimuli.json",
            "walk/reference.amc",
            "walk/reference.asf",
            "walk/spiht-cr10.amc",
            "walk/spiht-cr10.mcz",
        ]
    );
    // Again, without force: refused before anything is written, naming the folder and what
    // it holds.
    std::fs::write(out.join("rd.csv"), "the first sweep's table").unwrap();
    let e = walk_sweep(&clips, &out, false).unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(&e, lab::LabError::File(files::Error::NotEmpty { dir, .. }) if dir == &out),
        "{text}"
    );
    assert!(
        text.contains(&format!(
            "{} is not empty: it holds rd.csv, stimuli.json, walk/",
            out.display()
        )),
        "{text}"
    );
    assert!(text.contains("--force"), "{text}");
    assert_eq!(
        std::fs::read_to_string(out.join("rd.csv")).unwrap(),
        "the first sweep's table"
    );
    assert_eq!(tree(&out), first);
    // With force: the same files, replaced, and nothing else (no temporary files).
    walk_sweep(&clips, &out, true).unwrap();
    assert_eq!(tree(&out), first);
    assert!(
        std::fs::read_to_string(out.join("rd.csv"))
            .unwrap()
            .starts_with("clip,codec,")
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_forced_sweep_rewrites_the_reference_skeleton() {
    // The stimuli of a clip refer to its reference skeleton; a forced sweep of another clip
    // under the same name must not keep the old one.
    let (dir, clips) = walk_dir("skeleton");
    let out = dir.join("stimuli");
    walk_sweep(&clips, &out, false).unwrap();
    std::fs::write(out.join("walk/reference.asf"), "stale").unwrap();
    walk_sweep(&clips, &out, true).unwrap();
    let skeleton = motion::asf::read_asf(&out.join("walk/reference.asf")).unwrap();
    assert_eq!(skeleton, motion::asf::read_asf(&clips[1]).unwrap());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The manifest, the table and every file do not depend on the number of workers (jobs
/// are handed out longest clip first, results kept in clip, codec, rate order); only the
/// measured times differ.
#[test]
fn one_and_two_workers_write_the_same_sweep() {
    let Some(dir) = motion::data::mocap_dir() else {
        return;
    };
    let base = std::env::temp_dir().join(format!("lab-sweep-jobs-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let run = |jobs: usize| {
        let out = base.join(format!("jobs{jobs}"));
        let options = SweepOptions {
            clips: vec![
                dir.join("02_01.amc"),
                dir.join("12.asf"),
                dir.join("pirouette.amc"),
                dir.join("pirouette.asf"),
                dir.join("131_01.bvh"),
            ],
            clip_options: ClipOptions::default(),
            codecs: vec!["wavelet-perceptual".into(), "spiht".into()],
            targets: vec![20.0, 40.0],
            max_errors_cm: Vec::new(),
            params: vec![("window".into(), vec![128.0, 256.0])],
            output: out.clone(),
            jobs,
            database: None,
            codec_defs: None,
            cr_basis: codecs::basis::CrBasis::File,
            force: false,
        };
        let mut manifest = sweep(&options, &|_, _| {}).unwrap().manifest;
        for s in &mut manifest.stimuli {
            s.encode_ms = None;
            s.decode_ms = None;
        }
        let csv: Vec<String> = std::fs::read_to_string(out.join("rd.csv"))
            .unwrap()
            .lines()
            // Every column but the measured times (encode_ms, decode_ms).
            .map(|l| {
                let mut cells: Vec<&str> = l.split(',').collect();
                cells.drain(14..16);
                cells.join(",")
            })
            .collect();
        let files: Vec<(String, Vec<u8>)> = manifest
            .stimuli
            .iter()
            .flat_map(|s| std::iter::once(&s.file).chain(s.bitstream.as_ref()))
            .map(|f| (f.clone(), std::fs::read(out.join(f)).unwrap()))
            .collect();
        (manifest, csv, files)
    };
    let one = run(1);
    let two = run(2);
    assert_eq!(one.0, two.0);
    assert_eq!(one.1, two.1);
    assert_eq!(one.2, two.2);
    std::fs::remove_dir_all(&base).unwrap();
}

/// Two generated clips of different lengths (so the characters' raw sizes differ) in `dir`,
/// and a scene of three characters at two levels (`a` at 3 m; `b` at 6 then 4.5 m; `c` at 9
/// then 12 m) with importance 3, 1, 2.
fn crowd_scene(dir: &Path, importance: bool) -> (PathBuf, Vec<PathBuf>) {
    std::fs::create_dir_all(dir).unwrap();
    let mut clips = Vec::new();
    for (name, seconds) in [("walk", 2.0), ("march", 1.5)] {
        let p = dir.join(format!("{name}.bvh"));
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
            duration_s: seconds,
            ..motion::synth::WalkParams::default()
        });
        motion::io::write_clip(&clip, &p, None, files::Mode::Replace).unwrap();
        clips.push(p);
    }
    let imp = |v: f64| {
        if importance {
            format!("importance = {v}\n")
        } else {
            String::new()
        }
    };
    let scene = dir.join("scene.toml");
    std::fs::write(
        &scene,
        format!(
            "[scene]\nlevels = [\"one\", \"two\"]\n\
             [[scene.characters]]\nname = \"a\"\nclip = \"walk\"\ndistance_cm = 300\n{}\
             [[scene.characters]]\nname = \"b\"\ngroup = \"back\"\nclip = \"march\"\nx_cm = -100\n\
             distance_cm = [600, 450]\n{}\
             [[scene.characters]]\nname = \"c\"\ngroup = \"back\"\nclip = \"walk\"\nx_cm = 100\n\
             distance_cm = [900, 1200]\n{}",
            imp(3.0),
            imp(1.0),
            imp(2.0)
        ),
    )
    .unwrap();
    (scene, clips)
}

fn crowd_options(
    scene: &Path,
    clips: &[PathBuf],
    plan: lab::crowd::Plan,
    out: &Path,
) -> lab::crowd::CrowdOptions {
    lab::crowd::CrowdOptions {
        scene: scene.to_path_buf(),
        clips: clips.to_vec(),
        clip_options: ClipOptions::default(),
        codec: "spiht".into(),
        params: std::collections::BTreeMap::new(),
        plan,
        output: out.to_path_buf(),
        jobs: 2,
        force: false,
    }
}

/// A crowd under one budget (thesis eq. 6.4-6.5), shared by distance, uniformly and by
/// importance: every character's budget is the hand-computed share of the scene's, its stream
/// is within 1 % of it, and the scene's streams add up to the budget within 1 %.
#[test]
fn a_crowd_budget_is_shared_as_eq_6_5_says_and_met_within_one_percent() {
    use lab::crowd::{Budget, Plan, Share};
    let dir = std::env::temp_dir().join(format!("lab-crowd-budget-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (scene, clips) = crowd_scene(&dir, true);
    // Shares by hand. Level one: d = 3, 6, 9 m, S = 1, 1/2, 1/3 (sum 11/6), so B·6/11, B·3/11,
    // B·2/11. Level two: d = 3, 4.5, 12 m, S = 1, 2/3, 1/4 (sum 23/12): B·12/23, B·8/23, B·3/23.
    // Uniform: B/3 each. Importance 3, 1, 2: B/2, B/6, B/3.
    let cases: [(Share, [[f64; 3]; 2]); 3] = [
        (
            Share::Distance,
            [
                [6.0 / 11.0, 3.0 / 11.0, 2.0 / 11.0],
                [12.0 / 23.0, 8.0 / 23.0, 3.0 / 23.0],
            ],
        ),
        (Share::Uniform, [[1.0 / 3.0; 3]; 2]),
        (Share::Importance, [[0.5, 1.0 / 6.0, 1.0 / 3.0]; 2]),
    ];
    for (share, fractions) in cases {
        let out = dir.join(share.as_str());
        let plan = Plan::Budget {
            totals: vec![Budget::Cr(25.0), Budget::Bytes(4000.0)],
            share,
        };
        let summary =
            lab::crowd::crowd(&crowd_options(&scene, &clips, plan, &out), &|_, _| {}).unwrap();
        assert_eq!(summary.scenes, 4, "{share:?}");
        let m: StimulusManifest =
            serde_json::from_slice(&std::fs::read(out.join("stimuli.json")).unwrap()).unwrap();
        let scenes: Vec<_> = m
            .stimuli
            .iter()
            .filter(|s| s.scene.is_some() && s.codec != REFERENCE_CODEC)
            .collect();
        assert_eq!(scenes.len(), 4);
        for s in scenes {
            let sc = s.scene.as_ref().unwrap();
            let level = usize::from(sc.level == "two");
            let budget = sc.budget_bytes.unwrap();
            if s.id.contains("/b4000-") {
                assert!((budget - 4000.0).abs() < 1e-9, "{}", s.id);
            }
            let mut sum = 0;
            for (c, f) in sc.characters.iter().zip(fractions[level]) {
                let b = c.budget_bytes.unwrap();
                assert!(
                    (b - f * budget).abs() <= 1e-9 * budget,
                    "{} {}: {b}",
                    s.id,
                    c.name
                );
                let member = m.get(&c.stimulus).unwrap();
                assert!(
                    (member.bytes as f64 / b - 1.0).abs() <= 0.01,
                    "{} {}: {} bytes for a budget of {b}",
                    s.id,
                    c.name,
                    member.bytes
                );
                sum += member.bytes;
            }
            assert_eq!(s.bytes, sum);
            assert!(
                (sum as f64 / budget - 1.0).abs() <= 0.01,
                "{}: {sum} bytes for a budget of {budget}",
                s.id
            );
        }
        // rd.csv: one row per character of every compressed scene.
        let rd = std::fs::read_to_string(out.join("rd.csv")).unwrap();
        assert_eq!(rd.lines().count(), 1 + 4 * 3);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Fixed ratios per group make a scene per combination and level, each character's stimulus
/// made once however many scenes show it; plans that do not fit the scene are refused before
/// anything is written.
#[test]
fn a_crowd_at_fixed_ratios_and_the_plans_refused() {
    use lab::crowd::{Plan, Share};
    let dir = std::env::temp_dir().join(format!("lab-crowd-fixed-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (scene, clips) = crowd_scene(&dir, false);
    let out = dir.join("fixed");
    let plan = Plan::Fixed(vec![
        ("back".into(), vec![20.0, 40.0]),
        ("a".into(), vec![30.0]),
    ]);
    let summary =
        lab::crowd::crowd(&crowd_options(&scene, &clips, plan, &out), &|_, _| {}).unwrap();
    // 2 levels x 2 back ratios; walk at 30, 20, 40 and march at 20, 40.
    assert_eq!((summary.scenes, summary.encoded), (4, 5));
    let m = &summary.manifest;
    let s = m
        .get("two/spiht/a30-back40")
        .expect("ids name every group's ratio");
    let sc = s.scene.as_ref().unwrap();
    let ids: Vec<&str> = sc.characters.iter().map(|c| c.stimulus.as_str()).collect();
    assert_eq!(
        ids,
        ["walk/spiht/cr30", "march/spiht/cr40", "walk/spiht/cr40"]
    );
    let d: Vec<f64> = sc.characters.iter().map(|c| c.distance_cm).collect();
    assert_eq!(d, [300.0, 450.0, 1200.0]);
    let r = m.get("one/reference").unwrap().scene.as_ref().unwrap();
    assert!(
        r.characters
            .iter()
            .all(|c| c.stimulus.ends_with("/reference"))
    );

    let refused = |plan: Plan, clips: &[PathBuf], why: &str| {
        let out = dir.join("refused");
        let err = lab::crowd::crowd(&crowd_options(&scene, clips, plan, &out), &|_, _| {})
            .unwrap_err()
            .to_string();
        assert!(err.contains(why), "{err}");
        assert!(!out.exists(), "{why}: wrote {}", out.display());
    };
    refused(
        Plan::Fixed(vec![("back".into(), vec![20.0])]),
        &clips,
        "no ratio for group \"a\"",
    );
    refused(
        Plan::Fixed(vec![("a".into(), vec![20.0]), ("side".into(), vec![20.0])]),
        &clips,
        "the scene has no group \"side\"",
    );
    refused(
        Plan::Budget {
            totals: vec![lab::crowd::Budget::Cr(20.0)],
            share: Share::Importance,
        },
        &clips,
        "character \"a\" has no importance",
    );
    refused(
        Plan::Budget {
            totals: vec![lab::crowd::Budget::Cr(-1.0)],
            share: Share::Distance,
        },
        &clips,
        "must be positive",
    );
    refused(
        Plan::Fixed(vec![("a".into(), vec![20.0]), ("back".into(), vec![20.0])]),
        &clips[..1],
        "performs clip \"march\"",
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
