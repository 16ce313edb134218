//! A sweep on the shared clips: every stimulus file exists, reaches its target within ±2 %,
//! and its bitstream decodes with the reference skeleton.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

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
        output: out.clone(),
        jobs: 2,
        database: None,
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
                (s.achieved_cr / t - 1.0).abs() <= 0.02,
                "{}: {}",
                s.id,
                s.achieved_cr
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
            output: out.clone(),
            jobs,
            database: None,
        };
        let mut manifest = sweep(&options, &|_, _| {}).unwrap().manifest;
        for s in &mut manifest.stimuli {
            s.encode_ms = None;
            s.decode_ms = None;
        }
        let csv: Vec<String> = std::fs::read_to_string(out.join("rd.csv"))
            .unwrap()
            .lines()
            .map(|l| l.rsplitn(3, ',').nth(2).unwrap().to_string())
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
