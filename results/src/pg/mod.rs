//! Results in a PostgreSQL server (`docs/postgres.md`): the same sessions as a results folder,
//! written by several stations at once into one database.
//!
//! - A *run* (`study_runs`) is what a results folder is: one study's sessions, with its run
//!   manifest and the archived study file and stimulus manifest. Runs have names (by default
//!   the study's).
//! - A session is a row of `study_sessions` (its manifest, as `session.json` holds it, plus
//!   columns for queries) and its answers rows of `study_trials`, one column per `trials.csv`
//!   column. A window session's per-frame intervals are parts of a `frames.csv` in
//!   `study_session_files`.
//! - One writer per session: the writer's connection holds the session's advisory lock
//!   (`pg_try_advisory_lock(1398035780, id)`) for as long as it lives; the server releases it
//!   when the connection ends, however the station died. Rows may be inserted only by a
//!   connection that holds it (a row-level security policy for roles other than the owner).
//! - An answer is one statement (the row and the manifest that counts it), committed before
//!   [`crate::backend::SessionWriter::append`] returns.
//! - A writer whose connection is lost says so ([`ResultsError::Unavailable`]); called again,
//!   it reconnects, takes the lock again, looks at what was committed and commits the answer
//!   once.
//! - Subject numbers come from a per-run counter updated in one statement (a row lock orders
//!   concurrent stations), each number recorded once in `study_subject_numbers`.
//!
//! Every value goes to the server as a query parameter; the connection string's password is
//! never printed ([`Database`] shows the rest).

pub mod participants;
pub mod pool;
pub mod schema;
pub mod scratch;

mod leased;
mod rows;

pub use leased::LeasedWriter;
use pool::{Pool, Pooled};

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use postgres::{Client, NoTls, Statement};
use protocols::TrialRecord;

use crate::backend::{
    AssignedRow, Assignment, FRAMES_FILE, Found, GROUPS_FILE, GroupQuota, ResumedSession,
    SessionWriter, Store, assignments_csv, choose_group, frames_text, read_assignments,
    session_name,
};
use crate::store::{
    MAX_SESSIONS, RUN_FILE, SESSION_FILE, SessionState, TRIALS_FILE, read_limited, read_manifest,
    session_dirs, write_json, write_new,
};
use crate::trials::{TRIALS_FORMAT_VERSION, TrialsFile, encode_row_as, header_of, read_trials};
use crate::{ResultsError, RunManifest, SessionManifest, SessionResults};

/// The first key of every advisory lock this crate takes (`'STUD'`); the second is a
/// session's id (0: the schema migration).
pub const LOCK_NAMESPACE: i32 = 0x5354_5544;

/// The environment variable `--store env` reads the connection string from (by default).
pub const STORE_ENV: &str = "STUDY_DATABASE_URL";

/// The names the archived study file and stimulus manifest have in an exported folder (as
/// `lab::study` names them in a results folder).
pub const STUDY_COPY: &str = "study.toml";
/// See [`STUDY_COPY`].
pub const MANIFEST_COPY: &str = "stimuli.json";

/// How long a connection attempt may take before the server counts as unreachable.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);
/// How long sent data may stay unacknowledged before the connection counts as lost.
const TCP_USER_TIMEOUT: Duration = Duration::from_secs(15);

/// Whether `text` names a PostgreSQL database (`postgres://` or `postgresql://`).
pub fn is_url(text: &str) -> bool {
    text.starts_with("postgres://") || text.starts_with("postgresql://")
}

/// The message of a client error with its causes (the client's own text names only the kind).
fn chain(e: &postgres::Error) -> String {
    let mut text = e.to_string();
    if let Some(db) = e.as_db_error() {
        text = format!("{}: {}", db.severity(), db.message());
        if let Some(detail) = db.detail() {
            text.push_str(" (");
            text.push_str(detail);
            text.push(')');
        }
        return text;
    }
    let mut next = std::error::Error::source(e);
    while let Some(s) = next {
        text.push_str(": ");
        text.push_str(&s.to_string());
        next = s.source();
    }
    text
}

/// Whether `e` means the server could not be reached or went away (try again later), rather
/// than that it refused what was asked.
pub fn is_outage(e: &postgres::Error) -> bool {
    if e.is_closed() {
        return true;
    }
    if let Some(code) = e.code() {
        let c = code.code();
        // connection exceptions, admin/crash shutdown, cannot connect now, too many clients.
        return c.starts_with("08") || matches!(c, "57P01" | "57P02" | "57P03" | "53300");
    }
    let kind = e.to_string();
    [
        "error communicating with the server",
        "error connecting to server",
        "timeout waiting for server",
    ]
    .iter()
    .any(|k| kind.starts_with(k))
}

/// The crate's error for a client error met while doing `op` on the database shown as
/// `location`: [`ResultsError::Unavailable`] for an outage, [`ResultsError::Database`]
/// otherwise.
pub fn db_error(location: &str, op: &str, e: &postgres::Error) -> ResultsError {
    if is_outage(e) {
        ResultsError::Unavailable {
            location: location.to_owned(),
            op: op.to_owned(),
            message: chain(e),
        }
    } else {
        ResultsError::Database {
            location: location.to_owned(),
            op: op.to_owned(),
            message: chain(e),
        }
    }
}

fn refused(message: impl Into<String>) -> ResultsError {
    ResultsError::Store(message.into())
}

/// A PostgreSQL database to keep results in: its connection settings, and how messages name
/// it (`postgres://user@host:port/db`, never with the password).
#[derive(Clone)]
pub struct Database {
    config: postgres::Config,
    shown: String,
}

impl fmt::Debug for Database {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.shown)
    }
}

impl fmt::Display for Database {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.shown)
    }
}

impl Database {
    /// A connection string (a `postgres://` URL or `key=value` pairs). `source` says where it
    /// came from, for messages (which never repeat the string itself).
    ///
    /// # Errors
    /// [`ResultsError::Store`] when it does not parse.
    pub fn parse(text: &str, source: &str) -> Result<Self, ResultsError> {
        let text = text.trim();
        let mut config: postgres::Config = text.parse().map_err(|e: postgres::Error| {
            refused(format!(
                "{source}: not a PostgreSQL connection string ({})",
                chain(&e)
            ))
        })?;
        if config.get_password().is_none()
            && let Ok(p) = std::env::var("PGPASSWORD")
        {
            config.password(p);
        }
        let shown = show(&config);
        Ok(Self { config, shown })
    }

    /// The connection string given on the command line: refused when it holds a password,
    /// which every user of the machine could read (`ps`) and the shell keeps in its history.
    /// A password comes from `PGPASSWORD`, the environment variable [`STORE_ENV`]
    /// (`--store env`) or a file (`--store-file`).
    ///
    /// # Errors
    /// [`ResultsError::Store`].
    pub fn from_argument(text: &str) -> Result<Self, ResultsError> {
        let parsed: Result<postgres::Config, _> = text.parse();
        if parsed.is_ok_and(|c| c.get_password().is_some()) {
            return Err(refused(format!(
                "--store: a password on the command line is visible to every user of this \
                 machine; put the connection string in ${STORE_ENV} (--store env) or in a file \
                 only you can read (--store-file FILE), or the password in PGPASSWORD"
            )));
        }
        Self::parse(text, "--store")
    }

    /// The connection string in environment variable `var`.
    ///
    /// # Errors
    /// [`ResultsError::Store`] when it is unset or does not parse.
    pub fn from_env(var: &str) -> Result<Self, ResultsError> {
        let text =
            std::env::var(var).map_err(|_| refused(format!("--store env: ${var} is not set")))?;
        Self::parse(&text, &format!("${var}"))
    }

