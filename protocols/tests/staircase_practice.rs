//! Practice trials before a staircase (`[staircase] practice_trials`, `practice_level`): shown
//! first at a fixed level, the tracks in turn, logged in block `familiarization`, and moving no
//! staircase: each track's levels after them are those of the same study without practice,
//! for up-down staircases, QUEST+ tracks and a live (codec-in-the-loop) staircase alike.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::collections::BTreeMap;

use common::{LIVE, QUEST, example_text, parse};
use protocols::{Answer, Block, Response, Session, StudyDefinition, Trial};

fn with_practice(extra: &str) -> StudyDefinition {
    let text = example_text("staircase.toml").replace(
        "threshold_reversals = 3\n",
        &format!("threshold_reversals = 3\n{extra}"),
    );
    parse(&text).unwrap_or_else(|e| panic!("{e}"))
}

/// Runs subject `k` to the end; a deterministic observer is right when the level is at or
/// above `at` (wrong on every practice trial, so a practice answer that moved a staircase
/// would show). Returns the trials.
fn run(study: &StudyDefinition, k: u32, at: f64) -> Vec<Trial> {
    let mut s = Session::new(study, k).unwrap();
    let mut out = Vec::new();
    while let Some(t) = s.next_trial(0).unwrap() {
        let level = t.level.unwrap();
        let right = t.block != Block::Familiarization && level >= at - 1e-12;
        let p = t.reference_position;
        let r = Response {
            answer: Answer::Choice(if right { p } else { p.other() }),
            response_time_ms: 1,
            replays: 0,
            dropped_frames: 0,
        };
        let o = s.respond(&r).unwrap();
        if t.block == Block::Familiarization {
            assert_eq!(o.reversal, None);
            assert_eq!(o.correct, Some(false));
        }
        out.push(t);
    }
    out
}

fn track_levels(trials: &[Trial]) -> BTreeMap<String, Vec<f64>> {
    let mut out: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for t in trials.iter().filter(|t| t.block == Block::Test) {
        out.entry(t.condition.clone())
            .or_default()
            .push(t.level.unwrap());
    }
    out
}

#[test]
fn practice_comes_first_at_its_level_and_moves_no_staircase() {
    let plain = with_practice("");
    for (extra, level) in [
        ("practice_trials = 5\n", 0.024),
        ("practice_trials = 3\npractice_level = 0.04\n", 0.04),
    ] {
        let practised = with_practice(extra);
        for k in 0..4 {
            for at in [0.008, 0.013, 0.02] {
                let a = run(&practised, k, at);
                let n = practised.staircase.as_ref().unwrap().practice_trials as usize;
                for (i, t) in a.iter().take(n).enumerate() {
                    assert_eq!(t.block, Block::Familiarization);
                    assert!((t.level.unwrap() - level).abs() < 1e-12);
                    assert_eq!(t.condition, ["walk", "dance"][i % 2]);
                }
                assert!(a[n..].iter().all(|t| t.block == Block::Test));
                let b = run(&plain, k, at);
                assert_eq!(
                    track_levels(&a),
                    track_levels(&b),
                    "{extra} subject {k} at {at}"
                );
            }
        }
    }
}

/// QUEST+ tracks (whose posterior a practice answer would move) and a live staircase: the
/// practice trials come first at the practice level, the tracks in turn, and every track's
/// levels after them equal those of the same study without practice, answered alike.
#[test]
fn practice_moves_no_quest_track_and_no_live_staircase() {
    for (name, text, after, extra, level, thresholds) in [
        (
            "quest",
            QUEST,
            "max_trials = 24\n",
            "practice_trials = 4\npractice_level = 0.03\n",
            0.03,
            [0.006, 0.012, 0.02],
        ),
        (
            "live",
            LIVE,
            "max_trials = 50\n",
            "practice_trials = 3\npractice_level = 60\n",
            60.0,
            [20.0, 36.0, 52.0],
        ),
    ] {
        assert!(text.contains(after), "{name}");
        let plain = parse(text).unwrap_or_else(|e| panic!("{name}: {e}"));
        let practised = parse(&text.replace(after, &format!("{after}{extra}")))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let sc = practised.staircase.as_ref().unwrap();
        let n = sc.practice_trials as usize;
        let tracks: Vec<&str> = sc.tracks.iter().map(|t| t.name.as_str()).collect();
        for k in 0..3 {
            for at in thresholds {
                let a = run(&practised, k, at);
                for (i, t) in a.iter().take(n).enumerate() {
                    assert_eq!(t.block, Block::Familiarization, "{name}");
                    assert!((t.level.unwrap() - level).abs() < 1e-12, "{name}");
                    assert_eq!(t.condition, tracks[i % tracks.len()], "{name}");
                }
                assert!(a[n..].iter().all(|t| t.block == Block::Test), "{name}");
                let b = run(&plain, k, at);
                assert!(b.len() > 10, "{name}: {} trials", b.len());
                assert_eq!(
                    track_levels(&a),
                    track_levels(&b),
                    "{name}: subject {k} at {at}"
                );
            }
        }
    }
}

#[test]
fn a_session_with_practice_resumes_by_replay() {
    let st = with_practice("practice_trials = 4\n");
    let mut live = Session::new(&st, 2).unwrap();
    let mut log = Vec::new();
    while let Some(t) = live.next_trial(0).unwrap() {
        let r = Response {
            answer: Answer::Choice(if t.index % 3 == 0 {
                t.reference_position.other()
            } else {
                t.reference_position
            }),
            response_time_ms: 1,
            replays: 0,
            dropped_frames: 0,
        };
        let o = live.respond(&r).unwrap();
        log.push((t, r, o));
    }
    let mut again = Session::new(&st, 2).unwrap();
    for (t, r, o) in &log {
        again.replay(t, r, o).unwrap();
    }
    assert_eq!(again.next_trial(0).unwrap(), None);
    assert_eq!(again.thresholds(), live.thresholds());
}

#[test]
fn study_check_lists_practice_problems() {
    let bad = |extra: &str| {
        parse(&example_text("staircase.toml").replace(
            "threshold_reversals = 3\n",
            &format!("threshold_reversals = 3\n{extra}"),
        ))
        .unwrap_err()
        .to_string()
    };
    let e = bad("practice_trials = 2\npractice_level = 0.5\n");
    assert!(
        e.contains("staircase.practice_level: 0.5 is outside min..=max (0.002..=0.04)"),
        "{e}"
    );
    let e = bad("practice_level = 0.03\n");
    assert!(
        e.contains("staircase.practice_level: no practice trials"),
        "{e}"
    );
    let e = bad("practice_trials = 2\npractice_level = 0.0031\n");
    assert!(
        e.contains("track \"walk\" (staircase.tracks[0]) has no stimulus at practice level 0.0031"),
        "{e}"
    );
    assert!(e.contains("track \"dance\""), "{e}");
    let e = bad("practice_trials = 2000\n");
    assert!(
        e.contains("staircase.practice_trials: 2000 is outside 0..=1000"),
        "{e}"
    );
}

/// The instructions mention practice trials only where the staircase has them, by number.
#[test]
fn the_instructions_say_how_many_practice_trials_come_first() {
    let text = protocols::texts::default_instructions(&with_practice(""));
    assert!(!text.contains("practice"), "{text}");
    let text = protocols::texts::default_instructions(&with_practice("practice_trials = 3\n"));
    assert!(
        text.ends_with("The first 3 trials are for practice."),
        "{text}"
    );
    let text = protocols::texts::default_instructions(&with_practice("practice_trials = 1\n"));
    assert!(text.ends_with("The first trial is for practice."), "{text}");
}
