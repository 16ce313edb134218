//! The PostgreSQL store against a real server (a throw-away one, `initdb` in a temporary
//! folder): subject numbers never given twice, one writer per session, the roles of
//! `docs/postgres.md` (a station inserts rows only into the sessions it holds), schema
//! versions, an answer kept through a server restart, and passwords never shown. Between-
//! subject group assignments are checked here for both stores, the database and a folder.
//! Under CI a missing server fails these tests; elsewhere they say so and pass.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::BTreeMap;
use std::sync::{Arc, Barrier};

use protocols::{
    Answer, Arrangement, Block, Outcome, Position, Protocol, Response, Trial, TrialRecord,
};
use results::backend::{FolderStore, Found, GROUPS_FILE, GroupQuota, Store};
use results::pg::scratch::ScratchServer;
use results::pg::{Archive, Database, PgStore};
use results::store::{MANIFEST_FORMAT_VERSION, SessionState};
use results::{ResultsError, RunManifest, SessionManifest};

fn server() -> Option<ScratchServer> {
    // No fsync: what is tested is a server process stopped or killed, not the machine.
    match ScratchServer::start(&std::env::temp_dir(), &["fsync=off"]) {
        Ok(s) => Some(s),
        Err(e) if std::env::var_os("CI").is_none() && results::pg::scratch::bin_dir().is_err() => {
            eprintln!("skipped: {e}");
            None
        }
        Err(e) => panic!("{e}"),
    }
}

fn run_manifest() -> RunManifest {
    RunManifest {
        format_version: MANIFEST_FORMAT_VERSION,
        study: "pg-test".into(),
        study_hash: "h1".into(),
        manifest_hash: Some("m1".into()),
        study_file: "study.toml".into(),
        plan_seed: 7,
        observer_seed: None,
        subjects: 0,
        software_version: "test".into(),
        created_ms: 1,
    }
}

fn archive() -> Archive {
    Archive {
        study_copy: b"name = \"pg-test\"\n".to_vec(),
        manifest_copy: b"{}".to_vec(),
    }
}

fn open(db: &Database) -> PgStore {
    PgStore::open_or_create(db, "pg-test", &run_manifest(), &archive())
        .unwrap()
        .0
}

fn manifest(subject: &str) -> SessionManifest {
    SessionManifest {
        format_version: MANIFEST_FORMAT_VERSION,
        study: "pg-test".into(),
        study_hash: "h1".into(),
        manifest_hash: Some("m1".into()),
        protocol: Protocol::Mos,
        subject: subject.into(),
        subject_index: 3,
        session: 1,
        plan_seed: 7,
        observer_seed: None,
        software_version: "test".into(),
        subject_fields: BTreeMap::new(),
        started_ms: 5,
        ended_ms: None,
        status: SessionState::Running,
        trials_logged: 0,
        not_shown: Vec::new(),
        thresholds: Vec::new(),
        resumes: 0,
        torn_rows: Vec::new(),
        display: None,
        browser: None,
        viewing: None,
        group: None,
    }
}

fn record(subject: &str, index: u32, rating: f64) -> TrialRecord {
    TrialRecord {
        study: "pg-test".into(),
        subject: subject.into(),
        session: 1,
        protocol: Protocol::Mos,
        trial: Trial {
            index,
            block: Block::Test,
            condition: "c, with \"quotes\"".into(),
            stimulus: format!("walk/x/cr{index}"),
            reference: "walk/reference".into(),
            arrangement: Arrangement::SideBySide,
            reference_position: Position::Left,
            staircase: None,
            level: Some(0.1 + f64::from(index)),
            break_before: false,
        },
        response: Response {
            answer: Answer::Rating(rating),
            response_time_ms: 1234,
            replays: 1,
            dropped_frames: 0,
        },
        outcome: Outcome {
            score: rating,
            score_reference: None,
            score_test: None,
            correct: None,
            reversal: None,
        },
        elapsed_ms: 100 * u64::from(index),
        wall_clock_ms: 1_700_000_000_000,
        monotonic_ms: 17,
        encoding: None,
        timing: None,
    }
}

