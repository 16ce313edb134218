//! The single- and degradation-category rating methods of ITU-T P.910: ACR (one stimulus,
//! five quality grades), ACR-HR (the clips' references rated among the tests as hidden
//! references) and DCR (the labelled reference, then the test, five impairment categories).
//! Their study-file rules (each mistake in `study check`'s one list), their plans (every
//! condition once, hidden repeats, nothing random where nothing is placed), their scoring
//! and their replay.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::collections::BTreeMap;

use common::{has, issues, parse};
use protocols::Session;
use protocols::record::{Answer, Arrangement, Block, Position, Protocol, Response};
use protocols::rng::StudyRng;
use protocols::study::ReferencePlacement;
use protocols::texts::{default_instructions, grade_word, scale_words};

const ACR_HR: &str = r#"
format_version = 1
name = "acr"
protocol = "acr"
stimuli = "stimuli.json"
seed = 11

[conditions]
clips = ["walk", "dance"]
codecs = ["wavelet-perceptual"]
target_cr = [10, 30, 50]
hidden_reference = true

[session]
familiarization = 2
hidden_repeats = 3
"#;

const DCR: &str = r#"
format_version = 1
name = "dcr"
protocol = "dcr"
stimuli = "stimuli.json"
seed = 12

[conditions]
stimuli = ["walk/wavelet-perceptual/cr10", "walk/wavelet-perceptual/cr50", "dance/wavelet-perceptual/cr30"]

[session]
hidden_repeats = 1
"#;

fn rating(v: f64) -> Response {
    Response {
        answer: Answer::Rating(v),
        response_time_ms: 900,
        replays: 0,
        dropped_frames: 0,
    }
}

#[test]
fn acr_hr_rates_each_clips_reference_as_a_condition() {
    let s = parse(ACR_HR).unwrap();
    assert_eq!(s.protocol, Protocol::Acr);
    assert_eq!(s.presentation.arrangement, Arrangement::Single);
    assert_eq!(
        s.presentation.reference_position,
        ReferencePlacement::Fixed(Position::Hidden)
    );
    assert_eq!(s.presentation.labels, None, "ACR shows nothing to label");
    // P.910's five grades by default.
    assert_eq!(
        (s.scale.min, s.scale.max, s.scale.step),
        (1.0, 5.0, Some(1.0))
    );
    assert_eq!(
        scale_words(&s),
        ["Excellent", "Good", "Fair", "Poor", "Bad"]
    );
    let ids: Vec<&str> = s.conditions.iter().map(|c| c.stimulus.as_str()).collect();
    assert_eq!(ids.len(), 8, "{ids:?}");
    // The grid's six tests, then each clip's reference once, in the order the clips come.
    assert_eq!(&ids[6..], ["walk/reference", "dance/reference"]);
    for c in &s.conditions[6..] {
        assert_eq!(
            c.stimulus, c.reference,
            "a hidden reference is its own reference"
        );
    }
    // Listing a reference by id is the same thing.
    let listed = ACR_HR
        .replace(
            "clips = [\"walk\", \"dance\"]\ncodecs = [\"wavelet-perceptual\"]\ntarget_cr = [10, 30, 50]\nhidden_reference = true",
            "stimuli = [\"walk/wavelet-perceptual/cr10\", \"walk/reference\"]",
        )
        .replace("hidden_repeats = 3", "hidden_repeats = 1");
    let s = parse(&listed).unwrap();
    assert_eq!(s.conditions[1].stimulus, "walk/reference");
    assert!(
        default_instructions(&s).contains("Each trial shows one motion"),
        "{}",
        default_instructions(&s)
    );
}

