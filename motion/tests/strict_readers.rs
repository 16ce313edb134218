//! The readers' strictness about values (issue 19, item 5): ASF bone directions finite and
//! non-zero, normalised with a warning when off unit length, refused when zero or far from it;
//! bone lengths and BVH offsets bounded; a key given twice in one ASF bone block or BVH joint
//! refused; non-finite numbers refused in ASF, AMC and BVH. Every refusal must name the file
//! and the line and say its cause once; each test below checks all three, so it fails when any
//! is lost. The real CMU clips must still read, with no warning.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};

use motion::{Limits, ParseError, ReadWarning, Rest, Skeleton, amc, asf, bvh, io};

const ASF_PATH: &str = "/lab/clips/strict.asf";
const AMC_PATH: &str = "/lab/clips/strict.amc";
const BVH_PATH: &str = "/lab/clips/strict.bvh";

/// A small ASF skeleton; line `k` of the file is `ASF[k - 1]`.
const ASF: [&str; 37] = [
    ":version 1.10",             // 1
    ":name strict",              // 2
    ":units",                    // 3
    "  mass 1.0",                // 4
    "  length 0.45",             // 5
    "  angle deg",               // 6
    ":root",                     // 7
    "  order TX TY TZ RX RY RZ", // 8
    "  axis XYZ",                // 9
    "  position 0 0 0",          // 10
    "  orientation 0 0 0",       // 11
    ":bonedata",                 // 12
    "  begin",                   // 13
    "    id 1",                  // 14
    "    name lfemur",           // 15
    "    direction 0 -1 0",      // 16
    "    length 7",              // 17
    "    axis 0 0 20 XYZ",       // 18
    "    dof rx ry rz",          // 19
    "    limits (-160 20)",      // 20
    "           (-70 70)",       // 21
    "           (-60 70)",       // 22
    "  end",                     // 23
    "  begin",                   // 24
    "    id 2",                  // 25
    "    name ltibia",           // 26
    "    direction 0 -1 0",      // 27
    "    length 7.5",            // 28
    "    axis 0 0 20 XYZ",       // 29
    "    dof rx",                // 30
    "    limits (-10 170)",      // 31
    "  end",                     // 32
    ":hierarchy",                // 33
    "  begin",                   // 34
    "    root lfemur",           // 35
    "    lfemur ltibia",         // 36
    "  end",                     // 37
];

/// Motion for [`ASF`]: root 6 values, lfemur 3, ltibia 1.
const AMC: [&str; 10] = [
    ":FULLY-SPECIFIED", // 1
    ":DEGREES",         // 2
    "1",                // 3
    "root 0 0 0 0 0 0", // 4
    "lfemur 10 20 30",  // 5
    "ltibia 40",        // 6
    "2",                // 7
    "root 0 1 0 0 0 0", // 8
    "lfemur 11 21 31",  // 9
    "ltibia 41",        // 10
];

/// A small BVH clip: a root, one joint and its end site, two frames.
const BVH: [&str; 20] = [
    "HIERARCHY",                                                                // 1
    "ROOT Hips",                                                                // 2
    "{",                                                                        // 3
    "\tOFFSET 0 0 0",                                                           // 4
    "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation", // 5
    "\tJOINT LeftUpLeg",                                                        // 6
    "\t{",                                                                      // 7
    "\t\tOFFSET 3 -2 0",                                                        // 8
    "\t\tCHANNELS 3 Zrotation Xrotation Yrotation",                             // 9
    "\t\tEnd Site",                                                             // 10
    "\t\t{",                                                                    // 11
    "\t\t\tOFFSET 0 -40 0",                                                     // 12
    "\t\t}",                                                                    // 13
    "\t}",                                                                      // 14
    "}",                                                                        // 15
    "MOTION",                                                                   // 16
    "Frames: 2",                                                                // 17
    "Frame Time: 0.0083333",                                                    // 18
    "0 90 0 0 0 0 10 20 30",                                                    // 19
    "1 90 0 0 0 0 11 21 31",                                                    // 20
];

/// `lines` as a file, with line `line` (1-based) replaced by `with`.
fn replaced(lines: &[&str], line: usize, with: &str) -> String {
    assert!(line >= 1 && line <= lines.len(), "no line {line}");
    let mut v: Vec<&str> = lines.to_vec();
    v[line - 1] = with;
    v.join("\n") + "\n"
}

