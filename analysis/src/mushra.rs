//! MUSHRA-style studies (ITU-R BS.1534-3, adapted to motion): the post-screening of the
//! assessors and each condition's mean with its confidence interval over the assessors kept.
//!
//! Post-screening (BS.1534-3 §4.1.2): an assessor who rates the hidden reference below
//! `reference_below` (90) on more than `max_fraction` (15 %) of the test items (here the
//! screens, one per clip) is excluded. The anchor rule, which BS.1534-3 leaves to the
//! experimenter (assessors who rate the anchor above 90 on more than 15 % of the items *may*
//! be excluded), is applied as the study file says: listed only, or excluded too. The
//! conditions (every test stimulus, each clip's hidden reference and its anchor) are then
//! summarised over the assessors kept: mean, sample SD and the Student-t interval, each
//! assessor rating each stimulus once.

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

use crate::confidence::Confidence;
use crate::descriptive::{CiMethod, Rating, Summary, summarize};
use crate::error::AnalysisError;
use crate::findings::ConditionInfo;
use crate::report::Report;
use crate::tables::{Table, fmt_opt};

/// The post-screening rules of a study (`[mushra]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Rules {
    /// A hidden reference rated below this is missed.
    pub reference_below: f64,
    /// An anchor rated above this is rated too high.
    pub anchor_above: f64,
    /// The largest share of screens an assessor may miss (or rate the anchor high) on.
    pub max_fraction: f64,
    /// Whether rating the anchor too high excludes (else it is only listed).
    pub exclude_on_anchor: bool,
}

/// What a rated stimulus is on its screen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub enum Role {
    /// The clip's reference, unlabelled among the panes.
    HiddenReference,
    /// A test condition.
    Test,
    /// The clip's low anchor.
    Anchor,
}

impl Role {
    /// How tables name it.
    pub fn label(self) -> &'static str {
        match self {
            Role::HiddenReference => "hidden reference",
            Role::Test => "test",
            Role::Anchor => "anchor",
        }
    }
}

/// One assessor's post-screening.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Assessor {
    /// Subject id (as in the ratings).
    pub subject: u32,
    /// Screens rated (hidden references rated).
    pub screens: usize,
    /// Screens whose hidden reference was rated below the limit.
    pub reference_missed: usize,
    /// Screens whose anchor was rated above the limit.
    pub anchor_high: usize,
    /// Misses the hidden reference on more than the allowed share.
    pub fails_reference: bool,
    /// Rates the anchor high on more than the allowed share.
    pub fails_anchor: bool,
    /// Left out of the condition table.
    pub excluded: bool,
}

/// One condition over the assessors kept.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConditionRow {
    /// Condition id.
    pub condition: u32,
    /// Its role.
    pub role: Role,
    /// Mean, SD and intervals; `None` when no assessor kept rated it.
    pub summary: Option<Summary>,
}

/// The MUSHRA statistics of a study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MushraAnalysis {
    /// Every assessor, in subject order.
    pub assessors: Vec<Assessor>,
    /// Every rated stimulus, in table order (clip, role, stimulus).
    pub conditions: Vec<ConditionRow>,
}

/// The role of condition `c`: a reference is the hidden reference (`compression_ratio`
/// `None`), an id among `anchors` the anchor, anything else a test.
fn role_of(info: Option<&ConditionInfo>, c: u32, anchors: &BTreeSet<u32>) -> Role {
    if anchors.contains(&c) {
        Role::Anchor
    } else if info.is_some_and(|i| i.compression_ratio.is_none()) {
        Role::HiddenReference
    } else {
        Role::Test
    }
}

/// Post-screens the assessors of `ratings` and summarises every condition over those kept.
/// `names` are the stimulus ids by condition id (table order within a clip).
///
/// # Errors
/// Non-finite ratings ([`AnalysisError::NonFinite`]).
pub fn analyze(
    ratings: &[Rating],
    conditions: &[ConditionInfo],
    names: &[String],
    anchors: &BTreeSet<u32>,
    rules: &Rules,
    confidence: Confidence,
) -> Result<MushraAnalysis, AnalysisError> {
    let info: BTreeMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
    let role = |c: u32| role_of(info.get(&c).copied(), c, anchors);
    let mut per_subject: BTreeMap<u32, (usize, usize, usize)> = BTreeMap::new();
    for r in ratings {
        let e = per_subject.entry(r.subject).or_default();
        match role(r.condition) {
            Role::HiddenReference => {
                e.0 += 1;
                e.1 += usize::from(r.score < rules.reference_below);
            }
            Role::Anchor => e.2 += usize::from(r.score > rules.anchor_above),
            Role::Test => {}
        }
    }
    let share = |k: usize, n: usize| n > 0 && k as f64 / n as f64 > rules.max_fraction;
    let assessors: Vec<Assessor> = per_subject
        .into_iter()
        .map(|(subject, (screens, missed, high))| {
            let fails_reference = share(missed, screens);
            let fails_anchor = share(high, screens);
            Assessor {
                subject,
                screens,
                reference_missed: missed,
                anchor_high: high,
                fails_reference,
                fails_anchor,
                excluded: fails_reference || (rules.exclude_on_anchor && fails_anchor),
            }
        })
        .collect();
    let excluded: BTreeSet<u32> = assessors
        .iter()
        .filter(|a| a.excluded)
        .map(|a| a.subject)
        .collect();
    let mut values: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for r in ratings {
        let v = values.entry(r.condition).or_default();
        if !excluded.contains(&r.subject) {
            v.push(r.score);
        }
    }
    let mut rows = Vec::with_capacity(values.len());
    for (condition, v) in values {
        rows.push(ConditionRow {
            condition,
            role: role(condition),
            summary: if v.is_empty() {
                None
            } else {
                Some(summarize(&v, confidence)?)
            },
        });
    }
    let key = |r: &ConditionRow| {
        (
            info.get(&r.condition).map(|i| i.clip.clone()),
            r.role,
            names.get(r.condition as usize).cloned(),
        )
    };
    rows.sort_by_key(key);
    Ok(MushraAnalysis {
        assessors,
        conditions: rows,
    })
}

