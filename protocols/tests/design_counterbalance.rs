//! Counterbalancing (`[design] order = "latin_square"`, `reference_position = "balanced"`):
//! the Williams designs' two balance properties counted over complete blocks of subjects,
//! through the engine's plans as a subject meets them, for every n from 2 to 12; balanced
//! reference sides within and across subjects; resume by replay; `study check`'s problems.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop,
    missing_docs
)]

mod common;

use std::collections::BTreeMap;

use common::parse;
use protocols::design::{balanced_side_of_trial, williams_row, williams_rows};
use protocols::{
    Answer, Arrangement, Block, Position, Protocol, Response, Session, StudyDefinition,
};

const CODECS: [&str; 3] = ["wavelet-perceptual", "wavelet-bone", "wavelet-standard"];
const CRS: [u32; 7] = [10, 20, 30, 40, 50, 60, 70];

/// The first `n` (<= 42) test stimuli of the example manifest.
fn stimuli(n: usize) -> Vec<String> {
    let mut out = Vec::new();
    for clip in ["walk", "dance"] {
        for codec in CODECS {
            for cr in CRS {
                out.push(format!("{clip}/{codec}/cr{cr}"));
            }
        }
    }
    out.truncate(n);
    out
}

fn study(protocol: &str, n: usize, seed: u64, extra: &str) -> StudyDefinition {
    let list: Vec<String> = stimuli(n).iter().map(|s| format!("{s:?}")).collect();
    let scale = if protocol == "dscqs" {
        "[scale]\nkind = \"continuous\"\nmin = 0\nmax = 100\n"
    } else {
        ""
    };
    let text = format!(
        "format_version = 1\nname = \"design\"\nprotocol = \"{protocol}\"\n\
         stimuli = \"stimuli.json\"\nseed = {seed}\n{scale}\
         [conditions]\nstimuli = [{}]\n[presentation]\nreference_position = \"balanced\"\n\
         [design]\norder = \"latin_square\"\n{extra}",
        list.join(", ")
    );
    parse(&text).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// Subject `k`'s test trials (stimulus, block, reference position), as the engine plans them.
fn plan(study: &StudyDefinition, k: u32) -> Vec<(String, Block, Position)> {
    let mut s = Session::new(study, k).unwrap();
    let mut out = Vec::new();
    while let Some(t) = s.next_trial(0).unwrap() {
        out.push((t.stimulus.clone(), t.block, t.reference_position));
        let answer = match study.protocol {
            Protocol::Dscqs => Answer::Pair { a: 50.0, b: 40.0 },
            _ => Answer::Rating(3.0),
        };
        s.respond(&Response {
            answer,
            response_time_ms: 100,
            replays: 0,
            dropped_frames: 0,
        })
        .unwrap();
    }
    out
}

#[test]
fn williams_rows_balance_positions_and_first_order_carryover() {
    for n in 1..=40 {
        let rows = williams_rows(n);
        assert_eq!(rows, if n % 2 == 0 || n == 1 { n } else { 2 * n });
        let mut at = vec![vec![0usize; n]; n];
        let mut follows = vec![vec![0usize; n]; n];
        for r in 0..rows {
            let row = williams_row(n, r);
            let mut sorted = row.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..n).collect::<Vec<_>>(), "n {n} row {r}");
            for (p, &c) in row.iter().enumerate() {
                at[c][p] += 1;
            }
            for w in row.windows(2) {
                follows[w[0]][w[1]] += 1;
            }
        }
        for c in 0..n {
            for p in 0..n {
                assert_eq!(at[c][p], rows / n, "n {n}: condition {c} at position {p}");
            }
            for d in 0..n {
                let want = if c == d { 0 } else { rows / n };
                assert_eq!(follows[c][d], want, "n {n}: {d} right after {c}");
            }
        }
        // Row k + rows is row k again: the next block of subjects repeats the square.
        assert_eq!(williams_row(n, rows + 1), williams_row(n, 1));
    }
}

