//! The top-level table of a study file: its header keys, the stimulus manifest, and which
//! sections each protocol takes.

use std::collections::BTreeSet;

use toml::{Table, Value};

use super::check::Ctx;
use super::conditions::{References, parse_conditions, resolve_familiarization};
use super::crowdsourcing::parse_crowdsourcing;
use super::design::parse_design;
use super::mushra::parse_mushra;
use super::presentation::parse_presentation;
use super::rendering::parse_rendering;
use super::scale::parse_scale;
use super::scene::{SceneSettings, check_scene_stimulus, parse_scene};
use super::session::{FamSpec, parse_session};
use super::simulation::parse_simulation;
use super::staircase::parse_staircase;
use super::viewing::parse_viewing;
use super::{
    Condition, Detection, Metric, STUDY_FORMAT_VERSION, SessionSettings, SimulationSettings,
    StaircaseStudy, StudyDefinition,
};
use crate::catalog::CodecCatalog;
use crate::manifest::StimulusManifest;
use crate::methods::{Method, Sections};
use crate::record::Protocol;

/// Longest title shown to subjects, characters.
const MAX_TITLE_CHARS: usize = 120;

/// Longest study name.
const MAX_NAME_LEN: usize = 64;

/// Whether `name` is a safe study name: 1-[`MAX_NAME_LEN`] ASCII letters, digits, `-`, `_`
/// or `.`, starting with a letter or digit. The name becomes part of a folder name, so no
/// separator, no `..`, nothing a shell or another file system would read differently.
fn is_safe_name(name: &str) -> bool {
    name.len() <= MAX_NAME_LEN
        && name.starts_with(|c: char| c.is_ascii_alphanumeric())
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

const TOP_KEYS: &[&str] = &[
    "format_version",
    "name",
    "title",
    "protocol",
    "stimuli",
    "seed",
    "conditions",
    "presentation",
    "scale",
    "session",
    "staircase",
    "simulation",
    "rendering",
    "crowdsourcing",
    "scene",
    "design",
    "viewing",
    "mushra",
];

/// The whole study file: its header, the manifest, the sections every protocol has, then
/// the protocol's own; `None` when something the definition needs is missing (the problem is
/// in `cx`).
#[expect(
    clippy::too_many_lines,
    reason = "the study file's one walk: every protocol's sections in one match, read top to bottom"
)]
pub(super) fn parse_table(
    t: &Table,
    cx: &mut Ctx,
    load_manifest: impl FnOnce(&str) -> Result<StimulusManifest, String>,
    codecs: &dyn CodecCatalog,
) -> Option<StudyDefinition> {
    cx.known(t, "", TOP_KEYS);
    let header = parse_header(t, cx);
    let manifest = header
        .stimuli_path
        .as_deref()
        .and_then(|p| load_checked_manifest(p, load_manifest, cx));

    let empty = Table::new();
    let protocol = header.protocol;
    let pres_t = cx.table(t, "", "presentation").unwrap_or(&empty);
    let presentation = parse_presentation(pres_t, protocol, cx);
    let scale_t = cx.table(t, "", "scale");
    let scale = parse_scale(scale_t.unwrap_or(&empty), protocol, cx);
    let session_t = cx.table(t, "", "session").unwrap_or(&empty);
    let (session, familiarization_spec) = parse_session(session_t, cx);
    let sim_t = cx.table(t, "", "simulation").unwrap_or(&empty);
    let simulation = parse_simulation(sim_t, cx);
    let rendering = parse_rendering(cx.table(t, "", "rendering").unwrap_or(&empty), cx);
    let scene = cx.table(t, "", "scene").and_then(|s| parse_scene(s, cx));

    let mut conditions = Vec::new();
    let mut familiarization = Vec::new();
    let mut staircase = None;
    let mut mushra = None;
    let method = protocol.map(crate::methods::of);
    match method.map(Method::sections) {
        Some(Sections::Pairs) => {
            let m = manifest.as_ref();
            conditions = pc_sections(t, &session, &familiarization_spec, scale_t, m, cx);
        }
        Some(sections @ (Sections::RatedConditions | Sections::Screens)) => {
            let screens = sections == Sections::Screens;
            // A MUSHRA study's familiarization is a count of training screens, not stimuli.
            let (spec, training) = if screens {
                (FamSpec::None, familiarization_spec)
            } else {
                (familiarization_spec, FamSpec::None)
            };
            let references = References::of(method.is_some_and(Method::hidden_references));
            (conditions, familiarization) =
                rating_sections(t, &session, spec, manifest.as_ref(), references, cx);
            if let Some(m) = &manifest {
                check_crowd_conditions(
                    &conditions,
                    &familiarization,
                    scene.as_ref(),
                    t.contains_key("scene"),
                    m,
                    cx,
                );
            }
            if screens {
                let m = manifest.as_ref();
                mushra = mushra_sections(t, &conditions, &training, &session, m, cx);
            }
        }
        Some(Sections::Tracks) => {
            staircase = staircase_sections(
                t,
                &session,
                &familiarization_spec,
                scale_t.is_some(),
                manifest.as_ref(),
                codecs,
                cx,
            );
            check_live_metric(t, &simulation, cx);
        }
        None => {}
    }

    if let Some(m) = &manifest {
        check_known_ratios(&conditions, &familiarization, staircase.as_ref(), m, cx);
    }
    let mut crowdsourcing = parse_crowdsourcing(
        cx.table(t, "", "crowdsourcing").unwrap_or(&empty),
        protocol,
        &conditions,
        cx,
    );
    check_attention(&simulation, scene.as_ref(), t.contains_key("scene"), cx);
    let design = parse_design(
        cx.table(t, "", "design").unwrap_or(&empty),
        protocol,
        &conditions,
        &mut crowdsourcing,
        cx,
    );
    let viewing = cx.table(t, "", "viewing").map(|v| parse_viewing(v, cx));

    Some(StudyDefinition {
        format_version: header.version? as u32,
        name: header.name?,
        title: header.title,
        protocol: protocol?,
        stimuli_path: header.stimuli_path?,
        seed: header.seed? as u64,
        conditions,
        familiarization,
        presentation: presentation?,
        scale: scale?,
        session,
        staircase,
        simulation,
        rendering,
        crowdsourcing,
        design,
        viewing,
        scene,
        mushra,
        manifest: manifest?,
    })
}

