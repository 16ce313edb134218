//! Who takes part: one session per participant, found by an unguessable token.
//!
//! A participant's id comes from the crowd platform's URL (Prolific's `PROLIFIC_PID`, with
//! `STUDY_ID` and `SESSION_ID`; MTurk's `workerId`, with `assignmentId` and `hitId`) or is
//! generated. Each new participant gets a token of 32 bytes from the OS random source; only
//! its SHA-256 is kept, in `participants.csv` (one row per participant, appended and fsynced
//! before the token leaves the server), so a restarted server knows every link it gave out
//! and the results folder holds no usable token.

use std::collections::{BTreeMap, HashMap};
use std::fs::{File, OpenOptions};
use std::io::{Read as _, Seek as _, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, RwLock, RwLockReadGuard};

use sha2::{Digest as _, Sha256};

use crate::app::Slot;
use crate::limits::Bucket;
use crate::{Result, WebError, io};

/// Header of `participants.csv` (version 1).
pub const HEADER: &str = "subject,token_sha256,source,created_ms,group,ids";

/// Largest `participants.csv` read, bytes.
const MAX_FILE_BYTES: u64 = 256 << 20;

/// The URL parameters that name a participant, and the manifest field each is kept as.
/// The first of each platform names the subject.
const PLATFORM_IDS: &[(&str, &str, &str)] = &[
    ("prolific", "PROLIFIC_PID", ""),
    ("prolific", "STUDY_ID", "prolific_study_id"),
    ("prolific", "SESSION_ID", "prolific_session_id"),
    ("mturk", "workerId", ""),
    ("mturk", "assignmentId", "mturk_assignment_id"),
    ("mturk", "hitId", "mturk_hit_id"),
];

/// One participant.
pub struct Participant {
    /// Subject id (the platform's id, or generated).
    pub subject: String,
    /// Where the id came from: `prolific`, `mturk` or `generated`.
    pub source: String,
    /// The platform's other ids, as session manifest fields (`prolific_study_id`, ...).
    pub ids: BTreeMap<String, String>,
    /// The plan group the participant was given (`[crowdsourcing] groups`), which is their subject
    /// index; `None`: the index derives from the subject id.
    pub group: Option<u32>,
    /// The session.
    pub(crate) slot: Mutex<Slot>,
    /// Requests allowed.
    pub(crate) bucket: Mutex<Bucket>,
    /// When they last made a request (joined, at first), ms since the Unix epoch.
    last_seen_ms: AtomicU64,
    /// Their session is over (complete or out of time).
    finished: AtomicBool,
}

/// Who a join request says the participant is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// Subject id, when a platform names one.
    pub subject: Option<String>,
    /// `prolific`, `mturk` or `generated`.
    pub source: String,
    /// Other ids to keep.
    pub ids: BTreeMap<String, String>,
}

