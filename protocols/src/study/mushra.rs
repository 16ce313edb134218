//! `[mushra]`: a MUSHRA-style study's low anchors and BS.1534-3 post-screening rules, its
//! training screens (`[session] familiarization`, a count of screens), and the rules a MUSHRA
//! study file must keep (one screen per clip, a bounded grid, no repeats, no crowd scenes,
//! catch trials or `[staircase]`).
//!
//! A screen shows the clip's reference, labelled, and unlabelled in a shuffled grid every test
//! condition of the clip, the reference again (hidden reference) and the clip's anchor. The
//! anchor is named per clip in `anchors`: a stimulus of the clip that is not a test
//! condition, typically the coarsest rate or a low-passed version.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};
use toml::Table;

use super::check::{Ctx, join};
use super::session::FamSpec;
use super::{Condition, SessionSettings};
use crate::manifest::{REFERENCE_CODEC, StimulusManifest};
use crate::record::MAX_PANES;

const P: &str = "mushra";

/// What BS.1534-3's anchor rule does to a subject who rates the anchor too high.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnchorRule {
    /// Listed in the report; the subject's ratings are kept (the default: BS.1534-3 says such
    /// assessors *may* be excluded).
    Report,
    /// Listed in the report and excluded like a subject who misses the hidden reference.
    Exclude,
}

/// `[mushra]` of a MUSHRA study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MushraSettings {
    /// Each clip's low anchor (a test stimulus of the clip and its reference), in the order
    /// the clips first appear among the conditions.
    pub anchors: Vec<Condition>,
    /// A hidden reference rated below this misses it (BS.1534-3: 90).
    pub reference_below: f64,
    /// An anchor rated above this is rated too high (BS.1534-3: 90).
    pub anchor_above: f64,
    /// A subject who misses the hidden reference (or rates the anchor too high) on more than
    /// this fraction of the screens (test items) is screened out (BS.1534-3: 0.15).
    pub max_fraction: f64,
    /// What rating the anchor too high does.
    pub anchor_rule: AnchorRule,
    /// Training screens before the test (BS.1534-3's training phase): the screens of the
    /// first this many clips of `[conditions]`, shown first with their panes shuffled anew,
    /// rated, logged in block `familiarization` and left out of the analysis. `[session]
    /// familiarization`.
    #[serde(default)]
    pub training_screens: u32,
}

impl MushraSettings {
    /// Whether `stimulus` is one of the anchors.
    pub fn is_anchor(&self, stimulus: &str) -> bool {
        self.anchors.iter().any(|a| a.stimulus == stimulus)
    }
}

/// The clips' references in the order they first appear among `conditions`, each with its
/// conditions: one MUSHRA screen per entry.
pub fn screens(conditions: &[Condition]) -> Vec<(String, Vec<&Condition>)> {
    let mut out: Vec<(String, Vec<&Condition>)> = Vec::new();
    for c in conditions {
        match out.iter_mut().find(|(r, _)| *r == c.reference) {
            Some((_, v)) => v.push(c),
            None => out.push((c.reference.clone(), vec![c])),
        }
    }
    out
}

