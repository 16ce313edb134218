//! Load test of `study serve` on loopback: 200 simulated participants at once, each
//! completing a 20-trial MOS study (10 conditions and 10 hidden repeats over a generated
//! 1-s walk, 45 KB of joint positions per clip) against one in-process server, every answer
//! fsynced before its acknowledgement. Reports the answers lost or logged twice (read back
//! from every session's `trials.csv`), the answer acknowledgement latency and the next-trial
//! stimulus latency (the trial and both of its clips), p50 / p99 / max.
//!
//! The participants are tasks on one client thread (a single-threaded tokio runtime of
//! their own, apart from the server's), each with its own kept-alive connection, asking and
//! waiting as the blocking `web::client::Client` does: the same requests at the same moments
//! (each trial's presentation is waited out), but 200 OS threads competing with the server
//! for the same two cores no longer inflate its tail. A busy client thread can only delay
//! reading a reply, which counts against the server: the figures are not flattered.
//!
//! Bounded: 200 participants × 20 trials, and the run gives up after 300 s. Loopback only.
//!
//! `cargo bench -p web --bench load` (participants with `LOAD_PARTICIPANTS`, the clip length
//! in seconds with `LOAD_CLIP_S`).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::too_many_lines,
    missing_docs
)]

use std::net::SocketAddr;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tokio::io::{AsyncBufReadExt as _, AsyncReadExt as _, AsyncWriteExt as _, BufReader};
use tokio::net::TcpStream;
use tokio::sync::Barrier;
use web::{Limits, ServeOptions, client};

