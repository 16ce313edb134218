//! The on-disk record of study sessions.
//!
//! One directory per study run ([`store::RunManifest`] in `run.json`), one sub-directory per
//! session with a `trials.csv` appended one row per trial with flush and fsync before the next
//! trial ([`store::SessionLog`]), an atomically replaced `session.json`
//! ([`store::SessionManifest`]), a lock file against two writers, torn-row detection on resume,
//! and readers that load a results directory back into typed records for the analysis crate.
//! Formats are versioned and documented in `docs/results-format.md`.
//!
//! The same sessions can be kept in a PostgreSQL database instead ([`pg`],
//! `docs/postgres.md`; cargo feature `postgres`); [`backend::Store`] is what both give a
//! session recorder.

use std::path::PathBuf;

pub mod backend;
#[cfg(feature = "postgres")]
pub mod pg;
pub mod store;
pub mod trials;

pub use backend::{FolderStore, SessionWriter, Store};
pub use store::{
    RunManifest, SessionLog, SessionManifest, SessionResults, ViewingRecord, read_results_dir,
    read_session, session_dirs,
};
pub use trials::{TornRow, TrialsFile, read_trials};

/// Everything that can go wrong reading or writing results.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ResultsError {
    /// An I/O call failed.
    #[error("{}: {op}: {cause}", path.display())]
    Io {
        /// File or directory.
        path: PathBuf,
        /// What was being done.
        op: &'static str,
        /// Cause (part of the message, not a separate link of its chain).
        cause: std::io::Error,
    },
    /// Refusing to overwrite existing results.
    #[error("{} already exists; results are never overwritten (use --resume to continue, or another folder)", path.display())]
    Exists {
        /// The existing path.
        path: PathBuf,
    },
    /// Another live process holds the session lock.
    #[error("{} is locked by process {pid}; two runners may not write one session", path.display())]
    Locked {
        /// Lock file.
        path: PathBuf,
        /// Holder's process id.
        pid: u32,
    },
    /// A file is larger than its reader's limit.
    #[error("{}: {bytes} bytes is over the {limit}-byte limit", path.display())]
    TooLarge {
        /// File.
        path: PathBuf,
        /// Its size.
        bytes: u64,
        /// The limit.
        limit: u64,
    },
    /// A malformed row or header.
    #[error("{}: line {line}, column {column}: {message}", path.display())]
    Malformed {
        /// File.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column (CSV field number, or character for JSON).
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A manifest of a format version this build does not read.
    #[error("{}: format_version {version} is not one this build reads (1 to {max}); a newer `study` wrote it?", path.display())]
    UnknownVersion {
        /// File.
        path: PathBuf,
        /// Its version.
        version: u32,
        /// Newest version this build reads.
        max: u32,
    },
    /// A session directory has a trial log but no `session.json` (interrupted before its first
    /// manifest write).
    #[error("{}: trials.csv without session.json; the session was interrupted (resume it)", dir.display())]
    MissingManifest {
        /// Session directory.
        dir: PathBuf,
    },
    /// A value cannot be written in the format (e.g. a line break in an id).
    #[error("column {column}: cannot write: {reason}")]
    Unwritable {
        /// Column name.
        column: &'static str,
        /// Why.
        reason: String,
    },
    /// The results database cannot be reached (down, restarting, the network away): nothing
    /// was refused, and the same call may succeed later.
    #[error("{location}: the results database cannot be reached ({op}): {message}")]
    Unavailable {
        /// The database (never with its password), run or session.
        location: String,
        /// What was being done.
        op: String,
        /// The client's or server's words.
        message: String,
    },
    /// The database refused what was asked.
    #[error("{location}: {op}: {message}")]
    Database {
        /// The database (never with its password), run or session.
        location: String,
        /// What was being done.
        op: String,
        /// The server's words.
        message: String,
    },
    /// Another station writes this session (it holds the session's lock in the database).
    #[error("{}: {holder} is writing this session; two stations may not write one session", session.display())]
    SessionBusy {
        /// The session.
        session: PathBuf,
        /// Who holds it, as the database knows it.
        holder: String,
    },
    /// Another process moved this session on since this writer last wrote (a participant's
    /// request reached another server): nothing was written; open the session again.
    #[error("{}: {found} answers are committed, this writer expected {expected}; the session moved on elsewhere", session.display())]
    Moved {
        /// The session.
        session: PathBuf,
        /// Rows committed.
        found: u32,
        /// Rows this writer knew of.
        expected: u32,
    },
    /// The database's schema is not one this build can use.
    #[error("{location}: {message}")]
    Schema {
        /// The database.
        location: String,
        /// Why.
        message: String,
    },
    /// A store that cannot be used as asked (a connection string that does not parse or holds
    /// a password where it would show, a run that does not exist, duplicates on import).
    #[error("{0}")]
    Store(String),
}
