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
//! in seconds with `LOAD_CLIP_S`). `LOAD_SERVERS=3`: three `serve` processes (this binary,
//! re-run as each) on one throw-away PostgreSQL server behind nginx (`web::nginx`, round robin;
//! `LOAD_BALANCE=participant` for consistent hashing by participant), the answers read back
//! from the database; `LOAD_KILL_AT_S=T` SIGKILLs one of them T seconds into the run.
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
    /// Sends one request, asked again (as the page does) on a new connection while the
    /// server cannot be reached or answers 429, 502, 503 or 504, for up to 120 s (2,000
    /// joins at once take their turns on the run's row in the database).
    async fn request(
        &mut self,
        method: &str,
        path: &str,
        body: Option<&Value>,
    ) -> std::io::Result<Reply> {
        let start = Instant::now();
        loop {
            let last = self.try_request(method, path, body).await;
            match last {
                Ok(r) if !matches!(r.status, 429 | 502..=504) => return Ok(r),
                last if start.elapsed() > Duration::from_secs(120) => return last,
                _ => {}
            }
            self.conn = None;
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
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
        let r = c
            .request("GET", &c.session_path("trial"), None)
            .await
            .unwrap();
        let t = r.json();
        if t["done"] == json!(true) {
            break;
        }
        let Some(index) = t["index"].as_u64().filter(|_| r.status == 200) else {
            local
                .errors
                .push(format!("p{k:04} trial: {} {t}", r.status));
            break;
        };
        for slot in 0..2 {
            let r = c
                .request(
                    "GET",
                    &c.session_path(&format!("clip/{index}/{slot}")),
                    None,
                )
                .await
                .unwrap();
            if r.status != 200 {
                local.errors.push(format!(
                    "p{k:04} clip {index}/{slot}: {} {:?}",
                    r.status,
                    r.json()
                ));
            }
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

/// The environment variable that makes this binary one `serve` process of a cluster run:
/// `STUDY_FILE DATABASE_URL` (it prints its address and serves until killed).
const CHILD: &str = "LOAD_SERVE_CHILD";
const NGINX: &str = "/usr/sbin/nginx";

/// One `serve` process of a cluster run (see [`CHILD`]).
fn child(spec: &str) {
    let (study, url) = spec.split_once(' ').unwrap();
    let options = ServeOptions {
        study: study.into(),
        results: lab::results_dir::Destination::Database {
            db: Box::new(results::pg::Database::from_argument(url).unwrap()),
            run: None,
        },
        connections: 16,
        bind: "127.0.0.1:0".parse().unwrap(),
        page: Path::new(study).parent().unwrap().join("page"),
        dashboard_token: None,
        limits: Limits::default(),
    };
    web::serve(options, |_, addr| println!("{addr}")).unwrap();
}

/// A child process killed when dropped.
struct Proc(std::process::Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// nginx, stopped with SIGQUIT when dropped (its workers outlive a SIGKILLed master).
struct Nginx(std::process::Child);

impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = std::process::Command::new("kill")
            .args(["-QUIT", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
    }
}

/// What a cluster run started: PostgreSQL, the `serve` processes and nginx, whose address
/// the participants use.
struct Cluster {
    pg: results::pg::scratch::ScratchServer,
    db: results::pg::Database,
    servers: Vec<Proc>,
    _nginx: Nginx,
    front: SocketAddr,
}

fn cluster(dir: &Path, options: &ServeOptions, servers: usize) -> Cluster {
    let pg = results::pg::scratch::ScratchServer::start(dir, &["max_connections=400"]).unwrap();
    let db = pg.create_database("load").unwrap();
    let url = pg.url("load");
    let mut procs = Vec::new();
    let mut addrs = Vec::new();
    for _ in 0..servers {
        let mut c = std::process::Command::new(std::env::current_exe().unwrap())
            .env(CHILD, format!("{} {url}", options.study.display()))
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(c.stdout.take().unwrap()),
            &mut line,
        )
        .unwrap();
        addrs.push(line.trim().parse::<SocketAddr>().unwrap());
        procs.push(Proc(c));
    }
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let front: SocketAddr = ([127, 0, 0, 1], port).into();
    let balance = if std::env::var("LOAD_BALANCE").as_deref() == Ok("participant") {
        web::nginx::Balance::Participant
    } else {
        web::nginx::Balance::RoundRobin
    };
    let conf = dir.join("nginx.conf");
    std::fs::write(&conf, web::nginx::config(&addrs, front, balance, dir)).unwrap();
    let nginx = std::process::Command::new(NGINX)
        .arg("-c")
        .arg(&conf)
        .arg("-p")
        .arg(dir)
        .arg("-e")
        .arg(dir.join("nginx-error.log"))
        .spawn()
        .unwrap();
    while std::net::TcpStream::connect(front).is_err() {
        std::thread::sleep(Duration::from_millis(20));
    }
    Cluster {
        pg,
        db,
        servers: procs,
        _nginx: Nginx(nginx),
        front,
    }
}

/// Trial indices logged per participant (`p0000`, ...), from a folder or a database.
fn logged(dir: &Path, cluster: Option<&Cluster>, n: usize) -> Vec<Vec<u32>> {
    let Some(c) = cluster else {
        return (0..n)
            .map(|k| {
                let path = dir.join(format!("results/p{k:04}_s1/trials.csv"));
                results::read_trials(&path)
                    .map(|t| t.records.iter().map(|r| r.trial.index).collect())
                    .unwrap_or_default()
            })
            .collect();
    };
    let mut client = c.db.connect().unwrap();
    let mut out = vec![Vec::new(); n];
    for r in client
        .query(
            "SELECT s.subject, t.trial_index FROM study_trials t JOIN study_sessions s \
             ON s.id = t.session_id ORDER BY s.subject, t.row_number",
            &[],
        )
        .unwrap()
    {
        let subject: String = r.get(0);
        let index: i32 = r.get(1);
        if let Some(k) = subject
            .strip_prefix('p')
            .and_then(|k| k.parse::<usize>().ok())
            && k < n
        {
            out[k].push(index as u32);
        }
    }
    out
}

fn main() {
    if let Ok(spec) = std::env::var(CHILD) {
        child(&spec);
        return;
    }
    let n: usize = env_or("LOAD_PARTICIPANTS", 200);
    let clip_s: f64 = env_or("LOAD_CLIP_S", 1.0);
    let servers: usize = env_or("LOAD_SERVERS", 0);
    let kill_at: f64 = env_or("LOAD_KILL_AT_S", f64::INFINITY);
    let dir = std::env::temp_dir().join(format!("web-load-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let options = setup(&dir, clip_s);
    let rt = tokio::runtime::Runtime::new().unwrap();
    // LOAD_SERVERS=k: k `serve` processes on one PostgreSQL behind nginx; else one
    // in-process server on a results folder.
    let mut cluster = (servers > 0).then(|| cluster(&dir, &options, servers));
    let server = if cluster.is_none() {
        Some(rt.block_on(web::start(options)).unwrap())
    } else {
        None
    };
    let addr = cluster
        .as_ref()
        .map_or_else(|| server.as_ref().unwrap().addr, |c| c.front);
    if let Some(c) = cluster.as_mut()
        && kill_at.is_finite()
    {
        // One server SIGKILLed mid-run.
        let mut victim = c.servers.remove(0);
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_secs_f64(kill_at));
            victim.0.kill().unwrap();
            victim.0.wait().unwrap();
            println!("  (one serve process killed at {kill_at} s)");
        });
    }
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
    if let Some(server) = server {
        rt.block_on(server.stop()).unwrap();
    }

    // Every acknowledged answer must be in its session's log exactly once.
    let (mut rows, mut lost, mut duplicated) = (0usize, 0usize, 0usize);
    for indices in logged(&dir, cluster.as_ref(), n) {
        let mut seen = std::collections::BTreeSet::new();
        for i in &indices {
            if !seen.insert(*i) {
                duplicated += 1;
            }
        }
        rows += indices.len();
        lost += TRIALS.saturating_sub(seen.len());
    }
    let place = match &cluster {
        Some(c) => format!(
            "{servers} serve processes on one PostgreSQL ({}) behind nginx",
            c.pg.port()
        ),
        None => "one server".to_owned(),
    };
    drop(cluster);
    let o = out.lock().unwrap();
    let mut ack = o.ack_ms.clone();
    let mut next = o.next_ms.clone();
    ack.sort_by(f64::total_cmp);
    next.sort_by(f64::total_cmp);
    println!("load: {n} participants x {TRIALS}-trial MOS, {clip_s} s clips, {place}, loopback");
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
