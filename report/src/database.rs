//! A database run's sessions for a report (the cargo feature `postgres`): fetched in batches
//! by connections of their own while the readers check the ones before.

use std::collections::HashMap;

use anyhow::{Context, Result, bail};
use results::Store as _;

use crate::sessions::{Sessions, Source};

/// How many sessions a database fetcher reads in one query, and how many it may have queued
/// ahead of the readers.
const DB_BATCH: usize = 256;

/// How many connections fetch a database run's sessions, each taking every
/// `DB_FETCHERS`-th batch. The server reads and sends one connection's rows on one process,
/// about 4 s of CPU for 10^6 ratings: with one connection that was the slowest stage.
const DB_FETCHERS: usize = 2;

/// A database run's sessions, fetched in order, [`DB_BATCH`] at a time, by [`DB_FETCHERS`]
/// threads with a connection each (batch `k` by fetcher `k % DB_FETCHERS`) while the readers
/// check the ones before (fetching and checking overlap; a reader waited for each batch
/// before).
pub(crate) struct DbSessions {
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

impl DbSessions {
    /// `stores`: one connection per fetcher.
    fn new(stores: Vec<results::pg::PgStore>, heads: Vec<results::pg::SessionHead>) -> Self {
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
        DbSessions {
            heads,
            location,
            inbox: std::sync::Mutex::new(Inbox {
                from_fetchers,
                early: HashMap::new(),
                received: 0,
            }),
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.heads.len()
    }

    /// Session `i`, read: the readers ask for increasing indices, so it is either received
    /// already or still to come from its fetcher.
    pub(crate) fn load(&self, i: usize) -> Result<results::SessionResults> {
        let rows = self.rows(i)?;
        // Decoded here, on the reader's thread, which also frees the records.
        Ok(results::pg::decode_session(&self.heads[i], &rows)?)
    }

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
            "the study file kept with {} (--study names another)",
            store.location()
        )
    })
}

/// The sessions of run `run` (`None`: the database's one run) of `db`, where they come from
/// and the study file to report them with: `study`, else the copy the run keeps. `warn` hears
/// of subject numbers taken for a subject that has no session (a station stopped between
/// the two): a subject the study planned that the report lacks.
pub(crate) fn open(
    db: &results::pg::Database,
    run: Option<&str>,
    study: Option<&std::path::Path>,
    warn: &mut dyn FnMut(&str),
) -> Result<(Source, Sessions, lab::StudyFile)> {
    let mut store = results::pg::PgStore::open(db, run)?;
    let heads = store.sessions()?;
    if heads.is_empty() {
        bail!(
            "{} holds no sessions yet (nothing to report)",
            store.location()
        );
    }
    let unclaimed = store.unclaimed_numbers()?;
    if !unclaimed.is_empty() {
        let list: Vec<String> = unclaimed
            .iter()
            .map(|u| format!("{} ({}, by {})", u.number, u.subject, u.station))
            .collect();
        warn(&format!(
            "{}: {} subject numbers were taken for subjects that have no session: {}; no \
             session was begun under them (a station stopped before creating it, or a window \
             closed before the first answer), so the report lacks those subjects (`study \
             simulate --resume` creates a simulation's, `study run --subject ID` a real \
             subject's)",
            store.location(),
            unclaimed.len(),
            list.join(", ")
        ));
    }
    let (study_file, archived) = match study {
        // Its errors name the file.
        Some(path) => (lab::StudyFile::load(path)?, false),
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
    Ok((
        source,
        Sessions::Database(DbSessions::new(stores, heads)),
        study_file,
    ))
}
