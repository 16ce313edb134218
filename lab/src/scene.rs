//! What the renderer draws, computed without a GPU: per-instance bone and joint shapes of a
//! posed skeleton, the camera that frames a clip, and the ground plane.
//!
//! A [`Figure`] turns a clip and a presentation time into instances (a unit cylinder per bone,
//! a unit sphere per joint, each with a position, rotation and scale) and, when the view asks
//! for it, a ground shadow (soft discs under the joints and bone midpoints, darker and tighter
//! the nearer the ground, so a foot's contact and any sliding show against the grid).
//!
//! A [`View`] is the camera of one clip: it follows the clip's root along a smoothed path
//! ([`View::at`]) and frames a window around the figure rather than the whole path, so a
//! walking figure stays large. The reference and the test stimulus of a trial are drawn with
//! the reference's view at their presentation time, so both panes move alike and appear at
//! the same size and place. A crowd pane (thesis 6.5) is a [`Stage`] of several figures, each
//! [`Placed`] on one ground and seen by the fixed camera and light of the study's `[scene]`
//! ([`View::crowd`]). A [`Casting`] says what each pane of a trial draws (which clip, sized
//! by which view, placed where) and the camera the panes share: the study window builds its
//! stages from it and `study serve` sends it to the browser page, so both draw the same. The
//! renderer knows nothing of trials; this module knows nothing of wgpu.

use std::sync::Arc;

use motion::clip::Clip;
use motion::math::Vec3;
use motion::playback::{EndMode, Sampler};
use protocols::record::{Arrangement, Position, Trial};
use protocols::screen::{CrowdScene, stimulus_at};
use protocols::study::{Placement, SceneCamera, SceneLight, StudyDefinition};

use crate::error::{Context as _, Result};
use crate::source::{CrowdCharacter, TrialStimuli};

/// A column-major 4×4 matrix (`m[column][row]`), as WGSL reads it.
pub type Mat4 = [[f32; 4]; 4];

/// One drawn shape: a unit mesh placed by position, rotation (unit quaternion x, y, z, w) and
/// per-axis scale, with a colour (linear 0-1 RGBA as written to the target).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    /// World position of the mesh origin.
    pub position: [f32; 3],
    /// Rotation as a unit quaternion (x, y, z, w).
    pub rotation: [f32; 4],
    /// Scale along the mesh's own axes.
    pub scale: [f32; 3],
    /// Colour.
    pub color: [f32; 4],
}

impl Instance {
    /// Bytes per instance in the vertex buffer (14 floats).
    pub const BYTES: usize = 14 * 4;

