//! Reading a report's sessions: a results folder's session folders or a database run's
//! sessions, read and checked on threads in session order, converted into the analysis's
//! inputs one at a time (one session per reader in memory).

use std::path::PathBuf;

use analysis::from_results;
use anyhow::{Context, Result, bail};

use lab::results_dir::Destination;

use crate::Request;

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
/// missing (reported with `--allow-incomplete`), every session's display record and the
/// tidy export's rows.
pub(crate) struct Logs {
    pub(crate) converted: from_results::ConvertedResults,
    pub(crate) incomplete: Vec<lab::integrity::Problem>,
    pub(crate) displays: Vec<analysis::display::SessionDisplay>,
    /// What the study's `[crowdsourcing]` rules left out of the statistics.
    pub(crate) exclusions: Vec<analysis::exclusions::SessionExclusion>,
    /// Every trial of every session, spooled for `trials_tidy.csv`.
    pub(crate) tidy: crate::tidy::Spool,
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
    /// Every trial of every session, spooled for `trials_tidy.csv`.
    tidy: crate::tidy::Spool,
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

/// The sessions a report reads: a results folder's session folders, or a database run's
/// sessions.
pub(crate) enum Sessions {
    Folder(Vec<PathBuf>),
    #[cfg(feature = "postgres")]
    Database(crate::database::DbSessions),
}

impl Sessions {
    pub(crate) fn len(&self) -> usize {
        match self {
            Sessions::Folder(dirs) => dirs.len(),
            #[cfg(feature = "postgres")]
            Sessions::Database(db) => db.len(),
        }
    }

