//! `study preview`: the stimuli of a manifest played one at a time in the study window, each
//! beside its reference (the manifest's reference of its clip), both looping in sync, with
//! what the manifest says about it (codec, parameters, compression ratio, joint errors)
//! beside them, before a study is written.
//!
//! The clips are read as a session reads them ([`lab::source::ManifestStimuli`], the
//! manifest checked as a study checks it, [`StimulusManifest::problems`]) and drawn as a trial draws them: the reference's
//! framing for both panes, the study renderer's default ground shadow. The egui part
//! ([`PreviewUi`]) needs no display; [`run`] opens the native window around it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context as _, bail};
use egui::{Color32, Key, RichText};
use lab::source::ManifestStimuli;
use protocols::manifest::{CrBasis, REFERENCE_CODEC, Stimulus, StimulusManifest};
use protocols::study::{MAX_MANIFEST_BYTES, RenderingSettings};

use crate::native::{self, Next, WindowOptions, WindowReport};

use crate::scene::{Cast, FrameShapes, Stage, View};

/// One stimulus of the preview and the reference it is played against.
#[derive(Debug, Clone)]
pub struct Entry {
    /// The stimulus as the manifest has it.
    pub stimulus: Stimulus,
    /// The id of its clip's reference (itself, for a reference).
    pub reference: String,
    /// Which channels its CRs count (the manifest's basis).
    pub cr_basis: CrBasis,
}

/// The stimuli of a manifest to preview, in order, and where their clips come from.
pub struct PreviewSet {
    manifest: PathBuf,
    entries: Vec<Entry>,
    source: ManifestStimuli,
    shadow: bool,
    skipped: Vec<String>,
}

impl PreviewSet {
    /// The stimuli `only` of the manifest at `path` (every stimulus but the references, in
    /// the manifest's order, when `only` is empty), `parse` turning its text into a manifest.
    /// The manifest is checked as a study file's is (version, values, ids listed twice).
    /// Crowd scenes draw several characters per pane: named in `only` they are refused,
    /// otherwise left out ([`PreviewSet::skipped`]).
    ///
    /// # Errors
    /// The file cannot be read or parsed, its values cannot be true, an id of `only` is not
    /// in it or is a crowd scene, a stimulus' clip has no reference, or nothing is left to
    /// show; each naming the file and the stimulus.
    pub fn open(
        path: &Path,
        only: &[String],
        parse: impl FnOnce(&str) -> Result<StimulusManifest, String>,
    ) -> anyhow::Result<PreviewSet> {
        let shown = path.display();
        let size = std::fs::metadata(path)
            .with_context(|| format!("{shown}: reading the stimulus manifest"))?
            .len();
        if size > MAX_MANIFEST_BYTES {
            bail!("{shown}: {size} bytes is over the {MAX_MANIFEST_BYTES}-byte limit");
        }
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{shown}: reading the stimulus manifest"))?;
        let manifest =
            parse(&text).map_err(|e| anyhow::anyhow!("{shown}: not a stimulus manifest: {e}"))?;
        // Checked as a study file's manifest is: version, values, ids listed twice.
        let problems = manifest.problems();
        if !problems.is_empty() {
            bail!("{shown}: {}", problems.join(&format!("\n{shown}: ")));
        }
        let (entries, skipped) =
            select(&manifest, only).map_err(|e| anyhow::anyhow!("{shown}: {e}"))?;
        if entries.is_empty() {
            bail!(
                "{shown}: nothing to preview: every stimulus is a reference{}",
                if skipped.is_empty() {
                    ""
                } else {
                    " or a crowd scene"
                }
            );
        }
        let dir = path.parent().unwrap_or(Path::new("."));
        Ok(PreviewSet {
            manifest: path.to_path_buf(),
            shadow: RenderingSettings::default().ground_shadow,
            source: ManifestStimuli::of_manifest(dir.to_path_buf(), manifest),
            entries,
            skipped,
        })
    }

    /// The stimuli shown, in order.
    pub fn entries(&self) -> &[Entry] {
        &self.entries
    }

    /// The crowd scenes left out of a walk over the whole manifest.
    pub fn skipped(&self) -> &[String] {
        &self.skipped
    }

