//! A stimulus set: every clip × codec × parameter variant × target (a compression ratio, or a
//! bound on the max joint error), made on worker threads and written with its reference
//! copies, a `stimuli.json` manifest and a rate–distortion CSV.
//!
//! A variant is one combination of [`SweepOptions::params`] (their Cartesian product); its
//! parameters are part of the stimulus id (`walk/wavelet-perceptual/qp9-window128/cr20`),
//! the manifest entry's `variant` and the `rd.csv` row, and absent from all three when no
//! parameter is varied, so ids stay what they were. A target a codec cannot reach (the
//! primitive codec at 60:1, a bound below what its largest stream achieves) is recorded as an
//! `unreachable` row of `rd.csv` and in [`SweepSummary::unreachable`]; the sweep goes on,
//! and `stimuli.json` lists what was made.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use codecs::basis::CrBasis;
use codecs::codec::{CodecError, Params, RateControl};
use motion::Clip;
use protocols::manifest::{
    MANIFEST_VERSION, REFERENCE_CODEC, Stimulus, StimulusManifest, variant_label,
};

use crate::bounded;
use crate::catalog::Codecs;
use crate::clips::{self, ClipOptions};
use crate::error::{Context as _, LabError, Result, chain, io_error, refused};
use crate::stimulus::{self, Made, Request};

/// The manifest file a sweep writes.
pub const MANIFEST_FILE: &str = "stimuli.json";
/// The rate–distortion table a sweep writes.
pub const RD_FILE: &str = "rd.csv";
/// Header of [`RD_FILE`] (columns in `docs/codecs.md`, "rd.csv").
const RD_HEADER: &str = "clip,codec,params,target_cr,target_max_error_cm,status,achieved_cr,bytes,rms_cm,max_cm,worst_window_rms_cm,worst_window_start_frame,mean_angle_deg,foot_slide_cm_s,encode_ms,decode_ms,id,reason,cr_basis\n";

/// What a sweep makes.
#[derive(Debug, Clone, Default)]
pub struct SweepOptions {
    /// Clip files: motions and skeletons, paired by [`motion::pairing`].
    pub clips: Vec<PathBuf>,
    /// How they are read.
    pub clip_options: ClipOptions,
    /// Codec names (each with rate control).
    pub codecs: Vec<String>,
    /// Target compression ratios.
    pub targets: Vec<f64>,
    /// Bounds on the max joint position error, cm: for each, the smallest stream within it
    /// ([`bounded::make_within`]). A sweep needs targets, bounds or both.
    pub max_errors_cm: Vec<f64>,
    /// Codec parameters to vary, each key with its values (`qp` → 7, 9, 11): every codec is
    /// run at every combination (the Cartesian product) and every target. Each key must be a
    /// parameter of every codec swept, and neither `cr` nor the codec's rate knob (`alpha`,
    /// `t_l`), which the rate control sets. Empty: the codecs' defaults.
    pub params: Vec<(String, Vec<f64>)>,
    /// Output folder (gets the manifest, the CSV and one folder per clip).
    pub output: PathBuf,
    /// Worker threads (at least 1).
    pub jobs: usize,
    /// Primitive database for the `primitive` codec.
    pub database: Option<PathBuf>,
    /// A file of command-defined codecs ([`crate::codec_defs`]) the sweep may name.
    pub codec_defs: Option<PathBuf>,
    /// Which channels the targets and the achieved ratios count ([`CrBasis`]): the seed
    /// basis aims each target at the seeds' raw size and records it in the manifest.
    pub cr_basis: CrBasis,
    /// Write into an output folder that holds files, replacing those of the same names
    /// (atomically, each whole); without it such a folder is refused before anything is
    /// made. Files of an earlier sweep that this one does not make are left as they are.
    pub force: bool,
}

/// What a sweep wrote.
#[derive(Debug, Clone)]
pub struct SweepSummary {
    /// The manifest written (references first, then the stimuli made in clip, codec,
    /// variant, target order).
    pub manifest: StimulusManifest,
    /// Reference clips among them.
    pub references: usize,
    /// The targets not reached, in the same order (also `unreachable` rows of `rd.csv`).
    pub unreachable: Vec<Unreachable>,
}

