//! Figures drawn with `plotters` to SVG (for report.html, inlined) and PNG.
//!
//! Text needs a font: `plotters` is built without its system-font (`ttf`/font-kit) backend and
//! with `ab_glyph`, and this module registers DejaVu Sans from the `dejavu` crate (embedded in
//! the binary) as the `sans-serif` family, so PNG labels render on a bare machine with no fonts
//! installed and SVG layout uses real glyph metrics.

use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;

use crate::error::AnalysisError;
use crate::psychometric::{GroupedTrials, PsychometricFit};
use crate::staircase::StaircaseTrack;

/// Size of every figure in pixels.
const SIZE_PX: (u32, u32) = (800, 520);
const FONT: &str = "sans-serif";

/// Registers the embedded font once; the result is shared by all later calls.
fn ensure_font() -> Result<(), AnalysisError> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            for family in ["sans-serif", "serif", "monospace"] {
                plotters::style::register_font(family, FontStyle::Normal, dejavu::sans::regular())
                    .map_err(|_| "embedded DejaVu Sans did not parse".to_owned())?;
                plotters::style::register_font(family, FontStyle::Bold, dejavu::sans::bold())
                    .map_err(|_| "embedded DejaVu Sans Bold did not parse".to_owned())?;
            }
            Ok(())
        })
        .clone()
        .map_err(|message| AnalysisError::Plot {
            name: "font".to_owned(),
            message,
        })
}

/// One curve of a rate plot: (compression ratio, mean, CI lower, CI upper) points.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RateSeries {
    /// Legend label (codec, clip).
    pub label: String,
    /// (x, y, lower, upper); lower/upper equal y when the CI is undefined.
    pub points: Vec<(f64, f64, f64, f64)>,
}

/// A figure, kept as data so it can be drawn to any backend.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub enum Figure {
    /// MOS or DMOS against compression ratio with CI error bars, one curve per codec × clip.
    RateCurves {
        /// Title.
        title: String,
        /// Y axis label ("MOS" or "DMOS").
        y_label: String,
        /// The curves.
        series: Vec<RateSeries>,
        /// A horizontal limit line (4.5 MOS, 0.2 DMOS), if any.
        limit: Option<f64>,
    },
    /// Staircase tracks per subject with reversals marked.
    Staircases {
        /// Title.
        title: String,
        /// Y axis label (the level's name and unit).
        level_label: String,
        /// The tracks.
        tracks: Vec<StaircaseTrack>,
    },
    /// Proportion correct per level with the fitted psychometric function.
    Psychometric {
        /// Title.
        title: String,
        /// X axis label.
        level_label: String,
        /// The data.
        data: GroupedTrials,
        /// The fit.
        fit: PsychometricFit,
        /// (percent correct, threshold, CI lower, CI upper), if computed.
        threshold: Option<(f64, f64, f64, f64)>,
    },
    /// Distribution of staircase thresholds over viewers: the empirical share who notice a
    /// level (step function of the sorted thresholds, each threshold marked) and the normal
    /// model's share with its confidence band.
    Jnd {
        /// Title.
        title: String,
        /// X axis label (the level's name).
        level_label: String,
        /// Per-viewer thresholds.
        thresholds: Vec<f64>,
        /// (level, modelled share noticing, CI lower, CI upper).
        model: Vec<(f64, f64, f64, f64)>,
    },
    /// Per-subject score distributions: one column per subject, dot area ∝ count.
    ScoreDistributions {
        /// Title.
        title: String,
        /// (subject id, scores).
        per_subject: Vec<(String, Vec<f64>)>,
    },
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

fn padded(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = (hi - lo).abs().max(1e-9 * lo.abs().max(1.0));
    (lo - 0.08 * span, hi + 0.08 * span)
}

fn color(i: usize) -> RGBAColor {
    Palette99::pick(i).to_rgba()
}

impl Figure {
    /// The figure's title.
    pub fn title(&self) -> &str {
        match self {
            Self::RateCurves { title, .. }
            | Self::Staircases { title, .. }
            | Self::Psychometric { title, .. }
            | Self::Jnd { title, .. }
            | Self::ScoreDistributions { title, .. } => title,
        }
    }

