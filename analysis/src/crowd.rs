//! Crowd scenes (thesis 6.5): which rated conditions are crowd scenes, the ratio of the
//! characters whose ratio the study varies (the back characters), every character's ratio and
//! distance, and the report's table and figure of MOS against that ratio with one curve per
//! distance level (thesis Fig. 6.9).

use std::collections::{BTreeMap, BTreeSet};

use protocols::manifest::{REFERENCE_CODEC, StimulusManifest};
use serde::Serialize;

use crate::descriptive::{CiMethod, ConditionStats, Summary};
use crate::dmos::DscqsPair;
use crate::plots::RateSeries;
use crate::tables::{Table, fmt_opt};

/// One character of a rated crowd scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrowdMember {
    /// Character name.
    pub name: String,
    /// Its group.
    pub group: String,
    /// Its distance from the camera, cm.
    pub distance_cm: f64,
    /// The compression ratio its stream reached.
    pub achieved_cr: f64,
}

/// A crowd scene rated as a condition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrowdCondition {
    /// Condition id (as in the ratings).
    pub condition: u32,
    /// Its distance level.
    pub level: String,
    /// How far the varied group stands on this level (the mean over its characters), cm; or
    /// the farthest character when no one group varies.
    pub distance_cm: f64,
    /// The x of its point: the varied group's target ratio, else the scene's ratio.
    pub x: f64,
    /// The scene's ratio (every character's raw size over their bytes).
    pub scene_cr: f64,
    /// Its characters, in the scene's order.
    pub characters: Vec<CrowdMember>,
}

/// The crowd scenes of a study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrowdDesign {
    /// The one group whose ratio differs between the rated scenes (thesis 6.5: the back
    /// characters); `None` when none or several do, and the x axis is the scene's ratio.
    pub varied: Option<String>,
    /// The rated scenes, by condition id.
    pub conditions: Vec<CrowdCondition>,
}

impl CrowdDesign {
    /// The crowd scenes among the rated stimuli (`(condition id, stimulus id)`), with their
    /// characters from `manifest`; `None` when no rated stimulus is a compressed crowd scene.
    pub fn from_manifest(
        rated: &[(u32, &str)],
        manifest: &StimulusManifest,
    ) -> Option<CrowdDesign> {
        let scenes: Vec<(u32, &protocols::manifest::Stimulus)> = rated
            .iter()
            .filter_map(|(id, s)| manifest.get(s).map(|st| (*id, st)))
            .filter(|(_, st)| st.scene.is_some() && st.codec != REFERENCE_CODEC)
            .collect();
        if scenes.is_empty() {
            return None;
        }
        // The target ratio of each group in each scene: the group whose ratio takes several
        // values is the one the study varies.
        let target = |stimulus: &str| manifest.get(stimulus).and_then(|m| m.target_cr);
        let mut per_group: BTreeMap<&str, BTreeSet<u64>> = BTreeMap::new();
        for (_, st) in &scenes {
            for c in st.scene.iter().flat_map(|s| &s.characters) {
                per_group
                    .entry(c.group.as_str())
                    .or_default()
                    .insert(target(&c.stimulus).map_or(u64::MAX, f64::to_bits));
            }
        }
        let varied: Vec<&str> = per_group
            .iter()
            .filter(|(_, v)| v.len() > 1)
            .map(|(g, _)| *g)
            .collect();
        let varied = match varied.as_slice() {
            [g] => Some((*g).to_owned()),
            _ => None,
        };
        let conditions = scenes
            .iter()
            .filter_map(|(id, st)| {
                let scene = st.scene.as_ref()?;
                let characters: Vec<CrowdMember> = scene
                    .characters
                    .iter()
                    .map(|c| CrowdMember {
                        name: c.name.clone(),
                        group: c.group.clone(),
                        distance_cm: c.distance_cm,
                        achieved_cr: manifest
                            .get(&c.stimulus)
                            .and_then(|m| m.achieved_cr)
                            .unwrap_or(f64::NAN),
                    })
                    .collect();
                let of_group: Vec<&protocols::manifest::SceneMember> = scene
                    .characters
                    .iter()
                    .filter(|c| varied.as_deref() == Some(c.group.as_str()))
                    .collect();
                let (x, distance_cm) = match of_group.first() {
                    Some(first) => (
                        target(&first.stimulus)?,
                        of_group.iter().map(|c| c.distance_cm).sum::<f64>() / of_group.len() as f64,
                    ),
                    None => (
                        st.achieved_cr?,
                        characters.iter().map(|c| c.distance_cm).fold(0.0, f64::max),
                    ),
                };
                Some(CrowdCondition {
                    condition: *id,
                    level: scene.level.clone(),
                    distance_cm,
                    x,
                    scene_cr: st.achieved_cr?,
                    characters,
                })
            })
            .collect();
        Some(CrowdDesign { varied, conditions })
    }

    /// The x axis' title.
    pub fn x_label(&self) -> String {
        match &self.varied {
            Some(g) => format!("Compression ratio of the {g} characters (x:1)"),
            None => "Compression ratio of the scene (x:1)".to_owned(),
        }
    }

