//! `[staircase]`: the shared staircase settings, the tracks with their levels from the
//! manifest (or a live staircase's tracks, whose `[staircase.live]` table `live.rs` reads), and
//! the check that every level a staircase can reach has a stimulus.

use std::collections::{BTreeMap, BTreeSet};

use toml::{Table, Value};

use super::check::{Ctx, join, type_name};
use super::live::parse_live;
use super::quest::{check_domain, domain, parse_method, parse_quest};
use super::{MAX_TRACKS, StaircaseStudy, Track};
use crate::catalog::{CodecCatalog, TARGET_CR_PARAM};
use crate::manifest::StimulusManifest;
use crate::staircase::{GridPoint, StaircaseSettings, StepType, check_settings};

/// Most levels enumerated when checking that every staircase level has a stimulus.
const MAX_ENUMERATED_LEVELS: usize = 4096;

const STAIR_KEYS: &[&str] = &[
    "param",
    "codec",
    "level_tolerance",
    "start",
    "step",
    "step_type",
    "down_up_ratio",
    "min",
    "max",
    "n_up",
    "n_down",
    "apply_initial_rule",
    "stop_reversals",
    "min_trials",
    "max_trials",
    "threshold_reversals",
    "tracks",
    "live",
    "method",
    "quest",
    "practice_trials",
    "practice_level",
];

const P: &str = "staircase";

/// What `[staircase]` says for every track: the level parameter, the codec and the settings.
struct Shared {
    /// The level's parameter (`param`).
    param: Option<String>,
    /// The codec whose stimuli (or, live, whose encoder) give the levels.
    codec: Option<String>,
    /// `staircase.start` as written: a track without its own start needs it.
    start: Option<f64>,
    /// The settings every track starts from (the default start where none is written).
    settings: StaircaseSettings,
    /// A QUEST+ or Psi study (`method`): tracks take no start and the up-down rules are
    /// unused.
    bayesian: bool,
}

/// The settings shared by every track: `param`, `codec` and the staircase rules.
fn parse_shared(t: &Table, cx: &mut Ctx) -> Shared {
    let d = StaircaseSettings::default();
    let param = cx.string(t, P, "param");
    let param = cx.required(param, t, P, "param");
    let codec = cx.string(t, P, "codec");
    let codec = cx.required(codec, t, P, "codec");
    let start = cx.float(t, P, "start");
    let step = cx.float(t, P, "step");
    let step = cx.required(step, t, P, "step");
    let step_type = cx.pick(
        t,
        P,
        "step_type",
        &[
            ("linear", StepType::Linear),
            ("log", StepType::Log),
            ("db", StepType::Db),
        ],
    );
    let min = cx.float(t, P, "min");
    let min = cx.required(min, t, P, "min");
    let max = cx.float(t, P, "max");
    let max = cx.required(max, t, P, "max");
    let opt_u = |cx: &mut Ctx, key: &str| cx.uint(t, P, key, 100_000);
    let settings = StaircaseSettings {
        start: start.unwrap_or(d.start),
        step: step.unwrap_or(d.step),
        step_type: step_type.unwrap_or(StepType::Linear),
        down_up_ratio: cx.float(t, P, "down_up_ratio").unwrap_or(1.0),
        min,
        max,
        n_up: opt_u(cx, "n_up").unwrap_or(1),
        n_down: opt_u(cx, "n_down").unwrap_or(2),
        apply_initial_rule: cx.boolean(t, P, "apply_initial_rule").unwrap_or(false),
        stop_reversals: opt_u(cx, "stop_reversals"),
        min_trials: opt_u(cx, "min_trials").unwrap_or(0),
        max_trials: opt_u(cx, "max_trials"),
        threshold_reversals: opt_u(cx, "threshold_reversals").unwrap_or(3),
    };
    Shared {
        param,
        codec,
        start,
        settings,
        bayesian: false,
    }
}

/// `level_tolerance`: how far a manifest stimulus's parameter may be from a level (a live
/// staircase has none: it encodes every level exactly).
fn parse_tolerance(t: &Table, live: bool, settings: &StaircaseSettings, cx: &mut Ctx) -> f64 {
    if live && t.contains_key("level_tolerance") {
        cx.err(
            join(P, "level_tolerance"),
            "a live staircase encodes every level exactly; remove level_tolerance",
        );
    }
    match cx.float(t, P, "level_tolerance") {
        Some(v) if v >= 0.0 => v,
        Some(v) => {
            cx.err(join(P, "level_tolerance"), format!("must be >= 0, got {v}"));
            0.0
        }
        None => 1e-9 * settings.step.abs().max(f64::MIN_POSITIVE),
    }
}

