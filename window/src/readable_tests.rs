//! Every text a subject reads is large enough (issue 41): each example study's welcome, its
//! first trial as it plays and once its answers open, and the end, at 1280×720 and at a
//! lab's 1920×1080 (logical points, one pixel per point), must draw no text under
//! [`MIN_PX`] and no text outside the window or cut by its clip.
//!
//! What is measured: the font size of every text section the screen paints (the `FontId`
//! size of each section of each `epaint::Shape::Text` galley in the frame's output), in
//! pixels at one pixel per point: the em height a style sheet calls the font size. A row of
//! text is a little taller than that (egui's default fonts: about 1.2 times).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use egui::epaint::Shape;
use egui::{Pos2, Rect};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable as _;

use super::screens::{Exit, StudyUi};
use super::timing::FrameClock;
use super::ui_tests::{fixture, fresh_manifest};
use lab::StudyFile;
use lab::session::{Opened, Recorder};

/// The least font size a subject must read, pixels.
const MIN_PX: f32 = 14.0;

/// Seconds per step: the examples' motions last 4 s, DSCQS shows them four times.
const DT: f32 = 0.1;

/// The window sizes a lab runs the study at, points.
const SIZES: [(f32, f32); 2] = [(1280.0, 720.0), (1920.0, 1080.0)];

/// The example studies, one (or two) per method: MOS, DSCQS on continuous scales, ACR with
/// a hidden reference, DCR, pair comparison (with and without "no preference"), CCR,
/// MUSHRA, the 2AFC staircase and a crowd scene (DSCQS on a categorical scale).
const EXAMPLES: [&str; 10] = [
    "mos.toml",
    "dscqs.toml",
    "acr-hr.toml",
    "dcr.toml",
    "pc.toml",
    "pc-ties.toml",
    "ccr.toml",
    "mushra.toml",
    "staircase.toml",
    "crowd-run1.toml",
];

/// One text the frame painted.
#[derive(Debug)]
struct Text {
    words: String,
    size: f32,
    rect: Rect,
    clip: Rect,
}

fn collect(shape: &Shape, clip: Rect, out: &mut Vec<Text>) {
    match shape {
        Shape::Vec(shapes) => {
            for s in shapes {
                collect(s, clip, out);
            }
        }
        Shape::Text(t) if t.opacity_factor > 0.0 => {
            let job = &t.galley.job;
            for section in &job.sections {
                let range = section.byte_range.start.0..section.byte_range.end.0;
                let text = job.text[range].trim();
                if text.is_empty() {
                    continue;
                }
                out.push(Text {
                    words: text.to_string(),
                    size: section.format.font_id.size,
                    rect: shape.visual_bounding_rect(),
                    clip,
                });
            }
        }
        _ => {}
    }
}

/// The texts of the last frame that can be seen (inside their clip rectangle).
fn texts<S>(h: &Harness<'_, S>) -> Vec<Text> {
    let mut out = Vec::new();
    for c in &h.output().shapes {
        collect(&c.shape, c.clip_rect, &mut out);
    }
    out.retain(|t| t.rect.intersects(t.clip));
    out
}

/// What is wrong with the texts of the frame on screen: each too small, or outside the
/// window or its clip; and the smallest size seen.
fn problems<S>(h: &Harness<'_, S>, size: (f32, f32)) -> (Vec<String>, f32) {
    let screen = Rect::from_min_max(Pos2::ZERO, Pos2::new(size.0, size.1)).expand(1.0);
    let texts = texts(h);
    let mut out = Vec::new();
    for t in &texts {
        if t.size < MIN_PX {
            out.push(format!("{:?} is {} px", t.words, t.size));
        }
        if !screen.contains_rect(t.rect) || !t.clip.expand(1.0).contains_rect(t.rect) {
            out.push(format!("{:?} is cut off at {:?}", t.words, t.rect));
        }
    }
    let least = texts.iter().map(|t| t.size).fold(f32::INFINITY, f32::min);
    (out, least)
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// The screens over a new session of `study_path`, its results in `dir`.
fn open(
    study_path: &Path,
    dir: &Path,
    size: (f32, f32),
) -> Harness<'static, (StudyUi, FrameClock)> {
    let file = StudyFile::load(study_path).unwrap();
    let stimuli = lab::source::open(&file).unwrap();
    let study = file.definition;
    std::fs::create_dir_all(dir.join("results")).unwrap();
    let Opened::Ready { recorder, .. } = Recorder::open(
        &study,
        0,
        &mut results::FolderStore::new(dir.join("results")),
        false,
        fresh_manifest(&study),
    )
    .unwrap() else {
        panic!("a new session reported finished");
    };
    let ui = StudyUi::new(Arc::new(study), stimuli, recorder, false);
    Harness::builder()
        .with_size(egui::vec2(size.0, size.1))
        .with_pixels_per_point(1.0)
        .with_step_dt(DT)
        .build_ui_state(
            |ui, (screens, clock): &mut (StudyUi, FrameClock)| screens.ui(ui, clock),
            (ui, FrameClock::new(None)),
        )
}

