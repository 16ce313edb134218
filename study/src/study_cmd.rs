//! `study check` and `study simulate`: validate a study file, and dry-run whole sessions with
//! simulated observers through the same engines and results store a real session uses.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use lab::StudyFile;
use lab::live::LiveStimuli;
use lab::simulate::SimulateOptions;

use crate::progress::Progress;

/// Arguments of `study check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// Study file (TOML).
    pub study: PathBuf,
}

/// Arguments of `study simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Study file (TOML).
    pub study: PathBuf,
    /// Number of simulated subjects.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub subjects: u32,
    /// Seed of the simulated observers (the trial plans derive from the study file's seed).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Results directory to create (never overwritten).
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Or a results store: a folder, or a PostgreSQL database several stations simulate into
    /// at once (subject numbers from the database).
    #[command(flatten)]
    pub store: crate::store_args::StoreArgs,
    /// Seconds to wait for an unreachable database before stopping (the session resumes
    /// where its committed answers end).
    #[arg(long, default_value_t = 300)]
    pub patience_s: u64,
    /// Pause before each answer, ms (paces trials for kill tests).
    #[arg(long, default_value_t = 0)]
    pub trial_delay_ms: u64,
    /// Continue an interrupted run in an existing results directory.
    #[arg(long)]
    pub resume: bool,
    /// Simulate one subject with this id instead of `S001`, `S002`, ...: its plan is the one
    /// `study run --subject ID` and `study serve` give that id (a results folder only).
    #[arg(long, value_name = "ID", conflicts_with = "subjects")]
    pub subject: Option<String>,
}

/// `study check STUDY.toml`: every problem at once, or a summary of the study.
///
/// # Errors
/// The study file's problems.
pub fn check(args: &CheckArgs) -> anyhow::Result<()> {
    let file = StudyFile::load(&args.study)?;
    // A live staircase's decoder context and source clips are read now: their problems are
    // the study file's too.
    let live = LiveStimuli::from_study(&file)?;
    // Every stimulus the plan can show, read now: a missing or broken file is the study's
    // problem before any subject sees anything.
    let checked = preflight(&file)?;
    let study = &file.definition;
    let method = match &live {
        Some(live) => live.describe(study)?,
        None => protocols::describe::method(study),
    };
    let text = format!(
        "{}: ok\n{}{method}{}  stimuli: {checked}\n",
        args.study.display(),
        protocols::describe::header(study),
        protocols::describe::design(study)
    );
    std::io::Write::write_all(&mut std::io::stdout(), text.as_bytes())?;
    Ok(())
}

/// [`lab::preflight::verify`] with a progress bar on a terminal.
///
/// # Errors
/// Every stimulus problem, each naming its file.
pub fn preflight(file: &StudyFile) -> anyhow::Result<lab::preflight::Checked> {
    let bar = Progress::new("stimuli checked", false);
    Ok(lab::preflight::verify(file, &|d, t| bar.set(d, t))?)
}

/// `study simulate`: runs `--subjects` complete simulated sessions into a results directory.
///
/// # Errors
/// Study file problems, an existing output without `--resume`, a resume whose logged trials
/// the study no longer regenerates, I/O errors.
pub fn simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    preflight(&StudyFile::load(&args.study)?)?;
    let options = SimulateOptions {
        study: args.study.clone(),
        subjects: args.subjects,
        seed: args.seed,
        output: args.store.destination(args.output.as_deref(), || None)?,
        trial_delay: Duration::from_millis(args.trial_delay_ms),
        resume: args.resume,
        patience: Duration::from_secs(args.patience_s),
    };
    let bar = Progress::new("sessions", false);
    let say = &mut |line: &str| bar.say(line);
    match &args.subject {
        Some(id) => lab::simulate::simulate_subject(&options, id, say)?,
        None => lab::simulate::simulate_with_progress(&options, say, &mut |d, t| bar.set(d, t))?,
    }
    Ok(())
}
