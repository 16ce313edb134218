//! `study encode`, `study decode`, `study sweep` and `study codecs`: the codec suite on files,
//! and stimulus sets with a `stimuli.json` manifest and a rate–distortion CSV.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use codecs::bitstream::Bitstream;
use codecs::codec::{self, Codec, CodecContext, Params};
use codecs::primitives::Database;
use codecs::{metrics, rate};
use motion::{Clip, Skeleton, SkeletonFormat, asf, io};
use protocols::manifest::{
    MANIFEST_VERSION, REFERENCE_CODEC, Stimulus, StimulusManifest, StimulusMetrics,
};

/// Arguments of `study encode`.
#[derive(Debug, clap::Args)]
pub struct EncodeArgs {
    /// Motion file: one `.bvh`, or an `.amc` with `--asf`.
    pub input: PathBuf,
    /// ASF skeleton of an AMC motion.
    #[arg(long, value_name = "SKEL")]
    pub asf: Option<PathBuf>,
    /// Codec name (see `study codecs`).
    #[arg(long)]
    pub codec: String,
    /// Target compression ratio (4 bytes × channels × frames / bitstream bytes).
    #[arg(long)]
    pub cr: Option<f64>,
    /// Codec parameter `key=value` (repeatable), e.g. `--param qp=9 --param window=256`.
    #[arg(long = "param", value_name = "KEY=VALUE")]
    pub params: Vec<String>,
    /// Primitive database (`study primitives train`) for the `primitive` codec.
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `study decode`.
#[derive(Debug, clap::Args)]
pub struct DecodeArgs {
    /// The bitstream (`.mcz`).
    pub bitstream: PathBuf,
    /// The skeleton the stream was made for: an `.asf`, or a `.bvh` whose skeleton is used.
    #[arg(long, value_name = "ASF_OR_BVH")]
    pub skeleton: PathBuf,
    /// Primitive database the stream was coded with (`primitive` streams).
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Arguments of `study sweep`.
#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// Clips: `.bvh` files and `.amc` files; an AMC is paired with the `.asf` of the same stem,
    /// else one whose stem starts the AMC's (`charleston.asf` for `charleston1.amc`), else the
    /// one beside it of the same stem, else the only `.asf` given.
    #[arg(long, num_args = 1.., required = true)]
    pub clips: Vec<PathBuf>,
    /// Codec names, comma separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub codecs: Vec<String>,
    /// Target compression ratios, comma separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub cr: Vec<f64>,
    /// Output folder (gets `stimuli.json`, `rd.csv` and one folder per clip).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Parallel jobs (default: available cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Primitive database for the `primitive` codec.
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
}

/// The codec context of a command: the primitive database of `--db`, if given.
fn context(db: Option<&Path>) -> Result<CodecContext> {
    let Some(path) = db else {
        return Ok(CodecContext::default());
    };
    let d = Database::read(path).context("reading the primitive database (--db)")?;
    Ok(CodecContext::with_primitives(Arc::new(d)))
}

/// `study codecs`: prints every codec (the `primitive` codec with a note that it needs
/// `--db`).
pub fn list() {
    let mut out = String::new();
    for c in codec::registry_in(&CodecContext::default()) {
        let params: Vec<String> = c
            .default_params()
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        let rate = match c.rate_control() {
            codec::RateControl::Native => "target CR native",
            codec::RateControl::Search { .. } | codec::RateControl::SearchIncreasing { .. } => {
                "target CR by search"
            }
            codec::RateControl::None => "no target CR",
        };
        let _ = writeln!(out, "{:<20} id {}  {}", c.name(), c.id(), c.description());
        if c.name() == codec::primitive::NAME {
            let _ = writeln!(
                out,
                "{:<20}       needs a primitive database: `study encode|decode|sweep --db FILE` \
                 (`study primitives train`); its fingerprint is recorded as `db`",
                ""
            );
        }
        let _ = writeln!(
            out,
            "{:<20}       {rate}; defaults: {}",
            "",
            if params.is_empty() {
                "-".to_string()
            } else {
                params.join(" ")
            }
        );
    }
    print!("{out}");
}

fn parse_params(items: &[String]) -> Result<Params> {
    let mut p = Params::new();
    for item in items {
        let Some((k, v)) = item.split_once('=') else {
            bail!("--param `{item}`: expected KEY=VALUE");
        };
        let v: f64 = v
            .trim()
            .parse()
            .with_context(|| format!("--param `{item}`: not a number"))?;
        p.insert(k.trim().to_string(), v);
    }
    Ok(p)
}

fn find_codec(name: &str, ctx: &CodecContext) -> Result<Box<dyn Codec>> {
    codec::by_name_in(name, ctx).with_context(|| {
        let names: Vec<&str> = codec::registry_in(ctx)
            .iter()
            .map(|c| c.name())
            .collect::<Vec<_>>();
        format!("unknown codec `{name}`; known: {}", names.join(", "))
    })
}

fn encode_with(c: &dyn Codec, clip: &Clip, params: &Params, cr: Option<f64>) -> Result<Bitstream> {
    Ok(match cr {
        Some(t) => rate::encode_to_cr(c, clip, params, t)?,
        None => c.encode(clip, params)?,
    })
}

/// Writes `clip` as `<dir>/<stem>.bvh` or `<dir>/<stem>.amc` (+ `<stem>.asf`); returns the
/// motion file and the ASF, if any.
fn write_like(
    clip: &Clip,
    dir: &Path,
    stem: &str,
    asf_path: Option<&Path>,
) -> Result<(PathBuf, Option<PathBuf>)> {
    match clip.skeleton.format {
        SkeletonFormat::Bvh => {
            let m = dir.join(format!("{stem}.bvh"));
            io::write_clip(clip, &m, None).with_context(|| format!("writing {}", m.display()))?;
            Ok((m, None))
        }
        SkeletonFormat::Asf => {
            let m = dir.join(format!("{stem}.amc"));
            let a = asf_path.map_or_else(|| dir.join(format!("{stem}.asf")), Path::to_path_buf);
            let write_asf = (!a.exists()).then_some(a.as_path());
            io::write_clip(clip, &m, write_asf)
                .with_context(|| format!("writing {}", m.display()))?;
            Ok((m, Some(a)))
        }
    }
}

fn stem_of(p: &Path) -> String {
    p.file_stem()
        .map_or_else(|| "clip".into(), |s| s.to_string_lossy().into_owned())
}

/// `study encode`.
///
/// # Errors
/// On unreadable input, a bad codec or parameter, or an unwritable output folder.
pub fn encode(args: &EncodeArgs) -> Result<()> {
    let clip = io::read_clip(args.asf.as_deref(), &args.input)?;
    let ctx = context(args.db.as_deref())?;
    let c = find_codec(&args.codec, &ctx)?;
    let params = parse_params(&args.params)?;
    let t0 = Instant::now();
    let stream = encode_with(c.as_ref(), &clip, &params, args.cr)?;
    let encode_ms = t0.elapsed().as_secs_f64() * 1e3;
    let bytes = stream.to_bytes()?;
    let t1 = Instant::now();
    let decoded = c.decode(&stream, &clip.skeleton)?;
    let decode_ms = t1.elapsed().as_secs_f64() * 1e3;
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let stem = format!("{}.{}", stem_of(&args.input), c.name());
    let mcz = args.output.join(format!("{stem}.mcz"));
    std::fs::write(&mcz, &bytes).with_context(|| format!("writing {}", mcz.display()))?;
    let (motion, _) = write_like(&decoded, &args.output, &stem, None)?;
    let m = metrics::compare(&clip, &decoded)?;
    println!(
        "{}: {} bytes, CR {:.2}, joint RMS {:.3} cm (max {:.2} cm), angle {:.3}°, encode {encode_ms:.2} ms, decode {decode_ms:.2} ms",
        c.name(),
        bytes.len(),
        stream.compression_ratio(),
        m.rms_cm,
        m.max_cm,
        m.mean_angle_deg,
    );
    println!("wrote {} and {}", mcz.display(), motion.display());
    Ok(())
}

fn read_skeleton(path: &Path) -> Result<Skeleton> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bvh"))
    {
        Ok(io::read_clip(None, path)?.skeleton)
    } else {
        Ok(asf::read_asf(path)?)
    }
}

