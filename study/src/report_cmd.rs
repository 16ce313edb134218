//! `study report RESULTS -o DIR`: every table and figure of a results directory.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use analysis::psychometric::{BootstrapOptions, FitOptions, Lapse, Shape};
use analysis::study::{ReportOptions, analyze};
use analysis::{CiMethod, Confidence, export, from_results};
use anyhow::{Context, Result, bail};
use codecs::codec::keys;
use protocols::StudyDefinition;
use results::Store as _;

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
    #[arg(long, default_value_t = 1.0, value_name = "PERCENT")]
    pub drop_limit: f64,
    /// Reversals averaged per staircase (default: the study's `threshold_reversals`, the
    /// number the sessions used for their own thresholds; thesis §5.4: 3).
    #[arg(long)]
    pub reversals: Option<usize>,
    /// Percent correct (fraction) at which the psychometric threshold is read.
    #[arg(long, default_value_t = 0.75)]
    pub percent_correct: f64,
    /// Psychometric function family.
    #[arg(long, value_enum, default_value_t = ShapeArg::Weibull)]
    pub shape: ShapeArg,
    /// Upper bound of the fitted lapse rate.
    #[arg(long, default_value_t = 0.06)]
    pub lapse_max: f64,
    /// Bootstrap replicates of the threshold CI.
    #[arg(long, default_value_t = 1000)]
    pub bootstrap: usize,
    /// Seed of the bootstrap RNG (logged in the report).
    #[arg(long, default_value_t = 0x5EED)]
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

/// The staircase level's name in tables and figures: the thesis's `t_L`, a target ratio, or
/// the parameter as the study names it (live staircases add the codec).
fn level_label(study: &StudyDefinition) -> String {
    let Some(sc) = &study.staircase else {
        return "Level".to_owned();
    };
    let name = match sc.param.as_str() {
        keys::T_L => "t_L".to_owned(),
        keys::CR => "target CR".to_owned(),
        p => p.to_owned(),
    };
    if sc.live.is_some() {
        format!("{name} ({})", sc.codec)
    } else {
        name
    }
}

/// Reversals averaged per staircase: `--reversals`, else the study's `threshold_reversals`
/// (one setting shared by every track), else 3.
fn last_reversals(args: &ReportArgs, study: &StudyDefinition) -> usize {
    args.reversals.unwrap_or_else(|| {
        study
            .staircase
            .as_ref()
            .and_then(|sc| sc.tracks.first())
            .map_or(3, |t| t.settings.threshold_reversals as usize)
    })
}

/// `--mos-limit` and `--dmos-limit`, or their defaults from the study's scale (thesis §3.3's
/// 4.5 and §6.4.3's 0.2 on a 1-5 scale, scaled to the study's); a limit outside the scale is
/// refused, naming the option.
fn limits(args: &ReportArgs, study: &StudyDefinition) -> Result<(f64, f64)> {
    let (lo, hi) = (study.scale.min, study.scale.max);
    let range = hi - lo;
    let mos = args.mos_limit.unwrap_or(lo + 0.875 * range);
    let dmos = args.dmos_limit.unwrap_or(0.05 * range);
    if !(lo..=hi).contains(&mos) {
        bail!("--mos-limit {mos}: outside the study's scale {lo}-{hi}");
    }
    if !(dmos > -range && dmos <= range) {
        bail!(
            "--dmos-limit {dmos}: a difference on the study's scale {lo}-{hi} lies within ±{range}"
        );
    }
    Ok((mos, dmos))
}

/// The analysis options `args` ask for.
fn report_options(args: &ReportArgs, study: &StudyDefinition) -> Result<ReportOptions> {
    let (mos_limit, dmos_limit) = limits(args, study)?;
    Ok(ReportOptions {
        confidence: args.confidence,
        ci_method: match args.ci {
            CiArg::T => CiMethod::StudentT,
            CiArg::Z => CiMethod::NormalZ,
        },
        mos_limit,
        dmos_limit,
        baseline_codec: args.baseline.clone(),
        last_reversals: last_reversals(args, study),
        percent_correct: args.percent_correct,
        fit: FitOptions {
            shape: match args.shape {
                ShapeArg::Weibull => Shape::Weibull,
                ShapeArg::Logistic => Shape::Logistic,
            },
            guess_rate: 0.5,
            lapse: Lapse::Free {
                max: args.lapse_max,
            },
        },
        bootstrap: BootstrapOptions {
            replicates: args.bootstrap,
            confidence: args.confidence,
            seed: args.seed,
        },
        zscore: args.zscore,
        figures: true,
        level_label: level_label(study),
        pool_repeats: args.pool_repeats,
        scale: Some((study.scale.min, study.scale.max)),
    })
}

