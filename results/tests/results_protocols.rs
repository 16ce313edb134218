//! The results store: row round trip, fsynced append, torn-row detection and setting aside,
//! the session lock (held and left behind), never overwriting, atomic manifests, readers with
//! file/line/column errors, and 2,400 mutated results files that give errors, never panics.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use proptest::prelude::*;
use protocols::rng::StudyRng;
use protocols::{
    Answer, Arrangement, Block, FrameTiming, Outcome, Position, Protocol, Response,
    StimulusEncoding, Trial, TrialRecord,
};
use results::store::{
    DisplayInfo, MANIFEST_FORMAT_VERSION, SessionLock, SessionState, read_json, write_json,
};
use results::trials::{HEADER, HEADER_V1, encode_row, encode_row_as, parse_trials};
use results::{
    ResultsError, RunManifest, SessionLog, SessionManifest, read_results_dir, read_trials,
};

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("results-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A pair comparison row's arrangement, answer and outcome: the `reference` column holds the
/// pair's other test stimulus; score 1: the `stimulus` column's version was preferred.
fn pair_comparison_parts(
    rng: &mut StudyRng,
) -> (Arrangement, Answer, Outcome, Option<f64>, Option<u32>) {
    let side = if rng.coin() {
        Position::Left
    } else {
        Position::Right
    };
    let outcome = Outcome {
        score: 1.0,
        score_reference: None,
        score_test: None,
        correct: None,
        reversal: None,
    };
    (
        Arrangement::SideBySide,
        Answer::Choice(side),
        outcome,
        None,
        None,
    )
}

/// How a one-rating protocol's trial is laid out; a MUSHRA row names the pane its stimulus was
/// shown in (A to L) as its position.
fn rating_arrangement(protocol: Protocol) -> Arrangement {
    match protocol {
        Protocol::Acr => Arrangement::Single,
        Protocol::Dcr => Arrangement::Sequential,
        Protocol::Mushra => Arrangement::Grid,
        _ => Arrangement::SideBySide,
    }
}

/// A one-rating row's parts: `rating` given, `score` logged.
fn rating_parts(arrangement: Arrangement, rating: f64, score: f64) -> Parts {
    let outcome = Outcome {
        score,
        score_reference: None,
        score_test: None,
        correct: None,
        reversal: None,
    };
    (arrangement, Answer::Rating(rating), outcome, None, None)
}

/// Arrangement, answer, outcome, level and staircase of a row.
type Parts = (Arrangement, Answer, Outcome, Option<f64>, Option<u32>);

fn record(i: u32, protocol: Protocol, rng: &mut StudyRng) -> TrialRecord {
    let (arrangement, answer, outcome, level, staircase) = match protocol {
        Protocol::Mos | Protocol::Acr | Protocol::Dcr | Protocol::Mushra => rating_parts(
            rating_arrangement(protocol),
            1.0 + 0.5 * rng.below(9) as f64,
            3.5,
        ),
        // A CCR rating of the second version against the first, -3 … 3.
        Protocol::Ccr => rating_parts(Arrangement::Sequential, rng.below(7) as f64 - 3.0, -2.0),
        Protocol::Dscqs => (
            Arrangement::Abab,
            Answer::Pair {
                a: rng.unit_f64() * 100.0,
                b: 17.25,
            },
            Outcome {
                score: -12.5,
                score_reference: Some(40.0),
                score_test: Some(52.5),
                correct: None,
                reversal: None,
            },
            None,
            None,
        ),
        Protocol::Staircase => (
            Arrangement::Sequential,
            Answer::Choice(Position::Second),
            Outcome {
                score: 1.0,
                score_reference: None,
                score_test: None,
                correct: Some(true),
                reversal: Some(rng.coin()),
            },
            Some(0.024 - 0.002 * f64::from(i % 7)),
            Some(i % 3),
        ),
        Protocol::PairComparison => pair_comparison_parts(rng),
    };
    let reference_position = match (protocol, arrangement) {
        (_, Arrangement::SideBySide) => Position::Left,
        (Protocol::Dcr, Arrangement::Sequential) => Position::First,
        (_, Arrangement::Sequential) => Position::Second,
        (_, Arrangement::Abab) => Position::B,
        (_, Arrangement::Single) => Position::Hidden,
        (_, Arrangement::Grid) => Position::Pane((i % 12) as u8),
    };
    TrialRecord {
        study: "study, \"quoted\"".into(),
        subject: format!("S{i:03}"),
        session: 1,
        protocol,
        trial: Trial {
            index: i,
            block: if i == 0 {
                Block::Familiarization
            } else {
                Block::Test
            },
            condition: "walk/wavelet,cr10".into(),
            stimulus: "walk/wavelet/cr10".into(),
            reference: "walk/reference".into(),
            arrangement,
            reference_position,
            staircase,
            level,
            break_before: i % 5 == 4,
        },
        response: Response {
            answer,
            response_time_ms: rng.below(10_000),
            replays: 2,
            dropped_frames: 1,
        },
        outcome,
        elapsed_ms: u64::from(i) * 1000,
        wall_clock_ms: 1_795_000_000_000 + u64::from(i),
        monotonic_ms: u64::from(i) * 999,
        // Live staircase rows log how their stimulus was encoded: awkward floats on purpose.
        encoding: (protocol == Protocol::Staircase && i % 2 == 1).then(|| StimulusEncoding {
            codec_params: BTreeMap::from([
                ("cr".to_string(), 0.1 + 0.2 + f64::from(i)),
                ("qp".to_string(), 10.0),
                ("alpha".to_string(), 1e-7 / 3.0),
            ]),
            achieved_cr: 48.000_000_000_000_01 + rng.unit_f64(),
            rms_cm: rng.unit_f64() * 3.0,
        }),
        // Rows from the study window carry frame timing; simulated rows do not.
        timing: (protocol != Protocol::Staircase && i.is_multiple_of(3)).then(|| FrameTiming {
            frames_shown: 120 + i,
            interval_sd_ms: 0.1 + rng.unit_f64() / 7.0,
        }),
    }
}

fn manifest(trials: u32) -> SessionManifest {
    SessionManifest {
        format_version: MANIFEST_FORMAT_VERSION,
        study: "s".into(),
        study_hash: "00ff".into(),
        manifest_hash: Some("1234".into()),
        protocol: Protocol::Mos,
        subject: "S001".into(),
        subject_index: 0,
        session: 1,
        plan_seed: 1,
        observer_seed: None,
        software_version: "0.1.0".into(),
        subject_fields: BTreeMap::from([("age".to_string(), "31".to_string())]),
        started_ms: 1,
        ended_ms: None,
        status: SessionState::Running,
        trials_logged: trials,
        not_shown: vec![],
        thresholds: vec![("walk".into(), Some(0.012))],
        resumes: 0,
        torn_rows: vec![],
        display: Some(DisplayInfo {
            description: "19in 1440x900".into(),
            width_px: 1440,
            height_px: 900,
            refresh_hz: 60.0,
        }),
        browser: None,
        viewing: None,
        group: None,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]
    #[test]
    fn rows_round_trip(seed in any::<u64>(), which in 0_usize..8, n in 1_u32..20) {
        let protocol = [
            Protocol::Mos,
            Protocol::Dscqs,
            Protocol::Staircase,
            Protocol::Acr,
            Protocol::Dcr,
            Protocol::PairComparison,
            Protocol::Mushra,
            Protocol::Ccr,
        ][which];
        let mut rng = StudyRng::new(seed, &[]);
        let recs: Vec<TrialRecord> = (0..n).map(|i| record(i, protocol, &mut rng)).collect();
        let mut text = format!("{HEADER}\n");
        for r in &recs {
            text.push_str(&encode_row(r).unwrap());
        }
        let parsed = parse_trials(text.as_bytes(), Path::new("t.csv")).unwrap();
        prop_assert_eq!(parsed.records, recs);
        prop_assert!(parsed.torn.is_none());
    }
}

#[test]
fn ids_with_line_breaks_are_refused() {
    let mut rng = StudyRng::new(1, &[]);
    let mut r = record(1, Protocol::Mos, &mut rng);
    r.trial.stimulus = "a\nb".into();
    assert!(matches!(
        encode_row(&r),
        Err(ResultsError::Unwritable {
            column: "stimulus",
            ..
        })
    ));
}

#[test]
fn append_then_read_back_and_never_overwrite() {
    let root = scratch("append");
    let dir = root.join("S001_s1");
    let mut rng = StudyRng::new(2, &[]);
    let recs: Vec<TrialRecord> = (0..5)
        .map(|i| record(i, Protocol::Staircase, &mut rng))
        .collect();
    {
        let mut log = SessionLog::create(&dir).unwrap();
        for r in &recs {
            log.append(r).unwrap();
        }
        log.write_manifest(&manifest(5)).unwrap();
        // A second writer on the same session is refused while the first holds the lock.
        assert!(matches!(
            SessionLog::resume(&dir),
            Err(ResultsError::Locked { .. })
        ));
    }
    assert!(matches!(
        SessionLog::create(&dir),
        Err(ResultsError::Exists { .. })
    ));
    assert_eq!(read_trials(&dir.join("trials.csv")).unwrap().records, recs);
    let run = RunManifest {
        format_version: 1,
        study: "s".into(),
        study_hash: "00ff".into(),
        manifest_hash: None,
        study_file: "study.toml".into(),
        plan_seed: 1,
        observer_seed: None,
        subjects: 1,
        software_version: "0.1.0".into(),
        created_ms: 0,
    };
    // A version 1 run manifest (before `manifest_hash`) is read as it was written.
    let mut v1 = serde_json::to_value(&run).unwrap();
    v1.as_object_mut().unwrap().remove("manifest_hash");
    std::fs::write(root.join("run.json"), v1.to_string()).unwrap();
    let (r, sessions) = read_results_dir(&root).unwrap();
    assert_eq!(r, run);
    // A version this build does not know is refused, naming the file and the version.
    let future = RunManifest {
        format_version: MANIFEST_FORMAT_VERSION + 1,
        ..run.clone()
    };
    write_json(&root.join("run.json"), &future).unwrap();
    let err = read_results_dir(&root).unwrap_err();
    assert!(
        matches!(err, ResultsError::UnknownVersion { version, .. } if version == MANIFEST_FORMAT_VERSION + 1),
        "{err}"
    );
    assert!(err.to_string().contains("run.json"), "{err}");
    write_json(&root.join("run.json"), &run).unwrap();
    assert_eq!(sessions.len(), 1);
    assert_eq!(sessions[0].manifest, manifest(5));
    assert_eq!(sessions[0].trials.records, recs);
    // A session interrupted before its first manifest write is reported, not skipped.
    drop(SessionLog::create(&root.join("S002_s1")).unwrap());
    assert!(matches!(
        read_results_dir(&root),
        Err(ResultsError::MissingManifest { .. })
    ));
}

#[test]
fn torn_last_row_is_detected_set_aside_and_reported() {
    let root = scratch("torn");
    let dir = root.join("S001_s1");
    let mut rng = StudyRng::new(3, &[]);
    let recs: Vec<TrialRecord> = (0..4).map(|i| record(i, Protocol::Mos, &mut rng)).collect();
    {
        let mut log = SessionLog::create(&dir).unwrap();
        for r in &recs {
            log.append(r).unwrap();
        }
    }
    // Power cut mid-write: half of a fifth row without its line break.
    let row = encode_row(&record(4, Protocol::Mos, &mut rng)).unwrap();
    let torn = &row.as_bytes()[..row.len() / 2];
    let path = dir.join("trials.csv");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.extend_from_slice(torn);
    std::fs::write(&path, &bytes).unwrap();
    let read = read_trials(&path).unwrap();
    assert_eq!(read.records, recs, "complete rows are all there");
    let t = read.torn.clone().unwrap();
    assert_eq!(t.line, 6);
    assert_eq!(t.bytes, torn);
    let resumed = SessionLog::resume(&dir).unwrap();
    assert_eq!(resumed.records, recs);
    let (row, aside) = resumed.torn.clone().unwrap();
    assert_eq!(row.bytes, torn);
    assert_eq!(
        std::fs::read(&aside).unwrap(),
        torn,
        "set aside, not dropped"
    );
    let mut log = resumed.log;
    log.append(&recs[0]).unwrap();
    drop(log);
    let again = read_trials(&path).unwrap();
    assert_eq!(again.records.len(), 5);
    assert!(again.torn.is_none());
    // A row of NUL bytes (what some file systems show after a crash) is torn too.
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.extend_from_slice(&[0; 40]);
    bytes.push(b'\n');
    assert!(parse_trials(&bytes, &path).unwrap().torn.is_some());
}

#[test]
fn lock_left_by_a_dead_runner_is_free_a_held_lock_is_not() {
    let dir = scratch("lock");
    // A lock file left behind by a killed runner holds no kernel lock: whatever pid it names
    // (here pid 1, which is alive), the next runner takes it.
    std::fs::write(dir.join("session.lock"), "1\n").unwrap();
    let lock = SessionLock::acquire(&dir).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.join("session.lock"))
            .unwrap()
            .trim(),
        std::process::id().to_string()
    );
    // A second open file description is refused while the first holds the lock, and is told
    // who holds it.
    let me = std::process::id();
    match SessionLock::acquire(&dir) {
        Err(ResultsError::Locked { pid, .. }) => assert_eq!(pid, me),
        other => panic!("second lock: {other:?}"),
    }
    drop(lock);
    assert!(!dir.join("session.lock").exists(), "released lock removed");
    drop(SessionLock::acquire(&dir).unwrap());
}

