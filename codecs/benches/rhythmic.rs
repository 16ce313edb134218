//! The `rhythmic` codec (thesis ch. 4) on the shared CMU clips and the generated walk: before
//! timing, one line per clip and setting with the CR with and without the database section,
//! the joint position error, and `wavelet-perceptual` at the same CR (the peer, same run);
//! then encode and decode time per frame at the defaults (µs/frame = 10⁶ / thrpt).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::hint::black_box;
use std::time::Duration;

use codecs::codec::rhythmic::{self, RhythmicCodec};
use codecs::codec::{self, Codec, Params};
use codecs::metrics::compare;
use codecs::rate;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use motion::Clip;
use motion::synth::{WalkParams, walking_clip};

fn report(name: &str, clip: &Clip, settings: &[(&str, f64)]) {
    let c = RhythmicCodec::new();
    let p: Params = settings
        .iter()
        .map(|(k, v)| ((*k).to_string(), *v))
        .collect();
    let s = c.encode(clip, &p).unwrap();
    let t = c.decode_traced(&s, &clip.skeleton).unwrap();
    let m = compare(clip, &t.clip).unwrap();
    let worst = m
        .worst_stretch(clip.frame_rate_hz.round() as usize)
        .unwrap();
    let parts = rhythmic::stream_parts(&s).unwrap();
    let cr = parts.cr_with_database();
    let wavelet = codec::by_name("wavelet-perceptual").unwrap();
    let peer = rate::encode_to_cr(wavelet.as_ref(), clip, &Params::new(), cr).map_or_else(
        |e| format!("({e})"),
        |w| {
            let d = wavelet.decode(&w, &clip.skeleton).unwrap();
            format!("{:.2} cm", compare(clip, &d).unwrap().rms_cm)
        },
    );
    println!(
        "rhythmic/{name} {settings:?}: {} frames, {} segments, {} primitives; CR {cr:.1} with the \
         database ({} of {} bytes), {:.0} without; RMS {:.2} cm, max {:.2} cm, worst 1-s window \
         {:.2} cm, angle {:.2}°; wavelet-perceptual at CR {cr:.1}: {peer}",
        clip.frames(),
        t.segments.len(),
        t.primitives,
        parts.database_bytes,
        parts.total_bytes,
        parts.cr_without_database(),
        m.rms_cm,
        m.max_cm,
        worst.rms_cm,
        m.mean_angle_deg,
    );
}

fn bench(c: &mut Criterion) {
    let mut clips: Vec<(String, Clip)> = common::shared_clips();
    for duration_s in [20.0, 60.0] {
        clips.push((
            format!("walk-{duration_s}s"),
            walking_clip(&WalkParams {
                duration_s,
                ..WalkParams::default()
            }),
        ));
    }
    for (name, clip) in &clips {
        for settings in [
            &[][..],
            &[("k", 10.0)],
            &[("k", 40.0)],
            &[("blend", 0.0)],
            &[("anchor", 0.0)],
        ] {
            report(name, clip, settings);
        }
    }
    let codec = RhythmicCodec::new();
    for (name, clip) in &clips {
        let stream = codec.encode(clip, &Params::new()).unwrap();
        let mut g = c.benchmark_group(format!("rhythmic/{name}"));
        g.throughput(Throughput::Elements(clip.frames() as u64));
        g.sample_size(10)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs(2));
        g.bench_function("encode", |b| {
            b.iter(|| codec.encode(black_box(clip), &Params::new()).unwrap());
        });
        g.bench_function("decode", |b| {
            b.iter(|| codec.decode(black_box(&stream), &clip.skeleton).unwrap());
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
