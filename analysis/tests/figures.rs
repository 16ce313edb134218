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
    // The scale's ends are the ends of the axis, a marker's size inside the frame (issue
    // 39: a point at 5 was cut in half by the frame).
    assert!((label_y("5") - panels[0].1 - 6.0).abs() <= 1.0);
    assert!((panels[0].3 - label_y("1") - 6.0).abs() <= 1.0);
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

/// A MOS figure on a 1-5 scale whose points reach the scale's top: a mean of 5 (every rating
/// 5) and a mean of 4.8 whose t interval runs past 5.
fn mos_at_the_top() -> Figure {
    Figure::RateCurves {
        title: "MOS vs compression ratio".to_owned(),
        y_label: "MOS".to_owned(),
        series: ["perceptual", "wavelet", "pca"]
            .iter()
            .enumerate()
            .map(|(k, m)| RateSeries {
                label: (*m).to_owned(),
                clip: "walk".to_owned(),
                points: vec![
                    (10.0, 5.0, 5.0, 5.0),
                    (20.0, 4.8, 4.3, 5.3),
                    (40.0, 1.0 + 0.1 * k as f64, 1.0, 1.4),
                ],
            })
            .collect(),
        limit: Some(4.5),
        y_range: Some((1.0, 5.0)),
    }
}

/// Issue 39: the MOS axis ran to 6 on a 1-5 scale (widened for a CI past the top). The top
/// y tick is the scale's maximum, in the figure of a simulated study too, and the CI that
/// runs past it is cut at the frame without a cap.
#[test]
fn the_mos_axis_never_passes_the_scale() {
    for (name, fig) in [
        ("constructed", mos_at_the_top()),
        ("simulated", figure("mos_vs_cr")),
    ] {
        let svg = fig.render_svg().unwrap();
        let tags = tags(&svg);
        let y: Vec<f64> = texts(&tags)
            .into_iter()
            .filter(|t| t.get("text-anchor") == Some("end"))
            .filter_map(|t| t.text.parse().ok())
            .collect();
        assert!(!y.is_empty(), "{name}: no y ticks");
        let top = y.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let bottom = y.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(top <= 5.0, "{name}: y ticks {y:?} pass the scale's 5");
        assert!(bottom >= 1.0, "{name}: y ticks {y:?} pass the scale's 1");
        assert_eq!(
            (bottom, top),
            (1.0, 5.0),
            "{name}: the scale's ends are ticks"
        );
    }
}

/// The points of a figure: its circles and polygons filled in palette colours (markers, not
/// the legend's, which lie below `below`), as (left, top, right, bottom) boxes.
fn markers(tags: &[Tag], below: f64) -> Vec<(f64, f64, f64, f64)> {
    let palette: Vec<String> = PALETTE.iter().map(|c| hex(*c)).collect();
    tags.iter()
        .filter(|t| {
            (t.name == "circle" || t.name == "polygon")
                && t.get("fill")
                    .is_some_and(|f| palette.iter().any(|p| p == f))
        })
        .map(|t| {
            if t.name == "circle" {
                let (x, y, r) = (t.num("cx"), t.num("cy"), t.num("r"));
                (x - r, y - r, x + r, y + r)
            } else {
                let pts: Vec<(f64, f64)> = t
                    .get("points")
                    .unwrap()
                    .split_whitespace()
                    .map(|p| {
                        let (x, y) = p.split_once(',').unwrap();
                        (x.parse().unwrap(), y.parse().unwrap())
                    })
                    .collect();
                pts.iter().fold(
                    (
                        f64::INFINITY,
                        f64::INFINITY,
                        f64::NEG_INFINITY,
                        f64::NEG_INFINITY,
                    ),
                    |b, p| (b.0.min(p.0), b.1.min(p.1), b.2.max(p.0), b.3.max(p.1)),
                )
            }
        })
        .filter(|b| b.3 < below)
        .collect()
}