/// Every stimulus a study shows must have a known compression ratio: its tables, rate
/// findings, fits and thresholds are all per ratio. A stimulus added without its stream's size
/// (`achieved_cr: null`, "CR unknown") can be previewed and measured, not studied.
fn check_known_ratios(
    conditions: &[Condition],
    familiarization: &[Condition],
    staircase: Option<&StaircaseStudy>,
    m: &StimulusManifest,
    cx: &mut Ctx,
) {
    let conditioned = conditions
        .iter()
        .chain(familiarization)
        .flat_map(|c| [c.stimulus.as_str(), c.reference.as_str()]);
    let tracked = staircase
        .into_iter()
        .flat_map(|s| &s.tracks)
        .flat_map(|t| t.levels.iter().map(|(_, id)| id.as_str()));
    let mut seen = BTreeSet::new();
    for id in conditioned.chain(tracked) {
        if m.get(id).is_some_and(|s| s.achieved_cr.is_none()) && seen.insert(id) {
            cx.err(
                "stimuli",
                format!(
                    "stimulus {id:?} has no compression ratio (CR unknown: it was added without \
                     its stream's size); give it with `study stimuli add --stream FILE` or \
                     `--bytes N` before a study shows it"
                ),
            );
        }
    }
}

/// The top-level keys before the sections (`None` where missing or invalid, with the problem
/// reported).
struct Header {
    version: Option<i64>,
    name: Option<String>,
    title: Option<String>,
    protocol: Option<Protocol>,
    stimuli_path: Option<String>,
    seed: Option<i64>,
}

