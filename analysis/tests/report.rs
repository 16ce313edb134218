#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]
//! End to end: a simulated study → every statistic → report.md, report.html, tables, figures.

use analysis::psychometric::{BootstrapOptions, FitOptions, Lapse, PsychometricFit, Shape};
use analysis::study::{ReportOptions, StudyData, analyze};
use analysis::synthetic::{MosStudySpec, mos_study, staircase};
use analysis::{DscqsPair, export};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn simulated() -> StudyData {
    // Mid-scale qualities (perceptual 4.4 → 3.2, wavelet 4.1 → 2.3 from 20:1 to 40:1) so a
    // random observer's outliers fall on both sides of the panel mean.
    let spec = MosStudySpec {
        subjects: 15,
        erratic_subjects: 1,
        showings: 2,
        codecs: vec![("perceptual".to_owned(), 0.6), ("wavelet".to_owned(), 0.9)],
        ..MosStudySpec::default()
    };
    let mut data = mos_study(&spec);
    // DSCQS pairs from the same ratings: reference scored 4.5-5, test = the rating.
    data.dscqs = data
        .ratings
        .iter()
        .map(|r| DscqsPair {
            subject: r.subject,
            condition: r.condition,
            reference_score: 5.0,
            test_score: r.score,
        })
        .collect();
    let observer = PsychometricFit {
        shape: Shape::Weibull,
        alpha: 0.012,
        beta: 3.0,
        guess_rate: 0.5,
        lapse: 0.01,
        log_likelihood: 0.0,
        trials: 0,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for s in 0..6 {
        let (track, trials) = staircase(&mut rng, &observer, s, 0.024, 0.002, 50);
        data.staircases.push(track);
        data.two_afc.extend(trials);
    }
    data
}

fn options() -> ReportOptions {
    ReportOptions {
        baseline_codec: Some("wavelet".to_owned()),
        zscore: true,
        fit: FitOptions {
            lapse: Lapse::Free { max: 0.06 },
            ..FitOptions::default()
        },
        bootstrap: BootstrapOptions {
            replicates: 100,
            ..BootstrapOptions::default()
        },
        ..ReportOptions::default()
    }
}

#[test]
fn analysis_finds_what_the_simulation_put_in() {
    let data = simulated();
    let a = analyze(&data, &options()).unwrap();
    assert_eq!(a.mos.len(), 20);
    // The erratic subject 0 is rejected by BT.500 screening, and only it.
    let screening = a.screening.as_ref().unwrap();
    assert!(
        screening.rejected().contains(&0),
        "{:?}",
        screening.observers
    );
    assert!(screening.rejected().len() <= 2);
    assert!(a.mos_screened.is_some());
    // Perceptual beats wavelet significantly at 40:1 on both clips (one-tailed, Holm).
    let at40: Vec<_> = a
        .comparisons
        .iter()
        .filter(|c| c.compression_ratio == Some(40.0))
        .collect();
    assert_eq!(at40.len(), 2);
    for c in at40 {
        assert_eq!(c.first.0, "perceptual");
        assert!(c.p_holm.unwrap() < 0.05, "{c:?}");
    }
    // Hidden repeats were found for every subject.
    assert!(a.repeats.iter().all(|r| r.pairs == 20));
    // No codec reaches MOS 4.5 (perceptual is 4.4 at 20:1): no ratio may pass.
    assert_eq!(a.mos_findings.len(), 4);
    assert!(
        a.mos_findings
            .iter()
            .all(|f| f.highest_passing_ratio.is_none()),
        "{:?}",
        a.mos_findings
    );
    // DMOS = 5 − MOS: perceptual 0.6 at 20:1 fails a 0.2 limit; with a 1.0 limit 20:1 passes.
    assert!(
        a.dmos_findings
            .iter()
            .all(|f| f.highest_passing_ratio.is_none())
    );
    let loose = analyze(
        &data,
        &ReportOptions {
            dmos_limit: 1.0,
            ..options()
        },
    )
    .unwrap();
    let p22 = loose
        .dmos_findings
        .iter()
        .find(|f| f.codec == "perceptual" && f.clip == "2_2")
        .unwrap();
    assert_eq!(p22.highest_passing_ratio, Some(20.0), "{p22:?}");
    let t = a.thresholds.as_ref().unwrap();
    assert_eq!(t.per_subject.len() + t.unconverged.len(), 6);
    let (fit, ci) = a.psychometric.unwrap();
    assert!(ci.lower < fit.threshold(0.75).unwrap() && fit.threshold(0.75).unwrap() < ci.upper);
}

#[test]
fn report_writes_every_table_and_figure() {
    let data = simulated();
    let opts = options();
    let report = analyze(&data, &opts)
        .unwrap()
        .to_report(&data, &opts, "Simulated study");
    let dir = std::env::temp_dir().join(format!("analysis-report-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let written = report.write(&dir, true, files::Mode::New).unwrap();
    for name in [
        "mos",
        "mos_screened",
        "mos_zscored",
        "ttests",
        "screening",
        "repeats",
        "dmos",
        "dmos_ci",
        "thresholds",
        "jnd_thresholds",
        "jnd_notice",
        "mos_findings",
        "dmos_findings",
    ] {
        for ext in ["csv", "md", "tex"] {
            let p = dir.join("tables").join(format!("{name}.{ext}"));
            assert!(p.is_file(), "missing {}", p.display());
        }
    }
    let tex = std::fs::read_to_string(dir.join("tables/mos.tex")).unwrap();
    assert!(tex.contains("\\toprule") && tex.contains("\\midrule") && tex.contains("\\bottomrule"));
    let csv = std::fs::read_to_string(dir.join("tables/ttests.csv")).unwrap();
    assert!(csv.starts_with("Clip,CR,Method A"));
    assert!(!csv.contains("NaN"));
    for fig in [
        "mos_vs_cr",
        "score_distributions",
        "dmos_vs_cr",
        "staircases",
        "jnd",
        "psychometric",
        "mixed_forest_lmm",
        "mixed_forest_clmm",
    ] {
        let svg = std::fs::read_to_string(dir.join("figures").join(format!("{fig}.svg"))).unwrap();
        assert!(
            svg.contains("<svg") && svg.contains("<text"),
            "{fig} has no text"
        );
        let png = std::fs::read(dir.join("figures").join(format!("{fig}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        let info = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap()
            .info()
            .clone();
        // 6.5 in wide at 300 dpi; as tall as the figure's panels need (a forest plot's
        // rows: three effects here).
        assert_eq!(info.width, 1950, "{fig}");
        let least = if fig.starts_with("mixed_forest") {
            500
        } else {
            900
        };
        assert!(
            info.height > least && info.height < 2400,
            "{fig}: {}",
            info.height
        );
    }
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert_eq!(html.matches("<svg").count(), 8, "every figure inlined");
    assert!(!html.contains("<?xml"));
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("![MOS vs compression ratio](figures/mos_vs_cr.svg)"));
    assert!(written.files.len() >= 11 * 3 + 10 + 2);
    // A second report into the same folder replaces nothing unless asked to.
    std::fs::write(dir.join("report.md"), "the first report").unwrap();
    let again = report.write(&dir, false, files::Mode::New).unwrap_err();
    assert!(
        matches!(&again, analysis::AnalysisError::File(e) if e.is_refusal()),
        "{again}"
    );
    assert!(again.to_string().contains("already exists"), "{again}");
    assert_eq!(
        std::fs::read_to_string(dir.join("report.md")).unwrap(),
        "the first report"
    );
    report.write(&dir, false, files::Mode::Replace).unwrap();
    assert_eq!(std::fs::read_to_string(dir.join("report.md")).unwrap(), md);
    if std::env::var_os("ANALYSIS_KEEP_REPORT").is_none() {
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[test]
fn exports_for_pandas_and_sureal() {
    let data = simulated();
    let csv = export::tidy_csv(&data.subjects, &data.ratings, &data.conditions);
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("subject,condition,codec,clip,compression_ratio,score")
    );
    assert_eq!(lines.count(), data.ratings.len());
    let py = export::SurealDataset {
        name: "sim",
        subjects: &[],
        ratings: &data.ratings,
        dscqs: &[],
        conditions: &data.conditions,
        ref_score: 5.0,
    }
    .to_python();
    assert!(py.contains("ref_videos = [") && py.contains("dis_videos = ["));
    assert_eq!(py.matches("'asset_id'").count(), data.conditions.len());
    assert!(py.contains("'content_name': '2_2'"));
}

/// QUEST+ / Psi tracks (logged without reversals) leave the reversal table and get a Bayesian
/// fit each, beside the session's own estimate; every subject and the pool are fitted too.
#[test]
fn bayesian_tracks_get_their_own_fits() {
    let observer = PsychometricFit {
        shape: Shape::Weibull,
        alpha: 0.012,
        beta: 3.0,
        guess_rate: 0.5,
        lapse: 0.01,
        log_likelihood: 0.0,
        trials: 0,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let mut data = StudyData::default();
    for s in 0..3 {
        // A staircase's trials stand in for a Bayesian track's: the analysis only sees levels
        // and answers, and the missing reversal flags.
        let (mut track, trials) = staircase(&mut rng, &observer, s, 0.024, 0.002, 40);
        track.bayesian = true;
        track.logged_threshold = Some(0.0125);
        for step in &mut track.steps {
            step.reversal = false;
        }
        data.staircases.push(track);
        data.two_afc.extend(trials);
    }
    let a = analyze(&data, &options()).unwrap();
    assert!(
        a.thresholds.is_none(),
        "no up-down track, no reversal table"
    );
    let b = a.bayes.as_ref().unwrap();
    assert_eq!(b.per_track.len(), 3);
    for t in &b.per_track {
        assert!(t.bayesian && t.reversal_threshold.is_none());
        assert_eq!(t.logged_threshold, Some(0.0125));
        let f = t.fit.unwrap();
        assert!(f.threshold.lower < f.threshold.mean && f.threshold.mean < f.threshold.upper);
        assert!(f.threshold.mean > 0.004 && f.threshold.mean < 0.03, "{f:?}");
    }
    assert_eq!(b.per_subject.len(), 3);
    assert_eq!(b.pooled.unwrap().trials, 120);
    let report = a.to_report(&data, &options(), "QUEST+");
    let names: Vec<&str> = report.tables().map(|t| t.name.as_str()).collect();
    assert!(
        names.contains(&"adaptive_tracks") && names.contains(&"bayes_fits"),
        "{names:?}"
    );
    assert!(!names.contains(&"thresholds"), "{names:?}");
    let tracks = report
        .tables()
        .find(|t| t.name == "adaptive_tracks")
        .unwrap();
    assert!(
        tracks.rows.iter().all(|r| r[2] == "QUEST+/Psi"),
        "{:?}",
        tracks.rows
    );
}