/// Whether `v` can be an id: 1-64 letters, digits, `-` or `_`.
fn id_ok(v: &str) -> bool {
    !v.is_empty()
        && v.len() <= 64
        && v.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// The identity a page's URL parameters give.
///
/// # Errors
/// An id that is not 1-64 letters, digits, `-` or `_`; ids of two platforms at once; an
/// MTurk preview (`assignmentId=ASSIGNMENT_ID_NOT_AVAILABLE`: the HIT is not accepted yet).
pub fn identity(params: &BTreeMap<String, String>) -> Result<Identity> {
    let mut source: Option<&str> = None;
    let mut subject = None;
    let mut ids = BTreeMap::new();
    for (platform, key, field) in PLATFORM_IDS {
        let Some(v) = params.get(*key) else { continue };
        if *key == "assignmentId" && v == "ASSIGNMENT_ID_NOT_AVAILABLE" {
            return Err(WebError::Refused(
                "this is a preview of the task: accept the HIT to take part".into(),
            ));
        }
        if !id_ok(v) {
            return Err(WebError::Refused(format!(
                "URL parameter {key}: expected 1-64 letters, digits, '-' or '_'"
            )));
        }
        if source.is_some_and(|s| s != *platform) {
            return Err(WebError::Refused(
                "the URL names participants of two platforms".into(),
            ));
        }
        source = Some(platform);
        if field.is_empty() {
            subject = Some(v.clone());
        } else {
            ids.insert((*field).to_string(), v.clone());
        }
    }
    if source.is_some() && subject.is_none() {
        return Err(WebError::Refused(
            "the URL gives a platform's study ids without the participant's id".into(),
        ));
    }
    Ok(Identity {
        subject,
        source: source.unwrap_or("generated").to_string(),
        ids,
    })
}

/// A new token: 32 bytes from the OS random source, as 64 hex digits.
///
/// # Errors
/// The OS random source failed.
pub fn new_token() -> Result<String> {
    let mut b = [0u8; 32];
    getrandom::fill(&mut b)
        .map_err(|e| WebError::Refused(format!("the OS random source failed: {e}")))?;
    Ok(hex(&b))
}

/// A token's SHA-256.
pub fn token_hash(token: &str) -> [u8; 32] {
    Sha256::digest(token.as_bytes()).into()
}

fn hex(b: &[u8]) -> String {
    use std::fmt::Write as _;
    b.iter()
        .fold(String::with_capacity(b.len() * 2), |mut s, x| {
            let _ = write!(s, "{x:02x}");
            s
        })
}

fn unhex(s: &str) -> Option<[u8; 32]> {
    if s.len() != 64 {
        return None;
    }
    let mut out = [0u8; 32];
    for (i, o) in out.iter_mut().enumerate() {
        *o = u8::from_str_radix(s.get(2 * i..2 * i + 2)?, 16).ok()?;
    }
    Some(out)
}

/// Every participant, by token hash and by subject.
#[derive(Default)]
struct Index {
    by_hash: HashMap<[u8; 32], Arc<Participant>>,
    by_subject: HashMap<String, Arc<Participant>>,
    order: Vec<Arc<Participant>>,
}

impl Index {
    fn insert(&mut self, hash: [u8; 32], p: Participant) -> Arc<Participant> {
        let p = Arc::new(p);
        self.by_hash.insert(hash, Arc::clone(&p));
        self.by_subject.insert(p.subject.clone(), Arc::clone(&p));
        self.order.push(Arc::clone(&p));
        p
    }
}

/// `participants.csv`, appended to by one join at a time.
struct Appender {
    file: File,
    path: PathBuf,
}

impl Appender {
    fn append(&mut self, text: &str) -> Result<()> {
        self.file
            .write_all(text.as_bytes())
            .and_then(|()| self.file.sync_data())
            .map_err(io(self.path.display().to_string()))
    }
}

/// Where participants are kept: `participants.csv` of a results folder, or the
/// `study_participants` table of a database run that several servers share.
enum Backing {
    /// The file, held by a join for its whole check, append and fsync.
    File(Mutex<Appender>),
    /// The database (a join's check and insert are one transaction there).
    Db(Arc<crate::database::Db>),
}

/// Every participant, found by token or subject, and where they are kept.
///
/// Two locks, so that finding a participant (every request does) never waits for a disk:
/// the index is held only to look up or insert; a folder's file is held by a join for its
/// whole check, append and fsync, so joins take turns and never overrun a quota together.
/// With a database the index holds the participants this server has met; one another
/// server admitted is read from the database on their first request here.
pub struct Registry {
    index: RwLock<Index>,
    backing: Backing,
}

/// What a participant's place against a quota is measured with: the study's lease.
pub type Places = results::pg::participants::Places;

impl Registry {
    /// Opens (or creates) `participants.csv` in `dir`, reading every participant in it. A
    /// torn last row (a crash during its write: that participant never got a link) is cut
    /// off.
    ///
    /// # Errors
    /// The file cannot be read or written, or a complete row is malformed (named by line).
    pub fn open(dir: &Path) -> Result<Registry> {
        let path = dir.join(lab::results_dir::PARTICIPANTS_FILE);
        let at_path = || io(path.display().to_string());
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(&path)
            .map_err(at_path())?;
        let len = file.metadata().map_err(at_path())?.len();
        if len > MAX_FILE_BYTES {
            return Err(WebError::Refused(format!(
                "{}: {len} bytes is over the {MAX_FILE_BYTES}-byte limit",
                path.display()
            )));
        }
        let mut text = String::new();
        file.read_to_string(&mut text).map_err(at_path())?;
        let mut appender = Appender {
            file,
            path: path.clone(),
        };
        if text.is_empty() {
            appender.append(&format!("{HEADER}\n"))?;
        }
        let complete = text.rfind('\n').map_or(0, |i| i + 1);
        if complete < text.len() {
            eprintln!(
                "warning: {}: a torn last row ({} bytes) was cut off; that participant never got a link",
                path.display(),
                text.len() - complete
            );
            let f = &mut appender.file;
            f.set_len(complete as u64)
                .and_then(|()| f.sync_all())
                .and_then(|()| f.seek(std::io::SeekFrom::End(0)).map(drop))
                .map_err(at_path())?;
        }
        let mut index = Index::default();
        let reader = row_reader();
        for (i, line) in text[..complete].lines().enumerate() {
            let at = || format!("{} line {}", path.display(), i + 1);
            if i == 0 {
                if line != HEADER {
                    return Err(WebError::Refused(format!(
                        "{}: expected the header {HEADER:?}",
                        at()
                    )));
                }
                continue;
            }
            let (p, hash) = read_fields(&reader, line)
                .and_then(|fields| parse_row(&fields))
                .map_err(|e| WebError::Refused(format!("{}: {e}", at())))?;
            index.insert(hash, p);
        }
        Ok(Registry {
            index: RwLock::new(index),
            backing: Backing::File(Mutex::new(appender)),
        })
    }

    /// The participants of a database run, shared with every other server of the run.
    pub(crate) fn shared(db: Arc<crate::database::Db>) -> Registry {
        Registry {
            index: RwLock::new(Index::default()),
            backing: Backing::Db(db),
        }
    }

    fn index(&self) -> RwLockReadGuard<'_, Index> {
        self.index.read().unwrap_or_else(PoisonError::into_inner)
    }

    fn remember(
        &self,
        hash: [u8; 32],
        row: results::pg::participants::ParticipantRow,
    ) -> Arc<Participant> {
        let mut index = self.index.write().unwrap_or_else(PoisonError::into_inner);
        if let Some(p) = index.by_hash.get(&hash) {
            return Arc::clone(p);
        }
        index.insert(hash, Participant::from_row(row))
    }

    /// The participant a token belongs to.
    ///
    /// # Errors
    /// The database cannot be read.
    pub fn by_token(&self, token: &str) -> Result<Option<Arc<Participant>>> {
        let hash = token_hash(token);
        if let Some(p) = self.index().by_hash.get(&hash) {
            return Ok(Some(Arc::clone(p)));
        }
        let Backing::Db(db) = &self.backing else {
            return Ok(None);
        };
        let row =
            results::pg::participants::by_token(&mut *db.conn()?, db.run_id, &db.location, &hash)
                .map_err(lab::LabError::from)?;
        Ok(row.map(|r| self.remember(hash, r)))
    }

    /// The participants this server has met, in the order it met them (a folder's: every
    /// participant).
    pub fn local(&self) -> Vec<Arc<Participant>> {
        self.index().order.clone()
    }

    /// Adds a participant of identity `who` (a generated id when no platform names one)
    /// and returns it with its token, after it is on disk or committed. `admit` sees the
    /// places held, counted with a lease of `lease_s` seconds (no other join can add one
    /// meanwhile, on this server or another), and gives the newcomer's group, or refuses
    /// them.
    ///
    /// # Errors
    /// `admit` refuses, the id already took part (one session per participant), or the row
    /// cannot be written.
    pub fn join<E: From<WebError> + From<results::ResultsError>>(
        &self,
        who: &Identity,
        lease_s: u32,
        admit: impl FnOnce(&Places) -> std::result::Result<Option<u32>, E>,
    ) -> std::result::Result<(Arc<Participant>, String), E> {
        let taken = |s: &str| {
            WebError::Refused(format!(
                "participant {s} already has a session: continue it from its link"
            ))
        };
        let token = new_token()?;
        let hash = token_hash(&token);
        let file = match &self.backing {
            Backing::File(file) => file,
            Backing::Db(db) => {
                let subject = match &who.subject {
                    Some(s) => s.clone(),
                    None => generated_id()?,
                };
                let mut row = results::pg::participants::ParticipantRow {
                    subject,
                    source: who.source.clone(),
                    ids: who.ids.clone(),
                    group: None,
                    finished: false,
                };
                let mut conn = db.conn()?;
                row.group = results::pg::participants::join(
                    &mut conn,
                    db.run_id,
                    &db.location,
                    lease_s,
                    &row,
                    &hash,
                    |places, is_taken| {
                        if is_taken {
                            return Err(E::from(taken(&row.subject)));
                        }
                        admit(places)
                    },
                )?;
                return Ok((self.remember(hash, row), token));
            }
        };
        let mut file = file.lock().unwrap_or_else(PoisonError::into_inner);
        let (subject, group) = {
            let index = self.index();
            let now_ms = lab::session::now_ms();
            let lease_ms = u64::from(lease_s) * 1000;
            let mut places = Places {
                total: index.order.len() as u64,
                ..Places::default()
            };
            for p in index
                .order
                .iter()
                .filter(|p| p.holds_place(now_ms, lease_ms))
            {
                *places.held.entry(p.group).or_default() += 1;
            }
            let group = admit(&places)?;
            let subject = match &who.subject {
                Some(s) => {
                    if index.by_subject.contains_key(s) {
                        return Err(taken(s).into());
                    }
                    s.clone()
                }
                None => loop {
                    let s = generated_id()?;
                    if !index.by_subject.contains_key(&s) {
                        break s;
                    }
                },
            };
            (subject, group)
        };
        let ids: Vec<String> = who.ids.iter().map(|(k, v)| format!("{k}={v}")).collect();
        let created_ms = lab::session::now_ms();
        file.append(&encode_row(&[
            &subject,
            &hex(&hash),
            &who.source,
            &created_ms.to_string(),
            &group.map(|g| g.to_string()).unwrap_or_default(),
            &ids.join(";"),
        ])?)?;
        let p = self
            .index
            .write()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(
                hash,
                Participant::new(
                    subject,
                    who.source.clone(),
                    who.ids.clone(),
                    group,
                    created_ms,
                ),
            );
        Ok((p, token))
    }
}

