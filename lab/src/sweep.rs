//! A stimulus set: every clip × codec × target compression ratio, made on worker threads and
//! written with its reference copies, a `stimuli.json` manifest and a rate–distortion CSV.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use codecs::codec::RateControl;
use motion::Clip;
use protocols::manifest::{
    MANIFEST_VERSION, REFERENCE_CODEC, Stimulus, StimulusManifest, StimulusMetrics,
};

use crate::catalog::Codecs;
use crate::clips::{self, ClipOptions};
use crate::error::{Context as _, LabError, Result, io_error, refused};
use crate::stimulus::{self, Request};

/// The manifest file a sweep writes.
pub const MANIFEST_FILE: &str = "stimuli.json";
/// The rate–distortion table a sweep writes.
pub const RD_FILE: &str = "rd.csv";
/// Header of [`RD_FILE`].
const RD_HEADER: &str = "clip,codec,target_cr,achieved_cr,bytes,rms_cm,max_cm,mean_angle_deg,foot_slide_cm_s,encode_ms,decode_ms\n";

/// What a sweep makes.
#[derive(Debug, Clone)]
pub struct SweepOptions {
    /// Clip files: motions and skeletons, paired by [`motion::pairing`].
    pub clips: Vec<PathBuf>,
    /// How they are read.
    pub clip_options: ClipOptions,
    /// Codec names (each with rate control).
    pub codecs: Vec<String>,
    /// Target compression ratios.
    pub targets: Vec<f64>,
    /// Output folder (gets the manifest, the CSV and one folder per clip).
    pub output: PathBuf,
    /// Worker threads (at least 1).
    pub jobs: usize,
    /// Primitive database for the `primitive` codec.
    pub database: Option<PathBuf>,
}

/// What a sweep wrote.
#[derive(Debug, Clone)]
pub struct SweepSummary {
    /// The manifest written (references first, then the jobs in clip, codec, rate order).
    pub manifest: StimulusManifest,
    /// Reference clips among them.
    pub references: usize,
}

/// A sweep's clip: name, clip, its ASF in the output (for AMC), its output folder.
struct SweepClip {
    name: String,
    clip: Clip,
    skeleton: Option<PathBuf>,
    dir: PathBuf,
}

struct Job {
    clip: usize,
    codec: String,
    target: f64,
}

/// Runs a sweep; `progress(done, total)` is called from the workers after each stimulus.
///
/// # Errors
/// A bad target, an unknown codec or one without rate control, clips that do not pair or
/// read, a codec failing a target, or an output that cannot be written.
pub fn sweep(
    options: &SweepOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SweepSummary> {
    for &t in &options.targets {
        if !(t.is_finite() && t > 0.0) {
            return Err(refused(format!(
                "--cr {t}: compression ratios must be positive"
            )));
        }
    }
    let codecs = Codecs::with_database(options.database.as_deref())
        .context(|| "reading the primitive database".to_string())?;
    for name in &options.codecs {
        if codecs.get(name)?.rate_control() == RateControl::None {
            return Err(refused(format!(
                "codec `{name}` takes no target rate; sweep lossy codecs"
            )));
        }
    }
    let inputs = clips::sources(&options.clips, &options.clip_options)?;
    let out = &options.output;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let mut manifest = StimulusManifest {
        version: MANIFEST_VERSION,
        stimuli: Vec::new(),
    };
    // Reading a clip and writing its reference copy are a parse and a format of every
    // value: on the worker threads too, one clip each.
    let read = parallel(
        &inputs,
        options.jobs,
        |_| 0,
        |source| -> Result<(SweepClip, PathBuf)> {
            let clip = clips::read(source, options.clip_options.bvh_unit_cm)?;
            let dir = out.join(&source.name);
            std::fs::create_dir_all(&dir).map_err(io_error(&dir))?;
            let (file, skeleton) = stimulus::write_clip_as(&clip, &dir, "reference", None)?;
            let c = SweepClip {
                name: source.name.clone(),
                clip,
                skeleton,
                dir,
            };
            Ok((c, file))
        },
    )?;
    let mut sweep_clips = Vec::with_capacity(read.len());
    for r in read {
        let (c, file) = r?;
        manifest.stimuli.push(reference_stimulus(
            out,
            &c.name,
            &file,
            c.skeleton.as_deref(),
        ));
        sweep_clips.push(c);
    }
    let jobs: Vec<Job> = (0..sweep_clips.len())
        .flat_map(|clip| {
            options.codecs.iter().flat_map(move |codec| {
                options.targets.iter().map(move |&target| Job {
                    clip,
                    codec: codec.clone(),
                    target,
                })
            })
        })
        .collect();
    let done = AtomicUsize::new(0);
    let results = parallel(
        &jobs,
        options.jobs,
        // Longest clips first, so that no worker is left with a long job at the end.
        |job| sweep_clips[job.clip].clip.frames(),
        |job| {
            let r = make_job(job, &sweep_clips, out, &codecs);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, jobs.len());
            r
        },
    )?;
    let mut csv = String::from(RD_HEADER);
    for r in results {
        let (stimulus, row) = r?;
        csv.push_str(&row);
        manifest.stimuli.push(stimulus);
    }
    let json = serde_json::to_string_pretty(&manifest)?;
    let manifest_path = out.join(MANIFEST_FILE);
    std::fs::write(&manifest_path, json).map_err(io_error(&manifest_path))?;
    let rd = out.join(RD_FILE);
    std::fs::write(&rd, csv).map_err(io_error(&rd))?;
    Ok(SweepSummary {
        manifest,
        references: sweep_clips.len(),
    })
}

