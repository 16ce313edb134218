//! The subject's screens: welcome (title, subject fields, consent, instructions), trials, the
//! blank gap after each answer, breaks and the end, plus the experimenter's pause. Pure egui:
//! the window wraps it in eframe and the UI tests drive it with `egui_kittest`.
//!
//! A trial's answer widgets stay disabled, and its answer keys are ignored, until the stimuli
//! have been shown as the protocol requires ([`Presentation::accepts_response`]), and while
//! the experimenter pause is open. An answer is logged (fsynced) by the [`Recorder`] before
//! the next trial is even asked for; then "Answer recorded" shows over the blank gap
//! (`gap_ms`). Where the design tells the subject which motion is the reference (MOS), the
//! study file's labels say it on screen; DSCQS and 2AFC never do.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use egui::{Align, Color32, Key, Layout, RichText, Ui, Vec2};
use protocols::methods::{AnswerWidget, ChoiceOption};
use protocols::record::{Answer, Arrangement, Block, Position, Response, Trial};
use protocols::study::{FieldKind, RatingScale, ScaleKind, SubjectField};
use protocols::{FrameTiming, StimulusEncoding, StudyDefinition};

use super::flow::{Frame, Presentation, Show};

use super::scene::{Casting, FrameShapes, Stage, View};
use super::timing::FrameClock;
use super::viewing::ViewingForm;
use lab::session::Recorder;
use lab::source::StimulusSource;
pub use protocols::texts::{ANSWER_RECORDED, default_instructions};
use protocols::texts::{Planned, categories, format_rating, grade_word, planned_trials};

/// How long the acknowledgement stays up at least, seconds (into the next trial when the
/// gap is shorter).
const ACK_S: f64 = 1.0;
/// Seconds between tries to commit an answer while the results database is unreachable.
const RETRY_S: f64 = 1.0;

/// Font size of what a subject reads (instructions, fields, consent, buttons), pixels at one
/// pixel per point: at least 14 px at 1280×720 and 1920×1080 (issue 41; the text-size test
/// in `readable_tests.rs` measures every screen).
const TEXT_PX: f32 = 18.0;
/// Font size of a scale's words (under grade buttons, beside scales and sliders), pixels.
const WORD_PX: f32 = 16.0;
/// Font size of headings (the title, "Consent"), pixels.
const HEADING_PX: f32 = 24.0;
/// Space between the parts of a screen, points.
const SPACE: f32 = 16.0;

/// The subject's text styles: nothing under [`WORD_PX`] (egui's defaults are 9 px for small
/// text and 12.5 px for the body), and radio buttons and check boxes to match.
pub(crate) fn readable(style: &mut egui::Style) {
    use egui::{FontId, TextStyle};
    style.text_styles = [
        (TextStyle::Small, FontId::proportional(WORD_PX)),
        (TextStyle::Body, FontId::proportional(TEXT_PX)),
        (TextStyle::Button, FontId::proportional(TEXT_PX)),
        (TextStyle::Heading, FontId::proportional(HEADING_PX)),
        (TextStyle::Monospace, FontId::monospace(WORD_PX)),
    ]
    .into();
    style.spacing.icon_width = 18.0;
    style.spacing.icon_width_inner = 10.0;
    style.spacing.interact_size.y = 26.0;
}

/// The end screen ignores Enter this long, seconds, so the Enter that confirmed the last
/// answer cannot close it unseen.
const END_KEY_DELAY_S: f64 = 0.7;

enum Screen {
    /// The experimenter confirms the study's viewing conditions (`[viewing]`).
    Viewing(Box<ViewingForm>),
    Welcome,
    Break,
    Trial(Box<TrialScreen>),
    /// The blank between an answer and the next trial, until this presentation time.
    Gap(f64),
    /// The results database could not take the last answer: it is kept, and committed before
    /// the next trial (tried again at `retry_at`).
    Waiting {
        /// When the outage began (presentation time).
        since: f64,
        /// When to try again.
        retry_at: f64,
        /// What the store said.
        message: String,
    },
    End(String),
    Failed(String),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pause {
    None,
    Paused,
    ConfirmQuit,
}

/// How the session window should end.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Exit {
    /// Every trial done (or the time limit reached).
    Finished(String),
    /// The experimenter quit; the session is resumable.
    Quit {
        /// Trials logged so far.
        logged: u32,
    },
    /// SIGINT or SIGTERM stopped the session; it is resumable.
    Signalled {
        /// Trials logged so far.
        logged: u32,
    },
    /// An error stopped the session (it is resumable).
    Failed(String),
}

struct TrialScreen {
    trial: Trial,
    /// What the panes show: on a MUSHRA screen the labelled reference, then one per pane of
    /// [`TrialScreen::panes`].
    shown: TrialPanes,
    /// Plays `shown.described`'s schedule.
    presentation: Presentation,
    rating: Option<f64>,
    rating_b: Option<f64>,
    /// DSCQS keyboard: number keys now rate B.
    editing_b: bool,
    gate_open_s: Option<f64>,
    /// The phase of every frame drawn since the trial's frame count started (`frames.csv`).
    phases: Vec<&'static str>,
    /// How the test stimulus was encoded for this trial (live staircase).
    encoding: Option<StimulusEncoding>,
    /// MUSHRA: the screen's trials not yet answered, in pane order (the pending one first);
    /// empty for the other protocols.
    panes: Vec<Trial>,
    /// MUSHRA: each pane's rating, `None` until the subject has set its slider.
    pane_ratings: Vec<Option<f64>>,
}

/// One answer of a MUSHRA screen waiting to be logged: its trial, the response, the screen's
/// frame timing and frame phases (the first row of a screen carries them; the others show
/// no frames of their own).
struct Queued {
    trial: Trial,
    response: Response,
    timing: Option<FrameTiming>,
    intervals: Vec<f64>,
    phases: Vec<&'static str>,
}

/// The subject's screens over one open session.
pub struct StudyUi {
    study: Arc<StudyDefinition>,
    stimuli: Box<dyn StimulusSource>,
    recorder: Box<Recorder>,
    screen: Screen,
    pause: Pause,
    exit: Option<Exit>,
    /// The welcome's subject fields and what the subject has entered or chosen.
    fields: Vec<(SubjectField, String)>,
    consent: bool,
    views: HashMap<String, View>,
    planned: Planned,
    gpu: bool,
    /// Until when "Answer recorded" stays up.
    ack_until: Option<f64>,
    /// When the end screen first showed.
    end_since: Option<f64>,
    /// The subject (or experimenter) closed the end screen.
    closed: bool,
    /// A MUSHRA screen's answers still to be logged, one row each, in pane order.
    queued: VecDeque<Queued>,
}

impl StudyUi {
    /// Screens for `recorder`'s session, showing what `stimuli` gives each trial (files, or
    /// clips encoded per trial by a live staircase). `gpu`: draw the skeletons through the
    /// wgpu paint callback (off in UI tests, which have no renderer). A resumed session shows
    /// its subject fields as entered.
    pub fn new(
        study: Arc<StudyDefinition>,
        stimuli: Box<dyn StimulusSource>,
        recorder: Box<Recorder>,
        gpu: bool,
    ) -> StudyUi {
        let fields = study
            .session
            .subject_fields
            .iter()
            .map(|f| {
                let v = recorder
                    .manifest()
                    .subject_fields
                    .get(&f.name)
                    .cloned()
                    .unwrap_or_default();
                (f.clone(), v)
            })
            .collect();
        // A between-subject group's session has its group's trials (the recorder opened it
        // with the group, so the group is the study's).
        let planned = study
            .for_group(recorder.manifest().group.as_deref())
            .map_or_else(|_| planned_trials(&study), |s| planned_trials(&s));
        // A study with viewing conditions asks the experimenter to confirm them first (once:
        // a resumed session that confirmed them goes straight to the welcome).
        let screen = match (&study.viewing, &recorder.manifest().viewing) {
            (Some(_), Some(v)) if !v.confirmed => Screen::Viewing(Box::new(ViewingForm::new(v))),
            (Some(_), None) => Screen::Viewing(Box::new(ViewingForm::new(
                &results::ViewingRecord::default(),
            ))),
            _ => Screen::Welcome,
        };
        StudyUi {
            study,
            stimuli,
            recorder,
            screen,
            pause: Pause::None,
            exit: None,
            fields,
            consent: false,
            views: HashMap::new(),
            planned,
            gpu,
            ack_until: None,
            end_since: None,
            closed: false,
            queued: VecDeque::new(),
        }
    }

    /// The session's stimulus source (UI tests wait for what it prepares).
    #[cfg(test)]
    pub fn stimuli_mut(&mut self) -> &mut dyn StimulusSource {
        self.stimuli.as_mut()
    }

    /// The study (UI tests compare texts with it).
    #[cfg(test)]
    pub fn study_for_tests(&self) -> &StudyDefinition {
        &self.study
    }

    /// Answers every subject field as simulated subject 0 would, and ticks the consent box
    /// (tests that look at the screens, not at the form).
    #[cfg(test)]
    pub fn fill_fields_for_tests(&mut self) {
        for (f, v) in &mut self.fields {
            *v = f.simulated(0);
        }
        self.consent = true;
    }

