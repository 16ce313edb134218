//! `[scene]`: several characters on one ground plane per pane (thesis 6.5, crowd motion), seen
//! by a camera and lit by a light that the study file fixes.
//!
//! A scene has one or more distance *levels* (thesis 6.5: the back characters at three
//! distances). Every character names the clip it performs, where it stands (`x_cm` to the
//! right of the camera's axis, `distance_cm` ahead of the camera, one value for every level or
//! one per level), its turn about the vertical axis, the *group* it belongs to (characters of
//! a group are compressed alike: `front`, `back`) and optionally an importance score for the
//! budget shared by importance. The crowd stimuli of the manifest (`study crowd`) record which
//! level and which characters they were made for; loading the study checks that they match
//! this table ([`check_scene_stimulus`]).

use std::collections::BTreeSet;
use std::path::Path;

use serde::{Deserialize, Serialize};
use toml::{Table, Value};

use super::check::{Ctx, join, type_name};
use super::{StudyError, finish, parse_toml, read_limited};
use crate::manifest::{REFERENCE_CODEC, Stimulus, StimulusManifest};

/// Most characters in a scene.
pub const MAX_CHARACTERS: usize = 64;
/// Most distance levels of a scene.
pub const MAX_LEVELS: usize = 16;

/// The fixed camera of every pane of a scene: at `height_cm` above the ground at the origin,
/// looking along −z (the characters stand at negative z), tilted down by `pitch_deg`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct SceneCamera {
    /// Eye height above the ground, cm.
    pub height_cm: f64,
    /// Downward tilt of the view axis, degrees.
    pub pitch_deg: f64,
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
}

impl Default for SceneCamera {
    fn default() -> Self {
        SceneCamera {
            height_cm: 160.0,
            pitch_deg: 8.0,
            fov_deg: 40.0,
        }
    }
}

/// The scene's light: a directional light and an ambient share.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct SceneLight {
    /// Direction the light comes from, degrees about the vertical: 0 from behind the camera,
    /// positive from the camera's right.
    pub azimuth_deg: f64,
    /// Height of the light above the horizon, degrees.
    pub elevation_deg: f64,
    /// Share of ambient light, 0-1 (the rest is diffuse from the light's direction).
    pub ambient: f64,
}

impl Default for SceneLight {
    fn default() -> Self {
        SceneLight {
            azimuth_deg: 40.0,
            elevation_deg: 58.0,
            ambient: 0.35,
        }
    }
}

impl SceneLight {
    /// Unit vector towards the light in scene coordinates (y up, the camera looking along −z).
    pub fn direction(&self) -> [f64; 3] {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        [az.sin() * el.cos(), el.sin(), az.cos() * el.cos()]
    }
}

/// One character of a scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneCharacter {
    /// Name, unique in the scene (letters, digits, `_`): `front`, `back_left`.
    pub name: String,
    /// The group it is compressed with (default: its name): every character of a group gets
    /// the same ratio in a crowd set made with fixed ratios (`study crowd --cr back=...`).
    pub group: String,
    /// The clip it performs: a clip name of the stimulus manifest.
    pub clip: String,
    /// Where it stands across the view, cm to the right of the camera's axis.
    pub x_cm: f64,
    /// How far ahead of the camera it stands, cm, one value per level (the same value on
    /// every level for a character that does not move between levels).
    pub distance_cm: Vec<f64>,
    /// Turn of the clip about the vertical axis, degrees, counter-clockwise seen from above
    /// (0: as recorded; the generated motions then face the camera).
    pub facing_deg: f64,
    /// Importance score for a budget shared by importance (`study crowd --share
    /// importance`); `None` when not given.
    pub importance: Option<f64>,
}

/// Where one character stands on one level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Across the view, cm (right of the camera's axis).
    pub x_cm: f64,
    /// Ahead of the camera, cm.
    pub distance_cm: f64,
    /// Turn about the vertical, degrees.
    pub facing_deg: f64,
}

/// The `[scene]` table: levels, camera, light and characters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSettings {
    /// Names of the distance levels, nearest layout first (default one level, `scene`).
    pub levels: Vec<String>,
    /// The camera of every pane.
    pub camera: SceneCamera,
    /// The light of every pane.
    pub light: SceneLight,
    /// The characters, in the order they are listed.
    pub characters: Vec<SceneCharacter>,
}

