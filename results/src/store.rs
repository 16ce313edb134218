//! Results directories: session logs, manifests, the session lock, crash-safe writes.
//!
//! Crash safety, in the order a power cut could strike: a trial row is written with one
//! `write_all`, then `sync_data`, before [`SessionLog::append`] returns, so the next trial never
//! starts before its predecessor is on disk; manifests are written to a temporary file, synced,
//! renamed over the old one and the directory synced, so a reader sees the old or the new
//! manifest, never half of one; new files appear only through a rename of a complete temporary
//! file or `create_new`, so nothing existing is overwritten.

use std::collections::BTreeMap;
use std::fs::{self, File, OpenOptions};
use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};

use protocols::{Protocol, TrialRecord};
use serde::{Deserialize, Serialize};

use crate::ResultsError;
use crate::trials::{
    HEADER, TRIALS_FORMAT_VERSION, TornRow, TrialsFile, encode_row_as, read_trials, torn_path,
};

/// Version of `session.json` and `run.json` written by this build. Version 2 added
/// `manifest_hash`, 3 `browser`; version 4 added `viewing`, and in it `trials_logged` is the
/// count when the manifest was last written, not rewritten after every row (the rows are the
/// record); version 5 added a session's between-subject `group`. Versions 1 to 4 are still
/// read.
pub const MANIFEST_FORMAT_VERSION: u32 = 5;
/// Largest manifest accepted by the readers, bytes.
pub const MAX_MANIFEST_BYTES: u64 = 16 << 20;
/// Most session directories read from one results directory.
pub const MAX_SESSIONS: usize = 100_000;
/// File name of the session log.
pub const TRIALS_FILE: &str = "trials.csv";
/// File name of the session manifest.
pub const SESSION_FILE: &str = "session.json";
/// File name of the run manifest.
pub const RUN_FILE: &str = "run.json";
/// File name of the session lock.
pub const LOCK_FILE: &str = "session.lock";

fn io(path: &Path, op: &'static str) -> impl FnOnce(std::io::Error) -> ResultsError {
    let path = path.to_path_buf();
    move |cause| ResultsError::Io { path, op, cause }
}

/// Reads a whole file after checking its size against `limit`.
///
/// # Errors
/// [`ResultsError::Io`] or [`ResultsError::TooLarge`].
pub fn read_limited(path: &Path, limit: u64) -> Result<Vec<u8>, ResultsError> {
    let mut f = File::open(path).map_err(io(path, "open"))?;
    let len = f.metadata().map_err(io(path, "stat"))?.len();
    if len > limit {
        return Err(ResultsError::TooLarge {
            path: path.to_path_buf(),
            bytes: len,
            limit,
        });
    }
    let mut buf = Vec::with_capacity(len as usize);
    std::io::Read::by_ref(&mut f)
        .take(limit + 1)
        .read_to_end(&mut buf)
        .map_err(io(path, "read"))?;
    if buf.len() as u64 > limit {
        return Err(ResultsError::TooLarge {
            path: path.to_path_buf(),
            bytes: buf.len() as u64,
            limit,
        });
    }
    Ok(buf)
}

/// fsync of a directory, so a rename or a new entry in it survives a power cut (Linux).
///
/// # Errors
/// [`ResultsError::Io`].
pub fn sync_dir(dir: &Path) -> Result<(), ResultsError> {
    files::sync_dir(dir).map_err(from_files)
}

/// Writes `bytes` to `path` atomically, replacing it if it exists ([`files::write`] with
/// [`files::Mode::Replace`]: temporary file, fsync, rename, fsync of the directory). For a
/// session's own manifest, which each write replaces.
///
/// # Errors
/// [`ResultsError::Io`].
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ResultsError> {
    files::write(path, bytes, files::Mode::Replace).map_err(from_files)
}

