//! One rating per row: MOS, ACR (ACR-HR with hidden references) and DCR; a MUSHRA row is
//! added the same way (`super::mushra`).

use protocols::Answer;

use super::MethodAnalysis;
use crate::descriptive::Rating;
use crate::error::AnalysisError;
use crate::from_results::{Inputs, Row, bad, check_scale};

/// A method whose rows hold one rating each.
pub(super) struct Ratings {
    /// MOS and ACR: a test's DMOS is against its clip's hidden reference where one was rated.
    pub(super) hidden_reference_dmos: bool,
}

impl MethodAnalysis for Ratings {
    fn add(&self, row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError> {
        add_rating(row, into)
    }

    fn dmos_against_hidden_reference(&self) -> bool {
        self.hidden_reference_dmos
    }
}

/// Adds a row's one rating.
pub(super) fn add_rating(row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError> {
    let Row {
        record,
        path,
        index,
        subject,
        scale,
    } = *row;
    let Inputs { stimuli, data, .. } = into;
    let Answer::Rating(score) = record.response.answer else {
        return Err(bad(
            path,
            index,
            "response",
            format!("a {} trial needs one rating", record.protocol),
        ));
    };
    check_scale(path, index, "score", score, scale)?;
    let condition = stimuli.id(&record.trial.stimulus);
    data.ratings.push(Rating {
        subject,
        condition,
        score,
    });
    Ok(())
}
