//! Figures drawn with `plotters` to SVG (for report.html, inlined) and PNG, laid out for print.
//!
//! Every figure is 6.5 in wide (a page's text width) and as tall as its panels need. The SVG
//! has 100 user units per inch; the PNG is the same drawing at 300 dpi (3 pixels per unit,
//! fonts and lines scaled with it, the resolution stored in its `pHYs` chunk). Axes, ticks,
//! markers and legends are drawn here in pixel coordinates rather than with plotters' mesh, so
//! ticks fall on the tested ratios and the scale's ends, labels are integers where the values
//! are, and legends sit outside the data. Series are told apart by colour (Okabe & Ito's
//! colour-blind-safe palette, without its yellow), marker shape and line dash at once, so a
//! figure reads in greyscale.
//!
//! Text needs a font: `plotters` is built without its system-font (`ttf`/font-kit) backend and
//! with `ab_glyph`, and this module registers DejaVu Sans from the `dejavu` crate (embedded in
//! the binary) as the `sans-serif` family, so PNG labels render on a bare machine with no fonts
//! installed and SVG layout uses real glyph metrics.

use std::collections::BTreeSet;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::Serialize;

use crate::error::AnalysisError;
use crate::psychometric::{CurveBand, GroupedTrials, PsychometricFit};
use crate::staircase::StaircaseTrack;

const FONT: &str = "sans-serif";
/// Figure width in inches.
pub const WIDTH_IN: f64 = 6.5;
/// SVG user units per inch.
pub const SVG_UNITS_PER_IN: f64 = 100.0;
/// Resolution of the PNGs.
pub const PNG_DPI: f64 = 300.0;
/// Figure width in layout units (1/100 in).
const W: f64 = WIDTH_IN * SVG_UNITS_PER_IN;

/// Okabe & Ito (2008) colour-blind-safe palette in the order series take it: blue,
/// vermillion, bluish green, reddish purple, black, orange, sky blue (their yellow is left out:
/// it does not show on white).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0x00, 0x72, 0xB2),
    RGBColor(0xD5, 0x5E, 0x00),
    RGBColor(0x00, 0x9E, 0x73),
    RGBColor(0xCC, 0x79, 0xA7),
    RGBColor(0x00, 0x00, 0x00),
    RGBColor(0xE6, 0x9F, 0x00),
    RGBColor(0x56, 0xB4, 0xE9),
];
/// Text, axes and tick marks.
const INK: RGBColor = RGBColor(0x22, 0x22, 0x22);
/// The frame of every plotting area (tests find panels by it).
pub const FRAME: RGBColor = RGBColor(0x4D, 0x4D, 0x4D);
/// The frame of every legend (tests find legends by it).
pub const LEGEND_FRAME: RGBColor = RGBColor(0xA0, 0xA0, 0xA0);
const GRID: RGBColor = RGBColor(0xE6, 0xE6, 0xE6);
const REFERENCE: RGBColor = RGBColor(0x59, 0x59, 0x59);
/// Staircase trials answered correctly (filled dots).
pub const CORRECT: RGBColor = PALETTE[0];
/// Staircase trials answered wrongly (open dots).
pub const WRONG: RGBColor = PALETTE[1];
/// Staircase threshold lines.
pub const THRESHOLD: RGBColor = PALETTE[2];
/// The most staircase panels one figure shows.
pub const MAX_STAIRCASE_PANELS: usize = 12;

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

/// One curve of a rate plot: a method's (compression ratio, mean, CI lower, CI upper) points
/// on one clip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RateSeries {
    /// Legend label: the method (codec and variant).
    pub label: String,
    /// The clip, whose panel the curve is drawn in.
    pub clip: String,
    /// (x, y, lower, upper); lower/upper equal y when the CI is undefined.
    pub points: Vec<(f64, f64, f64, f64)>,
}

/// A figure, kept as data so it can be drawn to any backend.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub enum Figure {
    /// MOS or DMOS against compression ratio with CI error bars: one panel per clip (shared
    /// axes), one curve per method.
    RateCurves {
        /// Title.
        title: String,
        /// Y axis label ("MOS" or "DMOS").
        y_label: String,
        /// The curves.
        series: Vec<RateSeries>,
        /// A horizontal limit line (4.5 MOS, 0.2 DMOS), if any.
        limit: Option<f64>,
        /// The y axis' span (the rating scale): widened only where a mean or the limit lies
        /// outside it, never for a CI (its bar is cut at the frame). `None`: the data's range.
        y_range: Option<(f64, f64)>,
    },
    /// Crowd scenes (thesis Fig. 6.9): MOS against the compression ratio of the characters
    /// that vary, one curve per distance level, in one panel, with CI error bars.
    CrowdCurves {
        /// Title.
        title: String,
        /// Y axis label.
        y_label: String,
        /// X axis label (whose ratio: "Compression ratio of the back characters (x:1)").
        x_label: String,
        /// The panel's name (what the subjects were asked to judge).
        panel: String,
        /// The curves: one per level (label), all with [`RateSeries::clip`] = `panel`.
        series: Vec<RateSeries>,
        /// The y axis' span (the rating scale), if known.
        y_range: Option<(f64, f64)>,
    },
    /// Staircase tracks, one panel each (the first [`MAX_STAIRCASE_PANELS`]): the level held
    /// until the next trial, correct and wrong answers, reversals and the threshold.
    Staircases {
        /// Title.
        title: String,
        /// Y axis label (the level's name and unit).
        level_label: String,
        /// The tracks.
        tracks: Vec<StaircaseTrack>,
        /// Reversals averaged into a track's threshold (its line is drawn where the track
        /// has that many).
        last_reversals: usize,
        /// Subject names indexed by [`StaircaseTrack::subject`] (the number where missing).
        subjects: Vec<String>,
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
        /// Pointwise bootstrap band of the fitted curve, if computed.
        band: Option<CurveBand>,
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
        /// The y axis' span (the rating scale), if known.
        y_range: Option<(f64, f64)>,
    },
    /// A forest plot of one model's effects: one row per effect (its name the row's label,
    /// top to bottom in the given order), the estimate as a dot with its CI as a whisker, and
    /// a vertical line at 0 (no effect). One model per figure: effects of models on different
    /// scales never share an axis. A row whose CI is not finite is drawn without a whisker,
    /// and one whose estimate is not finite with its label only.
    Forest {
        /// Title.
        title: String,
        /// X axis label (the effects' scale: "Effect on the score", "Effect (log odds)").
        x_label: String,
        /// (effect name, estimate, CI lower, CI upper).
        rows: Vec<(String, f64, f64, f64)>,
    },
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A series' look: palette colour, marker and dash, each an index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct SeriesStyle {
    /// Index into [`PALETTE`].
    pub color: usize,
    /// Index into the marker shapes (circle, square, triangle up, diamond, triangle down,
    /// open circle, open square).
    pub marker: usize,
    /// Index into the dashes (solid, dashed, dotted, dash-dot, long dash, dash-dot-dot,
    /// sparse dash).
    pub dash: usize,
}

const MARKERS: usize = 7;
const DASHES: [&[f64]; 7] = [
    &[],
    &[5.0, 3.0],
    &[1.2, 2.2],
    &[6.0, 2.5, 1.2, 2.5],
    &[11.0, 3.5],
    &[6.0, 2.0, 1.2, 2.0, 1.2, 2.0],
    &[2.5, 4.0],
];

/// The look of series `i`: colour, marker and dash all change from one series to the next,
/// and the 49 first (colour, marker, dash) triples are distinct.
pub fn series_style(i: usize) -> SeriesStyle {
    let (a, b) = (i % 7, i / 7);
    SeriesStyle {
        color: a,
        marker: (a + b) % MARKERS,
        dash: (a + 2 * b) % DASHES.len(),
    }
}

/// Pixels per layout unit and helpers to scale lengths and fonts.
#[derive(Debug, Clone, Copy)]
struct Ctx {
    s: f64,
}

impl Ctx {
    fn p(self, v: f64) -> i32 {
        (v * self.s).round() as i32
    }
    fn w(self, v: f64) -> u32 {
        (v * self.s).round().max(1.0) as u32
    }
    fn font(self, size: f64) -> TextStyle<'static> {
        TextStyle::from((FONT, size * self.s).into_font()).color(&INK)
    }
}

/// Width of `text` at `size` layout units, in layout units (an estimate when the font fails).
fn text_width(text: &str, size: f64) -> f64 {
    (FONT, size)
        .into_font()
        .box_size(text)
        .map_or(0.6 * size * text.chars().count() as f64, |(w, _)| {
            f64::from(w)
        })
}

/// A plotting area: its pixel rectangle and the data ranges it spans. The frame drawn around
/// it lies `pad` pixels outside on every side ([`Frame::padded`]), so that a marker at the
/// edge of the data ranges (a rating at the top of the scale) is drawn whole inside the frame.
#[derive(Debug, Clone, Copy)]
struct Frame {
    left: f64,
    top: f64,
    right: f64,
    bottom: f64,
    x: (f64, f64),
    y: (f64, f64),
    pad: f64,
}