#[test]
fn only_acr_rates_references_and_every_misfit_key_is_listed_at_once() {
    // MOS (and DSCQS, DCR) show the reference beside or before the test: a reference as a
    // condition is still refused there, with the way to do it.
    let mos = ACR_HR.replace("protocol = \"acr\"", "protocol = \"mos\"");
    let got = issues(&mos);
    assert!(
        has(&got, "conditions.hidden_reference", "only an ACR study"),
        "{got:#?}"
    );
    let mos_listed = ACR_HR.replace("protocol = \"acr\"", "protocol = \"mos\"").replace(
        "clips = [\"walk\", \"dance\"]\ncodecs = [\"wavelet-perceptual\"]\ntarget_cr = [10, 30, 50]\nhidden_reference = true",
        "stimuli = [\"walk/wavelet-perceptual/cr10\", \"walk/reference\", \"walk/wavelet-perceptual/cr30\"]",
    );
    let got = issues(&mos_listed);
    assert!(
        has(
            &got,
            "conditions.stimuli[1]",
            "only an ACR or a pair comparison study shows references"
        ),
        "{got:#?}"
    );
    // ACR: no reference to place or label, no grey between stimuli, one arrangement.
    let acr = ACR_HR.replace(
        "[session]",
        "[presentation]\narrangement = \"side_by_side\"\nreference_position = \"left\"\nlabels = true\n\n[session]",
    );
    let got = issues(&acr);
    assert!(has(&got, "presentation.arrangement", "single"), "{got:#?}");
    let acr = ACR_HR.replace(
        "[session]",
        "[presentation]\nreference_position = \"left\"\nlabels = true\ngrey_ms = 300\n\n[session]",
    );
    let got = issues(&acr);
    for (key, words) in [
        ("presentation.reference_position", "ACR shows no reference"),
        ("presentation.labels", "ACR shows one motion"),
        ("presentation.grey_ms", "one stimulus"),
    ] {
        assert!(has(&got, key, words), "missing {key}: {got:#?}");
    }
    assert_eq!(got.len(), 3, "{got:#?}");
}

#[test]
fn dcr_shows_the_labelled_reference_first_on_five_impairment_categories() {
    let s = parse(DCR).unwrap();
    assert_eq!(s.presentation.arrangement, Arrangement::Sequential);
    assert_eq!(
        s.presentation.reference_position,
        ReferencePlacement::Fixed(Position::First)
    );
    assert!(s.presentation.labels.is_some(), "DCR labels the reference");
    let words = scale_words(&s);
    assert_eq!(grade_word(&words, &s.scale, 5.0), Some("Imperceptible"));
    assert_eq!(
        grade_word(&words, &s.scale, 4.0),
        Some("Perceptible but not annoying")
    );
    assert_eq!(grade_word(&words, &s.scale, 1.0), Some("Very annoying"));
    assert_eq!(grade_word(&words, &s.scale, 4.5), None, "between grades");
    let text = default_instructions(&s);
    assert!(
        text.contains("labelled “Original”, then a compressed version"),
        "{text}"
    );
    // Side by side, the reference on a side the study names.
    let side = DCR.replace(
        "[session]",
        "[presentation]\narrangement = \"side_by_side\"\nreference_position = \"right\"\n\n[session]",
    );
    assert_eq!(
        parse(&side).unwrap().presentation.reference_position,
        ReferencePlacement::Fixed(Position::Right)
    );
    // Never second, never drawn at random; never a continuous or other scale; never a
    // hidden reference.
    let bad = DCR
        .replace(
            "[session]",
            "[presentation]\nreference_position = \"second\"\n\n[scale]\nkind = \"continuous\"\n\n[session]",
        )
        .replace(
            "dance/wavelet-perceptual/cr30\"]",
            "dance/wavelet-perceptual/cr30\", \"dance/reference\"]",
        );
    let got = issues(&bad);
    assert!(
        has(&got, "presentation.reference_position", "reference first"),
        "{got:#?}"
    );
    assert!(has(&got, "scale", "five impairment categories"), "{got:#?}");
    assert!(
        has(&got, "conditions.stimuli[3]", "is a reference"),
        "{got:#?}"
    );
    let random = DCR.replace(
        "[session]",
        "[presentation]\nreference_position = \"random\"\n\n[session]",
    );
    assert!(has(
        &issues(&random),
        "presentation.reference_position",
        "reference first"
    ));
}