/// `[staircase]`: the shared settings, the live option (its codec checked against `codecs`),
/// the level tolerance and every track with its levels.
pub(super) fn parse_staircase(
    t: &Table,
    m: Option<&StimulusManifest>,
    codecs: &dyn CodecCatalog,
    cx: &mut Ctx,
) -> Option<StaircaseStudy> {
    cx.known(t, P, STAIR_KEYS);
    let method = parse_method(t, cx);
    let mut shared = parse_shared(t, cx);
    let quest_t = cx.table(t, P, "quest");
    let quest = method.and_then(|m| parse_quest(quest_t, m, &shared.settings, cx));
    if method.is_some() {
        // A Bayesian track's first level is its own choice; the grid's lowest stands in
        // where a start is shown (`study check`, the live preflight).
        shared.bayesian = true;
        shared.start = shared.settings.min;
        shared.settings.start = shared.settings.min.unwrap_or(shared.settings.start);
    }
    let live_t = cx.table(t, P, "live");
    let live_asked = t.contains_key("live");
    let (codec, param) = (shared.codec.as_deref(), shared.param.as_deref());
    let live = live_t.and_then(|lt| parse_live(lt, codec, param, m, codecs, cx));
    // A live level that is a compression ratio must stay positive, whatever the codec. Every
    // track shares `min` (a track sets only its start), so one check covers them all.
    if live_asked
        && param == Some(TARGET_CR_PARAM)
        && shared.settings.min.is_some_and(|lo| lo <= 0.0)
    {
        cx.err(join(P, "min"), "a compression ratio level needs min > 0");
    }
    let tolerance = parse_tolerance(t, live_asked, &shared.settings, cx);
    // A live staircase without [[staircase.tracks]] runs one staircase named "live".
    let default_track = [Value::Table(Table::from_iter([(
        "name".to_string(),
        Value::String("live".into()),
    )]))];
    let tracks_v = match t.get("tracks") {
        Some(Value::Array(a)) => a.as_slice(),
        Some(v) => {
            cx.wrong(P, "tracks", "an array of tables ([[staircase.tracks]])", v);
            &[]
        }
        None if live_asked => &default_track[..],
        None => {
            cx.err(
                join(P, "tracks"),
                "missing: add at least one [[staircase.tracks]]",
            );
            &[]
        }
    };
    if tracks_v.len() > MAX_TRACKS {
        cx.err(
            join(P, "tracks"),
            format!("{} tracks, limit {MAX_TRACKS}", tracks_v.len()),
        );
        return None;
    }
    if t.contains_key("tracks") && tracks_v.is_empty() {
        cx.err(join(P, "tracks"), "needs at least one track");
    }
    let mut tracks = Vec::new();
    let mut names = BTreeSet::new();
    for (i, tv) in tracks_v.iter().enumerate() {
        let tp = format!("{P}.tracks[{i}]");
        let Value::Table(tt) = tv else {
            cx.err(&tp, format!("expected a table, got {}", type_name(tv)));
            continue;
        };
        let head = parse_track(tt, &tp, &shared, live_asked, &mut names, cx);
        if live_asked {
            tracks.push(Track {
                name: head.name,
                clip: String::new(),
                reference: String::new(),
                settings: head.settings,
                levels: Vec::new(),
            });
            continue;
        }
        let Some(m) = m else { continue };
        let Some(mut track) = manifest_track(head, &shared, m, &tp, cx) else {
            continue;
        };
        if method.is_some() {
            // The domain even where the procedure's own settings have problems: those are
            // reported beside any level without a stimulus.
            check_domain(&mut track, &domain(&shared.settings), tolerance, &tp, cx);
        } else if check_settings(&track.settings).is_empty() {
            check_levels(&track, tolerance, &tp, cx);
        }
        tracks.push(track);
    }
    if live_asked && live.is_none() {
        return None;
    }
    if method.is_some() && quest.is_none() {
        return None;
    }
    let (practice_trials, practice_level) =
        parse_practice(t, &shared, &tracks, live_asked, tolerance, cx);
    Some(StaircaseStudy {
        param: shared.param?,
        codec: shared.codec?,
        level_tolerance: tolerance,
        tracks,
        live,
        quest,
        practice_trials,
        practice_level,
    })
}

/// Most practice trials before a staircase.
const MAX_PRACTICE: u32 = 1000;