#[test]
fn engine_plans_are_a_balanced_latin_square_over_a_complete_block_of_subjects() {
    for protocol in ["mos", "dscqs"] {
        for n in 2..=12 {
            let st = study(protocol, n, 20 + n as u64, "");
            let names = stimuli(n);
            let rows = williams_rows(n) as u32;
            // Counted over two complete blocks of subjects: each condition at each position
            // 2 rows/n times, each ordered pair adjacent 2 rows/n times.
            let mut at: BTreeMap<(String, usize), usize> = BTreeMap::new();
            let mut follows: BTreeMap<(String, String), usize> = BTreeMap::new();
            for k in 0..2 * rows {
                let p: Vec<String> = plan(&st, k).into_iter().map(|(s, _, _)| s).collect();
                assert_eq!(p.len(), n);
                for (i, s) in p.iter().enumerate() {
                    *at.entry((s.clone(), i)).or_default() += 1;
                }
                for w in p.windows(2) {
                    *follows.entry((w[0].clone(), w[1].clone())).or_default() += 1;
                }
            }
            let per = 2 * rows as usize / n;
            for a in &names {
                for i in 0..n {
                    assert_eq!(
                        at.get(&(a.clone(), i)),
                        Some(&per),
                        "{protocol} n {n} {a} at {i}"
                    );
                }
                for b in &names {
                    let got = follows.get(&(a.clone(), b.clone())).copied().unwrap_or(0);
                    assert_eq!(
                        got,
                        if a == b { 0 } else { per },
                        "{protocol} n {n} {a}->{b}"
                    );
                }
            }
        }
    }
}

#[test]
fn hidden_repeats_and_familiarization_keep_the_subjects_row() {
    let st = study(
        "mos",
        6,
        9,
        "[session]\nhidden_repeats = 2\nfamiliarization_stimuli = [\"dance/wavelet-bone/cr70\"]\n",
    );
    let names = stimuli(6);
    for k in 0..6 {
        let p = plan(&st, k);
        assert_eq!(p[0].1, Block::Familiarization);
        let test: Vec<&str> = p
            .iter()
            .filter(|t| t.1 == Block::Test)
            .map(|t| t.0.as_str())
            .collect();
        let want: Vec<&str> = williams_row(6, k as usize)
            .into_iter()
            .map(|c| names[c].as_str())
            .collect();
        assert_eq!(test, want, "subject {k}");
        assert_eq!(p.iter().filter(|t| t.1 == Block::HiddenRepeat).count(), 2);
    }
}

#[test]
fn balanced_sides_within_and_across_subjects_over_seeds() {
    for seed in 0..25u64 {
        for n in [2usize, 5, 8, 11] {
            for protocol in ["mos", "dscqs"] {
                let st = study(protocol, n, seed, "[session]\nhidden_repeats = 1\n");
                let first = match protocol {
                    "dscqs" => Position::A,
                    _ => Position::Left,
                };
                let mut per_condition: BTreeMap<String, [usize; 2]> = BTreeMap::new();
                for k in 0..4u32 {
                    let p = plan(&st, k);
                    let test: Vec<_> = p.iter().filter(|t| t.1 == Block::Test).collect();
                    let on_first = test.iter().filter(|t| t.2 == first).count();
                    assert!(
                        on_first.abs_diff(n - on_first) <= 1,
                        "seed {seed} n {n} subject {k}: {on_first} of {n} on {first}"
                    );
                    for t in &test {
                        per_condition.entry(t.0.clone()).or_default()[usize::from(t.2 != first)] +=
                            1;
                    }
                    // The hidden repeat shows the reference on the other side.
                    let rep = p.iter().find(|t| t.1 == Block::HiddenRepeat).unwrap();
                    let orig = test.iter().find(|t| t.0 == rep.0).unwrap();
                    assert_eq!(rep.2, orig.2.other());
                }
                // Over two pairs of subjects every condition showed its reference twice on
                // each side.
                assert!(
                    per_condition.values().all(|c| *c == [2, 2]),
                    "seed {seed} n {n}"
                );
            }
        }
    }
}