/// What one stimulus of a sweep is made for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// A compression ratio, reached by the codec's rate control within ±2 %.
    Cr(f64),
    /// A bound on the max joint position error, cm: the smallest stream within it.
    MaxErrorCm(f64),
}

impl Target {
    /// The target's part of a stimulus id and file name: `cr20`, `max0.5cm`.
    pub fn label(self) -> String {
        match self {
            Target::Cr(t) => format!("cr{t}"),
            Target::MaxErrorCm(e) => format!("max{e}cm"),
        }
    }
}

/// A stimulus a sweep could not make because its target cannot be reached.
#[derive(Debug, Clone, PartialEq)]
pub struct Unreachable {
    /// The id it would have had.
    pub id: String,
    /// Clip name.
    pub clip: String,
    /// Codec name.
    pub codec: String,
    /// The varied parameters.
    pub variant: Params,
    /// The target.
    pub target: Target,
    /// Why (the codec's message, with the closest it came).
    pub reason: String,
}

/// A sweep's clip: name, clip, its ASF in the output (for AMC), its output folder.
pub(crate) struct SweepClip {
    pub name: String,
    pub clip: Clip,
    pub skeleton: Option<PathBuf>,
    pub dir: PathBuf,
    /// A file-basis CR times this is the CR on the sweep's basis ([`CrBasis::factor`]).
    pub cr_factor: f64,
}

struct Job {
    clip: usize,
    codec: String,
    variant: Params,
    target: Target,
}

/// Fixed codec parameters written `KEY=VALUE` (`qp=9`), as `study encode --param` and `study
/// crowd --param` take them.
///
/// # Errors
/// An item without `=`, or a value that is not a number, naming the item.
pub fn parse_params(items: &[String]) -> Result<Params> {
    let mut p = Params::new();
    for item in items {
        let Some((k, v)) = item.split_once('=') else {
            return Err(refused(format!("--param `{item}`: expected KEY=VALUE")));
        };
        let Ok(v) = v.trim().parse::<f64>() else {
            return Err(refused(format!("--param `{item}`: not a number")));
        };
        p.insert(k.trim().to_string(), v);
    }
    Ok(p)
}

/// Values to vary written `KEY=V1,V2,...` (`--param qp=7,9,11` of `study sweep`, `--cr
/// back=20,40` of `study crowd`), in the order given, for [`SweepOptions::params`]; `flag`
/// names the option in messages.
///
/// # Errors
/// An item without `=`, or a value that is not a number, naming the item.
pub fn parse_grid(flag: &str, items: &[String]) -> Result<Vec<(String, Vec<f64>)>> {
    items
        .iter()
        .map(|item| {
            let Some((k, v)) = item.split_once('=') else {
                return Err(refused(format!("{flag} `{item}`: expected KEY=V1,V2,...")));
            };
            let values = v.split(',').map(|x| {
                x.trim()
                    .parse::<f64>()
                    .map_err(|_| refused(format!("{flag} `{item}`: `{x}` is not a number")))
            });
            Ok((k.trim().to_string(), values.collect::<Result<Vec<f64>>>()?))
        })
        .collect()
}

/// What became of one job.
enum Outcome {
    /// Made: its manifest entry and `rd.csv` row.
    Made(Box<Stimulus>, RdRow),
    /// Not reachable: what was asked and why, and its `rd.csv` row.
    Unreachable(Unreachable, RdRow),
}

