//! The analysis crate's error type.

use std::path::PathBuf;

/// Everything that can go wrong while computing statistics or writing a report.
///
/// Statistics that are merely *undefined* for the data (the SD of one rating, a t-test on
/// zero variance) are not errors: they come back as `None` or [`crate::Undefined`]. Errors are
/// for inputs the caller must fix (a non-finite score, a bad parameter) and for I/O.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    /// A computation needs more values than it was given.
    #[error("{what}: need at least {needed} values, got {got}")]
    TooFew {
        /// What was being computed.
        what: &'static str,
        /// The minimum number of values.
        needed: usize,
        /// The number given.
        got: usize,
    },
    /// A value in the input is NaN or infinite.
    #[error("{what}: value #{index} is not finite ({value})")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Zero-based position in the input.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// A parameter is outside its documented range.
    #[error("parameter {name} = {value} is invalid: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// The value passed.
        value: f64,
        /// What the valid range is.
        reason: &'static str,
    },
    /// A parameter given as text (a command-line flag) is not a number.
    #[error("parameter {name} = {text:?} is not a number")]
    NotANumber {
        /// Parameter name.
        name: &'static str,
        /// The text given.
        text: String,
    },
    /// Two inputs that must pair up have different lengths.
    #[error("{what}: paired inputs differ in length ({left} vs {right})")]
    LengthMismatch {
        /// Which inputs.
        what: &'static str,
        /// Length of the first.
        left: usize,
        /// Length of the second.
        right: usize,
    },
    /// An input is larger than the configured limit (checked before allocating).
    #[error("{what}: {count} exceeds the limit of {limit}")]
    TooLarge {
        /// Which input.
        what: &'static str,
        /// Its size.
        count: usize,
        /// The limit.
        limit: usize,
    },
    /// A per-subject z-score is undefined because that subject's scores do not vary.
    #[error(
        "subject {subject}: scores have zero variance or fewer than two ratings, z-score undefined"
    )]
    UndefinedZScore {
        /// The subject id.
        subject: u32,
    },
    /// A test condition names a hidden reference condition that the subject never rated.
    #[error("subject {subject}: condition {condition} has no rating of its reference {reference}")]
    MissingReference {
        /// The subject id.
        subject: u32,
        /// The test condition.
        condition: u32,
        /// The reference condition that was expected.
        reference: u32,
    },
    /// A trial record the analysis cannot use, named by file, line and column.
    #[error("{}: line {line}, column {column}: {message}", path.display())]
    BadRecord {
        /// The `trials.csv` (or manifest) file.
        path: PathBuf,
        /// 1-based line (0 when the problem is not tied to a line).
        line: usize,
        /// Column name.
        column: &'static str,
        /// What is wrong.
        message: String,
    },
    /// Sessions of one results directory ran different protocols.
    #[error("{}: protocol {found}, but earlier sessions ran {expected}", path.display())]
    MixedProtocols {
        /// The session manifest that differs.
        path: PathBuf,
        /// Protocol of the first session.
        expected: String,
        /// Protocol of this session.
        found: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {cause}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (part of the message, not a separate link of its chain).
        cause: std::io::Error,
    },
    /// An output file could not be written, or exists and was not to be replaced.
    #[error(transparent)]
    File(#[from] files::Error),
    /// Drawing a plot failed.
    #[error("plot {name}: {message}")]
    Plot {
        /// Figure name.
        name: String,
        /// What the plotting backend reported.
        message: String,
    },
}

impl AnalysisError {
    /// Wraps an I/O error with the path it happened on.
    pub(crate) fn io(path: impl Into<PathBuf>, cause: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            cause,
        }
    }
}

/// Checks that every value is finite, naming the first one that is not.
pub(crate) fn check_finite(what: &'static str, values: &[f64]) -> Result<(), AnalysisError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(AnalysisError::NonFinite {
            what,
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}
