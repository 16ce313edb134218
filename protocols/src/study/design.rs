//! `[design]`: counterbalancing of the test conditions' order (a balanced Latin square),
//! catch trials with their exclusion rule, and between-subject groups with quotas.

use toml::{Table, Value};

use super::check::{Ctx, join};
use super::crowdsourcing::parse_gold;
use super::{
    Condition, ConditionOrder, CrowdsourcingSettings, DesignSettings, GoldTrial, SubjectGroup,
};
use crate::methods::Method;
use crate::record::Protocol;

const D: &str = "design";

/// `[design]`; its catch trials (`catch`, `max_catch_failures`) go into `crowd`, the one list
/// of catch trials every runner and `study report` use (`[crowdsourcing] gold` is their older
/// name; a file may give them in one place).
pub(super) fn parse_design(
    t: &Table,
    protocol: Option<Protocol>,
    conditions: &[Condition],
    crowd: &mut CrowdsourcingSettings,
    cx: &mut Ctx,
) -> DesignSettings {
    cx.known(t, D, &["order", "catch", "max_catch_failures", "groups"]);
    let catch = parse_gold(t, D, "catch", protocol, conditions, cx);
    let max = cx.uint(t, D, "max_catch_failures", 1 << 20);
    if t.contains_key("catch") && !crowd.gold.is_empty() {
        cx.err(
            "design.catch",
            "catch trials are given twice: keep [[design.catch]] (for window, simulated and \
             browser sessions alike) and remove [[crowdsourcing.gold]], its older name",
        );
    } else if !catch.is_empty() {
        crowd.gold = catch;
    }
    if let Some(m) = max {
        if crowd.max_gold_failures > 0 {
            cx.err(
                "design.max_catch_failures",
                "given twice: keep it and remove [crowdsourcing] max_gold_failures, its older \
                 name",
            );
        }
        crowd.max_gold_failures = m;
    }
    let order = cx
        .pick(
            t,
            D,
            "order",
            &[
                ("random", ConditionOrder::Random),
                ("latin_square", ConditionOrder::LatinSquare),
            ],
        )
        .unwrap_or(ConditionOrder::Random);
    let method = protocol.map(crate::methods::of);
    let adaptive = method.is_some_and(Method::adaptive);
    if order == ConditionOrder::LatinSquare && adaptive {
        cx.err(
            "design.order",
            "a staircase decides each trial from the answers; a Latin square orders the \
             conditions of a rated study (mos, dscqs)",
        );
    }
    if order == ConditionOrder::LatinSquare
        && let Some(g) = crowd.groups
    {
        // A pair comparison's square orders its pairs, a MUSHRA study's its screens.
        let items = method.map_or(conditions.len(), |m| m.ordered_items(conditions));
        let rows = crate::design::williams_rows(items);
        if !(g as usize).is_multiple_of(rows) {
            cx.err(
                "crowdsourcing.groups",
                format!(
                    "{g} plan groups do not complete the Latin square's {rows} rows (subject \
                     index k takes row k mod {rows}): use a multiple of {rows}"
                ),
            );
        }
    }
    let groups = parse_groups(t, protocol, conditions, &crowd.gold, cx);
    DesignSettings { order, groups }
}

/// Longest group name.
const MAX_GROUP_NAME: usize = 32;
/// Most groups a study may declare.
const MAX_GROUPS: usize = 64;

/// `[[design.groups]]`: between-subject groups of a rated study. Each names its test
/// conditions (one of the study's, once each); every condition is in some group (groups may
/// share one, e.g. an anchor) or is a catch trial, which every session gets; a group's
/// `quota` is at least 1.
fn parse_groups(
    t: &Table,
    protocol: Option<Protocol>,
    conditions: &[Condition],
    catch: &[GoldTrial],
    cx: &mut Ctx,
) -> Vec<SubjectGroup> {
    const K: &str = "design.groups";
    let Some(v) = t.get("groups") else {
        return Vec::new();
    };
    let Value::Array(items) = v else {
        cx.wrong(D, "groups", "an array of tables ([[design.groups]])", v);
        return Vec::new();
    };
    if protocol.is_some_and(|p| crate::methods::of(p).adaptive()) {
        cx.err(
            K,
            "between-subject groups divide a rated study's conditions (mos, dscqs, acr, dcr); \
             a staircase study's tracks are every subject's",
        );
        return Vec::new();
    }
    if items.len() > MAX_GROUPS {
        cx.err(K, format!("{} groups; at most {MAX_GROUPS}", items.len()));
        return Vec::new();
    }
    let mut out: Vec<SubjectGroup> = Vec::new();
    for (i, item) in items.iter().enumerate() {
        if let Some(g) = parse_group(item, &format!("{K}[{i}]"), &out, conditions, cx) {
            out.push(g);
        }
    }
    if !out.is_empty() && out.len() == items.len() {
        for c in conditions {
            // A catch trial is every session's.
            let caught = catch.iter().any(|g| g.stimulus == c.stimulus);
            if !caught && !out.iter().any(|g| g.stimuli.contains(&c.stimulus)) {
                cx.err(
                    K,
                    format!(
                        "condition {:?} is in no group, so no session would show it: add it to \
                         a group or remove it from [conditions]",
                        c.stimulus
                    ),
                );
            }
        }
    }
    out
}

/// One `[[design.groups]]` table at `path`, checked against the groups before it (`before`).
fn parse_group(
    item: &Value,
    path: &str,
    before: &[SubjectGroup],
    conditions: &[Condition],
    cx: &mut Ctx,
) -> Option<SubjectGroup> {
    let Value::Table(g) = item else {
        cx.err(
            path,
            "expected a table with name, stimuli and (optionally) quota",
        );
        return None;
    };
    cx.known(g, path, &["name", "stimuli", "quota"]);
    let name = cx.string(g, path, "name");
    let stimuli = cx.strings(g, path, "stimuli");
    let quota = cx.uint(g, path, "quota", 1 << 24);
    if quota == Some(0) {
        cx.err(join(path, "quota"), "must be at least 1");
    }
    let Some(name) = name else {
        if !g.contains_key("name") {
            cx.err(join(path, "name"), "required");
        }
        return None;
    };
    if name.is_empty()
        || name.len() > MAX_GROUP_NAME
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        cx.err(
            join(path, "name"),
            format!("{name:?}: use 1-{MAX_GROUP_NAME} letters, digits, '-' or '_'"),
        );
    }
    if before.iter().any(|o| o.name == name) {
        cx.err(join(path, "name"), format!("{name:?} names two groups"));
    }
    let Some(stimuli) = stimuli else {
        if !g.contains_key("stimuli") {
            cx.err(
                join(path, "stimuli"),
                "required: the group's test conditions",
            );
        }
        return None;
    };
    if stimuli.is_empty() {
        cx.err(
            join(path, "stimuli"),
            "a group needs at least one condition",
        );
    }
    for (k, s) in stimuli.iter().enumerate() {
        if !conditions.iter().any(|c| &c.stimulus == s) {
            cx.err(
                join(path, "stimuli"),
                format!("{s:?} is not one of the study's conditions ([conditions])"),
            );
        }
        if stimuli[..k].contains(s) {
            cx.err(join(path, "stimuli"), format!("{s:?} is listed twice"));
        }
    }
    Some(SubjectGroup {
        name,
        stimuli,
        quota: quota.filter(|q| *q > 0),
    })
}
