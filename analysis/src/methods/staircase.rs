//! 2AFC staircase rows: each track's steps (level, correct, reversal) and the trials of the
//! psychometric fit.

use super::MethodAnalysis;
use crate::error::AnalysisError;
use crate::from_results::{Inputs, Row, bad};
use crate::psychometric::TwoAfcTrial;
use crate::staircase::{StaircaseStep, StaircaseTrack};

/// Two-alternative forced choice on staircases.
pub(super) struct Staircase;

impl MethodAnalysis for Staircase {
    fn add(&self, row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError> {
        let Row {
            record,
            path,
            index,
            subject,
            ..
        } = *row;
        let Inputs { data, tracks, .. } = into;
        let staircase = record
            .trial
            .staircase
            .ok_or_else(|| bad(path, index, "staircase", "missing staircase index"))?;
        // Logs written before the exact level grid hold accumulated levels
        // (0.003999999999999993 beside 0.004): every table keys them on the grid.
        let level = record
            .trial
            .level
            .map(protocols::staircase::canonical_level)
            .ok_or_else(|| bad(path, index, "level", "missing staircase level"))?;
        if !level.is_finite() {
            return Err(bad(
                path,
                index,
                "level",
                format!("level {level} is not finite"),
            ));
        }
        let correct = record
            .outcome
            .correct
            .ok_or_else(|| bad(path, index, "correct", "missing"))?;
        // A QUEST+ or Psi trial logs no reversal flag (an up-down staircase's always
        // does).
        let track = tracks
            .entry((subject, record.session, staircase))
            .or_insert_with(|| StaircaseTrack {
                subject,
                label: record.trial.condition.clone(),
                steps: Vec::new(),
                bayesian: record.outcome.reversal.is_none(),
                logged_threshold: None,
            });
        track.bayesian &= record.outcome.reversal.is_none();
        track.steps.push(StaircaseStep {
            level,
            correct,
            reversal: record.outcome.reversal.unwrap_or(false),
        });
        data.two_afc.push(TwoAfcTrial { level, correct });
        Ok(())
    }

    fn no_screening(&self) -> Option<&'static str> {
        Some("2AFC thresholds; BT.500 screening applies to ratings")
    }
}
