//! The experimenter's terminal during `study run`: where the session stands (trial k of n,
//! the last answer, frames dropped, elapsed time, a break or the experimenter's pause, how
//! it ended), on standard error.
//!
//! On a terminal it is one line redrawn in place (once a second, and at each change); on
//! anything else (a log file, a test's pipe) one plain line per event, so it can be kept and
//! read back. Nothing here slows the subject's screen: the window hands a small `Copy`
//! [`SessionStatus`] to a [`Watcher`] once a frame, which sends it on only when it changed,
//! and each answer is sent by the results writer ([`ExperimenterView::tap`]) when it is
//! committed. A thread of its own formats and writes the lines, so no write to standard
//! error (a stalled terminal, a full pipe) ever blocks a frame.

use std::fmt::Write as _;
use std::io::{IsTerminal as _, Write};
use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use protocols::record::TrialRecord;
use protocols::record::{Answer, Arrangement, Block};
use protocols::texts::{Planned, format_rating};
use results::backend::{Assignment, Found, GroupQuota, ResumedSession, SessionWriter, Store};
use results::{ResultsError, SessionManifest};

/// The screen a session is on, as the experimenter's terminal names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// The experimenter confirms the viewing conditions.
    Viewing,
    /// The welcome screen (until Begin).
    Welcome,
    /// A trial (its 0-based index in the session).
    Trial(u32),
    /// The blank gap after an answer.
    Gap,
    /// A rest break.
    Break,
    /// The results database is away; the last answer is kept.
    Waiting,
    /// The end screen (after the end, a stop or an error).
    End,
}

/// How a session ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// Every trial done (or the time limit reached).
    Finished,
    /// The experimenter quit (resumable).
    Quit,
    /// SIGINT or SIGTERM (resumable).
    Signalled,
    /// An error stopped it (resumable).
    Failed,
}

/// Where a session stands: what the window's screens tell the experimenter's terminal once a
/// frame (`StudyUi::status`). Small and `Copy`, so reading it costs a frame nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionStatus {
    /// The screen shown.
    pub stage: Stage,
    /// The experimenter's pause (or the quit confirmation) is open.
    pub paused: bool,
    /// Trials answered so far (a resumed session's earlier ones included).
    pub answered: u32,
    /// How many trials the session has.
    pub planned: Planned,
    /// The session clock, ms (what `trials.csv` logs as `elapsed_ms`).
    pub elapsed_ms: u64,
    /// Set once the session has ended, with how.
    pub ended: Option<Ended>,
}

impl SessionStatus {
    /// Whether `other` says something different to the experimenter (the clock aside).
    fn differs(&self, other: &SessionStatus) -> bool {
        (
            self.stage,
            self.paused,
            self.answered,
            self.planned,
            self.ended,
        ) != (
            other.stage,
            other.paused,
            other.answered,
            other.planned,
            other.ended,
        )
    }
}

/// How the view writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// One line redrawn in place (a terminal).
    Live,
    /// One plain line per event (a log file, a pipe).
    Lines,
}

/// One committed answer, as the results writer saw it.
#[derive(Debug, Clone, Copy)]
struct Answered {
    index: u32,
    practice: bool,
    answer: Answer,
    arrangement: Arrangement,
    reference_position: protocols::record::Position,
    correct: Option<bool>,
    response_ms: u64,
    dropped: u32,
    elapsed_ms: u64,
}

impl Answered {
    fn of(r: &TrialRecord) -> Answered {
        Answered {
            index: r.trial.index,
            practice: r.trial.block == Block::Familiarization,
            answer: r.response.answer,
            arrangement: r.trial.arrangement,
            reference_position: r.trial.reference_position,
            correct: r.outcome.correct,
            response_ms: r.response.response_time_ms,
            dropped: r.response.dropped_frames,
            elapsed_ms: r.elapsed_ms,
        }
    }

    /// The answer as the experimenter reads it: `4.5`, `A 62, B 40`, `left (correct)`,
    /// `C 80` (a MUSHRA pane).
    fn answer_text(&self) -> String {
        let mut t = match self.answer {
            Answer::Rating(v) => match self.reference_position.pane_letter() {
                Some(l) if self.arrangement == Arrangement::Grid => {
                    format!("{l} {}", format_rating(v))
                }
                _ => format_rating(v),
            },
            Answer::Pair { a, b } => {
                let [na, nb] = protocols::texts::dscqs_names(self.arrangement);
                format!("{na} {}, {nb} {}", format_rating(a), format_rating(b))
            }
            Answer::Choice(p) => p.to_string(),
        };
        if let Some(c) = self.correct {
            t.push_str(if c { " (correct)" } else { " (wrong)" });
        }
        t
    }
}

