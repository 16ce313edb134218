//! `study serve` end to end in a real headless Chromium (Debian's `chromium`, driven over
//! WebDriver by `chromedriver`): a participant completes a MOS, a DSCQS and a live-staircase
//! study on the page, with WebGL drawn by SwiftShader, answering as `study simulate` (the
//! real binary, `--subject` the id the browser got) answered for the same subject: the
//! ratings, choices and replays of its `trials.csv`; each served session's rows equal the
//! simulated session's column by column, timing columns aside; the staircase's practice trial
//! comes first, marked on the page and logged as familiarization. The MOS server is SIGKILLed
//! mid-study and restarted: the page carries on and no answer is lost or logged twice. A second browser holding another participant's token is
//! refused A's session.
//!
//! Needs `chromium`, `chromedriver` and the built page (`scripts/build-page`, which needs
//! npm); `scripts/test` installs and builds them. Without them the test fails under `CI` and
//! is skipped elsewhere.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::too_many_lines,
    missing_docs
)]

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead as _, BufReader};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use protocols::record::{Answer, Block, Position};

mod common;
use common::Rgb;
use serde_json::{Value, json};

fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The built page beside the binary's folder, built now if missing.
fn page_ready() -> bool {
    let exe = PathBuf::from(env!("CARGO_BIN_EXE_study"));
    let page = exe.parent().unwrap().parent().unwrap().join("page");
    if page.join("index.html").is_file() {
        return true;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    have("npm")
        && Command::new(root.join("scripts/build-page"))
            .status()
            .is_ok_and(|s| s.success())
}

/// One browser test at a time: each drives a Chromium drawing WebGL on the CPU, and several
/// at once on a 2-core CI machine starve each other's frames and WebDriver round trips.
static ONE_BROWSER: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn ready() -> bool {
    let ok = have("chromium") && have("chromedriver") && page_ready();
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "chromium, chromedriver and the built page (scripts/build-page) are needed under CI"
        );
        eprintln!("skipped: chromium, chromedriver or the built page is missing");
    }
    ok
}

/// Whether a browser test can run (see [`ready`]): then it holds [`ONE_BROWSER`] until it
/// ends (a failed test's poisoned lock still serializes).
fn browser_test() -> Option<std::sync::MutexGuard<'static, ()>> {
    ready().then(|| {
        ONE_BROWSER
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    })
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("serve-browser-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

// ---- a minimal WebDriver client (HTTP/1.1, JSON) ---------------------------------------

fn http(port: u16, method: &str, path: &str, body: Option<&Value>) -> (u16, Value) {
    // chromedriver keeps connections open: the client reads by Content-Length.
    let mut c = web::client::Client::new(([127, 0, 0, 1], port).into());
    let r = c.request(method, path, body).unwrap();
    (r.status, r.json())
}

struct Driver {
    child: Child,
    port: u16,
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Driver {
    fn start() -> Driver {
        let port = free_port();
        let child = Command::new("chromedriver")
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let d = Driver { child, port };
        let deadline = Instant::now() + Duration::from_secs(20);
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(Instant::now() < deadline, "chromedriver did not start");
            std::thread::sleep(Duration::from_millis(50));
        }
        d
    }

    fn browser(&self, profile: &Path) -> Browser {
        self.browser_at(profile, 1.0)
    }

    /// A browser whose screen has `scale` device pixels per CSS pixel (what WebGL draws
    /// scales with its square; CSS sizes do not change).
    fn browser_at(&self, profile: &Path, scale: f64) -> Browser {
        let caps = json!({ "capabilities": { "alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {
                "binary": "/usr/bin/chromium",
                "args": [
                    "--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                    // WebGL without a GPU: ANGLE on SwiftShader.
                    "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                    "--disable-background-networking", "--disable-component-update",
                    "--disable-sync", "--no-first-run", "--disable-quic",
                    "--window-size=1024,720",
                    format!("--user-data-dir={}", profile.display()),
                    format!("--force-device-scale-factor={scale}"),
                ],
            },
        }}});
        let (status, v) = http(self.port, "POST", "/session", Some(&caps));
        assert_eq!(status, 200, "new session: {v}");
        Browser {
            port: self.port,
            session: v["value"]["sessionId"].as_str().unwrap().to_string(),
        }
    }
}

struct Browser {
    port: u16,
    session: String,
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = http(
            self.port,
            "DELETE",
            &format!("/session/{}", self.session),
            None,
        );
    }
}

impl Browser {
    fn cmd(&self, method: &str, path: &str, body: Option<&Value>) -> Value {
        let (status, v) = http(
            self.port,
            method,
            &format!("/session/{}/{path}", self.session),
            body,
        );
        assert_eq!(status, 200, "{method} {path}: {v}");
        v["value"].clone()
    }

    fn go(&self, url: &str) {
        self.cmd("POST", "url", Some(&json!({ "url": url })));
    }

    fn js(&self, script: &str) -> Value {
        self.cmd(
            "POST",
            "execute/sync",
            Some(&json!({ "script": script, "args": [] })),
        )
    }

    fn element(&self, css: &str) -> String {
        let v = self.cmd(
            "POST",
            "element",
            Some(&json!({ "using": "css selector", "value": css })),
        );
        v.as_object()
            .and_then(|o| o.values().next())
            .and_then(Value::as_str)
            .unwrap()
            .to_string()
    }

    /// Clicks the element `css` names; tried again (for up to about ten seconds, a loaded
    /// machine lays out slowly) while the page is re-laying out under it (an intercepted
    /// click, a replaced element, one not yet interactable).
    fn click(&self, css: &str) {
        for attempt in 0.. {
            let found = http(
                self.port,
                "POST",
                &format!("/session/{}/element", self.session),
                Some(&json!({ "using": "css selector", "value": css })),
            );
            let id = found.1["value"]
                .as_object()
                .and_then(|o| o.values().next())
                .and_then(Value::as_str)
                .map(str::to_string);
            let clicked = id.map(|id| {
                http(
                    self.port,
                    "POST",
                    &format!("/session/{}/element/{id}/click", self.session),
                    Some(&json!({})),
                )
            });
            match clicked {
                Some((200, _)) => return,
                other if attempt >= 100 => panic!(
                    "click {css} on the screen {:?}: {found:?} {other:?}",
                    self.screen()
                ),
                _ => std::thread::sleep(Duration::from_millis(100)),
            }
        }
    }

    fn type_into(&self, css: &str, text: &str) {
        let id = self.element(css);
        self.cmd(
            "POST",
            &format!("element/{id}/value"),
            Some(&json!({ "text": text })),
        );
    }

    /// Presses keys (WebDriver key codes: `\u{E007}` Enter, `\u{E012}` left, `\u{E014}`
    /// right) as the keyboard does.
    fn keys(&self, keys: &[&str]) {
        let mut actions = Vec::new();
        for k in keys {
            actions.push(json!({ "type": "keyDown", "value": k }));
            actions.push(json!({ "type": "keyUp", "value": k }));
        }
        self.cmd(
            "POST",
            "actions",
            Some(&json!({ "actions": [{ "type": "key", "id": "kb", "actions": actions }] })),
        );
        self.cmd("DELETE", "actions", None);
    }

    /// Waits until `cond` (a JS expression) is true.
    fn wait(&self, cond: &str, secs: u64) {
        let deadline = Instant::now() + Duration::from_secs(secs);
        loop {
            if self.js(&format!("return !!({cond});")) == Value::Bool(true) {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {cond}; screen {}, text: {}",
                self.js("return document.body.dataset.screen;"),
                self.js("return document.body.innerText.slice(0, 600);")
            );
            std::thread::sleep(Duration::from_millis(40));
        }
    }

    /// Runs `script` (which calls `done(value)`) asynchronously in the page.
    fn js_async(&self, script: &str) -> Value {
        self.cmd(
            "POST",
            "execute/async",
            Some(&json!({
                "script": format!("const done = arguments[arguments.length - 1]; {script}"),
                "args": [],
            })),
        )
    }

    /// The viewport as the participant sees it, as a PNG at `path`.
    fn screenshot(&self, path: &Path) {
        use base64::Engine as _;
        let png = self.cmd("GET", "screenshot", None);
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(png.as_str().unwrap())
            .unwrap();
        std::fs::write(path, bytes).unwrap();
    }

    fn resize(&self, width: u32, height: u32) {
        self.cmd(
            "POST",
            "window/rect",
            Some(&json!({ "width": width, "height": height })),
        );
    }