/// The Weibull is fitted on the logarithm of the level: a level at or below 0 is refused here,
/// naming its file and line, rather than by the fit, which knows neither.
fn check_weibull_levels(s: &results::SessionResults) -> Result<()> {
    for (i, r) in s.trials.records.iter().enumerate() {
        if let Some(level) = r.trial.level.filter(|l| *l <= 0.0) {
            bail!(
                "{}: line {}: level {level}: the Weibull fit needs levels above 0 (use \
                 --shape logistic for levels that can be 0 or negative)",
                s.dir.join(results::store::TRIALS_FILE).display(),
                i + 2
            );
        }
    }
    Ok(())
}

/// What reading a results directory gave: the analysis inputs, the sessions with trials
/// missing (reported with `--allow-incomplete`) and every session's display record.
struct Logs {
    converted: from_results::ConvertedResults,
    incomplete: Vec<lab::integrity::Problem>,
    displays: Vec<analysis::display::SessionDisplay>,
    /// What the study's `[crowdsourcing]` rules left out of the statistics.
    exclusions: Vec<analysis::exclusions::SessionExclusion>,
}

/// Threads that read and check sessions.
const READERS: usize = 2;

/// What the sessions taken so far gave, taken in session order.
struct Taken<'a> {
    /// The session to take next.
    next: usize,
    /// The error that stops the reading: the first session that cannot be read (the readers
    /// stop at it), or a reader that panicked.
    stopped: Option<anyhow::Error>,
    converter: from_results::Converter<'a>,
    problems: Vec<lab::integrity::Problem>,
    displays: Vec<analysis::display::SessionDisplay>,
    /// What the study's `[crowdsourcing]` rules left out, per session.
    exclusions: Vec<analysis::exclusions::SessionExclusion>,
    /// The first error converting a sound session; the log check's verdict comes first.
    failed: Option<anyhow::Error>,
}

/// Sessions taken in order by [`READERS`] threads ([`read_in_order`]).
struct Turns<'a> {
    taken: std::sync::Mutex<Taken<'a>>,
    /// Signalled whenever `next` or `stopped` changes.
    turn: std::sync::Condvar,
}

impl<'a> Turns<'a> {
    fn lock(&self) -> std::sync::MutexGuard<'_, Taken<'a>> {
        self.taken
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Waits until session `i` is the next to take; `None` once the reading has stopped.
    fn wait_for(&self, i: usize) -> Option<std::sync::MutexGuard<'_, Taken<'a>>> {
        let mut taken = self.lock();
        while taken.next != i && taken.stopped.is_none() {
            taken = self
                .turn
                .wait(taken)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
        taken.stopped.is_none().then_some(taken)
    }
}

/// Stops the reading if its reader unwinds, so that no other reader waits for a session the
/// panicking one will never take.
struct StopOnPanic<'t, 'a>(&'t Turns<'a>);

impl Drop for StopOnPanic<'_, '_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0
                .lock()
                .stopped
                .get_or_insert_with(|| anyhow::anyhow!("a session reader thread panicked"));
            self.0.turn.notify_all();
        }
    }
}

/// How many sessions a database fetcher reads in one query, and how many it may have queued
/// ahead of the readers.
const DB_BATCH: usize = 256;

/// How many connections fetch a database run's sessions, each taking every
/// `DB_FETCHERS`-th batch. The server reads and sends one connection's rows on one process,
/// about 4 s of CPU for 10^6 ratings: with one connection that was the slowest stage.
const DB_FETCHERS: usize = 2;

/// The sessions a report reads: a results folder's session folders, or a database run's
/// sessions.
enum Sessions {
    Folder(Vec<PathBuf>),
    Database(DbSessions),
}

