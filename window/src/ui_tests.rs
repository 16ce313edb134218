//! The subject's screens driven as a screen reader sees them (`egui_kittest`, AccessKit
//! roles and labels), over real sessions written to a temporary results folder.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use egui::Key;
use egui::accesskit::Role;
use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT as _, Queryable as _};
use protocols::StudyDefinition;
use protocols::record::{Answer, Position};
use results::store::{SESSION_FILE, SessionState, TRIALS_FILE, read_json};
use results::trials::read_trials;

use super::screens::{Exit, StudyUi};
use super::timing::FrameClock;
use lab::StudyFile;
use lab::session::{Opened, Recorder};

/// Seconds per kittest step.
const DT: f32 = 0.05;

pub(super) struct Fixture {
    pub(super) dir: PathBuf,
    pub(super) study_path: PathBuf,
    /// The stimuli's manifest (`dir/stimuli/stimuli.json`).
    pub(super) manifest: protocols::manifest::StimulusManifest,
}

impl Drop for Fixture {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

pub(super) fn fixture(name: &str, study_body: &str) -> Fixture {
    let dir = std::env::temp_dir().join(format!(
        "study-ui-{name}-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    ));
    std::fs::create_dir_all(&dir).unwrap();
    // A one-second walk: short presentations keep the tests quick.
    let walk = motion::synth::WalkParams {
        duration_s: 1.0,
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    };
    let made = lab::generated::walk_stimuli(&dir, &walk, &["spiht"], &[10.0, 20.0]).unwrap();
    let study_path = dir.join("study.toml");
    std::fs::write(
        &study_path,
        format!(
            "format_version = 1\nname = \"ui-{name}\"\nstimuli = \"stimuli/stimuli.json\"\nseed = 3\n{study_body}"
        ),
    )
    .unwrap();
    Fixture {
        dir,
        study_path,
        manifest: made.manifest,
    }
}

const MOS: &str = "protocol = \"mos\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
    [presentation]\nplayback_count = 1\nmax_replays = 1\n\
    [session]\nfamiliarization = 0\nhidden_repeats = 0\nsubject_fields = [\"age\"]\n";

const CONSENT: &str = "protocol = \"mos\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10]\n\
    [session]\nfamiliarization = 0\nhidden_repeats = 0\n\
    consent = \"Your answers are stored without your name.\"\n\
    instructions = \"Rate the motion on the right.\"\n";

/// One MOS trial behind a welcome asking every kind of subject field, and a consent text.
pub(super) const TYPED: &str = "protocol = \"mos\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10]\n\
    [session]\nfamiliarization = 0\nhidden_repeats = 0\n\
    consent = \"Your answers are stored without your name.\"\n\
    subject_fields = [\"handedness\", \
    { name = \"age\", kind = \"number\", min = 18, max = 99, integer = true }, \
    { name = \"gender\", kind = \"choice\", options = [\"female\", \"male\", \"another\", \"prefer not to say\"] }, \
    { name = \"normal_vision\", kind = \"yes_no\", label = \"Normal or corrected vision\" }]\n";

const DSCQS: &str = "protocol = \"dscqs\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10]\n\
    [presentation]\ngap_ms = 200\n\
    [scale]\nkind = \"categorical\"\n\
    [session]\nfamiliarization = 0\nhidden_repeats = 0\n";

const AFC: &str = "protocol = \"staircase\"\n\
    [presentation]\narrangement = \"side_by_side\"\n\
    [staircase]\nparam = \"cr\"\ncodec = \"spiht\"\nstart = 20\nstep = 10\nmin = 10\nmax = 20\n\
    stop_reversals = 2\nmax_trials = 3\n\
    [[staircase.tracks]]\nclip = \"walk\"\n";

/// A codec-in-the-loop staircase over the walk: each trial's stimulus is encoded at its level.
const LIVE: &str = "protocol = \"staircase\"\n\
    [presentation]\narrangement = \"side_by_side\"\n\
    [staircase]\nparam = \"cr\"\ncodec = \"wavelet-perceptual\"\nstart = 20\nstep = 10\n\
    min = 10\nmax = 40\nstop_reversals = 2\nmax_trials = 3\n\
    [staircase.live]\nclips = [\"walk\"]\nparams = { window = 64 }\n";

struct Run {
    fx: Fixture,
    session_dir: PathBuf,
}

fn harness(fx: Fixture) -> (Harness<'static, (StudyUi, FrameClock)>, Run) {
    harness_after(fx, |_| {})
}

/// [`harness`] over a session to which `before` has already logged some answers (a session
/// stopped part way and resumed).
fn harness_after(
    fx: Fixture,
    before: impl FnOnce(&mut Recorder),
) -> (Harness<'static, (StudyUi, FrameClock)>, Run) {
    let file = StudyFile::load(&fx.study_path).unwrap();
    let stimuli = lab::source::open(&file).unwrap();
    let study = file.definition;
    let session_dir = fx.dir.join("results").join("S01_s1");
    std::fs::create_dir_all(session_dir.parent().unwrap()).unwrap();
    let manifest = fresh_manifest(&study);
    let Opened::Ready { mut recorder, .. } = Recorder::open(
        &study,
        0,
        &mut results::FolderStore::new(fx.dir.join("results")),
        false,
        manifest,
    )
    .unwrap() else {
        panic!("new session reported finished");
    };
    before(&mut recorder);
    let ui = StudyUi::new(Arc::new(study), stimuli, recorder, false);
    let h = Harness::builder()
        .with_size(egui::vec2(1280.0, 720.0))
        .with_step_dt(DT)
        .build_ui_state(
            |ui, (screens, clock): &mut (StudyUi, FrameClock)| screens.ui(ui, clock),
            (ui, FrameClock::new(None)),
        );
    (h, Run { fx, session_dir })
}

pub(super) fn fresh_manifest(study: &StudyDefinition) -> results::SessionManifest {
    lab::session::new_manifest(
        study,
        lab::session::SessionOf {
            study_hash: "test",
            manifest_hash: "test",
            subject: "S01".into(),
            subject_index: 0,
            session: 1,
            observer_seed: None,
            group: None,
        },
    )
}

fn rows(dir: &Path) -> Vec<protocols::TrialRecord> {
    let path = dir.join(TRIALS_FILE);
    if !path.exists() {
        return Vec::new();
    }
    read_trials(&path).unwrap().records
}

/// Runs long enough for a one-second presentation (or DSCQS's A B A B) to finish.
fn watch(h: &mut Harness<'_, (StudyUi, FrameClock)>, seconds: f32) {
    h.run_steps((seconds / DT).ceil() as usize + 2);
}

fn begin(h: &mut Harness<'_, (StudyUi, FrameClock)>) {
    h.run_steps(2);
    h.get_by_label("Begin").click();
    h.run_steps(2);
}

#[test]
fn a_mos_trial_is_rated_by_clicking_four_and_a_half() {
    let (mut h, run) = harness(fixture("mos", MOS));
    h.run_steps(2);
    // The subject field must be filled before the session can begin.
    let age = h.get_by_role_and_label(egui::accesskit::Role::TextInput, "age");
    age.focus();
    h.run_steps(1);
    h.get_by_role_and_label(egui::accesskit::Role::TextInput, "age")
        .type_text("31");
    h.run_steps(2);
    h.get_by_label("Begin").click();
    h.run_steps(2);
    assert!(h.query_by_label("Trial 1 of 2").is_some());
    watch(&mut h, 1.2);
    h.get_by_label("4.5").click();
    h.run_steps(1);
    h.get_by_label("Continue").click();
    h.run_steps(2);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].response.answer, Answer::Rating(4.5));
    // The second trial (after the 0.5 s gap), by keyboard: 3, up (3.5), Enter.
    watch(&mut h, 1.7);
    h.key_press(Key::Num3);
    h.run_steps(1);
    h.key_press(Key::ArrowUp);
    h.run_steps(1);
    h.key_press(Key::Enter);
    h.run_steps(3);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 2);
    assert_eq!(r[1].response.answer, Answer::Rating(3.5));
    watch(&mut h, 0.5);
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    let m: results::SessionManifest = read_json(&run.session_dir.join(SESSION_FILE)).unwrap();
    assert_eq!(m.status, SessionState::Complete);
    assert_eq!(m.subject_fields.get("age").map(String::as_str), Some("31"));
    drop(run.fx);
}

#[test]
fn the_study_files_instructions_and_consent_gate_the_session() {
    let (mut h, run) = harness(fixture("consent", CONSENT));
    h.run_steps(2);
    assert!(h.query_by_label("Rate the motion on the right.").is_some());
    assert!(
        h.query_by_label("Your answers are stored without your name.")
            .is_some()
    );
    assert!(h.get_by_label("Begin").accesskit_node().is_disabled());
    assert!(
        h.query_by_label("To begin, tick “I agree to take part”.")
            .is_some(),
        "the hint says what is missing"
    );
    h.key_press(Key::Enter);
    h.run_steps(2);
    assert!(
        h.query_by_label("Trial 1 of 1").is_none(),
        "Enter must not skip consent"
    );
    h.get_by_label("I agree to take part").click();
    h.run_steps(2);
    h.get_by_label("Begin").click();
    h.run_steps(2);
    assert!(h.query_by_label("Trial 1 of 1").is_some());
    let m: results::SessionManifest = read_json(&run.session_dir.join(SESSION_FILE)).unwrap();
    assert_eq!(
        m.subject_fields.get("consent").map(String::as_str),
        Some("given")
    );
    drop(run.fx);
}

#[test]
fn a_response_before_the_stimulus_finished_is_ignored() {
    let (mut h, run) = harness(fixture("early", AFC));
    begin(&mut h);
    // Half-way through the presentation: the arrow key and the button do nothing.
    h.run_steps(5);
    h.key_press(Key::ArrowRight);
    h.run_steps(2);
    assert!(rows(&run.session_dir).is_empty());
    assert!(h.get_by_label("Right").accesskit_node().is_disabled());
    h.get_by_label("Right").click();
    h.run_steps(2);
    assert!(rows(&run.session_dir).is_empty());
    // Once shown, the right arrow answers.
    watch(&mut h, 1.0);
    h.key_press(Key::ArrowRight);
    h.run_steps(2);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].response.answer, Answer::Choice(Position::Right));
    assert_eq!(
        r[0].outcome.correct,
        Some(r[0].trial.reference_position == Position::Right)
    );
    assert!(r[0].response.response_time_ms > 0);
    drop(run.fx);
}