/// Every condition once per session (hidden references included), the hidden repeats, the
/// familiarization first; every trial single with its reference hidden, and an ACR plan draws
/// no reference side, so it is the same plan whatever the placement code does.
#[test]
fn acr_sessions_plan_every_condition_once_and_replay_exactly() {
    let study = parse(ACR_HR).unwrap();
    for subject in 0..40 {
        let mut s = Session::new(&study, subject).unwrap();
        let mut rng = StudyRng::new(99, &[u64::from(subject)]);
        let mut log = Vec::new();
        while let Some(t) = s.next_trial(0).unwrap() {
            assert_eq!(t.arrangement, Arrangement::Single);
            assert_eq!(t.reference_position, Position::Hidden);
            // Off the scale or the wrong kind of answer: refused, the trial stays.
            assert!(s.respond(&rating(3.5)).is_err());
            assert!(
                s.respond(&Response {
                    answer: Answer::Choice(Position::Left),
                    ..rating(3.0)
                })
                .is_err()
            );
            let r = rating(f64::from(1 + rng.below(5) as u32));
            let o = s.respond(&r).unwrap();
            let Answer::Rating(v) = r.answer else {
                unreachable!()
            };
            assert_eq!(
                o.score.to_bits(),
                v.to_bits(),
                "ACR scores the rating itself"
            );
            log.push((t, r, o));
        }
        let mut per: BTreeMap<&str, (usize, usize)> = BTreeMap::new();
        for (t, _, _) in &log {
            let e = per.entry(t.stimulus.as_str()).or_default();
            match t.block {
                Block::Test => e.0 += 1,
                Block::HiddenRepeat => e.1 += 1,
                Block::Familiarization => {}
            }
        }
        assert_eq!(per.len(), 8);
        assert!(per.values().all(|&(tests, _)| tests == 1), "{per:?}");
        assert_eq!(per.values().map(|&(_, r)| r).sum::<usize>(), 3);
        assert_eq!(log.len(), 2 + 8 + 3);
        let fam = log
            .iter()
            .take_while(|(t, _, _)| t.block == Block::Familiarization)
            .count();
        assert_eq!(fam, 2);
        // Resume = replay of the log.
        let mut again = Session::new(&study, subject).unwrap();
        for (t, r, o) in &log {
            again.replay(t, r, o).unwrap();
        }
        assert_eq!(again.next_trial(0).unwrap(), None);
    }
}

#[test]
fn dcr_scores_one_impairment_rating_with_the_reference_first() {
    let study = parse(DCR).unwrap();
    let mut s = Session::new(&study, 4).unwrap();
    let mut n = 0;
    while let Some(t) = s.next_trial(0).unwrap() {
        assert_eq!(
            (t.arrangement, t.reference_position),
            (Arrangement::Sequential, Position::First)
        );
        assert!(
            s.respond(&Response {
                answer: Answer::Pair { a: 5.0, b: 3.0 },
                ..rating(3.0)
            })
            .is_err(),
            "DCR takes one rating"
        );
        let o = s.respond(&rating(2.0)).unwrap();
        assert_eq!((o.score, o.score_reference), (2.0, None));
        n += 1;
    }
    assert_eq!(n, 3 + 1);
}

const PC: &str = r#"
format_version = 1
name = "pc"
protocol = "pair_comparison"
stimuli = "stimuli.json"
seed = 13

[conditions]
clips = ["walk", "dance"]
codecs = ["wavelet-perceptual"]
target_cr = [10, 30, 50]
hidden_reference = true

[presentation]
reference_position = "balanced"

[session]
hidden_repeats = 3
"#;

fn choice(p: Position) -> Response {
    Response {
        answer: Answer::Choice(p),
        ..rating(0.0)
    }
}