enum Msg {
    Status(SessionStatus),
    Answered(Answered),
    Checking(usize, usize),
    Note(String),
    Named(String),
    Close,
}

/// The experimenter's view of one session: a thread writing to standard error (or another
/// writer), fed by a [`Watcher`] in the window and by the results writer. Dropping it (or
/// [`Self::finish`]) writes the last line and waits for the thread.
pub struct ExperimenterView {
    tx: Option<Sender<Msg>>,
    thread: Option<JoinHandle<()>>,
}

impl ExperimenterView {
    /// The view on standard error: live on a terminal, plain lines otherwise; nothing at all
    /// when `quiet`.
    pub fn stderr(quiet: bool) -> ExperimenterView {
        if quiet {
            return ExperimenterView::off();
        }
        let style = if std::io::stderr().is_terminal() {
            Style::Live
        } else {
            Style::Lines
        };
        ExperimenterView::start(style, Box::new(std::io::stderr()))
    }

    /// A view that shows nothing (`--quiet`).
    pub fn off() -> ExperimenterView {
        ExperimenterView {
            tx: None,
            thread: None,
        }
    }

    /// The view writing to `out` in `style`.
    pub fn start(style: Style, out: Box<dyn Write + Send>) -> ExperimenterView {
        let (tx, rx) = mpsc::channel();
        let printer = Printer::new(style, out);
        let thread = std::thread::Builder::new()
            .name("experimenter view".into())
            .spawn(move || printer.run(&rx));
        match thread {
            Ok(t) => ExperimenterView {
                tx: Some(tx),
                thread: Some(t),
            },
            Err(e) => {
                eprintln!("warning: no experimenter's view ({e}); the session runs without it");
                ExperimenterView::off()
            }
        }
    }

    /// What the window calls once a frame with its screens' status.
    pub fn watcher(&self) -> Watcher {
        Watcher {
            tx: self.tx.clone(),
            last: None,
        }
    }

    /// `store`, whose session writers also tell this view of every answer they commit.
    pub fn tap(&self, store: Box<dyn Store>) -> Box<dyn Store> {
        match &self.tx {
            Some(tx) => Box::new(Tapped {
                inner: store,
                tx: tx.clone(),
            }),
            None => store,
        }
    }

    /// Progress of the stimulus check (`done` of `total`), shown on a terminal's live line.
    pub fn checking(&self, done: usize, total: usize) {
        self.send(Msg::Checking(done, total));
    }

    /// Names the session (`S07 s1`) once the store has given its subject.
    pub fn name(&self, who: String) {
        self.send(Msg::Named(who));
    }

    /// A line of its own (a note before the session, such as what the stimulus check read).
    pub fn note(&self, line: String) {
        self.send(Msg::Note(line));
    }

    fn send(&self, msg: Msg) {
        if let Some(tx) = &self.tx {
            // The thread is gone only after Close: nothing left to show.
            let _ = tx.send(msg);
        }
    }

    /// Writes the last line (how the session ended, or that the window closed before it did)
    /// and waits until everything is written.
    pub fn finish(self) {
        drop(self);
    }
}