/// `make` of every item on `threads` workers, results in item order. Items are handed out
/// largest `size` first (ties in item order), so the output does not depend on the number of
/// threads or on which finishes first.
fn parallel<I: Sync, T: Send>(
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
fn rel(dir: &Path, p: &Path) -> String {
    p.strip_prefix(dir)
        .unwrap_or(p)
        .to_string_lossy()
        .replace('\\', "/")
}

fn reference_stimulus(out: &Path, name: &str, file: &Path, skeleton: Option<&Path>) -> Stimulus {
    Stimulus {
        id: format!("{name}/{REFERENCE_CODEC}"),
        clip: name.to_string(),
        codec: REFERENCE_CODEC.into(),
        params: BTreeMap::new(),
        target_cr: None,
        achieved_cr: 1.0,
        bytes: 0,
        file: rel(out, file),
        skeleton: skeleton.map(|s| rel(out, s)),
        bitstream: None,
        metrics: None,
        encode_ms: None,
        decode_ms: None,
    }
}

/// One stimulus and its CSV row.
fn make_job(
    job: &Job,
    clips: &[SweepClip],
    out: &Path,
    codecs: &Codecs,
) -> Result<(Stimulus, String), LabError> {
    let c = &clips[job.clip];
    let codec = codecs.get(&job.codec)?;
    let request = Request {
        params: codecs::codec::Params::new(),
        target_cr: Some(job.target),
    };
    let made = stimulus::make(codec.as_ref(), &c.clip, &request)
        .context(|| format!("{}: {} at CR {}", c.name, job.codec, job.target))?;
    let stem = format!("{}-cr{}", job.codec, job.target);
    let mcz = c.dir.join(format!("{stem}.mcz"));
    std::fs::write(&mcz, &made.bytes).map_err(io_error(&mcz))?;
    let (file, _) = stimulus::write_clip_as(&made.decoded, &c.dir, &stem, c.skeleton.as_deref())?;
    let achieved = made.achieved_cr();
    let m = &made.metrics;
    let row = format!(
        "{},{},{},{achieved:.4},{},{:.5},{:.5},{:.5},{},{:.3},{:.3}\n",
        c.name,
        job.codec,
        job.target,
        made.bytes.len(),
        m.rms_cm,
        m.max_cm,
        m.mean_angle_deg,
        m.foot_slide_cm_s
            .map_or_else(String::new, |v| format!("{v:.5}")),
        made.encode_ms,
        made.decode_ms,
    );
    let stimulus = Stimulus {
        id: format!("{}/{}/cr{}", c.name, job.codec, job.target),
        clip: c.name.clone(),
        codec: job.codec.clone(),
        params: made.stream.params.clone(),
        target_cr: Some(job.target),
        achieved_cr: achieved,
        bytes: made.bytes.len() as u64,
        file: rel(out, &file),
        skeleton: c.skeleton.as_deref().map(|s| rel(out, s)),
        bitstream: Some(rel(out, &mcz)),
        metrics: Some(StimulusMetrics {
            rms_cm: m.rms_cm,
            max_cm: m.max_cm,
            mean_angle_deg: m.mean_angle_deg,
            foot_slide_cm_s: m.foot_slide_cm_s,
        }),
        encode_ms: Some(made.encode_ms),
        decode_ms: Some(made.decode_ms),
    };
    Ok((stimulus, row))
}