    /// Where the reference is in the trial on screen (UI tests answer right or wrong).
    #[cfg(test)]
    pub fn pending_reference(&self) -> Option<protocols::record::Position> {
        match &self.screen {
            Screen::Trial(t) => Some(t.trial.reference_position),
            _ => None,
        }
    }

    /// Set once the window should close, with why.
    pub fn exit(&self) -> Option<&Exit> {
        self.exit.as_ref()
    }

    /// The session's recorder (for the final manifest).
    pub fn recorder_mut(&mut self) -> &mut Recorder {
        &mut self.recorder
    }

    /// True while a trial presentation or the gap after it runs (the window repaints
    /// continuously then).
    pub fn animating(&self) -> bool {
        matches!(
            self.screen,
            Screen::Trial(_) | Screen::Gap(_) | Screen::Waiting { .. }
        )
    }

    /// Whether the window may close now: once the session has stopped and, when it finished
    /// or failed, the end screen was closed (Close, or Enter). An experimenter's quit or a
    /// signal closes at once. The window's close button always may, once stopped.
    pub fn may_close(&self) -> bool {
        match self.exit {
            None => false,
            Some(Exit::Quit { .. } | Exit::Signalled { .. }) => true,
            Some(Exit::Finished(_) | Exit::Failed(_)) => self.closed,
        }
    }

    /// Stops the session before its end (the experimenter quit, or a signal): the manifest
    /// is marked interrupted with the rows on disk, and the end screen says it can be resumed.
    /// Does nothing once the session has ended.
    pub fn stop(&mut self, why: Exit) {
        if self.exit.is_some() {
            return;
        }
        let logged = self.recorder.answered();
        if let Err(e) = self.recorder.interrupt() {
            self.exit = Some(Exit::Failed(format!(
                "saving the interrupted session: {}",
                lab::error::chain(&e)
            )));
            return;
        }
        self.screen = Screen::End(format!(
            "Session paused after {logged} trials; it can be resumed."
        ));
        self.exit = Some(why);
    }

    /// The window's close button: asks for confirmation instead of closing mid-session.
    /// Returns true when the window may close now.
    pub fn close_requested(&mut self) -> bool {
        if self.exit.is_some() {
            return true;
        }
        self.pause = Pause::ConfirmQuit;
        false
    }

    /// The screen shown, by a name a test's input script waits for
    /// ([`super::test_input`]): `viewing`, `welcome` (Begin not yet possible: the display is
    /// being measured or the stimuli checked), `welcome/ready` (Begin takes once the fields
    /// and consent are done), `break`, `trial/playing #N` (trial N, answers not yet taken),
    /// `trial/open #N` (answers taken), `gap`, `waiting` (the results database is away),
    /// `end` (a stop, or the end before Enter may close it), `end/ready` (Enter closes it),
    /// `failed`; `paused` or `confirm-quit` while the experimenter's dialog is open. `now`
    /// is the presentation time of the frame just drawn.
    pub fn screen(&self, now: f64, clock: &FrameClock) -> String {
        match self.pause {
            Pause::Paused => return "paused".into(),
            Pause::ConfirmQuit => return "confirm-quit".into(),
            Pause::None => {}
        }
        match &self.screen {
            Screen::Viewing(_) => "viewing".into(),
            Screen::Welcome => {
                let measured = clock.calibrated() || !self.gpu;
                if measured {
                    "welcome/ready".into()
                } else {
                    "welcome".into()
                }
            }
            Screen::Break => "break".into(),
            Screen::Trial(t) => {
                let phase = if t.presentation.accepts_response() {
                    "open"
                } else {
                    "playing"
                };
                format!("trial/{phase} #{}", t.trial.index)
            }
            Screen::Gap(_) => "gap".into(),
            Screen::Waiting { .. } => "waiting".into(),
            Screen::End(_) => {
                let closable = matches!(self.exit, Some(Exit::Finished(_) | Exit::Failed(_)));
                if closable && self.end_since.is_some_and(|s| now - s >= END_KEY_DELAY_S) {
                    "end/ready".into()
                } else {
                    "end".into()
                }
            }
            Screen::Failed(_) => "failed".into(),
        }
    }

    /// Draws the current screen and handles its input; `clock` is the window's frame clock
    /// (trial timing is read from it).
    pub fn ui(&mut self, ui: &mut Ui, clock: &mut FrameClock) {
        readable(ui.style_mut());
        let now = ui.input(|i| i.time);
        let chord = ui.input(|i| super::native::ctrl_shift_pressed(i, Key::P));
        if chord && self.pause == Pause::None && self.exit.is_none() {
            self.pause = Pause::Paused;
        }
        let active = self.pause == Pause::None;
        match &self.screen {
            Screen::Viewing(_) => self.viewing_screen(ui, active),
            Screen::Welcome => self.welcome(ui, now, active, clock),
            Screen::Break => self.break_screen(ui, now, active, clock),
            Screen::Trial(_) => self.trial_screen(ui, now, active, clock),
            &Screen::Gap(until) => self.gap_screen(ui, now, until, clock),
            Screen::Waiting { .. } => self.waiting_screen(ui, now, clock),
            Screen::End(text) | Screen::Failed(text) => {
                let text = text.clone();
                self.end_screen(ui, now, &text, active);
            }
        }
        if self.pause != Pause::None {
            self.pause_dialog(ui, now, clock);
        }
    }

