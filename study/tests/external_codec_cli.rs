//! Issue 38, item 2: a codec defined by commands. The test writes a quantiser in Python (this
//! project knows nothing of it) and a definitions file naming its encode and decode commands;
//! `study codecs`, `study encode` (to a target CR, through the project's rate control),
//! `study decode`, `study sweep` and a codec-in-the-loop staircase (`study check`, `study
//! simulate`, `study report`) then use it as they use the built-in codecs, on ASF/AMC and BVH
//! clips. A command that fails, or runs past its time limit, is an error naming the codec,
//! the command and what it wrote on standard error.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use motion::synth::{WalkParams, walking_clip};

/// The outside codec: every motion value of an AMC or BVH file rounded to a multiple of
/// `step`, the file's text with those integers zlib-compressed as the stream. The decoder
/// multiplies them back. `encode IN OUT STEP`, `decode IN OUT STEP`.
const QUANTISER: &str = r"
import sys, zlib
mode, src, out, step = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
def body_start(lines):
    for k, l in enumerate(lines):
        s = l.strip()
        if s.startswith('Frame Time') or s == ':DEGREES' or s == ':RADIANS':
            return k + 1
    sys.exit('no motion section in ' + src)
def num(t):
    try:
        return float(t)
    except ValueError:
        return None
if mode == 'encode':
    lines = open(src).read().split('\n')
    at = body_start(lines)
    for k in range(at, len(lines)):
        toks = lines[k].split()
        if len(toks) > 1:
            lines[k] = ' '.join(t if num(t) is None else str(round(num(t) / step)) for t in toks)
    open(out, 'wb').write(zlib.compress('\n'.join(lines).encode(), 9))
else:
    lines = zlib.decompress(open(src, 'rb').read()).decode().split('\n')
    at = body_start(lines)
    for k in range(at, len(lines)):
        toks = lines[k].split()
        if len(toks) > 1:
            lines[k] = ' '.join(t if num(t) is None else '%.6f' % (int(t) * step) for t in toks)
    open(out, 'w').write('\n'.join(lines))
";

/// The definitions: the quantiser with its step as the rate knob (the CR grows with it), a
/// codec whose encoder fails, and one that never finishes.
const DEFINITIONS: &str = r#"format_version = 1

[codec.quantise]
description = "every motion value rounded to a multiple of step, zlib"
encode = ["python3", "quantise.py", "encode", "{input}", "{output}", "{step}"]
decode = ["python3", "quantise.py", "decode", "{input}", "{output}", "{step}"]
timeout_s = 60
params = { step = 0.5 }
rate = { param = "step", min = 0.0001, max = 200, cr = "grows" }

[codec.broken]
encode = ["python3", "-c", "import sys; sys.stderr.write('no licence for {input}'); sys.exit(3)", "{output}"]
decode = ["python3", "-c", "", "{input}", "{output}"]

[codec.slow]
encode = ["python3", "-c", "import time; time.sleep(30)", "{input}", "{output}"]
decode = ["python3", "-c", "", "{input}", "{output}"]
timeout_s = 1
"#;

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

