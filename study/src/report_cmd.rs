//! `study report RESULTS -o DIR`: every table and figure of a results directory or a
//! database run (the pipeline is the `report` crate's).

use std::path::PathBuf;

use analysis::psychometric::Shape;
use analysis::{CiMethod, Confidence};
use anyhow::{Result, bail};
use lab::results_dir::Destination;

/// Which confidence interval decides findings and fills the tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CiArg {
    /// Student t with n − 1 degrees of freedom.
    T,
    /// Normal approximation of BT.500 (1.96·S/√N at 95 %).
    Z,
}

/// Psychometric function family of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ShapeArg {
    /// 1 − exp(−(x/α)^β).
    Weibull,
    /// 1 / (1 + exp(−β(x − α))).
    Logistic,
}

/// Arguments of `study report`.
#[derive(Debug, Clone, clap::Args)]
#[expect(
    clippy::struct_excessive_bools,
    reason = "command-line switches: each bool is one flag a user passes"
)]
pub struct ReportArgs {
    /// Results directory written by `study run` or `study simulate` (or `--store`).
    #[arg(required_unless_present_any = ["store", "store_file"])]
    pub results: Option<PathBuf>,
    /// Or the results store: a folder, or a PostgreSQL database (and `--run`).
    #[command(flatten)]
    pub store: crate::store_args::StoreArgs,
    /// Output directory for report.md, report.html, tables/ and figures/.
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,
    /// Study file (default: the copy named in RESULTS/run.json); gives the stimulus manifest
    /// and the rating scale.
    #[arg(long, value_name = "TOML")]
    pub study: Option<PathBuf>,
    /// Codec every other codec is tested against, one-tailed ("scores higher than"); without
    /// it all pairs are tested two-tailed.
    #[arg(long, value_name = "CODEC")]
    pub baseline: Option<String>,
    /// Confidence level of every interval.
    #[arg(long, default_value_t = Confidence::default())]
    pub confidence: Confidence,
    /// Interval used in tables and findings.
    #[arg(long, value_enum, default_value_t = CiArg::T)]
    pub ci: CiArg,
    /// MOS a rate must keep (lower CI bound) to count as unnoticed, on the study's scale
    /// (default: 87.5 % of the way up the scale, thesis §3.3's 4.5 on 1-5).
    #[arg(long, value_name = "SCORE")]
    pub mos_limit: Option<f64>,
    /// DMOS a rate must stay under (upper CI bound), in the study's scale units (default: 5 %
    /// of the scale's range, thesis §6.4.3's 0.2 on 1-5).
    #[arg(long, value_name = "SCORE")]
    pub dmos_limit: Option<f64>,
    /// Count every rating as an observation in the MOS tables (n = ratings), instead of each
    /// subject's mean over its hidden repeats (n = subjects).
    #[arg(long)]
    pub pool_repeats: bool,
    /// Share of dropped frames (percent) above which the display section flags a session.
    #[arg(long, default_value_t = report::Settings::default().drop_limit, value_name = "PERCENT")]
    pub drop_limit: f64,
    /// Reversals averaged per staircase (default: the study's `threshold_reversals`, the
    /// number the sessions used for their own thresholds; thesis §5.4: 3).
    #[arg(long)]
    pub reversals: Option<usize>,
    /// Percent correct (fraction) at which the psychometric threshold is read.
    #[arg(long, default_value_t = report::Settings::default().percent_correct)]
    pub percent_correct: f64,
    /// Psychometric function family.
    #[arg(long, value_enum, default_value_t = ShapeArg::Weibull)]
    pub shape: ShapeArg,
    /// Upper bound of the fitted lapse rate.
    #[arg(long, default_value_t = report::Settings::default().lapse_max)]
    pub lapse_max: f64,
    /// Bootstrap replicates of the threshold CI.
    #[arg(long, default_value_t = report::Settings::default().bootstrap)]
    pub bootstrap: usize,
    /// Seed of the bootstrap RNG (logged in the report).
    #[arg(long, default_value_t = report::Settings::default().seed)]
    pub seed: u64,
    /// Also tabulate MOS of per-subject z-scores.
    #[arg(long)]
    pub zscore: bool,
    /// Write SVG figures only (no PNG).
    #[arg(long)]
    pub no_png: bool,
    /// Write into an output directory that holds files, replacing those of the same names
    /// (each atomically); without it such a directory is refused before the analysis.
    #[arg(long)]
    pub force: bool,
    /// Report on sessions with trials missing at the end (still running, interrupted, or cut
    /// short), with a warning and a section listing what is missing; without it they are
    /// refused. Damaged logs (rows twice, out of order, of another session) are refused
    /// either way.
    #[arg(long)]
    pub allow_incomplete: bool,
}