/// Runs a sweep; `progress(done, total)` is called from the workers after each stimulus.
///
/// # Errors
/// A bad target or bound (not positive, or given twice), no target at all, an unknown codec
/// or one without rate control, a varied parameter a codec does not take (naming the codec's
/// keys) or that its rate control sets, clips that do not pair or read, an output folder
/// holding files without [`SweepOptions::force`] ([`files::Error::NotEmpty`], naming the
/// folder and what it holds), a codec refusing a parameter's value, or an output that cannot
/// be written; all but the last two before anything is encoded. A target the codec cannot
/// reach is no error ([`SweepSummary::unreachable`]). Every file is written whole or not at
/// all ([`files::write`]), so a failed sweep (a full disk) leaves complete files only.
pub fn sweep(
    options: &SweepOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SweepSummary> {
    let targets = check_targets(options)?;
    let codecs = Codecs::with_files(options.database.as_deref(), options.codec_defs.as_deref())?;
    for name in &options.codecs {
        if codecs.get(name)?.rate_control() == RateControl::None {
            return Err(refused(format!(
                "codec `{name}` takes no target rate; sweep lossy codecs"
            )));
        }
    }
    let variants = variants(&options.params)?;
    for name in &options.codecs {
        let keys: Vec<&str> = options.params.iter().map(|(k, _)| k.as_str()).collect();
        codecs.check_varied_params(name, &keys)?;
    }
    let inputs = clips::sources(&options.clips, &options.clip_options)?;
    let out = &options.output;
    let mode = files::Mode::from_force(options.force);
    files::prepare_dir(out, mode)?;
    let (mut sweep_clips, references) = read_references(
        &inputs,
        options.clip_options.bvh_unit_cm,
        out,
        options.jobs,
        mode,
    )?;
    for c in &mut sweep_clips {
        c.cr_factor = options
            .cr_basis
            .factor(&c.clip.skeleton)
            .map_err(|e| refused(format!("{}: {e}", c.name)))?;
    }
    let mut manifest = StimulusManifest {
        version: MANIFEST_VERSION,
        cr_basis: manifest_basis(options.cr_basis),
        stimuli: references,
    };
    let mut jobs = Vec::new();
    for clip in 0..sweep_clips.len() {
        for codec in &options.codecs {
            for variant in &variants {
                for &target in &targets {
                    jobs.push(Job {
                        clip,
                        codec: codec.clone(),
                        variant: variant.clone(),
                        target,
                    });
                }
            }
        }
    }
    let done = AtomicUsize::new(0);
    let results = parallel(
        &jobs,
        options.jobs,
        // Longest clips first, so that no worker is left with a long job at the end.
        |job| sweep_clips[job.clip].clip.frames(),
        |job| {
            let r = make_job(job, &sweep_clips, out, &codecs, mode);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, jobs.len());
            r
        },
    )?;
    let mut csv = String::from(RD_HEADER);
    let mut unreachable = Vec::new();
    for r in results {
        match r? {
            Outcome::Made(stimulus, row) => {
                csv.push_str(&row.to_csv(options.cr_basis));
                manifest.stimuli.push(*stimulus);
            }
            Outcome::Unreachable(u, row) => {
                csv.push_str(&row.to_csv(options.cr_basis));
                unreachable.push(u);
            }
        }
    }
    write_set(out, &csv, &mut manifest, mode)?;
    Ok(SweepSummary {
        manifest,
        references: sweep_clips.len(),
        unreachable,
    })
}

/// Reads every clip of `inputs` and writes its reference copy into `out/<clip>/` (on `jobs`
/// worker threads: a parse and a format of every value), in input order, with their manifest
/// entries.
pub(crate) fn read_references(
    inputs: &[motion::pairing::ClipSource],
    bvh_unit_cm: Option<f64>,
    out: &Path,
    jobs: usize,
    mode: files::Mode,
) -> Result<(Vec<SweepClip>, Vec<Stimulus>)> {
    let read = parallel(
        inputs,
        jobs,
        |_| 0,
        |source| -> Result<(SweepClip, PathBuf)> {
            let clip = clips::read(source, bvh_unit_cm)?;
            let dir = out.join(&source.name);
            std::fs::create_dir_all(&dir).map_err(io_error(&dir))?;
            let (file, skeleton) = stimulus::write_clip_as(&clip, &dir, "reference", None, mode)?;
            let c = SweepClip {
                name: source.name.clone(),
                clip,
                skeleton,
                dir,
                cr_factor: 1.0,
            };
            Ok((c, file))
        },
    )?;
    let mut clips = Vec::with_capacity(read.len());
    let mut references = Vec::with_capacity(read.len());
    for r in read {
        let (c, file) = r?;
        references.push(reference_stimulus(
            out,
            &c.name,
            &file,
            c.skeleton.as_deref(),
        ));
        clips.push(c);
    }
    Ok((clips, references))
}

