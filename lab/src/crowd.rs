//! Crowd stimuli (thesis 6.5): the scenes of a study's `[scene]` compressed character by
//! character, either at a ratio per group (the thesis's study: the front character at 40:1,
//! the back ones varied) or under one total budget per scene shared uniformly, by distance
//! (eq. 6.4-6.5: `S_C = d_m / d_C`, `B_k = S_k·B / Σ S_i`) or by importance scores the scene
//! gives. Every character's stream, decoded clip, ratio and error are an ordinary stimulus of
//! the manifest; every scene, at every distance level, is a crowd stimulus naming them
//! ([`protocols::manifest::SceneStimulus`]), with a reference scene per level. `rd.csv` has
//! one row per character of every compressed scene.
//!
//! A budget is in bytes (or a scene ratio: the characters' raw sizes over it). Each
//! character's share `B_k` becomes its target ratio `raw_k / B_k`, rounded to 4 significant
//! digits (so scenes that give a character the same share reuse one stimulus); SPIHT reaches
//! a target within a byte, so the scene's streams add up to its budget within 0.1 %.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use codecs::codec::Params;
use codecs::codec::spiht::{crowd_scores, share_budget};
use motion::Clip;
use protocols::manifest::{
    MANIFEST_VERSION, REFERENCE_CODEC, SceneMember, SceneStimulus, Stimulus, StimulusManifest,
};
use protocols::study::SceneSettings;

use crate::catalog::Codecs;
use crate::clips::{self, ClipOptions};
use crate::error::{Context as _, Result, refused};
use crate::stimulus::{self, Request};
use crate::sweep::{
    Member, SweepClip, Target, csv_record, parallel, read_references, stimulus_id, write_made,
    write_set,
};

/// How the bytes of a scene are shared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Share {
    /// Every character the same share of the budget.
    Uniform,
    /// Eq. 6.4-6.5: in proportion to `d_m / d_C`.
    Distance,
    /// In proportion to each character's `importance` in the `[scene]`.
    Importance,
}

impl Share {
    /// The name in ids, the manifest and `rd.csv`.
    pub fn as_str(self) -> &'static str {
        match self {
            Share::Uniform => "uniform",
            Share::Distance => "distance",
            Share::Importance => "importance",
        }
    }
}

/// One scene's total budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// The scene's compression ratio: the characters' raw sizes (4 bytes × channels ×
    /// frames each) over the total.
    Cr(f64),
    /// The total in bytes.
    Bytes(f64),
}

impl Budget {
    /// The budget's part of a scene id: `cr30`, `b12000`.
    fn label(self) -> String {
        match self {
            Budget::Cr(c) => format!("cr{c}"),
            Budget::Bytes(b) => format!("b{b}"),
        }
    }
}

/// What the scenes' characters are compressed to.
#[derive(Debug, Clone, PartialEq)]
pub enum Plan {
    /// A ratio per group of the scene, every group named once; a group with several ratios
    /// makes a scene per ratio (every combination, the first group slowest).
    Fixed(Vec<(String, Vec<f64>)>),
    /// A total budget per scene (one scene per budget), shared as `share` says.
    Budget {
        /// The totals.
        totals: Vec<Budget>,
        /// How each is shared.
        share: Share,
    },
}

/// What `study crowd` makes.
#[derive(Debug, Clone)]
pub struct CrowdOptions {
    /// A TOML file with a `[scene]` (the study file).
    pub scene: PathBuf,
    /// Clip files, paired by [`motion::pairing`]; every clip a character performs.
    pub clips: Vec<PathBuf>,
    /// How they are read.
    pub clip_options: ClipOptions,
    /// The codec (one with rate control; the thesis's is `spiht`).
    pub codec: String,
    /// Fixed codec parameters (part of the characters' stimulus ids when given).
    pub params: Params,
    /// The ratios or budgets.
    pub plan: Plan,
    /// Output folder (gets `stimuli.json`, `rd.csv` and one folder per clip).
    pub output: PathBuf,
    /// Worker threads.
    pub jobs: usize,
    /// Write into a folder that holds files, replacing those of the same names.
    pub force: bool,
}

/// What `study crowd` wrote.
#[derive(Debug, Clone)]
pub struct CrowdSummary {
    /// The manifest written.
    pub manifest: StimulusManifest,
    /// Compressed scenes (not counting the reference scene of each level).
    pub scenes: usize,
    /// Character stimuli encoded.
    pub encoded: usize,
    /// The budgeted scenes whose streams add up furthest from their budget: (scene id,
    /// budget bytes, bytes).
    pub worst_budget: Option<(String, f64, u64)>,
}

