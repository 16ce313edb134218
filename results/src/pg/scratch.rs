//! A throw-away PostgreSQL server for tests and benchmarks: `initdb` in a temporary folder, the
//! server on a free loopback port (and a socket in that folder), removed when dropped.
//!
//! The binaries are Debian's (`postgresql` package): `$STUDY_PG_BIN`, else the newest
//! `/usr/lib/postgresql/<version>/bin`, else `pg_config --bindir`. PostgreSQL refuses to run as
//! root, so a root process runs it as the `postgres` user (or `nobody`) through `setpriv`,
//! with the folder handed to that user.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use super::Database;
use crate::ResultsError;

fn fail(message: impl Into<String>) -> ResultsError {
    ResultsError::Store(message.into())
}

/// The folder holding `initdb` and `postgres`.
///
/// # Errors
/// [`ResultsError::Store`] when no PostgreSQL server is installed (saying how to install it).
pub fn bin_dir() -> Result<PathBuf, ResultsError> {
    if let Some(dir) = std::env::var_os("STUDY_PG_BIN") {
        return Ok(PathBuf::from(dir));
    }
    let mut versions: Vec<(u32, PathBuf)> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let v = e.file_name().to_string_lossy().parse::<u32>().ok()?;
            let bin = e.path().join("bin");
            bin.join("initdb").is_file().then_some((v, bin))
        })
        .collect();
    versions.sort();
    if let Some((_, bin)) = versions.pop() {
        return Ok(bin);
    }
    if let Ok(out) = Command::new("pg_config").arg("--bindir").output() {
        let dir = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
        if dir.join("initdb").is_file() && dir.join("postgres").is_file() {
            return Ok(dir);
        }
    }
    Err(fail(
        "no PostgreSQL server found (install Debian's `postgresql` package, or set \
         STUDY_PG_BIN to the folder holding initdb and postgres)",
    ))
}

/// The user the server runs as when this process is root: `postgres`, else `nobody`
/// (uid, gid).
fn server_user() -> Result<Option<(u32, u32)>, ResultsError> {
    let id = |args: &[&str]| -> Option<u32> {
        let out = Command::new("id").args(args).output().ok()?;
        if !out.status.success() {
            return None;
        }
        String::from_utf8_lossy(&out.stdout).trim().parse().ok()
    };
    if id(&["-u"]) != Some(0) {
        return Ok(None);
    }
    for user in ["postgres", "nobody"] {
        if let (Some(u), Some(g)) = (id(&["-u", user]), id(&["-g", user])) {
            return Ok(Some((u, g)));
        }
    }
    Err(fail(
        "running as root, and neither a `postgres` nor a `nobody` user exists to run the server",
    ))
}

/// A running throw-away server.
pub struct ScratchServer {
    bin: PathBuf,
    dir: PathBuf,
    port: u16,
    user: Option<(u32, u32)>,
    settings: Vec<String>,
    child: Option<Child>,
}

fn free_port() -> Result<u16, ResultsError> {
    let l = TcpListener::bind("127.0.0.1:0").map_err(|e| fail(format!("finding a port: {e}")))?;
    l.local_addr()
        .map(|a| a.port())
        .map_err(|e| fail(format!("finding a port: {e}")))
}

