//! What `study run` and `study display-test` show in the native window: a subject's session
//! screens until the session ends, and two animated skeletons while the display's frame
//! timing is measured.

use std::cell::RefCell;
use std::fmt::Write as _;
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use eframe::egui_wgpu;
use results::store::DisplayInfo;

use crate::native::{self, DisplayFacts, Next, WindowOptions, WindowReport};
use crate::render::{BACKGROUND, SkeletonCallback};
use crate::scene::{Figure, FrameShapes, View};
use crate::screens::{Exit, StudyUi};
use crate::status::Watcher;
use crate::timing::FrameClock;

/// Runs the window over a subject's `screens` until the session ends or the window closes;
/// returns the frame timing and how the session ended (`None`: the window closed first). A
/// set `signalled` (SIGINT, SIGTERM) stops the session as "Quit and save" does. `watch`
/// gets the screens' status once a frame (the experimenter's terminal, [`crate::status`]).
///
/// # Errors
/// The window or its adapter cannot be opened.
pub fn session(
    options: &WindowOptions,
    mut screens: StudyUi,
    signalled: &Arc<AtomicBool>,
    mut watch: Watcher,
) -> anyhow::Result<(WindowReport, Option<Exit>)> {
    let signalled = Arc::clone(signalled);
    let exit = Rc::new(RefCell::new(None::<Exit>));
    let exit_seen = Rc::clone(&exit);
    // The clock's revision the manifest's display information was written at (rewritten
    // when a drift re-checked the period).
    let mut display_logged = None;
    let report = native::run_window(options, move |ui, ctx| {
        if ctx.close_requested {
            // Mid-session this opens the quit confirmation instead of closing.
            screens.close_requested();
        }
        if ctx.clock.calibrated() && display_logged != Some(ctx.clock.revision()) {
            display_logged = Some(ctx.clock.revision());
            let info = display_info(ctx.facts, ctx.clock);
            if let Err(e) = screens
                .recorder_mut()
                .update_manifest(|m| m.display = Some(info))
            {
                eprintln!(
                    "warning: writing the display information: {}",
                    lab::error::chain(&e)
                );
            }
        }
        if signalled.load(Ordering::Relaxed) {
            let logged = screens.recorder_mut().answered();
            screens.stop(Exit::Signalled { logged });
        }
        screens.ui(ui, ctx.clock);
        ctx.screen = screens.screen(ui.input(|i| i.time), ctx.clock);
        watch.frame(screens.status());
        if let Some(e) = screens.exit() {
            *exit_seen.borrow_mut() = Some(e.clone());
            // The end screen stays until the subject closes it (or the window is closed);
            // a quit or a signal closes at once.
            return if screens.may_close() || ctx.close_requested {
                Next::Close
            } else {
                Next::Idle
            };
        }
        // Idle screens still need frames to measure the display before the first trial.
        if screens.animating() || !ctx.clock.calibrated() {
            Next::Animate
        } else {
            Next::Idle
        }
    })?;
    let exit = exit.borrow().clone();
    Ok((report, exit))
}

fn display_info(facts: &DisplayFacts, clock: &FrameClock) -> DisplayInfo {
    let period = clock.period();
    DisplayInfo {
        description: clock.drift_note().map_or_else(
            || facts.describe(period),
            |d| format!("{}; {d}", facts.describe(period)),
        ),
        width_px: facts.width_px,
        height_px: facts.height_px,
        refresh_hz: period.map_or(0.0, |(p, _)| 1000.0 / p),
    }
}

/// Two copies of `clip` animated side by side for `seconds` once the refresh period is known
/// (the display test), and the window's frame timing.
///
/// # Errors
/// The window or its adapter cannot be opened.
pub fn display_test(
    options: &WindowOptions,
    clip: &motion::Clip,
    seconds: f64,
) -> anyhow::Result<WindowReport> {
    let view = View::framing(clip);
    let mut figures = [Figure::new(clip, &view), Figure::new(clip, &view)];
    let duration = figures[0].duration_s().max(0.1);
    let mut measuring_since: Option<f64> = None;
    let bg = egui::Color32::from_rgb(
        (BACKGROUND[0] * 255.0) as u8,
        (BACKGROUND[1] * 255.0) as u8,
        (BACKGROUND[2] * 255.0) as u8,
    );
    native::run_window(options, move |ui, ctx| {
        let now = ui.input(|i| i.time);
        if ctx.clock.calibrated() && measuring_since.is_none() {
            measuring_since = Some(now);
            ctx.clock.start_segment();
        }
        let elapsed = measuring_since.map_or(0.0, |s| now - s);
        egui::CentralPanel::default().show(ui, |ui| {
            ui.label(match measuring_since {
                None => "Estimating the refresh period…".to_string(),
                Some(_) => format!("Measuring: {elapsed:.1} / {seconds:.0} s"),
            });
            let full = ui.available_rect_before_wrap();
            let w = (full.width() - 12.0) * 0.5;
            for (k, fig) in figures.iter_mut().enumerate() {
                let rect = egui::Rect::from_min_size(
                    egui::pos2(full.left() + k as f32 * (w + 12.0), full.top()),
                    egui::vec2(w, full.height()),
                );
                ui.painter().rect_filled(rect, 0.0, bg);
                let mut shapes = FrameShapes::default();
                fig.shapes_at(now % duration, &mut shapes);
                ui.painter().add(egui_wgpu::Callback::new_paint_callback(
                    rect,
                    SkeletonCallback {
                        slot: k,
                        view,
                        aspect: rect.width() / rect.height().max(1.0),
                        shapes: Arc::new(shapes),
                    },
                ));
            }
        });
        ctx.screen = if measuring_since.is_some() {
            "display-test/measuring".into()
        } else {
            "display-test/calibrating".into()
        };
        if elapsed >= seconds || ctx.close_requested {
            Next::Close
        } else {
            Next::Animate
        }
    })
}

/// The `q` quantile (0-1) of `sorted`, the nearest rank; 0 for none.
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// The display, the frame intervals and the CPU time per frame of a window run, a line each
/// (what `study run` and `study display-test` print).
pub fn timing_text(report: &WindowReport) -> String {
    let mut cpu = report.cpu_ms.clone();
    cpu.sort_by(f64::total_cmp);
    let s = report.session;
    let mut t = String::new();
    let _ = writeln!(t, "display: {}", report.facts.describe(report.period));
    let _ = writeln!(
        t,
        "frames: {} presented, interval mean {:.2} ms, SD {:.3} ms, max {:.2} ms, {} dropped (> 1.5 periods)",
        s.frames, s.mean_ms, s.sd_ms, s.max_ms, s.dropped
    );
    let _ = writeln!(
        t,
        "CPU per frame (update + record + submit): p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms over {} frames",
        percentile(&cpu, 0.5),
        percentile(&cpu, 0.99),
        cpu.last().copied().unwrap_or(0.0),
        cpu.len()
    );
    if report.facts.device_type == "Cpu" {
        let _ = writeln!(
            t,
            "note: a software (Cpu) adapter: these are software-rendering figures, not a lab monitor's"
        );
    }
    t
}