/// P.910 PC: every unordered pair of a clip's four conditions (its original among them) is
/// one test trial, never a pair across clips; the hidden repeats show a pair again with its
/// sides swapped; the balanced placement shows each pair's second condition on the left for
/// one subject of a pair of subjects and on the right for the other; a choice scores 1 when
/// the `stimulus` column's version was preferred; replay regenerates the session.
#[test]
fn pair_comparison_plans_every_pair_of_a_clip_once_and_scores_the_preferred() {
    let study = parse(PC).unwrap();
    assert_eq!(study.protocol, Protocol::PairComparison);
    assert_eq!(study.presentation.arrangement, Arrangement::SideBySide);
    assert_eq!(study.presentation.labels, None);
    assert_eq!(study.conditions.len(), 8);
    assert_eq!(study.pairs().len(), 12, "6 pairs per clip of 4 conditions");
    let clip = |id: &str| id.split('/').next().unwrap().to_owned();
    let mut sides: BTreeMap<(u32, String), Position> = BTreeMap::new();
    for subject in 0..6 {
        let mut s = Session::new(&study, subject).unwrap();
        let mut log = Vec::new();
        let mut rng = StudyRng::new(7, &[u64::from(subject)]);
        while let Some(t) = s.next_trial(0).unwrap() {
            assert_eq!(clip(&t.stimulus), clip(&t.reference));
            assert_eq!(t.condition, format!("{} vs {}", t.stimulus, t.reference));
            // A rating, or a position of another arrangement: refused, the trial stays.
            assert!(s.respond(&rating(3.0)).is_err());
            assert!(s.respond(&choice(Position::First)).is_err());
            let pick = if rng.coin() {
                Position::Left
            } else {
                Position::Right
            };
            let o = s.respond(&choice(pick)).unwrap();
            let want: f64 = if pick == t.reference_position {
                0.0
            } else {
                1.0
            };
            assert_eq!(o.score.to_bits(), want.to_bits());
            assert_eq!((o.correct, o.reversal), (None, None));
            if t.block == Block::Test {
                sides.insert((subject, t.condition.clone()), t.reference_position);
            }
            log.push((t, choice(pick), o));
        }
        assert_eq!(log.len(), 12 + 3);
        let tests: Vec<&str> = log
            .iter()
            .filter(|(t, _, _)| t.block == Block::Test)
            .map(|(t, _, _)| t.condition.as_str())
            .collect();
        let unique: std::collections::BTreeSet<&str> = tests.iter().copied().collect();
        assert_eq!((tests.len(), unique.len()), (12, 12));
        for (t, _, _) in log
            .iter()
            .filter(|(t, _, _)| t.block == Block::HiddenRepeat)
        {
            let original = log
                .iter()
                .find(|(o, _, _)| o.block == Block::Test && o.condition == t.condition)
                .unwrap();
            assert_eq!(t.reference_position, original.0.reference_position.other());
        }
        // Within a subject the sides are balanced: six of the twelve pairs each way.
        let left = log
            .iter()
            .filter(|(t, _, _)| t.block == Block::Test && t.reference_position == Position::Left)
            .count();
        assert_eq!(left, 6);
        let mut again = Session::new(&study, subject).unwrap();
        for (t, r, o) in &log {
            again.replay(t, r, o).unwrap();
        }
        assert_eq!(again.next_trial(0).unwrap(), None);
    }
    // Across each pair of subjects, each pair's sides are mirrored.
    for k in [0, 2, 4] {
        for ((s, c), p) in sides.iter().filter(|((s, _), _)| *s == k) {
            assert_eq!(sides[&(s + 1, c.clone())], p.other(), "{c}");
        }
    }
    // The originals are among the conditions: the instructions say either may be one.
    let text = default_instructions(&study);
    assert!(
        text.contains("Either of them may be the original motion itself"),
        "{text}"
    );
    assert_eq!(
        protocols::texts::planned_trials(&study),
        protocols::texts::Planned::Exactly(15)
    );
}

/// A Latin square over a pair comparison orders its pairs: across a complete block of
/// subjects every pair is at every position equally often.
#[test]
fn pair_comparison_latin_square_orders_the_pairs() {
    let study = parse(
        &PC.replace(
            "[session]",
            "[design]\norder = \"latin_square\"\n\n[session]",
        )
        .replace("hidden_repeats = 3", "hidden_repeats = 0"),
    )
    .unwrap();
    let n = study.pairs().len();
    let rows = protocols::design::williams_rows(n);
    let mut at: BTreeMap<(String, usize), usize> = BTreeMap::new();
    for subject in 0..rows as u32 {
        let mut s = Session::new(&study, subject).unwrap();
        let mut k = 0;
        while let Some(t) = s.next_trial(0).unwrap() {
            *at.entry((t.condition.clone(), k)).or_default() += 1;
            s.respond(&choice(Position::Left)).unwrap();
            k += 1;
        }
        assert_eq!(k, n);
    }
    assert_eq!(at.len(), n * n);
    assert!(at.values().all(|&c| c == rows / n), "{at:?}");
}

