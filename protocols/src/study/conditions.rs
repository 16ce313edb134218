//! `[conditions]` (the test stimuli of a MOS or DSCQS study: a list or a clips × codecs ×
//! target_cr × params grid) and the familiarization stimuli chosen among them.
//!
//! A grid cell with a target ratio is one condition: when a manifest holds several variants
//! of a codec at one ratio (`study sweep --param`), the study names the one it means in
//! `params` (every combination of its values is a cell), or the cell is refused as ambiguous,
//! naming the parameters the candidates differ in.

use std::collections::{BTreeMap, BTreeSet};

use toml::{Table, Value};

use super::Condition;
use super::check::Ctx;
use super::session::FamSpec;
use crate::manifest::{REFERENCE_CODEC, Stimulus, StimulusManifest};

/// Whether a study's conditions may be references (rated as tests: ACR's hidden reference).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum References {
    /// Refused: the reference is shown beside or before its test (MOS, DSCQS, DCR).
    Refused,
    /// Allowed: ACR shows one stimulus, and a reference rated so is a hidden reference
    /// (P.910 ACR-HR); a pair comparison shows two unlabelled stimuli, and the original
    /// among them is one more condition, the anchor its scale values are read against.
    Hidden,
}

impl References {
    /// What a method allows: hidden references where it takes them
    /// ([`crate::methods::Method::hidden_references`]: ACR and pair comparison).
    pub(super) fn of(hidden_references: bool) -> Self {
        if hidden_references {
            Self::Hidden
        } else {
            Self::Refused
        }
    }
}