/// Half the size of a curve's marker, layout units.
const MARKER_R: f64 = 3.4;
/// The space between the data ranges and the frame, layout units: a marker's half-height
/// (a triangle's 1.25 × [`MARKER_R`]) and half its outline.
const MARKER_PAD: f64 = 6.0;

impl Frame {
    /// The data ranges spanning the frame `self` less `pad` pixels on every side; the frame
    /// drawn stays where `self` is.
    fn padded(self, pad: f64) -> Self {
        Self {
            left: self.left + pad,
            top: self.top + pad,
            right: self.right - pad,
            bottom: self.bottom - pad,
            pad: self.pad + pad,
            ..self
        }
    }
    /// The frame drawn: (left, top, right, bottom) in pixels.
    fn outer(&self) -> (f64, f64, f64, f64) {
        (
            self.left - self.pad,
            self.top - self.pad,
            self.right + self.pad,
            self.bottom + self.pad,
        )
    }
    fn px(&self, x: f64, y: f64) -> (f64, f64) {
        (
            self.left + (x - self.x.0) / (self.x.1 - self.x.0) * (self.right - self.left),
            self.bottom - (y - self.y.0) / (self.y.1 - self.y.0) * (self.bottom - self.top),
        )
    }
    fn at(&self, x: f64, y: f64) -> (i32, i32) {
        round(self.px(x, y))
    }
}

fn round(p: (f64, f64)) -> (i32, i32) {
    (p.0.round() as i32, p.1.round() as i32)
}

/// A tick label: integers without a decimal point, other values with at most four
/// significant decimals and no trailing zeros.
pub fn tick_label(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 * v.abs().max(1.0) {
        return format!("{:.0}", v.round() + 0.0);
    }
    let decimals = (4 - v.abs().log10().floor() as i32).clamp(1, 8) as usize;
    let s = format!("{v:.decimals$}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

/// `v` to three significant digits, as legends and annotations print a statistic.
pub fn sig3(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return tick_label(v);
    }
    let decimals = (2 - v.abs().log10().floor() as i32).clamp(0, 10) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    }
}

/// About `target` ticks at 1, 2, 2.5 or 5 × 10^k steps covering [lo, hi].
fn nice_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// The range a nice tick step spans around [lo, hi], and its ticks.
fn nice_range(lo: f64, hi: f64, target: usize) -> ((f64, f64), Vec<f64>) {
    if !(lo.is_finite() && hi.is_finite()) {
        return ((0.0, 1.0), vec![0.0, 1.0]);
    }
    let (lo, hi) = if hi - lo < 1e-12 * lo.abs().max(1.0) {
        (lo - 0.5 * lo.abs().max(1e-3), hi + 0.5 * hi.abs().max(1e-3))
    } else {
        (lo, hi)
    };
    let ticks = nice_ticks(lo, hi, target);
    let step = if ticks.len() >= 2 {
        ticks[1] - ticks[0]
    } else {
        hi - lo
    };
    let a = (lo / step + 1e-9).floor() * step;
    let b = (hi / step - 1e-9).ceil() * step;
    ((a, b), nice_ticks(a, b, target))
}

/// The y span of a rate figure: the scale when given, widened to a tick step only where a
/// mean or the limit falls outside it (a DSCQS DMOS below 0: the test rated above its
/// reference), never for a CI, whose bar is cut at the frame: a MOS axis never passes the
/// scale. Without a scale, the nice range of the means and CIs.
fn rate_y_range(
    y_range: Option<(f64, f64)>,
    series: &[RateSeries],
    limit: Option<f64>,
) -> ((f64, f64), Vec<f64>) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let scaled = matches!(y_range, Some((a, b)) if b > a);
    for &(_, y, l, u) in series.iter().flat_map(|s| s.points.iter()) {
        let values = if scaled { &[y][..] } else { &[y, l, u][..] };
        for &v in values {
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if let Some(l) = limit {
        lo = lo.min(l);
        hi = hi.max(l);
    }
    match y_range {
        Some((a, b)) if b > a => {
            let ticks = nice_ticks(a, b, 5);
            let step = if ticks.len() >= 2 {
                ticks[1] - ticks[0]
            } else {
                b - a
            };
            let a2 = if lo < a {
                a - ((a - lo) / step).ceil() * step
            } else {
                a
            };
            let b2 = if hi > b {
                b + ((hi - b) / step).ceil() * step
            } else {
                b
            };
            let ticks = if (a2, b2) == (a, b) {
                ticks
            } else {
                nice_ticks(a2, b2, 5)
            };
            ((a2, b2), ticks)
        }
        _ => nice_range(lo, hi, 5),
    }
}

/// The x ticks of rate figures: the tested ratios when there are few, else nice ticks.
fn ratio_ticks(ratios: &[f64]) -> Vec<f64> {
    if ratios.len() <= 8 {
        ratios.to_vec()
    } else {
        let (lo, hi) = (ratios[0], ratios[ratios.len() - 1]);
        nice_ticks(lo, hi, 6)
            .into_iter()
            .filter(|t| (t - t.round()).abs() < 1e-9)
            .collect()
    }
}

/// `pattern` (on, off, … lengths in pixels) laid along the polyline `points` (data
/// coordinates mapped to pixels by `to_px`): the pieces that are drawn, in data coordinates.
fn dash_pieces(
    points: &[(f64, f64)],
    to_px: impl Fn((f64, f64)) -> (f64, f64),
    pattern: &[f64],
) -> Vec<Vec<(f64, f64)>> {
    if pattern.is_empty() || pattern.iter().any(|d| *d <= 0.0) || points.len() < 2 {
        return vec![points.to_vec()];
    }
    let mut pieces = Vec::new();
    let mut current = vec![points[0]];
    let (mut k, mut left, mut on) = (0, pattern[0], true);
    for w in points.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (pa, pb) = (to_px(a), to_px(b));
        let len = (pb.0 - pa.0).hypot(pb.1 - pa.1);
        let mut t = 0.0;
        while len - t > left {
            t += left;
            let f = t / len;
            let p = (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1));
            if on {
                current.push(p);
                pieces.push(std::mem::take(&mut current));
            } else {
                current = vec![p];
            }
            on = !on;
            k = (k + 1) % pattern.len();
            left = pattern[k];
        }
        left -= len - t;
        if on {
            current.push(b);
        }
    }
    if on && current.len() >= 2 {
        pieces.push(current);
    }
    pieces
}

/// Draws a polyline in pixel coordinates with `dash` (layout units).
fn draw_dashed<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    points: &[(f64, f64)],
    dash: &[f64],
    style: ShapeStyle,
) -> DrawResult<DB> {
    let scaled: Vec<f64> = dash.iter().map(|d| d * c.s).collect();
    for piece in dash_pieces(points, |p| p, &scaled) {
        root.draw(&PathElement::new(
            piece.into_iter().map(round).collect::<Vec<_>>(),
            style,
        ))?;
    }
    Ok(())
}

/// Draws marker `shape` of half-size `r` pixels centred at `at`.
fn draw_marker<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    at: (i32, i32),
    shape: usize,
    r: f64,
    color: RGBColor,
    stroke: u32,
) -> DrawResult<DB> {
    let (x, y) = (f64::from(at.0), f64::from(at.1));
    let poly = |pts: &[(f64, f64)]| -> Vec<(i32, i32)> {
        pts.iter().map(|p| round((x + p.0, y + p.1))).collect()
    };
    let q = r * 0.9;
    let outline: Vec<(i32, i32)> = match shape % MARKERS {
        0 | 5 => {
            if shape.is_multiple_of(MARKERS) {
                return root.draw(&Circle::new(at, r.round() as u32, color.filled()));
            }
            root.draw(&Circle::new(at, r.round() as u32, WHITE.filled()))?;
            return root.draw(&Circle::new(
                at,
                r.round() as u32,
                color.stroke_width(stroke),
            ));
        }
        1 | 6 => poly(&[(-q, -q), (q, -q), (q, q), (-q, q)]),
        2 => poly(&[(0.0, -1.2 * r), (1.1 * r, 0.75 * r), (-1.1 * r, 0.75 * r)]),
        3 => poly(&[(0.0, -1.25 * r), (r, 0.0), (0.0, 1.25 * r), (-r, 0.0)]),
        _ => poly(&[(0.0, 1.2 * r), (1.1 * r, -0.75 * r), (-1.1 * r, -0.75 * r)]),
    };
    if shape % MARKERS == 6 {
        root.draw(&Polygon::new(outline.clone(), WHITE.filled()))?;
        let mut closed = outline;
        closed.push(closed[0]);
        return root.draw(&PathElement::new(closed, color.stroke_width(stroke)));
    }
    root.draw(&Polygon::new(outline, color.filled()))
}

/// What a legend entry shows before its label.
#[derive(Debug, Clone)]
enum Key {
    /// A line sample with an optional marker in its middle.
    Line {
        color: RGBColor,
        dash: &'static [f64],
        width: f64,
        marker: Option<usize>,
    },
    /// A marker alone (filled, or open with `open`).
    Dot {
        color: RGBColor,
        open: bool,
        ring: bool,
    },
    /// A filled band swatch.
    Band(RGBAColor),
}