#[test]
fn balanced_staircase_sides_per_block_of_four_and_mirrored_between_subjects() {
    let mut first_in_position = [0usize; 4];
    for seed in 0..50u64 {
        for k in 0..6u32 {
            let sides: Vec<Position> = (0..40)
                .map(|i| balanced_side_of_trial(seed, k, i, Arrangement::SideBySide))
                .collect();
            for block in sides.chunks(4) {
                assert_eq!(block.iter().filter(|p| **p == Position::Left).count(), 2);
            }
            if k % 2 == 1 {
                let before: Vec<Position> = (0..40)
                    .map(|i| balanced_side_of_trial(seed, k - 1, i, Arrangement::SideBySide))
                    .collect();
                assert!(sides.iter().zip(&before).all(|(a, b)| *a == b.other()));
            }
            for (i, p) in sides.iter().take(4).enumerate() {
                first_in_position[i] += usize::from(*p == Position::Left);
            }
        }
    }
    // Not a fixed pattern: each position of a block shows Left in about half the sessions
    // (300 sessions, so 150 +- about 4 SD of 8.7).
    assert!(
        first_in_position.iter().all(|&c| (115..=185).contains(&c)),
        "{first_in_position:?}"
    );
}

#[test]
fn a_latin_square_session_resumes_by_replay() {
    let st = study("dscqs", 7, 3, "[session]\nhidden_repeats = 2\n");
    for k in [0u32, 5, 13] {
        let mut live = Session::new(&st, k).unwrap();
        let mut log = Vec::new();
        while let Some(t) = live.next_trial(0).unwrap() {
            let r = Response {
                answer: Answer::Pair {
                    a: f64::from(t.index % 100),
                    b: 30.0,
                },
                response_time_ms: 1,
                replays: 0,
                dropped_frames: 0,
            };
            let o = live.respond(&r).unwrap();
            log.push((t, r, o));
        }
        let mut again = Session::new(&st, k).unwrap();
        for (t, r, o) in &log {
            again.replay(t, r, o).unwrap();
        }
        assert_eq!(again.next_trial(0).unwrap(), None);
    }
}

