//! `study encode`, `study decode`, `study sweep` and `study codecs`: the codec suite on files,
//! and stimulus sets with a `stimuli.json` manifest and a rate–distortion CSV.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use codecs::basis::CrBasis;
use codecs::bitstream::Bitstream;
use codecs::codec;
use lab::Codecs;
use lab::clips::{self, ClipOptions, stem_of};
use lab::stimulus::{self, Request};
use lab::sweep::{SweepOptions, parse_grid, parse_params};

use crate::progress::Progress;
use motion::{Skeleton, SkeletonFormat, asf, io};

/// Arguments of `study encode`.
#[derive(Debug, clap::Args)]
pub struct EncodeArgs {
    /// The clip: one `.bvh`, or an `.amc` with its `.asf` (here or in `--asf`), paired as
    /// every command pairs them (docs/study-file.md, "Clip files").
    #[arg(required = true)]
    pub input: Vec<PathBuf>,
    /// ASF skeleton of an AMC motion not named after one of the files.
    #[arg(long, value_name = "SKEL")]
    pub asf: Option<PathBuf>,
    /// Codec name (see `study codecs`).
    #[arg(long)]
    pub codec: String,
    /// Target compression ratio (4 bytes × channels × frames / bitstream bytes).
    #[arg(long, conflicts_with = "max_error_cm")]
    pub cr: Option<f64>,
    /// Which channels a CR counts: `file` (every channel of the file) or `seed` (the seeds'
    /// 56 DOF of a CMU skeleton; docs/codecs.md, "CR basis").
    #[arg(long, value_parser = parse_basis, default_value = "file")]
    pub cr_basis: CrBasis,
    /// Error bound: the smallest stream whose largest joint position error is at most this
    /// many cm (a search over the codec's rate knob, at most 13 encodes; docs/codecs.md).
    #[arg(long, value_name = "CM")]
    pub max_error_cm: Option<f64>,
    /// Codec parameter `key=value` (repeatable), e.g. `--param qp=9 --param window=256`.
    #[arg(long = "param", value_name = "KEY=VALUE")]
    pub params: Vec<String>,
    #[command(flatten)]
    pub codec_files: CodecFiles,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Replace output files that exist (each atomically); without it an existing output is
    /// refused before anything is written.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `study decode`.
#[derive(Debug, clap::Args)]
pub struct DecodeArgs {
    /// The bitstream (`.mcz`).
    pub bitstream: PathBuf,
    /// The skeleton the stream was made for: an `.asf`, or a `.bvh` whose skeleton is used.
    #[arg(long, value_name = "ASF_OR_BVH")]
    pub skeleton: PathBuf,
    #[command(flatten)]
    pub codec_files: CodecFiles,
    /// Output folder.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Replace output files that exist (each atomically); without it an existing output is
    /// refused before anything is written.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `study sweep`.
#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// Clips: `.bvh` files and `.amc` files with their `.asf`; an AMC is paired with the
    /// `.asf` of its stem, else one whose stem starts the AMC's (`charleston.asf` for
    /// `charleston1.amc`), else `--asf`, else the one beside it of its stem, else the one
    /// `.asf` no other motion is named after.
    #[arg(long, num_args = 1.., required = true)]
    pub clips: Vec<PathBuf>,
    /// ASF skeleton of the AMC motions not named after one of the files.
    #[arg(long, value_name = "SKEL")]
    pub asf: Option<PathBuf>,
    /// Codec names, comma separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub codecs: Vec<String>,
    /// Target compression ratios, comma separated.
    #[arg(long, value_delimiter = ',', required_unless_present = "max_error_cm")]
    pub cr: Vec<f64>,
    /// Which channels the targets and ratios count: `file` or `seed` (recorded in the
    /// manifest and rd.csv; docs/codecs.md, "CR basis").
    #[arg(long, value_parser = parse_basis, default_value = "file")]
    pub cr_basis: CrBasis,
    /// Error bounds in cm, comma separated: for each, the smallest stream whose largest joint
    /// position error stays within it (ids `clip/codec/max0.5cm`).
    #[arg(long, value_delimiter = ',', value_name = "CM")]
    pub max_error_cm: Vec<f64>,
    /// A codec parameter to vary, with its values (repeatable): `--param qp=7,9,11 --param
    /// window=64,128,256` makes every combination at every target, each with the parameters
    /// in its id (`walk/wavelet-perceptual/qp9-window128/cr20`).
    #[arg(long = "param", value_name = "KEY=V1,V2,...")]
    pub params: Vec<String>,
    #[command(flatten)]
    pub set: SetOutput,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub codec_files: CodecFiles,
}

/// `--cr-basis`.
fn parse_basis(s: &str) -> Result<CrBasis, String> {
    CrBasis::parse(s).ok_or_else(|| format!("{s:?}: expected file or seed"))
}

/// Codecs beyond the built-in ones: `--db`, `--codec-defs`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct CodecFiles {
    /// Primitive database (`study primitives train`) for the `primitive` codec (its streams
    /// decode only with the database they were coded with).
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// A file of command-defined codecs: a lab's own encoder and decoder run as commands
    /// (docs/codecs.md, "A codec of your own").
    #[arg(long, value_name = "TOML")]
    pub codec_defs: Option<PathBuf>,
}

