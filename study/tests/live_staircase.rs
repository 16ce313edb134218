//! Live (codec-in-the-loop) staircase end to end: the example's generated source clips,
//! `study check` / `study simulate` encoding each trial's stimulus on the fly and logging its
//! parameters, CR and error, and a simulated observer whose detection follows the real decoded
//! error recovered by the analysis within its confidence interval.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

#[path = "../../scripts/golden/tidy_readers.rs"]
mod tidy_readers;
#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use motion::synth::{WalkParams, walking_clip};

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// The five generated motions of `examples/live/` (thesis ch. 5 used five motions in turn):
/// (name, motion file, walk parameters). AMC clips are 120 Hz (what the reader assumes);
/// BVH clips carry their own rate.
fn example_motions() -> Vec<(&'static str, &'static str, WalkParams)> {
    let base = WalkParams {
        duration_s: 1.5,
        ..WalkParams::default()
    };
    vec![
        ("walk", "walk.amc", base),
        (
            "stroll",
            "stroll.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 80.0,
                cycle_hz: 0.7,
                amplitude: 0.8,
                ..base
            },
        ),
        (
            "brisk",
            "brisk.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 160.0,
                cycle_hz: 1.1,
                amplitude: 1.1,
                ..base
            },
        ),
        (
            "march",
            "march.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 100.0,
                cycle_hz: 0.8,
                amplitude: 1.4,
                ..base
            },
        ),
        (
            "sway",
            "sway.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 60.0,
                cycle_hz: 0.6,
                amplitude: 1.2,
                ..base
            },
        ),
    ]
}

/// The checked-in clips of `examples/live/clips` are exactly what `motion::synth` generates
/// (run with `REGENERATE_LIVE_EXAMPLE=1` to rewrite them after a change to the generator).
#[test]
fn example_clips_are_the_generated_motions() {
    let dir = examples().join("live/clips");
    let regenerate = std::env::var_os("REGENERATE_LIVE_EXAMPLE").is_some();
    let tmp =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("live-clips-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    for (name, file, params) in example_motions() {
        let clip = walking_clip(&params);
        let out = if regenerate { dir.clone() } else { tmp.clone() };
        let is_amc = Path::new(file)
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("amc"));
        let asf = is_amc.then(|| out.join("walker.asf"));
        motion::io::write_clip(&clip, &out.join(file), asf.as_deref(), files::Mode::Replace)
            .unwrap();
        if !regenerate {
            for f in std::iter::once(file).chain(asf.as_ref().map(|_| "walker.asf")) {
                assert_eq!(
                    std::fs::read(tmp.join(f)).unwrap(),
                    std::fs::read(dir.join(f)).unwrap(),
                    "{name}: examples/live/clips/{f} differs from the generator (REGENERATE_LIVE_EXAMPLE=1)"
                );
            }
        }
    }
}