    /// Makes the page's viewport (`innerWidth` × `innerHeight`) `width` × `height` CSS
    /// pixels at a device pixel ratio of 1, as a screen of that size shows it (Chromium's
    /// device metrics: a headless window cannot outgrow its virtual screen).
    fn viewport(&self, width: u32, height: u32) {
        self.cmd(
            "POST",
            "goog/cdp/execute",
            Some(&json!({
                "cmd": "Emulation.setDeviceMetricsOverride",
                "params": { "width": width, "height": height, "deviceScaleFactor": 1, "mobile": false },
            })),
        );
        self.wait(
            &format!("innerWidth === {width} && innerHeight === {height}"),
            10,
        );
    }

    /// Gives the viewport back to the window's own size ([`Self::viewport`] undone).
    fn window_viewport(&self) {
        self.cmd(
            "POST",
            "goog/cdp/execute",
            Some(&json!({ "cmd": "Emulation.clearDeviceMetricsOverride", "params": {} })),
        );
    }

    fn text(&self, id: &str) -> String {
        self.js(&format!(
            "return document.getElementById('{id}').textContent;"
        ))
        .as_str()
        .unwrap_or("")
        .to_string()
    }

    fn screen(&self) -> String {
        self.js("return document.body.dataset.screen;")
            .as_str()
            .unwrap_or("")
            .to_string()
    }
}

// ---- the server ------------------------------------------------------------------------

struct Serve {
    child: Child,
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn serve(study: &Path, out: &Path, port: u16) -> Serve {
    let mut child = Command::new(env!("CARGO_BIN_EXE_study"))
        .arg("serve")
        .arg(study)
        .arg("-o")
        .arg(out)
        .args(["--bind", &format!("127.0.0.1:{port}")])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.starts_with("serving "), "study serve said {line:?}");
    Serve { child }
}

/// Generated walk stimuli of half a second (clip `walk`, `spiht` at 10:1 and
/// 20:1) and a study file of `protocol` over them.
fn write_study(dir: &Path, body: &str) -> PathBuf {
    let walk = motion::synth::WalkParams {
        duration_s: 0.5,
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    };
    lab::generated::walk_stimuli(dir, &walk, &["spiht"], &[10.0, 20.0]).unwrap();
    let path = dir.join("study.toml");
    std::fs::write(
        &path,
        format!("format_version = 1\nstimuli = \"stimuli/stimuli.json\"\nseed = 9\n{body}"),
    )
    .unwrap();
    path
}