#[test]
fn a_dscqs_pair_is_rated_twice() {
    let (mut h, run) = harness(fixture("dscqs", DSCQS));
    begin(&mut h);
    // A, grey, B, grey, A, grey, B: 4 × 1 s + 3 × 0.2 s.
    watch(&mut h, 4.8);
    let fours: Vec<_> = h.get_all_by_label("4").collect();
    assert_eq!(fours.len(), 2, "one row of ratings for A and one for B");
    fours[0].click();
    h.run_steps(1);
    let twos: Vec<_> = h.get_all_by_label("2").collect();
    twos[1].click();
    h.run_steps(1);
    h.get_by_label("Continue").click();
    h.run_steps(3);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].response.answer, Answer::Pair { a: 4.0, b: 2.0 });
    let (reference, test) = if r[0].trial.reference_position == Position::A {
        (4.0, 2.0)
    } else {
        (2.0, 4.0)
    };
    assert_eq!(r[0].outcome.score_reference, Some(reference));
    assert_eq!(r[0].outcome.score_test, Some(test));
    watch(&mut h, 0.3);
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    drop(run.fx);
}

#[test]
fn a_dscqs_pair_can_be_rated_from_the_keyboard() {
    let (mut h, run) = harness(fixture("dscqs-keys", DSCQS));
    begin(&mut h);
    watch(&mut h, 4.8);
    // 5 rates A, 3 then ↓ rate B (2), Enter records.
    for key in [Key::Num5, Key::Num3, Key::ArrowDown, Key::Enter] {
        h.key_press(key);
        h.run_steps(1);
    }
    h.run_steps(2);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].response.answer, Answer::Pair { a: 5.0, b: 2.0 });
    drop(run.fx);
}

#[test]
fn pause_and_quit_need_confirmation_and_record_nothing() {
    let (mut h, run) = harness(fixture("pause", AFC));
    begin(&mut h);
    watch(&mut h, 1.2);
    // The experimenter's chord opens the pause; answer keys are ignored under it.
    h.key_press_modifiers(egui::Modifiers::CTRL | egui::Modifiers::SHIFT, Key::P);
    h.run_steps(2);
    assert!(h.query_by_label("Paused by the experimenter").is_some());
    h.key_press(Key::ArrowLeft);
    h.run_steps(2);
    assert!(rows(&run.session_dir).is_empty());
    // Quit asks once more; Back returns to the trial, shown again from the start.
    h.get_by_label("Quit session…").click();
    h.run_steps(2);
    assert!(h.query_by_label("Quit the session?").is_some());
    assert!(h.state().0.exit().is_none());
    h.get_by_label("Back").click();
    h.run_steps(2);
    assert!(
        h.get_by_label("Left").accesskit_node().is_disabled(),
        "the trial restarts its presentation"
    );
    watch(&mut h, 1.2);
    h.key_press(Key::ArrowLeft);
    h.run_steps(2);
    assert_eq!(rows(&run.session_dir).len(), 1);
    // Now quit for real: nothing else is recorded and the session stays resumable.
    h.key_press_modifiers(egui::Modifiers::CTRL | egui::Modifiers::SHIFT, Key::P);
    h.run_steps(2);
    h.get_by_label("Quit session…").click();
    h.run_steps(2);
    h.get_by_label("Quit and save").click();
    h.run_steps(2);
    assert_eq!(h.state().0.exit(), Some(&Exit::Quit { logged: 1 }));
    assert_eq!(rows(&run.session_dir).len(), 1);
    let m: results::SessionManifest = read_json(&run.session_dir.join(SESSION_FILE)).unwrap();
    assert_eq!(m.status, SessionState::Interrupted);
    assert_eq!(m.trials_logged, 1, "the manifest counts the rows on disk");
    // A signal afterwards changes nothing: the session has already stopped.
    h.state_mut().0.stop(Exit::Signalled { logged: 1 });
    assert_eq!(h.state().0.exit(), Some(&Exit::Quit { logged: 1 }));
    drop(run.fx);
}

