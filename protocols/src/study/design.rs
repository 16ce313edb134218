//! `[design]`: counterbalancing of the test conditions' order (a balanced Latin square).

use toml::Table;

use super::check::Ctx;
use super::{ConditionOrder, DesignSettings};
use crate::record::Protocol;

const D: &str = "design";

pub(super) fn parse_design(t: &Table, protocol: Option<Protocol>, cx: &mut Ctx) -> DesignSettings {
    cx.known(t, D, &["order"]);
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
    DesignSettings { order }
}
