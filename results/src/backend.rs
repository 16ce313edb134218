//! Where a study's sessions are kept, behind one interface: a results folder
//! ([`FolderStore`], the crash-safe files of [`crate::store`]) or a PostgreSQL database
//! (`pg::PgStore`, with the cargo feature `postgres`). Both give the same session semantics:
//! - one writer per session: the folder's kernel lock on `session.lock`, the database's
//!   session-level advisory lock held on the writer's connection; a second writer is refused
//!   with [`ResultsError::Locked`] or [`ResultsError::SessionBusy`];
//! - an answer is durable before [`SessionWriter::append`] returns (fsynced row, or a committed
//!   transaction), so the next trial never starts before it; the rows are the record of how
//!   many trials were logged (a manifest's `trials_logged` is the count when it was written);
//! - a resumed session returns the committed rows, which the recorder replays through the
//!   engine;
//! - the study file's and the stimulus manifest's hashes are in every session's manifest.

use std::fs;
use std::path::{Path, PathBuf};

use protocols::TrialRecord;

use crate::store::{LOCK_FILE, SESSION_FILE, SessionLock, SessionLog, TRIALS_FILE, read_manifest};
use crate::trials::TornRow;
use crate::{ResultsError, SessionManifest};

/// File name of a window session's per-frame presentation intervals, beside `trials.csv`.
pub const FRAMES_FILE: &str = "frames.csv";

/// The header of [`FRAMES_FILE`], with its line break.
pub const FRAMES_HEADER: &str = "trial_index,interval_ms,phase\n";

/// The folder name of `subject`'s session `session`: `<subject>_s<session>` (also the last
/// part of a database session's name in messages).
pub fn session_name(subject: &str, session: u32) -> String {
    format!("{subject}_s{session}")
}

/// What a store holds of one session.
#[derive(Debug, Clone, PartialEq)]
pub enum Found {
    /// Nothing.
    Absent,
    /// The session, with its manifest (a folder created by a run that died before its first
    /// manifest write has none).
    Present(Option<Box<SessionManifest>>),
}

/// What [`Store::resume_session`] found.
pub struct ResumedSession {
    /// The session, open for more rows.
    pub writer: Box<dyn SessionWriter>,
    /// The committed rows, in order.
    pub records: Vec<TrialRecord>,
    /// A torn last row set aside (folders only), and the name it was set aside under.
    pub torn: Option<(TornRow, String)>,
}

/// A between-subject group as [`Store::assign_group`] sees it: its name and its quota.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GroupQuota<'a> {
    /// The group's name.
    pub name: &'a str,
    /// Most sessions it takes; `None`: no limit.
    pub quota: Option<u32>,
}

/// A session's between-subject group, as [`Store::assign_group`] gave it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Assignment {
    /// The group's name.
    pub group: String,
    /// The session's place in its group: 0 for the group's first session, 1 for the next,
    /// ... (a subject index that completes the group's counterbalancing in turn).
    pub ordinal: u32,
    /// Whether this call made the assignment (`false`: the session had it already).
    pub new: bool,
}