#[test]
fn closing_the_window_mid_session_asks_first() {
    let (mut h, run) = harness(fixture("close", AFC));
    begin(&mut h);
    assert!(!h.state_mut().0.close_requested());
    h.run_steps(2);
    assert!(h.query_by_label("Quit the session?").is_some());
    drop(run.fx);
}

/// In the window, a live trial's stimulus is encoded at its level, and while the subject
/// watches, the levels a correct and a wrong answer lead to are encoded in the background:
/// after a wrong answer the next trial (a level up) is already cached.
#[test]
fn a_live_staircase_prefetches_the_next_levels_while_a_trial_runs() {
    let (mut h, run) = harness(fixture("live", LIVE));
    begin(&mut h);
    assert!(h.query_by_label("Trial 1 of at most 3").is_some());
    let live = h.state_mut().0.stimuli_mut();
    live.settle();
    // Level 20 shown; a correct answer keeps 20 (two-down), a wrong one goes up to 30.
    assert_eq!(live.ready(), 2);
    watch(&mut h, 1.0);
    let wrong = match rows(&run.session_dir).len() {
        0 => h.state().0.pending_reference().unwrap().other(),
        n => panic!("{n} rows before the first answer"),
    };
    h.key_press(if wrong == Position::Left {
        Key::ArrowLeft
    } else {
        Key::ArrowRight
    });
    h.run_steps(2);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].outcome.correct, Some(false));
    let e = r[0].encoding.as_ref().unwrap();
    assert_eq!(e.codec_params.get("cr"), Some(&20.0));
    assert!((e.achieved_cr - 20.0).abs() < 0.5, "{}", e.achieved_cr);
    // Trial 2 at 30 came from the cache; its own lookahead adds 40 (wrong) only, since a
    // correct answer keeps 30.
    watch(&mut h, 0.5);
    assert!(h.query_by_label("Trial 2 of at most 3").is_some());
    let live = h.state_mut().0.stimuli_mut();
    live.settle();
    assert_eq!(live.ready(), 3);
    drop(run.fx);
}

#[test]
fn practice_trials_before_a_staircase_are_marked_and_logged_as_practice() {
    let practice = AFC.replace("max_trials = 3\n", "max_trials = 3\npractice_trials = 1\n");
    let (mut h, run) = harness(fixture("practice", &practice));
    begin(&mut h);
    assert!(h.query_by_label("Trial 1 of at most 4").is_some());
    assert!(h.query_by_label("(practice)").is_some());
    for n in 1..=2 {
        watch(&mut h, 1.0);
        let right = h.state().0.pending_reference().unwrap();
        h.key_press(if right == Position::Left {
            Key::ArrowLeft
        } else {
            Key::ArrowRight
        });
        h.run_steps(2);
        assert_eq!(rows(&run.session_dir).len(), n);
        watch(&mut h, 0.5);
    }
    // Trial 2 is the staircase's first: no practice mark.
    assert!(h.query_by_label("(practice)").is_none());
    let r = rows(&run.session_dir);
    assert_eq!(r[0].trial.block, protocols::Block::Familiarization);
    assert_eq!(r[0].trial.level, Some(20.0));
    assert_eq!(r[0].outcome.reversal, None);
    assert_eq!(r[1].trial.block, protocols::Block::Test);
    drop(run.fx);
}

#[test]
fn the_experimenter_confirms_the_viewing_conditions_before_the_welcome() {
    let viewing = format!(
        "{MOS}[viewing]\ndistance_ph = 3\nscreen_size_cm = [60, 34]\n\
         peak_luminance_cd_m2 = 150\nroom_illuminance_lux = 20\n"
    );
    let (mut h, run) = harness(fixture("viewing", &viewing));
    h.run_steps(2);
    assert!(
        h.query_by_label("Viewing conditions (experimenter)")
            .is_some()
    );
    assert!(h.query_by_label("3 H (102 cm)").is_some());
    assert!(h.query_by_label("Begin").is_none());
    let field = "measured viewing distance (cm)";
    h.get_by_role_and_label(Role::TextInput, field).focus();
    h.run_steps(1);
    h.get_by_role_and_label(Role::TextInput, field)
        .type_text("10O");
    h.run_steps(2);
    h.get_by_label(super::viewing::CONFIRM).click();
    h.run_steps(2);
    // A typo is named and nothing is recorded.
    assert!(
        h.query_by_label("measured viewing distance: \"10O\" is not a number of cm")
            .is_some()
    );
    let manifest: results::SessionManifest =
        read_json(&run.session_dir.join(SESSION_FILE)).unwrap();
    assert_eq!(manifest.viewing, Some(results::ViewingRecord::default()));
    h.get_by_role_and_label(Role::TextInput, field).focus();
    h.run_steps(1);
    h.key_press(Key::Backspace);
    h.get_by_role_and_label(Role::TextInput, field)
        .type_text("0");
    h.run_steps(2);
    h.get_by_label(super::viewing::CONFIRM).click();
    h.run_steps(2);
    assert!(h.query_by_label("Begin").is_some());
    let manifest: results::SessionManifest =
        read_json(&run.session_dir.join(SESSION_FILE)).unwrap();
    let v = manifest.viewing.unwrap();
    assert!(v.confirmed && v.confirmed_ms.is_some());
    assert_eq!(v.distance_cm, Some(100.0));
    assert_eq!(v.peak_luminance_cd_m2, None);
    drop(run.fx);
}

