//! The keys of what a subject sees around the stimuli: the study title, the labels that say
//! which stimulus is the reference (only where the design tells the subject), and the grey
//! between the intervals of a sequential or DSCQS presentation.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use common::{example, example_text, has, issues, parse};
use protocols::study::StimulusLabels;

fn labels(reference: &str, test: &str) -> StimulusLabels {
    StimulusLabels {
        reference: reference.into(),
        test: test.into(),
    }
}

#[test]
fn mos_labels_the_reference_by_default_and_the_file_can_rename_or_hide_them() {
    let mos = example_text("mos.toml");
    let plain = mos
        .replace("reference_label = \"Original\"\n", "")
        .replace("test_label = \"Compressed\"\n", "")
        .replace("title = \"Motion quality study\"\n", "");
    let s = parse(&plain).unwrap();
    assert_eq!(
        s.presentation.labels,
        Some(labels("Original", "Compressed"))
    );
    assert_eq!(
        s.title(),
        protocols::texts::DEFAULT_TITLE,
        "no title: subjects see a neutral one, never the study's name"
    );
    let s = example("mos.toml");
    assert_eq!(s.title(), "Motion quality study");
    let renamed = mos
        .replace("\"Original\"", "\"Reference\"")
        .replace("\"Compressed\"", "\"Coded\"");
    let s = parse(&renamed).unwrap();
    assert_eq!(s.presentation.labels, Some(labels("Reference", "Coded")));
    let hidden = plain.replace("gap_ms = 500\n", "gap_ms = 500\nlabels = false\n");
    assert_eq!(parse(&hidden).unwrap().presentation.labels, None);
}

#[test]
fn dscqs_and_staircases_never_label_the_reference() {
    assert_eq!(example("dscqs.toml").presentation.labels, None);
    assert_eq!(example("staircase.toml").presentation.labels, None);
    let dscqs = example_text("dscqs.toml").replace(
        "arrangement = \"abab\"\n",
        "arrangement = \"abab\"\nlabels = true\nreference_label = \"Original\"\n",
    );
    let got = issues(&dscqs);
    assert!(has(&got, "presentation.labels", "BT.500"), "{got:#?}");
    assert!(
        has(&got, "presentation.reference_label", "not shown"),
        "{got:#?}"
    );
    let stair = example_text("staircase.toml").replace(
        "[presentation]\n",
        "[presentation]\nlabels = true\ntest_label = \"Compressed\"\n",
    );
    let got = issues(&stair);
    assert!(
        has(&got, "presentation.labels", "must find"),
        "2AFC: {got:#?}"
    );
    assert!(
        has(&got, "presentation.test_label", "not shown"),
        "{got:#?}"
    );
    // Hiding them where they are hidden anyway is fine.
    let off = example_text("staircase.toml")
        .replace("[presentation]\n", "[presentation]\nlabels = false\n");
    assert_eq!(parse(&off).unwrap().presentation.labels, None);
}

#[test]
fn bad_labels_and_titles_are_listed_together() {
    let text = example_text("mos.toml")
        .replace("\"Compressed\"", "\"Original\"")
        .replace("title = \"Motion quality study\"", "title = \"  \"")
        .replace("gap_ms = 500\n", "gap_ms = 500\ngrey_ms = 200\n");
    let got = issues(&text);
    assert!(
        has(&got, "presentation.test_label", "tell them apart"),
        "{got:#?}"
    );
    assert!(has(&got, "title", "1-120 characters"), "{got:#?}");
    assert!(
        has(&got, "presentation.grey_ms", "side-by-side"),
        "{got:#?}"
    );
    assert_eq!(got.len(), 3, "{got:#?}");
    let text = example_text("mos.toml")
        .replace("reference_label = \"Original\"", "reference_label = \"\"")
        .replace("gap_ms = 500\n", "gap_ms = 500\nlabels = false\n");
    let got = issues(&text);
    assert!(
        has(&got, "presentation.reference_label", "labels = false"),
        "{got:#?}"
    );
    assert!(
        has(&got, "presentation.test_label", "labels = false"),
        "{got:#?}"
    );
}

#[test]
fn the_grey_between_intervals_defaults_to_bt500_or_the_older_gap() {
    // The example sets BT.500's 3 s explicitly, and 1 s between trials.
    let s = example("dscqs.toml");
    assert_eq!(
        (s.presentation.grey_ms, s.presentation.gap_ms),
        (3000, 1000)
    );
    // Without grey_ms, a file that gives gap_ms keeps its meaning from before grey_ms.
    let older = example_text("dscqs.toml").replace("grey_ms = 3000\n", "");
    let s = parse(&older).unwrap();
    assert_eq!(
        (s.presentation.grey_ms, s.presentation.gap_ms),
        (1000, 1000)
    );
    // Neither: BT.500's 3 s and the default 500 ms gap.
    let neither = older.replace("gap_ms = 1000\n", "");
    let s = parse(&neither).unwrap();
    assert_eq!((s.presentation.grey_ms, s.presentation.gap_ms), (3000, 500));
    // A sequential MOS: 500 ms unless given.
    let seq = example_text("mos.toml").replace("\"side_by_side\"", "\"sequential\"");
    let s = parse(&seq).unwrap();
    assert_eq!(s.presentation.grey_ms, 500);
    let s = parse(&seq.replace("gap_ms = 500\n", "gap_ms = 500\ngrey_ms = 250\n")).unwrap();
    assert_eq!((s.presentation.grey_ms, s.presentation.gap_ms), (250, 500));
}

#[test]
fn no_preference_is_refused_where_the_method_offers_none() {
    for example_file in ["mos.toml", "dscqs.toml", "staircase.toml"] {
        let text = example_text(example_file)
            .replace("[presentation]\n", "[presentation]\nno_preference = true\n");
        let got = issues(&text);
        assert!(
            has(
                &got,
                "presentation.no_preference",
                "offers no \"no preference\""
            ),
            "{example_file}: {got:#?}"
        );
        // Saying no is always fine.
        let off = example_text(example_file).replace(
            "[presentation]\n",
            "[presentation]\nno_preference = false\n",
        );
        assert!(!parse(&off).unwrap().presentation.no_preference);
    }
}
