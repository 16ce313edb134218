//! The native window: eframe (winit + wgpu) around a screen-drawing closure, with vsync (FIFO
//! present mode), the skeleton renderer registered as a paint-callback resource, frame
//! timing and the adapter/display facts a session manifest records.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use anyhow::Context as _;
use eframe::egui_wgpu::{self, wgpu};

use super::render::{LOAD_SLOT, SkeletonCallback, SkeletonRenderer, Targets};
use super::scene::{Figure, FrameShapes, View};
use super::test_input::TestInput;
use super::timing::{FrameClock, IntervalStats, PeriodSource};

/// Depth buffer bits asked of eframe (egui-wgpu makes it `Depth24Plus`).
const DEPTH_BITS: u8 = 24;

/// How to open the window.
#[derive(Debug, Clone)]
pub struct WindowOptions {
    /// Title (also the X11 window name `xdotool search --name` finds).
    pub title: String,
    /// Borderless fullscreen.
    pub fullscreen: bool,
    /// Monitor index for fullscreen.
    pub monitor: Option<usize>,
    /// Inner size when not fullscreen, points.
    pub size: [f32; 2],
}

/// Facts about the display and adapter, filled in on the first frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DisplayFacts {
    /// Adapter name.
    pub adapter: String,
    /// Adapter type (`Cpu` = software rendering such as lavapipe).
    pub device_type: String,
    /// Backend (Vulkan, GL, ...).
    pub backend: String,
    /// Driver and its version.
    pub driver: String,
    /// Present mode asked for.
    pub present_mode: String,
    /// MSAA samples used.
    pub msaa: u32,
    /// Inner size, physical pixels.
    pub width_px: u32,
    /// Inner height, physical pixels.
    pub height_px: u32,
    /// Monitor's reported refresh rate, Hz.
    pub monitor_hz: Option<f64>,
    /// Monitor name.
    pub monitor: Option<String>,
}

impl DisplayFacts {
    /// One line for the session manifest and reports.
    pub fn describe(&self, period: Option<(f64, PeriodSource)>) -> String {
        let refresh = match period {
            Some((p, PeriodSource::Monitor)) => format!("{:.2} Hz (monitor)", 1000.0 / p),
            Some((p, PeriodSource::Measured)) => format!(
                "{:.2} Hz measured{}",
                1000.0 / p,
                self.monitor_hz
                    .map_or_else(String::new, |h| format!(", monitor reports {h:.2} Hz"))
            ),
            None => "refresh not measured".into(),
        };
        format!(
            "{} ({}, {}, driver {}), present mode {}, MSAA {}×, {}×{} px, {}{}",
            self.adapter,
            self.device_type,
            self.backend,
            self.driver,
            self.present_mode,
            self.msaa,
            self.width_px,
            self.height_px,
            refresh,
            self.monitor
                .as_ref()
                .map_or_else(String::new, |m| format!(", monitor {m}"))
        )
    }
}

/// What the window measured.
#[derive(Debug, Clone, Default)]
pub struct WindowReport {
    /// Display and adapter.
    pub facts: DisplayFacts,
    /// Refresh period used for drop counting.
    pub period: Option<(f64, PeriodSource)>,
    /// Intervals since calibration.
    pub session: IntervalStats,
    /// CPU time per frame (eframe: update, tessellation, record and submit; no vsync wait), ms.
    pub cpu_ms: Vec<f64>,
}

/// What a screen closure gets each frame.
pub struct FrameContext<'a> {
    /// The frame clock (already ticked for this frame).
    pub clock: &'a mut FrameClock,
    /// Display facts.
    pub facts: &'a DisplayFacts,
    /// True on the frame the user asked to close the window.
    pub close_requested: bool,
    /// The screen the frame ended on, set by the screen closure (`welcome/ready`,
    /// `trial/open #3`, ...): what a test input script waits for ([`TestInput`]).
    pub screen: String,
}