    /// The connection string in file `path` (its first line), which only its owner may read.
    ///
    /// # Errors
    /// [`ResultsError::Store`] when it is readable by others, empty or does not parse; I/O
    /// errors.
    pub fn from_file(path: &Path) -> Result<Self, ResultsError> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(path)
                .map_err(|cause| ResultsError::Io {
                    path: path.to_path_buf(),
                    op: "stat",
                    cause,
                })?
                .permissions()
                .mode();
            if mode & 0o077 != 0 {
                return Err(refused(format!(
                    "{}: holds a database password but others may read it (mode {:o}); `chmod 600 {}`",
                    path.display(),
                    mode & 0o777,
                    path.display()
                )));
            }
        }
        let bytes = read_limited(path, 64 * 1024)?;
        let text = String::from_utf8_lossy(&bytes);
        let line = text
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty() && !l.starts_with('#'));
        let Some(line) = line else {
            return Err(refused(format!(
                "{}: no connection string in it",
                path.display()
            )));
        };
        Self::parse(line, &path.display().to_string())
    }

    /// How messages name the database.
    pub fn shown(&self) -> &str {
        &self.shown
    }

    /// A new connection (connect timeout, TCP keepalives and user timeout set, so a server
    /// that went away is noticed within seconds; the application name says which station).
    ///
    /// # Errors
    /// [`ResultsError::Unavailable`] when the server cannot be reached, other database errors.
    pub fn connect(&self) -> Result<Client, ResultsError> {
        let mut config = self.config.clone();
        config
            .connect_timeout(CONNECT_TIMEOUT)
            .tcp_user_timeout(TCP_USER_TIMEOUT)
            .keepalives(true)
            .keepalives_idle(Duration::from_secs(10));
        if config.get_application_name().is_none() {
            config.application_name(&station());
        }
        config
            .connect(NoTls)
            .map_err(|e| db_error(&self.shown, "connecting", &e))
    }

    /// A connection to a database whose schema is this build's ([`schema::migrate`]).
    ///
    /// # Errors
    /// As [`Self::connect`], and [`ResultsError::Schema`] for a newer schema.
    pub fn open(&self) -> Result<Client, ResultsError> {
        let mut client = self.connect()?;
        schema::migrate(&mut client, &self.shown)?;
        Ok(client)
    }
}

/// `postgres://user@host:port/db` of `config`: what messages say, without the password.
fn show(config: &postgres::Config) -> String {
    use postgres::config::Host;
    let hosts: Vec<String> = config
        .get_hosts()
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let port = config
                .get_ports()
                .get(i)
                .or_else(|| config.get_ports().first())
                .map_or(String::new(), |p| format!(":{p}"));
            match h {
                Host::Tcp(name) => format!("{name}{port}"),
                #[cfg(unix)]
                Host::Unix(path) => format!("[{}]{port}", path.display()),
            }
        })
        .collect();
    format!(
        "postgres://{}{}/{}",
        config.get_user().map_or(String::new(), |u| format!("{u}@")),
        hosts.join(","),
        config.get_dbname().unwrap_or("")
    )
}

/// What a station calls itself in the database (`application_name`, subject numbers):
/// `study <host> pid <pid>`.
pub fn station() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_owned())
        .filter(|h| !h.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "unknown-host".into());
    format!("study {host} pid {}", std::process::id())
}

/// The study file and stimulus manifest kept with a run (what a results folder holds as
/// `study.toml` and `stimuli.json`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Archive {
    /// The study file's copy.
    pub study_copy: Vec<u8>,
    /// The stimulus manifest's copy.
    pub manifest_copy: Vec<u8>,
}

/// A run of a database, as listed by [`runs`].
#[derive(Debug, Clone, PartialEq)]
pub struct RunInfo {
    /// Its name.
    pub name: String,
    /// Its manifest.
    pub run: RunManifest,
    /// Sessions recorded.
    pub sessions: i64,
}

fn json<T: serde::Serialize>(v: &T) -> Result<serde_json::Value, ResultsError> {
    serde_json::to_value(v).map_err(|e| ResultsError::Unwritable {
        column: "manifest",
        reason: e.to_string(),
    })
}

fn from_json<T: for<'de> serde::Deserialize<'de>>(
    v: serde_json::Value,
    path: &Path,
) -> Result<T, ResultsError> {
    serde_json::from_value(v).map_err(|e| ResultsError::Malformed {
        path: path.to_path_buf(),
        line: 1,
        column: 1,
        message: e.to_string(),
    })
}

/// A subject number taken for a subject whose session was never created
/// ([`PgStore::unclaimed_numbers`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnclaimedNumber {
    /// The number.
    pub number: u32,
    /// The subject id it was taken for.
    pub subject: String,
    /// The station that took it ([`station`]).
    pub station: String,
    /// The simulated observer's seed, for a number a simulation took.
    pub observer_seed: Option<u64>,
}

/// A `u64` seed as PostgreSQL's `bigint` (the same 64 bits).
fn seed_to_sql(seed: u64) -> i64 {
    i64::from_le_bytes(seed.to_le_bytes())
}

/// [`seed_to_sql`] undone.
fn seed_from_sql(v: i64) -> u64 {
    u64::from_le_bytes(v.to_le_bytes())
}

/// The runs of the database, by name.
///
/// # Errors
/// Database errors.
pub fn runs(client: &mut Client, location: &str) -> Result<Vec<RunInfo>, ResultsError> {
    let rows = client
        .query(
            "SELECT r.name, r.run_manifest, \
             (SELECT count(*) FROM study_sessions s WHERE s.run_id = r.id) \
             FROM study_runs r ORDER BY r.name",
            &[],
        )
        .map_err(|e| db_error(location, "listing the runs", &e))?;
    rows.iter()
        .map(|r| {
            let name: String = r
                .try_get(0)
                .map_err(|e| db_error(location, "listing the runs", &e))?;
            let manifest = r
                .try_get(1)
                .map_err(|e| db_error(location, "listing the runs", &e))?;
            Ok(RunInfo {
                run: from_json(manifest, &Path::new(location).join(&name).join(RUN_FILE))?,
                sessions: r
                    .try_get(2)
                    .map_err(|e| db_error(location, "listing the runs", &e))?,
                name,
            })
        })
        .collect()
}

/// A session of a run as [`PgStore::sessions`] lists it: enough to read it.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionHead {
    id: i32,
    version: u32,
    /// The path naming it in messages.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: SessionManifest,
}

/// One run of a database as a results store ([`Store`]): sessions created, resumed, read.
pub struct PgStore {
    db: Database,
    client: Conn,
    /// Set on a store of [`PgStore::leased`]: its sessions are written by [`LeasedWriter`]s.
    pool: Option<Arc<Pool>>,
    run_id: i32,
    name: String,
    run: RunManifest,
    /// Bytes of the last [`PgStore::read_rows`], to size the next one's buffer.
    last_batch_bytes: usize,
}

/// A store's connection: its own, or one lent by a [`Pool`].
enum Conn {
    Own(Client),
    Lent(Pooled),
}

impl std::ops::Deref for Conn {
    type Target = Client;
    fn deref(&self) -> &Client {
        match self {
            Conn::Own(c) => c,
            Conn::Lent(c) => c,
        }
    }
}

impl std::ops::DerefMut for Conn {
    fn deref_mut(&mut self) -> &mut Client {
        match self {
            Conn::Own(c) => c,
            Conn::Lent(c) => c,
        }
    }
}

impl fmt::Debug for PgStore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PgStore({})", self.location())
    }
}

fn state_name(state: SessionState) -> &'static str {
    match state {
        SessionState::Running => "running",
        SessionState::Interrupted => "interrupted",
        SessionState::Complete => "complete",
        SessionState::TimeLimit => "time_limit",
    }
}

impl PgStore {
    /// Run `name` of the database (`None`: its one run), which must exist.
    ///
    /// # Errors
    /// No such run (the runs there are listed), more than one run without a name, database
    /// errors.
    pub fn open(db: &Database, name: Option<&str>) -> Result<Self, ResultsError> {
        let mut client = db.open()?;
        let all = runs(&mut client, db.shown())?;
        let names: Vec<&str> = all.iter().map(|r| r.name.as_str()).collect();
        let name = match name {
            Some(n) => n.to_owned(),
            None if all.len() == 1 => all[0].name.clone(),
            None => {
                return Err(refused(format!(
                    "{}: {}; name one with --run",
                    db.shown(),
                    if all.is_empty() {
                        "holds no run".to_owned()
                    } else {
                        format!("holds {} runs ({})", all.len(), names.join(", "))
                    }
                )));
            }
        };
        Self::find(db, client, &name)?.ok_or_else(|| {
            refused(format!(
                "{}: no run named {name:?} (runs: {})",
                db.shown(),
                if names.is_empty() {
                    "none".to_owned()
                } else {
                    names.join(", ")
                }
            ))
        })
    }

