//! Load test of `study serve` on loopback: 200 simulated participants at once, each
//! completing a 20-trial MOS study (10 conditions and 10 hidden repeats over a generated
//! 1-s walk, 45 KB of joint positions per clip) against one in-process server, every answer
//! fsynced before its acknowledgement. Reports the answers lost or logged twice (read back
//! from every session's `trials.csv`), the answer acknowledgement latency and the next-trial
//! stimulus latency (the trial and both of its clips), p50 / p99 / max.
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

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Barrier, Mutex};
use std::time::{Duration, Instant};

use serde_json::json;
use web::client::Client;
use web::{Limits, ServeOptions};

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
    ServeOptions {
        study: dir.join("study.toml"),
        output: dir.join("results"),
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

/// One participant: join, begin, then each trial: ask for it and its clips (timed), wait
/// out the presentation, answer (timed).
fn participant(
    addr: std::net::SocketAddr,
    k: usize,
    start: &Barrier,
    out: &Mutex<Timings>,
    t0: Instant,
) {
    let mut c = Client::new(addr);
    let mut local = Timings::default();
    start.wait();
    let r = c.join(&BTreeMap::from([(
        "PROLIFIC_PID".to_string(),
        format!("p{k:04}"),
    )]));
    if !r.as_ref().is_ok_and(|r| r.status == 200) {
        out.lock()
            .unwrap()
            .errors
            .push(format!("join {k}: {:?}", r.map(|r| r.json())));
        return;
    }
    let begin =
        json!({ "fields": {}, "consent": false, "environment": web::client::environment() });
    let r = c
        .request("POST", &c.session_path("begin"), Some(&begin))
        .unwrap();
    assert_eq!(r.status, 200);
    while t0.elapsed() < DEADLINE {
        let asked = Instant::now();
        let t = c
            .request("GET", &c.session_path("trial"), None)
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
                .unwrap();
            assert_eq!(r.status, 200);
        }
        local.next_ms.push(asked.elapsed().as_secs_f64() * 1e3);
        let need = t["presentation_ms"].as_f64().unwrap();
        let played = Instant::now();
        std::thread::sleep(Duration::from_secs_f64(need / 1e3 + 0.02));
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
    let threads: Vec<_> = (0..n)
        .map(|k| {
            let (out, start) = (Arc::clone(&out), Arc::clone(&start));
            std::thread::Builder::new()
                .stack_size(256 << 10)
                .spawn(move || participant(addr, k, &start, &out, t0))
                .unwrap()
        })
        .collect();
    for t in threads {
        t.join().unwrap();
    }
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