/// A character's compressed stimulus: clip and target.
#[derive(Debug, Clone, PartialEq)]
struct Job {
    clip: String,
    target: f64,
}

/// One compressed scene to assemble.
struct SceneSpec {
    id: String,
    level: usize,
    allocation: &'static str,
    budget_bytes: Option<f64>,
    scene_cr: Option<f64>,
    /// Per character: target ratio, share score and budget.
    members: Vec<(f64, Option<f64>, Option<f64>)>,
}

/// The header of a crowd set's `rd.csv` (columns in `docs/codecs.md`, "Crowds").
const RD_HEADER: &str = "scene,level,allocation,character,group,clip,distance_cm,score,budget_bytes,target_cr,achieved_cr,bytes,rms_cm,max_cm,worst_window_rms_cm,mean_angle_deg,stimulus,scene_budget_bytes,scene_bytes,scene_cr\n";

/// Rounds `v` to 4 significant digits (a budget's target ratio).
fn four_digits(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return v;
    }
    let e = v.log10().floor() as i32 - 3;
    let scale = 10f64.powi(-e);
    (v * scale).round() / scale
}

/// A clip's raw size, 4 bytes × channels × frames.
fn raw_size(clip: &Clip) -> f64 {
    4.0 * (clip.channel_count() * clip.frames()) as f64
}