    /// Appends the instance as little-endian floats in shader order.
    pub fn write(&self, out: &mut Vec<u8>) {
        for v in self
            .position
            .iter()
            .chain(&self.rotation)
            .chain(&self.scale)
            .chain(&self.color)
        {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// Bone colour (the same in both viewports: nothing tells the reference from the test).
pub const BONE_COLOR: [f32; 4] = [0.78, 0.80, 0.86, 1.0];
/// Joint colour.
pub const JOINT_COLOR: [f32; 4] = [0.93, 0.55, 0.22, 1.0];

/// Shadow colour (black; the alpha is per disc).
const SHADOW_RGB: [f32; 3] = [0.0, 0.0, 0.0];

/// Instances of one posed skeleton: bones first, then joints, then the ground shadow.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameShapes {
    /// Cylinders, one per bone of non-zero length.
    pub bones: Vec<Instance>,
    /// Spheres, one per joint.
    pub joints: Vec<Instance>,
    /// Flattened spheres on the ground (alpha in the colour's last channel); empty when the
    /// view's shadow is off.
    pub shadows: Vec<Instance>,
    /// Presentation time of the pose, s (the camera follows the clip to this time).
    pub time_s: f64,
}

/// A clip ready to be posed at any presentation time.
#[derive(Debug, Clone)]
pub struct Figure {
    sampler: Sampler,
    parents: Vec<Option<usize>>,
    bone_radius: f32,
    points: Vec<Vec3>,
    /// Ground height and figure height when the shadow is drawn.
    shadow: Option<(f32, f32)>,
}

impl Figure {
    /// Prepares `clip`; shapes are sized from `view`'s figure height so that the reference
    /// and the test stimulus are drawn alike.
    pub fn new(clip: &Clip, view: &View) -> Figure {
        Figure {
            sampler: Sampler::new(clip),
            parents: clip.skeleton.joints.iter().map(|j| j.parent).collect(),
            bone_radius: view.bone_radius,
            points: Vec::new(),
            shadow: view
                .shadow
                .then_some((view.ground_y, view.figure_height.max(1e-6))),
        }
    }

    /// Seconds from the first frame to one frame past the last.
    pub fn duration_s(&self) -> f64 {
        self.sampler.duration_s()
    }

    /// The shapes at presentation time `t_s` (held at the last frame past the end).
    pub fn shapes_at(&mut self, t_s: f64, out: &mut FrameShapes) {
        self.sampler.pose_at(t_s, EndMode::Hold, &mut self.points);
        out.bones.clear();
        out.joints.clear();
        out.shadows.clear();
        out.time_s = t_s;
        let r = self.bone_radius;
        for (j, p) in self.points.iter().enumerate() {
            let pj = to_f32(*p);
            out.joints.push(Instance {
                position: pj,
                rotation: [0.0, 0.0, 0.0, 1.0],
                scale: [r * 1.45; 3],
                color: JOINT_COLOR,
            });
            let Some(parent) = self.parents.get(j).copied().flatten() else {
                continue;
            };
            let Some(pp) = self.points.get(parent).map(|p| to_f32(*p)) else {
                continue;
            };
            let d = sub(pj, pp);
            let len = norm(d);
            if len <= r * 0.05 {
                continue;
            }
            out.bones.push(Instance {
                position: pp,
                rotation: rotation_from_y(scale3(d, 1.0 / len)),
                scale: [r, len, r],
                color: BONE_COLOR,
            });
            if let Some(ground) = self.shadow {
                out.shadows
                    .push(shadow_disc(scale3(add(pj, pp), 0.5), r, ground));
            }
        }
        if let Some(ground) = self.shadow {
            for p in &self.points {
                out.shadows.push(shadow_disc(to_f32(*p), r, ground));
            }
        }
    }
}

/// Where a crowd character's clip goes in its pane (centimetres, y up): scaled from file
/// units to cm, its start point (the smoothed root at time 0, on the ground) moved to the
/// origin, turned about the vertical and set down at its place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placed {
    /// The clip's start point on its ground, file units.
    pub origin: [f32; 3],
    /// Centimetres per file unit.
    pub scale: f32,
    /// Turn about +y (unit quaternion x, y, z, w).
    pub turn: [f32; 4],
    /// Where the start point goes, cm.
    pub at: [f32; 3],
}

impl Placed {
    /// The placement of a clip framed by `own` (its [`View::framing`], in file units, with
    /// `cm_per_unit`) at `placement`: `x_cm` to the right of the camera's axis and
    /// `distance_cm` ahead of it (−z), turned by `facing_deg` (counter-clockwise seen from
    /// above).
    pub fn new(own: &View, cm_per_unit: f64, placement: &Placement) -> Placed {
        let half = (placement.facing_deg as f32).to_radians() * 0.5;
        let scale = if cm_per_unit.is_finite() && cm_per_unit > 0.0 {
            cm_per_unit as f32
        } else {
            1.0
        };
        Placed {
            origin: [own.target[0], own.ground_y, own.target[2]],
            scale,
            turn: [0.0, half.sin(), 0.0, half.cos()],
            at: [placement.x_cm as f32, 0.0, -(placement.distance_cm as f32)],
        }
    }

    /// A point of the clip (file units) in the pane (cm).
    fn point(&self, p: [f32; 3]) -> [f32; 3] {
        add(
            rotate_by(self.turn, scale3(sub(p, self.origin), self.scale)),
            self.at,
        )
    }

    /// `i` moved into the pane.
    fn instance(&self, i: &Instance) -> Instance {
        Instance {
            position: self.point(i.position),
            rotation: quat_mul(self.turn, i.rotation),
            scale: scale3(i.scale, self.scale),
            color: i.color,
        }
    }
}

/// What one pane draws: one figure (its view follows it), or the characters of a crowd
/// scene, each placed on the pane's one ground ([`Placed`], seen by a [`View::crowd`]).
#[derive(Debug, Clone)]
pub struct Stage {
    figures: Vec<(Figure, Option<Placed>)>,
    scratch: FrameShapes,
}

impl Stage {
    /// One figure.
    pub fn single(figure: Figure) -> Stage {
        Stage {
            figures: vec![(figure, None)],
            scratch: FrameShapes::default(),
        }
    }

    /// The figures `casts` of one pane.
    pub fn of(casts: &[Cast]) -> Stage {
        Stage {
            figures: casts
                .iter()
                .map(|c| (Figure::new(&c.clip, &c.own), c.placed))
                .collect(),
            scratch: FrameShapes::default(),
        }
    }

    /// Seconds from the first frame to one frame past the last of the longest figure.
    pub fn duration_s(&self) -> f64 {
        self.figures
            .iter()
            .map(|(f, _)| f.duration_s())
            .fold(0.0, f64::max)
    }

