//! Encode and decode time per frame of the `primitive` codec (thesis ch. 5) on the shared CMU
//! clips at `t_L = 0.01`, and the compression ratio it reaches there.
//!
//! Each clip is coded with a database trained on the *other* shared clips (thesis defaults:
//! K from 5 to 25, error bound 0.01, S_M = 32), as Table 5.1 codes motions with a database
//! trained elsewhere. The CR of each clip is printed before timing. Throughput is in frames:
//! µs/frame = 10⁶ / thrpt. Targets: encode ≤ 200 µs/frame, decode ≤ 20 µs/frame.
//!
//! `primitive/<clip>/encode_cr20`: `rate::encode_to_cr` to 20:1 (±2 %), the whole search on
//! `t_L`, as `study encode --codec primitive --cr 20` runs it. Target (issue 20): ≤ 200
//! µs/frame.
//!
//! `primitive/<clip>/encode_own_length`: the encode with every difference at its segment's own
//! length (`normalized = 0`, the default before issue 21), timed in the same run as the
//! default for comparison.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use codecs::codec::{self, CodecContext, Params};
use codecs::primitives::{Database, TrainParams};
use codecs::rate;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use motion::Clip;

fn bench(c: &mut Criterion) {
    let clips: Vec<(String, Clip)> = common::shared_clips();
    let mut params = Params::new();
    params.insert(codec::keys::T_L.into(), 0.01);
    for (i, (name, clip)) in clips.iter().enumerate() {
        let others = common::others(&clips, i);
        let db = Database::train(&others, &TrainParams::default(), |_, _| {});
        let ctx = CodecContext::with_primitives(Arc::new(db));
        let codec = codec::by_name_in("primitive", &ctx).unwrap();
        let stream = codec.encode(clip, &params).unwrap();
        let mut literal = params.clone();
        literal.insert(codec::keys::STEP_FLOOR.into(), 0.0);
        let cr_literal = codec.encode(clip, &literal).unwrap().compression_ratio();
        let mut own = params.clone();
        own.insert(codec::keys::NORMALIZED.into(), 0.0);
        let cr_own = codec.encode(clip, &own).unwrap().compression_ratio();
        println!(
            "primitive/{name}: {} frames, CR {:.2} at t_L = 0.01 (step_floor 0: {cr_literal:.2}; \
             own length: {cr_own:.2}), {} bytes",
            clip.frames(),
            stream.compression_ratio(),
            stream.byte_len(),
        );
        let mut g = c.benchmark_group(format!("primitive/{name}"));
        g.throughput(Throughput::Elements(clip.frames() as u64));
        g.sample_size(10)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs(2));
        g.bench_function("encode", |b| {
            b.iter(|| codec.encode(black_box(clip), &params).unwrap());
        });
        g.bench_function("encode_own_length", |b| {
            b.iter(|| codec.encode(black_box(clip), &own).unwrap());
        });
        g.bench_function("decode", |b| {
            b.iter(|| codec.decode(black_box(&stream), &clip.skeleton).unwrap());
        });
        g.bench_function("encode_cr20", |b| {
            b.iter(|| {
                rate::encode_to_cr(codec.as_ref(), black_box(clip), &Params::new(), 20.0).unwrap()
            });
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