/// Makes the crowd set `options` asks for.
///
/// # Errors
/// The scene file's problems, a plan that does not fit the scene (a group not named, a ratio
/// or budget that is not positive, importance without scores), clips that do not pair or read
/// or that a character needs but are not given, a level named like a clip, an unknown codec
/// or one without rate control, an output folder holding files without `force`, a target
/// the codec cannot reach (naming the character, level and ratio), or an unwritable output;
/// all but the last two before anything is encoded.
pub fn crowd(
    options: &CrowdOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<CrowdSummary> {
    let scene = SceneSettings::read(&options.scene)?;
    let codecs = Codecs::default();
    let codec = codecs.get(&options.codec)?;
    if codec.rate_control() == codecs::codec::RateControl::None {
        return Err(refused(format!(
            "codec `{}` takes no target rate; a crowd needs one with rate control (spiht)",
            options.codec
        )));
    }
    check_plan(&options.plan, &scene)?;
    let sources = clips::sources(&options.clips, &options.clip_options)?;
    check_clips(options, &scene, &sources)?;
    let out = &options.output;
    let mode = files::Mode::from_force(options.force);
    files::prepare_dir(out, mode)?;
    // The clips the scene uses, read and copied as references.
    let used: Vec<_> = sources
        .into_iter()
        .filter(|s| scene.characters.iter().any(|c| c.clip == s.name))
        .collect();
    let (read, references) = read_references(
        &used,
        options.clip_options.bvh_unit_cm,
        out,
        options.jobs,
        mode,
    )?;
    let read: BTreeMap<String, SweepClip> = read.into_iter().map(|c| (c.name.clone(), c)).collect();
    let mut manifest = StimulusManifest {
        version: MANIFEST_VERSION,
        cr_basis: protocols::manifest::CrBasis::File,
        stimuli: references,
    };
    let raw = |clip: &str| read.get(clip).map_or(0.0, |c| raw_size(&c.clip));
    let specs = match &options.plan {
        Plan::Fixed(groups) => fixed_specs(options, &scene, groups),
        Plan::Budget { totals, share } => budget_specs(options, &scene, totals, *share, &raw)?,
    };
    let (members, encoded) =
        encode_members(options, codec.as_ref(), &scene, &specs, &read, progress)?;
    manifest.stimuli.extend(members.values().cloned());
    manifest.stimuli.extend(reference_scenes(&scene));
    let mut csv = String::from(RD_HEADER);
    let mut worst: Option<(String, f64, u64)> = None;
    for spec in &specs {
        let st = assemble(options, &scene, spec, &members, &raw, &mut csv)?;
        if let Some(b) = spec.budget_bytes {
            let off = |bytes: u64, budget: f64| (bytes as f64 - budget).abs() / budget;
            if worst
                .as_ref()
                .is_none_or(|(_, wb, wy)| off(st.bytes, b) > off(*wy, *wb))
            {
                worst = Some((spec.id.clone(), b, st.bytes));
            }
        }
        manifest.stimuli.push(st);
    }
    write_set(out, &csv, &mut manifest, mode)?;
    Ok(CrowdSummary {
        manifest,
        scenes: specs.len(),
        encoded,
        worst_budget: worst,
    })
}

/// Every clip a character performs is given, and no level is named like a clip.
fn check_clips(
    options: &CrowdOptions,
    scene: &SceneSettings,
    sources: &[motion::pairing::ClipSource],
) -> Result<()> {
    let names: BTreeSet<&str> = sources.iter().map(|s| s.name.as_str()).collect();
    for c in &scene.characters {
        if !names.contains(c.clip.as_str()) {
            return Err(refused(format!(
                "{}: character {:?} performs clip {:?}, which --clips does not give (it \
                 gives {})",
                options.scene.display(),
                c.name,
                c.clip,
                names.iter().copied().collect::<Vec<_>>().join(", ")
            )));
        }
    }
    if let Some(l) = scene.levels.iter().find(|l| names.contains(l.as_str())) {
        return Err(refused(format!(
            "{}: level {l:?} is also the name of a clip; rename one (a scene's stimuli are \
             named after its level)",
            options.scene.display()
        )));
    }
    Ok(())
}

/// Every character stimulus the scenes show, encoded once on the worker threads and written;
/// by id, with how many were encoded.
fn encode_members(
    options: &CrowdOptions,
    codec: &dyn codecs::codec::Codec,
    scene: &SceneSettings,
    specs: &[SceneSpec],
    read: &BTreeMap<String, SweepClip>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(BTreeMap<String, Stimulus>, usize)> {
    let mut jobs: Vec<Job> = Vec::new();
    for spec in specs {
        for (c, (target, _, _)) in scene.characters.iter().zip(&spec.members) {
            let job = Job {
                clip: c.clip.clone(),
                target: *target,
            };
            if !jobs.contains(&job) {
                jobs.push(job);
            }
        }
    }
    let out = &options.output;
    let mode = files::Mode::from_force(options.force);
    let done = AtomicUsize::new(0);
    let made = parallel(
        &jobs,
        options.jobs,
        |j| read.get(&j.clip).map_or(0, |f| f.clip.frames()),
        |j| {
            let id = stimulus_id(
                &j.clip,
                &options.codec,
                &options.params,
                Target::Cr(j.target),
            );
            let request = Request {
                params: options.params.clone(),
                target_cr: Some(j.target),
            };
            let r = read
                .get(&j.clip)
                .context(|| format!("{id}: clip {:?} was not read", j.clip))
                .and_then(|f| {
                    let m = stimulus::make(codec, &f.clip, &request)
                        .context(|| format!("{id} (a character of the crowd)"))?;
                    let member = Member {
                        id,
                        clip: &j.clip,
                        codec: &options.codec,
                        variant: &options.params,
                        target: Target::Cr(j.target),
                        dir: &f.dir,
                        skeleton: f.skeleton.as_deref(),
                        cr_factor: 1.0,
                    };
                    write_made(&m, member, out, mode)
                });
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, jobs.len());
            r
        },
    )?;
    let mut members = BTreeMap::new();
    for m in made {
        let m = m?;
        members.insert(m.id.clone(), m);
    }
    Ok((members, jobs.len()))
}

/// A scene stimulus of the manifest (no file of its own).
fn scene_stimulus(
    id: String,
    codec: &str,
    scene: SceneStimulus,
    cr: (Option<f64>, f64),
    bytes: u64,
) -> Stimulus {
    Stimulus {
        id,
        clip: scene.level.clone(),
        codec: codec.to_string(),
        params: BTreeMap::new(),
        variant: BTreeMap::new(),
        target_cr: cr.0,
        target_max_error_cm: None,
        achieved_cr: Some(cr.1),
        bytes,
        file: String::new(),
        skeleton: None,
        bitstream: None,
        metrics: None,
        encode_ms: None,
        decode_ms: None,
        scene: Some(scene),
        sha256: None,
        bitstream_sha256: None,
    }
}

/// The reference scene of every level: each character's reference clip.
fn reference_scenes(scene: &SceneSettings) -> Vec<Stimulus> {
    (0..scene.levels.len())
        .map(|level| {
            let name = &scene.levels[level];
            let characters = scene
                .characters
                .iter()
                .map(|c| SceneMember {
                    name: c.name.clone(),
                    group: c.group.clone(),
                    stimulus: format!("{}/{REFERENCE_CODEC}", c.clip),
                    distance_cm: scene.placement(c, level).distance_cm,
                    score: None,
                    budget_bytes: None,
                })
                .collect();
            let sc = SceneStimulus {
                level: name.clone(),
                allocation: REFERENCE_CODEC.into(),
                budget_bytes: None,
                characters,
            };
            scene_stimulus(
                format!("{name}/{REFERENCE_CODEC}"),
                REFERENCE_CODEC,
                sc,
                (None, 1.0),
                0,
            )
        })
        .collect()
}

/// One compressed scene's manifest entry from its characters' stimuli, and its `rd.csv` rows
/// appended to `csv`.
fn assemble(
    options: &CrowdOptions,
    scene: &SceneSettings,
    spec: &SceneSpec,
    members: &BTreeMap<String, Stimulus>,
    raw: &dyn Fn(&str) -> f64,
    csv: &mut String,
) -> Result<Stimulus> {
    let level = &scene.levels[spec.level];
    let mut characters = Vec::new();
    let (mut bytes, mut raw_total) = (0u64, 0.0);
    let mut shown = Vec::new();
    for (c, (target, score, budget)) in scene.characters.iter().zip(&spec.members) {
        let id = stimulus_id(
            &c.clip,
            &options.codec,
            &options.params,
            Target::Cr(*target),
        );
        let m = members
            .get(&id)
            .context(|| format!("{id}: the character's stimulus was not made"))?;
        bytes += m.bytes;
        raw_total += raw(&c.clip);
        shown.push((c, m, *target));
        characters.push(SceneMember {
            name: c.name.clone(),
            group: c.group.clone(),
            stimulus: id,
            distance_cm: scene.placement(c, spec.level).distance_cm,
            score: *score,
            budget_bytes: *budget,
        });
    }
    let scene_cr = raw_total / (bytes.max(1)) as f64;
    let opt = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v}"));
    let cents = |v: Option<f64>| opt(v.map(|b| (b * 100.0).round() / 100.0));
    for ((c, m, target), member) in shown.into_iter().zip(&characters) {
        let metric = |f: fn(&protocols::manifest::StimulusMetrics) -> Option<f64>| {
            m.metrics
                .as_ref()
                .and_then(f)
                .map_or_else(String::new, |v| format!("{v:.5}"))
        };
        csv.push_str(&csv_record(&[
            spec.id.clone(),
            level.clone(),
            spec.allocation.to_string(),
            c.name.clone(),
            c.group.clone(),
            c.clip.clone(),
            member.distance_cm.to_string(),
            opt(member.score),
            cents(member.budget_bytes),
            target.to_string(),
            m.achieved_cr
                .map_or_else(String::new, |c| format!("{c:.4}")),
            m.bytes.to_string(),
            metric(|x| Some(x.rms_cm)),
            metric(|x| Some(x.max_cm)),
            metric(|x| x.worst_window_rms_cm),
            metric(|x| Some(x.mean_angle_deg)),
            m.id.clone(),
            cents(spec.budget_bytes),
            bytes.to_string(),
            format!("{scene_cr:.4}"),
        ]));
    }
    let sc = SceneStimulus {
        level: level.clone(),
        allocation: spec.allocation.to_string(),
        budget_bytes: spec.budget_bytes,
        characters,
    };
    Ok(scene_stimulus(
        spec.id.clone(),
        &options.codec,
        sc,
        (spec.scene_cr, scene_cr),
        bytes,
    ))
}

