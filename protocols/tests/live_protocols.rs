//! Live (codec-in-the-loop) staircases: the study-file option, the engine's derived stimulus
//! ids and clips taking turns, replay, and the simulated observer that is told the measured
//! error of each trial's stimulus.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use common::{LIVE, issues, parse};
use protocols::observer::Observer;
use protocols::rng::StudyRng;
use protocols::{Answer, ClipOrder, Detection, Response, Session, SessionStatus, StudyDefinition};

fn live() -> StudyDefinition {
    parse(LIVE).unwrap()
}

#[test]
fn live_staircase_parses_with_a_default_track() {
    let s = live();
    let sc = s.staircase.as_ref().unwrap();
    let l = sc.live.as_ref().unwrap();
    assert_eq!(sc.codec, "wavelet-perceptual");
    assert_eq!(sc.param, "cr");
    let clips: Vec<(&str, &str)> = l
        .clips
        .iter()
        .map(|c| (c.clip.as_str(), c.reference.as_str()))
        .collect();
    assert_eq!(
        clips,
        [("walk", "walk/reference"), ("dance", "dance/reference")]
    );
    assert_eq!(l.order, ClipOrder::InTurn);
    assert_eq!(l.params.get("qp"), Some(&10.0));
    assert_eq!(l.database, None);
    assert_eq!(sc.tracks.len(), 1);
    assert_eq!(sc.tracks[0].name, "live");
    assert!((sc.tracks[0].settings.start - 40.0).abs() < 1e-12);
    assert_eq!(s.simulation.detection, Detection::Error);
    assert_eq!(
        sc.live_stimulus_id("walk", 36.0),
        "live:walk/wavelet-perceptual/cr=36"
    );
    assert_eq!(
        sc.live_stimulus_id("walk", 0.1 + 0.2),
        "live:walk/wavelet-perceptual/cr=0.30000000000000004",
        "the id names the exact level"
    );
}

#[test]
fn live_mistakes_are_reported_at_once_with_their_key_paths() {
    let text = LIVE
        .replace(
            "clips = [\"walk\", \"dance\"]",
            "clips = [\"walk\", \"salsa\", \"walk\"]",
        )
        .replace("order = \"in_turn\"", "order = \"random\"")
        .replace(
            "params = { qp = 10, window = 128 }",
            "params = { qp = \"ten\", cr = 3, \"a b\" = 1 }\ndatabase = \"\"\ncolour = 1",
        )
        .replace("max_trials = 50", "max_trials = 50\nlevel_tolerance = 0.1")
        + "\n[[staircase.tracks]]\nname = \"a\"\nclip = \"walk\"\n";
    let got = issues(&text);
    let has = |k: &str, r: &str| got.iter().any(|(gk, gr)| gk == k && gr.contains(r));
    assert!(
        has("staircase.live.clips[1]", "no reference stimulus"),
        "{got:#?}"
    );
    assert!(has("staircase.live.clips[2]", "listed twice"), "{got:#?}");
    assert!(has("staircase.live.order", "in_turn, shuffled"), "{got:#?}");
    assert!(
        has("staircase.live.params.qp", "expected a finite number"),
        "{got:#?}"
    );
    assert!(
        has("staircase.live.params.cr", "staircase's level"),
        "{got:#?}"
    );
    assert!(
        has("staircase.live.params.a b", "letters, digits"),
        "{got:#?}"
    );
    assert!(
        has("staircase.live.database", "must name a file"),
        "{got:#?}"
    );
    assert!(has("staircase.live.colour", "unknown key"), "{got:#?}");
    assert!(
        has("staircase.level_tolerance", "encodes every level exactly"),
        "{got:#?}"
    );
    assert!(
        has("staircase.tracks[0].clip", "staircase.live.clips"),
        "{got:#?}"
    );
    // No clips at all, and a live table of the wrong type.
    let got = issues(&LIVE.replace("clips = [\"walk\", \"dance\"]", "clips = []"));
    assert!(
        got.iter()
            .any(|(k, r)| k == "staircase.live.clips" && r.contains("at least one")),
        "{got:#?}"
    );
    let got = issues(&LIVE.replace("clips = [\"walk\", \"dance\"]\n", ""));
    assert!(
        got.iter()
            .any(|(k, r)| k == "staircase.live.clips" && r == "missing"),
        "{got:#?}"
    );
    let got = issues(&LIVE.replace("detection = \"error\"", "detection = \"rms\""));
    assert!(
        got.iter().any(|(k, _)| k == "simulation.detection"),
        "{got:#?}"
    );
}

/// Answers trial `t` of `session`: the reference's side with probability `p_correct`.
fn choose(session: &mut Session, t: &protocols::Trial, rng: &mut StudyRng, p_correct: f64) {
    let p = t.reference_position;
    let answer = Answer::Choice(if rng.unit_f64() < p_correct {
        p
    } else {
        p.other()
    });
    session
        .respond(&Response {
            answer,
            response_time_ms: 1,
            replays: 0,
            dropped_frames: 0,
        })
        .unwrap();
}

fn answer_all(study: &StudyDefinition, subject: u32) -> Vec<protocols::Trial> {
    let mut session = Session::new(study, subject).unwrap();
    let mut rng = StudyRng::new(3, &[u64::from(subject)]);
    let mut trials = Vec::new();
    while let Some(t) = session.next_trial(0).unwrap() {
        choose(&mut session, &t, &mut rng, 0.8);
        trials.push(t);
    }
    assert_eq!(session.status(), SessionStatus::Complete);
    trials
}