/// A database run's sessions, fetched in order, [`DB_BATCH`] at a time, by [`DB_FETCHERS`]
/// threads with a connection each (batch `k` by fetcher `k % DB_FETCHERS`) while the readers
/// check the ones before (fetching and checking overlap; a reader waited for each batch
/// before).
struct DbSessions {
    heads: std::sync::Arc<Vec<results::pg::SessionHead>>,
    location: String,
    inbox: std::sync::Mutex<Inbox>,
}

/// The fetched sessions as the readers take them.
struct Inbox {
    /// Each fetcher's sessions' rows in order (or its error), decoded by the reader that
    /// takes them.
    from_fetchers:
        Vec<std::sync::mpsc::Receiver<Result<results::pg::SessionRows, results::ResultsError>>>,
    /// Sessions' rows received that another reader will ask for, by index.
    early: HashMap<usize, results::pg::SessionRows>,
    /// How many sessions have been received.
    received: usize,
}

impl Sessions {
    /// `stores`: one connection per fetcher.
    fn database(stores: Vec<results::pg::PgStore>, heads: Vec<results::pg::SessionHead>) -> Self {
        let location = stores
            .first()
            .map(results::pg::PgStore::location)
            .unwrap_or_default();
        let heads = std::sync::Arc::new(heads);
        let count = stores.len();
        let from_fetchers = stores
            .into_iter()
            .enumerate()
            .map(|(k, mut store)| {
                let (to_readers, from_fetcher) = std::sync::mpsc::sync_channel(DB_BATCH);
                let fetched = std::sync::Arc::clone(&heads);
                std::thread::spawn(move || {
                    for batch in fetched.chunks(DB_BATCH).skip(k).step_by(count) {
                        let read = match store.read_rows(batch) {
                            Ok(read) => read,
                            Err(e) => {
                                let _ = to_readers.send(Err(e));
                                return;
                            }
                        };
                        for session in read {
                            // The readers stopped (an error elsewhere): nothing more to fetch.
                            if to_readers.send(Ok(session)).is_err() {
                                return;
                            }
                        }
                    }
                });
                from_fetcher
            })
            .collect();
        Sessions::Database(DbSessions {
            heads,
            location,
            inbox: std::sync::Mutex::new(Inbox {
                from_fetchers,
                early: HashMap::new(),
                received: 0,
            }),
        })
    }

    fn len(&self) -> usize {
        match self {
            Sessions::Folder(dirs) => dirs.len(),
            Sessions::Database(db) => db.heads.len(),
        }
    }

    /// Session `i` (< [`Self::len`]), read. The readers ask for increasing indices, so a
    /// database session is either received already or still to come from the fetcher.
    fn load(&self, i: usize) -> Result<results::SessionResults> {
        match self {
            Sessions::Folder(dirs) => Ok(results::read_session(&dirs[i])?),
            Sessions::Database(db) => {
                let rows = db.rows(i)?;
                // Decoded here, on the reader's thread, which also frees the records.
                Ok(results::pg::decode_session(&db.heads[i], &rows)?)
            }
        }
    }
}

impl DbSessions {
    /// The rows of session `i`, from the fetcher (or set aside by the other reader).
    fn rows(&self, i: usize) -> Result<results::pg::SessionRows> {
        let mut inbox = self
            .inbox
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(rows) = inbox.early.remove(&i) {
            return Ok(rows);
        }
        if i < inbox.received {
            bail!("session {i} of {} was handed out twice", self.location);
        }
        loop {
            // Session `received` is in batch `received / DB_BATCH`, which that batch's
            // fetcher sends.
            let which = (inbox.received / DB_BATCH) % inbox.from_fetchers.len().max(1);
            let Ok(next) = inbox.from_fetchers[which].recv() else {
                bail!(
                    "{} stopped sending sessions at {}",
                    self.location,
                    inbox.received
                );
            };
            let index = inbox.received;
            inbox.received += 1;
            let rows = next?;
            if index == i {
                return Ok(rows);
            }
            inbox.early.insert(index, rows);
        }
    }
}

