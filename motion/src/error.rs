//! Errors of the clip readers.

use std::path::PathBuf;

/// Why a motion file could not be read. Every variant names the file and, where there is one,
/// the 1-based line.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ParseError {
    /// The file could not be opened or read.
    #[error("{path}: cannot read: {err}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        err: std::io::Error,
    },
    /// A value is not a number (or not a finite one).
    #[error("{path}:{line}: {what}: `{text}` is not a finite number")]
    BadNumber {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What was being read (e.g. `bone lfemur`, `OFFSET`).
        what: String,
        /// The offending token.
        text: String,
    },
    /// A line has the wrong number of values.
    #[error("{path}:{line}: {what}: expected {expected} values, found {found}")]
    WrongCount {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What was being read.
        what: String,
        /// Values expected.
        expected: usize,
        /// Values found.
        found: usize,
    },
    /// A bone or joint referenced by name does not exist.
    #[error("{path}:{line}: unknown bone `{name}`")]
    UnknownBone {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The name.
        name: String,
    },
    /// A frame lacks a bone that has channels.
    #[error("{path}:{line}: frame {frame} has no line for bone `{name}`")]
    MissingBone {
        /// The file.
        path: PathBuf,
        /// 1-based line where the frame ends.
        line: usize,
        /// 1-based frame number.
        frame: usize,
        /// The bone without a line.
        name: String,
    },
    /// A channel name is not one the format knows.
    #[error("{path}:{line}: unknown channel `{name}`")]
    UnknownChannel {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The channel token.
        name: String,
    },
    /// The number of frames does not match what the file declares or numbers.
    #[error("{path}:{line}: frame count mismatch: {detail}")]
    FrameCount {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What disagreed.
        detail: String,
    },
    /// The file ended before a structure was complete.
    #[error("{path}:{line}: file ends early: {expected}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Last line read.
        line: usize,
        /// What was still expected.
        expected: String,
    },
    /// A declared size exceeds the reader's limits or the bytes present.
    #[error("{path}:{line}: {what} of {value} exceeds the limit of {limit}")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What was declared.
        what: String,
        /// The declared value.
        value: u64,
        /// The limit.
        limit: u64,
    },
    /// Any other structural problem, described.
    #[error("{path}:{line}: {reason}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// Something a reader accepted only after changing it (an ASF bone direction off unit length,
/// normalised), named by file and line so that a command can show it beside the clip.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadWarning {
    /// The file.
    pub path: PathBuf,
    /// 1-based line.
    pub line: usize,
    /// What was changed, and to what.
    pub message: String,
}

impl std::fmt::Display for ReadWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}: {}", self.path.display(), self.line, self.message)
    }
}

/// Size limits a reader checks before it allocates (cf. image-png's `Limits`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Maximum file size in bytes.
    pub max_file_bytes: u64,
    /// Maximum number of joints in a skeleton.
    pub max_joints: usize,
    /// Maximum number of frames in a clip.
    pub max_frames: usize,
    /// Maximum number of values in a channel matrix.
    pub max_values: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_file_bytes: 1 << 30,
            max_joints: 1024,
            max_frames: 10_000_000,
            max_values: 200_000_000,
        }
    }
}

/// Why a clip could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// The file could not be written, or exists and was not to be replaced (the error names
    /// the file).
    #[error(transparent)]
    File(#[from] files::Error),
    /// The clip cannot be expressed in the requested format.
    #[error("{path}: {reason}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// Why not.
        reason: String,
    },
}
