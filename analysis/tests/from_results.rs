#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]
//! Typed records of the results store → analysis inputs, and the errors that name the place.

use std::collections::BTreeMap;
use std::path::PathBuf;

use analysis::AnalysisError;
use analysis::from_results::convert;
use analysis::study::{ReportOptions, analyze};
use protocols::manifest::{Stimulus, StimulusManifest};
use protocols::{
    Answer, Arrangement, Block, Outcome, Position, Protocol, Response, Trial, TrialRecord,
};
use results::store::{SessionManifest, SessionState};
use results::{SessionResults, TrialsFile};

fn stimulus(id: &str, clip: &str, codec: &str, cr: f64) -> Stimulus {
    Stimulus {
        id: id.into(),
        clip: clip.into(),
        codec: codec.into(),
        params: BTreeMap::new(),
        variant: BTreeMap::new(),
        target_cr: None,
        target_max_error_cm: None,
        achieved_cr: Some(cr),
        bytes: 0,
        file: format!("{id}.amc"),
        skeleton: None,
        bitstream: None,
        metrics: None,
        encode_ms: None,
        decode_ms: None,
        scene: None,
        sha256: None,
        bitstream_sha256: None,
    }
}

fn manifest() -> StimulusManifest {
    StimulusManifest {
        version: 1,
        cr_basis: protocols::manifest::CrBasis::File,
        stimuli: vec![
            stimulus("walk/ref", "walk", "reference", 1.0),
            stimulus("walk/p/cr20", "walk", "perceptual", 20.0),
            stimulus("walk/w/cr20", "walk", "wavelet", 20.0),
        ],
    }
}

fn record(
    protocol: Protocol,
    subject: &str,
    index: u32,
    block: Block,
    stimulus: &str,
    answer: Answer,
    outcome: Outcome,
) -> TrialRecord {
    TrialRecord {
        study: "s".into(),
        subject: subject.into(),
        session: 1,
        protocol,
        trial: Trial {
            index,
            block,
            condition: stimulus.into(),
            stimulus: stimulus.into(),
            reference: "walk/ref".into(),
            arrangement: Arrangement::SideBySide,
            reference_position: Position::Left,
            staircase: None,
            level: None,
            break_before: false,
        },
        response: Response {
            answer,
            response_time_ms: 900,
            replays: 0,
            dropped_frames: 0,
        },
        outcome,
        elapsed_ms: 0,
        wall_clock_ms: 0,
        monotonic_ms: 0,
        encoding: None,
        timing: None,
    }
}

fn outcome(score: f64) -> Outcome {
    Outcome {
        score,
        score_reference: None,
        score_test: None,
        correct: None,
        reversal: None,
    }
}

fn session(subject: &str, protocol: Protocol, records: Vec<TrialRecord>) -> SessionResults {
    SessionResults {
        dir: PathBuf::from(format!("/results/{subject}-1")),
        manifest: SessionManifest {
            format_version: 1,
            study: "s".into(),
            study_hash: "0".into(),
            manifest_hash: None,
            protocol,
            subject: subject.into(),
            subject_index: 0,
            session: 1,
            plan_seed: 1,
            observer_seed: None,
            software_version: "test".into(),
            subject_fields: BTreeMap::new(),
            started_ms: 0,
            ended_ms: None,
            status: SessionState::Complete,
            trials_logged: records.len() as u32,
            not_shown: vec![],
            thresholds: vec![],
            resumes: 0,
            torn_rows: vec![],
            display: None,
            browser: None,
            viewing: None,
            group: None,
        },
        trials: TrialsFile {
            format_version: 2,
            records,
            complete_bytes: 0,
            torn: None,
        },
    }
}

fn mos_session(subject: &str, scores: [f64; 3]) -> SessionResults {
    let r = |i, block, stim: &str, v: f64| {
        record(
            Protocol::Mos,
            subject,
            i,
            block,
            stim,
            Answer::Rating(v),
            outcome(v),
        )
    };
    session(
        subject,
        Protocol::Mos,
        vec![
            r(0, Block::Familiarization, "walk/w/cr20", 1.0),
            r(1, Block::Test, "walk/p/cr20", scores[0]),
            r(2, Block::Test, "walk/w/cr20", scores[1]),
            r(3, Block::Test, "walk/ref", scores[2]),
            r(4, Block::HiddenRepeat, "walk/p/cr20", scores[0]),
        ],
    )
}

