//! A "no preference" answer (`Position::Neither`) counts only where the screen offered it:
//! `examples/pc-ties.toml` shows a third button and scores it 1/2; `examples/pc.toml` shows
//! two and its session refuses the same answer, leaving the trial pending.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::Path;

use protocols::methods::AnswerWidget;
use protocols::{Answer, EngineError, Position, Response, Session, StudyDefinition};

fn load(name: &str) -> StudyDefinition {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name);
    StudyDefinition::load(&path, &common::TestCodecs).unwrap()
}

fn answer(answer: Answer) -> Response {
    Response {
        answer,
        response_time_ms: 900,
        replays: 0,
        dropped_frames: 0,
    }
}

fn offered(study: &StudyDefinition) -> Vec<Position> {
    match study.method().answer_widget(study) {
        AnswerWidget::Choice { options, .. } => options.iter().map(|o| o.answer).collect(),
        other => panic!("not a choice: {other:?}"),
    }
}

#[test]
fn no_preference_counts_only_where_the_screen_offered_it() {
    let ties = load("pc-ties.toml");
    assert_eq!(
        offered(&ties),
        [Position::Left, Position::Neither, Position::Right]
    );
    let mut session = Session::new(&ties, 0).unwrap();
    session.next_trial(0).unwrap().unwrap();
    let outcome = session
        .respond(&answer(Answer::Choice(Position::Neither)))
        .unwrap();
    assert!((outcome.score - 0.5).abs() < 1e-12, "{outcome:?}");
    // A position of another arrangement is no button of this screen either.
    session.next_trial(1).unwrap().unwrap();
    let wrong = session.respond(&answer(Answer::Choice(Position::First)));
    assert!(
        matches!(wrong, Err(EngineError::WrongAnswer { .. })),
        "{wrong:?}"
    );

    let forced = load("pc.toml");
    assert_eq!(offered(&forced), [Position::Left, Position::Right]);
    let mut session = Session::new(&forced, 0).unwrap();
    let trial = session.next_trial(0).unwrap().unwrap();
    let refused = session.respond(&answer(Answer::Choice(Position::Neither)));
    assert!(
        matches!(refused, Err(EngineError::WrongAnswer { trial: t, .. }) if t == trial.index),
        "{refused:?}"
    );
    // The trial is still pending: a button the screen showed answers it.
    let outcome = session
        .respond(&answer(Answer::Choice(Position::Left)))
        .unwrap();
    assert!(
        outcome.score.abs() < 1e-12 || (outcome.score - 1.0).abs() < 1e-12,
        "{outcome:?}"
    );
}
