//! Video of clips as the study window draws them (`study clip video`): every frame drawn
//! offscreen ([`Offscreen`], the renderer of `study clip render`) and piped to Debian's
//! `ffmpeg` as raw RGBA, encoded to H.264 (CRF 16, 4:2:0, the index first for streaming)
//! under a temporary name beside the output, then renamed. Frame `k` shows time `k / fps`,
//! for the whole of the longest clip; every pane takes the first clip's camera.

use std::io::Write as _;
use std::path::Path;
use std::process::{Child, Command, Stdio};

use anyhow::{Context as _, Result, bail};
use motion::Clip;

use crate::render::{Offscreen, panes_of, shapes_at};
use crate::scene::{Figure, Stage, View};

/// How the video is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Height and width of one pane, pixels (even: H.264's 4:2:0 halves both).
    pub pane: u32,
    /// Frames per second (`None`: the first clip's frame rate).
    pub fps: Option<f64>,
    /// Ground shadows.
    pub shadow: bool,
}

impl Settings {
    /// Refuses a pane or rate the video cannot have, before anything is drawn.
    ///
    /// # Errors
    /// An odd pane, one outside 64-4096 pixels, a rate outside 1-240 frames per second.
    pub fn check(&self) -> Result<()> {
        if !(64..=4096).contains(&self.pane) || self.pane % 2 == 1 {
            bail!(
                "--pane {}: expected an even size, 64..=4096 pixels",
                self.pane
            );
        }
        if let Some(fps) = self
            .fps
            .filter(|f| !(f.is_finite() && (1.0..=240.0).contains(f)))
        {
            bail!("--fps {fps}: expected 1 to 240 frames per second");
        }
        Ok(())
    }
}

/// What [`write_mp4`] wrote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Made {
    /// Frames.
    pub frames: u64,
    /// Frames per second.
    pub fps: f64,
    /// Width, pixels (a pane per clip).
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
}

/// Draws `clips` side by side (a pane each) for every frame and writes them to `out` as MP4.
///
/// # Errors
/// No clip; [`Settings::check`]; a video too large; no GPU adapter; ffmpeg missing or
/// failing (its message); I/O errors. Nothing is left at `out` or beside it on an error.
pub fn write_mp4(clips: &[&Clip], settings: &Settings, out: &Path) -> Result<Made> {
    settings.check()?;
    let Some(first) = clips.first() else {
        bail!("no clip to draw");
    };
    let fps = settings.fps.unwrap_or(first.frame_rate_hz);
    Settings {
        fps: Some(fps),
        ..*settings
    }
    .check()?;
    let view = View::framing(first).with_shadow(settings.shadow);
    let mut stages: Vec<Stage> = clips
        .iter()
        .map(|c| Stage::single(Figure::new(c, &view)))
        .collect();
    let duration = stages.iter().map(Stage::duration_s).fold(0.0, f64::max);
    let frames = ((duration * fps).round() as u64).max(1);
    let (cols, pane) = (stages.len() as u32, settings.pane);
    let width = cols * pane;
    if u64::from(width) * u64::from(pane) > 1 << 26 {
        bail!("{cols} panes of {pane} px is too large a video");
    }
    let mut offscreen = Offscreen::new(4)?;
    let mut shapes = Vec::new();
    encode(out, (width, pane), fps, frames, |k| {
        shapes.clear();
        shapes_at(&mut stages, k as f64 / fps, &mut shapes);
        Ok(offscreen
            .render(width, pane, &panes_of(&shapes, &view, cols, pane, pane))?
            .rgba)
    })?;
    Ok(Made {
        frames,
        fps,
        width,
        height: pane,
    })
}

/// Writes `frames` frames of `size` at `fps`, each drawn by `draw(k)` (RGBA rows), to `out`
/// as MP4 through ffmpeg, under a temporary name beside it, renamed when complete.
fn encode(
    out: &Path,
    (width, height): (u32, u32),
    fps: f64,
    frames: u64,
    mut draw: impl FnMut(u64) -> Result<Vec<u8>>,
) -> Result<()> {
    let dir = out
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = out
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let temp = dir.join(format!(".{name}.{}.tmp.mp4", std::process::id()));
    let mut ffmpeg = spawn_ffmpeg(width, height, fps, &temp)?;
    let drawn = (|| -> Result<()> {
        let mut stdin = ffmpeg.stdin.take().context("ffmpeg's input")?;
        for k in 0..frames {
            stdin
                .write_all(&draw(k)?)
                .context("writing a frame to ffmpeg")?;
        }
        Ok(())
    })();
    let done = ffmpeg.wait_with_output().context("waiting for ffmpeg")?;
    if drawn.is_err() || !done.status.success() {
        let _ = std::fs::remove_file(&temp);
        drawn?;
        bail!(
            "ffmpeg failed ({}): {}",
            done.status,
            String::from_utf8_lossy(&done.stderr).trim()
        );
    }
    std::fs::rename(&temp, out)
        .with_context(|| format!("renaming {} to {}", temp.display(), out.display()))?;
    Ok(())
}

