//! `[viewing]`: the viewing conditions a study states (ITU-R BT.500, ITU-T P.910): viewing
//! distance, the display's size, the luminance targets and the room's illumination. A study
//! with the table asks the experimenter to confirm them before every session.

use serde::{Deserialize, Serialize};
use toml::Table;

use super::check::{Ctx, join};

/// The viewing distance (`distance_ph` or `distance_cm`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ViewingDistance {
    /// In picture heights (H), as BT.500 and P.910 state it.
    PictureHeights(f64),
    /// In centimetres.
    Cm(f64),
}

/// The display (`screen_diagonal_in` or `screen_size_cm`, `screen_resolution`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScreenSize {
    /// Diagonal, inches.
    DiagonalIn(f64),
    /// Width and height of the picture area, cm.
    Cm([f64; 2]),
}

/// Viewing conditions (`[viewing]`): targets the experimenter confirms before each session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewingSettings {
    /// Viewing distance.
    pub distance: Option<ViewingDistance>,
    /// Display size.
    pub screen: Option<ScreenSize>,
    /// Display resolution, pixels.
    pub resolution_px: Option<[u32; 2]>,
    /// Peak luminance of the display, cd/m².
    pub peak_luminance_cd_m2: Option<f64>,
    /// Luminance of the background (behind the display, or the screen's grey), cd/m².
    pub background_luminance_cd_m2: Option<f64>,
    /// Illumination of the room, lux.
    pub room_illuminance_lux: Option<f64>,
}

impl ViewingSettings {
    /// The viewing distance in cm, where the file gives it in cm or in picture heights with
    /// a screen size to convert by (the picture height of a 16:9 diagonal without one).
    pub fn distance_cm(&self) -> Option<f64> {
        match self.distance? {
            ViewingDistance::Cm(d) => Some(d),
            ViewingDistance::PictureHeights(h) => self.picture_height_cm().map(|ph| h * ph),
        }
    }

    /// The picture height, cm: from `screen_size_cm`, or from the diagonal with the
    /// resolution's aspect ratio (16:9 without one).
    pub fn picture_height_cm(&self) -> Option<f64> {
        match self.screen? {
            ScreenSize::Cm([_, h]) => Some(h),
            ScreenSize::DiagonalIn(d) => {
                let [w, h] = self
                    .resolution_px
                    .map_or([16.0, 9.0], |[w, h]| [f64::from(w), f64::from(h)]);
                Some(d * 2.54 * h / w.hypot(h))
            }
        }
    }
}

/// A number as people write it: at most 3 decimals, no trailing zeros.
fn num(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

impl ViewingSettings {
    /// The conditions in words, one (what, value) pair per stated condition, in the order
    /// BT.500 and P.910 list them: viewing distance, display, luminance, environment.
    pub fn describe(&self) -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        match self.distance {
            Some(ViewingDistance::PictureHeights(h)) => out.push((
                "viewing distance",
                match self.distance_cm() {
                    Some(cm) => format!("{} H ({} cm)", num(h), num(cm)),
                    None => format!("{} H", num(h)),
                },
            )),
            Some(ViewingDistance::Cm(cm)) => out.push((
                "viewing distance",
                match self.picture_height_cm() {
                    Some(ph) => format!("{} cm ({} H)", num(cm), num(cm / ph)),
                    None => format!("{} cm", num(cm)),
                },
            )),
            None => {}
        }
        let mut display = match self.screen {
            Some(ScreenSize::DiagonalIn(d)) => format!("{} in diagonal", num(d)),
            Some(ScreenSize::Cm([w, h])) => format!("{} × {} cm", num(w), num(h)),
            None => String::new(),
        };
        if let Some([w, h]) = self.resolution_px {
            if !display.is_empty() {
                display.push_str(", ");
            }
            display.push_str(&w.to_string());
            display.push_str(" × ");
            display.push_str(&h.to_string());
            display.push_str(" px");
        }
        if !display.is_empty() {
            out.push(("display", display));
        }
        if let Some(p) = self.peak_luminance_cd_m2 {
            out.push(("peak luminance", format!("{} cd/m²", num(p))));
        }
        if let Some(b) = self.background_luminance_cd_m2 {
            out.push(("background luminance", format!("{} cd/m²", num(b))));
        }
        if let Some(r) = self.room_illuminance_lux {
            out.push(("room illumination", format!("{} lux", num(r))));
        }
        out
    }
}

const V: &str = "viewing";

