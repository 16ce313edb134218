//! The renderer offscreen: a known pose drawn into a texture must match the stored reference
//! image (`window/tests/data/render-reference.png`) within a small per-pixel tolerance.
//!
//! Needs a Vulkan driver (Mesa's lavapipe on a machine without a GPU: `scripts/test` installs
//! it). Without one the test fails under `CI` and is skipped with a message elsewhere.
//! `UPDATE_REFERENCE=1` rewrites the reference after an intended change of the drawing.

use std::path::PathBuf;

use super::render::{BACKGROUND, Image, Offscreen, Pane};
use super::scene::{Figure, FrameShapes, View};

const W: u32 = 480;
const H: u32 = 240;

fn reference_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/render-reference.png")
}

fn offscreen() -> Option<Offscreen> {
    match Offscreen::new(1) {
        Ok(o) => Some(o),
        Err(e) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "no graphics adapter under CI: {e:#}"
            );
            eprintln!("skipping the offscreen render test: {e:#}");
            None
        }
    }
}

/// The generated walk at 0.5 s, twice side by side (the right one a quarter second later).
fn render(o: &mut Offscreen) -> Image {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let view = View::framing(&clip);
    let mut fig = Figure::new(&clip, &view);
    let (mut a, mut b) = (FrameShapes::default(), FrameShapes::default());
    fig.shapes_at(0.5, &mut a);
    fig.shapes_at(0.75, &mut b);
    let pane = |x, shapes| Pane {
        x,
        y: 0,
        width: W / 2,
        height: H,
        view: &view,
        shapes,
    };
    o.render(W, H, &[pane(0, &a), pane(W / 2, &b)]).unwrap()
}

fn is_background(p: [u8; 4]) -> bool {
    BACKGROUND
        .iter()
        .zip(p)
        .all(|(c, v)| (f32::from(v) - c * 255.0).abs() <= 2.0)
}

#[test]
fn a_known_pose_matches_the_reference_image() {
    let Some(mut o) = offscreen() else { return };
    let img = render(&mut o);
    // Both skeletons are drawn: joint orange in each half.
    for half in 0..2 {
        let orange = (0..H)
            .flat_map(|y| (half * W / 2..(half + 1) * W / 2).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let p = img.pixel(x, y);
                i32::from(p[0]) - i32::from(p[2]) > 60
            })
            .count();
        assert!(orange > 40, "half {half}: {orange} joint pixels");
    }
    let path = reference_path();
    if std::env::var_os("UPDATE_REFERENCE").is_some() {
        img.write_png(&path, files::Mode::Replace).unwrap();
        eprintln!("wrote {}", path.display());
        return;
    }
    let reference = Image::read_png(&path).unwrap();
    assert_eq!((reference.width, reference.height), (W, H));
    // Per pixel, every channel within 24 levels; rasterisers may place an edge pixel
    // differently, so at most 0.1 % of the pixels may differ more (a wrongly shaded bone
    // set alone changes more than that).
    let mut off = 0usize;
    let mut drawn = 0usize;
    for y in 0..H {
        for x in 0..W {
            let (p, q) = (img.pixel(x, y), reference.pixel(x, y));
            if !is_background(q) {
                drawn += 1;
            }
            if p.iter().zip(q).any(|(a, b)| a.abs_diff(b) > 24) {
                off += 1;
            }
        }
    }
    let limit = (W * H) as usize / 1000;
    assert!(
        off <= limit,
        "{off} pixels differ from {} (limit {limit}); adapter {:?}",
        path.display(),
        o.adapter().name
    );
    assert!(drawn > (W * H) as usize / 10, "the reference shows a scene");
}

#[test]
fn a_frame_differs_from_a_different_pose() {
    let Some(mut o) = offscreen() else { return };
    let a = render(&mut o);
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let view = View::framing(&clip);
    let mut fig = Figure::new(&clip, &view);
    let mut s = FrameShapes::default();
    fig.shapes_at(0.1, &mut s);
    let pane = Pane {
        x: 0,
        y: 0,
        width: W / 2,
        height: H,
        view: &view,
        shapes: &s,
    };
    let b = o.render(W, H, &[pane]).unwrap();
    let differing = a
        .rgba
        .chunks(4)
        .zip(b.rgba.chunks(4))
        .filter(|(p, q)| p != q)
        .count();
    assert!(differing > 500, "only {differing} pixels changed");
}

/// A pane of a side-by-side trial on a 1280×720 window: narrower than it is tall.
const PANE_W: u32 = 300;
const PANE_H: u32 = 340;

/// Figure colour of the measuring renders: pure red, so every figure pixel, however shaded,
/// has no green or blue, which the grey ground, its shadow and the background always have.
const MARK: [f32; 4] = [1.0, 0.0, 0.0, 1.0];

fn is_figure(p: [u8; 4]) -> bool {
    p[1] <= 2 && p[2] <= 2
}

/// `clip` at `t` in one pane, the figure marked red (no bone or joint is red otherwise).
fn render_marked(o: &mut Offscreen, view: &View, fig: &mut Figure, t: f64) -> Image {
    let mut s = FrameShapes::default();
    fig.shapes_at(t, &mut s);
    for i in s.bones.iter_mut().chain(&mut s.joints) {
        i.color = MARK;
    }
    let pane = Pane {
        x: 0,
        y: 0,
        width: PANE_W,
        height: PANE_H,
        view,
        shapes: &s,
    };
    o.render(PANE_W, PANE_H, &[pane]).unwrap()
}

