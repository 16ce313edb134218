//! `[presentation]`: layout, reference position, playbacks, replays, gaps.

use toml::Table;

use super::check::{Ctx, join};
use super::{PresentationSettings, ReferencePlacement};
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
            "stimulus_duration_ms",
        ],
    );
    let arrangement = if protocol == Some(Protocol::Dscqs) {
        match cx.pick(t, P, "arrangement", &[("abab", Arrangement::Abab)]) {
            Some(a) => a,
            None if t.contains_key("arrangement") => return None,
            None => Arrangement::Abab,
        }
    } else {
        match cx.pick(
            t,
            P,
            "arrangement",
            &[
                ("side_by_side", Arrangement::SideBySide),
                ("sequential", Arrangement::Sequential),
            ],
        ) {
            Some(a) => a,
            None if t.contains_key("arrangement") => return None,
            None => Arrangement::SideBySide,
        }
    };
    let reference_position = match cx.string(t, P, "reference_position").as_deref() {
        None | Some("random") => ReferencePlacement::Random,
        Some(s) => match s.parse::<Position>() {
            Ok(p) if p.fits(arrangement) => ReferencePlacement::Fixed(p),
            Ok(p) => {
                cx.err(
                    join(P, "reference_position"),
                    format!("{p} does not fit arrangement {arrangement}"),
                );
                ReferencePlacement::Random
            }
            Err(e) => {
                cx.err(join(P, "reference_position"), format!("{e} or \"random\""));
                ReferencePlacement::Random
            }
        },
    };
    let playback_count = cx.uint(t, P, "playback_count", 100).unwrap_or(1);
    if playback_count == 0 {
        cx.err(join(P, "playback_count"), "must be at least 1");
    }
    let max_replays = cx.uint(t, P, "max_replays", 1000);
    let loop_playback = cx.boolean(t, P, "loop").unwrap_or(false);
    let gap_ms = cx.uint(t, P, "gap_ms", 600_000).unwrap_or(500);
    let stimulus_duration_ms = cx
        .uint(t, P, "stimulus_duration_ms", 3_600_000)
        .unwrap_or(5000);
    Some(PresentationSettings {
        arrangement,
        reference_position,
        playback_count,
        max_replays,
        loop_playback,
        gap_ms: u64::from(gap_ms),
        stimulus_duration_ms: u64::from(stimulus_duration_ms),
    })
}
