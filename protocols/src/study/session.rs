//! `[session]`: time limit, breaks, hidden repeats, subject fields, consent and
//! instructions, and how familiarization is asked for.

use toml::Table;

use super::SessionSettings;
use super::check::{Ctx, join};

pub(super) enum FamSpec {
    None,
    Count(u32),
    Stimuli(Vec<String>),
}

pub(super) fn parse_session(t: &Table, cx: &mut Ctx) -> (SessionSettings, FamSpec) {
    const P: &str = "session";
    cx.known(
        t,
        P,
        &[
            "time_limit_min",
            "break_every_trials",
            "familiarization",
            "familiarization_stimuli",
            "hidden_repeats",
            "subject_fields",
            "consent",
            "instructions",
        ],
    );
    let time_limit_ms = cx.float(t, P, "time_limit_min").and_then(|m| {
        if m > 0.0 && m <= 24.0 * 60.0 {
            Some((m * 60_000.0).round() as u64)
        } else {
            cx.err(
                join(P, "time_limit_min"),
                format!("{m} must be in (0, 1440] minutes"),
            );
            None
        }
    });
    let break_every_trials = cx.uint(t, P, "break_every_trials", 100_000);
    if break_every_trials == Some(0) {
        cx.err(
            join(P, "break_every_trials"),
            "must be at least 1 (omit it for no breaks)",
        );
    }
    let hidden_repeats = cx.uint(t, P, "hidden_repeats", 100_000).unwrap_or(0);
    let subject_fields = super::fields::parse(t, P, cx);
    let mut text = |key: &str| {
        let v = cx.string(t, P, key)?;
        if v.trim().is_empty() {
            cx.err(join(P, key), "is empty (omit it instead)");
            None
        } else if v.len() > 16 * 1024 {
            cx.err(
                join(P, key),
                format!("{} bytes is over the 16 KiB limit", v.len()),
            );
            None
        } else {
            Some(v)
        }
    };
    let consent = text("consent");
    let instructions = text("instructions");
    let count = cx.uint(t, P, "familiarization", 10_000);
    let list = cx.strings(t, P, "familiarization_stimuli");
    let fam = match (count, list) {
        (Some(_), Some(_)) => {
            cx.err(
                join(P, "familiarization"),
                "give either familiarization (a count) or familiarization_stimuli, not both",
            );
            FamSpec::None
        }
        (Some(0) | None, None) => FamSpec::None,
        (Some(n), None) => FamSpec::Count(n),
        (None, Some(l)) => FamSpec::Stimuli(l),
    };
    (
        SessionSettings {
            time_limit_ms,
            break_every_trials,
            hidden_repeats,
            subject_fields,
            consent,
            instructions,
        },
        fam,
    )
}
