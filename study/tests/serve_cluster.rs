//! One online study on three `study serve --store` processes behind nginx (Debian's, started
//! here on loopback) sharing one PostgreSQL server (a throw-away one): participants whose
//! requests nginx spreads round robin (no stickiness, so sessions move between servers all
//! the time) take part while one server is killed with SIGKILL; every acknowledged answer is
//! in the database exactly once, every participant finishes through the other two, and
//! `study report --store` equals the report of the same participants' sessions served into a
//! results folder. Under CI a missing nginx or PostgreSQL fails this test; elsewhere it says
//! so and passes.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::too_many_lines,
    missing_docs
)]

use std::collections::BTreeMap;
use std::io::{BufRead as _, BufReader};
use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use results::pg::scratch::ScratchServer;
use serde_json::json;
use web::client::Client;

const NGINX: &str = "/usr/sbin/nginx";
const PARTICIPANTS: usize = 12;

/// A child process killed when dropped.
struct Proc(Child);

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

fn setup(dir: &Path) -> PathBuf {
    let walk = motion::synth::WalkParams {
        duration_s: 0.3,
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    };
    lab::generated::walk_stimuli(dir, &walk, &["spiht"], &[6.0, 10.0, 16.0]).unwrap();
    std::fs::create_dir_all(dir.join("page")).unwrap();
    std::fs::write(
        dir.join("page/index.html"),
        "<!doctype html><title>t</title>",
    )
    .unwrap();
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../web/page/src/capabilities.json"),
        dir.join("page/capabilities.json"),
    )
    .unwrap();
    let study = dir.join("study.toml");
    std::fs::write(
        &study,
        "format_version = 1\nname = \"cluster\"\nprotocol = \"mos\"\nstimuli = \"stimuli/stimuli.json\"\n\
         seed = 9\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [6, 10, 16]\n\
         [presentation]\ngap_ms = 0\n[session]\nhidden_repeats = 3\n",
    )
    .unwrap();
    study
}

/// Starts `study serve` with `args` on a free port and returns it with its address.
fn serve(study: &Path, page: &Path, url: &str, args: &[&str]) -> (Proc, SocketAddr) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_study"))
        .arg("serve")
        .arg(study)
        .arg("--page")
        .arg(page)
        .args(["--bind", "127.0.0.1:0"])
        .args(args)
        .env("STUDY_DATABASE_URL", url)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    out.read_line(&mut line).unwrap();
    // The rest (what it says when stopped) is read to the end: a closed pipe would fail it.
    std::thread::spawn(move || std::io::copy(&mut out, &mut std::io::sink()));
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|s| s.split('/').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    (Proc(child), addr.parse().unwrap())
}