impl SceneSettings {
    /// Index of level `name`.
    pub fn level_index(&self, name: &str) -> Option<usize> {
        self.levels.iter().position(|l| l == name)
    }

    /// The character named `name`.
    pub fn character(&self, name: &str) -> Option<&SceneCharacter> {
        self.characters.iter().find(|c| c.name == name)
    }

    /// Where character `c` stands on level `level` (the last level's distance past the end).
    pub fn placement(&self, c: &SceneCharacter, level: usize) -> Placement {
        let d = c
            .distance_cm
            .get(level)
            .or(c.distance_cm.last())
            .copied()
            .unwrap_or(f64::NAN);
        Placement {
            x_cm: c.x_cm,
            distance_cm: d,
            facing_deg: c.facing_deg,
        }
    }

    /// The groups in the order their first character is listed.
    pub fn groups(&self) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        for c in &self.characters {
            if !out.contains(&c.group.as_str()) {
                out.push(&c.group);
            }
        }
        out
    }

    /// Reads the `[scene]` table of a TOML file (a study file, or a file with only that
    /// table): `study crowd` takes a study's scene before its stimuli exist. Other tables are
    /// ignored.
    ///
    /// # Errors
    /// [`StudyError`]: unreadable, too large, not TOML, no `[scene]`, or every problem of
    /// the table (keys as in a study file).
    pub fn read(path: &Path) -> Result<SceneSettings, StudyError> {
        let text = read_limited(path, super::MAX_STUDY_BYTES)?;
        let table = parse_toml(&text, path)?;
        let mut cx = Ctx::default();
        if !table.contains_key("scene") {
            cx.err("scene", "missing: a crowd needs a [scene] table");
        }
        let scene = cx
            .table(&table, "", "scene")
            .and_then(|t| parse_scene(t, &mut cx));
        finish(scene, cx, path, &text, "the [scene] is invalid")
    }
}

/// Whether `s` is a name the scene allows for levels, characters and groups: 1-24 ASCII
/// letters, digits or `_`, starting with a letter (it becomes part of stimulus ids and, as
/// `cr_<name>`, of a trial row's `codec_params`, whose keys are at most 32 characters).
fn is_scene_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 24
        && s.starts_with(|c: char| c.is_ascii_alphabetic())
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

const NAME_RULE: &str = "use 1-24 letters, digits or _, starting with a letter";

/// Parses `[scene]`; `None` when the table cannot give a scene (the problems are in `cx`).
pub(super) fn parse_scene(t: &Table, cx: &mut Ctx) -> Option<SceneSettings> {
    const P: &str = "scene";
    cx.known(t, P, &["levels", "camera", "light", "characters"]);
    let levels = match cx.strings(t, P, "levels") {
        Some(l) => l,
        None => vec!["scene".to_string()],
    };
    let mut ok = true;
    if levels.is_empty() || levels.len() > MAX_LEVELS {
        cx.err(
            join(P, "levels"),
            format!("give 1-{MAX_LEVELS} level names, got {}", levels.len()),
        );
        ok = false;
    }
    let mut seen = BTreeSet::new();
    for (i, l) in levels.iter().enumerate() {
        if !is_scene_name(l) {
            cx.err(format!("{P}.levels[{i}]"), format!("{l:?}: {NAME_RULE}"));
            ok = false;
        } else if !seen.insert(l.as_str()) {
            cx.err(format!("{P}.levels[{i}]"), format!("{l:?} is listed twice"));
            ok = false;
        }
    }
    let camera = parse_camera(t, cx);
    let light = parse_light(t, cx);
    let characters = parse_characters(t, levels.len(), cx);
    if ok && characters.as_ref().is_some_and(|c| !c.is_empty()) {
        Some(SceneSettings {
            levels,
            camera,
            light,
            characters: characters.unwrap_or_default(),
        })
    } else {
        None
    }
}

/// A number of `t` at `key` within `lo..=hi`, else `default` (reported when given).
fn ranged(
    cx: &mut Ctx,
    t: &Table,
    path: &str,
    key: &str,
    (lo, hi): (f64, f64),
    default: f64,
) -> f64 {
    match cx.float(t, path, key) {
        Some(v) if (lo..=hi).contains(&v) => v,
        Some(v) => {
            cx.err(join(path, key), format!("{v} is outside {lo}..={hi}"));
            default
        }
        None => default,
    }
}

