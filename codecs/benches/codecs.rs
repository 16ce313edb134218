//! Encode and decode time per frame of every codec on the shared CMU clips.
//!
//! Lossy codecs run at CR 20:1: the rate search runs once before timing and the parameters it
//! found are used (the timing is of one encode, as in the seeds' tables). Throughput is in
//! frames, so criterion's "thrpt" is frames/s; µs/frame = 10⁶ / thrpt.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use codecs::codec::{self, Params};
use codecs::{data, io, rate};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let clips = data::shared_clips();
    for f in &clips {
        let clip = io::read_clip(f.asf.as_deref(), &f.motion).unwrap();
        for name in ["wavelet-perceptual", "spiht", "zstd", "raw-f32"] {
            let codec = codec::by_name(name).unwrap();
            let stream = if codec.rate_control() == codec::RateControl::None {
                codec.encode(&clip, &Params::new()).unwrap()
            } else {
                rate::encode_to_cr(codec.as_ref(), &clip, &Params::new(), 20.0).unwrap()
            };
            let params: Params = stream.params.clone();
            let mut g = c.benchmark_group(format!("{name}/{}", f.name));
            g.throughput(Throughput::Elements(clip.frames() as u64));
            g.sample_size(20)
                .warm_up_time(Duration::from_millis(500))
                .measurement_time(Duration::from_secs(2));
            g.bench_function("encode", |b| {
                b.iter(|| codec.encode(black_box(&clip), &params).unwrap());
            });
            g.bench_function("decode", |b| {
                b.iter(|| codec.decode(black_box(&stream), &clip.skeleton).unwrap());
            });
            g.finish();
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