/// nginx on a free loopback port in front of `upstreams`, round robin, with the documented
/// configuration (`web::nginx`).
fn nginx(dir: &Path, upstreams: &[SocketAddr]) -> (Nginx, SocketAddr) {
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let addr: SocketAddr = ([127, 0, 0, 1], port).into();
    let path = dir.join("nginx.conf");
    std::fs::write(
        &path,
        web::nginx::config(upstreams, addr, web::nginx::Balance::RoundRobin, dir),
    )
    .unwrap();
    let child = Command::new(NGINX)
        .arg("-c")
        .arg(&path)
        .arg("-p")
        .arg(dir)
        .arg("-e")
        .arg(dir.join("nginx-error.log"))
        .spawn()
        .unwrap();
    let start = Instant::now();
    while std::net::TcpStream::connect(addr).is_err() {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "nginx did not start"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    (Nginx(child), addr)
}

/// The rating participant `k` gives trial `index` (the same wherever it is served).
fn rating(k: usize, index: u64) -> f64 {
    1.0 + ((k as u64 * 7 + index * 3) % 9) as f64 * 0.5
}

/// A request (`path` under the participant's API unless it starts with `/`), asked again
/// (as the page does) while the server answers 502, 503 or 504 or cannot be reached.
fn call(
    c: &mut Client,
    method: &str,
    path: &str,
    body: Option<&serde_json::Value>,
) -> web::client::Reply {
    let path = if path.starts_with('/') {
        path.to_owned()
    } else {
        c.session_path(path)
    };
    let path = path.as_str();
    let start = Instant::now();
    loop {
        let last = match c.request(method, path, body) {
            Ok(r) if !matches!(r.status, 502..=504) => return r,
            Ok(r) => format!("{} {}", r.status, String::from_utf8_lossy(&r.body)),
            Err(e) => e.to_string(),
        };
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{method} {path}: no reply ({last})"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Participant `k` takes part through `addr`; returns their subject and the answers the
/// server acknowledged, in order.
fn take_part(addr: SocketAddr, k: usize) -> (String, Vec<(u64, f64)>) {
    let mut c = Client::new(addr);
    let pid = format!("p{k:02}");
    let params = BTreeMap::from([("PROLIFIC_PID".to_string(), pid.clone())]);
    let body = json!({ "params": params, "environment": web::client::environment() });
    let r = call(&mut c, "POST", "/api/join", Some(&body));
    assert_eq!(r.status, 200, "{:?}", r.json());
    let v = r.json();
    c.subject = v["subject"].as_str().unwrap().to_string();
    c.token = v["token"].as_str().unwrap().to_string();
    let begin =
        json!({ "fields": {}, "consent": false, "environment": web::client::environment() });
    let r = call(&mut c, "POST", "begin", Some(&begin));
    assert_eq!(r.status, 200, "{:?}", r.json());
    let mut acked = Vec::new();
    loop {
        let t = call(&mut c, "GET", "trial", None).json();
        if t["done"] == json!(true) {
            assert_eq!(t["status"], json!("complete"), "{t}");
            return (pid, acked);
        }
        let index = t["index"].as_u64().unwrap();
        for slot in 0..t["clips"].as_u64().unwrap() {
            let r = call(&mut c, "GET", &format!("clip/{index}/{slot}"), None);
            assert_eq!(r.status, 200);
        }
        let need = t["presentation_ms"].as_f64().unwrap();
        std::thread::sleep(Duration::from_millis(need as u64 + 30));
        let body = json!({
            "index": index, "answer": { "Rating": rating(k, index) }, "replays": 0,
            "response_time_ms": 500, "played_ms": need + 10.0,
            "intervals": [], "phases": [], "hidden": false, "fullscreen": false,
        });
        let r = call(&mut c, "POST", "answer", Some(&body));
        assert_eq!(r.status, 200, "trial {index}: {:?}", r.json());
        if r.json()["duplicate"] == json!(false) {
            acked.push((index, rating(k, index)));
        }
    }
}

/// A participant `pid` joined and begun through `front`, with a client to each of
/// `servers` holding their token.
fn joined(front: SocketAddr, servers: &[SocketAddr], pid: &str) -> Vec<Client> {
    let mut c = Client::new(front);
    let params = BTreeMap::from([("PROLIFIC_PID".to_string(), pid.to_string())]);
    assert_eq!(c.join(&params).unwrap().status, 200);
    let (subject, token) = (c.subject.clone(), c.token.clone());
    let again = Client::new(front).join(&params).unwrap();
    assert_eq!(
        again.status, 409,
        "one session per participant, on every server"
    );
    let r = call(
        &mut c,
        "POST",
        "begin",
        Some(&json!({ "fields": {}, "consent": false, "environment": web::client::environment() })),
    );
    assert_eq!(r.status, 200);
    servers
        .iter()
        .map(|a| {
            let mut s = Client::new(*a);
            s.subject.clone_from(&subject);
            s.token.clone_from(&token);
            s
        })
        .collect()
}

/// Answers that no page could give are refused whichever server takes them: to a trial
/// never sent (409), and to one sent by another server less than its playing time ago (422,
/// by the database's clock).
fn cheaters_are_refused(front: SocketAddr, servers: &[SocketAddr]) {
    let answer = |index: u64| {
        json!({
            "index": index, "answer": { "Rating": 3.0 }, "replays": 0, "response_time_ms": 500,
            "played_ms": 60_000.0, "intervals": [], "phases": [], "hidden": false, "fullscreen": false,
        })
    };
    let mut a = joined(front, servers, "cheat-a");
    let r = call(&mut a[1], "POST", "answer", Some(&answer(0)));
    assert_eq!(r.status, 409, "never sent: {:?}", r.json());
    let mut b = joined(front, servers, "cheat-b");
    let t = call(&mut b[0], "GET", "trial", None).json();
    let index = t["index"].as_u64().unwrap();
    let r = call(&mut b[1], "POST", "answer", Some(&answer(index)));
    assert_eq!(
        r.status,
        422,
        "sent a moment ago by another server: {:?}",
        r.json()
    );
    assert!(
        r.json()["error"]
            .as_str()
            .unwrap()
            .contains("before the stimuli had played"),
        "{:?}",
        r.json()
    );
    std::thread::sleep(Duration::from_millis(
        t["presentation_ms"].as_f64().unwrap() as u64 + 60,
    ));
    let r = call(&mut b[0], "POST", "answer", Some(&answer(index)));
    assert_eq!(r.status, 200, "once it has played: {:?}", r.json());
}

fn study_cmd(url: &str, args: &[&std::ffi::OsStr]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .env("STUDY_DATABASE_URL", url)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{text}");
    text
}

#[test]
fn three_servers_behind_nginx_lose_nothing_when_one_is_killed() {
    let nginx_missing = !Path::new(NGINX).exists();
    let pg = match ScratchServer::start(&std::env::temp_dir(), &["fsync=off"]) {
        Ok(s) if !nginx_missing => s,
        Ok(_) if std::env::var_os("CI").is_none() => {
            eprintln!("skipped: no {NGINX} (Debian package nginx-light)");
            return;
        }
        Ok(_) => panic!("{NGINX} is missing (Debian package nginx-light)"),
        Err(e) if std::env::var_os("CI").is_none() && results::pg::scratch::bin_dir().is_err() => {
            eprintln!("skipped: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("serve-cluster-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let study = setup(&dir);
    let page = dir.join("page");
    let lab_db = pg.create_database("lab").unwrap();
    let url = pg.url("lab");

    let mut servers: Vec<(Proc, SocketAddr)> = (0..3)
        .map(|_| {
            serve(
                &study,
                &page,
                &url,
                &["--store", "env", "--connections", "4"],
            )
        })
        .collect();
    let upstreams: Vec<SocketAddr> = servers.iter().map(|s| s.1).collect();
    let (_nginx, front) = nginx(&dir, &upstreams);

    let mut db = lab_db.connect().unwrap();
    let answers = |db: &mut postgres::Client| -> i64 {
        db.query_one(
            "SELECT count(*) FROM study_trials WHERE subject LIKE 'p%'",
            &[],
        )
        .unwrap()
        .get(0)
    };
    let done = AtomicBool::new(false);
    let runs: Vec<(String, Vec<(u64, f64)>)> = std::thread::scope(|s| {
        let parts: Vec<_> = (0..PARTICIPANTS)
            .map(|k| s.spawn(move || take_part(front, k)))
            .collect();
        // Server 2 is killed once a third of the answers are in (each participant has
        // 6 trials), in the middle of everyone's session.
        let start = Instant::now();
        while answers(&mut db) < (PARTICIPANTS * 2) as i64 {
            assert!(
                start.elapsed() < Duration::from_secs(120),
                "no answers came"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let (mut killed, _) = servers.remove(1);
        killed.0.kill().unwrap();
        killed.0.wait().unwrap();
        let out: Vec<_> = parts.into_iter().map(|p| p.join().unwrap()).collect();
        done.store(true, Ordering::Relaxed);
        out
    });
    assert!(done.load(Ordering::Relaxed));

    // Every acknowledged answer is in the database once, in order, and nothing else is.
    for (pid, acked) in &runs {
        let rows: Vec<(i32, f64)> = db
            .query(
                "SELECT t.trial_index, t.response FROM study_trials t \
                 JOIN study_sessions s ON s.id = t.session_id WHERE s.subject = $1 \
                 ORDER BY t.row_number",
                &[pid],
            )
            .unwrap()
            .iter()
            .map(|r| (r.get(0), r.get(1)))
            .collect();
        let want: Vec<(i32, f64)> = acked.iter().map(|(i, a)| (*i as i32, *a)).collect();
        assert_eq!(rows, want, "{pid}");
        assert_eq!(rows.len(), 6, "{pid}: every trial answered");
        let status: String = db
            .query_one(
                "SELECT status FROM study_sessions WHERE subject = $1",
                &[pid],
            )
            .unwrap()
            .get(0);
        assert_eq!(status, "complete", "{pid}");
    }
    let moved: i64 = db
        .query_one(
            "SELECT count(*) FROM study_sessions WHERE (manifest->>'resumes')::int > 0",
            &[],
        )
        .unwrap()
        .get(0);
    assert!(moved > 0, "round robin moved sessions between servers");

    // The same participants, answering the same, served into a results folder by one
    // server: the report is the same.
    let folder = dir.join("folder-results");
    let out = folder.display().to_string();
    let (_one, addr) = serve(&study, &page, &url, &["-o", &out]);
    std::thread::scope(|s| {
        for k in 0..PARTICIPANTS {
            s.spawn(move || take_part(addr, k));
        }
    });
    let from_db = dir.join("report-db");
    let from_folder = dir.join("report-folder");
    study_cmd(
        &url,
        &[
            "report".as_ref(),
            "--store".as_ref(),
            "env".as_ref(),
            "--run".as_ref(),
            "cluster".as_ref(),
            "-o".as_ref(),
            from_db.as_os_str(),
        ],
    );
    study_cmd(
        &url,
        &[
            "report".as_ref(),
            folder.as_os_str(),
            "-o".as_ref(),
            from_folder.as_os_str(),
        ],
    );
    let read = |d: &Path| std::fs::read_to_string(d.join("report.md")).unwrap();
    let (a, b) = (read(&from_db), read(&from_folder));
    let strip = |t: &str| -> Vec<String> {
        t.lines()
            .filter(|l| !l.contains(&folder.display().to_string()) && !l.contains("postgres://"))
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(
        strip(&a),
        strip(&b),
        "the two reports differ:\n{a}\n----\n{b}"
    );

    // The two servers left refuse answers no page could give.
    cheaters_are_refused(front, &[servers[0].1, servers[1].1]);
    // Stopped as an experimenter stops them (SIGTERM): each marks its open sessions
    // interrupted, lets its database connections go and exits 0 (closing them on an async
    // worker once panicked at exit).
    for (p, _) in &mut servers {
        let pid = p.0.id().to_string();
        assert!(
            Command::new("kill")
                .args(["-TERM", &pid])
                .status()
                .unwrap()
                .success()
        );
        let status = p.0.wait().unwrap();
        assert!(
            status.success(),
            "a server stopped by SIGTERM exited with {status}"
        );
    }
    drop(servers);
    let _ = std::fs::remove_dir_all(&dir);
}
