//! Issue 23's target: `study report` on 10⁶ ratings read from PostgreSQL within 2× of reading
//! them from folders, whole process, both measured in one run.
//!
//! ```sh
//! python3 scripts/bench/report_million.py make /tmp/million     # 20,000 sessions, 10^6 ratings
//! cargo build --release -p study
//! REPORT_MILLION_DIR=/tmp/million cargo bench -p lab --bench pg_report
//! ```
//!
//! Starts a throw-away server (fsync on), loads the folder with `study import` (timed), then
//! runs `study report FOLDER` and `study report --store DB` (`--no-png`, as
//! `report_million.py time` does) three times each, alternating, and prints each pair (wall
//! seconds, the client's CPU seconds, the server's CPU seconds), the medians, their ratio and
//! each one's peak memory; the two reports must be the same files. The server's CPU time is
//! what its postmaster counts for the backends it has reaped (`cutime + cstime` in
//! `/proc/PID/stat`). Without `REPORT_MILLION_DIR` it says how to make the data set and stops.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use results::pg::scratch::ScratchServer;

/// CPU seconds the reaped children of process `pid` have used (`cutime + cstime`).
fn children_cpu(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    // Fields after the command name in parentheses: state is field 3, cutime 16, cstime 17.
    let after = &stat[stat.rfind(')').unwrap() + 2..];
    let f: Vec<f64> = after.split(' ').map(|v| v.parse().unwrap_or(0.0)).collect();
    let ticks: f64 = String::from_utf8(
        Command::new("getconf")
            .arg("CLK_TCK")
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap()
    .trim()
    .parse()
    .unwrap();
    (f[13] + f[14]) / ticks
}

/// One run: wall seconds, peak resident MiB, the command's CPU seconds (user + system) and
/// the server's.
struct Run {
    wall: f64,
    mib: f64,
    cpu: f64,
    server_cpu: f64,
}

/// Runs `study ARGS` (GNU time); `server`, the postmaster whose reaped backends' CPU is
/// counted.
fn timed(study: &Path, args: &[&str], url: &str, server: u32) -> Run {
    let before = children_cpu(server);
    let start = Instant::now();
    let out = Command::new("/usr/bin/time")
        .arg("-v")
        .arg(study)
        .args(args)
        .env("STUDY_DATABASE_URL", url)
        .output()
        .unwrap();
    let wall = start.elapsed().as_secs_f64();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{args:?}: {err}");
    let field = |name: &str| {
        err.lines()
            .find_map(|l| l.trim().strip_prefix(name))
            .and_then(|v| v.trim().parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // The backend is reaped once it has seen the connection close.
    std::thread::sleep(std::time::Duration::from_millis(300));
    Run {
        wall,
        mib: field("Maximum resident set size (kbytes):") / 1024.0,
        cpu: field("User time (seconds):") + field("System time (seconds):"),
        server_cpu: children_cpu(server) - before,
    }
}

fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

fn median(v: &[Run]) -> &Run {
    let mut v: Vec<&Run> = v.iter().collect();
    v.sort_by(|a, b| a.wall.total_cmp(&b.wall));
    v[v.len() / 2]
}

fn main() {
    let Some(folder) = std::env::var_os("REPORT_MILLION_DIR").map(PathBuf::from) else {
        println!(
            "pg_report: set REPORT_MILLION_DIR to a folder made by \
             `python3 scripts/bench/report_million.py make DIR` (see this file's docs)"
        );
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let study = std::env::var_os("STUDY_BIN")
        .map_or_else(|| root.join("target/release/study"), PathBuf::from);
    let server = ScratchServer::start(&std::env::temp_dir(), &[]).unwrap();
    let pid = server.pid().unwrap();
    server.create_database("million").unwrap();
    let url = server.url("million");
    let import = timed(
        &study,
        &["import", folder.to_str().unwrap(), "--store", "env"],
        &url,
        pid,
    );
    println!(
        "study import: {:.1} s, {:.0} MiB peak",
        import.wall, import.mib
    );
    let out = std::env::temp_dir().join(format!("pg-report-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let (mut from_folder, mut from_db) = (Vec::new(), Vec::new());
    for k in 0..3 {
        let f = out.join(format!("folder-{k}"));
        let d = out.join(format!("db-{k}"));
        from_folder.push(timed(
            &study,
            &[
                "report",
                folder.to_str().unwrap(),
                "--no-png",
                "-o",
                f.to_str().unwrap(),
            ],
            &url,
            pid,
        ));
        from_db.push(timed(
            &study,
            &[
                "report",
                "--store",
                "env",
                "--no-png",
                "-o",
                d.to_str().unwrap(),
            ],
            &url,
            pid,
        ));
        let (f, d) = (&from_folder[k], &from_db[k]);
        println!(
            "pair {k}: folder {:.2} s (CPU {:.2} s), database {:.2} s (CPU {:.2} s here, {:.2} s \
             in the server): {:.2}x",
            f.wall,
            f.cpu,
            d.wall,
            d.cpu,
            d.server_cpu,
            d.wall / f.wall
        );
    }
    assert_eq!(
        files(&out.join("folder-0")),
        files(&out.join("db-0")),
        "the two reports differ"
    );
    let (f, d) = (median(&from_folder), median(&from_db));
    println!(
        "study report FOLDER:     {:.2} s, {:.0} MiB peak (median of 3)",
        f.wall, f.mib
    );
    println!(
        "study report --store DB: {:.2} s, {:.0} MiB peak (median of 3)",
        d.wall, d.mib
    );
    println!(
        "database / folder: {:.2}x (target <= 2x); the reports are identical",
        d.wall / f.wall
    );
    let _ = std::fs::remove_dir_all(&out);
}