/// `lines` as a file, with `new` inserted after line `after`, so that `new` is line
/// `after + 1`.
fn inserted(lines: &[&str], after: usize, new: &str) -> String {
    let mut v: Vec<&str> = lines.to_vec();
    v.insert(after, new);
    v.join("\n") + "\n"
}

fn parse_asf(text: &str) -> Result<(Skeleton, Vec<ReadWarning>), ParseError> {
    asf::parse_asf_with_warnings(text, Path::new(ASF_PATH), &Limits::default())
}

fn skeleton() -> Skeleton {
    let (sk, warnings) = parse_asf(&(ASF.join("\n") + "\n")).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    sk
}

/// The message of `result`'s error, after checking that it names `path` and `line`, and says
/// `reason` exactly once.
fn refused<T: std::fmt::Debug>(
    result: Result<T, ParseError>,
    path: &str,
    line: usize,
    reason: &str,
) -> String {
    let msg = match result {
        Ok(v) => panic!("expected an error at {path}:{line} ({reason}), got Ok({v:?})"),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.starts_with(&format!("{path}:{line}: ")),
        "`{msg}` does not name {path}:{line}"
    );
    assert_eq!(
        msg.matches(reason).count(),
        1,
        "`{msg}` should say `{reason}` once"
    );
    msg
}

fn direction_of(sk: &Skeleton, bone: &str) -> [f64; 3] {
    let j = sk.joint_index(bone).unwrap();
    match sk.joints[j].rest {
        Rest::Bone { direction, .. } => direction,
        Rest::Offset(_) => panic!("{bone} is not an ASF bone"),
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

// ---------------------------------------------------------------------------------------- ASF

#[test]
fn asf_zero_direction_is_refused_naming_file_and_line() {
    for zero in ["0 0 0", "0 -0 0", "-0 -0 -0", "0.0 0e10 0"] {
        let text = replaced(&ASF, 16, &format!("    direction {zero}"));
        let msg = refused(
            parse_asf(&text),
            ASF_PATH,
            16,
            "a zero vector points nowhere",
        );
        assert!(msg.contains("direction of bone lfemur"), "{msg}");
    }
    // The second bone's line is named, not the first's.
    let text = replaced(&ASF, 27, "    direction 0 0 0");
    let msg = refused(
        parse_asf(&text),
        ASF_PATH,
        27,
        "a zero vector points nowhere",
    );
    assert!(msg.contains("direction of bone ltibia"), "{msg}");
}

#[test]
fn asf_huge_or_tiny_directions_are_refused_naming_file_and_line() {
    for (dir, length) in [
        ("0 -1000 0", "1000"),
        ("1e308 0 0", "1e308"),
        // Squaring these would overflow to inf; the length is still computed.
        ("1e308 1e308 1e308", "1.7320508075688772e308"),
        ("0 2.001 0", "2.001"),
        ("0 0.499 0", "0.499"),
        ("0 1e-9 0", "1e-9"),
        ("1e-320 0 0", "1e-320"),
    ] {
        let text = replaced(&ASF, 16, &format!("    direction {dir}"));
        let msg = refused(
            parse_asf(&text),
            ASF_PATH,
            16,
            "too far from one to normalise",
        );
        assert!(
            msg.contains(&format!(
                "direction of bone lfemur is {dir}, of length {length}"
            )),
            "{msg}"
        );
    }
}

#[test]
fn asf_direction_off_unit_length_is_normalised_with_a_warning() {
    let s = 1.0 / 2.0_f64.sqrt();
    for (dir, want, norm_text) in [
        ("1 1 0", [s, s, 0.0], "1.4142135623730951"),
        ("0 -0.5 0", [0.0, -1.0, 0.0], "0.5"),
        ("0 -2 0", [0.0, -1.0, 0.0], "2"),
        ("0 0 1.01", [0.0, 0.0, 1.0], "1.01"),
    ] {
        let text = replaced(&ASF, 16, &format!("    direction {dir}"));
        let (sk, warnings) = parse_asf(&text).unwrap();
        let got = direction_of(&sk, "lfemur");
        for k in 0..3 {
            assert!(
                (got[k] - want[k]).abs() < 1e-15,
                "{dir}: {got:?} vs {want:?}"
            );
        }
        assert!((norm(got) - 1.0).abs() < 1e-15, "{dir}: {got:?}");
        // The length stays the file's: only the direction is changed.
        let j = sk.joint_index("lfemur").unwrap();
        assert!((sk.joints[j].rest.length() - 7.0).abs() < 1e-15);
        assert_eq!(warnings.len(), 1, "{dir}: {warnings:?}");
        let w = &warnings[0];
        assert_eq!(w.path, PathBuf::from(ASF_PATH));
        assert_eq!(w.line, 16);
        let shown = w.to_string();
        assert!(shown.starts_with(&format!("{ASF_PATH}:16: ")), "{shown}");
        assert!(
            w.message.contains(&format!(
                "direction of bone lfemur is {dir}, of length {norm_text}: normalised to "
            )),
            "{shown}"
        );
        // The warning says what the direction became, as the skeleton holds it.
        let after = w.message.rsplit("normalised to ").next().unwrap();
        let said: Vec<f64> = after.split(' ').map(|t| t.parse().unwrap()).collect();
        assert_eq!(said, got.to_vec(), "{shown}");
        // The reader that drops warnings gives the same skeleton.
        let plain = asf::parse_asf(&text, Path::new(ASF_PATH), &Limits::default()).unwrap();
        assert_eq!(plain, sk);
    }
}

#[test]
#[expect(
    clippy::float_cmp,
    reason = "kept as written is bit for bit, and c / |c| is exactly 1 for one non-zero axis"
)]
fn asf_direction_within_the_tolerance_is_kept_as_written_without_warning() {
    // 0.99995 is 5e-5 from unit length: inside the 1e-4 tolerance.
    let text = replaced(&ASF, 16, "    direction 0 -0.99995 0");
    let (sk, warnings) = parse_asf(&text).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(direction_of(&sk, "lfemur"), [0.0, -0.99995, 0.0]);
    // Just outside it, the same direction is normalised.
    let text = replaced(&ASF, 16, "    direction 0 -0.9998 0");
    let (sk, warnings) = parse_asf(&text).unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!(direction_of(&sk, "lfemur"), [0.0, -1.0, 0.0]);
}

