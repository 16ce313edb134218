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
        output: dir.join("results"),
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
                output: dir.join(format!("results-{}", path.display().to_string().len())),
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