    /// Draws to an SVG document in memory.
    ///
    /// # Errors
    /// [`AnalysisError::Plot`] when the font cannot be registered or drawing fails.
    pub fn render_svg(&self) -> Result<String, AnalysisError> {
        ensure_font()?;
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, SIZE_PX).into_drawing_area();
            self.draw(&root).map_err(|e| self.plot_error(&e))?;
            root.present().map_err(|e| self.plot_error(&e))?;
        }
        Ok(svg)
    }

    /// Draws to a PNG image in memory (8-bit RGB), for the caller to write whole
    /// ([`files::write`]); plotters' own PNG writer would create the file in place.
    ///
    /// # Errors
    /// [`AnalysisError::Plot`] when the font cannot be registered, drawing or encoding fails.
    pub fn render_png(&self) -> Result<Vec<u8>, AnalysisError> {
        ensure_font()?;
        let (w, h) = SIZE_PX;
        let mut rgb = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut rgb, SIZE_PX).into_drawing_area();
            self.draw(&root).map_err(|e| self.plot_error(&e))?;
            root.present().map_err(|e| self.plot_error(&e))?;
        }
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .write_header()
            .and_then(|mut writer| {
                writer.write_image_data(&rgb)?;
                writer.finish()
            })
            .map_err(|e| self.plot_error(&e))?;
        Ok(out)
    }

    fn plot_error(&self, e: &dyn std::fmt::Display) -> AnalysisError {
        AnalysisError::Plot {
            name: self.title().to_owned(),
            message: e.to_string(),
        }
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        root.fill(&WHITE)?;
        match self {
            Self::RateCurves {
                title,
                y_label,
                series,
                limit,
            } => draw_rate(root, title, y_label, series, *limit),
            Self::Staircases {
                title,
                level_label,
                tracks,
            } => draw_staircases(root, title, level_label, tracks),
            Self::Psychometric {
                title,
                level_label,
                data,
                fit,
                threshold,
            } => draw_psychometric(root, title, level_label, data, fit, *threshold),
            Self::Jnd {
                title,
                level_label,
                thresholds,
                model,
            } => draw_jnd(root, title, level_label, thresholds, model),
            Self::ScoreDistributions { title, per_subject } => {
                draw_distributions(root, title, per_subject)
            }
        }
    }
}

fn draw_rate<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    y_label: &str,
    series: &[RateSeries],
    limit: Option<f64>,
) -> DrawResult<DB> {
    let all = series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, _, lo, hi) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(lo);
        y1 = y1.max(hi);
    }
    if let Some(l) = limit {
        y0 = y0.min(l);
        y1 = y1.max(l);
    }
    let (x0, x1) = padded(x0, x1);
    let (y0, y1) = padded(y0, y1);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("Compression ratio (x:1)")
        .y_desc(y_label)
        .draw()?;
    if let Some(l) = limit {
        chart.draw_series(LineSeries::new(
            [(x0, l), (x1, l)],
            BLACK.mix(0.5).stroke_width(1),
        ))?;
    }
    for (i, s) in series.iter().enumerate() {
        let c = color(i);
        chart
            .draw_series(LineSeries::new(
                s.points.iter().map(|p| (p.0, p.1)),
                c.stroke_width(2),
            ))?
            .label(s.label.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(
            s.points
                .iter()
                .map(|p| Circle::new((p.0, p.1), 4, c.filled())),
        )?;
        // CI error bars: a vertical segment from lower to upper bound at each ratio.
        chart.draw_series(
            s.points
                .iter()
                .map(|p| PathElement::new(vec![(p.0, p.2), (p.0, p.3)], c.stroke_width(1))),
        )?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()?;
    Ok(())
}

fn draw_staircases<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    level_label: &str,
    tracks: &[StaircaseTrack],
) -> DrawResult<DB> {
    let max_trials = tracks
        .iter()
        .map(|t| t.steps.len())
        .max()
        .unwrap_or(1)
        .max(2);
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in tracks.iter().flat_map(|t| t.steps.iter()) {
        y0 = y0.min(s.level);
        y1 = y1.max(s.level);
    }
    let (y0, y1) = padded(y0, y1);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..(max_trials as f64), y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("Trial")
        .y_desc(level_label)
        .draw()?;
    for (i, t) in tracks.iter().enumerate() {
        let c = color(i);
        chart
            .draw_series(LineSeries::new(
                t.steps.iter().enumerate().map(|(j, s)| (j as f64, s.level)),
                c.stroke_width(1),
            ))?
            .label(format!("subject {} {}", t.subject, t.label))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        // Reversals as filled circles, other trials as small hollow ones.
        chart.draw_series(t.steps.iter().enumerate().map(|(j, s)| {
            if s.reversal {
                Circle::new((j as f64, s.level), 4, c.filled())
            } else {
                Circle::new((j as f64, s.level), 2, c.stroke_width(1))
            }
        }))?;
    }
    if tracks.len() <= 12 {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 12))
            .draw()?;
    }
    Ok(())
}