fn condition_of(
    id: &str,
    m: &StimulusManifest,
    key: &str,
    refs: References,
    cx: &mut Ctx,
) -> Option<Condition> {
    let Some(s) = m.get(id) else {
        cx.err(key, format!("stimulus {id:?} is not in the manifest"));
        return None;
    };
    if s.codec == REFERENCE_CODEC {
        if refs == References::Hidden {
            return Some(Condition {
                stimulus: s.id.clone(),
                reference: s.id.clone(),
            });
        }
        cx.err(
            key,
            format!(
                "stimulus {id:?} is a reference, not a test stimulus (only an ACR or a pair \
                 comparison study shows references as conditions, unlabelled)"
            ),
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

/// Whether two parameter values (or target ratios) are the same number, as written to and
/// read back from a manifest.
fn same_value(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

/// `conditions.params`: codec parameter → the values the grid takes (a number or an array of
/// numbers), in key order.
fn parse_param_grid(t: &Table, cx: &mut Ctx) -> Vec<(String, Vec<f64>)> {
    const P: &str = "conditions";
    let Some(table) = cx.table(t, P, "params") else {
        return Vec::new();
    };
    let mut grid = Vec::new();
    for (k, v) in table {
        let key = format!("{P}.params");
        let values = match v {
            Value::Array(_) => cx.floats(table, &key, k),
            _ => cx.float(table, &key, k).map(|x| vec![x]),
        };
        match values {
            Some(values) if values.is_empty() => {
                cx.err(format!("{key}.{k}"), "no values");
            }
            Some(values) => grid.push((k.clone(), values)),
            None => {}
        }
    }
    grid
}

/// Every combination of the grid's values, one map per combination (one empty map for no
/// grid).
fn param_combinations(grid: &[(String, Vec<f64>)]) -> Vec<BTreeMap<String, f64>> {
    let mut out = vec![BTreeMap::new()];
    for (k, values) in grid {
        out = out
            .iter()
            .flat_map(|m| {
                values.iter().map(move |v| {
                    let mut m = m.clone();
                    m.insert(k.clone(), *v);
                    m
                })
            })
            .collect();
    }
    out
}

/// ` with qp = 9, window = 128` for a non-empty combination, else nothing.
fn with_params(combo: &BTreeMap<String, f64>) -> String {
    if combo.is_empty() {
        return String::new();
    }
    let parts: Vec<String> = combo.iter().map(|(k, v)| format!("{k} = {v}")).collect();
    format!(" with {}", parts.join(", "))
}

/// The refusal of a grid cell that matches several stimuli: which variant parameters tell
/// them apart, and how to name one.
fn ambiguous(hits: &[&Stimulus], cell: &str) -> String {
    // The variant keys, compared on what each stream records (a stimulus made with the
    // defaults has no variant but records the value it used).
    let keys: BTreeSet<&str> = hits
        .iter()
        .flat_map(|s| s.variant.keys().map(String::as_str))
        .collect();
    let differ: Vec<&str> = keys
        .into_iter()
        .filter(|k| {
            let values: BTreeSet<Option<u64>> = hits
                .iter()
                .map(|s| s.params.get(*k).map(|v| v.to_bits()))
                .collect();
            values.len() > 1
        })
        .collect();
    let ids: Vec<String> = hits.iter().map(|s| format!("{:?}", s.id)).collect();
    let example = hits
        .iter()
        .find(|s| !s.variant.is_empty())
        .map(|s| {
            differ
                .iter()
                .filter_map(|k| s.params.get(*k).map(|v| format!("{k} = {v}")))
                .collect::<Vec<_>>()
        })
        .unwrap_or_default();
    let how = if differ.is_empty() || example.is_empty() {
        "list the one you mean in conditions.stimuli".to_string()
    } else {
        format!(
            "they differ in {}: name the variant with conditions.params (e.g. params = {{ {} }}) \
             or list the stimuli in conditions.stimuli",
            differ.join(", "),
            example.join(", ")
        )
    };
    format!(
        "{} stimuli match {cell} ({}); {how}",
        hits.len(),
        ids.join(", ")
    )
}

pub(super) fn parse_conditions(
    t: &Table,
    m: &StimulusManifest,
    refs: References,
    cx: &mut Ctx,
) -> Vec<Condition> {
    const P: &str = "conditions";
    cx.known(
        t,
        P,
        &[
            "stimuli",
            "clips",
            "codecs",
            "target_cr",
            "params",
            "hidden_reference",
        ],
    );
    let hidden_reference = cx.boolean(t, P, "hidden_reference").unwrap_or(false);
    if hidden_reference && refs != References::Hidden {
        cx.err(
            format!("{P}.hidden_reference"),
            "only an ACR study (protocol = \"acr\") or a pair comparison (protocol = \
             \"pair_comparison\") has hidden references",
        );
    }
    let mut out = grid_or_list(t, m, refs, cx);
    if hidden_reference && refs == References::Hidden {
        add_hidden_references(&mut out, m, cx);
    }
    out
}

/// P.910 ACR-HR: the reference of every clip among the conditions, rated as a test
/// condition of its own (once, and in the order the clips first appear).
fn add_hidden_references(out: &mut Vec<Condition>, m: &StimulusManifest, cx: &mut Ctx) {
    let mut have: BTreeSet<String> = out.iter().map(|c| c.stimulus.clone()).collect();
    let mut added = Vec::new();
    for c in out.iter() {
        if have.insert(c.reference.clone()) {
            added.extend(condition_of(
                &c.reference,
                m,
                "conditions.hidden_reference",
                References::Hidden,
                cx,
            ));
        }
    }
    out.extend(added);
}

fn grid_or_list(t: &Table, m: &StimulusManifest, refs: References, cx: &mut Ctx) -> Vec<Condition> {
    const P: &str = "conditions";
    let mut out = Vec::new();
    let list = cx.strings(t, P, "stimuli");
    let grid_keys = ["clips", "codecs", "target_cr", "params"]
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
            if let Some(c) = condition_of(id, m, &key, refs, cx) {
                out.push(c);
            }
        }
    } else if grid_keys {
        let clips = cx.strings(t, P, "clips");
        let clips = cx.required(clips, t, P, "clips").unwrap_or_default();
        let codecs = cx.strings(t, P, "codecs");
        let codecs = cx.required(codecs, t, P, "codecs").unwrap_or_default();
        let crs = cx.floats(t, P, "target_cr");
        let combos = param_combinations(&parse_param_grid(t, cx));
        for (ci, clip) in clips.iter().enumerate() {
            for (di, codec) in codecs.iter().enumerate() {
                for combo in &combos {
                    let matching: Vec<&Stimulus> = m
                        .stimuli
                        .iter()
                        .filter(|s| &s.clip == clip && &s.codec == codec)
                        .filter(|s| {
                            combo
                                .iter()
                                .all(|(k, v)| s.params.get(k).is_some_and(|x| same_value(*x, *v)))
                        })
                        .collect();
                    let params = with_params(combo);
                    match &crs {
                        None if matching.is_empty() => {
                            cx.err(
                                format!("{P}.codecs[{di}]"),
                                format!(
                                    "no stimulus of clip {clip:?} (clips[{ci}]) with codec \
                                     {codec:?}{params}"
                                ),
                            );
                        }
                        // Without target_cr a cell is every stimulus of the clip and codec
                        // (and named parameters): every rate and variant, each its own
                        // condition.
                        None => {
                            for s in matching {
                                out.extend(condition_of(
                                    &s.id,
                                    m,
                                    &format!("{P}.codecs[{di}]"),
                                    refs,
                                    cx,
                                ));
                            }
                        }
                        Some(crs) => {
                            for (ri, cr) in crs.iter().enumerate() {
                                let key = format!("{P}.target_cr[{ri}]");
                                let hit: Vec<&Stimulus> = matching
                                    .iter()
                                    .copied()
                                    .filter(|s| s.target_cr.is_some_and(|t| same_value(t, *cr)))
                                    .collect();
                                let cell = format!(
                                    "clip {clip:?} with codec {codec:?} at target_cr {cr}{params}"
                                );
                                match hit.as_slice() {
                                    [] => cx.err(key, format!("no stimulus of {cell}")),
                                    [s] => out.extend(condition_of(&s.id, m, &key, refs, cx)),
                                    // One cell, one condition: a grid never picks several
                                    // variants of a codec at one rate unasked.
                                    _ => cx.err(key, ambiguous(&hit, &cell)),
                                }
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
    refs: References,
    cx: &mut Ctx,
) -> Vec<Condition> {
    match spec {
        FamSpec::None => Vec::new(),
        FamSpec::Stimuli(list) => list
            .iter()
            .enumerate()
            .filter_map(|(i, id)| {
                condition_of(
                    id,
                    m,
                    &format!("session.familiarization_stimuli[{i}]"),
                    refs,
                    cx,
                )
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
                // A stimulus of unknown CR ranks first, as if it were the lowest.
                let cr = |c: &Condition| {
                    m.get(&c.stimulus)
                        .and_then(|s| s.achieved_cr)
                        .unwrap_or(0.0)
                };
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