impl Drop for ExperimenterView {
    fn drop(&mut self) {
        self.send(Msg::Close);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The window's side of the view: given the screens' status once a frame, it sends it on when
/// it changed (a compare of a few words; no allocation, no I/O).
pub struct Watcher {
    tx: Option<Sender<Msg>>,
    last: Option<SessionStatus>,
}

impl Watcher {
    /// A watcher that sends nothing.
    pub fn off() -> Watcher {
        Watcher {
            tx: None,
            last: None,
        }
    }

    /// This frame's status.
    pub fn frame(&mut self, status: SessionStatus) {
        let Some(tx) = &self.tx else {
            return;
        };
        if self.last.is_none_or(|l| l.differs(&status)) {
            self.last = Some(status);
            let _ = tx.send(Msg::Status(status));
        }
    }
}

/// A store whose session writers report each committed answer.
struct Tapped {
    inner: Box<dyn Store>,
    tx: Sender<Msg>,
}

struct TappedWriter {
    inner: Box<dyn SessionWriter>,
    tx: Sender<Msg>,
}

impl Store for Tapped {
    fn location(&self) -> String {
        self.inner.location()
    }

    fn session_path(&self, subject: &str, session: u32) -> PathBuf {
        self.inner.session_path(subject, session)
    }

    fn find_session(&mut self, subject: &str, session: u32) -> Result<Found, ResultsError> {
        self.inner.find_session(subject, session)
    }

    fn create_session(
        &mut self,
        manifest: &SessionManifest,
    ) -> Result<Box<dyn SessionWriter>, ResultsError> {
        let inner = self.inner.create_session(manifest)?;
        Ok(Box::new(TappedWriter {
            inner,
            tx: self.tx.clone(),
        }))
    }

    fn resume_session(
        &mut self,
        subject: &str,
        session: u32,
    ) -> Result<ResumedSession, ResultsError> {
        let mut resumed = self.inner.resume_session(subject, session)?;
        resumed.writer = Box::new(TappedWriter {
            inner: resumed.writer,
            tx: self.tx.clone(),
        });
        Ok(resumed)
    }

    fn check_not_held(&mut self, subject: &str, session: u32) -> Result<(), ResultsError> {
        self.inner.check_not_held(subject, session)
    }

    fn discard_unstarted(&mut self, subject: &str, session: u32) -> Result<bool, ResultsError> {
        self.inner.discard_unstarted(subject, session)
    }

    fn assign_group(
        &mut self,
        subject: &str,
        session: u32,
        groups: &[GroupQuota<'_>],
        wanted: Option<&str>,
    ) -> Result<Assignment, ResultsError> {
        self.inner.assign_group(subject, session, groups, wanted)
    }
}

impl SessionWriter for TappedWriter {
    fn rows(&self) -> u32 {
        self.inner.rows()
    }

    fn path(&self) -> PathBuf {
        self.inner.path()
    }

    fn append(&mut self, record: &TrialRecord) -> Result<(), ResultsError> {
        self.inner.append(record)?;
        // Committed: now it is the session's answer.
        let _ = self.tx.send(Msg::Answered(Answered::of(record)));
        Ok(())
    }

    fn write_manifest(&mut self, manifest: &SessionManifest) -> Result<(), ResultsError> {
        self.inner.write_manifest(manifest)
    }

    fn append_frames(
        &mut self,
        index: u32,
        intervals: &[f64],
        phases: &[&str],
    ) -> Result<(), ResultsError> {
        self.inner.append_frames(index, intervals, phases)
    }
}

/// `mm:ss`, or `h:mm:ss` from an hour.
pub fn clock_text(ms: u64) -> String {
    let s = ms / 1000;
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
    } else {
        format!("{:02}:{:02}", s / 60, s % 60)
    }
}

/// `1 frame`, `3 frames`.
fn frames(n: u32) -> String {
    format!("{n} frame{}", if n == 1 { "" } else { "s" })
}

/// Trial `k` against the plan: `3/14`, `3/≤40` (at most), `3`.
fn trial_of(k: u32, planned: Planned) -> String {
    match planned {
        Planned::Exactly(n) => format!("{k}/{n}"),
        Planned::AtMost(n) => format!("{k}/≤{n}"),
        Planned::Unknown => k.to_string(),
    }
}

/// `3 of 14 trials`, `3 of at most 40 trials`, `3 trials`.
fn trials_of(k: u32, planned: Planned) -> String {
    match planned {
        Planned::Exactly(n) => format!("{k} of {n} trials"),
        Planned::AtMost(n) => format!("{k} of at most {n} trials"),
        Planned::Unknown => format!("{k} trials"),
    }
}

/// The thread's state: what it last heard, and where it writes.
struct Printer {
    who: String,
    style: Style,
    out: Box<dyn Write + Send>,
    status: Option<SessionStatus>,
    /// The session clock at the last status or answer, and when that arrived.
    clock: (u64, Instant),
    /// Frames dropped during the trials answered in this run.
    dropped: u32,
    /// The last answer, short (live line).
    last: Option<String>,
    /// When the open break, pause or outage began (session clock, ms).
    since: Option<u64>,
    checking: Option<(usize, usize)>,
    /// The live line is drawn and not yet ended by a newline.
    drawn: bool,
}

impl Printer {
    fn new(style: Style, out: Box<dyn Write + Send>) -> Printer {
        Printer {
            who: String::new(),
            style,
            out,
            status: None,
            clock: (0, Instant::now()),
            dropped: 0,
            last: None,
            since: None,
            checking: None,
            drawn: false,
        }
    }

    fn run(mut self, rx: &Receiver<Msg>) {
        loop {
            let msg = match self.style {
                // The live line's clock moves once a second.
                Style::Live => match rx.recv_timeout(Duration::from_secs(1)) {
                    Ok(m) => m,
                    Err(RecvTimeoutError::Timeout) => {
                        self.draw();
                        continue;
                    }
                    Err(RecvTimeoutError::Disconnected) => Msg::Close,
                },
                Style::Lines => rx.recv().unwrap_or(Msg::Close),
            };
            let close = matches!(msg, Msg::Close);
            self.take(msg);
            if close {
                return;
            }
        }
    }

    /// The session clock now.
    fn now_ms(&self) -> u64 {
        self.clock.0 + self.clock.1.elapsed().as_millis() as u64
    }

    fn planned(&self) -> Planned {
        self.status.map_or(Planned::Unknown, |s| s.planned)
    }

    fn take(&mut self, msg: Msg) {
        match msg {
            Msg::Checking(done, total) => {
                self.checking = Some((done, total));
                self.draw();
            }
            Msg::Note(line) => {
                self.checking = None;
                self.event(&line, true);
            }
            Msg::Named(who) => self.who = who,
            Msg::Answered(a) => {
                self.clock = (a.elapsed_ms, Instant::now());
                self.dropped += a.dropped;
                self.last = Some(format!(
                    "{} in {:.2} s",
                    a.answer_text(),
                    a.response_ms as f64 / 1e3
                ));
                let line = format!(
                    "{}trial {} answered {}, {} dropped, {} elapsed",
                    if a.practice { "practice " } else { "" },
                    trial_of(a.index + 1, self.planned()),
                    self.last.as_deref().unwrap_or_default(),
                    frames(a.dropped),
                    clock_text(a.elapsed_ms)
                );
                self.event(&line, false);
            }
            Msg::Status(s) => {
                self.clock = (s.elapsed_ms, Instant::now());
                self.checking = None;
                let lasting = self.status.is_none() || s.ended.is_some();
                let lines = self.changes(s);
                self.status = Some(s);
                for l in &lines {
                    self.event(l, lasting);
                }
                if lines.is_empty() {
                    self.draw();
                }
            }
            Msg::Close => {
                if let Some(s) = self.status.filter(|s| s.ended.is_none()) {
                    let line = format!(
                        "the window closed before the session ended, after {}, {} elapsed (resumable)",
                        trials_of(s.answered, s.planned),
                        clock_text(self.now_ms())
                    );
                    self.event(&line, true);
                }
                self.end_line();
            }
        }
    }

    /// The events between the last status and `s`, a line each.
    fn changes(&mut self, s: SessionStatus) -> Vec<String> {
        let at = clock_text(s.elapsed_ms);
        let Some(old) = self.status else {
            let mut l = format!(
                "session{}{} opened: {} done, {at} elapsed",
                if self.who.is_empty() { "" } else { " " },
                self.who,
                trials_of(s.answered, s.planned)
            );
            if s.stage == Stage::Viewing {
                l.push_str("; the viewing conditions wait for confirmation");
            }
            return vec![l];
        };
        if old.ended.is_some() {
            return Vec::new();
        }
        let mut out = Vec::new();
        let took = |since: Option<u64>| {
            let ms = s.elapsed_ms.saturating_sub(since.unwrap_or(0));
            if ms < 60_000 {
                format!("{:.1} s", ms as f64 / 1e3)
            } else {
                clock_text(ms)
            }
        };
        if let Some(how) = s.ended.filter(|_| old.ended.is_none()) {
            let done = trials_of(s.answered, s.planned);
            out.push(match how {
                Ended::Finished => format!(
                    "finished: {done}, {} dropped, {at} elapsed",
                    frames(self.dropped)
                ),
                Ended::Quit => {
                    format!("stopped by the experimenter after {done}, {at} elapsed (resumable)")
                }
                Ended::Signalled => {
                    format!("interrupted by a signal after {done}, {at} elapsed (resumable)")
                }
                Ended::Failed => {
                    format!("stopped by an error after {done}, {at} elapsed (resumable)")
                }
            });
            return out;
        }
        if s.paused != old.paused {
            if s.paused {
                self.since = Some(s.elapsed_ms);
                out.push(format!("paused by the experimenter, {at} elapsed"));
            } else {
                out.push(format!(
                    "resumed after a pause of {} (the trial starts again)",
                    took(self.since)
                ));
            }
        }
        let next = trial_of(s.answered + 1, s.planned);
        match (old.stage, s.stage) {
            (a, b) if a == b => {}
            (Stage::Viewing | Stage::Welcome, Stage::Trial(_)) => {
                out.push(format!("began: trial {next}, {at} elapsed"));
            }
            (_, Stage::Break) => {
                self.since = Some(s.elapsed_ms);
                out.push(format!(
                    "break after {}, {at} elapsed",
                    trials_of(s.answered, s.planned)
                ));
            }
            (Stage::Break, _) => {
                out.push(format!(
                    "break over after {}: trial {next}",
                    took(self.since)
                ));
            }
            (_, Stage::Waiting) => {
                self.since = Some(s.elapsed_ms);
                out.push(format!(
                    "waiting for the results database (the answer is kept), {at} elapsed"
                ));
            }
            (Stage::Waiting, _) => {
                out.push(format!("results database back after {}", took(self.since)));
            }
            _ => {}
        }
        out
    }

    /// The live line: `S07 s1 · trial 4/14 · last 4.5 in 2.31 s · 0 frames dropped · 00:41`.
    fn live_line(&self) -> String {
        let mut t = if self.who.is_empty() {
            "study run".to_owned()
        } else {
            self.who.clone()
        };
        if let Some((done, total)) = self.checking {
            let _ = write!(t, " · checking the stimuli: {done} of {total}");
            return t;
        }
        let Some(s) = self.status else {
            return t;
        };
        let here = match s.stage {
            Stage::Viewing => "viewing conditions".to_owned(),
            Stage::Welcome => "welcome".to_owned(),
            Stage::Trial(_) => format!("trial {}", trial_of(s.answered + 1, s.planned)),
            Stage::Gap => format!("trial {} answered", trial_of(s.answered, s.planned)),
            Stage::Break => "break".to_owned(),
            Stage::Waiting => "waiting for the results database".to_owned(),
            Stage::End => "end screen".to_owned(),
        };
        let _ = write!(t, " · {here}");
        if s.paused {
            t.push_str(" · PAUSED");
        }
        if let Some(l) = &self.last {
            let _ = write!(t, " · last {l}");
        }
        let _ = write!(
            t,
            " · {} dropped · {}",
            frames(self.dropped),
            clock_text(self.now_ms())
        );
        t
    }

    /// Redraws the live line (nothing in [`Style::Lines`], nor once the session has ended).
    fn draw(&mut self) {
        let running = match self.status {
            Some(s) => s.ended.is_none(),
            None => self.checking.is_some(),
        };
        if self.style == Style::Live && running {
            let line = self.live_line();
            // Carriage return and erase line: the line is redrawn where it was.
            let _ = write!(self.out, "\r\x1b[2K{line}");
            let _ = self.out.flush();
            self.drawn = true;
        }
    }

    /// An event: its own line in [`Style::Lines`]. On a terminal a `lasting` one (the
    /// session opened or ended, a note) gets a line of its own above the live line, and the
    /// others only redraw it.
    fn event(&mut self, line: &str, lasting: bool) {
        match self.style {
            Style::Lines => {
                let _ = writeln!(self.out, "{line}");
                let _ = self.out.flush();
            }
            Style::Live if lasting => {
                let _ = writeln!(self.out, "\r\x1b[2K{line}");
                self.drawn = false;
                self.draw();
                let _ = self.out.flush();
            }
            Style::Live => self.draw(),
        }
    }

    /// Erases the live line, so what follows starts on a clean line.
    fn end_line(&mut self) {
        if self.drawn {
            let _ = write!(self.out, "\r\x1b[2K");
            self.drawn = false;
        }
        let _ = self.out.flush();
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use protocols::record::Position;

    use super::*;

    /// A writer the test reads back.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Shared {
        fn text(&self) -> String {
            String::from_utf8(self.0.lock().unwrap().clone()).unwrap()
        }
    }

    fn status(stage: Stage, answered: u32, elapsed_s: u64) -> SessionStatus {
        SessionStatus {
            stage,
            paused: false,
            answered,
            planned: Planned::Exactly(3),
            elapsed_ms: elapsed_s * 1000,
            ended: None,
        }
    }

    fn answered(index: u32, answer: Answer, dropped: u32, elapsed_s: u64) -> Msg {
        Msg::Answered(Answered {
            index,
            practice: index == 0,
            answer,
            arrangement: Arrangement::SideBySide,
            reference_position: Position::Left,
            correct: None,
            response_ms: 2310,
            dropped,
            elapsed_ms: elapsed_s * 1000,
        })
    }

    /// A 3-trial session's events, through a printer in `style`; what it wrote.
    fn session(style: Style) -> String {
        let out = Shared::default();
        let mut p = Printer::new(style, Box::new(out.clone()));
        p.take(Msg::Checking(1, 4));
        p.take(Msg::Note("stimuli checked: 4 stimuli".into()));
        // The subject is named once the store has given it (`--subject auto`).
        p.take(Msg::Named("S07 s1".into()));
        p.take(Msg::Status(status(Stage::Welcome, 0, 0)));
        p.take(Msg::Status(status(Stage::Trial(0), 0, 12)));
        p.take(answered(0, Answer::Rating(4.5), 0, 15));
        p.take(Msg::Status(status(Stage::Gap, 1, 15)));
        p.take(Msg::Status(status(Stage::Break, 1, 16)));
        p.take(Msg::Status(status(Stage::Trial(1), 1, 46)));
        p.take(Msg::Status(SessionStatus {
            paused: true,
            ..status(Stage::Trial(1), 1, 50)
        }));
        p.take(Msg::Status(status(Stage::Trial(1), 1, 55)));
        p.take(answered(1, Answer::Pair { a: 62.0, b: 40.0 }, 1, 61));
        p.take(Msg::Status(status(Stage::Waiting, 2, 61)));
        p.take(Msg::Status(status(Stage::Trial(2), 2, 64)));
        p.take(answered(2, Answer::Choice(Position::Right), 2, 3700));
        p.take(Msg::Status(SessionStatus {
            ended: Some(Ended::Finished),
            ..status(Stage::End, 3, 3700)
        }));
        // Nothing after the end, whatever the screens do then.
        p.take(Msg::Status(SessionStatus {
            ended: Some(Ended::Finished),
            paused: true,
            ..status(Stage::End, 3, 3701)
        }));
        p.take(Msg::Close);
        out.text()
    }

    #[test]
    fn plain_lines_say_each_event_once() {
        let text = session(Style::Lines);
        let want = "stimuli checked: 4 stimuli
session S07 s1 opened: 0 of 3 trials done, 00:00 elapsed
began: trial 1/3, 00:12 elapsed
practice trial 1/3 answered 4.5 in 2.31 s, 0 frames dropped, 00:15 elapsed
break after 1 of 3 trials, 00:16 elapsed
break over after 30.0 s: trial 2/3
paused by the experimenter, 00:50 elapsed
resumed after a pause of 5.0 s (the trial starts again)
trial 2/3 answered A 62, B 40 in 2.31 s, 1 frame dropped, 01:01 elapsed
waiting for the results database (the answer is kept), 01:01 elapsed
results database back after 3.0 s
trial 3/3 answered right in 2.31 s, 2 frames dropped, 1:01:40 elapsed
finished: 3 of 3 trials, 3 frames dropped, 1:01:40 elapsed
";
        assert_eq!(text, want);
        assert!(!text.contains('\r'));
    }

    #[test]
    fn a_terminal_gets_one_line_redrawn_in_place() {
        let text = session(Style::Live);
        // What stays on the screen: each redraw erases the line before it.
        let shown: Vec<&str> = text
            .split('\n')
            .map(|l| l.rsplit("\r\x1b[2K").next().unwrap())
            .collect();
        assert_eq!(
            shown,
            [
                "stimuli checked: 4 stimuli",
                "session S07 s1 opened: 0 of 3 trials done, 00:00 elapsed",
                "finished: 3 of 3 trials, 3 frames dropped, 1:01:40 elapsed",
                "",
            ]
        );
        // In between, the live line: the trial on screen, the last answer, the pause.
        for part in [
            "\r\x1b[2Kstudy run · checking the stimuli: 1 of 4\r",
            "\r\x1b[2KS07 s1 · trial 1/3 · 0 frames dropped · 00:12",
            "\r\x1b[2KS07 s1 · trial 2/3 · PAUSED · last 4.5 in 2.31 s · 0 frames dropped · 00:50",
            "\r\x1b[2KS07 s1 · waiting for the results database · last A 62, B 40 in 2.31 s · 1 \
             frame dropped · 01:01\r",
        ] {
            assert!(text.contains(part), "{part:?} in {text:?}");
        }
        assert!(!text.contains("began:") && !text.contains("practice trial"));
    }

    #[test]
    fn a_window_closed_mid_session_is_said_and_a_view_never_opened_says_nothing() {
        let out = Shared::default();
        let mut p = Printer::new(Style::Lines, Box::new(out.clone()));
        p.take(Msg::Status(SessionStatus {
            stage: Stage::Viewing,
            planned: Planned::AtMost(40),
            ..status(Stage::Viewing, 2, 70)
        }));
        p.take(Msg::Close);
        assert_eq!(
            out.text(),
            "session opened: 2 of at most 40 trials done, 01:10 elapsed; the viewing \
             conditions wait for confirmation\nthe window closed before the session ended, after \
             2 of at most 40 trials, 01:10 elapsed (resumable)\n"
        );
        let out = Shared::default();
        let mut p = Printer::new(Style::Live, Box::new(out.clone()));
        p.take(Msg::Checking(3, 9));
        p.take(Msg::Close);
        // The progress line is erased: an error that follows starts on a clean line.
        assert_eq!(
            out.text(),
            "\r\x1b[2Kstudy run · checking the stimuli: 3 of 9\r\x1b[2K"
        );
    }

    #[test]
    fn the_watcher_sends_a_status_only_when_it_changed() {
        let (tx, rx) = mpsc::channel();
        let mut w = Watcher {
            tx: Some(tx),
            last: None,
        };
        let s = status(Stage::Trial(0), 0, 1);
        w.frame(s);
        // The clock alone is no change.
        w.frame(SessionStatus {
            elapsed_ms: 1500,
            ..s
        });
        w.frame(SessionStatus { paused: true, ..s });
        w.frame(SessionStatus { paused: true, ..s });
        let sent: Vec<bool> = rx
            .try_iter()
            .map(|m| match m {
                Msg::Status(s) => s.paused,
                _ => panic!("only statuses"),
            })
            .collect();
        assert_eq!(sent, [false, true]);
        Watcher::off().frame(s);
    }

    #[test]
    fn answers_read_as_the_subject_gave_them() {
        let a = |answer, arrangement, reference_position, correct| Answered {
            index: 0,
            practice: false,
            answer,
            arrangement,
            reference_position,
            correct,
            response_ms: 0,
            dropped: 0,
            elapsed_ms: 0,
        };
        let pair = Answer::Pair { a: 3.0, b: 4.5 };
        let cases = [
            (
                a(pair, Arrangement::Sequential, Position::First, None),
                "1 3, 2 4.5",
            ),
            (
                a(pair, Arrangement::SideBySide, Position::A, None),
                "A 3, B 4.5",
            ),
            (
                a(
                    Answer::Rating(80.0),
                    Arrangement::Grid,
                    Position::Pane(2),
                    None,
                ),
                "C 80",
            ),
            (
                a(
                    Answer::Choice(Position::Left),
                    Arrangement::SideBySide,
                    Position::Left,
                    Some(true),
                ),
                "left (correct)",
            ),
            (
                a(
                    Answer::Choice(Position::Right),
                    Arrangement::SideBySide,
                    Position::Left,
                    Some(false),
                ),
                "right (wrong)",
            ),
        ];
        for (answered, want) in cases {
            assert_eq!(answered.answer_text(), want);
        }
        assert_eq!(clock_text(59_999), "00:59");
        assert_eq!(clock_text(3_600_000), "1:00:00");
    }
}