/// Reads and checks sessions on [`READERS`] threads, each taking the next unread session
/// ([`lab::integrity::Checker::check_alone`], the part that needs no other session), then,
/// when every session before it has been taken, adds it (`take`) and drops it itself: one
/// session per reader in memory, every row freed by the thread that read it.
fn read_in_order<'a>(
    checker: &lab::integrity::Checker<'_>,
    sessions: &Sessions,
    taken: Taken<'a>,
    take: &(dyn Fn(&mut Taken<'a>, &results::SessionResults, Vec<lab::integrity::Problem>) + Sync),
) -> Result<Taken<'a>> {
    let turns = Turns {
        taken: std::sync::Mutex::new(taken),
        turn: std::sync::Condvar::new(),
    };
    let unread = std::sync::atomic::AtomicUsize::new(0);
    let count = sessions.len();
    let read = || {
        let _stop = StopOnPanic(&turns);
        loop {
            let i = unread.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if i >= count {
                return;
            }
            let session = sessions.load(i).map(|session| {
                let found = checker.check_alone(&session);
                (session, found)
            });
            let Some(mut taken) = turns.wait_for(i) else {
                return;
            };
            let session = match session {
                Ok((session, found)) => {
                    take(&mut taken, &session, found);
                    taken.next += 1;
                    Some(session)
                }
                Err(e) => {
                    taken.stopped = Some(e);
                    None
                }
            };
            drop(taken);
            turns.turn.notify_all();
            // Freed here, by the thread that allocated it, outside the lock.
            drop(session);
        }
    };
    std::thread::scope(|scope| {
        let readers: Vec<_> = (0..READERS).map(|_| scope.spawn(read)).collect();
        for reader in readers {
            // A reader that panicked has said so in `stopped` (joined here, the panic is not
            // the scope's).
            let _ = reader.join();
        }
    });
    let mut taken = turns
        .taken
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    match taken.stopped.take() {
        Some(e) => Err(e),
        None => Ok(taken),
    }
}

/// Reads the sessions and checks each before any statistic ([`lab::integrity`]): damage is
/// refused, every problem named once; sessions with trials missing at the end are refused
/// unless `--allow-incomplete`, and then warned about and returned for the report to list.
fn read_logs(
    args: &ReportArgs,
    source: &Source,
    study: &lab::StudyFile,
    sessions: &Sessions,
    weibull: bool,
) -> Result<Logs> {
    use lab::integrity::Kind;
    let definition = &study.definition;
    let checker = match &source.folder {
        Some(folder) => lab::integrity::Checker::new(folder, study, &source.run),
        None => lab::integrity::Checker::with_archived(study, &source.run, source.archived),
    };
    let converter = from_results::Converter::new(
        &definition.manifest,
        Some((definition.scale.min, definition.scale.max)),
    );
    let taken = Taken {
        next: 0,
        stopped: None,
        converter,
        problems: Vec::new(),
        displays: Vec::with_capacity(sessions.len()),
        exclusions: Vec::with_capacity(sessions.len()),
        failed: None,
    };
    // In session order: a session recorded twice, the display record, the crowdsourcing
    // exclusions, the conversion.
    let take = |taken: &mut Taken<'_>,
                session: &results::SessionResults,
                found: Vec<lab::integrity::Problem>| {
        let found: Vec<_> = checker
            .check_repeat(session)
            .into_iter()
            .chain(found)
            .collect();
        let damaged = found.iter().any(|p| p.kind == Kind::Damage);
        taken.problems.extend(found);
        taken
            .displays
            .push(analysis::display::session_display(session, args.drop_limit));
        // The crowd rules (gold trials, hidden pages) apply to sound logs only; the
        // integrity check saw every row.
        let exclusion = analysis::exclusions::session_exclusion(session, &definition.crowdsourcing);
        let kept = analysis::exclusions::apply(session, &exclusion);
        taken.exclusions.push(exclusion);
        let Some(session) = kept else { return };
        if taken.failed.is_none() && !damaged {
            let added = if weibull {
                check_weibull_levels(&session)
            } else {
                Ok(())
            }
            .and_then(|()| taken.converter.add(&session).map_err(anyhow::Error::from));
            taken.failed = added.err();
        }
    };
    let Taken {
        converter,
        problems,
        displays,
        exclusions,
        failed,
        ..
    } = read_in_order(&checker, sessions, taken, &take)?;
    let refused: Vec<_> = problems
        .iter()
        .filter(|p| p.kind == Kind::Damage || !args.allow_incomplete)
        .collect();
    if !refused.is_empty() {
        let damaged = refused.iter().any(|p| p.kind == Kind::Damage);
        bail!(
            "{} cannot be reported: {}\n  {}{}",
            source.location,
            if damaged {
                "its logs are damaged (no statistic is drawn from logs that contradict themselves or the study)"
            } else {
                "sessions have trials missing"
            },
            refused
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join("\n  "),
            if damaged {
                ""
            } else {
                "\n(--allow-incomplete reports the trials that are there and lists what is missing)"
            }
        );
    }
    if let Some(e) = failed {
        return Err(e);
    }
    for p in &problems {
        eprintln!("warning: {p}");
    }
    Ok(Logs {
        converted: converter.finish()?,
        incomplete: problems,
        displays,
        exclusions,
    })
}