impl ReportArgs {
    /// The results these arguments name: a folder (RESULTS or `--store FOLDER`) or a database
    /// run (`--store DB`, `--run`), named once.
    fn results(&self) -> Result<Destination> {
        if let Some(db) = self.store.database()? {
            if self.results.is_some() {
                bail!("name the results once: a folder, or --store");
            }
            return Ok(Destination::Database {
                db: Box::new(db),
                run: self.store.run.clone(),
            });
        }
        match (&self.results, &self.store.store) {
            (Some(f), None) => Ok(Destination::Folder(f.clone())),
            (None, Some(f)) => Ok(Destination::Folder(PathBuf::from(f))),
            _ => bail!("name the results once: a folder, or --store"),
        }
    }

    /// The report these arguments ask for.
    fn request(&self) -> Result<report::Request> {
        Ok(report::Request {
            results: self.results()?,
            study: self.study.clone(),
            output: self.output.clone(),
            mode: files::Mode::from_force(self.force),
            allow_incomplete: self.allow_incomplete,
            png: !self.no_png,
            settings: report::Settings {
                baseline: self.baseline.clone(),
                confidence: self.confidence,
                ci: match self.ci {
                    CiArg::T => CiMethod::StudentT,
                    CiArg::Z => CiMethod::NormalZ,
                },
                mos_limit: self.mos_limit,
                dmos_limit: self.dmos_limit,
                pool_repeats: self.pool_repeats,
                drop_limit: self.drop_limit,
                reversals: self.reversals,
                percent_correct: self.percent_correct,
                shape: match self.shape {
                    ShapeArg::Weibull => Shape::Weibull,
                    ShapeArg::Logistic => Shape::Logistic,
                },
                lapse_max: self.lapse_max,
                bootstrap: self.bootstrap,
                seed: self.seed,
                zscore: self.zscore,
            },
        })
    }
}

/// Runs `study report`.
///
/// # Errors
/// Unreadable or malformed results (named by file, line and column), a study file that does
/// not load, or an output that cannot be written.
pub fn run(args: &ReportArgs) -> Result<()> {
    let bar = crate::progress::Progress::new("sessions read", false);
    let summary = report::report_with_progress(
        &args.request()?,
        &mut |w| bar.say(&format!("warning: {w}")),
        &|done, total| bar.set(done, total),
    );
    drop(bar);
    let summary = summary?;
    println!("{summary}");
    Ok(())
}

/// Arguments of `study plan` (docs/analysis.md, "Sample size planning").
#[derive(Debug, Clone, clap::Args)]
pub struct PlanArgs {
    /// A pilot's results folder: each comparison's observed effect, each track's threshold SD.
    pub pilot: Option<PathBuf>,
    #[arg(long, help = "Mean difference to detect (score units), with --sd")]
    pub difference: Option<f64>,
    #[arg(long, help = "SD of the differences (with --ci-width: of the values)")]
    pub sd: Option<f64>,
    #[arg(long, help = "Effect to detect as Cohen's d_z (difference / SD)")]
    pub dz: Option<f64>,
    #[arg(long, help = "Largest half-width of a mean's CI (level 1 - alpha)")]
    pub ci_width: Option<f64>,
    #[arg(long, default_value_t = 0.05, help = "Significance level")]
    pub alpha: f64,
    #[arg(long, default_value_t = 0.8, help = "Power to reach")]
    pub power: f64,
    #[arg(long, help = "One-sided test (default: two-sided)")]
    pub one_sided: bool,
}

pub fn plan(a: &PlanArgs) -> Result<()> {
    let stated = report::plan::Stated::new(a.difference, a.sd, a.dz, a.ci_width);
    let goal = report::plan::Goal::new(a.alpha, a.power, !a.one_sided);
    report::plan::plan(a.pilot.as_deref(), &stated, &goal).map(|text| print!("{text}"))
}