/// Everything a pair comparison has no use for, in `study check`'s one list.
#[test]
fn pair_comparison_rules_are_listed_at_once() {
    let bad = PC
        .replace(
            "reference_position = \"balanced\"",
            "reference_position = \"left\"\nlabels = true",
        )
        .replace(
            "[session]\nhidden_repeats = 3",
            "[scale]\nkind = \"continuous\"\n\n[session]\nhidden_repeats = 3\nfamiliarization = 2",
        );
    let got = issues(&bad);
    for (key, words) in [
        ("presentation.reference_position", "never on a fixed side"),
        ("presentation.labels", "no labelled reference"),
        ("scale", "not for a rating"),
        ("session.familiarization", "not offered"),
    ] {
        assert!(has(&got, key, words), "missing {key}: {got:#?}");
    }
    assert_eq!(got.len(), 4, "{got:#?}");
    // A clip with one condition has nothing to pair; more repeats than pairs.
    let lonely = PC
        .replace(
            "clips = [\"walk\", \"dance\"]\ncodecs = [\"wavelet-perceptual\"]\ntarget_cr = [10, 30, 50]\nhidden_reference = true",
            "stimuli = [\"walk/wavelet-perceptual/cr10\", \"walk/wavelet-perceptual/cr30\", \"dance/wavelet-perceptual/cr30\"]",
        )
        .replace("hidden_repeats = 3", "hidden_repeats = 2");
    let got = issues(&lonely);
    assert!(
        has(
            &got,
            "conditions",
            "\"dance/wavelet-perceptual/cr30\" is the only condition"
        ),
        "{got:#?}"
    );
    assert!(
        has(&got, "session.hidden_repeats", "2 repeats but only 1 pairs"),
        "{got:#?}"
    );
    assert_eq!(got.len(), 2, "{got:#?}");
}

const MUSHRA: &str = r#"
format_version = 1
name = "mushra"
protocol = "mushra"
stimuli = "stimuli.json"
seed = 13

[conditions]
clips = ["walk", "dance"]
codecs = ["wavelet-perceptual"]
target_cr = [10, 30, 50]

[mushra]
anchors = ["walk/wavelet-standard/cr70", "dance/wavelet-standard/cr70"]
"#;