impl CodecFiles {
    /// The codec registry with these files' codecs.
    fn codecs(&self) -> Result<Codecs> {
        Codecs::with_files(self.db.as_deref(), self.codec_defs.as_deref())
            .context("reading the codecs' files (--db, --codec-defs)")
    }
}

/// Where a stimulus set goes (`study sweep`, `study crowd`).
#[derive(Debug, clap::Args)]
pub struct SetOutput {
    /// Output folder (gets `stimuli.json`, `rd.csv` and one folder per clip).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Parallel jobs (default: available cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Write into an output folder that holds files, replacing those of the same names (each
    /// atomically); without it such a folder is refused before anything is made.
    #[arg(long)]
    pub force: bool,
}

impl SetOutput {
    /// `--jobs`, else the available cores.
    fn jobs(&self) -> usize {
        self.jobs
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from))
    }
}

/// Arguments of `study crowd`.
#[derive(Debug, clap::Args)]
pub struct CrowdArgs {
    /// The study file (or any TOML file) whose `[scene]` places the characters.
    pub scene: PathBuf,
    /// The clips the characters perform (`.bvh`, or `.amc` with `.asf`), paired as `study
    /// sweep` pairs them; a character's `clip` is a file's stem.
    #[arg(long, num_args = 1.., required = true)]
    pub clips: Vec<PathBuf>,
    /// ASF skeleton of the AMC motions not named after one of the files.
    #[arg(long, value_name = "SKEL")]
    pub asf: Option<PathBuf>,
    /// Codec (with rate control).
    #[arg(long, default_value = "spiht")]
    pub codec: String,
    /// A ratio per group (repeatable), every group of the scene once: `--cr front=40 --cr
    /// back=20,40,60,80` makes a scene per combination, at every level (thesis 6.5).
    #[arg(long = "cr", value_name = "GROUP=V1,V2,...", conflicts_with_all = ["budget_cr", "budget_bytes"])]
    pub cr: Vec<String>,
    /// Total budgets as scene ratios (the characters' raw sizes over the budget), comma
    /// separated: one scene per budget and level, shared as `--share` says.
    #[arg(long, value_delimiter = ',', value_name = "CR")]
    pub budget_cr: Vec<f64>,
    /// Total budgets in bytes, comma separated.
    #[arg(long, value_delimiter = ',', value_name = "BYTES")]
    pub budget_bytes: Vec<f64>,
    /// How a budget is shared: `uniform`, `distance` (eq. 6.4-6.5) or `importance` (the
    /// scene's `importance` scores).
    #[arg(long, value_enum, default_value_t = ShareArg::Distance)]
    pub share: ShareArg,
    /// Fixed codec parameter `key=value` (repeatable).
    #[arg(long = "param", value_name = "KEY=VALUE")]
    pub params: Vec<String>,
    #[command(flatten)]
    pub set: SetOutput,
}