#[test]
fn malformed_rows_name_file_line_and_column() {
    let mut rng = StudyRng::new(4, &[]);
    let good = encode_row(&record(1, Protocol::Dscqs, &mut rng)).unwrap();
    let bad = good.replacen(",abab,", ",abba,", 1);
    let text = format!("{HEADER}\n{good}{bad}{good}");
    match parse_trials(text.as_bytes(), Path::new("x/trials.csv")) {
        Err(ResultsError::Malformed {
            path,
            line,
            column,
            message,
        }) => {
            assert_eq!(path, Path::new("x/trials.csv"));
            assert_eq!(line, 3);
            assert_eq!(column, 11, "arrangement is column 11");
            assert!(message.contains("arrangement"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    let json = b"{\n  \"format_version\": 1,\n  \"study\": 5\n}";
    match results::store::parse_session_manifest(json, Path::new("session.json")) {
        Err(ResultsError::Malformed { line, .. }) => assert_eq!(line, 3),
        other => panic!("{other:?}"),
    }
}

#[test]
fn atomic_manifest_replace_leaves_no_temporary() {
    let dir = scratch("atomic");
    let p = dir.join("session.json");
    write_json(&p, &manifest(1)).unwrap();
    write_json(&p, &manifest(2)).unwrap();
    let m: SessionManifest = read_json(&p).unwrap();
    assert_eq!(m.trials_logged, 2);
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["session.json".to_string()]);
}

#[test]
fn mutated_results_files_give_errors_never_panics() {
    let mut rng = StudyRng::new(5, &[]);
    let mut text = format!("{HEADER}\n");
    for (i, p) in [
        Protocol::Mos,
        Protocol::Dscqs,
        Protocol::Staircase,
        Protocol::Acr,
        Protocol::Dcr,
        Protocol::PairComparison,
        Protocol::Mushra,
        Protocol::Ccr,
    ]
    .into_iter()
    .cycle()
    .take(9)
    .enumerate()
    {
        text.push_str(&encode_row(&record(i as u32, p, &mut rng)).unwrap());
    }
    let json = serde_json::to_vec_pretty(&manifest(9)).unwrap();
    // [trials.csv, session.json]: errors and accepted mutations.
    let (mut errs, mut oks) = ([0; 2], [0; 2]);
    for case in 0..2400 {
        let json_case = case % 4 == 3;
        let src: &[u8] = if json_case { &json } else { text.as_bytes() };
        let mut b = src.to_vec();
        for _ in 0..=rng.below(3) {
            let at = rng.index(b.len());
            match rng.below(5) {
                0 => b[at] = rng.below(256) as u8,
                1 => {
                    b.remove(at);
                }
                2 => b.insert(at, [b',', b'"', b'\n', b'-', b'9', 0xff][rng.index(6)]),
                3 => b.truncate(at),
                _ => {
                    let end = (at + rng.index(40)).min(b.len());
                    let chunk = b[at..end].to_vec();
                    b.splice(at..at, chunk);
                }
            }
        }
        let name = if json_case {
            "session.json"
        } else {
            "trials.csv"
        };
        let result = if json_case {
            results::store::parse_session_manifest(&b, Path::new(name)).map(|_| ())
        } else {
            parse_trials(&b, Path::new(name)).map(|_| ())
        };
        let k = usize::from(json_case);
        match result {
            Ok(()) => oks[k] += 1,
            Err(e) => {
                // Every error is about the file it was given, at a line (and, in the CSV,
                // a column) of it.
                let msg = e.to_string();
                assert!(msg.starts_with(&format!("{name}: ")), "{msg}");
                match e {
                    ResultsError::Malformed {
                        path, line, column, ..
                    } => {
                        assert_eq!(path, Path::new(name));
                        assert!(line >= 1 && column >= 1 || json_case, "{line}:{column}");
                    }
                    other => panic!("{name}: not a malformed-file error: {other:?}"),
                }
                errs[k] += 1;
            }
        }
        if b == src {
            // A mutation that changed nothing (a duplicated empty chunk) leaves a valid file.
            assert!(result_is_ok(&b, json_case), "{name} unchanged but refused");
        }
    }
    eprintln!(
        "trials.csv: {} errors, {} accepted; session.json: {} errors, {} accepted",
        errs[0], oks[0], errs[1], oks[1]
    );
    // A truncation at a row end is a valid shorter CSV file; JSON has no such escape.
    assert!(
        errs[0] > 1000,
        "trials.csv: {} errors, {} accepted",
        errs[0],
        oks[0]
    );
    assert!(
        errs[1] > 500,
        "session.json: {} errors, {} accepted",
        errs[1],
        oks[1]
    );
}

fn result_is_ok(b: &[u8], json: bool) -> bool {
    if json {
        results::store::parse_session_manifest(b, Path::new("session.json")).is_ok()
    } else {
        parse_trials(b, Path::new("trials.csv")).is_ok()
    }
}

/// A `trials.csv` written before the encoding columns existed (version 1, 29 columns) still
/// reads, and a session resumed into it keeps appending version 1 rows (torn-row handling
/// included), so one file never mixes layouts.
#[test]
fn version_1_files_read_and_resume_in_their_own_layout() {
    let root = scratch("v1");
    let dir = root.join("S001_s1");
    std::fs::create_dir_all(&dir).unwrap();
    let mut rng = StudyRng::new(8, &[]);
    let recs: Vec<TrialRecord> = (0..6)
        .map(|i| {
            let mut r = record(i, Protocol::Staircase, &mut rng);
            r.encoding = None;
            r.timing = None;
            r
        })
        .collect();
    let mut text = format!("{HEADER_V1}\n");
    for r in &recs[..4] {
        let row = encode_row_as(r, 1).unwrap();
        assert!(row.starts_with("1,"), "{row}");
        assert_eq!(
            row.trim_end().split(',').count(),
            29 + 2,
            "two quoted commas: {row}"
        );
        text.push_str(&row);
    }
    // Torn fifth row, as a power cut leaves it.
    let fifth = encode_row_as(&recs[4], 1).unwrap();
    text.push_str(&fifth[..fifth.len() / 3]);
    let path = dir.join("trials.csv");
    std::fs::write(&path, &text).unwrap();
    let read = read_trials(&path).unwrap();
    assert_eq!(read.format_version, 1);
    assert_eq!(read.records, recs[..4]);
    assert!(read.torn.is_some());

    let resumed = SessionLog::resume(&dir).unwrap();
    assert_eq!(resumed.records, recs[..4]);
    let mut log = resumed.log;
    assert_eq!(log.format_version(), 1);
    log.append(&recs[4]).unwrap();
    log.append(&recs[5]).unwrap();
    // An encoded stimulus has no columns in version 1: refused, not silently dropped.
    let mut encoded = record(7, Protocol::Staircase, &mut rng);
    assert!(encoded.encoding.is_some());
    assert!(matches!(
        log.append(&encoded),
        Err(ResultsError::Unwritable {
            column: "codec_params",
            ..
        })
    ));
    drop(log);
    let again = read_trials(&path).unwrap();
    assert_eq!(again.format_version, 1);
    assert_eq!(again.records, recs);
    assert!(
        std::fs::read_to_string(&path)
            .unwrap()
            .starts_with(&format!("{HEADER_V1}\n"))
    );
    // A version 2 row in a version 1 file is an error naming the first column.
    encoded.encoding = None;
    let mixed = format!("{HEADER_V1}\n{}", encode_row(&encoded).unwrap());
    match parse_trials(mixed.as_bytes(), Path::new("trials.csv")) {
        Err(ResultsError::Malformed { line: 2, .. }) => {}
        other => panic!("{other:?}"),
    }
}

/// The frame-timing columns: both or none, a standard deviation that is one.
#[test]
fn frame_timing_columns_are_checked() {
    let mut rng = StudyRng::new(10, &[]);
    let good = encode_row(&record(3, Protocol::Mos, &mut rng)).unwrap();
    let parsed = parse_trials(format!("{HEADER}\n{good}").as_bytes(), Path::new("t.csv")).unwrap();
    let t = parsed.records[0].timing.unwrap();
    assert_eq!(t.frames_shown, 123);
    let (prefix, tail) = good.trim_end().rsplit_once(',').unwrap();
    let (prefix, _) = prefix.rsplit_once(',').unwrap();
    assert!(tail.parse::<f64>().is_ok());
    for (row, want_col, want) in [
        (format!("{prefix},,{tail}"), 33, "frames_shown"),
        (format!("{prefix},12,"), 34, "interval_sd_ms"),
        (format!("{prefix},12,-1"), 34, "negative"),
        (format!("{prefix},x,1"), 33, "frames_shown"),
    ] {
        let text = format!("{HEADER}\n{row}\n");
        match parse_trials(text.as_bytes(), Path::new("trials.csv")) {
            Err(ResultsError::Malformed {
                line: 2,
                column,
                message,
                ..
            }) => {
                assert_eq!(column, want_col, "{row}: {message}");
                assert!(message.contains(want), "{row}: {message}");
            }
            other => panic!("{row}: {other:?}"),
        }
    }
    let mut r = record(3, Protocol::Mos, &mut rng);
    r.timing = Some(FrameTiming {
        frames_shown: 1,
        interval_sd_ms: f64::NAN,
    });
    assert!(matches!(
        encode_row(&r),
        Err(ResultsError::Unwritable {
            column: "interval_sd_ms",
            ..
        })
    ));
    assert!(encode_row_as(&record(3, Protocol::Mos, &mut StudyRng::new(10, &[])), 1).is_err());
}

/// The encoding columns: all three or none; bad parameter lists and values name column and
/// reason.
#[test]
fn encoding_columns_are_checked() {
    let mut rng = StudyRng::new(9, &[]);
    let good = encode_row(&record(1, Protocol::Staircase, &mut rng)).unwrap();
    // The last two columns (frame timing) are empty on a simulated row.
    let good = good.trim_end().strip_suffix(",,").unwrap();
    let fields: Vec<&str> = good.rsplitn(4, ',').collect();
    let (rms, cr, params) = (fields[0], fields[1], fields[2]);
    assert!(params.contains("cr=") && params.contains(';'), "{params}");
    let prefix = fields[3];
    let cases = [
        (format!("{prefix},{params},,{rms}"), 31, "achieved_cr"),
        (format!("{prefix},cr=x,{cr},{rms}"), 30, "codec_params"),
        (format!("{prefix},cr=1;cr=2,{cr},{rms}"), 30, "twice"),
        (format!("{prefix},c r=1,{cr},{rms}"), 30, "codec_params"),
        (format!("{prefix},{params},-4,{rms}"), 31, "positive"),
        (format!("{prefix},{params},{cr},nan"), 32, "rms_cm"),
    ];
    for (row, want_col, want) in cases {
        let text = format!("{HEADER}\n{row},,\n");
        match parse_trials(text.as_bytes(), Path::new("trials.csv")) {
            Err(ResultsError::Malformed {
                line: 2,
                column,
                message,
                ..
            }) => {
                assert_eq!(column, want_col, "{row}: {message}");
                assert!(message.contains(want), "{row}: {message}");
            }
            other => panic!("{row}: {other:?}"),
        }
    }
    let mut r = record(3, Protocol::Staircase, &mut rng);
    r.encoding
        .as_mut()
        .unwrap()
        .codec_params
        .insert("a;b".into(), 1.0);
    assert!(matches!(
        encode_row(&r),
        Err(ResultsError::Unwritable {
            column: "codec_params",
            ..
        })
    ));
}