/// `[mushra]` and the rules of a MUSHRA study; `None` when it cannot be built (the problems
/// are in `cx`). `training`: what `[session]` asks for as familiarization.
pub(super) fn parse_mushra(
    t: Option<&Table>,
    conditions: &[Condition],
    training: &FamSpec,
    session: &SessionSettings,
    manifest: Option<&StimulusManifest>,
    cx: &mut Ctx,
) -> Option<MushraSettings> {
    if session.hidden_repeats > 0 {
        cx.err(
            "session.hidden_repeats",
            "a MUSHRA screen rates every condition of its clip once, with the hidden reference \
             as its consistency check: remove hidden_repeats",
        );
    }
    let screens = screens(conditions);
    let training_screens = training_screens(training, screens.len(), cx);
    let Some(t) = t else {
        cx.err(
            P,
            "missing: a MUSHRA study names each clip's low anchor in [mushra] anchors",
        );
        return None;
    };
    cx.known(
        t,
        P,
        &[
            "anchors",
            "reference_below",
            "anchor_above",
            "max_fraction",
            "anchor_rule",
        ],
    );
    let mut limit = |key: &str, default: f64, hi: f64| match cx.float(t, P, key) {
        Some(v) if (0.0..=hi).contains(&v) => v,
        Some(v) => {
            cx.err(join(P, key), format!("{v} must be in 0..={hi}"));
            default
        }
        None => default,
    };
    let reference_below = limit("reference_below", 90.0, 100.0);
    let anchor_above = limit("anchor_above", 90.0, 100.0);
    let max_fraction = limit("max_fraction", 0.15, 1.0);
    let anchor_rule = cx
        .pick(
            t,
            P,
            "anchor_rule",
            &[
                ("report", AnchorRule::Report),
                ("exclude", AnchorRule::Exclude),
            ],
        )
        .unwrap_or(AnchorRule::Report);
    let ids = cx.strings(t, P, "anchors");
    let ids = cx.required(ids, t, P, "anchors")?;
    let m = manifest?;
    let mut by_reference = parse_anchors(&ids, m, conditions, &screens, cx);
    let mut anchors = Vec::new();
    for (reference, tests) in &screens {
        let rated = tests.len() + 2;
        if rated > MAX_PANES {
            cx.err(
                "conditions",
                format!(
                    "reference {reference:?}: {} test conditions + hidden reference + anchor = \
                     {rated} rated panes, more than the {MAX_PANES} a screen shows (BS.1534 \
                     asks for few stimuli at once): split the conditions over two studies",
                    tests.len()
                ),
            );
        }
        match by_reference.remove(reference) {
            Some(a) => anchors.push(a),
            None => cx.err(
                join(P, "anchors"),
                format!("no anchor for the clip of reference {reference:?}: give one per clip"),
            ),
        }
    }
    Some(MushraSettings {
        anchors,
        reference_below,
        anchor_above,
        max_fraction,
        anchor_rule,
        training_screens,
    })
}

/// The number of training screens `[session]` asks for, at most `screens` (whole screens,
/// never a list of stimuli).
fn training_screens(training: &FamSpec, screens: usize, cx: &mut Ctx) -> u32 {
    match *training {
        FamSpec::None => 0,
        FamSpec::Count(n) => {
            if n as usize > screens && screens > 0 {
                cx.err(
                    "session.familiarization",
                    format!(
                        "{n} training screens but only {screens} screens (one per clip): a \
                         MUSHRA study trains on its own screens"
                    ),
                );
            }
            n
        }
        FamSpec::Stimuli(_) => {
            cx.err(
                "session.familiarization_stimuli",
                "a MUSHRA study trains on whole screens (BS.1534-3's training phase): give \
                 familiarization, the number of training screens, instead",
            );
            0
        }
    }
}

/// `anchors`: each id's anchor by its clip's reference, every problem named by its index.
fn parse_anchors(
    ids: &[String],
    m: &StimulusManifest,
    conditions: &[Condition],
    screens: &[(String, Vec<&Condition>)],
    cx: &mut Ctx,
) -> BTreeMap<String, Condition> {
    let tests: BTreeSet<&str> = conditions.iter().map(|c| c.stimulus.as_str()).collect();
    let mut by_reference: BTreeMap<String, Condition> = BTreeMap::new();
    for (i, id) in ids.iter().enumerate() {
        let key = format!("{P}.anchors[{i}]");
        let Some(s) = m.get(id) else {
            cx.err(key, format!("stimulus {id:?} is not in the manifest"));
            continue;
        };
        if s.codec == REFERENCE_CODEC {
            cx.err(
                key,
                format!("{id:?} is a reference: an anchor is a low-quality version of it"),
            );
            continue;
        }
        if tests.contains(id.as_str()) {
            cx.err(
                key,
                format!("{id:?} is also a test condition: an anchor is rated as an anchor only"),
            );
            continue;
        }
        let Some(r) = m.reference_of(&s.clip) else {
            cx.err(
                key,
                format!(
                    "clip {:?} of {id:?} has no reference in the manifest",
                    s.clip
                ),
            );
            continue;
        };
        if !screens.iter().any(|(sr, _)| *sr == r.id) {
            cx.err(
                key,
                format!(
                    "clip {:?} of {id:?} has no test condition in this study",
                    s.clip
                ),
            );
            continue;
        }
        let anchor = Condition {
            stimulus: s.id.clone(),
            reference: r.id.clone(),
        };
        if let Some(before) = by_reference.insert(r.id.clone(), anchor) {
            cx.err(
                key,
                format!(
                    "clip {:?} has two anchors ({:?} and {id:?}): give one per clip",
                    s.clip, before.stimulus
                ),
            );
        }
    }
    by_reference
}