    /// The shapes of every figure at presentation time `t_s`, in the pane's coordinates.
    pub fn shapes_at(&mut self, t_s: f64, out: &mut FrameShapes) {
        out.bones.clear();
        out.joints.clear();
        out.shadows.clear();
        out.time_s = t_s;
        for (figure, placed) in &mut self.figures {
            figure.shapes_at(t_s, &mut self.scratch);
            let placed = *placed;
            let s = &self.scratch;
            for (from, to) in [
                (&s.bones, &mut out.bones),
                (&s.joints, &mut out.joints),
                (&s.shadows, &mut out.shadows),
            ] {
                match placed {
                    Some(p) => to.extend(from.iter().map(|i| p.instance(i))),
                    None => to.extend_from_slice(from),
                }
            }
        }
    }
}

/// One figure of a pane as it is cast: the clip it performs, the view that sizes it (bone
/// radius, ground, figure height: its reference's framing, so the reference and the test are
/// drawn alike) and, in a crowd scene, where it stands.
#[derive(Debug, Clone)]
pub struct Cast {
    /// The stimulus id of the clip (a crowd character's own stimulus).
    pub id: String,
    /// The clip drawn.
    pub clip: Arc<Clip>,
    /// The framing of the clip's reference.
    pub own: View,
    /// Where it stands in a crowd pane; `None`: alone in its pane, seen by its own view.
    pub placed: Option<Placed>,
}

impl Cast {
    /// A crowd character performing `clip` at `placement`, framed by its `reference` (so
    /// that it is drawn alike in the reference and the compressed scene: bone radius,
    /// ground, start point).
    pub fn in_crowd(
        id: &str,
        clip: &Arc<Clip>,
        reference: &Clip,
        placement: &Placement,
        shadow: bool,
    ) -> Cast {
        let own = View::framing(reference).with_shadow(shadow);
        let placed = Placed::new(&own, reference.skeleton.units.cm_per_unit, placement);
        Cast {
            id: id.to_owned(),
            clip: Arc::clone(clip),
            own,
            placed: Some(placed),
        }
    }
}

/// What a trial's panes draw and the camera they share: the window draws it
/// ([`Casting::stages`]), and the study server sends it to the page, so both show the same
/// figures, framed, lit and placed alike.
///
/// `panes[0]` is the first position (left, first, A, the test of a single-stimulus trial;
/// a MUSHRA screen's labelled reference), `panes[1]` the other (a MUSHRA screen's lettered
/// panes follow in order).
#[derive(Debug, Clone)]
pub struct Casting {
    /// The camera, ground and light of every pane: the reference's framing, or the crowd
    /// scene's fixed camera.
    pub view: View,
    /// Each pane's figures.
    pub panes: Vec<Vec<Cast>>,
}

impl Casting {
    /// The position of the first pane of a trial laid out as `arrangement`: left, A, or the
    /// first (a single stimulus, whose reference is never drawn, shows its test there).
    pub fn first(arrangement: Arrangement) -> Position {
        match arrangement {
            Arrangement::SideBySide => Position::Left,
            Arrangement::Abab => Position::A,
            Arrangement::Sequential | Arrangement::Single | Arrangement::Grid => Position::First,
        }
    }

    /// The figures of `trial` with its clips `shown`, the first pane at
    /// [`Casting::first`], the second at the other position. `framing`
    /// gives the view of a reference clip by its stimulus id (a front end keeps them, as
    /// the framing walks every frame). Crowd scenes place each character as the study's
    /// `[scene]` says.
    ///
    /// # Errors
    /// A crowd trial whose scene or characters are not the study's.
    pub fn of(
        study: &StudyDefinition,
        trial: &Trial,
        shown: &TrialStimuli,
        framing: &mut dyn FnMut(&str, &Clip) -> View,
    ) -> Result<Casting> {
        let shadow = study.rendering.ground_shadow;
        let first = Casting::first(trial.arrangement);
        if !shown.crowd.is_empty() {
            return crowd(study, trial, &shown.crowd, first, shadow);
        }
        let view = framing(&trial.reference, &shown.reference).with_shadow(shadow);
        let pane = |p: Position| {
            let id = stimulus_at(trial, p);
            let clip = if id == trial.reference {
                &shown.reference
            } else {
                &shown.test
            };
            vec![Cast {
                id: id.to_owned(),
                clip: Arc::clone(clip),
                own: view,
                placed: None,
            }]
        };
        Ok(Casting {
            view,
            panes: vec![pane(first), pane(first.other())],
        })
    }

    /// A MUSHRA screen: the labelled `reference` first, then each lettered pane's clip, all
    /// framed by the reference's `view`.
    pub fn grid(
        study: &StudyDefinition,
        view: View,
        reference: (&str, &Arc<Clip>),
        panes: &[(&str, &Arc<Clip>)],
    ) -> Casting {
        let view = view.with_shadow(study.rendering.ground_shadow);
        let cast = |&(id, clip): &(&str, &Arc<Clip>)| {
            vec![Cast {
                id: id.to_owned(),
                clip: Arc::clone(clip),
                own: view,
                placed: None,
            }]
        };
        Casting {
            view,
            panes: std::iter::once(&reference).chain(panes).map(cast).collect(),
        }
    }

    /// Seconds from the first frame to one frame past the last of the first pane's longest
    /// clip: what one step of the trial's schedule lasts.
    pub fn duration_s(&self) -> f64 {
        self.panes
            .first()
            .into_iter()
            .flatten()
            .map(|c| c.clip.duration_s())
            .fold(0.0, f64::max)
    }