/// A MOS study with a title, a 0.4 s gap and a break before every second trial.
const MOS_LABELLED: &str = "protocol = \"mos\"\ntitle = \"Motion quality\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
    [presentation]\nloop = true\ngap_ms = 400\n\
    [session]\nbreak_every_trials = 1\nsubject_fields = [\"age\", \"normal_vision\"]\n";

/// The label nodes reading `text`.
fn label_rects(h: &Harness<'_, (StudyUi, FrameClock)>, text: &str) -> Vec<egui::Rect> {
    h.get_all_by_label(text).map(|n| n.rect()).collect()
}

#[test]
fn a_mos_trial_says_which_motion_is_the_original() {
    let (mut h, run) = harness(fixture("labels", MOS_LABELLED));
    h.run_steps(2);
    // The subject sees the study's title, and the instructions say which is which.
    assert!(h.query_by_label("Motion quality").is_some());
    assert!(
        h.query_by_label("ui-labels").is_none(),
        "not the internal name"
    );
    let instructions = super::screens::default_instructions(h.state().0.study_for_tests());
    assert!(
        instructions.contains("labelled “Original”") && instructions.contains("“Compressed”"),
        "{instructions}"
    );
    assert!(h.query_by_label(&instructions).is_some());
    // Begin names what is missing, a line for each field.
    for line in [
        "age: enter an answer (required)",
        "normal vision: enter an answer (required)",
    ] {
        assert!(h.query_by_label(line).is_some(), "{line}");
    }
    for (field, value) in [("age", "31"), ("normal vision", "yes")] {
        let node = h.get_by_role_and_label(Role::TextInput, field);
        node.focus();
        h.run_steps(1);
        h.get_by_role_and_label(Role::TextInput, field)
            .type_text(value);
        h.run_steps(1);
        if field == "age" {
            h.run_steps(1);
            assert!(
                h.query_by_label("age: enter an answer (required)")
                    .is_none()
            );
            assert!(
                h.query_by_label("normal vision: enter an answer (required)")
                    .is_some()
            );
        }
    }
    h.run_steps(1);
    h.get_by_label("Begin").click();
    h.run_steps(3);
    // Both labels, each above its own motion: the reference's side is the plan's.
    let original = label_rects(&h, "Original");
    let compressed = label_rects(&h, "Compressed");
    assert_eq!((original.len(), compressed.len()), (1, 1));
    let reference = h.state().0.pending_reference().unwrap();
    let left_is_original = original[0].center().x < compressed[0].center().x;
    assert_eq!(left_is_original, reference == Position::Left);
    assert!((original[0].center().y - compressed[0].center().y).abs() < 1.0);
    assert!(
        h.query_by_label("Rate the quality of the motion labelled “Compressed”")
            .is_some()
    );
    // Continue is disabled, with a hint, until a rating is chosen.
    watch(&mut h, 1.2);
    assert!(h.get_by_label("Continue").accesskit_node().is_disabled());
    assert!(
        h.query_by_label("Choose a rating for “Compressed” to continue.")
            .is_some()
    );
    h.get_by_label("4").click();
    h.run_steps(1);
    assert!(
        h.query_by_label("Choose a rating for “Compressed” to continue.")
            .is_none()
    );
    h.get_by_label("Continue").click();
    h.run_steps(2);
    assert_eq!(rows(&run.session_dir).len(), 1);
    // The gap: a blank (no stimulus labels, no answer row) saying the answer was taken.
    assert!(h.query_by_label("Answer recorded.").is_some());
    assert!(h.query_by_label("Original").is_none());
    assert!(h.query_by_label("Continue").is_none());
    // Then the break, with the progress so far.
    watch(&mut h, 0.4);
    assert!(h.query_by_label("Take a short break.").is_some());
    assert!(h.query_by_label("Trials done: 1 of 2.").is_some());
    h.get_by_label("Continue").click();
    h.run_steps(2);
    assert!(h.query_by_label("Trial 2 of 2").is_some());
    watch(&mut h, 1.2);
    h.key_press(Key::Num2);
    h.run_steps(1);
    h.key_press(Key::Enter);
    h.run_steps(1);
    assert_eq!(rows(&run.session_dir).len(), 2);
    // The end screen stays until the subject closes it; the Enter that answered, or one
    // pressed at once, does not close it.
    watch(&mut h, 0.5);
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    assert!(
        h.query_by_label("The session is complete. Thank you!")
            .is_some()
    );
    h.key_press(Key::Enter);
    h.run_steps(1);
    assert!(!h.state().0.may_close());
    watch(&mut h, 3.0);
    assert!(
        !h.state().0.may_close(),
        "the end screen does not close by itself"
    );
    h.get_by_label("Close").click();
    h.run_steps(1);
    assert!(h.state().0.may_close());
    drop(run.fx);
}

#[test]
fn labels_can_be_hidden_and_are_never_shown_in_a_staircase() {
    let hidden = MOS.replace("max_replays = 1\n", "max_replays = 1\nlabels = false\n");
    let (mut h, run) = harness(fixture("nolabels", &hidden));
    h.run_steps(2);
    h.get_by_role_and_label(Role::TextInput, "age").focus();
    h.run_steps(1);
    h.get_by_role_and_label(Role::TextInput, "age")
        .type_text("40");
    h.run_steps(2);
    h.get_by_label("Begin").click();
    h.run_steps(3);
    assert!(h.query_by_label("Trial 1 of 2").is_some());
    assert!(h.query_by_label("Original").is_none());
    assert!(
        h.query_by_label("Rate the quality of the compressed motion")
            .is_some()
    );
    drop(run.fx);
    let (mut h, run) = harness(fixture("afc-labels", AFC));
    begin(&mut h);
    assert!(h.query_by_label("Trial 1 of at most 3").is_some());
    assert!(h.query_by_label("Original").is_none() && h.query_by_label("Compressed").is_none());
    drop(run.fx);
}

/// DSCQS on BT.500's continuous scale, with a short grey.
const DSCQS_CONTINUOUS: &str = "protocol = \"dscqs\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10]\n\
    [presentation]\ngrey_ms = 200\n\
    [session]\nfamiliarization = 0\nhidden_repeats = 0\n";

#[test]
fn dscqs_votes_on_two_vertical_scales_by_mouse_and_keys() {
    let (mut h, run) = harness(fixture("dscqs-cont", DSCQS_CONTINUOUS));
    begin(&mut h);
    // No scale while A, grey, B, grey, A, grey, B play (4 × 1 s + 3 × 0.2 s).
    watch(&mut h, 4.3);
    assert!(h.query_by_role_and_label(Role::Slider, "A").is_none());
    watch(&mut h, 0.5);
    // Two unmarked vertical scales (no value until the subject marks one), the five labels
    // once each per scale, a disabled Continue and the hint saying what is missing.
    for name in ["A", "B"] {
        let node = h.get_by_role_and_label(Role::Slider, name);
        assert_eq!(
            node.accesskit_node().numeric_value(),
            None,
            "{name} unmarked"
        );
        assert!(!node.accesskit_node().is_disabled());
        let r = node.rect();
        assert!(r.height() > 2.0 * r.width(), "{name} is vertical: {r:?}");
    }
    assert!(h.get_by_label("Continue").accesskit_node().is_disabled());
    assert!(
        h.query_by_label("Mark the scale of A and B to continue.")
            .is_some()
    );
    assert!(
        h.query_by_label("rating A").is_none(),
        "no internal ids on screen"
    );
    // A click in the middle of B marks it 50 and makes B the scale the keys move.
    h.get_by_role_and_label(Role::Slider, "B").click();
    h.run_steps(1);
    assert_eq!(
        h.get_by_role_and_label(Role::Slider, "B")
            .accesskit_node()
            .numeric_value(),
        Some(50.0)
    );
    assert!(
        h.query_by_label("Mark the scale of A to continue.")
            .is_some()
    );
    // ← selects A, 4 puts its mark in "Good" (70) and moves on to B, ↑ raises B to 51,
    // Page Down lowers it to 41.
    for key in [Key::ArrowLeft, Key::Num4, Key::ArrowUp, Key::PageDown] {
        h.key_press(key);
        h.run_steps(1);
    }
    let value = |h: &Harness<'_, (StudyUi, FrameClock)>, name: &str| {
        h.get_by_role_and_label(Role::Slider, name)
            .accesskit_node()
            .numeric_value()
    };
    assert_eq!((value(&h, "A"), value(&h, "B")), (Some(70.0), Some(41.0)));
    assert!(!h.get_by_label("Continue").accesskit_node().is_disabled());
    h.key_press(Key::Enter);
    h.run_steps(2);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].response.answer, Answer::Pair { a: 70.0, b: 41.0 });
    drop(run.fx);
}