/// Rows from the figure's highest to its lowest pixel, inclusive.
fn figure_rows(img: &Image) -> u32 {
    let rows: Vec<u32> = (0..img.height)
        .filter(|&y| (0..img.width).any(|x| is_figure(img.pixel(x, y))))
        .collect();
    match (rows.first(), rows.last()) {
        (Some(a), Some(b)) => b - a + 1,
        _ => 0,
    }
}

/// The walks the figure-size test measures: the generated one (4.8 m in 4 s) and, with
/// `MOCAP_DATA`, CMU 02_01 (a walk of about 3 s).
fn walks() -> Vec<(String, motion::Clip)> {
    let mut v = vec![(
        "generated walk".to_string(),
        motion::synth::walking_clip(&motion::synth::WalkParams::default()),
    )];
    if let Some(d) = motion::data::mocap_dir() {
        let clip = motion::io::read_clip(Some(&d.join("12.asf")), &d.join("02_01.amc")).unwrap();
        v.push(("CMU 02_01".to_string(), clip));
    }
    v
}

#[test]
fn a_walking_figure_keeps_at_least_60_percent_of_the_viewport_height_along_its_path() {
    let Some(mut o) = offscreen() else { return };
    for (name, clip) in walks() {
        let view = View::framing(&clip).with_shadow(false);
        let mut fig = Figure::new(&clip, &view);
        let duration = fig.duration_s();
        let positions = motion::fk::positions(&clip);
        let root = |t: f64| {
            let f = ((t * clip.frame_rate_hz) as usize).min(positions.frames() - 1);
            positions.frame(f)[0]
        };
        let (start, end) = (root(0.0), root(duration));
        let travelled = ((end[0] - start[0]).powi(2) + (end[2] - start[2]).powi(2)).sqrt();
        assert!(
            travelled > f64::from(view.figure_height),
            "{name}: the clip walks {travelled} units, not a path to follow"
        );
        let mut smallest = f64::INFINITY;
        let samples = 12;
        for k in 0..=samples {
            let t = duration * f64::from(k) / f64::from(samples);
            let img = render_marked(&mut o, &view, &mut fig, t);
            let share = f64::from(figure_rows(&img)) / f64::from(PANE_H);
            eprintln!(
                "{name}: t = {t:.2} s, figure {:.1} % of the height",
                share * 100.0
            );
            smallest = smallest.min(share);
            assert!(
                share >= 0.6,
                "{name} at {t:.2} s: the figure is {:.1} % of the viewport height",
                share * 100.0
            );
            // Inside the pane: nothing of the figure on its border.
            let border = (0..PANE_W)
                .flat_map(|x| [(x, 0), (x, PANE_H - 1)])
                .chain((0..PANE_H).flat_map(|y| [(0, y), (PANE_W - 1, y)]))
                .filter(|&(x, y)| is_figure(img.pixel(x, y)))
                .count();
            assert_eq!(
                border, 0,
                "{name} at {t:.2} s: the figure is cut by the pane"
            );
        }
        eprintln!("{name}: smallest figure {:.1} %", smallest * 100.0);
    }
}

#[test]
fn the_ground_shadow_is_drawn_when_on_and_absent_when_off() {
    let Some(mut o) = offscreen() else { return };
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let t = 1.3;
    // The ground alone at that time (same camera), then the figure with and without shadow.
    let empty = {
        let view = View::framing(&clip);
        let s = FrameShapes {
            time_s: t,
            ..FrameShapes::default()
        };
        let pane = Pane {
            x: 0,
            y: 0,
            width: PANE_W,
            height: PANE_H,
            view: &view,
            shapes: &s,
        };
        o.render(PANE_W, PANE_H, &[pane]).unwrap()
    };
    // Shadow pixels: not the figure, and darker than the bare ground there.
    let shadow_pixels = |img: &Image| {
        let mut n = 0usize;
        let mut lowest_figure = 0;
        let mut lowest_shadow = 0;
        for y in 0..PANE_H {
            for x in 0..PANE_W {
                let (p, q) = (img.pixel(x, y), empty.pixel(x, y));
                if is_figure(p) {
                    lowest_figure = lowest_figure.max(y);
                } else if (0..3).all(|c| i32::from(q[c]) - i32::from(p[c]) >= 8) {
                    n += 1;
                    lowest_shadow = lowest_shadow.max(y);
                }
            }
        }
        (n, lowest_figure, lowest_shadow)
    };
    let mut measure = |on: bool| {
        let view = View::framing(&clip).with_shadow(on);
        let mut fig = Figure::new(&clip, &view);
        render_marked(&mut o, &view, &mut fig, t)
    };
    let (on, off) = (measure(true), measure(false));
    let (n_on, feet, lowest) = shadow_pixels(&on);
    let (n_off, _, _) = shadow_pixels(&off);
    eprintln!("shadow pixels: {n_on} on, {n_off} off");
    assert!(n_on > 300, "only {n_on} shadow pixels with the shadow on");
    assert_eq!(n_off, 0, "{n_off} shadow pixels with the shadow off");
    // It lies on the ground at the feet, not somewhere up the figure.
    assert!(
        lowest + 25 >= feet,
        "the shadow ends at row {lowest}, the feet at {feet}"
    );
}
