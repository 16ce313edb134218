//! Issue 20, item 5: C3D the world reads. What the markers crate writes is read by the two
//! independent C3D readers on PyPI, ezc3d (C++) and py-c3d (pure Python), through
//! `scripts/reference/c3d_reference.py`, with the same labels, rate, units and values as ours
//! and as the CSV output of the same marker set; and our reader reads what they write (float
//! storage from ezc3d, in mm and in m, with and without analog channels; integer storage from
//! py-c3d, since ezc3d writes float only, with and without analog channels).
//!
//! The Python is `$STUDY_PYTHON`, which `scripts/test` points at the venv it makes
//! (`target/pyenv`, ezc3d, c3d and numpy pinned in `scripts/reference/c3d-requirements.txt`),
//! or without the variable that venv itself. Under `CI` a missing interpreter or package fails
//! the tests; elsewhere they skip with a message.
//!
//! Values: float storage holds `f32`, so a value read back is exactly `value as f32`, in every
//! reader. Integer storage holds `round(value / scale)`; the readers return that times the
//! scale, as an exact double (ezc3d) or rounded to `f32` (py-c3d, c3dio), so they agree exactly
//! once rounded to `f32`, and the value is within half a step of what was written (within one
//! step for py-c3d's writer, which truncates).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]
#![expect(
    clippy::float_cmp,
    reason = "a float C3D value must read back bit for bit: these comparisons are exact on purpose"
)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use markers::c3d::{C3dStorage, write_c3d_with};
use markers::data::{self, MarkerSet};
use markers::synth::{SynthOptions, synth_capture};
use serde_json::Value;

/// The Python that has ezc3d, c3d and numpy: `$STUDY_PYTHON`, else the venv scripts/test makes
/// (`target/pyenv`), or `None` (outside CI only) to skip.
fn python() -> Option<PathBuf> {
    let ci = std::env::var_os("CI").is_some();
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/pyenv/bin/python");
    let python = match std::env::var_os("STUDY_PYTHON") {
        Some(p) => PathBuf::from(p),
        None if venv.exists() => venv,
        None if ci => panic!(
            "neither STUDY_PYTHON nor {} is there: under CI the C3D interop tests need the \
             venv with ezc3d, c3d and numpy that scripts/test makes",
            venv.display()
        ),
        None => {
            eprintln!(
                "C3D interop skipped: no STUDY_PYTHON and no target/pyenv (scripts/test makes \
                 it: a venv with ezc3d, c3d and numpy)"
            );
            return None;
        }
    };
    let probe = Command::new(&python)
        .args(["-c", "import ezc3d, c3d, numpy"])
        .output();
    match probe {
        Ok(o) if o.status.success() => Some(python),
        Ok(o) if ci => panic!(
            "{} cannot import ezc3d, c3d and numpy:\n{}",
            python.display(),
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) if ci => panic!("cannot run {}: {e}", python.display()),
        _ => {
            eprintln!(
                "C3D interop skipped: {} lacks ezc3d, c3d or numpy",
                python.display()
            );
            None
        }
    }
}

/// Runs the reference script and parses the JSON it prints.
fn script(python: &Path, args: &[&str]) -> Value {
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/reference/c3d_reference.py");
    let out = Command::new(python)
        .arg(&script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    assert!(
        out.status.success(),
        "c3d_reference.py {args:?} failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the script prints one JSON object")
}

fn tmp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("c3d-interop-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// What one reader made of a file.
struct Read {
    labels: Vec<String>,
    rate_hz: f64,
    header_rate_hz: f64,
    units: String,
    scale: f64,
    frames: usize,
    /// `points[frame][marker]`, `None` where the reader says invalid.
    points: Vec<Vec<Option<[f64; 3]>>>,
    analog_channels: u64,
    warnings: Vec<String>,
}

fn points_of(v: &Value) -> Vec<Vec<Option<[f64; 3]>>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|row| {
            row.as_array()
                .unwrap()
                .iter()
                .map(|p| {
                    p.as_array()
                        .map(|xyz| [0, 1, 2].map(|k| xyz[k].as_f64().unwrap()))
                })
                .collect()
        })
        .collect()
}

fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect()
}

/// Reads `path` with both readers; each must accept it.
fn read_both(python: &Path, path: &Path) -> Vec<(&'static str, Read)> {
    let v = script(python, &["read", path.to_str().unwrap()]);
    [("ezc3d", "ezc3d"), ("py-c3d", "py_c3d")]
        .into_iter()
        .map(|(name, key)| {
            let r = &v[key];
            assert!(
                r.get("error").is_none(),
                "{name} {} refuses {}: {}",
                v["versions"],
                path.display(),
                r["error"]
            );
            let read = Read {
                labels: strings(&r["labels"]),
                rate_hz: r["rate_hz"].as_f64().unwrap(),
                header_rate_hz: r["header_rate_hz"].as_f64().unwrap(),
                units: r["units"].as_str().unwrap().to_string(),
                scale: r["scale"].as_f64().unwrap(),
                frames: r["frames"].as_u64().unwrap() as usize,
                points: points_of(&r["points"]),
                analog_channels: r["analog_channels"].as_u64().unwrap(),
                warnings: strings(&r["warnings"]),
            };
            (name, read)
        })
        .collect()
}

/// `x` as the nearest `f32`, back in `f64`: what a float C3D holds for `x`.
fn f32_of(x: f64) -> f64 {
    f64::from(x as f32)
}

/// Checks one reader's view of a file we wrote from `set` (mm): labels, rates, units, shape,
/// gaps, and every value as `expect` says.
fn check_written(
    what: &str,
    set: &MarkerSet,
    read: &Read,
    expect: impl Fn(f64, f64) -> Result<(), String>,
) {
    assert_eq!(read.labels, set.names(), "{what}: labels");
    assert_eq!(
        read.rate_hz,
        f32_of(set.frame_rate_hz),
        "{what}: POINT:RATE"
    );
    assert_eq!(read.header_rate_hz, read.rate_hz, "{what}: header rate");
    assert_eq!(read.units, "mm", "{what}: POINT:UNITS");
    assert_eq!(read.frames, set.frames(), "{what}: frames");
    assert_eq!(read.analog_channels, 0, "{what}: analog channels");
    // The one warning py-c3d gives every file without analog channels; anything else (an
    // inconsistent DATA_START, a missing POINT:DESCRIPTIONS) means the file is not standard.
    for w in &read.warnings {
        assert_eq!(w, "No analog data found in file.", "{what}: reader warning");
    }
    let mut samples = 0;
    for (f, row) in read.points.iter().enumerate() {
        assert_eq!(row.len(), set.marker_count(), "{what}: frame {f}");
        for (m, theirs) in row.iter().enumerate() {
            match (set.get(f, m), theirs) {
                (None, None) => {}
                (Some(ours), Some(theirs)) => {
                    for k in 0..3 {
                        expect(ours[k], theirs[k]).unwrap_or_else(|why| {
                            panic!(
                                "{what}: frame {f} marker {} axis {k}: {why}",
                                set.names()[m]
                            )
                        });
                    }
                    samples += 1;
                }
                (a, b) => panic!(
                    "{what}: frame {f} marker {}: we wrote {a:?}, it reads {b:?}",
                    set.names()[m]
                ),
            }
        }
    }
    assert!(samples > 0, "{what}: no samples compared");
}

/// Float storage: exactly the `f32` of our value.
fn exactly_f32(ours: f64, theirs: f64) -> Result<(), String> {
    if theirs == f32_of(ours) {
        Ok(())
    } else {
        Err(format!("{theirs} is not {ours} as f32 ({})", f32_of(ours)))
    }
}

/// The demo walk of `study markers synth --demo`, and 240 frames of a shared CMU clip when the
/// data is there: the captures `study markers synth` writes.
fn synth_sets() -> Vec<(String, MarkerSet)> {
    let demo = motion::synth::walking_clip(&motion::synth::WalkParams::default());
    let mut clips = vec![("demo-walk".to_string(), demo)];
    clips.extend(common::walk_clip(240));
    clips
        .into_iter()
        .map(|(name, clip)| {
            let capture = synth_capture(&clip, &SynthOptions::default()).unwrap();
            assert!(
                capture.markers.gap_count() > 0,
                "{name}: the capture has gaps"
            );
            (name, capture.markers)
        })
        .collect()
}