/// Number `key` in `lo..=hi` (reported otherwise).
fn ranged(t: &Table, key: &str, lo: f64, hi: f64, unit: &str, cx: &mut Ctx) -> Option<f64> {
    let v = cx.float(t, V, key)?;
    if (lo..=hi).contains(&v) {
        Some(v)
    } else {
        cx.err(join(V, key), format!("{v} is outside {lo}..={hi} {unit}"));
        None
    }
}

pub(super) fn parse_viewing(t: &Table, cx: &mut Ctx) -> ViewingSettings {
    cx.known(
        t,
        V,
        &[
            "distance_ph",
            "distance_cm",
            "screen_diagonal_in",
            "screen_size_cm",
            "screen_resolution",
            "peak_luminance_cd_m2",
            "background_luminance_cd_m2",
            "room_illuminance_lux",
        ],
    );
    let ph = ranged(t, "distance_ph", 0.5, 20.0, "picture heights", cx);
    let cm = ranged(t, "distance_cm", 10.0, 2000.0, "cm", cx);
    if ph.is_some() && cm.is_some() {
        cx.err(
            join(V, "distance_cm"),
            "give the distance once: distance_ph (picture heights) or distance_cm",
        );
    }
    let distance = ph
        .map(ViewingDistance::PictureHeights)
        .or(cm.map(ViewingDistance::Cm));
    let (screen, resolution_px) = parse_screen(t, cx);
    let peak = ranged(t, "peak_luminance_cd_m2", 1.0, 10_000.0, "cd/m²", cx);
    let background = ranged(t, "background_luminance_cd_m2", 0.0, 10_000.0, "cd/m²", cx);
    if let (Some(p), Some(b)) = (peak, background)
        && b > p
    {
        cx.err(
            join(V, "background_luminance_cd_m2"),
            format!("{b} cd/m² is above the peak luminance {p} cd/m²"),
        );
    }
    let room = ranged(t, "room_illuminance_lux", 0.0, 100_000.0, "lux", cx);
    if distance.is_none()
        && screen.is_none()
        && peak.is_none()
        && background.is_none()
        && room.is_none()
        && resolution_px.is_none()
        && cx.issues.iter().all(|i| !i.key.starts_with("viewing."))
    {
        cx.err(
            V,
            "states no condition: give the viewing distance, screen, luminance or room \
             illumination (or remove the table)",
        );
    }
    if matches!(distance, Some(ViewingDistance::PictureHeights(_))) && screen.is_none() {
        cx.err(
            join(V, "distance_ph"),
            "a distance in picture heights needs the screen's size (screen_diagonal_in or \
             screen_size_cm) to be set up and reported in cm",
        );
    }
    ViewingSettings {
        distance,
        screen,
        resolution_px,
        peak_luminance_cd_m2: peak,
        background_luminance_cd_m2: background,
        room_illuminance_lux: room,
    }
}

/// `screen_diagonal_in` or `screen_size_cm`, and `screen_resolution`.
fn parse_screen(t: &Table, cx: &mut Ctx) -> (Option<ScreenSize>, Option<[u32; 2]>) {
    let diagonal = ranged(t, "screen_diagonal_in", 1.0, 1000.0, "inches", cx);
    let size = match cx.floats(t, V, "screen_size_cm") {
        Some(v) if v.len() == 2 && v.iter().all(|x| *x > 0.0 && *x <= 5000.0) => Some([v[0], v[1]]),
        Some(_) => {
            cx.err(
                join(V, "screen_size_cm"),
                "expected [width, height] of the picture area in cm, each in (0, 5000]",
            );
            None
        }
        None => None,
    };
    if diagonal.is_some() && size.is_some() {
        cx.err(
            join(V, "screen_size_cm"),
            "give the screen once: screen_diagonal_in or screen_size_cm",
        );
    }
    let screen = diagonal
        .map(ScreenSize::DiagonalIn)
        .or(size.map(ScreenSize::Cm));
    let resolution_px = match cx.floats(t, V, "screen_resolution") {
        Some(v)
            if v.len() == 2
                && v.iter()
                    .all(|x| *x >= 1.0 && *x <= 65536.0 && x.fract() == 0.0) =>
        {
            Some([v[0] as u32, v[1] as u32])
        }
        Some(_) => {
            cx.err(
                join(V, "screen_resolution"),
                "expected [width, height] in whole pixels, at most 65536",
            );
            None
        }
        None => None,
    };
    (screen, resolution_px)
}
