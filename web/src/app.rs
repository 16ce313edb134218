//! The server's state and what each request does to it, without HTTP: the study, its
//! stimulus source, the participants and their sessions. Every call that touches a session
//! holds that participant's lock and may block on disk (the handlers run them on tokio's
//! blocking pool), so one participant's requests are served one at a time, in order, and
//! different participants' in parallel.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::Instant;

use lab::results_dir::Destination;
use lab::scene::{Casting, View};
use lab::session::{self, Opened, Recorder};
use lab::source::StimulusSource;
use lab::{LabError, StudyFile};
use protocols::TrialRecord;
use protocols::record::{Answer, Arrangement, Block, Response, Trial};
use protocols::screen::Screen;
use protocols::study::{
    CrowdsourcingSettings, HiddenRule, MAX_FIELD_CHARS, ScaleKind, StudyDefinition, SubjectField,
};
use protocols::{FrameTiming, StimulusEncoding, texts};
use results::pg::participants as participants_db;
use results::store::{BrowserInfo, DisplayInfo, SessionState};
use results::{SessionManifest, SessionResults};
use serde::{Deserialize, Serialize};

use crate::database::Db;
use crate::limits::{Bucket, Limits, MAX_INTERVALS, MAX_REPORTED_MS};
use crate::participants::{Participant, Places, Registry, identity};
use crate::{Result, ServeOptions, WebError, clipdata, io, staging, timing};

/// A refused request: the HTTP status and the reason the page shows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ApiError {
    /// HTTP status.
    pub status: u16,
    /// Why.
    pub message: String,
}

impl ApiError {
    /// A refusal with `status`.
    pub fn new(status: u16, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            message: message.into(),
        }
    }
}

impl From<WebError> for ApiError {
    fn from(e: WebError) -> ApiError {
        match e {
            WebError::Refused(m) => ApiError::new(409, m),
            WebError::Lab(e) => e.into(),
            e => ApiError::new(500, lab::error::chain(&e)),
        }
    }
}

impl From<results::ResultsError> for ApiError {
    fn from(e: results::ResultsError) -> ApiError {
        LabError::from(e).into()
    }
}

impl From<LabError> for ApiError {
    fn from(e: LabError) -> ApiError {
        match e {
            // Another server moved the session on meanwhile (asked again, this server
            // replays it first), or the database is away for now: the page asks again.
            LabError::Results(
                results::ResultsError::Moved { .. } | results::ResultsError::Unavailable { .. },
            ) => ApiError::new(503, format!("{}; try again", lab::error::chain(&e))),
            LabError::Engine(_) => ApiError::new(422, lab::error::chain(&e)),
            e => ApiError::new(500, lab::error::chain(&e)),
        }
    }
}

type ApiResult<T> = std::result::Result<T, ApiError>;

/// A participant's session.
pub(crate) enum Slot {
    /// Joined, not begun (welcome and consent not done yet).
    NotStarted,
    /// Open: the recorder and the trial on the page.
    Live(Box<Live>),
    /// Complete or out of time.
    Finished(Box<SessionManifest>),
}

pub(crate) struct Live {
    rec: Box<Recorder>,
    pending: Option<Pending>,
    /// The last logged trial's index and answer (a repeated post of it is acknowledged).
    last: Option<(u32, Answer)>,
    /// With a database: the trial it says was sent last, and when (by this process's
    /// clock), as read at the start of the request.
    db_sent: Option<(u32, Instant)>,
}

/// Where the sessions and participants are.
enum Place {
    /// A results folder.
    Folder(PathBuf),
    /// A database run shared with other servers.
    Db(Arc<Db>),
}

struct Pending {
    trial: Trial,
    /// The trials the screen answers: a MUSHRA screen's panes in order (the ones not yet
    /// answered), else `trial` alone.
    panes: Vec<Trial>,
    /// When it was sent: the page cannot have played the stimuli for longer.
    sent: Sent,
    /// The clips the page draws, in the order the scene's figures name them.
    clips: Vec<Arc<Vec<u8>>>,
    /// What the page shows: the screen (`protocols::screen::Screen`) and the scene.
    screen: Arc<serde_json::Value>,
    encoding: Option<StimulusEncoding>,
    /// When answers open, ms from the start of the first pass (the schedule's).
    answers_open_ms: f64,
}

/// When the pending trial was sent to the page.
#[derive(Debug, Clone, Copy)]
enum Sent {
    /// Not yet: no answer to it is taken.
    Never,
    /// When the page last asked for it, by this process's monotonic clock.
    At(Instant),
    /// When it was first sent, by a server that was restarted since: ms since the Unix
    /// epoch, from the session's [`SENT_FILE`].
    Before(u64),
}

impl Sent {
    /// Milliseconds since it was sent; `None` if it never was.
    fn since_ms(self) -> Option<f64> {
        match self {
            Sent::Never => None,
            Sent::At(t) => Some(t.elapsed().as_secs_f64() * 1e3),
            // A wall clock set back since counts as no time at all.
            Sent::Before(ms) => Some(lab::session::now_ms().saturating_sub(ms) as f64),
        }
    }
}

/// The session folder's record of when its pending trial was first sent (format version 1:
/// `{"format_version": 1, "index": I, "sent_ms": T}`, T in ms since the Unix epoch), written
/// whole (temporary name, fsync, rename) before the trial leaves the server, so that a
/// restarted server still knows how long the page can have played it.
pub const SENT_FILE: &str = lab::results_dir::TRIAL_SENT_FILE;

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SentRecord {
    format_version: u32,
    index: u32,
    sent_ms: u64,
}

/// When trial `index` of the session in `dir` was first sent, if [`SENT_FILE`] says.
fn sent_before(dir: &Path, index: u32) -> ApiResult<Sent> {
    let path = dir.join(SENT_FILE);
    if !path.exists() {
        return Ok(Sent::Never);
    }
    let bad = |why: String| ApiError::new(500, format!("{}: {why}", path.display()));
    let bytes = results::store::read_limited(&path, 4096).map_err(|e| bad(e.to_string()))?;
    let r: SentRecord = serde_json::from_slice(&bytes).map_err(|e| bad(e.to_string()))?;
    if r.format_version != 1 {
        return Err(bad(format!("format_version {} is not 1", r.format_version)));
    }
    Ok(if r.index == index {
        Sent::Before(r.sent_ms)
    } else {
        Sent::Never
    })
}

/// Records in `dir` that trial `index` is sent now.
fn record_sent(dir: &Path, index: u32) -> ApiResult<()> {
    let r = SentRecord {
        format_version: 1,
        index,
        sent_ms: lab::session::now_ms(),
    };
    let bytes = serde_json::to_vec(&r).map_err(|e| ApiError::new(500, e.to_string()))?;
    results::store::write_atomic(&dir.join(SENT_FILE), &bytes)
        .map_err(|e| ApiError::new(500, e.to_string()))
}

