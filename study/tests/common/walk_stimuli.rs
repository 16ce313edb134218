//! The generated stimulus set of the window tests: a one-second walk written as ASF/AMC, its
//! reference and two "compressed" stimuli of codec `x` at 10:1 and 20:1 (the same file, with
//! `cr` levels for staircases), in `stimuli.json`. Shared by the UI tests (`#[path]`) and the
//! end-to-end tests.

use std::path::Path;

/// Writes `walk.asf`, `walk.amc` and `stimuli.json` into `dir`.
pub fn write_walk_stimuli(dir: &Path) {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 1.0,
        // AMC files carry no rate: CMU's 120 Hz is assumed when they are read back.
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    });
    motion::io::write_clip(&clip, &dir.join("walk.amc"), Some(&dir.join("walk.asf"))).unwrap();
    let stim = |id: &str, codec: &str, cr: f64, rms: f64| {
        serde_json::json!({
            "id": id, "clip": "walk", "codec": codec,
            "target_cr": if codec == "reference" { serde_json::Value::Null } else { cr.into() },
            "achieved_cr": cr, "file": "walk.amc", "skeleton": "walk.asf",
            "params": if codec == "reference" { serde_json::json!({}) } else { serde_json::json!({"cr": cr}) },
            "metrics": { "rms_cm": rms, "max_cm": rms * 3.0, "mean_angle_deg": rms }
        })
    };
    let manifest = serde_json::json!({"version": 1, "stimuli": [
        stim("walk/reference", "reference", 1.0, 0.0),
        stim("walk/x/cr10", "x", 10.0, 0.5),
        stim("walk/x/cr20", "x", 20.0, 1.5),
    ]});
    std::fs::write(
        dir.join("stimuli.json"),
        serde_json::to_vec_pretty(&manifest).unwrap(),
    )
    .unwrap();
}