fn refused(args: &[&str]) -> String {
    let out = study(args);
    assert!(!out.status.success(), "{args:?} was accepted");
    String::from_utf8(out.stderr).unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("external-codec-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("quantise.py"), QUANTISER).unwrap();
    std::fs::write(dir.join("codecs.toml"), DEFINITIONS).unwrap();
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The number after `key` in a line of `study encode`.
fn after(line: &str, key: &str) -> f64 {
    let rest = &line[line.find(key).unwrap_or_else(|| panic!("{key}: {line}")) + key.len()..];
    let end = rest.find([' ', ',']).unwrap_or(rest.len());
    rest[..end].parse().unwrap()
}

/// A 3-s generated walk written as AMC + ASF and as BVH.
fn walks(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let clip = walking_clip(&WalkParams {
        duration_s: 3.0,
        ..WalkParams::default()
    });
    let (amc, asf, bvh) = (
        dir.join("walk.amc"),
        dir.join("walk.asf"),
        dir.join("walk.bvh"),
    );
    motion::io::write_clip(&clip, &amc, Some(&asf), files::Mode::New).unwrap();
    motion::io::write_clip(&clip, &bvh, None, files::Mode::New).unwrap();
    (amc, asf, bvh)
}

#[test]
fn a_command_defined_codec_encodes_to_a_target_and_decodes() {
    let dir = scratch("encode");
    let defs = dir.join("codecs.toml");
    let d = s(&defs);
    let (amc, asf, bvh) = walks(&dir);

    let listed = ok(&["codecs", "--codec-defs", d]);
    assert!(
        listed.contains("quantise") && listed.contains("id 255") && listed.contains("step=0.5"),
        "{listed}"
    );
    assert!(listed.contains("target CR by search"), "{listed}");

    for (input, skeleton) in [(vec![s(&amc), s(&asf)], &asf), (vec![s(&bvh)], &bvh)] {
        let out = dir.join(format!("enc-{}", input.len()));
        let mut args = vec!["encode"];
        args.extend(&input);
        args.extend([
            "--codec",
            "quantise",
            "--codec-defs",
            d,
            "--cr",
            "10",
            "-o",
            s(&out),
        ]);
        let said = ok(&args);
        let cr = after(&said, "CR ");
        // The project's rate control reached the target through the command's knob.
        assert!((cr / 10.0 - 1.0).abs() <= 0.02, "{said}");
        let (rms, max) = (after(&said, "joint RMS "), after(&said, "max "));
        assert!(rms > 0.0 && max >= rms && max < 50.0, "{said}");
        let ext = if input.len() == 2 { "amc" } else { "bvh" };
        let mcz = out.join("walk.quantise.mcz");
        // The stream decodes with the definitions, to the clip the encode wrote.
        let dec = dir.join(format!("dec-{ext}"));
        ok(&[
            "decode",
            s(&mcz),
            "--skeleton",
            s(skeleton),
            "--codec-defs",
            d,
            "-o",
            s(&dec),
        ]);
        let read = |p: &Path| {
            if ext == "amc" {
                motion::io::read_clip(Some(&asf), p).unwrap()
            } else {
                motion::io::read_clip(None, p).unwrap()
            }
        };
        let encoded = read(&out.join(format!("walk.quantise.{ext}")));
        let decoded = read(&dec.join(format!("walk.quantise.{ext}")));
        assert_eq!(encoded.frames(), decoded.frames());
        assert_eq!(encoded.data(), decoded.data());
        // Without the definitions the stream says which codec it needs.
        let e = refused(&[
            "decode",
            s(&mcz),
            "--skeleton",
            s(skeleton),
            "-o",
            s(&dir.join("nowhere")),
        ]);
        assert!(
            e.contains("`quantise`") && e.contains("--codec-defs"),
            "{e}"
        );
    }
}

#[test]
fn a_sweep_over_it_reaches_every_target_beside_a_built_in_codec() {
    let dir = scratch("sweep");
    let defs = dir.join("codecs.toml");
    let d = s(&defs);
    let (amc, asf, _) = walks(&dir);
    let set = dir.join("set");
    let said = ok(&[
        "sweep",
        "--clips",
        s(&amc),
        s(&asf),
        "--codecs",
        "quantise,spiht",
        "--cr",
        "6,15",
        "--codec-defs",
        d,
        "--quiet",
        "-o",
        s(&set),
    ]);
    assert!(said.contains("5 stimuli (1 references)"), "{said}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(set.join("stimuli.json")).unwrap()).unwrap();
    let mut quantised = 0;
    for st in manifest["stimuli"].as_array().unwrap() {
        if st["codec"] != "quantise" {
            continue;
        }
        quantised += 1;
        let target = st["target_cr"].as_f64().unwrap();
        let cr = st["achieved_cr"].as_f64().unwrap();
        assert!((cr / target - 1.0).abs() <= 0.02, "{st}");
        assert!(st["metrics"]["rms_cm"].as_f64().unwrap() > 0.0, "{st}");
        assert!(st["sha256"].as_str().is_some(), "{st}");
    }
    assert_eq!(quantised, 2);
    let rd = std::fs::read_to_string(set.join("rd.csv")).unwrap();
    assert_eq!(
        rd.lines().filter(|l| l.contains(",quantise,")).count(),
        2,
        "{rd}"
    );
}

#[test]
fn a_live_staircase_runs_with_the_command_defined_codec_in_the_loop() {
    let dir = scratch("live");
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/live/stimuli.json");
    let manifest = manifest.canonicalize().unwrap();
    let toml = dir.join("live.toml");
    std::fs::write(
        &toml,
        format!(
            r#"format_version = 1
name = "live-own-codec"
protocol = "staircase"
stimuli = "{}"
seed = 5

[presentation]
arrangement = "side_by_side"
stimulus_duration_ms = 1000

[staircase]
param = "cr"
codec = "quantise"
start = 20
step = 1.5
min = 2
max = 60
n_up = 1
n_down = 2
stop_reversals = 6
max_trials = 30
threshold_reversals = 4

[staircase.live]
clips = ["walk", "stroll"]
codecs = "codecs.toml"

[simulation]
detection = "error"
metric = "rms_cm"
psychometric = "weibull"
threshold = 1.0
slope = 3
lapse = 0.02
"#,
            manifest.display()
        ),
    )
    .unwrap();
    let checked = ok(&["check", s(&toml)]);
    assert!(checked.contains("codec quantise"), "{checked}");
    let res = dir.join("res");
    ok(&["simulate", s(&toml), "--subjects", "2", "-o", s(&res)]);
    // Every trial's stimulus was made by the command at the level's ratio.
    let mut trials = 0;
    for entry in std::fs::read_dir(&res).unwrap() {
        let path = entry.unwrap().path().join("trials.csv");
        let Ok(text) = std::fs::read_to_string(&path) else {
            continue;
        };
        let mut rows = csv::Reader::from_reader(text.as_bytes());
        let head = rows.headers().unwrap().clone();
        let col = |n: &str| head.iter().position(|h| h == n).unwrap();
        let (level, cr, params) = (col("level"), col("achieved_cr"), col("codec_params"));
        for row in rows.records() {
            let row = row.unwrap();
            assert!(row[params].contains("step="), "{row:?}");
            let (l, c): (f64, f64) = (row[level].parse().unwrap(), row[cr].parse().unwrap());
            assert!((c / l - 1.0).abs() <= 0.02, "level {l}, CR {c}");
            trials += 1;
        }
    }
    assert!(trials >= 12, "{trials} trials");
    let rep = dir.join("rep");
    ok(&["report", s(&res), "--no-png", "-o", s(&rep)]);
    let report = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(report.contains("quantise"), "{report}");

    // A definitions file that is not there is the study's problem, keyed.
    let text = std::fs::read_to_string(&toml).unwrap();
    std::fs::write(
        &toml,
        text.replace("codecs = \"codecs.toml\"", "codecs = \"gone.toml\""),
    )
    .unwrap();
    let e = refused(&["check", s(&toml)]);
    assert!(
        e.contains("staircase.live.codecs") && e.contains("gone.toml"),
        "{e}"
    );
}

#[test]
fn a_failing_or_hanging_command_is_an_error_naming_it() {
    let dir = scratch("fail");
    let defs = dir.join("codecs.toml");
    let (amc, asf, _) = walks(&dir);
    let e = refused(&[
        "encode",
        s(&amc),
        s(&asf),
        "--codec",
        "broken",
        "--codec-defs",
        s(&defs),
        "-o",
        s(&dir.join("out")),
    ]);
    assert!(
        e.contains("codec `broken`")
            && e.contains("exit status: 3")
            && e.contains("no licence for"),
        "{e}"
    );
    assert_eq!(
        e.matches("standard error ends: no licence").count(),
        1,
        "said once: {e}"
    );
    let started = std::time::Instant::now();
    let e = refused(&[
        "encode",
        s(&amc),
        s(&asf),
        "--codec",
        "slow",
        "--codec-defs",
        s(&defs),
        "-o",
        s(&dir.join("out")),
    ]);
    assert!(
        e.contains("codec `slow`") && e.contains("did not finish within 1 s"),
        "{e}"
    );
    assert!(
        started.elapsed().as_secs() < 20,
        "the command was not killed"
    );
    // Nothing is left in the temporary folder by either.
    let left: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("study-codec-broken-") || n.starts_with("study-codec-slow-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