/// The plan against the scene: fixed ratios name every group once, with positive ratios,
/// none twice; budgets are positive; importance needs every character's score.
fn check_plan(plan: &Plan, scene: &SceneSettings) -> Result<()> {
    match plan {
        Plan::Fixed(groups) => {
            let wanted = scene.groups();
            for (i, (g, values)) in groups.iter().enumerate() {
                if !wanted.contains(&g.as_str()) {
                    return Err(refused(format!(
                        "--cr {g}=...: the scene has no group {g:?} (its groups: {})",
                        wanted.join(", ")
                    )));
                }
                if groups[..i].iter().any(|(h, _)| h == g) {
                    return Err(refused(format!("--cr {g} is given twice")));
                }
                if values.is_empty() {
                    return Err(refused(format!("--cr {g}: no ratio")));
                }
                for (k, v) in values.iter().enumerate() {
                    if !(v.is_finite() && *v > 0.0) {
                        return Err(refused(format!("--cr {g}={v}: ratios must be positive")));
                    }
                    if values[..k].contains(v) {
                        return Err(refused(format!("--cr {g}: {v} is listed twice")));
                    }
                }
            }
            if let Some(g) = wanted.iter().find(|g| !groups.iter().any(|(h, _)| h == *g)) {
                return Err(refused(format!(
                    "no ratio for group {g:?}: give --cr {g}=... (every group of the scene: {})",
                    wanted.join(", ")
                )));
            }
        }
        Plan::Budget { totals, share } => {
            if totals.is_empty() {
                return Err(refused("no budget: give --budget-cr or --budget-bytes"));
            }
            for b in totals {
                let v = match b {
                    Budget::Cr(v) | Budget::Bytes(v) => *v,
                };
                if !(v.is_finite() && v > 0.0) {
                    return Err(refused(format!("budget {v}: must be positive")));
                }
            }
            if *share == Share::Importance
                && let Some(c) = scene.characters.iter().find(|c| c.importance.is_none())
            {
                return Err(refused(format!(
                    "--share importance: character {:?} has no importance in the [scene]",
                    c.name
                )));
            }
        }
    }
    Ok(())
}