    fn find(db: &Database, mut client: Client, name: &str) -> Result<Option<Self>, ResultsError> {
        let row = client
            .query_opt(
                "SELECT id, run_manifest FROM study_runs WHERE name = $1",
                &[&name],
            )
            .map_err(|e| db_error(db.shown(), "reading the run", &e))?;
        let Some(row) = row else {
            return Ok(None);
        };
        let err = |e: postgres::Error| db_error(db.shown(), "reading the run", &e);
        let run_id: i32 = row.try_get(0).map_err(err)?;
        let path = Path::new(db.shown()).join(name).join(RUN_FILE);
        let run = from_json(row.try_get(1).map_err(err)?, &path)?;
        Ok(Some(Self {
            db: db.clone(),
            client: Conn::Own(client),
            pool: None,
            run_id,
            name: name.to_owned(),
            run,
            last_batch_bytes: 0,
        }))
    }

    /// Run `name`, created with `run` and `archive` when the database does not hold it
    /// (several stations may do this at once: one creates it, the others join it). Returns
    /// the store and whether it created the run.
    ///
    /// # Errors
    /// Database errors.
    pub fn open_or_create(
        db: &Database,
        name: &str,
        run: &RunManifest,
        archive: &Archive,
    ) -> Result<(Self, bool), ResultsError> {
        let mut client = db.open()?;
        let created = client
            .execute(
                "INSERT INTO study_runs (name, study, study_hash, manifest_hash, run_manifest, \
                 study_copy, manifest_copy) VALUES ($1, $2, $3, $4, $5, $6, $7) \
                 ON CONFLICT (name) DO NOTHING",
                &[
                    &name,
                    &run.study,
                    &run.study_hash,
                    &run.manifest_hash,
                    &json(run)?,
                    &archive.study_copy,
                    &archive.manifest_copy,
                ],
            )
            .map_err(|e| db_error(db.shown(), "creating the run", &e))?;
        let store = Self::find(db, client, name)?
            .ok_or_else(|| refused(format!("{}: run {name:?} vanished", db.shown())))?;
        Ok((store, created == 1))
    }

    /// The same run on a connection lent by `pool`, for one request of a server that shares
    /// its sessions with other processes: the sessions it creates or resumes are written by
    /// [`LeasedWriter`]s (each write one transaction holding the session's lock), so no
    /// session holds a connection between requests. The connection goes back to the pool
    /// when the store is dropped.
    ///
    /// # Errors
    /// No connection could be had.
    pub fn leased(&self, pool: &Arc<Pool>) -> Result<Self, ResultsError> {
        Ok(Self {
            db: self.db.clone(),
            client: Conn::Lent(pool.get()?),
            pool: Some(Arc::clone(pool)),
            run_id: self.run_id,
            name: self.name.clone(),
            run: self.run.clone(),
            last_batch_bytes: 0,
        })
    }

    /// The run's id in the database.
    pub fn run_id(&self) -> i32 {
        self.run_id
    }

    /// The store's connection, for queries of the run's other tables.
    ///
    /// # Errors
    /// The server cannot be reached.
    pub fn client(&mut self) -> Result<&mut Client, ResultsError> {
        self.conn()
    }

    /// The run's manifest.
    pub fn run(&self) -> &RunManifest {
        &self.run
    }

    /// The run's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The database.
    pub fn database(&self) -> &Database {
        &self.db
    }

    /// The store's connection, made again when the server closed it (a restart).
    fn conn(&mut self) -> Result<&mut Client, ResultsError> {
        if self.client.is_closed() {
            self.client = match &self.pool {
                Some(pool) => Conn::Lent(pool.get()?),
                None => Conn::Own(self.db.open()?),
            };
        }
        Ok(&mut self.client)
    }

    fn err(&self, op: &str) -> impl Fn(postgres::Error) -> ResultsError + use<> {
        let location = self.location();
        let op = op.to_owned();
        move |e| db_error(&location, &op, &e)
    }

    /// The run's between-subject group assignments, by group and place.
    ///
    /// # Errors
    /// Database errors.
    pub(crate) fn assignments(&mut self) -> Result<Vec<AssignedRow>, ResultsError> {
        let run_id = self.run_id;
        let err = self.err("reading the group assignments");
        let rows = self
            .conn()?
            .query(
                "SELECT subject, session, group_name, ordinal FROM study_group_assignments \
                 WHERE run_id = $1 ORDER BY group_name, ordinal",
                &[&run_id],
            )
            .map_err(&err)?;
        rows.iter()
            .map(|r| {
                let number = |i: usize| -> Result<u32, ResultsError> {
                    let n: i32 = r.try_get(i).map_err(&err)?;
                    u32::try_from(n).map_err(|_| refused(format!("group assignment value {n}")))
                };
                Ok(AssignedRow {
                    subject: r.try_get(0).map_err(&err)?,
                    session: number(1)?,
                    group: r.try_get(2).map_err(&err)?,
                    ordinal: number(3)?,
                })
            })
            .collect()
    }

    /// The study file and stimulus manifest kept with the run.
    ///
    /// # Errors
    /// Database errors.
    pub fn archive(&mut self) -> Result<Archive, ResultsError> {
        let run_id = self.run_id;
        let err = self.err("reading the archived study");
        let row = self
            .conn()?
            .query_one(
                "SELECT study_copy, manifest_copy FROM study_runs WHERE id = $1",
                &[&run_id],
            )
            .map_err(err)?;
        let err = self.err("reading the archived study");
        Ok(Archive {
            study_copy: row.try_get(0).map_err(&err)?,
            manifest_copy: row.try_get(1).map_err(err)?,
        })
    }

    /// A new subject number of the run, never given out before (to this or any station), and
    /// the subject id `id_of(number)` it is taken for (with the simulated observer's seed, for
    /// a simulated subject), recorded in one transaction;
    /// `None` when the run's counter is past `limit` (nothing is taken then). A station that
    /// stops before it creates the subject's session leaves the number in
    /// [`Self::unclaimed_numbers`], where a resume finds it.
    ///
    /// # Errors
    /// Database errors.
    pub fn take_subject_number(
        &mut self,
        limit: Option<u32>,
        id_of: &dyn Fn(u32) -> String,
        observer_seed: Option<u64>,
    ) -> Result<Option<(u32, String)>, ResultsError> {
        let run_id = self.run_id;
        let err = self.err("taking a subject number");
        let limit = limit.map(|l| i32::try_from(l).unwrap_or(i32::MAX));
        let mut tx = self.conn()?.transaction().map_err(&err)?;
        // The row lock of the run's counter holds other stations until the commit.
        let row = tx
            .query_opt(
                "UPDATE study_runs SET next_subject = next_subject + 1 \
                 WHERE id = $1 AND ($2::integer IS NULL OR next_subject <= $2) \
                 RETURNING next_subject - 1",
                &[&run_id, &limit],
            )
            .map_err(&err)?;
        let Some(row) = row else {
            tx.commit().map_err(&err)?;
            return Ok(None);
        };
        let n: i32 = row.try_get(0).map_err(&err)?;
        let number =
            u32::try_from(n).map_err(|_| refused(format!("subject number {n} is out of range")))?;
        let subject = id_of(number);
        tx.execute(
            "INSERT INTO study_subject_numbers (run_id, number, station, subject, observer_seed) \
             VALUES ($1, $2, $3, $4, $5)",
            &[
                &run_id,
                &n,
                &station(),
                &subject,
                &observer_seed.map(seed_to_sql),
            ],
        )
        .map_err(&err)?;
        tx.commit().map_err(err)?;
        Ok(Some((number, subject)))
    }

    /// The subject numbers taken for a subject that has no session in the run (a station
    /// stopped between taking the number and creating the session), with that subject and
    /// the station that took it, by number. Numbers taken before schema version 3 name no
    /// subject and are not listed.
    ///
    /// # Errors
    /// Database errors.
    pub fn unclaimed_numbers(&mut self) -> Result<Vec<UnclaimedNumber>, ResultsError> {
        let run_id = self.run_id;
        let err = self.err("reading the subject numbers");
        let rows = self
            .conn()?
            .query(
                "SELECT n.number, n.subject, n.station, n.observer_seed FROM study_subject_numbers n \
                 WHERE n.run_id = $1 AND n.subject IS NOT NULL AND NOT EXISTS \
                 (SELECT 1 FROM study_sessions s WHERE s.run_id = n.run_id AND s.subject = n.subject) \
                 ORDER BY n.number",
                &[&run_id],
            )
            .map_err(&err)?;
        rows.iter()
            .map(|r| {
                let n: i32 = r.try_get(0).map_err(&err)?;
                Ok(UnclaimedNumber {
                    number: u32::try_from(n)
                        .map_err(|_| refused(format!("subject number {n} is out of range")))?,
                    subject: r.try_get(1).map_err(&err)?,
                    station: r.try_get(2).map_err(&err)?,
                    observer_seed: r
                        .try_get::<_, Option<i64>>(3)
                        .map_err(&err)?
                        .map(seed_from_sql),
                })
            })
            .collect()
    }

