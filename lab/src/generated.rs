//! Stimulus sets from motion the project generates itself ([`motion::synth`]), for the demo,
//! examples and tests: no capture data needed.

use std::path::Path;

use motion::synth::{WalkParams, walking_clip};

use crate::clips::ClipOptions;
use crate::error::{Result, io_error};
use crate::sweep::{self, SweepOptions, SweepSummary};

/// The generated walk `walk` written as `dir/clips/walk.asf` + `dir/clips/walk.amc`, and swept
/// into `dir/stimuli` (manifest `dir/stimuli/stimuli.json`, clip name `walk`) with `codecs`
/// at every ratio of `targets`. Nothing existing is replaced: `dir` is meant to be a fresh
/// folder.
///
/// # Errors
/// As [`sweep::sweep`] (also when `dir/stimuli` holds files), or the clip cannot be written
/// (also when it exists).
pub fn walk_stimuli(
    dir: &Path,
    walk: &WalkParams,
    codecs: &[&str],
    targets: &[f64],
) -> Result<SweepSummary> {
    let clips = dir.join("clips");
    std::fs::create_dir_all(&clips).map_err(io_error(&clips))?;
    let (asf, amc) = (clips.join("walk.asf"), clips.join("walk.amc"));
    motion::io::write_clip(&walking_clip(walk), &amc, Some(&asf), files::Mode::New)?;
    let options = SweepOptions {
        clips: vec![amc, asf],
        clip_options: ClipOptions::default(),
        codecs: codecs.iter().map(|c| (*c).to_string()).collect(),
        targets: targets.to_vec(),
        max_errors_cm: Vec::new(),
        params: Vec::new(),
        output: dir.join("stimuli"),
        jobs: std::thread::available_parallelism().map_or(1, usize::from),
        database: None,
        codec_defs: None,
        cr_basis: codecs::basis::CrBasis::File,
        force: false,
    };
    sweep::sweep(&options, &|_, _| {})
}