/// The scenes of fixed ratios: every combination of the groups' ratios (in the scene's group
/// order, the first slowest) at every level.
fn fixed_specs(
    options: &CrowdOptions,
    scene: &SceneSettings,
    groups: &[(String, Vec<f64>)],
) -> Vec<SceneSpec> {
    let mut combos: Vec<Vec<(&str, f64)>> = vec![Vec::new()];
    for g in scene.groups() {
        let values = groups
            .iter()
            .find(|(h, _)| h == g)
            .map(|(_, v)| v.as_slice())
            .unwrap_or_default();
        combos = combos
            .iter()
            .flat_map(|c| {
                values.iter().map(move |v| {
                    let mut c = c.clone();
                    c.push((g, *v));
                    c
                })
            })
            .collect();
    }
    let mut out = Vec::new();
    for level in 0..scene.levels.len() {
        for combo in &combos {
            let label: Vec<String> = combo.iter().map(|(g, v)| format!("{g}{v}")).collect();
            let ratio = |group: &str| {
                combo
                    .iter()
                    .find(|(g, _)| *g == group)
                    .map_or(f64::NAN, |(_, v)| *v)
            };
            out.push(SceneSpec {
                id: format!(
                    "{}/{}/{}",
                    scene.levels[level],
                    options.codec,
                    label.join("-")
                ),
                level,
                allocation: "fixed",
                budget_bytes: None,
                scene_cr: None,
                members: scene
                    .characters
                    .iter()
                    .map(|c| (ratio(&c.group), None, None))
                    .collect(),
            });
        }
    }
    out
}

/// The scenes of shared budgets: one per budget and level, each character's share by eq. 6.5
/// of the scores `share` gives.
fn budget_specs(
    options: &CrowdOptions,
    scene: &SceneSettings,
    totals: &[Budget],
    share: Share,
    raw: &dyn Fn(&str) -> f64,
) -> Result<Vec<SceneSpec>> {
    let raws: Vec<f64> = scene.characters.iter().map(|c| raw(&c.clip)).collect();
    let raw_total: f64 = raws.iter().sum();
    let mut out = Vec::new();
    for level in 0..scene.levels.len() {
        let scores: Vec<f64> = match share {
            Share::Uniform => vec![1.0; scene.characters.len()],
            Share::Importance => scene
                .characters
                .iter()
                .map(|c| c.importance.unwrap_or(f64::NAN))
                .collect(),
            Share::Distance => {
                let d: Vec<f64> = scene
                    .characters
                    .iter()
                    .map(|c| scene.placement(c, level).distance_cm)
                    .collect();
                crowd_scores(&d).context(|| {
                    format!(
                        "level {:?}: a distance is not positive",
                        scene.levels[level]
                    )
                })?
            }
        };
        for total in totals {
            let bytes = match total {
                Budget::Cr(c) => raw_total / c,
                Budget::Bytes(b) => *b,
            };
            let shares = share_budget(&scores, bytes)
                .context(|| format!("budget {bytes} bytes: a share score is not positive"))?;
            let members = scores
                .iter()
                .zip(&shares)
                .zip(&raws)
                .map(|((s, b), r)| (four_digits(r / b), Some(*s), Some(*b)))
                .collect();
            out.push(SceneSpec {
                id: format!(
                    "{}/{}/{}-{}",
                    scene.levels[level],
                    options.codec,
                    total.label(),
                    share.as_str()
                ),
                level,
                allocation: share.as_str(),
                budget_bytes: Some(bytes),
                scene_cr: match total {
                    Budget::Cr(c) => Some(*c),
                    Budget::Bytes(_) => None,
                },
                members,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::four_digits;

    #[test]
    fn budget_targets_keep_four_significant_digits() {
        assert!((four_digits(37.523_41) - 37.52).abs() < 1e-12);
        assert!((four_digits(123_456.0) - 123_500.0).abs() < 1e-6);
        assert!((four_digits(0.012_345_6) - 0.012_35).abs() < 1e-12);
        assert!((four_digits(40.0) - 40.0).abs() < 1e-12);
    }
}
