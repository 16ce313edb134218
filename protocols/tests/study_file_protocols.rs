//! Study file validation: examples load, every mistake is reported at once with its key path,
//! and 2,400 mutated study files give errors, never panics.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::Path;

use common::{LIVE, example, example_text, invalid, issues, manifest, parse};
use protocols::rng::StudyRng;
use protocols::{
    CodecCatalog, CodecInfo, Protocol, Staircase, StaircaseSettings, StepType, StudyDefinition,
    StudyError,
};

#[test]
fn examples_are_valid() {
    assert_eq!(example("mos.toml").protocol, Protocol::Mos);
    assert_eq!(example("dscqs.toml").protocol, Protocol::Dscqs);
    let s = example("staircase.toml");
    let sc = s.staircase.unwrap();
    assert_eq!(sc.tracks.len(), 2);
    assert!((sc.tracks[0].settings.start - 0.024).abs() < 1e-15);
    // The live example is the repository's own (its generated clips are committed).
    let live = protocols::StudyDefinition::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/live-staircase.toml"),
        &common::TestCodecs,
    )
    .unwrap()
    .staircase
    .unwrap();
    assert_eq!(live.live.unwrap().clips.len(), 5, "five motions in turn");
}

#[test]
fn every_mistake_is_reported_at_once_with_its_key_path() {
    let text = example_text("staircase.toml")
        .replace("step = 0.002", "step = 0.0")
        .replace("start = 0.024", "start = 0.5")
        .replace("n_down = 2", "n_down = \"two\"\ncolour = 3")
        .replace("clip = \"dance\"", "clip = \"salsa\"")
        .replace("loop = true", "loop = 1");
    let got = issues(&text);
    let keys: Vec<&str> = got.iter().map(|(k, _)| k.as_str()).collect();
    for want in [
        "staircase.step",
        "staircase.start",
        "staircase.n_down",
        "staircase.colour",
        "staircase.tracks[1].clip",
        "presentation.loop",
    ] {
        assert!(keys.contains(&want), "missing {want} in {got:#?}");
    }
    assert!(
        got.iter()
            .any(|(k, r)| k == "staircase.colour" && r.contains("unknown key"))
    );
    assert!(
        got.iter()
            .any(|(k, r)| k == "staircase.n_down" && r.contains("expected an integer"))
    );
    assert!(
        got.iter()
            .any(|(k, r)| k == "staircase.start" && r.contains("above max"))
    );
}

#[test]
fn consent_and_instructions_are_read_and_checked() {
    let text = example_text("mos.toml").replace(
        "hidden_repeats = 8",
        "hidden_repeats = 8\nconsent = \"I agree.\"\ninstructions = \"Rate the right one.\"",
    );
    let study = parse(&text).unwrap();
    assert_eq!(study.session.consent.as_deref(), Some("I agree."));
    assert_eq!(
        study.session.instructions.as_deref(),
        Some("Rate the right one.")
    );
    let text = example_text("mos.toml").replace(
        "hidden_repeats = 8",
        "hidden_repeats = 8\nconsent = \"  \"\ninstructions = 3",
    );
    let got = issues(&text);
    let has = |k: &str, r: &str| got.iter().any(|(gk, gr)| gk == k && gr.contains(r));
    assert!(has("session.consent", "is empty"), "{got:#?}");
    assert!(has("session.instructions", "expected a string"), "{got:#?}");
    assert!(example("mos.toml").session.consent.is_none());
}