    fn viewing_screen(&mut self, ui: &mut Ui, active: bool) {
        let (Screen::Viewing(form), Some(targets)) = (&mut self.screen, &self.study.viewing) else {
            return;
        };
        let now_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64);
        let Some(record) = form.ui(ui, targets, active, now_ms) else {
            return;
        };
        match self.recorder.update_manifest(|m| m.viewing = Some(record)) {
            Ok(()) => self.screen = Screen::Welcome,
            Err(e) => self.fail(&e),
        }
    }

    fn welcome(&mut self, ui: &mut Ui, now: f64, active: bool, clock: &mut FrameClock) {
        let mut begin = false;
        egui::CentralPanel::default().show(ui, |ui| {
            ui.vertical_centered(|ui| {
                ui.add_space(SPACE);
                ui.heading(self.study.title());
                if self.recorder.answered() > 0 {
                    ui.add_space(SPACE / 2.0);
                    ui.label(format!(
                        "Continuing the session: {} trials already done.",
                        self.recorder.answered()
                    ));
                }
            });
            ui.add_space(SPACE);
            let instructions = protocols::texts::instructions(&self.study);
            ui.label(RichText::new(instructions).size(TEXT_PX));
            ui.add_space(SPACE);
            if !self.fields.is_empty() {
                subject_fields(ui, &mut self.fields, active);
                ui.add_space(SPACE);
            }
            if let Some(consent) = &self.study.session.consent {
                ui.label(RichText::new("Consent").strong().size(HEADING_PX));
                ui.label(RichText::new(consent).size(TEXT_PX));
                ui.add_enabled(
                    active,
                    egui::Checkbox::new(
                        &mut self.consent,
                        RichText::new("I agree to take part").size(TEXT_PX),
                    ),
                );
                ui.add_space(SPACE);
            }
            let missing = self.missing_to_begin();
            let ready = missing.is_empty();
            // Trials start once the refresh period is known, so every trial's drop count is
            // against the measured period.
            let measured = clock.calibrated() || !self.gpu;
            ui.vertical_centered(|ui| {
                let button = egui::Button::new(RichText::new("Begin").size(20.0))
                    .min_size(Vec2::new(160.0, 44.0));
                let can = active && ready && measured;
                if ui.add_enabled(can, button).clicked()
                    || (can && ui.input(|i| i.key_pressed(Key::Enter)))
                {
                    begin = true;
                }
                for line in &missing {
                    ui.label(RichText::new(line).size(TEXT_PX));
                }
                if ready && !measured {
                    ui.label("Measuring the display…");
                }
            });
        });
        if begin {
            // Each field as its check writes it (Begin is only enabled when all pass).
            let fields: Vec<(String, String)> = self
                .fields
                .iter()
                .filter_map(|(f, v)| f.check(v).ok().map(|v| (f.name.clone(), v)))
                .collect();
            let consent = self.consent;
            let saved = self.recorder.update_manifest(|m| {
                m.subject_fields.extend(fields);
                if consent {
                    m.subject_fields.insert("consent".into(), "given".into());
                }
            });
            match saved {
                Ok(()) => self.advance(now, clock),
                Err(e) => self.fail(&e),
            }
        }
    }

    /// What the subject still has to do before Begin, a line each: why each field's answer
    /// is refused ([`SubjectField::check`]: "age: enter a whole number from 18 to 99"), and
    /// the consent box; empty when nothing.
    fn missing_to_begin(&self) -> Vec<String> {
        let mut todo: Vec<String> = self
            .fields
            .iter()
            .filter_map(|(f, v)| f.check(v).err())
            .collect();
        if self.study.session.consent.is_some() && !self.consent {
            todo.push("To begin, tick “I agree to take part”.".to_string());
        }
        todo
    }

    fn break_screen(&mut self, ui: &mut Ui, now: f64, active: bool, clock: &mut FrameClock) {
        let mut go = false;
        let done = self.recorder.answered();
        let planned = self.planned;
        egui::CentralPanel::default().show(ui, |ui| {
            ui.vertical_centered(|ui| {
                ui.add_space(ui.available_height() * 0.3);
                ui.heading("Take a short break.");
                ui.label(planned.done_text(done));
                if let Some(n) = planned.exact() {
                    ui.add(
                        egui::ProgressBar::new(done as f32 / n as f32)
                            .desired_width(320.0)
                            .show_percentage(),
                    );
                }
                ui.label("Continue when you are ready.");
                ui.add_space(16.0);
                go = ui
                    .add_enabled(active, egui::Button::new("Continue"))
                    .clicked()
                    || (active && ui.input(|i| i.key_pressed(Key::Enter)));
            });
        });
        if go {
            self.start_trial(now, false, clock);
        }
    }

    /// The blank between trials: mid-grey where the stimuli were, the progress panel saying
    /// the answer was recorded; then the next trial (or a break, or the end).
    fn gap_screen(&mut self, ui: &mut Ui, now: f64, until: f64, clock: &mut FrameClock) {
        let done = self.recorder.answered();
        egui::Panel::top("progress").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.label(RichText::new(format!("{ANSWER_RECORDED}.")).strong());
                ui.label(self.planned.done_text(done));
            });
        });
        egui::CentralPanel::default()
            .frame(egui::Frame::new().fill(Color32::from_gray(96)))
            .show(ui, |_| {});
        if now >= until {
            self.start_trial(now, true, clock);
        }
    }

    /// The end (or a stop): stays until the subject closes it (Close, or Enter once it has
    /// been up a moment) or the window is closed.
    fn end_screen(&mut self, ui: &mut Ui, now: f64, text: &str, active: bool) {
        let since = *self.end_since.get_or_insert(now);
        let closable = matches!(self.exit, Some(Exit::Finished(_) | Exit::Failed(_)));
        let mut close = false;
        egui::CentralPanel::default().show(ui, |ui| {
            ui.vertical_centered(|ui| {
                ui.add_space(ui.available_height() * 0.35);
                ui.heading(text);
                if closable {
                    ui.add_space(16.0);
                    close = ui
                        .add_enabled(active, egui::Button::new(RichText::new("Close").size(18.0)))
                        .clicked()
                        || (active
                            && now - since >= END_KEY_DELAY_S
                            && ui.input(|i| i.key_pressed(Key::Enter)));
                }
            });
        });
        if close {
            self.closed = true;
        }
    }

    fn fail(&mut self, e: &(dyn std::error::Error + 'static)) {
        let text = lab::error::chain(e);
        self.screen = Screen::Failed(format!("The session stopped: {text}"));
        self.exit = Some(Exit::Failed(text));
    }

    /// Asks the engine for the next trial (after logging the previous answer).
    fn advance(&mut self, now: f64, clock: &mut FrameClock) {
        self.start_trial(now, true, clock);
    }

    fn start_trial(&mut self, now: f64, allow_break: bool, clock: &mut FrameClock) {
        let elapsed = self.recorder.elapsed_ms();
        let next = match self.recorder.next_trial(elapsed) {
            Ok(n) => n,
            Err(e) => return self.fail(&e),
        };
        let Some(trial) = next else {
            return match self.recorder.finish() {
                Ok(_) => {
                    let text = "The session is complete. Thank you!".to_string();
                    self.exit = Some(Exit::Finished(self.recorder.summary()));
                    self.screen = Screen::End(text);
                }
                Err(e) => self.fail(&e),
            };
        };
        if allow_break && trial.break_before {
            self.screen = Screen::Break;
            return;
        }
        match self.load_trial(trial, now) {
            Ok(t) => {
                clock.start_segment();
                self.screen = Screen::Trial(Box::new(t));
            }
            Err(e) => self.fail(&e),
        }
    }

    fn load_trial(&mut self, trial: Trial, now: f64) -> lab::Result<TrialScreen> {
        if trial.arrangement == Arrangement::Grid {
            return self.load_grid(trial, now);
        }
        // A live trial's test stimulus is encoded now unless it was prepared (cached by
        // level); others are files.
        let shown = self.stimuli.stimuli(&trial)?;
        // While the subject watches this trial, prepare the stimuli a correct and a wrong
        // answer lead to, so the next trial starts without waiting for the codec.
        self.stimuli
            .prepare(&self.recorder.lookahead(self.recorder.elapsed_ms()));
        let views = &mut self.views;
        let panes = TrialPanes::of_trial(&self.study, &trial, &shown, &mut |id, clip| {
            *views
                .entry(id.to_owned())
                .or_insert_with(|| View::framing(clip))
        })?;
        let presentation = Presentation::new(panes.described.schedule.clone(), now);
        Ok(TrialScreen {
            trial,
            shown: panes,
            presentation,
            rating: None,
            rating_b: None,
            editing_b: false,
            gate_open_s: None,
            phases: Vec::new(),
            encoding: shown.encoding,
            panes: Vec::new(),
            pane_ratings: Vec::new(),
        })
    }

    /// A MUSHRA screen: the labelled reference and the screen's panes not yet answered (all
    /// of them, unless a resumed session stopped inside the screen), each its own figure.
    fn load_grid(&mut self, trial: Trial, now: f64) -> lab::Result<TrialScreen> {
        let mut panes = self.recorder.screen();
        if panes.first() != Some(&trial) {
            panes = vec![trial.clone()];
        }
        let mut reference = None;
        let mut clips = Vec::with_capacity(panes.len());
        for p in &panes {
            let shown = self.stimuli.stimuli(p)?;
            reference.get_or_insert(shown.reference);
            clips.push((p.stimulus.as_str(), shown.test));
        }
        let Some(reference) = reference else {
            return Err(lab::LabError::Refused(
                "a MUSHRA screen without panes".into(),
            ));
        };
        let view = *self
            .views
            .entry(trial.reference.clone())
            .or_insert_with(|| View::framing(&reference));
        let clips: Vec<(&str, &Arc<motion::Clip>)> = clips.iter().map(|(id, c)| (*id, c)).collect();
        let cast = Casting::grid(&self.study, view, (&trial.reference, &reference), &clips);
        let (view, stages) = (cast.view, cast.stages());
        let described =
            protocols::screen::Screen::of_screen(&self.study, &panes, cast.duration_s())
                .map(Arc::new)
                .ok_or_else(|| lab::LabError::Refused("a MUSHRA screen without panes".into()))?;
        let presentation = Presentation::new(described.schedule.clone(), now);
        Ok(TrialScreen {
            trial,
            shown: TrialPanes::new(described, Position::Pane(0), &view, stages),
            presentation,
            rating: None,
            rating_b: None,
            editing_b: false,
            gate_open_s: None,
            phases: Vec::new(),
            encoding: None,
            pane_ratings: vec![None; panes.len()],
            panes,
        })
    }

    /// One frame of the trial on screen: progress, the protocol's answer widgets and the
    /// stimuli; an answer is logged before the next trial starts.
    fn trial_screen(&mut self, ui: &mut Ui, now: f64, active: bool, clock: &mut FrameClock) {
        let Screen::Trial(t) = &mut self.screen else {
            return;
        };
        let frame = t.presentation.at(now);
        if frame.finished && t.gate_open_s.is_none() {
            t.gate_open_s = Some(now);
        }
        let open = active && t.presentation.accepts_response();
        let ack = self.ack_until.is_some_and(|u| now < u);
        progress_panel(ui, t, self.recorder.answered(), self.planned, ack);
        let scale = &self.study.scale;
        let (answer, replay) = egui::Panel::bottom("answer")
            .min_size(150.0)
            .resizable(false)
            .show(ui, |ui| {
                ui.add_space(8.0);
                let answer = ui
                    .vertical_centered(|ui| {
                        let described = Arc::clone(&t.shown.described);
                        answer(ui, &described.answer, t, scale, open)
                    })
                    .inner;
                (answer, replay_row(ui, t, active))
            })
            .inner;
        stimuli_panel(ui, &mut t.shown, &frame, self.gpu);
        // One phase per frame, as the clock keeps one interval per frame (frames.csv).
        t.phases.push(frame.phase());
        if replay {
            t.presentation.replay(now);
        }
        let Some(answer) = answer else {
            return;
        };
        let response_time_ms = t
            .gate_open_s
            .map_or(0, |g| ((now - g).max(0.0) * 1e3) as u64);
        let stats = clock.end_segment();
        let response = Response {
            answer,
            response_time_ms,
            replays: t.presentation.replays(),
            dropped_frames: stats.dropped,
        };
        // Timing is only known once the refresh period was measured (always, in the window:
        // trials start after it).
        let timing = clock.calibrated().then_some(FrameTiming {
            frames_shown: stats.frames,
            interval_sd_ms: stats.sd_ms,
        });
        let (trial, encoding) = (t.trial.clone(), t.encoding.take());
        let phases = std::mem::take(&mut t.phases);
        if trial.arrangement == Arrangement::Grid {
            // One row per pane, in pane order; the first carries the screen's frames.
            let ratings: Vec<f64> = t.pane_ratings.iter().map(|r| r.unwrap_or(0.0)).collect();
            let panes = std::mem::take(&mut t.panes);
            let intervals = clock.segment_intervals().to_vec();
            let mut first = true;
            for (trial, rating) in panes.into_iter().zip(ratings) {
                let answer = Answer::Rating(rating);
                self.queued.push_back(Queued {
                    trial,
                    response: Response {
                        answer,
                        dropped_frames: if first { response.dropped_frames } else { 0 },
                        ..response
                    },
                    timing: timing.map(|tm| {
                        if first {
                            tm
                        } else {
                            FrameTiming {
                                frames_shown: 0,
                                interval_sd_ms: 0.0,
                            }
                        }
                    }),
                    intervals: if first { intervals.clone() } else { Vec::new() },
                    phases: if first { phases.clone() } else { Vec::new() },
                });
                first = false;
            }
            return self.log_queued(now, clock);
        }
        let intervals = clock.segment_intervals().to_vec();
        match self.log_answer(trial, response, encoding, timing, &intervals, &phases) {
            Ok(()) => self.answered(now, clock),
            Err(e) if lab::session::is_outage(&e) => {
                self.screen = Screen::Waiting {
                    since: now,
                    retry_at: now + RETRY_S,
                    message: lab::error::chain(&e),
                };
            }
            Err(e) => self.fail(&e),
        }
    }

    /// Logs a MUSHRA screen's queued answers one row at a time (each committed before the
    /// next is asked for); an outage waits with the rest queued, then goes on from there.
    fn log_queued(&mut self, now: f64, clock: &mut FrameClock) {
        while let Some(q) = self.queued.pop_front() {
            // The engine's pending trial must be this pane's (the next of its screen).
            match self.recorder.next_trial(self.recorder.elapsed_ms()) {
                Ok(Some(t)) if t == q.trial => {}
                Ok(other) => {
                    let e = lab::LabError::Refused(format!(
                        "MUSHRA pane {} (trial {}) answered, but the session's next trial is {:?}",
                        q.trial.reference_position,
                        q.trial.index,
                        other.map(|t| t.index)
                    ));
                    return self.fail(&e);
                }
                Err(e) => return self.fail(&e),
            }
            let logged =
                self.log_answer(q.trial, q.response, None, q.timing, &q.intervals, &q.phases);
            match logged {
                Ok(()) => {}
                Err(e) if lab::session::is_outage(&e) => {
                    self.screen = Screen::Waiting {
                        since: now,
                        retry_at: now + RETRY_S,
                        message: lab::error::chain(&e),
                    };
                    return;
                }
                Err(e) => return self.fail(&e),
            }
        }
        self.answered(now, clock);
    }

    /// After an answer is committed: the documented gap between trials, as a blank with the
    /// acknowledgement (which stays a moment into the next trial when the gap is shorter).
    fn answered(&mut self, now: f64, clock: &mut FrameClock) {
        let gap = self.study.presentation.gap_ms as f64 / 1e3;
        self.ack_until = Some(now + gap.max(ACK_S));
        if gap > 0.0 {
            self.screen = Screen::Gap(now + gap);
        } else {
            self.advance(now, clock);
        }
    }

    /// The results database went away with an answer uncommitted: says so, and tries again
    /// every [`RETRY_S`] until it is back; then the session goes on.
    fn waiting_screen(&mut self, ui: &mut Ui, now: f64, clock: &mut FrameClock) {
        let Screen::Waiting {
            since,
            retry_at,
            message,
        } = &self.screen
        else {
            return;
        };
        let (since, retry_at) = (*since, *retry_at);
        let waited = now - since;
        egui::CentralPanel::default().show(ui, |ui| {
            ui.vertical_centered(|ui| {
                ui.add_space(ui.available_height() * 0.3);
                ui.heading("The results database cannot be reached");
                ui.add_space(8.0);
                ui.label(format!(
                    "The last answer is kept and will be saved as soon as it is back; the next \
                     trial waits for it. Waiting for {waited:.0} s."
                ));
                ui.add_space(8.0);
                ui.label(RichText::new(message.as_str()).small());
            });
        });
        if now < retry_at {
            return;
        }
        match self.recorder.commit_pending() {
            Ok(()) => self.log_queued(now, clock),
            Err(e) if lab::session::is_outage(&e) => {
                self.screen = Screen::Waiting {
                    since,
                    retry_at: now + RETRY_S,
                    message: lab::error::chain(&e),
                };
            }
            Err(e) => self.fail(&e),
        }
    }

    /// Logs an answer (fsynced) and, when the display was measured, the trial's frame
    /// intervals with the phase each frame showed.
    fn log_answer(
        &mut self,
        trial: Trial,
        response: Response,
        encoding: Option<StimulusEncoding>,
        timing: Option<FrameTiming>,
        intervals: &[f64],
        phases: &[&str],
    ) -> lab::Result<()> {
        let elapsed = self.recorder.elapsed_ms();
        let index = trial.index;
        let recorded = self
            .recorder
            .record(trial, response, elapsed, encoding, timing);
        if let Err(e) = recorded {
            if !lab::session::is_outage(&e) {
                return Err(e);
            }
            // Kept with the answer until the database is back.
            if timing.is_some() {
                self.recorder
                    .append_frame_intervals(index, intervals, phases)?;
            }
            return Err(e);
        }
        if timing.is_some() {
            self.recorder
                .append_frame_intervals(index, intervals, phases)?;
        }
        Ok(())
    }

    fn pause_dialog(&mut self, ui: &mut Ui, now: f64, clock: &mut FrameClock) {
        let ctx = ui.ctx().clone();
        let logged = self.recorder.answered();
        egui::Modal::new(ui.scope_id().with("experimenter pause")).show(&ctx, |ui| {
            ui.set_width(420.0);
            match self.pause {
                Pause::Paused => {
                    ui.heading("Paused by the experimenter");
                    ui.label(format!("{logged} trials are saved."));
                    ui.horizontal(|ui| {
                        if ui.button("Resume").clicked() {
                            self.pause = Pause::None;
                            self.restart_presentation(now, clock);
                        }
                        if ui.button("Quit session…").clicked() {
                            self.pause = Pause::ConfirmQuit;
                        }
                    });
                }
                Pause::ConfirmQuit | Pause::None => {
                    ui.heading("Quit the session?");
                    ui.label(format!(
                        "{logged} trials are saved. The session can be continued later with \
                         `study run … --resume`."
                    ));
                    ui.horizontal(|ui| {
                        if ui.button("Quit and save").clicked() {
                            self.pause = Pause::None;
                            self.stop(Exit::Quit { logged });
                        }
                        if ui.button("Back").clicked() {
                            self.pause = Pause::None;
                            self.restart_presentation(now, clock);
                        }
                    });
                }
            }
        });
    }

    /// After a pause the current trial is shown again from the start, as if new: the subject's
    /// view was interrupted, so the answer gate closes again.
    fn restart_presentation(&mut self, now: f64, clock: &mut FrameClock) {
        if let Screen::Trial(t) = &mut self.screen {
            t.presentation.restart(now);
            t.gate_open_s = None;
            t.phases.clear();
            clock.start_segment();
            clock.reset_last();
        }
    }
}