#[test]
fn mushra_takes_bs1534_defaults_and_lists_every_misfit_key_at_once() {
    let s = parse(MUSHRA).unwrap();
    assert_eq!(s.presentation.arrangement, Arrangement::Grid);
    assert_eq!(
        s.presentation.labels, None,
        "the panes are labelled by the window"
    );
    assert_eq!(
        (s.scale.min, s.scale.max, s.scale.step),
        (0.0, 100.0, Some(1.0))
    );
    let m = s.mushra.as_ref().unwrap();
    assert_eq!(
        (m.reference_below, m.anchor_above, m.max_fraction),
        (90.0, 90.0, 0.15)
    );
    assert_eq!(m.anchor_rule, protocols::study::AnchorRule::Report);
    assert_eq!(m.anchors.len(), 2);
    assert_eq!(m.anchors[0].reference, "walk/reference");
    // Every mistake in one list.
    let bad = MUSHRA
        .replace(
            "anchors = [\"walk/wavelet-standard/cr70\", \"dance/wavelet-standard/cr70\"]",
            "anchors = [\"walk/wavelet-perceptual/cr10\", \"walk/reference\", \"nope\"]\nmax_fraction = 1.5\nanchor_rule = \"drop\"",
        )
        .replace(
            "[mushra]",
            "[presentation]\narrangement = \"side_by_side\"\n\n[scale]\nkind = \"categorical\"\nmin = 1\nmax = 5\nstep = 1\n\n[session]\nhidden_repeats = 1\nfamiliarization = 3\n\n[mushra]",
        );
    let got = issues(&bad);
    for (key, words) in [
        ("presentation.arrangement", "grid"),
        ("scale", "continuous 0-100"),
        ("session.hidden_repeats", "remove hidden_repeats"),
        (
            "session.familiarization",
            "3 training screens but only 2 screens",
        ),
        ("mushra.max_fraction", "0..=1"),
        ("mushra.anchor_rule", "report, exclude"),
        ("mushra.anchors[0]", "also a test condition"),
        ("mushra.anchors[1]", "is a reference"),
        ("mushra.anchors[2]", "not in the manifest"),
        (
            "mushra.anchors",
            "no anchor for the clip of reference \"walk/reference\"",
        ),
        (
            "mushra.anchors",
            "no anchor for the clip of reference \"dance/reference\"",
        ),
    ] {
        assert!(has(&got, key, words), "missing {key} ({words}): {got:#?}");
    }
    // No anchor table at all; two anchors of one clip; a grid too large for a screen.
    let got = issues(&MUSHRA.replace(
        "[mushra]\nanchors = [\"walk/wavelet-standard/cr70\", \"dance/wavelet-standard/cr70\"]\n",
        "",
    ));
    assert!(has(&got, "mushra", "missing"), "{got:#?}");
    let got = issues(&MUSHRA.replace(
        "\"dance/wavelet-standard/cr70\"]",
        "\"dance/wavelet-standard/cr70\", \"walk/wavelet-bone/cr70\"]",
    ));
    assert!(has(&got, "mushra.anchors[2]", "two anchors"), "{got:#?}");
    let big = MUSHRA
        .replace(
            "codecs = [\"wavelet-perceptual\"]",
            "codecs = [\"wavelet-perceptual\", \"wavelet-bone\"]",
        )
        .replace(
            "target_cr = [10, 30, 50]",
            "target_cr = [10, 20, 30, 40, 50, 60]",
        );
    let got = issues(&big);
    assert!(
        has(&got, "conditions", "14 rated panes, more than the 12"),
        "{got:#?}"
    );
    // Another protocol does not take [mushra]; catch trials and scenes are not MUSHRA's.
    let got = issues(&MUSHRA.replace("protocol = \"mushra\"", "protocol = \"acr\""));
    assert!(has(&got, "mushra", "only a MUSHRA study"), "{got:#?}");
    let got = issues(&format!(
        "{MUSHRA}\n[[design.catch]]\nstimulus = \"walk/wavelet-perceptual/cr10\"\nmin = 50\n"
    ));
    assert!(has(&got, "design.catch", "MUSHRA screen"), "{got:#?}");
    // Training is a count of whole screens, never a list of stimuli.
    let got = issues(&format!(
        "{MUSHRA}\n[session]\nfamiliarization_stimuli = [\"walk/wavelet-perceptual/cr10\"]\n"
    ));
    assert!(
        has(&got, "session.familiarization_stimuli", "whole screens"),
        "{got:#?}"
    );
}

/// BS.1534-3's training phase: `[session] familiarization = 1` shows the first clip's screen
/// before the test, its panes shuffled by a draw of their own, every row in block
/// `familiarization` and one screen of its own (`screen()` stops at the block, also where
/// the subject's first test screen is the same clip's); the test screens after it are
/// exactly those of the same study without training, and the planned count holds them all.
#[test]
fn mushra_training_screens_come_first_and_leave_the_test_screens_alone() {
    let plain = parse(MUSHRA).unwrap();
    let trained = parse(&format!("{MUSHRA}\n[session]\nfamiliarization = 1\n")).unwrap();
    assert_eq!(trained.mushra.as_ref().unwrap().training_screens, 1);
    assert!(
        trained.familiarization.is_empty(),
        "no familiarization stimuli"
    );
    let mut same_panes = 0;
    let mut firsts = std::collections::BTreeSet::new();
    for subject in 0..40 {
        let run = |study: &protocols::StudyDefinition| {
            let mut s = Session::new(study, subject).unwrap();
            let mut screens: Vec<Vec<protocols::Trial>> = Vec::new();
            while let Some(t) = s.next_trial(0).unwrap() {
                let screen = s.screen();
                assert_eq!(screen[0], t);
                for p in &screen {
                    if p.index != t.index {
                        assert_eq!(s.next_trial(0).unwrap().as_ref(), Some(p));
                    }
                    s.respond(&rating(50.0)).unwrap();
                }
                screens.push(screen);
            }
            screens
        };
        let a = run(&trained);
        let b = run(&plain);
        assert_eq!(a.len(), 3, "a training screen and the two test screens");
        let training = &a[0];
        assert!(training.iter().all(|t| t.block == Block::Familiarization));
        assert!(a[1..].iter().flatten().all(|t| t.block == Block::Test));
        // The training screen is the first clip's, all its panes.
        let walk = b
            .iter()
            .find(|s| s[0].reference == "walk/reference")
            .unwrap();
        assert_eq!(training[0].reference, "walk/reference");
        let stimuli = |s: &[protocols::Trial]| -> std::collections::BTreeSet<String> {
            s.iter().map(|t| t.stimulus.clone()).collect()
        };
        assert_eq!(stimuli(training), stimuli(walk));
        same_panes += usize::from(
            training.iter().map(|t| &t.stimulus).collect::<Vec<_>>()
                == walk.iter().map(|t| &t.stimulus).collect::<Vec<_>>(),
        );
        firsts.insert(b[0][0].reference.clone());
        assert_eq!(
            protocols::texts::planned_trials(&trained).exact(),
            Some(a.iter().map(Vec::len).sum::<usize>() as u32)
        );
        // The test screens are those without training, trial indices shifted by its panes.
        let shift = training.len() as u32;
        let shifted: Vec<Vec<protocols::Trial>> = a[1..]
            .iter()
            .map(|s| {
                s.iter()
                    .map(|t| protocols::Trial {
                        index: t.index - shift,
                        ..t.clone()
                    })
                    .collect()
            })
            .collect();
        assert_eq!(shifted, b, "subject {subject}");
    }
    // Five panes: the same order by chance 1 time in 120; 40 subjects rarely see it twice.
    assert!(
        same_panes <= 2,
        "{same_panes} of 40 training screens in the test's order"
    );
    assert_eq!(
        firsts.len(),
        2,
        "some subjects test the training clip first"
    );
}

