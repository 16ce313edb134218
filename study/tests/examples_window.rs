//! The shipped example studies run as they are, from a fresh clone.
//!
//! - Their stimuli (`examples/stimuli/`, manifest `examples/stimuli.json`) are two generated
//!   motions swept with the seeds' codecs: the committed files must be exactly what
//!   [`make_example_stimuli`] makes now, so they cannot drift from the generator (run with
//!   `REGENERATE_EXAMPLES=1` to rewrite them after a change to a codec or the generator).
//! - Every example passes `study check` (which now reads every stimulus its plan can show).
//! - Under Xvfb + lavapipe, `study run` of each example reaches its first answer and records
//!   it (needs the tools of `window_e2e.rs`; skipped outside CI without them).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;
#[path = "../../scripts/golden/tidy_readers.rs"]
mod tidy_readers;
#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::time::Instant;

use codecs::codec::CodecContext;
use codecs::primitives::{Database, SegmentParams, TrainParams};
use motion::synth::{WalkParams, walking_clip};
use protocols::manifest::{Stimulus, StimulusManifest};

use common::{Env, Scripted, setup, study_ok};

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// The keys that answer a study's subject fields on the welcome screen, Tab to each in order:
/// "33" typed into a text field, a number's minimum, Space on a choice's or a yes/no field's
/// first option (Tab then passes its other options, each a focusable radio button); with the
/// answers `session.json` must then hold (a yes/no field stores `yes`).
fn welcome_keys(study: &Path) -> (String, BTreeMap<String, String>) {
    let text = std::fs::read_to_string(study).unwrap();
    let table: toml::Table = toml::from_str(&text).unwrap();
    let fields = table
        .get("session")
        .and_then(|s| s.get("subject_fields"))
        .and_then(toml::Value::as_array)
        .cloned()
        .unwrap_or_default();
    let mut keys = String::new();
    let mut answers = BTreeMap::new();
    let mut skip = 0;
    for f in &fields {
        keys += &" Tab".repeat(skip);
        skip = 0;
        let (name, kind) = match f {
            toml::Value::String(name) => (name.as_str(), "text"),
            f => (
                f.get("name").and_then(toml::Value::as_str).unwrap(),
                f.get("kind")
                    .and_then(toml::Value::as_str)
                    .unwrap_or("text"),
            ),
        };
        let answer = match kind {
            "number" => {
                let min = f.get("min").unwrap();
                let min = min
                    .as_integer()
                    .map_or_else(|| min.as_float().unwrap().to_string(), |i| i.to_string());
                keys += " Tab \"";
                keys += &min;
                keys += "\"";
                min
            }
            "choice" | "yes_no" => {
                keys += " Tab Space";
                let options = f.get("options").and_then(toml::Value::as_array);
                skip = options.map_or(1, |o| o.len() - 1);
                options
                    .map_or("yes", |o| o[0].as_str().unwrap())
                    .to_string()
            }
            _ => {
                keys += " Tab \"33\"";
                "33".to_string()
            }
        };
        answers.insert(name.to_string(), answer);
    }
    (keys, answers)
}