/// A generated subject id: `W` and 12 hex digits from the OS random source.
fn generated_id() -> Result<String> {
    let t = new_token()?;
    Ok(format!("W{}", &t[..12]))
}

impl Participant {
    fn new(
        subject: String,
        source: String,
        ids: BTreeMap<String, String>,
        group: Option<u32>,
        created_ms: u64,
    ) -> Participant {
        Participant {
            subject,
            source,
            ids,
            group,
            slot: Mutex::new(Slot::NotStarted),
            bucket: Mutex::new(Bucket::new(f64::MAX)),
            last_seen_ms: AtomicU64::new(created_ms),
            finished: AtomicBool::new(false),
        }
    }

    /// A participant as a database run holds them.
    pub(crate) fn from_row(row: results::pg::participants::ParticipantRow) -> Participant {
        let p = Participant::new(
            row.subject,
            row.source,
            row.ids,
            row.group,
            lab::session::now_ms(),
        );
        if row.finished {
            p.set_finished();
        }
        p
    }

    /// Notes a request of theirs at `now_ms` (ms since the Unix epoch).
    pub(crate) fn seen(&self, now_ms: u64) {
        self.last_seen_ms.fetch_max(now_ms, Ordering::Relaxed);
    }

    /// Notes that their session is over.
    pub(crate) fn set_finished(&self) {
        self.finished.store(true, Ordering::Relaxed);
    }