const LEGEND_FONT: f64 = 10.0;
const LEGEND_ROW: f64 = 17.0;
const KEY_WIDTH: f64 = 32.0;

/// Legend rows needed for `labels` across the figure's width.
fn legend_rows(labels: &[String]) -> (usize, usize, f64) {
    let widest = labels
        .iter()
        .map(|l| text_width(l, LEGEND_FONT))
        .fold(0.0, f64::max);
    let entry = KEY_WIDTH + 6.0 + widest + 16.0;
    let cols = ((W - 40.0) / entry).floor().max(1.0) as usize;
    let cols = cols.min(labels.len().max(1));
    (cols, labels.len().div_ceil(cols), entry)
}

/// Height of a legend of `labels` in layout units.
fn legend_height(labels: &[String]) -> f64 {
    if labels.is_empty() {
        return 0.0;
    }
    let (_, rows, _) = legend_rows(labels);
    rows as f64 * LEGEND_ROW + 10.0
}

/// Draws a framed legend centred on the figure with its top at `top` (layout units).
fn draw_legend<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    top: f64,
    entries: &[(Key, String)],
) -> DrawResult<DB> {
    if entries.is_empty() {
        return Ok(());
    }
    let labels: Vec<String> = entries.iter().map(|e| e.1.clone()).collect();
    let (cols, rows, entry) = legend_rows(&labels);
    let width = cols as f64 * entry;
    let left = (W - width) / 2.0;
    let height = rows as f64 * LEGEND_ROW + 10.0;
    root.draw(&Rectangle::new(
        [
            (c.p(left), c.p(top)),
            (c.p(left + width), c.p(top + height)),
        ],
        LEGEND_FRAME.stroke_width(c.w(0.8)),
    ))?;
    for (i, (key, label)) in entries.iter().enumerate() {
        let (row, col) = (i / cols, i % cols);
        let x = left + 8.0 + col as f64 * entry;
        let y = top + 5.0 + (row as f64 + 0.5) * LEGEND_ROW;
        let (px, py) = (x * c.s, y * c.s);
        match key {
            Key::Line {
                color,
                dash,
                width,
                marker,
            } => {
                draw_dashed(
                    root,
                    c,
                    &[(px, py), (px + KEY_WIDTH * c.s, py)],
                    dash,
                    color.stroke_width(c.w(*width)),
                )?;
                if let Some(m) = marker {
                    draw_marker(
                        root,
                        round((px + KEY_WIDTH * c.s / 2.0, py)),
                        *m,
                        3.6 * c.s,
                        *color,
                        c.w(1.2),
                    )?;
                }
            }
            Key::Dot { color, open, ring } => {
                let at = round((px + KEY_WIDTH * c.s / 2.0, py));
                if *ring {
                    root.draw(&Circle::new(at, c.w(5.5), INK.stroke_width(c.w(0.9))))?;
                } else {
                    draw_marker(
                        root,
                        at,
                        if *open { 5 } else { 0 },
                        3.0 * c.s,
                        *color,
                        c.w(1.2),
                    )?;
                }
            }
            Key::Band(color) => {
                root.draw(&Rectangle::new(
                    [(c.p(x), c.p(y - 4.5)), (c.p(x + KEY_WIDTH), c.p(y + 4.5))],
                    color.filled(),
                ))?;
            }
        }
        root.draw_text(
            label,
            &c.font(LEGEND_FONT).pos(Pos::new(HPos::Left, VPos::Center)),
            (c.p(x + KEY_WIDTH + 6.0), c.p(y)),
        )?;
    }
    Ok(())
}

/// Which tick labels a panel prints.
#[derive(Debug, Clone, Copy)]
struct Labels {
    x: bool,
    y: bool,
}

/// Grid lines at the y ticks, the frame, tick marks and tick labels of `f`.
fn draw_axes<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    f: &Frame,
    x_ticks: &[(f64, String)],
    y_ticks: &[(f64, String)],
    labels: Labels,
) -> DrawResult<DB> {
    let (l, t, r, b) = f.outer();
    for (v, _) in y_ticks {
        let (_, y) = f.px(f.x.0, *v);
        root.draw(&PathElement::new(
            vec![round((l, y)), round((r, y))],
            GRID.stroke_width(c.w(0.7)),
        ))?;
    }
    root.draw(&Rectangle::new(
        [round((l, t)), round((r, b))],
        FRAME.stroke_width(c.w(0.8)),
    ))?;
    let tick = 3.5 * c.s;
    let style = c.font(9.0);
    for (v, label) in x_ticks {
        let (x, _) = f.px(*v, f.y.0);
        root.draw(&PathElement::new(
            vec![round((x, b)), round((x, b + tick))],
            FRAME.stroke_width(c.w(0.8)),
        ))?;
        if labels.x {
            root.draw_text(
                label,
                &style.pos(Pos::new(HPos::Center, VPos::Top)),
                round((x, b + tick + 2.0 * c.s)),
            )?;
        }
    }
    for (v, label) in y_ticks {
        let (_, y) = f.px(f.x.0, *v);
        root.draw(&PathElement::new(
            vec![round((l - tick, y)), round((l, y))],
            FRAME.stroke_width(c.w(0.8)),
        ))?;
        if labels.y {
            root.draw_text(
                label,
                &style.pos(Pos::new(HPos::Right, VPos::Center)),
                round((l - tick - 2.0 * c.s, y)),
            )?;
        }
    }
    Ok(())
}

fn labelled(ticks: &[f64], fmt: impl Fn(f64) -> String) -> Vec<(f64, String)> {
    ticks.iter().map(|&t| (t, fmt(t))).collect()
}

/// Title centred at the top, axis titles centred under `x_span` and left of `y_span` (layout
/// units).
fn draw_titles<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    title: &str,
    x_label: (&str, f64, (f64, f64)),
    y_label: (&str, f64, (f64, f64)),
) -> DrawResult<DB> {
    root.draw_text(
        title,
        &TextStyle::from((FONT, 13.0 * c.s, FontStyle::Bold).into_font())
            .color(&INK)
            .pos(Pos::new(HPos::Center, VPos::Top)),
        (c.p(W / 2.0), c.p(7.0)),
    )?;
    let (text, y, (x0, x1)) = x_label;
    root.draw_text(
        text,
        &c.font(10.5).pos(Pos::new(HPos::Center, VPos::Top)),
        (c.p(f64::midpoint(x0, x1)), c.p(y)),
    )?;
    let (text, x, (y0, y1)) = y_label;
    root.draw_text(
        text,
        &c.font(10.5)
            .transform(FontTransform::Rotate270)
            .pos(Pos::new(HPos::Center, VPos::Top)),
        (c.p(x), c.p(f64::midpoint(y0, y1))),
    )?;
    Ok(())
}

/// Columns of a grid of `n` panels.
fn grid_columns(n: usize, max: usize) -> usize {
    match n {
        0 | 1 => 1,
        4 if max >= 3 => 2,
        _ => n.min(max),
    }
}

/// The panel rectangles of a grid in layout units: (left, top, right, bottom) each.
fn grid(
    n: usize,
    cols: usize,
    area: (f64, f64, f64),
    panel_h: f64,
    gaps: (f64, f64),
) -> Vec<(f64, f64, f64, f64)> {
    let (left, top, right) = area;
    let pw = (right - left - (cols as f64 - 1.0) * gaps.0) / cols as f64;
    (0..n)
        .map(|i| {
            let (row, col) = ((i / cols) as f64, (i % cols) as f64);
            let l = left + col * (pw + gaps.0);
            let t = top + row * (panel_h + gaps.1);
            (l, t, l + pw, t + panel_h)
        })
        .collect()
}

// Rate curves' layout, in layout units.
const TITLE_H: f64 = 28.0;
const PANEL_TITLE_H: f64 = 15.0;
const TICKS_H: f64 = 17.0;
const AXIS_TITLE_H: f64 = 16.0;
const LEFT: f64 = 50.0;
const RIGHT: f64 = 14.0;

#[derive(Debug)]
struct RateLayout {
    clips: Vec<String>,
    methods: Vec<String>,
    cols: usize,
    rows: usize,
    panel_h: f64,
    legend: Vec<String>,
}

impl RateLayout {
    fn new(series: &[RateSeries], limit: Option<f64>) -> Self {
        let clips: Vec<String> = series
            .iter()
            .map(|s| s.clip.clone())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let methods: Vec<String> = series
            .iter()
            .map(|s| s.label.clone())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let n = clips.len().max(1);
        let cols = grid_columns(n, 3);
        let rows = n.div_ceil(cols);
        let mut legend = methods.clone();
        if let Some(l) = limit {
            legend.push(format!("limit {}", tick_label(l)));
        }
        Self {
            clips,
            methods,
            cols,
            rows,
            panel_h: if rows == 1 { 240.0 } else { 165.0 },
            legend,
        }
    }
    fn panels_bottom(&self) -> f64 {
        TITLE_H + self.rows as f64 * (PANEL_TITLE_H + self.panel_h + TICKS_H)
    }
    fn height(&self) -> f64 {
        self.panels_bottom() + AXIS_TITLE_H + 6.0 + legend_height(&self.legend) + 8.0
    }
}