#[test]
fn study_check_lists_design_problems() {
    let base = "format_version = 1\nname = \"s\"\nprotocol = \"mos\"\nstimuli = \"stimuli.json\"\n\
                seed = 1\n[conditions]\nstimuli = [\"walk/wavelet-bone/cr10\"]\n";
    let err = parse(&format!(
        "{base}[presentation]\nreference_position = \"sometimes\"\n[design]\norder = \"latin\"\nblock = 3\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(err.contains("3 problem(s)"), "{err}");
    assert!(
        err.contains("design.order: expected one of random, latin_square, got \"latin\""),
        "{err}"
    );
    assert!(err.contains("design.block: unknown key"), "{err}");
    assert!(
        err.contains("presentation.reference_position:") && err.contains("\"balanced\""),
        "{err}"
    );
    // Served plan groups must complete the square: 3 conditions, 6 rows.
    let three = "format_version = 1\nname = \"s\"\nprotocol = \"mos\"\nstimuli = \"stimuli.json\"\n\
                 seed = 1\n[conditions]\nstimuli = [\"walk/wavelet-bone/cr10\", \"walk/wavelet-bone/cr20\", \
                 \"walk/wavelet-bone/cr30\"]\n[design]\norder = \"latin_square\"\n";
    let err = parse(&format!("{three}[crowdsourcing]\ngroups = 4\n"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(
            "crowdsourcing.groups: 4 plan groups do not complete the Latin square's 6 rows"
        ),
        "{err}"
    );
    parse(&format!("{three}[crowdsourcing]\ngroups = 12\n")).unwrap();
    let stair = common::example_text("staircase.toml") + "\n[design]\norder = \"latin_square\"\n";
    let err = parse(&stair).unwrap_err().to_string();
    assert!(
        err.contains("design.order: a staircase decides each trial"),
        "{err}"
    );
}

#[test]
fn a_balanced_staircase_session_takes_its_sides_from_the_blocks() {
    let text = common::example_text("staircase.toml").replace(
        "reference_position = \"random\"",
        "reference_position = \"balanced\"",
    );
    let st = parse(&text).unwrap();
    for k in 0..3u32 {
        let mut s = Session::new(&st, k).unwrap();
        let mut n = 0u32;
        while let Some(t) = s.next_trial(0).unwrap() {
            assert_eq!(
                t.reference_position,
                balanced_side_of_trial(st.seed, k, t.index, Arrangement::SideBySide)
            );
            // Always right: the staircase comes down, and the session ends by its rules.
            let answer = Answer::Choice(t.reference_position);
            s.respond(&Response {
                answer,
                response_time_ms: 1,
                replays: 0,
                dropped_frames: 0,
            })
            .unwrap();
            n += 1;
        }
        assert!(n >= 8, "{n} trials");
    }
}

#[test]
fn viewing_conditions_are_read_converted_and_checked() {
    let base = "format_version = 1\nname = \"s\"\nprotocol = \"mos\"\nstimuli = \"stimuli.json\"\n\
                seed = 1\n[conditions]\nstimuli = [\"walk/wavelet-bone/cr10\"]\n";
    let st = parse(&format!(
        "{base}[viewing]\ndistance_cm = 120\nscreen_size_cm = [80, 45]\nroom_illuminance_lux = 0\n"
    ))
    .unwrap();
    let v = st.viewing.unwrap();
    assert_eq!(v.distance_cm(), Some(120.0));
    assert_eq!(
        v.describe(),
        vec![
            ("viewing distance", "120 cm (2.667 H)".to_string()),
            ("display", "80 × 45 cm".to_string()),
            ("room illumination", "0 lux".to_string()),
        ]
    );
    let err = parse(&format!(
        "{base}[viewing]\ndistance_ph = 3\ndistance_cm = 100\npeak_luminance_cd_m2 = 100\n\
         background_luminance_cd_m2 = 200\nroom_illuminance_lux = -1\nscreen_resolution = [1920.5, 1080]\n\
         brightness = 1\n"
    ))
    .unwrap_err()
    .to_string();
    for want in [
        "viewing.distance_cm: give the distance once",
        "viewing.background_luminance_cd_m2: 200 cd/m² is above the peak luminance 100 cd/m²",
        "viewing.room_illuminance_lux: -1 is outside 0..=100000 lux",
        "viewing.screen_resolution: expected [width, height] in whole pixels",
        "viewing.brightness: unknown key",
        "viewing.distance_ph: a distance in picture heights needs the screen's size",
    ] {
        assert!(err.contains(want), "{want}\n{err}");
    }
    assert!(err.contains("6 problem(s)"), "{err}");
    let err = parse(&format!("{base}[viewing]\n"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("viewing: states no condition"), "{err}");
}

#[test]
fn catch_trials_in_design_are_the_one_list_every_runner_and_the_report_use() {
    let base = "format_version = 1\nname = \"s\"\nprotocol = \"mos\"\nstimuli = \"stimuli.json\"\n\
                seed = 1\n[conditions]\nstimuli = [\"walk/wavelet-bone/cr10\", \"walk/wavelet-bone/cr70\"]\n";
    let st = parse(&format!(
        "{base}[design]\nmax_catch_failures = 1\n[[design.catch]]\nstimulus = \"walk/wavelet-bone/cr70\"\nmax = 2\n"
    ))
    .unwrap();
    let g = st.crowdsourcing.gold_of("walk/wavelet-bone/cr70").unwrap();
    assert!(g.passes(2.0) && !g.passes(2.5));
    assert_eq!(st.crowdsourcing.max_gold_failures, 1);
    // The older [crowdsourcing] spelling still reads, into the same list.
    let old = parse(&format!(
        "{base}[crowdsourcing]\nmax_gold_failures = 1\n[[crowdsourcing.gold]]\nstimulus = \"walk/wavelet-bone/cr70\"\nmax = 2\n"
    ))
    .unwrap();
    assert_eq!(old.crowdsourcing.gold, st.crowdsourcing.gold);
    let err = parse(&format!(
        "{base}[crowdsourcing]\nmax_gold_failures = 2\n[[crowdsourcing.gold]]\nstimulus = \"walk/wavelet-bone/cr70\"\nmax = 2\n\
         [design]\nmax_catch_failures = 1\n[[design.catch]]\nstimulus = \"walk/wavelet-bone/cr10\"\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("design.catch: catch trials are given twice"),
        "{err}"
    );
    assert!(
        err.contains("design.max_catch_failures: given twice"),
        "{err}"
    );
    assert!(
        err.contains("design.catch[0]: give min (an identical pair) or max"),
        "{err}"
    );
    let stair = common::example_text("staircase.toml")
        + "\n[[design.catch]]\nstimulus = \"walk/reference\"\nmin = 4\n";
    let err = parse(&stair).unwrap_err().to_string();
    assert!(
        err.contains("design.catch: catch (gold) trials are rated conditions"),
        "{err}"
    );
}

/// `[[design.groups]]`: each group's sessions are planned over its own conditions (and every
/// catch trial), in `[conditions]` order, so a group's Latin square is complete over its own
/// block of subjects.
#[test]
fn between_subject_groups_plan_their_own_conditions() {
    let all = stimuli(7);
    let group_a: Vec<String> = vec![all[4].clone(), all[0].clone(), all[2].clone()];
    let group_b: Vec<String> = vec![all[1].clone(), all[3].clone(), all[5].clone()];
    let quoted = |v: &[String]| {
        v.iter()
            .map(|s| format!("{s:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let extra = format!(
        "[[design.catch]]\nstimulus = {:?}\nmax = 2\n\
         [[design.groups]]\nname = \"a\"\nstimuli = [{}]\nquota = 12\n\
         [[design.groups]]\nname = \"b-2\"\nstimuli = [{}]\n",
        all[6],
        quoted(&group_a),
        quoted(&group_b)
    );
    let study = study("mos", 7, 11, &extra);
    let groups = &study.design.groups;
    assert_eq!(groups.len(), 2);
    assert_eq!((groups[0].name.as_str(), groups[0].quota), ("a", Some(12)));
    assert_eq!((groups[1].name.as_str(), groups[1].quota), ("b-2", None));

    // Group a: its three conditions and the catch trial, in [conditions] order.
    let a = study.for_group(Some("a")).unwrap();
    let got: Vec<&str> = a.conditions.iter().map(|c| c.stimulus.as_str()).collect();
    assert_eq!(
        got,
        [&all[0], &all[2], &all[4], &all[6]].map(String::as_str)
    );
    // A complete block of the group's subjects (4 conditions: 4 rows) is a Latin square over
    // exactly those conditions.
    let rows = williams_rows(4);
    let mut at_position = vec![BTreeMap::<String, u32>::new(); 4];
    for k in 0..rows as u32 {
        let test: Vec<String> = plan(&a, k)
            .into_iter()
            .filter(|(_, b, _)| *b == Block::Test)
            .map(|(s, _, _)| s)
            .collect();
        assert_eq!(test.len(), 4, "subject {k}: {test:?}");
        for (p, s) in test.into_iter().enumerate() {
            *at_position[p].entry(s).or_default() += 1;
        }
    }
    for counts in &at_position {
        assert_eq!(counts.len(), 4, "{counts:?}");
        assert!(counts.values().all(|&n| n == 1), "{counts:?}");
    }
    let b = study.for_group(Some("b-2")).unwrap();
    let got: Vec<&str> = b.conditions.iter().map(|c| c.stimulus.as_str()).collect();
    assert_eq!(
        got,
        [&all[1], &all[3], &all[5], &all[6]].map(String::as_str)
    );

    // A session must name its group, one of the study's; a study without groups takes none.
    assert!(study.for_group(None).unwrap_err().contains("a, b-2"));
    assert!(
        study
            .for_group(Some("c"))
            .unwrap_err()
            .contains("no group \"c\"")
    );
    let plain = self::study("mos", 3, 1, "");
    assert!(plain.for_group(None).is_ok());
    assert!(plain.for_group(Some("a")).is_err());
}

/// `study check`'s problems of `[[design.groups]]`, all in its one list.
#[test]
fn between_subject_groups_problems_are_listed() {
    let base = "format_version = 1\nname = \"s\"\nprotocol = \"mos\"\nstimuli = \"stimuli.json\"\n\
                seed = 1\n[conditions]\nstimuli = [\"walk/wavelet-bone/cr10\", \
                \"walk/wavelet-bone/cr20\", \"walk/wavelet-bone/cr30\"]\n";
    let got = common::issues(&format!(
        "{base}[[design.groups]]\nname = \"a b\"\nstimuli = [\"walk/wavelet-bone/cr10\", \
         \"walk/wavelet-bone/cr10\", \"walk/nope\"]\nquota = 0\ncolour = 1\n\
         [[design.groups]]\nname = \"x\"\nstimuli = []\n\
         [[design.groups]]\nname = \"x\"\nstimuli = [\"walk/wavelet-bone/cr20\"]\n\
         [[design.groups]]\nstimuli = [\"walk/wavelet-bone/cr20\"]\n"
    ));
    let has = |key: &str, words: &str| common::has(&got, key, words);
    assert!(has("design.groups[0].name", "use 1-32 letters"), "{got:?}");
    assert!(has("design.groups[0].stimuli", "listed twice"), "{got:?}");
    assert!(
        has("design.groups[0].stimuli", "\"walk/nope\" is not one of"),
        "{got:?}"
    );
    assert!(has("design.groups[0].quota", "at least 1"), "{got:?}");
    assert!(has("design.groups[0].colour", "unknown key"), "{got:?}");
    assert!(
        has("design.groups[1].stimuli", "at least one condition"),
        "{got:?}"
    );
    assert!(has("design.groups[2].name", "names two groups"), "{got:?}");
    assert!(has("design.groups[3].name", "required"), "{got:?}");
    assert_eq!(got.len(), 8, "{got:?}");
    // Every condition is in some group.
    let got = common::issues(&format!(
        "{base}[[design.groups]]\nname = \"a\"\nstimuli = [\"walk/wavelet-bone/cr10\"]\n\
         [[design.groups]]\nname = \"b\"\nstimuli = [\"walk/wavelet-bone/cr20\"]\n"
    ));
    assert_eq!(got.len(), 1, "{got:?}");
    assert!(
        common::has(
            &got,
            "design.groups",
            "\"walk/wavelet-bone/cr30\" is in no group"
        ),
        "{got:?}"
    );
    // Not a table array, and not in a staircase.
    let got = common::issues(&format!("{base}[design]\ngroups = 2\n"));
    assert!(
        common::has(&got, "design.groups", "an array of tables"),
        "{got:?}"
    );
    let stair = common::example_text("staircase.toml")
        + "\n[[design.groups]]\nname = \"a\"\nstimuli = [\"x\"]\n";
    let got = common::issues(&stair);
    assert!(
        common::has(&got, "design.groups", "a staircase study's tracks"),
        "{got:?}"
    );
}