#[test]
fn a_normalised_skeleton_writes_and_reads_back_without_warning() {
    let text = replaced(&ASF, 16, "    direction 1 1 0");
    let (sk, warnings) = parse_asf(&text).unwrap();
    assert_eq!(warnings.len(), 1);
    let written = asf::write_asf(&sk, Path::new(ASF_PATH)).unwrap();
    let (back, warnings) = parse_asf(&written).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(back, sk);
}

#[test]
fn asf_bone_length_is_bounded_in_centimetres() {
    // length 0.45: one unit is 2.54 / 0.45 = 5.644 cm, so 1771 units is 9996 cm and 1772 is
    // 10001.96 cm.
    let text = replaced(&ASF, 17, "    length 1771");
    parse_asf(&text).unwrap();
    let cm_per_unit = 2.54 / 0.45;
    for (length, cm) in [
        ("1772", format!("{:?}", 1772.0 * cm_per_unit)),
        ("1e300", format!("{:?}", 1e300 * cm_per_unit)),
        ("1e308", "inf".to_string()),
    ] {
        assert!(cm.starts_with("10001.9") || cm.contains("e300") || cm == "inf");
        let text = replaced(&ASF, 17, &format!("    length {length}"));
        let msg = refused(parse_asf(&text), ASF_PATH, 17, "over the limit of 10000 cm");
        assert!(
            msg.contains(&format!("length of bone lfemur is {cm} cm")),
            "{msg}"
        );
    }
    // Without `:units length` a unit is taken as 1 cm: the bound is 1e4 units.
    let mut no_units: Vec<&str> = ASF.to_vec();
    no_units[4] = "  mass 1.0"; // line 5 `length 0.45` becomes a second `mass`
    no_units[16] = "    length 10001";
    let msg = refused(
        parse_asf(&(no_units.join("\n") + "\n")),
        ASF_PATH,
        17,
        "over the limit of 10000 cm",
    );
    assert!(msg.contains("length of bone lfemur is 10001 cm"), "{msg}");
    // A negative length was refused before and still is.
    let text = replaced(&ASF, 28, "    length -1");
    refused(parse_asf(&text), ASF_PATH, 28, "bone length is negative");
}

#[test]
fn asf_units_length_that_breaks_the_unit_is_refused() {
    for l in ["1e-310", "1e-320"] {
        let text = replaced(&ASF, 5, &format!("  length {l}"));
        let msg = refused(
            parse_asf(&text),
            ASF_PATH,
            5,
            "which no length can be measured in",
        );
        assert!(msg.contains("one unit inf cm"), "{msg}");
    }
}

