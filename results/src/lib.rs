//! The on-disk record of study sessions.
//!
//! Holds (protocols issue): per session a `trials.csv` appended one row per trial with flush
//! and fsync before the next trial, an atomically replaced `session.json` manifest, a session
//! lock, torn-row detection, resume by replay, and readers that load a results folder back into
//! typed records for the analysis crate.
