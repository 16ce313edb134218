//! `study encode --codec wavelet-perceptual --cr 20` as a user meets it, on a 60 s clip: what
//! the command does from the AMC on disk to the decoded AMC on disk, and its parts.
//!
//! The clip: the shared `lambada` (2 180 frames, 120 Hz, 62 channels) played forwards and
//! backwards until it lasts 60 s (7 200 frames), so the motion stays continuous; it is written
//! once as AMC + ASF in a temporary folder.
//!
//! - `encode_path/whole`: read and pair the files (`lab::clips::load_one`), make the stimulus
//!   (`lab::stimulus::make`: rate search, decode, error metrics), write the `.mcz` and the
//!   decoded clip (`lab::stimulus::write_clip_as`): the body of `study encode`.
//! - `encode_path/read`, `encode_path/make`, `encode_path/write`: the three parts alone.
//!
//! Throughput is in frames: µs/frame = 10⁶ / thrpt. Target (issue 20): the whole command at
//! most 15 µs/frame on a 60 s clip.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use lab::Codecs;
use lab::clips::{self, ClipOptions};
use lab::stimulus::{self, Request};
use motion::{Clip, data, io};

/// Frames of a 60 s clip at 120 Hz.
pub const FRAMES_60S: usize = 7200;

/// `clip` played forwards, then backwards, and so on, until it has `frames` frames.
fn ping_pong(clip: &Clip, frames: usize) -> Clip {
    let n = clip.frames();
    let order: Vec<usize> = (0..frames)
        .map(|k| {
            let period = 2 * (n - 1);
            let i = k % period;
            if i < n { i } else { period - i }
        })
        .collect();
    let mut data = Vec::with_capacity(clip.channel_count() * frames);
    for c in 0..clip.channel_count() {
        let ch = clip.channel(c);
        data.extend(order.iter().map(|&f| ch[f]));
    }
    clip.with_data(frames, data).unwrap()
}

/// Writes the 60 s clip as `<dir>/lambada60.amc` with `<dir>/lambada60.asf`.
fn write_source(dir: &Path) -> Vec<PathBuf> {
    let f = data::shared_clips()
        .into_iter()
        .find(|f| f.name == "lambada")
        .expect("the shared clips include lambada");
    let clip = ping_pong(
        &io::read_clip(f.asf.as_deref(), &f.motion).unwrap(),
        FRAMES_60S,
    );
    let (amc, asf) = (dir.join("lambada60.amc"), dir.join("lambada60.asf"));
    io::write_clip(&clip, &amc, Some(&asf), files::Mode::Replace).unwrap();
    vec![amc, asf]
}

fn bench(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("encode-path-bench-{}", std::process::id()));
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    let files = write_source(&dir);
    let options = ClipOptions::default();
    let codecs = Codecs::default();
    let codec = codecs.get("wavelet-perceptual").unwrap();
    let request = Request {
        params: codecs::codec::Params::new(),
        target_cr: Some(20.0),
    };
    let loaded = clips::load_one(&files, &options).unwrap();
    let made = stimulus::make(codec.as_ref(), &loaded.clip, &request).unwrap();
    println!(
        "encode_path: {} frames, CR {:.2}, joint RMS {:.3} cm",
        loaded.clip.frames(),
        made.achieved_cr(),
        made.metrics.rms_cm
    );

    let mut g = c.benchmark_group("encode_path");
    g.throughput(Throughput::Elements(FRAMES_60S as u64));
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(4));
    g.bench_function("whole", |b| {
        b.iter(|| {
            let loaded = clips::load_one(black_box(&files), &options).unwrap();
            let codec = Codecs::with_database(None)
                .unwrap()
                .get("wavelet-perceptual")
                .unwrap();
            let made = stimulus::make(codec.as_ref(), &loaded.clip, &request).unwrap();
            std::fs::write(out.join("whole.mcz"), &made.bytes).unwrap();
            stimulus::write_clip_as(&made.decoded, &out, "whole", None, files::Mode::Replace)
                .unwrap()
        });
    });
    g.bench_function("read", |b| {
        b.iter(|| clips::load_one(black_box(&files), &options).unwrap());
    });
    g.bench_function("make", |b| {
        b.iter(|| stimulus::make(codec.as_ref(), black_box(&loaded.clip), &request).unwrap());
    });
    g.bench_function("write", |b| {
        b.iter(|| {
            stimulus::write_clip_as(
                black_box(&made.decoded),
                &out,
                "part",
                None,
                files::Mode::Replace,
            )
            .unwrap()
        });
    });
    g.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
