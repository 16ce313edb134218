//! `[staircase.live]`: a codec-in-the-loop staircase's clips, their order, the codec's fixed
//! parameters and its decoder context file.

use std::collections::{BTreeMap, BTreeSet};

use toml::{Table, Value};

use super::check::{Ctx, join, type_name};
use super::{ClipOrder, LiveClip, LiveStaircase};
use crate::manifest::StimulusManifest;

/// Most clips a live staircase may alternate, and most fixed codec parameters.
const MAX_LIVE_CLIPS: usize = 256;
const MAX_LIVE_PARAMS: usize = 32;

/// `[staircase.live]`: clips, their order, fixed codec parameters, decoder context.
pub(super) fn parse_live(
    t: &Table,
    param: Option<&str>,
    m: Option<&StimulusManifest>,
    cx: &mut Ctx,
) -> Option<LiveStaircase> {
    const P: &str = "staircase.live";
    cx.known(t, P, &["clips", "order", "params", "database"]);
    let names = cx.strings(t, P, "clips");
    let names = cx.required(names, t, P, "clips");
    let mut clips = Vec::new();
    if let Some(names) = &names {
        if names.is_empty() {
            cx.err(join(P, "clips"), "needs at least one clip");
        } else if names.len() > MAX_LIVE_CLIPS {
            cx.err(
                join(P, "clips"),
                format!("{} clips, limit {MAX_LIVE_CLIPS}", names.len()),
            );
        }
        let mut seen = BTreeSet::new();
        for (i, clip) in names.iter().take(MAX_LIVE_CLIPS).enumerate() {
            let key = format!("{P}.clips[{i}]");
            if !seen.insert(clip.as_str()) {
                cx.err(&key, format!("clip {clip:?} is listed twice"));
                continue;
            }
            let Some(m) = m else { continue };
            match m.reference_of(clip) {
                Some(r) => clips.push(LiveClip {
                    clip: clip.clone(),
                    reference: r.id.clone(),
                }),
                None => cx.err(
                    &key,
                    format!(
                        "clip {clip:?} has no reference stimulus in the manifest (a live staircase encodes the reference)"
                    ),
                ),
            }
        }
    }
    let order = cx
        .pick(
            t,
            P,
            "order",
            &[
                ("in_turn", ClipOrder::InTurn),
                ("shuffled", ClipOrder::Shuffled),
            ],
        )
        .unwrap_or(ClipOrder::InTurn);
    let mut params = BTreeMap::new();
    match t.get("params") {
        None => {}
        Some(Value::Table(pt)) => {
            if pt.len() > MAX_LIVE_PARAMS {
                cx.err(
                    join(P, "params"),
                    format!("{} parameters, limit {MAX_LIVE_PARAMS}", pt.len()),
                );
            }
            for (k, v) in pt.iter().take(MAX_LIVE_PARAMS) {
                let key = format!("{P}.params.{k}");
                if k.is_empty()
                    || k.len() > 32
                    || !k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                {
                    cx.err(&key, "a parameter name is 1-32 letters, digits or _");
                    continue;
                }
                if Some(k.as_str()) == param {
                    cx.err(
                        &key,
                        format!("{k:?} is the staircase's level; it cannot also be fixed"),
                    );
                    continue;
                }
                match v {
                    Value::Float(f) if f.is_finite() => {
                        params.insert(k.clone(), *f);
                    }
                    Value::Integer(i) => {
                        params.insert(k.clone(), *i as f64);
                    }
                    v => cx.err(
                        &key,
                        format!("expected a finite number, got {}", type_name(v)),
                    ),
                }
            }
        }
        Some(v) => cx.wrong(P, "params", "a table of numbers", v),
    }
    let database = cx.string(t, P, "database");
    if database.as_deref().is_some_and(|d| d.trim().is_empty()) {
        cx.err(join(P, "database"), "must name a file");
    }
    names?;
    Some(LiveStaircase {
        clips,
        order,
        params,
        database,
    })
}
