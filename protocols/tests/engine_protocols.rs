//! Engine behaviour: determinism (property test), replay, MOS plan (familiarization, hidden
//! repeats, shuffle, time limit), DSCQS scoring, staircase interleaving.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::collections::BTreeSet;

use common::{example, example_text, parse};
use proptest::prelude::*;
use protocols::observer::Observer;
use protocols::rng::StudyRng;
use protocols::{
    Answer, Block, EngineError, Outcome, Position, Protocol, Response, Session, SessionStatus,
    StudyDefinition, Trial,
};

/// A valid random response to `trial`.
fn random_response(study: &StudyDefinition, trial: &Trial, rng: &mut StudyRng) -> Response {
    let s = study.scale;
    let rating = |rng: &mut StudyRng| s.snap(s.min + (s.max - s.min) * rng.unit_f64());
    let answer = match study.protocol {
        Protocol::Mos | Protocol::Acr | Protocol::Dcr | Protocol::Mushra | Protocol::Ccr => {
            Answer::Rating(rating(rng))
        }
        Protocol::Dscqs => Answer::Pair {
            a: rating(rng),
            b: rating(rng),
        },
        Protocol::Staircase | Protocol::PairComparison => {
            let p = trial.reference_position;
            Answer::Choice(if rng.coin() { p } else { p.other() })
        }
    };
    Response {
        answer,
        response_time_ms: rng.below(5000),
        replays: rng.below(u64::from(study.presentation.max_replays.unwrap_or(2)) + 1) as u32,
        dropped_frames: 0,
    }
}

type Log = Vec<(Trial, Response, Outcome)>;

fn drive(study: &StudyDefinition, subject: u32, answers_seed: u64) -> (Log, SessionStatus) {
    let mut session = Session::new(study, subject).unwrap();
    let mut rng = StudyRng::new(answers_seed, &[]);
    let mut log = Vec::new();
    let mut clock = 0;
    let mut ahead: Option<Vec<Trial>> = None;
    while let Some(t) = session.next_trial(clock).unwrap() {
        assert_eq!(
            session.next_trial(clock).unwrap().as_ref(),
            Some(&t),
            "next_trial is idempotent"
        );
        if let Some(ahead) = ahead.take() {
            assert!(
                ahead.contains(&t),
                "trial {} was not among the lookahead {ahead:?}",
                t.index
            );
        }
        let r = random_response(study, &t, &mut rng);
        let next_clock = clock + 10_000 + r.response_time_ms;
        let predicted = session.lookahead(next_clock);
        let branches = if study.protocol == Protocol::Staircase {
            2
        } else {
            1
        };
        assert!(predicted.len() <= branches, "{predicted:?}");
        assert_eq!(
            session.next_trial(clock).unwrap().as_ref(),
            Some(&t),
            "lookahead leaves the session as it was"
        );
        ahead = Some(predicted);
        let o = session.respond(&r).unwrap();
        clock = next_clock;
        log.push((t, r, o));
    }
    (log, session.status())
}

fn studies() -> Vec<StudyDefinition> {
    ["mos.toml", "dscqs.toml", "staircase.toml"]
        .iter()
        .map(|n| example(n))
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Same study + seed + responses -> same trials; replaying the log regenerates it.
    #[test]
    fn same_inputs_same_trials(which in 0_usize..3, subject in 0_u32..1000, answers in any::<u64>()) {
        let study = &studies()[which];
        let (a, sa) = drive(study, subject, answers);
        let (b, sb) = drive(study, subject, answers);
        prop_assert_eq!(&a, &b);
        prop_assert_eq!(sa, sb);
        prop_assert!(!a.is_empty());
        let mut replay = Session::new(study, subject).unwrap();
        for (t, r, o) in &a {
            replay.replay(t, r, o).unwrap();
        }
        prop_assert_eq!(replay.answered() as usize, a.len());
    }
}