/// The welcome's subject fields, a row each: the label, then a text box (text, numbers) or a
/// radio button per option (a choice; yes or no). A field shows what is stored for it, so a
/// resumed session shows the answers given.
fn subject_fields(ui: &mut Ui, fields: &mut [(SubjectField, String)], active: bool) {
    egui::Grid::new("subject fields")
        .num_columns(2)
        .spacing(Vec2::new(SPACE, 10.0))
        .show(ui, |ui| {
            for (field, value) in fields.iter_mut() {
                let label = ui.label(RichText::new(&field.label).size(TEXT_PX));
                let options = field.options();
                if options.is_empty() {
                    let mut edit = egui::TextEdit::singleline(value).desired_width(320.0);
                    if matches!(field.kind, FieldKind::Number { .. }) {
                        edit = edit.hint_text(field.hint());
                    }
                    ui.add_enabled(active, edit).labelled_by(label.id);
                } else {
                    let chosen = field.check(value).ok();
                    ui.horizontal_wrapped(|ui| {
                        ui.spacing_mut().item_spacing.x = SPACE;
                        for option in options {
                            let shown = match field.kind {
                                FieldKind::YesNo => capitalized(&option),
                                _ => option.clone(),
                            };
                            let on = chosen.as_deref() == Some(option.as_str());
                            let radio = egui::RadioButton::new(on, RichText::new(shown));
                            if ui.add_enabled(active, radio).clicked() {
                                *value = option;
                            }
                        }
                    });
                }
                ui.end_row();
            }
        });
}

/// `s` with its first letter in upper case ("yes" → "Yes").
fn capitalized(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().chain(c).collect())
        .unwrap_or_default()
}