/// Writes `bytes` to a new file `path`, failing if it exists ([`files::write`] with
/// [`files::Mode::New`]: temporary file, fsync, hard link, which refuses an existing target,
/// fsync of the directory).
///
/// # Errors
/// [`ResultsError::Exists`] or [`ResultsError::Io`].
pub fn write_new(path: &Path, bytes: &[u8]) -> Result<(), ResultsError> {
    files::write(path, bytes, files::Mode::New).map_err(from_files)
}

/// The results error for a `files` error: an existing file is [`ResultsError::Exists`] (whose
/// message says results are never overwritten), anything else an I/O error on its path.
fn from_files(e: files::Error) -> ResultsError {
    match e {
        files::Error::Exists { path } => ResultsError::Exists { path },
        files::Error::Io { path, op, source } => ResultsError::Io {
            path,
            op,
            cause: source,
        },
        other => ResultsError::Io {
            path: other.path().to_path_buf(),
            op: "write",
            cause: std::io::Error::other(other.to_string()),
        },
    }
}

/// A session lock: an exclusive kernel lock (`flock`) on `session.lock`, held on an open
/// descriptor for as long as this value lives.
///
/// The kernel releases the lock when the holder exits, however it exits (a crash, SIGKILL, a
/// power cut), so a lock left by a dead runner is free at once and no code ever decides that
/// another process's lock is stale or deletes it. The file holds the holder's pid, for the
/// message a second runner gets. The holder removes the file when it lets go, while it still
/// holds the lock; a runner that locked a file which is no longer the one at `session.lock`
/// (it opened it just before the holder removed it) lets go and starts again on the new one.
#[derive(Debug)]
pub struct SessionLock {
    path: PathBuf,
    file: File,
}

/// How long to wait between opening the lock file and locking it, read from
/// `STUDY_LOCK_GAP_MS` in debug builds only: tests widen the window between the two steps to
/// show that nothing depends on it.
fn lock_gap() -> Option<std::time::Duration> {
    if !cfg!(debug_assertions) {
        return None;
    }
    std::env::var("STUDY_LOCK_GAP_MS")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
        .map(std::time::Duration::from_millis)
}

/// Whether `file` is still the file at `path` (same device and inode).
#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt as _;
    match (file.metadata(), fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_file: &File, path: &Path) -> bool {
    path.exists()
}

impl SessionLock {
    /// Takes the lock of session directory `dir`, without waiting.
    ///
    /// # Errors
    /// [`ResultsError::Locked`] when another runner holds it (naming its pid as the file
    /// says), [`ResultsError::Io`] otherwise.
    pub fn acquire(dir: &Path) -> Result<Self, ResultsError> {
        let path = dir.join(LOCK_FILE);
        loop {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(io(&path, "open"))?;
            if let Some(gap) = lock_gap() {
                std::thread::sleep(gap);
            }
            match file.try_lock() {
                Ok(()) => {}
                Err(fs::TryLockError::WouldBlock) => {
                    let mut text = String::new();
                    let _ = file.read_to_string(&mut text);
                    let pid = text.trim().parse::<u32>().unwrap_or(0);
                    return Err(ResultsError::Locked { path, pid });
                }
                Err(fs::TryLockError::Error(e)) => return Err(io(&path, "lock")(e)),
            }
            if !same_file(&file, &path) {
                // The holder removed this file after we opened it: ours is an orphan.
                continue;
            }
            file.set_len(0).map_err(io(&path, "truncate"))?;
            file.write_all(format!("{}\n", std::process::id()).as_bytes())
                .map_err(io(&path, "write"))?;
            return Ok(Self { path, file });
        }
    }
}

impl Drop for SessionLock {
    fn drop(&mut self) {
        // Removed while still locked; the lock itself goes with the descriptor.
        if same_file(&self.file, &self.path) {
            let _ = fs::remove_file(&self.path);
        }
    }
}

