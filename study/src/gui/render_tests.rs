//! The renderer offscreen: a known pose drawn into a texture must match the stored reference
//! image (`study/tests/data/render-reference.png`) within a small per-pixel tolerance.
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
