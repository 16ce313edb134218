//! `study report` on 1,000,000 simulated rating rows (issue 6 target: ≤ 1 s on the CI machine).
//!
//! 1000 subjects × 1000 conditions (10 clips × 4 codecs × 25 ratios), one rating each.
//! `analyze` computes every statistic (MOS with t and z CIs and medians, BT.500 screening with
//! and without rejected observers, hidden-repeat consistency, paired t-tests with Holm, rate
//! findings); `report_tables` adds laying out and writing every table (figures excluded: their
//! cost does not depend on the number of rows). Compare with scripts/golden/analysis_bench.py.

#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use std::hint::black_box;

use analysis::study::{ReportOptions, analyze};
use analysis::synthetic::{MosStudySpec, mos_study};
use criterion::{Criterion, criterion_group, criterion_main};

fn spec() -> MosStudySpec {
    MosStudySpec {
        seed: 42,
        subjects: 1000,
        clips: (0..10).map(|i| format!("clip{i}")).collect(),
        codecs: vec![
            ("a".into(), 0.3),
            ("b".into(), 0.5),
            ("c".into(), 0.7),
            ("d".into(), 0.9),
        ],
        ratios: (0..25).map(|i| 10.0 + 2.0 * f64::from(i)).collect(),
        erratic_subjects: 20,
        ..MosStudySpec::default()
    }
}

fn bench(c: &mut Criterion) {
    let data = mos_study(&spec());
    assert_eq!(data.ratings.len(), 1_000_000);
    let options = ReportOptions {
        baseline_codec: Some("d".into()),
        figures: false,
        level_label: "Level".to_owned(),
        ..ReportOptions::default()
    };
    let mut group = c.benchmark_group("report_1m_ratings");
    group.sample_size(10);
    group.bench_function("analyze", |b| {
        b.iter(|| analyze(black_box(&data), &options).unwrap());
    });
    let dir = std::env::temp_dir().join("analysis-bench-report");
    group.bench_function("analyze_and_write_tables", |b| {
        b.iter(|| {
            let a = analyze(black_box(&data), &options).unwrap();
            a.to_report(&data, &options, "bench")
                .write(&dir, false, files::Mode::Replace)
                .unwrap()
        });
    });
    group.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