/// Issue 39: points at the edge of the plot were cut in half by the frame. Every marker of a
/// MOS figure with means at the scale's top and bottom, and every dot of the score
/// distributions (ratings of 1 and 5), lies wholly inside its panel's frame.
#[test]
fn markers_at_the_scale_s_ends_lie_inside_the_frame() {
    let distributions = Figure::ScoreDistributions {
        title: "Scores per subject".to_owned(),
        per_subject: vec![
            ("S1".to_owned(), vec![5.0; 8]),
            ("S2".to_owned(), vec![1.0, 1.0, 5.0, 3.0]),
        ],
        y_range: Some((1.0, 5.0)),
    };
    for (name, fig, expected) in [
        ("mos", mos_at_the_top(), 9),
        ("distributions", distributions, 4),
    ] {
        let svg = fig.render_svg().unwrap();
        let tags = tags(&svg);
        let frames = framed(&tags, FRAME);
        assert_eq!(frames.len(), 1, "{name}: one panel");
        let frame = frames[0];
        let inside: Vec<_> = markers(&tags, frame.3 + 2.0);
        assert_eq!(inside.len(), expected, "{name}: {inside:?}");
        // A 5 is at the top of the frame, a 1 at its bottom: drawn whole inside it.
        let top = inside.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
        let bottom = inside.iter().map(|m| m.3).fold(f64::NEG_INFINITY, f64::max);
        assert!(
            top - frame.1 < 12.0 && frame.3 - bottom < 12.0,
            "{name}: {inside:?}"
        );
        for m in &inside {
            assert!(
                m.0 >= frame.0 && m.1 >= frame.1 && m.2 <= frame.2 && m.3 <= frame.3,
                "{name}: marker {m:?} crosses the frame {frame:?}"
            );
        }
    }
}