    /// The window's stages, one per pane.
    pub fn stages(&self) -> Vec<Stage> {
        self.panes.iter().map(|casts| Stage::of(casts)).collect()
    }
}

/// A crowd trial: each pane the characters of its scene, placed on one ground and seen by
/// the scene's fixed camera.
fn crowd(
    study: &StudyDefinition,
    trial: &Trial,
    loaded: &[CrowdCharacter],
    first: Position,
    shadow: bool,
) -> Result<Casting> {
    let pane = |p: Position| -> Result<(Vec<Cast>, CrowdScene)> {
        let stimulus = stimulus_at(trial, p);
        let scene = CrowdScene::of(study, stimulus).context(|| {
            format!(
                "trial {}: {stimulus:?} is not a crowd scene of the study's [scene]",
                trial.index
            )
        })?;
        let reference = stimulus == trial.reference;
        let casts = scene
            .characters
            .iter()
            .map(|c| {
                let l = loaded
                    .iter()
                    .find(|l| l.name == c.name)
                    .context(|| format!("crowd character {:?} not loaded", c.name))?;
                let clip = if reference { &l.reference } else { &l.test };
                let placement = Placement {
                    x_cm: c.x_cm,
                    distance_cm: c.distance_cm,
                    facing_deg: c.facing_deg,
                };
                Ok(Cast::in_crowd(
                    &c.stimulus,
                    clip,
                    &l.reference,
                    &placement,
                    shadow,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok((casts, scene))
    };
    let (a, scene) = pane(first)?;
    let (b, _) = pane(first.other())?;
    let far = scene
        .characters
        .iter()
        .map(|c| c.distance_cm)
        .fold(0.0, f64::max);
    let view = View::crowd(&scene.camera, &scene.light, far).with_shadow(shadow);
    Ok(Casting {
        view,
        panes: vec![a, b],
    })
}

/// The shadow disc under point `p`: the nearer the ground (height `ground.0`), the smaller
/// and darker, so contact reads as a dark spot; a point a figure height (`ground.1`) up
/// leaves a faint wide one.
fn shadow_disc(p: [f32; 3], bone_radius: f32, (ground_y, height): (f32, f32)) -> Instance {
    let u = ((p[1] - ground_y) / height).clamp(0.0, 1.0);
    let radius = bone_radius * (2.2 + 4.0 * u);
    let alpha = 0.08 + 0.6 * (1.0 - u) * (1.0 - u);
    Instance {
        position: [p[0], ground_y + 0.05 * bone_radius, p[2]],
        rotation: [0.0, 0.0, 0.0, 1.0],
        scale: [radius, 0.01 * bone_radius, radius],
        color: [SHADOW_RGB[0], SHADOW_RGB[1], SHADOW_RGB[2], alpha],
    }
}

/// Knots of the camera's path over a clip.
pub const TRACK_KNOTS: usize = 64;
/// Width of the moving average that smooths the root's path (about a gait cycle), s.
const TRACK_SMOOTHING_S: f64 = 1.0;

/// The camera's path: the clip's root on the ground plane, smoothed by a moving average over
/// about a gait cycle (so the sway of each step does not shake the view; past the clip's ends
/// the path is continued by point reflection) and sampled at equal times.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Track {
    knots: [[f32; 2]; TRACK_KNOTS],
    count: usize,
    /// Time of the last knot, s.
    end_s: f32,
}

impl Track {
    /// The knots the path runs through, at equal times from 0 to [`Track::end_s`].
    pub fn knots(&self) -> &[[f32; 2]] {
        &self.knots[..self.count.clamp(1, TRACK_KNOTS)]
    }

    /// Time of the last knot, s.
    pub fn end_s(&self) -> f32 {
        self.end_s
    }

    /// A path standing still at `xz`.
    fn still(xz: [f32; 2]) -> Track {
        Track {
            knots: [xz; TRACK_KNOTS],
            count: 1,
            end_s: 0.0,
        }
    }

    /// The path's point at `t_s` (held at its ends): Catmull-Rom through the knots, so the
    /// camera's speed has no jumps.
    pub fn at(&self, t_s: f64) -> [f32; 2] {
        let n = self.count.clamp(1, TRACK_KNOTS);
        if n == 1 || self.end_s <= 0.0 {
            return self.knots[0];
        }
        let u = ((t_s as f32) / self.end_s).clamp(0.0, 1.0) * (n - 1) as f32;
        let i = (u.floor() as usize).min(n - 2);
        let f = u - i as f32;
        // Phantom knots past the ends continue the path straight on (a clamped end would
        // start and stop the camera with a jolt).
        let last = n as isize - 1;
        let k = |j: isize| {
            let q = |i: isize| self.knots[i.clamp(0, last) as usize];
            let (end, inner) = if j < 0 {
                (0, 1)
            } else if j > last {
                (last, last - 1)
            } else {
                return q(j);
            };
            let (e, i) = (q(end), q(inner));
            [2.0 * e[0] - i[0], 2.0 * e[1] - i[1]]
        };
        let (p0, p1, p2, p3) = (
            k(i as isize - 1),
            k(i as isize),
            k(i as isize + 1),
            k(i as isize + 2),
        );
        let mut out = [0.0; 2];
        for c in 0..2 {
            out[c] = 0.5
                * (2.0 * p1[c]
                    + (p2[c] - p0[c]) * f
                    + (2.0 * p0[c] - 5.0 * p1[c] + 4.0 * p2[c] - p3[c]) * f * f
                    + (3.0 * p1[c] - p0[c] - 3.0 * p2[c] + p3[c]) * f * f * f);
        }
        out
    }
}

/// The root's ground-plane path of `positions`, smoothed and sampled into a [`Track`].
fn track(positions: &motion::fk::Positions, rate_hz: f64) -> Option<Track> {
    let frames = positions.frames();
    let root: Vec<[f32; 2]> = (0..frames)
        .filter_map(|f| positions.frame(f).first().map(|p| to_f32(*p)))
        .map(|p| [p[0], p[2]])
        .collect();
    if root.len() != frames || frames == 0 || root.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let rate = if rate_hz.is_finite() && rate_hz > 0.0 {
        rate_hz
    } else {
        120.0
    };
    let half = ((0.5 * TRACK_SMOOTHING_S * rate).round() as isize).max(1);
    // Past its ends the path is continued by point reflection through the end point, which
    // keeps its direction and speed there: a full window everywhere, no kink at the ends.
    let last = frames as isize - 1;
    let at = |i: isize| -> [f64; 2] {
        let p = |k: isize| {
            let q = root[k.clamp(0, last) as usize];
            [f64::from(q[0]), f64::from(q[1])]
        };
        let (base, mirror) = if i < 0 {
            (0, -i)
        } else if i > last {
            (last, 2 * last - i)
        } else {
            return p(i);
        };
        let (b, m) = (p(base), p(mirror));
        [2.0 * b[0] - m[0], 2.0 * b[1] - m[1]]
    };
    let smooth = |f: usize| {
        let f = f as isize;
        let mut acc = [0.0f64; 2];
        for i in f - half..=f + half {
            let q = at(i);
            acc = [acc[0] + q[0], acc[1] + q[1]];
        }
        let n = (2 * half + 1) as f64;
        [(acc[0] / n) as f32, (acc[1] / n) as f32]
    };
    if frames == 1 {
        return Some(Track::still(smooth(0)));
    }
    let mut t = Track::still(smooth(0));
    t.count = TRACK_KNOTS.min(frames);
    t.end_s = ((frames - 1) as f64 / rate) as f32;
    for (k, knot) in t.knots.iter_mut().take(t.count).enumerate() {
        let f = (k * (frames - 1)) as f64 / (t.count - 1) as f64;
        let (a, b) = (f.floor() as usize, (f.ceil() as usize).min(frames - 1));
        let (pa, pb) = (smooth(a), smooth(b));
        let w = (f - a as f64) as f32;
        *knot = [pa[0] + (pb[0] - pa[0]) * w, pa[1] + (pb[1] - pa[1]) * w];
    }
    Some(t)
}

/// The camera and ground of one clip. `target`, `eye` and the ground centre are those at time
/// 0; [`View::at`] moves them along the clip's [`Track`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Point looked at (the figure's centre at time 0).
    pub target: [f32; 3],
    /// Camera position.
    pub eye: [f32; 3],
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Near and far planes.
    pub near: f32,
    /// Far plane.
    pub far: f32,
    /// Height of the ground plane (lowest point of the clip).
    pub ground_y: f32,
    /// Half the side of the drawn ground square.
    pub ground_half: f32,
    /// Grid spacing in clip units (one metre).
    pub grid: f32,
    /// Bone radius in clip units.
    pub bone_radius: f32,
    /// Height of the tallest pose, clip units.
    pub figure_height: f32,
    /// Radius of the sphere around the moving target that holds every pose.
    pub radius: f32,
    /// Whether the figures cast a ground shadow (on by default; the study file's
    /// `[rendering] ground_shadow`).
    pub shadow: bool,
    /// The path the camera follows.
    pub track: Track,
    /// Unit direction towards the light (x, y, z) and the ambient share (w).
    pub light: [f32; 4],
}

/// The light of a one-figure pane: from the front-right and above, 35 % ambient.
pub const DEFAULT_LIGHT: [f32; 4] = [0.349_128_27, 0.847_882_9, 0.399_003_73, 0.35];

/// Azimuth of the camera from +z towards +x, and its elevation, degrees.
const AZIMUTH_DEG: f32 = 30.0;
const ELEVATION_DEG: f32 = 18.0;

impl View {
    /// Follows the root of `clip` (y up), seen from the front-right and a little above, at a
    /// distance that holds every pose within the viewport.
    pub fn framing(clip: &Clip) -> View {
        let positions = motion::fk::positions(clip);
        let track = track(&positions, clip.frame_rate_hz);
        let (mut lo_y, mut hi_y) = (f32::INFINITY, f32::NEG_INFINITY);
        let mut tallest = 0.0f32;
        let frame_s = 1.0 / clip.frame_rate_hz.max(1e-9);
        for f in 0..positions.frames() {
            let (mut flo, mut fhi) = (f32::INFINITY, f32::NEG_INFINITY);
            for p in positions.frame(f) {
                let p = to_f32(*p);
                if !p.iter().all(|v| v.is_finite()) {
                    continue;
                }
                flo = flo.min(p[1]);
                fhi = fhi.max(p[1]);
            }
            if fhi >= flo {
                lo_y = lo_y.min(flo);
                hi_y = hi_y.max(fhi);
                tallest = tallest.max(fhi - flo);
            }
        }
        let cm = clip.skeleton.units.cm_per_unit as f32;
        let metre = if cm.is_finite() && cm > 0.0 {
            100.0 / cm
        } else {
            1.0
        };
        if !(lo_y.is_finite() && hi_y.is_finite()) {
            (lo_y, hi_y) = (0.0, metre * 1.7);
        }
        let height = if tallest > 0.0 { tallest } else { metre * 1.7 };
        let track = track.unwrap_or_else(|| Track::still([0.0, 0.0]));
        let centre_y = 0.5 * (lo_y + hi_y);
        // The smallest sphere about the moving centre that holds every pose.
        let mut reach = 0.5 * (hi_y - lo_y).max(height);
        for f in 0..positions.frames() {
            let c = track.at(f as f64 * frame_s);
            for p in positions.frame(f) {
                let p = to_f32(*p);
                if p.iter().all(|v| v.is_finite()) {
                    reach = reach.max(norm(sub(p, [c[0], centre_y, c[1]])));
                }
            }
        }
        let radius = reach * 1.04;
        let start = track.at(0.0);
        let target = [start[0], centre_y, start[1]];
        let fov_y = 40f32.to_radians();
        let distance = radius / (0.5 * fov_y).sin();
        let (az, el) = (AZIMUTH_DEG.to_radians(), ELEVATION_DEG.to_radians());
        let dir = [az.sin() * el.cos(), el.sin(), az.cos() * el.cos()];
        let eye = add(target, scale3(dir, distance));
        View {
            target,
            eye,
            fov_y,
            near: (distance - 2.5 * radius).max(distance * 0.02),
            far: distance + 4.0 * radius,
            ground_y: lo_y,
            ground_half: radius * 2.5,
            grid: metre,
            bone_radius: height * 0.022,
            figure_height: height,
            radius,
            shadow: true,
            track,
            light: DEFAULT_LIGHT,
        }
    }

    /// The fixed camera and light of a crowd pane (`[scene]`, thesis 6.5), in centimetres:
    /// the eye `camera.height_cm` above the ground at the origin, looking along −z tilted down
    /// by `camera.pitch_deg`, with the ground and its grid out past `far_cm`, the farthest a
    /// character stands. It never moves and never backs off for a narrow pane.
    pub fn crowd(camera: &SceneCamera, light: &SceneLight, far_cm: f64) -> View {
        let far_cm = if far_cm.is_finite() && far_cm > 0.0 {
            far_cm as f32
        } else {
            1000.0
        };
        let pitch = (camera.pitch_deg as f32).to_radians();
        let eye = [0.0, camera.height_cm as f32, 0.0];
        let forward = [0.0, -pitch.sin(), -pitch.cos()];
        // The point looked at, half way out to the farthest character; the ground is
        // centred under it and reaches past the camera and the farthest character.
        let target = add(eye, scale3(forward, 0.5 * far_cm));
        let dir = light.direction();
        View {
            target,
            eye,
            fov_y: (camera.fov_deg as f32).to_radians(),
            near: 5.0,
            far: 4.0 * far_cm + 2.0 * camera.height_cm as f32,
            ground_y: 0.0,
            ground_half: 1.2 * far_cm,
            grid: 100.0,
            bone_radius: 0.0,
            figure_height: 0.0,
            radius: 0.0,
            shadow: true,
            track: Track::still([target[0], target[2]]),
            light: [
                dir[0] as f32,
                dir[1] as f32,
                dir[2] as f32,
                light.ambient as f32,
            ],
        }
    }

    /// The same view with the ground shadow on or off.
    #[must_use]
    pub fn with_shadow(mut self, on: bool) -> View {
        self.shadow = on;
        self
    }

    /// The view at presentation time `t_s`: target, eye and ground moved along the track
    /// (the offset from target to eye is kept, so only the position changes, smoothly).
    #[must_use]
    pub fn at(&self, t_s: f64) -> View {
        let (a, b) = (self.track.at(0.0), self.track.at(t_s));
        let shift = [b[0] - a[0], 0.0, b[1] - a[1]];
        View {
            target: add(self.target, shift),
            eye: add(self.eye, shift),
            ..*self
        }
    }

    /// Projection × view for a viewport of aspect `width / height` (wgpu depth 0..1). A
    /// viewport narrower than it is tall moves the camera back so that the sphere of every
    /// pose still fits across it.
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        let aspect = if aspect.is_finite() && aspect > 0.0 {
            aspect
        } else {
            1.0
        };
        let half_fov_x = (aspect * (0.5 * self.fov_y).tan()).atan();
        let (mut eye, mut near, mut far) = (self.eye, self.near, self.far);
        if half_fov_x < 0.5 * self.fov_y {
            let d = norm(sub(self.eye, self.target));
            let wanted = self.radius / half_fov_x.sin();
            if d > 0.0 && wanted > d {
                eye = add(self.target, scale3(sub(self.eye, self.target), wanted / d));
                near = (wanted - 2.5 * self.radius).max(wanted * 0.02);
                far = wanted + 4.0 * self.radius;
            }
        }
        mul(
            &perspective(self.fov_y, aspect, near, far),
            &look_at(eye, self.target, [0.0, 1.0, 0.0]),
        )
    }
}

fn to_f32(p: Vec3) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale3(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

fn normalize(a: [f32; 3]) -> [f32; 3] {
    let n = norm(a);
    if n > 0.0 { scale3(a, 1.0 / n) } else { a }
}

/// `v` rotated by the unit quaternion `q` (x, y, z, w).
fn rotate_by(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let u = [q[0], q[1], q[2]];
    let t = scale3(cross(u, v), 2.0);
    add(add(v, scale3(t, q[3])), cross(u, t))
}

/// The Hamilton product `a b` (rotate by `b`, then by `a`).
fn quat_mul(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    [
        a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1],
        a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0],
        a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3],
        a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2],
    ]
}

