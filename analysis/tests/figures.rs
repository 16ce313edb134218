#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::float_cmp,
    clippy::too_many_lines,
    missing_docs,
    reason = "a test: SVG coordinates are integers, so exact comparison is the check"
)]
//! The report's figures, checked on what they draw: the SVG's panels, ticks, legend, markers
//! and lines, and the PNG's size and resolution. Set `FIGURES_OUT=<dir>` to also write every
//! figure there for looking at.

use std::collections::BTreeSet;
use std::time::Instant;

use analysis::plots::{
    CORRECT, FRAME, Figure, LEGEND_FRAME, MAX_STAIRCASE_PANELS, PALETTE, PNG_DPI, RateSeries,
    THRESHOLD, WRONG, series_style,
};
use analysis::psychometric::{BootstrapOptions, FitOptions, Lapse, PsychometricFit, Shape};
use analysis::report::Block;
use analysis::study::{ReportOptions, StudyData, analyze};
use analysis::synthetic::{MosStudySpec, mos_study, staircase};
use analysis::{DscqsPair, StaircaseTrack};
use plotters::style::RGBColor;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A tag of the SVG: its name, attributes and (for `<text>`) its content.
#[derive(Debug)]
struct Tag {
    name: String,
    attrs: Vec<(String, String)>,
    text: String,
}