/// `subject_fields` takes bare names (free text) and typed fields; every mistake in a typed
/// field is named by its index and key.
#[test]
fn subject_fields_are_typed_and_checked() {
    use protocols::study::{FieldKind, SubjectField};
    let with = |fields: &str| {
        example_text("mos.toml").replace(
            "subject_fields = [\"age\", \"gender\", \"normal_vision\"]",
            &format!("subject_fields = {fields}"),
        )
    };
    let study = parse(&with(
        "[\"handedness\", { name = \"age\", kind = \"number\", min = 18, max = 99, integer = true }, \
         { name = \"v\", kind = \"yes_no\", label = \"Normal vision\" }]",
    ))
    .unwrap();
    assert_eq!(
        study.session.subject_fields,
        vec![
            SubjectField::text("handedness"),
            SubjectField {
                name: "age".into(),
                label: "age".into(),
                kind: FieldKind::Number {
                    min: 18.0,
                    max: 99.0,
                    integer: true
                }
            },
            SubjectField {
                name: "v".into(),
                label: "Normal vision".into(),
                kind: FieldKind::YesNo
            },
        ]
    );
    let got = issues(&with(
        "[{ name = \"age\", kind = \"nmuber\" }, { name = \"a\", kind = \"number\", min = 9, max = 1 }, \
         { name = \"g\", kind = \"choice\", options = [] }, { name = \"h\", kind = \"choice\", options = [\"x\", \"X\"] }, \
         { name = \"y\", kind = \"yes_no\", min = 1 }, { kind = \"text\" }, 3, \"n n\", \"y\"]",
    ));
    let has = |k: &str, r: &str| got.iter().any(|(gk, gr)| gk == k && gr.contains(r));
    let p = "session.subject_fields";
    assert!(has(&format!("{p}[0].kind"), "not a field kind"), "{got:#?}");
    assert!(has(&format!("{p}[1].min"), "above max"), "{got:#?}");
    assert!(
        has(&format!("{p}[2].options"), "1 to 50 options"),
        "{got:#?}"
    );
    assert!(has(&format!("{p}[3].options"), "distinct"), "{got:#?}");
    assert!(has(&format!("{p}[4].min"), "unknown key"), "{got:#?}");
    assert!(has(&format!("{p}[5].name"), "missing"), "{got:#?}");
    assert!(
        has(&format!("{p}[6]"), "a name or a field table"),
        "{got:#?}"
    );
    assert!(has(&format!("{p}[7]"), "letters, digits or _"), "{got:#?}");
    assert!(has(&format!("{p}[8]"), "listed twice"), "{got:#?}");
}

#[test]
fn unknown_stimulus_and_wrong_types_in_mos() {
    let text = example_text("mos.toml")
        .replace("[conditions]\nclips = [\"walk\", \"dance\"]\ncodecs = [\"wavelet-perceptual\", \"wavelet-bone\", \"wavelet-standard\"]\ntarget_cr = [10, 20, 30, 40, 50, 60, 70]",
                 "[conditions]\nstimuli = [\"walk/wavelet-bone/cr10\", \"walk/nope\", \"walk/reference\", 5]")
        .replace("hidden_repeats = 8", "hidden_repeats = 8\nbreak_every = 3")
        .replace("protocol = \"mos\"", "protocol = \"mos\"\nseed2 = 1");
    let got = issues(&text);
    let has = |k: &str, r: &str| got.iter().any(|(gk, gr)| gk == k && gr.contains(r));
    assert!(
        has("conditions.stimuli[1]", "not in the manifest"),
        "{got:#?}"
    );
    assert!(has("conditions.stimuli[2]", "is a reference"), "{got:#?}");
    assert!(
        has("conditions.stimuli[3]", "expected a string"),
        "{got:#?}"
    );
    assert!(has("session.break_every", "unknown key"), "{got:#?}");
    assert!(has("seed2", "unknown key"), "{got:#?}");
    assert!(
        has("session.hidden_repeats", "only 1 conditions"),
        "{got:#?}"
    );
}

#[test]
fn a_level_without_stimulus_is_an_error() {
    // max 0.05 reaches t_l levels up to 0.05; the manifest stops at 0.040.
    let got = issues(&example_text("staircase.toml").replace("max = 0.040", "max = 0.050"));
    assert!(
        got.iter()
            .any(|(k, r)| k == "staircase.tracks[0].clip" && r.contains("no stimulus")),
        "{got:#?}"
    );
    // An odd step puts levels between the stimuli.
    let got = issues(&example_text("staircase.toml").replace("step = 0.002", "step = 0.003"));
    assert!(
        got.iter().any(|(_, r)| r.contains("reachable level")),
        "{got:#?}"
    );
}