    /// The levels, nearest first (by the distance of the varied group).
    fn levels(&self) -> Vec<(String, f64)> {
        let mut out: Vec<(String, f64)> = Vec::new();
        for c in &self.conditions {
            if !out.iter().any(|(l, _)| *l == c.level) {
                out.push((c.level.clone(), c.distance_cm));
            }
        }
        out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        out
    }

    /// A level's legend label: its name and how far the varied characters stand.
    fn level_label(&self, level: &str, distance_cm: f64) -> String {
        let who = self.varied.as_deref().unwrap_or("farthest");
        format!("{level} ({who} at {:.1} m)", distance_cm / 100.0)
    }

    /// MOS (`stats`, per condition) against the x of each scene, one curve per level, in one
    /// panel named `panel`: the points of the thesis's Fig. 6.9.
    pub fn series(
        &self,
        stats: &[ConditionStats],
        method: CiMethod,
        panel: &str,
    ) -> Vec<RateSeries> {
        let by_id: BTreeMap<u32, &Summary> =
            stats.iter().map(|s| (s.condition, &s.summary)).collect();
        self.levels()
            .into_iter()
            .map(|(level, d)| {
                let mut points: Vec<(f64, f64, f64, f64)> = self
                    .conditions
                    .iter()
                    .filter(|c| c.level == level)
                    .filter_map(|c| {
                        let s = by_id.get(&c.condition)?;
                        let ci = s.ci(method);
                        Some((
                            c.x,
                            s.mean,
                            ci.map_or(s.mean, |v| v.lower),
                            ci.map_or(s.mean, |v| v.upper),
                        ))
                    })
                    .collect();
                points.sort_by(|a, b| a.0.total_cmp(&b.0));
                RateSeries {
                    label: self.level_label(&level, d),
                    clip: panel.to_owned(),
                    points,
                }
            })
            .collect()
    }

    /// The table of every rated scene: level, the varied characters' distance, each
    /// character's ratio, the scene's, and the compressed scene's MOS, the reference's mean
    /// rating and the DMOS (DSCQS) with their intervals.
    pub fn table(
        &self,
        mos: &[ConditionStats],
        dmos: &[ConditionStats],
        pairs: &[DscqsPair],
        method: CiMethod,
    ) -> Table {
        let stat =
            |v: &[ConditionStats], id: u32| v.iter().find(|s| s.condition == id).map(|s| s.summary);
        let names: Vec<String> = self
            .conditions
            .first()
            .map(|c| c.characters.iter().map(|m| m.name.clone()).collect())
            .unwrap_or_default();
        let mut columns = vec![
            "Level".to_owned(),
            "Distance (m)".to_owned(),
            "x".to_owned(),
        ];
        columns.extend(names.iter().map(|n| format!("CR {n}")));
        columns.extend(
            [
                "Scene CR",
                "n",
                "MOS",
                "MOS CI ±",
                "Reference",
                "DMOS",
                "DMOS CI ±",
            ]
            .iter()
            .map(|s| (*s).to_owned()),
        );
        let order: Vec<String> = self.levels().into_iter().map(|(l, _)| l).collect();
        let mut rows: Vec<(usize, f64, Vec<String>)> = self
            .conditions
            .iter()
            .map(|c| {
                let m = stat(mos, c.condition);
                let d = stat(dmos, c.condition);
                let refs: Vec<f64> = pairs
                    .iter()
                    .filter(|p| p.condition == c.condition)
                    .map(|p| p.reference_score)
                    .collect();
                let reference =
                    (!refs.is_empty()).then(|| refs.iter().sum::<f64>() / refs.len() as f64);
                let mut cells = vec![
                    c.level.clone(),
                    format!("{:.1}", c.distance_cm / 100.0),
                    format!("{}", c.x),
                ];
                cells.extend(names.iter().map(|n| {
                    fmt_opt(
                        c.characters
                            .iter()
                            .find(|m| m.name == *n)
                            .map(|m| m.achieved_cr),
                        2,
                    )
                }));
                cells.extend([
                    format!("{:.2}", c.scene_cr),
                    m.as_ref()
                        .map_or_else(|| "0".to_owned(), |s| s.n.to_string()),
                    fmt_opt(m.as_ref().map(|s| s.mean), 3),
                    fmt_opt(
                        m.as_ref().and_then(|s| s.ci(method)).map(|c| c.half_width),
                        3,
                    ),
                    fmt_opt(reference, 3),
                    fmt_opt(d.as_ref().map(|s| s.mean), 3),
                    fmt_opt(
                        d.as_ref().and_then(|s| s.ci(method)).map(|c| c.half_width),
                        3,
                    ),
                ]);
                let rank = order
                    .iter()
                    .position(|l| *l == c.level)
                    .unwrap_or(usize::MAX);
                (rank, c.x, cells)
            })
            .collect();
        rows.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
        Table {
            name: "crowd".to_owned(),
            caption: format!(
                "Crowd scenes per distance level (thesis 6.5): the characters' compression \
                 ratios, the compressed scene's MOS, the reference's mean rating and the DMOS; x = {}",
                self.x_label()
            ),
            columns,
            rows: rows.into_iter().map(|(_, _, r)| r).collect(),
        }
    }
}