    /// The run's sessions that are not finished and that no writer holds (a station died or
    /// stopped in them): what `study simulate --resume` continues.
    ///
    /// # Errors
    /// Database errors, a malformed manifest.
    pub fn abandoned(&mut self) -> Result<Vec<SessionManifest>, ResultsError> {
        let run_id = self.run_id;
        let rows = self
            .conn()?
            .query(
                "SELECT s.manifest FROM study_sessions s WHERE s.run_id = $1 \
                 AND s.status IN ('running', 'interrupted') AND NOT EXISTS (\
                 SELECT 1 FROM pg_locks l WHERE l.locktype = 'advisory' AND l.granted \
                 AND l.classid = $2::bigint::oid AND l.objid = s.id::bigint::oid \
                 AND l.objsubid = 2) ORDER BY s.id",
                &[&run_id, &i64::from(LOCK_NAMESPACE)],
            )
            .map_err(self.err("listing abandoned sessions"))?;
        let path = Path::new(&self.location()).join(SESSION_FILE);
        rows.iter()
            .map(|r| from_json(r.try_get(0).map_err(self.err("listing sessions"))?, &path))
            .collect()
    }

    /// Every session of the run, sorted as a results folder's session folders are (by
    /// `<subject>_s<n>`, bytewise).
    ///
    /// # Errors
    /// Database errors, a malformed manifest, more than [`MAX_SESSIONS`] sessions.
    pub fn sessions(&mut self) -> Result<Vec<SessionHead>, ResultsError> {
        let run_id = self.run_id;
        // The manifest as text, parsed straight into its type (not through a JSON tree).
        let rows = self
            .conn()?
            .query(
                "SELECT id, subject, session, manifest::text, trials_format_version \
                 FROM study_sessions WHERE run_id = $1",
                &[&run_id],
            )
            .map_err(self.err("listing the sessions"))?;
        if rows.len() > MAX_SESSIONS {
            return Err(ResultsError::TooLarge {
                path: PathBuf::from(self.location()),
                bytes: rows.len() as u64,
                limit: MAX_SESSIONS as u64,
            });
        }
        let location = self.location();
        let head = |r: &postgres::Row| -> Result<SessionHead, ResultsError> {
            let err = |e: postgres::Error| db_error(&location, "listing the sessions", &e);
            let subject: &str = r.try_get(1).map_err(err)?;
            let session: i32 = r.try_get(2).map_err(err)?;
            let session = u32::try_from(session).unwrap_or(0);
            let dir = Path::new(&location).join(session_name(subject, session));
            let version: i32 = r.try_get(4).map_err(err)?;
            let manifest: &str = r.try_get(3).map_err(err)?;
            Ok(SessionHead {
                id: r.try_get(0).map_err(err)?,
                version: u32::try_from(version).unwrap_or(0),
                manifest: serde_json::from_str(manifest).map_err(|e| ResultsError::Malformed {
                    path: dir.join(SESSION_FILE),
                    line: e.line(),
                    column: e.column(),
                    message: e.to_string(),
                })?,
                dir,
            })
        };
        // Parsing the manifests is most of listing a large run: on every core.
        let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
        let part = rows.len().div_ceil(threads).max(1);
        let mut heads = std::thread::scope(|scope| {
            let parts: Vec<_> = rows
                .chunks(part)
                .map(|rows| scope.spawn(|| rows.iter().map(head).collect::<Result<Vec<_>, _>>()))
                .collect();
            let mut heads = Vec::with_capacity(rows.len());
            for p in parts {
                heads.extend(p.join().unwrap_or_else(|e| std::panic::resume_unwind(e))?);
            }
            Ok::<_, ResultsError>(heads)
        })?;
        heads.sort_by(|a, b| a.dir.as_os_str().cmp(b.dir.as_os_str()));
        Ok(heads)
    }

    /// The manifests and rows of `heads` (sessions of this run), in their order.
    ///
    /// # Errors
    /// Database errors, a row that does not decode (named by session, line and column).
    pub fn read(&mut self, heads: &[SessionHead]) -> Result<Vec<SessionResults>, ResultsError> {
        self.read_rows(heads)?
            .iter()
            .zip(heads)
            .map(|(rows, head)| decode_session(head, rows))
            .collect()
    }

    /// The rows of `heads` (sessions of this run) as the server sent them, one
    /// [`SessionRows`] per session in their order, for [`decode_session`] (which another
    /// thread may run: decoding is most of a read's work on the client).
    ///
    /// The rows come as a binary `COPY` (no per-row message parsing into `Row`s, no per-column
    /// type lookups: a third of the client's work in a report from the database before).
    /// `COPY` takes no parameters, so the session ids travel as one, a setting of this
    /// connection that the statement reads: no value is ever written into the SQL.
    ///
    /// # Errors
    /// Database errors; rows that are not the binary `COPY` of the columns asked for; more
    /// than [`crate::trials::MAX_TRIALS_BYTES`] of rows in one call.
    pub fn read_rows(&mut self, heads: &[SessionHead]) -> Result<Vec<SessionRows>, ResultsError> {
        use std::io::Read;
        let op = "reading the answers";
        let err = self.err(op);
        let location = self.location();
        let ids = heads
            .iter()
            .map(|h| h.id.to_string())
            .collect::<Vec<_>>()
            .join(",");
        let expected = self.last_batch_bytes;
        let conn = self.conn()?;
        conn.execute(
            "SELECT set_config('study.read_sessions', $1, false)",
            &[&format!("{{{ids}}}")],
        )
        .map_err(&err)?;
        let reader = conn
            .copy_out(&format!(
                "COPY (SELECT {} FROM study_trials \
                 WHERE session_id = ANY(current_setting('study.read_sessions')::integer[]) \
                 ORDER BY session_id, row_number) TO STDOUT (FORMAT binary)",
                rows::SELECT_COLUMNS
            ))
            .map_err(&err)?;
        let limit = crate::trials::MAX_TRIALS_BYTES;
        // Room for a batch as large as the last one, so that the stream is not copied again
        // each time the buffer doubles.
        let mut all = Vec::with_capacity(expected);
        let bad = |message: String| ResultsError::Database {
            location: location.clone(),
            op: op.to_owned(),
            message,
        };
        reader.take(limit + 1).read_to_end(&mut all).map_err(|e| {
            match e
                .get_ref()
                .and_then(|c| c.downcast_ref::<postgres::Error>())
            {
                Some(e) => db_error(&location, op, e),
                None => bad(e.to_string()),
            }
        })?;
        if all.len() as u64 > limit {
            return Err(ResultsError::TooLarge {
                path: PathBuf::from(&location),
                bytes: all.len() as u64,
                limit,
            });
        }
        self.last_batch_bytes = all.len() + all.len() / 8;
        // The rows of one session are consecutive (ordered by session id): each session is
        // a range of the one buffer, shared.
        let at: HashMap<i32, usize> = heads.iter().enumerate().map(|(i, h)| (h.id, i)).collect();
        let mut ranges: Vec<Option<std::ops::Range<usize>>> = vec![None; heads.len()];
        let mut stream = rows::CopyRows::stream(&all).map_err(bad)?;
        let mut last: Option<(i32, Option<usize>)> = None;
        while let Some(row) = stream.next().map_err(bad)? {
            let id = row
                .int4(0)
                .map_err(|(_, m)| bad(format!("session_id: {m}")))?;
            let i = match last {
                Some((was, i)) if was == id => i,
                _ => at.get(&id).copied(),
            };
            last = Some((id, i));
            let Some(i) = i else { continue };
            match &mut ranges[i] {
                Some(r) if r.end == row.span.start => r.end = row.span.end,
                Some(_) => return Err(bad(format!("the rows of session {id} are not together"))),
                r @ None => *r = Some(row.span),
            }
        }
        let all = std::sync::Arc::new(all);
        Ok(ranges
            .into_iter()
            .map(|r| SessionRows {
                batch: std::sync::Arc::clone(&all),
                rows: r.unwrap_or(0..0),
            })
            .collect())
    }