/// What a screen closure answers each frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next {
    /// Keep going, repainting continuously.
    Animate,
    /// Keep going; repaint on input only.
    Idle,
    /// Close the window now.
    Close,
}

/// Whether `key` was pressed with Ctrl and Shift held, read from the key events of this frame
/// with the modifiers each event carries. The frame's modifier state is not used: at a low
/// frame rate a quick chord is pressed and released between two frames, and by the time the
/// frame runs the modifiers are up again.
pub fn ctrl_shift_pressed(input: &egui::InputState, key: egui::Key) -> bool {
    input.events.iter().any(|e| {
        matches!(e, egui::Event::Key { key: k, pressed: true, repeat: false, modifiers, .. }
            if *k == key && modifiers.ctrl && modifiers.shift)
    })
}

/// What the window draws while the refresh period is being estimated, when the screen itself
/// draws fewer than two skeletons: two walking figures under the screen's own panels (hidden
/// by them), so the period is measured under a trial's load.
struct CalibrationLoad {
    view: View,
    figure: Figure,
    duration_s: f64,
}

impl CalibrationLoad {
    fn new() -> CalibrationLoad {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let view = View::framing(&clip);
        let figure = Figure::new(&clip, &view);
        let duration_s = figure.duration_s().max(0.1);
        CalibrationLoad {
            view,
            figure,
            duration_s,
        }
    }

    /// Adds the two skeletons to `ui`'s painter, side by side over its whole area, before the
    /// screen draws (so its panels cover them).
    fn paint(&mut self, ui: &egui::Ui, now: f64) {
        let full = ui.max_rect();
        let w = (full.width() * 0.5).max(1.0);
        for k in 0..2 {
            let rect = egui::Rect::from_min_size(
                egui::pos2(full.left() + k as f32 * w, full.top()),
                egui::vec2(w, full.height()),
            );
            let mut shapes = FrameShapes::default();
            self.figure
                .shapes_at((now + 0.25 * k as f64) % self.duration_s, &mut shapes);
            ui.painter().add(egui_wgpu::Callback::new_paint_callback(
                rect,
                SkeletonCallback {
                    slot: LOAD_SLOT + k,
                    view: self.view,
                    aspect: rect.width() / rect.height().max(1.0),
                    shapes: Arc::new(shapes),
                },
            ));
        }
    }
}

struct WindowApp<F> {
    draw: F,
    clock: FrameClock,
    facts: DisplayFacts,
    report: Arc<Mutex<WindowReport>>,
    first: bool,
    closing: bool,
    software: bool,
    /// Skeleton viewports the screens drew (load excluded), counted by the renderer.
    drawn: Arc<AtomicUsize>,
    load: Option<CalibrationLoad>,
    /// Keys from a test's script (`STUDY_TEST_INPUT`).
    script: Option<TestInput>,
}

impl<F> WindowApp<F> {
    fn first_frame(&mut self, frame: &eframe::Frame) {
        if let Some(w) = frame.winit_window() {
            let size = w.inner_size();
            self.facts.width_px = size.width;
            self.facts.height_px = size.height;
            if let Some(m) = w.current_monitor() {
                self.facts.monitor = m.name();
                self.facts.monitor_hz = m.refresh_rate_millihertz().map(|mhz| f64::from(mhz) / 1e3);
            }
        }
        self.clock = FrameClock::new(self.facts.monitor_hz).software(self.software);
    }

    fn publish(&self, cpu: Option<f32>) {
        let mut r = self.report.lock().unwrap_or_else(PoisonError::into_inner);
        r.facts = self.facts.clone();
        r.period = self.clock.period();
        r.session = self.clock.session();
        if let Some(c) = cpu {
            r.cpu_ms.push(f64::from(c) * 1e3);
        }
    }
}