/// `format_version`, `name`, `protocol`, `stimuli` and `seed`.
fn parse_header(t: &Table, cx: &mut Ctx) -> Header {
    let version = cx.int(t, "", "format_version", 0, i64::from(u32::MAX));
    let version = cx.required(version, t, "", "format_version");
    if let Some(v) = version
        && v != i64::from(STUDY_FORMAT_VERSION)
    {
        cx.err(
            "format_version",
            format!("version {v} is not supported (this build reads {STUDY_FORMAT_VERSION})"),
        );
    }
    let name = cx.string(t, "", "name");
    let name = cx.required(name, t, "", "name");
    if let Some(n) = name.as_deref().filter(|n| !is_safe_name(n)) {
        cx.err(
            "name",
            format!(
                "{n:?}: use 1-{MAX_NAME_LEN} letters, digits, '-', '_' or '.', starting with a \
                 letter or digit (it names the default results folder)"
            ),
        );
    }
    let title = cx.string(t, "", "title").and_then(|v| {
        let n = v.trim().chars().count();
        if n == 0 || n > MAX_TITLE_CHARS || v.contains(['\n', '\r']) {
            cx.err(
                "title",
                format!("{v:?}: give one line of 1-{MAX_TITLE_CHARS} characters (omit it to show the name)"),
            );
            None
        } else {
            Some(v.trim().to_string())
        }
    });
    let protocol: Option<Protocol> = cx.parse_enum(t, "", "protocol");
    let protocol = cx.required(protocol, t, "", "protocol");
    if protocol.is_some_and(|p| crate::methods::of(p).sections() != Sections::Screens)
        && t.contains_key("mushra")
    {
        cx.err(
            "mushra",
            "only a MUSHRA study (protocol = \"mushra\") has a [mushra] table",
        );
    }
    let stimuli_path = cx.string(t, "", "stimuli");
    let stimuli_path = cx.required(stimuli_path, t, "", "stimuli");
    let seed = cx.int(t, "", "seed", 0, i64::MAX);
    let seed = cx.required(seed, t, "", "seed");
    Header {
        version,
        name,
        title,
        protocol,
        stimuli_path,
        seed,
    }
}

/// The manifest named by `stimuli`, loaded and checked; `None` when it cannot be loaded.
fn load_checked_manifest(
    path: &str,
    load_manifest: impl FnOnce(&str) -> Result<StimulusManifest, String>,
    cx: &mut Ctx,
) -> Option<StimulusManifest> {
    match load_manifest(path) {
        Ok(m) => {
            check_manifest(path, &m, cx);
            Some(m)
        }
        Err(e) => {
            cx.err("stimuli", format!("cannot load the stimulus manifest: {e}"));
            None
        }
    }
}

/// A MUSHRA study's `[mushra]` and its rules (no crowd scenes); `fam`: the session asks
/// for familiarization trials.
fn mushra_sections(
    t: &Table,
    conditions: &[Condition],
    training: &FamSpec,
    session: &SessionSettings,
    manifest: Option<&StimulusManifest>,
    cx: &mut Ctx,
) -> Option<super::MushraSettings> {
    if t.contains_key("scene") {
        cx.err(
            "scene",
            "a MUSHRA screen shows one figure per pane, not crowd scenes",
        );
    }
    let table = cx.table(t, "", "mushra");
    parse_mushra(table, conditions, training, session, manifest, cx)
}

/// The sections of a rating study (MOS, DSCQS, ACR, DCR): no `[staircase]`, the
/// `[conditions]` and the familiarization stimuli chosen among them, and enough conditions to
/// hide the repeats in. `refs` says whether references may be conditions (ACR-HR).
fn rating_sections(
    t: &Table,
    session: &SessionSettings,
    familiarization_spec: FamSpec,
    manifest: Option<&StimulusManifest>,
    refs: References,
    cx: &mut Ctx,
) -> (Vec<Condition>, Vec<Condition>) {
    let mut conditions = Vec::new();
    let mut familiarization = Vec::new();
    if t.contains_key("staircase") {
        cx.err(
            "staircase",
            "only a staircase study may have a [staircase] table",
        );
    }
    match cx.table(t, "", "conditions") {
        Some(ct) => {
            if let Some(m) = manifest {
                conditions = parse_conditions(ct, m, refs, cx);
                familiarization =
                    resolve_familiarization(familiarization_spec, &conditions, m, refs, cx);
            } else {
                cx.known(
                    ct,
                    "conditions",
                    &[
                        "stimuli",
                        "clips",
                        "codecs",
                        "target_cr",
                        "hidden_reference",
                    ],
                );
            }
        }
        None if !t.contains_key("conditions") => cx.err("conditions", "missing"),
        None => {}
    }
    if session.hidden_repeats as usize > conditions.len() && manifest.is_some() {
        cx.err(
            "session.hidden_repeats",
            format!(
                "{} repeats but only {} conditions",
                session.hidden_repeats,
                conditions.len()
            ),
        );
    }
    (conditions, familiarization)
}