/// `practice_trials` and `practice_level`: trials shown before the staircases start, at a
/// fixed (easy) level, the tracks in turn; each track's start when no level is given (a
/// QUEST+ or Psi track has none, so it needs the level). The level must be within
/// `min`..=`max` and, from the manifest, have a stimulus in every track.
fn parse_practice(
    t: &Table,
    shared: &Shared,
    tracks: &[Track],
    live: bool,
    tolerance: f64,
    cx: &mut Ctx,
) -> (u32, Option<f64>) {
    let n = cx.uint(t, P, "practice_trials", MAX_PRACTICE).unwrap_or(0);
    let level = cx.float(t, P, "practice_level");
    if n == 0 {
        if level.is_some() {
            cx.err(
                join(P, "practice_level"),
                "no practice trials (set practice_trials, or remove practice_level)",
            );
        }
        return (0, level);
    }
    if shared.bayesian && level.is_none() {
        cx.err(
            join(P, "practice_level"),
            "missing: a QUEST+ or Psi track has no start to practise at; give the level",
        );
        return (n, None);
    }
    if let Some(v) = level {
        let (lo, hi) = (shared.settings.min, shared.settings.max);
        if lo.is_some_and(|lo| v < lo) || hi.is_some_and(|hi| v > hi) {
            cx.err(
                join(P, "practice_level"),
                format!(
                    "{v} is outside min..=max ({}..={})",
                    lo.unwrap_or(f64::NEG_INFINITY),
                    hi.unwrap_or(f64::INFINITY)
                ),
            );
            return (n, level);
        }
    }
    if !live {
        for (i, tr) in tracks.iter().enumerate() {
            let at = level.unwrap_or(tr.settings.start);
            if tr.stimulus_at(at, tolerance).is_none() {
                cx.err(
                    join(P, "practice_level"),
                    format!(
                        "track {:?} (staircase.tracks[{i}]) has no stimulus at practice level {at}",
                        tr.name
                    ),
                );
            }
        }
    }
    (n, level)
}

/// The keys a track table may have: `keys`, less `start` in a QUEST+ or Psi study.
fn track_keys<'a>(shared: &Shared, keys: &'a [&'a str]) -> &'a [&'a str] {
    if shared.bayesian {
        &keys[..keys.len() - 1]
    } else {
        keys
    }
}

/// A track as its `[[staircase.tracks]]` table gives it, before its levels are looked up.
struct TrackHead {
    name: String,
    /// The clip (`None` in a live staircase, or when the key is missing or mistyped).
    clip: Option<String>,
    /// The shared settings with this track's start.
    settings: StaircaseSettings,
}

/// One `[[staircase.tracks]]` table at `tp`: its keys, a name not used by an earlier track
/// (`names`), and its start checked together with the shared settings.
fn parse_track(
    tt: &Table,
    tp: &str,
    shared: &Shared,
    live: bool,
    names: &mut BTreeSet<String>,
    cx: &mut Ctx,
) -> TrackHead {
    let clip = if live {
        let mut others = tt.clone();
        if others.remove("clip").is_some() {
            cx.err(
                join(tp, "clip"),
                "a live staircase takes its clips from staircase.live.clips",
            );
        }
        cx.known(&others, tp, track_keys(shared, &["name", "start"]));
        None
    } else {
        cx.known(tt, tp, track_keys(shared, &["name", "clip", "start"]));
        let clip = cx.string(tt, tp, "clip");
        cx.required(clip, tt, tp, "clip")
    };
    let name = cx
        .string(tt, tp, "name")
        .or_else(|| clip.clone())
        .unwrap_or_else(|| if live { "live".into() } else { String::new() });
    if !names.insert(name.clone()) {
        cx.err(
            join(tp, "name"),
            format!("track name {name:?} is used twice"),
        );
    }
    let mut s = shared.settings.clone();
    if shared.bayesian {
        return TrackHead {
            name,
            clip,
            settings: s,
        };
    }
    if let Some(st) = cx.float(tt, tp, "start") {
        s.start = st;
    } else if shared.start.is_none() {
        cx.err(
            join(tp, "start"),
            "missing (set staircase.start or a start per track)",
        );
    }
    for e in check_settings(&s) {
        if let crate::staircase::StaircaseError::BadSetting { key, reason } = e {
            let at = if key == "start" && tt.contains_key("start") {
                join(tp, "start")
            } else {
                join(P, key)
            };
            if !cx.issues.iter().any(|x| x.key == at && x.reason == reason) {
                cx.err(at, reason);
            }
        }
    }
    TrackHead {
        name,
        clip,
        settings: s,
    }
}

/// The track of a staircase over manifest stimuli: its clip's reference and the levels its
/// clip's stimuli of the shared codec offer; `None` (with the problem reported) when the clip
/// has no reference or no such stimulus.
fn manifest_track(
    head: TrackHead,
    shared: &Shared,
    m: &StimulusManifest,
    tp: &str,
    cx: &mut Ctx,
) -> Option<Track> {
    let (Some(clip), Some(param), Some(codec)) = (head.clip, &shared.param, &shared.codec) else {
        return None;
    };
    let Some(reference) = m.reference_of(&clip) else {
        cx.err(
            join(tp, "clip"),
            format!("clip {clip:?} has no reference stimulus in the manifest"),
        );
        return None;
    };
    let levels = manifest_levels(m, &clip, codec, param);
    if levels.is_empty() {
        cx.err(
            join(tp, "clip"),
            format!("no stimulus of clip {clip:?} with codec {codec:?} has parameter {param:?}"),
        );
        return None;
    }
    // Several variants of the codec (`study sweep --param`) give one level several stimuli;
    // the track would show whichever sorts first. Refused, naming them.
    if let Some(w) = levels
        .windows(2)
        .find(|w| (w[0].0 - w[1].0).abs() <= 1e-9 * w[1].0.abs().max(1.0))
    {
        let same: Vec<String> = levels
            .iter()
            .filter(|(v, _)| (v - w[0].0).abs() <= 1e-9 * w[0].0.abs().max(1.0))
            .map(|(_, id)| format!("{id:?}"))
            .collect();
        cx.err(
            join(tp, "clip"),
            format!(
                "{} stimuli of clip {clip:?} with codec {codec:?} have {param} = {} ({}): a \
                 track needs one stimulus per level; give the variants their own manifest",
                same.len(),
                w[0].0,
                same.join(", ")
            ),
        );
        return None;
    }
    Some(Track {
        name: head.name,
        clip,
        reference: reference.id.clone(),
        settings: head.settings,
        levels,
    })
}

/// The levels the manifest offers a track: (value of `param`, stimulus id) of every stimulus
/// of `clip` made with `codec` that has a finite `param`, sorted by value, then id.
fn manifest_levels(
    m: &StimulusManifest,
    clip: &str,
    codec: &str,
    param: &str,
) -> Vec<(f64, String)> {
    let mut levels: Vec<(f64, String)> = m
        .stimuli
        .iter()
        .filter(|x| x.clip == clip && x.codec == codec)
        .filter_map(|x| {
            x.params
                .get(param)
                .filter(|v| v.is_finite())
                .map(|v| (*v, x.id.clone()))
        })
        .collect();
    levels.sort_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(&b.1)));
    levels
}