/// The two generated motions of the examples: a walk and a livelier march, 4 s each at 30 Hz
/// (BVH carries its rate): 120 frames, about 80 KB a file, the fewest with which the wavelet
/// codecs still reach 30:1 with a sensible error and t_L still changes the primitive codec's
/// output. Few conditions keep the committed set near 1.5 MB.
fn example_motions() -> [(&'static str, WalkParams); 2] {
    let base = WalkParams {
        duration_s: 4.0,
        frame_rate_hz: 30.0,
        ..WalkParams::default()
    };
    [
        ("walk", base),
        (
            "march",
            WalkParams {
                speed_cm_s: 100.0,
                cycle_hz: 1.0,
                amplitude: 1.4,
                ..base
            },
        ),
    ]
}

/// The wavelet codecs of the MOS and DSCQS examples (paper 000) and their target ratios.
const WAVELET_CODECS: [&str; 2] = ["wavelet-perceptual", "wavelet-standard"];
const TARGET_CR: [f64; 2] = [10.0, 30.0];
/// The staircase example's t_L levels of the primitive codec (thesis ch. 5): 0.004 to 0.040
/// in steps of 0.006, on the walk only.
fn t_l_levels() -> Vec<f64> {
    (0..7).map(|k| f64::from(4 + 6 * k) / 1000.0).collect()
}
const STAIRCASE_CLIP: &str = "walk";

/// Makes the examples' stimulus set in `root`: `root/stimuli/<clip>/...` and
/// `root/stimuli.json` (paths relative to `root`, no timings, so it is the same on every
/// machine). The wavelet stimuli are a `study sweep`; the primitive ones are encoded at each
/// level with a database trained on the two motions (the database is not kept: the manifest
/// names no decoder context, so these stimuli carry no bitstream).
fn make_example_stimuli(root: &Path) {
    let src = root.join("source");
    std::fs::create_dir_all(&src).unwrap();
    let mut sources = Vec::new();
    for (name, params) in example_motions() {
        let path = src.join(format!("{name}.bvh"));
        motion::io::write_clip(&walking_clip(&params), &path, None, files::Mode::New).unwrap();
        sources.push((name, path));
    }
    let out = root.join("stimuli");
    let summary = lab::sweep::sweep(
        &lab::sweep::SweepOptions {
            clips: sources.iter().map(|(_, p)| p.clone()).collect(),
            codecs: WAVELET_CODECS.iter().map(|c| (*c).to_string()).collect(),
            targets: TARGET_CR.to_vec(),
            output: out.clone(),
            jobs: 2,
            ..lab::sweep::SweepOptions::default()
        },
        &|_, _| {},
    )
    .unwrap();
    assert!(summary.unreachable.is_empty(), "{:?}", summary.unreachable);
    std::fs::remove_file(out.join("stimuli.json")).unwrap();
    std::fs::remove_file(out.join("rd.csv")).unwrap();
    let mut stimuli = summary.manifest.stimuli;
    // What the window and simulation read back: the files as written.
    let clips: Vec<(String, motion::Clip)> = sources
        .iter()
        .map(|(n, p)| ((*n).to_string(), motion::io::read_clip(None, p).unwrap()))
        .collect();
    stimuli.extend(primitive_stimuli(&out, &clips));
    // Relative to the examples folder, without the timings of this machine.
    let under = |p: &str| format!("stimuli/{p}");
    for s in &mut stimuli {
        s.file = under(&s.file);
        s.skeleton = s.skeleton.as_deref().map(under);
        s.bitstream = s.bitstream.as_deref().map(under);
        s.encode_ms = None;
        s.decode_ms = None;
    }
    let manifest = StimulusManifest {
        version: protocols::manifest::MANIFEST_VERSION,
        cr_basis: protocols::manifest::CrBasis::File,
        stimuli,
    };
    let json = serde_json::to_string_pretty(&manifest).unwrap() + "\n";
    std::fs::write(root.join("stimuli.json"), json).unwrap();
    std::fs::remove_dir_all(&src).unwrap();
}

/// The primitive codec's stimuli of the staircase clip at every t_L level, written under
/// `out/<clip>/`, with a database trained on every clip.
fn primitive_stimuli(out: &Path, clips: &[(String, motion::Clip)]) -> Vec<Stimulus> {
    let mut made_here = Vec::new();
    let refs: Vec<&motion::Clip> = clips.iter().map(|(_, c)| c).collect();
    let db = Database::train(
        &refs,
        &TrainParams {
            k_max: 8,
            segment: SegmentParams {
                min_frames: 8,
                max_frames: 16,
            },
            ..TrainParams::default()
        },
        |_, _| {},
    );
    let codecs = lab::Codecs::new(CodecContext::with_primitives(Arc::new(db)));
    let primitive = codecs.get("primitive").unwrap();
    for (name, clip) in clips.iter().filter(|(n, _)| n == STAIRCASE_CLIP) {
        for t_l in t_l_levels() {
            let made = lab::stimulus::make(
                primitive.as_ref(),
                clip,
                &lab::stimulus::Request {
                    params: BTreeMap::from([("t_l".to_string(), t_l)]),
                    target_cr: None,
                },
            )
            .unwrap();
            let label = format!("tl{:03}", (t_l * 1000.0).round() as u32);
            let stem = format!("primitive-{label}");
            let (file, _) = lab::stimulus::write_clip_as(
                &made.decoded,
                &out.join(name),
                &stem,
                None,
                files::Mode::New,
            )
            .unwrap();
            made_here.push(Stimulus {
                id: format!("{name}/primitive/{label}"),
                clip: name.clone(),
                codec: "primitive".into(),
                params: made.stream.params.clone(),
                variant: BTreeMap::new(),
                target_cr: None,
                target_max_error_cm: None,
                achieved_cr: Some(made.achieved_cr()),
                bytes: made.bytes.len() as u64,
                file: file
                    .strip_prefix(out)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/"),
                skeleton: None,
                bitstream: None,
                metrics: Some(lab::stimulus::manifest_metrics(
                    &made.metrics,
                    made.worst_window,
                )),
                encode_ms: None,
                decode_ms: None,
                scene: None,
                sha256: Some(lab::stimulus::sha256_file(&file).unwrap()),
                bitstream_sha256: None,
            });
        }
    }
    made_here
}

/// The crowd example's motion (thesis 6.5: every character performs the same movement in
/// sync): the generated figure marching in place, 4 s at 30 Hz.
fn crowd_motion() -> WalkParams {
    WalkParams {
        duration_s: 4.0,
        frame_rate_hz: 30.0,
        speed_cm_s: 0.0,
        cycle_hz: 1.0,
        amplitude: 1.4,
    }
}

/// The crowd example's ratios (thesis 6.5): the front character at 40:1, the back ones varied.
const CROWD_FRONT_CR: f64 = 40.0;
const CROWD_BACK_CR: [f64; 4] = [20.0, 40.0, 60.0, 80.0];

/// Makes the crowd examples' stimuli in `root/crowd` as `study crowd` does from the scene of
/// `examples/crowd-run1.toml`, without the timings of this machine.
fn make_crowd_stimuli(root: &Path) {
    let src = root.join("source");
    std::fs::create_dir_all(&src).unwrap();
    let march = src.join("march.bvh");
    motion::io::write_clip(
        &walking_clip(&crowd_motion()),
        &march,
        None,
        files::Mode::New,
    )
    .unwrap();
    let out = root.join("crowd");
    lab::crowd::crowd(
        &lab::crowd::CrowdOptions {
            scene: examples().join("crowd-run1.toml"),
            clips: vec![march],
            clip_options: lab::clips::ClipOptions::default(),
            codec: "spiht".into(),
            params: BTreeMap::new(),
            plan: lab::crowd::Plan::Fixed(vec![
                ("front".into(), vec![CROWD_FRONT_CR]),
                ("back".into(), CROWD_BACK_CR.to_vec()),
            ]),
            output: out.clone(),
            jobs: 2,
            force: false,
        },
        &|_, _| {},
    )
    .unwrap();
    let path = out.join("stimuli.json");
    let mut manifest: StimulusManifest =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    for s in &mut manifest.stimuli {
        s.encode_ms = None;
        s.decode_ms = None;
    }
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&manifest).unwrap() + "\n",
    )
    .unwrap();
    std::fs::remove_dir_all(&src).unwrap();
}

