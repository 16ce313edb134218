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
    let dir = out
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = out
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let temp = dir.join(format!(".{name}.{}.tmp.mp4", std::process::id()));
    let mut ffmpeg = spawn_ffmpeg(width, pane, fps, &temp)?;
    let drawn = (|| -> Result<()> {
        let mut offscreen = Offscreen::new(4)?;
        let mut stdin = ffmpeg.stdin.take().context("ffmpeg's input")?;
        let mut shapes = Vec::new();
        for k in 0..frames {
            shapes.clear();
            shapes_at(&mut stages, k as f64 / fps, &mut shapes);
            let image =
                offscreen.render(width, pane, &panes_of(&shapes, &view, cols, pane, pane))?;
            stdin
                .write_all(&image.rgba)
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
    Ok(Made {
        frames,
        fps,
        width,
        height: pane,
    })
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