/// The screen's name ([`StudyUi::screen`]).
fn screen_name(h: &Harness<'_, (StudyUi, FrameClock)>) -> String {
    let now = h.ctx.input(|i| i.time);
    let (ui, clock) = h.state();
    ui.screen(now, clock)
}

/// Steps until the screen's name starts with `prefix` (at most a simulated minute).
fn until(h: &mut Harness<'_, (StudyUi, FrameClock)>, prefix: &str) {
    for _ in 0..600 {
        if screen_name(h).starts_with(prefix) {
            return;
        }
        h.step();
    }
    panic!("no {prefix} screen; still on {}", screen_name(h));
}

/// Runs `name`'s welcome, first trial (playing, then open) and end at `size`; every
/// problem, prefixed by the screen, and the smallest text on each screen.
fn one_example(study: &Path, size: (f32, f32)) -> (Vec<String>, Vec<(String, f32)>) {
    let dir = std::env::temp_dir().join(format!(
        "study-readable-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let mut h = open(study, &dir, size);
    let mut all = Vec::new();
    let mut least = Vec::new();
    let mut look = |h: &Harness<'_, (StudyUi, FrameClock)>, what: &str| {
        let (p, l) = problems(h, size);
        all.extend(p.into_iter().map(|p| format!("{what}: {p}")));
        least.push((what.to_string(), l));
    };
    h.run_steps(2);
    look(&h, "welcome");
    h.state_mut().0.fill_fields_for_tests();
    h.run_steps(1);
    h.get_by_label("Begin").click();
    h.run_steps(2);
    until(&mut h, "trial/playing");
    look(&h, "trial playing");
    until(&mut h, "trial/open");
    h.run_steps(1);
    look(&h, "trial open");
    h.state_mut().0.stop(Exit::Quit { logged: 0 });
    h.run_steps(2);
    until(&mut h, "end");
    look(&h, "end");
    drop(h);
    let _ = std::fs::remove_dir_all(&dir);
    (all, least)
}

#[test]
fn every_text_of_every_methods_screens_is_at_least_14_px() {
    let mut all = Vec::new();
    for size in SIZES {
        for name in EXAMPLES {
            let (problems, least) = one_example(&examples().join(name), size);
            eprintln!("{name} at {}x{}: smallest text {least:?}", size.0, size.1);
            all.extend(
                problems
                    .into_iter()
                    .map(|p| format!("{name} at {}x{}: {p}", size.0, size.1)),
            );
        }
    }
    assert!(
        all.is_empty(),
        "{} problems:\n{}",
        all.len(),
        all.join("\n")
    );
}

/// The welcome with every kind of subject field and a consent text, and a session run to
/// its real end (the Close button), at both sizes.
#[test]
fn the_welcome_with_fields_and_consent_and_the_end_are_readable() {
    let fx = fixture("readable-welcome", super::ui_tests::TYPED);
    for size in SIZES {
        let dir = fx.dir.join(format!("run-{}", size.0));
        let mut h = open(&fx.study_path, &dir, size);
        h.run_steps(2);
        assert!(h.query_by_label("Consent").is_some(), "the consent heading");
        let (p, least) = problems(&h, size);
        eprintln!("welcome at {}x{}: smallest text {least}", size.0, size.1);
        assert!(p.is_empty(), "welcome at {size:?}:\n{}", p.join("\n"));
        h.state_mut().0.fill_fields_for_tests();
        h.run_steps(1);
        h.get_by_label("Begin").click();
        h.run_steps(2);
        until(&mut h, "trial/open");
        h.get_by_label("4").click();
        h.run_steps(1);
        h.get_by_label("Continue").click();
        h.run_steps(2);
        let (p, least) = problems(&h, size);
        eprintln!("gap at {}x{}: smallest text {least}", size.0, size.1);
        assert!(p.is_empty(), "gap at {size:?}:\n{}", p.join("\n"));
        until(&mut h, "end");
        h.run_steps(2);
        assert!(h.query_by_label("Close").is_some());
        let (p, least) = problems(&h, size);
        eprintln!("end at {}x{}: smallest text {least}", size.0, size.1);
        assert!(p.is_empty(), "end at {size:?}:\n{}", p.join("\n"));
    }
}
