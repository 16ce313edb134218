//! `study clip ...`: inspect, convert and evaluate motion clips.

/// Clip subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum ClipCommand {}

/// Runs a clip subcommand.
pub fn run(cmd: ClipCommand) -> anyhow::Result<()> {
    match cmd {}
}