/// The group a new session joins, given how many sessions each group has: `wanted` when
/// given (refused when at its quota), else the group with the fewest sessions among those
/// under their quota, the first listed of equals. `Err` says why none can be.
///
/// # Errors
/// `wanted` is not a group or is full; every group is full.
pub fn choose_group(
    groups: &[GroupQuota<'_>],
    counts: &[u32],
    wanted: Option<&str>,
) -> Result<usize, String> {
    let open = |i: usize| groups[i].quota.is_none_or(|q| counts[i] < q);
    if let Some(w) = wanted {
        let Some(i) = groups.iter().position(|g| g.name == w) else {
            let names: Vec<&str> = groups.iter().map(|g| g.name).collect();
            return Err(format!(
                "there is no group {w:?} (the study's groups: {})",
                names.join(", ")
            ));
        };
        if !open(i) {
            return Err(format!(
                "group {w:?} is full: {} of its {} sessions are assigned",
                counts[i],
                groups[i].quota.unwrap_or(0)
            ));
        }
        return Ok(i);
    }
    (0..groups.len())
        .filter(|&i| open(i))
        .min_by_key(|&i| (counts[i], i))
        .ok_or_else(|| {
            let full: Vec<String> = groups
                .iter()
                .zip(counts)
                .map(|(g, n)| format!("{} {n}/{}", g.name, g.quota.unwrap_or(0)))
                .collect();
            format!(
                "every group has its quota of sessions ({}); the study is complete",
                full.join(", ")
            )
        })
}

/// A results store: where sessions are created, resumed and found.
pub trait Store {
    /// Where the results are, for messages: the folder, or the database (never with its
    /// password) and the run.
    fn location(&self) -> String;

    /// The path that names a session in messages: its folder, or
    /// `<database>/<run>/<subject>_s<n>` for a database session (whose rows are numbered as
    /// the lines of its exported `trials.csv`).
    fn session_path(&self, subject: &str, session: u32) -> PathBuf;

    /// Whether a session is recorded.
    ///
    /// # Errors
    /// The store cannot be read.
    fn find_session(&mut self, subject: &str, session: u32) -> Result<Found, ResultsError>;

    /// Records a new session with `manifest` (its first manifest) and opens it for rows,
    /// holding its lock.
    ///
    /// # Errors
    /// [`ResultsError::Exists`] when it is recorded already, store errors otherwise.
    fn create_session(
        &mut self,
        manifest: &SessionManifest,
    ) -> Result<Box<dyn SessionWriter>, ResultsError>;

    /// Reopens a recorded session for more rows: takes its lock and returns its committed
    /// rows (a folder's torn last row set aside first).
    ///
    /// # Errors
    /// Another writer holds it, or its rows cannot be read.
    fn resume_session(
        &mut self,
        subject: &str,
        session: u32,
    ) -> Result<ResumedSession, ResultsError>;

    /// Checks that no live writer holds a session (one that finished, before saying so); a
    /// folder's lock left by a crash is taken over and released.
    ///
    /// # Errors
    /// A live writer holds it.
    fn check_not_held(&mut self, subject: &str, session: u32) -> Result<(), ResultsError>;

    /// Removes a session in which nothing happened (no row logged, never resumed: what a
    /// window that never opened leaves); returns whether it did.
    ///
    /// # Errors
    /// The store cannot be read or changed.
    fn discard_unstarted(&mut self, subject: &str, session: u32) -> Result<bool, ResultsError>;

    /// The between-subject group of session `session` of `subject`: the one it was given
    /// before (the same on every station, and on resume), else a new assignment by
    /// [`choose_group`] from the sessions already assigned to each group, recorded before
    /// it is returned. Two stations asking at once are served one after the other (the
    /// folder's kernel lock on [`GROUPS_LOCK_FILE`], a lock on the run's row in the
    /// database), so no group is given past its quota and no place twice. An assignment
    /// stays with its session: a session that is never run keeps its place for that
    /// subject and session.
    ///
    /// # Errors
    /// The wanted group is not one of `groups` or is full, every group is full, or the
    /// store cannot be read or written.
    fn assign_group(
        &mut self,
        subject: &str,
        session: u32,
        groups: &[GroupQuota<'_>],
        wanted: Option<&str>,
    ) -> Result<Assignment, ResultsError>;
}

/// A results folder's record of between-subject group assignments: CSV with the header
/// `subject,session,group,ordinal`, rewritten whole (a temporary file renamed) under
/// [`GROUPS_LOCK_FILE`] for each new assignment.
pub const GROUPS_FILE: &str = "groups.csv";

/// The lock file [`FolderStore::assign_group`] holds while it reads and writes
/// [`GROUPS_FILE`].
pub const GROUPS_LOCK_FILE: &str = "groups.lock";

/// Most assignments [`GROUPS_FILE`] may hold, and its largest size.
const MAX_ASSIGNMENTS: usize = 1 << 20;
const MAX_GROUPS_BYTES: u64 = 256 << 20;

/// One line of [`GROUPS_FILE`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct AssignedRow {
    pub(crate) subject: String,
    pub(crate) session: u32,
    pub(crate) group: String,
    pub(crate) ordinal: u32,
}

/// The text of [`GROUPS_FILE`] holding `rows` (written by the `csv` crate).
pub(crate) fn assignments_csv(rows: &[AssignedRow]) -> String {
    let mut w = csv::Writer::from_writer(Vec::with_capacity(32 * (rows.len() + 1)));
    // Writing into memory cannot fail.
    let _ = w.write_record(GROUPS_HEADER);
    for r in rows {
        let _ = w.write_record([
            r.subject.as_str(),
            &r.session.to_string(),
            r.group.as_str(),
            &r.ordinal.to_string(),
        ]);
    }
    String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default()
}

/// Reads [`GROUPS_FILE`] (absent: no assignments), refusing a malformed line by number.
pub(crate) fn read_assignments(path: &Path) -> Result<Vec<AssignedRow>, ResultsError> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let bytes = crate::store::read_limited(path, MAX_GROUPS_BYTES)?;
    let bad = |line: u64, column: usize, message: String| ResultsError::Malformed {
        path: path.to_path_buf(),
        line: line as usize,
        column,
        message,
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(bytes.as_slice());
    let mut record = csv::StringRecord::new();
    let mut out = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut header = true;
    loop {
        let more = reader.read_record(&mut record).map_err(|e| {
            let line = e.position().map_or(1, csv::Position::line);
            bad(line, 1, e.to_string())
        })?;
        let line = record.position().map_or(1, csv::Position::line);
        if header {
            if !more || record != GROUPS_HEADER[..] {
                return Err(bad(
                    1,
                    1,
                    format!("the header must be {:?}", GROUPS_HEADER.join(",")),
                ));
            }
            header = false;
            continue;
        }
        if !more {
            break;
        }
        if out.len() >= MAX_ASSIGNMENTS {
            return Err(bad(
                line,
                1,
                format!("more than {MAX_ASSIGNMENTS} assignments"),
            ));
        }
        if record.len() != 4 {
            return Err(bad(line, 1, format!("{} fields; 4 expected", record.len())));
        }
        let f = |k: usize| record.get(k).unwrap_or_default();
        let number = |k: usize| {
            f(k).parse::<u32>()
                .map_err(|_| bad(line, k + 1, format!("{:?} is not a whole number", f(k))))
        };
        let row = AssignedRow {
            subject: f(0).to_owned(),
            session: number(1)?,
            group: f(2).to_owned(),
            ordinal: number(3)?,
        };
        if row.subject.is_empty() || row.group.is_empty() {
            return Err(bad(line, 1, "an empty subject or group".to_owned()));
        }
        if !seen.insert((row.subject.clone(), row.session)) {
            return Err(bad(
                line,
                1,
                format!(
                    "session {} of {:?} is assigned twice",
                    row.session, row.subject
                ),
            ));
        }
        out.push(row);
    }
    Ok(out)
}

/// The header of [`GROUPS_FILE`].
const GROUPS_HEADER: [&str; 4] = ["subject", "session", "group", "ordinal"];

/// One session open for rows, holding its lock until dropped.
pub trait SessionWriter: Send {
    /// Rows committed.
    fn rows(&self) -> u32;

    /// The path that names this session in messages ([`Store::session_path`]).
    fn path(&self) -> PathBuf;

    /// Commits one row before returning: a folder appends it to `trials.csv` and fsyncs it
    /// (one fsync; `session.json` is not rewritten per row), a database inserts it and counts
    /// it in the session's `trials_logged` column in one transaction. The rows are the
    /// record: the manifest's `trials_logged` is the count when it was last written (at open,
    /// resume, display changes, interrupt and finish), and readers count the rows. After an
    /// error the row may be committed or not; calling again with the same row commits it
    /// once (a database writer that lost its connection reconnects, takes the session's lock
    /// again and looks).
    ///
    /// # Errors
    /// [`ResultsError::Unavailable`] when the database cannot be reached (try again later),
    /// other errors when the row cannot be written.
    fn append(&mut self, record: &TrialRecord) -> Result<(), ResultsError>;

    /// Replaces the session's manifest.
    ///
    /// # Errors
    /// As [`Self::append`].
    fn write_manifest(&mut self, manifest: &SessionManifest) -> Result<(), ResultsError>;

    /// Appends the presentation intervals of trial `index` to [`FRAMES_FILE`] (`phases[k]`
    /// what frame `k` showed). A folder flushes without fsync: the answer itself is already
    /// durable.
    ///
    /// # Errors
    /// As [`Self::append`].
    fn append_frames(
        &mut self,
        index: u32,
        intervals: &[f64],
        phases: &[&str],
    ) -> Result<(), ResultsError>;
}

/// The rows [`FRAMES_FILE`] gets for trial `index`: `trial_index,interval_ms,phase` (or
/// without the phase, `phased` false, for a file begun before the phase column).
pub fn frame_rows(index: u32, intervals: &[f64], phases: &[&str], phased: bool) -> String {
    let mut w = csv::Writer::from_writer(Vec::with_capacity(intervals.len() * 20));
    let index = index.to_string();
    for (k, ms) in intervals.iter().enumerate() {
        let ms = format!("{ms:.3}");
        // Writing into memory cannot fail.
        let _ = if phased {
            w.write_record([index.as_str(), &ms, phases.get(k).copied().unwrap_or("")])
        } else {
            w.write_record([&index, &ms])
        };
    }
    String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default()
}

/// What one answer appends to [`FRAMES_FILE`]: [`FRAMES_HEADER`] when the file begins with
/// it (`first`), then the trial's [`frame_rows`].
pub fn frames_text(
    first: bool,
    index: u32,
    intervals: &[f64],
    phases: &[&str],
    phased: bool,
) -> String {
    let mut text = String::new();
    if first {
        text.push_str(FRAMES_HEADER);
    }
    text.push_str(&frame_rows(index, intervals, phases, phased));
    text
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ResultsError {
    let path = path.to_path_buf();
    move |cause| ResultsError::Io {
        path,
        op: "write",
        cause,
    }
}

/// A results folder (`docs/results-format.md`): one sub-folder per session.
#[derive(Debug, Clone)]
pub struct FolderStore {
    root: PathBuf,
}

impl FolderStore {
    /// The results folder `root` (its run manifest is `lab::results_dir`'s).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The results folder.
    pub fn root(&self) -> &Path {
        &self.root
    }
}

impl Store for FolderStore {
    fn location(&self) -> String {
        self.root.display().to_string()
    }

    fn session_path(&self, subject: &str, session: u32) -> PathBuf {
        self.root.join(session_name(subject, session))
    }

    fn find_session(&mut self, subject: &str, session: u32) -> Result<Found, ResultsError> {
        let dir = self.session_path(subject, session);
        if !dir.exists() {
            return Ok(Found::Absent);
        }
        let manifest = dir.join(SESSION_FILE);
        Ok(Found::Present(if manifest.exists() {
            Some(Box::new(read_manifest(&manifest)?))
        } else {
            None
        }))
    }

    fn create_session(
        &mut self,
        manifest: &SessionManifest,
    ) -> Result<Box<dyn SessionWriter>, ResultsError> {
        let log = SessionLog::create(&self.session_path(&manifest.subject, manifest.session))?;
        log.write_manifest(manifest)?;
        Ok(Box::new(FolderWriter { log }))
    }

    fn resume_session(
        &mut self,
        subject: &str,
        session: u32,
    ) -> Result<ResumedSession, ResultsError> {
        let resumed = SessionLog::resume(&self.session_path(subject, session))?;
        let torn = resumed.torn.map(|(row, aside)| {
            let name = aside
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            (row, name)
        });
        Ok(ResumedSession {
            writer: Box::new(FolderWriter { log: resumed.log }),
            records: resumed.records,
            torn,
        })
    }

    fn check_not_held(&mut self, subject: &str, session: u32) -> Result<(), ResultsError> {
        // A crash after the final manifest write can leave the lock behind: take the stale
        // lock over and release it (refused if a live runner holds it).
        drop(SessionLock::acquire(&self.session_path(subject, session))?);
        Ok(())
    }

    fn discard_unstarted(&mut self, subject: &str, session: u32) -> Result<bool, ResultsError> {
        let dir = self.session_path(subject, session);
        let manifest: SessionManifest = read_manifest(&dir.join(SESSION_FILE))?;
        let trials = crate::read_trials(&dir.join(TRIALS_FILE))?;
        if manifest.resumes > 0 || !trials.records.is_empty() || trials.torn.is_some() {
            return Ok(false);
        }
        for f in [SESSION_FILE, TRIALS_FILE, LOCK_FILE] {
            let path = dir.join(f);
            match fs::remove_file(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io(&path)(e)),
                _ => {}
            }
        }
        Ok(fs::remove_dir(&dir).is_ok())
    }

    fn assign_group(
        &mut self,
        subject: &str,
        session: u32,
        groups: &[GroupQuota<'_>],
        wanted: Option<&str>,
    ) -> Result<Assignment, ResultsError> {
        let lock_path = self.root.join(GROUPS_LOCK_FILE);
        let lock = fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(false)
            .open(&lock_path)
            .map_err(io(&lock_path))?;
        // Waits for another station's assignment (held only while it reads and writes the
        // small file).
        lock.lock().map_err(io(&lock_path))?;
        let path = self.root.join(GROUPS_FILE);
        let mut rows = read_assignments(&path)?;
        if let Some(r) = rows
            .iter()
            .find(|r| r.subject == subject && r.session == session)
        {
            return Ok(Assignment {
                group: r.group.clone(),
                ordinal: r.ordinal,
                new: false,
            });
        }
        let counts: Vec<u32> = groups
            .iter()
            .map(|g| rows.iter().filter(|r| r.group == g.name).count() as u32)
            .collect();
        let i = choose_group(groups, &counts, wanted)
            .map_err(|why| ResultsError::Store(format!("{}: {why}", self.root.display())))?;
        let assignment = Assignment {
            group: groups[i].name.to_owned(),
            ordinal: counts[i],
            new: true,
        };
        rows.push(AssignedRow {
            subject: subject.to_owned(),
            session,
            group: assignment.group.clone(),
            ordinal: assignment.ordinal,
        });
        crate::store::write_atomic(&path, assignments_csv(&rows).as_bytes())?;
        drop(lock);
        Ok(assignment)
    }
}

/// A folder session open for rows ([`SessionLog`]).
#[derive(Debug)]
pub struct FolderWriter {
    log: SessionLog,
}

impl SessionWriter for FolderWriter {
    fn rows(&self) -> u32 {
        self.log.rows()
    }

    fn path(&self) -> PathBuf {
        self.log.dir().to_path_buf()
    }

    fn append(&mut self, record: &TrialRecord) -> Result<(), ResultsError> {
        // The fsynced row is the commit point; the manifest is rewritten only when the
        // session's state changes (a temporary file, its fsync, a rename and the folder's
        // fsync per row cost two more fsyncs per answer).
        self.log.append(record)
    }

    fn write_manifest(&mut self, manifest: &SessionManifest) -> Result<(), ResultsError> {
        self.log.write_manifest(manifest)
    }

    fn append_frames(
        &mut self,
        index: u32,
        intervals: &[f64],
        phases: &[&str],
    ) -> Result<(), ResultsError> {
        use std::io::{Read as _, Write as _};
        let path = self.log.dir().join(FRAMES_FILE);
        let read = |e| ResultsError::Io {
            path: path.clone(),
            op: "read",
            cause: e,
        };
        // A session begun before the phase column keeps its two columns when resumed.
        let (new, phased) = match fs::File::open(&path) {
            Ok(f) => {
                let mut head = Vec::with_capacity(64);
                f.take(64).read_to_end(&mut head).map_err(read)?;
                let phased = head
                    .split(|b| *b == b'\n')
                    .next()
                    .is_some_and(|h| h.ends_with(b",phase"));
                (false, phased)
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => (true, true),
            Err(e) => return Err(read(e)),
        };
        let text = frames_text(new, index, intervals, phases, phased);
        let mut f = fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io(&path))?;
        f.write_all(text.as_bytes())
            .and_then(|()| f.flush())
            .map_err(io(&path))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn row(subject: &str, session: u32, group: &str, ordinal: u32) -> AssignedRow {
        AssignedRow {
            subject: subject.into(),
            session,
            group: group.into(),
            ordinal,
        }
    }

    fn read(dir: &Path, text: &str) -> Result<Vec<AssignedRow>, ResultsError> {
        let path = dir.join(GROUPS_FILE);
        fs::write(&path, text).unwrap();
        read_assignments(&path)
    }

    #[test]
    fn group_assignments_round_trip_and_bad_lines_are_named() {
        let dir = std::env::temp_dir().join(format!("results-groups-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let rows = vec![row("S001", 1, "fast", 0), row("P, \"x\"", 2, "slow", 7)];
        let text = assignments_csv(&rows);
        assert_eq!(
            text,
            "subject,session,group,ordinal\nS001,1,fast,0\n\"P, \"\"x\"\"\",2,slow,7\n"
        );
        assert_eq!(read(&dir, &text).unwrap(), rows);
        assert!(
            read(&dir, "")
                .unwrap_err()
                .to_string()
                .contains("the header must be")
        );
        let e = read(&dir, "subject,session,group,ordinal\nS001,1,fast\n").unwrap_err();
        assert!(
            e.to_string()
                .contains("line 2, column 1: 3 fields; 4 expected"),
            "{e}"
        );
        let e = read(
            &dir,
            "subject,session,group,ordinal\nS001,1,a,0\nS002,1,a,1\nS001,1,b,0\n",
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("line 4, column 1: session 1 of \"S001\" is assigned twice"),
            "{e}"
        );
        let e = read(&dir, "subject,session,group,ordinal\nS001,one,a,0\n").unwrap_err();
        assert!(
            e.to_string()
                .contains("line 2, column 2: \"one\" is not a whole number"),
            "{e}"
        );
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn frame_rows_carry_the_phase_when_the_file_has_its_column() {
        let phases = ["stimulus", "gap"];
        assert_eq!(
            frame_rows(3, &[16.6667, 16.5], &phases, true),
            "3,16.667,stimulus\n3,16.500,gap\n"
        );
        assert_eq!(frame_rows(0, &[8.0], &[], true), "0,8.000,\n");
        assert_eq!(
            frame_rows(0, &[8.0, 9.25], &phases, false),
            "0,8.000\n0,9.250\n"
        );
    }
}
