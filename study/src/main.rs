//! The `study` command: a thin layer that parses arguments and wires the library crates.
//!
//! Each command group lives in its own module with an `Args` type and a `run` function; this
//! file only dispatches.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod clip_cmd;
mod codec_cmd;
mod db_cmd;
mod demo_cmd;
mod markers_cmd;
mod preview_cmd;
mod primitives_cmd;
mod progress;
mod report_cmd;
mod run_cmd;
mod serve_cmd;
mod stimuli_cmd;
mod store_args;
mod study_cmd;

/// Perceptual user studies of motion-capture compression.
#[derive(Debug, Parser)]
#[command(name = "study", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a short study on generated motion end to end (no files needed): stimuli, MOS,
    /// DSCQS and staircase sessions with simulated observers, reports.
    Demo(demo_cmd::DemoArgs),
    /// Run one subject's session in the study window (any method a study file can name).
    Run(run_cmd::RunArgs),
    /// Serve a study to participants' browsers (HTTP; the engine and results stay here).
    Serve(serve_cmd::ServeArgs),
    /// Measure the display: refresh rate, frame-interval mean/SD/max and dropped frames.
    DisplayTest(run_cmd::DisplayTestArgs),
    /// Inspect, convert and evaluate motion clips (ASF/AMC, BVH).
    #[command(subcommand)]
    Clip(clip_cmd::ClipCommand),
    /// Skeletons from raw markers: synthetic captures and GDKE solving (C3D/CSV in, BVH or
    /// ASF/AMC out).
    #[command(subcommand)]
    Markers(markers_cmd::MarkersCommand),
    /// Build and inspect the primitive database of the incremental codec (thesis ch. 5).
    #[command(subcommand)]
    Primitives(primitives_cmd::PrimitivesCommand),
    /// Encode one clip with a codec: writes the bitstream and the decoded clip.
    Encode(codec_cmd::EncodeArgs),
    /// Decode a bitstream for its skeleton into a clip file.
    Decode(codec_cmd::DecodeArgs),
    /// Build a stimulus set (clips × codecs × rates) with stimuli.json and rd.csv.
    Sweep(codec_cmd::SweepArgs),
    /// Play a manifest's stimuli in the study window, each beside its reference, with its
    /// metrics (codec, parameters, compression ratio, joint errors) beside them.
    Preview(preview_cmd::PreviewArgs),
    /// Stimulus sets made elsewhere: add a clip decoded by a codec of your own, measured as
    /// the sweep measures its own.
    #[command(subcommand)]
    Stimuli(stimuli_cmd::StimuliCommand),
    /// Compress the crowd scenes of a study's `[scene]` (thesis 6.5): a ratio per group, or
    /// one budget per scene shared uniformly, by distance (eq. 6.4-6.5) or by importance.
    Crowd(codec_cmd::CrowdArgs),
    /// List the codecs and their parameters (with `--codec-defs`, a lab's own too).
    Codecs(codec_cmd::CodecFiles),
    /// Validate a study file and list every problem at once.
    Check(study_cmd::CheckArgs),
    /// Dry-run sessions with simulated observers into a results directory.
    Simulate(study_cmd::SimulateArgs),
    /// Every table and figure of a results directory: MOS / DMOS with CIs, t-tests, screening,
    /// thresholds, psychometric fit (report.md, report.html, CSV / Markdown / LaTeX, SVG / PNG).
    Report(report_cmd::ReportArgs),
    /// Subjects needed for a power or a CI width: from stated effect sizes or a pilot's results.
    Plan(report_cmd::PlanArgs),
    /// Write a database run's results as a results folder (the format `study run -o` writes).
    Export(db_cmd::ExportArgs),
    /// Load a results folder into a database run (refusing sessions it holds already).
    Import(db_cmd::ImportArgs),
    /// Create or upgrade the results schema of a database (as its owner role) and list its
    /// runs.
    DbInit(db_cmd::DbInitArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => demo_cmd::run(&args),
        Command::Run(args) => run_cmd::run(&args),
        Command::Serve(args) => serve_cmd::run(&args),
        Command::DisplayTest(args) => run_cmd::display_test(&args),
        Command::Clip(cmd) => clip_cmd::run(cmd),
        Command::Markers(cmd) => markers_cmd::run(cmd),
        Command::Primitives(cmd) => primitives_cmd::run(cmd),
        Command::Encode(args) => codec_cmd::encode(&args),
        Command::Decode(args) => codec_cmd::decode(&args),
        Command::Sweep(args) => codec_cmd::sweep(&args),
        Command::Crowd(args) => codec_cmd::crowd(&args),
        Command::Stimuli(cmd) => stimuli_cmd::run(cmd),
        Command::Preview(args) => preview_cmd::run(&args),
        Command::Codecs(files) => codec_cmd::list(&files),
        Command::Check(args) => study_cmd::check(&args),
        Command::Simulate(args) => study_cmd::simulate(&args),
        Command::Report(args) => report_cmd::run(&args),
        Command::Plan(args) => report_cmd::plan(&args),
        Command::Export(args) => db_cmd::export(&args),
        Command::Import(args) => db_cmd::import(&args),
        Command::DbInit(args) => db_cmd::init(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