/// What a pair comparison (P.910 PC) has no use for: a rating scale (the subject picks one
/// of two), familiarization trials (not offered yet: the test pairs start at once), and a
/// crowd `[scene]` (rated scenes only).
fn pair_comparison_rules(t: &Table, familiarization: &FamSpec, has_scale: bool, cx: &mut Ctx) {
    if has_scale {
        cx.err(
            "scale",
            "a pair comparison asks which of two motions is better, not for a rating: remove \
             [scale]",
        );
    }
    if !matches!(familiarization, FamSpec::None) {
        cx.err(
            "session.familiarization",
            "familiarization trials are not offered in a pair comparison study (its pairs start \
             at once); remove familiarization",
        );
    }
    if t.contains_key("scene") {
        cx.err(
            "scene",
            "crowd scenes are rated (protocol \"dscqs\" or \"mos\"), not compared in pairs",
        );
    }
}

/// The conditions of a pair comparison, checked as a rating study's (no familiarization) and
/// for pairs, and what a pair comparison has no use for ([`pair_comparison_rules`]).
fn pc_sections(
    t: &Table,
    session: &SessionSettings,
    familiarization: &FamSpec,
    scale: Option<&Table>,
    manifest: Option<&StimulusManifest>,
    cx: &mut Ctx,
) -> Vec<Condition> {
    pair_comparison_rules(t, familiarization, scale.is_some(), cx);
    let (conditions, _) =
        rating_sections(t, session, FamSpec::None, manifest, References::Hidden, cx);
    if manifest.is_some() {
        check_pairs(&conditions, session.hidden_repeats, cx);
    }
    conditions
}

/// A pair comparison compares conditions of the same clip: every clip needs two of them, the
/// pairs may be at most [`super::MAX_PAIRS`], and the hidden repeats repeat pairs.
fn check_pairs(conditions: &[Condition], hidden_repeats: u32, cx: &mut Ctx) {
    for members in super::conditions_by_clip(conditions) {
        if members.len() < 2
            && let Some(c) = members.first().and_then(|&i| conditions.get(i))
        {
            cx.err(
                "conditions",
                format!(
                    "{:?} is the only condition of its clip (reference {:?}): a pair comparison \
                     compares two versions of the same clip, so each clip needs at least 2",
                    c.stimulus, c.reference
                ),
            );
        }
    }
    let pairs = super::pair_count(conditions);
    if pairs > super::MAX_PAIRS {
        cx.err(
            "conditions",
            format!(
                "{pairs} pairs (every pair of a clip's conditions) is over the limit of {}",
                super::MAX_PAIRS
            ),
        );
    } else if pairs > 0
        && hidden_repeats as usize > pairs
        && hidden_repeats as usize <= conditions.len()
    {
        cx.err(
            "session.hidden_repeats",
            format!("{hidden_repeats} repeats but only {pairs} pairs"),
        );
    }
}

