//! What the codec benchmarks share: the shared CMU clips and the leave-one-out training set.
#![allow(dead_code, reason = "each bench uses what it needs")]

use motion::{Clip, data, io};

/// The shared clips (`MOCAP_DATA` or `../shared/data/mocap`), by name.
pub fn shared_clips() -> Vec<(String, Clip)> {
    data::shared_clips()
        .into_iter()
        .map(|f| (f.name, io::read_clip(f.asf.as_deref(), &f.motion).unwrap()))
        .collect()
}

/// Every clip of `clips` but the `i`-th: what a database for clip `i` is trained on.
pub fn others(clips: &[(String, Clip)], i: usize) -> Vec<&Clip> {
    clips
        .iter()
        .enumerate()
        .filter(|(k, _)| *k != i)
        .map(|(_, (_, c))| c)
        .collect()
}
