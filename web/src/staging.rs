//! What the page draws for one trial, from the same [`Casting`] the study window draws: the
//! camera, ground and light every pane shares, and each pane's figures with their sizes and
//! places, all in centimetres (the unit of the clips the page is sent, `clipdata`).
//!
//! The page (`web/page/src/render.js`) poses each clip and draws it exactly as
//! `lab::scene` and the window's shader do; nothing here decides how a figure looks.

use std::sync::Arc;

use lab::scene::{Casting, View};
use serde_json::{Value, json};

/// Centimetres per unit of `clip` (1 when the file does not say).
fn cm(clip: &motion::Clip) -> f32 {
    let k = clip.skeleton.units.cm_per_unit as f32;
    if k.is_finite() && k > 0.0 { k } else { 1.0 }
}

fn scaled(p: [f32; 3], k: f32) -> [f32; 3] {
    [p[0] * k, p[1] * k, p[2] * k]
}

/// The page's scene of `cast` and the stimulus id of each clip it draws, in the order the
/// figures' `clip` indices name them (each id once per pane: that two panes show the same
/// stimulus, a hidden reference, is not told by their indices).
pub fn scene(cast: &Casting) -> (Value, Vec<(String, Arc<motion::Clip>)>) {
    let mut clips: Vec<(String, Arc<motion::Clip>)> = Vec::new();
    // A crowd camera is in centimetres already; a one-figure view is in its clip's units.
    let crowd = cast.panes.iter().flatten().any(|c| c.placed.is_some());
    let k = match cast.panes.iter().flatten().next() {
        Some(c) if !crowd => cm(&c.clip),
        _ => 1.0,
    };
    let panes: Vec<Value> = cast
        .panes
        .iter()
        .map(|figures| {
            let pane_start = clips.len();
            let figures: Vec<Value> = figures
                .iter()
                .map(|c| {
                    let index = clips[pane_start..]
                        .iter()
                        .position(|(id, _)| *id == c.id)
                        .map_or_else(
                            || {
                                clips.push((c.id.clone(), Arc::clone(&c.clip)));
                                clips.len() - 1
                            },
                            |i| pane_start + i,
                        );
                    let own = cm(&c.clip);
                    json!({
                        "clip": index,
                        "bone_radius": c.own.bone_radius * own,
                        "ground_y": c.own.ground_y * own,
                        "height": c.own.figure_height * own,
                        "placed": c.placed.map(|p| json!({
                            // The clip arrives in cm: its start point too, and no scaling.
                            "origin": scaled(p.origin, own),
                            "scale": p.scale / own,
                            "turn": p.turn,
                            "at": p.at,
                        })),
                    })
                })
                .collect();
            json!({ "figures": figures })
        })
        .collect();
    (view(&cast.view, k, &panes), clips)
}

fn view(v: &View, k: f32, panes: &[Value]) -> Value {
    let knots: Vec<[f32; 2]> = v
        .track
        .knots()
        .iter()
        .map(|q| [q[0] * k, q[1] * k])
        .collect();
    json!({
        "camera": {
            "target": scaled(v.target, k),
            "eye": scaled(v.eye, k),
            "fov_y": v.fov_y,
            "near": v.near * k,
            "far": v.far * k,
            "radius": v.radius * k,
            "track": { "knots": knots, "end_s": v.track.end_s() },
        },
        "ground": { "y": v.ground_y * k, "half": v.ground_half * k, "grid": v.grid * k },
        "light": v.light,
        "shadow": v.shadow,
        "panes": panes,
    })
}

/// `screen` (a serialized `Screen`) as the participant's browser may see it: without the
/// stimulus ids and the reference flags of its panes and characters, so nothing the page
/// is sent tells which pane holds the original in a blind design.
pub fn blind(mut screen: Value) -> Value {
    if let Some(panes) = screen["panes"].as_array_mut() {
        for pane in panes {
            if let Some(p) = pane.as_object_mut() {
                p.remove("stimulus");
                p.remove("reference");
            }
            if let Some(characters) = pane["content"]["characters"].as_array_mut() {
                for c in characters.iter_mut().filter_map(Value::as_object_mut) {
                    c.remove("stimulus");
                }
            }
        }
    }
    screen
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_blind_screen_names_no_stimulus_and_no_reference() {
        let screen = json!({
            "title": "t",
            "panes": [
                { "position": "left", "stimulus": "walk/reference", "reference": true,
                  "label": null, "content": { "kind": "figure" } },
                { "position": "right", "stimulus": "walk/spiht/cr10", "reference": false,
                  "label": null, "content": { "kind": "crowd_scene", "characters": [
                      { "name": "front", "stimulus": "walk/reference", "x_cm": 0.0 } ] } },
            ],
        });
        let text = blind(screen).to_string();
        for word in ["walk/", "reference", "stimulus"] {
            assert!(!text.contains(word), "{word} in {text}");
        }
        assert!(
            text.contains("\"front\"") && text.contains("\"left\""),
            "{text}"
        );
    }
}
