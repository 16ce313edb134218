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
    // An AMC alone in its folder has no skeleton to be read with.
    std::fs::create_dir_all(dir.join("alone")).unwrap();
    std::fs::copy(dir.join("w.amc"), dir.join("alone/w.amc")).unwrap();
    let out = study(&["primitives", "train", &p("alone/w.amc"), "-o", &p("x.pdb")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("w.amc: no ASF skeleton for this motion"),
        "{err}"
    );
}

/// `--db` on encode, decode and sweep with a database trained by `study primitives train` on
/// a shared clip; the manifest records `t_l` and the database fingerprint; a missing or
/// different database is refused with a clear message.
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "one scenario: train, list, encode, decode, mismatch, truncation, sweep"
)]
fn primitive_codec_end_to_end_with_db() {
    let Some(data) = motion::data::mocap_dir() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("study-prim-codec-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let p = |n: &str| dir.join(n).display().to_string();
    let d = |n: &str| data.join(n).display().to_string();
    let ok = |out: &Output| {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let out = study(&["codecs"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("primitive") && text.contains("id 8") && text.contains("--db"),
        "{text}"
    );
    for (db, k) in [("a.pdb", "8"), ("b.pdb", "5")] {
        ok(&study(&[
            "primitives",
            "train",
            &d("12.asf"),
            &d("02_01.amc"),
            "-o",
            &p(db),
            "--k-max",
            k,
        ]));
    }
    let fp = codecs::primitives::Database::read(&dir.join("a.pdb"))
        .unwrap()
        .fingerprint();
    let enc = |db: Option<&str>| {
        let mut args = vec![
            "encode".to_string(),
            d("02_01.amc"),
            "--asf".into(),
            d("12.asf"),
            "--codec".into(),
            "primitive".into(),
            "--param".into(),
            "t_l=0.01".into(),
            "-o".into(),
            p("enc"),
        ];
        if let Some(db) = db {
            args.extend(["--db".to_string(), p(db)]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        study(&args)
    };
    let out = enc(None);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("needs a primitive database"),
        "{err}"
    );
    let out = enc(Some("a.pdb"));
    ok(&out);
    assert!(String::from_utf8_lossy(&out.stdout).contains("CR"));
    let mcz = p("enc/02_01.primitive.mcz");
    let dec = |db: &str| {
        study(&[
            "decode",
            &mcz,
            "--skeleton",
            &d("12.asf"),
            "--db",
            &p(db),
            "-o",
            &p("dec"),
        ])
    };
    ok(&dec("a.pdb"));
    assert!(dir.join("dec/02_01.primitive.amc").is_file());
    let out = dec("b.pdb");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains(&format!("{fp:08x}"))
            && err.contains("fingerprint")
            && err.contains("b.pdb"),
        "{err}"
    );
    let mut bytes = std::fs::read(dir.join("a.pdb")).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(dir.join("cut.pdb"), bytes).unwrap();
    let out = dec("cut.pdb");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("cut.pdb") && err.contains("--db"),
        "{err}"
    );
    ok(&study(&[
        "sweep",
        "--clips",
        &d("02_01.amc"),
        &d("12.asf"),
        "--codecs",
        "primitive",
        "--cr",
        "10",
        "--db",
        &p("a.pdb"),
        "--quiet",
        "-o",
        &p("sweep"),
    ]));
    let json = std::fs::read_to_string(dir.join("sweep/stimuli.json")).unwrap();
    let manifest: serde_json::Value = serde_json::from_str(&json).unwrap();
    let s = manifest["stimuli"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["codec"] == "primitive")
        .unwrap();
    let t_l = s["params"]["t_l"].as_f64().unwrap();
    assert!(t_l > 0.0 && t_l < 1.0, "{s}");
    // The fingerprint is a u32: exact in f64 and in JSON.
    assert_eq!(
        s["params"]["db"]
            .as_u64()
            .or_else(|| s["params"]["db"].as_f64().map(|v| v as u64)),
        Some(u64::from(fp))
    );
    let cr = s["achieved_cr"].as_f64().unwrap();
    assert!((cr / 10.0 - 1.0).abs() <= 0.02, "{cr}");
    std::fs::remove_dir_all(&dir).unwrap();
}
