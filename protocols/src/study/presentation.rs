//! `[presentation]`: layout, reference position, playbacks, replays, the gap between trials,
//! the grey between intervals, and the labels that say which stimulus is the reference.

use toml::Table;

use super::check::{Ctx, join};
use super::{PresentationSettings, ReferencePlacement, StimulusLabels};
use crate::methods::{Method, ReferenceRule, SIDE_BY_SIDE_OR_SEQUENTIAL};
use crate::record::{Arrangement, Position, Protocol};

pub(super) fn parse_presentation(
    t: &Table,
    protocol: Option<Protocol>,
    cx: &mut Ctx,
) -> Option<PresentationSettings> {
    const P: &str = "presentation";
    cx.known(
        t,
        P,
        &[
            "arrangement",
            "reference_position",
            "playback_count",
            "max_replays",
            "loop",
            "gap_ms",
            "grey_ms",
            "stimulus_duration_ms",
            "labels",
            "reference_label",
            "test_label",
            "no_preference",
        ],
    );
    let method = protocol.map(crate::methods::of);
    let arrangement = pick_arrangement(
        t,
        method.map_or(SIDE_BY_SIDE_OR_SEQUENTIAL, |m| m.arrangements()),
        cx,
    )?;
    let reference_position = parse_reference_position(t, method, arrangement, cx);
    let playback_count = cx.uint(t, P, "playback_count", 100).unwrap_or(1);
    if playback_count == 0 {
        cx.err(join(P, "playback_count"), "must be at least 1");
    }
    let max_replays = cx.uint(t, P, "max_replays", 1000);
    let loop_playback = cx.boolean(t, P, "loop").unwrap_or(false);
    let gap_given = cx.uint(t, P, "gap_ms", 600_000);
    let gap_ms = gap_given.unwrap_or(500);
    let grey_ms = parse_grey(t, arrangement, gap_given, cx);
    let labels = parse_labels(t, method, cx);
    let stimulus_duration_ms = cx
        .uint(t, P, "stimulus_duration_ms", 3_600_000)
        .unwrap_or(5000);
    let no_preference = cx.boolean(t, P, "no_preference").unwrap_or(false);
    if no_preference
        && let Some(m) = method
        && !m.offers_no_preference()
    {
        cx.err(
            join(P, "no_preference"),
            format!(
                "{} offers no \"no preference\" answer: its answers are rated or have a right \
                 one (a pair comparison takes it)",
                m.protocol()
            ),
        );
    }
    Some(PresentationSettings {
        arrangement,
        reference_position,
        playback_count,
        max_replays,
        loop_playback,
        gap_ms: u64::from(gap_ms),
        grey_ms: u64::from(grey_ms),
        labels,
        stimulus_duration_ms: u64::from(stimulus_duration_ms),
        no_preference,
    })
}

/// `arrangement`, one of `choices` (the first is the default); `None` when given and not
/// one of them (the problem is in `cx`).
fn pick_arrangement(
    t: &Table,
    choices: &[(&str, Arrangement)],
    cx: &mut Ctx,
) -> Option<Arrangement> {
    match cx.pick(t, "presentation", "arrangement", choices) {
        Some(a) => Some(a),
        None if t.contains_key("arrangement") => None,
        None => choices.first().map(|c| c.1),
    }
}

/// `reference_position`: a position of the arrangement or `"random"` (the default). ACR
/// shows no reference, so it takes none; DCR shows the reference first (P.910), or on the
/// side the study names; a pair comparison takes `"random"` or `"balanced"` only (the
/// position of a pair's second stimulus).
fn parse_reference_position(
    t: &Table,
    method: Option<&dyn Method>,
    arrangement: Arrangement,
    cx: &mut Ctx,
) -> ReferencePlacement {
    const P: &str = "presentation";
    let given = cx.string(t, P, "reference_position");
    let rule = method.map_or(ReferenceRule::Any, Method::reference_rule);
    match rule {
        ReferenceRule::None { why, placement } => {
            if given.is_some() {
                cx.err(join(P, "reference_position"), why);
            }
            return placement;
        }
        ReferenceRule::ShownFirst => {
            let default = if arrangement == Arrangement::Sequential {
                Position::First
            } else {
                Position::Left
            };
            return match given.as_deref() {
                None => ReferencePlacement::Fixed(default),
                Some(s) => match s.parse::<Position>() {
                    Ok(p)
                        if p.fits(arrangement)
                            && !(arrangement == Arrangement::Sequential
                                && p == Position::Second) =>
                    {
                        ReferencePlacement::Fixed(p)
                    }
                    _ => {
                        cx.err(
                            join(P, "reference_position"),
                            format!(
                                "{s:?}: DCR shows the labelled reference first (P.910): give \
                                 \"first\" with arrangement \"sequential\", \"left\" or \"right\" \
                                 side by side"
                            ),
                        );
                        ReferencePlacement::Fixed(default)
                    }
                },
            };
        }
        ReferenceRule::Any | ReferenceRule::NotFixed { .. } => {}
    }
    match (given.as_deref(), rule) {
        (None | Some("random"), _) => ReferencePlacement::Random,
        (Some("balanced"), _) => ReferencePlacement::Balanced,
        (Some(s), ReferenceRule::NotFixed { why }) => {
            cx.err(join(P, "reference_position"), format!("{s:?}: {why}"));
            ReferencePlacement::Random
        }
        (Some(s), _) => match s.parse::<Position>() {
            Ok(p) if p.fits(arrangement) => ReferencePlacement::Fixed(p),
            Ok(p) => {
                cx.err(
                    join(P, "reference_position"),
                    format!("{p} does not fit arrangement {arrangement}"),
                );
                ReferencePlacement::Random
            }
            Err(e) => {
                cx.err(
                    join(P, "reference_position"),
                    format!("{e}, \"random\" or \"balanced\""),
                );
                ReferencePlacement::Random
            }
        },
    }
}