#[test]
fn a_dscqs_scale_is_divided_into_the_five_bt500_grades() {
    let (mut h, run) = harness(fixture("dscqs-grades", DSCQS_CONTINUOUS));
    begin(&mut h);
    watch(&mut h, 4.8);
    let a = h.get_by_role_and_label(Role::Slider, "A").rect();
    // Clicking in each fifth from the top gives a value in that grade's 20-point band.
    for (k, grade) in ["Excellent", "Good", "Fair", "Poor", "Bad"]
        .iter()
        .enumerate()
    {
        let y = a.top() + 8.0 + (a.height() - 16.0) * (k as f32 + 0.5) / 5.0;
        let at = egui::pos2(a.center().x, y);
        h.hover_at(at);
        h.run_steps(1);
        h.drag_at(at);
        h.drop_at(at);
        h.run_steps(2);
        let v = h
            .get_by_role_and_label(Role::Slider, "A")
            .accesskit_node()
            .numeric_value()
            .unwrap();
        let band = (80.0 - 20.0 * k as f64)..=(100.0 - 20.0 * k as f64);
        assert!(band.contains(&v), "{grade}: {v} outside {band:?}");
    }
    drop(run.fx);
}

/// The results database stopped with an answer uncommitted: the window says so, keeps the
/// answer, shows no next trial, and goes on when the server is back (a throw-away PostgreSQL
/// server; under CI a missing one fails the test, elsewhere it is skipped).
#[test]
fn a_database_outage_keeps_the_answer_and_the_window_says_so() {
    use results::pg::scratch::{ScratchServer, bin_dir};
    let mut server = match ScratchServer::start(&std::env::temp_dir(), &["fsync=off"]) {
        Ok(s) => s,
        Err(e) if std::env::var_os("CI").is_none() && bin_dir().is_err() => {
            eprintln!("skipped: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let fx = fixture("pg", MOS);
    let file = StudyFile::load(&fx.study_path).unwrap();
    let stimuli = lab::source::open(&file).unwrap();
    let db = server.create_database("ui").unwrap();
    let (mut store, _) = lab::results_dir::open_database_for_subjects(&db, None, &file).unwrap();
    let study = file.definition;
    let Opened::Ready { recorder, .. } =
        Recorder::open(&study, 0, &mut store, false, fresh_manifest(&study)).unwrap()
    else {
        panic!("new session reported finished");
    };
    let answers = || -> i64 {
        db.connect()
            .unwrap()
            .query_one("SELECT count(*) FROM study_trials", &[])
            .map_or(-1, |r| r.get(0))
    };
    let ui = StudyUi::new(Arc::new(study), stimuli, recorder, false);
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 720.0))
        .with_step_dt(DT)
        .build_ui_state(
            |ui, (screens, clock): &mut (StudyUi, FrameClock)| screens.ui(ui, clock),
            (ui, FrameClock::new(None)),
        );
    h.run_steps(2);
    h.get_by_role_and_label(Role::TextInput, "age").focus();
    h.run_steps(1);
    h.get_by_role_and_label(Role::TextInput, "age")
        .type_text("40");
    h.run_steps(2);
    begin(&mut h);
    watch(&mut h, 1.2);
    h.get_by_label("4.5").click();
    h.run_steps(1);
    h.get_by_label("Continue").click();
    h.run_steps(2);
    assert_eq!(answers(), 1);
    server.stop();
    watch(&mut h, 1.7);
    h.key_press(Key::Num3);
    h.run_steps(1);
    h.key_press(Key::Enter);
    h.run_steps(3);
    assert!(
        h.query_by_label("The results database cannot be reached")
            .is_some()
    );
    assert!(h.state().0.exit().is_none());
    server.resume().unwrap();
    // Tried again every second: the answer goes in, and the session ends (2 trials).
    watch(&mut h, 2.5);
    assert!(
        h.query_by_label("The results database cannot be reached")
            .is_none()
    );
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    assert_eq!(answers(), 2);
    drop(fx);
}

/// ACR-HR over the one-second walk: the two compressed versions and the walk's reference as
/// a hidden reference.
const ACR_HR: &str = "protocol = \"acr\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
    hidden_reference = true\n\
    [presentation]\ngap_ms = 200\n\
    [session]\nfamiliarization = 0\nhidden_repeats = 0\n";

const DCR: &str = "protocol = \"dcr\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10]\n\
    [presentation]\ngrey_ms = 200\n\
    [session]\nfamiliarization = 0\nhidden_repeats = 0\n";

/// ACR (P.910): each trial shows one motion alone, unlabelled, then asks for one of the five
/// quality grades on grey; every condition, the hidden reference included, is rated once and
/// logged as a single-stimulus trial whose reference was hidden.
#[test]
fn an_acr_trial_shows_one_motion_and_takes_a_grade() {
    let (mut h, run) = harness(fixture("acr", ACR_HR));
    begin(&mut h);
    assert!(h.query_by_label("Trial 1 of 3").is_some());
    assert!(h.query_by_label("Rate the quality of the motion").is_some());
    for grade in ["Excellent", "Good", "Fair", "Poor", "Bad"] {
        assert!(h.query_by_label(grade).is_some(), "{grade}");
    }
    assert_eq!(
        h.query_all_by_label("Original").count(),
        0,
        "no reference shown"
    );
    assert_eq!(h.state().0.pending_reference(), Some(Position::Hidden));
    // After the one-second motion: the vote on grey.
    watch(&mut h, 1.2);
    assert!(h.query_by_label("Please answer below").is_some());
    for (k, key) in [Key::Num5, Key::Num2, Key::Num4].into_iter().enumerate() {
        h.key_press(key);
        h.run_steps(1);
        h.key_press(Key::Enter);
        h.run_steps(3);
        assert_eq!(rows(&run.session_dir).len(), k + 1);
        watch(&mut h, 1.5);
    }
    let r = rows(&run.session_dir);
    let answers: Vec<Answer> = r.iter().map(|r| r.response.answer).collect();
    assert_eq!(
        answers,
        [
            Answer::Rating(5.0),
            Answer::Rating(2.0),
            Answer::Rating(4.0)
        ]
    );
    let mut shown: Vec<&str> = r.iter().map(|r| r.trial.stimulus.as_str()).collect();
    shown.sort_unstable();
    assert_eq!(shown.len(), 3);
    assert!(shown.contains(&"walk/reference"), "{shown:?}");
    for r in &r {
        assert_eq!(r.protocol, protocols::Protocol::Acr);
        assert_eq!(r.trial.arrangement, protocols::Arrangement::Single);
    }
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    drop(run.fx);
}

/// DCR (P.910): the labelled reference first, grey, the labelled test, then one of the five
/// impairment categories.
#[test]
fn a_dcr_trial_shows_the_reference_first_and_takes_an_impairment() {
    let (mut h, run) = harness(fixture("dcr", DCR));
    begin(&mut h);
    assert_eq!(h.state().0.pending_reference(), Some(Position::First));
    // The first interval is the reference, labelled so.
    assert_eq!(label_rects(&h, "Original").len(), 1);
    assert_eq!(h.query_all_by_label("Compressed").count(), 0);
    assert!(
        h.query_by_label("How impaired is “Compressed” compared with “Original”?")
            .is_some()
    );
    for words in [
        "Imperceptible",
        "Perceptible but not annoying",
        "Slightly annoying",
        "Annoying",
        "Very annoying",
    ] {
        assert!(h.query_by_label(words).is_some(), "{words}");
    }
    // The grade buttons are evenly spaced on one line, however long their words.
    let centres: Vec<egui::Pos2> = ["1", "2", "3", "4", "5"]
        .iter()
        .map(|k| h.get_by_role_and_label(Role::Button, k).rect().center())
        .collect();
    let gaps: Vec<f32> = centres.windows(2).map(|w| w[1].x - w[0].x).collect();
    assert!(
        gaps.iter().all(|g| (g - gaps[0]).abs() < 0.5)
            && centres.iter().all(|c| (c.y - centres[0].y).abs() < 0.5),
        "grade buttons at {centres:?}"
    );
    watch(&mut h, 1.1);
    assert_eq!(label_rects(&h, "Compressed").len(), 1, "then the test");
    watch(&mut h, 1.0);
    h.get_by_label("3").click();
    h.run_steps(1);
    h.get_by_label("Continue").click();
    h.run_steps(2);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].response.answer, Answer::Rating(3.0));
    assert_eq!(r[0].protocol, protocols::Protocol::Dcr);
    drop(run.fx);
}