/// How a session ended (or that it has not).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionState {
    /// Started, not finished: being run, or stopped without a word (a crash, SIGKILL).
    Running,
    /// Stopped on purpose before the end (the experimenter quit, SIGINT or SIGTERM), with its
    /// state saved: resumable, like a running one.
    Interrupted,
    /// Every trial done.
    Complete,
    /// Ended by the session time limit.
    TimeLimit,
}

/// Display the session ran on (a simulated session records `simulated`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisplayInfo {
    /// Description (monitor model, or `simulated`).
    pub description: String,
    /// Width, pixels.
    pub width_px: u32,
    /// Height, pixels.
    pub height_px: u32,
    /// Refresh rate, Hz.
    pub refresh_hz: f64,
}

/// `session.json` (format version 5; 1-4 are read).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionManifest {
    /// [`MANIFEST_FORMAT_VERSION`].
    pub format_version: u32,
    /// Study name.
    pub study: String,
    /// [`protocols::study::content_hash`] of the study file.
    pub study_hash: String,
    /// Hash of the stimulus manifest the session's plan used (version 2; `None` in version 1).
    #[serde(default)]
    pub manifest_hash: Option<String>,
    /// Protocol.
    pub protocol: Protocol,
    /// Subject id.
    pub subject: String,
    /// 0-based subject index the trial plan derives from.
    pub subject_index: u32,
    /// Session number (1-based).
    pub session: u32,
    /// Study seed the plan derives from.
    pub plan_seed: u64,
    /// Seed of the simulated observer, for simulated sessions.
    pub observer_seed: Option<u64>,
    /// `study` version that wrote the session.
    pub software_version: String,
    /// Subject fields collected before the session.
    pub subject_fields: BTreeMap<String, String>,
    /// Start, ms since the Unix epoch.
    pub started_ms: u64,
    /// End, ms since the Unix epoch.
    pub ended_ms: Option<u64>,
    /// State.
    pub status: SessionState,
    /// Rows in `trials.csv` when this manifest was written (version 4: at open, resume,
    /// display changes, interrupt and finish, so a running session's log may hold more;
    /// versions 1-3 rewrote it after every row). Count the rows for the trials logged.
    pub trials_logged: u32,
    /// Stimulus ids planned but not shown (time limit).
    pub not_shown: Vec<String>,
    /// Staircase thresholds (name, mean of the last reversals), staircase sessions only.
    pub thresholds: Vec<(String, Option<f64>)>,
    /// How often the session was resumed.
    pub resumes: u32,
    /// Torn rows set aside on resume (file names in the session directory).
    pub torn_rows: Vec<String>,
    /// Display.
    pub display: Option<DisplayInfo>,
    /// What the participant's browser measured (`study serve`, version 3); `None` for a
    /// window or simulated session, and absent from their files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub browser: Option<BrowserInfo>,
    /// The study's viewing conditions as the experimenter confirmed and measured them before
    /// the session (version 4); `None` for a study without `[viewing]`, and absent from its
    /// files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viewing: Option<ViewingRecord>,
    /// The between-subject group the session was assigned (`[[design.groups]]`, version 5);
    /// `None` for a study without groups, and absent from its files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
}

/// What the experimenter confirmed of a study's `[viewing]` conditions before a session, and
/// what was measured (`study run --measured-*`, or typed on the window's confirmation screen);
/// `None` where nothing was measured.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewingRecord {
    /// The experimenter confirmed that the conditions are as the study states them.
    pub confirmed: bool,
    /// When, ms since the Unix epoch.
    pub confirmed_ms: Option<u64>,
    /// Measured viewing distance, cm.
    pub distance_cm: Option<f64>,
    /// Measured peak luminance of the display, cd/m².
    pub peak_luminance_cd_m2: Option<f64>,
    /// Measured background luminance, cd/m².
    pub background_luminance_cd_m2: Option<f64>,
    /// Measured room illumination, lux.
    pub room_illuminance_lux: Option<f64>,
}