/// Two stations asking for subject numbers at the same moment, 100 times each: 200
/// different numbers, 1 to 200, each recorded once.
fn two_stations_never_get_the_same_subject_number(server: &ScratchServer) {
    let db = server.create_database("numbers").unwrap();
    drop(open(&db));
    let barrier = Arc::new(Barrier::new(2));
    let stations: Vec<_> = (0..2)
        .map(|_| {
            let (db, barrier) = (db.clone(), Arc::clone(&barrier));
            std::thread::spawn(move || {
                let mut store = PgStore::open(&db, Some("pg-test")).unwrap();
                (0..100)
                    .map(|_| {
                        barrier.wait();
                        store
                            .take_subject_number(None, &|n| format!("S{n:02}"), None)
                            .unwrap()
                            .unwrap()
                            .0
                    })
                    .collect::<Vec<u32>>()
            })
        })
        .collect();
    let mut all: Vec<u32> = stations
        .into_iter()
        .flat_map(|s| s.join().unwrap())
        .collect();
    all.sort_unstable();
    assert_eq!(all, (1..=200).collect::<Vec<_>>());
    let mut client = db.connect().unwrap();
    let recorded: i64 = client
        .query_one(
            "SELECT count(DISTINCT number) FROM study_subject_numbers",
            &[],
        )
        .unwrap()
        .get(0);
    assert_eq!(recorded, 200);
}

/// A session has one writer: a second station is refused while the first holds it, and gets
/// it (with every committed row) once the first is gone. Rows and manifest come back as
/// written.
fn one_writer_per_session_and_rows_read_back_as_written(server: &ScratchServer) {
    let db = server.create_database("writers").unwrap();
    let mut a = open(&db);
    let mut b = PgStore::open(&db, None).unwrap();
    let mut m = manifest("S01");
    let mut writer = a.create_session(&m).unwrap();
    assert!(matches!(
        a.create_session(&m),
        Err(ResultsError::Exists { .. })
    ));
    for i in 0..3 {
        writer
            .append(&record("S01", i, 1.5 + f64::from(i)))
            .unwrap();
    }
    // The rows are the record: the session's column counts them as they are committed, the
    // manifest is the one last written (at creation here) until it is written again.
    let column = |db: &Database| -> (i32, i64) {
        let row = db
            .connect()
            .unwrap()
            .query_one(
                "SELECT trials_logged, (manifest->>'trials_logged')::bigint FROM study_sessions \
                 WHERE subject = 'S01'",
                &[],
            )
            .unwrap();
        (row.get(0), row.get(1))
    };
    assert_eq!(column(&db), (3, 0));
    m.trials_logged = 3;
    writer.write_manifest(&m).unwrap();
    assert_eq!(column(&db), (3, 3));
    let busy = b.resume_session("S01", 1).err().unwrap();
    let text = busy.to_string();
    assert!(
        matches!(busy, ResultsError::SessionBusy { .. }) && text.contains("pid"),
        "{text}"
    );
    drop(writer);
    let resumed = b.resume_session("S01", 1).unwrap();
    assert_eq!(resumed.records.len(), 3);
    assert_eq!(resumed.writer.rows(), 3);
    assert_eq!(resumed.records[2], record("S01", 2, 3.5));
    let Found::Present(Some(back)) = a.find_session("S01", 1).unwrap() else {
        panic!("session not found");
    };
    assert_eq!(*back, m);
    drop(resumed);
    let heads = a.sessions().unwrap();
    let read = a.read(&heads).unwrap();
    assert_eq!(read.len(), 1);
    assert_eq!(read[0].trials.records.len(), 3);
}

/// A MUSHRA pane's row (row 4 of session S04): the grid and its pane (L, the last letter), a
/// window row whose screen's frames went with its first pane (none of its own).
fn mushra_pane_row() -> TrialRecord {
    let mut pane = record("S04", 4, 0.0);
    pane.protocol = Protocol::Mushra;
    pane.trial.arrangement = Arrangement::Grid;
    pane.trial.reference_position = Position::Pane(11);
    pane.response.answer = Answer::Rating(73.0);
    pane.outcome.score = 73.0;
    pane.timing = Some(protocols::FrameTiming {
        frames_shown: 0,
        interval_sd_ms: 0.0,
    });
    pane
}

