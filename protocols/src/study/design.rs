//! `[design]`: counterbalancing of the test conditions' order (a balanced Latin square), and
//! catch trials with their exclusion rule.

use toml::Table;

use super::check::Ctx;
use super::crowdsourcing::parse_gold;
use super::{Condition, ConditionOrder, CrowdsourcingSettings, DesignSettings};
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
    cx.known(t, D, &["order", "catch", "max_catch_failures"]);
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
    if order == ConditionOrder::LatinSquare && protocol == Some(Protocol::Staircase) {
        cx.err(
            "design.order",
            "a staircase decides each trial from the answers; a Latin square orders the \
             conditions of a rated study (mos, dscqs)",
        );
    }
    if order == ConditionOrder::LatinSquare
        && let Some(g) = crowd.groups
    {
        // A pair comparison's square orders its pairs.
        let items = if protocol == Some(Protocol::PairComparison) {
            super::pair_count(conditions)
        } else {
            conditions.len()
        };
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
    DesignSettings { order }
}
