//! Each study method's analysis, found by [`of`] as `protocols::methods::of` finds its
//! running code: how its trial rows become the analysis's inputs, and what of the report
//! depends on it. One module per method (the rating methods share one); nothing else in
//! this crate matches on a protocol's name.

mod ccr;
mod dscqs;
mod mushra;
mod pair_comparison;
mod ratings;
mod staircase;

use protocols::Protocol;
use protocols::study::ReferencePlacement;

use crate::error::AnalysisError;
use crate::from_results::{Inputs, Row};
use crate::report::Report;
use crate::study::{ReportOptions, StudyData};

/// A method's analysis.
pub(crate) trait MethodAnalysis: Sync {
    /// Adds one test trial's row (familiarization rows never come here) to the inputs.
    ///
    /// # Errors
    /// A row whose answer or outcome does not fit the method, or a score off the scale,
    /// named by file, line and column.
    fn add(&self, row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError>;

    /// Whether a rated test whose clip's reference was rated as a condition too gets its
    /// DMOS against that hidden reference (P.910 ACR-HR; MOS with hidden references).
    fn dmos_against_hidden_reference(&self) -> bool {
        false
    }

    /// Where the reference (or what stands for it) was placed, in the method section's
    /// words.
    fn placement(&self, placement: ReferencePlacement) -> String {
        placement_line(placement, "reference position")
    }

    /// Why BT.500 observer screening does not apply to its answers (`None`: it does).
    fn no_screening(&self) -> Option<&'static str> {
        None
    }

    /// Adds the report sections only this method has, from the inputs its rows gave
    /// ([`MethodAnalysis::add`]); the sections every method shares come from
    /// [`crate::StudyAnalysis::to_report`]. None by default.
    fn report_sections(&self, _report: &mut Report, _data: &StudyData, _options: &ReportOptions) {}
}

/// The analysis of `protocol`'s method: the one place in this crate a protocol's name picks
/// its code.
pub(crate) fn of(protocol: Protocol) -> &'static dyn MethodAnalysis {
    match protocol {
        Protocol::Mos | Protocol::Acr => &ratings::Ratings {
            hidden_reference_dmos: true,
        },
        Protocol::Dcr => &ratings::Ratings {
            hidden_reference_dmos: false,
        },
        Protocol::Mushra => &mushra::Mushra,
        Protocol::Dscqs => &dscqs::Dscqs,
        Protocol::PairComparison => &pair_comparison::PairComparison,
        Protocol::Staircase => &staircase::Staircase,
        Protocol::Ccr => &ccr::Ccr,
    }
}

/// A placement in the method section's words; `what` names what is placed.
fn placement_line(placement: ReferencePlacement, what: &str) -> String {
    match placement {
        ReferencePlacement::Fixed(p) => format!("reference always {p}"),
        ReferencePlacement::Random => format!("{what} random per trial"),
        ReferencePlacement::Balanced => {
            format!("{what} counterbalanced within and across subjects")
        }
    }
}