/// A pair comparison over the one-second walk: its two compressed versions and its original,
/// unlabelled, in pairs.
const PC: &str = "protocol = \"pair_comparison\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
    hidden_reference = true\n\
    [presentation]\ngap_ms = 200\n\
    [session]\nhidden_repeats = 0\n";

/// Pair comparison (P.910 PC): two unlabelled versions side by side and "which looks
/// better?"; the Left/Right buttons and keys stay closed until the motions have played, then
/// a key or a click answers; the three pairs are logged with the position picked and the
/// score saying which column's version won.
#[test]
fn a_pair_comparison_trial_shows_two_versions_and_takes_a_side() {
    let (mut h, run) = harness(fixture("pc", PC));
    begin(&mut h);
    assert!(h.query_by_label("Trial 1 of 3").is_some());
    assert!(h.query_by_label("Which motion looks better?").is_some());
    assert!(h.query_by_label("Original").is_none() && h.query_by_label("Compressed").is_none());
    assert!(h.get_by_label("Left").accesskit_node().is_disabled());
    // An early key is ignored.
    h.key_press(Key::ArrowLeft);
    h.run_steps(1);
    assert_eq!(rows(&run.session_dir).len(), 0);
    watch(&mut h, 1.2);
    h.key_press(Key::ArrowLeft);
    h.run_steps(3);
    assert_eq!(rows(&run.session_dir).len(), 1);
    watch(&mut h, 1.5);
    watch(&mut h, 1.2);
    h.get_by_label("Right").click();
    h.run_steps(3);
    assert_eq!(rows(&run.session_dir).len(), 2);
    watch(&mut h, 1.5);
    watch(&mut h, 1.2);
    h.key_press(Key::ArrowRight);
    h.run_steps(3);
    let r = rows(&run.session_dir);
    let picked: Vec<Answer> = r.iter().map(|r| r.response.answer).collect();
    assert_eq!(
        picked,
        [
            Answer::Choice(Position::Left),
            Answer::Choice(Position::Right),
            Answer::Choice(Position::Right)
        ]
    );
    let mut pairs: Vec<&str> = r.iter().map(|r| r.trial.condition.as_str()).collect();
    pairs.sort_unstable();
    pairs.dedup();
    assert_eq!(pairs.len(), 3, "every pair once: {pairs:?}");
    for r in &r {
        assert_eq!(r.protocol, protocols::Protocol::PairComparison);
        let Answer::Choice(p) = r.response.answer else {
            unreachable!()
        };
        let stimulus_won = p != r.trial.reference_position;
        let want: f64 = if stimulus_won { 1.0 } else { 0.0 };
        assert_eq!(r.outcome.score.to_bits(), want.to_bits());
    }
    watch(&mut h, 1.5);
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    drop(run.fx);
}

/// MUSHRA over the one-second walk: the test at 10:1, the hidden reference and the 20:1
/// anchor on one screen.
const MUSHRA: &str = "protocol = \"mushra\"\n\
    [conditions]\nstimuli = [\"walk/spiht/cr10\"]\n\
    [mushra]\nanchors = [\"walk/spiht/cr20\"]\n\
    [presentation]\ngap_ms = 200\n";

fn sliders(h: &Harness<'_, (StudyUi, FrameClock)>) -> Vec<(egui::Rect, bool)> {
    let mut v: Vec<(egui::Rect, bool)> = h
        .get_all_by_role(Role::Slider)
        .map(|n| (n.rect(), n.accesskit_node().is_disabled()))
        .collect();
    v.sort_by(|a, b| a.0.left().total_cmp(&b.0.left()));
    v
}

/// Focuses the `k`-th slider from the left and presses `keys` on it, a frame each.
fn set_slider(h: &mut Harness<'_, (StudyUi, FrameClock)>, k: usize, keys: &[Key]) {
    let rect = sliders(h)[k].0;
    h.get_all_by_role(Role::Slider)
        .find(|n| n.rect() == rect)
        .unwrap()
        .focus();
    h.run_steps(1);
    for key in keys {
        h.key_press(*key);
        h.run_steps(1);
    }
}

