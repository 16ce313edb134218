//! Encode and decode time per frame of every codec on the shared CMU clips.
//!
//! Lossy codecs run at CR 20:1: the rate search runs once before timing and the parameters it
//! found are used (the timing is of one encode, as in the seeds' tables). Throughput is in
//! frames, so criterion's "thrpt" is frames/s; µs/frame = 10⁶ / thrpt.
//!
//! `decode_10s/<codec>/<rate>`: decoding a 10 s clip (the first 1 200 frames of `lambada`, 120
//! Hz, 62 channels) from near-lossless to 40:1 (target ≤ 5 ms at any rate). 2.2:1 is about
//! the wavelet codec's highest rate (the rate search reaches 2.14:1 at most); SPIHT goes down
//! to 1:1.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use codecs::codec::{self, Params};
use codecs::rate;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use motion::{data, io};

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

fn decode_10s(c: &mut Criterion) {
    let f = data::shared_clips()
        .into_iter()
        .find(|f| f.name == "lambada")
        .expect("the shared clips include lambada");
    let clip = io::read_clip(f.asf.as_deref(), &f.motion)
        .unwrap()
        .excerpt(0..1200);
    let mut g = c.benchmark_group("decode_10s");
    g.sample_size(20)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    let cases: [(&str, &[f64]); 2] = [
        ("wavelet-perceptual", &[2.2, 3.0, 5.0, 10.0, 20.0, 40.0]),
        ("spiht", &[1.0, 1.5, 2.2, 3.0, 5.0, 10.0, 20.0, 40.0]),
    ];
    for (name, rates) in cases {
        let codec = codec::by_name(name).unwrap();
        for &cr in rates {
            let stream = rate::encode_to_cr(codec.as_ref(), &clip, &Params::new(), cr).unwrap();
            let label = format!("{cr}");
            println!(
                "decode_10s/{name}/{label}: CR {:.2}, {} bytes",
                stream.compression_ratio(),
                stream.byte_len()
            );
            g.bench_function(format!("{name}/{label}"), |b| {
                b.iter(|| codec.decode(black_box(&stream), &clip.skeleton).unwrap());
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench, decode_10s);
criterion_main!(benches);