    /// Whether they hold a place against a quota at `now_ms`: their session is over, or
    /// their last request (their join, before any) is less than `lease_ms` ago.
    pub fn holds_place(&self, now_ms: u64, lease_ms: u64) -> bool {
        self.finished.load(Ordering::Relaxed)
            || now_ms.saturating_sub(self.last_seen_ms.load(Ordering::Relaxed)) < lease_ms
    }
}

/// One `participants.csv` row with its `\n`, written by the csv crate: a value that holds a
/// comma or a quote is quoted, its quotes doubled (none of today's values has either: ids,
/// hex, numbers). A line break is refused, so that every row stays one line and a torn last
/// row is what follows the last `\n`.
///
/// # Errors
/// A value holds a line break.
fn encode_row(fields: &[&str; 6]) -> Result<String> {
    if let Some(f) = fields.iter().find(|f| f.contains(['\n', '\r'])) {
        return Err(WebError::Refused(format!(
            "{}: the value {f:?} holds a line break",
            lab::results_dir::PARTICIPANTS_FILE
        )));
    }
    let failed = |e: &dyn std::fmt::Display| {
        WebError::Refused(format!(
            "{}: cannot write a row: {e}",
            lab::results_dir::PARTICIPANTS_FILE
        ))
    };
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .buffer_capacity(512)
        .from_writer(Vec::with_capacity(160));
    w.write_record(fields).map_err(|e| failed(&e))?;
    let bytes = w.into_inner().map_err(|e| failed(e.error()))?;
    String::from_utf8(bytes).map_err(|e| failed(&e))
}

