//! Issue 38, item 1: a lab's own codec. A quantiser the test writes in Python (this project
//! knows nothing of it) makes decoded clips and streams; `study stimuli add` measures them
//! against their reference; `study check`, `study simulate` and `study report` then run a
//! MOS study over them. The measurement is the project's own: a clip `study encode` made,
//! added as if it came from elsewhere, gets the ratio and errors `study encode` printed.
//! A clip of another length, the reference given as its own decoded version, files swapped
//! afterwards and a manifest with a negative error are refused, each naming its file or key.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use motion::synth::{WalkParams, walking_clip};

/// The outside codec: every channel value of a BVH's motion rounded to a multiple of `q`;
/// the "stream" is the integers, zlib-compressed.
const QUANTISER: &str = r"
import struct, sys, zlib
src, q, out_bvh, out_stream = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4]
lines = open(src).read().split('\n')
at = next(k for k, l in enumerate(lines) if l.strip().startswith('Frame Time'))
ints, decoded = [], []
for line in lines[at + 1:]:
    if not line.strip():
        continue
    row = [round(float(x) / q) for x in line.split()]
    ints += row
    decoded.append(' '.join('%.6f' % (k * q) for k in row))
open(out_bvh, 'w').write('\n'.join(lines[:at + 1] + decoded) + '\n')
open(out_stream, 'wb').write(zlib.compress(struct.pack('<%di' % len(ints), *ints), 9))
";

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
        .join(format!("stimuli-add-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The numbers after `CR `, `joint RMS ` and `max ` in a `study encode` or `study stimuli
/// add` line.
fn measured(line: &str) -> [f64; 3] {
    ["CR ", "joint RMS ", "max "].map(|key| {
        let rest = &line[line.find(key).unwrap_or_else(|| panic!("{key}: {line}")) + key.len()..];
        let end = rest.find([' ', ',']).unwrap_or(rest.len());
        rest[..end].parse().unwrap()
    })
}

#[test]
#[expect(clippy::too_many_lines, reason = "one lab's steps, in order")]
fn a_codec_of_your_own_is_added_measured_checked_simulated_and_reported() {
    let dir = scratch("own");
    let set = dir.join("set");
    std::fs::create_dir_all(&set).unwrap();
    let walk = set.join("walk.bvh");
    let clip = walking_clip(&WalkParams {
        duration_s: 2.0,
        ..WalkParams::default()
    });
    motion::io::write_clip(&clip, &walk, None, files::Mode::New).unwrap();
    let manifest = set.join("stimuli.json");
    let m = s(&manifest);
    ok(&[
        "stimuli",
        "add",
        m,
        "--clip",
        "walk",
        "--reference",
        s(&walk),
    ]);

    // The outside codec at two steps.
    let script = dir.join("quantise.py");
    std::fs::write(&script, QUANTISER).unwrap();
    // The reference as the file holds it (BVH gives every joint its own channels).
    let read = motion::io::read_clip(None, &walk).unwrap();
    let raw = 4 * read.channel_count() * read.frames();
    for q in ["0.5", "2"] {
        let (bvh, stream) = (
            set.join(format!("walk-q{q}.bvh")),
            set.join(format!("walk-q{q}.bin")),
        );
        let status = Command::new("python3")
            .args([s(&script), s(&walk), q, s(&bvh), s(&stream)])
            .status()
            .unwrap();
        assert!(status.success());
        let said = ok(&[
            "stimuli",
            "add",
            m,
            "--clip",
            "walk",
            "--codec",
            "quant",
            "--file",
            s(&bvh),
            "--stream",
            s(&stream),
            "--param",
            &format!("q={q}"),
        ]);
        let bytes = std::fs::metadata(&stream).unwrap().len();
        let [cr, rms, max] = measured(&said);
        assert!(
            (cr - raw as f64 / bytes as f64).abs() < 0.006,
            "{said}: {raw} / {bytes}"
        );
        assert!(rms > 0.0 && max >= rms, "{said}");
        assert!(
            said.starts_with(&format!("walk/quant/q{q}: {bytes} bytes")),
            "{said}"
        );
    }

    // The same measurement as the project's own codecs: `study encode`'s output, added.
    let enc = set.join("enc");
    let encoded = ok(&[
        "encode",
        s(&walk),
        "--codec",
        "spiht",
        "--cr",
        "12",
        "-o",
        s(&enc),
    ]);
    let added = ok(&[
        "stimuli",
        "add",
        m,
        "--clip",
        "walk",
        "--codec",
        "spiht-elsewhere",
        "--file",
        s(&enc.join("walk.spiht.bvh")),
        "--stream",
        s(&enc.join("walk.spiht.mcz")),
    ]);
    let (a, b) = (measured(&encoded), measured(&added));
    for (x, y) in a.iter().zip(&b) {
        // Printed to 2-3 decimals; the decoded file keeps 6.
        assert!((x - y).abs() <= 0.0011, "encode: {encoded}\nadded: {added}");
    }

    // A MOS study over them: checked, simulated, reported.
    let toml = dir.join("own.toml");
    std::fs::write(
        &toml,
        "format_version = 1\nname = \"own-codec\"\nprotocol = \"mos\"\n\
         stimuli = \"set/stimuli.json\"\nseed = 3\n[conditions]\n\
         stimuli = [\"walk/quant/q0.5\", \"walk/quant/q2\", \"walk/spiht-elsewhere\"]\n",
    )
    .unwrap();
    let checked = ok(&["check", s(&toml)]);
    assert!(checked.contains("4 stimuli read and matched"), "{checked}");
    let res = dir.join("res");
    ok(&["simulate", s(&toml), "--subjects", "4", "-o", s(&res)]);
    let rep = dir.join("rep");
    ok(&[
        "report",
        s(&res),
        "--bootstrap",
        "50",
        "--no-png",
        "-o",
        s(&rep),
    ]);
    let report = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(
        report.contains("quant") && report.contains("spiht-elsewhere"),
        "{report}"
    );

    // Refused: a clip of another length, named with its reference.
    let short = set.join("short.bvh");
    let one_s = walking_clip(&WalkParams {
        duration_s: 1.0,
        ..WalkParams::default()
    });
    motion::io::write_clip(&one_s, &short, None, files::Mode::New).unwrap();
    let add_as = |file: &Path| {
        refused(&[
            "stimuli",
            "add",
            m,
            "--clip",
            "walk",
            "--codec",
            "x",
            "--file",
            s(file),
            "--bytes",
            "100",
        ])
    };
    let err = add_as(&short);
    assert!(
        err.contains("short.bvh")
            && err.contains("walk.bvh")
            && err.contains("frames, its reference"),
        "{err}"
    );
    // The reference as its own decoded version.
    let err = add_as(&walk);
    assert!(
        err.contains("walk.bvh: is the file of its reference \"walk/reference\""),
        "{err}"
    );

    // Files swapped after they were added: the study's preflight names both.
    let (q1, q2) = (set.join("walk-q0.5.bvh"), set.join("walk-q2.bvh"));
    let (t1, t2) = (std::fs::read(&q1).unwrap(), std::fs::read(&q2).unwrap());
    std::fs::write(&q1, &t2).unwrap();
    std::fs::write(&q2, &t1).unwrap();
    let err = refused(&["check", s(&toml)]);
    assert_eq!(
        err.matches("is not the file the manifest was written with")
            .count(),
        2,
        "{err}"
    );
    assert!(
        err.contains("walk-q0.5.bvh") && err.contains("walk-q2.bvh"),
        "{err}"
    );
    std::fs::write(&q1, &t1).unwrap();
    std::fs::write(&q2, &t2).unwrap();
    ok(&["check", s(&toml)]);

    // Without the stream's size: measured, its CR unknown (null), and no study shows it.
    let said = ok(&[
        "stimuli",
        "add",
        m,
        "--clip",
        "walk",
        "--codec",
        "quant",
        "--file",
        s(&q1),
        "--id",
        "walk/quant/no-size",
    ]);
    assert!(
        said.contains("walk/quant/no-size: 0 bytes, CR unknown, joint RMS "),
        "{said}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    let unknown = json["stimuli"]
        .as_array()
        .unwrap()
        .iter()
        .find(|st| st["id"] == "walk/quant/no-size")
        .unwrap();
    assert!(unknown["achieved_cr"].is_null(), "{unknown}");
    assert!(unknown["metrics"]["rms_cm"].as_f64().unwrap() > 0.0);
    let unsized_study = dir.join("unknown.toml");
    std::fs::write(
        &unsized_study,
        std::fs::read_to_string(&toml)
            .unwrap()
            .replace("\"walk/quant/q2\"", "\"walk/quant/no-size\""),
    )
    .unwrap();
    let err = refused(&["check", s(&unsized_study)]);
    assert!(
        err.contains("\"walk/quant/no-size\" has no compression ratio (CR unknown"),
        "{err}"
    );
    // The study that does not show it still loads; a manifest without the key is refused.
    ok(&["check", s(&toml)]);
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(&manifest, text.replacen("\"achieved_cr\": null,", "", 1)).unwrap();
    let err = refused(&["check", s(&toml)]);
    assert!(err.contains("achieved_cr"), "{err}");
    std::fs::write(&manifest, &text).unwrap();

    // A negative error in the manifest: the study does not load, the key named.
    let text = std::fs::read_to_string(&manifest).unwrap();
    let at = text.find("\"rms_cm\": ").unwrap() + "\"rms_cm\": ".len();
    let broken = format!("{}-{}", &text[..at], &text[at..]);
    std::fs::write(&manifest, broken).unwrap();
    let err = refused(&["check", s(&toml)]);
    assert!(
        err.contains("(\"walk/quant/q0.5\").metrics.rms_cm: -")
            && err.contains("is not a finite number 0 or more"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