impl ScratchServer {
    /// `initdb` in a new folder under `parent` and the server started on a free port, with
    /// `settings` (`name=value`, passed as `-c`) beside the defaults.
    ///
    /// # Errors
    /// No server installed, or it does not initialise or start (its log is in the message).
    pub fn start(parent: &Path, settings: &[&str]) -> Result<Self, ResultsError> {
        let bin = bin_dir()?;
        let user = server_user()?;
        let dir = parent.join(format!(
            "pg-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos())
        ));
        std::fs::create_dir_all(&dir).map_err(|e| fail(format!("{}: {e}", dir.display())))?;
        if let Some((uid, gid)) = user {
            std::os::unix::fs::chown(&dir, Some(uid), Some(gid))
                .map_err(|e| fail(format!("{}: chown: {e}", dir.display())))?;
        }
        let mut server = Self {
            bin,
            dir,
            port: free_port()?,
            user,
            settings: settings.iter().map(|s| (*s).to_owned()).collect(),
            child: None,
        };
        let out = server
            .command("initdb")
            .args([
                "-A",
                "trust",
                "-U",
                "postgres",
                "-E",
                "UTF8",
                "--no-sync",
                "-D",
            ])
            .arg(server.dir.join("data"))
            .output()
            .map_err(|e| fail(format!("running initdb: {e}")))?;
        if !out.status.success() {
            return Err(fail(format!(
                "initdb failed: {}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            )));
        }
        server.resume()?;
        Ok(server)
    }

    fn command(&self, program: &str) -> Command {
        let path = self.bin.join(program);
        match self.user {
            Some((uid, gid)) => {
                let mut c = Command::new("setpriv");
                c.arg(format!("--reuid={uid}"))
                    .arg(format!("--regid={gid}"))
                    .arg("--clear-groups")
                    .arg("--")
                    .arg(path);
                c
            }
            None => Command::new(path),
        }
    }

    /// Starts the server again (after [`Self::stop`] or [`Self::kill`]) on the same port and
    /// data, and waits until it takes connections.
    ///
    /// # Errors
    /// It does not start within 30 s.
    pub fn resume(&mut self) -> Result<(), ResultsError> {
        let log = self.dir.join("server.log");
        let log_file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log)
            .map_err(|e| fail(format!("{}: {e}", log.display())))?;
        if let Some((uid, gid)) = self.user {
            let _ = std::os::unix::fs::chown(&log, Some(uid), Some(gid));
        }
        let mut c = self.command("postgres");
        c.arg("-D")
            .arg(self.dir.join("data"))
            .args(["-p", &self.port.to_string(), "-k"])
            .arg(&self.dir)
            .args(["-c", "listen_addresses=127.0.0.1"]);
        for s in &self.settings {
            c.args(["-c", s]);
        }
        let stderr = log_file
            .try_clone()
            .map_err(|e| fail(format!("{}: {e}", log.display())))?;
        c.stdin(Stdio::null())
            .stdout(Stdio::from(log_file))
            .stderr(Stdio::from(stderr));
        self.child = Some(
            c.spawn()
                .map_err(|e| fail(format!("starting postgres: {e}")))?,
        );
        let start = Instant::now();
        let db = self.database();
        loop {
            if let Some(child) = self.child.as_mut()
                && let Ok(Some(status)) = child.try_wait()
            {
                self.child = None;
                return Err(fail(format!(
                    "postgres exited ({status}): {}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                )));
            }
            if db.connect().is_ok() {
                return Ok(());
            }
            if start.elapsed() > Duration::from_secs(30) {
                return Err(fail(format!(
                    "postgres did not take connections within 30 s: {}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                )));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn signal(&mut self, signal: &str) {
        if let Some(mut child) = self.child.take() {
            let _ = Command::new("kill")
                .args([signal, &child.id().to_string()])
                .status();
            let _ = child.wait();
        }
    }

    /// The server's process id (the postmaster), while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    /// Stops the server as an administrator would (fast shutdown: every connection ended).
    pub fn stop(&mut self) {
        self.signal("-INT");
    }

    /// Kills the server and its processes at once (SIGKILL to the postmaster, SIGQUIT to the
    /// rest): a crash, after which it recovers from its write-ahead log on [`Self::resume`].
    pub fn kill(&mut self) {
        // Immediate shutdown: what a power cut or a crash leaves, minus the lost disk cache.
        self.signal("-QUIT");
    }

    /// The server's TCP port.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The connection string of database `name` as the superuser (trust authentication on
    /// loopback; no password).
    pub fn url(&self, name: &str) -> String {
        format!("postgres://postgres@127.0.0.1:{}/{name}", self.port)
    }

    /// The `postgres` database.
    ///
    /// # Panics
    /// Never: the URL is built here.
    pub fn database(&self) -> Database {
        match Database::parse(&self.url("postgres"), "scratch server") {
            Ok(db) => db,
            Err(_) => unreachable_database(),
        }
    }

    /// A new database `name` on the server.
    ///
    /// # Errors
    /// It cannot be created.
    pub fn create_database(&self, name: &str) -> Result<Database, ResultsError> {
        let mut client = self.database().connect()?;
        // A name cannot be a query parameter: it is checked here instead.
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        {
            return Err(fail(format!("database name {name:?}: use a-z, 0-9 and _")));
        }
        client
            .batch_execute(&format!("CREATE DATABASE {name}"))
            .map_err(|e| super::db_error("scratch server", "creating a database", &e))?;
        Database::parse(&self.url(name), "scratch server")
    }

    /// The folder holding the server's data, socket and log.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

#[expect(clippy::panic, reason = "a URL built from a port number always parses")]
fn unreachable_database() -> Database {
    panic!("the scratch server's own URL does not parse")
}

impl Drop for ScratchServer {
    fn drop(&mut self) {
        self.kill();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