/// The "Incomplete sessions" section of a report made with `--allow-incomplete`.
fn incomplete_section(
    report: &mut analysis::report::Report,
    incomplete: &[lab::integrity::Problem],
) {
    if !incomplete.is_empty() {
        let section = report.section("Incomplete sessions");
        section.text(
            "Reported with --allow-incomplete: trials are missing at the end of these sessions; \
             the trials they logged are in every table.",
        );
        for p in incomplete {
            section.text(p.to_string());
        }
    }
}

/// The "Display" section: every session's display and frame record, sessions over
/// `drop_limit` percent dropped frames flagged (and warned about).
fn display_section(
    report: &mut analysis::report::Report,
    displays: &[analysis::display::SessionDisplay],
    drop_limit: f64,
) {
    let flagged: Vec<&str> = displays
        .iter()
        .filter(|d| d.flagged)
        .map(|d| d.session.as_str())
        .collect();
    let display = report.section("Display");
    display.text(if flagged.is_empty() {
        format!(
            "The display each session ran on, as it measured it; no session dropped more than {drop_limit} % of its frames."
        )
    } else {
        format!(
            "The display each session ran on, as it measured it. Over {} % of the frames dropped (--drop-limit): {}; their stimuli did not play as made.",
            drop_limit,
            flagged.join(", ")
        )
    });
    display.table(analysis::display::display_table(displays, drop_limit));
    if let Some(t) = analysis::display::browser_table(displays) {
        display.table(t);
    }
    for f in &flagged {
        eprintln!("warning: {f} dropped more than {drop_limit} % of its frames");
    }
}

/// A MUSHRA study's statistics and the rules they followed.
struct MushraReport {
    analysis: analysis::mushra::MushraAnalysis,
    rules: analysis::mushra::Rules,
}

impl MushraReport {
    /// Adds the "MUSHRA" section to `report`.
    fn add_to(
        &self,
        report: &mut analysis::report::Report,
        converted: &from_results::ConvertedResults,
    ) {
        let data = &converted.data;
        self.analysis.section(
            report,
            &converted.stimuli,
            &data.conditions,
            &|s| data.subject_name(s),
            &self.rules,
        );
    }
}

/// The MUSHRA statistics (BS.1534-3 post-screening, each stimulus over the assessors kept)
/// of a MUSHRA study, `None` for other protocols: its anchors are the study file's, found
/// among the rated stimuli by id.
fn mushra_analysis(
    study: &protocols::StudyDefinition,
    converted: &from_results::ConvertedResults,
    confidence: analysis::Confidence,
) -> Result<Option<MushraReport>> {
    use analysis::mushra::{Rules, analyze};
    let Some(m) = &study.mushra else {
        return Ok(None);
    };
    let anchors: std::collections::BTreeSet<u32> = converted
        .stimuli
        .iter()
        .enumerate()
        .filter(|(_, s)| m.is_anchor(s))
        .map(|(i, _)| i as u32)
        .collect();
    let rules = Rules {
        reference_below: m.reference_below,
        anchor_above: m.anchor_above,
        max_fraction: m.max_fraction,
        exclude_on_anchor: m.anchor_rule == protocols::study::AnchorRule::Exclude,
    };
    let data = &converted.data;
    let analysis = analyze(
        &data.ratings,
        &data.conditions,
        &converted.stimuli,
        &anchors,
        &rules,
        confidence,
    )?;
    Ok(Some(MushraReport { analysis, rules }))
}