fn scratch(name: &str) -> PathBuf {
    let d =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("live-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn study() -> Command {
    Command::new(env!("CARGO_BIN_EXE_study"))
}

/// The example's source clips, read the way the manifest names them.
fn source_clips() -> Vec<(String, motion::Clip)> {
    let dir = examples().join("live");
    let m: protocols::manifest::StimulusManifest =
        serde_json::from_str(&std::fs::read_to_string(dir.join("stimuli.json")).unwrap()).unwrap();
    m.stimuli
        .iter()
        .map(|s| {
            let skeleton = s.skeleton.as_ref().map(|k| dir.join(k));
            let clip = motion::io::read_clip(skeleton.as_deref(), &dir.join(&s.file)).unwrap();
            (s.clip.clone(), clip)
        })
        .collect()
}

/// RMS error (cm) of SPIHT at target CR `level` on `clip`, computed here independently of the
/// runner, with the example's fixed parameters.
fn spiht_rms_cm(clip: &motion::Clip, level: f64) -> f64 {
    let codec = codecs::codec::by_name("spiht").unwrap();
    let params = BTreeMap::from([("cr".to_string(), level), ("window".to_string(), 128.0)]);
    let stream = codec.encode(clip, &params).unwrap();
    let decoded = codec.decode(&stream, &clip.skeleton).unwrap();
    codecs::metrics::compare(clip, &decoded).unwrap().rms_cm
}

/// The simulated observers of the example detect the decoded RMS error through a Weibull
/// (α = 1.5 cm, β = 3, λ = 0.02). With the five clips in turn, the staircase sees the mean of
/// the five psychometric functions of the level; a two-down-one-up staircase converges where
/// that mean is √½ correct (Levitt 1971). That level, found here from independently measured
/// errors, is the observers' true threshold; the analysis of `study simulate`'s logged trials
/// (mean of the last 6 reversals per subject, Student-t CI over subjects) must cover it. Every
/// row must also log the exact parameters, a CR within rate control's ±2 % of the level and
/// the RMS error the codec really gives at that level.
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "one scenario: check, simulate, verify rows, find the truth, analyse, report"
)]
fn simulated_live_staircase_recovers_the_observers_true_threshold() {
    let toml = examples().join("live-staircase.toml");
    let check = study().arg("check").arg(&toml).output().unwrap();
    let text = String::from_utf8_lossy(&check.stdout);
    assert!(
        check.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&check.stderr)
    );
    assert!(text.contains("live staircase: codec spiht"), "{text}");
    assert_eq!(text.matches("  clip \"").count(), 5, "{text}");

    let out = scratch("coverage");
    let sim = study()
        .arg("simulate")
        .arg(&toml)
        .args(["--subjects", "10", "--seed", "4", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );

    let clips = source_clips();
    let mut rms_at: BTreeMap<(String, u64), f64> = BTreeMap::new();
    let mut rms = |clip: &str, level: f64| -> f64 {
        *rms_at
            .entry((clip.to_string(), level.to_bits()))
            .or_insert_with(|| {
                let (_, c) = clips.iter().find(|(n, _)| n == clip).unwrap();
                spiht_rms_cm(c, level)
            })
    };
    let (_, sessions) = results::read_results_dir(&out).unwrap();
    assert_eq!(sessions.len(), 10);
    let mut rows = 0;
    for s in &sessions {
        for r in &s.trials.records {
            let level = r.trial.level.unwrap();
            let clip = r.trial.reference.strip_suffix("/reference").unwrap();
            assert_eq!(r.trial.stimulus, format!("live:{clip}/spiht/cr={level}"));
            let e = r.encoding.as_ref().expect("a live row logs its encoding");
            assert_eq!(e.codec_params.get("cr"), Some(&level));
            assert_eq!(e.codec_params.get("window"), Some(&128.0));
            assert!(
                (e.achieved_cr / level - 1.0).abs() <= 0.02,
                "CR {} at level {level}",
                e.achieved_cr
            );
            // Same codec, same input: the logged error is the bit-exact one.
            assert_eq!(
                e.rms_cm.to_bits(),
                rms(clip, level).to_bits(),
                "{clip} at {level}"
            );
            rows += 1;
        }
    }
    assert!(rows > 300, "{rows} rows");

    // True threshold: the level where the clips' mean p(correct) crosses √½.
    let f = |x: f64| 0.5 + (0.5 - 0.02) * (1.0 - (-(x / 1.5).powi(3)).exp());
    let target = 0.5_f64.sqrt();
    let names: Vec<String> = clips.iter().map(|(n, _)| n.clone()).collect();
    let mean_p = |level: f64, rms: &mut dyn FnMut(&str, f64) -> f64| {
        names.iter().map(|n| f(rms(n, level))).sum::<f64>() / names.len() as f64
    };
    let mut truth = None;
    let mut prev = (8.0, mean_p(8.0, &mut rms));
    let mut level = 10.0;
    while level <= 80.0 {
        let p = mean_p(level, &mut rms);
        if prev.1 < target && p >= target {
            truth = Some(prev.0 + (target - prev.1) / (p - prev.1) * (level - prev.0));
            break;
        }
        prev = (level, p);
        level += 2.0;
    }
    let truth = truth.expect("the observers' threshold lies inside [8, 80]");

    let study_def = lab::StudyFile::load(&toml).unwrap().definition;
    let converted = analysis::from_results::convert(&sessions, &study_def.manifest, None).unwrap();
    let t = analysis::staircase::staircase_thresholds(
        &converted.data.staircases,
        6,
        analysis::Confidence::default(),
    )
    .unwrap();
    assert!(t.unconverged.is_empty(), "{:?}", t.unconverged);
    let ci = t.summary.unwrap().ci_t.unwrap();
    eprintln!(
        "true threshold CR {truth:.3}; estimated {:.3} [{:.3}, {:.3}] over {} subjects",
        t.summary.unwrap().mean,
        ci.lower,
        ci.upper,
        t.per_subject.len()
    );
    assert!(
        ci.lower <= truth && truth <= ci.upper,
        "95 % CI [{}, {}] misses the true threshold {truth}",
        ci.lower,
        ci.upper
    );
    // The JND report's share at the true threshold is near one half.
    let values: Vec<f64> = t.per_subject.iter().map(|p| p.1).collect();
    let share =
        analysis::jnd::unnoticed_share(&values, truth, analysis::Confidence::default()).unwrap();
    let (lo, hi) = share.model_ci.unwrap();
    assert!(
        lo <= 0.5 && 0.5 <= hi,
        "share not noticing at the truth: [{lo}, {hi}]"
    );

    // And `study report` writes the JND tables for it, averaging the study's
    // `threshold_reversals` (6) reversals unless told otherwise.
    let report = scratch("coverage-report");
    let rep = study()
        .arg("report")
        .arg(&out)
        .args(["--bootstrap", "50", "--no-png", "-o"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        rep.status.success(),
        "{}",
        String::from_utf8_lossy(&rep.stderr)
    );
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("Just-noticeable difference"), "{md}");
    assert!(md.contains("Mean of the last 6 reversals"), "{md}");
    let notice = std::fs::read_to_string(report.join("tables/jnd_notice.csv")).unwrap();
    assert!(
        notice.lines().next().unwrap().contains("CR on walk"),
        "{notice}"
    );
    assert!(report.join("figures/jnd.svg").is_file());
    // The tidy export of live trials (stimuli made per trial, not in the manifest) reads in
    // pandas and R.
    tidy_readers::check_tidy(&out, &report, "live-staircase.toml");
}