/// Writes a set's `rd.csv`, then its manifest: a `stimuli.json` on disk means every file it
/// names is complete. Each stimulus' file and bitstream are hashed first, as written (their
/// SHA-256 in the manifest, which every preflight checks).
pub(crate) fn write_set(
    out: &Path,
    csv: &str,
    manifest: &mut StimulusManifest,
    mode: files::Mode,
) -> Result<()> {
    for st in &mut manifest.stimuli {
        if !st.file.is_empty() {
            st.sha256 = Some(stimulus::sha256_file(&out.join(&st.file))?);
        }
        if let Some(b) = &st.bitstream {
            st.bitstream_sha256 = Some(stimulus::sha256_file(&out.join(b))?);
        }
    }
    files::write(&out.join(RD_FILE), csv, mode)?;
    let json = serde_json::to_string_pretty(manifest)?;
    files::write(&out.join(MANIFEST_FILE), json, mode)?;
    Ok(())
}

/// The sweep's targets, ratios first: each positive, none twice (they would make one id
/// twice), and at least one.
fn check_targets(options: &SweepOptions) -> Result<Vec<Target>> {
    for &t in &options.targets {
        if !(t.is_finite() && t > 0.0) {
            return Err(refused(format!(
                "--cr {t}: compression ratios must be positive"
            )));
        }
    }
    for &e in &options.max_errors_cm {
        if !(e.is_finite() && e > 0.0) {
            return Err(refused(format!(
                "--max-error-cm {e}: error bounds must be a positive number of cm"
            )));
        }
    }
    once_each("--cr", &options.targets)?;
    once_each("--max-error-cm", &options.max_errors_cm)?;
    let targets: Vec<Target> = options
        .targets
        .iter()
        .map(|&t| Target::Cr(t))
        .chain(options.max_errors_cm.iter().map(|&e| Target::MaxErrorCm(e)))
        .collect();
    if targets.is_empty() {
        return Err(refused(
            "nothing to make: give target ratios (--cr) or error bounds (--max-error-cm)",
        ));
    }
    Ok(targets)
}

/// Refuses a value listed twice in `flag`'s list.
fn once_each(flag: &str, values: &[f64]) -> Result<()> {
    for (i, v) in values.iter().enumerate() {
        if values[..i].contains(v) {
            return Err(refused(format!("{flag}: {v} is listed twice")));
        }
    }
    Ok(())
}

/// Every combination of the varied parameters' values (one empty set when none varies), in
/// the order the values were given, the first parameter slowest.
fn variants(params: &[(String, Vec<f64>)]) -> Result<Vec<Params>> {
    let mut out = vec![Params::new()];
    for (i, (key, values)) in params.iter().enumerate() {
        if params[..i].iter().any(|(k, _)| k == key) {
            return Err(refused(format!(
                "--param {key} is given twice; list its values in one: {key}=7,9,11"
            )));
        }
        if values.is_empty() {
            return Err(refused(format!("--param {key}: no values")));
        }
        for v in values {
            if !v.is_finite() {
                return Err(refused(format!("--param {key}={v}: not a finite number")));
            }
        }
        once_each(&format!("--param {key}"), values)?;
        out = out
            .iter()
            .flat_map(|p| {
                values.iter().map(move |v| {
                    let mut p = p.clone();
                    p.insert(key.clone(), *v);
                    p
                })
            })
            .collect();
    }
    Ok(out)
}

