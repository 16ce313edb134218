//! Issue 23's target: 4 stations × 50 simulated sessions of a 50-trial MOS study at once into
//! one local PostgreSQL server (a throw-away one, fsync on): 0 answers lost or duplicated,
//! p99 commit ≤ 20 ms.
//!
//! Each station is a thread with its own connections, as a station process has: it takes
//! subject numbers from the database and runs each session through the same recorder as
//! `study simulate --store` (`lab::session::Recorder` over `results::pg::PgStore`), timing
//! every answer's commit (`Recorder::record`: the row and the manifest in one statement, until
//! the server says it is committed). Then every session is checked against the same subject
//! simulated into a results folder: the same rows, each once, none missing.
//!
//! A bounded run, not a criterion loop: `cargo bench -p lab --bench pg_stations`. Needs
//! Debian's `postgresql` package (or `STUDY_PG_BIN`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use lab::StudyFile;
use lab::results_dir::Destination;
use lab::session::{Opened, Recorder, SessionOf};
use lab::simulate::{SimulateOptions, subject_id};
use protocols::observer::Observer;
use results::Store as _;
use results::pg::scratch::ScratchServer;

const STATIONS: u32 = 4;
const PER_STATION: u32 = 50;

const STUDY: &str = r#"format_version = 1
name = "mos-stations"
title = "Motion quality study"
protocol = "mos"
stimuli = "stimuli/stimuli.json"
seed = 20110512

[conditions]
clips = ["walk"]
codecs = ["wavelet-perceptual", "wavelet-bone", "wavelet-standard"]
target_cr = [10, 15, 20, 25, 30, 35, 40, 45, 50, 55, 60, 65, 70]

[presentation]
arrangement = "side_by_side"
reference_position = "random"
stimulus_duration_ms = 6000

[scale]
kind = "categorical"
min = 1.0
max = 5.0
step = 0.5

[session]
familiarization = 4
hidden_repeats = 7

[simulation]
metric = "rms_cm"
quality_scale = 4.0
bias_sd = 0.3
noise_sd = 0.4
response_time_ms = 4000
"#;

fn percentile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i]
}