/// How long a trial video goes on after the presentation: the screen while answers are open
/// (the held or looping stimuli, or the grey field with its question), seconds.
pub const ANSWER_HOLD_S: f64 = 1.0;

/// A logged or planned trial of `study` drawn as the study window shows it (issue 38): its
/// presentation schedule ([`protocols::screen::Schedule`], the one every front end plays)
/// from the first frame to [`ANSWER_HOLD_S`] after answers open, each frame laid out by the
/// window's own trial panel (panes, labels, the grey between and the "Please answer below"
/// after) and drawn offscreen at `width × height`, `fps` frames per second. A MUSHRA screen
/// is refused (its panes are several trials).
///
/// # Errors
/// A MUSHRA trial; a size or rate out of range; the trial's clips cannot be read; no GPU
/// adapter; ffmpeg missing or failing. Nothing is left at `out` on an error.
pub fn write_trial_mp4(
    study: &lab::StudyFile,
    trial: &protocols::Trial,
    (width, height): (u32, u32),
    fps: f64,
    out: &Path,
) -> Result<Made> {
    use std::collections::HashMap;
    if trial.arrangement == protocols::Arrangement::Grid {
        bail!(
            "trial {}: a MUSHRA screen shows several trials at once; draw its clips with \
             `study clip video`",
            trial.index
        );
    }
    if !(64..=4096).contains(&width)
        || !(64..=4096).contains(&height)
        || width % 2 == 1
        || height % 2 == 1
    {
        bail!("--size {width}x{height}: expected even sizes of 64..=4096 pixels");
    }
    Settings {
        pane: 64,
        fps: Some(fps),
        shadow: true,
    }
    .check()?;
    let source = lab::source::open(study)?;
    let shown = source.stimuli(trial)?;
    let mut views: HashMap<String, View> = HashMap::new();
    let mut panes =
        crate::screens::TrialPanes::of_trial(&study.definition, trial, &shown, &mut |id, clip| {
            *views
                .entry(id.to_owned())
                .or_insert_with(|| View::framing(clip))
        })?;
    let schedule = panes.described.schedule.clone();
    let mut presentation = crate::flow::Presentation::new(schedule.clone(), 0.0);
    let total = schedule.answers_open_s + ANSWER_HOLD_S;
    let frames = ((total * fps).round() as u64).max(1);
    let ctx = egui::Context::default();
    let mut offscreen = Offscreen::new(4)?;
    encode(out, (width, height), fps, frames, |k| {
        let t = k as f64 / fps;
        let frame = presentation.at(t);
        let input = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(
                egui::Pos2::ZERO,
                egui::vec2(width as f32, height as f32),
            )),
            time: Some(t),
            ..egui::RawInput::default()
        };
        let output = ctx.run_ui(input, |ui| {
            crate::screens::readable(ui.style_mut());
            crate::screens::stimuli_panel(ui, &mut panes, &frame, true);
        });
        Ok(offscreen.render_ui(&ctx, output, width, height)?.rgba)
    })?;
    Ok(Made {
        frames,
        fps,
        width,
        height,
    })
}

/// The study and the trial with index `index` as session folder `session` (of a results
/// directory, which keeps the study's copy) logged it: what [`write_trial_mp4`] draws.
///
/// # Errors
/// The session or the study copy cannot be read, or the session logged no such trial.
pub fn logged_trial(session: &Path, index: u32) -> Result<(lab::StudyFile, protocols::Trial)> {
    let s = results::store::read_session(session)?;
    let Some(record) = s.trials.records.iter().find(|r| r.trial.index == index) else {
        bail!(
            "{}: logged {} trial(s), none with index {index} (0-based, as trials.csv counts)",
            session.display(),
            s.trials.records.len()
        );
    };
    let copy = session
        .parent()
        .unwrap_or(Path::new("."))
        .join(lab::study::STUDY_COPY);
    let study = lab::StudyFile::load(&copy)
        .with_context(|| format!("the study kept with {}", session.display()))?;
    Ok((study, record.trial.clone()))
}

/// ffmpeg reading raw RGBA frames of `width` × `height` at `fps` on its standard input and
/// writing H.264 to `out`.
fn spawn_ffmpeg(width: u32, height: u32, fps: f64, out: &Path) -> Result<Child> {
    Command::new("ffmpeg")
        .args([
            "-loglevel",
            "error",
            "-y",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgba",
            "-s",
        ])
        .arg(format!("{width}x{height}"))
        .arg("-r")
        .arg(fps.to_string())
        .args([
            "-i", "-", "-c:v", "libx264", "-crf", "16", "-pix_fmt", "yuv420p",
        ])
        .args(["-movflags", "+faststart"])
        .arg(out)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| {
            anyhow::anyhow!(
                "ffmpeg: {e} (study clip video encodes with ffmpeg; on Debian: apt-get install \
                 ffmpeg)"
            )
        })
}