/// One method's curve in a rate panel: dashed line, capped error bars, markers; `k` is the
/// method's index among `m`.
fn draw_rate_curve<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    f: &Frame,
    s: &RateSeries,
    k: usize,
    m: usize,
) -> DrawResult<DB> {
    let style = series_style(k);
    let color = PALETTE[style.color];
    // Methods at one ratio are dodged apart so their error bars do not overlap.
    let dodge = (k as f64 - (m as f64 - 1.0) / 2.0) * 3.5 * c.s;
    let pts: Vec<(f64, f64)> = s
        .points
        .iter()
        .map(|p| {
            let (x, y) = f.px(p.0, p.1);
            (x + dodge, y)
        })
        .collect();
    draw_dashed(
        root,
        c,
        &pts,
        DASHES[style.dash],
        color.stroke_width(c.w(1.5)),
    )?;
    let cap = 3.0 * c.s;
    // A CI reaching past the axis (a t interval above the top of the scale) is cut at the
    // frame, without a cap there: the cap marks where an interval ends.
    let (_, top, _, bottom) = f.outer();
    for (p, &(x, _)) in s.points.iter().zip(&pts) {
        let (_, lo) = f.px(p.0, p.2);
        let (_, hi) = f.px(p.0, p.3);
        let ends = [(lo, lo > bottom), (hi, hi < top)].map(|(y, cut)| (y.clamp(top, bottom), cut));
        let (lo, hi) = (ends[0].0, ends[1].0);
        if (lo - hi).abs() > 0.5 {
            let bar = color.stroke_width(c.w(1.1));
            root.draw(&PathElement::new(vec![round((x, lo)), round((x, hi))], bar))?;
            for (yy, cut) in ends {
                if !cut {
                    root.draw(&PathElement::new(
                        vec![round((x - cap, yy)), round((x + cap, yy))],
                        bar,
                    ))?;
                }
            }
        }
    }
    for &p in &pts {
        draw_marker(
            root,
            round(p),
            style.marker,
            MARKER_R * c.s,
            color,
            c.w(1.2),
        )?;
    }
    Ok(())
}

/// The limit as a dashed line across a panel, labelled at its right end.
fn draw_limit<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    f: &Frame,
    lim: f64,
) -> DrawResult<DB> {
    let (_, y) = f.px(f.x.0, lim);
    let (left, top, right, _) = f.outer();
    draw_dashed(
        root,
        c,
        &[(left, y), (right, y)],
        &[4.0, 2.5],
        REFERENCE.stroke_width(c.w(1.0)),
    )?;
    let above = y - top > 14.0 * c.s;
    root.draw_text(
        &format!("limit {}", tick_label(lim)),
        &c.font(8.5).color(&REFERENCE).pos(Pos::new(
            HPos::Right,
            if above { VPos::Bottom } else { VPos::Top },
        )),
        round((
            right - 3.0 * c.s,
            if above { y - 2.0 * c.s } else { y + 2.0 * c.s },
        )),
    )?;
    Ok(())
}

/// The rate figures' legend: each method's line and marker, and the limit.
fn rate_legend(methods: &[String], limit: Option<f64>) -> Vec<(Key, String)> {
    let mut entries: Vec<(Key, String)> = methods
        .iter()
        .enumerate()
        .map(|(k, label)| {
            let style = series_style(k);
            (
                Key::Line {
                    color: PALETTE[style.color],
                    dash: DASHES[style.dash],
                    width: 1.5,
                    marker: Some(style.marker),
                },
                label.clone(),
            )
        })
        .collect();
    if let Some(l) = limit {
        entries.push((
            Key::Line {
                color: REFERENCE,
                dash: &[4.0, 2.5],
                width: 1.0,
                marker: None,
            },
            format!("limit {}", tick_label(l)),
        ));
    }
    entries
}

/// The texts of a rate plot's axes: the x axis' title and what a panel's name says before
/// its clip.
#[derive(Clone, Copy)]
struct RateAxes<'a> {
    x_label: &'a str,
    panel_prefix: &'a str,
}

/// The axes of MOS/DMOS against CR, a panel per clip.
const RATE_AXES: RateAxes<'static> = RateAxes {
    x_label: "Compression ratio (x:1)",
    panel_prefix: "clip ",
};

/// Draws MOS/DMOS against CR: a panel per clip, a curve per method.
#[expect(
    clippy::too_many_arguments,
    reason = "the figure's fields, passed as the match arm unpacks them"
)]
fn draw_rate<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    title: &str,
    y_label: &str,
    series: &[RateSeries],
    limit: Option<f64>,
    y_range: Option<(f64, f64)>,
    axes: RateAxes<'_>,
) -> DrawResult<DB> {
    let layout = RateLayout::new(series, limit);
    let (y_span, y_ticks) = rate_y_range(y_range, series, limit);
    let mut ratios: Vec<f64> = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0))
        .filter(|x| x.is_finite())
        .collect();
    ratios.sort_by(f64::total_cmp);
    ratios.dedup();
    let (x_lo, x_hi) = match (ratios.first(), ratios.last()) {
        (Some(a), Some(b)) => (*a, *b),
        _ => (0.0, 1.0),
    };
    let span = (x_hi - x_lo).max(x_lo.abs() * 0.2).max(1.0);
    let x_span = (x_lo - 0.08 * span, x_hi + 0.08 * span);
    let x_ticks = labelled(&ratio_ticks(&ratios), tick_label);
    let y_ticks = labelled(&y_ticks, tick_label);
    let rects = grid(
        layout.clips.len().max(1),
        layout.cols,
        (LEFT, TITLE_H + PANEL_TITLE_H, W - RIGHT),
        layout.panel_h,
        (14.0, PANEL_TITLE_H + TICKS_H),
    );
    let m = layout.methods.len();
    for (i, (l, t, r, b)) in rects.iter().copied().enumerate() {
        let f = Frame {
            left: l * c.s,
            top: t * c.s,
            right: r * c.s,
            bottom: b * c.s,
            x: x_span,
            y: y_span,
            pad: 0.0,
        }
        .padded(MARKER_PAD * c.s);
        let bottom_row = i + layout.cols >= rects.len();
        draw_axes(
            root,
            c,
            &f,
            &x_ticks,
            &y_ticks,
            Labels {
                x: true,
                y: i % layout.cols == 0,
            },
        )?;
        let _ = bottom_row;
        let clip = layout.clips.get(i).cloned().unwrap_or_default();
        root.draw_text(
            &format!("{}{clip}", axes.panel_prefix),
            &c.font(10.0).pos(Pos::new(HPos::Center, VPos::Bottom)),
            (c.p(f64::midpoint(l, r)), c.p(t - 3.0)),
        )?;
        if let Some(lim) = limit {
            draw_limit(root, c, &f, lim)?;
        }
        for s in series.iter().filter(|s| s.clip == clip) {
            let k = layout
                .methods
                .iter()
                .position(|x| *x == s.label)
                .unwrap_or(0);
            draw_rate_curve(root, c, &f, s, k, m)?;
        }
    }
    let plot_left = LEFT;
    let plot_right = W - RIGHT;
    let bottom = layout.panels_bottom();
    draw_titles(
        root,
        c,
        title,
        (axes.x_label, bottom + 1.0, (plot_left, plot_right)),
        (y_label, 6.0, (TITLE_H + PANEL_TITLE_H, bottom - TICKS_H)),
    )?;
    let entries = rate_legend(&layout.methods, limit);
    draw_legend(root, c, bottom + AXIS_TITLE_H + 6.0, &entries)
}

// Staircases' layout.
const STAIR_PANEL_H: f64 = 118.0;

fn staircase_legend(last_reversals: usize) -> Vec<(Key, String)> {
    vec![
        (
            Key::Dot {
                color: CORRECT,
                open: false,
                ring: false,
            },
            "correct".to_owned(),
        ),
        (
            Key::Dot {
                color: WRONG,
                open: true,
                ring: false,
            },
            "wrong".to_owned(),
        ),
        (
            Key::Dot {
                color: INK,
                open: true,
                ring: true,
            },
            "reversal".to_owned(),
        ),
        (
            Key::Line {
                color: THRESHOLD,
                dash: &[],
                width: 1.5,
                marker: None,
            },
            format!("threshold (mean of last {last_reversals} reversals)"),
        ),
    ]
}

fn staircase_height(n: usize, last_reversals: usize) -> f64 {
    let shown = n.clamp(1, MAX_STAIRCASE_PANELS);
    let rows = shown.div_ceil(grid_columns(shown, 3));
    let labels: Vec<String> = staircase_legend(last_reversals)
        .into_iter()
        .map(|e| e.1)
        .collect();
    TITLE_H
        + rows as f64 * (PANEL_TITLE_H + STAIR_PANEL_H + TICKS_H)
        + AXIS_TITLE_H
        + 6.0
        + legend_height(&labels)
        + if n > MAX_STAIRCASE_PANELS { 16.0 } else { 0.0 }
        + 8.0
}