/// What the page checked before the participant could join, and reports when the session
/// begins.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Environment {
    /// WebGL2 is available.
    pub webgl2: bool,
    /// The WebGL renderer string.
    pub webgl_renderer: String,
    /// `navigator.userAgent`.
    pub user_agent: String,
    /// `screen.width`, `screen.height`.
    pub screen_px: [u32; 2],
    /// `innerWidth`, `innerHeight`.
    pub window_px: [u32; 2],
    /// `devicePixelRatio`.
    pub device_pixel_ratio: f64,
    /// Refresh rate measured from `requestAnimationFrame`, Hz.
    pub refresh_hz: f64,
    /// In fullscreen.
    pub fullscreen: bool,
}

/// What the browser must offer before a participant may join (an environment check before
/// consent).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Requirements {
    /// Smallest window, CSS pixels.
    pub min_window_px: [u32; 2],
    /// Lowest refresh rate, Hz.
    pub min_refresh_hz: f64,
    /// The study is shown in fullscreen.
    pub fullscreen: bool,
}

impl Requirements {
    /// What a study's `[crowdsourcing]` settings ask of the browser.
    pub fn of(crowd: &CrowdsourcingSettings) -> Requirements {
        Requirements {
            min_window_px: crowd.min_window_px,
            min_refresh_hz: crowd.min_refresh_hz,
            fullscreen: crowd.fullscreen,
        }
    }

    /// What `env` lacks, one sentence each; empty when it will do.
    pub fn unmet(&self, env: &Environment) -> Vec<String> {
        let mut out = Vec::new();
        if !env.webgl2 {
            out.push("the browser offers no WebGL2 (3-D graphics)".to_string());
        }
        let [w, h] = self.min_window_px;
        if env.window_px[0] < w || env.window_px[1] < h {
            out.push(format!(
                "the window is {}×{}; the study needs at least {w}×{h}",
                env.window_px[0], env.window_px[1]
            ));
        }
        if !env.refresh_hz.is_finite() || env.refresh_hz > 1000.0 {
            out.push("the page measured no refresh rate".to_string());
        } else if env.refresh_hz < self.min_refresh_hz {
            out.push(format!(
                "the display refreshes at {:.0} Hz; the study needs at least {:.0} Hz",
                env.refresh_hz, self.min_refresh_hz
            ));
        }
        if self.fullscreen && !env.fullscreen {
            out.push("the study runs in fullscreen".to_string());
        }
        out
    }
}

/// `POST .../begin`: the welcome screen's fields, consent and the measured environment.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeginRequest {
    /// The study's subject fields.
    pub fields: BTreeMap<String, String>,
    /// "I agree to take part" ticked.
    pub consent: bool,
    /// The browser.
    pub environment: Environment,
}

/// `POST .../answer`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnswerRequest {
    /// The trial's index.
    pub index: u32,
    /// The answer.
    pub answer: Answer,
    /// Replays used.
    pub replays: u32,
    /// From the end of the presentation to the answer, ms.
    pub response_time_ms: u64,
    /// How long the page showed the stimuli before the answer, ms.
    pub played_ms: f64,
    /// A MUSHRA screen's rating of each pane, in pane order (`answer` is the first's);
    /// empty for any other trial.
    #[serde(default)]
    pub pane_ratings: Vec<f64>,
    /// The `requestAnimationFrame` intervals of the trial, ms.
    pub intervals: Vec<f64>,
    /// What each frame showed (`both`, `a`, `grey`, `answer`, ...).
    pub phases: Vec<String>,
    /// The page was hidden while the stimuli played.
    pub hidden: bool,
    /// The page was in fullscreen when answered.
    pub fullscreen: bool,
}

/// The acknowledgement of an answer.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct AnswerReply {
    /// The same answer to the same trial was already logged; nothing was written.
    pub duplicate: bool,
    /// Trials answered so far.
    pub answered: u32,
}

/// A participant, their session's state, manifest and committed rows (the dashboard's).
type Overview = (
    Arc<Participant>,
    &'static str,
    Option<SessionManifest>,
    Vec<TrialRecord>,
);

/// A stimulus' joint positions as served, made by whichever request needs them first.
type ClipCell = Arc<OnceLock<Arc<Vec<u8>>>>;