#[test]
fn replay_detects_a_changed_study() {
    let study = example("mos.toml");
    let (log, _) = drive(&study, 3, 9);
    // The same file with another seed plans another order: replay must refuse it.
    let other = parse(&example_text("mos.toml").replace("seed = 20110512", "seed = 7")).unwrap();
    let mut s = Session::new(&other, 3).unwrap();
    let err = log
        .iter()
        .try_for_each(|(t, r, o)| s.replay(t, r, o))
        .unwrap_err();
    assert!(matches!(err, EngineError::ReplayMismatch { .. }), "{err}");
    assert!(
        err.to_string().contains("does not follow from the study"),
        "{err}"
    );
}

#[test]
fn replay_detects_an_edited_response() {
    let study = example("staircase.toml");
    let (mut log, _) = drive(&study, 1, 5);
    // Flip one logged answer: its scoring no longer matches the logged outcome.
    let (_, r, _) = &mut log[4];
    if let Answer::Choice(p) = r.answer {
        r.answer = Answer::Choice(p.other());
    }
    let mut s = Session::new(&study, 1).unwrap();
    assert!(
        log.iter()
            .try_for_each(|(t, r, o)| s.replay(t, r, o))
            .is_err()
    );
}

#[test]
fn mos_plan_follows_paper_000() {
    let study = example("mos.toml");
    assert_eq!(study.conditions.len(), 42);
    let (log, status) = drive(&study, 0, 1);
    assert_eq!(status, SessionStatus::Complete);
    assert_eq!(log.len(), 4 + 42 + 8);
    let blocks: Vec<Block> = log.iter().map(|(t, _, _)| t.block).collect();
    assert!(
        blocks[..4].iter().all(|b| *b == Block::Familiarization),
        "familiarization comes first"
    );
    assert!(blocks[4..].iter().all(|b| *b != Block::Familiarization));
    let tests: Vec<&Trial> = log
        .iter()
        .map(|(t, _, _)| t)
        .filter(|t| t.block == Block::Test)
        .collect();
    let ids: BTreeSet<&str> = tests.iter().map(|t| t.stimulus.as_str()).collect();
    assert_eq!(
        ids.len(),
        42,
        "every condition exactly once as a test trial"
    );
    for (i, (t, _, _)) in log.iter().enumerate() {
        if t.block == Block::HiddenRepeat {
            let orig = log
                .iter()
                .position(|(o, _, _)| o.block == Block::Test && o.stimulus == t.stimulus)
                .unwrap();
            assert!(
                orig.abs_diff(i) > 1,
                "repeat of {} at {i} is next to its original at {orig}",
                t.stimulus
            );
        }
        assert_eq!(t.break_before, i > 0 && i % 25 == 0);
    }
    // Familiarization spans the compression ratios (paper 000: 10:1 to 70:1).
    let fam: BTreeSet<&str> = log[..4]
        .iter()
        .map(|(t, _, _)| t.stimulus.as_str())
        .collect();
    assert!(
        fam.iter().any(|s| s.ends_with("cr10")) && fam.iter().any(|s| s.ends_with("cr70")),
        "{fam:?}"
    );
    // Shuffled per subject, sides random.
    let (other, _) = drive(&study, 1, 1);
    assert_ne!(
        log.iter().map(|(t, _, _)| &t.stimulus).collect::<Vec<_>>(),
        other
            .iter()
            .map(|(t, _, _)| &t.stimulus)
            .collect::<Vec<_>>()
    );
    let left = log
        .iter()
        .filter(|(t, _, _)| t.reference_position == Position::Left)
        .count();
    assert!(left > 10 && left < 44, "{left}");
}

#[test]
fn mos_time_limit_ends_cleanly_and_lists_the_rest() {
    let study = example("mos.toml");
    let mut s = Session::new(&study, 2).unwrap();
    let plan_len = 54;
    let mut shown = 0;
    let mut clock = 0;
    let limit = study.session.time_limit_ms.unwrap();
    assert_eq!(limit, 40 * 60_000);
    while let Some(_t) = s.next_trial(clock).unwrap() {
        s.respond(&Response {
            answer: Answer::Rating(3.5),
            response_time_ms: 0,
            replays: 0,
            dropped_frames: 0,
        })
        .unwrap();
        shown += 1;
        clock += 60_000;
    }
    assert_eq!(s.status(), SessionStatus::TimeLimit);
    assert_eq!(shown, 40);
    assert_eq!(s.not_shown().len(), plan_len - 40);
}