impl MushraAnalysis {
    /// The "MUSHRA" section: the rules, the post-screening of every assessor, and the
    /// condition table over the assessors kept.
    pub fn section(
        &self,
        report: &mut Report,
        names: &[String],
        conditions: &[ConditionInfo],
        subject_name: &dyn Fn(u32) -> String,
        rules: &Rules,
    ) {
        let info: BTreeMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
        let excluded: Vec<String> = self
            .assessors
            .iter()
            .filter(|a| a.excluded)
            .map(|a| crate::tables::md_escape(&subject_name(a.subject)))
            .collect();
        let listed: Vec<String> = self
            .assessors
            .iter()
            .filter(|a| a.fails_anchor && !a.excluded)
            .map(|a| crate::tables::md_escape(&subject_name(a.subject)))
            .collect();
        let pct = 100.0 * rules.max_fraction;
        let s = report.section("MUSHRA");
        s.text(format!(
            "Post-screening (ITU-R BS.1534-3 §4.1.2): an assessor who rates the hidden reference \
             below {} on more than {pct} % of the screens (one screen per clip) is excluded. \
             Anchor rule, as the study file sets it: an assessor who rates the anchor above {} \
             on more than {pct} % of the screens is {}. Excluded: {}. Listed for the anchor \
             (kept): {}.",
            rules.reference_below,
            rules.anchor_above,
            if rules.exclude_on_anchor {
                "excluded"
            } else {
                "listed and kept (BS.1534-3: such assessors may be excluded)"
            },
            if excluded.is_empty() {
                "none".to_owned()
            } else {
                excluded.join(", ")
            },
            if listed.is_empty() {
                "none".to_owned()
            } else {
                listed.join(", ")
            },
        ));
        s.table(self.screening_table(subject_name));
        s.text(format!(
            "Each stimulus over the {} assessors kept (each rates each stimulus once): mean, \
             sample SD and the {:.0} % Student-t confidence interval; the hidden reference and \
             the anchor of each clip shown with the tests.",
            self.assessors.iter().filter(|a| !a.excluded).count(),
            self.conditions
                .iter()
                .find_map(|c| c.summary.map(|s| s.confidence.percent()))
                .unwrap_or(95.0)
        ));
        s.table(self.condition_table(names, &info));
    }

    /// `tables/mushra_screening.csv`: every assessor's post-screening.
    fn screening_table(&self, subject_name: &dyn Fn(u32) -> String) -> Table {
        Table {
            name: "mushra_screening".into(),
            caption: "BS.1534-3 post-screening of the assessors".into(),
            columns: [
                "Subject",
                "Screens",
                "Hidden reference low",
                "Anchor high",
                "Excluded",
            ]
            .map(String::from)
            .to_vec(),
            rows: self
                .assessors
                .iter()
                .map(|a| {
                    vec![
                        subject_name(a.subject),
                        a.screens.to_string(),
                        a.reference_missed.to_string(),
                        a.anchor_high.to_string(),
                        match (a.excluded, a.fails_reference, a.fails_anchor) {
                            (true, true, _) => "yes: hidden reference",
                            (true, false, _) => "yes: anchor",
                            (false, _, true) => "no (anchor listed)",
                            (false, _, false) => "no",
                        }
                        .to_owned(),
                    ]
                })
                .collect(),
        }
    }

