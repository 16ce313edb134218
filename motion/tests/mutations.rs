//! Every reader against mutated real files: truncations, byte flips, deleted and duplicated
//! lines, huge declared counts. Each must return `Ok` or an `Err` that names the file, never
//! panic, and never allocate more than the test's memory cap (a capped global allocator makes
//! an unbounded allocation abort the test). 2,000+ cases per format.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use cap::Cap;
use motion::{Limits, ParseError, Skeleton, amc, asf, bvh};
use proptest::prelude::*;

/// 1 GiB for the whole test binary: far above what parsing the real clips needs (a few MB
/// each), far below what a trusted `Frames: 10^12` would ask for.
#[global_allocator]
static ALLOC: Cap<std::alloc::System> = Cap::new(std::alloc::System, 1 << 30);

struct Inputs {
    asf: (PathBuf, String),
    amc: (PathBuf, String),
    bvh: (PathBuf, String),
    skeleton: Skeleton,
}

fn inputs() -> &'static Inputs {
    static I: OnceLock<Inputs> = OnceLock::new();
    I.get_or_init(|| {
        let dir = motion::data::mocap_dir().unwrap_or_else(|| PathBuf::from("/nonexistent"));
        let read = |n: &str| {
            let p = dir.join(n);
            let t = std::fs::read_to_string(&p).unwrap_or_else(|e| {
                panic!("mutation tests need {}: {e} (set MOCAP_DATA)", p.display())
            });
            (p, t)
        };
        let asf = read("12.asf");
        let skeleton = asf::parse_asf(&asf.1, &asf.0, &Limits::default()).unwrap();
        // The first 40 frames keep each case fast; every structure of the file is still there.
        let (amc_path, amc_text) = read("02_01.amc");
        let cut = amc_text
            .find("\n41\r")
            .or_else(|| amc_text.find("\n41\n"))
            .unwrap_or(amc_text.len());
        let (bvh_path, bvh_text) = read("131_01.bvh");
        let bvh_short = shorten_bvh(&bvh_text, 40);
        Inputs {
            asf,
            amc: (amc_path, amc_text[..cut].to_string()),
            bvh: (bvh_path, bvh_short),
            skeleton,
        }
    })
}

fn shorten_bvh(text: &str, frames: usize) -> String {
    let motion = text.find("MOTION").unwrap();
    let (head, tail) = text.split_at(motion);
    let mut lines: Vec<&str> = tail.lines().collect();
    lines.truncate(3 + frames);
    lines[1] = "";
    let mut out = format!("{head}{}\nFrames: {frames}\n", lines[0]);
    for l in &lines[2..] {
        out.push_str(l);
        out.push('\n');
    }
    out
}