#[test]
fn mos_rejects_ratings_off_the_scale_and_keeps_the_trial() {
    let study = example("mos.toml");
    let mut s = Session::new(&study, 0).unwrap();
    let t = s.next_trial(0).unwrap().unwrap();
    for bad in [
        Answer::Rating(3.25),
        Answer::Rating(0.5),
        Answer::Rating(f64::NAN),
        Answer::Choice(Position::Left),
    ] {
        assert!(
            s.respond(&Response {
                answer: bad,
                response_time_ms: 1,
                replays: 0,
                dropped_frames: 0
            })
            .is_err()
        );
    }
    assert_eq!(s.next_trial(0).unwrap().unwrap(), t);
    assert!(
        s.respond(&Response {
            answer: Answer::Rating(4.5),
            response_time_ms: 1,
            replays: 0,
            dropped_frames: 0
        })
        .is_ok()
    );
}

#[test]
fn replays_beyond_the_study_limit_are_refused() {
    let study = example("dscqs.toml");
    assert_eq!(study.presentation.max_replays, Some(0));
    let mut s = Session::new(&study, 0).unwrap();
    s.next_trial(0).unwrap().unwrap();
    let r = Response {
        answer: Answer::Pair { a: 50.0, b: 60.0 },
        response_time_ms: 1,
        replays: 1,
        dropped_frames: 0,
    };
    assert!(matches!(
        s.respond(&r),
        Err(EngineError::TooManyReplays {
            replays: 1,
            max: 0,
            ..
        })
    ));
    assert!(s.respond(&Response { replays: 0, ..r }).is_ok());
}

#[test]
fn dscqs_scores_reference_minus_test_with_random_slots() {
    let study = example("dscqs.toml");
    let mut s = Session::new(&study, 0).unwrap();
    let mut slots = BTreeSet::new();
    while let Some(t) = s.next_trial(0).unwrap() {
        assert_eq!(t.arrangement, protocols::Arrangement::Abab);
        slots.insert(t.reference_position);
        let o = s
            .respond(&Response {
                answer: Answer::Pair { a: 80.0, b: 55.5 },
                response_time_ms: 1,
                replays: 0,
                dropped_frames: 0,
            })
            .unwrap();
        let (r, x) = if t.reference_position == Position::A {
            (80.0, 55.5)
        } else {
            (55.5, 80.0)
        };
        assert_eq!(o.score_reference, Some(r));
        assert_eq!(o.score_test, Some(x));
        assert!((o.score - (r - x)).abs() < 1e-12);
    }
    assert_eq!(slots.len(), 2, "A/B assigned at random");
    assert_eq!(s.status(), SessionStatus::Complete);
}

#[test]
fn staircase_interleaves_tracks_and_maps_levels_to_stimuli() {
    let study = example("staircase.toml");
    let mut s = Session::new(&study, 0).unwrap();
    let obs = Observer::new(&study, 42, 0);
    let mut per_track = [0; 2];
    let mut switches = 0;
    let mut last = None;
    while let Some(t) = s.next_trial(0).unwrap() {
        let k = t.staircase.unwrap() as usize;
        per_track[k] += 1;
        if last.is_some_and(|l| l != k) {
            switches += 1;
        }
        last = Some(k);
        let level = t.level.unwrap();
        let m = study.manifest.get(&t.stimulus).unwrap();
        assert!(
            (m.params["t_l"] - level).abs() < 1e-9,
            "{} shown for level {level}",
            t.stimulus
        );
        assert_eq!(m.clip, t.condition);
        s.respond(&obs.respond(&t).unwrap()).unwrap();
    }
    assert!(per_track.iter().all(|&n| n > 5), "{per_track:?}");
    assert!(switches > 5, "interleaved at random: {switches} switches");
    assert!(s.thresholds().iter().all(|(_, t)| t.is_some()));
}