/// A staircase panel's title: who, which, and its threshold.
fn staircase_title(track: &StaircaseTrack, subjects: &[String], threshold: Option<f64>) -> String {
    let who = subject_label(subjects, track.subject);
    match threshold {
        Some(th) => format!("{who} · {} · threshold {}", track.label, sig3(th)),
        None => format!("{who} · {} · not converged", track.label),
    }
}

fn subject_label(names: &[String], id: u32) -> String {
    match names.get(id as usize) {
        Some(n) if !n.is_empty() => n.clone(),
        _ => format!("subject {id}"),
    }
}

/// One staircase in its panel: the level as steps, each trial's answer, the reversals.
fn draw_track<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    f: &Frame,
    track: &StaircaseTrack,
) -> DrawResult<DB> {
    // Steps: each trial's level is held until the next trial.
    let mut path = Vec::with_capacity(2 * track.steps.len());
    for (j, s) in track.steps.iter().enumerate() {
        let x = (j + 1) as f64;
        if j > 0 {
            path.push(f.px(x, track.steps[j - 1].level));
        }
        path.push(f.px(x, s.level));
    }
    root.draw(&PathElement::new(
        path.into_iter().map(round).collect::<Vec<_>>(),
        REFERENCE.stroke_width(c.w(1.0)),
    ))?;
    let spacing = (f.right - f.left) / (f.x.1 - f.x.0);
    let r_dot = (2.8 * c.s).min(0.42 * spacing).max(1.0);
    for (j, s) in track.steps.iter().enumerate() {
        let at = f.at((j + 1) as f64, s.level);
        if s.reversal {
            root.draw(&Circle::new(
                at,
                (r_dot * 2.0).round() as u32,
                INK.stroke_width(c.w(0.9)),
            ))?;
        }
        draw_marker(
            root,
            at,
            if s.correct { 0 } else { 5 },
            r_dot,
            if s.correct { CORRECT } else { WRONG },
            c.w(1.2),
        )?;
    }
    Ok(())
}

/// Draws each staircase as steps with correct/wrong marks, reversals and its threshold.
fn draw_staircases<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    title: &str,
    level_label: &str,
    tracks: &[StaircaseTrack],
    last_reversals: usize,
    subjects: &[String],
) -> DrawResult<DB> {
    let shown = &tracks[..tracks.len().min(MAX_STAIRCASE_PANELS)];
    let n = shown.len().max(1);
    let cols = grid_columns(n, 3);
    let max_trials = shown
        .iter()
        .map(|t| t.steps.len())
        .max()
        .unwrap_or(1)
        .max(2);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in shown.iter().flat_map(|t| t.steps.iter()) {
        lo = lo.min(s.level);
        hi = hi.max(s.level);
    }
    let (y_span, y_ticks) = nice_range(lo, hi, 4);
    let x_span = (0.0, max_trials as f64 + 1.0);
    let x_ticks: Vec<f64> = nice_ticks(1.0, max_trials as f64, 5)
        .into_iter()
        .filter(|t| *t >= 1.0 && (t - t.round()).abs() < 1e-9)
        .collect();
    let x_ticks = labelled(&x_ticks, tick_label);
    let y_ticks = labelled(&y_ticks, tick_label);
    let rects = grid(
        n,
        cols,
        (LEFT + 6.0, TITLE_H + PANEL_TITLE_H, W - RIGHT),
        STAIR_PANEL_H,
        (12.0, PANEL_TITLE_H + TICKS_H),
    );
    for (i, (track, (l, t, r, b))) in shown.iter().zip(rects.iter().copied()).enumerate() {
        let f = Frame {
            left: l * c.s,
            top: t * c.s,
            right: r * c.s,
            bottom: b * c.s,
            x: x_span,
            y: y_span,
            pad: 0.0,
        }
        .padded(MARKER_PAD * c.s);
        draw_axes(
            root,
            c,
            &f,
            &x_ticks,
            &y_ticks,
            Labels {
                x: true,
                y: i % cols == 0,
            },
        )?;
        let threshold = track.threshold(last_reversals);
        root.draw_text(
            &staircase_title(track, subjects, threshold),
            &c.font(9.0).pos(Pos::new(HPos::Center, VPos::Bottom)),
            (c.p(f64::midpoint(l, r)), c.p(t - 3.0)),
        )?;
        if let Some(th) = threshold {
            let (_, y) = f.px(0.0, th);
            let (left, _, right, _) = f.outer();
            root.draw(&PathElement::new(
                vec![round((left, y)), round((right, y))],
                THRESHOLD.stroke_width(c.w(1.5)),
            ))?;
        }
        draw_track(root, c, &f, track)?;
    }
    let rows = n.div_ceil(cols);
    let bottom = TITLE_H + rows as f64 * (PANEL_TITLE_H + STAIR_PANEL_H + TICKS_H);
    draw_titles(
        root,
        c,
        title,
        ("Trial", bottom + 1.0, (LEFT + 6.0, W - RIGHT)),
        (
            level_label,
            6.0,
            (TITLE_H + PANEL_TITLE_H, bottom - TICKS_H),
        ),
    )?;
    let legend_top = bottom + AXIS_TITLE_H + 6.0;
    draw_legend(root, c, legend_top, &staircase_legend(last_reversals))?;
    if tracks.len() > MAX_STAIRCASE_PANELS {
        let labels: Vec<String> = staircase_legend(last_reversals)
            .into_iter()
            .map(|e| e.1)
            .collect();
        root.draw_text(
            &format!(
                "First {MAX_STAIRCASE_PANELS} of {} staircases shown; every threshold is in the table.",
                tracks.len()
            ),
            &c.font(9.5).pos(Pos::new(HPos::Center, VPos::Top)),
            (c.p(W / 2.0), c.p(legend_top + legend_height(&labels) + 4.0)),
        )?;
    }
    Ok(())
}

// Single-panel figures' layout.
const SINGLE_PLOT_H: f64 = 250.0;

/// The plot area of a single-panel figure, its data ranges [`MARKER_PAD`] inside the frame.
fn single_frame(c: Ctx, x: (f64, f64), y: (f64, f64)) -> Frame {
    Frame {
        left: (LEFT + 6.0) * c.s,
        top: TITLE_H * c.s,
        right: (W - RIGHT) * c.s,
        bottom: (TITLE_H + SINGLE_PLOT_H) * c.s,
        x,
        y,
        pad: 0.0,
    }
    .padded(MARKER_PAD * c.s)
}

fn single_height(legend: &[String]) -> f64 {
    TITLE_H + SINGLE_PLOT_H + TICKS_H + AXIS_TITLE_H + 6.0 + legend_height(legend) + 8.0
}

fn single_titles<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    title: &str,
    x_label: &str,
    y_label: &str,
) -> DrawResult<DB> {
    draw_titles(
        root,
        c,
        title,
        (
            x_label,
            TITLE_H + SINGLE_PLOT_H + TICKS_H + 1.0,
            (LEFT + 6.0, W - RIGHT),
        ),
        (y_label, 6.0, (TITLE_H, TITLE_H + SINGLE_PLOT_H)),
    )
}

fn legend_top_single() -> f64 {
    TITLE_H + SINGLE_PLOT_H + TICKS_H + AXIS_TITLE_H + 6.0
}

fn psychometric_legend(
    fit: &PsychometricFit,
    data: &GroupedTrials,
    threshold: Option<(f64, f64, f64, f64)>,
    band: Option<&CurveBand>,
) -> Vec<(Key, String)> {
    let (nmin, nmax) = data
        .levels
        .iter()
        .filter(|l| l.1 > 0)
        .fold((u32::MAX, 0), |(a, b), l| (a.min(l.1), b.max(l.1)));
    let mut entries = vec![
        (
            Key::Dot {
                color: PALETTE[1],
                open: false,
                ring: false,
            },
            format!(
                "proportion correct (area ∝ trials, {}–{nmax})",
                nmin.min(nmax)
            ),
        ),
        (
            Key::Line {
                color: PALETTE[0],
                dash: &[],
                width: 2.0,
                marker: None,
            },
            format!(
                "{:?} fit (α = {}, β = {:.2}, λ = {:.3})",
                fit.shape,
                sig3(fit.alpha),
                fit.beta,
                fit.lapse
            ),
        ),
    ];
    if let Some(b) = band {
        entries.push((
            Key::Band(PALETTE[0].mix(0.22)),
            format!("{:.0} % pointwise bootstrap band", b.confidence.percent()),
        ));
    }
    if let Some((pc, t, lo, hi)) = threshold {
        entries.push((
            Key::Line {
                color: INK,
                dash: &[],
                width: 1.5,
                marker: None,
            },
            format!(
                "threshold at {:.0} % = {} [{}, {}]",
                pc * 100.0,
                sig3(t),
                sig3(lo),
                sig3(hi)
            ),
        ));
    }
    entries.push((
        Key::Line {
            color: REFERENCE,
            dash: &[1.2, 2.2],
            width: 1.0,
            marker: None,
        },
        format!("chance ({})", tick_label(fit.guess_rate)),
    ));
    entries
}