/// `make` of every item on `threads` workers, results in item order. Items are handed out
/// largest `size` first (ties in item order), so the output does not depend on the number of
/// threads or on which finishes first.
pub(crate) fn parallel<I: Sync, T: Send>(
    items: &[I],
    threads: usize,
    size: impl Fn(&I) -> usize,
    make: impl Fn(&I) -> T + Sync,
) -> Result<Vec<T>> {
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(size(&items[i])));
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, T)>> = Mutex::new(Vec::with_capacity(items.len()));
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, 64).min(items.len().max(1)) {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&i) = order.get(k) else { break };
                    let r = make(&items[i]);
                    if let Ok(mut v) = results.lock() {
                        v.push((i, r));
                    }
                }
            });
        }
    });
    let mut results = results
        .into_inner()
        .map_err(|_| refused("a sweep worker panicked"))?;
    if results.len() != items.len() {
        return Err(refused("a sweep worker panicked"));
    }
    results.sort_by_key(|(i, _)| *i);
    Ok(results.into_iter().map(|(_, r)| r).collect())
}

/// `p` relative to the manifest folder `dir`, with `/` separators.
pub(crate) fn rel(dir: &Path, p: &Path) -> String {
    p.strip_prefix(dir)
        .unwrap_or(p)
        .to_string_lossy()
        .replace('\\', "/")
}

pub(crate) fn reference_stimulus(
    out: &Path,
    name: &str,
    file: &Path,
    skeleton: Option<&Path>,
) -> Stimulus {
    Stimulus {
        id: format!("{name}/{REFERENCE_CODEC}"),
        clip: name.to_string(),
        codec: REFERENCE_CODEC.into(),
        params: BTreeMap::new(),
        variant: BTreeMap::new(),
        target_cr: None,
        target_max_error_cm: None,
        achieved_cr: Some(1.0),
        bytes: 0,
        file: rel(out, file),
        skeleton: skeleton.map(|s| rel(out, s)),
        bitstream: None,
        metrics: None,
        encode_ms: None,
        decode_ms: None,
        scene: None,
        sha256: None,
        bitstream_sha256: None,
    }
}

/// The id of a sweep stimulus: clip, codec, the variant when one is varied, and the target
/// (`walk/wavelet-perceptual/qp9-window128/cr20`, `walk/spiht/max0.5cm`).
pub fn stimulus_id(clip: &str, codec: &str, variant: &Params, target: Target) -> String {
    if variant.is_empty() {
        format!("{clip}/{codec}/{}", target.label())
    } else {
        format!(
            "{clip}/{codec}/{}/{}",
            variant_label(variant),
            target.label()
        )
    }
}

/// The manifest's name of a CR basis.
pub fn manifest_basis(basis: CrBasis) -> protocols::manifest::CrBasis {
    match basis {
        CrBasis::File => protocols::manifest::CrBasis::File,
        CrBasis::Seed => protocols::manifest::CrBasis::Seed,
    }
}

/// The counting of a manifest's CR basis.
pub fn codec_basis(basis: protocols::manifest::CrBasis) -> CrBasis {
    match basis {
        protocols::manifest::CrBasis::File => CrBasis::File,
        protocols::manifest::CrBasis::Seed => CrBasis::Seed,
    }
}

/// One stimulus and its CSV row, or its target recorded as unreachable.
fn make_job(
    job: &Job,
    clips: &[SweepClip],
    out: &Path,
    codecs: &Codecs,
    mode: files::Mode,
) -> Result<Outcome, LabError> {
    let c = &clips[job.clip];
    let codec = codecs.get(&job.codec)?;
    let id = stimulus_id(&c.name, &job.codec, &job.variant, job.target);
    let made = match job.target {
        // The rate control counts the file's channels: a target on another basis is
        // aimed at the same bytes.
        Target::Cr(t) => stimulus::make(
            codec.as_ref(),
            &c.clip,
            &Request {
                params: job.variant.clone(),
                target_cr: Some(t / c.cr_factor),
            },
        ),
        Target::MaxErrorCm(e) => {
            bounded::make_within(codec.as_ref(), &c.clip, &job.variant, e).map(|b| b.made)
        }
    };
    let unreachable = |reason: String| {
        let row = RdRow::unreachable(c, job, &id, &reason);
        Outcome::Unreachable(
            Unreachable {
                id: id.clone(),
                clip: c.name.clone(),
                codec: job.codec.clone(),
                variant: job.variant.clone(),
                target: job.target,
                reason,
            },
            row,
        )
    };
    let made = match made {
        Ok(m) => m,
        Err(e @ (LabError::Codec(CodecError::Rate { .. }) | LabError::BoundUnreachable { .. })) => {
            return Ok(unreachable(chain(&e)));
        }
        Err(e) => {
            return Err(e).context(|| id.clone());
        }
    };
    // The CR search of the wavelet codecs steps the quantiser when α alone cannot reach a
    // target; the stream would then not be the variant its id names.
    if let Some(reason) = off_variant(&made, &job.variant, job.target) {
        return Ok(unreachable(reason));
    }
    let row = RdRow::made(c, job, &id, &made);
    let stimulus = write_made(
        &made,
        Member {
            id,
            clip: &c.name,
            codec: &job.codec,
            variant: &job.variant,
            target: job.target,
            dir: &c.dir,
            skeleton: c.skeleton.as_deref(),
            cr_factor: c.cr_factor,
        },
        out,
        mode,
    )?;
    Ok(Outcome::Made(Box::new(stimulus), row))
}

