//! Study files over a manifest holding several variants of one codec at one target ratio
//! (`study sweep --param qp=9,11`): a grid names the variant in `conditions.params`, or the
//! cell is refused as ambiguous, naming the parameters the candidates differ in. A staircase
//! whose levels have several stimuli is refused too.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::Path;

use common::{TestCodecs, manifest};
use protocols::manifest::{Stimulus, StimulusManifest};
use protocols::{StudyDefinition, StudyError};

/// The example manifest plus `walk/wavelet-perceptual/qp{9,11}-window128/cr20`.
fn with_variants() -> StimulusManifest {
    let mut m = manifest();
    let base: Stimulus = m.get("walk/wavelet-perceptual/cr20").unwrap().clone();
    for qp in [9.0, 11.0] {
        let mut s = base.clone();
        s.id = format!("walk/wavelet-perceptual/qp{qp}-window128/cr20");
        s.params.insert("qp".into(), qp);
        s.params.insert("window".into(), 128.0);
        s.variant = [("qp".to_string(), qp), ("window".to_string(), 128.0)].into();
        m.stimuli.push(s);
    }
    m
}

fn study(conditions: &str) -> String {
    format!(
        "format_version = 1\nname = \"v\"\nprotocol = \"mos\"\nstimuli = \"stimuli.json\"\n\
         seed = 1\n[conditions]\n{conditions}\n"
    )
}

fn parse(conditions: &str) -> Result<StudyDefinition, StudyError> {
    let m = with_variants();
    StudyDefinition::parse(
        &study(conditions),
        Path::new("v.toml"),
        move |_| Ok(m),
        &TestCodecs,
    )
}

fn issues(conditions: &str) -> Vec<(String, String)> {
    match parse(conditions) {
        Err(StudyError::Invalid { issues, .. }) => {
            issues.into_iter().map(|i| (i.key, i.reason)).collect()
        }
        other => panic!("expected Invalid, got {other:?}"),
    }
}

const GRID: &str = "clips = [\"walk\"]\ncodecs = [\"wavelet-perceptual\"]\ntarget_cr = [20]";

#[test]
fn a_grid_cell_matching_several_variants_is_refused_naming_what_differs() {
    let got = issues(GRID);
    let [(key, reason)] = got.as_slice() else {
        panic!("{got:#?}")
    };
    assert_eq!(key, "conditions.target_cr[0]");
    // The default stimulus (qp 8 in the example) and the two variants.
    assert!(
        reason.starts_with(
            "3 stimuli match clip \"walk\" with codec \"wavelet-perceptual\" at target_cr 20"
        ),
        "{reason}"
    );
    assert!(
        reason.contains("\"walk/wavelet-perceptual/qp9-window128/cr20\""),
        "{reason}"
    );
    assert!(
        reason.contains(
            "they differ in qp: name the variant with conditions.params (e.g. params = { qp = 9 })"
        ),
        "{reason}"
    );
}

#[test]
fn conditions_params_name_the_variants() {
    let one = parse(&format!("{GRID}\nparams = {{ qp = 9 }}")).unwrap();
    let ids: Vec<&str> = one.conditions.iter().map(|c| c.stimulus.as_str()).collect();
    assert_eq!(ids, ["walk/wavelet-perceptual/qp9-window128/cr20"]);
    // Every combination of the values is a cell.
    let two = parse(&format!(
        "{GRID}\nparams = {{ qp = [9, 11], window = [128] }}"
    ))
    .unwrap();
    let ids: Vec<&str> = two.conditions.iter().map(|c| c.stimulus.as_str()).collect();
    assert_eq!(
        ids,
        [
            "walk/wavelet-perceptual/qp9-window128/cr20",
            "walk/wavelet-perceptual/qp11-window128/cr20"
        ]
    );
    // params match what the stream records: the default variant too (qp 8 in the example).
    let default = parse(&format!("{GRID}\nparams = {{ qp = 8 }}")).unwrap();
    assert_eq!(
        default.conditions[0].stimulus,
        "walk/wavelet-perceptual/cr20"
    );
    // A value no stimulus has is a cell without a stimulus.
    let got = issues(&format!("{GRID}\nparams = {{ qp = 10, window = \"x\" }}"));
    assert!(
        got.iter()
            .any(|(k, r)| k == "conditions.params.window" && r.contains("expected a number")),
        "{got:#?}"
    );
    let got = issues(&format!("{GRID}\nparams = {{ qp = 12 }}"));
    assert!(
        got.iter()
            .any(|(k, r)| k == "conditions.target_cr[0]"
                && r.ends_with("at target_cr 20 with qp = 12")),
        "{got:#?}"
    );
}

#[test]
fn a_staircase_level_with_several_variants_is_refused() {
    let text = "format_version = 1\nname = \"s\"\nprotocol = \"staircase\"\n\
                stimuli = \"stimuli.json\"\nseed = 1\n[staircase]\nparam = \"window\"\n\
                codec = \"wavelet-perceptual\"\nstart = 128\nstep = 1\nmin = 128\nmax = 128\n\
                max_trials = 10\n[[staircase.tracks]]\nclip = \"walk\"\n";
    let m = with_variants();
    let Err(StudyError::Invalid { issues, .. }) =
        StudyDefinition::parse(text, Path::new("s.toml"), move |_| Ok(m), &TestCodecs)
    else {
        panic!("expected problems");
    };
    assert!(
        issues.iter().any(|i| i.key == "staircase.tracks[0].clip"
            && i.reason
                .contains("with codec \"wavelet-perceptual\" have window = 128")
            && i.reason.contains("one stimulus per level")),
        "{issues:#?}"
    );
}