/// The unit quaternion turning +y onto the unit vector `d`.
fn rotation_from_y(d: [f32; 3]) -> [f32; 4] {
    let c = d[1];
    if c < -0.999_999 {
        // Opposite: half a turn about x.
        return [1.0, 0.0, 0.0, 0.0];
    }
    // q = (y × d, 1 + y·d), normalised.
    let axis = [d[2], 0.0, -d[0]];
    let w = 1.0 + c;
    let n = (axis[0] * axis[0] + axis[2] * axis[2] + w * w).sqrt();
    [axis[0] / n, 0.0, axis[2] / n, w / n]
}

/// Column-major product `a × b`.
pub fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for (c, col) in m.iter_mut().enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

/// Right-handed perspective projection with depth mapped to 0..1.
pub fn perspective(fov_y: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    let f = 1.0 / (0.5 * fov_y).tan();
    let range = far / (near - far);
    [
        [f / aspect, 0.0, 0.0, 0.0],
        [0.0, f, 0.0, 0.0],
        [0.0, 0.0, range, -1.0],
        [0.0, 0.0, range * near, 0.0],
    ]
}

/// Right-handed view matrix looking from `eye` at `target`.
pub fn look_at(eye: [f32; 3], target: [f32; 3], up: [f32; 3]) -> Mat4 {
    let f = normalize(sub(target, eye));
    let s = normalize(cross(f, up));
    let u = cross(s, f);
    [
        [s[0], u[0], -f[0], 0.0],
        [s[1], u[1], -f[1], 0.0],
        [s[2], u[2], -f[2], 0.0],
        [-dot(s, eye), -dot(u, eye), dot(f, eye), 1.0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transform(m: &Mat4, p: [f32; 3]) -> [f32; 3] {
        let v = [p[0], p[1], p[2], 1.0];
        let mut o = [0.0f32; 4];
        for (r, out) in o.iter_mut().enumerate() {
            *out = (0..4).map(|c| m[c][r] * v[c]).sum();
        }
        [o[0] / o[3], o[1] / o[3], o[2] / o[3]]
    }

    #[test]
    fn rotation_from_y_maps_y_onto_the_direction() {
        for d in [
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.3, -0.5, 0.81],
            [-0.6, 0.7, -0.2],
        ] {
            let d = normalize(d);
            let r = rotate_by(rotation_from_y(d), [0.0, 1.0, 0.0]);
            for k in 0..3 {
                assert!((r[k] - d[k]).abs() < 1e-5, "{d:?} -> {r:?}");
            }
        }
    }

    #[test]
    fn every_pose_of_the_walk_projects_inside_the_view() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let view = View::framing(&clip);
        let positions = motion::fk::positions(&clip);
        // A wide pane and one narrower than it is tall (two panes side by side).
        for aspect in [16.0 / 9.0, 0.6] {
            let mut tallest = 0.0f32;
            for f in (0..positions.frames()).step_by(7) {
                let vp = view.at(f as f64 / clip.frame_rate_hz).view_proj(aspect);
                let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                for p in positions.frame(f) {
                    let ndc = transform(&vp, to_f32(*p));
                    assert!(ndc[0].abs() < 1.0 && ndc[1].abs() < 1.0, "{ndc:?}");
                    assert!((0.0..1.0).contains(&ndc[2]), "depth {ndc:?}");
                    (lo, hi) = (lo.min(ndc[1]), hi.max(ndc[1]));
                }
                tallest = tallest.max(hi - lo);
            }
            // The joints span over half the height (NDC spans 2) in the wide pane.
            if aspect > 1.0 {
                assert!(tallest > 1.2, "figure spans {tallest} of 2 in NDC");
            }
        }
    }

    #[test]
    fn the_camera_follows_the_walk_smoothly() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let view = View::framing(&clip);
        let frame_s = 1.0 / 60.0;
        let mut last = view.at(0.0).target;
        let mut prev_step: Option<f32> = None;
        let mut worst_change = 0.0f32;
        // Up to the last frame (past it the figure and the camera hold still).
        let n = ((clip.duration_s() - 1.0 / clip.frame_rate_hz) / frame_s) as usize;
        for k in 1..=n {
            let t = view.at(k as f64 * frame_s).target;
            let step = norm(sub(t, last));
            if let Some(p) = prev_step {
                worst_change = worst_change.max((step - p).abs());
            }
            prev_step = Some(step);
            last = t;
        }
        let travelled = norm(sub(view.at(clip.duration_s()).target, view.at(0.0).target));
        // 1.2 m/s for 4 s, less the smoothing at the ends; in clip units.
        let metre = view.grid;
        assert!(travelled > 3.0 * metre, "the camera moved {travelled}");
        // Per 60 Hz frame the camera's step changes by under 1 mm: no jerks.
        assert!(
            worst_change < 0.001 * metre,
            "step changed by {worst_change} in one frame"
        );
        // Shadows follow the view's switch.
        let mut s = FrameShapes::default();
        Figure::new(&clip, &view).shapes_at(1.0, &mut s);
        assert_eq!(s.shadows.len(), s.joints.len() + s.bones.len());
        Figure::new(&clip, &view.with_shadow(false)).shapes_at(1.0, &mut s);
        assert!(s.shadows.is_empty());
    }

    /// A crowd pane: each figure stands on the ground (y = 0 cm) at its place, as tall as it
    /// is in centimetres, turned as asked; with the camera of the crowd example every joint
    /// of every level projects inside a 16:9 pane, nearer figures taller.
    #[test]
    fn crowd_figures_stand_at_their_places_in_view() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
            speed_cm_s: 0.0,
            ..motion::synth::WalkParams::default()
        });
        let camera = SceneCamera {
            height_cm: 250.0,
            pitch_deg: 19.0,
            fov_deg: 40.0,
        };
        let view = View::crowd(&camera, &SceneLight::default(), 1300.0);
        let place = |x_cm, distance_cm, facing_deg| Placement {
            x_cm,
            distance_cm,
            facing_deg,
        };
        let mut heights = Vec::new();
        for (x, d) in [(0.0, 350.0), (-150.0, 600.0), (150.0, 1300.0)] {
            for facing in [0.0, 180.0] {
                let shown = Arc::new(clip.clone());
                let cast = Cast::in_crowd("walk", &shown, &clip, &place(x, d, facing), true);
                let mut stage = Stage::of(&[cast]);
                let mut s = FrameShapes::default();
                stage.shapes_at(0.0, &mut s);
                let ys: Vec<f32> = s.joints.iter().map(|j| j.position[1]).collect();
                let (lo, hi) = ys
                    .iter()
                    .fold((f32::MAX, f32::MIN), |(a, b), y| (a.min(*y), b.max(*y)));
                // The lowest point of the whole clip is the ground: a foot at time 0 is on it.
                assert!(lo > -0.5 && lo < 8.0, "feet at {lo} cm");
                assert!((150.0..200.0).contains(&(hi - lo)), "{} cm tall", hi - lo);
                let root = s.joints[0].position;
                assert!(
                    (root[0] - x as f32).abs() < 1.0 && (root[2] + d as f32).abs() < 1.0,
                    "{root:?}"
                );
                // Turning half round puts the left hip on the other side of the root.
                let hip = s.joints[1].position[0] - root[0];
                if facing == 0.0 {
                    assert!(hip > 0.0, "{hip}");
                } else {
                    assert!(hip < 0.0, "{hip}");
                }
                let vp = view.view_proj(16.0 / 9.0);
                let ndc: Vec<[f32; 3]> = s
                    .joints
                    .iter()
                    .map(|j| transform(&vp, j.position))
                    .collect();
                for p in &ndc {
                    assert!(
                        p[0].abs() < 1.0 && p[1].abs() < 1.0 && (0.0..1.0).contains(&p[2]),
                        "{p:?}"
                    );
                }
                let (nlo, nhi) = ndc
                    .iter()
                    .fold((f32::MAX, f32::MIN), |(a, b), p| (a.min(p[1]), b.max(p[1])));
                heights.push(nhi - nlo);
            }
        }
        assert!(
            heights[0] > heights[2] && heights[2] > heights[4],
            "{heights:?}"
        );
    }

    #[test]
    fn bones_join_parent_and_child_joints() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let view = View::framing(&clip);
        let mut fig = Figure::new(&clip, &view);
        let mut shapes = FrameShapes::default();
        fig.shapes_at(0.37, &mut shapes);
        assert_eq!(shapes.joints.len(), clip.skeleton.joints.len());
        assert!(shapes.bones.len() >= clip.skeleton.joints.len() / 2);
        for b in &shapes.bones {
            // The cylinder's far end is a joint.
            let end = add(b.position, rotate_by(b.rotation, [0.0, b.scale[1], 0.0]));
            let hit = shapes
                .joints
                .iter()
                .any(|j| norm(sub(j.position, end)) < 1e-3 * b.scale[1].max(1.0));
            assert!(hit, "bone ending at {end:?} meets no joint");
        }
        let mut bytes = Vec::new();
        shapes.bones[0].write(&mut bytes);
        assert_eq!(bytes.len(), Instance::BYTES);
    }
}