/// What a participant's browser reported and measured (`study serve`): the environment the
/// page ran in, and the trials during whose stimuli the page was hidden or not fullscreen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BrowserInfo {
    /// `navigator.userAgent`.
    pub user_agent: String,
    /// The WebGL renderer string (`UNMASKED_RENDERER_WEBGL` where the browser tells it).
    pub webgl_renderer: String,
    /// `screen.width` × `screen.height`, CSS pixels.
    pub screen_px: [u32; 2],
    /// The window's inner size when the session began, CSS pixels.
    pub window_px: [u32; 2],
    /// `devicePixelRatio`.
    pub device_pixel_ratio: f64,
    /// Refresh rate estimated from `requestAnimationFrame` intervals before the session, Hz.
    pub refresh_hz: f64,
    /// Fullscreen when the session began.
    pub fullscreen: bool,
    /// Trials during whose stimuli the page was hidden (another tab, a minimised window).
    #[serde(default)]
    pub hidden_trials: Vec<u32>,
    /// Trials answered outside fullscreen in a study that asks for it.
    #[serde(default)]
    pub windowed_trials: Vec<u32>,
}

/// `run.json` (format version 1): what a results directory is a run of.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunManifest {
    /// [`MANIFEST_FORMAT_VERSION`].
    pub format_version: u32,
    /// Study name.
    pub study: String,
    /// Hash of the study file.
    pub study_hash: String,
    /// Hash of the stimulus manifest (version 2; `None` in version 1).
    #[serde(default)]
    pub manifest_hash: Option<String>,
    /// Copy of the study file kept in the run directory.
    pub study_file: String,
    /// Study seed.
    pub plan_seed: u64,
    /// Observer seed (simulated runs).
    pub observer_seed: Option<u64>,
    /// Subjects planned.
    pub subjects: u32,
    /// `study` version.
    pub software_version: String,
    /// Created, ms since the Unix epoch.
    pub created_ms: u64,
}

fn json_error(path: &Path, e: &serde_json::Error) -> ResultsError {
    ResultsError::Malformed {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    }
}

/// Reads a JSON manifest.
///
/// # Errors
/// [`ResultsError::Malformed`] with line and column, or I/O and size errors.
pub fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, ResultsError> {
    let bytes = read_limited(path, MAX_MANIFEST_BYTES)?;
    serde_json::from_slice(&bytes).map_err(|e| json_error(path, &e))
}

/// A manifest with a `format_version`, read by [`read_manifest`].
pub trait Versioned {
    /// The file's format version.
    fn format_version(&self) -> u32;
}

impl Versioned for SessionManifest {
    fn format_version(&self) -> u32 {
        self.format_version
    }
}

impl Versioned for RunManifest {
    fn format_version(&self) -> u32 {
        self.format_version
    }
}

/// Reads `session.json` or `run.json`, refusing a format version this build does not know
/// (a newer build's file would otherwise be read as if it were one of ours).
///
/// # Errors
/// [`ResultsError::Malformed`] for bad JSON, [`ResultsError::UnknownVersion`], I/O and size
/// errors.
pub fn read_manifest<T: Versioned + for<'de> Deserialize<'de>>(
    path: &Path,
) -> Result<T, ResultsError> {
    let m: T = read_json(path)?;
    let v = m.format_version();
    if v == 0 || v > MANIFEST_FORMAT_VERSION {
        return Err(ResultsError::UnknownVersion {
            path: path.to_path_buf(),
            version: v,
            max: MANIFEST_FORMAT_VERSION,
        });
    }
    Ok(m)
}

/// Writes a JSON manifest atomically.
///
/// # Errors
/// [`ResultsError::Io`].
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), ResultsError> {
    let mut text = serde_json::to_string_pretty(value).map_err(|e| ResultsError::Unwritable {
        column: "json",
        reason: e.to_string(),
    })?;
    text.push('\n');
    write_atomic(path, text.as_bytes())
}

