//! DSCQS rows: a reference and a test score, the pair for DMOS and the test for MOS.

use super::MethodAnalysis;
use crate::descriptive::Rating;
use crate::dmos::DscqsPair;
use crate::error::AnalysisError;
use crate::from_results::{Inputs, Row, bad, check_scale};

/// Double-stimulus continuous quality scale.
pub(super) struct Dscqs;

impl MethodAnalysis for Dscqs {
    fn add(&self, row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError> {
        let Row {
            record,
            path,
            index,
            subject,
            scale,
        } = *row;
        let Inputs { stimuli, data, .. } = into;
        let reference_score = record
            .outcome
            .score_reference
            .ok_or_else(|| bad(path, index, "score_reference", "missing"))?;
        let test_score = record
            .outcome
            .score_test
            .ok_or_else(|| bad(path, index, "score_test", "missing"))?;
        check_scale(path, index, "score_reference", reference_score, scale)?;
        check_scale(path, index, "score_test", test_score, scale)?;
        let condition = stimuli.id(&record.trial.stimulus);
        data.dscqs.push(DscqsPair {
            subject,
            condition,
            reference_score,
            test_score,
        });
        // The absolute test ratings also give a MOS table, screening and repeats.
        data.ratings.push(Rating {
            subject,
            condition,
            score: test_score,
        });
        Ok(())
    }
}