#[test]
fn mos_sessions_become_ratings_with_conditions_and_hidden_reference() {
    let sessions = vec![
        mos_session("ann", [4.5, 3.5, 5.0]),
        mos_session("bob", [4.0, 3.0, 4.5]),
        mos_session("cy", [4.5, 4.0, 5.0]),
    ];
    let c = convert(&sessions, &manifest(), Some((1.0, 5.0))).unwrap();
    assert_eq!(c.protocol, Protocol::Mos);
    assert_eq!(c.data.subjects, vec!["ann", "bob", "cy"]);
    // Familiarization dropped, the hidden repeat kept.
    assert_eq!(c.data.ratings.len(), 12);
    let p = c.stimuli.iter().position(|s| s == "walk/p/cr20").unwrap() as u32;
    let r = c.stimuli.iter().position(|s| s == "walk/ref").unwrap() as u32;
    let info = c.data.conditions.iter().find(|i| i.id == p).unwrap();
    assert_eq!(
        (
            info.codec.as_str(),
            info.clip.as_str(),
            info.compression_ratio
        ),
        ("perceptual", "walk", Some(20.0))
    );
    assert_eq!(
        c.data
            .conditions
            .iter()
            .find(|i| i.id == r)
            .unwrap()
            .compression_ratio,
        None
    );
    assert_eq!(c.data.reference_of.get(&p), Some(&r));
    let a = analyze(
        &c.data,
        &ReportOptions {
            figures: false,
            level_label: "Level".to_owned(),
            ..ReportOptions::default()
        },
    )
    .unwrap();
    let mos_p = a.mos.iter().find(|s| s.condition == p).unwrap();
    assert!((mos_p.summary.mean - (4.5 * 2.0 + 4.0 * 2.0 + 4.5 * 2.0) / 6.0).abs() < 1e-12);
    // ACR-HR: DV = V(test) − V(ref) + 5 per rating, e.g. ann 4.5 − 5 + 5 = 4.5.
    let dmos_p = a.dmos.iter().find(|s| s.condition == p).unwrap();
    assert!((dmos_p.summary.mean - (4.5 + 4.5 + 4.5 + 4.5 + 4.5 + 4.5) / 6.0).abs() < 1e-12);
}

#[test]
fn score_outside_the_scale_names_file_line_and_column() {
    let sessions = vec![mos_session("ann", [4.5, 6.0, 5.0])];
    let err = convert(&sessions, &manifest(), Some((1.0, 5.0))).unwrap_err();
    match &err {
        AnalysisError::BadRecord {
            path, line, column, ..
        } => {
            assert_eq!(path, &PathBuf::from("/results/ann-1/trials.csv"));
            assert_eq!((*line, *column), (4, "score"));
        }
        other => panic!("{other:?}"),
    }
    assert!(
        err.to_string()
            .contains("/results/ann-1/trials.csv: line 4, column score")
    );
}

