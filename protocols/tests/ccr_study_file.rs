//! CCR's study-file rules (ITU-T P.910): its own seven-category scale, both orders (never a
//! fixed place for the original), no labels saying which version is the original; each
//! refused in `study check`'s one list, and the default file gives the P.910 scale.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use common::{example_text, has, issues, parse};
use protocols::study::ScaleKind;

/// The MOS test study as a CCR study: no `[scale]`, no labels, the original's place random.
fn ccr() -> String {
    let mos = example_text("mos.toml");
    let scale = &mos[mos.find("[scale]").unwrap()..mos.find("[session]").unwrap()];
    mos.replace("protocol = \"mos\"", "protocol = \"ccr\"")
        .replace(scale, "")
        .replace("reference_label = \"Original\"\n", "")
        .replace("test_label = \"Compressed\"\n", "")
}

#[test]
fn ccr_takes_its_scale_and_both_orders() {
    let s = parse(&ccr()).unwrap();
    assert_eq!(s.scale.kind, ScaleKind::Categorical);
    assert!((s.scale.min + 3.0).abs() < 1e-12 && (s.scale.max - 3.0).abs() < 1e-12);
    assert_eq!(s.scale.step, Some(1.0));
    assert_eq!(
        protocols::texts::scale_words(&s)
            .first()
            .map(String::as_str),
        Some("Much better")
    );

    let bad = ccr()
        .replace(
            "reference_position = \"random\"",
            "reference_position = \"first\"",
        )
        .replace(
            "[session]\n",
            "[scale]\nkind = \"categorical\"\nmin = 1\nmax = 5\nstep = 1\n\n[session]\n",
        )
        .replace("[presentation]\n", "[presentation]\nlabels = true\n");
    let got = issues(&bad);
    assert!(
        has(
            &got,
            "presentation.reference_position",
            "CCR shows the original first"
        ),
        "{got:#?}"
    );
    assert!(
        has(&got, "scale", "CCR rates seven comparison categories"),
        "{got:#?}"
    );
    assert!(
        has(&got, "presentation.labels", "CCR does not tell"),
        "{got:#?}"
    );
}