/// The threshold at its criterion: a dashed drop line, the interval as a capped bar and a
/// diamond at the threshold.
fn draw_threshold_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    f: &Frame,
    (pc, t, lower, upper): (f64, f64, f64, f64),
) -> DrawResult<DB> {
    let (tx, ty) = f.px(t, pc);
    draw_dashed(
        root,
        c,
        &[(tx, f.outer().3), (tx, ty)],
        &[3.0, 2.0],
        INK.stroke_width(c.w(1.0)),
    )?;
    let (lx, _) = f.px(lower, pc);
    let (ux, _) = f.px(upper, pc);
    let bar = INK.stroke_width(c.w(1.5));
    root.draw(&PathElement::new(
        vec![round((lx, ty)), round((ux, ty))],
        bar,
    ))?;
    let cap = 4.0 * c.s;
    for x in [lx, ux] {
        root.draw(&PathElement::new(
            vec![round((x, ty - cap)), round((x, ty + cap))],
            bar,
        ))?;
    }
    draw_marker(root, round((tx, ty)), 3, 3.6 * c.s, INK, c.w(1.0))?;
    Ok(())
}

/// Draws the data, the fitted ψ with its band, and the threshold with its interval.
fn draw_psychometric<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    (title, level_label): (&str, &str),
    data: &GroupedTrials,
    fit: &PsychometricFit,
    threshold: Option<(f64, f64, f64, f64)>,
    band: Option<&CurveBand>,
) -> DrawResult<DB> {
    let mut lo = data.levels.first().map_or(0.0, |l| l.0);
    let mut hi = data.levels.last().map_or(1.0, |l| l.0);
    if let Some((_, t, a, b)) = threshold {
        for v in [t, a, b] {
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    let ((x0, x1), x_ticks) = nice_range(lo, hi, 6);
    let min_p = data
        .levels
        .iter()
        .filter(|l| l.1 > 0)
        .map(|l| f64::from(l.2) / f64::from(l.1))
        .fold(fit.guess_rate, f64::min);
    let y0 = ((min_p - 0.05) * 10.0).floor() / 10.0;
    let y_span = (y0.max(0.0), 1.0);
    let y_ticks = nice_ticks(y_span.0, 1.0, 5);
    let f = single_frame(c, (x0, x1), y_span);
    draw_axes(
        root,
        c,
        &f,
        &labelled(&x_ticks, tick_label),
        &labelled(&y_ticks, tick_label),
        Labels { x: true, y: true },
    )?;
    let (_, gy) = f.px(x0, fit.guess_rate);
    draw_dashed(
        root,
        c,
        &[(f.outer().0, gy), (f.outer().2, gy)],
        &[1.2, 2.2],
        REFERENCE.stroke_width(c.w(1.0)),
    )?;
    if let Some(b) = band {
        let pts: Vec<(i32, i32)> = b
            .points
            .iter()
            .filter(|p| p.0 >= x0 && p.0 <= x1)
            .map(|p| f.at(p.0, p.1))
            .chain(
                b.points
                    .iter()
                    .rev()
                    .filter(|p| p.0 >= x0 && p.0 <= x1)
                    .map(|p| f.at(p.0, p.2)),
            )
            .collect();
        if pts.len() >= 3 {
            root.draw(&Polygon::new(pts, PALETTE[0].mix(0.22).filled()))?;
        }
    }
    let steps = 240;
    let curve: Vec<(i32, i32)> = (0..=steps)
        .map(|i| {
            let x = x0 + (x1 - x0) * f64::from(i) / f64::from(steps);
            f.at(x, fit.probability(x).clamp(y_span.0, 1.0))
        })
        .collect();
    root.draw(&PathElement::new(curve, PALETTE[0].stroke_width(c.w(2.0))))?;
    let max_n = data.levels.iter().map(|l| l.1).max().unwrap_or(1).max(1);
    for &(x, n, k) in data.levels.iter().filter(|l| l.1 > 0) {
        let r = (7.0 * (f64::from(n) / f64::from(max_n)).sqrt()).max(1.5) * c.s;
        let at = f.at(x, f64::from(k) / f64::from(n));
        root.draw(&Circle::new(
            at,
            r.round() as u32,
            PALETTE[1].mix(0.75).filled(),
        ))?;
        root.draw(&Circle::new(
            at,
            r.round() as u32,
            WHITE.stroke_width(c.w(0.6)),
        ))?;
    }
    if let Some(th) = threshold {
        draw_threshold_bar(root, c, &f, th)?;
    }
    single_titles(root, c, title, level_label, "Proportion correct")?;
    draw_legend(
        root,
        c,
        legend_top_single(),
        &psychometric_legend(fit, data, threshold, band),
    )
}

fn jnd_legend(n: usize, model: bool) -> Vec<(Key, String)> {
    let mut entries = vec![(
        Key::Line {
            color: PALETTE[1],
            dash: &[],
            width: 1.8,
            marker: Some(0),
        },
        format!("empirical ({n} viewers, each threshold marked)"),
    )];
    if model {
        entries.push((
            Key::Line {
                color: PALETTE[0],
                dash: &[5.0, 3.0],
                width: 1.8,
                marker: None,
            },
            "normal model".to_owned(),
        ));
        entries.push((
            Key::Band(PALETTE[0].mix(0.2)),
            "its confidence band".to_owned(),
        ));
    }
    entries
}

/// Draws the share of viewers noticing each level: empirical steps and the normal model.
fn draw_jnd<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
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
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in sorted.iter().copied().chain(model.iter().map(|m| m.0)) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    // Levels are magnitudes: where every threshold is positive the axis starts at 0 and the
    // model's tail below it is not drawn.
    let positive = sorted.first().is_some_and(|t| *t > 0.0);
    if positive {
        lo = lo.max(0.0);
    }
    let ((x0, x1), x_ticks) = nice_range(lo, hi, 6);
    let model: Vec<(f64, f64, f64, f64)> = model
        .iter()
        .copied()
        .filter(|m| m.0 >= x0 && m.0 <= x1)
        .collect();
    let model = model.as_slice();
    let f = single_frame(c, (x0, x1), (0.0, 1.0));
    draw_axes(
        root,
        c,
        &f,
        &labelled(&x_ticks, tick_label),
        &labelled(&[0.0, 0.2, 0.4, 0.6, 0.8, 1.0], |v| tick_label(v * 100.0)),
        Labels { x: true, y: true },
    )?;
    if !model.is_empty() {
        let band: Vec<(i32, i32)> = model
            .iter()
            .map(|m| f.at(m.0, m.2))
            .chain(model.iter().rev().map(|m| f.at(m.0, m.3)))
            .collect();
        root.draw(&Polygon::new(band, PALETTE[0].mix(0.2).filled()))?;
        let line: Vec<(f64, f64)> = model.iter().map(|m| f.px(m.0, m.1)).collect();
        draw_dashed(
            root,
            c,
            &line,
            &[5.0, 3.0],
            PALETTE[0].stroke_width(c.w(1.8)),
        )?;
    }
    // Empirical CDF: the share noticing steps up by 1/n at each threshold.
    let n = sorted.len().max(1) as f64;
    let mut steps = vec![f.at(x0, 0.0)];
    for (i, &t) in sorted.iter().enumerate() {
        steps.push(f.at(t, i as f64 / n));
        steps.push(f.at(t, (i + 1) as f64 / n));
    }
    steps.push(f.at(x1, if sorted.is_empty() { 0.0 } else { 1.0 }));
    root.draw(&PathElement::new(steps, PALETTE[1].stroke_width(c.w(1.8))))?;
    for (i, &t) in sorted.iter().enumerate() {
        draw_marker(
            root,
            f.at(t, (i + 1) as f64 / n),
            0,
            2.6 * c.s,
            PALETTE[1],
            c.w(1.0),
        )?;
    }
    single_titles(root, c, title, level_label, "Viewers who notice (%)")?;
    draw_legend(
        root,
        c,
        legend_top_single(),
        &jnd_legend(sorted.len(), !model.is_empty()),
    )
}

/// Draws each subject's scores as dots of area ∝ count with the subject's mean.
fn draw_distributions<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    title: &str,
    per_subject: &[(String, Vec<f64>)],
    y_range: Option<(f64, f64)>,
) -> DrawResult<DB> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in per_subject.iter().flat_map(|s| s.1.iter()) {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    let (y_span, y_ticks) = match y_range {
        Some((a, b)) if b > a && lo >= a && hi <= b => ((a, b), nice_ticks(a, b, 5)),
        _ => nice_range(lo, hi, 5),
    };
    let columns = per_subject.len().max(1);
    // A dot's radius is up to 9 units: the frame stands clear of the largest at the scale's ends.
    let f = single_frame(c, (-0.6, columns as f64 - 0.4), y_span).padded(4.0 * c.s);
    let every = columns.div_ceil(25);
    let x_ticks: Vec<(f64, String)> = per_subject
        .iter()
        .enumerate()
        .filter(|(i, _)| i % every == 0)
        .map(|(i, s)| (i as f64, s.0.clone()))
        .collect();
    draw_axes(
        root,
        c,
        &f,
        &x_ticks,
        &labelled(&y_ticks, tick_label),
        Labels { x: true, y: true },
    )?;
    let spacing = (f.right - f.left) / (columns as f64 + 0.2);
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
        let r_max = (0.45 * spacing).min(9.0 * c.s);
        for &(v, k) in &counts {
            let r = (r_max * (k as f64 / total).sqrt()).max(1.2 * c.s);
            root.draw(&Circle::new(
                f.at(i as f64, v),
                r.round() as u32,
                PALETTE[0].mix(0.6).filled(),
            ))?;
        }
        if !scores.is_empty() {
            let mean = scores.iter().sum::<f64>() / total;
            root.draw(&PathElement::new(
                vec![f.at(i as f64 - 0.35, mean), f.at(i as f64 + 0.35, mean)],
                INK.stroke_width(c.w(1.8)),
            ))?;
        }
    }
    single_titles(root, c, title, "Subject", "Score")?;
    draw_legend(
        root,
        c,
        legend_top_single(),
        &[
            (
                Key::Dot {
                    color: PALETTE[0],
                    open: false,
                    ring: false,
                },
                "scores (area ∝ share of the subject's ratings)".to_owned(),
            ),
            (
                Key::Line {
                    color: INK,
                    dash: &[],
                    width: 1.8,
                    marker: None,
                },
                "subject's mean".to_owned(),
            ),
        ],
    )
}