impl Tag {
    fn get(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
    fn num(&self, key: &str) -> f64 {
        self.get(key).unwrap().parse().unwrap()
    }
}

fn tags(svg: &str) -> Vec<Tag> {
    let mut out = Vec::new();
    for chunk in svg.split('<').skip(1) {
        if chunk.starts_with('/') || chunk.starts_with('?') || chunk.starts_with('!') {
            continue;
        }
        let (head, rest) = chunk.split_once('>').unwrap_or((chunk, ""));
        let mut parts = head.trim_end_matches('/').splitn(2, ' ');
        let name = parts.next().unwrap_or_default().to_owned();
        let mut attrs = Vec::new();
        let mut s = parts.next().unwrap_or_default();
        while let Some((k, v)) = s.split_once("=\"") {
            let (value, after) = v.split_once('"').unwrap();
            attrs.push((k.trim().to_owned(), value.to_owned()));
            s = after;
        }
        out.push(Tag {
            name,
            attrs,
            text: rest.trim().to_owned(),
        });
    }
    out
}

fn hex(c: RGBColor) -> String {
    format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
}

/// (left, top, right, bottom) of the rects stroked in `color`.
fn framed(tags: &[Tag], color: RGBColor) -> Vec<(f64, f64, f64, f64)> {
    tags.iter()
        .filter(|t| t.name == "rect" && t.get("stroke") == Some(&hex(color)))
        .map(|t| {
            let (x, y) = (t.num("x"), t.num("y"));
            (x, y, x + t.num("width"), y + t.num("height"))
        })
        .collect()
}

fn texts(tags: &[Tag]) -> Vec<&Tag> {
    tags.iter().filter(|t| t.name == "text").collect()
}

fn simulated() -> StudyData {
    let spec = MosStudySpec {
        subjects: 12,
        erratic_subjects: 0,
        showings: 2,
        codecs: vec![
            ("perceptual".to_owned(), 0.6),
            ("wavelet".to_owned(), 0.9),
            ("pca".to_owned(), 1.2),
        ],
        ..MosStudySpec::default()
    };
    let mut data = mos_study(&spec);
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
    for s in 0..5 {
        let (track, trials) = staircase(&mut rng, &observer, s, 0.024, 0.002, 40);
        data.staircases.push(track);
        data.two_afc.extend(trials);
    }
    data
}

fn options() -> ReportOptions {
    ReportOptions {
        fit: FitOptions {
            lapse: Lapse::Free { max: 0.06 },
            ..FitOptions::default()
        },
        bootstrap: BootstrapOptions {
            replicates: 200,
            ..BootstrapOptions::default()
        },
        scale: Some((1.0, 5.0)),
        ..ReportOptions::default()
    }
}

/// Every figure of the simulated study's report, by name.
fn figures(data: &StudyData, options: &ReportOptions) -> Vec<(String, Figure)> {
    let report = analyze(data, options)
        .unwrap()
        .to_report(data, options, "Figures");
    report
        .sections
        .into_iter()
        .flat_map(|s| s.blocks)
        .filter_map(|b| match b {
            Block::Figure { name, figure } => Some((name, figure)),
            _ => None,
        })
        .collect()
}

fn figure(name: &str) -> Figure {
    figures(&simulated(), &options())
        .into_iter()
        .find(|f| f.0 == name)
        .unwrap()
        .1
}

fn overlaps(a: (f64, f64, f64, f64), b: (f64, f64, f64, f64)) -> bool {
    a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3
}

#[test]
fn rate_curves_are_small_multiples_on_the_scale() {
    let data = simulated();
    let fig = figure("mos_vs_cr");
    let Figure::RateCurves { series, .. } = &fig else {
        panic!("{fig:?}")
    };
    let clips: BTreeSet<&str> = series.iter().map(|s| s.clip.as_str()).collect();
    let methods: BTreeSet<&str> = series.iter().map(|s| s.label.as_str()).collect();
    assert_eq!(clips.len(), 2);
    assert_eq!(methods.len(), 3, "labels are the methods: {methods:?}");
    let svg = fig.render_svg().unwrap();
    let tags = tags(&svg);
    // One panel per clip, titled by it.
    let panels = framed(&tags, FRAME);
    assert_eq!(panels.len(), clips.len(), "{panels:?}");
    for clip in &clips {
        assert!(
            texts(&tags)
                .iter()
                .any(|t| t.text == format!("clip {clip}")),
            "{clip}"
        );
    }
    // Shared y axis: all panels span the same rows.
    assert!(
        panels
            .iter()
            .all(|p| p.1 == panels[0].1 && p.3 == panels[0].3)
    );
    // Tick labels: integers without ".0"; the tested ratios on x; the scale's ends on y, at
    // the frame's top and bottom.
    let numbers: Vec<&Tag> = texts(&tags)
        .into_iter()
        .filter(|t| t.text.parse::<f64>().is_ok())
        .collect();
    assert!(numbers.iter().all(|t| !t.text.contains('.')), "{numbers:?}");
    let ratios: BTreeSet<String> = data
        .conditions
        .iter()
        .filter_map(|c| c.compression_ratio)
        .map(|r| format!("{r:.0}"))
        .collect();
    for r in &ratios {
        assert!(numbers.iter().any(|t| &t.text == r), "no tick {r}");
    }
    let label_y = |s: &str| {
        numbers
            .iter()
            .filter(|t| t.text == s && t.get("text-anchor") == Some("end"))
            .map(|t| t.num("y"))
            .next()
            .unwrap_or_else(|| panic!("no y tick {s}"))
    };
    assert!((label_y("5") - panels[0].1).abs() <= 1.0);
    assert!((label_y("1") - panels[0].3).abs() <= 1.0);
    for v in ["2", "3", "4"] {
        let y = label_y(v);
        assert!(y > panels[0].1 && y < panels[0].3);
    }
    // The legend is outside every panel and names the methods and the limit.
    let legend = framed(&tags, LEGEND_FRAME);
    assert_eq!(legend.len(), 1);
    assert!(panels.iter().all(|p| !overlaps(*p, legend[0])));
    for m in &methods {
        assert!(texts(&tags).iter().any(|t| t.text == *m), "{m}");
    }
    assert!(texts(&tags).iter().any(|t| t.text == "limit 4.5"));
    // Each method has its own palette colour; the series' marks use no other colour.
    let palette: Vec<String> = PALETTE.iter().map(|c| hex(*c)).collect();
    let used: BTreeSet<String> = tags
        .iter()
        .filter(|t| t.name == "polygon" || (t.name == "circle" && t.get("fill") != Some("none")))
        .filter_map(|t| t.get("fill").map(str::to_owned))
        .filter(|f| f != "#FFFFFF")
        .collect();
    let expected: BTreeSet<String> = (0..methods.len())
        .map(|k| palette[series_style(k).color].clone())
        .collect();
    assert_eq!(used, expected);
    let triples: BTreeSet<_> = (0..methods.len()).map(series_style).collect();
    assert_eq!(triples.len(), methods.len());
    // Markers differ by shape: method 0 draws circles, method 1 squares (4-point polygons),
    // method 2 triangles; with 2 clips × 5 ratios each, plus the legend's.
    let count = |name: &str, colour: &str, points: Option<usize>| {
        tags.iter()
            .filter(|t| t.name == name && t.get("fill") == Some(colour))
            .filter(|t| {
                points.is_none_or(|n| t.get("points").unwrap().split_whitespace().count() == n)
            })
            .count()
    };
    let per_method = series
        .iter()
        .filter(|s| s.label == "pca")
        .map(|s| s.points.len())
        .sum::<usize>()
        + 1;
    let style = |name: &str| {
        let k = methods.iter().position(|m| *m == name).unwrap();
        palette[series_style(k).color].clone()
    };
    assert_eq!(count("circle", &style("pca"), None), per_method);
    assert_eq!(count("polygon", &style("perceptual"), Some(4)), per_method);
    assert_eq!(count("polygon", &style("wavelet"), Some(3)), per_method);
    // Error bars have caps: per point a vertical bar and two horizontal caps.
    let bars = tags
        .iter()
        .filter(|t| t.name == "polyline" && t.get("stroke") == Some(style("pca").as_str()))
        .filter(|t| {
            let p: Vec<&str> = t.get("points").unwrap().split_whitespace().collect();
            p.len() == 2 && {
                let a: Vec<f64> = p[0].split(',').map(|v| v.parse().unwrap()).collect();
                let b: Vec<f64> = p[1].split(',').map(|v| v.parse().unwrap()).collect();
                a[1] == b[1] && (b[0] - a[0]).abs() == 6.0
            }
        })
        .count();
    assert_eq!(bars, 2 * (per_method - 1), "caps");
}

#[test]
fn dmos_axis_runs_from_zero_to_the_scale_range() {
    let fig = figure("dmos_vs_cr");
    let Figure::RateCurves { y_range, .. } = &fig else {
        panic!()
    };
    assert_eq!(*y_range, Some((0.0, 4.0)));
    let svg = fig.render_svg().unwrap();
    let tags = tags(&svg);
    let labels: Vec<&str> = texts(&tags)
        .into_iter()
        .filter(|t| t.get("text-anchor") == Some("end"))
        .map(|t| t.text.as_str())
        .collect();
    assert!(labels.contains(&"0") && labels.contains(&"4"), "{labels:?}");
}

#[test]
fn png_is_the_print_size_at_300_dpi() {
    for (name, fig) in figures(&simulated(), &options()) {
        let start = Instant::now();
        let png = fig.render_png().unwrap();
        let elapsed = start.elapsed();
        let decoder = png::Decoder::new(std::io::Cursor::new(&png));
        let reader = decoder.read_info().unwrap();
        let info = reader.info();
        let (w_in, h_in) = fig.size_in();
        assert_eq!(info.width, (w_in * PNG_DPI).round() as u32, "{name}");
        assert_eq!(info.width, 1950, "{name}: 6.5 in at 300 dpi");
        assert_eq!(info.height, (h_in * PNG_DPI).round() as u32, "{name}");
        let dims = info.pixel_dims.unwrap();
        assert_eq!((dims.xppu, dims.unit), (11811, png::Unit::Meter), "{name}");
        // The SVG is the same figure at 100 units per inch.
        let start = Instant::now();
        let svg = fig.render_svg().unwrap();
        let svg_time = start.elapsed();
        let root = &tags(&svg)[0];
        assert_eq!(root.num("width"), 650.0);
        assert_eq!(root.num("height"), (h_in * 100.0).round());
        eprintln!(
            "{name}: {}x{} px in {elapsed:?}, SVG in {svg_time:?}",
            info.width, info.height
        );
        if let Ok(dir) = std::env::var("FIGURES_OUT") {
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(format!("{dir}/{name}.png"), &png).unwrap();
            std::fs::write(format!("{dir}/{name}.svg"), &svg).unwrap();
            // The figure's data, for scripts/compare/figures_matplotlib.py.
            std::fs::write(
                format!("{dir}/{name}.json"),
                serde_json::to_string_pretty(&fig).unwrap(),
            )
            .unwrap();
        }
    }
}

#[test]
fn staircases_mark_every_answer_reversal_and_threshold() {
    let fig = figure("staircases");
    let Figure::Staircases {
        tracks,
        last_reversals,
        ..
    } = &fig
    else {
        panic!()
    };
    let svg = fig.render_svg().unwrap();
    let tags = tags(&svg);
    assert_eq!(framed(&tags, FRAME).len(), tracks.len());
    let circles = |fill: &str, stroke: &str| {
        tags.iter()
            .filter(|t| {
                t.name == "circle" && t.get("fill") == Some(fill) && t.get("stroke") == Some(stroke)
            })
            .count()
    };
    let steps = tracks.iter().flat_map(|t| t.steps.iter());
    let correct = steps.clone().filter(|s| s.correct).count();
    let wrong = steps.clone().filter(|s| !s.correct).count();
    let reversals = steps.filter(|s| s.reversal).count();
    assert!(correct > 0 && wrong > 0 && reversals > 0);
    // Each plus the legend's sample.
    assert_eq!(circles(&hex(CORRECT), "none"), correct + 1);
    assert_eq!(circles("none", &hex(WRONG)), wrong + 1);
    assert_eq!(circles("none", "#222222"), reversals + 1);
    let converged = tracks
        .iter()
        .filter(|t| t.threshold(*last_reversals).is_some())
        .count();
    assert!(converged > 0);
    let threshold_lines = tags
        .iter()
        .filter(|t| t.name == "polyline" && t.get("stroke") == Some(hex(THRESHOLD).as_str()))
        .count();
    assert_eq!(threshold_lines, converged + 1);
    // Steps: the level is held until the next trial, so the path has 2n − 1 vertices.
    let grey_paths: Vec<usize> = tags
        .iter()
        .filter(|t| t.name == "polyline" && t.get("stroke") == Some("#595959"))
        .map(|t| t.get("points").unwrap().split_whitespace().count())
        .collect();
    for t in tracks {
        assert!(
            grey_paths.contains(&(2 * t.steps.len() - 1)),
            "{grey_paths:?}"
        );
    }
    let legend = framed(&tags, LEGEND_FRAME);
    assert_eq!(legend.len(), 1);
    assert!(
        framed(&tags, FRAME)
            .iter()
            .all(|p| !overlaps(*p, legend[0]))
    );
}

#[test]
fn many_staircases_show_twelve_panels_and_say_so() {
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
    let tracks: Vec<StaircaseTrack> = (0..15)
        .map(|s| staircase(&mut rng, &observer, s, 0.024, 0.002, 30).0)
        .collect();
    let fig = Figure::Staircases {
        title: "Staircase tracks".to_owned(),
        level_label: "t_L".to_owned(),
        tracks,
        last_reversals: 3,
        subjects: Vec::new(),
    };
    let svg = fig.render_svg().unwrap();
    let tags = tags(&svg);
    assert_eq!(framed(&tags, FRAME).len(), MAX_STAIRCASE_PANELS);
    assert!(
        texts(&tags)
            .iter()
            .any(|t| t.text.starts_with("First 12 of 15 staircases shown")),
    );
}

#[test]
fn psychometric_draws_its_band_around_the_fit() {
    let fig = figure("psychometric");
    let Figure::Psychometric {
        band, fit, data, ..
    } = &fig
    else {
        panic!()
    };
    let band = band.as_ref().expect("the report computes the band");
    assert!(band.points.len() > 20);
    for &(x, lo, hi) in &band.points {
        let p = fit.probability(x);
        assert!(lo <= p + 1e-3 && p <= hi + 1e-3, "{x}: {lo} {p} {hi}");
    }
    // The band has a width.
    let widths: Vec<f64> = band.points.iter().map(|p| p.2 - p.1).collect();
    assert!(widths.iter().copied().fold(0.0, f64::max) > 0.02);
    let svg = fig.render_svg().unwrap();
    let tags = tags(&svg);
    let bands = tags
        .iter()
        .filter(|t| t.name == "polygon" && t.get("fill") == Some(hex(PALETTE[0]).as_str()))
        .count();
    assert_eq!(bands, 1);
    // One dot per level tried (area ∝ trials) plus the legend's.
    let dots = tags
        .iter()
        .filter(|t| t.name == "circle" && t.get("fill") == Some(hex(PALETTE[1]).as_str()))
        .count();
    assert_eq!(dots, data.levels.iter().filter(|l| l.1 > 0).count() + 1);
    assert!(
        texts(&tags)
            .iter()
            .any(|t| t.text.contains("pointwise bootstrap band"))
    );
    let legend = framed(&tags, LEGEND_FRAME);
    assert!(
        framed(&tags, FRAME)
            .iter()
            .all(|p| !overlaps(*p, legend[0]))
    );
}

#[test]
fn one_clip_draws_one_panel_and_many_methods_stay_distinct() {
    let series: Vec<RateSeries> = (0..9)
        .map(|k| RateSeries {
            label: format!("method-{k}"),
            clip: "walk".to_owned(),
            points: vec![
                (10.0, 4.0 - 0.1 * k as f64, 3.8, 4.2),
                (20.0, 3.0, 2.7, 3.3),
            ],
        })
        .collect();
    let fig = Figure::RateCurves {
        title: "t".to_owned(),
        y_label: "MOS".to_owned(),
        series,
        limit: None,
        y_range: Some((0.0, 100.0)),
    };
    let svg = fig.render_svg().unwrap();
    let tags = tags(&svg);
    assert_eq!(framed(&tags, FRAME).len(), 1);
    let y: Vec<&str> = texts(&tags)
        .into_iter()
        .filter(|t| t.get("text-anchor") == Some("end"))
        .map(|t| t.text.as_str())
        .collect();
    assert_eq!(y, ["0", "20", "40", "60", "80", "100"]);
    let triples: BTreeSet<_> = (0..9).map(series_style).collect();
    assert_eq!(triples.len(), 9);
}
