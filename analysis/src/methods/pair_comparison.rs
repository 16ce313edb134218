//! Pair comparison rows: each the choice it logs (a preference, or no preference: a tie),
//! for the Bradley-Terry (Davidson's, with ties) scale values.

use std::path::Path;

use protocols::study::ReferencePlacement;
use protocols::{Answer, Position, TrialRecord};

use super::MethodAnalysis;
use crate::bradley_terry::PairChoice;
use crate::error::AnalysisError;
use crate::from_results::{Inputs, Interner, Row, bad};

/// Pair comparison.
pub(super) struct PairComparison;

impl MethodAnalysis for PairComparison {
    fn add(&self, row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError> {
        let choice = pair_choice(row.record, row.path, row.index, row.subject, into.stimuli)?;
        into.data.pair_choices.push(choice);
        Ok(())
    }

    fn placement(&self, placement: ReferencePlacement) -> String {
        super::placement_line(placement, "the side of each pair's versions")
    }

    fn no_screening(&self) -> Option<&'static str> {
        Some("pair comparison choices; BT.500 screening applies to ratings")
    }
}

/// A pair comparison row as the choice it logs: the `reference` column holds the pair's
/// other test stimulus, shown at the reference position; "neither" is a tie of the two.
fn pair_choice(
    record: &TrialRecord,
    path: &Path,
    index: usize,
    subject: u32,
    stimuli: &mut Interner,
) -> Result<PairChoice, AnalysisError> {
    let t = &record.trial;
    let choice = match record.response.answer {
        Answer::Choice(p) if p.fits(t.arrangement) || p == Position::Neither => p,
        other => {
            return Err(bad(
                path,
                index,
                "response",
                format!(
                    "a pair_comparison trial needs a position of arrangement {} or \"neither\", \
                     got {other:?}",
                    t.arrangement
                ),
            ));
        }
    };
    let (a, b) = (stimuli.id(&t.stimulus), stimuli.id(&t.reference));
    let (winner, loser) = if choice == t.reference_position {
        (b, a)
    } else {
        (a, b)
    };
    Ok(PairChoice {
        subject,
        winner,
        loser,
        tie: choice == Position::Neither,
    })
}
