//! GDKE (closed form, seed 003 eq. 5) against the iterative Levenberg-Marquardt least-squares
//! sphere fit on the same noisy samples of a spherical joint (σ = 2 mm, R = 300 mm), for
//! N = 100 (the paper's typical preprocessing count) and N = 1000; and the whole solver on
//! synthetic markers of CMU 02_01 (σ = 2 mm, gaps), per frame: the plain solve of the walk,
//! the calibration on its range-of-motion trial, and the calibrated solve of the walk.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use markers::calibration::Calibration;
use markers::gdke::{GdkeOptions, LsqOptions, gdke, least_squares_sphere};
use markers::segments::{self, parse_segments};
use markers::synth::{RomOptions, SynthOptions, rom_capture, segment_map_toml, synth_capture};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Points on a cap of a sphere (±60° flexion, ±35° abduction) with Gaussian noise.
fn samples(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (r, sigma) = (300.0, 2.0);
    let c0 = [100.0, -50.0, 900.0];
    (0..n)
        .map(|_| {
            let a = (rng.random::<f64>() * 2.0 - 1.0) * 60f64.to_radians();
            let b = (rng.random::<f64>() * 2.0 - 1.0) * 35f64.to_radians();
            let d = [b.sin(), -a.cos() * b.cos(), a.sin() * b.cos()];
            [0, 1, 2].map(|k| c0[k] + r * d[k] + sigma * gaussian(&mut rng))
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    for n in [100usize, 1000] {
        let pts = samples(n, 42);
        let mut g = c.benchmark_group(format!("sphere-fit/N={n}"));
        g.throughput(Throughput::Elements(n as u64));
        g.sample_size(50)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(2));
        let opts = GdkeOptions::default();
        g.bench_function("gdke", |b| b.iter(|| gdke(black_box(&pts), &opts).unwrap()));
        let lsq = LsqOptions::default();
        g.bench_function("least-squares-lm", |b| {
            b.iter(|| least_squares_sphere(black_box(&pts), None, &lsq).unwrap());
        });
        g.finish();
    }
    solver(c);
}

/// The solver on CMU 02_01 (480 frames) and its range-of-motion trial; skipped without the
/// shared clips (outside CI).
fn solver(c: &mut Criterion) {
    let Some(dir) = motion::data::mocap_dir() else {
        eprintln!("shared clips not found: solver benchmarks skipped");
        return;
    };
    let clip = motion::io::read_clip(Some(&dir.join("12.asf")), &dir.join("02_01.amc")).unwrap();
    let clip = clip.excerpt(0..480);
    let options = SynthOptions::default();
    let motion = synth_capture(&clip, &options).unwrap().markers;
    let rom = rom_capture(&clip, &RomOptions::default(), &options)
        .unwrap()
        .markers;
    let map = parse_segments(&segment_map_toml(&clip), std::path::Path::new("s.toml")).unwrap();
    let cal = Calibration::estimate(&rom, &map).unwrap();
    let mut g = c.benchmark_group("solve/cmu-02_01");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(3));
    g.throughput(Throughput::Elements(motion.frames() as u64));
    g.bench_function("plain-walk", |b| {
        b.iter(|| segments::solve(black_box(&motion), &map).unwrap());
    });
    g.bench_function("calibrated-walk", |b| {
        b.iter(|| cal.solve(black_box(&motion)).unwrap());
    });
    g.throughput(Throughput::Elements(rom.frames() as u64));
    g.bench_function("calibrate-rom", |b| {
        b.iter(|| Calibration::estimate(black_box(&rom), &map).unwrap());
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
