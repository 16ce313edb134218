//! `[conditions]` (the test stimuli of a MOS or DSCQS study: a list or a clips × codecs ×
//! target_cr grid) and the familiarization stimuli chosen among them.

use std::collections::BTreeSet;

use toml::Table;

use super::Condition;
use super::check::Ctx;
use super::session::FamSpec;
use crate::manifest::{REFERENCE_CODEC, StimulusManifest};

fn condition_of(id: &str, m: &StimulusManifest, key: &str, cx: &mut Ctx) -> Option<Condition> {
    let Some(s) = m.get(id) else {
        cx.err(key, format!("stimulus {id:?} is not in the manifest"));
        return None;
    };
    if s.codec == REFERENCE_CODEC {
        cx.err(
            key,
            format!("stimulus {id:?} is a reference, not a test stimulus"),
        );
        return None;
    }
    let Some(r) = m.reference_of(&s.clip) else {
        cx.err(
            key,
            format!(
                "clip {:?} of stimulus {id:?} has no reference in the manifest",
                s.clip
            ),
        );
        return None;
    };
    Some(Condition {
        stimulus: s.id.clone(),
        reference: r.id.clone(),
    })
}

pub(super) fn parse_conditions(t: &Table, m: &StimulusManifest, cx: &mut Ctx) -> Vec<Condition> {
    const P: &str = "conditions";
    cx.known(t, P, &["stimuli", "clips", "codecs", "target_cr"]);
    let mut out = Vec::new();
    let list = cx.strings(t, P, "stimuli");
    let grid_keys = ["clips", "codecs", "target_cr"]
        .iter()
        .any(|k| t.contains_key(*k));
    if let Some(list) = list {
        if grid_keys {
            cx.err(
                P,
                "give either stimuli or a clips x codecs x target_cr grid, not both",
            );
        }
        let mut seen = BTreeSet::new();
        for (i, id) in list.iter().enumerate() {
            let key = format!("{P}.stimuli[{i}]");
            if !seen.insert(id.as_str()) {
                cx.err(
                    &key,
                    format!(
                        "stimulus {id:?} is listed twice (use session.hidden_repeats for repeats)"
                    ),
                );
                continue;
            }
            if let Some(c) = condition_of(id, m, &key, cx) {
                out.push(c);
            }
        }
    } else if grid_keys {
        let clips = cx.strings(t, P, "clips");
        let clips = cx.required(clips, t, P, "clips").unwrap_or_default();
        let codecs = cx.strings(t, P, "codecs");
        let codecs = cx.required(codecs, t, P, "codecs").unwrap_or_default();
        let crs = cx.floats(t, P, "target_cr");
        for (ci, clip) in clips.iter().enumerate() {
            for (di, codec) in codecs.iter().enumerate() {
                let matching: Vec<_> = m
                    .stimuli
                    .iter()
                    .filter(|s| &s.clip == clip && &s.codec == codec)
                    .collect();
                match &crs {
                    None if matching.is_empty() => {
                        cx.err(
                            format!("{P}.codecs[{di}]"),
                            format!(
                                "no stimulus of clip {clip:?} (clips[{ci}]) with codec {codec:?}"
                            ),
                        );
                    }
                    None => {
                        for s in matching {
                            out.extend(condition_of(&s.id, m, &format!("{P}.codecs[{di}]"), cx));
                        }
                    }
                    Some(crs) => {
                        for (ri, cr) in crs.iter().enumerate() {
                            let hit: Vec<_> = matching
                                .iter()
                                .filter(|s| {
                                    s.target_cr
                                        .is_some_and(|t| (t - cr).abs() <= 1e-9 * cr.abs().max(1.0))
                                })
                                .collect();
                            if hit.is_empty() {
                                cx.err(format!("{P}.target_cr[{ri}]"), format!("no stimulus of clip {clip:?} with codec {codec:?} at target_cr {cr}"));
                            }
                            for s in hit {
                                out.extend(condition_of(
                                    &s.id,
                                    m,
                                    &format!("{P}.target_cr[{ri}]"),
                                    cx,
                                ));
                            }
                        }
                    }
                }
            }
        }
    } else {
        cx.err(P, "give stimuli = [...] or clips, codecs (and target_cr)");
    }
    if out.is_empty() && cx.issues.is_empty() {
        cx.err(P, "no test stimulus selected");
    }
    out
}

pub(super) fn resolve_familiarization(
    spec: FamSpec,
    conditions: &[Condition],
    m: &StimulusManifest,
    cx: &mut Ctx,
) -> Vec<Condition> {
    match spec {
        FamSpec::None => Vec::new(),
        FamSpec::Stimuli(list) => list
            .iter()
            .enumerate()
            .filter_map(|(i, id)| {
                condition_of(id, m, &format!("session.familiarization_stimuli[{i}]"), cx)
            })
            .collect(),
        FamSpec::Count(n) => {
            let n = n as usize;
            if n > conditions.len() {
                cx.err(
                    "session.familiarization",
                    format!(
                        "{n} familiarization trials but only {} conditions",
                        conditions.len()
                    ),
                );
                return Vec::new();
            }
            // Paper 000: familiarization spans the range of compression ratios (10:1 to 70:1);
            // pick evenly spaced ranks of the achieved ratio.
            let mut ranked: Vec<&Condition> = conditions.iter().collect();
            ranked.sort_by(|a, b| {
                let cr = |c: &Condition| m.get(&c.stimulus).map_or(0.0, |s| s.achieved_cr);
                cr(a)
                    .total_cmp(&cr(b))
                    .then_with(|| a.stimulus.cmp(&b.stimulus))
            });
            (0..n)
                .map(|i| {
                    if n == 1 {
                        ranked.len() / 2
                    } else {
                        (i * (ranked.len() - 1) + (n - 1) / 2) / (n - 1)
                    }
                })
                .filter_map(|i| ranked.get(i).map(|c| (*c).clone()))
                .collect()
        }
    }
}