/// The study, its stimuli, participants and sessions.
pub struct App {
    study: StudyFile,
    place: Place,
    page: Page,
    stimuli: Mutex<Box<dyn StimulusSource>>,
    /// Reference stimulus id → the view that frames it (every frame of it walked once).
    views: Mutex<HashMap<String, View>>,
    /// Held while a session of a results folder is opened (created or resumed).
    opening: Mutex<()>,
    /// Stimulus id → its joint positions as served, each made once (the first request for
    /// an id makes it; others for the same id wait for that one instead of making it too).
    clips: Mutex<HashMap<String, ClipCell>>,
    /// Stimuli read and made ready before the first participant.
    preloaded: usize,
    registry: Registry,
    limits: Limits,
    dashboard: Option<String>,
    joins: Mutex<Bucket>,
    requirements: Requirements,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Reads the built page: every file of `dir` (not below it).
/// The built page: file name → content type and bytes.
type Page = HashMap<String, (&'static str, Arc<Vec<u8>>)>;

fn read_page(dir: &Path) -> Result<Page> {
    if !dir.join("index.html").is_file() {
        return Err(WebError::Refused(format!(
            "{}: the study page is not built (no index.html); run scripts/build-page",
            dir.display()
        )));
    }
    let mut page = HashMap::new();
    for entry in std::fs::read_dir(dir).map_err(io(dir.display().to_string()))? {
        let entry = entry.map_err(io(dir.display().to_string()))?;
        let path = entry.path();
        if !path.is_file() {
            continue;
        }
        let name = entry.file_name().to_string_lossy().into_owned();
        let kind = match path.extension().and_then(|e| e.to_str()) {
            Some("html") => "text/html; charset=utf-8",
            Some("js") => "text/javascript; charset=utf-8",
            Some("css") => "text/css; charset=utf-8",
            Some("map" | "json") => "application/json",
            _ => continue,
        };
        let bytes = std::fs::read(&path).map_err(io(path.display().to_string()))?;
        page.insert(name, (kind, Arc::new(bytes)));
    }
    Ok(page)
}

/// What the built page cannot draw of `study`'s screens, as "answer rating_pair" and the
/// like: its first trial's [`Screen`] (every trial of a study has the same answer widget,
/// pane content and schedule kinds) against the page's `capabilities.json`.
fn unsupported(study: &StudyDefinition, page: &Page) -> Result<Vec<String>> {
    let caps: serde_json::Value = page
        .get("capabilities.json")
        .and_then(|(_, bytes)| serde_json::from_slice(bytes).ok())
        .ok_or_else(|| {
            WebError::Refused(
                "the study page has no readable capabilities.json; run scripts/build-page".into(),
            )
        })?;
    let mut engine = protocols::engine::Session::new(study, 0)
        .map_err(|e| WebError::Refused(format!("the study's plan: {e}")))?;
    let Some(trial) = engine
        .next_trial(0)
        .map_err(|e| WebError::Refused(format!("the study's plan: {e}")))?
    else {
        return Ok(Vec::new());
    };
    let screen = serde_json::to_value(Screen::of(study, &trial, 1.0))
        .map_err(|e| WebError::Refused(format!("the study's screen: {e}")))?;
    let mut wanted: Vec<(&str, serde_json::Value)> =
        vec![("answer", screen["answer"]["kind"].clone())];
    if let Some(panes) = screen["panes"].as_array() {
        wanted.extend(
            panes
                .iter()
                .map(|p| ("content", p["content"]["kind"].clone())),
        );
    }
    if let Some(steps) = screen["schedule"]["steps"].as_array() {
        wanted.extend(steps.iter().map(|s| ("show", s["show"].clone())));
    }
    let mut missing: Vec<String> = wanted
        .into_iter()
        .filter(|(what, kind)| {
            !caps[*what]
                .as_array()
                .is_some_and(|known| known.contains(kind))
        })
        .map(|(what, kind)| format!("{what} {}", kind.as_str().unwrap_or("?")))
        .collect();
    missing.dedup();
    Ok(missing)
}

/// The welcome screen's fields as the page draws and checks them: each field as the study
/// definition serializes it (`name`, `label`, `kind` and its bounds), with `hint` (what an
/// answer must be, in the words a refusal gives), `options` (the buttons: a choice's
/// options, yes and no; none for typed answers) and `max_chars`.
fn fields_json(fields: &[SubjectField]) -> Vec<serde_json::Value> {
    fields
        .iter()
        .map(|f| {
            let mut v = serde_json::json!(f);
            if let Some(o) = v.as_object_mut() {
                o.insert("hint".into(), f.hint().into());
                o.insert("max_chars".into(), MAX_FIELD_CHARS.into());
                let options = f.options();
                if !options.is_empty() {
                    o.insert("options".into(), options.into());
                }
            }
            v
        })
        .collect()
}

impl App {
    /// Loads the study, checks every stimulus its plan can show, opens the results
    /// directory (created on first use; a later run continues it) and the participants.
    ///
    /// # Errors
    /// As [`crate::start`].
    pub fn open(options: &ServeOptions) -> Result<App> {
        let page = read_page(&options.page)?;
        let study = StudyFile::load(&options.study)?;
        // A study whose screens the page cannot draw is refused before anyone joins.
        let missing = unsupported(&study.definition, &page)?;
        if !missing.is_empty() {
            return Err(WebError::Refused(format!(
                "{}: the browser page cannot show this study's screens ({}); run it in the \
                 study window (study run)",
                options.study.display(),
                missing.join(", ")
            )));
        }
        // The clips the preflight read are kept: every stimulus the plan can show is in
        // memory, its joint positions made, before the first participant (200 first trials
        // at once would otherwise queue behind the file reads and the forward kinematics).
        let (_, read) = lab::preflight::verify_keeping(&study, &|_, _| {})?;
        let out = match &options.results {
            Destination::Folder(out) => out.clone(),
            Destination::Database { db, run } => {
                let (db, notes) = Db::open(db, run.as_deref(), &study, options.connections)?;
                for note in notes {
                    eprintln!("{note}");
                }
                let db = Arc::new(db);
                let place = Place::Db(Arc::clone(&db));
                return Self::with(options, study, page, read, place, Registry::shared(db));
            }
        };
        for note in lab::results_dir::open_for_subjects(&out, &study, false)? {
            eprintln!("{note}");
        }
        let registry = Registry::open(&out)?;
        // A session that is over keeps its place against a quota and in its group (an
        // unfinished one holds it for the lease from its participant's next request).
        let crowd = &study.definition.crowdsourcing;
        if crowd.quota.is_some() || crowd.groups.is_some() {
            for p in registry.local() {
                let dir = session::session_dir(&out, &p.subject, 1);
                let path = dir.join(results::store::SESSION_FILE);
                if path.is_file() {
                    let m: SessionManifest =
                        results::store::read_manifest(&path).map_err(LabError::from)?;
                    if matches!(m.status, SessionState::Complete | SessionState::TimeLimit) {
                        p.set_finished();
                    }
                }
            }
        }
        Self::with(options, study, page, read, Place::Folder(out), registry)
    }

    /// The server over `study` (whose clips the preflight `read`), its sessions at
    /// `place`.
    fn with(
        options: &ServeOptions,
        study: StudyFile,
        page: Page,
        read: Vec<(String, Arc<motion::Clip>)>,
        place: Place,
        registry: Registry,
    ) -> Result<App> {
        let stimuli = lab::source::open(&study)?;
        let preloaded = stimuli.keep(&read);
        let clips = read
            .into_iter()
            .take(preloaded)
            .map(|(id, clip)| {
                let bytes = OnceLock::from(Arc::new(clipdata::encode(&clip)));
                (id, Arc::new(bytes))
            })
            .collect();
        Ok(App {
            place,
            page,
            stimuli: Mutex::new(stimuli),
            views: Mutex::new(HashMap::new()),
            opening: Mutex::new(()),
            clips: Mutex::new(clips),
            preloaded,
            registry,
            limits: options.limits,
            dashboard: options.dashboard_token.clone(),
            joins: Mutex::new(Bucket::new(options.limits.join_burst)),
            requirements: Requirements::of(&study.definition.crowdsourcing),
            study,
        })
    }

    /// The study.
    pub fn definition(&self) -> &StudyDefinition {
        &self.study.definition
    }

    /// How many stimuli were read, and their joint positions made, before the first
    /// participant (every stimulus the plan can show; none for a live staircase, which
    /// encodes per trial).
    pub fn stimuli_ready(&self) -> usize {
        self.preloaded
    }

    /// Where the sessions are: the results folder, or the database run (no password).
    pub fn location(&self) -> String {
        match &self.place {
            Place::Folder(out) => out.display().to_string(),
            Place::Db(db) => db.location.clone(),
        }
    }

    /// The limits.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// A file of the built page: content type and bytes.
    pub fn page_file(&self, name: &str) -> Option<(&'static str, Arc<Vec<u8>>)> {
        self.page.get(name).map(|(k, b)| (*k, Arc::clone(b)))
    }

    /// Whether the experimenter's dashboard is served (a token was given).
    pub fn has_dashboard(&self) -> bool {
        self.dashboard.is_some()
    }

    /// Whether `token` is the dashboard's (compared in constant time).
    pub fn dashboard_allows(&self, token: &str) -> bool {
        self.dashboard.as_ref().is_some_and(|want| {
            want.len() == token.len()
                && want
                    .bytes()
                    .zip(token.bytes())
                    .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                    == 0
        })
    }

    /// What the page shows before anyone joins: the title and what the browser must offer.
    pub fn public_info(&self) -> serde_json::Value {
        serde_json::json!({
            "title": self.definition().title(),
            "requirements": self.requirements,
        })
    }

    /// A new participant from the page's URL parameters, once the environment check passed;
    /// returns the subject id and the token.
    ///
    /// # Errors
    /// 429 over the join rate, 400 bad ids or an environment that fails the check, 409 an id
    /// that already took part, 503 when the study is full.
    pub fn join(
        &self,
        params: &BTreeMap<String, String>,
        env: &Environment,
    ) -> ApiResult<(String, String)> {
        if !lock(&self.joins).take(self.limits.join_rate, self.limits.join_burst) {
            return Err(ApiError::new(
                429,
                "too many new participants at once; try again in a moment",
            ));
        }
        let unmet = self.requirements.unmet(env);
        if !unmet.is_empty() {
            return Err(ApiError::new(
                400,
                format!("this browser cannot run the study: {}", unmet.join("; ")),
            ));
        }
        let who = identity(params).map_err(|e| ApiError::new(400, e.to_string()))?;
        let crowd = &self.definition().crowdsourcing;
        let full = || {
            ApiError::new(
                503,
                "the study has all the participants it needs; thank you for your interest",
            )
        };
        let admit = |places: &Places| {
            if places.total >= self.limits.max_participants as u64 {
                return Err(full());
            }
            // Quotas count the places held: sessions that completed and participants active
            // within the lease (a participant idle longer gives their place back). The group
            // with the fewest places held takes the next one, so every group gets its share;
            // a group (or, without groups, the study) at its quota takes no more.
            if let Some(n) = crowd.groups {
                let mut counts = vec![0u32; n as usize];
                for (g, held) in &places.held {
                    if let Some(c) = g.and_then(|g| counts.get_mut(g as usize)) {
                        *c += held;
                    }
                }
                let (g, count) = counts
                    .iter()
                    .enumerate()
                    .min_by_key(|(_, c)| **c)
                    .map_or((0, 0), |(g, c)| (g as u32, *c));
                if crowd.quota.is_some_and(|q| count >= q) {
                    return Err(full());
                }
                Ok(Some(g))
            } else if crowd
                .quota
                .is_some_and(|q| places.held.values().sum::<u32>() >= q)
            {
                Err(full())
            } else {
                Ok(None)
            }
        };
        let (p, token) = self.registry.join(&who, crowd.lease_s, admit)?;
        Ok((p.subject.clone(), token))
    }

    /// The participant `subject` if `token` is theirs, within their request rate.
    ///
    /// # Errors
    /// 401 unknown token, 403 a token of another participant, 429 over the rate.
    pub fn authorize(&self, subject: &str, token: &str) -> ApiResult<Arc<Participant>> {
        let p = match self.registry.by_token(token)? {
            Some(p) if p.subject == subject => p,
            Some(_) => {
                return Err(ApiError::new(
                    403,
                    "this link belongs to another participant",
                ));
            }
            None => return Err(ApiError::new(401, "unknown session link")),
        };
        // Active: their place against a quota is kept for the lease from now.
        p.seen(lab::session::now_ms());
        if !lock(&p.bucket).take(self.limits.participant_rate, self.limits.participant_burst) {
            return Err(ApiError::new(429, "too many requests; slow down"));
        }
        Ok(p)
    }

    /// Opens (resuming it) the session of `p` if it was begun and is not open. With a
    /// database, first reads what it holds of the session: a session another server moved
    /// on is opened again (replayed), and the time the pending trial was last sent is the
    /// database's.
    fn ensure_open(&self, p: &Participant, slot: &mut Slot) -> ApiResult<()> {
        let begun = match &self.place {
            Place::Folder(out) => {
                if !matches!(slot, Slot::NotStarted) {
                    return Ok(());
                }
                session::session_dir(out, &p.subject, 1).exists()
            }
            Place::Db(db) => {
                let seen =
                    participants_db::touch(&mut *db.conn()?, db.run_id, &db.location, &p.subject)?;
                if let (Slot::Live(l), Some((rows, status))) = (&*slot, &seen.session)
                    && (*rows != l.rec.rows() || status == "complete" || status == "time_limit")
                {
                    *slot = Slot::NotStarted;
                }
                if matches!(slot, Slot::NotStarted) && seen.session.is_some() {
                    *slot = self.open_session(p, &|_| {})?;
                }
                if let Slot::Live(l) = slot {
                    let now = Instant::now();
                    l.db_sent = seen.sent.map(|(i, ago_ms)| {
                        let ago = std::time::Duration::from_secs_f64(ago_ms / 1e3);
                        (i, now.checked_sub(ago).unwrap_or(now))
                    });
                    if let (Some(pd), Some((i, at))) = (&mut l.pending, l.db_sent)
                        && pd.trial.index == i
                    {
                        pd.sent = Sent::At(at);
                    }
                }
                return Ok(());
            }
        };
        if begun {
            *slot = self.open_session(p, &|_| {})?;
        }
        Ok(())
    }

    /// Notes that `p`'s session is over (their place against a quota is kept).
    fn set_finished(&self, p: &Participant) -> ApiResult<()> {
        p.set_finished();
        if let Place::Db(db) = &self.place {
            participants_db::set_finished(&mut *db.conn()?, db.run_id, &db.location, &p.subject)
                .map_err(LabError::from)?;
        }
        Ok(())
    }

    /// The committed rows of `p`'s session.
    fn records(&self, p: &Participant) -> ApiResult<Vec<TrialRecord>> {
        let fail = |e: &dyn std::fmt::Display| ApiError::new(500, e.to_string());
        match &self.place {
            Place::Folder(out) => {
                let path =
                    session::session_dir(out, &p.subject, 1).join(results::store::TRIALS_FILE);
                if !path.exists() {
                    return Ok(Vec::new());
                }
                Ok(results::read_trials(&path).map_err(|e| fail(&e))?.records)
            }
            Place::Db(db) => db
                .store()?
                .session_records(&p.subject, 1)
                .map_err(|e| fail(&e)),
        }
    }

    /// Opens `p`'s session (one per participant): resumed from disk when it was begun, else
    /// a new one whose manifest `fill` completes. Their plan group, if the study spreads
    /// participants over groups, is their subject index.
    fn open_session(
        &self,
        p: &Participant,
        fill: &dyn Fn(&mut SessionManifest),
    ) -> ApiResult<Slot> {
        let who = session::SessionFor {
            subject: &p.subject,
            session: 1,
            group: None,
            subject_index: p.group,
            observer_seed: None,
            resume: true,
        };
        let (opened, _) = match &self.place {
            Place::Folder(out) => {
                // One session opened at a time: a study with between-subject groups assigns
                // each new one from those already in the results folder.
                let _opening = lock(&self.opening);
                session::open_subject(&self.study, &mut results::FolderStore::new(out), &who, fill)?
            }
            // The database orders group assignments itself (a lock on the run's row).
            Place::Db(db) => session::open_subject(&self.study, &mut db.store()?, &who, fill)?,
        };
        Ok(match opened {
            Opened::Finished(m) => {
                self.set_finished(p)?;
                Slot::Finished(m)
            }
            Opened::Ready { recorder, .. } => Slot::Live(Box::new(Live {
                last: recorder.resumed_last(),
                rec: recorder,
                pending: None,
                db_sent: None,
            })),
        })
    }

    /// What the page needs for the welcome, trial and end screens of `p`'s session.
    ///
    /// # Errors
    /// The session cannot be resumed from disk.
    pub fn session_info(&self, p: &Participant) -> ApiResult<serde_json::Value> {
        let mut slot = lock(&p.slot);
        self.ensure_open(p, &mut slot)?;
        let (state, answered) = match &*slot {
            Slot::NotStarted => ("welcome", 0),
            Slot::Live(l) => ("running", l.rec.answered()),
            Slot::Finished(m) => ("finished", m.trials_logged),
        };
        drop(slot);
        let def = self.definition();
        let scale = &def.scale;
        let words = texts::scale_words(def);
        let categories: Vec<serde_json::Value> = if scale.kind == ScaleKind::Categorical {
            texts::categories(scale)
                .into_iter()
                .map(|v| {
                    serde_json::json!({
                        "value": v,
                        "text": texts::format_rating(v),
                        "label": texts::grade_word(&words, scale, v),
                    })
                })
                .collect()
        } else {
            Vec::new()
        };
        let p_settings = &def.presentation;
        let (planned_kind, planned_n) = planned(def);
        Ok(serde_json::json!({
            "subject": p.subject,
            "title": def.title(),
            "instructions": texts::instructions(def),
            "consent": def.session.consent,
            "fields": fields_json(&def.session.subject_fields),
            "scale": {
                "kind": scale.kind,
                "min": scale.min,
                "max": scale.max,
                "step": scale.step,
                "categories": categories,
            },
            "presentation": { "gap_ms": p_settings.gap_ms },
            "answer_recorded": texts::ANSWER_RECORDED,
            "planned": { "kind": planned_kind, "n": planned_n },
            "state": state,
            "answered": answered,
            "requirements": self.requirements,
            "hidden_rule": def.crowdsourcing.hidden,
            "completion": (state == "finished").then(|| self.completion()).flatten(),
        }))
    }

    /// Begins `p`'s session: the subject fields (each answer checked by its kind and stored
    /// as [`SubjectField::check`] normalizes it), consent and the browser's measurements go
    /// into its manifest. A session already begun is left as it is.
    ///
    /// # Errors
    /// 400 a field's answer its kind refuses (the reason `check` gives, which names the
    /// field), an unknown field, missing consent, an environment that fails the check; the
    /// session cannot be created.
    pub fn begin(&self, p: &Participant, req: &BeginRequest) -> ApiResult<()> {
        let mut slot = lock(&p.slot);
        self.ensure_open(p, &mut slot)?;
        if !matches!(*slot, Slot::NotStarted) {
            return Ok(());
        }
        let def = self.definition();
        let mut fields = BTreeMap::new();
        for f in &def.session.subject_fields {
            let v = f
                .check(req.fields.get(&f.name).map_or("", String::as_str))
                .map_err(|why| ApiError::new(400, why))?;
            fields.insert(f.name.clone(), v);
        }
        if let Some(unknown) = req
            .fields
            .keys()
            .find(|k| !def.session.subject_fields.iter().any(|f| &f.name == *k))
        {
            return Err(ApiError::new(
                400,
                format!("{unknown:?} is not a field of this study"),
            ));
        }
        if def.session.consent.is_some() {
            if !req.consent {
                return Err(ApiError::new(400, "tick “I agree to take part” to begin"));
            }
            fields.insert("consent".into(), "given".into());
        }
        let env = &req.environment;
        let unmet = self.requirements.unmet(env);
        if !unmet.is_empty() {
            return Err(ApiError::new(
                400,
                format!("this browser cannot run the study: {}", unmet.join("; ")),
            ));
        }
        fields.insert("source".into(), p.source.clone());
        fields.extend(p.ids.clone());
        let dpr = if env.device_pixel_ratio.is_finite() && env.device_pixel_ratio > 0.0 {
            env.device_pixel_ratio.min(16.0)
        } else {
            1.0
        };
        let display = DisplayInfo {
            description: format!("browser: {}", clip_text(&env.webgl_renderer, 200)),
            width_px: (f64::from(env.window_px[0]) * dpr) as u32,
            height_px: (f64::from(env.window_px[1]) * dpr) as u32,
            refresh_hz: env.refresh_hz,
        };
        let browser = BrowserInfo {
            user_agent: clip_text(&env.user_agent, 400),
            webgl_renderer: clip_text(&env.webgl_renderer, 200),
            screen_px: env.screen_px,
            window_px: env.window_px,
            device_pixel_ratio: dpr,
            refresh_hz: env.refresh_hz,
            fullscreen: env.fullscreen,
            hidden_trials: Vec::new(),
            windowed_trials: Vec::new(),
        };
        *slot = self.open_session(p, &|fresh| {
            fresh.subject_fields.clone_from(&fields);
            fresh.display = Some(display.clone());
            fresh.browser = Some(browser.clone());
        })?;
        Ok(())
    }

    /// The clip bytes of stimulus `id` (decoded joint positions), made once.
    fn clip_bytes(&self, id: &str, clip: &motion::Clip) -> Arc<Vec<u8>> {
        let cell = Arc::clone(lock(&self.clips).entry(id.to_string()).or_default());
        Arc::clone(cell.get_or_init(|| Arc::new(clipdata::encode(clip))))
    }

    /// The pending trial of `p` (asked for again after a reload: the same trial, played from
    /// the start), or the next one; `{"done": true}` once the session is over.
    ///
    /// # Errors
    /// 409 before the session began; a stimulus or engine error.
    pub fn trial(&self, p: &Participant) -> ApiResult<serde_json::Value> {
        let mut slot = lock(&p.slot);
        self.ensure_open(p, &mut slot)?;
        let live = match &mut *slot {
            Slot::NotStarted => return Err(ApiError::new(409, "the session has not begun")),
            Slot::Finished(m) => return Ok(Self::done_info(m)),
            Slot::Live(l) => l,
        };
        if !self.ensure_pending(live, p)? {
            live.rec.finish()?;
            let m = Box::new(live.rec.manifest().clone());
            let info = Self::done_info(&m);
            *slot = Slot::Finished(m);
            self.set_finished(p)?;
            return Ok(info);
        }
        let answered = live.rec.answered();
        let Some(pending) = live.pending.as_mut() else {
            return Err(ApiError::new(500, "no pending trial"));
        };
        // Its first sending is on disk before the trial leaves; asked for again (a reload
        // plays it from the start) the page cannot have played it longer than since then.
        // A database holds every sending (another server may be asked next).
        match &self.place {
            Place::Folder(out) if matches!(pending.sent, Sent::Never) => {
                record_sent(
                    &session::session_dir(out, &p.subject, 1),
                    pending.trial.index,
                )?;
            }
            Place::Folder(_) => {}
            Place::Db(db) => participants_db::record_sent(
                &mut *db.conn()?,
                db.run_id,
                &db.location,
                &p.subject,
                pending.trial.index,
            )
            .map_err(LabError::from)?,
        }
        pending.sent = Sent::At(Instant::now());
        let t = &pending.trial;
        Ok(serde_json::json!({
            "done": false,
            "index": t.index,
            "practice": t.block == Block::Familiarization,
            "page": &*pending.screen,
            "clips": pending.clips.len(),
            // The trials the screen answers (a MUSHRA screen's panes), in pane order.
            "indices": pending.panes.iter().map(|t| t.index).collect::<Vec<_>>(),
            "presentation_ms": pending.answers_open_ms,
            "answered": answered,
        }))
    }

    /// Makes the engine's next trial the pending one, with its clips, unless one is pending;
    /// false when the session has no next trial. Whether an earlier server sent the trial
    /// already is the session folder's [`SENT_FILE`], or the database's.
    fn ensure_pending(&self, live: &mut Live, p: &Participant) -> ApiResult<bool> {
        if live.pending.is_some() {
            return Ok(true);
        }
        let elapsed = live.rec.elapsed_ms();
        let Some(trial) = live.rec.next_trial(elapsed)? else {
            return Ok(false);
        };
        let study = self.definition();
        // A MUSHRA screen shows the panes not yet answered (all, unless a resumed session
        // stopped inside it), every one of them at once.
        let mut panes = vec![trial.clone()];
        if trial.arrangement == Arrangement::Grid {
            let screen = live.rec.screen();
            if screen.first() == Some(&trial) {
                panes = screen;
            }
        }
        let mut shown = Vec::with_capacity(panes.len());
        for t in &panes {
            shown.push(lock(&self.stimuli).stimuli(t)?);
        }
        let lookahead = live.rec.lookahead(live.rec.elapsed_ms());
        lock(&self.stimuli).prepare(&lookahead);
        let first = &shown[0];
        let mut framing = |id: &str, clip: &motion::Clip| {
            *lock(&self.views)
                .entry(id.to_owned())
                .or_insert_with(|| View::framing(clip))
        };
        let cast = if trial.arrangement == Arrangement::Grid {
            let view = framing(&trial.reference, &first.reference);
            let tests: Vec<(&str, &Arc<motion::Clip>)> = panes
                .iter()
                .zip(&shown)
                .map(|(t, s)| (t.stimulus.as_str(), &s.test))
                .collect();
            Casting::grid(study, view, (&trial.reference, &first.reference), &tests)
        } else {
            Casting::of(study, &trial, first, &mut framing)?
        };
        let screen = Screen::of_screen(study, &panes, cast.duration_s())
            .ok_or_else(|| ApiError::new(500, "a screen without trials"))?;
        let (scene, clips) = staging::scene(&cast);
        let clips = clips
            .iter()
            .map(|(id, clip)| self.clip_bytes(id, clip))
            .collect();
        let encoding = shown.swap_remove(0).encoding;
        let sent = match &self.place {
            Place::Folder(out) => {
                sent_before(&session::session_dir(out, &p.subject, 1), trial.index)?
            }
            Place::Db(_) => match live.db_sent {
                Some((i, at)) if i == trial.index => Sent::At(at),
                _ => Sent::Never,
            },
        };
        live.pending = Some(Pending {
            answers_open_ms: screen.schedule.answers_open_s * 1e3,
            screen: Arc::new(serde_json::json!({
                "screen": staging::blind(serde_json::to_value(&screen).map_err(|e| ApiError::new(500, e.to_string()))?),
                "scene": scene,
            })),
            trial,
            panes,
            sent,
            clips,
            encoding,
        });
        Ok(true)
    }

    /// The completion code and where the end screen sends the participant.
    fn completion(&self) -> Option<serde_json::Value> {
        let c = &self.definition().crowdsourcing;
        (c.completion_code.is_some() || c.completion_url.is_some())
            .then(|| serde_json::json!({ "code": c.completion_code, "url": c.completion_url }))
    }

    fn done_info(m: &SessionManifest) -> serde_json::Value {
        serde_json::json!({
            "done": true,
            "status": match m.status {
                SessionState::TimeLimit => "time_limit",
                _ => "complete",
            },
            "answered": m.trials_logged,
        })
    }

    /// Clip `slot_no` of the scene of `p`'s pending trial `index` (the figures' `clip`).
    ///
    /// # Errors
    /// 404 when that trial is not pending or it has no such clip.
    pub fn clip(&self, p: &Participant, index: u32, slot_no: usize) -> ApiResult<Arc<Vec<u8>>> {
        let mut slot = lock(&p.slot);
        self.ensure_open(p, &mut slot)?;
        let Slot::Live(live) = &mut *slot else {
            return Err(ApiError::new(404, "no trial is pending"));
        };
        self.ensure_pending(live, p)?;
        match &live.pending {
            Some(pd) if pd.trial.index == index => {
                pd.clips.get(slot_no).cloned().ok_or_else(|| {
                    ApiError::new(404, format!("trial {index} has {} clips", pd.clips.len()))
                })
            }
            _ => Err(ApiError::new(404, format!("trial {index} is not pending"))),
        }
    }

    /// Logs `req` (fsynced) as the answer to `p`'s pending trial. The same answer posted
    /// again for the trial last logged is acknowledged as a duplicate and not logged twice.
    ///
    /// # Errors
    /// 409 another trial is pending, or another answer was logged for that index; 422 the
    /// stimuli have not played yet, the answer does not fit the protocol or scale, or too
    /// many replays; 500 the row could not be written (the session is reopened from disk).
    pub fn answer(&self, p: &Participant, req: &AnswerRequest) -> ApiResult<AnswerReply> {
        let mut slot = lock(&p.slot);
        self.ensure_open(p, &mut slot)?;
        let live = match &mut *slot {
            Slot::NotStarted => return Err(ApiError::new(409, "the session has not begun")),
            Slot::Finished(m) => return self.repeat_after_end(p, m, req),
            Slot::Live(l) => l,
        };
        if let Some((i, a)) = &live.last
            && *i == req.index
        {
            return if *a == req.answer {
                Ok(AnswerReply {
                    duplicate: true,
                    answered: live.rec.answered(),
                })
            } else {
                Err(ApiError::new(
                    409,
                    format!("trial {i} was answered otherwise already"),
                ))
            };
        }
        // After a restart the trial on the page is the engine's next one again.
        self.ensure_pending(live, p)?;
        let Some(pending) = &live.pending else {
            return Err(ApiError::new(409, "the session has no trial left"));
        };
        if pending.trial.index != req.index {
            return Err(ApiError::new(
                409,
                format!(
                    "trial {} is not pending (trial {} is)",
                    req.index, pending.trial.index
                ),
            ));
        }
        self.check_answer(pending, req)?;
        let browser = live.rec.manifest().browser.clone();
        let period_ms = browser.as_ref().map_or(0.0, |b| {
            if b.refresh_hz > 0.0 {
                1e3 / b.refresh_hz
            } else {
                0.0
            }
        });
        let stats = timing::stats(&req.intervals, period_ms);
        let response = Response {
            answer: req.answer,
            response_time_ms: req.response_time_ms,
            replays: req.replays,
            dropped_frames: stats.map_or(0, |s| s.dropped),
        };
        let frame_timing = stats.map(|s| FrameTiming {
            frames_shown: s.frames,
            interval_sd_ms: s.sd_ms,
        });
        let (trial, encoding) = (pending.trial.clone(), pending.encoding.clone());
        let index = trial.index;
        let panes = pending.panes.clone();
        let logged = Self::record(live, trial, &panes, encoding, req, response, frame_timing);
        match logged {
            Ok(()) => {}
            Err(e @ LabError::Engine(_)) => return Err(e.into()),
            Err(e) => {
                // The engine moved on but the row may not be on disk: reopen from the log.
                *slot = Slot::NotStarted;
                return Err(e.into());
            }
        }
        live.pending = None;
        live.last = Some((index, req.answer));
        let answered = live.rec.answered();
        let mut note = Ok(());
        if frame_timing.is_some() {
            let phases: Vec<&str> = req.phases.iter().map(String::as_str).collect();
            note = live
                .rec
                .append_frame_intervals(index, &req.intervals, &phases);
        }
        let windowed = self.requirements.fullscreen && !req.fullscreen;
        if (req.hidden || windowed) && browser.is_some() {
            note = note.and(live.rec.update_manifest(|m| {
                if let Some(b) = &mut m.browser {
                    if req.hidden {
                        b.hidden_trials.push(index);
                    }
                    if windowed {
                        b.windowed_trials.push(index);
                    }
                }
            }));
        }
        // The answer is on disk; a frame log or manifest that failed is said, not fatal.
        if let Err(e) = note {
            eprintln!("warning: {}: {}", p.subject, lab::error::chain(&e));
        }
        Ok(AnswerReply {
            duplicate: false,
            answered,
        })
    }

    /// Logs the answer to `trial`, or a MUSHRA screen's: one row per pane, in pane order,
    /// each its pane's rating, the first carrying the screen's frames (every rating was
    /// checked before, so a refused screen logs nothing).
    fn record(
        live: &mut Live,
        trial: Trial,
        panes: &[Trial],
        encoding: Option<StimulusEncoding>,
        req: &AnswerRequest,
        response: Response,
        timing: Option<FrameTiming>,
    ) -> std::result::Result<(), LabError> {
        if trial.arrangement != Arrangement::Grid {
            let elapsed = live.rec.elapsed_ms();
            return live
                .rec
                .record(trial, response, elapsed, encoding, timing)
                .map(|_| ());
        }
        for (k, (t, r)) in panes.iter().zip(&req.pane_ratings).enumerate() {
            let first = k == 0;
            // Since the first is logged, the engine's next trial is this pane's.
            if !first {
                let next = live.rec.next_trial(live.rec.elapsed_ms())?;
                if next.as_ref() != Some(t) {
                    return Err(LabError::Refused(format!(
                        "MUSHRA pane {} (trial {}) answered, but the session's next trial is {:?}",
                        t.reference_position,
                        t.index,
                        next.map(|n| n.index)
                    )));
                }
            }
            let response = Response {
                answer: Answer::Rating(*r),
                dropped_frames: if first { response.dropped_frames } else { 0 },
                ..response
            };
            let timing = timing.map(|tm| {
                if first {
                    tm
                } else {
                    FrameTiming {
                        frames_shown: 0,
                        interval_sd_ms: 0.0,
                    }
                }
            });
            let elapsed = live.rec.elapsed_ms();
            live.rec
                .record(t.clone(), response, elapsed, None, timing)?;
        }
        Ok(())
    }

    /// After the end only a repeat of a logged answer can come (acknowledged as a
    /// duplicate); anything else is refused.
    fn repeat_after_end(
        &self,
        p: &Participant,
        m: &SessionManifest,
        req: &AnswerRequest,
    ) -> ApiResult<AnswerReply> {
        match self.records(p)?.iter().find(|r| r.trial.index == req.index) {
            Some(r) if r.response.answer == req.answer => Ok(AnswerReply {
                duplicate: true,
                answered: m.trials_logged,
            }),
            _ => Err(ApiError::new(409, "the session is over")),
        }
    }

    /// Refuses an answer the pending trial cannot take: to a trial never sent (409), before
    /// its stimuli played (by the server's clock since it sent the trial, and the page's),
    /// times that are not finite, negative or over [`MAX_REPORTED_MS`], more replays than
    /// allowed, malformed frame records, or a hidden page where the study shows the trial
    /// again.
    fn check_answer(&self, pending: &Pending, req: &AnswerRequest) -> ApiResult<()> {
        let def = &self.study.definition;
        let need_ms = pending.answers_open_ms;
        let Some(since_served) = pending.sent.since_ms() else {
            return Err(ApiError::new(
                409,
                format!(
                    "trial {} was never sent to this participant: ask for it and play it first",
                    pending.trial.index
                ),
            ));
        };
        let in_range = |v: f64| v.is_finite() && (0.0..=MAX_REPORTED_MS).contains(&v);
        if !in_range(req.played_ms) || !in_range(req.response_time_ms as f64) {
            return Err(ApiError::new(
                422,
                format!("played_ms and response_time_ms must be from 0 to {MAX_REPORTED_MS} ms"),
            ));
        }
        // The page cannot have played longer than since the trial was sent; a little slack
        // for clocks that tick at slightly different rates.
        if req.played_ms + 50.0 < need_ms || since_served + 50.0 < need_ms {
            return Err(ApiError::new(
                422,
                format!(
                    "answered before the stimuli had played ({:.0} ms of {need_ms:.0} ms)",
                    req.played_ms.min(since_served)
                ),
            ));
        }
        let method = protocols::methods::of(def.protocol);
        if pending.trial.arrangement == Arrangement::Grid {
            if req.pane_ratings.len() != pending.panes.len()
                || req.answer != Answer::Rating(req.pane_ratings[0])
            {
                return Err(ApiError::new(
                    422,
                    format!(
                        "the screen has {} panes: rate each of them (the answer is the first's)",
                        pending.panes.len()
                    ),
                ));
            }
            for (t, r) in pending.panes.iter().zip(&req.pane_ratings) {
                if method.score(t, Answer::Rating(*r), &def.scale).is_err() {
                    return Err(ApiError::new(
                        422,
                        format!("{r} is not a rating on the study's scale"),
                    ));
                }
            }
        } else if !req.pane_ratings.is_empty() {
            return Err(ApiError::new(
                422,
                "pane ratings answer a MUSHRA screen only",
            ));
        }
        if def
            .presentation
            .max_replays
            .is_some_and(|m| req.replays > m)
        {
            return Err(ApiError::new(422, "more replays than the study allows"));
        }
        if req.intervals.len() > MAX_INTERVALS || req.phases.len() > MAX_INTERVALS {
            return Err(ApiError::new(413, "too many frame intervals"));
        }
        if !req.intervals.iter().all(|v| in_range(*v)) {
            return Err(ApiError::new(
                422,
                format!("frame intervals must be from 0 to {MAX_REPORTED_MS} ms"),
            ));
        }
        if req
            .phases
            .iter()
            .any(|p| p.len() > 16 || !p.chars().all(|c| c.is_ascii_lowercase()))
        {
            return Err(ApiError::new(422, "unknown frame phase"));
        }
        if req.hidden && def.crowdsourcing.hidden == HiddenRule::Repeat {
            return Err(ApiError::new(
                422,
                "the page was hidden while the stimuli played; the trial is shown again",
            ));
        }
        Ok(())
    }

    /// Progress per participant and the running mean score per condition, for the
    /// experimenter.
    ///
    /// # Errors
    /// A session log that cannot be read.
    pub fn dashboard(&self) -> ApiResult<serde_json::Value> {
        let sessions = self.overview()?;
        let mut rows = Vec::new();
        let mut scores: BTreeMap<String, (f64, u32)> = BTreeMap::new();
        let mut states: BTreeMap<&str, u32> = BTreeMap::new();
        let mut last_answer_ms: Option<u64> = None;
        for (p, state, manifest, records) in &sessions {
            let state = *state;
            *states.entry(state).or_default() += 1;
            last_answer_ms = last_answer_ms.max(records.iter().map(|r| r.wall_clock_ms).max());
            let crowd = &self.definition().crowdsourcing;
            let mut gold_failed = 0u32;
            for r in records {
                if crowd.gold_verdict(r).is_some_and(|(_, passed)| !passed) {
                    gold_failed += 1;
                }
                // A track's scores are right or wrong, not a condition's quality.
                if r.trial.block != Block::Familiarization
                    && !protocols::methods::of(r.protocol).adaptive()
                {
                    let e = scores.entry(r.trial.condition.clone()).or_insert((0.0, 0));
                    e.0 += r.outcome.score;
                    e.1 += 1;
                }
            }
            let browser = manifest.as_ref().and_then(|m| m.browser.clone());
            rows.push(serde_json::json!({
                "subject": p.subject,
                "source": p.source,
                "state": state,
                "answered": records.len(),
                "gold_failed": gold_failed,
                "excluded": gold_failed > crowd.max_gold_failures,
                "hidden_trials": browser.as_ref().map_or(0, |b| b.hidden_trials.len()),
                "windowed_trials": browser.as_ref().map_or(0, |b| b.windowed_trials.len()),
                "refresh_hz": browser.as_ref().map(|b| b.refresh_hz),
            }));
        }
        let conditions: Vec<serde_json::Value> = scores
            .into_iter()
            .map(|(c, (sum, n))| serde_json::json!({ "condition": c, "n": n, "mean": sum / f64::from(n) }))
            .collect();
        Ok(serde_json::json!({
            "study": self.definition().name,
            "protocol": self.definition().protocol,
            "states": states,
            // Share of participants whose session is complete.
            "complete_share": if sessions.is_empty() {
                0.0
            } else {
                f64::from(states.get("finished").copied().unwrap_or(0)) / sessions.len() as f64
            },
            // When the last answer was logged, ms since the Unix epoch.
            "last_answer_ms": last_answer_ms,
            "participants": rows,
            "conditions": conditions,
        }))
    }

    /// Marks every open session interrupted (a stop on purpose; each resumes on the next
    /// request after a restart).
    ///
    /// # Errors
    /// A manifest that cannot be written (the others are still marked).
    pub fn interrupt_all(&self) -> Result<()> {
        let mut first = Ok(());
        for p in self.registry.local() {
            if let Slot::Live(l) = &mut *lock(&p.slot)
                && let Err(e) = l.rec.interrupt()
                // A session another server moved on is that server's to mark.
                && !matches!(e, LabError::Results(results::ResultsError::Moved { .. }))
                && first.is_ok()
            {
                first = Err(e.into());
            }
        }
        first
    }

    /// Every participant with their session's state (`joined`, `begun`, `running`,
    /// `finished`), manifest and committed rows: a folder's as this server holds them, a
    /// database run's as the database does (whichever server drives each).
    fn overview(&self) -> ApiResult<Vec<Overview>> {
        let db = match &self.place {
            Place::Folder(out) => {
                let mut all = Vec::new();
                for p in self.registry.local() {
                    let dir = session::session_dir(out, &p.subject, 1);
                    let (state, manifest) = match &*lock(&p.slot) {
                        Slot::NotStarted if !dir.exists() => ("joined", None),
                        Slot::Live(l) => ("running", Some(l.rec.manifest().clone())),
                        Slot::Finished(m) => ("finished", Some((**m).clone())),
                        Slot::NotStarted => ("begun", None),
                    };
                    let records = self.records(&p)?;
                    all.push((p, state, manifest, records));
                }
                return Ok(all);
            }
            Place::Db(db) => db,
        };
        let fail = |e: results::ResultsError| ApiError::new(500, e.to_string());
        let mut store = db.store()?;
        let heads = store.sessions().map_err(fail)?;
        let mut by_subject: HashMap<String, SessionResults> = store
            .read(&heads)
            .map_err(fail)?
            .into_iter()
            .filter(|s| s.manifest.session == 1)
            .map(|s| (s.manifest.subject.clone(), s))
            .collect();
        let everyone = participants_db::all(store.client().map_err(fail)?, db.run_id, &db.location)
            .map_err(fail)?;
        Ok(everyone
            .into_iter()
            .map(|row| {
                let session = by_subject.remove(&row.subject);
                let p = Arc::new(Participant::from_row(row));
                match session {
                    None => (p, "joined", None, Vec::new()),
                    Some(s) => {
                        let state = match s.manifest.status {
                            SessionState::Complete | SessionState::TimeLimit => "finished",
                            _ => "running",
                        };
                        (p, state, Some(s.manifest), s.trials.records)
                    }
                }
            })
            .collect())
    }
}

/// At most `n` characters of `s`, without control characters.
fn clip_text(s: &str, n: usize) -> String {
    s.chars().filter(|c| !c.is_control()).take(n).collect()
}

/// How many trials the session has, as the subject can be told (as the window says it).
fn planned(study: &StudyDefinition) -> (&'static str, Option<u32>) {
    match texts::planned_trials(study) {
        texts::Planned::Exactly(n) => ("exactly", Some(n)),
        texts::Planned::AtMost(n) => ("at_most", Some(n)),
        texts::Planned::Unknown => ("unknown", None),
    }
}