/// BT.500's mid-grey between the DSCQS intervals, about 3 s.
const DSCQS_GREY_MS: u32 = 3000;

/// Longest stimulus label, characters.
const MAX_LABEL_CHARS: usize = 40;

/// `grey_ms`: the grey between the intervals of a sequential or DSCQS presentation. Without
/// it, `gap_ms` when the file gives one (before `grey_ms` existed, `gap_ms` was also this
/// grey, so older study files keep their timing), else BT.500's 3 s for DSCQS and 500 ms for
/// sequential. A side-by-side presentation has no such grey.
fn parse_grey(t: &Table, arrangement: Arrangement, gap_given: Option<u32>, cx: &mut Ctx) -> u32 {
    const P: &str = "presentation";
    let grey = cx.uint(t, P, "grey_ms", 600_000);
    if grey.is_some() && arrangement == Arrangement::SideBySide {
        cx.err(
            join(P, "grey_ms"),
            "a side-by-side presentation has no grey field between stimuli (grey_ms is for \
             sequential and DSCQS)",
        );
    }
    if grey.is_some() && arrangement == Arrangement::Grid {
        cx.err(
            join(P, "grey_ms"),
            "a MUSHRA screen shows every stimulus at once: there is no grey field between \
             stimuli (gap_ms is the pause between screens)",
        );
    }
    if grey.is_some() && arrangement == Arrangement::Single {
        cx.err(
            join(P, "grey_ms"),
            "an ACR trial shows one stimulus: there is no grey field between stimuli (gap_ms \
             is the pause between trials)",
        );
    }
    grey.or(gap_given).unwrap_or(match arrangement {
        Arrangement::Abab => DSCQS_GREY_MS,
        Arrangement::Sequential
        | Arrangement::SideBySide
        | Arrangement::Single
        | Arrangement::Grid => 500,
    })
}

/// `labels`, `reference_label`, `test_label`: shown only where the design tells the subject
/// which stimulus is the reference (MOS, paper 000: "compare side by side the original and
/// compressed motions"). DSCQS (BT.500: the subject is not told which of A and B is the
/// reference) and 2AFC (the reference's side is what the subject must find) refuse them.
fn parse_labels(t: &Table, method: Option<&dyn Method>, cx: &mut Ctx) -> Option<StimulusLabels> {
    const P: &str = "presentation";
    let asked = cx.boolean(t, P, "labels");
    let hidden_by_design = method.and_then(Method::labels_hidden);
    if let (Some(true), Some(why)) = (asked, hidden_by_design) {
        cx.err(join(P, "labels"), format!("cannot be true: {why}"));
    }
    // Shown by default where the design tells the subject which is the reference (MOS, DCR).
    let shown = asked.unwrap_or(method.is_some() && hidden_by_design.is_none())
        && hidden_by_design.is_none();
    let mut text = |key: &str, default: &str| -> String {
        let Some(v) = cx.string(t, P, key) else {
            return default.to_string();
        };
        let n = v.trim().chars().count();
        if !shown {
            cx.err(
                join(P, key),
                match hidden_by_design {
                    Some(why) => format!("not shown: {why}"),
                    None => "not shown with labels = false (remove it or the labels setting)"
                        .to_string(),
                },
            );
        } else if n == 0 || n > MAX_LABEL_CHARS || v.contains(['\n', '\r']) {
            cx.err(
                join(P, key),
                format!("{v:?}: give one line of 1-{MAX_LABEL_CHARS} characters"),
            );
        }
        v.trim().to_string()
    };
    let reference = text("reference_label", "Original");
    let test = text("test_label", "Compressed");
    if shown && !reference.is_empty() && reference == test {
        cx.err(
            join(P, "test_label"),
            format!(
                "{test:?} is also the reference's label: the subject could not tell them apart"
            ),
        );
    }
    shown.then_some(StimulusLabels { reference, test })
}
