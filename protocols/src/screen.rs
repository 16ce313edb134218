//! What a subject sees in one trial, described once in Rust for every front end: the
//! [`Screen`] (its panes, their labels and what each shows, the answer widget and its
//! words) and its [`Schedule`] (the timed steps, the greys between them, what shows after
//! them while the subject answers, replays, and when answers open).
//!
//! The study window renders it (`window`), and it is serialized with serde for the browser
//! page; its JSON Schema ([`schema`]) is generated from these types and kept in
//! `docs/screen.schema.json`, which `protocols/tests/screen_schema.rs` checks against the
//! types, so nothing describes a screen a second time.

use schemars::JsonSchema;
use serde::Serialize;

use crate::methods::AnswerWidget;
use crate::record::{Arrangement, Position, Trial};
use crate::study::{PresentationSettings, SceneCamera, SceneLight, StudyDefinition};

/// What one step of a trial's schedule shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(tag = "show", content = "position", rename_all = "snake_case")]
pub enum Show {
    /// Both stimuli side by side: left and right.
    Both,
    /// One stimulus, full width: the one at this position.
    One(Position),
    /// The test stimulus alone, full width (a single-stimulus trial: ACR).
    Test,
    /// A mid-grey field (between sequential stimuli, and BT.500's vote).
    Grey,
    /// Every pane of a MUSHRA screen at once: the labelled reference and the lettered
    /// stimuli.
    Grid,
}

impl Show {
    /// The phase name of a frame showing this (`frames.csv`).
    pub fn phase(self) -> &'static str {
        match self {
            Show::Both => "both",
            Show::One(Position::A) => "a",
            Show::One(Position::B) => "b",
            Show::One(Position::First) => "first",
            Show::One(Position::Second) => "second",
            Show::One(Position::Left) => "left",
            Show::One(Position::Right) => "right",
            Show::One(Position::Hidden) | Show::Test => "test",
            Show::One(Position::Pane(_)) | Show::Grid => "grid",
            // Nothing is shown at Neither; a schedule never holds it.
            Show::Grey | Show::One(Position::Neither) => "grey",
        }
    }
}

/// One timed step of a schedule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, JsonSchema)]
pub struct Step {
    /// What is shown.
    #[serde(flatten)]
    pub show: Show,
    /// The label drawn above the stimulus ("A", "B", "1", "2"), if any.
    pub label: Option<&'static str>,
    /// Duration, seconds.
    pub duration_s: f64,
}

/// What the screen shows once the schedule has run, while the subject answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum After {
    /// The last step's stimuli, held at their last frame.
    Hold,
    /// The last step's stimuli, looping (`[presentation] loop`).
    Loop,
    /// A grey field with the question (sequential, single and DSCQS trials).
    Grey,
}

/// The schedule of one trial: its steps in order, what follows them, how often it may be
/// replayed. Answers open once every step has been shown (BT.500's vote after the last
/// presentation; P.910's after the stimulus), and stay open through replays.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Schedule {
    /// The steps of one pass, in order.
    pub steps: Vec<Step>,
    /// What shows after the last step.
    pub after: After,
    /// Replays allowed after the first pass (`None`: any number).
    pub max_replays: Option<u32>,
    /// When answers open, seconds from the start of the first pass: once every step has
    /// been shown.
    pub answers_open_s: f64,
}

