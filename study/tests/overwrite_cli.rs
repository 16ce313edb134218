//! Outputs are never replaced without `--force`, and a failed write (a full disk) leaves no
//! incomplete file under a final name: `study sweep`, `study report` and the single-file
//! writers, run as a user runs them.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> Output {
    let out = study(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs `args`, which must fail; returns its stderr.
fn refused(args: &[&str]) -> String {
    let out = study(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} succeeded: {err}");
    err
}

/// A fresh scratch folder for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("study-overwrite-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// A one-second generated walk as `dir/walk.amc` + `dir/walk.asf`.
fn walk(dir: &Path) -> (String, String) {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 1.0,
        ..motion::synth::WalkParams::default()
    });
    let (amc, asf) = (dir.join("walk.amc"), dir.join("walk.asf"));
    motion::io::write_clip(&clip, &amc, Some(&asf), files::Mode::New).unwrap();
    (s(&amc), s(&asf))
}

/// Every file under `dir` (relative path → bytes), hidden ones included.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Temporary files (`.<name>.<pid>-<n>.tmp`) left anywhere under `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    tree(dir)
        .into_keys()
        .filter(|k| {
            Path::new(k)
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'))
        })
        .collect()
}

#[test]
fn a_sweep_into_a_folder_holding_files_is_refused_and_force_replaces_them() {
    let dir = scratch("sweep");
    let (amc, asf) = walk(&dir);
    let out = dir.join("stimuli");
    let sweep = |force: bool| {
        let mut args = vec![
            "sweep", "--clips", &amc, &asf, "--codecs", "spiht", "--cr", "10", "--quiet", "-o",
        ];
        let o = s(&out);
        args.push(&o);
        if force {
            args.push("--force");
        }
        args.iter().map(|a| (*a).to_string()).collect::<Vec<_>>()
    };
    let run = |force: bool| study(&sweep(force).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(run(false).status.success());
    // The second run is refused before anything is made, naming the folder and its files.
    std::fs::write(out.join("rd.csv"), "the first sweep's table").unwrap();
    let before = tree(&out);
    let second = run(false);
    assert!(!second.status.success());
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(
        err.contains(&format!(
            "{} is not empty: it holds rd.csv, stimuli.json, walk/",
            out.display()
        )),
        "{err}"
    );
    assert!(err.contains("--force"), "{err}");
    assert_eq!(tree(&out), before, "nothing changed");
    // With --force it runs and replaces its own files, and leaves no temporary file.
    let forced = run(true);
    assert!(
        forced.status.success(),
        "{}",
        String::from_utf8_lossy(&forced.stderr)
    );
    let after = tree(&out);
    assert_eq!(
        after.keys().collect::<Vec<_>>(),
        before.keys().collect::<Vec<_>>()
    );
    assert!(after["rd.csv"].starts_with(b"clip,codec,"));
    assert!(temporaries(&out).is_empty(), "{:?}", temporaries(&out));
    // A folder holding only someone else's file is refused as well.
    let other = dir.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::write(other.join("notes.txt"), "mine").unwrap();
    let err = refused(&[
        "sweep",
        "--clips",
        &amc,
        &asf,
        "--codecs",
        "spiht",
        "--cr",
        "10",
        "--quiet",
        "-o",
        &s(&other),
    ]);
    assert!(err.contains("it holds notes.txt"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_report_into_a_folder_holding_files_is_refused_and_force_replaces_them() {
    let dir = scratch("report");
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let res = s(&dir.join("res"));
    ok(&[
        "simulate",
        &s(&examples.join("mos.toml")),
        "--subjects",
        "3",
        "--seed",
        "5",
        "-o",
        &res,
    ]);
    let rep = dir.join("rep");
    let report = |extra: &[&str]| {
        let mut args = vec!["report", &res, "-o"];
        let r = s(&rep);
        args.push(&r);
        args.extend_from_slice(&["--no-png", "--bootstrap", "50"]);
        args.extend_from_slice(extra);
        study(&args)
    };
    assert!(report(&[]).status.success());
    std::fs::write(rep.join("report.md"), "the first report").unwrap();
    let before = tree(&rep);
    let second = report(&[]);
    assert!(!second.status.success());
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(
        err.contains(&format!("{} is not empty: it holds", rep.display())),
        "{err}"
    );
    assert!(
        err.contains("report.md") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(tree(&rep), before, "nothing changed");
    let forced = report(&["--force"]);
    assert!(
        forced.status.success(),
        "{}",
        String::from_utf8_lossy(&forced.stderr)
    );
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(md.starts_with("# Study"), "{md}");
    assert!(temporaries(&rep).is_empty(), "{:?}", temporaries(&rep));
    // The results folder itself is not a report folder.
    let err = refused(&["report", &res, "-o", &res, "--no-png"]);
    assert!(err.contains("is not empty"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn single_file_outputs_are_refused_unless_forced() {
    let dir = scratch("single");
    let (amc, asf) = walk(&dir);
    let bvh = s(&dir.join("walk.bvh"));
    let csv = s(&dir.join("positions.csv"));
    let enc = dir.join("enc");
    let dec = dir.join("dec");
    let markers = s(&dir.join("walk-markers.csv"));
    let segments = s(&dir.join("segments.toml"));
    let mcz = s(&enc.join("walk.spiht.mcz"));
    let commands: Vec<Vec<String>> = [
        vec!["clip", "convert", &asf, &amc, "-o", &bvh],
        vec!["clip", "positions", &asf, &amc, "--csv", &csv],
        vec![
            "encode",
            &asf,
            &amc,
            "--codec",
            "spiht",
            "--cr",
            "10",
            "-o",
            &s(&enc),
        ],
        vec!["decode", &mcz, "--skeleton", &asf, "-o", &s(&dec)],
        vec![
            "markers",
            "synth",
            &asf,
            &amc,
            "-o",
            &markers,
            "--segments-out",
            &segments,
        ],
    ]
    .iter()
    .map(|c| c.iter().map(|a| (*a).to_string()).collect())
    .collect();
    for c in &commands {
        let args: Vec<&str> = c.iter().map(String::as_str).collect();
        ok(&args);
    }
    let before = tree(&dir);
    for c in &commands {
        let args: Vec<&str> = c.iter().map(String::as_str).collect();
        let err = refused(&args);
        assert!(
            err.contains("already exists") && err.contains("--force"),
            "{args:?}: {err}"
        );
    }
    assert_eq!(tree(&dir), before, "a refused command changed a file");
    for c in &commands {
        let mut args: Vec<&str> = c.iter().map(String::as_str).collect();
        args.push("--force");
        ok(&args);
    }
    assert_eq!(
        tree(&dir).keys().collect::<Vec<_>>(),
        before.keys().collect::<Vec<_>>(),
        "--force replaced the same files and left no temporary"
    );
    // A refusal of a pair names the file that exists and writes neither.
    std::fs::remove_file(dir.join("walk-markers.csv")).unwrap();
    let err = refused(&[
        "markers",
        "synth",
        &asf,
        &amc,
        "-o",
        &markers,
        "--segments-out",
        &segments,
    ]);
    assert!(err.contains("segments.toml already exists"), "{err}");
    assert!(!dir.join("walk-markers.csv").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `study ARGS` with the largest file it may write limited to `blocks` blocks (RLIMIT_FSIZE,
/// `ulimit -f`) and SIGXFSZ ignored, so a write past the limit fails with EFBIG as a write to
/// a full disk fails with ENOSPC: the file system stops taking bytes in the middle of a file.
/// (A small tmpfs would be the real thing, but mounting one needs privileges tests lack.)
fn study_with_file_size_limit(blocks: u32, args: &[&str]) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f {blocks} && exec \"$0\" \"$@\""
        ))
        .arg(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn a_full_disk_leaves_no_incomplete_file_under_a_final_name() {
    let dir = scratch("full");
    let (amc, asf) = walk(&dir);
    // The whole sweep without a limit, for reference (the codecs are deterministic).
    let whole = dir.join("whole");
    let sweep = |out: &Path| -> Vec<String> {
        [
            "sweep", "--clips", &amc, &asf, "--codecs", "spiht", "--cr", "10,20", "--quiet",
            "--jobs", "1", "-o",
        ]
        .iter()
        .map(|a| (*a).to_string())
        .chain([s(out)])
        .collect()
    };
    ok(&sweep(&whole).iter().map(String::as_str).collect::<Vec<_>>());
    let whole_files = tree(&whole);
    // A limit the reference skeleton fits under and the reference motion (written next) does
    // not, whether the shell counts 512- or 1024-byte blocks: the disk fills in the middle of
    // the sweep, and in the middle of a file.
    let (asf_bytes, amc_bytes) = (
        whole_files["walk/reference.asf"].len(),
        whole_files["walk/reference.amc"].len(),
    );
    let blocks = u32::try_from(asf_bytes / 512 + 1).unwrap();
    assert!(
        1024 * blocks as usize + 512 < amc_bytes,
        "the skeleton ({asf_bytes} bytes) and the motion ({amc_bytes} bytes) do not straddle a limit"
    );
    let cut = dir.join("cut");
    let out = study_with_file_size_limit(
        blocks,
        &sweep(&cut).iter().map(String::as_str).collect::<Vec<_>>(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the limited sweep succeeded: {err}");
    assert!(err.contains("File too large"), "{err}");
    // What is there under a final name is complete: byte for byte the file the whole sweep
    // wrote (timings live only in rd.csv and stimuli.json, which come last and are absent).
    let cut_files = tree(&cut);
    assert!(
        !cut_files.is_empty(),
        "the limit stopped the sweep before any file"
    );
    assert!(
        cut_files.len() < whole_files.len(),
        "every file was written"
    );
    assert!(temporaries(&cut).is_empty(), "{:?}", temporaries(&cut));
    for (name, bytes) in &cut_files {
        assert!(
            whole_files.get(name) == Some(bytes),
            "{name} is incomplete ({} bytes)",
            bytes.len()
        );
    }
    // The motion the disk filled up in is not there at all, nor the manifest.
    assert!(
        !cut_files.contains_key("walk/reference.amc"),
        "{:?}",
        cut_files.keys()
    );
    assert!(!cut_files.contains_key("stimuli.json"));
    std::fs::remove_dir_all(&dir).unwrap();
}
