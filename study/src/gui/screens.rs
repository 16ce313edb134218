//! The subject's screens: welcome (subject fields, consent, instructions), trials, breaks and
//! the end, plus the experimenter's pause. Pure egui: the window wraps it in eframe and the
//! UI tests drive it with `egui_kittest`.
//!
//! A trial's answer widgets stay disabled, and its answer keys are ignored, until the stimuli
//! have been shown as the protocol requires ([`Presentation::accepts_response`]), and while
//! the experimenter pause is open. An answer is logged (fsynced) by the [`Recorder`] before
//! the next trial is even asked for.

use std::collections::HashMap;
use std::sync::Arc;

use egui::{Align, Color32, Key, Layout, RichText, Ui, Vec2};
use protocols::record::{Answer, Arrangement, Block, Position, Protocol, Response, Trial};
use protocols::study::{RatingScale, ScaleKind};
use protocols::{FrameTiming, StimulusEncoding, StudyDefinition};

use super::flow::{Frame, Presentation, Show, stimulus_at};
use super::render::{BACKGROUND, SkeletonCallback};
use super::scene::{Figure, FrameShapes, View};
use super::timing::FrameClock;
use lab::session::Recorder;
use lab::source::StimulusSource;

/// The BT.500 five-grade quality labels, best first.
pub const QUALITY_LABELS: [&str; 5] = ["Excellent", "Good", "Fair", "Poor", "Bad"];

/// The 2AFC question of thesis ch. 5.
pub const AFC_QUESTION: &str = "Which motion looks more natural?";

/// The protocol's default instructions.
pub fn default_instructions(protocol: Protocol) -> &'static str {
    match protocol {
        Protocol::Mos => {
            "You will see an original motion and a compressed version of it side by side. \
             Rate the quality of the compressed motion from 1 (Bad) to 5 (Excellent) in half \
             steps, with the mouse or the number keys, then press Continue (Enter). The first \
             few trials show the range of qualities you will meet."
        }
        Protocol::Dscqs => {
            "Each trial shows two motions, A and B, twice: A, B, A, B. One of them is the \
             original, in random order. After the second showing, rate the quality of both A \
             and B (with the mouse, or number keys: first A, then B), then press Continue \
             (Enter)."
        }
        Protocol::Staircase => {
            "Each trial shows two motions side by side. Choose the one that looks more natural \
             with the Left or Right arrow key (or click). Answer even when you are unsure."
        }
    }
}

enum Screen {
    Welcome,
    Break,
    Trial(Box<TrialScreen>),
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
    presentation: Presentation,
    /// Figures at the arrangement's first and second position.
    figures: [Figure; 2],
    view: View,
    first: Position,
    rating: Option<f64>,
    rating_b: Option<f64>,
    /// DSCQS keyboard: number keys now rate B.
    editing_b: bool,
    gate_open_s: Option<f64>,
    shapes: [Arc<FrameShapes>; 2],
    /// How the test stimulus was encoded for this trial (live staircase).
    encoding: Option<StimulusEncoding>,
}

/// Total trials of a session, when the protocol plans them up front.
fn planned_trials(study: &StudyDefinition) -> Option<u32> {
    match study.protocol {
        Protocol::Mos | Protocol::Dscqs => Some(
            (study.familiarization.len()
                + study.conditions.len()
                + study.session.hidden_repeats as usize) as u32,
        ),
        Protocol::Staircase => None,
    }
}

/// The rating values of a categorical scale, low to high.
fn categories(scale: &RatingScale) -> Vec<f64> {
    let step = scale.step.filter(|s| *s > 0.0).unwrap_or(1.0);
    let n = ((scale.max - scale.min) / step).round().clamp(0.0, 200.0) as usize;
    (0..=n).map(|k| scale.min + k as f64 * step).collect()
}

fn format_rating(v: f64) -> String {
    if v.fract().abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

/// BT.500 label of an integer rating on a five-grade scale.
fn quality_label(scale: &RatingScale, v: f64) -> Option<&'static str> {
    if (scale.max - scale.min - 4.0).abs() > 1e-9 || v.fract().abs() > 1e-9 {
        return None;
    }
    QUALITY_LABELS
        .get((scale.max - v).round() as usize)
        .copied()
}

