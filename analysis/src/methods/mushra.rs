//! MUSHRA rows: each rates one pane of a screen (a test condition, the hidden reference or
//! the anchor); the post-screening and per-stimulus statistics are `crate::mushra`'s.

use protocols::study::ReferencePlacement;

use super::MethodAnalysis;
use super::ratings::add_rating;
use crate::error::AnalysisError;
use crate::from_results::{Inputs, Row};

/// MUSHRA screens.
pub(super) struct Mushra;

impl MethodAnalysis for Mushra {
    fn add(&self, row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError> {
        add_rating(row, into)
    }

    /// The labelled reference has a pane of its own; the rated stimuli are shuffled.
    fn placement(&self, _placement: ReferencePlacement) -> String {
        "on each screen the tests, the hidden reference and the anchor in lettered panes \
         shuffled per screen and subject"
            .to_string()
    }
}
