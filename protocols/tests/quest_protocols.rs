//! QUEST+ / Psi tracks in a study: the study file's keys (every problem in one list), the
//! session as a deterministic state machine (replay regenerates it, an edited level is named),
//! and the lookahead a runner prepares stimuli from (issue 24).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use common::{QUEST, issues};
use protocols::engine::EngineError;
use protocols::{Answer, Response, Session, Trial, TrialRecord};

fn answer(t: &Trial, correct: bool) -> Response {
    Response {
        answer: Answer::Choice(if correct {
            t.reference_position
        } else {
            t.reference_position.other()
        }),
        response_time_ms: 700,
        replays: 0,
        dropped_frames: 0,
    }
}

/// A whole session, answered by a rule of the trial index; its rows.
fn run(study: &protocols::StudyDefinition, subject: u32) -> Vec<TrialRecord> {
    let mut s = Session::new(study, subject).unwrap();
    let mut rows = Vec::new();
    while let Some(t) = s.next_trial(0).unwrap() {
        let r = answer(&t, t.index % 4 != 1);
        let outcome = s.respond(&r).unwrap();
        rows.push(TrialRecord {
            study: "quest".into(),
            subject: "S1".into(),
            session: 1,
            protocol: study.protocol,
            trial: t,
            response: r,
            outcome,
            elapsed_ms: 0,
            wall_clock_ms: 0,
            monotonic_ms: 0,
            encoding: None,
            timing: None,
        });
    }
    rows
}

#[test]
fn a_quest_session_replays_exactly_and_logs_no_reversals() {
    let study = common::parse(QUEST).unwrap();
    let q = study.staircase.as_ref().unwrap().quest.as_ref().unwrap();
    assert_eq!(q.levels.len(), 20);
    assert_eq!(q.thresholds.len() * q.slopes.len() * q.lapses.len(), 360);
    let rows = run(&study, 3);
    assert_eq!(rows.len(), 48, "two tracks of 24 trials");
    assert!(rows.iter().all(|r| r.outcome.reversal.is_none()));
    assert!(rows.iter().all(|r| r.trial.stimulus.contains("primitive")));
    let levels: std::collections::BTreeSet<u64> = rows
        .iter()
        .map(|r| r.trial.level.unwrap().to_bits())
        .collect();
    assert!(levels.len() > 2, "the track moves: {levels:?}");
    let mut again = Session::new(&study, 3).unwrap();
    for r in &rows {
        again.replay(&r.trial, &r.response, &r.outcome).unwrap();
    }
    assert_eq!(again.next_trial(0).unwrap(), None);
    let thresholds = again.thresholds();
    assert!(
        thresholds
            .iter()
            .all(|(_, t)| t.is_some_and(|t| t > 0.002 && t < 0.06))
    );
    // A level edited in the log is named.
    let mut edited = rows[5].clone();
    edited.trial.level = Some(edited.trial.level.unwrap() + 0.002);
    let mut s = Session::new(&study, 3).unwrap();
    for r in &rows[..5] {
        s.replay(&r.trial, &r.response, &r.outcome).unwrap();
    }
    let err = s
        .replay(&edited.trial, &edited.response, &edited.outcome)
        .unwrap_err();
    assert!(
        matches!(
            err,
            EngineError::ReplayMismatch { field: "level", .. }
                | EngineError::ReplayMismatch {
                    field: "stimulus",
                    ..
                }
        ),
        "{err}"
    );
}

#[test]
fn the_lookahead_is_the_trial_after_each_answer() {
    let study = common::parse(QUEST).unwrap();
    let mut s = Session::new(&study, 0).unwrap();
    for i in 0..10 {
        let t = s.next_trial(0).unwrap().unwrap();
        let ahead = s.lookahead(0);
        let after = |correct: bool| {
            let mut branch = s.clone();
            branch.respond(&answer(&t, correct)).unwrap();
            branch.next_trial(0).unwrap().unwrap()
        };
        let (right, wrong) = (after(true), after(false));
        assert!(
            ahead.contains(&right) && ahead.contains(&wrong),
            "trial {i}"
        );
        assert_eq!(ahead.len(), if right == wrong { 1 } else { 2 });
        s.respond(&answer(&t, i % 3 != 0)).unwrap();
    }
}

#[test]
fn every_quest_mistake_is_reported_at_once() {
    let text = QUEST
        .replace(
            "method = \"quest_plus\"",
            "method = \"psi\"\nstart = 0.02\nn_down = 3",
        )
        .replace("max = 0.040\n", "max = 0.050\n")
        .replace(
            "slope = [1.5, 2.5, 3.5, 5]",
            "slope = [1.5, 0, 3.5]\ncolour = 1",
        )
        .replace("clip = \"dance\"", "clip = \"dance\"\nstart = 0.01");
    let got = issues(&text);
    let has = |key: &str, part: &str| got.iter().any(|(k, r)| k == key && r.contains(part));
    assert!(has("staircase.start", "up-down"), "{got:?}");
    assert!(has("staircase.n_down", "up-down"), "{got:?}");
    assert!(has("staircase.quest.colour", "unknown key"), "{got:?}");
    assert!(
        has("staircase.quest.slope", "slopes must be > 0"),
        "{got:?}"
    );
    assert!(has("staircase.quest.lapse", "Psi"), "{got:?}");
    assert!(has("staircase.tracks[1].start", "unknown key"), "{got:?}");
    assert!(has("staircase.tracks[0].clip", "0.042"), "{got:?}");
    let no_table = QUEST.split("[staircase.quest]").next().unwrap().to_owned()
        + "[[staircase.tracks]]\nname = \"walk\"\nclip = \"walk\"\n";
    let got = issues(&no_table);
    assert!(got.iter().any(|(k, _)| k == "staircase.quest"), "{got:?}");
    let up_down_with_table = QUEST.replace("method = \"quest_plus\"", "method = \"up_down\"");
    let got = issues(&up_down_with_table);
    assert!(
        got.iter()
            .any(|(k, r)| k == "staircase.quest" && r.contains("only method")),
        "{got:?}"
    );
}