/// `study decode`.
///
/// # Errors
/// On an unreadable or invalid stream, a mismatched skeleton, or an unwritable folder.
pub fn decode(args: &DecodeArgs) -> Result<()> {
    let bytes = std::fs::read(&args.bitstream)
        .with_context(|| format!("reading {}", args.bitstream.display()))?;
    let stream =
        Bitstream::from_bytes(&bytes).with_context(|| format!("{}", args.bitstream.display()))?;
    let skeleton = read_skeleton(&args.skeleton)?;
    let ctx = context(args.db.as_deref())?;
    let clip = codec::decode_any_in(&stream, &skeleton, &ctx)
        .with_context(|| format!("decoding {}", args.bitstream.display()))?;
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let asf = (skeleton.format == SkeletonFormat::Asf).then(|| args.skeleton.clone());
    let (motion, _) = write_like(
        &clip,
        &args.output,
        &stem_of(&args.bitstream),
        asf.as_deref(),
    )?;
    println!(
        "decoded {} frames × {} channels into {}",
        clip.frames(),
        clip.channel_count(),
        motion.display()
    );
    Ok(())
}

/// The clips a sweep names: (name, asf, motion).
fn sweep_inputs(files: &[PathBuf]) -> Result<Vec<(String, Option<PathBuf>, PathBuf)>> {
    let ext = |p: &Path, e: &str| p.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
    let asfs: Vec<&PathBuf> = files.iter().filter(|p| ext(p, "asf")).collect();
    let mut out = Vec::new();
    for p in files.iter().filter(|p| !ext(p, "asf")) {
        let name = stem_of(p);
        if ext(p, "bvh") {
            out.push((name, None, p.clone()));
        } else if ext(p, "amc") {
            let beside = p.with_file_name(format!("{name}.asf"));
            let asf = asfs
                .iter()
                .find(|a| stem_of(a) == name)
                .or_else(|| asfs.iter().find(|a| name.starts_with(&stem_of(a))))
                .map(|a| (*a).clone())
                .or_else(|| beside.exists().then_some(beside))
                .or_else(|| (asfs.len() == 1).then(|| asfs[0].clone()));
            let Some(asf) = asf else {
                bail!(
                    "{}: no ASF skeleton (give `{name}.asf` or exactly one .asf)",
                    p.display()
                );
            };
            out.push((name, Some(asf), p.clone()));
        } else {
            bail!("{}: expected .bvh, .amc or .asf", p.display());
        }
    }
    if out.is_empty() {
        bail!("no motion files among --clips");
    }
    Ok(out)
}