/// A pair comparison's choice (row 3 of session S04): the `reference` column is the pair's
/// other test stimulus, and the `stimulus` column's version was preferred.
fn pair_comparison_row() -> TrialRecord {
    let mut preferred = record("S04", 3, 0.0);
    preferred.protocol = Protocol::PairComparison;
    preferred.trial.condition = "walk/x/cr3 vs walk/y/cr3".into();
    preferred.trial.reference = "walk/y/cr3".into();
    preferred.trial.level = None;
    preferred.trial.reference_position = Position::Right;
    preferred.response.answer = Answer::Choice(Position::Left);
    preferred.outcome = Outcome {
        score: 1.0,
        score_reference: None,
        score_test: None,
        correct: None,
        reversal: None,
    };
    preferred
}

/// Records of every kind (a DSCQS pair, a 2AFC choice of a live staircase with its encoding
/// and frame timing, a pair comparison's choice, a MUSHRA pane, text needing quotes) come back from a report's read exactly as written;
/// a value the database holds that no record can have is refused, naming the session's
/// trials, the row's line in an exported `trials.csv`, the column and the reason.
fn every_kind_of_row_read_back_and_bad_values_named(server: &ScratchServer) {
    let db = server.create_database("kinds").unwrap();
    let mut store = open(&db);
    let m = manifest("S04");
    let mut writer = store.create_session(&m).unwrap();
    let mut pair = record("S04", 0, 0.0);
    pair.protocol = Protocol::Dscqs;
    pair.response.answer = Answer::Pair { a: 71.5, b: 12.25 };
    pair.outcome = Outcome {
        score: 59.25,
        score_reference: Some(71.5),
        score_test: Some(12.25),
        correct: None,
        reversal: None,
    };
    let mut choice = record("S04", 1, 0.0);
    choice.protocol = Protocol::Staircase;
    choice.trial.block = Block::Familiarization;
    choice.trial.staircase = Some(2);
    choice.trial.level = Some(-0.003_125);
    choice.trial.break_before = true;
    choice.trial.condition = "ünïcode, \"quoted\"\nline".into();
    choice.response.answer = Answer::Choice(Position::Right);
    choice.response.response_time_ms = u64::from(u32::MAX) + 7;
    choice.outcome = Outcome {
        score: 1.0,
        score_reference: None,
        score_test: None,
        correct: Some(true),
        reversal: Some(false),
    };
    choice.encoding = Some(protocols::StimulusEncoding {
        codec_params: BTreeMap::from([("qp".to_string(), 9.0), ("window".to_string(), 128.0)]),
        achieved_cr: 23.5,
        rms_cm: 0.125,
    });
    choice.timing = Some(protocols::FrameTiming {
        frames_shown: 240,
        interval_sd_ms: 0.375,
    });
    let written = [
        pair,
        choice,
        record("S04", 2, 4.5),
        pair_comparison_row(),
        mushra_pane_row(),
    ];
    for r in &written {
        writer.append(r).unwrap();
    }
    drop(writer);
    let heads = store.sessions().unwrap();
    assert_eq!(store.read(&heads).unwrap()[0].trials.records, written);

    let mut admin = db.connect().unwrap();
    // Each damage committed (the store reads on its own connection), read, then undone.
    for (sql, undo, line, column, says) in [
        (
            "UPDATE study_trials SET score = 'NaN' WHERE row_number = 2",
            "UPDATE study_trials SET score = 4.5 WHERE row_number = 2",
            4,
            19,
            "score: NaN is not finite",
        ),
        (
            "UPDATE study_trials SET block = 'warmup' WHERE row_number = 1",
            "UPDATE study_trials SET block = 'familiarization' WHERE row_number = 1",
            3,
            6,
            "block: ",
        ),
        (
            "UPDATE study_trials SET replays = -1 WHERE row_number = 0",
            "UPDATE study_trials SET replays = 1 WHERE row_number = 0",
            2,
            25,
            "replays: -1 is out of range",
        ),
        (
            "UPDATE study_trials SET row_number = 7 WHERE row_number = 4",
            "UPDATE study_trials SET row_number = 4 WHERE row_number = 7",
            6,
            1,
            "row 7 follows row 3",
        ),
    ] {
        admin.execute(sql, &[]).unwrap();
        let e = store.read(&heads).unwrap_err();
        admin.execute(undo, &[]).unwrap();
        let text = e.to_string();
        assert!(
            matches!(&e, ResultsError::Malformed { line: l, column: c, .. } if *l == line && *c == column)
                && text.contains(says)
                && text.contains("S04_s1"),
            "{sql}: {text:?} ({e:?})"
        );
    }
    // Undamaged again: the same records.
    assert_eq!(store.read(&heads).unwrap()[0].trials.records, written);
}