/// The "Exclusions" section of a crowd study (gold trials, or trials left out because the
/// page was hidden): who the `[crowdsourcing]` rules left out of the statistics, and why.
fn exclusions_section(
    report: &mut analysis::report::Report,
    exclusions: &[analysis::exclusions::SessionExclusion],
    crowd: &protocols::study::CrowdsourcingSettings,
) {
    if crowd.gold.is_empty()
        && !exclusions
            .iter()
            .any(analysis::exclusions::SessionExclusion::any)
    {
        return;
    }
    let left_out: Vec<&str> = exclusions
        .iter()
        .filter(|e| e.excluded)
        .map(|e| e.session.as_str())
        .collect();
    let section = report.section("Exclusions");
    section.text(format!(
        "The study's crowd rules ([crowdsourcing] in the study file) left out {} of {} sessions{}.",
        left_out.len(),
        exclusions.len(),
        if left_out.is_empty() {
            String::new()
        } else {
            format!(" ({})", left_out.join(", "))
        }
    ));
    section.table(analysis::exclusions::exclusions_table(exclusions, crowd));
}

/// Writes `path` whole or not at all ([`files::AtomicFile`]) from `fill`, which streams it.
fn write_streamed(
    path: &Path,
    mode: files::Mode,
    fill: impl FnOnce(&mut files::AtomicFile) -> std::io::Result<()>,
) -> Result<()> {
    let mut file = files::AtomicFile::create(path, mode)?;
    fill(&mut file).map_err(|source| files::Error::Io {
        path: path.to_path_buf(),
        op: "write",
        source,
    })?;
    file.commit()?;
    Ok(())
}

/// Where a report's sessions come from.
struct Source {
    /// The results folder (`None`: a database run).
    folder: Option<PathBuf>,
    /// How messages name it.
    location: String,
    /// Its run manifest.
    run: results::RunManifest,
    /// Whether the study file is the run's archived copy (a database run's, written out).
    archived: bool,
}

/// The archived study file of a database run, written to a temporary folder and loaded.
fn load_archived(store: &mut results::pg::PgStore) -> Result<lab::StudyFile> {
    let archive = store.archive()?;
    let dir = std::env::temp_dir().join(format!(
        "study-report-{}-{}",
        std::process::id(),
        lab::session::now_ms()
    ));
    std::fs::create_dir_all(&dir)?;
    let loaded = (|| {
        files::write(
            &dir.join(results::pg::STUDY_COPY),
            &archive.study_copy,
            files::Mode::New,
        )?;
        files::write(
            &dir.join(results::pg::MANIFEST_COPY),
            &archive.manifest_copy,
            files::Mode::New,
        )?;
        Ok::<_, anyhow::Error>(lab::StudyFile::load(&dir.join(results::pg::STUDY_COPY))?)
    })();
    let _ = std::fs::remove_dir_all(&dir);
    loaded.with_context(|| {
        format!(
            "loading the study file kept with {} (pass --study to name another)",
            store.location()
        )
    })
}

/// The results `args` name, their sessions and the study file to report them with.
fn open_source(args: &ReportArgs) -> Result<(Source, Sessions, lab::StudyFile)> {
    if let Some(db) = args.store.database()? {
        if args.results.is_some() {
            bail!("name the results once: a folder, or --store");
        }
        let mut store = results::pg::PgStore::open(&db, args.store.run.as_deref())?;
        let heads = store.sessions()?;
        if heads.is_empty() {
            bail!("{}: no sessions yet; nothing to report", store.location());
        }
        let (study_file, archived) = match &args.study {
            Some(path) => (
                lab::StudyFile::load(path)
                    .with_context(|| format!("loading the study file {}", path.display()))?,
                false,
            ),
            None => (load_archived(&mut store)?, true),
        };
        let source = Source {
            folder: None,
            location: store.location(),
            run: store.run().clone(),
            archived,
        };
        // The other fetchers' connections, opened before any thread starts.
        let others = (1..DB_FETCHERS)
            .map(|_| results::pg::PgStore::open(store.database(), Some(store.name())))
            .collect::<Result<Vec<_>, _>>()?;
        let mut stores = vec![store];
        stores.extend(others);
        return Ok((source, Sessions::database(stores, heads), study_file));
    }
    let folder = match (&args.results, &args.store.store) {
        (Some(f), None) => f.clone(),
        (None, Some(f)) => PathBuf::from(f),
        _ => bail!("name the results once: a folder, or --store"),
    };
    if !folder.is_dir() {
        bail!("{}: no such results folder", folder.display());
    }
    if !folder.join(results::store::RUN_FILE).is_file() {
        bail!(
            "{}: not a results folder (it has no {}); `study run`, `study simulate` and `study serve` write one",
            folder.display(),
            results::store::RUN_FILE
        );
    }
    let (run, dirs) = results::session_dirs(&folder)?;
    if dirs.is_empty() {
        bail!(
            "{}: no sessions yet (no session folder holds a {}); nothing to report",
            folder.display(),
            results::store::SESSION_FILE
        );
    }
    let study_path = args
        .study
        .clone()
        .unwrap_or_else(|| folder.join(&run.study_file));
    let study_file = lab::StudyFile::load(&study_path).with_context(|| {
        format!(
            "loading the study file {} (pass --study to name another)",
            study_path.display()
        )
    })?;
    let source = Source {
        location: folder.display().to_string(),
        folder: Some(folder),
        run,
        archived: false,
    };
    Ok((source, Sessions::Folder(dirs), study_file))
}