/// Every file under `dir`, by path relative to it.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// The files under `made` are the files under `committed` (named `name` in messages), byte
/// for byte.
fn same_files(made: &Path, committed: &Path, name: &str) {
    let (made, committed) = (tree(made), tree(committed));
    assert_eq!(
        made.keys().collect::<Vec<_>>(),
        committed.keys().collect::<Vec<_>>(),
        "{name}/ holds other files than the generator makes (REGENERATE_EXAMPLES=1)"
    );
    for (rel, bytes) in &made {
        assert!(
            committed[rel] == *bytes,
            "{name}/{rel} differs from the generator (REGENERATE_EXAMPLES=1)"
        );
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("examples-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The committed stimuli are exactly what the generator makes now, and the examples'
/// manifest names only files that exist.
#[test]
fn example_stimuli_are_the_generated_ones() {
    let root = scratch("generated");
    make_example_stimuli(&root);
    let ex = examples();
    if std::env::var_os("REGENERATE_EXAMPLES").is_some() {
        let _ = std::fs::remove_dir_all(ex.join("stimuli"));
        for (rel, bytes) in tree(&root.join("stimuli")) {
            let to = ex.join("stimuli").join(rel);
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::write(to, bytes).unwrap();
        }
        std::fs::copy(root.join("stimuli.json"), ex.join("stimuli.json")).unwrap();
    }
    assert!(
        std::fs::read(root.join("stimuli.json")).unwrap()
            == std::fs::read(ex.join("stimuli.json")).unwrap(),
        "examples/stimuli.json differs from the generator (REGENERATE_EXAMPLES=1 rewrites it)"
    );
    same_files(
        &root.join("stimuli"),
        &ex.join("stimuli"),
        "examples/stimuli",
    );
    let manifest: StimulusManifest =
        serde_json::from_slice(&std::fs::read(ex.join("stimuli.json")).unwrap()).unwrap();
    for s in &manifest.stimuli {
        for f in std::iter::once(&s.file)
            .chain(&s.skeleton)
            .chain(&s.bitstream)
        {
            assert!(ex.join(f).is_file(), "{}: {f} does not exist", s.id);
        }
    }
    std::fs::remove_dir_all(&root).unwrap();
}

/// The crowd example's committed stimuli (`examples/crowd/`) are exactly what `study crowd`
/// makes from its scene now (`REGENERATE_EXAMPLES=1` rewrites them).
#[test]
fn crowd_example_stimuli_are_the_generated_ones() {
    let root = scratch("crowd-generated");
    make_crowd_stimuli(&root);
    let (made, committed) = (root.join("crowd"), examples().join("crowd"));
    if std::env::var_os("REGENERATE_EXAMPLES").is_some() {
        let _ = std::fs::remove_dir_all(&committed);
        for (rel, bytes) in tree(&made) {
            let to = committed.join(rel);
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::write(to, bytes).unwrap();
        }
    }
    same_files(&made, &committed, "examples/crowd");
    std::fs::remove_dir_all(&root).unwrap();
}

const EXAMPLES: [&str; 11] = [
    "mos.toml",
    "dscqs.toml",
    "staircase.toml",
    "live-staircase.toml",
    "quest.toml",
    "acr-hr.toml",
    "dcr.toml",
    "pc.toml",
    "pc-ties.toml",
    "mushra.toml",
    "ccr.toml",
];

/// The two runs of the crowd study (thesis 6.5).
const CROWD_EXAMPLES: [&str; 2] = ["crowd-run1.toml", "crowd-run2.toml"];

/// `study check` of every example passes, its stimuli read.
#[test]
fn every_example_passes_check() {
    for name in EXAMPLES.into_iter().chain(CROWD_EXAMPLES) {
        let out = Command::new(env!("CARGO_BIN_EXE_study"))
            .arg("check")
            .arg(examples().join(name))
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(stdout.contains("stimuli:"), "{name}: {stdout}");
        // What subjects read: a title that is not the study's internal name, and the
        // instructions as the design makes them.
        let line = |key: &str| {
            stdout
                .lines()
                .find_map(|l| l.trim().strip_prefix(key))
                .unwrap_or_else(|| panic!("{name}: no {key:?} in {stdout}"))
                .trim()
                .to_string()
        };
        let (study, title) = (line("name:"), line("title (subjects see):"));
        assert_ne!(title, study, "{name}: subjects would see the internal name");
        let instructions = line("instructions (subjects read):");
        if name == "pc.toml" {
            assert!(
                instructions.contains("may be the original motion itself"),
                "{name}: hidden references: {instructions}"
            );
        }
    }
}

/// `study check` on a copy of the MOS example with one stimulus file deleted and one cut
/// short fails, naming both files (and `study simulate` refuses the same way).
#[test]
fn check_names_a_missing_and_a_corrupt_stimulus() {
    let dir = scratch("broken");
    for (rel, bytes) in tree(&examples().join("stimuli")) {
        let to = dir.join("stimuli").join(rel);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::write(to, bytes).unwrap();
    }
    for f in ["stimuli.json", "mos.toml"] {
        std::fs::copy(examples().join(f), dir.join(f)).unwrap();
    }
    let missing = "wavelet-standard-cr30.bvh";
    let corrupt = "wavelet-perceptual-cr10.bvh";
    std::fs::remove_file(dir.join("stimuli/march").join(missing)).unwrap();
    let text = std::fs::read_to_string(dir.join("stimuli/walk").join(corrupt)).unwrap();
    std::fs::write(
        dir.join("stimuli/walk").join(corrupt),
        &text[..text.len() - 500],
    )
    .unwrap();
    for args in [vec!["check"], vec!["simulate", "-o", "res"]] {
        let out = Command::new(env!("CARGO_BIN_EXE_study"))
            .args(&args[..1])
            .arg(dir.join("mos.toml"))
            .args(&args[1..])
            .current_dir(&dir)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}: {err}");
        assert!(
            err.contains(&format!("march/{missing}")) && err.contains(&format!("walk/{corrupt}")),
            "{args:?}: {err}"
        );
        assert!(err.contains("2 stimulus problem(s)"), "{err}");
    }
    assert!(!dir.join("res").exists());
}

/// `study run STUDY --subject S01 [EXTRA] -o OUT` in a window that takes its keys from
/// `script`.
fn run_scripted(
    env: &Env,
    name: &str,
    study: &Path,
    extra: &[&str],
    out: &Path,
    script: &str,
) -> Scripted {
    // A MUSHRA screen draws six panes at once: a small window keeps lavapipe's frames quick.
    let size = if study.ends_with("mushra.toml") {
        "640x480"
    } else {
        "1280x720"
    };
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "run".as_ref(),
        study.as_os_str(),
        "--subject".as_ref(),
        "S01".as_ref(),
        "--window-size".as_ref(),
        size.as_ref(),
    ];
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    args.extend(["-o".as_ref(), out.as_os_str()]);
    Scripted::spawn(env, name, &args, script)
}

/// The keys that answer an example's first trial (or MUSHRA screen) once its answers open:
/// DSCQS's two continuous scales with the number keys (Backspace to A, 4 marks A Good, 2
/// marks B Poor), MUSHRA's sliders A to E in the order they are drawn (Tab to each, Up sets
/// it to 1), a grade for MOS, ACR and DCR (4), CCR's "Better" (2), "No preference" (N)
/// where a pair comparison offers it, the left motion for 2AFC and pair comparison.
fn first_answer_keys(name: &str) -> &'static str {
    match name {
        "dscqs.toml" => "Backspace 4 2 Enter",
        "mushra.toml" => "Tab Up Tab Up Tab Up Tab Up Tab Up Enter",
        "mos.toml" | "acr-hr.toml" | "dcr.toml" => "4 Enter",
        "pc-ties.toml" => "N",
        "ccr.toml" => "2 Enter",
        _ => "Left",
    }
}

