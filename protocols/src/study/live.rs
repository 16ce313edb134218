//! `[staircase.live]`: a codec-in-the-loop staircase's clips, their order, the codec's fixed
//! parameters, its decoder context file and the file of command-defined codecs it may name.

use std::collections::{BTreeMap, BTreeSet};

use toml::{Table, Value};

use super::check::{Ctx, join, type_name};
use super::{ClipOrder, LiveClip, LiveStaircase};
use crate::catalog::{CodecCatalog, TARGET_CR_PARAM};
use crate::manifest::StimulusManifest;

const P: &str = "staircase.live";

/// Most clips a live staircase may alternate, and most fixed codec parameters.
const MAX_LIVE_CLIPS: usize = 256;
const MAX_LIVE_PARAMS: usize = 32;

/// `[staircase.live]`: clips, their order, fixed codec parameters, decoder context, and the
/// codec of `[staircase]` (`codec`, whose parameter `param` is the level) checked against the
/// catalog `codecs`.
pub(super) fn parse_live(
    t: &Table,
    codec: Option<&str>,
    param: Option<&str>,
    m: Option<&StimulusManifest>,
    codecs: &dyn CodecCatalog,
    cx: &mut Ctx,
) -> Option<LiveStaircase> {
    cx.known(t, P, &["clips", "order", "params", "database", "codecs"]);
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
    let params = parse_fixed_params(t, param, cx);
    let database = cx.string(t, P, "database");
    if database.as_deref().is_some_and(|d| d.trim().is_empty()) {
        cx.err(join(P, "database"), "must name a file");
    }
    let codec_file = cx.string(t, P, "codecs");
    if codec_file.as_deref().is_some_and(|d| d.trim().is_empty()) {
        cx.err(join(P, "codecs"), "must name a codec definitions file");
    }
    if let Some(codec) = codec {
        check_codec(codecs, codec, param, &params, database.as_deref(), cx);
    }
    names?;
    Some(LiveStaircase {
        clips,
        order,
        params,
        database,
        codecs: codec_file,
    })
}

/// `params`: fixed values of the codec's other parameters (never the level's `param`).
fn parse_fixed_params(t: &Table, param: Option<&str>, cx: &mut Ctx) -> BTreeMap<String, f64> {
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
    params
}

/// The live staircase's codec against the catalog, as the runner will use it: the codec
/// exists, takes the level's parameter and every fixed one, can aim at a compression ratio
/// when the level is one, and has the decoder context file it needs. Each problem is reported
/// on its own, so a file with several shows them all.
fn check_codec(
    codecs: &dyn CodecCatalog,
    codec: &str,
    param: Option<&str>,
    fixed: &BTreeMap<String, f64>,
    database: Option<&str>,
    cx: &mut Ctx,
) {
    let Some(info) = codecs.codec(codec) else {
        cx.err(
            "staircase.codec",
            format!(
                "unknown codec {codec:?} (known: {}; `study codecs` lists them)",
                codecs.names().join(", ")
            ),
        );
        return;
    };
    let accepts = |k: &str| info.params.iter().any(|p| p == k);
    let accepted = || info.params.join(", ");
    if let Some(param) = param {
        if !accepts(param) {
            cx.err(
                "staircase.param",
                format!(
                    "codec {codec:?} has no parameter {param:?} (accepted: {})",
                    accepted()
                ),
            );
        }
        if param == TARGET_CR_PARAM && !info.target_cr {
            cx.err(
                "staircase.param",
                format!("codec {codec:?} takes no target compression ratio"),
            );
        }
    }
    for k in fixed.keys().filter(|k| !accepts(k)) {
        cx.err(
            format!("staircase.live.params.{k}"),
            format!(
                "codec {codec:?} has no such parameter (accepted: {})",
                accepted()
            ),
        );
    }
    if info.needs_database && database.is_none() {
        cx.err(
            "staircase.live.database",
            format!("codec {codec:?} needs a primitive database file here"),
        );
    }
}