/// Rating buttons of a categorical scale, or a slider for a continuous one.
fn rating_row(
    ui: &mut Ui,
    scale: &RatingScale,
    words: &[String],
    value: &mut Option<f64>,
    open: bool,
    id: &str,
) {
    match scale.kind {
        ScaleKind::Categorical => {
            let cats = categories(scale);
            let labels: Vec<Option<&str>> =
                cats.iter().map(|&v| grade_word(words, scale, v)).collect();
            // Every grade gets a column of the same width, its button centred over its word
            // (wrapped when the row would not fit), so the buttons are evenly spaced however
            // long their words are.
            let font = egui::FontId::proportional(WORD_PX);
            let widest = labels
                .iter()
                .flatten()
                .map(|l| {
                    ui.painter()
                        .layout_no_wrap((*l).to_string(), font.clone(), Color32::WHITE)
                        .size()
                        .x
                })
                .fold(0.0, f32::max);
            let n = cats.len().max(1) as f32;
            let gap = 8.0;
            let fit = (ui.available_width() - gap * (n - 1.0)) / n;
            let col = (widest + 12.0).max(56.0).min(fit.max(56.0));
            // Top-aligned: the buttons stay on one line whatever their words' heights.
            ui.horizontal_top(|ui| {
                ui.spacing_mut().item_spacing.x = gap;
                ui.add_space(((ui.available_width() - n * col - gap * (n - 1.0)) * 0.5).max(0.0));
                for (v, label) in cats.into_iter().zip(labels) {
                    ui.allocate_ui_with_layout(
                        Vec2::new(col, 0.0),
                        Layout::top_down(Align::Center),
                        |ui| {
                            ui.set_width(col);
                            let text = RichText::new(format_rating(v)).size(TEXT_PX);
                            let button = egui::Button::new(text)
                                .selected(*value == Some(v))
                                .min_size(Vec2::new(48.0, 36.0));
                            if ui.add_enabled(open, button).clicked() {
                                *value = Some(v);
                            }
                            if let Some(label) = label {
                                ui.add(
                                    egui::Label::new(RichText::new(label).size(WORD_PX))
                                        .halign(Align::Center)
                                        .wrap(),
                                );
                            }
                        },
                    );
                }
            });
        }
        ScaleKind::Continuous => {
            vertical_scale(ui, scale, words, value, open, false, id);
        }
    }
}

/// Height of a continuous scale, points: BT.500's scale is about 10 cm; on a small window
/// it is what fits.
fn scale_height(ui: &Ui) -> f32 {
    (ui.ctx().content_rect().height() * 0.35).clamp(150.0, 380.0)
}

/// The value on a continuous scale at `y` in a bar spanning `top..bottom`, rounded to the
/// scale's step, or to a hundredth of its range (whole numbers on BT.500's 0-100).
fn scale_value_at(scale: &RatingScale, y: f32, top: f32, bottom: f32) -> f64 {
    let f = f64::from(((bottom - y) / (bottom - top).max(1.0)).clamp(0.0, 1.0));
    let v = scale.min + f * (scale.max - scale.min);
    if scale.step.is_some() {
        scale.snap(v)
    } else {
        let q = (scale.max - scale.min) / 100.0;
        (scale.min + ((v - scale.min) / q).round() * q).clamp(scale.min, scale.max)
    }
}

/// One BT.500 continuous quality scale: a vertical bar divided into five equal sections,
/// Excellent at the top to Bad at the bottom, named `name` above it. It carries no mark
/// until the subject places one (click or drag; keys in [`keyboard_continuous`]); `active`
/// outlines it as the one the keys move. Screen readers see a slider named `name` whose
/// value is absent until marked.
fn vertical_scale(
    ui: &mut Ui,
    scale: &RatingScale,
    words: &[String],
    value: &mut Option<f64>,
    open: bool,
    active: bool,
    name: &str,
) -> egui::Response {
    let h = scale_height(ui);
    ui.vertical(|ui| {
        ui.label(RichText::new(name).strong().size(20.0));
        let (rect, _) = ui.allocate_exact_size(Vec2::new(190.0, h + 16.0), egui::Sense::hover());
        let bar = egui::Rect::from_min_size(
            egui::pos2(rect.right() - 60.0, rect.top() + 8.0),
            Vec2::new(44.0, h),
        );
        let id = ui.scope_id().with(("quality scale", name));
        let sense = if open {
            egui::Sense::click_and_drag()
        } else {
            egui::Sense::hover()
        };
        let response = ui.interact(bar.expand(8.0), id, sense);
        if open
            && (response.clicked() || response.dragged())
            && let Some(pos) = response
                .interact_pointer_pos()
                .or_else(|| ui.input(|i| i.pointer.latest_pos()))
        {
            *value = Some(scale_value_at(scale, pos.y, bar.top(), bar.bottom()));
        }
        let visuals = ui.visuals();
        let text = if open {
            visuals.text_color()
        } else {
            visuals.weak_text_color()
        };
        let painter = ui.painter();
        painter.rect_filled(bar, 2.0, visuals.extreme_bg_color);
        let section = h / words.len().max(1) as f32;
        for (k, label) in words.iter().enumerate() {
            let y = bar.top() + section * k as f32;
            if k > 0 {
                painter.hline(bar.x_range(), y, egui::Stroke::new(1.0, text));
            }
            painter.text(
                egui::pos2(bar.left() - 10.0, y + section * 0.5),
                egui::Align2::RIGHT_CENTER,
                label,
                egui::FontId::proportional(16.0),
                text,
            );
        }
        let outline = if active && open {
            egui::Stroke::new(3.0, visuals.selection.stroke.color)
        } else {
            egui::Stroke::new(1.5, text)
        };
        painter.rect_stroke(bar, 2.0, outline, egui::StrokeKind::Outside);
        if let Some(v) = *value {
            let f = ((v - scale.min) / (scale.max - scale.min)).clamp(0.0, 1.0) as f32;
            let y = bar.bottom() - f * h;
            let mark = Color32::from_rgb(230, 80, 40);
            painter.hline(
                (bar.left() - 6.0)..=(bar.right() + 6.0),
                y,
                egui::Stroke::new(4.0, mark),
            );
            painter.add(egui::Shape::convex_polygon(
                vec![
                    egui::pos2(bar.right() + 6.0, y),
                    egui::pos2(bar.right() + 16.0, y - 7.0),
                    egui::pos2(bar.right() + 16.0, y + 7.0),
                ],
                mark,
                egui::Stroke::NONE,
            ));
        }
        let marked = *value;
        response.widget_info(|| {
            let mut info = egui::WidgetInfo::labeled(egui::accesskit::Role::Slider, open, name);
            info.value = marked;
            info
        });
        response
    })
    .inner
}

/// Keys of a continuous scale: 1-5 place the mark in the middle of Bad … Excellent, ↑/↓
/// move it by one hundredth of the range (or the step), Page Up/Down by a tenth; true when a
/// number key was used.
fn keyboard_continuous(ui: &Ui, scale: &RatingScale, value: &mut Option<f64>) -> bool {
    let range = scale.max - scale.min;
    let fine = scale.step.unwrap_or(range / 100.0);
    let mut digit = false;
    ui.input(|i| {
        for (k, key) in DIGITS.iter().take(5).enumerate() {
            if i.key_pressed(*key) {
                *value = Some(scale.snap(scale.min + (k as f64 + 0.5) / 5.0 * range));
                digit = true;
            }
        }
        let moves = [
            (Key::ArrowUp, fine),
            (Key::ArrowDown, -fine),
            (Key::PageUp, range / 10.0),
            (Key::PageDown, -range / 10.0),
        ];
        for (key, d) in moves {
            for _ in 0..i.num_presses(key) {
                let from = value.unwrap_or(scale.min + 0.5 * range);
                let to = (from + d).clamp(scale.min, scale.max);
                *value = Some(match scale.step {
                    Some(_) => scale.snap(to),
                    None => (to / fine).round() * fine,
                });
            }
        }
    });
    digit
}

/// The number keys 1-9.
const DIGITS: [Key; 9] = [
    Key::Num1,
    Key::Num2,
    Key::Num3,
    Key::Num4,
    Key::Num5,
    Key::Num6,
    Key::Num7,
    Key::Num8,
    Key::Num9,
];

/// Number keys pick whole ratings (on a continuous scale: a section); up/down move by the
/// scale's step. True when a number key rated.
fn keyboard_rating(ui: &Ui, scale: &RatingScale, value: &mut Option<f64>) -> bool {
    if scale.kind == ScaleKind::Continuous {
        return keyboard_continuous(ui, scale, value);
    }
    let cats = categories(scale);
    let mut digit = false;
    ui.input(|i| {
        for (k, &key) in DIGITS.iter().enumerate() {
            let v = (k + 1) as f64;
            if i.key_pressed(key) && cats.iter().any(|c| (c - v).abs() < 1e-9) {
                *value = Some(v);
                digit = true;
            }
        }
        let step = |d: isize| {
            let at = value
                .and_then(|v| cats.iter().position(|c| (c - v).abs() < 1e-9))
                .map_or(cats.len() / 2, |p| {
                    (p as isize + d).clamp(0, cats.len() as isize - 1) as usize
                });
            cats.get(at).copied()
        };
        if i.key_pressed(Key::ArrowUp) {
            *value = step(1);
        } else if i.key_pressed(Key::ArrowDown) {
            *value = step(-1);
        }
    });
    digit
}