// Forest plots' layout, in layout units.
const FOREST_FONT: f64 = 9.0;
/// Height of a one-line row.
const FOREST_ROW_H: f64 = 20.0;
/// Height of each further line of a wrapped label.
const FOREST_LINE_H: f64 = 11.0;
/// The widest a label column may grow: a longer name wraps onto more lines.
const FOREST_LABEL_MAX: f64 = 0.55 * W;
/// Space between the frame and the plot's top and bottom rows.
const FOREST_PAD: f64 = 6.0;
/// The space right of a row label: tick, gap, and the tick label's offset.
const FOREST_LABEL_GAP: f64 = 3.5 + 2.0 + 4.0;

/// Splits `name` into lines no wider than `max` at [`FOREST_FONT`]: after a `:` or a space
/// where one falls in the line, else between characters. Every character is kept, in order
/// (a line's trailing space included), so the lines joined are the name; a line is drawn
/// without its trailing space.
fn wrap_label(name: &str, max: f64) -> Vec<String> {
    let mut lines = Vec::new();
    let mut rest: &str = name;
    while !rest.is_empty() {
        if text_width(rest, FOREST_FONT) <= max {
            lines.push(rest.to_owned());
            break;
        }
        // The longest prefix that fits (at least one character).
        let ends: Vec<usize> = rest
            .char_indices()
            .map(|(i, ch)| i + ch.len_utf8())
            .collect();
        let fit = ends
            .iter()
            .copied()
            .take_while(|&e| text_width(&rest[..e], FOREST_FONT) <= max)
            .last()
            .unwrap_or(ends[0]);
        let cut = rest[..fit]
            .char_indices()
            .filter(|&(i, ch)| (ch == ':' || ch == ' ') && i > 0)
            .map(|(i, ch)| i + ch.len_utf8())
            .next_back()
            .filter(|&c| c < fit)
            .unwrap_or(fit);
        lines.push(rest[..cut].to_owned());
        rest = &rest[cut..];
    }
    if lines.is_empty() {
        lines.push(String::new());
    }
    lines
}

/// A forest plot's rows, labels and label column.
#[derive(Debug)]
struct ForestLayout {
    /// Each row's label lines.
    labels: Vec<Vec<String>>,
    /// Left edge of the frame.
    left: f64,
    /// Each row's centre, from the frame's top, and the frame's inner height.
    centres: Vec<f64>,
    plot_h: f64,
}

impl ForestLayout {
    fn new(rows: &[(String, f64, f64, f64)]) -> Self {
        let labels: Vec<Vec<String>> = rows
            .iter()
            .map(|r| wrap_label(&r.0, FOREST_LABEL_MAX))
            .collect();
        let widest = labels
            .iter()
            .flatten()
            .map(|l| text_width(l, FOREST_FONT))
            .fold(0.0, f64::max);
        let left = (widest + FOREST_LABEL_GAP + 8.0).max(LEFT + 6.0);
        let mut centres = Vec::with_capacity(rows.len());
        let mut y = FOREST_PAD;
        for l in &labels {
            let h = FOREST_ROW_H + FOREST_LINE_H * (l.len().max(1) - 1) as f64;
            centres.push(y + h / 2.0);
            y += h;
        }
        Self {
            labels,
            left,
            centres,
            plot_h: (y + FOREST_PAD).max(2.0 * FOREST_PAD + FOREST_ROW_H),
        }
    }
    fn height(&self) -> f64 {
        TITLE_H + self.plot_h + TICKS_H + AXIS_TITLE_H + 10.0
    }
}