/// What a made stimulus is and where its files go ([`write_made`]).
pub(crate) struct Member<'a> {
    /// Its id ([`stimulus_id`]).
    pub id: String,
    /// Clip name.
    pub clip: &'a str,
    /// Codec name.
    pub codec: &'a str,
    /// The parameters asked for (its variant).
    pub variant: &'a Params,
    /// Its target.
    pub target: Target,
    /// The clip's output folder.
    pub dir: &'a Path,
    /// The clip's ASF in the output (AMC clips).
    pub skeleton: Option<&'a Path>,
    /// The factor from the stream's (file-basis) CR to the manifest's basis.
    pub cr_factor: f64,
}

/// Writes `made`'s bitstream and decoded clip into `m.dir` (`<codec>[-<variant>]-<target>`,
/// `.mcz` and the clip's format) and returns its manifest entry, paths relative to `out`.
pub(crate) fn write_made(
    made: &Made,
    m: Member<'_>,
    out: &Path,
    mode: files::Mode,
) -> Result<Stimulus> {
    let stem = if m.variant.is_empty() {
        format!("{}-{}", m.codec, m.target.label())
    } else {
        format!(
            "{}-{}-{}",
            m.codec,
            variant_label(m.variant),
            m.target.label()
        )
    };
    let mcz = m.dir.join(format!("{stem}.mcz"));
    files::write(&mcz, &made.bytes, mode)?;
    let (file, _) = stimulus::write_clip_as(&made.decoded, m.dir, &stem, m.skeleton, mode)?;
    let (target_cr, target_max_error_cm) = match m.target {
        Target::Cr(t) => (Some(t), None),
        Target::MaxErrorCm(e) => (None, Some(e)),
    };
    Ok(Stimulus {
        id: m.id,
        clip: m.clip.to_string(),
        codec: m.codec.to_string(),
        params: made.stream.params.clone(),
        variant: m.variant.clone(),
        target_cr,
        target_max_error_cm,
        achieved_cr: Some(made.achieved_cr() * m.cr_factor),
        bytes: made.bytes.len() as u64,
        file: rel(out, &file),
        skeleton: m.skeleton.map(|s| rel(out, s)),
        bitstream: Some(rel(out, &mcz)),
        metrics: Some(stimulus::manifest_metrics(&made.metrics, made.worst_window)),
        encode_ms: Some(made.encode_ms),
        decode_ms: Some(made.decode_ms),
        scene: None,
        sha256: None,
        bitstream_sha256: None,
    })
}

/// Why `made` is not the variant asked for: a varied parameter the stream records with
/// another value.
fn off_variant(made: &Made, variant: &Params, target: Target) -> Option<String> {
    let off: Vec<String> = variant
        .iter()
        .filter_map(|(k, v)| {
            let got = made.stream.params.get(k)?;
            // The stream records the value it was given, bit for bit, unless the rate control
            // changed it.
            (got.to_bits() != v.to_bits()).then(|| format!("{k} {got} (asked {v})"))
        })
        .collect();
    (!off.is_empty()).then(|| {
        format!(
            "{} needs {}: the rate control left the variant",
            target.label(),
            off.join(", ")
        )
    })
}