#[test]
fn mushra_screens_hold_each_clip_tests_hidden_reference_and_anchor_shuffled_and_replay() {
    let study = parse(MUSHRA).unwrap();
    let mut first_pane_is_reference = 0;
    let mut orders = std::collections::BTreeSet::new();
    let subjects = 60;
    for subject in 0..subjects {
        let mut s = Session::new(&study, subject).unwrap();
        let mut log = Vec::new();
        let mut screens: Vec<Vec<protocols::Trial>> = Vec::new();
        while let Some(t) = s.next_trial(0).unwrap() {
            assert_eq!(t.arrangement, Arrangement::Grid);
            assert_eq!(t.block, Block::Test);
            let screen = s.screen();
            assert_eq!(screen[0], t);
            if screens
                .last()
                .is_none_or(|last| last[0].reference != t.reference)
            {
                screens.push(screen);
            }
            assert!(s.respond(&rating(100.5)).is_err(), "off the 0-100 scale");
            let r = rating(f64::from(subject % 101));
            let o = s.respond(&r).unwrap();
            assert_eq!(o.score.to_bits(), f64::from(subject % 101).to_bits());
            log.push((t, r, o));
        }
        assert_eq!(
            log.len(),
            2 * (3 + 2),
            "3 tests + hidden reference + anchor per clip"
        );
        assert_eq!(screens.len(), 2);
        for screen in &screens {
            let reference = screen[0].reference.clone();
            let clip = reference.split('/').next().unwrap().to_string();
            let mut ids: Vec<&str> = screen.iter().map(|t| t.stimulus.as_str()).collect();
            // The pending trial's screen is the whole screen, panes A.. in order.
            let panes: Vec<Position> = screen.iter().map(|t| t.reference_position).collect();
            assert_eq!(panes, (0..5).map(Position::Pane).collect::<Vec<_>>());
            assert!(screen.iter().all(|t| t.reference == reference));
            if screen[0].stimulus == reference {
                first_pane_is_reference += 1;
            }
            orders.insert(ids.join(","));
            ids.sort_unstable();
            let mut want = vec![
                format!("{clip}/reference"),
                format!("{clip}/wavelet-perceptual/cr10"),
                format!("{clip}/wavelet-perceptual/cr30"),
                format!("{clip}/wavelet-perceptual/cr50"),
                format!("{clip}/wavelet-standard/cr70"),
            ];
            want.sort_unstable();
            assert_eq!(ids, want);
        }
        // The same subject gets the same plan; resume = replay, also from inside a screen.
        let mut again = Session::new(&study, subject).unwrap();
        for (t, r, o) in &log[..3] {
            again.replay(t, r, o).unwrap();
        }
        assert_eq!(again.next_trial(0).unwrap().as_ref(), Some(&log[3].0));
        let rest: Vec<_> = again.screen();
        assert_eq!(
            rest.len(),
            2,
            "a screen resumed after 3 of 5 panes shows the other 2"
        );
        again.respond(&log[3].1).unwrap();
        for (t, r, o) in &log[4..] {
            again.replay(t, r, o).unwrap();
        }
        assert_eq!(again.next_trial(0).unwrap(), None);
    }
    // The hidden reference lands on pane A about one screen in five (2 x 60 screens: the
    // binomial's 99.9 % range for p = 0.2 is about 10-40).
    assert!(
        (10..=40).contains(&first_pane_is_reference),
        "{first_pane_is_reference}"
    );
    assert!(
        orders.len() > 60,
        "orders vary per subject and screen: {}",
        orders.len()
    );
}