    /// `tables/mushra.csv`: every stimulus over the assessors kept.
    fn condition_table(&self, names: &[String], info: &BTreeMap<u32, &ConditionInfo>) -> Table {
        Table {
            name: "mushra".into(),
            caption: "MUSHRA scores per stimulus (assessors kept)".into(),
            columns: [
                "Stimulus",
                "Clip",
                "Role",
                "n",
                "Mean",
                "SD",
                "CI ± (t)",
                "Lower",
                "Upper",
            ]
            .map(String::from)
            .to_vec(),
            rows: self
                .conditions
                .iter()
                .map(|c| {
                    let ci = c.summary.and_then(|s| s.ci(CiMethod::StudentT));
                    vec![
                        names
                            .get(c.condition as usize)
                            .cloned()
                            .unwrap_or_else(|| format!("condition {}", c.condition)),
                        info.get(&c.condition)
                            .map_or_else(String::new, |i| i.clip.clone()),
                        c.role.label().to_owned(),
                        c.summary.map_or(0, |s| s.n).to_string(),
                        fmt_opt(c.summary.map(|s| s.mean), 3),
                        fmt_opt(c.summary.and_then(|s| s.sd), 3),
                        fmt_opt(ci.map(|c| c.half_width), 3),
                        fmt_opt(ci.map(|c| c.lower), 3),
                        fmt_opt(ci.map(|c| c.upper), 3),
                    ]
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn info(id: u32, clip: &str, cr: Option<f64>) -> ConditionInfo {
        ConditionInfo {
            id,
            codec: if cr.is_some() { "c" } else { "reference" }.into(),
            params: BTreeMap::new(),
            clip: clip.into(),
            compression_ratio: cr,
        }
    }

    /// BS.1534-3's "more than 15 %" is strict: 3 missed hidden references of 20 screens
    /// (exactly 15 %) keep an assessor, 4 exclude; the anchor only lists unless asked to
    /// exclude; the excluded assessor's ratings leave every mean.
    #[test]
    fn post_screening_is_strict_at_the_share_and_the_anchor_rule_is_as_set() {
        // 20 clips: condition 3k = hidden reference, 3k+1 = test, 3k+2 = anchor.
        let mut conditions = Vec::new();
        let mut names = Vec::new();
        for k in 0..20 {
            conditions.push(info(3 * k, &format!("c{k:02}"), None));
            conditions.push(info(3 * k + 1, &format!("c{k:02}"), Some(10.0)));
            conditions.push(info(3 * k + 2, &format!("c{k:02}"), Some(90.0)));
            names.extend([format!("r{k}"), format!("t{k}"), format!("a{k}")]);
        }
        let anchors: BTreeSet<u32> = (0..20).map(|k| 3 * k + 2).collect();
        let mut ratings = Vec::new();
        for subject in 0..3_u32 {
            for k in 0..20_u32 {
                // Subject 0 misses 3 hidden references, subject 1 misses 4; subject 2 rates
                // 4 anchors at 95.
                let reference = if k < 3 + subject.min(1) && subject < 2 {
                    80.0
                } else {
                    100.0
                };
                let anchor = if subject == 2 && k < 4 { 95.0 } else { 10.0 };
                ratings.push(Rating {
                    subject,
                    condition: 3 * k,
                    score: reference,
                });
                ratings.push(Rating {
                    subject,
                    condition: 3 * k + 1,
                    score: f64::from(50 + subject),
                });
                ratings.push(Rating {
                    subject,
                    condition: 3 * k + 2,
                    score: anchor,
                });
            }
        }
        let mut rules = Rules {
            reference_below: 90.0,
            anchor_above: 90.0,
            max_fraction: 0.15,
            exclude_on_anchor: false,
        };
        let run = |rules: &Rules| {
            analyze(
                &ratings,
                &conditions,
                &names,
                &anchors,
                rules,
                Confidence::default(),
            )
            .unwrap()
        };
        let a = run(&rules);
        let got: Vec<(usize, usize, bool, bool, bool)> = a
            .assessors
            .iter()
            .map(|x| {
                (
                    x.reference_missed,
                    x.anchor_high,
                    x.fails_reference,
                    x.fails_anchor,
                    x.excluded,
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                (3, 0, false, false, false),
                (4, 0, true, false, true),
                (0, 4, false, true, false)
            ]
        );
        // The test of clip c00 over subjects 0 and 2: ratings 50 and 52.
        let t0 = a.conditions.iter().find(|c| c.condition == 1).unwrap();
        assert_eq!(t0.role, Role::Test);
        let s = t0.summary.unwrap();
        assert_eq!((s.n, s.mean), (2, 51.0));
        // Table order within a clip: hidden reference, test, anchor.
        let roles: Vec<Role> = a.conditions.iter().take(3).map(|c| c.role).collect();
        assert_eq!(roles, [Role::HiddenReference, Role::Test, Role::Anchor]);
        rules.exclude_on_anchor = true;
        let b = run(&rules);
        assert!(b.assessors[2].excluded);
        let s = b
            .conditions
            .iter()
            .find(|c| c.condition == 1)
            .unwrap()
            .summary
            .unwrap();
        assert_eq!((s.n, s.mean), (1, 50.0));
    }
}