#[derive(Debug, Clone)]
enum Mutation {
    Truncate(usize),
    Flip(Vec<(usize, u8)>),
    DeleteLine(usize),
    DuplicateLine(usize),
    HugeNumber(usize, &'static str),
    SwapLines(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::Truncate),
        prop::collection::vec((any::<usize>(), any::<u8>()), 1..6).prop_map(Mutation::Flip),
        any::<usize>().prop_map(Mutation::DeleteLine),
        any::<usize>().prop_map(Mutation::DuplicateLine),
        (
            any::<usize>(),
            prop::sample::select(vec![
                "99999999999999999999",
                "4294967296",
                "1e308",
                "-1",
                "nan",
                "inf",
                "",
                "1000000000",
            ])
        )
            .prop_map(|(i, s)| Mutation::HugeNumber(i, s)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
    ]
}

fn apply(text: &str, m: &Mutation) -> String {
    let bytes = text.as_bytes();
    match m {
        Mutation::Truncate(i) => String::from_utf8_lossy(&bytes[..i % bytes.len()]).into_owned(),
        Mutation::Flip(flips) => {
            let mut b = bytes.to_vec();
            for (i, v) in flips {
                let k = i % b.len();
                b[k] = *v;
            }
            String::from_utf8_lossy(&b).into_owned()
        }
        Mutation::DeleteLine(i) | Mutation::DuplicateLine(i) => {
            let mut lines: Vec<&str> = text.split_inclusive('\n').collect();
            let k = i % lines.len();
            if matches!(m, Mutation::DeleteLine(_)) {
                lines.remove(k);
            } else {
                lines.insert(k, lines[k]);
            }
            lines.concat()
        }
        Mutation::SwapLines(a, b) => {
            let mut lines: Vec<&str> = text.split_inclusive('\n').collect();
            let (x, y) = (a % lines.len(), b % lines.len());
            lines.swap(x, y);
            lines.concat()
        }
        Mutation::HugeNumber(i, s) => {
            // Replace the i-th whitespace-separated numeric token.
            let toks: Vec<(usize, &str)> = text
                .split(|c: char| c.is_whitespace())
                .scan(0usize, |pos, t| {
                    let start = *pos;
                    *pos += t.len() + 1;
                    Some((start, t))
                })
                .filter(|(_, t)| t.parse::<f64>().is_ok())
                .collect();
            if toks.is_empty() {
                return text.to_string();
            }
            let (start, t) = toks[i % toks.len()];
            format!("{}{}{}", &text[..start], s, &text[start + t.len()..])
        }
    }
}

fn check(result: Result<impl Sized, ParseError>, path: &Path) {
    if let Err(e) = result {
        let msg = e.to_string();
        assert!(
            msg.contains(&path.display().to_string()),
            "error does not name the file: {msg}"
        );
        assert!(
            msg.len() < 600,
            "unbounded error message: {} bytes",
            msg.len()
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"))), ..ProptestConfig::default() })]

    #[test]
    fn mutated_asf_never_panics(m in mutation()) {
        let inp = inputs();
        let text = apply(&inp.asf.1, &m);
        check(asf::parse_asf(&text, &inp.asf.0, &Limits::default()), &inp.asf.0);
    }

    #[test]
    fn mutated_amc_never_panics(m in mutation()) {
        let inp = inputs();
        let text = apply(&inp.amc.1, &m);
        check(amc::parse_amc(&text, &inp.amc.0, &inp.skeleton, 120.0, &Limits::default()), &inp.amc.0);
    }

    #[test]
    fn mutated_bvh_never_panics(m in mutation()) {
        let inp = inputs();
        let text = apply(&inp.bvh.1, &m);
        check(bvh::parse_bvh(&text, &inp.bvh.0, &Limits::default()), &inp.bvh.0);
    }
}

fn err<T: std::fmt::Debug>(r: Result<T, ParseError>) -> String {
    r.expect_err("expected an error").to_string()
}

#[test]
fn declared_sizes_are_checked_before_allocating() {
    let inp = inputs();
    let p = &inp.bvh.0;
    let huge = inp.bvh.1.replace("Frames: 40", "Frames: 100000000000");
    let e = err(bvh::parse_bvh(&huge, p, &Limits::default()));
    assert!(e.contains("exceeds the limit"), "{e}");
    // More frames than the bytes present could hold, though under the limits.
    let more = inp.bvh.1.replace("Frames: 40", "Frames: 5000000");
    let e = err(bvh::parse_bvh(&more, p, &Limits::default()));
    assert!(e.contains("exceeds the limit"), "{e}");
    let chans = inp.bvh.1.replacen("CHANNELS 6", "CHANNELS 4000000000", 1);
    let e = err(bvh::parse_bvh(&chans, p, &Limits::default()));
    assert!(e.contains("channels of one joint"), "{e}");
    let small = Limits {
        max_frames: 10,
        ..Limits::default()
    };
    let e = err(amc::parse_amc(
        &inp.amc.1,
        &inp.amc.0,
        &inp.skeleton,
        120.0,
        &small,
    ));
    assert!(e.contains("number of frames"), "{e}");
}

#[test]
fn each_kind_of_bad_input_gets_its_own_clear_error() {
    let inp = inputs();
    let (ap, at) = (&inp.amc.0, &inp.amc.1);
    let sk = &inp.skeleton;
    let amc = |t: &str| err(amc::parse_amc(t, ap, sk, 120.0, &Limits::default()));
    // unknown bone
    let e = amc(&at.replacen("lowerback ", "lowerbak ", 1));
    assert!(
        e.contains("unknown bone `lowerbak`") && e.contains(":6:"),
        "{e}"
    );
    // wrong number of values
    let e = amc(&at.replacen("rtibia 11.5302", "rtibia 11.5302 1.0", 1));
    assert!(e.contains("bone rtibia: expected 1 values, found 2"), "{e}");
    // non-numeric value
    let e = amc(&at.replacen("16.7048", "16.7O48", 1));
    assert!(e.contains("`16.7O48` is not a finite number"), "{e}");
    // a bone missing from a frame
    let e = amc(&at.replacen("ltoes -10.2227", "", 1));
    assert!(e.contains("frame 1 has no line for bone `ltoes`"), "{e}");
    // frame numbering
    let e = amc(&at.replacen("\n2\r", "\n3\r", 1));
    assert!(
        e.contains("frame count mismatch: frame 3 follows frame 1"),
        "{e}"
    );
    // truncated in the middle of a bone line
    let cut = at.rfind("lfemur").unwrap();
    let e = amc(&format!("{} 1.0", &at[..cut + 6]));
    assert!(e.contains("bone lfemur: expected 3 values, found 1"), "{e}");

    let (bp, bt) = (&inp.bvh.0, &inp.bvh.1);
    let bvh = |t: &str| err(bvh::parse_bvh(t, bp, &Limits::default()));
    let e = bvh(&bt.replacen("Zrotation", "Qrotation", 1));
    assert!(e.contains("unknown channel `Qrotation`"), "{e}");
    let e = bvh(&bt.replace("Frames: 40", "Frames: 41"));
    assert!(e.contains("`Frames: 41` but 40 frame lines"), "{e}");
    let e = bvh(&bt[..bt.find("MOTION").unwrap() - 20]);
    assert!(e.contains("file ends early"), "{e}");
    let e = bvh(&bt[..bt.len() - 30]);
    assert!(e.contains("frame 40: expected 96 values"), "{e}");

    let (sp, st) = (&inp.asf.0, &inp.asf.1);
    let asf = |t: &str| err(asf::parse_asf(t, sp, &Limits::default()));
    let e = asf(&st.replacen("lfemur ltibia", "lfemur ltibiaX", 1));
    assert!(e.contains("unknown bone `ltibiaX`"), "{e}");
    let e = asf(&st.replacen("dof rx ry rz", "dof rx ry rq", 1));
    assert!(e.contains("unknown channel `rq`"), "{e}");
    let e = asf(&st[..st.find(":hierarchy").unwrap()]);
    assert!(e.contains("file ends early"), "{e}");
    let e = asf(&st.replacen("length 5.95383", "length five", 1));
    assert!(e.contains("`five` is not a finite number"), "{e}");
}

#[test]
fn crlf_lf_and_mixed_line_endings_read_the_same() {
    let inp = inputs();
    let lf = inp.bvh.1.replace("\r\n", "\n");
    let crlf = lf.replace('\n', "\r\n");
    let mixed: String = lf
        .split_inclusive('\n')
        .enumerate()
        .map(|(i, l)| {
            if i % 2 == 0 {
                l.replace('\n', "\r\n")
            } else {
                l.to_string()
            }
        })
        .collect();
    let a = bvh::parse_bvh(&lf, &inp.bvh.0, &Limits::default()).unwrap();
    let b = bvh::parse_bvh(&crlf, &inp.bvh.0, &Limits::default()).unwrap();
    let c = bvh::parse_bvh(&mixed, &inp.bvh.0, &Limits::default()).unwrap();
    assert_eq!(a, b);
    assert_eq!(a, c);
    let asf_lf = inp.asf.1.replace("\r\n", "\n");
    assert_eq!(
        asf::parse_asf(&asf_lf, &inp.asf.0, &Limits::default()).unwrap(),
        inp.skeleton
    );
}

#[test]
fn bones_without_dof_lines_and_radians_headers_are_read() {
    let inp = inputs();
    // lhipjoint has no dof line in CMU skeletons: it has no channels and stays at rest.
    let j = inp.skeleton.joint_index("lhipjoint").unwrap();
    assert!(inp.skeleton.joints[j].dofs.is_empty());
    // The same motion in radians reads back to the same degrees.
    let deg = amc::parse_amc(
        &inp.amc.1,
        &inp.amc.0,
        &inp.skeleton,
        120.0,
        &Limits::default(),
    )
    .unwrap();
    let mut rad = String::from(":FULLY-SPECIFIED\n:RADIANS\n");
    let mut c = 0;
    for line in inp.amc.1.lines().skip(3) {
        let toks: Vec<&str> = line.split_whitespace().collect();
        if toks.len() == 1 {
            rad.push_str(line.trim());
            rad.push('\n');
            continue;
        }
        let j = inp.skeleton.joint_index(toks[0]).unwrap();
        rad.push_str(toks[0]);
        for (k, t) in toks[1..].iter().enumerate() {
            let v: f64 = t.parse().unwrap();
            let v = if inp.skeleton.joints[j].dofs[k].is_rotation() {
                v.to_radians()
            } else {
                v
            };
            write!(rad, " {v:?}").unwrap();
        }
        rad.push('\n');
        c += 1;
    }
    assert!(c > 0);
    let back = amc::parse_amc(&rad, &inp.amc.0, &inp.skeleton, 120.0, &Limits::default()).unwrap();
    assert_eq!(deg.data().len(), back.data().len());
    for (a, b) in deg.data().iter().zip(back.data()) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
}