/// Runs `study report`.
///
/// # Errors
/// Unreadable or malformed results (named by file, line and column), a study file that does
/// not load, or an output that cannot be written.
pub fn run(args: &ReportArgs) -> Result<()> {
    let (source, sessions, study_file) = open_source(args)?;
    let run = &source.run;
    let options = report_options(args, &study_file.definition)?;
    let Logs {
        converted,
        incomplete,
        displays,
        exclusions,
    } = read_logs(
        args,
        &source,
        &study_file,
        &sessions,
        options.fit.shape == Shape::Weibull,
    )?;
    let study = study_file.definition;
    let mode = files::Mode::from_force(args.force);
    files::prepare_dir(&args.output, mode)?;
    let analysis = analyze(&converted.data, &options)?;
    let mushra = mushra_analysis(&study, &converted, options.confidence)?;
    let data = &converted.data;
    // The two exports (10⁶ rows each at a million ratings) are written on a second thread
    // while this one lays out and writes the report.
    let (written, exported) = std::thread::scope(|scope| {
        let exports = scope.spawn(|| -> Result<()> {
            write_streamed(&args.output.join("ratings.csv"), mode, |out| {
                export::write_tidy_csv(out, &data.subjects, &data.ratings, &data.conditions)
            })?;
            write_streamed(&args.output.join("sureal_dataset.py"), mode, |out| {
                export::SurealDataset {
                    name: &run.study,
                    subjects: &data.subjects,
                    ratings: &data.ratings,
                    dscqs: &data.dscqs,
                    conditions: &data.conditions,
                    ref_score: study.scale.max,
                }
                .write_python(out)
            })
        });
        let title = format!(
            "Study {} ({} protocol, {} sessions)",
            run.study,
            converted.protocol,
            sessions.len()
        );
        let mut report = analysis.to_report(data, &options, &title);
        if let Some(m) = &mushra {
            m.add_to(&mut report, &converted);
        }
        analysis::method::method_section(
            &mut report,
            &study,
            analysis::method::Observers {
                sessions: displays.len(),
                subjects: data.subjects.len(),
                excluded_sessions: exclusions.iter().filter(|e| e.excluded).count(),
                rejected: analysis.screening.as_ref().map(|s| s.rejected().len()),
            },
            &displays,
        );
        incomplete_section(&mut report, &incomplete);
        display_section(&mut report, &displays, args.drop_limit);
        exclusions_section(&mut report, &exclusions, &study.crowdsourcing);
        let names = report.section("Subjects and stimuli");
        names.text(format!(
            "Subjects ({}): {}. Condition ids: {}.",
            data.subjects.len(),
            data.subjects.join(", "),
            converted
                .stimuli
                .iter()
                .enumerate()
                .map(|(i, s)| format!("{i} = {s}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        let written = report.write(&args.output, !args.no_png, mode);
        let exported = exports
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the export writer thread panicked")));
        (written, exported)
    });
    let written = written?;
    exported?;
    let choices = match converted.data.pair_choices.len() {
        0 => String::new(),
        n => format!(", {n} pair comparison choices"),
    };
    println!(
        "{}: {} files ({} ratings, {} DSCQS pairs, {} staircases, {} 2AFC trials{choices}); open {}",
        args.output.display(),
        written.files.len() + 2,
        converted.data.ratings.len(),
        converted.data.dscqs.len(),
        converted.data.staircases.len(),
        converted.data.two_afc.len(),
        args.output.join("report.html").display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use clap::Parser;

    use crate::{Cli, Command};

    fn parse(args: &[&str]) -> Command {
        Cli::try_parse_from(args).unwrap().command
    }

    /// `study simulate` → `study report` on the three example studies: every table and figure
    /// is written; then a score edited outside the scale is an error naming file and line.
    #[test]
    #[expect(
        clippy::too_many_lines,
        reason = "one scenario: simulate, report, corrupt, report"
    )]
    fn simulate_then_report_writes_tables_and_figures() {
        let examples = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples");
        let root = std::env::temp_dir().join(format!("study-report-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let expected: [(&str, &[&str], &[&str]); 3] = [
            (
                "mos",
                &["mos", "ttests", "screening", "mos_findings"],
                &["mos_vs_cr", "score_distributions"],
            ),
            (
                "dscqs",
                &["mos", "dmos", "dmos_ci", "dmos_findings", "ttests"],
                &["dmos_vs_cr", "mos_vs_cr"],
            ),
            (
                "staircase",
                &["thresholds", "jnd_thresholds", "jnd_notice"],
                &["staircases", "psychometric", "jnd"],
            ),
        ];
        for (name, tables, figures) in expected {
            let toml = format!("{examples}/{name}.toml");
            let results = root.join(format!("{name}-results"));
            let out = root.join(format!("{name}-report"));
            let Command::Simulate(sim) = parse(&[
                "study",
                "simulate",
                &toml,
                "--subjects",
                "6",
                "--seed",
                "2",
                "-o",
                results.to_str().unwrap(),
            ]) else {
                panic!("simulate did not parse");
            };
            crate::study_cmd::simulate(&sim).unwrap();
            let Command::Report(args) = parse(&[
                "study",
                "report",
                results.to_str().unwrap(),
                "--study",
                &toml,
                "-o",
                out.to_str().unwrap(),
                "--bootstrap",
                "50",
                "--no-png",
            ]) else {
                panic!("report did not parse");
            };
            super::run(&args).unwrap();
            for t in tables {
                for ext in ["csv", "md", "tex"] {
                    assert!(
                        out.join("tables").join(format!("{t}.{ext}")).is_file(),
                        "{name}: {t}.{ext}"
                    );
                }
            }
            for f in figures {
                assert!(
                    out.join("figures").join(format!("{f}.svg")).is_file(),
                    "{name}: {f}.svg"
                );
            }
            for f in [
                "report.md",
                "report.html",
                "ratings.csv",
                "sureal_dataset.py",
            ] {
                assert!(out.join(f).is_file(), "{name}: {f}");
            }
        }
        // Corrupt one MOS rating: 9 on a 1-5 scale.
        let results = root.join("mos-results");
        let session = std::fs::read_dir(&results)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.join("trials.csv").is_file())
            .unwrap();
        let trials = session.join("trials.csv");
        let text = std::fs::read_to_string(&trials).unwrap();
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        let header: Vec<&str> = lines[0].split(',').collect();
        let (response, score) = (
            header.iter().position(|c| *c == "response").unwrap(),
            header.iter().position(|c| *c == "score").unwrap(),
        );
        let row = lines.iter().position(|l| l.contains(",test,")).unwrap();
        let mut fields: Vec<String> = lines[row].split(',').map(str::to_owned).collect();
        fields[response] = "9".into();
        fields[score] = "9".into();
        lines[row] = fields.join(",");
        std::fs::write(&trials, lines.join("\n") + "\n").unwrap();
        let Command::Report(args) = parse(&[
            "study",
            "report",
            results.to_str().unwrap(),
            "--study",
            &format!("{examples}/mos.toml"),
            "-o",
            root.join("bad-report").to_str().unwrap(),
            "--no-png",
        ]) else {
            panic!("report did not parse");
        };
        let err = format!("{:#}", super::run(&args).unwrap_err());
        assert!(
            err.contains("trials.csv") && err.contains(&format!("line {}", row + 1)),
            "{err}"
        );
        std::fs::remove_dir_all(&root).unwrap();
    }
}