/// MUSHRA (BS.1534 adapted): the labelled reference and the lettered panes together, a
/// slider per letter that stays shut (keys and clicks ignored) until every pane has played;
/// then each is set from the keyboard (focus, arrows by one, Page Up by ten), Continue waits
/// for every letter, and one row per pane is logged in pane order.
#[test]
fn a_mushra_screen_rates_every_pane_on_a_slider_after_the_play() {
    let (mut h, run) = harness(fixture("mushra", MUSHRA));
    begin(&mut h);
    assert!(
        h.query_by_label("Trials done: 0 of 3. This screen: 3 lettered motions.")
            .is_some()
    );
    assert_eq!(label_rects(&h, "Reference").len(), 1);
    for letter in ["A", "B", "C"] {
        // Above its pane and above its slider.
        assert_eq!(label_rects(&h, letter).len(), 2, "{letter}");
    }
    let shut = sliders(&h);
    assert_eq!(shut.len(), 3);
    assert!(shut.iter().all(|(_, disabled)| *disabled), "{shut:?}");
    // Keys and Enter while the panes play: nothing.
    h.get_all_by_role(Role::Slider).next().unwrap().focus();
    h.run_steps(1);
    h.key_press(Key::PageUp);
    h.key_press(Key::Enter);
    h.run_steps(2);
    assert!(rows(&run.session_dir).is_empty());
    assert_eq!(h.query_all_by_label("–").count(), 3, "still unrated");
    watch(&mut h, 1.2);
    assert!(sliders(&h).iter().all(|(_, disabled)| !*disabled));
    set_slider(
        &mut h,
        0,
        &[Key::ArrowUp, Key::ArrowUp, Key::ArrowUp, Key::PageUp],
    );
    set_slider(&mut h, 1, &[Key::PageUp; 5]);
    set_slider(&mut h, 1, &[Key::ArrowDown]);
    // Two of three rated: Continue stays shut and says which letter is left.
    assert!(h.query_by_label("Rate C to continue.").is_some());
    h.key_press(Key::Enter);
    h.run_steps(2);
    assert!(rows(&run.session_dir).is_empty());
    set_slider(&mut h, 2, &[Key::ArrowUp]);
    h.get_by_label("Continue").click();
    h.run_steps(3);
    let r = rows(&run.session_dir);
    let got: Vec<(String, Answer)> = r
        .iter()
        .map(|r| (r.trial.reference_position.to_string(), r.response.answer))
        .collect();
    assert_eq!(
        got,
        [
            ("pane_a".to_string(), Answer::Rating(13.0)),
            ("pane_b".to_string(), Answer::Rating(49.0)),
            ("pane_c".to_string(), Answer::Rating(1.0)),
        ]
    );
    let mut shown: Vec<&str> = r.iter().map(|r| r.trial.stimulus.as_str()).collect();
    shown.sort_unstable();
    assert_eq!(
        shown,
        ["walk/reference", "walk/spiht/cr10", "walk/spiht/cr20"]
    );
    assert!(r.iter().all(|r| r.protocol == protocols::Protocol::Mushra
        && r.trial.arrangement == protocols::Arrangement::Grid
        && r.trial.reference == "walk/reference"));
    watch(&mut h, 0.5);
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    drop(run.fx);
}

/// A MUSHRA training screen (`[session] familiarization = 1`): the same clip's screen twice,
/// first marked "(practice)" and logged in block familiarization, then the test screen on a
/// screen of its own (its three panes, not six), unmarked, logged in block test.
#[test]
fn a_mushra_training_screen_is_marked_and_logged_apart_from_the_test() {
    let study = format!("{MUSHRA}[session]\nfamiliarization = 1\n");
    let (mut h, run) = harness(fixture("mushra-training", &study));
    begin(&mut h);
    assert!(
        h.query_by_label("Trials done: 0 of 6. This screen: 3 lettered motions.")
            .is_some()
    );
    for (screen, practice) in [(0, true), (1, false)] {
        assert_eq!(
            h.query_by_label("(practice)").is_some(),
            practice,
            "screen {screen}"
        );
        assert_eq!(sliders(&h).len(), 3, "screen {screen}");
        watch(&mut h, 1.2);
        for k in 0..3 {
            set_slider(&mut h, k, &[Key::PageUp]);
        }
        h.key_press(Key::Enter);
        h.run_steps(3);
        assert_eq!(rows(&run.session_dir).len(), 3 * (screen + 1));
        watch(&mut h, 0.5);
    }
    let blocks: Vec<protocols::Block> = rows(&run.session_dir)
        .iter()
        .map(|r| r.trial.block)
        .collect();
    assert_eq!(
        blocks,
        [
            [protocols::Block::Familiarization; 3],
            [protocols::Block::Test; 3]
        ]
        .concat()
    );
    assert!(matches!(h.state().0.exit(), Some(Exit::Finished(_))));
    drop(run.fx);
}

/// A MUSHRA session stopped after the first pane of a screen was logged shows, on resume,
/// the reference and the panes not yet rated (B and C, not A), and logs them after it.
#[test]
fn a_mushra_screen_resumed_part_way_shows_the_panes_left() {
    let mut first = None;
    let (mut h, run) = harness_after(fixture("mushra-resume", MUSHRA), |recorder| {
        let t = recorder.next_trial(0).unwrap().unwrap();
        let response = protocols::Response {
            answer: Answer::Rating(70.0),
            response_time_ms: 900,
            replays: 0,
            dropped_frames: 0,
        };
        recorder.record(t.clone(), response, 0, None, None).unwrap();
        first = Some(t);
    });
    begin(&mut h);
    assert!(
        h.query_by_label("Trials done: 1 of 3. This screen: 2 lettered motions.")
            .is_some()
    );
    assert_eq!(label_rects(&h, "Reference").len(), 1);
    assert_eq!(h.query_all_by_label("A").count(), 0, "pane A was rated");
    for letter in ["B", "C"] {
        assert_eq!(label_rects(&h, letter).len(), 2, "{letter}");
    }
    watch(&mut h, 1.2);
    for k in 0..2 {
        set_slider(&mut h, k, &[Key::PageUp]);
    }
    h.key_press(Key::Enter);
    h.run_steps(3);
    let r = rows(&run.session_dir);
    assert_eq!(r.len(), 3);
    assert_eq!(Some(&r[0].trial), first.as_ref());
    let panes: Vec<String> = r
        .iter()
        .map(|r| r.trial.reference_position.to_string())
        .collect();
    assert_eq!(panes, ["pane_a", "pane_b", "pane_c"]);
    let answers: Vec<Answer> = r.iter().map(|r| r.response.answer).collect();
    assert_eq!(
        answers,
        [
            Answer::Rating(70.0),
            Answer::Rating(10.0),
            Answer::Rating(10.0)
        ]
    );
    drop(run.fx);
}

fn begin_disabled(h: &Harness<'_, (StudyUi, FrameClock)>) -> bool {
    h.get_by_label("Begin").accesskit_node().is_disabled()
}

/// Types `text` into the text box labelled `label` (after what it holds).
fn type_into(h: &mut Harness<'_, (StudyUi, FrameClock)>, label: &str, text: &str) {
    h.get_by_role_and_label(Role::TextInput, label).focus();
    h.run_steps(1);
    h.get_by_role_and_label(Role::TextInput, label)
        .type_text(text);
    h.run_steps(2);
}

