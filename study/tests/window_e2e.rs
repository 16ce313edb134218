//! End to end in a real X server: `study run` on a 6-trial MOS study under Xvfb with Mesa's
//! software Vulkan driver (lavapipe). The first test types real keys (`xdotool`): a screenshot
//! of a trial shows both skeletons; the session is SIGKILLed mid-way and `--resume` completes
//! it with every response kept exactly once. The others drive the window from a test input
//! script (`window/src/test_input.rs`) and wait for the screens it reports, so they do not
//! depend on how fast software rendering draws.
//!
//! Needs `Xvfb`, `xdotool`, `import` (ImageMagick) and a Vulkan driver; `scripts/test`
//! installs them. Without them the test fails under `CI` and is skipped elsewhere.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use common::{Env, Scripted, find_window, press, setup};

/// The shared walk stimuli and a MOS study of 2 familiarization + 2 test + 2 hidden-repeat
/// trials.
fn write_study(dir: &Path) {
    common::write_walk_stimuli(dir);
    std::fs::write(
        dir.join("study.toml"),
        "format_version = 1\nname = \"e2e\"\nprotocol = \"mos\"\nstimuli = \"stimuli/stimuli.json\"\n\
         seed = 5\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
         [presentation]\nplayback_count = 1\n\
         [session]\nfamiliarization = 2\nhidden_repeats = 2\n",
    )
    .unwrap();
}

fn session_dir(env: &Env) -> PathBuf {
    env.dir.join("results/S07_s1")
}

fn logged_rows(env: &Env) -> usize {
    std::fs::read_to_string(session_dir(env).join("trials.csv"))
        .map_or(0, |s| s.lines().count().saturating_sub(1))
}

