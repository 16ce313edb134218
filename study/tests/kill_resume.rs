//! Kill test: `study simulate` is killed with SIGKILL at random moments (at least 20 kills),
//! resumed each time with `--resume`; after every kill the logs hold a prefix of the
//! uninterrupted run (no response lost or duplicated), and the completed results equal those
//! of an uninterrupted run with the same seed, timestamps aside. The live staircase (stimuli
//! encoded by the runner) is killed and resumed the same way, and so are MOS and DSCQS.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use protocols::TrialRecord;
use protocols::rng::StudyRng;
use results::store::SessionState;

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("kill-resume-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn simulate(study: &Path, out: &Path, delay_ms: u64, resume: bool) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_study"));
    c.arg("simulate")
        .arg(study)
        .args(["--subjects", "3", "--seed", "11", "-o"])
        .arg(out);
    c.args(["--trial-delay-ms", &delay_ms.to_string()]);
    if resume {
        c.arg("--resume");
    }
    // Each run's messages go beside its results, so a failed resume can say why.
    let log = std::fs::File::create(out.with_extension(if resume { "resume.log" } else { "log" }))
        .unwrap();
    c.stdout(Stdio::null()).stderr(Stdio::from(log));
    c
}

/// Every session's records with the timestamps zeroed, by session directory name.
fn logs(dir: &Path) -> Vec<(String, Vec<TrialRecord>)> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return out;
    };
    let mut dirs: Vec<PathBuf> = entries
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("trials.csv").is_file())
        .collect();
    dirs.sort();
    for d in dirs {
        let t = results::read_trials(&d.join("trials.csv")).unwrap();
        assert!(
            t.torn.is_none(),
            "SIGKILL does not tear a row written with one write call"
        );
        let recs = t
            .records
            .into_iter()
            .map(|mut r| {
                r.wall_clock_ms = 0;
                r.monotonic_ms = 0;
                r
            })
            .collect();
        out.push((d.file_name().unwrap().to_string_lossy().into_owned(), recs));
    }
    out
}

/// Bytes of every session's `trials.csv` under `dir` (read without parsing: a runner may be
/// writing one).
fn logged_bytes(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .filter_map(|e| std::fs::metadata(e.ok()?.path().join("trials.csv")).ok())
        .map(|m| m.len())
        .sum()
}

/// Waits (at most a minute) until `child` has logged past `before` bytes or ended: a kill
/// then strikes a session, not the stimulus preflight that runs first (a live staircase
/// encodes every clip there, which under load outlasted every random delay: 20 kills, no
/// session struck).
fn wait_for_a_row(dir: &Path, before: u64, child: &mut Child) {
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while logged_bytes(dir) <= before
        && child.try_wait().unwrap().is_none()
        && std::time::Instant::now() < deadline
    {
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn kill(child: &mut Child) -> bool {
    let running = child.try_wait().unwrap().is_none();
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();
    running
}

fn kill_and_resume(study_name: &str, min_kills: u32) {
    let study = examples().join(study_name);
    let reference = scratch(&format!("{study_name}-reference"));
    let status = simulate(&study, &reference, 0, false).status().unwrap();
    assert!(status.success());
    let want = logs(&reference);
    assert_eq!(want.len(), 3);

    let mut rng = StudyRng::new(0x6b69_6c6c, &[u64::from(min_kills)]);
    let mut kills = 0;
    let mut attempt = 0;
    let mut all_resumes = 0;
    while kills < min_kills {
        attempt += 1;
        assert!(attempt < 20, "could not kill the runner {min_kills} times");
        let out = scratch(&format!("{study_name}-killed-{attempt}"));
        let mut child = simulate(&study, &out, 4, false).spawn().unwrap();
        let mut previous = 0;
        loop {
            wait_for_a_row(&out, logged_bytes(&out), &mut child);
            std::thread::sleep(Duration::from_millis(5 + rng.below(120)));
            if kill(&mut child) {
                kills += 1;
            }
            // Invariant after every kill: each session log is a prefix of the reference.
            let got = logs(&out);
            let mut total = 0;
            for (name, recs) in &got {
                let (_, full) = want.iter().find(|(n, _)| n == name).unwrap();
                assert!(
                    recs.len() <= full.len(),
                    "{name}: more rows than the uninterrupted run"
                );
                assert_eq!(
                    recs[..],
                    full[..recs.len()],
                    "{name}: logged rows differ from the uninterrupted run"
                );
                total += recs.len();
            }
            assert!(total >= previous, "rows were lost: {total} < {previous}");
            previous = total;
            // A kill before the results directory existed (the stimulus preflight runs
            // first) left nothing to resume: that run starts again.
            let mut resumed = simulate(&study, &out, 4, out.is_dir()).spawn().unwrap();
            if kills >= min_kills {
                assert!(
                    resumed.wait().unwrap().success(),
                    "final resume completes: {}",
                    std::fs::read_to_string(out.with_extension("resume.log")).unwrap_or_default()
                );
                break;
            }
            // A resume that finished before the next kill ends this attempt.
            std::thread::sleep(Duration::from_millis(5 + rng.below(120)));
            if let Some(status) = resumed.try_wait().unwrap() {
                assert!(
                    status.success(),
                    "a resume after SIGKILL failed: {status}: {}",
                    std::fs::read_to_string(out.with_extension("resume.log")).unwrap_or_default()
                );
                break;
            }
            child = resumed;
        }
        let got = logs(&out);
        assert_eq!(got, want, "completed log equals the uninterrupted run");
        let mut resumes = 0;
        for (name, recs) in &got {
            let m: results::SessionManifest =
                results::store::read_json(&out.join(name).join("session.json")).unwrap();
            assert_ne!(m.status, SessionState::Running, "{name} finished");
            assert_eq!(m.trials_logged as usize, recs.len());
            assert!(
                !out.join(name).join("session.lock").exists(),
                "{name}: lock released"
            );
            resumes += m.resumes;
        }
        // A kill can land between two sessions (or before the first): an attempt may resume
        // none, but over all the kills some must have struck mid-session.
        all_resumes += resumes;
        eprintln!(
            "{study_name}: attempt {attempt}: {kills} kills so far, {resumes} session resumes"
        );
    }
    assert!(kills >= min_kills);
    assert!(all_resumes > 0, "no kill struck a session mid-way");
}

#[test]
fn staircase_survives_sigkill_and_resumes_identically() {
    kill_and_resume("staircase.toml", 20);
}

/// A live staircase encodes each trial's stimulus in the runner: a resumed process starts with
/// an empty cache, re-encodes what it needs, and must log the same trials, parameters, CRs and
/// errors as an uninterrupted run (the logs are compared row by row, encoding columns
/// included).
#[test]
fn live_staircase_survives_sigkill_and_resumes_identically() {
    kill_and_resume("live-staircase.toml", 20);
}

#[test]
fn mos_survives_sigkill_and_resumes_identically() {
    kill_and_resume("mos.toml", 20);
}

/// DSCQS logs both ratings of a pair and their difference in one row: a kill can never leave
/// half a pair, and a resumed run rates the same pairs in the same order.
#[test]
fn dscqs_survives_sigkill_and_resumes_identically() {
    kill_and_resume("dscqs.toml", 20);
}