#[expect(
    clippy::too_many_lines,
    reason = "one bounded run: the study, four stations, the check"
)]
fn main() {
    let dir = std::env::temp_dir().join(format!("pg-stations-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let codecs = ["wavelet-perceptual", "wavelet-bone", "wavelet-standard"];
    let targets: Vec<f64> = (2..=14).map(|k| f64::from(k) * 5.0).collect();
    lab::generated::walk_stimuli(
        &dir,
        &motion::synth::WalkParams::default(),
        &codecs,
        &targets,
    )
    .unwrap();
    let study_path = dir.join("study.toml");
    std::fs::write(&study_path, STUDY).unwrap();
    let study = Arc::new(StudyFile::load(&study_path).unwrap());
    let def = &study.definition;
    let trials =
        def.conditions.len() + def.familiarization.len() + def.session.hidden_repeats as usize;
    println!("study: {trials} trials per session");

    let server = ScratchServer::start(&std::env::temp_dir(), &[]).unwrap();
    let db = server.create_database("stations").unwrap();
    let seed = 1;
    let subjects = STATIONS * PER_STATION;
    let store =
        lab::results_dir::open_database_for_simulation(&db, None, &study, seed, subjects).unwrap();
    drop(store);
    let commits = Arc::new(Mutex::new(Vec::<f64>::new()));
    let start = Instant::now();
    let stations: Vec<_> = (0..STATIONS)
        .map(|_| {
            let (db, study, commits) = (db.clone(), Arc::clone(&study), Arc::clone(&commits));
            std::thread::spawn(move || {
                let mut store = lab::results_dir::open_database_for_simulation(
                    &db, None, &study, seed, subjects,
                )
                .unwrap();
                let def = &study.definition;
                let mut mine = Vec::new();
                let mut sessions = 0;
                let id_of = |n: u32| lab::simulate::subject_id(n - 1);
                while let Some((number, _)) = store
                    .take_subject_number(Some(subjects), &id_of, Some(seed))
                    .unwrap()
                {
                    let index = number - 1;
                    let mut fresh = lab::session::new_manifest(
                        def,
                        SessionOf {
                            study_hash: &study.hash,
                            manifest_hash: &study.manifest_hash,
                            subject: subject_id(index),
                            subject_index: index,
                            session: 1,
                            observer_seed: Some(seed),
                            group: None,
                        },
                    );
                    fresh.display = None;
                    let Opened::Ready { recorder, .. } =
                        Recorder::open(def, index, &mut store, false, fresh).unwrap()
                    else {
                        panic!("new session finished");
                    };
                    let mut rec = recorder;
                    let observer = Observer::new(def, seed, index);
                    let mut clock = 0;
                    while let Some(trial) = rec.next_trial(clock).unwrap() {
                        let response = observer.respond_measured(&trial, None).unwrap();
                        clock += def.trial_presentation_ms() * (1 + u64::from(response.replays))
                            + response.response_time_ms
                            + def.presentation.gap_ms;
                        let t = Instant::now();
                        rec.record(trial, response, clock, None, None).unwrap();
                        mine.push(t.elapsed().as_secs_f64() * 1e3);
                    }
                    rec.finish().unwrap();
                    sessions += 1;
                }
                commits.lock().unwrap().extend(mine);
                sessions
            })
        })
        .collect();
    let per_station: Vec<u32> = stations.into_iter().map(|s| s.join().unwrap()).collect();
    let wall = start.elapsed();
    let mut ms = commits.lock().unwrap().clone();
    ms.sort_by(f64::total_cmp);
    println!(
        "{STATIONS} stations: {per_station:?} sessions, {} answers committed in {:.1} s",
        ms.len(),
        wall.as_secs_f64()
    );
    println!(
        "commit: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms (target p99 <= 20 ms)",
        percentile(&ms, 0.5),
        percentile(&ms, 0.99),
        ms[ms.len() - 1]
    );

    // Every session against the same subjects simulated into a folder: nothing lost, nothing
    // twice (the clock stamps aside).
    let folder = dir.join("folder");
    lab::simulate::simulate(
        &SimulateOptions {
            study: study_path.clone(),
            subjects,
            seed,
            output: Destination::Folder(folder.clone()),
            trial_delay: Duration::ZERO,
            resume: false,
            patience: Duration::ZERO,
        },
        &mut |_| {},
    )
    .unwrap();
    let mut store = results::pg::PgStore::open(&db, None).unwrap();
    let heads = store.sessions().unwrap();
    let from_db = store.read(&heads).unwrap();
    let (_, dirs) = results::session_dirs(&folder).unwrap();
    assert_eq!(from_db.len(), dirs.len(), "sessions");
    let (mut lost, mut extra) = (0, 0);
    for (s, d) in from_db.iter().zip(&dirs) {
        let f = results::read_session(d).unwrap();
        assert_eq!(s.manifest.subject, f.manifest.subject);
        let strip = |r: &protocols::TrialRecord| {
            let mut r = r.clone();
            r.wall_clock_ms = 0;
            r.monotonic_ms = 0;
            r
        };
        let a: Vec<_> = s.trials.records.iter().map(strip).collect();
        let b: Vec<_> = f.trials.records.iter().map(strip).collect();
        lost += b.iter().filter(|r| !a.contains(r)).count();
        extra += a.len().saturating_sub(b.len());
        assert_eq!(
            a,
            b,
            "{}",
            store.session_path(&s.manifest.subject, 1).display()
        );
    }
    println!(
        "{} sessions, {} answers checked against the same subjects simulated into a folder: {lost} lost, {extra} duplicated",
        from_db.len(),
        from_db
            .iter()
            .map(|s| s.trials.records.len())
            .sum::<usize>()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