/// The sections of a staircase study: none of the settings only rating studies have
/// (conditions, familiarization, hidden repeats, a `[scale]`, which `has_scale` tells), and the
/// `[staircase]` table.
fn staircase_sections(
    t: &Table,
    session: &SessionSettings,
    familiarization_spec: &FamSpec,
    has_scale: bool,
    manifest: Option<&StimulusManifest>,
    codecs: &dyn CodecCatalog,
    cx: &mut Ctx,
) -> Option<StaircaseStudy> {
    if t.contains_key("conditions") {
        cx.err(
            "conditions",
            "a staircase study takes its stimuli from [staircase]; remove [conditions]",
        );
    }
    if !matches!(familiarization_spec, FamSpec::None) {
        cx.err(
            "session.familiarization",
            "familiarization trials are not supported in a staircase study (practice trials \
             before the staircases: [staircase] practice_trials)",
        );
    }
    if session.hidden_repeats > 0 {
        cx.err(
            "session.hidden_repeats",
            "hidden repeats are not supported in a staircase study",
        );
    }
    if has_scale {
        cx.err("scale", "a staircase study has no rating scale");
    }
    if t.contains_key("scene") {
        cx.err(
            "scene",
            "crowd scenes are rated (protocol \"dscqs\" or \"mos\"), not a staircase",
        );
    }
    match cx.table(t, "", "staircase") {
        Some(st) => parse_staircase(st, manifest, codecs, cx),
        None if !t.contains_key("staircase") => {
            cx.err("staircase", "missing");
            None
        }
        None => None,
    }
}

/// A study with a `[scene]` rates crowd scenes, and only those; every one of them must be made
/// for the study's scene (levels, characters, distances), and a crowd stimulus needs a
/// `[scene]` to be drawn.
fn check_crowd_conditions(
    conditions: &[Condition],
    familiarization: &[Condition],
    scene: Option<&SceneSettings>,
    has_scene: bool,
    m: &StimulusManifest,
    cx: &mut Ctx,
) {
    let all = conditions.iter().map(|c| ("conditions", c)).chain(
        familiarization
            .iter()
            .map(|c| ("session.familiarization", c)),
    );
    for (key, c) in all {
        for id in [&c.stimulus, &c.reference] {
            let Some(st) = m.get(id) else { continue };
            match (st.scene.is_some(), scene) {
                (true, Some(scene)) => check_scene_stimulus(st, scene, m, key, cx),
                (true, None) if !has_scene => cx.err(
                    key,
                    format!("{id:?} is a crowd scene: the study needs a [scene] to draw it"),
                ),
                (false, Some(_)) => cx.err(
                    key,
                    format!(
                        "{id:?} is one clip, not a crowd scene: a study with a [scene] rates \
                         the scenes of `study crowd`"
                    ),
                ),
                _ => {}
            }
        }
    }
}

/// `[simulation] attention` names groups or characters of the `[scene]`.
fn check_attention(
    simulation: &SimulationSettings,
    scene: Option<&SceneSettings>,
    has_scene: bool,
    cx: &mut Ctx,
) {
    if simulation.attention.is_empty() {
        return;
    }
    let Some(scene) = scene else {
        if !has_scene {
            cx.err(
                "simulation.attention",
                "attention weights are for the characters of a [scene]",
            );
        }
        return;
    };
    for k in simulation.attention.keys() {
        if scene.character(k).is_none() && !scene.groups().contains(&k.as_str()) {
            cx.err(
                format!("simulation.attention.{k}"),
                format!(
                    "{k:?} is neither a group ({}) nor a character of the [scene]",
                    scene.groups().join(", ")
                ),
            );
        }
    }
}

/// A live staircase's simulated observer is told the error measured on the decoded clip,
/// which is its joint RMS error: detecting by error there needs `metric = "rms_cm"`.
fn check_live_metric(t: &Table, simulation: &SimulationSettings, cx: &mut Ctx) {
    let live = t
        .get("staircase")
        .and_then(Value::as_table)
        .is_some_and(|st| st.contains_key("live"));
    if live && simulation.detection == Detection::Error && simulation.metric != Metric::RmsCm {
        cx.err(
            "simulation.metric",
            "a live staircase measures rms_cm on the decoded clip; set metric = \"rms_cm\"",
        );
    }
}

/// The manifest's own problems, each naming its file (`path`, as the `stimuli` key gives it)
/// and the entry.
fn check_manifest(path: &str, m: &StimulusManifest, cx: &mut Ctx) {
    for problem in m.problems() {
        cx.err("stimuli", format!("{path}: {problem}"));
    }
}