#[test]
fn clips_take_turns_and_stimuli_are_named_by_clip_codec_and_level() {
    let study = live();
    let sc = study.staircase.as_ref().unwrap();
    let trials = answer_all(&study, 0);
    assert!(trials.len() > 10);
    for t in &trials {
        let clip = if t.index % 2 == 0 { "walk" } else { "dance" };
        assert_eq!(t.reference, format!("{clip}/reference"));
        assert_eq!(
            t.stimulus,
            sc.live_stimulus_id(clip, t.level.unwrap()),
            "trial {}",
            t.index
        );
        assert_eq!(t.condition, "live");
        let level = t.level.unwrap();
        assert!((8.0..=80.0).contains(&level));
    }
    assert!(
        (trials[0].level.unwrap() - 40.0).abs() < 1e-12,
        "starts at start"
    );
}

#[test]
fn shuffled_order_is_fixed_by_seed_and_subject_and_replays() {
    let text = LIVE
        .replace(
            "clips = [\"walk\", \"dance\"]",
            "clips = [\"dance\", \"walk\"]",
        )
        .replace("order = \"in_turn\"", "order = \"shuffled\"");
    let study = parse(&text).unwrap();
    let firsts: Vec<String> = (0..16)
        .map(|s| answer_all(&study, s)[0].reference.clone())
        .collect();
    assert!(
        firsts.iter().any(|r| r == "walk/reference")
            && firsts.iter().any(|r| r == "dance/reference"),
        "subjects get different orders: {firsts:?}"
    );
    for s in 0..4 {
        let a = answer_all(&study, s);
        assert_eq!(
            a,
            answer_all(&study, s),
            "same seed and subject, same trials"
        );
        // In turn within the drawn order: every two trials show both clips.
        for pair in a.chunks(2).filter(|p| p.len() == 2) {
            assert_ne!(pair[0].reference, pair[1].reference);
        }
        assert!(
            a.iter()
                .all(|t| t.reference == a[t.index as usize % 2].reference)
        );
    }
    // Replay regenerates every trial exactly (resume).
    let mut first = Session::new(&study, 2).unwrap();
    let mut log = Vec::new();
    let mut rng = StudyRng::new(9, &[]);
    while let Some(t) = first.next_trial(0).unwrap() {
        let r = Response {
            answer: Answer::Choice(if rng.coin() {
                t.reference_position
            } else {
                t.reference_position.other()
            }),
            response_time_ms: 5,
            replays: 0,
            dropped_frames: 0,
        };
        let o = first.respond(&r).unwrap();
        log.push((t, r, o));
    }
    let mut again = Session::new(&study, 2).unwrap();
    for (t, r, o) in &log {
        again.replay(t, r, o).unwrap();
    }
    assert_eq!(again.next_trial(0).unwrap(), None);
    // A logged stimulus of another codec is a replay mismatch.
    let mut edited = Session::new(&study, 2).unwrap();
    let mut t = log[0].0.clone();
    t.stimulus = t.stimulus.replace("wavelet-perceptual", "spiht");
    let err = edited.replay(&t, &log[0].1, &log[0].2).unwrap_err();
    assert!(err.to_string().contains("stimulus"), "{err}");
}

/// With `detection = "error"` the observer's answers follow the measured error it is given,
/// not the level: at an error far above α it is almost always right, far below it guesses.
#[test]
fn observer_detects_the_measured_error() {
    let study = live();
    let mut session = Session::new(&study, 0).unwrap();
    let trial = session.next_trial(0).unwrap().unwrap();
    let obs = Observer::new(&study, 1, 0);
    let correct_share = |error: f64| {
        let mut n = 0;
        for i in 0..2000 {
            let mut t = trial.clone();
            t.index = i;
            let r = obs.respond_measured(&t, Some(error)).unwrap();
            if r.answer == Answer::Choice(t.reference_position) {
                n += 1;
            }
        }
        f64::from(n) / 2000.0
    };
    let f = obs.psychometric();
    for e in [0.2, 1.5, 6.0] {
        let p = correct_share(e);
        assert!(
            (p - f.p_correct(e)).abs() < 0.035,
            "error {e}: {p} vs {}",
            f.p_correct(e)
        );
    }
    // Without a measured error there is nothing to detect: the live stimulus is not in the
    // manifest.
    assert!(obs.respond(&trial).is_err());
    // The same draw with and without detection by level: only the input differs.
    let by_level = parse(&LIVE.replace("detection = \"error\"", "detection = \"level\"")).unwrap();
    let obs_level = Observer::new(&by_level, 1, 0);
    let a = obs_level.respond(&trial).unwrap();
    let b = obs_level.respond_measured(&trial, Some(1e9)).unwrap();
    assert_eq!(a, b, "detection by level ignores the measured error");
}

/// A runner prepares the next live stimulus while the subject watches: the lookahead names the
/// next clip at the level a correct and a wrong answer lead to, and one of them is the trial
/// that really follows.
#[test]
fn lookahead_names_the_next_clip_at_both_possible_levels() {
    let study = live();
    let mut session = Session::new(&study, 2).unwrap();
    let mut rng = StudyRng::new(11, &[]);
    let mut two_levels = 0;
    while let Some(t) = session.next_trial(0).unwrap() {
        let ahead = session.lookahead(0);
        let next_clip = if t.index % 2 == 0 { "dance" } else { "walk" };
        for a in &ahead {
            assert_eq!(a.index, t.index + 1);
            assert_eq!(a.reference, format!("{next_clip}/reference"));
        }
        if let [a, b] = ahead.as_slice() {
            assert_ne!(a.level, b.level, "branches differ in level: {ahead:?}");
            two_levels += 1;
        }
        choose(&mut session, &t, &mut rng, 0.75);
        if let Some(next) = session.next_trial(0).unwrap() {
            assert!(ahead.contains(&next), "{next:?} not in {ahead:?}");
        }
    }
    assert!(two_levels > 5, "a staircase trial has two futures");
}