/// Under Xvfb + lavapipe, `study run` of each example reaches its first answer and records
/// it: the subject form is filled in (Tab to each field, typed), Begin pressed, the first
/// trial watched and answered from the keyboard, all from a test input script (one key a
/// frame, each once its screen shows); then the experimenter stops the session with SIGINT,
/// which saves it.
#[test]
fn each_example_records_its_first_answer_in_the_window() {
    let Some(env) = setup("examples") else { return };
    for name in EXAMPLES {
        let started = Instant::now();
        let out = env.dir.join(format!("results-{name}"));
        let session = out.join("S01_s1");
        // Welcome: Tab to each field and answer it; Escape leaves the last field and Enter
        // begins (the screen is `welcome/ready` once the display is measured). Line 2: the
        // first trial's answer.
        let (keys, answers) = welcome_keys(&examples().join(name));
        let script = format!(
            "welcome/ready:{keys} Escape Enter\ntrial/open once: {}\n",
            first_answer_keys(name)
        );
        let mut run = run_scripted(&env, name, &examples().join(name), &[], &out, &script);
        // `SCREENSHOTS=DIR` (scripts/screenshots): the first trial as it plays, for
        // docs/serve.md beside the browser's.
        if let Some(shots) = std::env::var_os("SCREENSHOTS") {
            run.wait_screen("trial/playing");
            std::thread::sleep(std::time::Duration::from_millis(1500));
            let stem = name.trim_end_matches(".toml");
            common::screenshot(&env, &Path::new(&shots).join(format!("{stem}-window.png")));
        }
        run.wait_line("done 2");
        let (_, stderr) = run.interrupt();
        assert!(!stderr.contains("test input: dropped"), "{name}: {stderr}");
        let manifest: results::SessionManifest =
            serde_json::from_str(&std::fs::read_to_string(session.join("session.json")).unwrap())
                .unwrap();
        assert_eq!(
            manifest.subject_fields, answers,
            "{name}: the fields as answered, each as its kind stores it"
        );
        let trials = results::trials::read_trials(&session.join("trials.csv")).unwrap();
        assert!(!trials.records.is_empty(), "{name}");
        assert_eq!(trials.records[0].trial.index, 0, "{name}");
        check_first_answers(name, &trials.records);
        eprintln!(
            "{name}: first answer in the window after {:.1?}",
            started.elapsed()
        );
    }
}

