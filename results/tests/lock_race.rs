//! Two processes resuming one session at the same moment: exactly one proceeds and the other
//! is refused with [`ResultsError::Locked`], in 100 tries, half of them with the window
//! between opening the lock file and locking it widened (`STUDY_LOCK_GAP_MS`, debug builds).
//!
//! The children are this test binary itself, started on [`race_child`] with the session
//! folder in `LOCK_RACE_DIR`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use results::trials::{HEADER, read_trials};
use results::{ResultsError, SessionLog};

/// Exit status of a child refused with `Locked`.
const REFUSED: i32 = 3;

/// How long a child that got the session keeps it: far longer than the two children's start
/// skew, so a sequential "both got it" cannot pass for a race won.
const HOLD: Duration = Duration::from_millis(150);

/// Not a test of its own: the body of a racing child, run when `LOCK_RACE_DIR` is set.
#[test]
fn race_child() {
    let Some(dir) = std::env::var_os("LOCK_RACE_DIR") else {
        return;
    };
    let dir = PathBuf::from(dir);
    match SessionLog::resume(&dir) {
        Ok(resumed) => {
            // Proceed as a runner would, holding the session a while.
            std::fs::write(
                dir.join(format!("proceeded-{}", std::process::id())),
                resumed.records.len().to_string(),
            )
            .unwrap();
            std::thread::sleep(HOLD);
            drop(resumed);
        }
        Err(ResultsError::Locked { .. }) => std::process::exit(REFUSED),
        Err(e) => panic!("{e}"),
    }
}

fn child(dir: &Path, gap_ms: u64) -> Command {
    let mut c = Command::new(std::env::current_exe().unwrap());
    c.args(["--exact", "race_child", "--nocapture", "--test-threads=1"])
        .env("LOCK_RACE_DIR", dir)
        .env("STUDY_LOCK_GAP_MS", gap_ms.to_string())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c
}

#[test]
fn two_resumes_at_once_exactly_one_proceeds() {
    let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("race-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    let mut widened = 0;
    for attempt in 0..100 {
        let dir = root.join(format!("S{attempt:03}_s1"));
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(dir.join("trials.csv"), format!("{HEADER}\n")).unwrap();
        // Half the tries leave a lock file behind, as a killed runner does.
        if attempt % 2 == 1 {
            std::fs::write(dir.join("session.lock"), "4194305\n").unwrap();
        }
        let gap = if attempt % 4 < 2 { 0 } else { 40 };
        widened += usize::from(gap > 0);
        let a = child(&dir, gap).spawn().unwrap();
        let b = child(&dir, gap).spawn().unwrap();
        let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
        let codes = [a.status.code(), b.status.code()];
        let ok = codes.iter().filter(|c| **c == Some(0)).count();
        let refused = codes.iter().filter(|c| **c == Some(REFUSED)).count();
        assert_eq!(
            (ok, refused),
            (1, 1),
            "try {attempt} (gap {gap} ms): exit codes {codes:?}\n{}\n{}",
            String::from_utf8_lossy(&a.stderr),
            String::from_utf8_lossy(&b.stderr)
        );
        let proceeded = std::fs::read_dir(&dir)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with("proceeded-")
            })
            .count();
        assert_eq!(proceeded, 1, "try {attempt}");
        assert!(read_trials(&dir.join("trials.csv")).is_ok());
        assert!(
            !dir.join("session.lock").exists(),
            "try {attempt}: the winner removed its lock"
        );
    }
    assert_eq!(widened, 50);
}