impl<F: FnMut(&mut egui::Ui, &mut FrameContext<'_>) -> Next> eframe::App for WindowApp<F> {
    fn raw_input_hook(&mut self, _ctx: &egui::Context, raw_input: &mut egui::RawInput) {
        if let Some(script) = &mut self.script {
            script.inject(raw_input);
        }
    }

    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        if self.first {
            self.first = false;
            self.first_frame(frame);
        }
        self.clock.tick(Instant::now());
        // The screens' skeletons of the previous frame: fewer than a trial's two while the
        // period is estimated, and the window adds the rest of the load.
        let drawn = self.drawn.swap(0, Ordering::Relaxed);
        if self.clock.calibrated() {
            self.load = None;
        } else if drawn < 2 {
            let now = ui.input(|i| i.time);
            self.load
                .get_or_insert_with(CalibrationLoad::new)
                .paint(ui, now);
        }
        let close_requested = ui.input(|i| i.viewport().close_requested());
        if close_requested && !self.closing {
            ui.ctx()
                .send_viewport_cmd(egui::ViewportCommand::CancelClose);
        }
        let mut ctx = FrameContext {
            clock: &mut self.clock,
            facts: &self.facts,
            close_requested: close_requested && !self.closing,
            screen: String::new(),
        };
        let next = (self.draw)(ui, &mut ctx);
        let screen = ctx.screen;
        self.publish(frame.info().cpu_usage);
        if let Some(script) = &mut self.script {
            script.observe(&screen);
            if script.pending() {
                ui.ctx().request_repaint();
            }
        }
        match next {
            Next::Animate => ui.ctx().request_repaint(),
            // Still woken a few times a second, so a signal is noticed on an idle screen.
            Next::Idle => ui
                .ctx()
                .request_repaint_after(std::time::Duration::from_millis(200)),
            Next::Close => {
                self.closing = true;
                ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
    }
}

/// Whether a display server is reachable (X11 `DISPLAY` or Wayland `WAYLAND_DISPLAY`).
pub fn display_available() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()))
}

/// The first adapter's facts, without a window (to choose MSAA before the window opens).
pub fn probe_adapter() -> Option<wgpu::AdapterInfo> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
        .ok()
        .map(|a| a.get_info())
}