/// How `study crowd` shares a budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ShareArg {
    /// The same share for every character.
    Uniform,
    /// Thesis eq. 6.4-6.5: in proportion to the nearest distance over the character's.
    Distance,
    /// In proportion to the `importance` the scene gives each character.
    Importance,
}

/// `study codecs`: prints every codec (the `primitive` codec with a note that it needs
/// `--db`), and those of `--codec-defs`.
///
/// # Errors
/// The definitions file cannot be read or has problems.
pub fn list(files: &CodecFiles) -> Result<()> {
    let mut out = String::new();
    for c in files.codecs()?.all() {
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
    Ok(())
}

/// `study encode`.
///
/// # Errors
/// On unreadable input, a bad codec or parameter, an unreachable target or error bound, or
/// an unwritable output folder.
pub fn encode(args: &EncodeArgs) -> Result<()> {
    let options = ClipOptions {
        asf: args.asf.clone(),
        bvh_unit_cm: None,
    };
    let loaded = clips::load_one(&args.input, &options)?;
    let factor = args
        .cr_basis
        .factor(&loaded.clip.skeleton)
        .with_context(|| format!("--cr-basis {}", args.cr_basis))?;
    let c = args.codec_files.codecs()?.get(&args.codec)?;
    let params = parse_params(&args.params)?;
    if args.max_error_cm.is_some() {
        lab::bounded::check_params(c.as_ref(), &params)?;
    }
    // Every output is checked before the (possibly long) encode, so a refusal costs nothing
    // and leaves no partial set behind.
    let mode = files::Mode::from_force(args.force);
    let stem = format!("{}.{}", loaded.source.name, c.name());
    let mcz = args.output.join(format!("{stem}.mcz"));
    let (motion_file, asf_file, _) = stimulus::clip_files(&loaded.clip, &args.output, &stem, None);
    for p in std::iter::once(&mcz)
        .chain([&motion_file])
        .chain(asf_file.as_ref())
    {
        files::check_new(p, mode)?;
    }
    let (made, search) = if let Some(bound) = args.max_error_cm {
        let b = lab::bounded::make_within(c.as_ref(), &loaded.clip, &params, bound)?;
        let line = b.describe(bound);
        (b.made, Some(line))
    } else {
        // Rate control counts the file's channels: the same bytes, another raw size.
        let request = Request {
            params,
            target_cr: args.cr.map(|t| t / factor),
        };
        (stimulus::make(c.as_ref(), &loaded.clip, &request)?, None)
    };
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    files::write(&mcz, &made.bytes, mode)?;
    let (motion, _) = stimulus::write_clip_as(&made.decoded, &args.output, &stem, None, mode)?;
    let m = &made.metrics;
    println!(
        "{}: {} bytes, CR {:.2}{}, joint RMS {:.3} cm, max {:.3} cm, {}, angle {:.3}°, encode {:.2} ms, decode {:.2} ms",
        c.name(),
        made.bytes.len(),
        made.achieved_cr() * factor,
        match args.cr_basis {
            CrBasis::File => String::new(),
            CrBasis::Seed => format!(" ({})", args.cr_basis.describe(&loaded.clip.skeleton)?),
        },
        m.rms_cm,
        m.max_cm,
        stimulus::worst_window_text(made.worst_window, loaded.clip.frame_rate_hz),
        m.mean_angle_deg,
        made.encode_ms,
        made.decode_ms,
    );
    if let Some(line) = search {
        println!("{line}");
    }
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
    let codecs = args.codec_files.codecs()?;
    let clip =
        codec::decode_any_in(&stream, &skeleton, codecs.context()).with_context(|| match &args
            .codec_files
            .db
        {
            Some(db) => format!(
                "decoding {} with the database {}",
                args.bitstream.display(),
                db.display()
            ),
            None => format!("decoding {}", args.bitstream.display()),
        })?;
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    // An ASF clip refers to the skeleton it was decoded for; only the motion is written.
    let asf = (skeleton.format == SkeletonFormat::Asf).then(|| args.skeleton.clone());
    let (motion, _) = stimulus::write_clip_as(
        &clip,
        &args.output,
        &stem_of(&args.bitstream),
        asf.as_deref(),
        files::Mode::from_force(args.force),
    )?;
    println!(
        "decoded {} frames × {} channels into {}",
        clip.frames(),
        clip.channel_count(),
        motion.display()
    );
    Ok(())
}

/// `study crowd`.
///
/// # Errors
/// As [`lab::crowd::crowd`], and a `--cr` that is not `GROUP=V1,V2,...`.
pub fn crowd(args: &CrowdArgs) -> Result<()> {
    use lab::crowd::{Budget, CrowdOptions, Plan, Share};
    let plan = if args.cr.is_empty() {
        Plan::Budget {
            totals: args
                .budget_cr
                .iter()
                .map(|&c| Budget::Cr(c))
                .chain(args.budget_bytes.iter().map(|&b| Budget::Bytes(b)))
                .collect(),
            share: match args.share {
                ShareArg::Uniform => Share::Uniform,
                ShareArg::Distance => Share::Distance,
                ShareArg::Importance => Share::Importance,
            },
        }
    } else {
        Plan::Fixed(parse_grid("--cr", &args.cr)?)
    };
    let options = CrowdOptions {
        scene: args.scene.clone(),
        clips: args.clips.clone(),
        clip_options: ClipOptions {
            asf: args.asf.clone(),
            bvh_unit_cm: None,
        },
        codec: args.codec.clone(),
        params: parse_params(&args.params)?,
        plan,
        output: args.set.output.clone(),
        jobs: args.set.jobs(),
        force: args.set.force,
    };
    let bar = Progress::new("character stimuli", false);
    let summary = lab::crowd::crowd(&options, &|done, total| bar.set(done, total));
    drop(bar);
    let summary = summary?;
    println!(
        "{} crowd scenes ({} character stimuli encoded) and a reference scene per level in {}; \
         manifest stimuli.json, per-character rd.csv",
        summary.scenes,
        summary.encoded,
        args.set.output.display()
    );
    if let Some((id, budget, bytes)) = summary.worst_budget {
        println!(
            "budgets met: the furthest, {id}, holds {bytes} bytes for a budget of {budget:.0} \
             ({:+.2} %)",
            (bytes as f64 / budget - 1.0) * 100.0
        );
    }
    Ok(())
}

/// `study sweep`.
///
/// # Errors
/// On unreadable clips, unknown codecs, parameters a codec does not take, a codec refusing a
/// parameter's value, or unwritable output. Unreachable targets are listed, not errors.
pub fn sweep(args: &SweepArgs) -> Result<()> {
    let options = SweepOptions {
        clips: args.clips.clone(),
        clip_options: ClipOptions {
            asf: args.asf.clone(),
            bvh_unit_cm: None,
        },
        codecs: args.codecs.clone(),
        targets: args.cr.clone(),
        max_errors_cm: args.max_error_cm.clone(),
        params: parse_grid("--param", &args.params)?,
        output: args.set.output.clone(),
        jobs: args.set.jobs(),
        database: args.codec_files.db.clone(),
        codec_defs: args.codec_files.codec_defs.clone(),
        cr_basis: args.cr_basis,
        force: args.set.force,
    };
    let bar = Progress::new("stimuli", args.quiet);
    let summary = lab::sweep::sweep(&options, &|done, total| bar.set(done, total));
    drop(bar);
    let summary = summary?;
    println!(
        "{} stimuli ({} references) in {}; manifest stimuli.json, rate–distortion rd.csv",
        summary.manifest.stimuli.len(),
        summary.references,
        args.set.output.display()
    );
    // Not reached is not a failure of the sweep: the rest is written, and rd.csv says why.
    if !summary.unreachable.is_empty() {
        println!(
            "{} target(s) not reached (rd.csv rows with status unreachable):",
            summary.unreachable.len()
        );
        for u in &summary.unreachable {
            println!("  {}: {}", u.id, u.reason);
        }
    }
    Ok(())
}
