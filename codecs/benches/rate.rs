//! The rate search: `rate::encode_to_cr` (what `study encode --cr` and the sweep run) of
//! `wavelet-perceptual` on the shared CMU clips at 10:1, 20:1 and 40:1, against one encode at
//! the parameters the search found.
//!
//! - `rate/<clip>/search_cr<T>`: the whole search to target T (±2 %);
//! - `rate/<clip>/single`: one encode at the parameters the 20:1 search found (the figure the
//!   `codecs` bench reports).
//!
//! The number of encodes each search ran is printed before timing. Throughput is in frames:
//! µs/frame = 10⁶ / thrpt. Target (issue 20): a search costs at most 4 single encodes.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use codecs::codec::{self, Params};
use codecs::rate;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use motion::{data, io};

const TARGETS: [f64; 3] = [10.0, 20.0, 40.0];

fn bench(c: &mut Criterion) {
    let codec = codec::by_name("wavelet-perceptual").unwrap();
    for f in data::shared_clips() {
        let clip = io::read_clip(f.asf.as_deref(), &f.motion).unwrap();
        let mut g = c.benchmark_group(format!("rate/{}", f.name));
        g.throughput(Throughput::Elements(clip.frames() as u64));
        g.sample_size(10)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(2));
        for target in TARGETS {
            let s = rate::search_to_cr(codec.as_ref(), &clip, &Params::new(), target).unwrap();
            println!(
                "rate/{}/search_cr{target}: {} encodes, CR {:.2}",
                f.name,
                s.encodes,
                s.stream.compression_ratio()
            );
            g.bench_function(format!("search_cr{target}"), |b| {
                b.iter(|| {
                    rate::encode_to_cr(codec.as_ref(), black_box(&clip), &Params::new(), target)
                        .unwrap()
                });
            });
        }
        let found = rate::encode_to_cr(codec.as_ref(), &clip, &Params::new(), 20.0)
            .unwrap()
            .params;
        g.bench_function("single", |b| {
            b.iter(|| codec.encode(black_box(&clip), &found).unwrap());
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
