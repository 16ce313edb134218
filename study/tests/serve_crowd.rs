//! Crowd practice through `study serve` and `study report`, without a browser (participants
//! are `web::client`s): plan groups filled in turn up to their quota, the completion code at
//! the end, a gold trial failed (the session is excluded) and a page hidden during the
//! stimuli under `hidden = "exclude"` (the trial is left out), both applied and listed by
//! `study report`, whose display section lists the browsers.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::too_many_lines,
    missing_docs
)]

use std::collections::BTreeMap;
use std::io::{BufRead as _, BufReader};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::json;
use web::client::Client;

struct Serve(Child);

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn setup(dir: &Path) -> PathBuf {
    let walk = motion::synth::WalkParams {
        duration_s: 0.3,
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    };
    lab::generated::walk_stimuli(dir, &walk, &["spiht"], &[10.0, 20.0]).unwrap();
    std::fs::create_dir_all(dir.join("page")).unwrap();
    std::fs::write(
        dir.join("page/index.html"),
        "<!doctype html><title>t</title>",
    )
    .unwrap();
    // What the real page says it draws (the server checks the study against it).
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../web/page/src/capabilities.json"),
        dir.join("page/capabilities.json"),
    )
    .unwrap();
    let study = dir.join("study.toml");
    std::fs::write(
        &study,
        "format_version = 1\nname = \"crowd\"\nprotocol = \"mos\"\nstimuli = \"stimuli/stimuli.json\"\n\
         seed = 4\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n\
         [crowdsourcing]\nhidden = \"exclude\"\ngroups = 3\nquota = 1\ncompletion_code = \"DONE-1\"\n\
         [[crowdsourcing.gold]]\nstimulus = \"walk/spiht/cr20\"\nmax = 2\n",
    )
    .unwrap();
    study
}

/// Joins, begins and answers every trial with `rating`, the first with the page reported
/// hidden when `hide_first`.
fn take_part(addr: std::net::SocketAddr, pid: &str, rating: f64, hide_first: bool) -> Client {
    let mut c = Client::new(addr);
    let r = c
        .join(&BTreeMap::from([(
            "PROLIFIC_PID".to_string(),
            pid.to_string(),
        )]))
        .unwrap();
    assert_eq!(r.status, 200, "{:?}", r.json());
    let begin =
        json!({ "fields": {}, "consent": false, "environment": web::client::environment() });
    assert_eq!(
        c.request("POST", &c.session_path("begin"), Some(&begin))
            .unwrap()
            .status,
        200
    );
    let mut first = true;
    loop {
        let t = c
            .request("GET", &c.session_path("trial"), None)
            .unwrap()
            .json();
        if t["done"] == json!(true) {
            return c;
        }
        let need = t["presentation_ms"].as_f64().unwrap();
        std::thread::sleep(Duration::from_millis(need as u64 + 30));
        let body = json!({
            "index": t["index"], "answer": { "Rating": rating }, "replays": 0,
            "response_time_ms": 500, "played_ms": need + 10.0,
            "intervals": [16.7, 16.7, 16.7], "phases": ["both", "both", "answer"],
            "hidden": hide_first && first, "fullscreen": false,
        });
        let r = c
            .request("POST", &c.session_path("answer"), Some(&body))
            .unwrap();
        assert_eq!(r.status, 200, "{:?}", r.json());
        first = false;
    }
}

#[test]
fn quotas_completion_gold_and_hidden_pages_reach_the_report() {
    let dir = std::env::temp_dir().join(format!("serve-crowd-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let study = setup(&dir);
    let out = dir.join("results");
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut child = Command::new(env!("CARGO_BIN_EXE_study"))
        .arg("serve")
        .arg(&study)
        .arg("-o")
        .arg(&out)
        .arg("--page")
        .arg(dir.join("page"))
        .args(["--bind", &format!("127.0.0.1:{port}")])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let server = Serve(child);
    let addr = ([127, 0, 0, 1], port).into();

    // pA rates everything 5: the obvious degradation (cr20, at most 2) fails.
    let mut a = take_part(addr, "pA", 5.0, false);
    let info = a
        .request("GET", &a.session_path("session"), None)
        .unwrap()
        .json();
    assert_eq!(info["completion"]["code"], json!("DONE-1"), "{info}");
    take_part(addr, "pB", 1.0, true);
    take_part(addr, "pC", 2.0, false);
    // Three groups of one: the fourth is turned away.
    let r = Client::new(addr)
        .join(&BTreeMap::from([(
            "PROLIFIC_PID".to_string(),
            "pD".to_string(),
        )]))
        .unwrap();
    assert_eq!(r.status, 503);
    let mut groups: Vec<u32> = ["pA", "pB", "pC"]
        .iter()
        .map(|s| {
            let m: results::SessionManifest =
                results::store::read_manifest(&out.join(format!("{s}_s1/session.json"))).unwrap();
            m.subject_index
        })
        .collect();
    groups.sort_unstable();
    assert_eq!(groups, [0, 1, 2], "each group took one participant");
    drop(server);

    let report = dir.join("report");
    let status = Command::new(env!("CARGO_BIN_EXE_study"))
        .arg("report")
        .arg(&out)
        .arg("-o")
        .arg(&report)
        .status()
        .unwrap();
    assert!(status.success());
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    let exclusions = md
        .split("## Exclusions")
        .nth(1)
        .expect("an Exclusions section");
    assert!(
        exclusions.contains("left out 1 of 3 sessions (pA session 1)"),
        "{exclusions}"
    );
    assert!(exclusions.contains("walk/spiht/cr20: 5"), "{exclusions}");
    // pB's first trial was hidden: left out of the statistics, listed.
    let pb = exclusions
        .lines()
        .find(|l| l.contains("pB session 1"))
        .expect("pB listed");
    assert!(pb.contains("| 0 |"), "{pb}");
    assert!(
        md.contains("Browser per session"),
        "the display section lists the browsers"
    );
    assert!(
        !md.contains("Subjects (3)"),
        "pA's session is not in the statistics"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
