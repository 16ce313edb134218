//! The server's API over loopback, in process: an answer is acknowledged once it is on disk
//! and logged once however often it is posted; an answer before the stimuli played is
//! refused; a participant's token opens only their own session; ids take part once; body
//! size, request rate and the dashboard's token are enforced.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::too_many_lines,
    missing_docs
)]

use std::collections::BTreeMap;
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::json;
use web::client::Client;
use web::{Limits, ServeOptions};

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("web-api-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A MOS study of two conditions over a generated walk of 0.3 s, and a stand-in page.
fn setup(dir: &Path) -> ServeOptions {
    let walk = motion::synth::WalkParams {
        duration_s: 0.3,
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    };
    lab::generated::walk_stimuli(dir, &walk, &["spiht"], &[10.0, 20.0]).unwrap();
    std::fs::write(
        dir.join("study.toml"),
        "format_version = 1\nname = \"api\"\nprotocol = \"mos\"\nstimuli = \"stimuli/stimuli.json\"\n\
         seed = 3\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\n\
         target_cr = [10, 20]\n[session]\nconsent = \"ok?\"\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("page")).unwrap();
    std::fs::write(
        dir.join("page/index.html"),
        "<!doctype html><title>t</title>",
    )
    .unwrap();
    // What the real page says it draws (the server checks the study against it).
    std::fs::copy(capabilities(), dir.join("page/capabilities.json")).unwrap();
    ServeOptions {
        study: dir.join("study.toml"),
        results: lab::results_dir::Destination::Folder(dir.join("results")),
        connections: 16,
        bind: "127.0.0.1:0".parse().unwrap(),
        page: dir.join("page"),
        dashboard_token: Some("dashboard-token-0123456789".into()),
        limits: Limits::default(),
    }
}

fn params(kv: &[(&str, &str)]) -> BTreeMap<String, String> {
    kv.iter().map(|(k, v)| ((*k).into(), (*v).into())).collect()
}

fn begin(c: &mut Client) {
    let body = json!({ "fields": {}, "consent": true, "environment": web::client::environment() });
    let r = c
        .request("POST", &c.session_path("begin"), Some(&body))
        .unwrap();
    assert_eq!(r.status, 200, "{:?}", r.json());
}

fn answer(index: u64, rating: f64, played_ms: f64) -> serde_json::Value {
    json!({
        "index": index, "answer": { "Rating": rating }, "replays": 0,
        "response_time_ms": 800, "played_ms": played_ms,
        "intervals": [16.7, 16.6, 16.8, 33.4], "phases": ["both", "both", "both", "answer"],
        "hidden": false, "fullscreen": false,
    })
}

fn rows(dir: &Path, subject: &str) -> usize {
    results::read_trials(&dir.join(format!("results/{subject}_s1/trials.csv")))
        .unwrap()
        .records
        .len()
}

#[test]
fn answers_are_logged_once_and_only_by_their_participant() {
    let dir = temp_dir("once");
    let options = setup(&dir);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    // Both conditions and their reference are read before the first participant.
    assert_eq!(server.app().stimuli_ready(), 3);
    let addr = server.addr;
    let mut a = Client::new(addr);
    assert_eq!(
        a.join(&params(&[("PROLIFIC_PID", "pa")])).unwrap().status,
        200
    );
    // One session per participant.
    assert_eq!(
        Client::new(addr)
            .join(&params(&[("PROLIFIC_PID", "pa")]))
            .unwrap()
            .status,
        409
    );
    let mut b = Client::new(addr);
    assert_eq!(
        b.join(&params(&[("PROLIFIC_PID", "pb")])).unwrap().status,
        200
    );
    assert_ne!(a.token, b.token);
    assert_eq!(a.token.len(), 64);

    // Consent is required when the study asks for it.
    let no = json!({ "fields": {}, "consent": false, "environment": web::client::environment() });
    assert_eq!(
        a.request("POST", &a.session_path("begin"), Some(&no))
            .unwrap()
            .status,
        400
    );
    begin(&mut a);
    let t = a
        .request("GET", &a.session_path("trial"), None)
        .unwrap()
        .json();
    let k = t["index"].as_u64().unwrap();
    let clip = a
        .request("GET", &a.session_path(&format!("clip/{k}/0")), None)
        .unwrap();
    assert_eq!((clip.status, &clip.body[..4]), (200, &b"MCJP"[..]));
    let need = t["presentation_ms"].as_f64().unwrap();

    // Too early: the server's own clock says the stimuli cannot have played.
    let early = a
        .request(
            "POST",
            &a.session_path("answer"),
            Some(&answer(k, 4.0, need + 10.0)),
        )
        .unwrap();
    assert_eq!(early.status, 422, "{:?}", early.json());
    std::thread::sleep(Duration::from_millis(need as u64 + 60));
    // The page's own account counts too.
    let short = a
        .request(
            "POST",
            &a.session_path("answer"),
            Some(&answer(k, 4.0, need * 0.5)),
        )
        .unwrap();
    assert_eq!(short.status, 422);
    // B's token on A's session: refused, nothing logged; a made-up token likewise.
    let path_a = a.session_path("answer");
    let foreign = b
        .request("POST", &path_a, Some(&answer(k, 1.0, need)))
        .unwrap();
    assert_eq!(foreign.status, 403);
    assert_eq!(
        b.request("GET", &a.session_path(&format!("clip/{k}/0")), None)
            .unwrap()
            .status,
        403
    );
    let mut forged = Client::new(addr);
    forged.subject = a.subject.clone();
    forged.token = "00".repeat(32);
    assert_eq!(
        forged
            .request("POST", &path_a, Some(&answer(k, 1.0, need)))
            .unwrap()
            .status,
        401
    );

    let ok = a
        .request("POST", &path_a, Some(&answer(k, 4.0, need)))
        .unwrap();
    assert_eq!(
        (ok.status, ok.json()["duplicate"].as_bool()),
        (200, Some(false))
    );
    assert_eq!(rows(&dir, "pa"), 1, "on disk when acknowledged");
    // The same post again (a retry after a lost reply): acknowledged, not logged again.
    let again = a
        .request("POST", &path_a, Some(&answer(k, 4.0, need)))
        .unwrap();
    assert_eq!(
        (again.status, again.json()["duplicate"].as_bool()),
        (200, Some(true))
    );
    // Another answer to the logged trial is refused.
    assert_eq!(
        a.request("POST", &path_a, Some(&answer(k, 2.0, need)))
            .unwrap()
            .status,
        409
    );
    assert_eq!(rows(&dir, "pa"), 1);
    // The frame intervals became the trial's timing, against the measured 60 Hz.
    let rec = &results::read_trials(&dir.join("results/pa_s1/trials.csv"))
        .unwrap()
        .records[0];
    assert_eq!(rec.timing.map(|t| t.frames_shown), Some(5));
    assert_eq!(rec.response.dropped_frames, 1);

    // A body over the limit is refused before it is read whole.
    let big = json!({ "pad": "x".repeat(300 << 10) });
    assert_eq!(a.request("POST", &path_a, Some(&big)).unwrap().status, 413);

    // The dashboard needs its token.
    let mut d = Client::new(addr);
    assert_eq!(
        d.request("GET", "/api/dashboard", None).unwrap().status,
        401
    );
    d.token = a.token.clone();
    assert_eq!(
        d.request("GET", "/api/dashboard", None).unwrap().status,
        403
    );
    d.token = "dashboard-token-0123456789".into();
    let dash = d.request("GET", "/api/dashboard", None).unwrap().json();
    assert_eq!(
        dash["participants"].as_array().map(Vec::len),
        Some(2),
        "{dash}"
    );
    // Counts per state (A answering, B begun or joined), none complete, and when A's
    // answer was logged.
    assert_eq!(dash["states"]["running"], json!(1), "{dash}");
    assert_eq!(dash["complete_share"], json!(0.0), "{dash}");
    assert_eq!(
        dash["last_answer_ms"].as_u64(),
        Some(rec.wall_clock_ms),
        "{dash}"
    );
    rt.block_on(server.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn requests_over_the_rate_are_refused() {
    let dir = temp_dir("rate");
    let mut options = setup(&dir);
    options.limits = Limits {
        participant_rate: 0.5,
        participant_burst: 5.0,
        join_rate: 0.5,
        join_burst: 2.0,
        ..Limits::default()
    };
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    let mut a = Client::new(server.addr);
    assert_eq!(a.join(&params(&[])).unwrap().status, 200);
    assert_eq!(
        Client::new(server.addr).join(&params(&[])).unwrap().status,
        200
    );
    assert_eq!(
        Client::new(server.addr).join(&params(&[])).unwrap().status,
        429
    );
    let statuses: Vec<u16> = (0..8)
        .map(|_| {
            a.request("GET", &a.session_path("session"), None)
                .unwrap()
                .status
        })
        .collect();
    assert_eq!(
        statuses.iter().filter(|s| **s == 200).count(),
        5,
        "{statuses:?}"
    );
    assert!(statuses[5..].iter().all(|s| *s == 429), "{statuses:?}");
    rt.block_on(server.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

fn capabilities() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("page/src/capabilities.json")
}

/// The page says what it draws (`capabilities.json`): every method's screen and crowd
/// scenes open with the real page's list; a page that lacks an answer widget or a pane
/// content a study needs is refused before the server listens, naming the file and what is
/// missing; a page without the list is refused.
#[test]
fn studies_whose_screens_the_page_lacks_are_refused() {
    let dir = temp_dir("refused");
    let options = setup(&dir);
    let mos = std::fs::read_to_string(&options.study).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let crowd = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/crowd-run1.toml");
    let mut studies = vec![(crowd, "content crowd_scene")];
    for (protocol, extra, lacking) in [
        ("acr", "", "answer rating"),
        ("dcr", "", "answer rating"),
        (
            "pair_comparison",
            "hidden_reference = false\n",
            "answer choice",
        ),
    ] {
        let text = mos
            .replace("protocol = \"mos\"", &format!("protocol = \"{protocol}\""))
            .replace(
                "target_cr = [10, 20]\n",
                &format!("target_cr = [10, 20]\n{extra}"),
            );
        let path = dir.join(format!("{protocol}.toml"));
        std::fs::write(&path, text).unwrap();
        studies.push((path, lacking));
    }
    let real = std::fs::read_to_string(capabilities()).unwrap();
    for (path, lacking) in &studies {
        let open = |page: &str| {
            std::fs::write(dir.join("page/capabilities.json"), page).unwrap();
            rt.block_on(web::start(ServeOptions {
                study: path.clone(),
                // One folder per study, by its name (a folder named by the path's length
                // was shared by two studies whenever their paths were as long).
                results: lab::results_dir::Destination::Folder(dir.join(format!(
                    "results-{}",
                    path.file_stem().unwrap().to_string_lossy()
                ))),
                ..options.clone()
            }))
        };
        let server = open(&real).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        rt.block_on(server.stop()).unwrap();
        // The same page without what this study needs.
        let (what, kind) = lacking.split_once(' ').unwrap();
        let mut less: serde_json::Value = serde_json::from_str(&real).unwrap();
        less[what]
            .as_array_mut()
            .unwrap()
            .retain(|k| k.as_str() != Some(kind));
        let err = match open(&less.to_string()) {
            Ok(_) => panic!("{}: served without {lacking}", path.display()),
            Err(e) => e.to_string(),
        };
        assert!(
            err.contains(lacking) && err.contains(&path.display().to_string()),
            "{err}"
        );
    }
    std::fs::remove_file(dir.join("page/capabilities.json")).unwrap();
    let err = rt
        .block_on(web::start(options.clone()))
        .err()
        .map(|e| e.to_string());
    assert!(
        err.as_deref()
            .is_some_and(|e| e.contains("capabilities.json")),
        "{err:?}"
    );
    std::fs::copy(capabilities(), dir.join("page/capabilities.json")).unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    rt.block_on(server.stop()).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Typed subject fields: the session's JSON gives each field's kind, bounds, options and
/// hint; `begin` refuses an answer the field's kind does not take (400, the reason naming
/// the field, no session created) and stores the answer as the field normalizes it.
#[test]
fn subject_fields_are_checked_by_kind_and_stored_normalized() {
    let dir = temp_dir("fields");
    let options = setup(&dir);
    let study = std::fs::read_to_string(&options.study).unwrap().replace(
        "[session]\n",
        "[session]\nsubject_fields = [\
         { name = \"age\", kind = \"number\", min = 18, max = 99, integer = true }, \
         { name = \"gender\", kind = \"choice\", options = [\"female\", \"male\", \"prefer not to say\"] }, \
         { name = \"normal_vision\", kind = \"yes_no\", label = \"Normal vision\" }]\n",
    );
    std::fs::write(&options.study, study).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    let mut a = Client::new(server.addr);
    assert_eq!(
        a.join(&params(&[("PROLIFIC_PID", "pf")])).unwrap().status,
        200
    );
    let info = a
        .request("GET", &a.session_path("session"), None)
        .unwrap()
        .json();
    let fields = &info["fields"];
    assert_eq!(
        fields[0],
        json!({ "name": "age", "label": "age", "kind": "number", "min": 18.0, "max": 99.0,
                "integer": true, "hint": "enter a whole number from 18 to 99", "max_chars": 200 }),
        "{info}"
    );
    assert_eq!(
        fields[1]["hint"],
        json!("choose one of: female, male, prefer not to say")
    );
    assert_eq!(
        (&fields[2]["label"], &fields[2]["options"]),
        (&json!("Normal vision"), &json!(["yes", "no"]))
    );
    let begin = |c: &mut Client, age: &str, gender: &str, vision: &str| {
        let body = json!({
            "fields": { "age": age, "gender": gender, "normal_vision": vision },
            "consent": true, "environment": web::client::environment(),
        });
        let r = c
            .request("POST", &c.session_path("begin"), Some(&body))
            .unwrap();
        (
            r.status,
            r.json()["error"].as_str().unwrap_or("").to_string(),
        )
    };
    let session = dir.join("results/pf_s1/session.json");
    for (age, gender, vision, why) in [
        (
            "abc",
            "female",
            "yes",
            "age: enter a whole number from 18 to 99",
        ),
        (
            "17",
            "female",
            "yes",
            "age: enter a whole number from 18 to 99",
        ),
        (
            "31.5",
            "female",
            "yes",
            "age: enter a whole number from 18 to 99",
        ),
        (
            "31",
            "other",
            "yes",
            "gender: choose one of: female, male, prefer not to say",
        ),
        ("31", "female", "maybe", "Normal vision: choose yes or no"),
        (
            "31",
            "female",
            "",
            "Normal vision: choose yes or no (required)",
        ),
    ] {
        assert_eq!(
            begin(&mut a, age, gender, vision),
            (400, why.to_string()),
            "{age} {gender} {vision}"
        );
        assert!(!session.exists(), "no session begun by a refused answer");
    }
    assert_eq!(begin(&mut a, " 31 ", "Female", "Y").0, 200);
    let m: results::SessionManifest = results::store::read_manifest(&session).unwrap();
    for (k, v) in [
        ("age", "31"),
        ("gender", "female"),
        ("normal_vision", "yes"),
    ] {
        assert_eq!(m.subject_fields.get(k).map(String::as_str), Some(v), "{k}");
    }
    rt.block_on(server.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A study whose trial plays for several seconds (`playback_count` plays of the 0.3-s walk),
/// so that a restart takes less time than the stimuli play.
fn long_presentation(options: &ServeOptions, plays: u32) {
    let study = std::fs::read_to_string(&options.study).unwrap().replace(
        "[session]\n",
        &format!("[presentation]\nplayback_count = {plays}\n[session]\n"),
    );
    std::fs::write(&options.study, study).unwrap();
}

fn pending_trial(c: &mut Client) -> (u64, f64) {
    let t = c
        .request("GET", &c.session_path("trial"), None)
        .unwrap()
        .json();
    (
        t["index"].as_u64().unwrap(),
        t["presentation_ms"].as_f64().unwrap(),
    )
}

/// An answer is taken only for a trial the server sent, and no sooner than the stimuli's
/// playing time after it sent it, by its own clock: a client that answers without asking for
/// the trial is refused (409), one that answers at once claiming the stimuli played is
/// refused (422), and so is the same right after a restart (the send time is on disk);
/// once the stimuli have had time to play the answer is taken without asking again.
#[test]
fn answers_only_for_sent_trials_after_they_played_even_across_a_restart() {
    let dir = temp_dir("sent");
    let options = setup(&dir);
    long_presentation(&options, 12);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options.clone())).unwrap();
    let mut a = Client::new(server.addr);
    assert_eq!(
        a.join(&params(&[("PROLIFIC_PID", "ps")])).unwrap().status,
        200
    );
    begin(&mut a);
    // Every index a scripted client could guess, unasked for: never sent, refused.
    for k in 0..4 {
        let r = a
            .request(
                "POST",
                &a.session_path("answer"),
                Some(&answer(k, 4.0, 1e5)),
            )
            .unwrap();
        assert_eq!(r.status, 409, "{:?}", r.json());
        let why = r.json()["error"].as_str().unwrap_or("").to_string();
        assert!(
            why.contains("never sent") || why.contains("is not pending"),
            "{why}"
        );
    }
    let sent_file = dir.join("results/ps_s1").join(web::app::SENT_FILE);
    assert!(!sent_file.exists(), "nothing sent yet");
    let (k, need) = pending_trial(&mut a);
    let sent_at = std::time::Instant::now();
    assert!(need > 3000.0, "the trial plays for {need} ms");
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&sent_file).unwrap()).unwrap();
    assert_eq!(record["index"].as_u64(), Some(k), "{record}");
    // Answered at once, claiming the stimuli played: the server's clock says they cannot have.
    let path = a.session_path("answer");
    let early = a
        .request("POST", &path, Some(&answer(k, 4.0, need + 10.0)))
        .unwrap();
    assert_eq!(early.status, 422, "{:?}", early.json());

    // A restart: the trial's send time is read back, so answering at once is still early.
    rt.block_on(server.stop()).unwrap();
    let server = rt.block_on(web::start(options.clone())).unwrap();
    let mut again = Client::new(server.addr);
    again.subject.clone_from(&a.subject);
    again.token.clone_from(&a.token);
    let after_restart = again
        .request("POST", &path, Some(&answer(k, 4.0, need + 10.0)))
        .unwrap();
    assert!(
        sent_at.elapsed().as_secs_f64() * 1e3 < need - 100.0,
        "the restart took longer than the stimuli play"
    );
    assert_eq!(after_restart.status, 422, "{:?}", after_restart.json());
    assert!(
        after_restart.json()["error"]
            .as_str()
            .is_some_and(|e| e.contains("before the stimuli had played")),
        "{:?}",
        after_restart.json()
    );
    assert!(!dir.join("results/ps_s1/trials.csv").exists() || rows(&dir, "ps") == 0);
    // Once they have had time to play since it was first sent: taken, without asking again.
    std::thread::sleep(Duration::from_millis(need as u64 + 100).saturating_sub(sent_at.elapsed()));
    let ok = again
        .request("POST", &path, Some(&answer(k, 4.0, need + 10.0)))
        .unwrap();
    assert_eq!(ok.status, 200, "{:?}", ok.json());
    assert_eq!(rows(&dir, "ps"), 1);
    // The next trial the normal way: asked for, played, answered.
    let (k2, need2) = pending_trial(&mut again);
    assert_ne!(k2, k);
    std::thread::sleep(Duration::from_millis(need2 as u64 + 60));
    let next = again
        .request("POST", &path, Some(&answer(k2, 3.0, need2 + 10.0)))
        .unwrap();
    assert_eq!(next.status, 200, "{:?}", next.json());
    assert_eq!(rows(&dir, "ps"), 2);
    rt.block_on(server.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Timing data that is finite but absurd (intervals whose sum overflows, a time played of
/// 1e308 or negative, NaN sent as JSON's null, a response time of 10^19 ms) is refused with
/// 422 and logs nothing; the trial stays pending and a sound answer is then taken.
#[test]
fn absurd_timing_is_refused_with_422() {
    let dir = temp_dir("absurd");
    let options = setup(&dir);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    let mut a = Client::new(server.addr);
    assert_eq!(
        a.join(&params(&[("PROLIFIC_PID", "px")])).unwrap().status,
        200
    );
    begin(&mut a);
    let (k, need) = pending_trial(&mut a);
    std::thread::sleep(Duration::from_millis(need as u64 + 60));
    let path = a.session_path("answer");
    let with = |key: &str, v: serde_json::Value| {
        let mut body = answer(k, 4.0, need + 10.0);
        body[key] = v;
        if key == "intervals" {
            let n = body["intervals"].as_array().map_or(0, Vec::len);
            body["phases"] = json!(vec!["both"; n]);
        }
        body
    };
    for (what, body) in [
        (
            "overflowing intervals",
            with("intervals", json!([1e308, 0.0, 1e308])),
        ),
        ("one huge interval", with("intervals", json!([16.7, 1e300]))),
        (
            "a negative interval",
            with("intervals", json!([16.7, -1.0])),
        ),
        ("played 1e308 ms", with("played_ms", json!(1e308))),
        ("played NaN (null)", with("played_ms", json!(null))),
        ("played a negative time", with("played_ms", json!(-5.0))),
        (
            "a response time of 10^19 ms",
            with("response_time_ms", json!(10_000_000_000_000_000_000u64)),
        ),
    ] {
        let r = a.request("POST", &path, Some(&body)).unwrap();
        assert_eq!(r.status, 422, "{what}: {:?}", r.json());
    }
    assert!(!dir.join("results/px_s1/trials.csv").exists() || rows(&dir, "px") == 0);
    let ok = a
        .request("POST", &path, Some(&answer(k, 4.0, need + 10.0)))
        .unwrap();
    assert_eq!(ok.status, 200, "{:?}", ok.json());
    assert_eq!(rows(&dir, "px"), 1);
    rt.block_on(server.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A quota counts places held: sessions that completed and participants active within the
/// lease. Five bare joins fill a quota of five only for the lease; then the places of those
/// who made no request since go back to the pool, while one who kept asking keeps theirs.
/// A participant whose lease ran out and who comes back continues their session.
#[test]
fn idle_participants_give_their_place_back_after_the_lease() {
    let dir = temp_dir("lease");
    let options = setup(&dir);
    let study = std::fs::read_to_string(&options.study).unwrap()
        + "[crowdsourcing]\nquota = 5\nlease_s = 3\n";
    std::fs::write(&options.study, study).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    let addr = server.addr;
    let join = |id: &str| {
        let mut c = Client::new(addr);
        let status = c.join(&params(&[("PROLIFIC_PID", id)])).unwrap().status;
        (status, c)
    };
    let mut first: Vec<Client> = (0..5)
        .map(|i| {
            let (status, c) = join(&format!("bare{i}"));
            assert_eq!(status, 200, "join {i}");
            c
        })
        .collect();
    assert_eq!(
        join("sixth").0,
        503,
        "the quota is full while the five hold it"
    );
    let start = std::time::Instant::now();
    // One of them stays active; the other four make no request.
    std::thread::sleep(Duration::from_millis(1500));
    let active = &mut first[0];
    let r = active
        .request("GET", &active.session_path("session"), None)
        .unwrap();
    assert_eq!(r.status, 200);
    std::thread::sleep(Duration::from_millis(3500).saturating_sub(start.elapsed()));
    // Four places came back; the active participant keeps theirs.
    for i in 0..4 {
        assert_eq!(join(&format!("late{i}")).0, 200, "late join {i}");
    }
    assert!(
        start.elapsed() < Duration::from_millis(4400),
        "the active participant's lease may have run out meanwhile"
    );
    assert_eq!(join("over").0, 503);
    // An idle participant who comes back continues (and holds a place again).
    let back = &mut first[1];
    let r = back
        .request("GET", &back.session_path("session"), None)
        .unwrap();
    assert_eq!(
        (r.status, r.json()["state"].as_str()),
        (200, Some("welcome"))
    );
    assert_eq!(join("still-over").0, 503);
    rt.block_on(server.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Whether the server has closed `s` (end of stream or reset); false while it is open.
fn closed(s: &mut TcpStream) -> bool {
    use std::io::Read as _;
    s.set_nonblocking(true).unwrap();
    let mut b = [0u8; 512];
    match s.read(&mut b) {
        Ok(0) => true,
        // A reply (a 408 or 400 before closing) counts once read; the close follows.
        Ok(_) => closed(s),
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => false,
        Err(_) => true,
    }
}

/// A connection to `addr` from the loopback address `from` (127.0.0.2, ...: another client).
fn connect_from(rt: &tokio::runtime::Runtime, from: &str, addr: SocketAddr) -> TcpStream {
    let s = rt.block_on(async {
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.bind(format!("{from}:0").parse().unwrap()).unwrap();
        socket.connect(addr).await.unwrap().into_std().unwrap()
    });
    s.set_nonblocking(false).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s
}

/// 300 connections from one address that send half a request line and stall: those over the
/// per-address cap are closed at once, the rest when the header timeout runs out; meanwhile
/// a participant from another address is served at once, and one from the same address once
/// the stalled connections are gone. A kept-alive connection left idle is closed after the
/// header timeout too. A body sent too slowly is answered 408.
#[test]
fn stalled_connections_are_capped_and_timed_out() {
    use std::io::{Read as _, Write as _};
    let dir = temp_dir("slow");
    let mut options = setup(&dir);
    // Long enough that "at once" (the cap) and "after the timeout" stay apart on a loaded
    // 2-core machine: a fresh-clone run, its test binaries busy beside this one, took over 2 s
    // to take the first of the 300 connections.
    let header = Duration::from_secs(8);
    options.limits = Limits {
        header_timeout: header,
        body_timeout: Duration::from_secs(1),
        max_connections_per_address: 100,
        ..Limits::default()
    };
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(web::start(options)).unwrap();
    let addr = server.addr;
    // A kept-alive connection from a third address, idle after one request.
    let mut idle = connect_from(&rt, "127.0.0.3", addr);
    idle.write_all(web::client::request_text("GET", "/api/study", addr, "", None).as_bytes())
        .unwrap();
    let mut got = [0u8; 12];
    idle.read_exact(&mut got).unwrap();
    assert_eq!(&got, b"HTTP/1.1 200");
    let start = std::time::Instant::now();
    let mut stalled: Vec<TcpStream> = (0..300)
        .map(|_| {
            let mut s = TcpStream::connect(addr).unwrap();
            s.write_all(b"GET /api/stu").unwrap();
            s
        })
        .collect();
    // The 200 over the cap are closed as soon as they are taken, well before the header
    // timeout.
    let mut shut = 0;
    while start.elapsed() < header.saturating_sub(Duration::from_secs(2)) {
        shut = stalled.iter_mut().map(closed).filter(|c| *c).count();
        if shut >= 200 {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(shut, 200, "closed at once: those over the cap of 100");
    // A participant from another address is served at once.
    let asked = std::time::Instant::now();
    let mut other = connect_from(&rt, "127.0.0.2", addr);
    other
        .write_all(
            web::client::request_text("GET", "/api/study", addr, "", None)
                .replace("HTTP/1.1\r\n", "HTTP/1.1\r\nConnection: close\r\n")
                .as_bytes(),
        )
        .unwrap();
    let mut reply = String::new();
    other.read_to_string(&mut reply).unwrap();
    assert!(reply.starts_with("HTTP/1.1 200"), "{reply}");
    let waited = asked.elapsed();
    assert!(waited < header / 2, "a normal request waited {waited:?}");
    // Before the header timeout (the loop above and the request end well inside it on an
    // idle machine: about 0.3 s here), the 100 under the cap wait for their head.
    if start.elapsed() < header.saturating_sub(Duration::from_secs(1)) {
        assert_eq!(
            stalled.iter_mut().map(closed).filter(|c| *c).count(),
            200,
            "the 100 under the cap are still open, waiting for their head"
        );
    }
    assert!(
        !closed(&mut idle),
        "the idle connection is kept alive for a while"
    );
    // After the header timeout every stalled connection is closed.
    while start.elapsed() < header * 3 {
        if stalled.iter_mut().all(closed) {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        stalled.iter_mut().all(closed),
        "stalled connections left open"
    );
    assert!(start.elapsed() >= header);
    assert!(closed(&mut idle), "an idle kept-alive connection left open");
    // Their places under the cap are free again.
    let mut a = Client::new(addr);
    assert_eq!(a.join(&params(&[])).unwrap().status, 200);
    // A body announced but sent too slowly: 408 after the body timeout.
    let mut slow = TcpStream::connect(addr).unwrap();
    slow.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let sent = std::time::Instant::now();
    slow.write_all(
        format!(
            "POST /api/join HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/json\r\n\
             Content-Length: 100\r\n\r\n{{\"params\""
        )
        .as_bytes(),
    )
    .unwrap();
    let mut head = [0u8; 12];
    slow.read_exact(&mut head).unwrap();
    assert_eq!(&head, b"HTTP/1.1 408");
    assert!(sent.elapsed() >= Duration::from_millis(900));
    rt.block_on(server.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// The same rule across servers (issue 37): two servers of one database run share its
/// places. Five bare joins, taken in turn by the two, fill a quota of five for the lease;
/// a participant who asks again (through the other server) keeps their place while the four
/// idle ones give theirs back; an idle one who comes back continues. The database notes a
/// request at most every 2 s, so the active participant asks after that.
#[test]
fn two_servers_of_one_database_share_the_quota_and_the_lease() {
    let pg = match results::pg::scratch::ScratchServer::start(&std::env::temp_dir(), &["fsync=off"])
    {
        Ok(s) => s,
        Err(e) if std::env::var_os("CI").is_none() && results::pg::scratch::bin_dir().is_err() => {
            eprintln!("skipped: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let dir = temp_dir("db-lease");
    let mut options = setup(&dir);
    let study = std::fs::read_to_string(&options.study).unwrap()
        + "[crowdsourcing]\nquota = 5\nlease_s = 3\n";
    std::fs::write(&options.study, study).unwrap();
    options.results = lab::results_dir::Destination::Database {
        db: Box::new(pg.create_database("lease").unwrap()),
        run: None,
    };
    let rt = tokio::runtime::Runtime::new().unwrap();
    let a = rt.block_on(web::start(options.clone())).unwrap();
    let b = rt.block_on(web::start(options)).unwrap();
    let addrs = [a.addr, b.addr];
    let turn = std::cell::Cell::new(0);
    // A join through the next server in turn: its status, the client and the server's turn.
    let join = |id: &str| {
        let server = turn.get() % 2;
        turn.set(turn.get() + 1);
        let mut c = Client::new(addrs[server]);
        let status = c.join(&params(&[("PROLIFIC_PID", id)])).unwrap().status;
        (status, (c, server))
    };
    // A participant through the server that did not take their join.
    let elsewhere = |(c, server): &(Client, usize)| {
        let mut other = Client::new(addrs[1 - server]);
        other.subject.clone_from(&c.subject);
        other.token.clone_from(&c.token);
        other
    };
    let start = std::time::Instant::now();
    let first: Vec<(Client, usize)> = (0..5)
        .map(|i| {
            let (status, c) = join(&format!("bare{i}"));
            assert_eq!(status, 200, "join {i}");
            c
        })
        .collect();
    for _ in 0..2 {
        assert_eq!(join("sixth").0, 503, "the quota is full on both servers");
    }
    std::thread::sleep(Duration::from_millis(2300).saturating_sub(start.elapsed()));
    let mut active = elsewhere(&first[0]);
    let r = active
        .request("GET", &active.session_path("session"), None)
        .unwrap();
    assert_eq!(r.status, 200, "{:?}", r.json());
    std::thread::sleep(Duration::from_millis(3600).saturating_sub(start.elapsed()));
    for i in 0..4 {
        assert_eq!(join(&format!("late{i}")).0, 200, "late join {i}");
    }
    assert!(
        start.elapsed() < Duration::from_secs(5),
        "the active participant's lease may have run out meanwhile"
    );
    assert_eq!(join("over").0, 503);
    let mut back = elsewhere(&first[1]);
    let r = back
        .request("GET", &back.session_path("session"), None)
        .unwrap();
    assert_eq!(
        (r.status, r.json()["state"].as_str()),
        (200, Some("welcome"))
    );
    assert_eq!(join("still-over").0, 503);
    rt.block_on(a.stop()).unwrap();
    rt.block_on(b.stop()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}
