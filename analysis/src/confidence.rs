//! The confidence level of an interval, checked once when it is made.

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

use crate::error::AnalysisError;

/// A confidence level strictly between 0 and 1 (0.95 for a 95 % interval).
///
/// Every statistic that reports an interval takes one of these instead of a bare `f64`, so the
/// range is checked once, where the level enters the program (a CLI flag, an options struct),
/// and no function further down can be handed 1.5 or NaN. It serialises as the plain number.
///
/// ```
/// use analysis::Confidence;
/// let c = Confidence::new(0.9)?;
/// assert_eq!(c.level(), 0.9);
/// assert_eq!(Confidence::default().level(), 0.95);
/// assert!(Confidence::new(1.0).is_err());
/// assert_eq!("0.99".parse::<Confidence>()?.level(), 0.99);
/// # Ok::<(), analysis::AnalysisError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Serialize)]
#[serde(transparent)]
pub struct Confidence(f64);

impl Confidence {
    /// The level `level`, a fraction in (0, 1).
    ///
    /// # Errors
    /// [`AnalysisError::InvalidParameter`] (named `confidence`) unless 0 < `level` < 1; NaN is
    /// rejected too.
    pub fn new(level: f64) -> Result<Self, AnalysisError> {
        if level > 0.0 && level < 1.0 {
            Ok(Self(level))
        } else {
            Err(AnalysisError::InvalidParameter {
                name: "confidence",
                value: level,
                reason: "must lie strictly between 0 and 1",
            })
        }
    }

    /// The level as a fraction in (0, 1), e.g. 0.95.
    pub fn level(self) -> f64 {
        self.0
    }

    /// α = 1 − level, the probability mass outside a two-sided interval (split α/2 per tail).
    pub fn alpha(self) -> f64 {
        1.0 - self.0
    }

    /// The level in percent, e.g. 95 for 0.95, as the report prints it.
    pub fn percent(self) -> f64 {
        self.0 * 100.0
    }
}

/// 95 %, the level of the seeds' tables and of BT.500's δ = 1.96·S/√N.
impl Default for Confidence {
    fn default() -> Self {
        Self(0.95)
    }
}

/// The level as a plain number (`0.95`), which [`FromStr`] reads back.
impl fmt::Display for Confidence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

/// Parses a level written as a fraction (`0.95`), for command-line flags.
impl FromStr for Confidence {
    type Err = AnalysisError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let level: f64 = text.parse().map_err(|_| AnalysisError::NotANumber {
            name: "confidence",
            text: text.to_owned(),
        })?;
        Self::new(level)
    }
}
