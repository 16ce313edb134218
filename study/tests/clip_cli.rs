//! `study clip ...` end to end, as a user runs it.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = study(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn data(name: &str) -> String {
    motion::data::mocap_dir()
        .map_or_else(
            || PathBuf::from("/nonexistent").join(name),
            |d| d.join(name),
        )
        .display()
        .to_string()
}

fn have_data() -> bool {
    motion::data::mocap_dir().is_some()
}

fn tmp() -> PathBuf {
    let d = std::env::temp_dir().join(format!("study-cli-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn info_reports_frames_rate_and_dof() {
    if !have_data() {
        return;
    }
    let s = ok(&[
        "clip",
        "info",
        "--asf",
        &data("12.asf"),
        "--amc",
        &data("02_01.amc"),
    ]);
    assert!(s.contains("DOF         62 channels"), "{s}");
    assert!(s.contains("frames      343"), "{s}");
    assert!(s.contains("frame rate  120.0000 Hz"), "{s}");
    assert!(s.contains("5.6444 cm (declared by the file)"), "{s}");
    let s = ok(&["clip", "info", &data("131_01.bvh")]);
    assert!(s.contains("DOF         96 channels"), "{s}");
    assert!(s.contains("frames      994"), "{s}");
    assert!(s.contains("frame rate  120.0005 Hz"), "{s}");
    assert!(
        s.contains("is constant"),
        "the BVH's finger channels never move: {s}"
    );
    // Several clips at once, with the ASF given positionally.
    let s = ok(&[
        "clip",
        "info",
        &data("charleston.asf"),
        &data("charleston1.amc"),
    ]);
    assert!(s.contains("frames      506"), "{s}");
}

#[test]
fn info_on_the_demo_needs_no_files() {
    let s = ok(&["clip", "info", "--demo"]);
    assert!(
        s.contains("demo-walk") && s.contains("frames      480"),
        "{s}"
    );
}

#[test]
fn positions_csv_has_one_row_per_joint_and_frame_with_file_names() {
    let out = tmp().join("pos.csv");
    let o = out.display().to_string();
    if have_data() {
        ok(&["clip", "positions", &data("131_01.bvh"), "--csv", &o]);
        let text = std::fs::read_to_string(&out).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("frame,joint,x,y,z"));
        assert!(
            lines
                .next()
                .unwrap()
                .starts_with("0,Hips,5.23,16.9002,-33.8986")
        );
        assert!(text.contains(",LeftToe_End,"));
        assert_eq!(text.lines().count(), 1 + 994 * 38);
    }
    // The same file again: replaced only with --force.
    ok(&["clip", "positions", "--demo", "--csv", &o, "--force"]);
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.lines().nth(1).unwrap().starts_with("0,root,"));
}

#[test]
fn positions_npy_is_a_valid_numpy_file() {
    let out = tmp().join("pos.npy");
    ok(&[
        "clip",
        "positions",
        "--demo",
        "--npy",
        &out.display().to_string(),
    ]);
    let bytes = std::fs::read(&out).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!((10 + hlen) % 64, 0, "header must be 64-byte aligned");
    let header = std::str::from_utf8(&bytes[10..10 + hlen]).unwrap();
    assert!(header.contains("'shape': (480, 24, 3)"), "{header}");
    assert_eq!(bytes.len(), 10 + hlen + 480 * 24 * 3 * 8);
    let names = std::fs::read_to_string(out.with_extension("joints.txt")).unwrap();
    assert_eq!(names.lines().next(), Some("root"));
}

#[test]
fn convert_asf_amc_to_bvh_and_back_through_files() {
    let dir = tmp();
    let bvh = dir.join("walk.bvh").display().to_string();
    ok(&["clip", "convert", "--demo", "-o", &bvh]);
    let s = ok(&["clip", "info", &bvh]);
    assert!(s.contains("frames      480"), "{s}");
    let (a, m) = (
        dir.join("w.asf").display().to_string(),
        dir.join("w.amc").display().to_string(),
    );
    ok(&["clip", "convert", "--demo", "-o", &m, "--out-asf", &a]);
    let s = ok(&["clip", "info", "--asf", &a, "--amc", &m]);
    assert!(s.contains("DOF         49 channels"), "{s}");
    // BVH cannot become AMC: a clear refusal, not a broken file.
    let out = study(&["clip", "convert", &bvh, "-o", &m]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("AMC needs an ASF skeleton"));
}