const MOS: &str = "name = \"web-mos\"\nprotocol = \"mos\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
    [presentation]\nloop = true\ngap_ms = 100\nstimulus_duration_ms = 500\n\
    [session]\nfamiliarization = 1\nhidden_repeats = 1\nbreak_every_trials = 2\n\
    subject_fields = [\"age\"]\nconsent = \"You agree to watch four short motions.\"\n";

// Whole grades on the continuous scale, so that the keyboard can give any rating the
// simulated observer gives.
const DSCQS: &str = "name = \"web-dscqs\"\nprotocol = \"dscqs\"\n[scale]\nstep = 1\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
    [presentation]\narrangement = \"abab\"\ngrey_ms = 150\ngap_ms = 100\nmax_replays = 0\n\
    stimulus_duration_ms = 500\n[crowdsourcing]\nfullscreen = true\nmin_window = [640, 480]\n";

const STAIRCASE: &str = "name = \"web-stairs\"\nprotocol = \"staircase\"\n\
    [presentation]\nloop = true\ngap_ms = 100\nstimulus_duration_ms = 500\n\
    [staircase]\nparam = \"cr\"\ncodec = \"spiht\"\nstart = 20\nstep = 5\nmin = 10\nmax = 30\n\
    max_trials = 4\npractice_trials = 1\npractice_level = 25\n[[staircase.tracks]]\nname = \"walk\"\n\
    [staircase.live]\nclips = [\"walk\"]\n";

/// What the simulated observer answered, by trial index: the answer and the replays.
type Script = BTreeMap<u32, (Answer, u32)>;

/// Runs `study simulate STUDY --subject SUBJECT --seed SEED` (the real binary) into a
/// folder of its own, and returns its rows and the answers they hold.
fn simulate(
    study: &Path,
    dir: &Path,
    subject: &str,
    seed: u64,
) -> (Vec<protocols::TrialRecord>, Script) {
    let out = dir.join(format!("simulated-{seed}"));
    let run = Command::new(env!("CARGO_BIN_EXE_study"))
        .arg("simulate")
        .arg(study)
        .args(["--subject", subject, "--seed", &seed.to_string(), "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "study simulate --subject {subject}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let rows = results::read_trials(&out.join(format!("{subject}_s1/trials.csv")))
        .unwrap()
        .records;
    let script = rows
        .iter()
        .map(|r| (r.trial.index, (r.response.answer, r.response.replays)))
        .collect();
    (rows, script)
}

/// Gives `answer` to the open trial as a participant does, after `replays` replays: MOS by
/// mouse (the grade, then Continue), DSCQS by keyboard (a grade's digit, then Up/Down to the
/// exact value, A then B, Enter), 2AFC by arrow key or click.
fn give(b: &Browser, (answer, replays): (Answer, u32)) {
    for _ in 0..replays {
        b.wait("!document.getElementById('replay').hidden", 30);
        b.click("#replay");
    }
    match answer {
        Answer::Rating(v) => {
            b.click(&format!(".rating[data-value=\"{v}\"]"));
            b.click("#continue");
        }
        Answer::Pair { a, b: bv }
            if b.js("return !!document.querySelector('.rating');") == Value::Bool(true) =>
        {
            // Two rows of grade buttons (a categorical scale), by mouse.
            b.click(&format!(".rating[data-row=\"0\"][data-value=\"{a}\"]"));
            b.click(&format!(".rating[data-row=\"1\"][data-value=\"{bv}\"]"));
            b.click("#continue");
        }
        Answer::Pair { a, b: bv } => {
            // Digit d marks the middle of grade d on BT.500's 0-100 scale, (d - 0.5) x 20;
            // Up/Down move by the scale's step (1).
            let keys = |v: f64| -> Vec<String> {
                let d = ((v / 20.0).floor() + 1.0).clamp(1.0, 5.0);
                let steps = (v - (d - 0.5) * 20.0).round() as i32;
                let arrow = if steps > 0 { "\u{E013}" } else { "\u{E015}" };
                std::iter::once(d.to_string())
                    .chain((0..steps.abs()).map(|_| arrow.to_string()))
                    .collect()
            };
            let mut all = vec!["\u{E012}".to_string()];
            let ka = keys(a);
            all.push(ka[0].clone());
            // The digit moved the edit to B: back to A for the steps.
            all.push("\u{E012}".into());
            all.extend(ka[1..].iter().cloned());
            all.push("\u{E014}".into());
            all.extend(keys(bv));
            all.push("\u{E007}".into());
            let all: Vec<&str> = all.iter().map(String::as_str).collect();
            b.keys(&all);
        }
        Answer::Choice(Position::Left) => b.keys(&["\u{E012}"]),
        Answer::Choice(p) => {
            let name = serde_json::to_value(p).unwrap();
            b.click(&format!("#choice-{}", name.as_str().unwrap()));
        }
    }
}

/// Rates every pane of an open MUSHRA screen as the script says (each slider moved to its
/// value) after the screen's replays (every pane's row logs them), then Continue.
fn give_screen(b: &Browser, script: &Script, panes: &[u32]) {
    let replays = script.get(&panes[0]).map_or(0, |a| a.1);
    for _ in 0..replays {
        b.wait("!document.getElementById('replay').hidden", 30);
        b.click("#replay");
    }
    for (k, index) in panes.iter().enumerate() {
        let Some((Answer::Rating(v), _)) = script.get(index) else {
            panic!("pane trial {index} has no rating in the simulated session");
        };
        b.js(&format!(
            "const i = document.querySelector('input[data-pane=\"{k}\"]'); \
             i.value = {v}; i.dispatchEvent(new Event('input')); return null;"
        ));
    }
    b.click("#continue");
}

/// Joins from a Prolific link, passes the welcome screen and answers trials until the
/// session ends (or `stop_after` trials, then returns), answering as `script` says; notes
/// the trials answered in `given`.
fn take_part(
    b: &Browser,
    url: Option<&str>,
    script: &Script,
    stop_after: Option<u32>,
    given: &mut BTreeSet<u32>,
) {
    if let Some(url) = url {
        b.go(url);
        welcome(b);
    }
    answer_trials(b, script, stop_after, given);
}

/// From the environment check through the welcome screen.
fn welcome(b: &Browser) {
    reach_welcome(b);
    if b.screen() == "welcome" {
        fill_welcome(b);
        b.click("#begin");
    }
}

/// From the environment check to the welcome screen (or a resumed session's trial).
fn reach_welcome(b: &Browser) {
    if b.screen() != "welcome" {
        b.wait("document.body.dataset.checked === 'ok' || document.body.dataset.screen === 'welcome' || document.body.dataset.screen === 'trial'", 30);
        if b.screen() == "check" {
            b.click("#check-continue");
        }
    }
    b.wait(
        "['welcome', 'trial'].includes(document.body.dataset.screen)",
        30,
    );
}

/// Answers every subject field of the welcome screen validly (an age typed as 31, another
/// number its smallest value, a choice's or yes/no's first option, text "x") and ticks
/// the consent box where there is one.
fn fill_welcome(b: &Browser) {
    if b.js("return !!document.querySelector('input[name=age]:not([type=radio])');")
        == Value::Bool(true)
    {
        b.type_into("input[name=age]", "31");
    }
    // An example's other fields, whatever they are called.
    b.js(
        "for (const i of document.querySelectorAll('#welcome-fields input')) { \
            if (i.type === 'radio') { \
              if (!document.querySelector(`#welcome-fields input[name=\"${i.name}\"]:checked`)) { \
                i.checked = true; i.dispatchEvent(new Event('change', { bubbles: true })); } \
            } else if (!i.value) { \
              i.value = i.type === 'number' ? (i.min || '1') : 'x'; \
              i.dispatchEvent(new Event('input', { bubbles: true })); } } \
          return null;",
    );
    if b.js("return !document.getElementById('welcome-consent').hidden;") == Value::Bool(true) {
        b.click("#consent");
    }
}

/// The page's count of answers the server refused, as a JS expression.
const REFUSALS: &str = "Number(document.body.dataset.refusals || 0)";

/// Answers trials (and breaks) until the end, or until `stop_after` answers in all. An
/// answer the server refuses (the page shows the reason and the trial again) is given
/// again once the trial has replayed.
fn answer_trials(b: &Browser, script: &Script, stop_after: Option<u32>, given: &mut BTreeSet<u32>) {
    loop {
        // Screen and trial read together: the page may move on between two reads.
        b.wait(
            "['break', 'end'].includes(document.body.dataset.screen) || \
             (document.body.dataset.screen === 'trial' && document.body.dataset.open === '1')",
            60,
        );
        let at = b.js(&format!(
            "const d = document.body.dataset; return [d.screen, Number(d.trial), {REFUSALS}];"
        ));
        match at[0].as_str() {
            Some("end") => return,
            Some("break") => {
                b.click("#break-continue");
                // The page leaves the break at once; read again before, the screen
                // would still say "break" and a second click would find it hidden.
                b.wait("document.body.dataset.screen !== 'break'", 30);
                continue;
            }
            Some("trial") => {}
            // Moved on since the wait.
            _ => continue,
        }
        let k = at[1].as_u64().unwrap() as u32;
        // An answer closes the trial's widgets; only a refusal opens them again.
        assert!(!given.contains(&k), "trial {k}, answered, is open again");
        let Some(&answer) = script.get(&k) else {
            panic!(
                "trial {k} is not in the simulated session ({} rows)",
                script.len()
            );
        };
        // The trials this screen answers (a MUSHRA screen's panes).
        let panes = b.js("return document.body.dataset.trials;");
        let panes: Vec<u32> = panes
            .as_str()
            .unwrap_or("")
            .split(',')
            .filter_map(|i| i.parse().ok())
            .collect();
        if panes.len() > 1 {
            given.extend(&panes);
            give_screen(b, script, &panes);
        } else {
            given.insert(k);
            give(b, answer);
        }
        let refusals = &at[2];
        b.wait(
            &format!(
                "document.body.dataset.screen !== 'trial' || document.body.dataset.trial !== '{k}' \
                 || {REFUSALS} !== {refusals}"
            ),
            60,
        );
        if b.js(&format!("return {REFUSALS};")) != *refusals {
            // Refused: the same trial again, from the start.
            given.remove(&k);
            for p in &panes {
                given.remove(p);
            }
            continue;
        }
        if stop_after.is_some_and(|n| given.len() as u32 >= n) {
            return;
        }
    }
}

/// The rows of the served session against the simulated session's, column by column,
/// timing columns aside (the response time, dropped frames, the three clocks, the frame
/// timing).
fn check_rows(
    out: &Path,
    subject: &str,
    simulated: &[protocols::TrialRecord],
    given: &BTreeSet<u32>,
) {
    let served = results::read_trials(&out.join(format!("{subject}_s1/trials.csv"))).unwrap();
    assert_eq!(served.records.len(), simulated.len(), "rows of {subject}");
    assert_eq!(
        served.records.len(),
        given.len(),
        "one row per answer given"
    );
    for (got, want) in served.records.iter().zip(simulated) {
        let at = format!("{subject} trial {}", want.trial.index);
        assert_eq!(got.study, want.study, "{at}");
        assert_eq!(got.subject, want.subject, "{at}");
        assert_eq!(got.session, want.session, "{at}");
        assert_eq!(got.protocol, want.protocol, "{at}");
        assert_eq!(got.trial, want.trial, "{at}");
        assert_eq!(got.response.answer, want.response.answer, "{at}");
        assert_eq!(got.response.replays, want.response.replays, "{at}");
        assert_eq!(got.outcome, want.outcome, "{at}");
        assert_eq!(got.encoding, want.encoding, "{at}");
        // The page measured its frames: every trial has timing from the browser.
        assert!(
            got.timing.is_some_and(|t| t.frames_shown > 2),
            "{at}: {:?}",
            got.timing
        );
    }
}

/// Reloads the page once the pending trial's stimuli have played: the page continues the
/// same session and the same trial, which plays again from the start before it can be
/// answered; nothing is logged for it meanwhile.
fn reload_mid_trial(b: &Browser, out: &Path, given: &BTreeSet<u32>) {
    b.wait(
        "document.body.dataset.screen === 'trial' && document.body.dataset.open === '1'",
        60,
    );
    let k = b.js("return document.body.dataset.trial;");
    let rows = std::fs::read(out.join("pidA_s1/trials.csv")).unwrap();
    b.cmd("POST", "refresh", Some(&json!({})));
    b.wait("document.body.dataset.screen === 'welcome'", 30);
    assert_eq!(
        b.text("welcome-resume"),
        format!(
            "Continuing the session: {} trials already done.",
            given.len()
        )
    );
    // Every state the page goes through from here, as it happens (not polled: a loaded
    // machine's WebDriver round trips are slower than the presentation).
    b.js(
        "window.seen = []; new MutationObserver(() => { const d = document.body.dataset; \
          const r = document.querySelector('.rating'); \
          window.seen.push([d.screen, d.trial, d.open, r ? r.disabled : null, performance.now()]); \
          }).observe(document.body, { attributes: true, subtree: true }); return null;",
    );
    b.click("#begin");
    b.wait(
        "document.body.dataset.screen === 'trial' && document.body.dataset.open === '1'",
        30,
    );
    let seen = b.js("return window.seen;");
    let seen = seen.as_array().unwrap();
    let shown = seen
        .iter()
        .position(|s| s[0] == "trial")
        .expect("the trial screen");
    let opened = seen
        .iter()
        .position(|s| s[0] == "trial" && s[2] == "1")
        .expect("the answer opened");
    // The same trial, from the start: the answer widgets stay closed until it has played
    // (500 ms of stimulus) again.
    assert_eq!(seen[shown][1], k, "{seen:?}");
    assert!(
        seen[shown..opened]
            .iter()
            .all(|s| s[2] == "0" && s[3] != false),
        "{seen:?}"
    );
    let waited = seen[opened][4].as_f64().unwrap() - seen[shown][4].as_f64().unwrap();
    assert!(
        waited >= 450.0,
        "answers opened {waited:.0} ms after the trial showed"
    );
    assert_eq!(
        std::fs::read(out.join("pidA_s1/trials.csv")).unwrap(),
        rows,
        "nothing logged by the reload"
    );
}

/// From here on, the first answer the page posts after a break claims that nothing was
/// played, which the server refuses (422); every change of screen, trial, open state and
/// error text is traced as it happens.
fn refuse_first_answer_after_a_break(b: &Browser) {
    b.js(
        "window.trace = []; window.refusedTrial = null; let last = ''; \
         const note = () => { const d = document.body.dataset; \
           const e = document.getElementById('trial-error').textContent; \
           const s = [d.screen, d.trial, d.open, e].join('|'); \
           if (s !== last) { last = s; window.trace.push([d.screen, d.trial, d.open, e].map(String)); } }; \
         note(); \
         new MutationObserver(note).observe(document.body, \
           { attributes: true, childList: true, subtree: true, characterData: true }); \
         const real = window.fetch; \
         window.fetch = (path, init) => { \
           if (window.refusedTrial === null && init && init.method === 'POST' \
               && String(path).endsWith('/answer') && window.trace.some((t) => t[0] === 'break')) { \
             const body = JSON.parse(init.body); body.played_ms = 0; \
             window.refusedTrial = body.index; window.trace.push(['refusing', String(body.index), '', '']); \
             init = { ...init, body: JSON.stringify(body) }; \
           } \
           return real(path, init); }; \
         return null;",
    );
}

/// The refused answer's trial was shown again at once, without its break, closed until
/// it had played, with the server's reason on screen; then answered.
fn check_refusal(b: &Browser) {
    let k = b.js("return window.refusedTrial;");
    let k = k
        .as_u64()
        .unwrap_or_else(|| panic!("no answer refused: {}", b.js("return window.trace;")))
        .to_string();
    let trace = b.js("return window.trace;");
    let trace: Vec<Vec<String>> = serde_json::from_value(trace).unwrap();
    let at = trace.iter().position(|t| t[0] == "refusing").unwrap();
    let until_gap: Vec<&Vec<String>> = trace[at + 1..]
        .iter()
        .take_while(|t| t[0] != "gap")
        .collect();
    assert!(
        until_gap.iter().all(|t| t[0] == "trial" && t[1] == k),
        "only trial {k} between the refusal and the next blank: {until_gap:?}"
    );
    let reopened = until_gap
        .iter()
        .position(|t| t[2] == "1")
        .expect("the answers opened again");
    assert!(
        until_gap[..reopened].iter().any(|t| t[2] == "0"),
        "closed until the trial had played again: {until_gap:?}"
    );
    assert!(
        until_gap[reopened][3].contains("answered before the stimuli had played"),
        "the reason on screen: {until_gap:?}"
    );
    assert!(
        trace[at + 1 + until_gap.len()..]
            .iter()
            .any(|t| t[0] == "gap"),
        "then answered: {trace:?}"
    );
}

/// The environment check of a study that asks for fullscreen and a 640×480 window, in a
/// window too small: the page refuses with the reasons and offers no way on; the server
/// refuses the same environment posted to it, and no participant or session is recorded.
/// Enlarged, the window still waits for fullscreen; in fullscreen the check passes.
fn environment_check(b: &Browser, url: &str, out: &Path) {
    b.resize(560, 420);
    b.go(url);
    b.wait("document.body.dataset.checked === 'failed'", 30);
    let problems = b.text("check-problems");
    assert!(
        problems.contains("the study needs at least 640×480. Enlarge the window.")
            && problems.contains("The study runs in full screen."),
        "{problems}"
    );
    assert_eq!(
        b.js("return document.getElementById('check-continue').disabled;"),
        json!(true)
    );
    let refused = b.js_async(
        "fetch('/api/join', { method: 'POST', headers: { 'Content-Type': 'application/json' }, \
         body: JSON.stringify({ params: { workerId: 'Wsmall' }, environment: state_env() }) })\
         .then(async (r) => done([r.status, (await r.json()).error]));\
         function state_env() { return { webgl2: true, webgl_renderer: 'x', user_agent: navigator.userAgent, \
         screen_px: [screen.width, screen.height], window_px: [innerWidth, innerHeight], \
         device_pixel_ratio: 1, refresh_hz: 60, fullscreen: false }; }",
    );
    assert_eq!(refused[0], json!(400), "{refused}");
    let said = refused[1].as_str().unwrap();
    assert!(
        said.starts_with("this browser cannot run the study: the window is ")
            && said.contains("the study needs at least 640×480; the study runs in fullscreen"),
        "{said}"
    );
    let joined = std::fs::read_to_string(out.join("participants.csv")).unwrap_or_default();
    assert!(!joined.contains("Wsmall"), "{joined}");
    assert!(!out.join("Wsmall_s1").exists());
    // Large enough, but not yet in fullscreen.
    b.resize(1024, 720);
    b.wait(
        "!document.getElementById('check-problems').textContent.includes('Enlarge')",
        30,
    );
    assert_eq!(b.text("check-problems"), "The study runs in full screen.");
    assert_eq!(
        b.js("return document.body.dataset.checked;"),
        json!("failed")
    );
    b.click("#fullscreen");
    b.wait("document.body.dataset.checked === 'ok'", 30);
    assert_eq!(b.js("return !!document.fullscreenElement;"), json!(true));
}

fn manifest(out: &Path, subject: &str) -> results::SessionManifest {
    results::store::read_manifest(&out.join(format!("{subject}_s1/session.json"))).unwrap()
}

#[test]
fn a_browser_completes_mos_through_a_server_kill_and_a_foreign_token_is_refused() {
    let Some(_one) = browser_test() else {
        return;
    };
    let dir = temp_dir("mos");
    let study = write_study(&dir, MOS);
    let out = dir.join("results");
    let port = free_port();
    // The first observer whose session replays a trial (one in ten trials does), so that
    // the page replays too.
    let (simulated, script) = (1..=30)
        .map(|seed| simulate(&study, &dir, "pidA", seed))
        .find(|(_, script)| script.values().any(|(_, replays)| *replays > 0))
        .expect("a simulated session with a replay among 30 observer seeds");
    let mut server = serve(&study, &out, port);
    let driver = Driver::start();
    let b = driver.browser(&dir.join("profile-a"));
    let url = format!("http://127.0.0.1:{port}/?PROLIFIC_PID=pidA&STUDY_ID=st1&SESSION_ID=se1");
    let mut given = BTreeSet::new();
    take_part(&b, Some(&url), &script, Some(2), &mut given);
    // Mid-study: the server dies without a word, and comes back.
    server.child.kill().unwrap();
    server.child.wait().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    server = serve(&study, &out, port);
    // The page carries on from where it was (it retries what it was sending). The next
    // answer after the break it reaches is refused, and given again.
    refuse_first_answer_after_a_break(&b);
    take_part(&b, None, &script, Some(3), &mut given);
    check_refusal(&b);
    reload_mid_trial(&b, &out, &given);
    take_part(&b, None, &script, None, &mut given);
    assert_eq!(b.screen(), "end");
    check_rows(&out, "pidA", &simulated, &given);
    let m = manifest(&out, "pidA");
    assert_eq!(m.status, results::store::SessionState::Complete);
    assert_eq!(
        m.subject_fields
            .get("prolific_session_id")
            .map(String::as_str),
        Some("se1")
    );
    assert_eq!(
        m.subject_fields.get("consent").map(String::as_str),
        Some("given")
    );
    let browser = m.browser.expect("the browser's measurements");
    assert!(
        browser.user_agent.contains("Chrome"),
        "{}",
        browser.user_agent
    );
    assert!(browser.refresh_hz > 20.0, "{}", browser.refresh_hz);
    assert!(m.resumes >= 1, "the session was resumed after the kill");

    // A second browser joins as B, then opens A's link with B's token: refused.
    let b2 = driver.browser(&dir.join("profile-b"));
    b2.go(&format!("http://127.0.0.1:{port}/?PROLIFIC_PID=pidB"));
    b2.wait("document.body.dataset.checked === 'ok'", 30);
    b2.click("#check-continue");
    b2.wait("document.body.dataset.screen === 'welcome'", 30);
    let token_b = b2.js("return new URLSearchParams(location.hash.slice(1)).get('t');");
    let token_b = token_b.as_str().unwrap();
    let rows_a = std::fs::read(out.join("pidA_s1/trials.csv")).unwrap();
    b2.go(&format!("http://127.0.0.1:{port}/?s=pidA#t={token_b}"));
    b2.wait("document.body.dataset.screen === 'message'", 30);
    let text = b2.js("return document.body.innerText;");
    assert!(
        text.as_str().unwrap().contains("This link is not valid"),
        "{text}"
    );
    assert_eq!(
        std::fs::read(out.join("pidA_s1/trials.csv")).unwrap(),
        rows_a
    );
    drop(server);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A MOS study asking a number, a choice and a yes/no question.
const TYPED_FIELDS: &str = "name = \"web-fields\"\nprotocol = \"mos\"\n\
    [conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
    [presentation]\ngap_ms = 100\nstimulus_duration_ms = 500\n\
    [session]\nconsent = \"You agree to watch four short motions.\"\nsubject_fields = [\
    { name = \"age\", kind = \"number\", min = 18, max = 99, integer = true, label = \"Age (years)\" }, \
    { name = \"gender\", kind = \"choice\", options = [\"female\", \"male\", \"prefer not to say\"] }, \
    { name = \"normal_vision\", kind = \"yes_no\", label = \"Normal or corrected vision\" }]\n";

/// Types `text` into the empty field `css` (cleared first).
fn retype(b: &Browser, css: &str, text: &str) {
    let id = b.element(css);
    b.cmd("POST", &format!("element/{id}/clear"), Some(&json!({})));
    b.type_into(css, text);
}

/// The welcome form draws each subject field by its kind (a number box with the field's
/// range, a radio button per option, each labelled and reached by the keyboard) and checks
/// an answer by the server's rules before sending it: "abc" and 17 for an age from 18 to 99
/// are refused on the page, the reason beside the field, and nothing is sent; an answer the
/// server refuses anyway (the page's request altered on its way) shows the server's reason
/// there too. Then 31, a choice and yes begin the session, and `session.json` holds them as
/// the fields store them.
#[test]
fn the_welcome_form_checks_each_field_by_its_kind() {
    let Some(_one) = browser_test() else {
        return;
    };
    let dir = temp_dir("fields");
    let study = write_study(&dir, TYPED_FIELDS);
    let out = dir.join("results");
    let port = free_port();
    let _server = serve(&study, &out, port);
    let driver = Driver::start();
    let b = driver.browser(&dir.join("profile"));
    b.go(&format!("http://127.0.0.1:{port}/?PROLIFIC_PID=pidF"));
    reach_welcome(&b);
    assert_eq!(b.screen(), "welcome");
    let form = b.js(
        "const age = document.querySelector('input[name=age]'); \
         const radios = (n) => [...document.querySelectorAll(`input[type=radio][name=${n}]`)]; \
         const said = (i) => document.querySelector(`label[for=\"${i.id}\"]`).textContent.trim(); \
         return { age: [age.type, age.min, age.max, age.step, said(age)], \
           gender: radios('gender').map(said), vision: radios('normal_vision').map(said), \
           groups: [...document.querySelectorAll('[role=radiogroup]')].map((g) => \
             document.getElementById(g.getAttribute('aria-labelledby')).textContent), \
           reachable: radios('gender').concat(radios('normal_vision')).every((r) => r.tabIndex >= 0 && !r.disabled), \
           consent: document.getElementById('consent-title').textContent };",
    );
    assert_eq!(
        form,
        json!({
            "age": ["number", "18", "99", "1", "Age (years)"],
            "gender": ["female", "male", "prefer not to say"],
            "vision": ["yes", "no"],
            "groups": ["gender", "Normal or corrected vision"],
            "reachable": true,
            "consent": "Consent",
        })
    );
    // Every request to begin, counted; the next one altered to an age the server refuses.
    b.js(
        "window.begins = 0; window.alterBegin = false; const real = window.fetch; \
         window.fetch = (path, init) => { \
           if (init && init.method === 'POST' && String(path).endsWith('/begin')) { \
             window.begins += 1; \
             if (window.alterBegin) { window.alterBegin = false; \
               const body = JSON.parse(init.body); body.fields.age = '17'; \
               init = { ...init, body: JSON.stringify(body) }; } } \
           return real(path, init); }; return null;",
    );
    // The choice by mouse, yes by keyboard (focus, Space), consent ticked.
    b.click("label[for=field-gender-1]");
    b.js("document.getElementById('field-normal_vision-0').focus(); return null;");
    b.keys(&["\u{E00D}"]);
    b.click("#consent");
    let reason = "Age (years): enter a whole number from 18 to 99";
    let session = out.join("pidF_s1/session.json");
    for typed in ["abc", "17"] {
        retype(&b, "input[name=age]", typed);
        b.click("#begin");
        b.wait(
            &format!(
                "document.getElementById('field-age-reason').textContent.startsWith('{reason}')"
            ),
            10,
        );
        assert_eq!(
            b.js("return window.begins;"),
            json!(0),
            "{typed}: nothing sent"
        );
        assert_eq!(b.screen(), "welcome", "{typed}");
        assert!(!session.exists(), "{typed}: no session begun");
    }
    // The page lets 31 through; the server refuses the 17 it receives instead, and its
    // reason shows beside the field and under Begin.
    retype(&b, "input[name=age]", "31");
    b.wait(
        "document.getElementById('field-age-reason').textContent === ''",
        10,
    );
    b.js("window.alterBegin = true; return null;");
    b.click("#begin");
    b.wait(
        &format!("document.getElementById('begin-error').textContent === '{reason}'"),
        10,
    );
    assert_eq!(b.text("field-age-reason"), reason);
    assert_eq!(b.js("return window.begins;"), json!(1));
    assert_eq!(b.screen(), "welcome");
    assert!(!session.exists(), "no session begun by the refused request");
    b.click("#begin");
    b.wait(
        "['trial', 'gap'].includes(document.body.dataset.screen)",
        30,
    );
    assert_eq!(b.js("return window.begins;"), json!(2));
    let m = manifest(&out, "pidF");
    for (k, v) in [
        ("age", "31"),
        ("gender", "male"),
        ("normal_vision", "yes"),
        ("consent", "given"),
    ] {
        assert_eq!(m.subject_fields.get(k).map(String::as_str), Some(v), "{k}");
    }
    drop(b);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_browser_completes_dscqs_and_a_live_staircase() {
    let Some(_one) = browser_test() else {
        return;
    };
    let driver = Driver::start();
    for (name, body) in [("dscqs", DSCQS), ("stairs", STAIRCASE)] {
        let dir = temp_dir(name);
        let study = write_study(&dir, body);
        let out = dir.join("results");
        let port = free_port();
        let subject = format!("W{name}");
        let (simulated, script) = simulate(&study, &dir, &subject, 1);
        let _server = serve(&study, &out, port);
        let b = driver.browser(&dir.join("profile"));
        let mut given = BTreeSet::new();
        let url = format!("http://127.0.0.1:{port}/?workerId={subject}&assignmentId=A1&hitId=H1");
        let fullscreen = name == "dscqs";
        if fullscreen {
            environment_check(&b, &url, &out);
            welcome(&b);
            // One trial in fullscreen, the others after leaving it.
            answer_trials(&b, &script, Some(1), &mut given);
            b.js("document.exitFullscreen(); return null;");
            b.wait("!document.fullscreenElement", 10);
            answer_trials(&b, &script, None, &mut given);
        } else {
            b.go(&url);
            welcome(&b);
            // The staircase's practice trial comes first, marked on the page.
            b.wait("document.body.dataset.open === '1'", 60);
            assert_eq!(
                b.js("return !document.getElementById('practice').hidden;"),
                Value::Bool(true),
                "the practice trial is marked"
            );
            answer_trials(&b, &script, None, &mut given);
        }
        assert_eq!(b.screen(), "end");
        check_rows(&out, &subject, &simulated, &given);
        if name == "stairs" {
            // One practice trial at its own level, logged apart, then the staircase's four.
            let rows = results::read_trials(&out.join(format!("{subject}_s1/trials.csv")))
                .unwrap()
                .records;
            let blocks: Vec<Block> = rows.iter().map(|r| r.trial.block).collect();
            assert_eq!(
                blocks,
                [
                    Block::Familiarization,
                    Block::Test,
                    Block::Test,
                    Block::Test,
                    Block::Test
                ]
            );
            assert_eq!(rows[0].trial.level, Some(25.0));
            assert_eq!(
                rows[1].trial.level,
                Some(20.0),
                "the staircase starts at its start"
            );
        }
        if fullscreen {
            let m = manifest(&out, &subject);
            let browser = m.browser.expect("the browser's measurements");
            assert!(browser.fullscreen, "the session began in fullscreen");
            let first = *given.first().unwrap();
            let after: Vec<u32> = given.iter().copied().filter(|k| *k != first).collect();
            assert_eq!(
                browser.windowed_trials, after,
                "trials answered outside fullscreen"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// How many times shorter the examples' clips and grey screens are when their whole sessions
/// run in the browser: their 3-4-second clips and 1-3-second greys make the 14 sessions about
/// half an hour of playback, which CI's time cannot hold; a sixteenth of it takes a few minutes.
/// What a session is (its trials, order, hidden repeats, groups, staircases, answers) does not
/// depend on the clips' length. `SCREENSHOTS` (for docs/serve.md) takes the examples as they
/// are.
const SHORTER: usize = 16;

/// How many times fewer trials a staircase may take (`max_trials`) in the shortened copy,
/// and how many times fewer reversals end it (`stop_reversals`, no fewer than the examples'
/// `threshold_reversals`): the staircases' 190 trials were half of the examples' whole
/// sessions in the browser. Each staircase still turns, stops by its rule and is estimated.
const FEWER_TRIALS: usize = 4;
/// See [`FEWER_TRIALS`].
const FEWER_REVERSALS: usize = 2;

/// Copies the example folder into `dir` with every stimulus clip (BVH, AMC) cut to its first
/// 1/[`SHORTER`] of frames, every study's `grey_ms` and `gap_ms` divided by [`SHORTER`], its
/// `max_trials` by [`FEWER_TRIALS`] and its `stop_reversals` by [`FEWER_REVERSALS`]
/// (the live staircase's 3-s clips stay whole: it encodes them as it goes at up to 80:1,
/// which a cut clip's stream headers cannot reach).
/// The stimulus manifests keep their error metrics (which both the server and `study
/// simulate` read) and drop their bitstreams, whose decodings the cut clips no longer are,
/// and their files' SHA-256.
/// Adds two variants the examples lack: `quest.toml` with Psi's rule (`psi.toml`) and
/// `groups.toml` with catch trials, which every session gets whatever its group
/// (`groups-catch.toml`). Returns the studies, sorted by name.
fn short_examples(dir: &Path) -> Vec<PathBuf> {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap() {
            let path = e.unwrap().path();
            let target = to.join(path.file_name().unwrap());
            let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
            if path.is_dir() {
                copy(&path, &target);
            } else if (ext == "bvh" || ext == "amc") && !from.ends_with("live/clips") {
                let text = std::fs::read_to_string(&path).unwrap();
                let cut = if ext == "bvh" {
                    cut_bvh(&text)
                } else {
                    cut_amc(&text)
                };
                std::fs::write(&target, cut).unwrap();
            } else if ext == "mcz" {
                // A cut clip is no longer its bitstream's decoding (the manifest drops it).
            } else if path.file_name().is_some_and(|n| n == "stimuli.json") {
                let mut manifest: Value =
                    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
                for s in manifest["stimuli"].as_array_mut().unwrap() {
                    if let Some(b) = s.get_mut("bitstream") {
                        *b = Value::Null;
                    }
                    // The cut files are no longer the files the manifest was written with.
                    let s = s.as_object_mut().unwrap();
                    s.remove("sha256");
                    s.remove("bitstream_sha256");
                }
                std::fs::write(&target, manifest.to_string()).unwrap();
            } else if ext == "toml" && from.file_name().is_some_and(|n| n == "examples") {
                let text = std::fs::read_to_string(&path).unwrap();
                let mut short = String::new();
                for line in text.lines() {
                    let cut = [
                        ("grey_ms = ", SHORTER),
                        ("gap_ms = ", SHORTER),
                        ("max_trials = ", FEWER_TRIALS),
                        ("stop_reversals = ", FEWER_REVERSALS),
                    ]
                    .into_iter()
                    .find_map(|(key, by)| {
                        let n: usize = line.strip_prefix(key)?.trim().parse().unwrap();
                        Some(format!("{key}{}", n / by))
                    });
                    short.push_str(cut.as_deref().unwrap_or(line));
                    short.push('\n');
                }
                std::fs::write(&target, short).unwrap();
            } else {
                std::fs::copy(&path, &target).unwrap();
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let to = dir.join("examples");
    copy(&root.join("examples"), &to);
    let quest = std::fs::read_to_string(to.join("quest.toml")).unwrap();
    let psi = quest
        .replace("name = \"quest-plus-t_l\"", "name = \"psi-t_l\"")
        .replace("method = \"quest_plus\"", "method = \"psi\"")
        // Psi fixes the lapse rate (QUEST+ puts it under the posterior).
        .replace(
            "lapse = { values = [0.0, 0.01, 0.02, 0.03, 0.04], prior = { kind = \"beta\", a = 1, b = 10 } }",
            "lapse = { values = [0.02] }",
        );
    assert_eq!(
        psi.matches("psi").count(),
        quest.matches("psi").count() + 2,
        "quest.toml names its method and lapse rates as before"
    );
    assert!(psi.contains("lapse = { values = [0.02] }"));
    std::fs::write(to.join("psi.toml"), psi).unwrap();
    // Catch trials every session gets, whichever group it is in.
    let groups = std::fs::read_to_string(to.join("groups.toml")).unwrap();
    std::fs::write(
        to.join("groups-catch.toml"),
        format!(
            "{}\n[[design.catch]]\nstimulus = \"walk/wavelet-standard/cr30\"\nmax = 4.5\n\n\
             [[design.catch]]\nstimulus = \"march/wavelet-perceptual/cr10\"\nmin = 1.5\n",
            groups.replace("name = \"mos-groups\"", "name = \"mos-groups-catch\"")
        ),
    )
    .unwrap();
    studies_in(&to, 16)
}

/// A BVH clip cut to its first 1/[`SHORTER`] of frames (at least 2).
fn cut_bvh(text: &str) -> String {
    let mut out = String::new();
    let mut keep = usize::MAX;
    let mut motion = false;
    for line in text.lines() {
        if let Some(n) = line.trim().strip_prefix("Frames:") {
            keep = (n.trim().parse::<usize>().unwrap() / SHORTER).max(2);
            out.push_str("Frames: ");
            out.push_str(&keep.to_string());
            out.push('\n');
            continue;
        }
        if motion {
            if keep == 0 {
                break;
            }
            keep -= 1;
        }
        if line.trim().starts_with("Frame Time:") {
            motion = true;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// An AMC clip cut to its first 1/[`SHORTER`] of frames (at least 2): a frame begins at a
/// line holding only its number.
fn cut_amc(text: &str) -> String {
    let is_frame = |l: &str| !l.trim().is_empty() && l.trim().bytes().all(|b| b.is_ascii_digit());
    let frames = text.lines().filter(|l| is_frame(l)).count();
    let keep = (frames / SHORTER).max(2);
    let mut seen = 0;
    let mut out = String::new();
    for line in text.lines() {
        if is_frame(line) {
            seen += 1;
            if seen > keep {
                break;
            }
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// The example studies (`examples/*.toml`), sorted by name.
fn examples() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    studies_in(&root.join("examples"), 14)
}

/// The study files (`*.toml`) in `dir`, sorted by name; at least `least` of them.
fn studies_in(dir: &Path, least: usize) -> Vec<PathBuf> {
    let mut studies: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    studies.sort();
    assert!(studies.len() >= least, "{studies:?}");
    studies
}

/// An example study's folder and the subject a browser takes part as (`ex` and the name
/// without dashes); [`Example::open`] serves it and opens its Prolific link.
struct Example {
    study: PathBuf,
    name: String,
    dir: PathBuf,
    out: PathBuf,
    subject: String,
}

impl Example {
    fn new(study: &Path, tag: &str) -> Example {
        let name = study.file_stem().unwrap().to_string_lossy().into_owned();
        let dir = temp_dir(&format!("{tag}-{name}"));
        Example {
            study: study.to_path_buf(),
            out: dir.join("results"),
            subject: format!("ex{}", name.replace('-', "")),
            name,
            dir,
        }
    }

    /// The study served on a port of its own, and a fresh browser profile at its link.
    fn open(&self, driver: &Driver) -> (Serve, Browser) {
        let port = free_port();
        let server = serve(&self.study, &self.out, port);
        // Half a device pixel per CSS pixel: SwiftShader draws a quarter of the pixels, which
        // was most of the CPU a browser took; the texts measured are CSS pixels.
        let b = driver.browser_at(&self.dir.join("profile"), 0.5);
        b.go(&format!(
            "http://127.0.0.1:{port}/?PROLIFIC_PID={}",
            self.subject
        ));
        (server, b)
    }
}

/// One example's whole session in a browser of its own (see
/// [`every_example_study_runs_in_the_browser_as_simulated`]); texts under [`MIN_TEXT_PX`] are
/// noted in `small`.
fn run_example(
    driver: &Driver,
    study: &Path,
    sizes: &[(u32, u32)],
    shots: Option<&std::ffi::OsStr>,
    small: &mut Vec<String>,
) {
    let started = Instant::now();
    let ex = Example::new(study, "example");
    let Example {
        name,
        dir,
        out,
        subject,
        ..
    } = &ex;
    let (simulated, script) = simulate(study, dir, subject, 3);
    let (_server, b) = ex.open(driver);
    reach_welcome(&b);
    assert_eq!(b.screen(), "welcome", "{name}");
    measure_texts(&b, &format!("{name} welcome"), sizes, small);
    b.window_viewport();
    fill_welcome(&b);
    b.click("#begin");
    if let Some(shots) = shots {
        b.wait(
            "document.body.dataset.screen === 'trial' && window.drawn && window.drawn.show !== 'grey' \
             && (window.drawn.clipTime > 1.5 || document.body.dataset.open === '1')",
            60,
        );
        b.screenshot(&Path::new(shots).join(format!("{name}-page.png")));
    }
    b.wait(
        "document.body.dataset.screen === 'trial' && document.body.dataset.open === '1'",
        90,
    );
    measure_texts(&b, &format!("{name} vote"), sizes, small);
    b.window_viewport();
    let mut given = BTreeSet::new();
    if shots.is_some() {
        answer_trials(&b, &script, Some(1), &mut given);
    } else {
        answer_trials(&b, &script, None, &mut given);
        assert_eq!(b.screen(), "end", "{name}");
    }
    let served = results::read_trials(&out.join(format!("{subject}_s1/trials.csv")))
        .unwrap()
        .records;
    assert_eq!(
        served.len(),
        given.len(),
        "{name}: one row per answer given"
    );
    if shots.is_none() {
        assert_eq!(
            served.len(),
            simulated.len(),
            "{name}: every trial answered"
        );
    }
    for (got, want) in served.iter().zip(&simulated) {
        let at = format!("{name} trial {}", want.trial.index);
        assert_eq!(got.trial, want.trial, "{at}");
        assert_eq!(got.encoding, want.encoding, "{at}");
        assert_eq!(got.response.replays, want.response.replays, "{at}");
        // A continuous scale without a step (the DSCQS example's BT.500 0-100) takes
        // marks to a hundredth of its range by keyboard: the simulated observer's
        // fraction is given to the nearest of them, and its score follows from it.
        let (a, b) = (got.response.answer, want.response.answer);
        match (a, b) {
            (Answer::Pair { a: ga, b: gb }, Answer::Pair { a: wa, b: wb }) if a != b => {
                assert!(
                    (ga - wa).abs() <= 0.5 && (gb - wb).abs() <= 0.5,
                    "{at}: {a:?} {b:?}"
                );
            }
            _ => {
                assert_eq!(a, b, "{at}");
                assert_eq!(got.outcome, want.outcome, "{at}");
            }
        }
    }
    drop(b);
    eprintln!(
        "{name}: {} trials in {:.1} s",
        served.len(),
        started.elapsed().as_secs_f64()
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// Every example study `study serve` is given runs in Chromium as a participant takes it,
/// the whole session to its end screen, and its rows equal `study simulate --subject` for
/// the same subject, answer for answer (replays too): each method's screen (ratings, pairs,
/// choices with and without "no preference", MUSHRA's sliders, crowd scenes, up-down,
/// QUEST+, Psi and live staircases, familiarization, hidden repeats, Latin squares, groups
/// with catch trials) comes from the one description the window draws. The sessions run on
/// [`short_examples`]: the examples with their clips and greys cut to a sixteenth and their
/// staircases shorter.
///
/// On the way the page is measured at 1280×720 and 1920×1080: every text a participant
/// must read on the welcome screen (title, instructions, field labels and answers, the
/// consent heading and text) and on the first vote screen (the question, the grade words
/// under rating buttons, DCR's impairment words, a scale's words, MUSHRA's slider words and
/// marks, the progress text) has a computed font and line of at least 14 px, and so does
/// what is typed into a field. Every example is measured before the test fails on a size,
/// listing each text too small.
#[test]
fn every_example_study_runs_in_the_browser_as_simulated() {
    let Some(_one) = browser_test() else {
        return;
    };
    let sizes = [(1280, 720), (1920, 1080)];
    let mut small = Vec::new();
    let driver = Driver::start();
    // `SCREENSHOTS=DIR` (scripts/screenshots): each example as it is, to its first trial,
    // for docs/serve.md beside the window's.
    let shots = std::env::var_os("SCREENSHOTS");
    let copies = temp_dir("short-examples");
    let studies = if shots.is_some() {
        examples()
    } else {
        short_examples(&copies)
    };
    for study in &studies {
        run_example(&driver, study, &sizes, shots.as_deref(), &mut small);
    }
    let _ = std::fs::remove_dir_all(&copies);
    assert!(
        small.is_empty(),
        "{} texts under {MIN_TEXT_PX} px:\n{}",
        small.len(),
        small.join("\n")
    );
}

/// Every text on the page a participant sees now, as `[text, where, font px, height px]`:
/// each visible text node's computed font size and the height of its smallest rendered line
/// box (`Range.getClientRects`), and each visible text or number input's font size and box
/// height (what is typed into it).
const VISIBLE_TEXTS: &str = "
    const out = [];
    const shown = (el) => el.checkVisibility({ checkOpacity: true, checkVisibilityCSS: true });
    const px = (el) => parseFloat(getComputedStyle(el).fontSize);
    const where = (el) => el.tagName.toLowerCase() + (el.id ? '#' + el.id : '')
      + (el.className && typeof el.className === 'string' ? '.' + el.className.trim().split(/\\s+/).join('.') : '');
    const walk = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
    for (let n = walk.nextNode(); n; n = walk.nextNode()) {
      const el = n.parentElement;
      const text = n.textContent.trim();
      if (!text || !el || el.closest('script, style') || !shown(el)) continue;
      const range = document.createRange();
      range.selectNodeContents(n);
      const lines = [...range.getClientRects()].filter((r) => r.width > 0 && r.height > 0);
      if (!lines.length) continue;
      out.push([text.slice(0, 60), where(el), px(el), Math.min(...lines.map((r) => r.height))]);
    }
    for (const el of document.querySelectorAll('input[type=text], input[type=number], select, textarea')) {
      if (!shown(el)) continue;
      out.push([`<${el.name || el.id}>`, where(el), px(el), el.getBoundingClientRect().height]);
    }
    return out;";

/// The smallest font a participant must read, CSS pixels.
const MIN_TEXT_PX: f64 = 14.0;

/// Measures every visible text now (see [`VISIBLE_TEXTS`]) at each viewport size; notes the
/// smallest font and line of the screen and every text under [`MIN_TEXT_PX`] in `small`.
fn measure_texts(b: &Browser, what: &str, sizes: &[(u32, u32)], small: &mut Vec<String>) {
    for &(w, h) in sizes {
        b.viewport(w, h);
        let texts: Vec<(String, String, f64, f64)> =
            serde_json::from_value(b.js(VISIBLE_TEXTS)).unwrap();
        assert!(!texts.is_empty(), "{what} at {w}×{h}: no text seen");
        let least = |k: fn(&(String, String, f64, f64)) -> f64| {
            texts
                .iter()
                .min_by(|a, b| k(a).total_cmp(&k(b)))
                .map(|t| (k(t), t.0.clone(), t.1.clone()))
                .unwrap()
        };
        let (font, ft, fw) = least(|t| t.2);
        let (line, lt, lw) = least(|t| t.3);
        eprintln!(
            "{what} at {w}×{h}: {} texts; smallest font {font} px ({ft:?} in {fw}), \
             lowest line {line:.1} px ({lt:?} in {lw})",
            texts.len()
        );
        for (text, at, px, height) in &texts {
            if *px < MIN_TEXT_PX || *height < MIN_TEXT_PX {
                small.push(format!(
                    "{what} at {w}×{h}: {text:?} in {at}: font {px} px, line {height:.1} px"
                ));
            }
        }
    }
}

/// A pane of an image: its top-left corner and size, pixels.
#[derive(Debug, Clone, Copy)]
struct Rect {
    x: f64,
    y: f64,
    w: f64,
    h: f64,
}

/// Where the figures of a pane are, measured from its pixels (the joints' orange), in pane
/// heights from the pane's centre (so that panes of different widths compare): each
/// figure's horizontal centre, top and bottom, and whether each of its feet has a dark
/// shadow on the ground below it.
#[derive(Debug)]
struct Seen {
    figures: Vec<Figure>,
}

#[derive(Debug)]
struct Figure {
    x: f64,
    top: f64,
    bottom: f64,
    /// Per foot (the lowest joints, split where they are apart): a shadow under it.
    shadows: Vec<bool>,
}

fn luminance(img: &Rgb, x: usize, y: usize) -> f64 {
    let [r, g, b] = img.pixel(x, y);
    0.299 * f64::from(r) + 0.587 * f64::from(g) + 0.114 * f64::from(b)
}

/// Intervals of `xs` (sorted) separated by gaps wider than `gap`.
fn runs(xs: &[usize], gap: usize) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for &x in xs {
        match out.last_mut() {
            Some((_, hi)) if x <= *hi + gap => *hi = x,
            _ => out.push((x, x)),
        }
    }
    out
}

fn look(img: &Rgb, pane: Rect) -> Seen {
    let (x0, y0) = (pane.x.round() as usize, pane.y.round() as usize);
    let (x1, y1) = (
        ((pane.x + pane.w).round() as usize).min(img.width),
        ((pane.y + pane.h).round() as usize).min(img.height),
    );
    let (cx, cy) = (pane.x + 0.5 * pane.w, pane.y + 0.5 * pane.h);
    // Figures stand apart across the pane; a gap of 3 % of its height parts them.
    let figures = img
        .orange_figures(x0..x1, y0..y1, (0.03 * pane.h) as usize)
        .into_iter()
        .map(|f| {
            let (top, bottom) = (f.top, f.bottom);
            let tall = (bottom - top).max(1);
            // The feet: the joints in the lowest 6 % of the figure, parted where apart.
            let low = bottom.saturating_sub(tall * 6 / 100);
            let feet: Vec<usize> = (f.left..=f.right)
                .filter(|&x| (low..=bottom).any(|y| img.is_orange(x, y)))
                .collect();
            let shadows = runs(&feet, (0.02 * pane.h) as usize)
                .into_iter()
                .map(|(a, b)| {
                    // The ground beside the figure at the feet's height, against the ground
                    // under the foot: a shadow is clearly darker.
                    let band = (bottom.saturating_sub(tall / 50))..(bottom + tall / 25).min(y1);
                    let reach = (0.04 * pane.h) as usize;
                    let beside: Vec<f64> = band
                        .clone()
                        .flat_map(|y| [x0 + 2, x1 - 3].into_iter().map(move |x| (x, y)))
                        .map(|(x, y)| luminance(img, x, y))
                        .collect();
                    let ground = beside.iter().sum::<f64>() / beside.len().max(1) as f64;
                    let under = band
                        .flat_map(|y| {
                            (a.saturating_sub(reach)..(b + reach).min(x1)).map(move |x| (x, y))
                        })
                        .filter(|&(x, y)| {
                            !img.is_orange(x, y) && luminance(img, x, y) < ground - 25.0
                        })
                        .count();
                    under >= 6
                })
                .collect();
            Figure {
                x: ((f.left + f.right) as f64 * 0.5 - cx) / pane.h,
                top: (top as f64 - cy) / pane.h,
                bottom: (bottom as f64 - cy) / pane.h,
                shadows,
            }
        })
        .collect();
    Seen { figures }
}

/// The browser's figures against the window's: as many, each within 5 % of the pane's
/// height in place and size, and a shadow under every foot in both.
fn same_figures(what: &str, page: &Seen, window: &Seen) {
    assert_eq!(
        page.figures.len(),
        window.figures.len(),
        "{what}: figures\npage {page:?}\nwindow {window:?}"
    );
    for (p, w) in page.figures.iter().zip(&window.figures) {
        for (name, a, b) in [
            ("centre", p.x, w.x),
            ("top", p.top, w.top),
            ("bottom", p.bottom, w.bottom),
        ] {
            assert!(
                (a - b).abs() <= 0.05,
                "{what}: {name} {a:.3} in the page, {b:.3} in the window\npage {page:?}\nwindow {window:?}"
            );
        }
        for (seen, s) in [("page", p), ("window", w)] {
            assert!(
                !s.shadows.is_empty() && s.shadows.iter().all(|&x| x),
                "{what}: a foot without a shadow in the {seen}: {s:?}"
            );
        }
    }
}

/// Stops the page's drawing during the first trial's stimuli (its animation frames no
/// longer come), takes the screenshot, and returns the clip time of the frame left on
/// screen and the panes drawn.
fn freeze(b: &Browser, show: &str, path: &Path) -> (f64, Vec<(usize, Rect)>) {
    b.wait(
        &format!(
            "document.body.dataset.screen === 'trial' && window.drawn && window.drawn.trial === 0 \
             && window.drawn.show === '{show}' && window.drawn.clipTime > 0.8"
        ),
        60,
    );
    b.js("window.requestAnimationFrame = () => 0; return null;");
    std::thread::sleep(Duration::from_millis(400));
    let v = b.js(
        "const r = document.getElementById('view').getBoundingClientRect(); \
         return [window.drawn, r.left, r.top];",
    );
    let drawn = &v[0];
    assert_eq!(
        drawn["show"].as_str(),
        Some(show),
        "the frame left on screen: {drawn}"
    );
    assert_eq!(
        drawn["trial"].as_u64(),
        Some(0),
        "the first trial is on screen: {drawn}"
    );
    b.screenshot(path);
    let (left, top) = (v[1].as_f64().unwrap(), v[2].as_f64().unwrap());
    let layout: Vec<Vec<f64>> = serde_json::from_value(drawn["panes"].clone()).unwrap();
    let panes = layout
        .iter()
        .map(|r| {
            (
                r[0] as usize,
                Rect {
                    x: left + r[1],
                    y: top + r[2],
                    w: r[3],
                    h: r[4],
                },
            )
        })
        .collect();
    (drawn["clipTime"].as_f64().unwrap(), panes)
}

/// The page draws what the window draws: the MOS example's trial and the crowd example's
/// scene, drawn by the page in headless Chromium and by the window's renderer offscreen
/// (`study clip render`, lavapipe) at the same clip time: as many figures, each as tall and
/// in the same place in its pane (within 5 % of its height), a shadow under each foot.
#[test]
fn the_page_draws_the_figures_the_window_draws() {
    let Some(_one) = browser_test() else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let driver = Driver::start();
    let dir = temp_dir("same-figures");
    for (example, show) in [("mos", "both"), ("crowd-run1", "one")] {
        let study = root.join(format!("examples/{example}.toml"));
        let out = dir.join(format!("results-{example}"));
        let port = free_port();
        let _server = serve(&study, &out, port);
        let b = driver.browser(&dir.join(format!("profile-{example}")));
        let subject = format!("look{}", example.len());
        b.go(&format!("http://127.0.0.1:{port}/?PROLIFIC_PID={subject}"));
        welcome(&b);
        let shot = dir.join(format!("{example}-page.png"));
        let (t, panes) = freeze(&b, show, &shot);
        // What each pane shows (the page is not told): the same subject's plan, simulated.
        let (rows, _) = simulate(&study, &dir, &subject, example.len() as u64);
        let first = &rows[0].trial;
        let positions = if show == "both" {
            [Position::Left, Position::Right]
        } else {
            [Position::First, Position::Second]
        };
        let stimuli: Vec<&str> = positions
            .iter()
            .map(|&p| {
                if p == first.reference_position {
                    first.reference.as_str()
                } else {
                    first.stimulus.as_str()
                }
            })
            .collect();
        let page = Rgb::read(&shot);
        let drawn = dir.join(format!("{example}-window.png"));
        for (k, rect) in panes {
            let size = rect.h.round().to_string();
            let time = t.to_string();
            let stimulus = stimuli[k];
            let mut args: Vec<std::ffi::OsString> = [
                "clip", "render", "--times", &time, "--pane", &size, "--force", "-o",
            ]
            .into_iter()
            .map(Into::into)
            .collect();
            args.push(drawn.clone().into());
            if example == "mos" {
                // Both panes framed by the reference, as a trial draws them: the reference
                // first, the pane's stimulus second.
                let manifest: Value = serde_json::from_str(
                    &std::fs::read_to_string(root.join("examples/stimuli.json")).unwrap(),
                )
                .unwrap();
                let file = |id: &str| {
                    let entry = manifest["stimuli"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .find(|s| s["id"] == id)
                        .unwrap_or_else(|| panic!("{id} in the manifest"));
                    root.join("examples").join(entry["file"].as_str().unwrap())
                };
                let clip = stimulus.split('/').next().unwrap();
                args.push(file(&format!("{clip}/reference")).into());
                args.push(file(stimulus).into());
            } else {
                args.extend([
                    "--study".into(),
                    study.clone().into(),
                    "--scenes".into(),
                    stimulus.into(),
                ]);
            }
            let run = Command::new(env!("CARGO_BIN_EXE_study"))
                .args(&args)
                .output()
                .unwrap();
            assert!(
                run.status.success(),
                "study clip render: {}",
                String::from_utf8_lossy(&run.stderr)
            );
            let window = Rgb::read(&drawn);
            // The pane's stimulus: the second column for two clips, the only one for a scene.
            let col = if example == "mos" { 1.0 } else { 0.0 };
            let w_pane = Rect {
                x: col * window.width as f64 / if example == "mos" { 2.0 } else { 1.0 },
                y: 0.0,
                w: if example == "mos" {
                    window.width as f64 / 2.0
                } else {
                    window.width as f64
                },
                h: window.height as f64,
            };
            let what = format!("{example} pane {k} ({stimulus}) at {t:.3} s");
            let (p, w) = (look(&page, rect), look(&window, w_pane));
            eprintln!("{what}:\n  page   {p:?}\n  window {w:?}");
            if example == "crowd-run1" {
                assert_eq!(
                    p.figures.len(),
                    3,
                    "{what}: the scene's three characters {p:?}"
                );
            }
            same_figures(&what, &p, &w);
        }
        drop(b);
    }
    if std::env::var_os("KEEP_SCREENSHOTS").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
}
