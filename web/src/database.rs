//! `study serve --store`: one run of a PostgreSQL database served by any number of servers
//! at once. Sessions, participants, quotas and the time each trial was sent are in the
//! database; a server keeps only caches. Every request of a participant finds what the
//! database holds of their session first ([`results::pg::participants::touch`]): when
//! another server moved the session on (the participant's last request reached it), this
//! server opens it again by replaying the committed rows. Each write is one transaction
//! holding the session's lock ([`results::pg::LeasedWriter`]), so two servers never both
//! write one session, and a server that dies holds nothing: the next request, wherever it
//! lands, continues the session.

use std::sync::{Arc, Mutex, PoisonError};

use lab::StudyFile;
use results::pg::pool::{Pool, Pooled};
use results::pg::{Database, PgStore};

use crate::{Result, WebError};

/// The database run a server serves, and its pool of connections.
pub struct Db {
    /// The run, on a connection of its own; each request works on a copy on a pooled one.
    store: Mutex<PgStore>,
    pool: Arc<Pool>,
    /// The run's id.
    pub run_id: i32,
    /// The database and run, for messages (no password).
    pub location: String,
}

impl std::fmt::Debug for Db {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Db({})", self.location)
    }
}

impl Db {
    /// Opens run `run` (by default the study's name) of `db` for `study`'s participants,
    /// creating it on first use, with at most `connections` pooled connections; returns
    /// notes for the experimenter as `lab::results_dir::open_database_for_subjects` does.
    ///
    /// # Errors
    /// The run holds another study; database errors.
    pub fn open(
        db: &Database,
        run: Option<&str>,
        study: &StudyFile,
        connections: usize,
    ) -> Result<(Db, Vec<String>)> {
        let (store, notes) = lab::results_dir::open_database_for_subjects(db, run, study)?;
        let location = format!("{}/{}", db.shown(), store.name());
        Ok((
            Db {
                run_id: store.run_id(),
                pool: Pool::new(db, connections),
                store: Mutex::new(store),
                location,
            },
            notes,
        ))
    }

    /// A pooled connection.
    ///
    /// # Errors
    /// None could be had (the database is away, or every connection stayed busy).
    pub fn conn(&self) -> Result<Pooled> {
        self.pool.get().map_err(WebError::from)
    }

    /// The run as a results store on a pooled connection, whose sessions are written one
    /// transaction at a time.
    ///
    /// # Errors
    /// As [`Self::conn`].
    pub fn store(&self) -> Result<PgStore> {
        self.store
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .leased(&self.pool)
            .map_err(WebError::from)
    }
}