/// The roles of docs/postgres.md, run as written there: a station inserts answers only into
/// a session whose lock it holds, and can neither change nor delete a committed answer; an
/// analyst reads and writes nothing.
fn roles_from_the_docs_allow_what_they_say(server: &ScratchServer) {
    let db = server.create_database("roles").unwrap();
    drop(open(&db));
    let docs = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/postgres.md"))
        .unwrap();
    let sql = docs
        .split("```sql\n")
        .nth(2)
        .and_then(|s| s.split("```").next())
        .expect("docs/postgres.md: the grants block (the second ```sql block)");
    let mut admin = db.connect().unwrap();
    admin
        .batch_execute(
            "CREATE ROLE study_station LOGIN; CREATE ROLE study_analyst LOGIN; \
             CREATE ROLE study_owner LOGIN",
        )
        .unwrap();
    admin.batch_execute(sql).unwrap();
    let as_role = |role: &str| {
        Database::parse(
            &format!("postgres://{role}@127.0.0.1:{}/roles", server.port()),
            "test",
        )
        .unwrap()
    };
    let station = as_role("study_station");
    let mut store = PgStore::open(&station, Some("pg-test")).unwrap();
    assert_eq!(
        store
            .take_subject_number(None, &|n| format!("S{n:02}"), None)
            .unwrap(),
        Some((1, "S01".into()))
    );
    let m = manifest("S02");
    let mut writer = store.create_session(&m).unwrap();
    writer.append(&record("S02", 0, 4.0)).unwrap();
    let mut other = station.connect().unwrap();
    let id: i32 = other
        .query_one("SELECT id FROM study_sessions WHERE subject = 'S02'", &[])
        .unwrap()
        .get(0);
    // Another connection of the same role does not hold the session.
    let err = other
        .execute(
            "INSERT INTO study_trials SELECT session_id, 1, study, subject, session, 1, block, \
             protocol, condition, stimulus, reference, arrangement, reference_position, \
             break_before, staircase, level, response, response_a, response_b, choice, score, \
             score_reference, score_test, correct, reversal, response_time_ms, replays, \
             dropped_frames, elapsed_ms, wall_clock_ms, monotonic_ms, codec_params, \
             achieved_cr, rms_cm, frames_shown, interval_sd_ms FROM study_trials \
             WHERE session_id = $1",
            &[&id],
        )
        .unwrap_err();
    let why = err
        .as_db_error()
        .map(|e| e.message().to_owned())
        .unwrap_or_default();
    assert!(why.contains("row-level security"), "{err}: {why}");
    for sql in [
        "UPDATE study_trials SET score = 1",
        "DELETE FROM study_trials",
    ] {
        assert!(other.execute(sql, &[]).is_err(), "a station may not: {sql}");
    }
    let mut analyst = as_role("study_analyst").connect().unwrap();
    let n: i64 = analyst
        .query_one("SELECT count(*) FROM study_trials", &[])
        .unwrap()
        .get(0);
    assert_eq!(n, 1);
    assert!(
        analyst
            .execute("DELETE FROM study_session_files", &[])
            .is_err()
    );
}

/// The schema is migrated once by stations that start together, and a database whose schema
/// is newer than this build is refused, saying so.
fn schema_is_versioned_and_a_newer_one_refused(server: &ScratchServer) {
    let db = server.create_database("schema").unwrap();
    let starts: Vec<_> = (0..3)
        .map(|_| {
            let db = db.clone();
            std::thread::spawn(move || db.open().map(|_| ()))
        })
        .collect();
    for s in starts {
        s.join().unwrap().unwrap();
    }
    let mut client = db.connect().unwrap();
    let versions: Vec<i32> = client
        .query("SELECT version FROM study_schema_version", &[])
        .unwrap()
        .iter()
        .map(|r| r.get(0))
        .collect();
    assert_eq!(
        versions,
        (1..=results::pg::schema::SCHEMA_VERSION).collect::<Vec<i32>>()
    );
    client
        .execute(
            "INSERT INTO study_schema_version (version, software) VALUES (99, 'future')",
            &[],
        )
        .unwrap();
    let err = db.open().err().unwrap().to_string();
    assert!(err.contains("version 99") && err.contains("newer"), "{err}");
}