    /// The files kept with `head` beside its rows (`frames.csv`, rows set aside as torn by a
    /// folder before it was imported), by name, each whole.
    ///
    /// # Errors
    /// Database errors.
    pub fn files(&mut self, head: &SessionHead) -> Result<Vec<(String, Vec<u8>)>, ResultsError> {
        let rows = self
            .conn()?
            .query(
                "SELECT name, bytes FROM study_session_files WHERE session_id = $1 \
                 ORDER BY name, part",
                &[&head.id],
            )
            .map_err(self.err("reading the session's files"))?;
        let mut out: Vec<(String, Vec<u8>)> = Vec::new();
        for r in &rows {
            let name: String = r.try_get(0).map_err(self.err("reading files"))?;
            let bytes: Vec<u8> = r.try_get(1).map_err(self.err("reading files"))?;
            match out.last_mut() {
                Some((last, all)) if *last == name => all.extend_from_slice(&bytes),
                _ => out.push((name, bytes)),
            }
        }
        Ok(out)
    }

    fn holder(&mut self, id: i32) -> String {
        let Ok(client) = self.conn() else {
            return "another station".into();
        };
        let row = client.query_opt(
            "SELECT a.application_name, host(a.client_addr) FROM pg_locks l \
             JOIN pg_stat_activity a ON a.pid = l.pid WHERE l.locktype = 'advisory' \
             AND l.granted AND l.classid = $1::bigint::oid AND l.objid = $2::bigint::oid \
             AND l.objsubid = 2",
            &[&i64::from(LOCK_NAMESPACE), &i64::from(id)],
        );
        describe_holder(row)
    }

    fn session_id(&mut self, subject: &str, session: u32) -> Result<Option<i32>, ResultsError> {
        let run_id = self.run_id;
        let session = i32::try_from(session).map_err(|_| refused("session number too large"))?;
        let row = self
            .conn()?
            .query_opt(
                "SELECT id FROM study_sessions WHERE run_id = $1 AND subject = $2 AND session = $3",
                &[&run_id, &subject, &session],
            )
            .map_err(self.err("finding the session"))?;
        row.map(|r| r.try_get(0))
            .transpose()
            .map_err(self.err("finding the session"))
    }
}

impl PgStore {
    /// The committed rows of `subject`'s `session` (none when it does not exist).
    ///
    /// # Errors
    /// Database errors.
    pub fn session_records(
        &mut self,
        subject: &str,
        session: u32,
    ) -> Result<Vec<TrialRecord>, ResultsError> {
        let path = self.session_path(subject, session);
        match self.session_id(subject, session)? {
            Some(id) => self.committed(subject, session, id, &path),
            None => Ok(Vec::new()),
        }
    }

    /// The committed rows of session `id` (`subject`'s `session`, named `path`).
    fn committed(
        &mut self,
        subject: &str,
        session: u32,
        id: i32,
        path: &Path,
    ) -> Result<Vec<TrialRecord>, ResultsError> {
        let head = SessionHead {
            id,
            version: TRIALS_FORMAT_VERSION,
            dir: path.to_path_buf(),
            manifest: match self.find_session(subject, session)? {
                Found::Present(Some(m)) => *m,
                _ => return Err(refused(format!("{}: no such session", path.display()))),
            },
        };
        let mut read = self.read(std::slice::from_ref(&head))?;
        Ok(read.pop().map(|s| s.trials.records).unwrap_or_default())
    }
}

fn describe_holder(row: Result<Option<postgres::Row>, postgres::Error>) -> String {
    match row {
        Ok(Some(r)) => {
            let app: Option<String> = r.try_get(0).ok().flatten();
            let addr: Option<String> = r.try_get(1).ok().flatten();
            match (app.filter(|a| !a.is_empty()), addr) {
                (Some(app), Some(addr)) => format!("{app} at {addr}"),
                (Some(app), None) => app,
                (None, Some(addr)) => format!("a connection from {addr}"),
                (None, None) => "another connection".into(),
            }
        }
        _ => "another station".into(),
    }
}

impl Store for PgStore {
    fn location(&self) -> String {
        format!("{}/{}", self.db.shown(), self.name)
    }

    fn session_path(&self, subject: &str, session: u32) -> PathBuf {
        Path::new(&self.location()).join(session_name(subject, session))
    }

    fn find_session(&mut self, subject: &str, session: u32) -> Result<Found, ResultsError> {
        let run_id = self.run_id;
        let s = i32::try_from(session).map_err(|_| refused("session number too large"))?;
        let row = self
            .conn()?
            .query_opt(
                "SELECT manifest FROM study_sessions WHERE run_id = $1 AND subject = $2 AND session = $3",
                &[&run_id, &subject, &s],
            )
            .map_err(self.err("finding the session"))?;
        let path = self.session_path(subject, session).join(SESSION_FILE);
        Ok(match row {
            None => Found::Absent,
            Some(r) => Found::Present(Some(Box::new(from_json(
                r.try_get(0).map_err(self.err("finding the session"))?,
                &path,
            )?))),
        })
    }

    fn create_session(
        &mut self,
        manifest: &SessionManifest,
    ) -> Result<Box<dyn SessionWriter>, ResultsError> {
        let path = self.session_path(&manifest.subject, manifest.session);
        let location = self.location();
        let err = |e: postgres::Error| db_error(&location, "creating the session", &e);
        let leased = self.pool.clone();
        let mut client = match &leased {
            Some(pool) => Conn::Lent(pool.get()?),
            None => Conn::Own(self.db.connect()?),
        };
        let session =
            i32::try_from(manifest.session).map_err(|_| refused("session number too large"))?;
        let version = TRIALS_FORMAT_VERSION as i32;
        let mut tx = client.transaction().map_err(err)?;
        let row = tx
            .query_opt(
                "INSERT INTO study_sessions (run_id, subject, session, study_hash, manifest_hash, \
                 status, trials_logged, trials_format_version, manifest) \
                 VALUES ($1, $2, $3, $4, $5, $6, 0, $7, $8) \
                 ON CONFLICT (run_id, subject, session) DO NOTHING RETURNING id",
                &[
                    &self.run_id,
                    &manifest.subject,
                    &session,
                    &manifest.study_hash,
                    &manifest.manifest_hash,
                    &state_name(manifest.status),
                    &version,
                    &json(manifest)?,
                ],
            )
            .map_err(err)?;
        let Some(row) = row else {
            return Err(ResultsError::Exists { path });
        };
        let id: i32 = row.try_get(0).map_err(err)?;
        if let Some(pool) = leased {
            tx.commit().map_err(err)?;
            return Ok(Box::new(LeasedWriter::new(pool, id, 0, path)));
        }
        // Taken before the row is visible to anyone: no other station can hold it first.
        tx.execute("SELECT pg_advisory_lock($1, $2)", &[&LOCK_NAMESPACE, &id])
            .map_err(err)?;
        tx.commit().map_err(err)?;
        let Conn::Own(client) = client else {
            return Err(refused("a station's session on a lent connection"));
        };
        Ok(Box::new(PgWriter::new(
            self.db.clone(),
            client,
            id,
            0,
            path,
        )))
    }

    fn resume_session(
        &mut self,
        subject: &str,
        session: u32,
    ) -> Result<ResumedSession, ResultsError> {
        let path = self.session_path(subject, session);
        let Some(id) = self.session_id(subject, session)? else {
            return Err(refused(format!("{}: no such session", path.display())));
        };
        if let Some(pool) = self.pool.clone() {
            let records = self.committed(subject, session, id, &path)?;
            let rows = records.len() as u32;
            return Ok(ResumedSession {
                writer: Box::new(LeasedWriter::new(pool, id, rows, path)),
                records,
                torn: None,
            });
        }
        let location = self.location();
        let err = |e: postgres::Error| db_error(&location, "resuming the session", &e);
        let mut client = self.db.connect()?;
        let locked: bool = client
            .query_one(
                "SELECT pg_try_advisory_lock($1, $2)",
                &[&LOCK_NAMESPACE, &id],
            )
            .and_then(|r| r.try_get(0))
            .map_err(err)?;
        if !locked {
            return Err(ResultsError::SessionBusy {
                session: path,
                holder: self.holder(id),
            });
        }
        let records = self.committed(subject, session, id, &path)?;
        let rows = records.len() as u32;
        Ok(ResumedSession {
            writer: Box::new(PgWriter::new(self.db.clone(), client, id, rows, path)),
            records,
            torn: None,
        })
    }