/// The subject's screens over one open session.
pub struct StudyUi {
    study: Arc<StudyDefinition>,
    stimuli: Box<dyn StimulusSource>,
    recorder: Box<Recorder>,
    screen: Screen,
    pause: Pause,
    exit: Option<Exit>,
    fields: Vec<(String, String)>,
    consent: bool,
    views: HashMap<String, View>,
    planned: Option<u32>,
    gpu: bool,
    /// The stimulus check Begin waits for (`None`: nothing to wait for).
    preflight: Option<Preflight>,
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
                    .get(f)
                    .cloned()
                    .unwrap_or_default();
                (f.clone(), v)
            })
            .collect();
        let planned = planned_trials(&study);
        StudyUi {
            study,
            stimuli,
            recorder,
            screen: Screen::Welcome,
            pause: Pause::None,
            exit: None,
            fields,
            consent: false,
            views: HashMap::new(),
            planned,
            gpu,
            preflight: None,
        }
    }

    /// Begin waits for `preflight` (every stimulus of the plan checked), with a progress bar
    /// once it takes over a second; problems end the session before its first trial.
    pub fn with_preflight(mut self, preflight: Preflight) -> StudyUi {
        self.preflight = Some(preflight);
        self
    }

    /// True while the stimulus check runs (the window repaints to show its progress).
    pub fn checking(&self) -> bool {
        self.preflight.as_ref().is_some_and(|p| p.outcome.is_none())
    }

    /// The session's stimulus source (UI tests wait for what it prepares).
    #[cfg(test)]
    pub fn stimuli_mut(&mut self) -> &mut dyn StimulusSource {
        self.stimuli.as_mut()
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

    /// True while a trial presentation is running (the window repaints continuously then).
    pub fn animating(&self) -> bool {
        matches!(self.screen, Screen::Trial(_))
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

    /// Draws the current screen and handles its input; `clock` is the window's frame clock
    /// (trial timing is read from it).
    pub fn ui(&mut self, ui: &mut Ui, clock: &mut FrameClock) {
        let now = ui.input(|i| i.time);
        let chord = ui.input(|i| i.modifiers.ctrl && i.modifiers.shift && i.key_pressed(Key::P));
        if chord && self.pause == Pause::None && self.exit.is_none() {
            self.pause = Pause::Paused;
        }
        let active = self.pause == Pause::None;
        match &self.screen {
            Screen::Welcome => self.welcome(ui, now, active, clock),
            Screen::Break => self.break_screen(ui, now, active, clock),
            Screen::Trial(_) => self.trial_screen(ui, now, active, clock),
            Screen::End(text) | Screen::Failed(text) => {
                let text = text.clone();
                egui::CentralPanel::default().show(ui, |ui| {
                    ui.vertical_centered(|ui| {
                        ui.add_space(ui.available_height() * 0.35);
                        ui.heading(text);
                    });
                });
            }
        }
        if self.pause != Pause::None {
            self.pause_dialog(ui, now, clock);
        }
    }

    fn welcome(&mut self, ui: &mut Ui, now: f64, active: bool, clock: &mut FrameClock) {
        let mut begin = false;
        egui::CentralPanel::default().show(ui, |ui| {
            ui.vertical_centered(|ui| {
                ui.add_space(24.0);
                ui.heading(&self.study.name);
                ui.add_space(12.0);
                if self.recorder.answered() > 0 {
                    ui.label(format!(
                        "Continuing the session: {} trials already done.",
                        self.recorder.answered()
                    ));
                }
            });
            ui.add_space(12.0);
            let instructions = self
                .study
                .session
                .instructions
                .clone()
                .unwrap_or_else(|| default_instructions(self.study.protocol).to_string());
            ui.label(RichText::new(instructions).size(18.0));
            ui.add_space(16.0);
            if !self.fields.is_empty() {
                egui::Grid::new("subject fields")
                    .num_columns(2)
                    .show(ui, |ui| {
                        for (name, value) in &mut self.fields {
                            let label = ui.label(name.replace('_', " "));
                            ui.add_enabled(active, egui::TextEdit::singleline(value))
                                .labelled_by(label.id);
                            ui.end_row();
                        }
                    });
                ui.add_space(12.0);
            }
            if let Some(consent) = &self.study.session.consent {
                ui.label(consent);
                ui.add_enabled(
                    active,
                    egui::Checkbox::new(&mut self.consent, "I agree to take part"),
                );
                ui.add_space(12.0);
            }
            let ready = self.fields.iter().all(|(_, v)| !v.trim().is_empty())
                && (self.study.session.consent.is_none() || self.consent);
            // Trials start once the refresh period is known, so every trial's drop count is
            // against the measured period.
            let measured = clock.calibrated() || !self.gpu;
            let checked = self.preflight.as_mut().is_none_or(|p| p.ui(ui));
            ui.vertical_centered(|ui| {
                let button = egui::Button::new(RichText::new("Begin").size(20.0))
                    .min_size(Vec2::new(160.0, 44.0));
                let can = active && ready && measured && checked;
                if ui.add_enabled(can, button).clicked()
                    || (can && ui.input(|i| i.key_pressed(Key::Enter)))
                {
                    begin = true;
                }
                if !ready {
                    ui.label("Fill in every field to begin.");
                } else if !measured {
                    ui.label("Measuring the display…");
                }
            });
        });
        if let Some(Some(Err(problems))) = self.preflight.as_ref().map(|p| &p.outcome) {
            let problems = problems.clone();
            self.screen = Screen::Failed(format!(
                "The stimuli have problems; the session cannot start.\n\n{problems}"
            ));
            self.exit = Some(Exit::Failed(problems));
            return;
        }
        if begin {
            let fields: Vec<(String, String)> = self
                .fields
                .iter()
                .map(|(k, v)| (k.clone(), v.trim().to_string()))
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

    fn break_screen(&mut self, ui: &mut Ui, now: f64, active: bool, clock: &mut FrameClock) {
        let mut go = false;
        egui::CentralPanel::default().show(ui, |ui| {
            ui.vertical_centered(|ui| {
                ui.add_space(ui.available_height() * 0.3);
                ui.heading("Take a short break.");
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
        let first = match trial.arrangement {
            Arrangement::SideBySide => Position::Left,
            Arrangement::Sequential => Position::First,
            Arrangement::Abab => Position::A,
        };
        // A live trial's test stimulus is encoded now unless it was prepared (cached by
        // level); others are files.
        let shown = self.stimuli.stimuli(&trial)?;
        // While the subject watches this trial, prepare the stimuli a correct and a wrong
        // answer lead to, so the next trial starts without waiting for the codec.
        self.stimuli
            .prepare(&self.recorder.lookahead(self.recorder.elapsed_ms()));
        let (reference, test, encoding) = (shown.reference, shown.test, shown.encoding);
        let view = *self
            .views
            .entry(trial.reference.clone())
            .or_insert_with(|| View::framing(&reference));
        let at = |p: Position| {
            if stimulus_at(&trial, p) == trial.reference {
                Arc::clone(&reference)
            } else {
                Arc::clone(&test)
            }
        };
        let (a, b) = (at(first), at(first.other()));
        let presentation = Presentation::new(
            &trial,
            &self.study.presentation,
            reference.duration_s(),
            now,
        );
        Ok(TrialScreen {
            trial,
            presentation,
            figures: [Figure::new(&a, &view), Figure::new(&b, &view)],
            view,
            first,
            rating: None,
            rating_b: None,
            editing_b: false,
            gate_open_s: None,
            shapes: [Arc::default(), Arc::default()],
            encoding,
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
        progress_panel(ui, t, self.recorder.answered(), self.planned);
        let (answer, replay) = egui::Panel::bottom("answer")
            .min_size(150.0)
            .show(ui, |ui| {
                ui.add_space(8.0);
                let answer = ui
                    .vertical_centered(|ui| match self.study.protocol {
                        Protocol::Mos => mos_answer(ui, t, &self.study.scale, open),
                        Protocol::Dscqs => dscqs_answer(ui, t, &self.study.scale, open),
                        Protocol::Staircase => afc_answer(ui, t, open),
                    })
                    .inner;
                (answer, replay_row(ui, t, active))
            })
            .inner;
        stimuli_panel(ui, t, &frame, self.gpu);
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
        match self.log_answer(trial, response, encoding, timing, clock) {
            Ok(()) => self.advance(now, clock),
            Err(e) => self.fail(&e),
        }
    }

    /// Logs an answer (fsynced) and, when the display was measured, the trial's frame
    /// intervals.
    fn log_answer(
        &mut self,
        trial: Trial,
        response: Response,
        encoding: Option<StimulusEncoding>,
        timing: Option<FrameTiming>,
        clock: &FrameClock,
    ) -> lab::Result<()> {
        let elapsed = self.recorder.elapsed_ms();
        let index = trial.index;
        self.recorder
            .record(trial, response, elapsed, encoding, timing)?;
        if timing.is_some() {
            self.recorder
                .append_frame_intervals(index, clock.segment_intervals())?;
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
            clock.start_segment();
            clock.reset_last();
        }
    }
}

/// How a position is named on an answer button.
fn position_label(p: Position) -> &'static str {
    match p {
        Position::Left => "Left",
        Position::Right => "Right",
        Position::First => "First",
        Position::Second => "Second",
        Position::A => "A",
        Position::B => "B",
    }
}

/// Rating buttons of a categorical scale, or a slider for a continuous one.
fn rating_row(ui: &mut Ui, scale: &RatingScale, value: &mut Option<f64>, open: bool, id: &str) {
    match scale.kind {
        ScaleKind::Categorical => {
            let cats = categories(scale);
            ui.horizontal(|ui| {
                let per = 44.0 + ui.spacing().item_spacing.x;
                ui.add_space(((ui.available_width() - per * cats.len() as f32) * 0.5).max(0.0));
                for v in cats {
                    ui.vertical(|ui| {
                        let text = RichText::new(format_rating(v)).size(18.0);
                        let button = egui::Button::new(text)
                            .selected(*value == Some(v))
                            .min_size(Vec2::new(44.0, 36.0));
                        if ui.add_enabled(open, button).clicked() {
                            *value = Some(v);
                        }
                        if let Some(label) = quality_label(scale, v) {
                            ui.label(RichText::new(label).small());
                        }
                    });
                }
            });
        }
        ScaleKind::Continuous => {
            ui.horizontal(|ui| {
                ui.label(QUALITY_LABELS[4]);
                let mut v = value.unwrap_or(0.5 * (scale.min + scale.max));
                let slider = egui::Slider::new(&mut v, scale.min..=scale.max)
                    .step_by(scale.step.unwrap_or(1.0))
                    .text(id);
                if ui.add_enabled(open, slider).changed() {
                    *value = Some(scale.snap(v));
                }
                ui.label(QUALITY_LABELS[0]);
            });
        }
    }
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

/// Number keys pick whole ratings; up/down move by the scale's step.
fn keyboard_rating(ui: &Ui, scale: &RatingScale, value: &mut Option<f64>) {
    if scale.kind != ScaleKind::Categorical {
        return;
    }
    let cats = categories(scale);
    ui.input(|i| {
        for (k, &key) in DIGITS.iter().enumerate() {
            let v = (k + 1) as f64;
            if i.key_pressed(key) && cats.iter().any(|c| (c - v).abs() < 1e-9) {
                *value = Some(v);
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
}

/// "Trial k of n", a practice mark and a progress bar.
fn progress_panel(ui: &mut Ui, t: &TrialScreen, done: u32, planned: Option<u32>) {
    egui::Panel::top("progress").show(ui, |ui| {
        ui.horizontal(|ui| {
            let text = match planned {
                Some(n) => format!("Trial {} of {n}", done + 1),
                None => format!("Trial {}", done + 1),
            };
            ui.label(text);
            if t.trial.block == Block::Familiarization {
                ui.label(RichText::new("(practice)").italics());
            }
            if let Some(n) = planned.filter(|n| *n > 0) {
                ui.add(
                    egui::ProgressBar::new(done as f32 / n as f32)
                        .desired_width(240.0)
                        .show_percentage(),
                );
            }
        });
    });
}

/// Whether Continue (or Enter) confirms an answer that is complete.
fn confirmed(ui: &mut Ui, open: bool, complete: bool) -> bool {
    ui.add_enabled(open && complete, egui::Button::new("Continue"))
        .clicked()
        || (open && complete && ui.input(|i| i.key_pressed(Key::Enter)))
}

/// MOS: one rating of the compressed motion.
fn mos_answer(ui: &mut Ui, t: &mut TrialScreen, scale: &RatingScale, open: bool) -> Option<Answer> {
    ui.label(RichText::new("Rate the quality of the compressed motion").size(18.0));
    rating_row(ui, scale, &mut t.rating, open, "rating");
    if open {
        keyboard_rating(ui, scale, &mut t.rating);
    }
    if confirmed(ui, open, t.rating.is_some()) {
        return t.rating.map(Answer::Rating);
    }
    None
}

/// DSCQS: a rating of A and one of B.
fn dscqs_answer(
    ui: &mut Ui,
    t: &mut TrialScreen,
    scale: &RatingScale,
    open: bool,
) -> Option<Answer> {
    ui.label(RichText::new("Rate the quality of A and of B").size(18.0));
    ui.horizontal(|ui| {
        ui.label(RichText::new("A").strong().size(18.0));
        rating_row(ui, scale, &mut t.rating, open, "rating A");
    });
    ui.horizontal(|ui| {
        ui.label(RichText::new("B").strong().size(18.0));
        rating_row(ui, scale, &mut t.rating_b, open, "rating B");
    });
    if open {
        // Keys: number keys rate A, then B; arrows adjust the row being rated; Backspace goes
        // back to A.
        let row = if t.editing_b {
            &mut t.rating_b
        } else {
            &mut t.rating
        };
        keyboard_rating(ui, scale, row);
        let digit = ui.input(|i| DIGITS.iter().any(|k| i.key_pressed(*k)));
        if digit && !t.editing_b && t.rating.is_some() {
            t.editing_b = true;
        }
        if ui.input(|i| i.key_pressed(Key::Backspace)) {
            t.editing_b = false;
        }
    }
    let both = t.rating.zip(t.rating_b);
    if confirmed(ui, open, both.is_some()) {
        return both.map(|(a, b)| Answer::Pair { a, b });
    }
    None
}

/// 2AFC: which of the two is the distorted one, by button or key.
fn afc_answer(ui: &mut Ui, t: &TrialScreen, open: bool) -> Option<Answer> {
    ui.label(RichText::new(AFC_QUESTION).size(20.0));
    let (l, r, lk, rk) = match t.trial.arrangement {
        Arrangement::Sequential => (Position::First, Position::Second, Key::Num1, Key::Num2),
        Arrangement::Abab => (Position::A, Position::B, Key::A, Key::B),
        Arrangement::SideBySide => (
            Position::Left,
            Position::Right,
            Key::ArrowLeft,
            Key::ArrowRight,
        ),
    };
    let mut answer = None;
    ui.horizontal(|ui| {
        let w = 140.0;
        ui.add_space(((ui.available_width() - 2.0 * w - 24.0) * 0.5).max(0.0));
        for p in [l, r] {
            let b = egui::Button::new(RichText::new(position_label(p)).size(18.0))
                .min_size(Vec2::new(w, 40.0));
            if ui.add_enabled(open, b).clicked() {
                answer = Some(Answer::Choice(p));
            }
        }
    });
    if open {
        // Arrow keys (or 1/2, A/B) answer at once.
        ui.input(|i| {
            if i.key_pressed(lk) {
                answer = Some(Answer::Choice(l));
            } else if i.key_pressed(rk) {
                answer = Some(Answer::Choice(r));
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

/// The stimuli as the presentation schedule shows them now: both side by side, one of them,
/// or the grey between, with the position's label.
fn stimuli_panel(ui: &mut Ui, t: &mut TrialScreen, frame: &Frame, gpu: bool) {
    egui::CentralPanel::default()
        .frame(egui::Frame::new().fill(Color32::from_gray(96)))
        .show(ui, |ui| {
            let full = ui.available_rect_before_wrap();
            let painter = ui.painter();
            match frame.show {
                Show::Grey => {}
                Show::Both => {
                    let gap = 12.0;
                    let w = (full.width() - gap) * 0.5;
                    let h = w.min(full.height());
                    let top = full.center().y - h * 0.5;
                    for k in 0..2 {
                        let left = full.left() + k as f32 * (w + gap);
                        let rect =
                            egui::Rect::from_min_size(egui::pos2(left, top), Vec2::new(w, h));
                        draw_viewport(painter, gpu, t, k, rect, frame.clip_time_s);
                    }
                }
                Show::One(p) => {
                    let k = usize::from(p != t.first);
                    let h = full.height() - 40.0;
                    let w = (h * 16.0 / 9.0).min(full.width());
                    let rect = egui::Rect::from_center_size(
                        full.center() + Vec2::new(0.0, 20.0),
                        Vec2::new(w, h),
                    );
                    draw_viewport(painter, gpu, t, k, rect, frame.clip_time_s);
                }
            }
            if let Some(label) = frame.label {
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

fn draw_viewport(
    painter: &egui::Painter,
    gpu: bool,
    t: &mut TrialScreen,
    k: usize,
    rect: egui::Rect,
    clip_time_s: f64,
) {
    let bg = Color32::from_rgb(
        (BACKGROUND[0] * 255.0) as u8,
        (BACKGROUND[1] * 255.0) as u8,
        (BACKGROUND[2] * 255.0) as u8,
    );
    painter.rect_filled(rect, 0.0, bg);
    let mut shapes = FrameShapes::default();
    t.figures[k].shapes_at(clip_time_s, &mut shapes);
    t.shapes[k] = Arc::new(shapes);
    if gpu {
        painter.add(egui_wgpu::Callback::new_paint_callback(
            rect,
            SkeletonCallback {
                slot: k,
                view: t.view,
                aspect: rect.width() / rect.height().max(1.0),
                shapes: Arc::clone(&t.shapes[k]),
            },
        ));
    }
}

/// The stimulus preflight ([`lab::preflight`]) on a background thread, so the window stays
/// responsive while a large stimulus set is read: the welcome screen shows its progress
/// after a second, Begin waits for it, and its problems end the session before any trial.
pub struct Preflight {
    started: std::time::Instant,
    /// (done, total).
    progress: Arc<(
        std::sync::atomic::AtomicUsize,
        std::sync::atomic::AtomicUsize,
    )>,
    worker: Option<std::thread::JoinHandle<Result<(), String>>>,
    /// The problems, set when the check found any (the runner reads it after the window).
    failed: Arc<std::sync::OnceLock<String>>,
    /// `Some` once the check has ended: `Err` holds every problem, one per line.
    pub outcome: Option<Result<(), String>>,
}

impl Preflight {
    /// Starts checking every stimulus `study`'s plan can show.
    pub fn start(study: lab::StudyFile) -> Preflight {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let progress = Arc::new((AtomicUsize::new(0), AtomicUsize::new(0)));
        let shared = Arc::clone(&progress);
        let failed = Arc::new(std::sync::OnceLock::new());
        let failure = Arc::clone(&failed);
        let worker = std::thread::spawn(move || {
            let (_, problems) = lab::preflight::check(&study, &|done, total| {
                shared.0.store(done, Ordering::Relaxed);
                shared.1.store(total, Ordering::Relaxed);
            });
            if problems.is_empty() {
                Ok(())
            } else {
                let text = lab::preflight::describe(&study, &problems);
                let _ = failure.set(text.clone());
                Err(text)
            }
        });
        Preflight {
            started: std::time::Instant::now(),
            progress,
            worker: Some(worker),
            failed,
            outcome: None,
        }
    }

    /// Where the problems appear if the check finds any.
    pub fn failure(&self) -> Arc<std::sync::OnceLock<String>> {
        Arc::clone(&self.failed)
    }

    /// Shows the progress while the check runs; true once it has ended without problems.
    fn ui(&mut self, ui: &mut Ui) -> bool {
        use std::sync::atomic::Ordering;
        if self
            .worker
            .as_ref()
            .is_some_and(std::thread::JoinHandle::is_finished)
            && let Some(w) = self.worker.take()
        {
            self.outcome = Some(
                w.join()
                    .unwrap_or_else(|_| Err("the stimulus check stopped unexpectedly".into())),
            );
        }
        if let Some(r) = &self.outcome {
            return r.is_ok();
        }
        if self.started.elapsed() > std::time::Duration::from_secs(1) {
            let done = self.progress.0.load(Ordering::Relaxed);
            let total = self.progress.1.load(Ordering::Relaxed).max(1);
            ui.vertical_centered(|ui| {
                ui.add(
                    egui::ProgressBar::new(done as f32 / total as f32)
                        .desired_width(320.0)
                        .text(format!("Checking the stimuli: {done} of {total}")),
                );
            });
        }
        false
    }
}