/// The welcome draws each subject field by its kind: text boxes for a text and a number,
/// radio buttons for a choice and for yes or no. A number that is not one ("abc") keeps Begin
/// disabled, and the line under it says why in the field's check's words; once every field
/// passes, Begin stores each answer as its check writes it (" 31 " as "31", "Yes" as "yes").
#[test]
fn typed_subject_fields_gate_begin_and_are_stored_as_checked() {
    let (mut h, run) = harness(fixture("typed", TYPED));
    h.run_steps(2);
    assert!(begin_disabled(&h));
    for option in [
        "female",
        "male",
        "another",
        "prefer not to say",
        "Yes",
        "No",
    ] {
        let node = h.get_by_role_and_label(Role::RadioButton, option);
        assert_ne!(
            node.accesskit_node().toggled(),
            Some(egui::accesskit::Toggled::True)
        );
    }
    type_into(&mut h, "handedness", "left");
    type_into(&mut h, "age", "abc");
    h.get_by_role_and_label(Role::RadioButton, "male").click();
    h.run_steps(1);
    h.get_by_role_and_label(Role::RadioButton, "Yes").click();
    h.run_steps(1);
    h.get_by_label("I agree to take part").click();
    h.run_steps(2);
    assert!(
        h.query_by_label("age: enter a whole number from 18 to 99")
            .is_some(),
        "the reason under Begin"
    );
    assert!(begin_disabled(&h), "abc is not an age");
    assert!(
        h.query_by_label(
            "gender: choose one of: female, male, another, prefer not to say (required)"
        )
        .is_none()
    );
    h.key_press(Key::Enter);
    h.run_steps(2);
    assert!(
        h.query_by_label("Trial 1 of 1").is_none(),
        "Enter does not begin"
    );
    // Out of range, then a whole number with spaces around it.
    h.get_by_role_and_label(Role::TextInput, "age").focus();
    h.run_steps(1);
    for _ in 0..3 {
        h.key_press(Key::Backspace);
        h.run_steps(1);
    }
    type_into(&mut h, "age", "17");
    assert!(begin_disabled(&h), "17 is under the minimum");
    for _ in 0..2 {
        h.key_press(Key::Backspace);
        h.run_steps(1);
    }
    type_into(&mut h, "age", " 31 ");
    assert!(
        h.query_by_label("age: enter a whole number from 18 to 99")
            .is_none()
    );
    assert!(!begin_disabled(&h));
    h.get_by_label("Begin").click();
    h.run_steps(2);
    assert!(h.query_by_label("Trial 1 of 1").is_some());
    let m: results::SessionManifest = read_json(&run.session_dir.join(SESSION_FILE)).unwrap();
    let stored: Vec<(&str, &str)> = m
        .subject_fields
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    for want in [
        ("handedness", "left"),
        ("age", "31"),
        ("gender", "male"),
        ("normal_vision", "yes"),
        ("consent", "given"),
    ] {
        assert!(stored.contains(&want), "{want:?} in {stored:?}");
    }
    drop(run.fx);
}

/// A resumed session's welcome shows the answers stored for it: the typed ones in their
/// boxes, the chosen options selected; Begin waits only for the consent box.
#[test]
fn a_resumed_welcome_shows_the_stored_field_values() {
    let (mut h, run) = harness_after(fixture("typed-resume", TYPED), |recorder| {
        recorder
            .update_manifest(|m| {
                for (k, v) in [
                    ("handedness", "right"),
                    ("age", "42"),
                    ("gender", "prefer not to say"),
                    ("normal_vision", "no"),
                ] {
                    m.subject_fields.insert(k.into(), v.into());
                }
            })
            .unwrap();
    });
    h.run_steps(2);
    let value = |h: &Harness<'_, (StudyUi, FrameClock)>, label: &str| {
        h.get_by_role_and_label(Role::TextInput, label)
            .accesskit_node()
            .value()
    };
    assert_eq!(value(&h, "age").as_deref(), Some("42"));
    assert_eq!(value(&h, "handedness").as_deref(), Some("right"));
    for (option, on) in [
        ("prefer not to say", true),
        ("female", false),
        ("No", true),
        ("Yes", false),
    ] {
        let toggled = h
            .get_by_role_and_label(Role::RadioButton, option)
            .accesskit_node()
            .toggled();
        assert_eq!(
            toggled == Some(egui::accesskit::Toggled::True),
            on,
            "{option}"
        );
    }
    assert!(
        h.query_by_label("To begin, tick “I agree to take part”.")
            .is_some()
    );
    assert_eq!(
        h.query_all_by_label_contains("enter").count()
            + h.query_all_by_label_contains("choose").count(),
        0,
        "no field is refused"
    );
    h.get_by_label("I agree to take part").click();
    h.run_steps(2);
    assert!(!begin_disabled(&h));
    drop(run.fx);
}

/// The MUSHRA sliders stand beside BS.1534's five words in equal sections, Excellent at the
/// top, with 100 and 0 marked at the ends; an unrated slider's knob is drawn hollow below the
/// 0 line (apart from a rating of 0) and reads as no value, a rated one on the scale.
#[test]
fn mushra_sliders_have_the_scale_words_and_unrated_knobs_apart_from_zero() {
    let (mut h, run) = harness(fixture("mushra-scale", MUSHRA));
    begin(&mut h);
    watch(&mut h, 1.2);
    let centre = |h: &Harness<'_, (StudyUi, FrameClock)>, text: &str| {
        let r = label_rects(h, text);
        assert_eq!(r.len(), 1, "{text}: {r:?}");
        r[0].center()
    };
    let words: Vec<egui::Pos2> = ["Excellent", "Good", "Fair", "Poor", "Bad"]
        .iter()
        .map(|w| centre(&h, w))
        .collect();
    let (top, bottom) = (centre(&h, "100"), centre(&h, "0"));
    let section = (bottom.y - top.y) / 5.0;
    assert!(section > 30.0, "sections of {section} points");
    for (k, w) in words.iter().enumerate() {
        let want = top.y + section * (k as f32 + 0.5);
        assert!((w.y - want).abs() < 1.0, "word {k} at {} not {want}", w.y);
    }
    let sliders = sliders(&h);
    assert!(
        words.iter().all(|w| w.x < sliders[0].0.left()),
        "words beside the sliders"
    );
    let values = |h: &Harness<'_, (StudyUi, FrameClock)>| -> Vec<Option<f64>> {
        let mut v: Vec<(f32, Option<f64>)> = h
            .get_all_by_role(Role::Slider)
            .map(|n| (n.rect().left(), n.accesskit_node().numeric_value()))
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v.into_iter().map(|(_, v)| v).collect()
    };
    assert_eq!(values(&h), [None, None, None]);
    let hollow = |h: &Harness<'_, (StudyUi, FrameClock)>| -> Vec<egui::Pos2> {
        h.output()
            .shapes
            .iter()
            .filter_map(|c| match &c.shape {
                // The knob, not the ring that marks the focused slider.
                egui::epaint::Shape::Circle(c)
                    if c.fill == egui::Color32::TRANSPARENT && c.radius < 12.0 =>
                {
                    Some(c.center)
                }
                _ => None,
            })
            .collect()
    };
    let parked = hollow(&h);
    assert_eq!(parked.len(), 3, "{parked:?}");
    assert!(
        parked.iter().all(|p| p.y > bottom.y + 20.0),
        "{parked:?} below 0 at {}",
        bottom.y
    );
    // Rated 0 from the keys: the knob moves onto the 0 line, no longer hollow.
    set_slider(&mut h, 0, &[Key::ArrowDown]);
    assert_eq!(values(&h), [Some(0.0), None, None]);
    assert_eq!(hollow(&h).len(), 2);
    drop(run.fx);
}
