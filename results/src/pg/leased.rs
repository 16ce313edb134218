//! Session writers for a process that serves many sessions and shares them with other such
//! processes (`study serve --store` behind a load balancer): every write is one transaction on
//! a pooled connection that takes the session's lock for that transaction only
//! (`pg_advisory_xact_lock`), checks that the session still has the rows this writer
//! expects, and writes. A writer whose session was moved on by another process (the
//! participant's next request reached another server) is told so
//! ([`ResultsError::Moved`]) and writes nothing; its caller opens the session again, which
//! replays what was committed.

use std::path::PathBuf;
use std::sync::Arc;

use postgres::Transaction;
use protocols::TrialRecord;

use super::pool::{Pool, Pooled};
use super::{LOCK_NAMESPACE, db_error, json, refused, rows, state_name};
use crate::backend::{FRAMES_FILE, SessionWriter, frames_text};
use crate::{ResultsError, SessionManifest};

/// How long a write waits for another process's transaction on the same session.
const LOCK_WAIT: &str = "5s";

/// A session's writer over a [`Pool`] (see the module's text).
pub struct LeasedWriter {
    pool: Arc<Pool>,
    id: i32,
    rows: u32,
    path: PathBuf,
    /// The last row whose commit was not confirmed (the connection failed during it):
    /// its trial index and wall clock, to know it again if it was committed.
    unconfirmed: Option<(i32, i64)>,
}

impl LeasedWriter {
    pub(crate) fn new(pool: Arc<Pool>, id: i32, rows: u32, path: PathBuf) -> Self {
        Self {
            pool,
            id,
            rows,
            path,
            unconfirmed: None,
        }
    }

    fn location(&self) -> String {
        self.path.display().to_string()
    }

    /// Runs `work` in one transaction that holds the session's lock and finds the session
    /// with the rows this writer expects (`Ok(None)` when it finds one more, and `confirm`
    /// says that row is the one this writer sent before; [`ResultsError::Moved`] otherwise).
    fn with_session<T>(
        &mut self,
        op: &str,
        confirm: Option<(i32, i64)>,
        work: impl FnOnce(&mut Transaction<'_>, i32) -> Result<T, postgres::Error>,
    ) -> Result<Option<T>, ResultsError> {
        let location = self.location();
        let err = |e: &postgres::Error| db_error(&location, op, e);
        let mut conn: Pooled = self.pool.get()?;
        let result = (|| {
            let mut tx = conn.transaction()?;
            tx.batch_execute(&format!("SET LOCAL lock_timeout = '{LOCK_WAIT}'"))?;
            tx.execute(
                "SELECT pg_advisory_xact_lock($1, $2)",
                &[&LOCK_NAMESPACE, &self.id],
            )?;
            let n: i32 = tx
                .query_one(
                    "SELECT trials_logged FROM study_sessions WHERE id = $1",
                    &[&self.id],
                )?
                .try_get(0)?;
            let expected = i32::try_from(self.rows).unwrap_or(i32::MAX);
            if n == expected + 1
                && let Some((index, wall)) = confirm
            {
                let row = tx.query_opt(
                    "SELECT trial_index, wall_clock_ms FROM study_trials \
                     WHERE session_id = $1 AND row_number = $2",
                    &[&self.id, &expected],
                )?;
                let same = row.is_some_and(|r| {
                    r.try_get::<_, i32>(0).ok() == Some(index)
                        && r.try_get::<_, i64>(1).ok() == Some(wall)
                });
                if same {
                    return Ok(Ok(None));
                }
            }
            if n != expected {
                return Ok(Err(n));
            }
            let out = work(&mut tx, expected)?;
            tx.commit()?;
            Ok(Ok(Some(out)))
        })();
        match result {
            Ok(Ok(done)) => Ok(done),
            Ok(Err(found)) => Err(ResultsError::Moved {
                session: self.path.clone(),
                found: u32::try_from(found).unwrap_or(0),
                expected: self.rows,
            }),
            Err(e) => {
                // The connection's state is unknown: let it go.
                conn.discard();
                Err(err(&e))
            }
        }
    }
}

impl SessionWriter for LeasedWriter {
    fn rows(&self) -> u32 {
        self.rows
    }

    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    fn append(&mut self, record: &TrialRecord) -> Result<(), ResultsError> {
        let params = rows::Values::of(record)?;
        let index =
            i32::try_from(record.trial.index).map_err(|_| refused("trial index too large"))?;
        let wall = i64::try_from(record.wall_clock_ms).unwrap_or(i64::MAX);
        let id = self.id;
        let sql = rows::append_sql();
        let confirm = self.unconfirmed.take();
        let done = self.with_session("committing an answer", confirm, |tx, row_number| {
            let mut all: Vec<&(dyn postgres::types::ToSql + Sync)> = vec![&id, &row_number];
            let values = params.refs();
            all.extend_from_slice(&values);
            tx.execute(sql.as_str(), &all)
        });
        match done {
            Ok(Some(1) | None) => {
                self.rows += 1;
                Ok(())
            }
            Ok(Some(_)) => Err(refused(format!(
                "{}: the answer was not committed",
                self.location()
            ))),
            Err(e) => {
                if matches!(e, ResultsError::Unavailable { .. }) {
                    self.unconfirmed = Some((index, wall));
                }
                Err(e)
            }
        }
    }

    fn write_manifest(&mut self, manifest: &SessionManifest) -> Result<(), ResultsError> {
        let value = json(manifest)?;
        let status = state_name(manifest.status);
        let id = self.id;
        self.with_session("writing the session's manifest", None, |tx, _| {
            tx.execute(
                "UPDATE study_sessions SET manifest = $2, status = $3 WHERE id = $1",
                &[&id, &value, &status],
            )
        })
        .map(drop)
    }

    fn append_frames(
        &mut self,
        index: u32,
        intervals: &[f64],
        phases: &[&str],
    ) -> Result<(), ResultsError> {
        let id = self.id;
        self.with_session("appending to frames.csv", None, |tx, _| {
            let part: i32 = tx
                .query_one(
                    "SELECT count(*)::integer FROM study_session_files WHERE session_id = $1 AND name = $2",
                    &[&id, &FRAMES_FILE],
                )?
                .try_get(0)?;
            let text = frames_text(part == 0, index, intervals, phases, true);
            tx.execute(
                "INSERT INTO study_session_files (session_id, name, part, bytes) VALUES ($1, $2, $3, $4)",
                &[&id, &FRAMES_FILE, &part, &text.as_bytes()],
            )
        })
        .map(drop)
    }
}