/// "Trial k of n" (or "of at most n"), a practice mark, a progress bar, and the previous
/// answer's acknowledgement while it lasts.
fn progress_panel(ui: &mut Ui, t: &TrialScreen, done: u32, planned: Planned, ack: bool) {
    egui::Panel::top("progress").show(ui, |ui| {
        ui.horizontal(|ui| {
            if t.trial.arrangement == Arrangement::Grid {
                // A MUSHRA screen rates several panes at once: count the ratings.
                ui.label(format!(
                    "{} This screen: {} lettered motions.",
                    planned.done_text(done),
                    t.panes.len()
                ));
            } else {
                ui.label(planned.trial_text(done + 1));
            }
            if t.trial.block == Block::Familiarization {
                ui.label(RichText::new("(practice)").italics());
            }
            if ack {
                ui.label(RichText::new(format!("{ANSWER_RECORDED}.")).strong());
            }
            if let Some(n) = planned.exact() {
                ui.add(
                    egui::ProgressBar::new(done as f32 / n as f32)
                        .desired_width(240.0)
                        .show_percentage(),
                );
            }
        });
    });
}

/// Whether Continue (or Enter) confirms an answer that is complete; while it is not, and
/// answers are open, `missing` says beside the disabled button what is left to do.
fn confirmed(ui: &mut Ui, open: bool, complete: bool, missing: &str) -> bool {
    ui.horizontal(|ui| {
        let w = 110.0;
        ui.add_space(((ui.available_width() - w) * 0.5).max(0.0));
        let go = ui
            .add_enabled(
                open && complete,
                egui::Button::new("Continue").min_size(Vec2::new(w, 30.0)),
            )
            .clicked()
            || (open && complete && ui.input(|i| i.key_pressed(Key::Enter)));
        if open && !complete {
            ui.label(RichText::new(missing).color(ui.visuals().warn_fg_color));
        }
        go
    })
    .inner
}

/// What a missing rating asks for.
fn rate_hint(scale: &RatingScale, what: &str) -> String {
    match scale.kind {
        ScaleKind::Categorical => format!("Choose a rating for {what} to continue."),
        ScaleKind::Continuous => format!("Mark the scale of {what} to continue."),
    }
}

/// The widget the study's method answers with ([`AnswerWidget`]), drawn with its words;
/// the answer once the subject confirms it.
fn answer(
    ui: &mut Ui,
    widget: &AnswerWidget,
    t: &mut TrialScreen,
    scale: &RatingScale,
    open: bool,
) -> Option<Answer> {
    match widget {
        AnswerWidget::Rating {
            question,
            missing,
            name,
            words,
        } => single_rating(ui, t, (scale, words), open, (question, missing, name)),
        AnswerWidget::RatingPair {
            question,
            names,
            words,
        } => dscqs_answer(ui, t, (scale, words), open, (question, names)),
        AnswerWidget::Choice { question, options } => choice(ui, question, options, open),
        AnswerWidget::SliderGrid { question, words } => {
            mushra_answer(ui, t, scale, question, words, open)
        }
    }
}

/// One rating on a scale under `question`: buttons for a categorical scale, a vertical
/// scale for a continuous one; the keys as in MOS.
fn single_rating(
    ui: &mut Ui,
    t: &mut TrialScreen,
    (scale, words): (&RatingScale, &[String]),
    open: bool,
    (question, what, name): (&str, &str, &str),
) -> Option<Answer> {
    ui.label(RichText::new(question).size(18.0));
    if scale.kind == ScaleKind::Continuous {
        ui.horizontal(|ui| {
            ui.add_space(((ui.available_width() - 190.0) * 0.5).max(0.0));
            vertical_scale(ui, scale, words, &mut t.rating, open, true, name);
        });
    } else {
        rating_row(ui, scale, words, &mut t.rating, open, name);
    }
    if open {
        keyboard_rating(ui, scale, &mut t.rating);
    }
    if confirmed(ui, open, t.rating.is_some(), &rate_hint(scale, what)) {
        return t.rating.map(Answer::Rating);
    }
    None
}

/// DSCQS: a rating of A and one of B (of 1 and 2 when shown one after the other). On a
/// continuous scale, BT.500's pair of vertical scales, shown for the vote once the
/// presentation is over; on a categorical one, a row of grades for each.
fn dscqs_answer(
    ui: &mut Ui,
    t: &mut TrialScreen,
    (scale, words): (&RatingScale, &[String]),
    open: bool,
    (question, [name_a, name_b]): (&str, &[String; 2]),
) -> Option<Answer> {
    ui.label(RichText::new(question).size(18.0));
    match scale.kind {
        ScaleKind::Continuous => {
            if t.presentation.accepts_response() {
                let touched = ui
                    .horizontal(|ui| {
                        let w = 2.0 * 190.0 + 60.0;
                        ui.add_space(((ui.available_width() - w) * 0.5).max(0.0));
                        let a = vertical_scale(
                            ui,
                            scale,
                            words,
                            &mut t.rating,
                            open,
                            !t.editing_b,
                            name_a,
                        );
                        ui.add_space(60.0);
                        let b = vertical_scale(
                            ui,
                            scale,
                            words,
                            &mut t.rating_b,
                            open,
                            t.editing_b,
                            name_b,
                        );
                        let used = |r: &egui::Response| r.clicked() || r.dragged();
                        [used(&a), used(&b)]
                    })
                    .inner;
                // The scale last used by mouse is the one the keys move.
                if touched[0] {
                    t.editing_b = false;
                } else if touched[1] {
                    t.editing_b = true;
                }
            }
        }
        ScaleKind::Categorical => {
            for (name, row, editing) in [
                (name_a, &mut t.rating, !t.editing_b),
                (name_b, &mut t.rating_b, t.editing_b),
            ] {
                ui.horizontal(|ui| {
                    let text = RichText::new(name).strong().size(18.0);
                    ui.label(if editing && open {
                        text.underline()
                    } else {
                        text
                    });
                    rating_row(ui, scale, words, row, open, name);
                });
            }
        }
    }
    if open {
        // Keys: number keys rate A, then B; ↑/↓ (and Page Up/Down) adjust the one being
        // rated; ←/→ choose A or B; Backspace goes back to A.
        let row = if t.editing_b {
            &mut t.rating_b
        } else {
            &mut t.rating
        };
        let digit = keyboard_rating(ui, scale, row);
        if digit && !t.editing_b && t.rating.is_some() {
            t.editing_b = true;
        }
        ui.input(|i| {
            if i.key_pressed(Key::Backspace) || i.key_pressed(Key::ArrowLeft) {
                t.editing_b = false;
            } else if i.key_pressed(Key::ArrowRight) {
                t.editing_b = true;
            }
        });
    }
    let both = t.rating.zip(t.rating_b);
    let missing = match (t.rating, t.rating_b) {
        (None, None) => format!("{name_a} and {name_b}"),
        (None, Some(_)) => name_a.clone(),
        _ => name_b.clone(),
    };
    if confirmed(ui, open, both.is_some(), &rate_hint(scale, &missing)) {
        return both.map(|(a, b)| Answer::Pair { a, b });
    }
    None
}

/// A choice (2AFC: which of the two is the original; pair comparison: which of two versions
/// is better, or no preference where the study allows it): one button per option, in
/// order, and each option's key, which answers at once.
fn choice(ui: &mut Ui, question: &str, options: &[ChoiceOption], open: bool) -> Option<Answer> {
    ui.label(RichText::new(question).size(20.0));
    let mut answer = None;
    ui.horizontal(|ui| {
        let w = 140.0;
        let n = options.len() as f32;
        ui.add_space(((ui.available_width() - n * w - (n - 1.0) * 12.0) * 0.5).max(0.0));
        for o in options {
            let b =
                egui::Button::new(RichText::new(&o.label).size(18.0)).min_size(Vec2::new(w, 40.0));
            if ui.add_enabled(open, b).clicked() {
                answer = Some(Answer::Choice(o.answer));
            }
        }
    });
    if open {
        ui.input(|i| {
            for o in options {
                if Key::from_name(&o.key).is_some_and(|k| i.key_pressed(k)) {
                    answer = Some(Answer::Choice(o.answer));
                }
            }
        });
    }
    answer
}

/// The Replay button (where replays are left) and the "watch" hint; true when pressed.
fn replay_row(ui: &mut Ui, t: &TrialScreen, active: bool) -> bool {
    ui.horizontal(|ui| {
        let replay = t.presentation.can_replay()
            && ui
                .add_enabled(active, egui::Button::new("Replay"))
                .clicked();
        if !t.presentation.accepts_response() {
            ui.label(RichText::new("Watch the motions…").weak());
        }
        replay
    })
    .inner
}

/// Height of the band above side-by-side viewports that holds their labels, points.
const LABEL_BAND: f32 = 44.0;