fn rel(dir: &Path, p: &Path) -> String {
    p.strip_prefix(dir)
        .unwrap_or(p)
        .to_string_lossy()
        .replace('\\', "/")
}

struct Job {
    clip: usize,
    codec: String,
    target: f64,
}

/// `study sweep`.
///
/// # Errors
/// On unreadable clips, unknown codecs, a codec failing a target, or unwritable output.
#[expect(
    clippy::too_many_lines,
    reason = "inputs, references, parallel jobs, outputs: one pipeline"
)]
pub fn sweep(args: &SweepArgs) -> Result<()> {
    for &t in &args.cr {
        if !(t.is_finite() && t > 0.0) {
            bail!("--cr {t}: compression ratios must be positive");
        }
    }
    let ctx = context(args.db.as_deref())?;
    for name in &args.codecs {
        let c = find_codec(name, &ctx)?;
        if c.rate_control() == codec::RateControl::None {
            bail!("codec `{name}` takes no target rate; sweep lossy codecs");
        }
    }
    let inputs = sweep_inputs(&args.clips)?;
    let out = &args.output;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut manifest = StimulusManifest {
        version: MANIFEST_VERSION,
        stimuli: Vec::new(),
    };
    let mut clips = Vec::new();
    for (name, asf, motion) in &inputs {
        let clip = io::read_clip(asf.as_deref(), motion)?;
        let dir = out.join(name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let (file, skel) = write_like(&clip, &dir, "reference", None)?;
        manifest.stimuli.push(Stimulus {
            id: format!("{name}/{REFERENCE_CODEC}"),
            clip: name.clone(),
            codec: REFERENCE_CODEC.into(),
            params: BTreeMap::new(),
            target_cr: None,
            achieved_cr: 1.0,
            bytes: 0,
            file: rel(out, &file),
            skeleton: skel.as_deref().map(|s| rel(out, s)),
            bitstream: None,
            metrics: None,
            encode_ms: None,
            decode_ms: None,
        });
        clips.push((name.clone(), clip, skel, dir));
    }
    let jobs: Vec<Job> = (0..clips.len())
        .flat_map(|clip| {
            args.codecs.iter().flat_map(move |codec| {
                args.cr.iter().map(move |&target| Job {
                    clip,
                    codec: codec.clone(),
                    target,
                })
            })
        })
        .collect();
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(jobs.len() as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} stimuli {elapsed} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let threads = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from))
        .clamp(1, 64);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, JobResult)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..threads.min(jobs.len().max(1)) {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(job) = jobs.get(i) else { break };
                    let r = run_job(job, &clips, out, &ctx);
                    bar.inc(1);
                    if let Ok(mut v) = results.lock() {
                        v.push((i, r));
                    }
                }
            });
        }
    });
    bar.finish_and_clear();
    let mut results = results
        .into_inner()
        .map_err(|_| anyhow::anyhow!("a sweep worker panicked"))?;
    results.sort_by_key(|(i, _)| *i);
    let mut csv = String::from(
        "clip,codec,target_cr,achieved_cr,bytes,rms_cm,max_cm,mean_angle_deg,foot_slide_cm_s,encode_ms,decode_ms\n",
    );
    for (_, r) in results {
        let (stimulus, row) = r?;
        csv.push_str(&row);
        manifest.stimuli.push(stimulus);
    }
    let json = serde_json::to_string_pretty(&manifest)?;
    std::fs::write(out.join("stimuli.json"), json).context("writing stimuli.json")?;
    std::fs::write(out.join("rd.csv"), csv).context("writing rd.csv")?;
    println!(
        "{} stimuli ({} references) in {}; manifest stimuli.json, rate–distortion rd.csv",
        manifest.stimuli.len(),
        clips.len(),
        out.display()
    );
    Ok(())
}

