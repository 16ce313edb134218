//! Skeletons from raw markers (issue 9): marker trajectories in, joint centres, a skeleton and
//! joint rotations out.
//!
//! The estimator is the Generalized Delogne-Kåsa method of Knight & Semwal (seed 003): for a
//! marker of a child segment expressed in its parent's frame, the centre of rotation is
//! `c = x̄ + ½·C⁻¹·S` (eq. 5), with a planar (hinge) variant (eq. 6) when the covariance is
//! near-singular. [`gdke`] holds the estimator and an iterative least-squares sphere fit for
//! comparison; [`data`] the marker set with CSV I/O; [`c3d`] C3D files (read through `c3dio`,
//! written by our own standard writer); [`segments`] the segment/marker
//! assignment file, segment frames (section 2.5) and the solver that produces a
//! [`Clip`](motion::Clip); [`calibration`] joint centres estimated on a range-of-motion trial
//! and applied to a motion trial; [`acclaim`] the solved clip as ASF/AMC; [`synth`] synthetic
//! captures (motion and range-of-motion trials) with ground truth; [`quiet`] catches the C3D
//! parser's panics without printing them.

pub mod acclaim;
pub mod c3d;
pub mod calibration;
pub mod data;
pub mod gdke;
pub mod quiet;
pub mod segments;
pub mod synth;

use std::path::PathBuf;

/// Why marker data could not be read, written, fitted or solved.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MarkerError {
    /// A fit needs at least `needed` samples.
    #[error("{what}: {got} samples, at least {needed} needed")]
    TooFewSamples {
        /// What was being fitted (a segment or marker name, or `points`).
        what: String,
        /// Samples available.
        got: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A sample is NaN or infinite.
    #[error("sample {index} is not finite")]
    NonFinite {
        /// Index of the sample.
        index: usize,
    },
    /// The file could not be read.
    #[error("{path}: {err}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        err: std::io::Error,
    },
    /// The file could not be written, or exists and was not to be replaced.
    #[error(transparent)]
    File(#[from] files::Error),
    /// A CSV marker file is malformed.
    #[error("{path}:{line}: {reason}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A C3D file is malformed or unsupported.
    #[error("{path}: C3D: {reason}")]
    C3d {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A file exceeds a size limit (checked before allocation).
    #[error("{path}: {what} is {value}, more than the limit {max}")]
    Limit {
        /// The file.
        path: PathBuf,
        /// What was counted.
        what: &'static str,
        /// The count found.
        value: u64,
        /// The limit.
        max: u64,
    },
    /// A segment assignment file is malformed.
    #[error("{path}: {key}: {reason}")]
    Segments {
        /// The file (empty when parsed from a string).
        path: PathBuf,
        /// Key path of the offending value, e.g. `segment[3].parent`.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A marker that a calibration or segment map uses is not in the marker set it is
    /// applied to.
    #[error("marker {marker:?} of segment {segment} is not in the marker data")]
    MissingMarker {
        /// The marker.
        marker: String,
        /// The segment it is on.
        segment: String,
    },
    /// A calibration does not fit the segment map or marker set it is applied to.
    #[error("calibration: {reason}")]
    Calibration {
        /// What does not fit.
        reason: String,
    },
    /// The markers do not determine a segment or joint.
    #[error("segment {segment}: {reason}")]
    Solve {
        /// The segment.
        segment: String,
        /// Why it cannot be solved.
        reason: String,
    },
}

/// Size limits for marker files, checked before allocating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MarkerLimits {
    /// Maximum file size in bytes.
    pub max_file_bytes: u64,
    /// Maximum number of markers.
    pub max_markers: usize,
    /// Maximum number of frames.
    pub max_frames: usize,
    /// Maximum number of samples (markers × frames).
    pub max_samples: usize,
}

impl Default for MarkerLimits {
    fn default() -> Self {
        MarkerLimits {
            max_file_bytes: 1 << 30,
            max_markers: 4096,
            max_frames: 10_000_000,
            max_samples: 50_000_000,
        }
    }
}
