//! 2AFC staircases (thesis ch. 5: two-down-one-up; QUEST+ and Psi; live, with the codec in
//! the loop): two motions side by side, the more natural one chosen. The tracks are
//! `staircase`'s and `quest`'s, the study file's `[staircase]` `study::staircase`'s.

use std::fmt::{self, Write as _};

use super::common::{choice, describe_reference, scored};
use super::{AnswerKind, AnswerWidget, ChoiceOption, Method, Refusal, Sections};
use crate::observer::{Observer, ObserverError};
use crate::record::{Answer, Outcome, Protocol, Trial};
use crate::rng::StudyRng;
use crate::study::{Detection, RatingScale, ReferencePlacement, StudyDefinition};
use crate::texts::{AFC_QUESTION, Planned};

/// Two-alternative forced choice on staircases.
pub(super) struct Staircase;

impl Method for Staircase {
    fn protocol(&self) -> Protocol {
        Protocol::Staircase
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Choice
    }

    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        AnswerWidget::Choice {
            question: AFC_QUESTION.to_string(),
            options: ChoiceOption::positions(study.presentation.arrangement),
        }
    }

    /// The instructions, with its practice trials where it has any.
    fn instructions(&self, study: &StudyDefinition) -> String {
        let practice = match study.staircase.as_ref().map_or(0, |s| s.practice_trials) {
            0 => String::new(),
            1 => " The first trial is for practice.".to_string(),
            n => format!(" The first {n} trials are for practice."),
        };
        format!(
            "Each trial shows two motions side by side. Choose the one that looks more natural \
             with the Left or Right arrow key (or click). Answer even when you are unsure.\
             {practice}"
        )
    }

    /// An upper bound when every interleaved staircase has `max_trials`.
    fn planned_trials(&self, study: &StudyDefinition) -> Planned {
        study
            .staircase
            .as_ref()
            .and_then(|s| {
                s.tracks
                    .iter()
                    .map(|t| t.settings.max_trials)
                    .sum::<Option<u32>>()
                    .map(|n| n + s.practice_trials)
            })
            .map_or(Planned::Unknown, Planned::AtMost)
    }

    /// Each track's clip and levels (a live staircase's lines come from its stimulus
    /// source, which encodes).
    fn describe(&self, study: &StudyDefinition, text: &mut String) -> fmt::Result {
        let Some(sc) = &study.staircase else {
            return Ok(());
        };
        for t in &sc.tracks {
            writeln!(
                text,
                "  staircase {:?}: clip {:?}, {} stimulus levels of {} from {} to {}",
                t.name,
                t.clip,
                t.levels.len(),
                sc.param,
                t.levels.first().map_or(0.0, |l| l.0),
                t.levels.last().map_or(0.0, |l| l.0)
            )?;
        }
        Ok(())
    }

    fn describe_reference(&self, placement: ReferencePlacement) -> String {
        describe_reference(placement, "each block of 4 trials")
    }

    /// No plan: the tracks pick each trial (`engine`).
    fn plan(&self, _study: &StudyDefinition, _subject: u32) -> Vec<Trial> {
        Vec::new()
    }

    /// Thesis ch. 5: picking the original motion is the correct answer (score 1); the
    /// engine's track takes `correct` and adds the reversal.
    fn score(
        &self,
        trial: &Trial,
        answer: Answer,
        _scale: &RatingScale,
    ) -> Result<Outcome, Refusal> {
        let correct = choice(trial, answer)? == trial.reference_position;
        Ok(Outcome {
            correct: Some(correct),
            ..scored(if correct { 1.0 } else { 0.0 })
        })
    }

    /// The original picked with the observer's psychometric probability at the trial's
    /// level (or, with `[simulation] detection = "error"`, at the test's measured error).
    fn simulate(
        &self,
        observer: &Observer,
        trial: &Trial,
        test_error: &dyn Fn() -> Result<f64, ObserverError>,
        rng: &mut StudyRng,
    ) -> Result<Answer, ObserverError> {
        let level = trial
            .level
            .ok_or(ObserverError::NoLevel { trial: trial.index })?;
        let x = match observer.detection() {
            Detection::Level => level,
            Detection::Error => test_error()?,
        };
        let correct = rng.unit_f64() < observer.psychometric().p_correct(x);
        Ok(Answer::Choice(if correct {
            trial.reference_position
        } else {
            trial.reference_position.other()
        }))
    }

    fn adaptive(&self) -> bool {
        true
    }

    fn labels_hidden(&self) -> Option<&'static str> {
        Some("in a 2AFC trial the reference's position is what the subject must find")
    }

    fn sections(&self) -> Sections {
        Sections::Tracks
    }

    fn distinct_answers(&self, trial: &Trial, _scale: &RatingScale) -> Vec<Answer> {
        // A correct and a wrong choice move the staircase differently.
        vec![
            Answer::Choice(trial.reference_position),
            Answer::Choice(trial.reference_position.other()),
        ]
    }
}
