//! Plays a trial's [`Schedule`] (built once, for every front end, by
//! `protocols::screen::Schedule::of`) and says when its response is accepted.
//!
//! Pure (no drawing): the window asks [`Presentation::at`] what to show at the current
//! presentation time and [`Presentation::accepts_response`] whether an answer counts yet
//! (once every step has been shown, and through replays). Each frame names its phase
//! ([`Frame::phase`]), which the session's frame log records.

pub use protocols::screen::{After, Schedule, Show, Step};

/// The phase name of frames after the required presentation, while the subject answers.
pub const ANSWER_PHASE: &str = "answer";

/// What to draw at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// What is shown.
    pub show: Show,
    /// Its label.
    pub label: Option<&'static str>,
    /// Clip time to pose the stimuli at, seconds.
    pub clip_time_s: f64,
    /// True once the whole required presentation has been shown.
    pub finished: bool,
    /// True after the end of the schedule (not inside a replay).
    pub past_end: bool,
}

impl Frame {
    /// Which phase of the trial this frame belongs to: `a`, `b`, `first`, `second`, `both`,
    /// `grey`, or `answer` once the presentation is over (replays show their stimuli again).
    pub fn phase(&self) -> &'static str {
        if self.finished && self.past_end {
            ANSWER_PHASE
        } else {
            self.show.phase()
        }
    }
}

/// The schedule of one trial and where its playback stands.
#[derive(Debug, Clone, PartialEq)]
pub struct Presentation {
    steps: Vec<Step>,
    after: After,
    start_s: f64,
    shown_once: bool,
    replays: u32,
    max_replays: Option<u32>,
}

impl Presentation {
    /// `schedule` ([`Schedule`], the trial's from its [`protocols::screen::Screen`]), starting
    /// at presentation time `now_s`.
    pub fn new(schedule: Schedule, now_s: f64) -> Presentation {
        Presentation {
            steps: schedule.steps,
            after: schedule.after,
            start_s: now_s,
            shown_once: false,
            replays: 0,
            max_replays: schedule.max_replays,
        }
    }

    /// The steps.
    #[cfg(test)]
    pub fn steps(&self) -> &[Step] {
        &self.steps
    }

    /// Total duration of one pass, seconds.
    #[cfg(test)]
    pub fn duration_s(&self) -> f64 {
        self.steps.iter().map(|s| s.duration_s).sum()
    }

    /// What to draw at presentation time `now_s`; marks the presentation shown once its
    /// end has been reached.
    pub fn at(&mut self, now_s: f64) -> Frame {
        let mut t = (now_s - self.start_s).max(0.0);
        for s in &self.steps {
            if t < s.duration_s {
                return Frame {
                    show: s.show,
                    label: s.label,
                    clip_time_s: t,
                    finished: self.shown_once,
                    past_end: false,
                };
            }
            t -= s.duration_s;
        }
        self.shown_once = true;
        let last = self.steps.last().copied().unwrap_or(Step {
            show: Show::Grey,
            label: None,
            duration_s: 0.0,
        });
        let (show, clip_time_s) = match self.after {
            // Side by side and grids: keep looping (if the study says so) or hold the last
            // frame while the subject answers.
            After::Loop => (last.show, t % last.duration_s.max(1e-3)),
            After::Hold => (last.show, last.duration_s),
            // Sequential, single and DSCQS: a grey field with the voting question.
            After::Grey => (Show::Grey, 0.0),
        };
        Frame {
            show,
            label: None,
            clip_time_s,
            finished: true,
            past_end: true,
        }
    }

    /// Whether an answer counts now: only after the stimuli were shown as required.
    pub fn accepts_response(&self) -> bool {
        self.shown_once
    }

    /// Replays used.
    pub fn replays(&self) -> u32 {
        self.replays
    }

    /// Whether the study allows another replay.
    pub fn can_replay(&self) -> bool {
        self.shown_once && self.max_replays.is_none_or(|m| self.replays < m)
    }

    /// Starts the presentation again at `now_s` (a replay, once shown; answers stay allowed).
    pub fn replay(&mut self, now_s: f64) -> bool {
        if !self.can_replay() {
            return false;
        }
        self.replays += 1;
        self.start_s = now_s;
        true
    }

