//! `study sweep` on one worker thread and on two: the five shared clips (four AMC, one BVH;
//! 6 794 frames) × `wavelet-perceptual` × CR 20 and 40, written to a temporary folder (the
//! references, the streams, the decoded clips, `stimuli.json`, `rd.csv`).
//!
//! - `sweep/jobs1`, `sweep/jobs2`: the whole sweep with `jobs = 1` and `jobs = 2`.
//!
//! Throughput is in source frames × targets (the frames the sweep encodes): µs/frame =
//! 10⁶ / thrpt. Issue 20: sweeps use both cores, so `jobs2` should take about half of `jobs1`
//! on an idle 2-core machine.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use lab::clips::ClipOptions;
use lab::sweep::{SweepOptions, sweep};
use motion::{data, io};

fn bench(c: &mut Criterion) {
    let shared = data::shared_clips();
    let mut files = Vec::new();
    let mut frames = 0;
    for f in &shared {
        frames += io::read_clip(f.asf.as_deref(), &f.motion).unwrap().frames();
        files.push(f.motion.clone());
        files.extend(f.asf.clone());
    }
    files.sort();
    files.dedup();
    let targets = vec![20.0, 40.0];
    let dir = std::env::temp_dir().join(format!("sweep-bench-{}", std::process::id()));
    let options = |jobs: usize| SweepOptions {
        clips: files.clone(),
        clip_options: ClipOptions::default(),
        codecs: vec!["wavelet-perceptual".into()],
        targets: targets.clone(),
        max_errors_cm: Vec::new(),
        params: Vec::new(),
        output: dir.join(format!("jobs{jobs}")),
        jobs,
        database: None,
        codec_defs: None,
        cr_basis: codecs::basis::CrBasis::File,
        // Every iteration rewrites the same folder.
        force: true,
    };
    let mut g = c.benchmark_group("sweep");
    g.throughput(Throughput::Elements((frames * targets.len()) as u64));
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(5));
    for jobs in [1, 2] {
        let o = options(jobs);
        g.bench_function(format!("jobs{jobs}"), |b| {
            b.iter(|| sweep(&o, &|_, _| {}).unwrap());
        });
    }
    g.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