    /// The manifest's path.
    pub fn manifest(&self) -> &Path {
        &self.manifest
    }
}

/// The entries `only` names (all but the references when empty) and the crowd scenes left
/// out; an error names the stimulus.
fn select(
    manifest: &StimulusManifest,
    only: &[String],
) -> Result<(Vec<Entry>, Vec<String>), String> {
    let mut chosen: Vec<&Stimulus> = Vec::new();
    let mut skipped = Vec::new();
    if only.is_empty() {
        for s in &manifest.stimuli {
            if s.scene.is_some() {
                skipped.push(s.id.clone());
            } else if s.codec != REFERENCE_CODEC {
                chosen.push(s);
            }
        }
    } else {
        for id in only {
            let s = manifest
                .get(id)
                .ok_or_else(|| format!("stimulus {id:?} is not in the manifest"))?;
            if let Some(scene) = &s.scene {
                return Err(format!(
                    "stimulus {id:?} is a crowd scene ({} characters on level {:?}): the \
                     preview draws one figure per pane; draw its scenes with `study clip \
                     render --study STUDY --scenes {id}`, or preview its characters' stimuli",
                    scene.characters.len(),
                    scene.level
                ));
            }
            if !chosen.iter().any(|c| c.id == *id) {
                chosen.push(s);
            }
        }
    }
    let entries = chosen
        .into_iter()
        .map(|s| {
            let reference = manifest
                .reference_of(&s.clip)
                .filter(|r| r.scene.is_none())
                .ok_or_else(|| {
                    format!(
                        "stimulus {:?} has no reference: no stimulus of clip {:?} has codec \
                         {REFERENCE_CODEC:?}",
                        s.id, s.clip
                    )
                })?;
            Ok(Entry {
                stimulus: s.clone(),
                reference: reference.id.clone(),
                cr_basis: manifest.cr_basis,
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    Ok((entries, skipped))
}

/// A number as the metrics panel shows it: whole numbers as they are, others to four
/// significant decimals without trailing zeros.
fn number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        return format!("{v}");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// What the metrics panel shows of `entry`, a (label, value) pair a row: the stimulus and its
/// reference, codec and parameters, targets, the compression ratio reached and the objective
/// errors the manifest records.
pub fn metrics(entry: &Entry) -> Vec<(String, String)> {
    let s = &entry.stimulus;
    let mut rows: Vec<(String, String)> = vec![
        ("stimulus".into(), s.id.clone()),
        ("reference".into(), entry.reference.clone()),
        ("clip".into(), s.clip.clone()),
        ("codec".into(), s.method()),
    ];
    let params: Vec<String> = s
        .params
        .iter()
        .map(|(k, v)| format!("{k} {}", number(*v)))
        .collect();
    rows.push((
        "parameters".into(),
        if params.is_empty() {
            "none".into()
        } else {
            params.join(", ")
        },
    ));
    if let Some(t) = s.target_cr {
        rows.push(("target CR".into(), format!("{}:1", number(t))));
    }
    if let Some(t) = s.target_max_error_cm {
        rows.push(("target max error".into(), format!("{} cm", number(t))));
    }
    let basis = match entry.cr_basis {
        CrBasis::File => "file basis",
        CrBasis::Seed => "seed basis",
    };
    rows.push((
        "achieved CR".into(),
        s.achieved_cr.map_or_else(
            || "unknown (no stream size given)".to_string(),
            |c| format!("{c:.2}:1 ({basis})"),
        ),
    ));
    if s.bytes > 0 {
        rows.push(("stream".into(), format!("{} bytes", s.bytes)));
    }
    match &s.metrics {
        Some(m) => {
            rows.push(("joint RMS error".into(), format!("{:.3} cm", m.rms_cm)));
            rows.push(("joint max error".into(), format!("{:.3} cm", m.max_cm)));
            if let Some(w) = m.worst_window_rms_cm {
                let place = match (m.worst_window_start_frame, m.worst_window_frames) {
                    (Some(a), Some(n)) => {
                        format!(", frames {a}-{}", a + n.saturating_sub(1))
                    }
                    _ => String::new(),
                };
                rows.push(("worst 1-s window".into(), format!("RMS {w:.3} cm{place}")));
            }
            rows.push((
                "mean angle error".into(),
                format!("{:.3}°", m.mean_angle_deg),
            ));
            if let Some(f) = m.foot_slide_cm_s {
                rows.push(("foot slide".into(), format!("{f:+.3} cm/s")));
            }
        }
        None if s.codec == REFERENCE_CODEC => {
            rows.push(("error".into(), "none (the reference itself)".into()));
        }
        None => rows.push((
            "error".into(),
            "not measured (no metrics in the manifest)".into(),
        )),
    }
    for (label, ms) in [("encode time", s.encode_ms), ("decode time", s.decode_ms)] {
        if let Some(ms) = ms {
            rows.push((label.into(), format!("{ms:.1} ms")));
        }
    }
    rows
}

/// The line the terminal gets when stimulus `k` of `n` is shown.
fn shown_line(k: usize, n: usize, entry: &Entry) -> String {
    let s = &entry.stimulus;
    let errors = s.metrics.map_or_else(String::new, |m| {
        format!(", RMS {:.3} cm, max {:.3} cm", m.rms_cm, m.max_cm)
    });
    format!(
        "preview {}/{n}: {} against {} ({}, CR {}{errors})",
        k + 1,
        s.id,
        entry.reference,
        s.method(),
        s.achieved_cr
            .map_or_else(|| "unknown".to_string(), |c| format!("{c:.2}:1"))
    )
}

/// The shown stimulus' two panes, ready to pose, or why its clips could not be read.
enum Shown {
    Ready(Box<Panes>),
    Failed(String),
}

/// The two panes of a stimulus shown: the reference's, then the stimulus'.
struct Panes {
    view: View,
    stages: [Stage; 2],
    duration_s: f64,
    shapes: [Arc<FrameShapes>; 2],
}

/// The preview's screens in egui: the stimulus beside its reference, the metrics panel, and
/// the controls (also keys: Right or N next, Left or P previous, Space pause and play, Escape
/// or Q quit). Testable without a display (`gpu` false draws no skeletons).
pub struct PreviewUi {
    set: PreviewSet,
    index: usize,
    /// What `index` shows (`None` until it is loaded, on the next frame).
    shown: Option<Shown>,
    /// Reference framings by reference id (a framing walks every frame of its clip).
    views: HashMap<String, View>,
    playing: bool,
    /// Presentation time within the loop, s.
    time_s: f64,
    last_frame_s: Option<f64>,
    gpu: bool,
    quit: bool,
    said: Vec<String>,
}

/// Label of the button that goes to the next stimulus.
pub const NEXT: &str = "Next";
/// Label of the button that goes to the previous stimulus.
pub const PREVIOUS: &str = "Previous";
/// Label of the button that pauses the loop.
pub const PAUSE: &str = "Pause";
/// Label of the button that plays it again.
pub const PLAY: &str = "Play";
/// Label of the button that closes the preview.
pub const QUIT: &str = "Quit";

impl PreviewUi {
    /// The first stimulus of `set`, playing. `gpu`: paint the skeletons with the window's
    /// renderer (false in tests without one).
    pub fn new(set: PreviewSet, gpu: bool) -> PreviewUi {
        PreviewUi {
            set,
            index: 0,
            shown: None,
            views: HashMap::new(),
            playing: true,
            time_s: 0.0,
            last_frame_s: None,
            gpu,
            quit: false,
            said: Vec::new(),
        }
    }

    /// The stimulus shown.
    pub fn current(&self) -> &Entry {
        &self.set.entries[self.index]
    }

    /// Whether the loop plays (not paused).
    pub fn playing(&self) -> bool {
        self.playing
    }

    /// Whether the viewer asked to quit.
    pub fn quit(&self) -> bool {
        self.quit
    }

    /// The screen's name for a test input script ([`crate::test_input`]): `preview #K` for
    /// stimulus K (0-based), `preview/failed #K` when its clips could not be read.
    pub fn screen(&self) -> String {
        match self.shown {
            Some(Shown::Failed(_)) => format!("preview/failed #{}", self.index),
            _ => format!("preview #{}", self.index),
        }
    }

    /// The lines for the terminal since the last call: one per stimulus shown, and each
    /// failure to read one.
    pub fn take_said(&mut self) -> Vec<String> {
        std::mem::take(&mut self.said)
    }

    /// Shows stimulus `k` (wrapping around the set), from the start of its loop.
    fn go(&mut self, k: isize) {
        let n = self.set.entries.len() as isize;
        self.index = k.rem_euclid(n.max(1)) as usize;
        self.shown = None;
        self.time_s = 0.0;
    }

    /// Reads the clips of the shown stimulus and prepares its panes.
    fn load(&mut self) -> Shown {
        let n = self.set.entries.len();
        let entry = &self.set.entries[self.index];
        let read = |id: &str| self.set.source.clip(id);
        let clips = read(&entry.reference).and_then(|r| Ok((r, read(&entry.stimulus.id)?)));
        let (reference, test) = match clips {
            Ok(c) => c,
            Err(e) => {
                let message = format!(
                    "{}: stimulus {:?}: {}",
                    self.set.manifest.display(),
                    entry.stimulus.id,
                    lab::error::chain(&e)
                );
                self.said.push(format!("error: {message}"));
                return Shown::Failed(message);
            }
        };
        self.said.push(shown_line(self.index, n, entry));
        let shadow = self.set.shadow;
        let view = *self
            .views
            .entry(entry.reference.clone())
            .or_insert_with(|| View::framing(&reference).with_shadow(shadow));
        let stage = |id: &str, clip: &Arc<motion::Clip>| {
            Stage::of(&[Cast {
                id: id.to_owned(),
                clip: Arc::clone(clip),
                own: view,
                placed: None,
            }])
        };
        let stages = [
            stage(&entry.reference, &reference),
            stage(&entry.stimulus.id, &test),
        ];
        let duration_s = stages
            .iter()
            .map(Stage::duration_s)
            .fold(0.0, f64::max)
            .max(0.1);
        Shown::Ready(Box::new(Panes {
            view,
            stages,
            duration_s,
            shapes: [Arc::default(), Arc::default()],
        }))
    }

    /// Takes this frame's keys.
    fn keys(&mut self, ui: &egui::Ui) {
        let (next, previous, pause, quit) = ui.input(|i| {
            let any = |keys: &[Key]| keys.iter().any(|k| i.key_pressed(*k));
            (
                any(&[Key::ArrowRight, Key::N]),
                any(&[Key::ArrowLeft, Key::P]),
                any(&[Key::Space]),
                any(&[Key::Escape, Key::Q]),
            )
        });
        if next {
            self.go(self.index as isize + 1);
        }
        if previous {
            self.go(self.index as isize - 1);
        }
        if pause {
            self.playing = !self.playing;
        }
        if quit {
            self.quit = true;
        }
    }

    /// The controls below the panes: previous, pause or play, next, quit, where the set
    /// stands and the keys.
    fn controls(&mut self, ui: &mut egui::Ui) {
        let n = self.set.entries.len();
        egui::Panel::bottom("preview controls").show(ui, |ui| {
            ui.add_space(4.0);
            ui.horizontal(|ui| {
                if ui.button(PREVIOUS).clicked() {
                    self.go(self.index as isize - 1);
                }
                let toggle = if self.playing { PAUSE } else { PLAY };
                if ui.button(toggle).clicked() {
                    self.playing = !self.playing;
                }
                if ui.button(NEXT).clicked() {
                    self.go(self.index as isize + 1);
                }
                if ui.button(QUIT).clicked() {
                    self.quit = true;
                }
                ui.separator();
                ui.label(format!("Stimulus {} of {n}", self.index + 1));
                ui.separator();
                ui.weak("Right/N next · Left/P previous · Space pause · Esc/Q quit");
            });
            ui.add_space(4.0);
        });
    }

    /// Draws one frame: keys, the controls, the metrics and the two panes.
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let now = ui.input(|i| i.time);
        if self.playing
            && let Some(last) = self.last_frame_s
        {
            self.time_s += (now - last).max(0.0);
        }
        self.last_frame_s = Some(now);
        self.keys(ui);
        if self.shown.is_none() {
            self.shown = Some(self.load());
        }
        self.controls(ui);
        let entry = self.set.entries[self.index].clone();
        let manifest = self.set.manifest.display().to_string();
        let playing = self.playing;
        let gpu = self.gpu;
        let time_s = &mut self.time_s;
        let shown = &mut self.shown;
        egui::CentralPanel::default().show(ui, |ui| {
            // The metrics to the right of the panes, which share the rest.
            let full = ui.available_rect_before_wrap();
            let split = (full.right() - METRICS_WIDTH).max(full.left());
            metrics_column(
                &mut ui.new_child(egui::UiBuilder::new().max_rect(egui::Rect::from_min_max(
                    egui::pos2(split + 12.0, full.top()),
                    full.max,
                ))),
                &entry,
                &manifest,
            );
            let area = egui::Rect::from_min_max(full.min, egui::pos2(split, full.bottom()));
            let mut ui = ui.new_child(egui::UiBuilder::new().max_rect(area));
            match shown {
                Some(Shown::Ready(panes)) => {
                    let Panes {
                        view,
                        stages,
                        duration_s,
                        shapes,
                    } = &mut **panes;
                    let t = time_s.rem_euclid(*duration_s);
                    *time_s = t;
                    ui.label(format!(
                        "{} {t:.2} / {duration_s:.2} s",
                        if playing { "Playing" } else { "Paused at" }
                    ));
                    let full = ui.available_rect_before_wrap();
                    let w = ((full.width() - 12.0) * 0.5).max(1.0);
                    let titles = [
                        format!("Reference: {}", entry.reference),
                        format!("Stimulus: {}", entry.stimulus.id),
                    ];
                    for (k, title) in titles.iter().enumerate() {
                        let column = egui::Rect::from_min_size(
                            egui::pos2(full.left() + k as f32 * (w + 12.0), full.top()),
                            egui::vec2(w, full.height()),
                        );
                        let mut inner = ui.new_child(egui::UiBuilder::new().max_rect(column));
                        inner.label(RichText::new(title).strong());
                        let rect = inner.available_rect_before_wrap();
                        crate::render::paint_pane(
                            ui.painter(),
                            gpu,
                            k,
                            rect,
                            view,
                            &mut stages[k],
                            &mut shapes[k],
                            t,
                        );
                    }
                }
                Some(Shown::Failed(message)) => {
                    ui.add_space(24.0);
                    ui.label(
                        RichText::new(format!("Cannot show this stimulus: {message}"))
                            .color(Color32::from_rgb(200, 60, 40)),
                    );
                }
                None => {}
            }
        });
        if self.shown.is_none() {
            // Moved by a button this frame: the next frame loads it, at once.
            ui.ctx().request_repaint();
        }
    }
}

/// Width of the metrics column, points.
const METRICS_WIDTH: f32 = 340.0;

/// The metrics of `entry` in `ui` (a column right of the panes), long values wrapped.
fn metrics_column(ui: &mut egui::Ui, entry: &Entry, manifest: &str) {
    ui.style_mut().wrap_mode = Some(egui::TextWrapMode::Wrap);
    ui.heading("Metrics");
    ui.add_space(6.0);
    egui::Grid::new("preview metrics rows")
        .num_columns(2)
        .striped(true)
        .max_col_width(METRICS_WIDTH - 130.0)
        .show(ui, |ui| {
            for (label, value) in metrics(entry) {
                ui.label(label);
                ui.label(RichText::new(value).strong());
                ui.end_row();
            }
        });
    ui.add_space(8.0);
    ui.weak(manifest);
}

/// Runs the preview of `set` in the native window until the viewer quits or closes it.
/// `say` gets the lines for the terminal: how many stimuli there are, then one per stimulus
/// shown; the crowd scenes left out go to standard error. Returns the window's frame timing.
///
/// # Errors
/// No display, or the window or its adapter cannot be opened.
pub fn run(set: PreviewSet, mut say: impl FnMut(&str) + 'static) -> anyhow::Result<WindowReport> {
    let skipped = set.skipped().join(", ");
    if !skipped.is_empty() {
        eprintln!("note: crowd scenes left out (one figure per pane): {skipped}");
    }
    if !native::display_available() {
        bail!("no display (DISPLAY and WAYLAND_DISPLAY are unset): the preview opens a window");
    }
    let name = set.manifest().display().to_string();
    say(&format!(
        "{name}: {} stimuli to preview",
        set.entries().len()
    ));
    let options = WindowOptions {
        title: format!("Stimulus preview: {name}"),
        fullscreen: false,
        monitor: None,
        size: [1200.0, 680.0],
    };
    let mut preview = PreviewUi::new(set, true);
    native::run_window(&options, move |ui, ctx| {
        preview.ui(ui);
        for line in preview.take_said() {
            say(&line);
        }
        ctx.screen = preview.screen();
        if preview.quit() || ctx.close_requested {
            Next::Close
        } else if preview.playing() || !ctx.clock.calibrated() {
            Next::Animate
        } else {
            Next::Idle
        }
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use std::path::PathBuf;

    use egui::Key;
    use egui_kittest::Harness;
    use egui_kittest::kittest::Queryable as _;
    use protocols::manifest::{CrBasis, SceneMember, SceneStimulus, StimulusManifest};

    use super::{Entry, NEXT, PreviewSet, PreviewUi, metrics};

    /// A fresh folder with the window tests' walk swept by SPIHT at 10:1 and 20:1; removed on
    /// drop.
    struct Walk {
        dir: PathBuf,
        manifest: StimulusManifest,
        /// Removes the folder when dropped.
        _fixture: crate::ui_tests::Fixture,
    }

    impl Walk {
        /// The ui tests' one-second walk swept with SPIHT at 10:1 and 20:1 (its study file is
        /// not read here).
        fn new(name: &str) -> Walk {
            let fixture = crate::ui_tests::fixture(&format!("preview-{name}"), "");
            Walk {
                dir: fixture.dir.clone(),
                manifest: fixture.manifest.clone(),
                _fixture: fixture,
            }
        }

        fn path(&self) -> PathBuf {
            self.dir.join("stimuli").join("stimuli.json")
        }

        /// The preview of `only` over `manifest` (the sweep's when `None`).
        fn open(
            &self,
            only: &[&str],
            manifest: Option<StimulusManifest>,
        ) -> anyhow::Result<PreviewSet> {
            let m = manifest.unwrap_or_else(|| self.manifest.clone());
            let only: Vec<String> = only.iter().map(|s| (*s).to_string()).collect();
            PreviewSet::open(&self.path(), &only, |_| Ok(m))
        }

        fn tests(&self) -> Vec<String> {
            self.manifest
                .stimuli
                .iter()
                .filter(|s| s.codec != "reference")
                .map(|s| s.id.clone())
                .collect()
        }
    }

    fn harness(set: PreviewSet) -> Harness<'static, PreviewUi> {
        Harness::builder()
            .with_size(egui::vec2(1280.0, 720.0))
            .with_step_dt(0.05)
            .build_ui_state(|ui, p: &mut PreviewUi| p.ui(ui), PreviewUi::new(set, false))
    }

    #[test]
    fn the_stimulus_and_its_metrics_show_and_next_and_previous_walk_the_set() {
        let walk = Walk::new("walk");
        let ids = walk.tests();
        assert_eq!(ids.len(), 2, "{ids:?}");
        // Many parameters: a long line that must not widen the metrics panel over the panes.
        let mut m = walk.manifest.clone();
        let first = m.stimuli.iter_mut().find(|s| s.id == ids[0]).unwrap();
        first.params = (0..8)
            .map(|k| (format!("parameter{k}"), 0.123_456))
            .collect();
        let set = walk.open(&[], Some(m)).unwrap();
        assert!(set.skipped().is_empty());
        let mut h = harness(set);
        h.run_steps(2);
        let shown = |h: &Harness<'_, PreviewUi>, k: usize| {
            let s = walk.manifest.get(&ids[k]).unwrap();
            let m = s.metrics.unwrap();
            assert_eq!(h.state().current().stimulus.id, ids[k]);
            assert_eq!(h.state().screen(), format!("preview #{k}"));
            for text in [
                format!("Stimulus: {}", ids[k]),
                "Reference: walk/reference".to_string(),
                format!("Stimulus {} of 2", k + 1),
                s.id.clone(),
                "spiht".to_string(),
                format!("{:.2}:1 (file basis)", s.achieved_cr.unwrap()),
                format!("{:.3} cm", m.rms_cm),
                format!("{:.3} cm", m.max_cm),
                format!("{:.3}°", m.mean_angle_deg),
            ] {
                assert!(
                    h.query_by_label(&text).is_some(),
                    "stimulus {k}: no {text:?}"
                );
            }
            assert!(h.query_by_label("joint RMS error").is_some());
            assert!(h.query_by_label("worst 1-s window").is_some());
        };
        shown(&h, 0);
        // The metrics stand right of the panes, long values wrapped within the window.
        let metrics_left = h.get_by_label("Metrics").rect().left();
        let params = h.get_by_label_contains("parameter7 0.1235").rect();
        assert!(
            metrics_left < params.left() && params.right() <= 1280.0,
            "{params:?}"
        );
        // The two panes (8 points of margin, 12 between) end where the metrics begin: the
        // second starts one pane and a gap in.
        let second = h
            .get_by_label(&format!("Stimulus: {}", ids[0]))
            .rect()
            .left();
        let panes_right = second + (second - 8.0 - 12.0);
        assert!(
            panes_right <= metrics_left && panes_right > 0.6 * 1280.0,
            "panes to {panes_right}, metrics at {metrics_left}"
        );
        assert!(h.state_mut().take_said()[0].starts_with(&format!("preview 1/2: {}", ids[0])));
        h.key_press(Key::ArrowRight);
        h.run_steps(2);
        shown(&h, 1);
        assert!(h.state_mut().take_said()[0].starts_with(&format!("preview 2/2: {}", ids[1])));
        // Past the last, back to the first; Left and P go back, N and the button forward.
        h.key_press(Key::N);
        h.run_steps(2);
        shown(&h, 0);
        h.key_press(Key::ArrowLeft);
        h.run_steps(2);
        shown(&h, 1);
        h.key_press(Key::P);
        h.run_steps(2);
        shown(&h, 0);
        h.get_by_label(NEXT).click();
        h.run_steps(2);
        shown(&h, 1);
        // Space pauses the loop where it is and plays it again.
        assert!(h.state().playing());
        h.key_press(Key::Space);
        h.run_steps(1);
        assert!(!h.state().playing());
        let paused_at = h.state().time_s;
        h.run_steps(5);
        assert!((h.state().time_s - paused_at).abs() < 1e-9);
        assert!(h.query_by_label(super::PLAY).is_some());
        h.key_press(Key::Space);
        h.run_steps(5);
        assert!(h.state().playing() && (h.state().time_s - paused_at).abs() > 1e-6);
        assert!(!h.state().quit());
        h.key_press(Key::Q);
        h.run_steps(1);
        assert!(h.state().quit());
    }

    #[test]
    fn bad_choices_are_refused_naming_the_file_or_the_stimulus() {
        let walk = Walk::new("bad");
        let ids = walk.tests();
        let e = walk.open(&["walk/nope"], None).err().unwrap().to_string();
        assert!(e.contains("\"walk/nope\" is not in the manifest"), "{e}");
        // A stimulus whose clip has no reference.
        let mut m = walk.manifest.clone();
        m.stimuli.retain(|s| s.codec != "reference");
        let e = walk.open(&[], Some(m)).err().unwrap().to_string();
        assert!(e.contains(&format!("{:?} has no reference", ids[0])), "{e}");
        // A crowd scene named is refused; left out of a walk over the whole manifest.
        let mut m = walk.manifest.clone();
        let mut scene = m.get(&ids[0]).unwrap().clone();
        scene.id = "scene/near".into();
        scene.clip = "near".into();
        scene.file = String::new();
        scene.scene = Some(SceneStimulus {
            level: "near".into(),
            allocation: "fixed".into(),
            budget_bytes: None,
            characters: vec![SceneMember {
                name: "a".into(),
                group: "g".into(),
                stimulus: ids[0].clone(),
                distance_cm: 500.0,
                score: None,
                budget_bytes: None,
            }],
        });
        m.stimuli.push(scene);
        let e = walk
            .open(&["scene/near"], Some(m.clone()))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("\"scene/near\" is a crowd scene"), "{e}");
        let set = walk.open(&[], Some(m)).unwrap();
        assert_eq!(set.skipped(), ["scene/near"]);
        assert_eq!(set.entries().len(), 2);
        // Values that cannot be true are refused as a study file's manifest is.
        let mut m = walk.manifest.clone();
        m.stimuli[2].achieved_cr = Some(-1.0);
        let e = format!("{:#}", walk.open(&[], Some(m)).err().unwrap());
        assert!(
            e.starts_with(&format!(
                "{}: stimuli[2] (\"{}\").achieved_cr: -1 is not",
                walk.path().display(),
                m_id(&walk, 2)
            )),
            "{e}"
        );
        let mut m = walk.manifest.clone();
        m.stimuli.push(m.stimuli[1].clone());
        let e = format!("{:#}", walk.open(&[], Some(m)).err().unwrap());
        assert!(
            e.ends_with(&format!(
                "stimuli[3]: stimulus id {:?} is listed twice",
                m_id(&walk, 1)
            )),
            "{e}"
        );
        // Not a manifest, or no file at all: named.
        let e = PreviewSet::open(&walk.path(), &[], |_| Err("expected value".into()))
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("stimuli.json: not a stimulus manifest: expected value"),
            "{e}"
        );
        let missing = walk.dir.join("none.json");
        let e = format!(
            "{:#}",
            PreviewSet::open(&missing, &[], |_| unreachable!())
                .err()
                .unwrap()
        );
        assert!(e.contains("none.json"), "{e}");
    }

    fn m_id(walk: &Walk, k: usize) -> String {
        walk.manifest.stimuli[k].id.clone()
    }

    #[test]
    fn a_clip_that_cannot_be_read_is_shown_as_such_and_the_next_one_still_plays() {
        let walk = Walk::new("unreadable");
        let ids = walk.tests();
        let first = walk.manifest.get(&ids[0]).unwrap();
        std::fs::remove_file(walk.dir.join("stimuli").join(&first.file)).unwrap();
        let mut h = harness(walk.open(&[], None).unwrap());
        h.run_steps(2);
        assert_eq!(h.state().screen(), "preview/failed #0");
        let said = h.state_mut().take_said();
        assert!(
            said[0].starts_with("error: ") && said[0].contains(&format!("{:?}", ids[0])),
            "{said:?}"
        );
        h.key_press(Key::ArrowRight);
        h.run_steps(2);
        assert_eq!(h.state().screen(), "preview #1");
    }

    #[test]
    fn metrics_name_what_the_manifest_holds() {
        let walk = Walk::new("metrics");
        let reference = walk.manifest.get("walk/reference").unwrap().clone();
        let rows = metrics(&Entry {
            stimulus: reference,
            reference: "walk/reference".into(),
            cr_basis: CrBasis::File,
        });
        assert!(rows.contains(&("error".into(), "none (the reference itself)".into())));
        assert!(rows.contains(&("parameters".into(), "none".into())));
        let mut s = walk.manifest.get(&walk.tests()[0]).unwrap().clone();
        s.params = [
            ("alpha".to_string(), 0.352_804_695),
            ("qp".to_string(), 10.0),
        ]
        .into();
        s.metrics = None;
        let rows = metrics(&Entry {
            stimulus: s,
            reference: "walk/reference".into(),
            cr_basis: CrBasis::Seed,
        });
        assert!(
            rows.contains(&("parameters".into(), "alpha 0.3528, qp 10".into())),
            "{rows:?}"
        );
        assert!(
            rows.iter()
                .any(|(l, v)| l == "error" && v.starts_with("not measured"))
        );
        assert!(
            rows.iter()
                .any(|(l, v)| l == "achieved CR" && v.ends_with(":1 (seed basis)")),
            "{rows:?}"
        );
    }
}