/// What a trial's stimulus panes show: the screen as described for every front end (the
/// panes' labels, the schedule, the answer widget), the position of the first pane, and at
/// the arrangement's first and second position a figure each, or a crowd scene each. The
/// study window's trial and a trial drawn to video ([`crate::video::write_trial_mp4`]) both
/// draw theirs with [`stimuli_panel`], so both lay it out alike.
pub(crate) struct TrialPanes {
    pub(crate) described: Arc<protocols::screen::Screen>,
    first: Position,
    view: View,
    stages: Vec<Stage>,
    shapes: Vec<Arc<FrameShapes>>,
}

impl TrialPanes {
    fn new(
        described: Arc<protocols::screen::Screen>,
        first: Position,
        view: &View,
        stages: Vec<Stage>,
    ) -> TrialPanes {
        TrialPanes {
            shapes: vec![Arc::default(); stages.len()],
            described,
            first,
            view: *view,
            stages,
        }
    }

    /// The panes of a one-trial screen (not a MUSHRA screen): `trial`'s clips `shown`, cast
    /// with the framing `framing` gives each clip, and described as every front end is told
    /// it, timed by the clips' length.
    ///
    /// # Errors
    /// The clips cannot be cast (a crowd scene's characters missing).
    pub(crate) fn of_trial(
        study: &StudyDefinition,
        trial: &Trial,
        shown: &lab::TrialStimuli,
        framing: &mut dyn FnMut(&str, &motion::Clip) -> View,
    ) -> lab::Result<TrialPanes> {
        let cast = Casting::of(study, trial, shown, framing)?;
        let described = Arc::new(protocols::screen::Screen::of(
            study,
            trial,
            cast.duration_s(),
        ));
        Ok(TrialPanes::new(
            described,
            Casting::first(trial.arrangement),
            &cast.view,
            cast.stages(),
        ))
    }

    /// Paints pane `k` into `rect`, posed at `clip_time_s`.
    fn draw(
        &mut self,
        painter: &egui::Painter,
        gpu: bool,
        k: usize,
        rect: egui::Rect,
        clip_time_s: f64,
    ) {
        crate::render::paint_pane(
            painter,
            gpu,
            k,
            rect,
            &self.view,
            &mut self.stages[k],
            &mut self.shapes[k],
            clip_time_s,
        );
    }
}

/// The stimuli as the presentation schedule shows them now: both side by side, one of them,
/// or the grey between, with the position's label; where the study labels the reference
/// (MOS), "Original" and "Compressed" (its texts) above or before the motions instead.
pub(crate) fn stimuli_panel(ui: &mut Ui, t: &mut TrialPanes, frame: &Frame, gpu: bool) {
    egui::CentralPanel::default()
        .frame(egui::Frame::new().fill(Color32::from_gray(96)))
        .show(ui, |ui| {
            let full = ui.available_rect_before_wrap();
            let painter = ui.painter().clone();
            let described = Arc::clone(&t.described);
            let labelled = described.panes.iter().any(|p| p.label.is_some());
            let mut names: Vec<(egui::Rect, &str)> = Vec::new();
            match frame.show {
                Show::Grey => {}
                Show::Grid => {
                    grid_panes(
                        &painter,
                        gpu,
                        t,
                        &described,
                        full,
                        frame.clip_time_s,
                        &mut names,
                    );
                }
                Show::Both => {
                    let gap = 12.0;
                    let band = if labelled { LABEL_BAND } else { 0.0 };
                    let w = (full.width() - gap) * 0.5;
                    let h = w.min(full.height() - band);
                    let top = full.center().y - (h - band) * 0.5;
                    for k in 0..2 {
                        let left = full.left() + k as f32 * (w + gap);
                        let rect =
                            egui::Rect::from_min_size(egui::pos2(left, top), Vec2::new(w, h));
                        t.draw(&painter, gpu, k, rect, frame.clip_time_s);
                        let p = if k == 0 { t.first } else { t.first.other() };
                        if let Some(name) = described.label(p) {
                            let above = egui::Rect::from_min_max(
                                egui::pos2(rect.left(), top - band),
                                egui::pos2(rect.right(), top),
                            );
                            names.push((above, name));
                        }
                    }
                }
                Show::One(_) | Show::Test => {
                    let k = match frame.show {
                        Show::One(p) => usize::from(p != t.first),
                        _ => 0,
                    };
                    let h = full.height() - 40.0;
                    let w = (h * 16.0 / 9.0).min(full.width());
                    let rect = egui::Rect::from_center_size(
                        full.center() + Vec2::new(0.0, 20.0),
                        Vec2::new(w, h),
                    );
                    t.draw(&painter, gpu, k, rect, frame.clip_time_s);
                }
            }
            for (rect, name) in names {
                ui.put(
                    rect,
                    egui::Label::new(
                        RichText::new(name)
                            .size(28.0)
                            .strong()
                            .color(Color32::WHITE),
                    ),
                );
            }
            // One stimulus at a time: its label (MOS: which is the original), else the
            // schedule's ("A", "B", "1", "2").
            let label = match frame.show {
                Show::One(p) => described.label(p).or(frame.label),
                Show::Both | Show::Grey | Show::Test | Show::Grid => frame.label,
            };
            if let Some(label) = label {
                ui.with_layout(Layout::top_down(Align::Center), |ui| {
                    ui.label(
                        RichText::new(label)
                            .size(30.0)
                            .strong()
                            .color(Color32::WHITE),
                    );
                });
            }
            if frame.show == Show::Grey && frame.finished {
                ui.centered_and_justified(|ui| {
                    ui.label(
                        RichText::new("Please answer below")
                            .size(22.0)
                            .color(Color32::WHITE),
                    );
                });
            }
        });
}

/// Columns of a grid of `n` panes of aspect 4:3 in a `w` x `h` area that make them largest.
fn grid_columns(n: usize, w: f32, h: f32) -> usize {
    (1..=n.max(1))
        .max_by(|&a, &b| {
            let size = |c: usize| {
                let rows = n.div_ceil(c) as f32;
                (w / c as f32).min(h / rows * 4.0 / 3.0)
            };
            size(a).total_cmp(&size(b)).then(b.cmp(&a))
        })
        .unwrap_or(1)
}

/// A MUSHRA screen's panes in a grid: the labelled reference first, then the lettered panes
/// (each labelled above its viewport, `names`).
fn grid_panes<'a>(
    painter: &egui::Painter,
    gpu: bool,
    t: &mut TrialPanes,
    described: &'a protocols::screen::Screen,
    full: egui::Rect,
    clip_time_s: f64,
    names: &mut Vec<(egui::Rect, &'a str)>,
) {
    let n = t.stages.len();
    let (gap, band) = (8.0, 26.0);
    let cols = grid_columns(n, full.width(), full.height());
    let rows = n.div_ceil(cols);
    let cell = Vec2::new(
        (full.width() - gap * (cols - 1) as f32) / cols as f32,
        (full.height() - gap * (rows - 1) as f32) / rows as f32,
    );
    for k in 0..n {
        let (c, r) = (k % cols, k / cols);
        let min = full.min + Vec2::new(c as f32 * (cell.x + gap), r as f32 * (cell.y + gap));
        let label = egui::Rect::from_min_size(min, Vec2::new(cell.x, band));
        let rect = egui::Rect::from_min_size(
            min + Vec2::new(0.0, band),
            Vec2::new(cell.x, (cell.y - band).max(1.0)),
        );
        t.draw(painter, gpu, k, rect, clip_time_s);
        let name = described
            .panes
            .get(k)
            .and_then(|p| p.label.as_deref())
            .unwrap_or("");
        names.push((label, name));
    }
}

/// Width of a MUSHRA slider's column, points.
const MUSHRA_COL: f32 = 76.0;
/// Width of the column of scale words and of the 0 and 100 marks beside the sliders, points.
const MUSHRA_WORDS: f32 = 150.0;
/// Height of the band of letters above the sliders, and of the values under them, points.
const MUSHRA_BAND: f32 = 28.0;
/// How far below 0 an unrated slider's knob waits, points: apart from the scale, so that it
/// never reads as a rating of 0.
const MUSHRA_PARK: f32 = 30.0;

/// Height of MUSHRA's sliders, points: what leaves the panes most of a small window.
fn mushra_height(ui: &Ui) -> f32 {
    (ui.ctx().content_rect().height() * 0.3).clamp(150.0, 320.0)
}