#[test]
fn asf_non_finite_numbers_are_refused_naming_file_and_line() {
    for bad in ["nan", "NaN", "inf", "-inf", "infinity", "1e999", "-1e999"] {
        for (line, with, what) in [
            (4, format!("  mass {bad}"), "units mass"),
            (5, format!("  length {bad}"), "units length"),
            (10, format!("  position 0 {bad} 0"), "root position"),
            (11, format!("  orientation {bad} 0 0"), "root orientation"),
            (
                16,
                format!("    direction 0 {bad} 0"),
                "direction of bone lfemur",
            ),
            (17, format!("    length {bad}"), "length of bone lfemur"),
            (
                18,
                format!("    axis 0 {bad} 20 XYZ"),
                "axis of bone lfemur",
            ),
            (21, format!("           (-70 {bad})"), "limits"),
            (
                29,
                format!("    axis {bad} 0 20 XYZ"),
                "axis of bone ltibia",
            ),
        ] {
            // `inf` in limits is an unbounded range, which ASF allows; tested below.
            if line == 21 && ["inf", "-inf"].contains(&bad) {
                continue;
            }
            let text = replaced(&ASF, line, &with);
            let msg = refused(
                parse_asf(&text),
                ASF_PATH,
                line,
                &format!("`{bad}` is not a finite number"),
            );
            assert!(msg.contains(what), "{msg}");
        }
    }
    let text = replaced(&ASF, 21, "           (-inf inf)");
    let sk = parse_asf(&text).unwrap().0;
    let j = sk.joint_index("lfemur").unwrap();
    assert_eq!(sk.joints[j].limits[1], (f64::NEG_INFINITY, f64::INFINITY));
}

#[test]
fn asf_radian_angles_too_large_for_degrees_are_refused() {
    let rad = |line: usize, with: &str| {
        let mut v: Vec<&str> = ASF.to_vec();
        v[5] = "  angle rad";
        v[line - 1] = with;
        v.join("\n") + "\n"
    };
    let msg = refused(
        parse_asf(&rad(18, "    axis 0 0 1e307 XYZ")),
        ASF_PATH,
        18,
        "1e307 rad is too large to hold in degrees",
    );
    assert!(msg.contains("axis of bone lfemur"), "{msg}");
    refused(
        parse_asf(&rad(11, "  orientation 0 -1e307 0")),
        ASF_PATH,
        11,
        "-1e307 rad is too large to hold in degrees",
    );
    refused(
        parse_asf(&rad(21, "           (-1e307 1)")),
        ASF_PATH,
        21,
        "-1e307 rad is too large to hold in degrees",
    );
    // Ordinary radians still read.
    let sk = parse_asf(&rad(18, "    axis 0 0 1 XYZ")).unwrap().0;
    let j = sk.joint_index("lfemur").unwrap();
    assert!((sk.joints[j].axis_deg[2] - 1.0_f64.to_degrees()).abs() < 1e-12);
}

#[test]
fn asf_repeated_keys_in_one_bone_block_are_refused() {
    // Each duplicate goes after line 22 (the last `limits` line of lfemur), so it is line 23.
    for (dup, key, first) in [
        ("    id 9", "id", 14),
        ("    name lfemur2", "name", 15),
        ("    direction 0 1 0", "direction", 16),
        ("    length 3", "length", 17),
        ("    axis 0 0 0 XYZ", "axis", 18),
        ("    dof rx", "dof", 19),
        ("    limits (-1 1)", "limits", 20),
    ] {
        let text = inserted(&ASF, 22, dup);
        refused(
            parse_asf(&text),
            ASF_PATH,
            23,
            &format!("bone lfemur: `{key}` given twice in one bone block (first on line {first})"),
        );
    }
    // The same key in two blocks is one per block: the base file has that and reads.
    skeleton();
}