/// A sweep's clip: name, clip, its ASF in the output (for AMC), its output folder.
type SweepClip = (String, Clip, Option<PathBuf>, PathBuf);
/// One stimulus and its CSV row.
type JobResult = Result<(Stimulus, String)>;

fn run_job(job: &Job, clips: &[SweepClip], out: &Path, ctx: &CodecContext) -> JobResult {
    let (name, clip, skel, dir) = &clips[job.clip];
    let c = find_codec(&job.codec, ctx)?;
    let t0 = Instant::now();
    let stream = rate::encode_to_cr(c.as_ref(), clip, &Params::new(), job.target)
        .with_context(|| format!("{name}: {} at CR {}", job.codec, job.target))?;
    let encode_ms = t0.elapsed().as_secs_f64() * 1e3;
    let bytes = stream.to_bytes()?;
    let t1 = Instant::now();
    let decoded = c.decode(&stream, &clip.skeleton)?;
    let decode_ms = t1.elapsed().as_secs_f64() * 1e3;
    let m = metrics::compare(clip, &decoded)?;
    let stem = format!("{}-cr{}", job.codec, job.target);
    let mcz = dir.join(format!("{stem}.mcz"));
    std::fs::write(&mcz, &bytes).with_context(|| format!("writing {}", mcz.display()))?;
    let (file, _) = write_like(&decoded, dir, &stem, skel.as_deref())?;
    let achieved = stream.compression_ratio();
    let row = format!(
        "{name},{},{},{achieved:.4},{},{:.5},{:.5},{:.5},{},{encode_ms:.3},{decode_ms:.3}\n",
        job.codec,
        job.target,
        bytes.len(),
        m.rms_cm,
        m.max_cm,
        m.mean_angle_deg,
        m.foot_slide_cm_s
            .map_or_else(String::new, |v| format!("{v:.5}")),
    );
    let stimulus = Stimulus {
        id: format!("{name}/{}/cr{}", job.codec, job.target),
        clip: name.clone(),
        codec: job.codec.clone(),
        params: stream.params.clone(),
        target_cr: Some(job.target),
        achieved_cr: achieved,
        bytes: bytes.len() as u64,
        file: rel(out, &file),
        skeleton: skel.as_deref().map(|s| rel(out, s)),
        bitstream: Some(rel(out, &mcz)),
        metrics: Some(StimulusMetrics {
            rms_cm: m.rms_cm,
            max_cm: m.max_cm,
            mean_angle_deg: m.mean_angle_deg,
            foot_slide_cm_s: m.foot_slide_cm_s,
        }),
        encode_ms: Some(encode_ms),
        decode_ms: Some(decode_ms),
    };
    Ok((stimulus, row))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
    use super::*;

    #[test]
    fn sweep_two_shared_clips_three_codecs_four_rates() {
        let Some(dir) = motion::data::mocap_dir() else {
            return;
        };
        let out = std::env::temp_dir().join(format!("study-sweep-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let args = SweepArgs {
            clips: vec![
                dir.join("02_01.amc"),
                dir.join("12.asf"),
                dir.join("131_01.bvh"),
            ],
            codecs: vec![
                "wavelet-perceptual".into(),
                "wavelet-bone".into(),
                "spiht".into(),
            ],
            cr: vec![15.0, 20.0, 30.0, 40.0],
            output: out.clone(),
            jobs: Some(2),
            quiet: true,
            db: None,
        };
        sweep(&args).unwrap();
        let text = std::fs::read_to_string(out.join("stimuli.json")).unwrap();
        let manifest: StimulusManifest = serde_json::from_str(&text).unwrap();
        assert_eq!(manifest.stimuli.len(), 2 + 2 * 3 * 4);
        for s in &manifest.stimuli {
            assert!(out.join(&s.file).is_file(), "{}", s.file);
            if let Some(k) = &s.skeleton {
                assert!(out.join(k).is_file(), "{k}");
            }
            if s.codec != REFERENCE_CODEC {
                let t = s.target_cr.unwrap();
                assert!(
                    (s.achieved_cr / t - 1.0).abs() <= 0.02,
                    "{}: {}",
                    s.id,
                    s.achieved_cr
                );
                let m = s.metrics.unwrap();
                assert!(m.rms_cm.is_finite() && m.rms_cm > 0.0);
                // The bitstream on disk decodes with the reference skeleton to the stimulus file.
                let bytes = std::fs::read(out.join(s.bitstream.as_ref().unwrap())).unwrap();
                assert_eq!(bytes.len() as u64, s.bytes);
                let reference = manifest.reference_of(&s.clip).unwrap();
                let skel = read_skeleton(
                    &out.join(reference.skeleton.as_ref().unwrap_or(&reference.file)),
                )
                .unwrap();
                codec::decode_any(&Bitstream::from_bytes(&bytes).unwrap(), &skel).unwrap();
            }
        }
        let csv = std::fs::read_to_string(out.join("rd.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 24);
        std::fs::remove_dir_all(&out).unwrap();
    }
}