    fn check_not_held(&mut self, subject: &str, session: u32) -> Result<(), ResultsError> {
        let Some(id) = self.session_id(subject, session)? else {
            return Ok(());
        };
        let free: bool = self
            .conn()?
            .query_one(
                "SELECT pg_try_advisory_lock($1, $2)",
                &[&LOCK_NAMESPACE, &id],
            )
            .and_then(|r| r.try_get(0))
            .map_err(self.err("checking the session's lock"))?;
        if !free {
            return Err(ResultsError::SessionBusy {
                session: self.session_path(subject, session),
                holder: self.holder(id),
            });
        }
        self.conn()?
            .execute("SELECT pg_advisory_unlock($1, $2)", &[&LOCK_NAMESPACE, &id])
            .map_err(self.err("checking the session's lock"))?;
        Ok(())
    }

    fn discard_unstarted(&mut self, subject: &str, session: u32) -> Result<bool, ResultsError> {
        let Some(id) = self.session_id(subject, session)? else {
            return Ok(false);
        };
        let err = self.err("discarding the unstarted session");
        let mut tx = self.conn()?.transaction().map_err(err)?;
        let err = |e| db_error("", "discarding the unstarted session", &e);
        let locked: bool = tx
            .query_one(
                "SELECT pg_try_advisory_xact_lock($1, $2)",
                &[&LOCK_NAMESPACE, &id],
            )
            .and_then(|r| r.try_get(0))
            .map_err(err)?;
        if !locked {
            return Ok(false);
        }
        tx.execute(
            "DELETE FROM study_session_files WHERE session_id = $1",
            &[&id],
        )
        .map_err(err)?;
        let gone = tx
            .execute(
                "DELETE FROM study_sessions s WHERE id = $1 AND trials_logged = 0 \
                 AND coalesce((manifest->>'resumes')::integer, 0) = 0 \
                 AND NOT EXISTS (SELECT 1 FROM study_trials t WHERE t.session_id = s.id)",
                &[&id],
            )
            .map_err(err)?;
        tx.commit().map_err(err)?;
        Ok(gone == 1)
    }

    fn assign_group(
        &mut self,
        subject: &str,
        session: u32,
        groups: &[GroupQuota<'_>],
        wanted: Option<&str>,
    ) -> Result<Assignment, ResultsError> {
        let (run_id, location) = (self.run_id, self.location());
        let session_no = i32::try_from(session)
            .map_err(|_| refused(format!("session number {session} is out of range")))?;
        let op = "assigning a between-subject group";
        let err = |e| db_error(&location, op, &e);
        let mut tx = self.conn()?.transaction().map_err(err)?;
        // One assignment of this run at a time, on every station: the run's row is locked
        // until this transaction ends.
        tx.execute(
            "SELECT 1 FROM study_runs WHERE id = $1 FOR UPDATE",
            &[&run_id],
        )
        .map_err(err)?;
        let before = tx
            .query_opt(
                "SELECT group_name, ordinal FROM study_group_assignments \
                 WHERE run_id = $1 AND subject = $2 AND session = $3",
                &[&run_id, &subject, &session_no],
            )
            .map_err(err)?;
        let ordinal = |n: i32| {
            u32::try_from(n).map_err(|_| refused(format!("{location}: group ordinal {n}")))
        };
        if let Some(row) = before {
            return Ok(Assignment {
                group: row.try_get(0).map_err(err)?,
                ordinal: ordinal(row.try_get(1).map_err(err)?)?,
                new: false,
            });
        }
        let names: Vec<&str> = groups.iter().map(|g| g.name).collect();
        let counted = tx
            .query(
                "SELECT group_name, count(*) FROM study_group_assignments \
                 WHERE run_id = $1 AND group_name = ANY($2) GROUP BY group_name",
                &[&run_id, &names],
            )
            .map_err(err)?;
        let mut counts = vec![0_u32; groups.len()];
        for row in &counted {
            let name: &str = row.try_get(0).map_err(err)?;
            let n: i64 = row.try_get(1).map_err(err)?;
            if let Some(i) = names.iter().position(|g| *g == name) {
                counts[i] = u32::try_from(n).unwrap_or(u32::MAX);
            }
        }
        let i = choose_group(groups, &counts, wanted)
            .map_err(|why| refused(format!("{location}: {why}")))?;
        let assignment = Assignment {
            group: groups[i].name.to_owned(),
            ordinal: counts[i],
            new: true,
        };
        let place = i32::try_from(assignment.ordinal)
            .map_err(|_| refused(format!("{location}: group ordinal out of range")))?;
        tx.execute(
            "INSERT INTO study_group_assignments \
             (run_id, subject, session, group_name, ordinal, station) \
             VALUES ($1, $2, $3, $4, $5, $6)",
            &[
                &run_id,
                &subject,
                &session_no,
                &assignment.group,
                &place,
                &station(),
            ],
        )
        .map_err(err)?;
        tx.commit().map_err(err)?;
        Ok(assignment)
    }
}

/// A database session open for rows: its own connection, which holds the session's lock.
pub struct PgWriter {
    db: Database,
    client: Option<Client>,
    append: Option<Statement>,
    id: i32,
    rows: u32,
    path: PathBuf,
    /// Rows found committed after a reconnect, not yet reconciled with the pending row.
    recount: Option<u32>,
    /// Parts of `frames.csv` written so far, once known.
    frame_parts: Option<i32>,
}

impl PgWriter {
    fn new(db: Database, client: Client, id: i32, rows: u32, path: PathBuf) -> Self {
        Self {
            db,
            client: Some(client),
            append: None,
            id,
            rows,
            path,
            recount: None,
            frame_parts: None,
        }
    }

    fn location(&self) -> String {
        self.path.display().to_string()
    }

    /// The error for `e` met doing `op`; an outage drops the connection so that the next
    /// call reconnects.
    fn fail(&mut self, op: &str, e: &postgres::Error) -> ResultsError {
        let err = db_error(&self.location(), op, e);
        if matches!(err, ResultsError::Unavailable { .. }) {
            self.client = None;
            self.append = None;
        }
        err
    }

    /// The connection, reconnected (and the session's lock taken again, and the committed
    /// rows counted) when it was lost.
    fn client(&mut self) -> Result<&mut Client, ResultsError> {
        if self.client.as_ref().is_some_and(Client::is_closed) {
            self.client = None;
            self.append = None;
        }
        if self.client.is_none() {
            let mut client = self.db.connect().map_err(|e| match e {
                ResultsError::Unavailable { op, message, .. } => ResultsError::Unavailable {
                    location: self.location(),
                    op,
                    message,
                },
                other => other,
            })?;
            let location = self.location();
            let err = |e: postgres::Error| db_error(&location, "taking the session again", &e);
            let locked: bool = client
                .query_one(
                    "SELECT pg_try_advisory_lock($1, $2)",
                    &[&LOCK_NAMESPACE, &self.id],
                )
                .and_then(|r| r.try_get(0))
                .map_err(err)?;
            if !locked {
                return Err(ResultsError::SessionBusy {
                    session: self.path.clone(),
                    holder:
                        "another station, which took the session over while the database was away"
                            .into(),
                });
            }
            let n: i64 = client
                .query_one(
                    "SELECT count(*) FROM study_trials WHERE session_id = $1",
                    &[&self.id],
                )
                .and_then(|r| r.try_get(0))
                .map_err(err)?;
            self.recount = Some(u32::try_from(n).unwrap_or(u32::MAX));
            self.frame_parts = None;
            self.client = Some(client);
        }
        self.client.as_mut().ok_or_else(|| refused("no connection"))
    }