const TRIALS: usize = 20;
const DEADLINE: Duration = Duration::from_secs(300);

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn setup(dir: &Path, clip_s: f64) -> ServeOptions {
    let walk = motion::synth::WalkParams {
        duration_s: clip_s,
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    };
    let targets: Vec<f64> = (0..10).map(|k| 4.0 + 2.0 * f64::from(k)).collect();
    lab::generated::walk_stimuli(dir, &walk, &["spiht"], &targets).unwrap();
    std::fs::write(
        dir.join("study.toml"),
        "format_version = 1\nname = \"load\"\nprotocol = \"mos\"\nstimuli = \"stimuli/stimuli.json\"\n\
         seed = 1\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\n\
         [presentation]\ngap_ms = 0\n[session]\nhidden_repeats = 10\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("page")).unwrap();
    std::fs::write(dir.join("page/index.html"), "<!doctype html>").unwrap();
    // What the real page says it draws (the server checks the study against it).
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("page/src/capabilities.json"),
        dir.join("page/capabilities.json"),
    )
    .unwrap();
    ServeOptions {
        study: dir.join("study.toml"),
        results: lab::results_dir::Destination::Folder(dir.join("results")),
        connections: 16,
        bind: "127.0.0.1:0".parse().unwrap(),
        page: dir.join("page"),
        dashboard_token: None,
        limits: Limits::default(),
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = ((p / 100.0) * (sorted.len() - 1) as f64).round() as usize;
    sorted[k.min(sorted.len() - 1)]
}

#[derive(Default)]
struct Timings {
    ack_ms: Vec<f64>,
    next_ms: Vec<f64>,
    acked: usize,
    errors: Vec<String>,
}

/// A participant's HTTP/1.1 connection, kept alive, as `web::client::Client` but async.
struct Participant {
    addr: SocketAddr,
    conn: Option<BufReader<TcpStream>>,
    subject: String,
    token: String,
}

struct Reply {
    status: u16,
    body: Vec<u8>,
}

impl Reply {
    fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
}

impl Participant {
    /// Sends one request (reconnecting once if the kept-alive connection was closed).
    async fn request(
        &mut self,
        method: &str,
        path: &str,
        body: Option<&Value>,
    ) -> std::io::Result<Reply> {
        if let Ok(r) = self.try_request(method, path, body).await {
            return Ok(r);
        }
        self.conn = None;
        self.try_request(method, path, body).await
    }

    async fn try_request(
        &mut self,
        method: &str,
        path: &str,
        body: Option<&Value>,
    ) -> std::io::Result<Reply> {
        if self.conn.is_none() {
            let s = TcpStream::connect(self.addr).await?;
            s.set_nodelay(true)?;
            self.conn = Some(BufReader::new(s));
        }
        let conn = self.conn.as_mut().unwrap();
        let request = client::request_text(method, path, self.addr, &self.token, body);
        conn.get_mut().write_all(request.as_bytes()).await?;
        let mut line = String::new();
        if conn.read_line(&mut line).await? == 0 {
            return Err(std::io::Error::other("connection closed"));
        }
        let mut head = client::ReplyHead::from_status_line(&line)?;
        loop {
            line.clear();
            conn.read_line(&mut line).await?;
            if !head.header(&line) {
                break;
            }
        }
        let (status, len, close) = (head.status, head.length, head.close);
        let mut body = vec![0u8; len];
        conn.read_exact(&mut body).await?;
        if close {
            self.conn = None;
        }
        Ok(Reply { status, body })
    }

    fn session_path(&self, path: &str) -> String {
        format!("/api/s/{}/{path}", self.subject)
    }
}

/// One participant: join, begin, then each trial: ask for it and its clips (timed), wait
/// out the presentation, answer (timed).
async fn participant(
    addr: SocketAddr,
    k: usize,
    start: Arc<Barrier>,
    out: Arc<Mutex<Timings>>,
    t0: Instant,
) {
    let mut c = Participant {
        addr,
        conn: None,
        subject: String::new(),
        token: String::new(),
    };
    let mut local = Timings::default();
    start.wait().await;
    let join = json!({
        "params": { "PROLIFIC_PID": format!("p{k:04}") },
        "environment": web::client::environment(),
    });
    let r = c.request("POST", "/api/join", Some(&join)).await;
    match &r {
        Ok(r) if r.status == 200 => {
            let v = r.json();
            c.subject = v["subject"].as_str().unwrap_or_default().to_string();
            c.token = v["token"].as_str().unwrap_or_default().to_string();
        }
        _ => {
            out.lock()
                .unwrap()
                .errors
                .push(format!("join {k}: {:?}", r.map(|r| r.json())));
            return;
        }
    }
    let begin =
        json!({ "fields": {}, "consent": false, "environment": web::client::environment() });
    let r = c
        .request("POST", &c.session_path("begin"), Some(&begin))
        .await
        .unwrap();
    assert_eq!(r.status, 200);
    while t0.elapsed() < DEADLINE {
        let asked = Instant::now();
        let t = c
            .request("GET", &c.session_path("trial"), None)
            .await
            .unwrap()
            .json();
        if t["done"] == json!(true) {
            break;
        }
        let index = t["index"].as_u64().unwrap();
        for slot in 0..2 {
            let r = c
                .request(
                    "GET",
                    &c.session_path(&format!("clip/{index}/{slot}")),
                    None,
                )
                .await
                .unwrap();
            assert_eq!(r.status, 200);
        }
        local.next_ms.push(asked.elapsed().as_secs_f64() * 1e3);
        let need = t["presentation_ms"].as_f64().unwrap();
        let played = Instant::now();
        tokio::time::sleep(Duration::from_secs_f64(need / 1e3 + 0.02)).await;
        let body = json!({
            "index": index, "answer": { "Rating": 1.0 + (k + index as usize) as f64 % 5.0 },
            "replays": 0, "response_time_ms": 100,
            "played_ms": played.elapsed().as_secs_f64() * 1e3,
            "intervals": vec![16.7; (need / 16.7) as usize],
            "phases": vec!["both"; (need / 16.7) as usize],
            "hidden": false, "fullscreen": false,
        });
        let sent = Instant::now();
        let r = c
            .request("POST", &c.session_path("answer"), Some(&body))
            .await
            .unwrap();
        local.ack_ms.push(sent.elapsed().as_secs_f64() * 1e3);
        if r.status == 200 {
            local.acked += 1;
        } else {
            local.errors.push(format!(
                "p{k:04} trial {index}: {} {:?}",
                r.status,
                r.json()
            ));
        }
    }
    let mut o = out.lock().unwrap();
    o.ack_ms.extend(local.ack_ms);
    o.next_ms.extend(local.next_ms);
    o.acked += local.acked;
    o.errors.extend(local.errors);
}

fn main() {
    let n: usize = env_or("LOAD_PARTICIPANTS", 200);
    let clip_s: f64 = env_or("LOAD_CLIP_S", 1.0);
    let dir = std::env::temp_dir().join(format!("web-load-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let options = setup(&dir, clip_s);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    let addr = server.addr;
    let out = Arc::new(Mutex::new(Timings::default()));
    let start = Arc::new(Barrier::new(n));
    let t0 = Instant::now();
    // Every participant on one client thread of its own (the server keeps its runtime).
    let clients = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    clients.block_on(async {
        let mut tasks = tokio::task::JoinSet::new();
        for k in 0..n {
            let (out, start) = (Arc::clone(&out), Arc::clone(&start));
            tasks.spawn(participant(addr, k, start, out, t0));
        }
        while let Some(done) = tasks.join_next().await {
            done.unwrap();
        }
    });
    let wall = t0.elapsed();
    rt.block_on(server.stop()).unwrap();

    // Every acknowledged answer must be in its session's log exactly once.
    let (mut rows, mut lost, mut duplicated) = (0usize, 0usize, 0usize);
    for k in 0..n {
        let path = dir.join(format!("results/p{k:04}_s1/trials.csv"));
        let records = results::read_trials(&path)
            .map(|t| t.records)
            .unwrap_or_default();
        let mut seen = std::collections::BTreeSet::new();
        for r in &records {
            if !seen.insert(r.trial.index) {
                duplicated += 1;
            }
        }
        rows += records.len();
        lost += TRIALS.saturating_sub(seen.len());
    }
    let o = out.lock().unwrap();
    let mut ack = o.ack_ms.clone();
    let mut next = o.next_ms.clone();
    ack.sort_by(f64::total_cmp);
    next.sort_by(f64::total_cmp);
    println!("load: {n} participants x {TRIALS}-trial MOS, {clip_s} s clips, one server, loopback");
    println!(
        "  answers acknowledged {} of {}, rows logged {rows}, lost {lost}, duplicated {duplicated}, errors {}",
        o.acked,
        n * TRIALS,
        o.errors.len()
    );
    for e in o.errors.iter().take(5) {
        println!("  error: {e}");
    }
    println!(
        "  answer ack (fsync included): p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
        percentile(&ack, 50.0),
        percentile(&ack, 99.0),
        ack.last().copied().unwrap_or(f64::NAN)
    );
    println!(
        "  next-trial stimulus (trial + 2 clips): p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
        percentile(&next, 50.0),
        percentile(&next, 99.0),
        next.last().copied().unwrap_or(f64::NAN)
    );
    println!("  wall {:.1} s", wall.as_secs_f64());
    let _ = std::fs::remove_dir_all(&dir);
    let ok = lost == 0
        && duplicated == 0
        && o.acked == n * TRIALS
        && percentile(&ack, 99.0) <= 50.0
        && percentile(&next, 99.0) <= 100.0;
    println!(
        "  targets (0 lost or duplicated, p99 ack <= 50 ms, p99 next <= 100 ms): {}",
        if ok { "met" } else { "NOT met" }
    );
}
