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
//! `report_million.py time` does) three times each, alternating, and prints the medians,
//! their ratio and each one's peak memory; the two reports must be the same files. Without
//! `REPORT_MILLION_DIR` it says how to make the data set and stops.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use results::pg::scratch::ScratchServer;

/// Wall seconds and peak resident MiB of `cmd` (GNU time).
fn timed(study: &Path, args: &[&str], url: &str) -> (f64, f64) {
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
    let rss = err
        .lines()
        .find_map(|l| {
            l.trim()
                .strip_prefix("Maximum resident set size (kbytes): ")
        })
        .and_then(|v| v.parse::<f64>().ok())
        .map_or(0.0, |kb| kb / 1024.0);
    (wall, rss)
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

fn median(mut v: Vec<(f64, f64)>) -> (f64, f64) {
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
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
    server.create_database("million").unwrap();
    let url = server.url("million");
    let (import_s, import_mib) = timed(
        &study,
        &["import", folder.to_str().unwrap(), "--store", "env"],
        &url,
    );
    println!("study import: {import_s:.1} s, {import_mib:.0} MiB peak");
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
        ));
    }
    assert_eq!(
        files(&out.join("folder-0")),
        files(&out.join("db-0")),
        "the two reports differ"
    );
    let (f, d) = (median(from_folder), median(from_db));
    println!(
        "study report FOLDER:     {:.2} s, {:.0} MiB peak (median of 3)",
        f.0, f.1
    );
    println!(
        "study report --store DB: {:.2} s, {:.0} MiB peak (median of 3)",
        d.0, d.1
    );
    println!(
        "database / folder: {:.2}x (target <= 2x); the reports are identical",
        d.0 / f.0
    );
    let _ = std::fs::remove_dir_all(&out);
}