/// What each example's first answers must be, as the keys gave them.
fn check_first_answers(name: &str, records: &[protocols::TrialRecord]) {
    if name == "ccr.toml" {
        // The second version rated "Better" than the first, on -3 … +3.
        assert_eq!(records[0].protocol, protocols::Protocol::Ccr);
        assert_eq!(records[0].response.answer, protocols::Answer::Rating(2.0));
    }
    if matches!(name, "acr-hr.toml" | "dcr.toml") {
        assert_eq!(
            records[0].response.answer,
            protocols::Answer::Rating(4.0),
            "{name}"
        );
    }
    if name == "pc.toml" {
        let r = &records[0];
        assert_eq!(r.protocol, protocols::Protocol::PairComparison);
        assert_eq!(
            r.response.answer,
            protocols::Answer::Choice(protocols::Position::Left)
        );
        assert_ne!(r.trial.stimulus, r.trial.reference, "two test versions");
    }
    if name == "pc-ties.toml" {
        // The third button the screen offered: no preference, a tie scored 1/2.
        let r = &records[0];
        assert_eq!(
            r.response.answer,
            protocols::Answer::Choice(protocols::Position::Neither)
        );
        assert!((r.outcome.score - 0.5).abs() < 1e-12, "{:?}", r.outcome);
    }
    if name == "mushra.toml" {
        // The whole first screen, the example's training screen: one row per pane, A to E,
        // each rated from the keys, logged as familiarization, the first carrying the
        // screen's frames.
        let panes: Vec<String> = records
            .iter()
            .map(|r| r.trial.reference_position.to_string())
            .collect();
        assert_eq!(panes, ["pane_a", "pane_b", "pane_c", "pane_d", "pane_e"]);
        assert!(
            records
                .iter()
                .all(|r| r.trial.block == protocols::Block::Familiarization)
        );
        assert!(records.iter().all(|r| matches!(
            r.response.answer,
            protocols::Answer::Rating(v) if (1.0..=100.0).contains(&v)
        )));
        assert!(records[0].timing.is_some_and(|t| t.frames_shown > 0));
    }
}