/// QUEST+ live (codec-in-the-loop), with practice: the example's five clips in turn under a
/// QUEST+ track over CR 8, 16, ... 80 and two practice trials at CR 10. Every row logs the
/// encoding the codec really gave at its level (the error recomputed here, bit for bit); the
/// practice rows come first at their level; each subject's test rows are exactly the levels a
/// QUEST+ track fed with the logged answers asks for, one after the other (nothing else moved
/// it), and its posterior mean is the threshold `session.json` records; `study check`
/// describes the track by its levels and `study report` lists each subject's QUEST+ track.
#[test]
fn a_live_quest_plus_track_encodes_its_levels_and_replays_from_the_rows() {
    let dir = scratch("quest");
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(examples().join("live-staircase.toml")).unwrap();
    let up_down = "start = 64\nstep = 2\nmin = 8\nmax = 80\nn_up = 1\nn_down = 2\n\
                   stop_reversals = 12\nmax_trials = 90\nthreshold_reversals = 6\n";
    assert!(text.contains(up_down));
    let quest = "method = \"quest_plus\"\nstep = 8\nmin = 8\nmax = 80\nmax_trials = 24\n\
                 practice_trials = 2\npractice_level = 10\n";
    let settings = "[staircase.quest]\nthreshold = { min = 5, max = 120, count = 40, \
                    spacing = \"log\" }\nslope = [1.5, 2, 3, 4, 6]\nlapse = [0, 0.02, 0.04]\n";
    let text = text
        .replace(
            "stimuli = \"live/stimuli.json\"",
            &format!("stimuli = {:?}", examples().join("live/stimuli.json")),
        )
        .replace(up_down, quest)
        .replace("[staircase.live]", &format!("{settings}\n[staircase.live]"));
    let toml = dir.join("live-quest.toml");
    std::fs::write(&toml, text).unwrap();
    let check = study().arg("check").arg(&toml).output().unwrap();
    let described = String::from_utf8_lossy(&check.stdout);
    assert!(check.status.success(), "{described}");
    assert!(
        described.contains(
            "QUEST+ track \"live\": 10 levels in [8, 80], each chosen from the posterior"
        ),
        "{described}"
    );
    let out = dir.join("results");
    let sim = study()
        .arg("simulate")
        .arg(&toml)
        .args(["--subjects", "4", "--seed", "2", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let clips = source_clips();
    let def = lab::StudyFile::load(&toml).unwrap().definition;
    let q = def.staircase.as_ref().unwrap().quest.clone().unwrap();
    let (_, sessions) = results::read_results_dir(&out).unwrap();
    assert_eq!(sessions.len(), 4);
    for s in &sessions {
        let rows = &s.trials.records;
        assert_eq!(rows.len(), 2 + 24, "{}", s.manifest.subject);
        let mut track = protocols::QuestPlus::new(q.clone()).unwrap();
        for (k, r) in rows.iter().enumerate() {
            let level = r.trial.level.unwrap();
            let clip = r.trial.reference.strip_suffix("/reference").unwrap();
            let e = r.encoding.as_ref().expect("a live row logs its encoding");
            assert_eq!(e.codec_params.get("cr"), Some(&level));
            let (_, c) = clips.iter().find(|(n, _)| n == clip).unwrap();
            assert_eq!(e.rms_cm.to_bits(), spiht_rms_cm(c, level).to_bits());
            if k < 2 {
                assert_eq!(r.trial.block, protocols::Block::Familiarization);
                assert_eq!(level.to_bits(), 10.0_f64.to_bits());
                continue;
            }
            assert_eq!(r.trial.block, protocols::Block::Test);
            assert_eq!(track.next_level(), Some(level), "row {k}");
            track.add_response(r.outcome.correct.unwrap()).unwrap();
        }
        let recorded = &s.manifest.thresholds;
        assert_eq!(recorded.len(), 1);
        assert_eq!(
            recorded[0].1.map(f64::to_bits),
            Some(track.threshold().mean.to_bits()),
            "{}",
            s.manifest.subject
        );
    }
    let report = dir.join("report");
    let rep = study()
        .arg("report")
        .arg(&out)
        .args(["--no-png", "-o"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        rep.status.success(),
        "{}",
        String::from_utf8_lossy(&rep.stderr)
    );
    let tracks = std::fs::read_to_string(report.join("tables/adaptive_tracks.csv")).unwrap();
    assert_eq!(
        tracks
            .lines()
            .filter(|l| l.contains(",live,QUEST+/Psi,24,"))
            .count(),
        4,
        "{tracks}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