#[test]
fn bad_input_prints_one_clear_message_and_fails() {
    let dir = tmp();
    let bad = dir.join("bad.bvh");
    std::fs::write(&bad, "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 zero\n").unwrap();
    let out = study(&["clip", "info", &bad.display().to_string()]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.starts_with("error: "), "{err}");
    assert!(
        err.contains("bad.bvh:4: OFFSET of Hips: `zero` is not a finite number"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    let out = study(&["clip", "info", "/no/such/file.bvh"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("/no/such/file.bvh: cannot read"),
        "{err}"
    );
    let out = study(&[
        "clip",
        "info",
        "--amc",
        &Path::new("x.amc").display().to_string(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("x.amc: no ASF skeleton for this motion: give x.asf"),
        "{err}"
    );
}

#[test]
fn an_svg_still_carries_each_panes_name_and_time_as_text() {
    // Renders offscreen: needs a Vulkan driver (lavapipe without a GPU).
    let dir = tmp();
    let bvh = dir.join("still-walk.bvh").display().to_string();
    ok(&["clip", "convert", "--demo", "-o", &bvh, "--force"]);
    let svg = dir.join("still.svg");
    let o = svg.display().to_string();
    ok(&[
        "clip",
        "render",
        "--demo",
        &bvh,
        "--times",
        "0.5,1.25",
        "--pane",
        "96",
        "--labels",
        "reference,wavelet <8:1>",
        "-o",
        &o,
        "--force",
    ]);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg "), "{}", &text[..80.min(text.len())]);
    assert!(
        text.contains(r#"width="192" height="192""#),
        "two panes across, two down"
    );
    assert!(
        text.contains("data:image/png;base64,iVBORw0KGgo"),
        "the pixels as PNG"
    );
    let labels: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("<text"))
        .filter_map(|l| l.split('>').nth(1)?.split('<').next())
        .collect();
    assert_eq!(
        labels,
        [
            "reference",
            "t = 0.50 s",
            "wavelet &lt;8:1&gt;",
            "t = 0.50 s",
            "reference",
            "t = 1.25 s",
            "wavelet &lt;8:1&gt;",
            "t = 1.25 s",
        ]
    );
    // One name per clip, said once; an unknown output kind refused before rendering.
    let out = study(&[
        "clip", "render", "--demo", "--labels", "a,b", "-o", &o, "--force",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--labels: 2 names for 1 clips"),
        "{err}"
    );
    let out = study(&["clip", "render", "--demo", "-o", "x.jpg"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("x.jpg: expected an .svg (labelled) or .png output"),
        "{err}"
    );
}

/// `study clip render --study --scenes` draws crowd scenes of a study with its camera: a 16:9
/// pane per scene (as the window shows them), each holding three figures (joint-orange pixels
/// in three groups of columns), at the nearest and the farthest level; a scene id the
/// manifest lacks is refused, naming it.
#[test]
fn crowd_scenes_of_a_study_render_as_the_window_draws_them() {
    let dir = tmp();
    let png = dir.join("crowd.png");
    let o = png.display().to_string();
    let study_file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples/crowd-run1.toml")
        .display()
        .to_string();
    let args = |scenes: &str| {
        [
            "clip",
            "render",
            "--study",
            &study_file,
            "--scenes",
            scenes,
            "--times",
            "1",
            "--pane",
            "240",
            "-o",
            &o,
            "--force",
        ]
        .map(str::to_string)
    };
    let run = |scenes: &str| {
        let a = args(scenes);
        study(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let out = run("near/reference,far/spiht/front40-back80");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let image = common::Rgb::read(&png);
    assert_eq!((image.width, image.height), (2 * 426, 240));
    for pane in 0..2 {
        // Columns of this pane holding joint orange, grouped by gaps of 4 or more pixels.
        let orange: Vec<bool> = (pane * 426..(pane + 1) * 426)
            .map(|x| (0..240).any(|y| image.is_orange(x, y)))
            .collect();
        let mut figures = 0;
        let mut gap = usize::MAX;
        for o in orange {
            if o {
                if gap >= 4 {
                    figures += 1;
                }
                gap = 0;
            } else {
                gap = gap.saturating_add(1);
            }
        }
        assert_eq!(figures, 3, "pane {pane}");
    }
    let out = run("far/spiht/front40-back90");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("\"far/spiht/front40-back90\" is not a crowd scene"),
        "{err}"
    );
}