/// The append-only trial log of one session, holding the session lock.
#[derive(Debug)]
pub struct SessionLog {
    dir: PathBuf,
    file: File,
    rows: u32,
    version: u32,
    _lock: SessionLock,
}

/// What [`SessionLog::resume`] found.
#[derive(Debug)]
pub struct Resumed {
    /// The reopened log.
    pub log: SessionLog,
    /// Rows already logged.
    pub records: Vec<TrialRecord>,
    /// A torn last row that was set aside, and where it went.
    pub torn: Option<(TornRow, PathBuf)>,
}

impl SessionLog {
    /// Creates session directory `dir` (which must not exist) with an empty `trials.csv`.
    ///
    /// # Errors
    /// [`ResultsError::Exists`] when `dir` exists, I/O errors otherwise.
    pub fn create(dir: &Path) -> Result<Self, ResultsError> {
        match fs::create_dir(dir) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                return Err(ResultsError::Exists {
                    path: dir.to_path_buf(),
                });
            }
            Err(e) => {
                return Err(ResultsError::Io {
                    path: dir.to_path_buf(),
                    op: "create directory",
                    cause: e,
                });
            }
        }
        if let Some(parent) = dir.parent() {
            sync_dir(parent)?;
        }
        let lock = SessionLock::acquire(dir)?;
        let trials = dir.join(TRIALS_FILE);
        write_new(&trials, format!("{HEADER}\n").as_bytes())?;
        Self::open_append(dir, 0, TRIALS_FORMAT_VERSION, lock)
    }

    fn open_append(
        dir: &Path,
        rows: u32,
        version: u32,
        lock: SessionLock,
    ) -> Result<Self, ResultsError> {
        let trials = dir.join(TRIALS_FILE);
        let file = OpenOptions::new()
            .append(true)
            .open(&trials)
            .map_err(io(&trials, "open for append"))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file,
            rows,
            version,
            _lock: lock,
        })
    }

    /// Reopens an interrupted session: takes the lock, reads the log, sets a torn last row
    /// aside in `trials.csv.torn-<n>` (copied and synced before `trials.csv` is cut back to
    /// its complete rows), and returns the logged records. A session directory without
    /// `trials.csv` (crash right after creating it) gets a fresh one.
    ///
    /// # Errors
    /// [`ResultsError::Locked`], [`ResultsError::Malformed`] for a bad row that is not the
    /// torn last one, I/O errors.
    pub fn resume(dir: &Path) -> Result<Resumed, ResultsError> {
        let lock = SessionLock::acquire(dir)?;
        let trials = dir.join(TRIALS_FILE);
        if !trials.exists() {
            write_new(&trials, format!("{HEADER}\n").as_bytes())?;
        }
        let TrialsFile {
            format_version,
            records,
            complete_bytes,
            torn,
        } = read_trials(&trials)?;
        let torn = match torn {
            Some(t) => {
                let aside = torn_path(&trials);
                write_new(&aside, &t.bytes)?;
                let f = OpenOptions::new()
                    .write(true)
                    .open(&trials)
                    .map_err(io(&trials, "open"))?;
                f.set_len(complete_bytes).map_err(io(&trials, "truncate"))?;
                f.sync_all().map_err(io(&trials, "fsync"))?;
                Some((t, aside))
            }
            None => None,
        };
        // Rows appended to an older file keep its layout, so the file stays one version.
        let log = Self::open_append(dir, records.len() as u32, format_version, lock)?;
        Ok(Resumed { log, records, torn })
    }

    /// Session directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Rows in the log.
    pub fn rows(&self) -> u32 {
        self.rows
    }

    /// Format version of this log's `trials.csv` (an older file resumed keeps its version).
    pub fn format_version(&self) -> u32 {
        self.version
    }

    /// Appends one row; it is on disk (written and `sync_data`) when this returns.
    ///
    /// # Errors
    /// [`ResultsError::Unwritable`] or [`ResultsError::Io`].
    pub fn append(&mut self, record: &TrialRecord) -> Result<(), ResultsError> {
        let line = encode_row_as(record, self.version)?;
        let path = self.dir.join(TRIALS_FILE);
        self.file
            .write_all(line.as_bytes())
            .map_err(io(&path, "append"))?;
        self.file.flush().map_err(io(&path, "flush"))?;
        self.file.sync_data().map_err(io(&path, "fsync"))?;
        self.rows += 1;
        Ok(())
    }

    /// Replaces `session.json` atomically.
    ///
    /// # Errors
    /// [`ResultsError::Io`].
    pub fn write_manifest(&self, manifest: &SessionManifest) -> Result<(), ResultsError> {
        write_json(&self.dir.join(SESSION_FILE), manifest)
    }
}