/// Opens the window and runs `draw` every frame until it answers [`Next::Close`] (or the
/// window is closed while `draw` allows it). Returns what the window measured.
///
/// With `STUDY_TEST_INPUT` set, the window also takes keys from that script
/// ([`TestInput`]).
///
/// # Errors
/// No display, no adapter, eframe failed to start, or a test input script that cannot be read.
pub fn run_window<F>(options: &WindowOptions, draw: F) -> anyhow::Result<WindowReport>
where
    F: FnMut(&mut egui::Ui, &mut FrameContext<'_>) -> Next + 'static,
{
    let script = TestInput::from_env()?;
    // MSAA only where it is cheap: a software adapter rasterises every sample on the CPU.
    let software = probe_adapter().is_none_or(|i| i.device_type == wgpu::DeviceType::Cpu);
    let msaa: u32 = if software { 1 } else { 4 };
    let present_mode = wgpu::PresentMode::Fifo;
    let mut viewport = egui::ViewportBuilder::default()
        .with_title(options.title.clone())
        .with_app_id("mocap-study")
        .with_inner_size(options.size)
        .with_fullscreen(options.fullscreen);
    if let Some(m) = options.monitor {
        viewport = viewport.with_monitor(m);
    }
    let native = eframe::NativeOptions {
        viewport,
        renderer: eframe::Renderer::Wgpu,
        multisampling: msaa as u16,
        depth_buffer: DEPTH_BITS,
        wgpu_options: egui_wgpu::WgpuConfiguration {
            surface: egui_wgpu::SurfaceConfig {
                present_mode,
                desired_maximum_frame_latency: Some(1),
            },
            ..egui_wgpu::WgpuConfiguration::default()
        },
        ..eframe::NativeOptions::default()
    };
    let report = Arc::new(Mutex::new(WindowReport::default()));
    let shared = Arc::clone(&report);
    let result = eframe::run_native(
        &options.title,
        native,
        Box::new(move |cc| {
            let rs = cc
                .wgpu_render_state
                .as_ref()
                .ok_or("eframe started without a wgpu render state")?;
            let info = rs.adapter.get_info();
            let depth = egui_wgpu::depth_format_from_bits(DEPTH_BITS, 0);
            let renderer = SkeletonRenderer::new(
                &rs.device,
                Targets {
                    color: rs.target_format,
                    depth,
                    samples: msaa,
                },
            );
            let drawn = renderer.drawn_counter();
            rs.renderer.write().callback_resources.insert(renderer);
            let facts = DisplayFacts {
                adapter: info.name.clone(),
                device_type: format!("{:?}", info.device_type),
                backend: format!("{:?}", info.backend),
                driver: format!("{} {}", info.driver, info.driver_info)
                    .trim()
                    .to_string(),
                present_mode: format!("{present_mode:?}"),
                msaa,
                ..DisplayFacts::default()
            };
            Ok(Box::new(WindowApp {
                draw,
                clock: FrameClock::new(None),
                facts,
                report: shared,
                first: true,
                closing: false,
                software,
                drawn,
                load: None,
                script,
            }) as Box<dyn eframe::App>)
        }),
    );
    result
        .map_err(|e| anyhow::anyhow!("{e}"))
        .context("opening the study window")?;
    let r = report
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone();
    Ok(r)
}

#[cfg(test)]
mod tests {
    use egui::{Event, Key, Modifiers};

    use super::ctrl_shift_pressed;

    fn key(key: Key, pressed: bool, modifiers: Modifiers) -> Event {
        Event::Key {
            key,
            physical_key: None,
            pressed,
            repeat: false,
            modifiers,
        }
    }

    /// Runs one frame over `events`; answers (the chord from the events, the chord as the
    /// frame's modifier state tells it).
    fn frame(events: Vec<Event>) -> (bool, bool) {
        let ctx = egui::Context::default();
        let mut seen = (false, false);
        let mut out = ctx.run_ui(
            egui::RawInput {
                events,
                ..egui::RawInput::default()
            },
            |ui| {
                seen = ui.input(|i| {
                    (
                        ctrl_shift_pressed(i, Key::P),
                        i.modifiers.ctrl && i.modifiers.shift && i.key_pressed(Key::P),
                    )
                });
            },
        );
        out.textures_delta.clear();
        seen
    }

    #[test]
    fn a_quick_chord_is_taken_from_its_key_event_when_the_modifiers_are_up_by_the_frame() {
        let both = Modifiers::CTRL | Modifiers::SHIFT;
        // At 21 fps the whole chord falls between two frames: Ctrl+Shift down, P down and
        // up, Ctrl+Shift up. The frame's modifier state says none are held.
        let quick = vec![
            Event::ModifiersChanged(both),
            key(Key::P, true, both),
            key(Key::P, false, both),
            Event::ModifiersChanged(Modifiers::NONE),
        ];
        assert_eq!(frame(quick), (true, false));
        // Held across the frame, both readings agree.
        assert_eq!(
            frame(vec![Event::ModifiersChanged(both), key(Key::P, true, both)]),
            (true, true)
        );
        // P alone, or with Ctrl only, is no chord, whatever the modifiers do later in the
        // frame.
        assert_eq!(
            frame(vec![
                key(Key::P, true, Modifiers::CTRL),
                Event::ModifiersChanged(both),
            ]),
            (false, true)
        );
        assert!(!frame(vec![key(Key::P, true, Modifiers::NONE)]).0);
        // Another key with the chord's modifiers is not the chord.
        assert!(!frame(vec![key(Key::O, true, both)]).0);
    }
}
