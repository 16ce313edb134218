//! `study preview`: the example stimuli in the study window under Xvfb with Mesa's software
//! Vulkan driver (lavapipe), driven by a test input script (`window/src/test_input.rs`) to
//! the next stimulus, then closed by a real Q key (`xdotool`); and bad input refused before
//! any window opens, naming the file or the stimulus.
//!
//! The window test needs `Xvfb`, `xdotool`, `import` (ImageMagick) and a Vulkan driver; without
//! them it fails under `CI` and is skipped elsewhere (`common::setup`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use common::{Scripted, setup};

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// The first two non-reference stimuli of the example manifest and their references.
fn first_two() -> Vec<(String, String)> {
    let text = std::fs::read_to_string(examples().join("stimuli.json")).unwrap();
    let m: protocols::manifest::StimulusManifest = serde_json::from_str(&text).unwrap();
    m.stimuli
        .iter()
        .filter(|s| s.codec != "reference")
        .take(2)
        .map(|s| (s.id.clone(), m.reference_of(&s.clip).unwrap().id.clone()))
        .collect()
}

#[test]
fn the_preview_shows_a_stimulus_beside_its_reference_goes_to_the_next_and_quits_on_q() {
    let Some(env) = setup("preview") else { return };
    let manifest = examples().join("stimuli.json");
    // Right on the first stimulus; the test quits with a real key once it has seen the second.
    let mut run = Scripted::spawn(
        &env,
        "preview",
        &["preview".as_ref(), manifest.as_os_str()],
        "preview once: Right\n",
    );
    run.wait_screen("preview #1");
    // Both panes draw a figure: the reference on the left, the stimulus on the right, framed
    // alike (about as tall). Screenshots until both are drawn; the state ends the wait.
    let shot = env.dir.join("preview.png");
    let deadline = Instant::now() + common::STATE_WAIT;
    let figures = loop {
        common::screenshot(&env, &shot);
        let image = common::Rgb::read(&shot);
        // Above the controls; the metrics column holds no orange.
        let rows = (image.height as f64 * 0.85) as usize;
        let found = image.orange_figures(0..image.width, 0..rows, 12);
        eprintln!("screenshot: figures {found:?}");
        if found.len() == 2 {
            break found;
        }
        assert!(Instant::now() < deadline, "never two figures: {found:?}");
        std::thread::sleep(Duration::from_millis(300));
    };
    if let Some(shots) = std::env::var_os("SCREENSHOTS") {
        std::fs::copy(&shot, Path::new(&shots).join("preview-window.png")).unwrap();
    }
    let [left, right] = [figures[0], figures[1]];
    assert!(left.right < 600 && right.left > 430, "{figures:?}");
    let (hl, hr) = (left.bottom - left.top, right.bottom - right.top);
    assert!(
        hl.abs_diff(hr) * 10 <= hl.max(hr),
        "heights {hl} and {hr} px: not framed alike"
    );
    // Q closes the window. A real key can be lost before the window has the focus, so it is
    // pressed until the process exits.
    let wid = env.xdotool(&["search", "--name", "Stimulus preview"]);
    let wid = wid.lines().next().expect("the preview window").to_string();
    let done = AtomicBool::new(false);
    let (status, stdout, stderr) = std::thread::scope(|s| {
        s.spawn(|| {
            let deadline = Instant::now() + common::STATE_WAIT;
            while !done.load(Ordering::Relaxed) && Instant::now() < deadline {
                common::press(&env, &wid, &["q"]);
                std::thread::sleep(Duration::from_millis(700));
            }
        });
        let out = run.wait_exit();
        done.store(true, Ordering::Relaxed);
        out
    });
    assert!(status.success(), "{stdout}{stderr}");
    let [(a, ra), (b, rb)] = <[_; 2]>::try_from(first_two()).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    let first = lines
        .iter()
        .position(|l| l.starts_with(&format!("preview 1/15: {a} against {ra} (")));
    let second = lines
        .iter()
        .position(|l| l.starts_with(&format!("preview 2/15: {b} against {rb} (")));
    assert!(
        matches!((first, second), (Some(x), Some(y)) if x < y),
        "{stdout}"
    );
    assert!(stdout.contains("15 stimuli to preview"), "{stdout}");
}

/// `study preview ARGS` without a display; it must fail, and its standard error.
fn refused(args: &[&std::ffi::OsStr]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_study"))
        .arg("preview")
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} was not refused: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

#[test]
fn bad_input_is_refused_naming_the_file_or_the_stimulus() {
    let manifest = examples().join("stimuli.json");
    let shown = manifest.display().to_string();
    // An id the manifest does not have: named, with the manifest, before any window.
    let e = refused(&[
        manifest.as_os_str(),
        "--stimulus".as_ref(),
        "walk/wavelet-perceptual/cr10".as_ref(),
        "--stimulus".as_ref(),
        "walk/nope".as_ref(),
    ]);
    assert!(
        e.contains(&format!(
            "{shown}: stimulus \"walk/nope\" is not in the manifest"
        )),
        "{e}"
    );
    assert!(!e.contains("no display"), "{e}");
    // No manifest at all.
    let dir = std::env::temp_dir().join(format!("study-preview-bad-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("none.json");
    let e = refused(&[missing.as_os_str()]);
    assert!(e.contains(&missing.display().to_string()), "{e}");
    // A stimulus whose clip has no reference.
    let text = std::fs::read_to_string(&manifest).unwrap();
    let mut m: protocols::manifest::StimulusManifest = serde_json::from_str(&text).unwrap();
    m.stimuli.retain(|s| s.id != "walk/reference");
    let unreferenced = dir.join("stimuli.json");
    std::fs::write(&unreferenced, serde_json::to_string(&m).unwrap()).unwrap();
    let e = refused(&[
        unreferenced.as_os_str(),
        "--stimulus".as_ref(),
        "walk/wavelet-standard/cr30".as_ref(),
    ]);
    assert!(
        e.contains("stimulus \"walk/wavelet-standard/cr30\" has no reference")
            && e.contains(&unreferenced.display().to_string()),
        "{e}"
    );
    // Not a manifest: the file and the parser's reason.
    std::fs::write(&unreferenced, "{\"version\": 4}").unwrap();
    let e = refused(&[unreferenced.as_os_str()]);
    assert!(
        e.contains(&format!(
            "{}: not a stimulus manifest: missing field `stimuli`",
            unreferenced.display()
        )),
        "{e}"
    );
    // With the file in order, no display is the only problem left, and it is said.
    let e = refused(&[manifest.as_os_str()]);
    assert!(e.contains("no display"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