#[test]
#[expect(
    clippy::float_cmp,
    reason = "c / |c| is exactly 1 for a direction along one axis"
)]
fn read_asf_names_the_file_it_read() {
    let dir = std::env::temp_dir().join(format!("strict-readers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("zero-direction.asf");
    std::fs::write(&path, replaced(&ASF, 27, "    direction 0 0 0")).unwrap();
    let shown = path.display().to_string();
    refused(
        asf::read_asf(&path),
        &shown,
        27,
        "a zero vector points nowhere",
    );
    // And the clip reader, which the commands use, says the same.
    let amc_path = dir.join("zero-direction.amc");
    std::fs::write(&amc_path, AMC.join("\n")).unwrap();
    refused(
        io::read_clip(Some(&path), &amc_path),
        &shown,
        27,
        "a zero vector points nowhere",
    );
    // A normalised direction reaches the clip reader's warnings.
    std::fs::write(&path, replaced(&ASF, 27, "    direction 0 -3 0")).unwrap();
    let err = io::read_clip(Some(&path), &amc_path).unwrap_err();
    assert!(
        err.to_string().contains("too far from one to normalise"),
        "{err}"
    );
    std::fs::write(&path, replaced(&ASF, 27, "    direction 0 -1.5 0")).unwrap();
    let (clip, warnings) = io::read_clip_with_warnings(Some(&path), &amc_path).unwrap();
    assert_eq!(direction_of(&clip.skeleton, "ltibia"), [0.0, -1.0, 0.0]);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!(
        (warnings[0].path.as_path(), warnings[0].line),
        (path.as_path(), 27)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

// ---------------------------------------------------------------------------------------- AMC

fn parse_amc(text: &str) -> Result<motion::Clip, ParseError> {
    amc::parse_amc(
        text,
        Path::new(AMC_PATH),
        &skeleton(),
        120.0,
        &Limits::default(),
    )
}

#[test]
fn amc_non_finite_values_are_refused_naming_file_and_line() {
    parse_amc(&AMC.join("\n")).unwrap();
    for bad in [
        "nan", "NaN", "inf", "-inf", "+inf", "infinity", "1e999", "-1e400",
    ] {
        let text = replaced(&AMC, 9, &format!("lfemur 11 {bad} 31"));
        let msg = refused(
            parse_amc(&text),
            AMC_PATH,
            9,
            &format!("`{bad}` is not a finite number"),
        );
        assert!(msg.contains("bone lfemur"), "{msg}");
        let text = replaced(&AMC, 4, &format!("root {bad} 0 0 0 0 0"));
        let msg = refused(
            parse_amc(&text),
            AMC_PATH,
            4,
            &format!("`{bad}` is not a finite number"),
        );
        assert!(msg.contains("bone root"), "{msg}");
    }
}

#[test]
fn amc_radians_too_large_for_degrees_are_refused() {
    let mut v: Vec<&str> = AMC.to_vec();
    v[1] = ":RADIANS";
    v[9] = "ltibia 1e307";
    let msg = refused(
        parse_amc(&v.join("\n")),
        AMC_PATH,
        10,
        "1e307 rad is too large to hold in degrees",
    );
    assert!(msg.contains("bone ltibia"), "{msg}");
    // A translation is not an angle: the same value there is no rotation to convert.
    v[9] = "ltibia 1";
    v[7] = "root 1e307 0 0 0 0 0";
    parse_amc(&v.join("\n")).unwrap();
}

// ---------------------------------------------------------------------------------------- BVH

fn parse_bvh(text: &str) -> Result<motion::Clip, ParseError> {
    bvh::parse_bvh(text, Path::new(BVH_PATH), &Limits::default())
}

#[test]
fn bvh_offsets_are_finite_and_bounded() {
    parse_bvh(&BVH.join("\n")).unwrap();
    let ok = replaced(&BVH, 8, "\t\tOFFSET 3 -100000 0");
    parse_bvh(&ok).unwrap();
    for (line, with, joint, value) in [
        (8, "\t\tOFFSET 3 100001 0", "LeftUpLeg", "100001"),
        (8, "\t\tOFFSET -1e308 0 0", "LeftUpLeg", "-1e308"),
        (4, "\tOFFSET 0 1e6 0", "Hips", "1000000"),
        (12, "\t\t\tOFFSET 0 -2e5 0", "LeftUpLeg_End", "-200000"),
    ] {
        let text = replaced(&BVH, line, with);
        refused(
            parse_bvh(&text),
            BVH_PATH,
            line,
            &format!("OFFSET of {joint}: {value} is beyond the limit of 100000 file units"),
        );
    }
    for bad in ["nan", "inf", "-inf", "1e999"] {
        let text = replaced(&BVH, 12, &format!("\t\t\tOFFSET 0 {bad} 0"));
        refused(
            parse_bvh(&text),
            BVH_PATH,
            12,
            &format!("OFFSET of LeftUpLeg_End: `{bad}` is not a finite number"),
        );
    }
}

#[test]
fn bvh_non_finite_channel_values_are_refused() {
    for bad in ["nan", "NaN", "inf", "-inf", "infinity", "1e999"] {
        let text = replaced(&BVH, 20, &format!("1 90 0 0 0 0 11 {bad} 31"));
        refused(
            parse_bvh(&text),
            BVH_PATH,
            20,
            &format!("frame 2: `{bad}` is not a finite number"),
        );
    }
}

#[test]
fn bvh_repeated_offset_or_channels_in_one_joint_are_refused() {
    for (after, dup, reason) in [
        (
            9,
            "\t\tOFFSET 1 1 1",
            "joint LeftUpLeg: `OFFSET` given twice (first on line 8)",
        ),
        (
            9,
            "\t\tCHANNELS 1 Xrotation",
            "joint LeftUpLeg: `CHANNELS` given twice (first on line 9)",
        ),
        (
            5,
            "\tOFFSET 0 0 0",
            "joint Hips: `OFFSET` given twice (first on line 4)",
        ),
        (
            12,
            "\t\t\tOFFSET 0 0 0",
            "joint LeftUpLeg_End: `OFFSET` given twice (first on line 12)",
        ),
    ] {
        let text = inserted(&BVH, after, dup);
        refused(parse_bvh(&text), BVH_PATH, after + 1, reason);
    }
}

// ----------------------------------------------------------------------------- real CMU clips

/// The shared clips; under `CI` all five must be there (a missing folder fails in
/// `motion::data::mocap_dir`).
fn shared() -> Vec<motion::pairing::ClipSource> {
    let c = motion::data::shared_clips();
    if std::env::var_os("CI").is_some() {
        assert!(
            c.len() >= 5,
            "expected the 5 shared clips, found {}",
            c.len()
        );
    }
    c
}

#[test]
fn every_shared_clip_reads_with_no_warning() {
    let clips = shared();
    for c in &clips {
        let (clip, warnings) = io::read_clip_with_warnings(c.asf.as_deref(), &c.motion)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(warnings.is_empty(), "{}: {warnings:?}", c.name);
        assert!(clip.data().iter().all(|v| v.is_finite()), "{}", c.name);
        if let Some(a) = &c.asf {
            let (sk, warnings) = asf::read_asf_with_warnings(a, &Limits::default()).unwrap();
            assert!(warnings.is_empty(), "{}: {warnings:?}", a.display());
            // Every direction is the file's and unit within the tolerance.
            for j in &sk.joints {
                if let Rest::Bone { direction, length } = j.rest {
                    assert!(
                        (norm(direction) - 1.0).abs() < 1e-6,
                        "{}: {}",
                        c.name,
                        j.name
                    );
                    assert!(
                        length * sk.units.cm_per_unit < 60.0,
                        "{}: {}",
                        c.name,
                        j.name
                    );
                }
            }
        }
    }
    if clips.is_empty() {
        eprintln!("the shared clips are absent (set MOCAP_DATA); skipped outside CI");
    }
}

#[test]
fn a_real_asf_with_a_zero_or_huge_direction_is_refused_naming_file_and_line() {
    let Some(dir) = motion::data::mocap_dir() else {
        eprintln!("the shared clips are absent (set MOCAP_DATA); skipped outside CI");
        return;
    };
    let path = dir.join("12.asf");
    let text = std::fs::read_to_string(&path).unwrap();
    // The line of lfemur's direction: the first `direction` after `name lfemur`.
    let lines: Vec<&str> = text.split('\n').collect();
    let name_at = lines
        .iter()
        .position(|l| l.trim() == "name lfemur")
        .unwrap();
    let k = name_at
        + lines[name_at..]
            .iter()
            .position(|l| l.trim_start().starts_with("direction"))
            .unwrap();
    let shown = path.display().to_string();
    for (dir, reason) in [
        ("0 0 0", "a zero vector points nowhere"),
        ("0 -1000 0", "too far from one to normalise"),
        ("1e308 0 0", "too far from one to normalise"),
    ] {
        let mut mutated = lines.clone();
        let line = format!("   direction {dir}\r");
        mutated[k] = &line;
        let msg = refused(
            asf::parse_asf(&mutated.join("\n"), &path, &Limits::default()),
            &shown,
            k + 1,
            reason,
        );
        assert!(msg.contains("direction of bone lfemur"), "{msg}");
    }
}