/// One row of [`RD_FILE`]; empty cells for what an unreachable target has not.
struct RdRow {
    clip: String,
    codec: String,
    params: String,
    target: Target,
    status: &'static str,
    achieved_cr: Option<f64>,
    bytes: Option<usize>,
    rms_cm: Option<f64>,
    max_cm: Option<f64>,
    worst_window_rms_cm: Option<f64>,
    worst_window_start_frame: Option<usize>,
    mean_angle_deg: Option<f64>,
    foot_slide_cm_s: Option<f64>,
    encode_ms: Option<f64>,
    decode_ms: Option<f64>,
    id: String,
    reason: String,
}

impl RdRow {
    /// The `params` cell: `qp=9;window=128` (`;`, not `,`, inside a CSV cell).
    fn params_cell(variant: &Params) -> String {
        variant
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(";")
    }

    fn made(c: &SweepClip, job: &Job, id: &str, made: &Made) -> RdRow {
        let m = &made.metrics;
        RdRow {
            clip: c.name.clone(),
            codec: job.codec.clone(),
            params: Self::params_cell(&job.variant),
            target: job.target,
            status: "made",
            achieved_cr: Some(made.achieved_cr() * c.cr_factor),
            bytes: Some(made.bytes.len()),
            rms_cm: Some(m.rms_cm),
            max_cm: Some(m.max_cm),
            worst_window_rms_cm: made.worst_window.map(|w| w.rms_cm),
            worst_window_start_frame: made.worst_window.map(|w| w.start_frame),
            mean_angle_deg: Some(m.mean_angle_deg),
            foot_slide_cm_s: m.foot_slide_cm_s,
            encode_ms: Some(made.encode_ms),
            decode_ms: Some(made.decode_ms),
            id: id.to_string(),
            reason: String::new(),
        }
    }

    fn unreachable(c: &SweepClip, job: &Job, id: &str, reason: &str) -> RdRow {
        RdRow {
            clip: c.name.clone(),
            codec: job.codec.clone(),
            params: Self::params_cell(&job.variant),
            target: job.target,
            status: "unreachable",
            achieved_cr: None,
            bytes: None,
            rms_cm: None,
            max_cm: None,
            worst_window_rms_cm: None,
            worst_window_start_frame: None,
            mean_angle_deg: None,
            foot_slide_cm_s: None,
            encode_ms: None,
            decode_ms: None,
            id: id.to_string(),
            reason: reason.to_string(),
        }
    }

    /// The row as a CSV line (with its newline).
    fn to_csv(&self, basis: CrBasis) -> String {
        let num =
            |v: Option<f64>, digits: usize| v.map_or_else(String::new, |v| format!("{v:.digits$}"));
        let (target_cr, bound) = match self.target {
            Target::Cr(t) => (t.to_string(), String::new()),
            Target::MaxErrorCm(e) => (String::new(), e.to_string()),
        };
        let cells = [
            self.clip.clone(),
            self.codec.clone(),
            self.params.clone(),
            target_cr,
            bound,
            self.status.to_string(),
            num(self.achieved_cr, 4),
            self.bytes.map_or_else(String::new, |b| b.to_string()),
            num(self.rms_cm, 5),
            num(self.max_cm, 5),
            num(self.worst_window_rms_cm, 5),
            self.worst_window_start_frame
                .map_or_else(String::new, |f| f.to_string()),
            num(self.mean_angle_deg, 5),
            num(self.foot_slide_cm_s, 5),
            num(self.encode_ms, 3),
            num(self.decode_ms, 3),
            self.id.clone(),
            self.reason.clone(),
            basis.name().to_string(),
        ];
        csv_record(&cells)
    }
}

/// `cells` as one CSV record with its line break, quoted by the `csv` crate where a cell
/// needs it (RFC 4180).
pub(crate) fn csv_record(cells: &[String]) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    // Writing into memory cannot fail.
    let _ = w.write_record(cells);
    let bytes = w.into_inner().unwrap_or_default();
    String::from_utf8(bytes).unwrap_or_default()
}