    fn update_manifest(&mut self, manifest: &SessionManifest) -> Result<(), ResultsError> {
        let value = json(manifest)?;
        let id = self.id;
        let status = state_name(manifest.status);
        // `trials_logged` counts the rows: each answer's insert sets it.
        let result = self.client()?.execute(
            "UPDATE study_sessions SET manifest = $2, status = $3 WHERE id = $1",
            &[&id, &value, &status],
        );
        match result {
            Ok(1) => Ok(()),
            Ok(_) => Err(refused(format!(
                "{}: the session's manifest was not updated (is its lock still held?)",
                self.location()
            ))),
            Err(e) => Err(self.fail("writing the session's manifest", &e)),
        }
    }
}

impl SessionWriter for PgWriter {
    fn rows(&self) -> u32 {
        self.rows
    }

    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    fn append(&mut self, record: &TrialRecord) -> Result<(), ResultsError> {
        let params = rows::Values::of(record)?;
        self.client()?;
        if let Some(found) = self.recount.take() {
            if found == self.rows + 1 {
                // The answer was committed before the connection was lost.
                self.rows = found;
                return Ok(());
            }
            if found != self.rows {
                return Err(refused(format!(
                    "{}: {found} answers are committed, this station expected {}; resume the session",
                    self.location(),
                    self.rows
                )));
            }
        }
        if self.append.is_none() {
            let prepared = self.client()?.prepare(&rows::append_sql());
            match prepared {
                Ok(s) => self.append = Some(s),
                Err(e) => return Err(self.fail("preparing the answer's insert", &e)),
            }
        }
        let statement = self.append.clone().ok_or_else(|| refused("no statement"))?;
        let row_number = i32::try_from(self.rows).map_err(|_| refused("too many rows"))?;
        let mut all: Vec<&(dyn postgres::types::ToSql + Sync)> = vec![&self.id, &row_number];
        let values = params.refs();
        all.extend_from_slice(&values);
        let result = self
            .client
            .as_mut()
            .ok_or_else(|| refused("no connection"))?
            .execute(&statement, &all);
        match result {
            Ok(1) => {
                self.rows += 1;
                Ok(())
            }
            Ok(_) => Err(refused(format!(
                "{}: the answer was not committed (is the session's lock still held?)",
                self.location()
            ))),
            Err(e) => Err(self.fail("committing an answer", &e)),
        }
    }

    fn write_manifest(&mut self, manifest: &SessionManifest) -> Result<(), ResultsError> {
        self.update_manifest(manifest)
    }