fn draw_psychometric<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    level_label: &str,
    data: &GroupedTrials,
    fit: &PsychometricFit,
    threshold: Option<(f64, f64, f64, f64)>,
) -> DrawResult<DB> {
    let lo = data.levels.first().map_or(0.0, |l| l.0);
    let hi = data.levels.last().map_or(1.0, |l| l.0);
    let (x0, x1) = padded(lo, hi);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(x0..x1, 0.4..1.02)?;
    chart
        .configure_mesh()
        .x_desc(level_label)
        .y_desc("Proportion correct")
        .draw()?;
    let max_n = data.levels.iter().map(|l| l.1).max().unwrap_or(1).max(1);
    chart.draw_series(data.levels.iter().filter(|l| l.1 > 0).map(|&(x, n, k)| {
        let r = (3.0 + 7.0 * (f64::from(n) / f64::from(max_n)).sqrt()) as i32;
        Circle::new((x, f64::from(k) / f64::from(n)), r, BLUE.mix(0.6).filled())
    }))?;
    let steps = 200;
    chart
        .draw_series(LineSeries::new(
            (0..=steps).map(|i| {
                let x = x0 + (x1 - x0) * f64::from(i) / f64::from(steps);
                (x, fit.probability(x))
            }),
            RED.stroke_width(2),
        ))?
        .label(format!(
            "{:?} fit (α = {:.4}, β = {:.2}, λ = {:.3})",
            fit.shape, fit.alpha, fit.beta, fit.lapse
        ))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    if let Some((pc, t, lower, upper)) = threshold {
        chart
            .draw_series(LineSeries::new([(t, 0.4), (t, pc)], BLACK.stroke_width(1)))?
            .label(format!(
                "threshold at {:.0}% = {t:.4} [{lower:.4}, {upper:.4}]",
                pc * 100.0
            ))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(1)));
        chart.draw_series(LineSeries::new(
            [(lower, pc), (upper, pc)],
            BLACK.stroke_width(3),
        ))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()?;
    Ok(())
}