/// The CSV reader of one line of `participants.csv` (its line end taken off): only `\n`
/// ends a row, so a `\r` inside one is text.
fn row_reader() -> csv::ReaderBuilder {
    let mut b = csv::ReaderBuilder::new();
    b.has_headers(false)
        .flexible(true)
        .terminator(csv::Terminator::Any(b'\n'))
        .buffer_capacity(512);
    b
}

/// The fields of one line (without its line end), read by the csv crate; an empty line is
/// one empty field.
fn read_fields(
    reader: &csv::ReaderBuilder,
    line: &str,
) -> std::result::Result<csv::StringRecord, String> {
    let mut fields = csv::StringRecord::new();
    match reader.from_reader(line.as_bytes()).read_record(&mut fields) {
        Ok(true) => Ok(fields),
        // The reader skips an empty line.
        Ok(false) => Ok(csv::StringRecord::from(vec![""])),
        Err(e) => Err(e.to_string()),
    }
}

fn parse_row(fields: &csv::StringRecord) -> std::result::Result<(Participant, [u8; 32]), String> {
    let f: Vec<&str> = fields.iter().collect();
    let [subject, hash, source, created, group, ids] = f[..] else {
        return Err(format!("expected 6 fields, found {}", f.len()));
    };
    let group = if group.is_empty() {
        None
    } else {
        Some(
            group
                .parse::<u32>()
                .map_err(|_| format!("group {group:?} is not a number"))?,
        )
    };
    if !id_ok(subject) {
        return Err(format!("subject {subject:?} is not an id"));
    }
    let hash = unhex(hash).ok_or("token_sha256 is not 64 hex digits")?;
    if !matches!(source, "prolific" | "mturk" | "generated") {
        return Err(format!("unknown source {source:?}"));
    }
    let created_ms = created
        .parse::<u64>()
        .map_err(|_| format!("created_ms {created:?} is not a number"))?;
    let mut map = BTreeMap::new();
    for kv in ids.split(';').filter(|s| !s.is_empty()) {
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| format!("id {kv:?} is not key=value"))?;
        if !PLATFORM_IDS.iter().any(|(_, _, f)| *f == k) || !id_ok(v) {
            return Err(format!("id {kv:?} is not one of the platforms' ids"));
        }
        map.insert(k.to_string(), v.to_string());
    }
    Ok((
        Participant::new(subject.into(), source.into(), map, group, created_ms),
        hash,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(kv: &[(&str, &str)]) -> BTreeMap<String, String> {
        kv.iter().map(|(k, v)| ((*k).into(), (*v).into())).collect()
    }

    #[test]
    fn platform_ids_name_the_subject_and_bad_ones_are_refused() {
        let p = identity(&params(&[
            ("PROLIFIC_PID", "5f3a9c"),
            ("STUDY_ID", "st1"),
            ("SESSION_ID", "se1"),
        ]))
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(p.subject.as_deref(), Some("5f3a9c"));
        assert_eq!(p.source, "prolific");
        assert_eq!(
            p.ids.get("prolific_session_id").map(String::as_str),
            Some("se1")
        );
        assert_eq!(
            identity(&params(&[])).map(|i| i.source).ok().as_deref(),
            Some("generated")
        );
        for bad in [
            params(&[("PROLIFIC_PID", "../x")]),
            params(&[("PROLIFIC_PID", "a"), ("workerId", "b")]),
            params(&[
                ("workerId", "A1"),
                ("assignmentId", "ASSIGNMENT_ID_NOT_AVAILABLE"),
            ]),
            params(&[("STUDY_ID", "s")]),
        ] {
            assert!(identity(&bad).is_err(), "{bad:?}");
        }
    }

    /// Today's values (ids, hex, numbers) are written as they are, the same bytes as ever.
    #[test]
    fn a_row_of_plain_values_is_written_as_it_is() {
        let hash = hex(&token_hash("t"));
        let fields = [
            "A1",
            hash.as_str(),
            "mturk",
            "1795000000000",
            "",
            "mturk_assignment_id=X;mturk_hit_id=H",
        ];
        let row = encode_row(&fields).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(row, format!("{}\n", fields.join(",")));
        let read = read_fields(&row_reader(), row.trim_end_matches('\n'))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(read, csv::StringRecord::from(fields.to_vec()));
        let (p, h) = parse_row(&read).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (p.subject.as_str(), p.group, h),
            ("A1", None, token_hash("t"))
        );
        assert_eq!(p.ids.len(), 2);
    }

    /// A value with a comma or a quote is quoted and reads back as it was, in its own
    /// column, instead of splitting the row; a line break is refused.
    #[test]
    fn values_with_commas_and_quotes_round_trip() {
        let fields = ["a,b", "say \"hi\"", "\"", ",", "", "k=v;x=\"1,2\""];
        let row = encode_row(&fields).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            row,
            "\"a,b\",\"say \"\"hi\"\"\",\"\"\"\",\",\",,\"k=v;x=\"\"1,2\"\"\"\n"
        );
        assert_eq!(row.lines().count(), 1);
        let read = read_fields(&row_reader(), row.trim_end_matches('\n'))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(read, csv::StringRecord::from(fields.to_vec()));
        // Six fields: the row is refused for its values, not for its shape.
        let err = parse_row(&read).err().unwrap_or_default();
        assert_eq!(err, "subject \"a,b\" is not an id");
        assert!(encode_row(&["a\nb", "", "", "", "", ""]).is_err());
        assert!(encode_row(&["a", "", "", "", "", "\r"]).is_err());
        // A line of other than six fields, an empty one included, is named by its count.
        for (line, n) in [("", 1), ("a,b", 2), ("a,b,c,d,e,f,g", 7), ("\"a,b\",c", 2)] {
            let read = read_fields(&row_reader(), line).unwrap_or_else(|e| panic!("{e}"));
            let err = parse_row(&read).err().unwrap_or_default();
            assert_eq!(err, format!("expected 6 fields, found {n}"), "{line:?}");
        }
    }

    /// A malformed complete row is an error naming the file and the line.
    #[test]
    fn a_bad_row_is_named_by_file_and_line() {
        let dir = std::env::temp_dir().join(format!("web-reg-bad-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let path = dir.join(lab::results_dir::PARTICIPANTS_FILE);
        let good = format!("A1,{},mturk,5,,\n", hex(&token_hash("t")));
        for (rows, want) in [
            ("a,b\n", "line 3: expected 6 fields, found 2"),
            ("\n", "line 3: expected 6 fields, found 1"),
            (
                "\"a,b\",x,mturk,5,,\n",
                "line 3: subject \"a,b\" is not an id",
            ),
        ] {
            std::fs::write(&path, format!("{HEADER}\n{good}{rows}"))
                .unwrap_or_else(|e| panic!("{e}"));
            let err = Registry::open(&dir).err().map(|e| e.to_string());
            assert_eq!(err, Some(format!("{} {want}", path.display())));
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_registry_survives_a_restart_and_a_torn_row() {
        let dir = std::env::temp_dir().join(format!("web-reg-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let who = identity(&params(&[("workerId", "A1"), ("hitId", "H")]))
            .unwrap_or_else(|e| panic!("{e}"));
        let token = {
            let reg = Registry::open(&dir).unwrap_or_else(|e| panic!("{e}"));
            let (_, token) = reg
                .join::<WebError>(&who, 60, |_| Ok(Some(3)))
                .unwrap_or_else(|e| panic!("{e}"));
            // One session per participant.
            assert!(reg.join::<WebError>(&who, 60, |_| Ok(Some(1))).is_err());
            token
        };
        // A crash in the middle of the next row.
        let path = dir.join(lab::results_dir::PARTICIPANTS_FILE);
        let mut f = OpenOptions::new()
            .append(true)
            .open(&path)
            .unwrap_or_else(|e| panic!("{e}"));
        f.write_all(b"W12,abc").unwrap_or_else(|e| panic!("{e}"));
        drop(f);
        let reg = Registry::open(&dir).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(reg.local().len(), 1);
        let found = |t: &str| reg.by_token(t).unwrap_or_else(|e| panic!("{e}"));
        let p = found(&token).map(|p| (p.subject.clone(), p.group));
        assert_eq!(p, Some(("A1".to_string(), Some(3))));
        assert!(found(&new_token().unwrap_or_default()).is_none());
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(text.ends_with('\n') && !text.contains(&token), "{text}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn joins_at_once_keep_the_quota_and_lookups_never_wait_for_a_join() {
        let dir = std::env::temp_dir().join(format!("web-reg-q-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let reg = Registry::open(&dir).unwrap_or_else(|e| panic!("{e}"));
        // 24 joins at once against a quota of 10: exactly 10 get in, each once.
        let admitted: Vec<(String, String)> = std::thread::scope(|s| {
            let joins: Vec<_> = (0..24)
                .map(|k| {
                    let reg = &reg;
                    s.spawn(move || {
                        let who = identity(&params(&[("PROLIFIC_PID", &format!("q{k}"))]))
                            .unwrap_or_else(|e| panic!("{e}"));
                        reg.join(&who, 60, |places| {
                            if places.total >= 10 {
                                Err(WebError::Refused("full".into()))
                            } else {
                                Ok(Some(u32::try_from(places.total).unwrap_or(0)))
                            }
                        })
                        .ok()
                        .map(|(p, t)| (p.subject.clone(), t))
                    })
                })
                .collect();
            joins
                .into_iter()
                .filter_map(|j| j.join().unwrap_or_else(|_| panic!("a join panicked")))
                .collect()
        });
        assert_eq!(admitted.len(), 10);
        let mut groups: Vec<Option<u32>> = reg.local().iter().map(|p| p.group).collect();
        groups.sort_unstable();
        assert_eq!(groups, (0..10).map(Some).collect::<Vec<_>>());
        let rows = std::fs::read_to_string(dir.join(lab::results_dir::PARTICIPANTS_FILE))
            .unwrap_or_default()
            .lines()
            .count();
        assert_eq!(rows, 11, "the header and one row per participant");

        // While a join holds the file (its append and fsync), every participant is still
        // found: a request never waits for another participant's disk write.
        let (subject, token) = &admitted[0];
        let Backing::File(file) = &reg.backing else {
            panic!("a folder's registry")
        };
        let held = file.lock().unwrap_or_else(PoisonError::into_inner);
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::scope(|s| {
            s.spawn(|| {
                let _ = tx.send(
                    reg.by_token(token)
                        .ok()
                        .flatten()
                        .map(|p| p.subject.clone()),
                );
            });
            let found = rx.recv_timeout(std::time::Duration::from_secs(10));
            drop(held);
            assert_eq!(found.ok().flatten().as_ref(), Some(subject));
        });
        let _ = std::fs::remove_dir_all(&dir);
    }
}