/// An answer whose commit met a stopped server is kept by the caller and committed once when
/// the server is back; the writer takes its session again.
fn an_answer_survives_a_server_restart(server: &mut ScratchServer) {
    let db = server.create_database("restart").unwrap();
    let mut store = open(&db);
    let m = manifest("S03");
    let mut writer = store.create_session(&m).unwrap();
    writer.append(&record("S03", 0, 2.0)).unwrap();
    server.stop();
    let err = writer.append(&record("S03", 1, 3.0)).unwrap_err();
    assert!(matches!(err, ResultsError::Unavailable { .. }), "{err:?}");
    assert!(err.to_string().contains("cannot be reached"), "{err}");
    server.resume().unwrap();
    writer.append(&record("S03", 1, 3.0)).unwrap();
    assert_eq!(writer.rows(), 2);
    drop(writer);
    let resumed = open(&db).resume_session("S03", 1).unwrap();
    assert_eq!(
        resumed.records,
        [record("S03", 0, 2.0), record("S03", 1, 3.0)]
    );
}

/// One throw-away server for every scenario (starting one is most of their cost), each in a
/// database of its own; the restart comes last.
/// Two stations assigning between-subject groups at the same moment, 25 new sessions each,
/// into groups `a` and `b` of 20 sessions each: 40 assignments, 20 per group with the places
/// 0 to 19 once each, and 10 refusals saying the study is complete; a session asked again
/// keeps its group (full or not); the fewest-first order; a wanted group, full or unknown.
fn stations_assign_groups_within_their_quotas(
    station: &(dyn Fn() -> Box<dyn Store + Send> + Sync),
) {
    const GROUPS: [GroupQuota<'static>; 2] = [
        GroupQuota {
            name: "a",
            quota: Some(20),
        },
        GroupQuota {
            name: "b",
            quota: Some(20),
        },
    ];
    // Fewest first, the first listed of equals.
    let mut first = station();
    let order: Vec<String> = (0..3)
        .map(|k| {
            first
                .assign_group(&format!("F{k}"), 1, &GROUPS, None)
                .unwrap()
                .group
        })
        .collect();
    assert_eq!(order, ["a", "b", "a"]);
    let again = first.assign_group("F1", 1, &GROUPS, None).unwrap();
    assert_eq!(
        (again.group.as_str(), again.ordinal, again.new),
        ("b", 0, false)
    );
    let wanted = first.assign_group("W", 1, &GROUPS, Some("b")).unwrap();
    assert_eq!((wanted.group.as_str(), wanted.ordinal), ("b", 1));
    let err = first.assign_group("W2", 1, &GROUPS, Some("z")).unwrap_err();
    assert!(err.to_string().contains("there is no group \"z\""), "{err}");
    drop(first);

    let barrier = Barrier::new(2);
    let results: Vec<Vec<Result<(String, u32), String>>> = std::thread::scope(|scope| {
        let runs: Vec<_> = (0..2)
            .map(|s| {
                let barrier = &barrier;
                scope.spawn(move || {
                    let mut store = station();
                    (0..25)
                        .map(|k| {
                            barrier.wait();
                            store
                                .assign_group(&format!("S{s}-{k}"), 1, &GROUPS, None)
                                .map(|a| (a.group, a.ordinal))
                                .map_err(|e| e.to_string())
                        })
                        .collect()
                })
            })
            .collect();
        runs.into_iter().map(|r| r.join().unwrap()).collect()
    });
    let mut places: BTreeMap<String, Vec<u32>> = BTreeMap::new();
    let mut refused = 0;
    for r in results.into_iter().flatten() {
        match r {
            Ok((g, k)) => places.entry(g).or_default().push(k),
            Err(e) => {
                assert!(e.contains("every group has its quota"), "{e}");
                refused += 1;
            }
        }
    }
    // 4 sessions were assigned before the race: a 0, 1 and b 0, 1.
    for (g, mut ks) in places {
        ks.sort_unstable();
        assert_eq!(ks, (2..20).collect::<Vec<u32>>(), "group {g}");
    }
    assert_eq!(refused, 50 - 36);
    let mut store = station();
    let err = store
        .assign_group("late", 1, &GROUPS, Some("a"))
        .unwrap_err();
    assert!(
        err.to_string()
            .contains("group \"a\" is full: 20 of its 20"),
        "{err}"
    );
    let kept = store.assign_group("S0-0", 1, &GROUPS, None).unwrap();
    assert!(!kept.new);
}