fn spawn_run(env: &Env, resume: bool) -> Child {
    let mut c = env.cmd(env!("CARGO_BIN_EXE_study"));
    c.arg("run")
        .arg(env.dir.join("study.toml"))
        .args(["--subject", "S07", "-o"])
        .arg(env.dir.join("results"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if resume {
        c.arg("--resume");
    }
    c.spawn().unwrap()
}

/// `study run` of the study (resumed or not) with its keys from `script`.
fn run_scripted(env: &Env, resume: bool, script: &str) -> Scripted {
    let study = env.dir.join("study.toml");
    let results = env.dir.join("results");
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "run".as_ref(),
        study.as_os_str(),
        "--subject".as_ref(),
        "S07".as_ref(),
        "-o".as_ref(),
        results.as_os_str(),
    ];
    if resume {
        args.push("--resume".as_ref());
    }
    Scripted::spawn(env, if resume { "resume" } else { "run" }, &args, script)
}

/// Begins, answers every trial 3, and closes the end screen.
const ANSWER_ALL_3: &str = "welcome/ready: Enter\ntrial/open: 3 Enter\nend/ready: Enter\n";

/// Presses `keys` every half second until `rows` trials are logged (keys pressed while the
/// stimulus plays are ignored by design, so repeating is safe). Real X keys: a key can be
/// lost (before the window's first frames, or when software rendering falls behind), so the
/// wait is generous, [`common::STATE_WAIT`] for all of them.
fn answer_until(env: &Env, wid: &str, keys: &[&str], rows: usize) {
    let deadline = Instant::now() + common::STATE_WAIT;
    while logged_rows(env) < rows {
        assert!(
            Instant::now() < deadline,
            "stuck at {} rows",
            logged_rows(env)
        );
        press(env, wid, keys);
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// Presses Enter on the end screen (it stays until the subject closes it) until the runner
/// exits; returns its output.
fn close_end_screen(env: &Env, wid: &str, mut child: Child) -> std::process::Output {
    let deadline = Instant::now() + common::STATE_WAIT;
    while child.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "the end screen did not close");
        std::thread::sleep(Duration::from_millis(700));
        if child.try_wait().unwrap().is_none() {
            press(env, wid, &["Return"]);
        }
    }
    child.wait_with_output().unwrap()
}

/// Pixels that are joint orange, in the left and in the right half of the screen.
fn orange_per_half(png_path: &Path) -> [usize; 2] {
    let image = common::Rgb::read(png_path);
    let mut halves = [0; 2];
    for y in 0..image.height {
        for x in 0..image.width {
            if image.is_orange(x, y) {
                halves[usize::from(x >= image.width / 2)] += 1;
            }
        }
    }
    halves
}

/// The one test that types real X keys (`xdotool`), as a subject's keyboard does: each key is
/// repeated until the state it leads to is on disk, within [`common::STATE_WAIT`].
#[test]
fn study_run_under_xvfb_logs_every_trial_and_resumes_after_a_kill() {
    let Some(env) = setup("e2e") else { return };
    write_study(&env.dir);
    let mut child = spawn_run(&env, false);
    // The study has no title: the window shows the neutral default, never the internal name.
    let wid = find_window(&env, &mut child, protocols::texts::DEFAULT_TITLE);
    assert_eq!(env.xdotool(&["search", "--name", "e2e"]).trim(), "");
    // Welcome: Enter begins once the display is measured (~30 frames).
    let deadline = Instant::now() + common::STATE_WAIT;
    while !session_dir(&env).join("session.json").exists() || logged_rows(&env) == 0 {
        press(&env, &wid, &["Return"]);
        std::thread::sleep(Duration::from_millis(700));
        // Screenshot mid-presentation of the first trial.
        let shot = env.dir.join("trial.png");
        if !shot.exists() {
            common::screenshot(&env, &shot);
            let halves = orange_per_half(&shot);
            eprintln!("screenshot: joint pixels per half {halves:?}");
            if halves[0] == 0 || halves[1] == 0 {
                // Still on the welcome screen: try again.
                std::fs::remove_file(&shot).unwrap();
            } else {
                assert!(halves[0] > 30 && halves[1] > 30, "{halves:?}");
            }
        }
        if env.dir.join("trial.png").exists() {
            break;
        }
        assert!(Instant::now() < deadline, "no trial screen appeared");
    }
    // Three answers, then a kill between trials.
    answer_until(&env, &wid, &["4", "Return"], 3);
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(logged_rows(&env), 3);

    let mut child = spawn_run(&env, true);
    let wid = find_window(&env, &mut child, protocols::texts::DEFAULT_TITLE);
    answer_until(&env, &wid, &["Return", "3", "Return"], 6);
    let out = close_end_screen(&env, &wid, child);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("resuming after 3 logged trials"),
        "{stdout}"
    );
    assert!(stdout.contains("dropped"), "timing summary: {stdout}");

    let trials = results::trials::read_trials(&session_dir(&env).join("trials.csv")).unwrap();
    let idx: Vec<u32> = trials.records.iter().map(|r| r.trial.index).collect();
    assert_eq!(idx, [0, 1, 2, 3, 4, 5], "every trial exactly once");
    let ratings: Vec<f64> = trials
        .records
        .iter()
        .map(|r| match r.response.answer {
            protocols::Answer::Rating(v) => v,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(ratings, [4.0, 4.0, 4.0, 3.0, 3.0, 3.0]);
    // Every row of a real session records how the display kept time during its trial, and
    // frames.csv keeps each of those frames' intervals.
    let frames = std::fs::read_to_string(session_dir(&env).join("frames.csv")).unwrap();
    let mut lines = frames.lines();
    assert_eq!(lines.next(), Some("trial_index,interval_ms,phase"));
    let per_trial: Vec<(u32, f64)> = lines
        .map(|l| {
            let mut f = l.split(',');
            let (t, ms) = (f.next().unwrap(), f.next().unwrap());
            (t.parse().unwrap(), ms.parse().unwrap())
        })
        .collect();
    for r in &trials.records {
        let t = r.timing.expect("frame timing in a window session");
        assert!(t.frames_shown > 0 && t.interval_sd_ms >= 0.0, "{t:?}");
        let n = per_trial
            .iter()
            .filter(|(i, ms)| *i == r.trial.index && *ms > 0.0)
            .count();
        // The intervals are written just after the answer: a kill in between (trial 2 here,
        // the last before the kill) may leave that one trial without them, never with wrong ones.
        assert!(
            n == t.frames_shown as usize || (n == 0 && r.trial.index == 2),
            "trial {}: {n} intervals, {} frames",
            r.trial.index,
            t.frames_shown
        );
    }
    let manifest: results::SessionManifest =
        results::store::read_json(&session_dir(&env).join("session.json")).unwrap();
    assert_eq!(manifest.status, results::store::SessionState::Complete);
    assert_eq!(manifest.resumes, 1);
    let display = manifest.display.expect("display facts recorded");
    assert!(
        display.description.contains("present mode Fifo"),
        "{display:?}"
    );
    assert!(display.refresh_hz > 0.0);
}

/// Without a display, `study run` and `study display-test` stop with one clear error that
/// points at `study simulate`, and `study run` writes no results.
#[test]
fn without_a_display_run_says_so_and_writes_nothing() {
    let dir = std::env::temp_dir().join(format!("study-nodisplay-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    write_study(&dir);
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_study"))
            .args(args)
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .current_dir(&dir)
            .output()
            .unwrap()
    };
    let out = run(&["run", "study.toml", "--subject", "S01", "-o", "results"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("no display") && err.contains("study simulate study.toml"),
        "{err}"
    );
    assert!(!dir.join("results").exists());
    let out = run(&["display-test", "--seconds", "1"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no display"));
    let out = run(&["run", "study.toml", "--subject", "../x"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("--subject"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// SIGINT (Ctrl+C in the experimenter's terminal) in the middle of a session: the runner
/// saves, marks the session interrupted with as many trials in the manifest as rows on disk,
/// prints the resume command and exits; `--resume` then completes the session, each trial
/// once.
#[test]
fn sigint_saves_the_session_and_resume_completes_it() {
    let Some(env) = setup("sigint") else { return };
    write_study(&env.dir);
    // Two trials answered (4, Enter), then Ctrl+C.
    let mut run = run_scripted(
        &env,
        false,
        "welcome/ready: Enter\ntrial/open times 2: 4 Enter\n",
    );
    run.wait_until("two answers carried out", |r| {
        r.stderr().matches("test input: done 2\n").count() == 2
    });
    let (stdout, _) = run.interrupt();
    assert!(
        stdout.contains("interrupted by a signal after 2 trials") && stdout.contains("--resume"),
        "{stdout}"
    );
    let manifest = |env: &Env| -> results::SessionManifest {
        results::store::read_json(&session_dir(env).join("session.json")).unwrap()
    };
    let m = manifest(&env);
    assert_eq!(m.status, results::store::SessionState::Interrupted);
    assert_eq!(m.trials_logged as usize, logged_rows(&env));
    assert_eq!(logged_rows(&env), 2);

    // Resumed: every trial left answered 3, then the end screen closed.
    let run = run_scripted(&env, true, ANSWER_ALL_3);
    let (status, _, stderr) = run.wait_exit();
    assert!(status.success(), "{stderr}");
    let trials = results::trials::read_trials(&session_dir(&env).join("trials.csv")).unwrap();
    let idx: Vec<u32> = trials.records.iter().map(|r| r.trial.index).collect();
    assert_eq!(idx, [0, 1, 2, 3, 4, 5], "every trial exactly once");
    let m = manifest(&env);
    assert_eq!(m.status, results::store::SessionState::Complete);
    assert_eq!((m.trials_logged, m.resumes), (6, 1));
}

/// A display that cannot be opened (a DISPLAY naming no X server) stops `study run` with an
/// error and leaves no session folder behind.
#[test]
fn a_window_that_cannot_open_leaves_no_session() {
    let dir = std::env::temp_dir().join(format!("study-nowindow-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    write_study(&dir);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_study"))
        .args(["run", "study.toml", "--subject", "S01", "-o", "results"])
        .env("DISPLAY", ":4093")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("no session was recorded"), "{err}");
    assert!(!dir.join("results/S01_s1").exists(), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The phases of trial `index` in the session's `frames.csv`, runs of equal phases merged.
fn phase_runs(env: &Env, index: u32) -> Vec<String> {
    let frames = std::fs::read_to_string(session_dir(env).join("frames.csv")).unwrap();
    let mut runs: Vec<String> = Vec::new();
    for line in frames.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 3, "{line}");
        if f[0].parse::<u32>().unwrap() != index {
            continue;
        }
        if runs.last().is_none_or(|r| r != f[2]) {
            runs.push(f[2].to_string());
        }
    }
    runs
}

/// DSCQS as BT.500 gives it: the frame log shows A, grey, B, grey, A, grey, B (the grey
/// between the second A and B included), then the vote; both marks are placed by keys on the
/// continuous scale and recorded on 0-100.
#[test]
fn a_dscqs_trial_is_presented_as_bt500_says_in_the_frame_log() {
    let Some(env) = setup("dscqs-e2e") else {
        return;
    };
    common::write_walk_stimuli(&env.dir);
    std::fs::write(
        env.dir.join("study.toml"),
        "format_version = 1\nname = \"e2e\"\nprotocol = \"dscqs\"\n\
         stimuli = \"stimuli/stimuli.json\"\nseed = 5\n[conditions]\nclips = [\"walk\"]\n\
         codecs = [\"spiht\"]\ntarget_cr = [10]\n[presentation]\ngrey_ms = 700\n",
    )
    .unwrap();
    // Begin, then once the vote is open Backspace to start at A, 4 (A: Good, 70), 2 (B:
    // Poor, 30) and Enter; Enter closes the end screen.
    let run = run_scripted(
        &env,
        false,
        "welcome/ready: Enter\ntrial/open: Backspace 4 2 Enter\nend/ready: Enter\n",
    );
    let (status, _, stderr) = run.wait_exit();
    assert!(status.success(), "{stderr}");
    let trials = results::trials::read_trials(&session_dir(&env).join("trials.csv")).unwrap();
    assert_eq!(
        trials.records[0].response.answer,
        protocols::Answer::Pair { a: 70.0, b: 30.0 }
    );
    assert_eq!(
        phase_runs(&env, 0),
        ["a", "grey", "b", "grey", "a", "grey", "b", "answer"],
        "frames.csv phases"
    );
}

/// Near-white pixels (label text) in the band just above the skeleton viewports, per half.
fn label_pixels_per_half(png_path: &Path) -> [usize; 2] {
    let mut dec = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(png_path).unwrap(),
    ));
    dec.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.line_size / info.width as usize;
    let mut halves = [0; 2];
    // The progress panel is the top ~30 px; the label band lies below it.
    for y in 30..(info.height as usize / 5) {
        for x in 0..info.width as usize {
            let i = y * info.line_size + x * channels;
            let white = (0..channels.min(3)).all(|c| buf[i + c] > 235);
            if white {
                halves[usize::from(x >= info.width as usize / 2)] += 1;
            }
        }
    }
    halves
}

/// A screenshot of a MOS trial shows "Original" and "Compressed" as text above the two
/// motions: white text on both sides of the band above the viewports, read back by OCR
/// (`tesseract`, which `scripts/test` installs; under `CI` its absence fails the test).
#[test]
fn a_mos_trial_screenshot_shows_both_labels() {
    let Some(env) = setup("labels-e2e") else {
        return;
    };
    write_study(&env.dir);
    // Enter begins; the first trial then holds its last frame, both motions and their
    // labels, until it is answered (side by side, no loop): the screenshot is taken there.
    let mut run = run_scripted(&env, false, "welcome/ready: Enter\n");
    run.wait_screen("trial/open #0");
    let shot = env.dir.join("labels.png");
    common::screenshot(&env, &shot);
    let joints = orange_per_half(&shot);
    assert!(joints[0] > 30 && joints[1] > 30, "both motions: {joints:?}");
    let white = label_pixels_per_half(&shot);
    eprintln!("label pixels per half {white:?}");
    assert!(
        white[0] > 40 && white[1] > 40,
        "labels above both motions: {white:?}"
    );
    assert!(
        common::have("tesseract") || std::env::var_os("CI").is_none(),
        "tesseract is not installed (scripts/test installs tesseract-ocr): under CI the labels must be read back"
    );
    // Kept for a failing run to look at.
    let _ = std::fs::copy(
        &shot,
        std::env::temp_dir().join("study-labels-e2e-last.png"),
    );
    if common::have("tesseract") {
        // OCR the label band only (below the progress panel, above the viewports), its
        // near-white pixels as black on white: the labels sit between the dark panel and the
        // 3-D panes, which a whole-window OCR reads as noise.
        let band = env.dir.join("band.png");
        let ok = env
            .cmd("convert")
            .arg(&shot)
            .args([
                "-crop",
                "100%x16%+0+30",
                "+repage",
                "-colorspace",
                "Gray",
                "-threshold",
                "90%",
                "-negate",
            ])
            .arg(&band)
            .status()
            .unwrap()
            .success();
        assert!(ok);
        let out = std::process::Command::new("tesseract")
            .arg(&band)
            .args(["-", "--psm", "11"])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains("Original") && text.contains("Compressed"),
            "OCR of the label band: {text}"
        );
    } else {
        eprintln!("tesseract not installed: the labels were checked as pixels only");
    }
    run.kill();
}