fn parse_camera(t: &Table, cx: &mut Ctx) -> SceneCamera {
    const P: &str = "scene.camera";
    let d = SceneCamera::default();
    let Some(c) = cx.table(t, "scene", "camera") else {
        return d;
    };
    cx.known(c, P, &["height_cm", "pitch_deg", "fov_deg"]);
    SceneCamera {
        height_cm: ranged(cx, c, P, "height_cm", (1.0, 100_000.0), d.height_cm),
        pitch_deg: ranged(cx, c, P, "pitch_deg", (-80.0, 80.0), d.pitch_deg),
        fov_deg: ranged(cx, c, P, "fov_deg", (5.0, 120.0), d.fov_deg),
    }
}

fn parse_light(t: &Table, cx: &mut Ctx) -> SceneLight {
    const P: &str = "scene.light";
    let d = SceneLight::default();
    let Some(l) = cx.table(t, "scene", "light") else {
        return d;
    };
    cx.known(l, P, &["azimuth_deg", "elevation_deg", "ambient"]);
    SceneLight {
        azimuth_deg: ranged(cx, l, P, "azimuth_deg", (-360.0, 360.0), d.azimuth_deg),
        elevation_deg: ranged(cx, l, P, "elevation_deg", (0.0, 90.0), d.elevation_deg),
        ambient: ranged(cx, l, P, "ambient", (0.0, 1.0), d.ambient),
    }
}

/// `[[scene.characters]]`.
fn parse_characters(t: &Table, levels: usize, cx: &mut Ctx) -> Option<Vec<SceneCharacter>> {
    let list = match t.get("characters") {
        Some(Value::Array(a)) => a,
        Some(v) => {
            cx.wrong("scene", "characters", "an array of tables", v);
            return None;
        }
        None => {
            cx.err("scene.characters", "missing: list the characters");
            return None;
        }
    };
    if list.is_empty() || list.len() > MAX_CHARACTERS {
        cx.err(
            "scene.characters",
            format!("give 1-{MAX_CHARACTERS} characters, got {}", list.len()),
        );
        return None;
    }
    let mut out = Vec::with_capacity(list.len());
    let mut names = BTreeSet::new();
    for (i, v) in list.iter().enumerate() {
        let p = format!("scene.characters[{i}]");
        let Value::Table(c) = v else {
            cx.err(&p, format!("expected a table, got {}", type_name(v)));
            continue;
        };
        cx.known(
            c,
            &p,
            &[
                "name",
                "group",
                "clip",
                "x_cm",
                "distance_cm",
                "facing_deg",
                "importance",
            ],
        );
        let name = cx.string(c, &p, "name");
        let name = cx.required(name, c, &p, "name");
        if let Some(n) = &name {
            if !is_scene_name(n) {
                cx.err(join(&p, "name"), format!("{n:?}: {NAME_RULE}"));
            } else if !names.insert(n.clone()) {
                cx.err(join(&p, "name"), format!("{n:?} names two characters"));
            }
        }
        let group = cx.string(c, &p, "group");
        if let Some(g) = group.as_deref().filter(|g| !is_scene_name(g)) {
            cx.err(join(&p, "group"), format!("{g:?}: {NAME_RULE}"));
        }
        let clip = cx.string(c, &p, "clip");
        let clip = cx.required(clip, c, &p, "clip");
        if clip.as_deref().is_some_and(str::is_empty) {
            cx.err(join(&p, "clip"), "empty");
        }
        let x_cm = ranged(cx, c, &p, "x_cm", (-1e6, 1e6), 0.0);
        let facing_deg = ranged(cx, c, &p, "facing_deg", (-360.0, 360.0), 0.0);
        let importance = cx.float(c, &p, "importance");
        if let Some(v) = importance.filter(|v| v.is_nan() || *v <= 0.0) {
            cx.err(join(&p, "importance"), format!("must be positive, got {v}"));
        }
        let distance = parse_distances(c, &p, levels, cx);
        if let (Some(name), Some(clip), Some(distance_cm)) = (name, clip, distance) {
            out.push(SceneCharacter {
                group: group.unwrap_or_else(|| name.clone()),
                name,
                clip,
                x_cm,
                distance_cm,
                facing_deg,
                importance,
            });
        }
    }
    Some(out)
}