/// The check that every reachable level has a stimulus steps with the staircase's own
/// arithmetic: a log step down divides by 10^step, and the level it names as missing is the
/// exact value a session would show (multiplying by 10^-step differs in the last digit here).
#[test]
fn a_missing_log_level_is_named_as_the_staircase_computes_it() {
    let text = example_text("staircase.toml")
        .replace("start = 0.024", "start = 0.012")
        .replace("step = 0.002", "step = 0.02")
        .replace("step_type = \"linear\"", "step_type = \"log\"")
        .replace("min = 0.002", "min = 0.010")
        .replace("max = 0.040", "max = 0.012");
    let got = issues(&text);
    let mut s = Staircase::new(StaircaseSettings {
        start: 0.012,
        step: 0.02,
        step_type: StepType::Log,
        min: Some(0.010),
        max: Some(0.012),
        ..StaircaseSettings::default()
    })
    .unwrap();
    s.add_response(true).unwrap();
    s.add_response(true).unwrap();
    let first_down = s.next_level().unwrap();
    assert_ne!(
        first_down.to_bits(),
        (0.012 * 10_f64.powf(-0.02)).to_bits(),
        "the example needs a level where the two roundings differ"
    );
    let (_, reason) = got
        .iter()
        .find(|(k, _)| k == "staircase.tracks[0].clip")
        .unwrap_or_else(|| panic!("{got:#?}"));
    let listed = reason.rsplit(": ").next().unwrap();
    assert!(
        listed.split(", ").any(|v| v == first_down.to_string()),
        "{first_down} not in {reason}"
    );
}