fn draw_jnd<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    level_label: &str,
    thresholds: &[f64],
    model: &[(f64, f64, f64, f64)],
) -> DrawResult<DB> {
    let mut sorted: Vec<f64> = thresholds
        .iter()
        .copied()
        .filter(|t| t.is_finite())
        .collect();
    sorted.sort_by(f64::total_cmp);
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in sorted.iter().copied().chain(model.iter().map(|m| m.0)) {
        x0 = x0.min(x);
        x1 = x1.max(x);
    }
    let (x0, x1) = padded(x0, x1);
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(x0..x1, 0.0..1.0)?;
    chart
        .configure_mesh()
        .x_desc(level_label)
        .y_desc("Share of viewers who notice")
        .draw()?;
    if !model.is_empty() {
        let band: Vec<(f64, f64)> = model
            .iter()
            .map(|m| (m.0, m.2))
            .chain(model.iter().rev().map(|m| (m.0, m.3)))
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(band, RED.mix(0.15).filled())))?;
        chart
            .draw_series(LineSeries::new(
                model.iter().map(|m| (m.0, m.1)),
                RED.stroke_width(2),
            ))?
            .label("normal model with confidence band")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    }
    // Empirical CDF: the share noticing steps up by 1/n at each threshold.
    let n = sorted.len().max(1) as f64;
    let mut steps = vec![(x0, 0.0)];
    for (i, &t) in sorted.iter().enumerate() {
        steps.push((t, i as f64 / n));
        steps.push((t, (i + 1) as f64 / n));
    }
    steps.push((x1, if sorted.is_empty() { 0.0 } else { 1.0 }));
    chart
        .draw_series(LineSeries::new(steps, BLUE.stroke_width(2)))?
        .label(format!("empirical ({} viewers)", sorted.len()))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
    chart.draw_series(
        sorted
            .iter()
            .map(|&t| Circle::new((t, 0.0), 4, BLUE.mix(0.6).filled())),
    )?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()?;
    Ok(())
}

fn draw_distributions<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    per_subject: &[(String, Vec<f64>)],
) -> DrawResult<DB> {
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in per_subject.iter().flat_map(|s| s.1.iter()) {
        y0 = y0.min(*v);
        y1 = y1.max(*v);
    }
    let (y0, y1) = padded(y0, y1);
    let columns = per_subject.len().max(1) as f64;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(-0.5..(columns - 0.5), y0..y1)?;
    let labels: Vec<String> = per_subject.iter().map(|s| s.0.clone()).collect();
    chart
        .configure_mesh()
        .x_desc("Subject")
        .y_desc("Score")
        .x_labels(per_subject.len().min(40))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 {
                labels.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .draw()?;
    for (i, (_, scores)) in per_subject.iter().enumerate() {
        let mut sorted = scores.clone();
        sorted.sort_by(f64::total_cmp);
        let mut counts: Vec<(f64, usize)> = Vec::new();
        for v in sorted {
            match counts.last_mut() {
                Some(last) if last.0.total_cmp(&v).is_eq() => last.1 += 1,
                _ => counts.push((v, 1)),
            }
        }
        let total = scores.len().max(1) as f64;
        let c = color(i);
        chart.draw_series(counts.iter().map(|&(v, k)| {
            let r = (2.0 + 10.0 * (k as f64 / total).sqrt()) as i32;
            Circle::new((i as f64, v), r, c.mix(0.7).filled())
        }))?;
        if !scores.is_empty() {
            let mean = scores.iter().sum::<f64>() / total;
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(i as f64 - 0.3, mean), (i as f64 + 0.3, mean)],
                BLACK.stroke_width(2),
            )))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    /// The caption is drawn with the embedded font into the bitmap: the band above the plot
    /// area, where only the title is, must hold dark pixels. Without a usable font plotters
    /// would fail or leave it white.
    #[test]
    fn png_text_renders_without_system_fonts() {
        let figure = Figure::RateCurves {
            title: "MOS vs compression ratio".to_owned(),
            y_label: "MOS".to_owned(),
            series: vec![RateSeries {
                label: "a / walk".to_owned(),
                points: vec![(20.0, 4.5, 4.3, 4.7), (40.0, 3.5, 3.2, 3.8)],
            }],
            limit: Some(4.5),
        };
        ensure_font().unwrap();
        let (w, h) = SIZE_PX;
        let mut buffer = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buffer, SIZE_PX).into_drawing_area();
            figure.draw(&root).unwrap();
            root.present().unwrap();
        }
        let dark_in_title_band = (0..30u32)
            .flat_map(|y| (0..w).map(move |x| ((y * w + x) * 3) as usize))
            .filter(|&i| buffer[i] < 100 && buffer[i + 1] < 100 && buffer[i + 2] < 100)
            .count();
        assert!(
            dark_in_title_band > 200,
            "title pixels: {dark_in_title_band}"
        );
        let svg = figure.render_svg().unwrap();
        assert!(svg.contains("<text") && svg.contains("MOS vs compression ratio"));
    }
}