    fn append_frames(
        &mut self,
        index: u32,
        intervals: &[f64],
        phases: &[&str],
    ) -> Result<(), ResultsError> {
        let id = self.id;
        if self.frame_parts.is_none() {
            let result = self.client()?.query_one(
                "SELECT count(*)::integer FROM study_session_files WHERE session_id = $1 AND name = $2",
                &[&id, &FRAMES_FILE],
            );
            let n: i32 = match result.and_then(|r| r.try_get(0)) {
                Ok(n) => n,
                Err(e) => return Err(self.fail("reading frames.csv", &e)),
            };
            self.frame_parts = Some(n);
        }
        let part = self.frame_parts.unwrap_or(0);
        let text = frames_text(part == 0, index, intervals, phases, true);
        let result = self.client()?.execute(
            "INSERT INTO study_session_files (session_id, name, part, bytes) VALUES ($1, $2, $3, $4)",
            &[&id, &FRAMES_FILE, &part, &text.as_bytes()],
        );
        match result {
            Ok(_) => {
                self.frame_parts = Some(part + 1);
                Ok(())
            }
            Err(e) => Err(self.fail("appending to frames.csv", &e)),
        }
    }
}

/// Writes run `store` as a results folder `out` (which must not exist or be empty): `run.json`,
/// the archived study file and stimulus manifest, and one folder per session with its
/// `trials.csv`, `session.json` and kept files, each written whole (temporary name, fsync,
/// rename). Returns the number of sessions.
///
/// # Errors
/// `out` holds anything, database errors, I/O errors.
pub fn export(store: &mut PgStore, out: &Path) -> Result<usize, ResultsError> {
    files::prepare_dir(out, files::Mode::New).map_err(|e| refused(e.to_string()))?;
    let archive = store.archive()?;
    let run = serde_json::to_vec_pretty(store.run()).map_err(|e| ResultsError::Unwritable {
        column: "run.json",
        reason: e.to_string(),
    })?;
    write_new(&out.join(RUN_FILE), &run)?;
    write_new(&out.join(STUDY_COPY), &archive.study_copy)?;
    write_new(&out.join(MANIFEST_COPY), &archive.manifest_copy)?;
    let heads = store.sessions()?;
    for batch in heads.chunks(256) {
        let sessions = store.read(batch)?;
        for (head, s) in batch.iter().zip(sessions) {
            let m = &s.manifest;
            let dir = out.join(session_name(&m.subject, m.session));
            std::fs::create_dir(&dir).map_err(|cause| ResultsError::Io {
                path: dir.clone(),
                op: "create directory",
                cause,
            })?;
            let header = header_of(s.trials.format_version).ok_or_else(|| {
                refused(format!(
                    "{}: trials format version {} is not one this build writes",
                    head.dir.display(),
                    s.trials.format_version
                ))
            })?;
            let mut text = String::with_capacity(64 + s.trials.records.len() * 256);
            text.push_str(header);
            text.push('\n');
            for r in &s.trials.records {
                text.push_str(&encode_row_as(r, s.trials.format_version)?);
            }
            write_new(&dir.join(TRIALS_FILE), text.as_bytes())?;
            write_json(&dir.join(SESSION_FILE), m)?;
            for (name, bytes) in store.files(head)? {
                if name.contains(['/', '\\']) || name.starts_with('.') || name.is_empty() {
                    return Err(refused(format!(
                        "{}: kept file name {name:?} cannot name a file",
                        head.dir.display()
                    )));
                }
                write_new(&dir.join(&name), &bytes)?;
            }
        }
    }
    let assigned = store.assignments()?;
    if !assigned.is_empty() {
        write_new(
            &out.join(GROUPS_FILE),
            assignments_csv(&assigned).as_bytes(),
        )?;
    }
    crate::store::sync_dir(out)?;
    Ok(heads.len())
}

/// Folder `dir`'s group assignments (`groups.csv`), to be imported into `store`'s run, which
/// must have none of its own (two records of places in the same groups would give places
/// twice).
fn folder_assignments(store: &mut PgStore, dir: &Path) -> Result<Vec<AssignedRow>, ResultsError> {
    let assigned = read_assignments(&dir.join(GROUPS_FILE))?;
    if !assigned.is_empty() && !store.assignments()?.is_empty() {
        return Err(refused(format!(
            "{}: {} assigns sessions to between-subject groups, and so does run {}; import \
             into a new run (--run NAME); nothing was imported",
            dir.join(GROUPS_FILE).display(),
            dir.display(),
            store.location()
        )));
    }
    Ok(assigned)
}

/// Records what a folder keeps beside its sessions' rows in run `run_id`, as imported: the
/// kept files (session id, name, bytes) and the group assignments (`groups.csv`).
fn insert_kept(
    tx: &mut postgres::Transaction<'_>,
    run_id: i32,
    kept: &[(i32, String, Vec<u8>)],
    assigned: &[AssignedRow],
) -> Result<(), postgres::Error> {
    for (id, file, bytes) in kept {
        tx.execute(
            "INSERT INTO study_session_files (session_id, name, part, bytes) VALUES ($1, $2, 0, $3)",
            &[id, file, bytes],
        )?;
    }
    let importer = format!("{} (import)", station());
    let number = |n: u32| i32::try_from(n).unwrap_or(i32::MAX);
    for a in assigned {
        tx.execute(
            "INSERT INTO study_group_assignments \
             (run_id, subject, session, group_name, ordinal, station) \
             VALUES ($1, $2, $3, $4, $5, $6)",
            &[
                &run_id,
                &a.subject,
                &number(a.session),
                &a.group,
                &number(a.ordinal),
                &importer,
            ],
        )?;
    }
    Ok(())
}

/// Loads results folder `dir` into run `name` of `db` (by default its study's name), created
/// with the folder's run manifest and archived study when the database does not hold it. All
/// or nothing, in one transaction; refused before anything is written when a session is
/// already in the run (or twice in the folder), when a session's last row is torn, when the
/// run holds another study, or when the folder and the run both assign between-subject
/// groups (`groups.csv`, which is loaded with the sessions). Returns the run's name and the
/// sessions loaded.
///
/// # Errors
/// As above; malformed files (named by file, line and column); database errors.
pub fn import(
    db: &Database,
    dir: &Path,
    name: Option<&str>,
) -> Result<(String, usize), ResultsError> {
    let (run, dirs) = session_dirs(dir)?;
    let read = |f: &str| read_limited(&dir.join(f), crate::store::MAX_MANIFEST_BYTES);
    let archive = Archive {
        study_copy: read(&run.study_file)?,
        manifest_copy: read(MANIFEST_COPY)?,
    };
    let name = name.unwrap_or(&run.study).to_owned();
    let (mut store, _) = PgStore::open_or_create(db, &name, &run, &archive)?;
    if store.run.study != run.study {
        return Err(refused(format!(
            "{}: run {name:?} holds study {:?}; {} is study {:?}",
            db.shown(),
            store.run.study,
            dir.display(),
            run.study
        )));
    }
    let manifests: Vec<SessionManifest> = dirs
        .iter()
        .map(|d| read_manifest(&d.join(SESSION_FILE)))
        .collect::<Result<_, _>>()?;
    check_new_sessions(&mut store, dir, &dirs, &manifests)?;
    let assigned = folder_assignments(&mut store, dir)?;
    let location = store.location();
    let err = |e: postgres::Error| db_error(&location, "importing", &e);
    let run_id = store.run_id;
    let mut tx = store.conn()?.transaction().map_err(err)?;
    let mut ids = Vec::with_capacity(dirs.len());
    let insert = tx
        .prepare(
            "INSERT INTO study_sessions (run_id, subject, session, study_hash, manifest_hash, \
             status, trials_logged, trials_format_version, manifest) \
             VALUES ($1, $2, $3, $4, $5, $6, 0, $7, $8) RETURNING id",
        )
        .map_err(err)?;
    for m in &manifests {
        // The trials format version and the rows' count are set once the rows are in, below.
        let row = tx
            .query_one(
                &insert,
                &[
                    &run_id,
                    &m.subject,
                    &(i32::try_from(m.session).unwrap_or(i32::MAX)),
                    &m.study_hash,
                    &m.manifest_hash,
                    &state_name(m.status),
                    &0_i32,
                    &json(m)?,
                ],
            )
            .map_err(err)?;
        ids.push(row.try_get::<_, i32>(0).map_err(err)?);
    }
    // Every answer in one binary COPY, each session's file read once, as it is written.
    let sink = tx
        .copy_in(&format!(
            "COPY study_trials (session_id, row_number, {}) FROM STDIN (FORMAT binary)",
            rows::COLUMNS
        ))
        .map_err(err)?;
    let mut types = vec![postgres::types::Type::INT4, postgres::types::Type::INT4];
    types.extend(rows::types());
    let mut writer = postgres::binary_copy::BinaryCopyInWriter::new(sink, &types);
    let mut kept = Vec::new();
    let mut versions = Vec::with_capacity(ids.len());
    for (d, &id) in dirs.iter().zip(&ids) {
        let trials = read_trials(&d.join(TRIALS_FILE))?;
        if let Some(t) = &trials.torn {
            return Err(refused(format!(
                "{}: line {} is torn (the session stopped mid-write); resume it (`--resume` sets \
                 the row aside) before importing; nothing was imported",
                d.join(TRIALS_FILE).display(),
                t.line
            )));
        }
        versions.push(trials.format_version as i32);
        for (i, r) in trials.records.iter().enumerate() {
            let params = rows::Values::of(r)?;
            let n = i as i32;
            let mut all: Vec<&(dyn postgres::types::ToSql + Sync)> = vec![&id, &n];
            all.extend_from_slice(&params.refs());
            writer.write(&all).map_err(err)?;
        }
        kept.extend(kept_files(d)?.into_iter().map(|(f, b)| (id, f, b)));
    }
    writer.finish().map_err(err)?;
    insert_kept(&mut tx, run_id, &kept, &assigned).map_err(err)?;
    tx.execute(
        "UPDATE study_sessions s SET trials_format_version = v.version, trials_logged = \
         (SELECT count(*) FROM study_trials t WHERE t.session_id = s.id) \
         FROM unnest($1::integer[], $2::integer[]) AS v(id, version) WHERE s.id = v.id",
        &[&ids, &versions],
    )
    .map_err(err)?;
    tx.commit().map_err(err)?;
    vacuum_imported(&mut store, ids.len())?;
    Ok((name, ids.len()))
}

/// Vacuums and analyses the tables an import of `sessions` sessions loaded. A bulk load
/// leaves each new row's visibility to be settled by its first reader (who then writes the
/// page back) and the planner without statistics: the first report after an import paid
/// for both. A role that does not own the tables gets a warning from the server, and
/// nothing is vacuumed.
///
/// # Errors
/// Database errors (the message says the import itself is committed).
fn vacuum_imported(store: &mut PgStore, sessions: usize) -> Result<(), ResultsError> {
    let op = format!("vacuuming after the import (its {sessions} sessions are committed)");
    let err = store.err(&op);
    store
        .conn()?
        .batch_execute("VACUUM (ANALYZE) study_trials, study_sessions, study_session_files")
        .map_err(err)
}

/// Refuses an import whose sessions (`manifests`, of folders `dirs` in `dir`) are in the
/// folder twice or in the run already.
fn check_new_sessions(
    store: &mut PgStore,
    dir: &Path,
    dirs: &[PathBuf],
    manifests: &[SessionManifest],
) -> Result<(), ResultsError> {
    let mut seen: HashMap<(String, u32), &Path> = HashMap::new();
    for (m, d) in manifests.iter().zip(dirs) {
        if let Some(first) = seen.insert((m.subject.clone(), m.session), d) {
            return Err(refused(format!(
                "{}: subject {:?} session {} is also in {}; nothing was imported",
                d.display(),
                m.subject,
                m.session,
                first.display()
            )));
        }
    }
    let existing: HashSet<(String, u32)> = store
        .sessions()?
        .into_iter()
        .map(|h| (h.manifest.subject, h.manifest.session))
        .collect();
    let dup: Vec<String> = manifests
        .iter()
        .filter(|m| existing.contains(&(m.subject.clone(), m.session)))
        .map(|m| session_name(&m.subject, m.session))
        .collect();
    if !dup.is_empty() {
        return Err(refused(format!(
            "{}: {} of the sessions in {} are already there ({}{}); nothing was imported",
            store.location(),
            dup.len(),
            dir.display(),
            dup.iter().take(5).cloned().collect::<Vec<_>>().join(", "),
            if dup.len() > 5 { ", ..." } else { "" }
        )));
    }
    Ok(())
}

/// The files of session folder `dir` a database keeps beside its rows: `frames.csv` and
/// rows set aside as torn.
fn kept_files(dir: &Path) -> Result<Vec<(String, Vec<u8>)>, ResultsError> {
    let list = |cause| ResultsError::Io {
        path: dir.to_path_buf(),
        op: "list",
        cause,
    };
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(list)? {
        let entry = entry.map_err(list)?;
        let file = entry.file_name().to_string_lossy().into_owned();
        let keep = file == FRAMES_FILE || file.starts_with("trials.csv.torn-");
        if keep && entry.path().is_file() {
            let bytes = read_limited(&entry.path(), crate::trials::MAX_TRIALS_BYTES)?;
            out.push((file, bytes));
        }
    }
    out.sort();
    Ok(out)
}

/// One session's rows as the server sent them ([`PgStore::read_rows`]), undecoded: the
/// rows of a binary `COPY`, back to back, in the buffer of the batch they came in.
pub struct SessionRows {
    batch: std::sync::Arc<Vec<u8>>,
    rows: std::ops::Range<usize>,
}

/// The session `head` from its rows ([`PgStore::read_rows`]), which must run 0, 1, 2 ... in
/// order.
///
/// # Errors
/// A row that does not decode or is out of order, named by session, line and column.
pub fn decode_session(
    head: &SessionHead,
    rows: &SessionRows,
) -> Result<SessionResults, ResultsError> {
    let path = head.dir.join(TRIALS_FILE);
    let mut records = Vec::new();
    let mut stream = rows::CopyRows::rows(&rows.batch[rows.rows.clone()]);
    let malformed = |line: usize, column: usize, message: String| ResultsError::Malformed {
        path: path.clone(),
        line,
        column,
        message,
    };
    while let Some(row) = stream
        .next()
        .map_err(|m| malformed(records.len() + 2, 1, m))?
    {
        let n = row
            .int4(1)
            .map_err(|(_, m)| malformed(records.len() + 2, 1, format!("row_number: {m}")))?;
        if usize::try_from(n).ok() != Some(records.len()) {
            return Err(malformed(
                records.len() + 2,
                1,
                format!("row {n} follows row {}", records.len() as i64 - 1),
            ));
        }
        records.push(rows::Decoder { trials: &path }.decode(&row)?);
    }
    Ok(SessionResults {
        dir: head.dir.clone(),
        manifest: head.manifest.clone(),
        trials: TrialsFile {
            format_version: head.version,
            records,
            complete_bytes: 0,
            torn: None,
        },
    })
}