/// The crowd examples simulate (both runs, ten subjects each) and their reports draw thesis
/// Fig. 6.9: a curve per distance level of the MOS against the back characters' ratio, and a
/// table of every scene with each character's ratio.
#[test]
fn the_crowd_examples_simulate_and_report_fig_6_9() {
    let dir = scratch("crowd-report");
    for run in CROWD_EXAMPLES {
        let results = dir.join(format!("results-{run}"));
        study_ok(&[
            "simulate".as_ref(),
            examples().join(run).as_os_str(),
            "--subjects".as_ref(),
            "10".as_ref(),
            "--seed".as_ref(),
            "3".as_ref(),
            "-o".as_ref(),
            results.as_os_str(),
        ]);
        // Every row carries the characters' ratios and the level.
        let trials = results::trials::read_trials(&results.join("S001_s1/trials.csv")).unwrap();
        assert_eq!(trials.records.len(), 12, "{run}");
        for r in &trials.records {
            let e = r.encoding.as_ref().expect("a crowd row logs its scene");
            let level = e.codec_params["level"];
            let name = r.trial.stimulus.split('/').next().unwrap();
            assert_eq!(["near", "middle", "far"][level as usize - 1], name, "{run}");
            assert!((e.codec_params["cr_front"] - CROWD_FRONT_CR).abs() < 0.02 * CROWD_FRONT_CR);
            let back = e.codec_params["cr_back_left"];
            assert_eq!(back.to_bits(), e.codec_params["cr_back_right"].to_bits());
            assert!(
                r.trial
                    .stimulus
                    .ends_with(&format!("back{}", (back / 10.0).round() * 10.0)),
                "{run}: {} logs back CR {back}",
                r.trial.stimulus
            );
        }
        let report = dir.join(format!("report-{run}"));
        study_ok(&[
            "report".as_ref(),
            results.as_os_str(),
            "--no-png".as_ref(),
            "-o".as_ref(),
            report.as_os_str(),
        ]);
        let table = std::fs::read_to_string(report.join("tables/crowd.csv")).unwrap();
        let mut lines = table.lines();
        let header = lines.next().unwrap();
        assert!(
            header.starts_with("Level,Distance (m),x,CR front,CR back_left,CR back_right"),
            "{header}"
        );
        let rows: Vec<&str> = lines.collect();
        assert_eq!(rows.len(), 12, "{table}");
        // Nearest level first, each level's ratios in order.
        assert!(rows[0].starts_with("near,6.0,20,") && rows[11].starts_with("far,13.0,80,"));
        let svg = std::fs::read_to_string(report.join("figures/crowd_mos.svg")).unwrap();
        for legend in [
            "near (back at 6.0 m)",
            "middle (back at 9.0 m)",
            "far (back at 13.0 m)",
        ] {
            assert!(svg.contains(legend), "{run}: no curve {legend:?}");
        }
        assert!(svg.contains("Compression ratio of the back characters (x:1)"));
        tidy_readers::check_tidy(&results, &report, run);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Figures in a screenshot: joint-orange pixels in the top `within` rows, grouped into
/// columns separated by at least 12 empty pixel columns; each group's (left, right, height)
/// in pixels, left to right.
fn figures_in(png_path: &Path, within: f64) -> Vec<(usize, usize, usize)> {
    let image = common::Rgb::read(png_path);
    let rows = (image.height as f64 * within) as usize;
    image
        .orange_figures(0..image.width, 0..rows, 12)
        .into_iter()
        .map(|f| (f.left, f.right, f.bottom - f.top))
        .collect()
}

/// Under Xvfb + lavapipe, a trial of the crowd example shows three figures in its pane, the
/// front one taller than the two at the back by about the ratio of their distances (read
/// from the screenshot), and its answer is recorded with the scene's ratios and level. One
/// trial only (software rendering on two cores is slow).
#[test]
fn a_crowd_trial_shows_three_figures_at_their_distances_in_the_window() {
    let Some(env) = setup("crowd") else { return };
    let out = env.dir.join("results-crowd");
    let session = out.join("S01_s1");
    // Enter begins; once the vote opens, 4 for the first scene, 2 for the second, Enter.
    let mut run = run_scripted(
        &env,
        "crowd",
        &examples().join("crowd-run1.toml"),
        &[],
        &out,
        "welcome/ready: Enter\ntrial/open once: Backspace 4 2 Enter\n",
    );
    // Screenshots while the first trial plays (its scenes, with greys between, for about
    // 20 s) until one shows a scene; the state, not a sleep, ends the wait.
    run.wait_screen("trial/playing #0");
    let shot = env.dir.join("crowd.png");
    let figures = loop {
        assert!(
            !run.stderr().contains("screen trial/open #0"),
            "the first trial ended without a screenshot showing its scene"
        );
        common::screenshot(&env, &shot);
        // The stimulus area (the answer panel below it has no orange).
        let found = figures_in(&shot, 0.74);
        eprintln!("screenshot: figures (left, right, height) {found:?}");
        if found.len() == 3 {
            break found;
        }
    };
    if let Some(shots) = std::env::var_os("SCREENSHOTS") {
        std::fs::copy(&shot, Path::new(&shots).join("crowd-run1-window.png")).unwrap();
    }
    run.wait_line("done 2");
    run.interrupt();
    let trials = results::trials::read_trials(&session.join("trials.csv")).unwrap();
    let r = &trials.records[0];
    assert_eq!(
        r.response.answer,
        protocols::Answer::Pair { a: 4.0, b: 2.0 },
        "rated 1 then 2"
    );
    assert_eq!(
        r.outcome.score_reference,
        Some(4.0),
        "the reference is shown first"
    );
    let e = r.encoding.as_ref().expect("the row logs the scene");
    assert!(e.codec_params.contains_key("cr_back_left") && e.codec_params.contains_key("level"));
    // The front figure stands between the two at the back and is taller than both; the two
    // at the back, at one distance, are as tall as each other. Perspective makes heights go
    // as 1/distance; the camera looking down 19° shrinks a far figure a little less (its
    // ratio to the front one is 0.8-1.0 of the distances' ratio for this scene).
    let back_cm = [600.0, 900.0, 1300.0][e.codec_params["level"] as usize - 1];
    let ratio_of_distances = back_cm / 350.0;
    let [(_, _, left), (_, _, front), (_, _, right)] = figures[..] else {
        unreachable!()
    };
    let (left, front, right) = (left as f64, front as f64, right as f64);
    assert!((left - right).abs() <= 0.1 * left.max(right), "{figures:?}");
    let ratio = front / (0.5 * (left + right));
    assert!(
        ratio > 0.75 * ratio_of_distances && ratio < 1.1 * ratio_of_distances,
        "front/back height {ratio:.2}, distances {ratio_of_distances:.2}: {figures:?}"
    );
}

/// `study run --measured-*` on a study with `[viewing]` (the MOS example with viewing targets):
/// the window opens on the experimenter's confirmation screen with the measurements filled in;
/// "Conditions confirmed" (Tab to it, Space) records them with the confirmation in
/// `session.json`; after one answer the session is stopped, and `study report
/// --allow-incomplete`'s Method section states what was measured and confirmed.
#[test]
fn measured_viewing_conditions_are_confirmed_recorded_and_reported() {
    let Some(env) = setup("viewing") else { return };
    let study = env.dir.join("viewing.toml");
    // The example without its subject fields (their line and any continuation lines).
    let example = std::fs::read_to_string(examples().join("mos.toml")).unwrap();
    let (before, after) = example.split_once("subject_fields = [").unwrap();
    let after = &after[after.find("]\n").unwrap() + 2..];
    let text = format!("{before}{after}").replace(
        "stimuli = \"stimuli.json\"",
        &format!("stimuli = {:?}", examples().join("stimuli.json")),
    ) + "\n[viewing]\ndistance_cm = 90\nscreen_diagonal_in = 24\nroom_illuminance_lux = 20\n";
    std::fs::write(&study, text).unwrap();
    let out = env.dir.join("results");
    let session = out.join("S01_s1");
    // Four measurement fields, then the button (Tab to it, Space); then the subject's
    // welcome (no fields): Enter begins; one trial answered (4, Enter), so the session is
    // kept when the experimenter stops it.
    let mut run = run_scripted(
        &env,
        "viewing",
        &study,
        &[
            "--measured-distance-cm",
            "88.5",
            "--measured-room-lux",
            "17",
        ],
        &out,
        "viewing: Escape Tab Tab Tab Tab Tab Space\nwelcome/ready: Enter\ntrial/open once: 4 Enter\n",
    );
    run.wait_line("done 3");
    run.interrupt();
    let m: results::SessionManifest =
        results::store::read_manifest(&session.join("session.json")).unwrap();
    let v = m.viewing.expect("the viewing record");
    assert!(v.confirmed && v.confirmed_ms.is_some());
    assert_eq!(v.distance_cm, Some(88.5));
    assert_eq!(v.room_illuminance_lux, Some(17.0));
    assert_eq!(v.peak_luminance_cd_m2, None);
    let report = env.dir.join("report");
    study_ok(&[
        "report".as_ref(),
        out.as_os_str(),
        "--no-png".as_ref(),
        "--allow-incomplete".as_ref(),
        "-o".as_ref(),
        report.as_os_str(),
    ]);
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    for words in [
        "measured 88.5 cm in 1 of 1 sessions",
        "measured 17 lux in 1 of 1 sessions",
        "Viewing conditions confirmed by the experimenter before 1 of 1 sessions.",
    ] {
        assert!(md.contains(words), "{words}: {md}");
    }
}