#[test]
fn mixed_protocols_and_unknown_stimuli_are_errors() {
    let mut dscqs = mos_session("bob", [4.0, 3.0, 4.5]);
    dscqs.manifest.protocol = Protocol::Dscqs;
    let err = convert(
        &[mos_session("ann", [4.5, 3.5, 5.0]), dscqs],
        &manifest(),
        None,
    )
    .unwrap_err();
    assert!(
        matches!(err, AnalysisError::MixedProtocols { .. }),
        "{err:?}"
    );
    let mut odd = mos_session("ann", [4.5, 3.5, 5.0]);
    odd.trials.records[2].trial.stimulus = "run/x/cr9".into();
    let err = convert(&[odd], &manifest(), None).unwrap_err();
    assert!(err.to_string().contains("run/x/cr9"), "{err}");
    let mut wrong = mos_session("ann", [4.5, 3.5, 5.0]);
    wrong.trials.records[1].response.answer = Answer::Choice(Position::Left);
    let err = convert(&[wrong], &manifest(), None).unwrap_err();
    assert!(
        matches!(
            err,
            AnalysisError::BadRecord {
                line: 3,
                column: "response",
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn staircase_records_become_tracks_and_2afc_trials() {
    // One length in both types: a level without an answer does not compile.
    let levels: [f64; 9] = [
        0.024, 0.024, 0.022, 0.022, 0.020, 0.022, 0.022, 0.020, 0.022,
    ];
    let correct: [bool; 9] = [true, true, true, true, false, true, true, false, true];
    let records = levels
        .iter()
        .zip(correct)
        .enumerate()
        .map(|(i, (&level, c))| {
            let mut r = record(
                Protocol::Staircase,
                "ann",
                i as u32,
                Block::Test,
                "walk/p/cr20",
                Answer::Choice(Position::Left),
                Outcome {
                    score: f64::from(u8::from(c)),
                    score_reference: None,
                    score_test: None,
                    correct: Some(c),
                    reversal: Some(i == 4 || i == 6 || i == 7),
                },
            );
            r.trial.staircase = Some(0);
            r.trial.level = Some(level);
            r.trial.condition = "t_l".into();
            r
        })
        .collect();
    let c = convert(
        &[session("ann", Protocol::Staircase, records)],
        &manifest(),
        None,
    )
    .unwrap();
    assert_eq!(c.data.staircases.len(), 1);
    assert_eq!(c.data.two_afc.len(), 9);
    let t = &c.data.staircases[0];
    assert_eq!(t.label, "t_l");
    assert_eq!(t.reversal_levels(), vec![0.020, 0.022, 0.020]);
    assert!((t.threshold(3).unwrap() - 0.062 / 3.0).abs() < 1e-15);
    let mut bad = session("ann", Protocol::Staircase, vec![]);
    let mut r = record(
        Protocol::Staircase,
        "ann",
        0,
        Block::Test,
        "walk/p/cr20",
        Answer::Choice(Position::Left),
        outcome(1.0),
    );
    r.trial.staircase = Some(0);
    bad.trials.records.push(r);
    let err = convert(&[bad], &manifest(), None).unwrap_err();
    assert!(
        matches!(
            err,
            AnalysisError::BadRecord {
                line: 2,
                column: "level",
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn accumulated_levels_of_older_logs_are_keyed_on_the_grid() {
    // Before the exact grid, a staircase accumulated `level - step`: ten steps down from 0.024
    // logged 0.003999999999999993 where another path logged 0.004.
    let accumulated = (0..10).fold(0.024_f64, |x, _| x - 0.002);
    assert_ne!(accumulated.to_bits(), 0.004_f64.to_bits());
    let track = |subject: &str, level: f64| {
        let mut r = record(
            Protocol::Staircase,
            subject,
            0,
            Block::Test,
            "walk/p/cr20",
            Answer::Choice(Position::Left),
            outcome(1.0),
        );
        r.outcome.correct = Some(true);
        r.trial.staircase = Some(0);
        r.trial.level = Some(level);
        session(subject, Protocol::Staircase, vec![r])
    };
    let c = convert(
        &[track("ann", accumulated), track("bob", 0.004)],
        &manifest(),
        None,
    )
    .unwrap();
    let levels: Vec<u64> = c.data.two_afc.iter().map(|t| t.level.to_bits()).collect();
    assert_eq!(levels, vec![0.004_f64.to_bits(); 2]);
    let encoded: Vec<u64> = c
        .data
        .encoded_levels
        .iter()
        .map(|e| e.level.to_bits())
        .collect();
    assert_eq!(encoded, vec![0.004_f64.to_bits(); 2]);
}

/// Ratings of two variants of one codec at one target ratio (`study sweep --param
/// qp=9,11`) and the reference, by three subjects.
fn variant_study() -> analysis::from_results::ConvertedResults {
    let variant = |id: &str, qp: f64| Stimulus {
        params: [("qp".to_string(), qp), ("alpha".to_string(), 0.1)].into(),
        variant: [("qp".to_string(), qp)].into(),
        target_cr: Some(20.0),
        ..stimulus(id, "walk", "wavelet-perceptual", 19.9)
    };
    let m = StimulusManifest {
        version: 2,
        cr_basis: protocols::manifest::CrBasis::File,
        stimuli: vec![
            stimulus("walk/ref", "walk", "reference", 1.0),
            variant("walk/wavelet-perceptual/qp9/cr20", 9.0),
            variant("walk/wavelet-perceptual/qp11/cr20", 11.0),
        ],
    };
    let session_of = |subject: &str, scores: [f64; 3]| {
        let r = |i, stim: &str, v: f64| {
            record(
                Protocol::Mos,
                subject,
                i,
                Block::Test,
                stim,
                Answer::Rating(v),
                outcome(v),
            )
        };
        session(
            subject,
            Protocol::Mos,
            vec![
                r(0, "walk/wavelet-perceptual/qp9/cr20", scores[0]),
                r(1, "walk/wavelet-perceptual/qp11/cr20", scores[1]),
                r(2, "walk/ref", scores[2]),
            ],
        )
    };
    let sessions = vec![
        session_of("ann", [3.0, 4.5, 5.0]),
        session_of("bob", [2.5, 4.0, 5.0]),
        session_of("cy", [3.5, 4.0, 4.5]),
    ];
    convert(&sessions, &m, Some((1.0, 5.0))).unwrap()
}

fn report_options() -> ReportOptions {
    ReportOptions {
        figures: false,
        level_label: "Level".to_owned(),
        ..ReportOptions::default()
    }
}

/// Two variants of one codec at one target ratio are two conditions with two labels
/// everywhere: the MOS and DMOS tables, the paired t-test between them, the rate curves (one
/// per variant, not one curve with two points at 20:1), and the tidy CSV.
#[test]
fn two_variants_at_one_ratio_get_two_labels_in_every_table_test_and_curve() {
    let c = variant_study();
    let mut methods: Vec<String> = c
        .data
        .conditions
        .iter()
        .filter(|i| i.compression_ratio.is_some())
        .map(analysis::ConditionInfo::method)
        .collect();
    methods.sort();
    let want = [
        "wavelet-perceptual/qp11".to_string(),
        "wavelet-perceptual/qp9".to_string(),
    ];
    assert_eq!(methods, want);
    let options = report_options();
    let a = analyze(&c.data, &options).unwrap();
    // One paired test, variant against variant.
    assert_eq!(a.comparisons.len(), 1);
    let row = &a.comparisons[0];
    assert_eq!(
        [row.first.0.as_str(), row.second.0.as_str()],
        ["wavelet-perceptual/qp11", "wavelet-perceptual/qp9"]
    );
    // One rate curve per variant.
    let curves: Vec<(&str, usize)> = a
        .mos_findings
        .iter()
        .map(|f| (f.codec.as_str(), f.points.len()))
        .collect();
    assert_eq!(
        curves,
        [
            ("wavelet-perceptual/qp11", 1),
            ("wavelet-perceptual/qp9", 1)
        ]
    );
    let report = a.to_report(&c.data, &options, "variants");
    let mos = report.tables().find(|t| t.name == "mos").unwrap();
    let labels: Vec<&str> = mos
        .rows
        .iter()
        .filter(|r| r[2] == "20:1")
        .map(|r| r[0].as_str())
        .collect();
    assert_eq!(
        labels,
        ["wavelet-perceptual/qp11", "wavelet-perceptual/qp9"]
    );
    let dmos = report.tables().find(|t| t.name == "dmos").unwrap();
    let rows: Vec<&str> = dmos.rows.iter().map(|r| r[0].as_str()).collect();
    assert!(
        rows.contains(&"wavelet-perceptual/qp9 @ 20:1")
            && rows.contains(&"wavelet-perceptual/qp11 @ 20:1"),
        "{rows:?}"
    );
    let csv = analysis::export::tidy_csv(&c.data.subjects, &c.data.ratings, &c.data.conditions);
    assert!(csv.contains(",wavelet-perceptual/qp9,walk,20,"), "{csv}");
}

/// A baseline names one variant; the codec's name alone is ambiguous there, so no test.
#[test]
fn a_baseline_names_one_variant() {
    let c = variant_study();
    let against = |base: &str| {
        let o = ReportOptions {
            baseline_codec: Some(base.to_owned()),
            ..report_options()
        };
        analyze(&c.data, &o).unwrap().comparisons
    };
    let rows = against("wavelet-perceptual/qp9");
    assert_eq!(rows.len(), 1);
    assert_eq!(
        [rows[0].first.0.as_str(), rows[0].second.0.as_str()],
        ["wavelet-perceptual/qp11", "wavelet-perceptual/qp9"]
    );
    assert!(against("wavelet-perceptual").is_empty());
}

/// A QUEST+ / Psi session's rows carry no reversal flag: its track is marked Bayesian, and
/// the session's own threshold (`session.json`) is attached to the track of that name; an
/// up-down track stays an up-down track.
#[test]
fn bayesian_tracks_are_told_apart_and_keep_their_session_threshold() {
    let make = |reversal: Option<bool>| -> Vec<TrialRecord> {
        [0.010, 0.016, 0.010, 0.004]
            .iter()
            .enumerate()
            .map(|(i, &level)| {
                let mut r = record(
                    Protocol::Staircase,
                    "ann",
                    i as u32,
                    Block::Test,
                    "walk/p/cr20",
                    Answer::Choice(Position::Left),
                    Outcome {
                        score: 1.0,
                        score_reference: None,
                        score_test: None,
                        correct: Some(i != 2),
                        reversal,
                    },
                );
                r.trial.staircase = Some(0);
                r.trial.level = Some(level);
                r.trial.condition = "walk".into();
                r
            })
            .collect()
    };
    let mut quest = session("ann", Protocol::Staircase, make(None));
    quest.manifest.thresholds = vec![("walk".into(), Some(0.0117))];
    let c = convert(&[quest], &manifest(), None).unwrap();
    let t = &c.data.staircases[0];
    assert!(t.bayesian);
    assert_eq!(t.logged_threshold, Some(0.0117));
    let up_down = session("bob", Protocol::Staircase, make(Some(false)));
    let c = convert(&[up_down], &manifest(), None).unwrap();
    assert!(!c.data.staircases[0].bayesian);
    assert_eq!(c.data.staircases[0].logged_threshold, None);
}

/// Issue 37: answers sooner after the answer before them than their stimuli play (here 4 s
/// each) are found when both clocks say so; a session taken over by another server (its
/// monotonic clock restarted) or a stepped wall clock is not flagged, a MUSHRA screen's rows
/// are one answer, simulated sessions and trials of unknown length are not checked, and only
/// `too_fast = "exclude"` excludes.
#[test]
fn answers_sooner_than_the_stimuli_play_are_found_by_both_clocks() {
    use analysis::exclusions::{session_exclusion, too_fast};
    use protocols::study::{CrowdsourcingSettings, TooFastRule};
    let timed = |times: &[(u64, u64)]| {
        let mut s = mos_session("A", [3.0, 4.0, 5.0]);
        s.manifest.started_ms = 1_000_000;
        s.trials.records.truncate(times.len());
        for (r, &(wall, mono)) in s.trials.records.iter_mut().zip(times) {
            r.wall_clock_ms = 1_000_000 + wall;
            r.monotonic_ms = mono;
        }
        s
    };
    let need = |_: &TrialRecord| Some(4000.0);
    let flagged =
        |s: &SessionResults| -> Vec<u32> { too_fast(s, &need).iter().map(|t| t.trial).collect() };
    let paced = timed(&[(5000, 5000), (10_000, 10_000), (15_000, 15_000)]);
    assert_eq!(flagged(&paced), Vec::<u32>::new());
    let scripted = timed(&[(10, 10), (20, 20), (4030, 4030)]);
    assert_eq!(flagged(&scripted), [0, 1]);
    let t = too_fast(&scripted, &need);
    assert_eq!((t[1].after_ms, t[1].need_ms), (10.0, 4000.0));
    // Within the slack (50 ms) of the need: not flagged (the third row above).
    // Taken over: the next server's monotonic clock counts from its replay.
    let taken_over = timed(&[(5000, 5000), (10_000, 5010), (15_000, 5020)]);
    assert_eq!(flagged(&taken_over), Vec::<u32>::new());
    // The wall clock stepped back 3 s between two answers.
    let stepped = timed(&[(5000, 5000), (7000, 10_000), (12_000, 15_000)]);
    assert_eq!(flagged(&stepped), Vec::<u32>::new());
    // The first answer counts from the session's start.
    let first = timed(&[(900, 900), (6000, 6000)]);
    assert_eq!(flagged(&first), [0]);
    // A MUSHRA screen: its rows come together; the next screen (another reference) is checked.
    let mut grid = timed(&[(5000, 5000), (5001, 5001), (5002, 5002), (5003, 5003)]);
    for (i, r) in grid.trials.records.iter_mut().enumerate() {
        r.trial.arrangement = Arrangement::Grid;
        r.trial.block = Block::Test;
        r.trial.reference = if i < 3 { "walk/ref" } else { "run/ref" }.into();
    }
    assert_eq!(flagged(&grid), [3]);
    // Simulated sessions and trials whose length is unknown are not checked.
    let mut simulated = scripted.clone();
    simulated.manifest.observer_seed = Some(3);
    assert_eq!(flagged(&simulated), Vec::<u32>::new());
    assert!(too_fast(&scripted, &|_| None).is_empty());
    // Flagged, kept; excluded only where the study says so.
    let mut crowd = CrowdsourcingSettings::default();
    let e = session_exclusion(&scripted, &crowd, &need);
    assert!(e.any() && !e.excluded && e.too_fast.len() == 2);
    crowd.too_fast = TooFastRule::Exclude;
    assert!(session_exclusion(&scripted, &crowd, &need).excluded);
    assert!(!session_exclusion(&paced, &crowd, &need).excluded);
}
