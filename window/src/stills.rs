//! Stills of clips and crowd scenes as the study window draws them (`study clip render`):
//! panes (columns) at given times (rows), drawn offscreen by [`crate::render::Offscreen`].

use std::path::Path;

use anyhow::{Context as _, Result, bail};
use motion::Clip;

use crate::render::Image;

/// What `study clip render` draws: times (rows), pane size, shadow.
pub struct Still<'a> {
    /// Clip times, seconds (one row of panes each).
    pub times: &'a [f64],
    /// Pane height, pixels (`--pane`).
    pub pane: u32,
    /// Wide panes (16:9, the window's stimulus pane: crowd scenes), else square.
    pub wide: bool,
    /// Ground shadows.
    pub shadow: bool,
}

impl Still<'_> {
    /// Pane width, pixels.
    pub fn width(&self) -> u32 {
        if self.wide {
            self.pane * 16 / 9
        } else {
            self.pane
        }
    }
}

/// Draws crowd scenes of `study` (columns) at every time (rows), each with the study's
/// `[scene]` camera and light, each character framed by its clip in the level's reference
/// scene, as the study window draws them.
///
/// # Errors
/// The study cannot be loaded or has no `[scene]`, a scene id is not one of its crowd scenes
/// or has no reference scene, or the image cannot be drawn (as [`clips`]).
pub fn crowd_scenes(study: &Path, scenes: &[String], still: &Still<'_>) -> Result<Image> {
    use crate::scene::{Cast, Stage, View};
    let file = lab::StudyFile::load(study)?;
    let Some(settings) = file.definition.scene.as_ref() else {
        bail!("{}: has no [scene] to draw", study.display());
    };
    let source = lab::source::ManifestStimuli::new(&file);
    let mut crowds = Vec::new();
    for id in scenes {
        let st = source
            .manifest()
            .get(id)
            .filter(|s| s.scene.is_some())
            .with_context(|| format!("--scenes: {id:?} is not a crowd scene of the study"))?;
        let reference = source
            .manifest()
            .reference_of(&st.clip)
            .with_context(|| format!("--scenes: {id:?} has no reference scene"))?;
        crowds.push(source.crowd_pair(id, &reference.id)?);
    }
    let far = crowds
        .iter()
        .flatten()
        .map(|c| c.placement.distance_cm)
        .fold(0.0, f64::max);
    let view = View::crowd(&settings.camera, &settings.light, far).with_shadow(still.shadow);
    let stages: Vec<Stage> = crowds
        .iter()
        .map(|crowd| {
            let casts: Vec<Cast> = crowd
                .iter()
                .map(|c| Cast::in_crowd(&c.name, &c.test, &c.reference, &c.placement, still.shadow))
                .collect();
            Stage::of(&casts)
        })
        .collect();
    draw_panes(stages, &view, still)
}

/// Draws every clip (columns) at every time (rows) with the first clip's camera at that time,
/// so a reference and its stimuli are framed alike.
///
/// # Errors
/// No clip, a pane size outside 64-4096 pixels, a time that is not a non-negative number of
/// seconds, an image over 64 M pixels, or no GPU adapter for the offscreen render.
pub fn clips(clips: &[&Clip], still: &Still<'_>) -> Result<Image> {
    use crate::scene::{Figure, Stage, View};
    let Some(first) = clips.first() else {
        bail!("no clip to render");
    };
    let view = View::framing(first).with_shadow(still.shadow);
    let stages = clips
        .iter()
        .map(|c| Stage::single(Figure::new(c, &view)))
        .collect();
    draw_panes(stages, &view, still)
}

/// Draws `stages` (columns) at every time of `still` (rows) with `view`, offscreen.
fn draw_panes(
    mut stages: Vec<crate::scene::Stage>,
    view: &crate::scene::View,
    still: &Still<'_>,
) -> Result<Image> {
    let (times, pane) = (still.times, still.pane);
    if stages.is_empty() {
        bail!("nothing to render");
    }
    if !(64..=4096).contains(&pane) {
        bail!("--pane {pane}: expected 64..=4096 pixels");
    }
    if let Some(t) = times.iter().find(|t| !t.is_finite() || **t < 0.0) {
        bail!("--times: {t} is not a time in seconds");
    }
    let (cols, rows, width) = (stages.len() as u32, times.len() as u32, still.width());
    if u64::from(cols * width) * u64::from(rows * pane) > 1 << 26 {
        bail!("{cols}×{rows} panes of {pane} px is too large an image");
    }
    let mut shapes = Vec::new();
    for t in times {
        crate::render::shapes_at(&mut stages, *t, &mut shapes);
    }
    let panes = crate::render::panes_of(&shapes, view, cols, width, pane);
    let mut offscreen = crate::render::Offscreen::new(4)?;
    let image = offscreen.render(cols * width, rows * pane, &panes)?;
    eprintln!("rendered with adapter {}", offscreen.adapter().name);
    Ok(image)
}