/// `study export` writes the run's group assignments as the folder's `groups.csv`, and
/// `study import` loads them into a run that has none; into one that has its own they are
/// refused, nothing imported.
fn assignments_travel_with_export_and_import(server: &ScratchServer, db: &Database) {
    let scratch =
        std::env::temp_dir().join(format!("results-groups-export-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&scratch);
    let out = scratch.join("exported");
    results::pg::export(&mut open(db), &out).unwrap();
    let csv = std::fs::read_to_string(out.join(GROUPS_FILE)).unwrap();
    assert_eq!(csv.lines().count(), 1 + 40, "{csv}");
    assert!(
        csv.starts_with("subject,session,group,ordinal\nF0,1,a,0\nF2,1,a,1\n"),
        "{csv}"
    );
    let other = server.create_database("groups_imported").unwrap();
    results::pg::import(&other, &out, None).unwrap();
    let again = scratch.join("again");
    results::pg::export(&mut open(&other), &again).unwrap();
    assert_eq!(
        std::fs::read_to_string(again.join(GROUPS_FILE)).unwrap(),
        csv
    );
    let err = results::pg::import(&other, &out, None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("assigns sessions to between-subject groups, and so does run"),
        "{err}"
    );
    std::fs::remove_dir_all(&scratch).unwrap();
}

#[test]
fn folder_stations_assign_groups_within_their_quotas() {
    let dir = std::env::temp_dir().join(format!("results-groups-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    stations_assign_groups_within_their_quotas(&|| Box::new(FolderStore::new(&dir)));
    // A damaged record is refused, naming its line.
    let path = dir.join(GROUPS_FILE);
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen(",a,0", ",a,zero", 1)).unwrap();
    let err = FolderStore::new(&dir)
        .assign_group(
            "X",
            1,
            &[GroupQuota {
                name: "a",
                quota: None,
            }],
            None,
        )
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("groups.csv: line 2, column 4: \"zero\" is not a whole number"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn postgres_store() {
    let Some(mut server) = server() else { return };
    let db = server.create_database("groups").unwrap();
    drop(open(&db));
    stations_assign_groups_within_their_quotas(&|| Box::new(open(&db)));
    assignments_travel_with_export_and_import(&server, &db);
    two_stations_never_get_the_same_subject_number(&server);
    one_writer_per_session_and_rows_read_back_as_written(&server);
    every_kind_of_row_read_back_and_bad_values_named(&server);
    roles_from_the_docs_allow_what_they_say(&server);
    schema_is_versioned_and_a_newer_one_refused(&server);
    an_answer_survives_a_server_restart(&mut server);
}

/// A password given on the command line is refused; one from a file is used but never shown.
#[test]
fn passwords_are_never_shown() {
    let err = Database::from_argument("postgres://station:s3cret@db.lab:5432/study")
        .unwrap_err()
        .to_string();
    assert!(
        !err.contains("s3cret") && err.contains("STUDY_DATABASE_URL"),
        "{err}"
    );
    let dir = std::env::temp_dir().join(format!("pg-pass-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("url");
    std::fs::write(&file, "postgres://station:s3cret@127.0.0.1:1/study\n").unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o644)).unwrap();
        let err = Database::from_file(&file).unwrap_err().to_string();
        assert!(
            err.contains("chmod 600") && !err.contains("s3cret"),
            "{err}"
        );
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).unwrap();
    }
    let db = Database::from_file(&file).unwrap();
    assert_eq!(db.to_string(), "postgres://station@127.0.0.1:1/study");
    assert!(!format!("{db:?}").contains("s3cret"));
    let err = db.connect().err().unwrap().to_string();
    assert!(
        err.contains("cannot be reached") && !err.contains("s3cret"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