/// Issue 39: the HTML report shrank figures until tick labels were 5-7 px. In `report.html`
/// every figure is shown at the layout width its style gives (the body's `max-width`), and
/// no narrower than the figure's `min-width`: its text's displayed size (font size × shown
/// width / viewBox width) is at least 10 px at the layout width, and its tick labels stay at
/// 10 px or more at the narrowest.
#[test]
fn html_figures_keep_tick_labels_at_10_px() {
    let mut report = analysis::report::Report::new("Figures");
    for (name, fig) in figures(&simulated(), &options()) {
        report.section(&name).figure(name.clone(), fig);
    }
    let dir = std::env::temp_dir().join(format!("figures-html-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    report.write(&dir, false, files::Mode::New).unwrap();
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let style = html
        .split_once("<style>")
        .and_then(|(_, s)| s.split_once("</style>"))
        .unwrap()
        .0;
    let rule = |selector: &str| -> &str {
        style
            .split('}')
            .find_map(|r| r.strip_prefix(selector).and_then(|r| r.strip_prefix('{')))
            .unwrap_or_else(|| panic!("no rule for {selector} in {style}"))
    };
    let px = |rule: &str, property: &str| -> f64 {
        rule.split(';')
            .find_map(|d| d.strip_prefix(&format!("{property}:")))
            .and_then(|v| v.strip_suffix("px"))
            .unwrap_or_else(|| panic!("no {property} in px in {rule}"))
            .parse()
            .unwrap()
    };
    let layout = px(rule("body"), "max-width");
    let figure_rule = rule("figure svg");
    assert!(figure_rule.contains("width:100%"), "{figure_rule}");
    let narrowest = px(figure_rule, "min-width");
    // The figure takes the body's whole width: no side margins.
    assert!(rule("figure").contains("margin:1em 0"), "{style}");
    let svgs: Vec<&str> = html.split("<svg").skip(1).collect();
    assert!(svgs.len() >= 6, "{} figures", svgs.len());
    for svg in svgs {
        let svg = svg.split("</svg>").next().unwrap();
        let tags = tags(&format!("<svg{svg}"));
        let view_box: Vec<f64> = tags[0]
            .get("viewBox")
            .unwrap()
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        let units = view_box[2];
        let sizes: Vec<(f64, bool)> = texts(&tags)
            .iter()
            .map(|t| {
                let size: f64 = t.get("font-size").unwrap().parse().unwrap();
                // Numbers right of a y axis or centred under an x axis (a forest plot has
                // only the latter; its row names are drawn at the same size).
                let tick = matches!(t.get("text-anchor"), Some("end" | "middle"))
                    && t.text.parse::<f64>().is_ok();
                (size, tick)
            })
            .collect();
        assert!(sizes.iter().any(|s| s.1), "no tick labels");
        for (size, tick) in sizes {
            let shown = size * layout / units;
            assert!(shown >= 10.0, "text of {size} units shown at {shown:.1} px");
            if tick {
                let least = size * narrowest / units;
                assert!(
                    least >= 10.0,
                    "tick label shown at {least:.1} px at the narrowest"
                );
            }
        }
    }
}

fn forest(rows: &[(&str, f64, f64, f64)]) -> Figure {
    Figure::Forest {
        title: "Fixed effects".to_owned(),
        x_label: "Effect on the score".to_owned(),
        rows: rows
            .iter()
            .map(|&(n, e, l, u)| (n.to_owned(), e, l, u))
            .collect(),
    }
}

/// A polyline's points.
fn points(t: &Tag) -> Vec<(f64, f64)> {
    t.get("points")
        .unwrap()
        .split_whitespace()
        .map(|p| {
            let (x, y) = p.split_once(',').unwrap();
            (x.parse().unwrap(), y.parse().unwrap())
        })
        .collect()
}

/// The polylines' point lists.
fn polylines(tags: &[Tag]) -> Vec<Vec<(f64, f64)>> {
    tags.iter()
        .filter(|t| t.name == "polyline")
        .map(points)
        .collect()
}

/// The forest plot of the mixed models: each estimate's dot and its CI whisker's ends at
/// their values on the x axis (read from the tick labels' positions), the zero line across
/// the frame, every effect name drawn whole inside the figure, and a row without a finite CI
/// drawn with its dot only.
#[test]
fn forest_rows_sit_at_their_values() {
    let rows = [
        ("methodwavelet", 0.42, 0.1, 0.74),
        ("ratio16", -0.8, -1.25, -0.35),
        (
            "methodwavelet-long-variant-name:ratio16 (interaction)",
            0.05,
            -0.3,
            0.4,
        ),
        ("methodpca", 1.1, f64::NEG_INFINITY, f64::NAN),
        ("ratio8", 0.2, 0.0, f64::INFINITY),
        ("ratio32", f64::NAN, f64::NAN, f64::NAN),
    ];
    let fig = forest(&rows);
    let svg = fig.render_svg().unwrap();
    fig.render_png().unwrap();
    let tags = tags(&svg);
    let frames = framed(&tags, FRAME);
    assert_eq!(frames.len(), 1, "{frames:?}");
    let (l, t, r, b) = frames[0];
    // The x axis: tick labels under the frame, centred on their ticks.
    let ticks: Vec<(f64, f64)> = texts(&tags)
        .into_iter()
        .filter(|tag| tag.get("text-anchor") == Some("middle") && tag.num("y") > b)
        .filter_map(|tag| Some((tag.text.parse::<f64>().ok()?, tag.num("x"))))
        .collect();
    assert!(ticks.len() >= 3, "{ticks:?}");
    let tick_size = texts(&tags)
        .into_iter()
        .find(|tag| tag.get("text-anchor") == Some("middle") && tag.num("y") > b)
        .and_then(|tag| tag.get("font-size"));
    let (v0, x0) = ticks[0];
    let (v1, x1) = ticks[ticks.len() - 1];
    let at = |v: f64| x0 + (v - v0) * (x1 - x0) / (v1 - v0);
    for &(v, x) in &ticks {
        assert!((at(v) - x).abs() <= 1.0, "tick {v} at {x}, not {}", at(v));
    }
    let lines = polylines(&tags);
    for &(v, x) in &ticks {
        assert!(
            lines
                .iter()
                .any(|p| p.len() == 2 && p[0] == (x, b) && p[1].0 == x && p[1].1 > b),
            "no tick mark under the label {v}"
        );
    }
    // The zero line: vertical, across the whole frame, at 0.
    assert!(
        lines.iter().any(|p| p.len() == 2
            && p[0].0 == p[1].0
            && (p[0].0 - at(0.0)).abs() <= 1.0
            && p[0].1.min(p[1].1) == t
            && p[0].1.max(p[1].1) == b),
        "no zero line at {}",
        at(0.0)
    );
    let dots: Vec<(f64, f64)> = tags
        .iter()
        .filter(|tag| tag.name == "circle" && tag.get("fill") == Some(&hex(PALETTE[0])))
        .map(|tag| (tag.num("cx"), tag.num("cy")))
        .collect();
    assert_eq!(dots.len(), 5, "one dot per finite estimate: {dots:?}");
    assert!(
        dots.iter().all(|d| d.0 > l && d.0 < r),
        "{dots:?} outside the frame"
    );
    // Whiskers: horizontal lines in the dots' colour.
    let horizontal: Vec<Vec<(f64, f64)>> = tags
        .iter()
        .filter(|tag| tag.name == "polyline" && tag.get("stroke") == Some(&hex(PALETTE[0])))
        .map(points)
        .filter(|p| p.len() == 2 && p[0].1 == p[1].1)
        .collect();
    assert_eq!(
        horizontal.len(),
        3,
        "one whisker per finite CI: {horizontal:?}"
    );
    let font = plotters::style::IntoFont::into_font(("sans-serif", 9.0));
    let mut previous = f64::NEG_INFINITY;
    for (i, &(name, estimate, lower, upper)) in rows.iter().enumerate() {
        // The name, whole, in one label right of the figure's edge and left of the frame.
        let label = texts(&tags)
            .into_iter()
            .find(|tag| tag.text == name)
            .unwrap_or_else(|| panic!("no label {name:?}"));
        assert_eq!(label.get("text-anchor"), Some("end"), "{name}");
        // As large as the axis' tick labels (which the HTML report keeps at 10 px or more).
        assert_eq!(label.get("font-size"), tick_size, "{name}");
        let width = f64::from(font.box_size(name).unwrap().0);
        assert!(label.num("x") < l, "{name} overlaps the frame");
        assert!(
            label.num("x") - width >= 0.0,
            "{name} is cut off at the left"
        );
        // Rows run top to bottom in the given order.
        let y = label.num("y");
        assert!(y > previous && y > t && y < b, "{name} at y {y}");
        previous = y;
        let dot = dots.iter().find(|d| (d.1 - y).abs() <= 6.0);
        if estimate.is_finite() {
            let dot = dot.unwrap_or_else(|| panic!("no dot for {name}"));
            assert!(
                (dot.0 - at(estimate)).abs() <= 1.0,
                "{name}: dot at {}",
                dot.0
            );
        } else {
            assert!(dot.is_none(), "{name}: a dot without an estimate");
        }
        let whisker = horizontal.iter().find(|p| (p[0].1 - y).abs() <= 6.0);
        if lower.is_finite() && upper.is_finite() {
            let w = whisker.unwrap_or_else(|| panic!("no whisker for {name}"));
            let (a, z) = (w[0].0.min(w[1].0), w[0].0.max(w[1].0));
            assert!((a - at(lower)).abs() <= 1.0, "{name}: whisker from {a}");
            assert!((z - at(upper)).abs() <= 1.0, "{name}: whisker to {z}");
            assert_eq!(
                w[0].1,
                dots.iter().find(|d| (d.1 - y).abs() <= 6.0).unwrap().1
            );
        } else {
            assert!(
                whisker.is_none(),
                "{name}: a whisker without a finite CI (row {i})"
            );
        }
    }
}

/// A name wider than the label column wraps onto lines that, joined, are the name, each
/// inside the figure and left of the frame; the figure grows with the rows.
#[test]
fn forest_wraps_long_names_whole() {
    let long = "methodperceptual-codec-with-a-very-long-variant-description:ratio32 against the baseline of every other method and ratio in the study, spelled out";
    let fig = forest(&[(long, 0.3, 0.1, 0.5), ("ratio8", -0.2, -0.4, 0.0)]);
    let short = forest(&[("a", 0.3, 0.1, 0.5), ("ratio8", -0.2, -0.4, 0.0)]);
    assert!(fig.size_in().1 > short.size_in().1);
    let svg = fig.render_svg().unwrap();
    let tags = tags(&svg);
    let (l, ..) = framed(&tags, FRAME)[0];
    let font = plotters::style::IntoFont::into_font(("sans-serif", 9.0));
    let lines: Vec<&Tag> = texts(&tags)
        .into_iter()
        .filter(|tag| tag.get("text-anchor") == Some("end") && tag.num("x") < l)
        .filter(|tag| tag.text != "ratio8")
        .collect();
    assert!(lines.len() >= 2, "not wrapped");
    // The SVG's lines, joined, are the name (the spaces at the breaks are not drawn).
    let joined: String = lines.iter().map(|tag| tag.text.as_str()).collect();
    let bare = |s: &str| s.split_whitespace().collect::<String>();
    assert_eq!(bare(&joined), bare(long));
    for tag in lines {
        let width = f64::from(font.box_size(&tag.text).unwrap().0);
        assert!(tag.num("x") - width >= 0.0, "{:?} cut off", tag.text);
    }
}

/// The report draws the two models' forest plots apart: the linear model's effects on the
/// score scale, the ordinal model's in log odds, never on one axis.
#[test]
fn mixed_models_draw_one_forest_plot_each() {
    let figs = figures(&simulated(), &options());
    for name in ["mixed_forest_lmm", "mixed_forest_clmm"] {
        let fig = figs
            .iter()
            .find(|f| f.0 == name)
            .unwrap_or_else(|| panic!("no {name}"));
        let Figure::Forest { rows, .. } = &fig.1 else {
            panic!("{name} is not a forest plot");
        };
        assert!(!rows.is_empty(), "{name}");
        assert!(
            rows.iter()
                .all(|r| !r.0.starts_with("clmm") && r.0 != "(Intercept)")
        );
    }
}
