//! The one error type of the lab crate.

use std::path::PathBuf;

/// Why a lab operation failed. Library errors keep their own types (and their file, line and
/// key); [`LabError::Context`] says what was being done when one happened, the way a chain of
/// messages reads: `session results/S001_s1: replaying the logged responses: ...`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LabError {
    /// A file or folder could not be read or written.
    #[error("{}: {cause}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The OS error (part of the message, not a separate link of its chain).
        cause: std::io::Error,
    },
    /// An output file could not be written, or exists and was not to be replaced (an output
    /// folder holding files, without `force`).
    #[error(transparent)]
    File(#[from] files::Error),
    /// A study file's problems.
    #[error(transparent)]
    Study(#[from] protocols::StudyError),
    /// A clip file could not be read.
    #[error(transparent)]
    Parse(#[from] motion::ParseError),
    /// A clip file could not be written.
    #[error(transparent)]
    Write(#[from] motion::WriteError),
    /// Clip files that do not pair for certain.
    #[error(transparent)]
    Pairing(#[from] motion::pairing::PairingError),
    /// A codec refused a clip, a parameter or a stream.
    #[error(transparent)]
    Codec(#[from] codecs::codec::CodecError),
    /// A container could not be serialised or parsed.
    #[error(transparent)]
    Bitstream(#[from] codecs::bitstream::BitstreamError),
    /// A decoded clip could not be compared with its source.
    #[error(transparent)]
    Metrics(#[from] codecs::metrics::MetricsError),
    /// A primitive database could not be read.
    #[error(transparent)]
    Database(#[from] codecs::primitives::DatabaseError),
    /// A results folder could not be read or written.
    #[error(transparent)]
    Results(#[from] results::ResultsError),
    /// The protocol engine refused a trial or a response.
    #[error(transparent)]
    Engine(#[from] protocols::EngineError),
    /// A simulated observer could not answer.
    #[error(transparent)]
    Observer(#[from] protocols::observer::ObserverError),
    /// A JSON file could not be written.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// An error bound no stream of the codec meets: even its largest stream along the rate
    /// knob exceeds it.
    #[error(
        "codec `{codec}`: max joint error {max_error_cm} cm not reachable (closest {closest_cm:.4} cm, at {knob})"
    )]
    BoundUnreachable {
        /// Codec name.
        codec: String,
        /// The bound asked for, cm.
        max_error_cm: f64,
        /// The largest stream's max joint error, cm.
        closest_cm: f64,
        /// The knob setting of that stream (`alpha = 1`).
        knob: String,
    },
    /// A request that cannot be carried out as asked (an existing folder, a resume with other
    /// settings, an unknown codec), with the reason.
    #[error("{0}")]
    Refused(String),
    /// What was being done when `source` happened.
    #[error("{what}")]
    Context {
        /// The step, e.g. `loading stimulus "walk/reference"`.
        what: String,
        /// The error it met.
        #[source]
        source: Box<LabError>,
    },
}

/// A lab result.
pub type Result<T, E = LabError> = std::result::Result<T, E>;

/// Adds what was being done to an error, as a step of the message chain.
pub trait Context<T> {
    /// On error, wraps it in [`LabError::Context`] with `what()`.
    ///
    /// # Errors
    /// The original error, wrapped.
    fn context(self, what: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Into<LabError>> Context<T> for std::result::Result<T, E> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| LabError::Context {
            what: what(),
            source: Box::new(e.into()),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T> {
        self.ok_or_else(|| LabError::Refused(what()))
    }
}

/// An I/O error on `path`.
pub fn io_error(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> LabError {
    let path = path.into();
    move |cause| LabError::Io { path, cause }
}

/// A refusal with `reason`.
pub fn refused(reason: impl Into<String>) -> LabError {
    LabError::Refused(reason.into())
}

/// The whole chain of `err` in one line, `a: b: c` (as `{:#}` prints an `anyhow` chain).
pub fn chain(err: &(dyn std::error::Error + 'static)) -> String {
    let mut text = err.to_string();
    let mut next = err.source();
    while let Some(e) = next {
        text.push_str(": ");
        text.push_str(&e.to_string());
        next = e.source();
    }
    text
}