/// MUSHRA (BS.1534): a 0-100 slider per lettered pane, opened once every pane has played,
/// beside BS.1534's words (Excellent … Bad, in five equal sections) with 0 and 100 marked;
/// an unrated slider's knob waits below the scale, apart from 0. Tab moves from slider to
/// slider, the arrow keys move the focused one by a step (from 0 when unrated), Page Up and
/// Page Down by 10. Continue once every pane has a rating; the answer returned is the first
/// pane's (the caller logs every pane's from `pane_ratings`).
fn mushra_answer(
    ui: &mut Ui,
    t: &mut TrialScreen,
    scale: &RatingScale,
    question: &str,
    words: &[String],
    open: bool,
) -> Option<Answer> {
    ui.label(RichText::new(question).size(TEXT_PX));
    let n = t.panes.len();
    let h = mushra_height(ui);
    let width = MUSHRA_WORDS + MUSHRA_COL * n as f32;
    ui.horizontal(|ui| {
        ui.add_space(((ui.available_width() - width - MUSHRA_WORDS) * 0.5).max(0.0));
        let size = Vec2::new(width, 2.0 * MUSHRA_BAND + h + MUSHRA_PARK + 20.0);
        let (block, _) = ui.allocate_exact_size(size, egui::Sense::hover());
        let top = block.top() + MUSHRA_BAND + 10.0;
        let track = egui::Rangef::new(top, top + h);
        mushra_scale(ui, block, track, words, open);
        for (k, (pane, rating)) in t.panes.iter().zip(t.pane_ratings.iter_mut()).enumerate() {
            let name = pane
                .reference_position
                .pane_letter()
                .map_or_else(|| "?".to_owned(), String::from);
            let x = block.left() + MUSHRA_WORDS + MUSHRA_COL * (k as f32 + 0.5);
            let column = egui::Rangef::new(x - MUSHRA_COL * 0.5, x + MUSHRA_COL * 0.5);
            ui.put(
                egui::Rect::from_x_y_ranges(column, block.top()..=block.top() + MUSHRA_BAND),
                egui::Label::new(RichText::new(&name).strong().size(TEXT_PX)),
            );
            mushra_slider(ui, scale, (x, track), rating, open, &name);
        }
    });
    let missing: Vec<String> = t
        .panes
        .iter()
        .zip(&t.pane_ratings)
        .filter(|(_, r)| r.is_none())
        .filter_map(|(p, _)| p.reference_position.pane_letter().map(String::from))
        .collect();
    let hint = format!("Rate {} to continue.", missing.join(", "));
    if confirmed(ui, open, missing.is_empty() && n > 0, &hint) {
        return t
            .pane_ratings
            .first()
            .copied()
            .flatten()
            .map(Answer::Rating);
    }
    None
}

/// The scale beside MUSHRA's sliders: lines across every slider at 0, 20, … 100, BS.1534's
/// words in the five sections between them, "100" and "0" at the ends.
fn mushra_scale(ui: &mut Ui, block: egui::Rect, track: egui::Rangef, words: &[String], open: bool) {
    let visuals = ui.visuals();
    let line = if open {
        visuals.weak_text_color()
    } else {
        visuals.widgets.noninteractive.bg_stroke.color
    };
    let section = track.span() / words.len().max(1) as f32;
    let lines = block.left() + MUSHRA_WORDS - 34.0..=block.right();
    for k in 0..=words.len() {
        ui.painter().hline(
            lines.clone(),
            track.min + section * k as f32,
            egui::Stroke::new(1.0, line),
        );
    }
    let words_x = block.left()..=block.left() + MUSHRA_WORDS - 40.0;
    for (k, word) in words.iter().enumerate() {
        let y = track.min + section * (k as f32 + 0.5);
        ui.put(
            egui::Rect::from_x_y_ranges(words_x.clone(), y - 12.0..=y + 12.0),
            egui::Label::new(RichText::new(word.as_str()).size(WORD_PX)),
        );
    }
    let marks_x = block.left() + MUSHRA_WORDS - 40.0..=block.left() + MUSHRA_WORDS - 4.0;
    for (mark, y) in [("100", track.min), ("0", track.max)] {
        ui.put(
            egui::Rect::from_x_y_ranges(marks_x.clone(), y - 12.0..=y + 12.0),
            egui::Label::new(RichText::new(mark).size(WORD_PX)),
        );
    }
}

/// One pane's slider: a track at `x` over `track`, its knob at the rating (or waiting below
/// the scale while unrated), its value under it ("–" until set). A pane counts as rated once
/// its slider is clicked, dragged or moved by a key while focused. Screen readers see a
/// slider "Rating of A" with no value until it is set.
fn mushra_slider(
    ui: &mut Ui,
    scale: &RatingScale,
    (x, track): (f32, egui::Rangef),
    rating: &mut Option<f64>,
    open: bool,
    name: &str,
) {
    let step = scale.step.unwrap_or(1.0);
    let id = ui.scope_id().with(("mushra slider", name));
    let hit = egui::Rect::from_x_y_ranges(
        x - MUSHRA_COL * 0.5 + 6.0..=x + MUSHRA_COL * 0.5 - 6.0,
        track.min - 10.0..=track.max + 10.0,
    );
    let sense = if open {
        egui::Sense::click_and_drag()
    } else {
        egui::Sense::hover()
    };
    let r = ui.interact(hit, id, sense);
    let mut v = rating.unwrap_or(scale.min);
    let mut set = false;
    if open
        && (r.clicked() || r.dragged() || r.drag_started())
        && let Some(pos) = r.interact_pointer_pos()
    {
        v = scale_value_at(scale, pos.y, track.min, track.max);
        set = true;
    }
    if open && r.has_focus() {
        ui.memory_mut(|m| {
            m.set_focus_lock_filter(
                id,
                egui::EventFilter {
                    vertical_arrows: true,
                    ..Default::default()
                },
            );
        });
        ui.input(|i| {
            let arrows = i.num_presses(Key::ArrowUp) as f64 - i.num_presses(Key::ArrowDown) as f64;
            let pages = i.num_presses(Key::PageUp) as f64 - i.num_presses(Key::PageDown) as f64;
            let pressed = [Key::ArrowUp, Key::ArrowDown, Key::PageUp, Key::PageDown]
                .into_iter()
                .any(|k| i.key_pressed(k));
            if pressed {
                v = (v + arrows * step + pages * 10.0).clamp(scale.min, scale.max);
                set = true;
            }
        });
    }
    if set && open {
        *rating = Some(scale.snap(v));
    }
    paint_mushra_slider(ui, scale, (x, track), *rating, r.has_focus() && open);
    let value = rating.map_or_else(|| "–".to_string(), format_rating);
    let below = track.max + MUSHRA_PARK + 12.0;
    ui.put(
        egui::Rect::from_x_y_ranges(
            x - MUSHRA_COL * 0.5..=x + MUSHRA_COL * 0.5,
            below..=below + MUSHRA_BAND,
        ),
        egui::Label::new(RichText::new(value).size(TEXT_PX)),
    );
    let marked = *rating;
    let r = r.on_hover_text(format!("Rating of {name}"));
    r.widget_info(|| {
        let mut info = egui::WidgetInfo::labeled(
            egui::accesskit::Role::Slider,
            open,
            format!("Rating of {name}"),
        );
        info.value = marked;
        info
    });
    ui.ctx().accesskit_node_builder(id, |b| {
        b.set_min_numeric_value(scale.min);
        b.set_max_numeric_value(scale.max);
        b.set_numeric_value_step(step);
    });
}

/// A MUSHRA slider's rail at `x` over `track` and its knob: filled at the rating, or hollow
/// below the scale while unrated; ringed while it has the keyboard's focus.
fn paint_mushra_slider(
    ui: &Ui,
    scale: &RatingScale,
    (x, track): (f32, egui::Rangef),
    rating: Option<f64>,
    focus: bool,
) {
    let visuals = ui.visuals();
    let painter = ui.painter();
    let rail = egui::Rect::from_x_y_ranges(x - 4.0..=x + 4.0, track);
    painter.rect_filled(rail, 4.0, visuals.extreme_bg_color);
    painter.rect_stroke(
        rail,
        4.0,
        visuals.widgets.noninteractive.bg_stroke,
        egui::StrokeKind::Outside,
    );
    let at = if let Some(v) = rating {
        let f = ((v - scale.min) / (scale.max - scale.min)).clamp(0.0, 1.0) as f32;
        let at = egui::pos2(x, track.max - f * track.span());
        painter.circle_filled(at, 10.0, visuals.selection.bg_fill);
        at
    } else {
        // Waiting below the scale, hollow: not a rating of 0.
        let at = egui::pos2(x, track.max + MUSHRA_PARK);
        painter.circle_stroke(at, 9.0, egui::Stroke::new(2.0, visuals.weak_text_color()));
        at
    };
    if focus {
        painter.circle_stroke(at, 14.0, egui::Stroke::new(2.0, visuals.text_color()));
    }
}

impl StudyUi {
    /// Where the session stands, for the experimenter's terminal ([`crate::status`]): read
    /// once a frame, so it copies a few words and nothing more.
    pub fn status(&self) -> crate::status::SessionStatus {
        use crate::status::{Ended, SessionStatus, Stage};
        SessionStatus {
            stage: match &self.screen {
                Screen::Viewing(_) => Stage::Viewing,
                Screen::Welcome => Stage::Welcome,
                Screen::Break => Stage::Break,
                Screen::Trial(t) => Stage::Trial(t.trial.index),
                Screen::Gap(_) => Stage::Gap,
                Screen::Waiting { .. } => Stage::Waiting,
                Screen::End(_) | Screen::Failed(_) => Stage::End,
            },
            paused: self.pause != Pause::None,
            answered: self.recorder.answered(),
            planned: self.planned,
            elapsed_ms: self.recorder.elapsed_ms(),
            ended: self.exit.as_ref().map(|e| match e {
                Exit::Finished(_) => Ended::Finished,
                Exit::Quit { .. } => Ended::Quit,
                Exit::Signalled { .. } => Ended::Signalled,
                Exit::Failed(_) => Ended::Failed,
            }),
        }
    }
}