/// One session read back from a results directory.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionResults {
    /// Session directory.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: SessionManifest,
    /// Its trials (complete rows).
    pub trials: TrialsFile,
}

/// Loads every session of a results directory (sub-directories holding `session.json`),
/// sorted by directory name. A sub-directory with `trials.csv` but no `session.json` is an
/// error ([`ResultsError::MissingManifest`]), never skipped.
///
/// # Errors
/// The first malformed file, named with line and column.
pub fn read_results_dir(dir: &Path) -> Result<(RunManifest, Vec<SessionResults>), ResultsError> {
    let (run, dirs) = session_dirs(dir)?;
    let sessions = dirs
        .iter()
        .map(|d| read_session(d))
        .collect::<Result<_, _>>()?;
    Ok((run, sessions))
}

/// A results directory's run manifest and its session folders (sub-directories holding
/// `session.json`), sorted by name, for a reader that takes one session at a time
/// ([`read_session`]) and so holds one session's rows in memory, not every session's.
///
/// # Errors
/// `run.json` unreadable or malformed; a sub-directory with `trials.csv` but no
/// `session.json` ([`ResultsError::MissingManifest`]); more than [`MAX_SESSIONS`] sessions.
pub fn session_dirs(dir: &Path) -> Result<(RunManifest, Vec<PathBuf>), ResultsError> {
    let run: RunManifest = read_manifest(&dir.join(RUN_FILE))?;
    let mut dirs = Vec::new();
    for entry in fs::read_dir(dir).map_err(io(dir, "list"))? {
        let entry = entry.map_err(io(dir, "list"))?;
        let p = entry.path();
        // One look per folder at a session (it has its manifest); a second only for others.
        let session = p.join(SESSION_FILE).is_file();
        if !session && p.join(TRIALS_FILE).is_file() {
            // A crash between creating the log and the first manifest write: say so rather
            // than skip the session (`study simulate --resume` completes it).
            return Err(ResultsError::MissingManifest { dir: p });
        }
        if session {
            dirs.push(p);
            if dirs.len() > MAX_SESSIONS {
                return Err(ResultsError::TooLarge {
                    path: dir.to_path_buf(),
                    bytes: dirs.len() as u64,
                    limit: MAX_SESSIONS as u64,
                });
            }
        }
    }
    dirs.sort();
    Ok((run, dirs))
}

/// Reads one session folder: its manifest and its trials.
///
/// # Errors
/// The first malformed file, named with line and column.
pub fn read_session(dir: &Path) -> Result<SessionResults, ResultsError> {
    let manifest: SessionManifest = read_manifest(&dir.join(SESSION_FILE))?;
    let trials = read_trials(&dir.join(TRIALS_FILE))?;
    Ok(SessionResults {
        dir: dir.to_path_buf(),
        manifest,
        trials,
    })
}

/// Parses `session.json` text (for tests and tools that hold the bytes).
///
/// # Errors
/// [`ResultsError::Malformed`].
pub fn parse_session_manifest(bytes: &[u8], path: &Path) -> Result<SessionManifest, ResultsError> {
    serde_json::from_slice(bytes).map_err(|e| json_error(path, &e))
}