/// `distance_cm`: one positive number for every level, or an array with one per level.
fn parse_distances(c: &Table, p: &str, levels: usize, cx: &mut Ctx) -> Option<Vec<f64>> {
    let key = join(p, "distance_cm");
    let values = match c.get("distance_cm") {
        None => {
            cx.err(&key, "missing: how far ahead of the camera, cm");
            return None;
        }
        Some(Value::Array(_)) => {
            let v = cx.floats(c, p, "distance_cm")?;
            if v.len() != levels {
                cx.err(
                    &key,
                    format!(
                        "{} distances for {levels} level(s): give one per level, or one number",
                        v.len()
                    ),
                );
                return None;
            }
            v
        }
        Some(_) => vec![cx.float(c, p, "distance_cm")?; levels],
    };
    if let Some(bad) = values.iter().find(|d| !(**d > 0.0 && **d <= 1e6)) {
        cx.err(
            &key,
            format!("{bad}: a distance ahead of the camera must be in (0, 1e6] cm"),
        );
        return None;
    }
    Some(values)
}

/// Whether two distances are the one a crowd set recorded and the one the study gives.
fn same_distance(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

/// Checks a crowd stimulus of the manifest against the study's scene: its level is one of the
/// scene's, its characters are the scene's (names, groups, clips, in order), each at the
/// distance the scene gives it on that level, and each member a plain (non-scene) stimulus
/// of the manifest of the character's clip. Problems are reported under `key`.
pub(super) fn check_scene_stimulus(
    st: &Stimulus,
    scene: &SceneSettings,
    m: &StimulusManifest,
    key: &str,
    cx: &mut Ctx,
) {
    let Some(sc) = &st.scene else { return };
    let id = &st.id;
    let Some(level) = scene.level_index(&sc.level) else {
        cx.err(
            key,
            format!(
                "crowd stimulus {id:?} was made for level {:?}, which the study's [scene] does \
                 not have (levels: {})",
                sc.level,
                scene.levels.join(", ")
            ),
        );
        return;
    };
    let names: Vec<&str> = sc.characters.iter().map(|c| c.name.as_str()).collect();
    let wanted: Vec<&str> = scene.characters.iter().map(|c| c.name.as_str()).collect();
    if names != wanted {
        cx.err(
            key,
            format!(
                "crowd stimulus {id:?} has the characters {names:?}, the study's [scene] \
                 {wanted:?} (make the stimuli with `study crowd` from this study file)"
            ),
        );
        return;
    }
    for (member, c) in sc.characters.iter().zip(&scene.characters) {
        let want = scene.placement(c, level).distance_cm;
        if !same_distance(member.distance_cm, want) {
            cx.err(
                key,
                format!(
                    "crowd stimulus {id:?}: character {:?} was compressed for {} cm, the study \
                     places it {want} cm ahead on level {:?} (remake the stimuli with `study \
                     crowd`)",
                    c.name, member.distance_cm, sc.level
                ),
            );
        }
        if member.group != c.group {
            cx.err(
                key,
                format!(
                    "crowd stimulus {id:?}: character {:?} is in group {:?}, the study puts \
                     it in {:?}",
                    c.name, member.group, c.group
                ),
            );
        }
        match m.get(&member.stimulus) {
            None => cx.err(
                key,
                format!(
                    "crowd stimulus {id:?}: character {:?} shows {:?}, which is not in the \
                     manifest",
                    c.name, member.stimulus
                ),
            ),
            Some(s) if s.scene.is_some() => cx.err(
                key,
                format!(
                    "crowd stimulus {id:?}: character {:?} shows {:?}, itself a crowd",
                    c.name, member.stimulus
                ),
            ),
            Some(s) if s.clip != c.clip => cx.err(
                key,
                format!(
                    "crowd stimulus {id:?}: character {:?} shows clip {:?}, the study gives it \
                     {:?}",
                    c.name, s.clip, c.clip
                ),
            ),
            Some(s) if (st.codec == REFERENCE_CODEC) != (s.codec == REFERENCE_CODEC) => cx.err(
                key,
                format!(
                    "crowd stimulus {id:?}: character {:?} shows {:?}; a reference scene \
                     shows references only, a compressed one compressed stimuli only",
                    c.name, member.stimulus
                ),
            ),
            Some(_) => {}
        }
    }
}