/// What it must show: ezc3d (and py-c3d) read `markers synth` output with values equal to the
/// CSV output. `study markers synth -o X.c3d` and `-o X.csv` are `synth_capture` then
/// `data::write_markers`, as here.
#[test]
fn synth_c3d_reads_in_ezc3d_and_py_c3d_as_the_csv_does() {
    let Some(python) = python() else { return };
    let dir = tmp("synth");
    for (name, set) in synth_sets() {
        let (c3d, csv) = (
            dir.join(format!("{name}.c3d")),
            dir.join(format!("{name}.csv")),
        );
        data::write_markers(&set, &c3d, files::Mode::Replace).unwrap();
        data::write_markers(&set, &csv, files::Mode::Replace).unwrap();
        let from_csv = data::read_markers(&csv).unwrap();
        assert_eq!(from_csv, set, "{name}: the CSV holds the set exactly");
        let ours = data::read_markers(&c3d).unwrap();
        for (reader, read) in read_both(&python, &c3d) {
            check_written(
                &format!("{name} in {reader}"),
                &from_csv,
                &read,
                exactly_f32,
            );
            assert_eq!(read.scale, -1.0, "{name} in {reader}: POINT:SCALE");
            // And our reader agrees with theirs.
            for (f, row) in read.points.iter().enumerate() {
                for (m, p) in row.iter().enumerate() {
                    assert_eq!(ours.get(f, m), *p, "{name}: ours vs {reader}, frame {f}");
                }
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Integer storage: every reader returns the same value once rounded to `f32` (ours, c3dio,
/// rounds there), within half a scale step of the set's.
#[test]
fn integer_c3d_reads_the_same_in_ezc3d_py_c3d_and_ours() {
    let Some(python) = python() else { return };
    let dir = tmp("integer");
    for (name, set) in synth_sets() {
        let path = dir.join(format!("{name}.c3d"));
        write_c3d_with(&set, &path, C3dStorage::Integer, files::Mode::Replace).unwrap();
        let ours = data::read_c3d(&path).unwrap();
        let reads = read_both(&python, &path);
        let scale = reads[0].1.scale;
        assert!(
            scale > 0.0,
            "{name}: POINT:SCALE {scale} marks integer storage"
        );
        for (reader, read) in &reads {
            assert_eq!(read.scale, scale, "{name}: {reader}'s POINT:SCALE");
            let within_half_a_step = |ours: f64, theirs: f64| {
                // Half a step, and the f32 rounding of the step count times the scale.
                let bound = scale * (0.5 + 1e-6) + ours.abs() * 1e-7;
                if (theirs - ours).abs() <= bound {
                    Ok(())
                } else {
                    Err(format!(
                        "{theirs} is {} from {ours}, more than {bound}",
                        theirs - ours
                    ))
                }
            };
            check_written(
                &format!("{name} in {reader}"),
                &set,
                read,
                within_half_a_step,
            );
            for (f, row) in read.points.iter().enumerate() {
                for (m, p) in row.iter().enumerate() {
                    let theirs = p.map(|p| p.map(f32_of));
                    assert_eq!(
                        ours.get(f, m),
                        theirs,
                        "{name}: ours vs {reader}, frame {f}"
                    );
                }
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Past 255 markers the labels continue in `POINT:LABELS2`, `LABELS3`: both readers (and ours)
/// find all of them, in order.
#[test]
fn labels_past_255_markers_read_in_ezc3d_and_py_c3d() {
    let Some(python) = python() else { return };
    let dir = tmp("labels");
    let names: Vec<String> = (0..600).map(|i| format!("marker_{i:03}")).collect();
    let mut set = MarkerSet::new(names, 3, 240.0);
    for f in 0..3 {
        for m in 0..600 {
            if (f + m) % 7 != 0 {
                set.set(
                    f,
                    m,
                    Some([m as f64 + 0.125, -(f as f64) * 3.5, 900.0 + m as f64]),
                );
            }
        }
    }
    let path = dir.join("many.c3d");
    data::write_c3d(&set, &path, files::Mode::Replace).unwrap();
    assert_eq!(data::read_c3d(&path).unwrap(), set);
    for (reader, read) in read_both(&python, &path) {
        check_written(
            &format!("600 markers in {reader}"),
            &set,
            &read,
            exactly_f32,
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Our reader on files ezc3d and py-c3d write: the same labels, rate and points (in mm) as
/// ezc3d and py-c3d read from them, and the values the writer was given.
#[test]
fn our_reader_reads_what_ezc3d_and_py_c3d_write() {
    let Some(python) = python() else { return };
    let dir = tmp("theirs");
    let written = script(&python, &["write", dir.to_str().unwrap()]);
    let files = written["files"].as_array().unwrap();
    let kinds: Vec<(&str, &str, bool)> = files
        .iter()
        .map(|f| {
            (
                f["writer"].as_str().unwrap(),
                f["storage"].as_str().unwrap(),
                f["analog_channels"].as_u64().unwrap() > 0,
            )
        })
        .collect();
    for want in [
        ("ezc3d", "float", false),
        ("ezc3d", "float", true),
        ("py-c3d", "integer", false),
        ("py-c3d", "integer", true),
    ] {
        assert!(
            kinds.contains(&want),
            "no reference file {want:?}: {kinds:?}"
        );
    }
    for file in files {
        let name = file["name"].as_str().unwrap();
        let path = dir.join(name);
        let what = format!("{name} ({})", written["versions"]);
        let ours = data::read_c3d(&path).unwrap_or_else(|e| panic!("{what}: {e}"));
        let units = file["units"].as_str().unwrap();
        let mm_per_unit = match units {
            "mm" => 1.0,
            "m" => 1000.0,
            other => panic!("{what}: units {other}"),
        };
        assert_eq!(ours.names(), strings(&file["labels"]), "{what}: labels");
        let rate = file["rate_hz"].as_f64().unwrap();
        assert_eq!(ours.frame_rate_hz, rate, "{what}: rate");
        // What the writer was given, in mm: floats exactly as f32, integers within the one
        // step py-c3d's truncation may lose.
        let given = points_of(&file["points"]);
        assert_eq!(ours.frames(), given.len(), "{what}: frames");
        let scale = file["scale"].as_f64().unwrap();
        for (f, row) in given.iter().enumerate() {
            for (m, p) in row.iter().enumerate() {
                match (ours.get(f, m), p) {
                    (None, None) => {}
                    (Some(a), Some(b)) => {
                        for k in 0..3 {
                            let ok = if scale < 0.0 {
                                a[k] == f32_of(b[k]) * mm_per_unit
                            } else {
                                (a[k] - b[k]).abs() <= scale * (1.0 + 1e-6) + b[k].abs() * 1e-7
                            };
                            assert!(ok, "{what}: frame {f} marker {m}: ours {a:?}, given {b:?}");
                        }
                    }
                    (a, b) => panic!("{what}: frame {f} marker {m}: ours {a:?}, given {b:?}"),
                }
            }
        }
        // And exactly what ezc3d and py-c3d read from the same file.
        for (reader, read) in read_both(&python, &path) {
            assert_eq!(ours.names(), read.labels, "{what}: labels in {reader}");
            assert_eq!(ours.frame_rate_hz, read.rate_hz, "{what}: rate in {reader}");
            assert_eq!(read.units, units, "{what}: units in {reader}");
            assert_eq!(
                read.analog_channels,
                file["analog_channels"].as_u64().unwrap(),
                "{what}: analog channels in {reader}"
            );
            for (f, row) in read.points.iter().enumerate() {
                for (m, p) in row.iter().enumerate() {
                    let theirs = p.map(|p| p.map(|v| f32_of(v) * mm_per_unit));
                    assert_eq!(
                        ours.get(f, m),
                        theirs,
                        "{what}: ours vs {reader}, frame {f} marker {m}"
                    );
                }
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