#[test]
fn mushra_time_limits_and_breaks_fall_between_screens() {
    let study = parse(&MUSHRA.replace(
        "[mushra]",
        "[session]\nbreak_every_trials = 1\ntime_limit_min = 1\n\n[mushra]",
    ))
    .unwrap();
    let mut s = Session::new(&study, 3).unwrap();
    let mut breaks = Vec::new();
    for k in 0..5 {
        // Past the limit inside the first screen: the screen is finished.
        let t = s
            .next_trial(if k == 0 { 0 } else { 120_000 })
            .unwrap()
            .unwrap();
        breaks.push(t.break_before);
        s.respond(&rating(50.0)).unwrap();
    }
    assert_eq!(breaks, [false; 5]);
    assert_eq!(
        s.next_trial(120_000).unwrap(),
        None,
        "no new screen after the limit"
    );
    assert_eq!(s.status(), protocols::SessionStatus::TimeLimit);
    let study = parse(&MUSHRA.replace("[mushra]", "[session]\nbreak_every_trials = 1\n\n[mushra]"))
        .unwrap();
    let mut s = Session::new(&study, 3).unwrap();
    let mut breaks = Vec::new();
    while let Some(t) = s.next_trial(0).unwrap() {
        breaks.push(t.break_before);
        s.respond(&rating(50.0)).unwrap();
    }
    assert_eq!(
        breaks,
        [
            false, false, false, false, false, true, false, false, false, false
        ],
        "a break before the second screen only"
    );
}

#[test]
fn mushra_screens_follow_the_latin_square_when_asked() {
    let study =
        parse(&MUSHRA.replace("[mushra]", "[design]\norder = \"latin_square\"\n\n[mushra]"))
            .unwrap();
    let first_screen = |subject: u32| {
        let mut s = Session::new(&study, subject).unwrap();
        s.next_trial(0).unwrap().unwrap().reference
    };
    // Williams rows over the two screens (walk, dance): 0 1, then 1 0, for every block.
    for subject in 0..6 {
        let want = if subject % 2 == 0 {
            "walk/reference"
        } else {
            "dance/reference"
        };
        assert_eq!(first_screen(subject), want, "subject {subject}");
    }
}

/// The default instructions follow the design as it runs: practice is promised only where the
/// session has familiarization trials, and a pair comparison says the original may be one of
/// the two only where the original is among its conditions (`study check` of every example
/// shows a title that is not the study's name: `study/tests/examples_window.rs`).
#[test]
fn instructions_follow_the_design() {
    let practice = "The first few trials show the range";
    let acr = default_instructions(&parse(ACR_HR).unwrap());
    assert!(acr.contains(practice), "familiarization = 2: {acr}");
    let dcr = default_instructions(&parse(DCR).unwrap());
    assert!(!dcr.contains(practice), "no familiarization: {dcr}");
    let hidden = parse(PC).unwrap();
    assert!(hidden.conditions.iter().any(|c| c.stimulus == c.reference));
    let text = default_instructions(&hidden);
    assert!(
        text.contains("Either of them may be the original motion itself")
            && !text.contains("Neither is the original"),
        "hidden references: {text}"
    );
    let plain = parse(&PC.replace("hidden_reference = true\n", "")).unwrap();
    assert!(plain.conditions.iter().all(|c| c.stimulus != c.reference));
    let text = default_instructions(&plain);
    assert!(
        text.contains("Neither is the original") && !text.contains("may be the original"),
        "no hidden references: {text}"
    );
}