    /// Session `i` (< [`Self::len`]), read. The readers ask for increasing indices, so a
    /// database session is either received already or still to come from the fetcher.
    fn load(&self, i: usize) -> Result<results::SessionResults> {
        match self {
            Sessions::Folder(dirs) => Ok(results::read_session(&dirs[i])?),
            #[cfg(feature = "postgres")]
            Sessions::Database(db) => db.load(i),
        }
    }
}

/// What a reader makes of a session before its turn, besides the log check: the study's
/// exclusions of it and its tidy rows.
type Prepared = (analysis::exclusions::SessionExclusion, crate::tidy::Encoded);

/// What adds a session, in session order: its log check's problems and what its reader
/// prepared.
type Take<'a, 't> = dyn Fn(&mut Taken<'a>, &results::SessionResults, Vec<lab::integrity::Problem>, Prepared)
    + Sync
    + 't;

/// Reads and checks sessions on [`READERS`] threads, each taking the next unread session
/// ([`lab::integrity::Checker::check_alone`], the part that needs no other session, and
/// `prepare`), then, when every session before it has been taken, adds it (`take`), says so
/// (`progress(taken, total)`) and drops it itself: one session per reader in memory, every
/// row freed by the thread that read it.
fn read_in_order<'a>(
    checker: &lab::integrity::Checker<'_>,
    sessions: &Sessions,
    taken: Taken<'a>,
    prepare: &(dyn Fn(&results::SessionResults) -> Prepared + Sync),
    take: &Take<'a, '_>,
    progress: &(dyn Fn(usize, usize) + Sync),
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
                let prepared = prepare(&session);
                (session, found, prepared)
            });
            let Some(mut taken) = turns.wait_for(i) else {
                return;
            };
            let session = match session {
                Ok((session, found, prepared)) => {
                    take(&mut taken, &session, found, prepared);
                    taken.next += 1;
                    progress(taken.next, count);
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

/// Refuses logs with damage, or with trials missing unless `allow_incomplete`, naming every
/// problem once.
fn refuse(
    source: &Source,
    problems: &[lab::integrity::Problem],
    allow_incomplete: bool,
) -> Result<()> {
    use lab::integrity::Kind;
    let refused: Vec<_> = problems
        .iter()
        .filter(|p| p.kind == Kind::Damage || !allow_incomplete)
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
    Ok(())
}

/// Reads the sessions and checks each before any statistic ([`lab::integrity`]): damage is
/// refused, every problem named once; sessions with trials missing at the end are refused
/// unless `--allow-incomplete`, and then warned about and returned for the report to list.
/// `progress(read, total)` hears each session taken.
pub(crate) fn read_logs(
    request: &Request,
    source: &Source,
    study: &lab::StudyFile,
    sessions: &Sessions,
    weibull: bool,
    warn: &mut dyn FnMut(&str),
    progress: &(dyn Fn(usize, usize) + Sync),
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
        tidy: crate::tidy::Spool::new(),
        failed: None,
    };
    // Before the session's turn, on its reader's thread: the crowdsourcing exclusions and
    // the tidy rows.
    let answer_times = lab::answer_times::AnswerTimes::new(study);
    let encoder = crate::tidy::Encoder::new(definition, &answer_times);
    let prepare = |session: &results::SessionResults| encoder.prepare(session);
    // In session order: a session recorded twice, the display record, the crowdsourcing
    // exclusions, the tidy rows, the conversion.
    let take = |taken: &mut Taken<'_>,
                session: &results::SessionResults,
                found: Vec<lab::integrity::Problem>,
                (exclusion, rows): Prepared| {
        let found: Vec<_> = checker
            .check_repeat(session)
            .into_iter()
            .chain(found)
            .collect();
        let damaged = found.iter().any(|p| p.kind == Kind::Damage);
        taken.problems.extend(found);
        taken.displays.push(analysis::display::session_display(
            session,
            request.settings.drop_limit,
        ));
        // The crowd rules (gold trials, hidden pages) apply to sound logs only; the
        // integrity check saw every row.
        let kept = analysis::exclusions::apply(session, &exclusion);
        taken.tidy.add(rows);
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
        tidy,
        failed,
        ..
    } = read_in_order(&checker, sessions, taken, &prepare, &take, progress)?;
    refuse(source, &problems, request.allow_incomplete)?;
    if let Some(e) = failed {
        return Err(e);
    }
    for p in &problems {
        warn(&p.to_string());
    }
    if let Some((n, why)) = answer_times.unchecked() {
        warn(&format!(
            "the answer times of {n} kinds of trial were not checked against their stimuli' \
             playing time (the stimuli could not be read: {why})"
        ));
    }
    Ok(Logs {
        converted: converter.finish()?,
        incomplete: problems,
        displays,
        exclusions,
        tidy,
    })
}

/// Where a report's sessions come from.
pub(crate) struct Source {
    /// The results folder (`None`: a database run).
    pub(crate) folder: Option<PathBuf>,
    /// How messages name it.
    pub(crate) location: String,
    /// Its run manifest.
    pub(crate) run: results::RunManifest,
    /// Whether the study file is the run's archived copy (a database run's, written out).
    pub(crate) archived: bool,
}

/// The sessions `request` names, where they come from and the study file to report them
/// with; `warn` hears what the source itself warns about (a database run's subject numbers
/// taken without a session).
pub(crate) fn open(
    request: &Request,
    #[cfg_attr(
        not(feature = "postgres"),
        expect(unused_variables, reason = "a folder warns of nothing here")
    )]
    warn: &mut dyn FnMut(&str),
) -> Result<(Source, Sessions, lab::StudyFile)> {
    // Without the `postgres` feature a folder is the only source.
    #[cfg_attr(
        not(feature = "postgres"),
        allow(clippy::infallible_destructuring_match)
    )]
    let folder = match &request.results {
        Destination::Folder(folder) => folder.clone(),
        #[cfg(feature = "postgres")]
        Destination::Database { db, run } => {
            return crate::database::open(db, run.as_deref(), request.study.as_deref(), warn);
        }
    };
    if !folder.is_dir() {
        bail!("{}: no such results folder", folder.display());
    }
    if !folder.join(results::store::RUN_FILE).is_file() {
        bail!(
            "{} holds no results: no {} (make results with `study run`, `study simulate` or \
             `study serve`)",
            folder.display(),
            results::store::RUN_FILE
        );
    }
    let (run, dirs) = results::session_dirs(&folder)?;
    if dirs.is_empty() {
        bail!(
            "{} holds no sessions yet: no session folder with a {} (nothing to report)",
            folder.display(),
            results::store::SESSION_FILE
        );
    }
    // The study file named, or the copy the results keep (the load's error names the file).
    let study_file = match &request.study {
        Some(path) => lab::StudyFile::load(path)?,
        None => lab::StudyFile::load(&folder.join(&run.study_file)).with_context(|| {
            format!(
                "the study file {} names (--study names another)",
                folder.join(results::store::RUN_FILE).display()
            )
        })?,
    };
    let source = Source {
        location: folder.display().to_string(),
        folder: Some(folder),
        run,
        archived: false,
    };
    Ok((source, Sessions::Folder(dirs), study_file))
}