/// The x span and ticks of a forest plot: 0 and every finite estimate and CI end.
fn forest_x_range(rows: &[(String, f64, f64, f64)]) -> ((f64, f64), Vec<f64>) {
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for v in rows.iter().flat_map(|r| [r.1, r.2, r.3]) {
        if v.is_finite() {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    nice_range(lo, hi, 6)
}

/// Draws a forest plot: labels left of the frame, a dot and whisker per row, 0 marked.
fn draw_forest<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: Ctx,
    title: &str,
    x_label: &str,
    rows: &[(String, f64, f64, f64)],
) -> DrawResult<DB> {
    let layout = ForestLayout::new(rows);
    let (x_span, x_ticks) = forest_x_range(rows);
    let f = Frame {
        left: layout.left * c.s,
        top: TITLE_H * c.s,
        right: (W - RIGHT) * c.s,
        bottom: (TITLE_H + layout.plot_h) * c.s,
        x: x_span,
        // Rows are placed in pixels; y spans the frame one to one.
        y: (0.0, layout.plot_h),
        pad: 0.0,
    }
    .padded(MARKER_PAD * c.s);
    // The y "ticks": each row's centre, as a data value measured up from the bottom.
    let row_y = |i: usize| layout.plot_h - layout.centres[i];
    let y_ticks: Vec<(f64, String)> = (0..rows.len()).map(|i| (row_y(i), String::new())).collect();
    draw_axes(
        root,
        c,
        &f,
        &labelled(&x_ticks, tick_label),
        &y_ticks,
        Labels { x: true, y: false },
    )?;
    let (_, t, _, b) = f.outer();
    let (zero, _) = f.px(0.0, 0.0);
    root.draw(&PathElement::new(
        vec![round((zero, t)), round((zero, b))],
        REFERENCE.stroke_width(c.w(1.0)),
    ))?;
    let style = c.font(FOREST_FONT);
    let (l, ..) = f.outer();
    for (i, (row, lines)) in rows.iter().zip(&layout.labels).enumerate() {
        let (_, y) = f.px(0.0, row_y(i));
        let first = y - FOREST_LINE_H * c.s * (lines.len() as f64 - 1.0) / 2.0;
        for (k, line) in lines.iter().enumerate() {
            root.draw_text(
                line.trim_end(),
                &style.pos(Pos::new(HPos::Right, VPos::Center)),
                round((
                    l - (3.5 + 2.0) * c.s,
                    first + FOREST_LINE_H * c.s * k as f64,
                )),
            )?;
        }
        let (_, estimate, lower, upper) = *row;
        if lower.is_finite() && upper.is_finite() {
            let (x0, _) = f.px(lower, 0.0);
            let (x1, _) = f.px(upper, 0.0);
            let cap = 3.5 * c.s;
            let ink = PALETTE[0].stroke_width(c.w(1.4));
            root.draw(&PathElement::new(vec![round((x0, y)), round((x1, y))], ink))?;
            for x in [x0, x1] {
                root.draw(&PathElement::new(
                    vec![round((x, y - cap)), round((x, y + cap))],
                    ink,
                ))?;
            }
        }
        if estimate.is_finite() {
            let (x, _) = f.px(estimate, 0.0);
            root.draw(&Circle::new(
                round((x, y)),
                c.w(MARKER_R),
                PALETTE[0].filled(),
            ))?;
        }
    }
    // The title and x axis title as [`draw_titles`] draws them; the labels name the rows, so
    // there is no y axis title.
    root.draw_text(
        title,
        &TextStyle::from((FONT, 13.0 * c.s, FontStyle::Bold).into_font())
            .color(&INK)
            .pos(Pos::new(HPos::Center, VPos::Top)),
        (c.p(W / 2.0), c.p(7.0)),
    )?;
    root.draw_text(
        x_label,
        &c.font(10.5).pos(Pos::new(HPos::Center, VPos::Top)),
        (
            c.p(f64::midpoint(layout.left, W - RIGHT)),
            c.p(TITLE_H + layout.plot_h + TICKS_H + 1.0),
        ),
    )?;
    Ok(())
}

impl Figure {
    /// The figure's title.
    pub fn title(&self) -> &str {
        match self {
            Self::RateCurves { title, .. }
            | Self::CrowdCurves { title, .. }
            | Self::Staircases { title, .. }
            | Self::Psychometric { title, .. }
            | Self::Jnd { title, .. }
            | Self::ScoreDistributions { title, .. }
            | Self::Forest { title, .. } => title,
        }
    }

    /// The figure's size in inches (6.5 wide; as tall as its panels and legend need).
    pub fn size_in(&self) -> (f64, f64) {
        let h = match self {
            Self::RateCurves { series, limit, .. } => RateLayout::new(series, *limit).height(),
            Self::CrowdCurves { series, .. } => RateLayout::new(series, None).height(),
            Self::Staircases {
                tracks,
                last_reversals,
                ..
            } => staircase_height(tracks.len(), *last_reversals),
            Self::Psychometric {
                data,
                fit,
                threshold,
                band,
                ..
            } => single_height(
                &psychometric_legend(fit, data, *threshold, band.as_ref())
                    .into_iter()
                    .map(|e| e.1)
                    .collect::<Vec<_>>(),
            ),
            Self::Jnd {
                thresholds, model, ..
            } => single_height(
                &jnd_legend(thresholds.len(), !model.is_empty())
                    .into_iter()
                    .map(|e| e.1)
                    .collect::<Vec<_>>(),
            ),
            Self::ScoreDistributions { .. } => single_height(&["a".to_owned()]),
            Self::Forest { rows, .. } => ForestLayout::new(rows).height(),
        };
        (WIDTH_IN, h / SVG_UNITS_PER_IN)
    }

    /// Pixel size at `per_inch` pixels per inch.
    fn pixels(&self, per_inch: f64) -> (u32, u32) {
        let (w, h) = self.size_in();
        ((w * per_inch).round() as u32, (h * per_inch).round() as u32)
    }

    /// The PNG's pixel size: [`Self::size_in`] at [`PNG_DPI`].
    pub fn png_size(&self) -> (u32, u32) {
        self.pixels(PNG_DPI)
    }

    /// Draws to an SVG document in memory, 100 user units per inch.
    ///
    /// # Errors
    /// [`AnalysisError::Plot`] when the font cannot be registered or drawing fails.
    pub fn render_svg(&self) -> Result<String, AnalysisError> {
        ensure_font()?;
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, self.pixels(SVG_UNITS_PER_IN))
                .into_drawing_area();
            self.draw(&root, Ctx { s: 1.0 })
                .map_err(|e| self.plot_error(&e))?;
            root.present().map_err(|e| self.plot_error(&e))?;
        }
        Ok(svg)
    }

    /// Draws to a PNG image in memory (8-bit RGB, 300 dpi recorded in `pHYs`), for the caller
    /// to write whole ([`files::write`]); plotters' own PNG writer would create the file in
    /// place.
    ///
    /// # Errors
    /// [`AnalysisError::Plot`] when the font cannot be registered, drawing or encoding fails.
    pub fn render_png(&self) -> Result<Vec<u8>, AnalysisError> {
        let (w, h, rgb) = self.render_rgb()?;
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Fast);
        let per_metre = (PNG_DPI / 0.0254).round() as u32;
        encoder.set_pixel_dims(Some(png::PixelDimensions {
            xppu: per_metre,
            yppu: per_metre,
            unit: png::Unit::Meter,
        }));
        encoder
            .write_header()
            .and_then(|mut writer| {
                writer.write_image_data(&rgb)?;
                writer.finish()
            })
            .map_err(|e| self.plot_error(&e))?;
        Ok(out)
    }

    /// The 300-dpi drawing as (width, height, RGB bytes).
    fn render_rgb(&self) -> Result<(u32, u32, Vec<u8>), AnalysisError> {
        ensure_font()?;
        let (w, h) = self.png_size();
        let mut rgb = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
            self.draw(
                &root,
                Ctx {
                    s: PNG_DPI / SVG_UNITS_PER_IN,
                },
            )
            .map_err(|e| self.plot_error(&e))?;
            root.present().map_err(|e| self.plot_error(&e))?;
        }
        Ok((w, h, rgb))
    }

    fn plot_error(&self, e: &dyn std::fmt::Display) -> AnalysisError {
        AnalysisError::Plot {
            name: self.title().to_owned(),
            message: e.to_string(),
        }
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, c: Ctx) -> DrawResult<DB> {
        root.fill(&WHITE)?;
        match self {
            Self::RateCurves {
                title,
                y_label,
                series,
                limit,
                y_range,
            } => draw_rate(root, c, title, y_label, series, *limit, *y_range, RATE_AXES),
            Self::CrowdCurves {
                title,
                y_label,
                x_label,
                panel: _,
                series,
                y_range,
            } => draw_rate(
                root,
                c,
                title,
                y_label,
                series,
                None,
                *y_range,
                RateAxes {
                    x_label,
                    panel_prefix: "",
                },
            ),
            Self::Staircases {
                title,
                level_label,
                tracks,
                last_reversals,
                subjects,
            } => draw_staircases(
                root,
                c,
                title,
                level_label,
                tracks,
                *last_reversals,
                subjects,
            ),
            Self::Psychometric {
                title,
                level_label,
                data,
                fit,
                threshold,
                band,
            } => draw_psychometric(
                root,
                c,
                (title, level_label),
                data,
                fit,
                *threshold,
                band.as_ref(),
            ),
            Self::Jnd {
                title,
                level_label,
                thresholds,
                model,
            } => draw_jnd(root, c, title, level_label, thresholds, model),
            Self::ScoreDistributions {
                title,
                per_subject,
                y_range,
            } => draw_distributions(root, c, title, per_subject, *y_range),
            Self::Forest {
                title,
                x_label,
                rows,
            } => draw_forest(root, c, title, x_label, rows),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn rate_figure() -> Figure {
        Figure::RateCurves {
            title: "MOS vs compression ratio".to_owned(),
            y_label: "MOS".to_owned(),
            series: vec![RateSeries {
                label: "a".to_owned(),
                clip: "walk".to_owned(),
                points: vec![(20.0, 4.5, 4.3, 4.7), (40.0, 3.5, 3.2, 3.8)],
            }],
            limit: Some(4.5),
            y_range: Some((1.0, 5.0)),
        }
    }

    /// The caption is drawn with the embedded font into the bitmap: the band above the plot
    /// area, where only the title is, must hold dark pixels. Without a usable font plotters
    /// would fail or leave it white.
    #[test]
    fn png_text_renders_without_system_fonts() {
        let figure = rate_figure();
        let (w, _, buffer) = figure.render_rgb().unwrap();
        let dark_in_title_band = (0..60u32)
            .flat_map(|y| (0..w).map(move |x| ((y * w + x) * 3) as usize))
            .filter(|&i| buffer[i] < 100 && buffer[i + 1] < 100 && buffer[i + 2] < 100)
            .count();
        assert!(
            dark_in_title_band > 600,
            "title pixels: {dark_in_title_band}"
        );
        let svg = figure.render_svg().unwrap();
        assert!(svg.contains("<text") && svg.contains("MOS vs compression ratio"));
    }

    #[test]
    fn tick_labels_are_integers_where_the_values_are() {
        assert_eq!(tick_label(10.0), "10");
        assert_eq!(tick_label(-0.0), "0");
        assert_eq!(tick_label(2.5), "2.5");
        assert_eq!(tick_label(0.0125), "0.0125");
        assert_eq!(tick_label(0.1 + 0.2), "0.3");
        assert_eq!(sig3(0.011_662), "0.0117");
        assert_eq!(sig3(0.006_666_7), "0.00667");
        assert_eq!(sig3(123.456), "123");
        assert_eq!(sig3(0.0125), "0.0125");
    }

    #[test]
    fn nice_ticks_cover_the_scale() {
        assert_eq!(nice_ticks(1.0, 5.0, 5), vec![1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(
            nice_ticks(0.0, 100.0, 5),
            vec![0.0, 20.0, 40.0, 60.0, 80.0, 100.0]
        );
        let ((a, b), t) = nice_range(0.013, 0.047, 4);
        assert!(a <= 0.013 && b >= 0.047 && t.len() >= 3, "{a} {b} {t:?}");
    }

    #[test]
    fn dashes_alternate_along_the_path() {
        let pieces = dash_pieces(&[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)], |p| p, &[3.0, 1.0]);
        // 20 px of path in 4 px periods: five drawn pieces of 3 px.
        assert_eq!(pieces.len(), 5, "{pieces:?}");
        let len = |p: &Vec<(f64, f64)>| {
            p.windows(2)
                .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
                .sum::<f64>()
        };
        for p in &pieces {
            assert!((len(p) - 3.0).abs() < 1e-9, "{p:?}");
        }
        // The piece across the corner keeps the corner.
        assert_eq!(pieces[2], vec![(8.0, 0.0), (10.0, 0.0), (10.0, 1.0)]);
    }

    #[test]
    fn series_styles_are_distinct_triples() {
        let styles: BTreeSet<SeriesStyle> = (0..49).map(series_style).collect();
        assert_eq!(styles.len(), 49);
        for i in 0..48 {
            let (a, b) = (series_style(i), series_style(i + 1));
            assert!(a.color != b.color && a.marker != b.marker && a.dash != b.dash);
        }
    }
}