/// Every level the staircase can reach must have a stimulus within the tolerance. Reachable
/// levels are enumerated when they form a small set, each step taken by
/// [`GridPoint::stepped`] as a session takes it; otherwise the stimuli's tolerance intervals
/// must cover [min, max].
fn check_levels(track: &Track, tol: f64, path: &str, cx: &mut Ctx) {
    let s = &track.settings;
    let (Some(lo), Some(hi)) = (s.min, s.max) else {
        return;
    };
    let mut points = std::collections::HashSet::new();
    let mut seen: BTreeMap<u64, f64> = BTreeMap::new();
    let mut queue = vec![GridPoint::start(s)];
    let mut bounded = true;
    while let Some(p) = queue.pop() {
        if !points.insert(p) {
            continue;
        }
        let v = p.level(s);
        seen.insert(v.to_bits(), v);
        if points.len() > MAX_ENUMERATED_LEVELS {
            bounded = false;
            break;
        }
        for up in [true, false] {
            let next = p.stepped(s, up);
            if !points.contains(&next) {
                queue.push(next);
            }
        }
    }
    if bounded {
        let mut missing: Vec<f64> = seen
            .values()
            .copied()
            .filter(|v| track.stimulus_at(*v, tol).is_none())
            .collect();
        missing.sort_by(f64::total_cmp);
        if !missing.is_empty() {
            let shown: Vec<String> = missing.iter().take(8).map(|v| format!("{v}")).collect();
            cx.err(
                join(path, "clip"),
                format!(
                    "{} reachable level(s) have no stimulus of clip {:?} within {tol}: {}{}",
                    missing.len(),
                    track.clip,
                    shown.join(", "),
                    if missing.len() > 8 { ", ..." } else { "" }
                ),
            );
        }
    } else {
        let mut covered = lo;
        for (v, _) in &track.levels {
            if v - tol > covered {
                break;
            }
            covered = covered.max(v + tol);
        }
        if covered < hi {
            cx.err(
                join(path, "clip"),
                format!(
                    "levels form no finite grid, and stimuli within level_tolerance {tol} cover [{lo}, {covered}] but not up to max {hi}"
                ),
            );
        }
    }
}