impl Schedule {
    /// The schedule of a trial laid out as `arrangement`, under the study's presentation
    /// `settings`, for clips of `clip_s` seconds (a clip of no length counts as 1 s).
    ///
    /// Side by side: both clips together, `playback_count` times. Sequential: first, grey,
    /// second (the pair `playback_count` times, grey between). DSCQS (BT.500): A, grey, B,
    /// grey, A, grey, B, labelled "A" and "B", then the vote on grey. Single (P.910 ACR):
    /// the test alone `playback_count` times, then the vote on grey. Grid (MUSHRA): every
    /// pane together `playback_count` times, then the sliders open while the panes hold or
    /// loop. The grey lasts `grey_ms`.
    pub fn of(arrangement: Arrangement, settings: &PresentationSettings, clip_s: f64) -> Self {
        let clip_s = if clip_s.is_finite() && clip_s > 0.0 {
            clip_s
        } else {
            1.0
        };
        let gap = settings.grey_ms as f64 / 1e3;
        let plays = settings.playback_count.max(1);
        let mut steps = Vec::new();
        let step = |show, label| Step {
            show,
            label,
            duration_s: clip_s,
        };
        let grey = |steps: &mut Vec<Step>| {
            if gap > 0.0 {
                steps.push(Step {
                    show: Show::Grey,
                    label: None,
                    duration_s: gap,
                });
            }
        };
        match arrangement {
            Arrangement::SideBySide => {
                steps.extend((0..plays).map(|_| step(Show::Both, None)));
            }
            Arrangement::Grid => {
                steps.extend((0..plays).map(|_| step(Show::Grid, None)));
            }
            Arrangement::Sequential => {
                for k in 0..plays {
                    if k > 0 {
                        grey(&mut steps);
                    }
                    steps.push(step(Show::One(Position::First), Some("1")));
                    grey(&mut steps);
                    steps.push(step(Show::One(Position::Second), Some("2")));
                }
            }
            Arrangement::Single => {
                for k in 0..plays {
                    if k > 0 {
                        grey(&mut steps);
                    }
                    steps.push(step(Show::Test, None));
                }
            }
            Arrangement::Abab => {
                for (i, p) in [Position::A, Position::B, Position::A, Position::B]
                    .into_iter()
                    .enumerate()
                {
                    if i > 0 {
                        grey(&mut steps);
                    }
                    let label = if p == Position::A { "A" } else { "B" };
                    steps.push(step(Show::One(p), Some(label)));
                }
            }
        }
        let after = match arrangement {
            Arrangement::SideBySide | Arrangement::Grid if settings.loop_playback => After::Loop,
            Arrangement::SideBySide | Arrangement::Grid => After::Hold,
            Arrangement::Sequential | Arrangement::Abab | Arrangement::Single => After::Grey,
        };
        let answers_open_s = steps.iter().map(|s| s.duration_s).sum();
        Schedule {
            steps,
            after,
            max_replays: settings.max_replays,
            answers_open_s,
        }
    }

    /// Total duration of one pass, seconds.
    pub fn duration_s(&self) -> f64 {
        self.steps.iter().map(|s| s.duration_s).sum()
    }
}

/// What a pane shows.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PaneContent {
    /// One figure: the stimulus' skeleton, framed to the pane.
    Figure,
    /// A crowd scene (`[scene]`, thesis 6.5): the pane's scene of the stimulus manifest,
    /// every character placed on one ground, lit and seen through the study's camera.
    CrowdScene(CrowdScene),
}

/// A crowd scene as a pane shows it.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct CrowdScene {
    /// The distance level it was made for (`[scene] levels`).
    pub level: String,
    /// The camera every pane looks through.
    pub camera: SceneCamera,
    /// The light of every pane.
    pub light: SceneLight,
    /// The characters, in the scene's order.
    pub characters: Vec<CrowdCharacter>,
}

/// One character of a crowd scene: the stimulus it performs and where it stands.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct CrowdCharacter {
    /// Its name in the `[scene]`.
    pub name: String,
    /// The stimulus (an id of the manifest) it performs in this pane's scene.
    pub stimulus: String,
    /// Across the view, cm to the right of the camera's axis.
    pub x_cm: f64,
    /// Ahead of the camera, cm, on the scene's level.
    pub distance_cm: f64,
    /// Turn about the vertical, degrees, counter-clockwise seen from above.
    pub facing_deg: f64,
}

impl CrowdScene {
    /// The crowd scene `stimulus` of the study's manifest under its `[scene]`; `None` when
    /// the study has no scene or the stimulus is not one of its scenes (on a level it has,
    /// with its characters).
    pub fn of(study: &StudyDefinition, stimulus: &str) -> Option<Self> {
        let settings = study.scene.as_ref()?;
        let scene = study.manifest.get(stimulus)?.scene.as_ref()?;
        let level = settings.level_index(&scene.level)?;
        let characters = scene
            .characters
            .iter()
            .map(|m| {
                let c = settings.character(&m.name)?;
                let at = settings.placement(c, level);
                Some(CrowdCharacter {
                    name: m.name.clone(),
                    stimulus: m.stimulus.clone(),
                    x_cm: at.x_cm,
                    distance_cm: at.distance_cm,
                    facing_deg: at.facing_deg,
                })
            })
            .collect::<Option<Vec<_>>>()?;
        Some(CrowdScene {
            level: scene.level.clone(),
            camera: settings.camera,
            light: settings.light,
            characters,
        })
    }
}

/// One pane of a trial: where it is, what the subject reads above it, and what it shows.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Pane {
    /// Its position (left/right, first/second, A/B, the test alone, a lettered MUSHRA
    /// pane); `None` for the labelled reference of a MUSHRA screen, which no answer names.
    pub position: Option<Position>,
    /// The stimulus id it shows.
    pub stimulus: String,
    /// Whether it shows the trial's reference (never told to the subject unless `label`
    /// says so).
    pub reference: bool,
    /// Its label where the design names the stimuli (`[presentation] reference_label`,
    /// `test_label`); `None`: no label, or the schedule's step label ("A", "1").
    pub label: Option<String>,
    /// What it shows.
    pub content: PaneContent,
}

