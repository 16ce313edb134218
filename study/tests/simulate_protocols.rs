//! `study check` and `study simulate` end to end on the shipped examples: MOS, DSCQS,
//! staircase, QUEST+, ACR-HR, DCR, pair comparison, MUSHRA and CCR runs write complete results directories that the readers load back,
//! and their reports' tidy exports read in pandas and R with the documented columns.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

#[path = "../../scripts/golden/tidy_readers.rs"]
mod tidy_readers;
#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

use std::path::{Path, PathBuf};
use std::process::Command;

use protocols::{Answer, Block, Position, Protocol};
use results::store::SessionState;

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("simulate-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn study() -> Command {
    Command::new(env!("CARGO_BIN_EXE_study"))
}

/// `study report` of the results `out` (of example `file`), and its tidy export read by
/// pandas and R.
fn reported_tidy_reads(out: &Path, file: &str) {
    let report = out.with_extension("report");
    let st = study()
        .arg("report")
        .arg(out)
        .args(["--no-png", "--bootstrap", "50", "-o"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{file}: {}",
        String::from_utf8_lossy(&st.stderr)
    );
    tidy_readers::check_tidy(out, &report, file);
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "one loop over the examples: simulate, check the rows, report, read the export"
)]
fn simulate_writes_complete_results_for_every_protocol() {
    for (file, protocol, per_session) in [
        ("mos.toml", Protocol::Mos, Some(14)),
        ("dscqs.toml", Protocol::Dscqs, Some(10)),
        ("staircase.toml", Protocol::Staircase, None),
        ("quest.toml", Protocol::Staircase, None),
        ("acr-hr.toml", Protocol::Acr, Some(14)),
        ("dcr.toml", Protocol::Dcr, Some(12)),
        ("pc.toml", Protocol::PairComparison, Some(22)),
        ("pc-ties.toml", Protocol::PairComparison, Some(22)),
        ("mushra.toml", Protocol::Mushra, Some(15)),
        ("ccr.toml", Protocol::Ccr, Some(16)),
    ] {
        let out = scratch(file);
        let st = study()
            .arg("simulate")
            .arg(examples().join(file))
            .args(["--subjects", "2", "--seed", "3", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{file}: {}",
            String::from_utf8_lossy(&st.stderr)
        );
        let (run, sessions) = results::read_results_dir(&out).unwrap();
        assert_eq!(run.subjects, 2);
        assert_eq!(run.observer_seed, Some(3));
        assert!(out.join("study.toml").is_file());
        assert_eq!(sessions.len(), 2);
        for s in &sessions {
            assert_eq!(s.manifest.protocol, protocol);
            assert_eq!(s.manifest.status, SessionState::Complete);
            assert_eq!(s.manifest.trials_logged as usize, s.trials.records.len());
            if let Some(n) = per_session {
                assert_eq!(s.trials.records.len(), n, "{file}");
            }
            for (i, r) in s.trials.records.iter().enumerate() {
                assert_eq!(r.trial.index as usize, i);
                assert_eq!(r.protocol, protocol);
            }
            match protocol {
                Protocol::Mos | Protocol::Acr | Protocol::Dcr => {
                    // Simulated ratings follow quality: compression ratio 10 beats 30 on average.
                    let mean = |suffix: &str| {
                        let v: Vec<f64> = s
                            .trials
                            .records
                            .iter()
                            .filter(|r| {
                                r.trial.block != Block::Familiarization
                                    && r.trial.stimulus.ends_with(suffix)
                            })
                            .map(|r| r.outcome.score)
                            .collect();
                        v.iter().sum::<f64>() / v.len() as f64
                    };
                    // (One category per grade in ACR and DCR: the standard wavelet's, whose
                    // errors differ most.)
                    let (hi, lo) = if protocol == Protocol::Mos {
                        ("cr10", "cr30")
                    } else {
                        ("standard/cr10", "standard/cr30")
                    };
                    assert!(
                        mean(hi) > mean(lo) + 0.5,
                        "{file}: {} vs {}",
                        mean(hi),
                        mean(lo)
                    );
                    // ACR-HR: the hidden references are rated, and near the top.
                    if protocol == Protocol::Acr {
                        assert!(mean("/reference") >= 4.0, "{}", mean("/reference"));
                    }
                }
                Protocol::Dscqs => assert!(
                    s.trials
                        .records
                        .iter()
                        .all(|r| r.outcome.score_reference.is_some())
                ),
                Protocol::PairComparison => pair_comparison_session(s, file == "pc-ties.toml"),
                Protocol::Ccr => ccr_session(s),
                Protocol::Mushra => check_mushra(s),
                Protocol::Staircase => {
                    // The staircase example runs two tracks, the QUEST+ example one.
                    let tracks = if file == "quest.toml" { 1 } else { 2 };
                    assert_eq!(s.manifest.thresholds.len(), tracks, "{file}");
                    assert!(
                        s.manifest
                            .thresholds
                            .iter()
                            .all(|(_, t)| t.is_some_and(|t| (0.002..=0.040).contains(&t)))
                    );
                }
            }
        }
        reported_tidy_reads(&out, file);
        // Never overwritten.
        let again = study()
            .arg("simulate")
            .arg(examples().join(file))
            .args(["--subjects", "2", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(!again.status.success());
        assert!(String::from_utf8_lossy(&again.stderr).contains("never overwritten"));
    }
}

/// A simulated MUSHRA session of the example: a training screen (familiarization) and then
/// two screens of five panes (3 tests, hidden reference, anchor), each screen's panes
/// lettered A-E in order, the training screen of the first clip (walk); the hidden
/// reference rated near the top and far above the anchor.
fn check_mushra(s: &results::SessionResults) {
    let records = &s.trials.records;
    let panes: Vec<String> = records
        .iter()
        .map(|r| r.trial.reference_position.to_string())
        .collect();
    let letters = ["pane_a", "pane_b", "pane_c", "pane_d", "pane_e"];
    assert_eq!(panes, [letters, letters, letters].concat());
    let blocks: Vec<Block> = records.iter().map(|r| r.trial.block).collect();
    assert_eq!(
        blocks,
        [
            [Block::Familiarization; 5],
            [Block::Test; 5],
            [Block::Test; 5]
        ]
        .concat()
    );
    assert!(records[0].trial.reference.starts_with("walk/"));
    let score = |suffix: &str| {
        let v: Vec<f64> = records
            .iter()
            .filter(|r| r.trial.block == Block::Test && r.trial.stimulus.ends_with(suffix))
            .map(|r| r.outcome.score)
            .collect();
        assert_eq!(v.len(), 2, "{suffix}: one per screen");
        v.iter().sum::<f64>() / 2.0
    };
    assert!(score("/reference") >= 85.0, "{}", score("/reference"));
    assert!(
        score("standard/cr30") + 50.0 < score("/reference"),
        "anchor {} vs hidden reference {}",
        score("standard/cr30"),
        score("/reference")
    );
}

/// A simulated observer replays a MUSHRA screen whole, as the window and the page do (one
/// Replay button per screen): every pane of a screen logs the same replays. Over 20
/// subjects' 60 screens some are replayed and some are not (each is, one time in ten: none
/// of 60 replayed has probability 0.2 %).
#[test]
fn simulated_mushra_screens_replay_whole() {
    let out = scratch("mushra-replays");
    let st = study()
        .arg("simulate")
        .arg(examples().join("mushra.toml"))
        .args(["--subjects", "20", "--seed", "5", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let (_, sessions) = results::read_results_dir(&out).unwrap();
    let mut replayed = [0, 0];
    for s in &sessions {
        for screen in s.trials.records.chunk_by(|a, b| {
            a.trial.reference == b.trial.reference && a.trial.block == b.trial.block
        }) {
            assert_eq!(screen.len(), 5, "{}", s.manifest.subject);
            let replays = screen[0].response.replays;
            assert!(
                screen.iter().all(|r| r.response.replays == replays),
                "{}: a screen's panes replayed apart: {:?}",
                s.manifest.subject,
                screen
                    .iter()
                    .map(|r| r.response.replays)
                    .collect::<Vec<_>>()
            );
            replayed[usize::from(replays > 0)] += 1;
        }
    }
    assert_eq!(replayed[0] + replayed[1], 60);
    assert!(replayed[0] > 0 && replayed[1] > 0, "{replayed:?}");
    let _ = std::fs::remove_dir_all(&out);
}

/// A simulated pair comparison session of the example: every pair of a clip's five
/// conditions once, then two again with the sides swapped; each row's two stimuli are of one
/// clip, and the score says which column's version won (1/2 for no preference).
fn pair_comparison_session(s: &results::SessionResults, ties_offered: bool) {
    let mut pairs: Vec<&str> = s
        .trials
        .records
        .iter()
        .filter(|r| r.trial.block == Block::Test)
        .map(|r| r.trial.condition.as_str())
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    assert_eq!(pairs.len(), 20, "{pairs:?}");
    for r in &s.trials.records {
        let clip = |id: &str| id.split('/').next().unwrap_or("").to_owned();
        assert_eq!(clip(&r.trial.stimulus), clip(&r.trial.reference));
        assert_ne!(r.trial.stimulus, r.trial.reference);
        // A tie (no preference) scores 1/2, and only where the screen offered it.
        let tie = r.response.answer == Answer::Choice(Position::Neither);
        let want: &[f64] = if tie { &[0.5] } else { &[0.0, 1.0] };
        assert!(want.contains(&r.outcome.score), "{r:?}");
        assert!(!tie || ties_offered, "{r:?}");
    }
    let repeats = s
        .trials
        .records
        .iter()
        .filter(|r| r.trial.block == Block::HiddenRepeat)
        .count();
    assert_eq!(repeats, 2);
}

#[test]
fn check_lists_every_problem_and_fails() {
    let dir = scratch("check");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(examples().join("stimuli.json"), dir.join("stimuli.json")).unwrap();
    let text = std::fs::read_to_string(examples().join("staircase.toml"))
        .unwrap()
        .replace("step = 0.006", "step = 0")
        .replace("n_up = 1", "n_up = 1\nn_upp = 1");
    std::fs::write(dir.join("bad.toml"), text).unwrap();
    let out = study()
        .arg("check")
        .arg(dir.join("bad.toml"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("staircase.step") && err.contains("staircase.n_upp"),
        "{err}"
    );
    let ok = study()
        .arg("check")
        .arg(examples().join("mos.toml"))
        .output()
        .unwrap();
    assert!(ok.status.success());
    assert!(String::from_utf8_lossy(&ok.stdout).contains("trials per session: 14"));
}

#[test]
fn resume_with_a_changed_study_is_a_clear_error() {
    let dir = scratch("changed");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(examples().join("stimuli.json"), dir.join("stimuli.json")).unwrap();
    std::os::unix::fs::symlink(examples().join("stimuli"), dir.join("stimuli")).unwrap();
    let original = std::fs::read_to_string(examples().join("mos.toml")).unwrap();
    std::fs::write(dir.join("s.toml"), &original).unwrap();
    let out = dir.join("out");
    assert!(
        study()
            .arg("simulate")
            .arg(dir.join("s.toml"))
            .args(["-o"])
            .arg(&out)
            .status()
            .unwrap()
            .success()
    );
    // Pretend the session was interrupted, then change the familiarization block.
    let m = out.join("S001_s1/session.json");
    let text = std::fs::read_to_string(&m)
        .unwrap()
        .replace("\"complete\"", "\"running\"");
    std::fs::write(&m, text).unwrap();
    std::fs::write(
        dir.join("s.toml"),
        original.replace("familiarization = 2", "familiarization = 1"),
    )
    .unwrap();
    let r = study()
        .arg("simulate")
        .arg(dir.join("s.toml"))
        .args(["--resume", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        err.contains("s.toml") && err.contains("another version"),
        "{err}"
    );
}

/// `--subject ID` simulates one subject under that id, with the plan index `study run
/// --subject ID` and `study serve` derive from it (FNV-1a 32 of `ID/1`, computed here
/// independently), so a test can give a browser the answers that subject's observer gives;
/// an id that cannot name a folder, or `--subject` with `--subjects`, is refused.
#[test]
fn simulate_one_subject_by_id() {
    let out = scratch("subject");
    let st = study()
        .arg("simulate")
        .arg(examples().join("mos.toml"))
        .args(["--subject", "pidA", "--seed", "3", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let (_, sessions) = results::read_results_dir(&out).unwrap();
    assert_eq!(sessions.len(), 1);
    let m = &sessions[0].manifest;
    let fnv = b"pidA/1".iter().fold(0x811c_9dc5_u32, |h, b| {
        (h ^ u32::from(*b)).wrapping_mul(0x0100_0193)
    });
    assert_eq!(
        (m.subject.as_str(), m.subject_index, m.observer_seed),
        ("pidA", fnv, Some(3))
    );
    assert_eq!(m.status, SessionState::Complete);
    assert_eq!(sessions[0].trials.records.len(), 14);
    for (args, says) in [
        (
            &["--subject", "../x"][..],
            "--subject \"../x\": use 1-64 letters, digits, '-' or '_'",
        ),
        (
            &["--subject", "pidB", "--subjects", "2"][..],
            "cannot be used with",
        ),
    ] {
        let st = study()
            .arg("simulate")
            .arg(examples().join("mos.toml"))
            .args(args)
            .arg("-o")
            .arg(scratch("refused"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&st.stderr);
        assert!(
            !st.status.success() && err.contains(says),
            "{args:?}: {err}"
        );
    }
}

/// `examples/groups.toml` (two between-subject groups of 12): simulated subjects are assigned
/// alternately, each session's rows are its group's conditions only (its place in the group
/// picks its Latin-square row), the report's integrity check replays every session over its
/// group and its Method section counts the groups' sessions.
#[test]
fn between_subject_groups_are_assigned_simulated_and_reported() {
    let out = scratch("groups");
    let example = examples().join("groups.toml");
    let simulate = |subjects: &str| {
        study()
            .arg("simulate")
            .arg(&example)
            .args(["--subjects", subjects, "--seed", "5", "-o"])
            .arg(&out)
            .output()
            .unwrap()
    };
    let st = simulate("24");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let (_, sessions) = results::read_results_dir(&out).unwrap();
    assert_eq!(sessions.len(), 24);
    let mut places = std::collections::BTreeMap::<String, Vec<u32>>::new();
    for s in &sessions {
        let m = &s.manifest;
        let group = m.group.clone().expect("every session has a group");
        // S001 (index 0) to the first group, S002 to the second, ...
        let number: u32 = m.subject[1..].parse().unwrap();
        let first = if number % 2 == 1 {
            "perceptual"
        } else {
            "standard"
        };
        assert_eq!(group, first, "{}", m.subject);
        places
            .entry(group.clone())
            .or_default()
            .push(m.subject_index);
        let codec = format!("wavelet-{group}/");
        for r in s
            .trials
            .records
            .iter()
            .filter(|r| r.trial.block == Block::Test)
        {
            assert!(
                r.trial.stimulus.contains(&codec),
                "{}: {}",
                m.subject,
                r.trial.stimulus
            );
        }
        let tests = s
            .trials
            .records
            .iter()
            .filter(|r| r.trial.block == Block::Test)
            .count();
        assert_eq!(tests, 4, "{}", m.subject);
    }
    for (g, mut ks) in places {
        ks.sort_unstable();
        assert_eq!(ks, (0..12).collect::<Vec<u32>>(), "group {g}");
    }
    let groups_csv = std::fs::read_to_string(out.join("groups.csv")).unwrap();
    assert_eq!(groups_csv.lines().count(), 25, "{groups_csv}");

    let report = out.with_extension("report");
    let st = study()
        .arg("report")
        .arg(&out)
        .args(["--no-png", "-o"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    tidy_readers::check_tidy(&out, &report, "groups.toml");
    let text = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(
        text.contains(
            "Between-subject groups, each session assigned one by the results store (the group \
             with the fewest sessions first) and shown its conditions and the catch trials: \
             perceptual (4 condition(s), 12 session(s) of a quota of 12); standard (4 \
             condition(s), 12 session(s) of a quota of 12)."
        ),
        "{text}"
    );
}

/// `examples/groups.toml` with quotas of 2: the fifth simulated subject is refused, every
/// group being full, before anything of it is written.
#[test]
fn a_study_whose_groups_are_full_refuses_the_next_subject() {
    let example = examples().join("groups.toml");
    let small = scratch("groups-quota");
    std::fs::create_dir_all(&small).unwrap();
    let text = std::fs::read_to_string(&example)
        .unwrap()
        .replace("quota = 12", "quota = 2")
        .replace(
            "stimuli = \"stimuli.json\"",
            &format!("stimuli = {:?}", examples().join("stimuli.json")),
        );
    std::fs::write(small.join("groups.toml"), text).unwrap();
    let results = small.join("results");
    let st = study()
        .arg("simulate")
        .arg(small.join("groups.toml"))
        .args(["--subjects", "5", "--seed", "5", "-o"])
        .arg(&results)
        .output()
        .unwrap();
    assert!(!st.status.success());
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(
        err.contains("every group has its quota of sessions (perceptual 2/2, standard 2/2)"),
        "{err}"
    );
    assert!(results.join("S004_s1").is_dir() && !results.join("S005_s1").exists());
}

/// A simulated CCR session of the example: every condition (the originals compared with
/// themselves among them) in both orders over the session's trials, each rating one of the
/// seven categories -3 … 3 and logged as its own score; the standard wavelet at 30:1, the
/// worst version, is rated worse than the original once the order is folded (a rating with
/// the original second counts negated).
fn ccr_session(s: &results::SessionResults) {
    let test: Vec<&protocols::TrialRecord> = s
        .trials
        .records
        .iter()
        .filter(|r| r.trial.block != Block::Familiarization)
        .collect();
    for r in &s.trials.records {
        let Answer::Rating(v) = r.response.answer else {
            panic!("{r:?}")
        };
        assert!((-3.0..=3.0).contains(&v) && v.fract() == 0.0, "{r:?}");
        assert!((r.outcome.score - v).abs() < 1e-12, "{r:?}");
        assert!(matches!(
            r.trial.reference_position,
            Position::First | Position::Second
        ));
    }
    for order in [Position::First, Position::Second] {
        assert!(test.iter().any(|r| r.trial.reference_position == order));
    }
    assert!(test.iter().any(|r| r.trial.stimulus == r.trial.reference));
    let folded: Vec<f64> = test
        .iter()
        .filter(|r| r.trial.stimulus.ends_with("standard/cr30"))
        .map(|r| match r.trial.reference_position {
            Position::First => r.outcome.score,
            _ => -r.outcome.score,
        })
        .collect();
    assert!(!folded.is_empty());
    assert!(
        folded.iter().sum::<f64>() / (folded.len() as f64) < -0.5,
        "{folded:?}"
    );
}
