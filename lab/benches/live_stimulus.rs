//! How long a subject waits, after answering a live (codec-in-the-loop) staircase trial, for
//! the next trial's stimulus: a 10 s clip (the first or the last 1 200 frames of the shared
//! `lambada`, 120 Hz, taking turns) coded by the `primitive` codec at a new `t_L`, with a
//! database trained on the other shared clips. Target (issue #8): ready ≤ 50 ms after the
//! response.
//!
//! - `live/new_level_cold`: a level nobody encoded yet, in the foreground (encode, decode,
//!   error measure): what the subject would wait without prefetching.
//! - `live/prefetch_both_branches`: the window's background work during a trial: the levels a
//!   correct and a wrong answer lead to (`Session::lookahead`), encoded one after the other.
//!   The window accepts no answer before the stimuli have played, so this has the whole
//!   presentation (10 s here) to finish.
//! - `live/after_response_prefetched`: the answer's next trial once that prefetch has ended:
//!   the time from the response to a ready stimulus.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use codecs::primitives::{Database, TrainParams};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use lab::StudyFile;
use lab::live::LiveStimuli;
use motion::{Clip, data, io};
use protocols::{Answer, Response, Session, Trial};

const FRAMES: usize = 1200;

/// A study folder with the 10 s source clip, its manifest, the database and the study file.
fn study_dir() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("live-stimulus-bench-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("clips")).unwrap();
    let mut source = None;
    let mut others: Vec<Clip> = Vec::new();
    for f in data::shared_clips() {
        let clip = io::read_clip(f.asf.as_deref(), &f.motion).unwrap();
        if f.name == "lambada" {
            source = Some(clip);
        } else {
            others.push(clip);
        }
    }
    let clip = source.expect("the shared clips include lambada.amc");
    assert!(
        clip.frames() >= FRAMES,
        "lambada has {} frames",
        clip.frames()
    );
    // Two 10 s stimuli that take turns (as the thesis's five motions do): the first and the
    // last 1 200 frames, so every branch of the lookahead is a level not encoded yet.
    let n = clip.frames();
    for (name, from) in [("start", 0), ("end", n - FRAMES)] {
        io::write_clip(
            &clip.excerpt(from..from + FRAMES),
            &dir.join(format!("clips/{name}.amc")),
            Some(&dir.join("clips/lambada.asf")),
            files::Mode::Replace,
        )
        .unwrap();
    }
    let refs: Vec<&Clip> = others.iter().collect();
    Database::train(&refs, &TrainParams::default(), |_, _| {})
        .write(&dir.join("others.mpdb"), files::Mode::Replace)
        .unwrap();
    std::fs::write(
        dir.join("stimuli.json"),
        r#"{"version": 1, "stimuli": [
        {"id": "start/reference", "clip": "start", "codec": "reference", "achieved_cr": 1.0,
         "file": "clips/start.amc", "skeleton": "clips/lambada.asf"},
        {"id": "end/reference", "clip": "end", "codec": "reference", "achieved_cr": 1.0,
         "file": "clips/end.amc", "skeleton": "clips/lambada.asf"}]}"#,
    )
    .unwrap();
    std::fs::write(
        dir.join("study.toml"),
        r#"format_version = 1
name = "live-bench"
protocol = "staircase"
stimuli = "stimuli.json"
seed = 7

[presentation]
arrangement = "side_by_side"
reference_position = "random"

[staircase]
param = "t_l"
codec = "primitive"
start = 0.02
step = 0.002
min = 0.002
max = 0.05
stop_reversals = 12
max_trials = 80

[staircase.live]
clips = ["start", "end"]
database = "others.mpdb"
"#,
    )
    .unwrap();
    dir
}

fn open(study: &StudyFile) -> LiveStimuli {
    LiveStimuli::from_study(study).unwrap().unwrap()
}

/// A fresh cache that has shown the first trial; the session waits for its answer.
fn first_trial(study: &StudyFile) -> (LiveStimuli, Session, Trial) {
    let live = open(study);
    let mut session = Session::new(&study.definition, 0).unwrap();
    let t = session.next_trial(0).unwrap().unwrap();
    live.resolve(&t).unwrap();
    (live, session, t)
}

/// Answers `t` wrongly (the level moves up) and returns the next trial.
fn answer(session: &mut Session, t: &Trial) -> Trial {
    session
        .respond(&Response {
            answer: Answer::Choice(t.reference_position.other()),
            response_time_ms: 800,
            replays: 0,
            dropped_frames: 0,
        })
        .unwrap();
    session.next_trial(0).unwrap().unwrap()
}

fn bench(c: &mut Criterion) {
    let dir = study_dir();
    let study = StudyFile::load(&dir.join("study.toml")).unwrap();
    let mut g = c.benchmark_group("live");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    g.bench_function("new_level_cold", |b| {
        b.iter_batched(
            || {
                let (live, mut session, t) = first_trial(&study);
                let next = answer(&mut session, &t);
                (live, next)
            },
            |(live, next)| {
                let s = live.resolve(&next).unwrap();
                (live, black_box(s))
            },
            BatchSize::PerIteration,
        );
    });
    g.bench_function("prefetch_both_branches", |b| {
        b.iter_batched(
            || first_trial(&study),
            |(mut live, session, _)| {
                live.prefetch(&session.lookahead(0));
                live.wait_prefetch();
                live
            },
            BatchSize::PerIteration,
        );
    });
    g.bench_function("after_response_prefetched", |b| {
        b.iter_batched(
            || {
                let (mut live, mut session, t) = first_trial(&study);
                live.prefetch(&session.lookahead(0));
                live.wait_prefetch();
                let cached = live.cached();
                let next = answer(&mut session, &t);
                (live, next, cached)
            },
            |(live, next, cached)| {
                let s = live.resolve(&next).unwrap();
                assert_eq!(live.cached(), cached, "the next trial was prefetched");
                black_box(s);
                live
            },
            BatchSize::PerIteration,
        );
    });
    g.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