/// What a subject sees in one trial: the study's title and instructions, whether a break
/// comes first, the panes, the schedule and the answer widget.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
pub struct Screen {
    /// The study's title (never its internal name).
    pub title: String,
    /// The instructions the session opens with ([`crate::texts::instructions`]).
    pub instructions: String,
    /// Whether the session pauses for a break before this trial (`[session]
    /// break_every_trials`).
    pub break_before: bool,
    /// The panes the schedule's steps show, in position order; a single-stimulus trial has
    /// one, a MUSHRA screen's rated panes come with the trials of its screen.
    pub panes: Vec<Pane>,
    /// When each pane shows.
    pub schedule: Schedule,
    /// How the subject answers, with its words.
    pub answer: AnswerWidget,
}

impl Screen {
    /// The screen of `trial` of `study` (as the session's group runs it) with clips of
    /// `clip_s` seconds.
    pub fn of(study: &StudyDefinition, trial: &Trial, clip_s: f64) -> Self {
        let positions: &[Position] = match trial.arrangement {
            Arrangement::SideBySide => &[Position::Left, Position::Right],
            Arrangement::Sequential => &[Position::First, Position::Second],
            Arrangement::Abab => &[Position::A, Position::B],
            Arrangement::Single => &[Position::Hidden],
            Arrangement::Grid => &[],
        };
        let content = |stimulus: &str| match CrowdScene::of(study, stimulus) {
            Some(scene) => PaneContent::CrowdScene(scene),
            None => PaneContent::Figure,
        };
        let mut panes: Vec<Pane> = positions
            .iter()
            .map(|&position| {
                let reference = position == trial.reference_position;
                let label = study.presentation.labels.as_ref().map(|l| {
                    if reference {
                        l.reference.clone()
                    } else {
                        l.test.clone()
                    }
                });
                let stimulus = stimulus_at(trial, position);
                Pane {
                    position: Some(position),
                    stimulus: stimulus.to_owned(),
                    reference,
                    label,
                    content: content(stimulus),
                }
            })
            .collect();
        if trial.arrangement == Arrangement::Single {
            // The test alone: its reference is never drawn.
            panes[0].stimulus.clone_from(&trial.stimulus);
            panes[0].reference = false;
            panes[0].content = content(&trial.stimulus);
        }
        Screen {
            title: study.title().to_owned(),
            instructions: crate::texts::instructions(study),
            break_before: trial.break_before,
            panes,
            schedule: Schedule::of(trial.arrangement, &study.presentation, clip_s),
            answer: study.method().answer_widget(study),
        }
    }

    /// The screen of a MUSHRA screen's `panes` (its trials, in pane order; [`Screen::of`]
    /// for any other trial): the labelled reference first, then each pane lettered as the
    /// subject reads it ("A", "B", ...), every pane shown at once.
    pub fn of_screen(study: &StudyDefinition, panes: &[Trial], clip_s: f64) -> Option<Self> {
        let first = panes.first()?;
        let mut screen = Self::of(study, first, clip_s);
        if first.arrangement == Arrangement::Grid {
            let reference = Pane {
                position: None,
                stimulus: first.reference.clone(),
                reference: true,
                label: Some(crate::texts::MUSHRA_REFERENCE.to_owned()),
                content: PaneContent::Figure,
            };
            let lettered = panes.iter().map(|t| Pane {
                position: Some(t.reference_position),
                stimulus: t.stimulus.clone(),
                reference: false,
                label: t.reference_position.pane_letter().map(String::from),
                content: PaneContent::Figure,
            });
            screen.panes = std::iter::once(reference).chain(lettered).collect();
        }
        Some(screen)
    }

    /// The label above the stimulus at `position`, where the design names the stimuli.
    pub fn label(&self, position: Position) -> Option<&str> {
        self.panes
            .iter()
            .find(|p| p.position == Some(position))
            .and_then(|p| p.label.as_deref())
    }
}

/// The stimulus id shown at `position` of `trial`.
pub fn stimulus_at(trial: &Trial, position: Position) -> &str {
    if position == trial.reference_position {
        &trial.reference
    } else {
        &trial.stimulus
    }
}

/// The JSON Schema of [`Screen`], generated from the types (`docs/screen.schema.json`).
pub fn schema() -> serde_json::Value {
    serde_json::to_value(schemars::schema_for!(Screen)).unwrap_or_default()
}