#[test]
fn syntax_errors_name_line_and_column() {
    let err = parse("format_version = 1\nname = \"x\nprotocol = 3").unwrap_err();
    match err {
        StudyError::Syntax { line, column, .. } => {
            assert!(line >= 2 && column >= 1, "{line}:{column}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn unsupported_version_is_rejected() {
    let got =
        issues(&example_text("dscqs.toml").replace("format_version = 1", "format_version = 2"));
    assert!(got.iter().any(|(k, _)| k == "format_version"));
}

fn mutate(text: &str, rng: &mut StudyRng) -> String {
    let mut s: Vec<u8> = text.as_bytes().to_vec();
    let tokens: [&[u8]; 14] = [
        b"=",
        b"[",
        b"]",
        b"\"",
        b"-1",
        b"0",
        b"1e400",
        b"nan",
        b"[[staircase.tracks]]",
        b"\n",
        b"{",
        b"x = 1\n",
        b"true",
        b"99999999999999999999",
    ];
    for _ in 0..=rng.below(3) {
        let at = rng.index(s.len() + 1);
        match rng.below(6) {
            0 if !s.is_empty() => {
                let end = (at + 1 + rng.index(12)).min(s.len());
                s.drain(at.min(s.len())..end);
            }
            1 => {
                let tok = tokens[rng.index(tokens.len())];
                s.splice(at..at, tok.iter().copied());
            }
            2 if at < s.len() => s[at] = (rng.below(95) + 32) as u8,
            3 => {
                // Replace a number somewhere with another value.
                let text = String::from_utf8_lossy(&s).into_owned();
                let lines: Vec<&str> = text.lines().collect();
                let i = rng.index(lines.len().max(1));
                let mut out: Vec<String> = lines.iter().map(|l| (*l).to_string()).collect();
                if let Some(l) = out.get_mut(i)
                    && let Some(eq) = l.find('=')
                {
                    let vals = [
                        "0",
                        "-3",
                        "0.0",
                        "\"\"",
                        "[]",
                        "1e9",
                        "4294967296",
                        "\"random\"",
                        "false",
                        "0.5",
                    ];
                    *l = format!("{}= {}", &l[..eq], vals[rng.index(vals.len())]);
                }
                s = out.join("\n").into_bytes();
            }
            4 => {
                // Drop a whole line.
                let text = String::from_utf8_lossy(&s).into_owned();
                let mut lines: Vec<&str> = text.lines().collect();
                if !lines.is_empty() {
                    lines.remove(rng.index(lines.len()));
                }
                s = lines.join("\n").into_bytes();
            }
            _ => {
                // Duplicate a line (duplicate keys, repeated tables).
                let text = String::from_utf8_lossy(&s).into_owned();
                let mut lines: Vec<&str> = text.lines().collect();
                if !lines.is_empty() {
                    let i = rng.index(lines.len());
                    lines.insert(i, lines[i]);
                }
                s = lines.join("\n").into_bytes();
            }
        }
    }
    String::from_utf8_lossy(&s).into_owned()
}

#[test]
fn mutated_study_files_give_errors_never_panics() {
    let mut rng = StudyRng::new(2026, &[]);
    let (mut errors, mut oks, mut unchanged) = (0, 0, 0);
    for name in ["mos.toml", "dscqs.toml", "staircase.toml"] {
        let text = example_text(name);
        let (mut syntax, mut invalid) = (0, 0);
        for _ in 0..800 {
            let m = mutate(&text, &mut rng);
            match parse(&m) {
                Ok(_) => oks += 1,
                Err(e) => {
                    // Every error names the file it is about, and says where or what.
                    let msg = e.to_string();
                    assert!(msg.starts_with("test.toml:"), "{name}: {msg}");
                    match &e {
                        StudyError::Syntax { line, column, .. } => {
                            assert!(*line >= 1 && *column >= 1, "{name}: {msg}");
                            syntax += 1;
                        }
                        StudyError::Invalid { issues, .. } => {
                            assert!(!issues.is_empty(), "{name}: {msg}");
                            assert!(issues.iter().all(|i| !i.reason.is_empty()), "{msg}");
                            invalid += 1;
                        }
                        other => panic!("{name}: neither a syntax nor a study error: {other:?}"),
                    }
                    errors += 1;
                }
            }
            if m == text {
                // Some mutations change nothing (a deletion past the end): still valid.
                assert!(parse(&m).is_ok(), "{name} unchanged but refused");
                unchanged += 1;
            }
        }
        eprintln!("{name}: {syntax} syntax errors, {invalid} study errors");
        // Both kinds of mistake are made, and caught, in every file.
        assert!(
            syntax > 100 && invalid > 100,
            "{name}: {syntax} syntax errors, {invalid} study errors"
        );
    }
    assert!(
        errors > 1200,
        "most mutations are caught: {errors} errors, {oks} still valid ({unchanged} unchanged)"
    );
}

/// The live staircase option (`[staircase.live]`) under the same mutations: clear errors,
/// never a panic, and every accepted mutation still names a reference for each live clip.
#[test]
fn mutated_live_study_files_give_errors_never_panics() {
    let mut rng = StudyRng::new(2027, &[]);
    let (mut errors, mut oks) = (0, 0);
    for _ in 0..800 {
        let m = mutate(LIVE, &mut rng);
        match parse(&m) {
            Ok(s) => {
                if let Some(live) = s.staircase.and_then(|sc| sc.live) {
                    assert!(!live.clips.is_empty(), "{m}");
                    assert!(live.clips.iter().all(|c| !c.reference.is_empty()), "{m}");
                }
                oks += 1;
            }
            Err(e) => {
                assert!(!e.to_string().is_empty());
                if let StudyError::Invalid { issues, .. } = &e {
                    assert!(!issues.is_empty());
                    assert!(issues.iter().all(|i| !i.reason.is_empty()));
                }
                errors += 1;
            }
        }
    }
    assert!(
        errors > 400,
        "most mutations are caught: {errors} errors, {oks} still valid"
    );
}

/// `LIVE` with another codec, level parameter and fixed parameters.
fn live_with(codec: &str, param: &str, params: &str) -> String {
    LIVE.replace(
        "codec = \"wavelet-perceptual\"",
        &format!("codec = \"{codec}\""),
    )
    .replace("param = \"cr\"", &format!("param = \"{param}\""))
    .replace(
        "params = { qp = 10, window = 128 }",
        &format!("params = {{ {params} }}"),
    )
}

fn pairs(want: &[(&str, &str)]) -> Vec<(String, String)> {
    want.iter()
        .map(|(k, r)| ((*k).to_string(), (*r).to_string()))
        .collect()
}

const KNOWN: &str =
    "known: raw-f32, wavelet-perceptual, spiht, primitive; `study codecs` lists them";

#[test]
fn a_live_staircase_names_a_known_codec() {
    assert!(parse(&live_with("spiht", "cr", "window = 64")).is_ok());
    assert_eq!(
        issues(&live_with("spiht2", "cr", "window = 64")),
        pairs(&[(
            "staircase.codec",
            &format!("unknown codec \"spiht2\" ({KNOWN})")
        )]),
        "nothing else is checked against a codec that does not exist"
    );
}

#[test]
fn a_live_level_is_a_parameter_of_the_codec() {
    assert_eq!(
        issues(&live_with("spiht", "qp", "window = 64")),
        pairs(&[(
            "staircase.param",
            "codec \"spiht\" has no parameter \"qp\" (accepted: cr, window)"
        )])
    );
}

#[test]
fn every_fixed_live_parameter_is_one_the_codec_takes() {
    assert_eq!(
        issues(&live_with(
            "spiht",
            "cr",
            "window = 64, qp = 10, alpha = 0.1"
        )),
        pairs(&[
            (
                "staircase.live.params.alpha",
                "codec \"spiht\" has no such parameter (accepted: cr, window)"
            ),
            (
                "staircase.live.params.qp",
                "codec \"spiht\" has no such parameter (accepted: cr, window)"
            ),
        ])
    );
}

#[test]
fn a_compression_ratio_level_needs_rate_control_and_a_positive_min() {
    // raw-f32 has neither the parameter nor rate control: both are said.
    assert_eq!(
        issues(&live_with("raw-f32", "cr", "")),
        pairs(&[
            (
                "staircase.param",
                "codec \"raw-f32\" has no parameter \"cr\" (accepted: )"
            ),
            (
                "staircase.param",
                "codec \"raw-f32\" takes no target compression ratio"
            ),
        ])
    );
    let text = live_with("spiht", "cr", "window = 64").replace("min = 8", "min = 0");
    assert_eq!(
        issues(&text),
        pairs(&[("staircase.min", "a compression ratio level needs min > 0")])
    );
    // Another level parameter may start at 0.
    let text = live_with("primitive", "t_l", "")
        .replace("min = 8", "min = 0")
        .replace(
            "order = \"in_turn\"",
            "order = \"in_turn\"\ndatabase = \"db.bin\"",
        );
    assert!(parse(&text).is_ok(), "{:?}", parse(&text).err());
}

#[test]
fn a_codec_that_needs_a_database_is_given_one() {
    assert_eq!(
        issues(&live_with("primitive", "t_l", "")),
        pairs(&[(
            "staircase.live.database",
            "codec \"primitive\" needs a primitive database file here"
        )])
    );
    let text = live_with("primitive", "t_l", "").replace(
        "order = \"in_turn\"",
        "order = \"in_turn\"\ndatabase = \"db.bin\"",
    );
    let study = parse(&text).unwrap();
    assert_eq!(
        study.staircase.unwrap().live.unwrap().database.as_deref(),
        Some("db.bin")
    );
}

#[test]
fn a_live_observer_detecting_error_measures_rms_cm() {
    let text = LIVE.replace(
        "detection = \"error\"",
        "detection = \"error\"\nmetric = \"max_cm\"",
    );
    assert_eq!(
        issues(&text),
        pairs(&[(
            "simulation.metric",
            "a live staircase measures rms_cm on the decoded clip; set metric = \"rms_cm\""
        )])
    );
    // Detection by level does not use the metric; a manifest staircase has every metric.
    let by_level = text.replace("detection = \"error\"", "detection = \"level\"");
    assert!(parse(&by_level).is_ok());
    let manifest_study = example_text("staircase.toml").replace(
        "psychometric = \"weibull\"",
        "psychometric = \"weibull\"\ndetection = \"error\"\nmetric = \"max_cm\"",
    );
    assert!(parse(&manifest_study).is_ok());
}

/// A catalog that knows no codec.
struct NoCodecs;

impl CodecCatalog for NoCodecs {
    fn codec(&self, _: &str) -> Option<CodecInfo> {
        None
    }
    fn names(&self) -> Vec<String> {
        Vec::new()
    }
}

/// Studies over manifest stimuli name codecs only as the manifest does; the catalog is not
/// asked about them.
#[test]
fn manifest_studies_are_not_checked_against_the_catalog() {
    for name in ["mos.toml", "dscqs.toml", "staircase.toml"] {
        let m = manifest();
        let parsed = StudyDefinition::parse(
            &example_text(name),
            Path::new(name),
            move |_| Ok(m),
            &NoCodecs,
        );
        assert!(parsed.is_ok(), "{name}: {:?}", parsed.err());
    }
    let m = manifest();
    let live = StudyDefinition::parse(LIVE, Path::new("live.toml"), move |_| Ok(m), &NoCodecs);
    assert!(matches!(live, Err(StudyError::Invalid { .. })), "{live:?}");
}

/// Codec problems land in the same list as every other problem of the file.
#[test]
fn codec_problems_are_listed_with_every_other_problem() {
    let text = LIVE
        .replace(
            "params = { qp = 10, window = 128 }",
            "params = { qp = 10, colour = 3 }",
        )
        .replace("seed = 5\n", "")
        + "\n[scale]\nkind = \"categorical\"\n";
    let got = issues(&text);
    let keys: Vec<&str> = got.iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(
        keys,
        ["seed", "scale", "staircase.live.params.colour"],
        "{got:#?}"
    );
    assert_eq!(got[0].1, "missing");
    assert_eq!(got[1].1, "a staircase study has no rating scale");
    assert!(
        got[2]
            .1
            .starts_with("codec \"wavelet-perceptual\" has no such parameter")
    );
}

#[test]
fn crowdsourcing_settings_are_read_and_every_mistake_is_listed() {
    use protocols::study::HiddenRule;
    let base = example_text("mos.toml");
    let first = example("mos.toml").conditions[0].stimulus.clone();
    let study = parse(&format!(
        "{base}\n[crowdsourcing]\nmin_window = [1024, 600]\nmin_refresh_hz = 59\nfullscreen = true\n\
         hidden = \"exclude\"\ncompletion_code = \"C0DE-1\"\n\
         completion_url = \"https://app.prolific.com/submissions/complete?cc=C0DE-1\"\n\
         max_gold_failures = 1\ngroups = 4\nquota = 25\ntoo_fast = \"exclude\"\n\
         [[crowdsourcing.gold]]\nstimulus = \"{first}\"\nmax = 2\n"
    ))
    .unwrap();
    let c = &study.crowdsourcing;
    assert_eq!(
        (c.min_window_px, c.min_refresh_hz, c.fullscreen),
        ([1024, 600], 59.0, true)
    );
    assert_eq!(c.hidden, HiddenRule::Exclude);
    assert_eq!(c.too_fast, protocols::study::TooFastRule::Exclude);
    assert_eq!(
        (c.groups, c.quota, c.max_gold_failures),
        (Some(4), Some(25), 1)
    );
    let gold = c.gold_of(&first).unwrap();
    assert!(gold.passes(1.5) && gold.passes(2.0) && !gold.passes(2.5));
    // Without the table: the defaults (a 50 Hz display, 800 x 500, repeat a hidden trial).
    let d = example("mos.toml").crowdsourcing;
    assert_eq!(
        (d.min_refresh_hz, d.min_window_px, d.hidden, d.too_fast),
        (
            50.0,
            [800, 500],
            HiddenRule::Repeat,
            protocols::study::TooFastRule::Flag
        )
    );

    let got = issues(&format!(
        "{base}\n[crowdsourcing]\nmin_window = [10]\nhidden = \"skip\"\ncompletion_code = \"a b\"\n\
         completion_url = \"http://x\"\ngroups = 0\ncolour = 1\ntoo_fast = \"warn\"\n\
         [[crowdsourcing.gold]]\nstimulus = \"nope\"\n"
    ));
    let has = |k: &str, r: &str| got.iter().any(|(gk, gr)| gk == k && gr.contains(r));
    assert!(
        has("crowdsourcing.min_window", "[width, height]"),
        "{got:#?}"
    );
    assert!(
        has("crowdsourcing.hidden", "\"repeat\" or \"exclude\""),
        "{got:#?}"
    );
    assert!(
        has("crowdsourcing.completion_code", "letters, digits"),
        "{got:#?}"
    );
    assert!(has("crowdsourcing.completion_url", "https://"), "{got:#?}");
    assert!(has("crowdsourcing.groups", "at least 1"), "{got:#?}");
    assert!(
        has(
            "crowdsourcing.too_fast",
            "expected \"flag\" or \"exclude\", got \"warn\""
        ),
        "{got:#?}"
    );
    assert!(has("crowdsourcing.colour", "unknown key"), "{got:#?}");
    assert!(has("crowdsourcing.gold[0]", "give min"), "{got:#?}");
    assert!(
        has(
            "crowdsourcing.gold[0].stimulus",
            "not one of the study's conditions"
        ),
        "{got:#?}"
    );
    assert_eq!(got.len(), 9, "{got:#?}");
}

/// The repository's crowd example (thesis 6.5) with `edit` applied to its text, over its own
/// manifest (`examples/crowd/stimuli.json`).
fn crowd(edit: impl Fn(String) -> String) -> Result<StudyDefinition, StudyError> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let text = edit(std::fs::read_to_string(dir.join("crowd-run1.toml")).unwrap());
    let json = std::fs::read_to_string(dir.join("crowd/stimuli.json")).unwrap();
    let m: protocols::manifest::StimulusManifest = serde_json::from_str(&json).unwrap();
    StudyDefinition::parse(
        &text,
        Path::new("crowd.toml"),
        move |_| Ok(m),
        &common::TestCodecs,
    )
}

fn crowd_issues(edit: impl Fn(String) -> String) -> Vec<(String, String)> {
    invalid(crowd(edit))
}

/// Thesis 6.5 as a study file: three levels, three characters, twelve crowd scenes rated one
/// after the other with the reference first; the engine scores both ratings, reference first.
#[test]
fn the_crowd_example_is_a_sequential_dscqs_over_twelve_scenes() {
    let s = crowd(|t| t).unwrap();
    assert_eq!(s.protocol, Protocol::Dscqs);
    let scene = s.scene.as_ref().unwrap();
    assert_eq!(scene.levels, ["near", "middle", "far"]);
    let names: Vec<&str> = scene.characters.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["front", "back_left", "back_right"]);
    assert_eq!(scene.groups(), ["front", "back"]);
    assert_eq!(
        scene
            .placement(&scene.characters[1], 2)
            .distance_cm
            .to_bits(),
        1300f64.to_bits()
    );
    assert_eq!(
        scene
            .placement(&scene.characters[0], 2)
            .distance_cm
            .to_bits(),
        350f64.to_bits()
    );
    assert_eq!(s.conditions.len(), 12);
    let mut session = protocols::Session::new(&s, 3).unwrap();
    let mut shown = std::collections::BTreeSet::new();
    while let Some(t) = session.next_trial(0).unwrap() {
        assert_eq!(t.arrangement, protocols::Arrangement::Sequential);
        assert_eq!(t.reference_position, protocols::Position::First);
        let level = t.stimulus.split('/').next().unwrap();
        assert_eq!(t.reference, format!("{level}/reference"));
        shown.insert(t.stimulus.clone());
        let o = session
            .respond(&protocols::Response {
                answer: protocols::Answer::Pair { a: 5.0, b: 3.0 },
                response_time_ms: 1,
                replays: 0,
                dropped_frames: 0,
            })
            .unwrap();
        assert_eq!(
            (o.score_reference, o.score_test, o.score),
            (Some(5.0), Some(3.0), 2.0)
        );
    }
    assert_eq!(shown.len(), 12, "every scene once");
}

/// A crowd stimulus made for another layout, a crowd without a [scene], a scene in a
/// staircase, bad scene keys and attention for a group the scene lacks are each reported with
/// their key.
#[test]
fn crowd_mistakes_are_reported_with_their_keys() {
    // The middle level's back characters moved: the stimuli were compressed for 9 m.
    let got = crowd_issues(|t| t.replace("[600, 900, 1300]", "[600, 950, 1300]"));
    assert!(
        got.iter().any(|(k, r)| k == "conditions"
            && r.contains("\"middle/spiht/front40-back20\"")
            && r.contains("compressed for 900 cm")
            && r.contains("950 cm ahead on level \"middle\"")),
        "{got:#?}"
    );
    let got = crowd_issues(|t| {
        let cut = t.find("\n[scene]").unwrap();
        let end = t.find("\n[simulation]").unwrap();
        format!("{}{}", &t[..cut], &t[end..])
    });
    assert!(
        got.iter()
            .any(|(k, r)| k == "conditions" && r.contains("needs a [scene]")),
        "{got:#?}"
    );
    let got = crowd_issues(|t| {
        t.replace("fov_deg = 40 }", "fov_deg = 400, zoom = 2 }")
            .replace("name = \"back_right\"", "name = \"back right\"")
            .replace(
                "levels = [\"near\", \"middle\", \"far\"]",
                "levels = [\"near\", \"middle\"]",
            )
    });
    let attention =
        crowd_issues(|t| t.replace("[simulation]", "[simulation]\nattention = { side = 1 }"));
    for (key, why) in [
        ("scene.camera.fov_deg", "400 is outside 5..=120"),
        ("scene.camera.zoom", "unknown key"),
        (
            "scene.characters[2].name",
            "\"back right\": use 1-24 letters",
        ),
        (
            "scene.characters[1].distance_cm",
            "3 distances for 2 level(s)",
        ),
    ] {
        assert!(
            got.iter().any(|(k, r)| k == key && r.contains(why)),
            "{key}: {why} not in {got:#?}"
        );
    }
    assert!(
        attention
            .iter()
            .any(|(k, r)| k == "simulation.attention.side"
                && r.contains("neither a group (front, back)")),
        "{attention:#?}"
    );
    let staircase = crowd_issues(|t| t.replace("protocol = \"dscqs\"", "protocol = \"staircase\""));
    for (key, why) in [("scene", "not a staircase"), ("staircase", "missing")] {
        assert!(
            staircase.iter().any(|(k, r)| k == key && r.contains(why)),
            "{key}: {why} not in {staircase:#?}"
        );
    }
}

/// The simulated observer's error of a crowd scene: each character's manifest error scaled
/// by its apparent size (the nearest distance over its own), averaged with the attention
/// weights. Checked by hand on the example's scenes.
#[test]
fn a_simulated_observer_sees_a_crowd_by_size_and_attention() {
    let run1 = crowd(|t| t).unwrap();
    let run2 =
        crowd(|t| t.replace("[simulation]", "[simulation]\nattention = { front = 0.2 }")).unwrap();
    let rms = |id: &str| run1.manifest.get(id).unwrap().metrics.unwrap().rms_cm;
    let (front, back) = (rms("march/spiht/cr40"), rms("march/spiht/cr80"));
    let error = |s: &StudyDefinition, id: &str| {
        protocols::observer::Observer::new(s, 1, 0)
            .manifest_error(id)
            .unwrap()
    };
    for (level, d) in [("near", 600.0), ("middle", 900.0), ("far", 1300.0)] {
        let id = format!("{level}/spiht/front40-back80");
        let size = 350.0 / d;
        let want1 = (front + 2.0 * size * back) / 3.0;
        let want2 = (0.2 * front + 2.0 * size * back) / 2.2;
        assert!((error(&run1, &id) - want1).abs() < 1e-12, "{id}");
        assert!((error(&run2, &id) - want2).abs() < 1e-12, "{id}");
    }
    assert_eq!(error(&run1, "far/reference").to_bits(), 0f64.to_bits());
}
