//! `study primitives train/info` end to end.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::process::{Command, Output};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn train_then_info_then_refuse_a_corrupt_database() {
    let dir = std::env::temp_dir().join(format!("study-prim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = |n: &str| dir.join(n).display().to_string();
    let out = study(&[
        "clip",
        "convert",
        "--demo",
        "-o",
        &p("w.amc"),
        "--out-asf",
        &p("w.asf"),
    ]);
    assert!(out.status.success());
    let out = study(&[
        "primitives",
        "train",
        &p("w.asf"),
        &p("w.amc"),
        "-o",
        &p("w.pdb"),
        "--k-max",
        "6",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("fingerprint"));
    let out = study(&["primitives", "info", &p("w.pdb")]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("lfemur") && text.contains("segments"),
        "{text}"
    );
    let mut bytes = std::fs::read(dir.join("w.pdb")).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x40;
    std::fs::write(dir.join("bad.pdb"), bytes).unwrap();
    let out = study(&["primitives", "info", &p("bad.pdb")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("bad.pdb") && err.contains("checksum"),
        "{err}"
    );
    let out = study(&["primitives", "train", &p("w.amc"), "-o", &p("x.pdb")]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("needs an ASF before it"));
}