    /// Starts over from the beginning, as if never shown (after an experimenter pause).
    pub fn restart(&mut self, now_s: f64) {
        self.start_s = now_s;
        self.shown_once = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocols::record::{Arrangement, Block, Position, Trial};
    use protocols::screen::stimulus_at;
    use protocols::study::{PresentationSettings, ReferencePlacement};

    fn presentation(t: &Trial, s: &PresentationSettings, clip_s: f64, now_s: f64) -> Presentation {
        Presentation::new(Schedule::of(t.arrangement, s, clip_s), now_s)
    }

    fn trial(arrangement: Arrangement, reference_position: Position) -> Trial {
        Trial {
            index: 0,
            block: Block::Test,
            condition: "c".into(),
            stimulus: "test".into(),
            reference: "ref".into(),
            arrangement,
            reference_position,
            staircase: None,
            level: None,
            break_before: false,
        }
    }

    fn settings(arrangement: Arrangement, gap_ms: u64, plays: u32) -> PresentationSettings {
        PresentationSettings {
            arrangement,
            reference_position: ReferencePlacement::Random,
            playback_count: plays,
            max_replays: Some(1),
            loop_playback: false,
            gap_ms: 700,
            grey_ms: gap_ms,
            labels: None,
            stimulus_duration_ms: 2000,
            no_preference: false,
        }
    }

    #[test]
    fn dscqs_shows_a_grey_b_grey_a_grey_b_then_asks() {
        let t = trial(Arrangement::Abab, Position::B);
        let mut p = presentation(&t, &settings(Arrangement::Abab, 500, 1), 2.0, 10.0);
        let shows: Vec<(Show, Option<&str>)> =
            p.steps().iter().map(|s| (s.show, s.label)).collect();
        assert_eq!(
            shows,
            [
                (Show::One(Position::A), Some("A")),
                (Show::Grey, None),
                (Show::One(Position::B), Some("B")),
                (Show::Grey, None),
                (Show::One(Position::A), Some("A")),
                (Show::Grey, None),
                (Show::One(Position::B), Some("B")),
            ]
        );
        assert!((p.duration_s() - 9.5).abs() < 1e-12);
        assert_eq!(stimulus_at(&t, Position::B), "ref");
        assert_eq!(stimulus_at(&t, Position::A), "test");
        // A 10-12, grey 12-12.5, B 12.5-14.5, grey 14.5-15, A 15-17, grey 17-17.5, B 17.5-19.5.
        let f = p.at(10.0 + 3.25);
        assert_eq!(f.show, Show::One(Position::B));
        assert!((f.clip_time_s - 0.75).abs() < 1e-9 && !f.finished);
        assert_eq!(f.phase(), "b");
        assert_eq!(p.at(14.75).phase(), "grey");
        assert_eq!(
            p.at(17.25).phase(),
            "grey",
            "grey between the second A and B"
        );
        let f = p.at(17.6);
        assert_eq!((f.show, f.phase()), (Show::One(Position::B), "b"));
        assert!((f.clip_time_s - 0.1).abs() < 1e-9);
        assert!(!p.at(19.4).finished && !p.accepts_response());
        let f = p.at(19.51);
        assert!(f.finished && f.show == Show::Grey && p.accepts_response());
        assert_eq!(f.phase(), "answer");
        // A replay shows the stimuli again under their own phases.
        assert!(p.replay(30.0));
        assert_eq!(p.at(30.5).phase(), "a");
    }

    #[test]
    fn side_by_side_plays_the_required_count_then_holds() {
        let t = trial(Arrangement::SideBySide, Position::Left);
        let mut p = presentation(&t, &settings(Arrangement::SideBySide, 0, 2), 1.5, 0.0);
        assert_eq!(p.steps().len(), 2);
        assert!(!p.at(2.9).finished);
        assert!(!p.accepts_response());
        let f = p.at(3.2);
        assert!(f.finished && (f.clip_time_s - 1.5).abs() < 1e-12);
        assert!(p.can_replay());
        assert!(p.replay(4.0));
        // A replay keeps answers allowed but the study allows only one.
        assert!(p.accepts_response() && !p.can_replay() && !p.replay(9.0));
        assert_eq!(p.replays(), 1);
        assert!((p.at(4.5).clip_time_s - 0.5).abs() < 1e-12);
        p.restart(20.0);
        assert!(!p.accepts_response());
    }

    #[test]
    fn sequential_inserts_grey_between_the_intervals() {
        let t = trial(Arrangement::Sequential, Position::Second);
        let p = presentation(&t, &settings(Arrangement::Sequential, 300, 1), 1.0, 0.0);
        let shows: Vec<Show> = p.steps().iter().map(|s| s.show).collect();
        assert_eq!(
            shows,
            [
                Show::One(Position::First),
                Show::Grey,
                Show::One(Position::Second)
            ]
        );
        assert_eq!(stimulus_at(&t, Position::First), "test");
    }

    #[test]
    fn single_shows_the_test_alone_then_asks_on_grey() {
        let t = trial(Arrangement::Single, Position::Hidden);
        let mut p = presentation(&t, &settings(Arrangement::Single, 400, 2), 1.5, 0.0);
        let shows: Vec<Show> = p.steps().iter().map(|s| s.show).collect();
        assert_eq!(shows, [Show::Test, Show::Grey, Show::Test]);
        assert!((p.duration_s() - 3.4).abs() < 1e-12);
        let f = p.at(2.0);
        assert_eq!((f.show, f.phase()), (Show::Test, "test"));
        assert!(!p.accepts_response());
        let f = p.at(3.5);
        assert_eq!((f.show, f.phase()), (Show::Grey, "answer"));
        assert!(p.accepts_response());
    }
}
