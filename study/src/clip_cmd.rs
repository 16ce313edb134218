//! `study clip ...`: inspect, convert and export motion clips.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use lab::clips::ClipOptions;
use motion::{Clip, SkeletonFormat, fk, io, synth};

/// Where a clip comes from: `--asf A --amc M`, one `.bvh`, or the built-in demo walk.
#[derive(Debug, Clone, clap::Args)]
pub struct ClipInput {
    /// Motion files: `.bvh` files, or `.amc` files with their `.asf` files, paired as every
    /// command pairs them (an AMC with the ASF named after it, else `--asf`, else the ASF
    /// beside it, else the one ASF no other motion is named after).
    pub files: Vec<PathBuf>,
    /// ASF skeleton for the AMC motions not named after one of the files.
    #[arg(long, value_name = "SKEL")]
    pub asf: Option<PathBuf>,
    /// AMC motion (needs `--asf`).
    #[arg(long, value_name = "MOTION")]
    pub amc: Vec<PathBuf>,
    /// Use the built-in generated walk instead of files.
    #[arg(long)]
    pub demo: bool,
    /// Length unit of BVH files in cm, overriding the inferred one (BVH states no unit).
    #[arg(long, value_name = "CM")]
    pub bvh_unit_cm: Option<f64>,
}

/// A loaded clip and the name to show for it.
pub struct Loaded {
    /// Display name (file or `demo-walk`).
    pub name: String,
    /// The clip.
    pub clip: Clip,
}

impl ClipInput {
    /// Loads every clip the arguments name.
    ///
    /// # Errors
    /// When a file cannot be read or the arguments do not name a clip.
    pub fn load(&self) -> Result<Vec<Loaded>> {
        let mut out = Vec::new();
        if self.demo {
            out.push(Loaded {
                name: "demo-walk".into(),
                clip: synth::walking_clip(&synth::WalkParams::default()),
            });
        }
        let files: Vec<PathBuf> = self.amc.iter().chain(&self.files).cloned().collect();
        if !files.is_empty() || self.asf.is_some() {
            let options = ClipOptions {
                asf: self.asf.clone(),
                bvh_unit_cm: self.bvh_unit_cm,
            };
            out.extend(
                lab::clips::load(&files, &options)?
                    .into_iter()
                    .map(|l| Loaded {
                        name: l.source.motion.display().to_string(),
                        clip: l.clip,
                    }),
            );
        }
        if out.is_empty() {
            bail!("no clip given: pass a .bvh file, --asf SKEL --amc MOTION, or --demo");
        }
        Ok(out)
    }

    /// Loads exactly one clip.
    ///
    /// # Errors
    /// When the arguments name none or several.
    pub fn load_one(&self) -> Result<Loaded> {
        let mut all = self.load()?;
        if all.len() != 1 {
            bail!("expected one clip, the arguments name {}", all.len());
        }
        Ok(all.remove(0))
    }
}

/// Clip subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum ClipCommand {
    /// Joints, channels, frames, rate, units, bone lengths, ranges and warnings.
    Info(ClipInput),
    /// World positions of every joint (FK) as CSV `frame,joint,x,y,z` or NumPy `.npy`.
    Positions {
        #[command(flatten)]
        input: ClipInput,
        /// Write CSV here (default: standard output).
        #[arg(long, value_name = "OUT", conflicts_with = "npy")]
        csv: Option<PathBuf>,
        /// Write a float64 array of shape (frames, joints, 3) here; joint names go to
        /// `OUT.joints.txt`.
        #[arg(long, value_name = "OUT")]
        npy: Option<PathBuf>,
        /// Positions in centimetres instead of file units.
        #[arg(long)]
        cm: bool,
        /// Replace output files that exist (atomically); without it an existing output is
        /// refused.
        #[arg(long)]
        force: bool,
    },
    /// Convert between formats: ASF/AMC → BVH, or rewrite in the same format.
    Convert {
        #[command(flatten)]
        input: ClipInput,
        /// Output motion file (`.bvh` or `.amc`).
        #[arg(short, long, value_name = "OUT")]
        output: PathBuf,
        /// Output skeleton for `.amc` output.
        #[arg(long, value_name = "SKEL")]
        out_asf: Option<PathBuf>,
        /// Replace output files that exist (atomically); without it an existing output is
        /// refused.
        #[arg(long)]
        force: bool,
    },
    /// Render stills of the clips side by side as the study window draws them (offscreen,
    /// no display needed), e.g. a reference and its decoded stimulus for a figure; or, with
    /// `--study` and `--scenes`, crowd scenes of a study with its `[scene]` camera and light.
    /// An `.svg` output labels each pane with its name and time as text (for papers); a
    /// `.png` output is the bare pixels.
    Render(RenderArgs),
    /// A video (MP4, H.264 by Debian's ffmpeg) of the clips side by side as the study window
    /// draws them (the offscreen renderer of `study clip render`), at the first clip's frame
    /// rate or `--fps`, for the whole of the longest clip: a stimulus beside its reference for
    /// supplementary material, or to play a stimulus set before subjects come.
    Video(VideoArgs),
}

/// Arguments of `study clip video`.
#[derive(Debug, clap::Args)]
pub struct VideoArgs {
    #[command(flatten)]
    input: ClipInput,
    /// Frames per second of the video (default: the first clip's frame rate).
    #[arg(long)]
    fps: Option<f64>,
    /// Size of one pane, pixels (its height and width; even, as H.264's 4:2:0 needs).
    #[arg(long, default_value_t = 480)]
    pane: u32,
    /// Draw no ground shadow.
    #[arg(long)]
    no_shadow: bool,
    /// A session folder of a results directory: draw its trial `--trial` as the subject saw
    /// it (its schedule, panes and labels, as the study window lays them out), not clips.
    #[arg(long, value_name = "DIR", requires = "trial")]
    session: Option<PathBuf>,
    /// The trial's index in `--session` (0-based, as trials.csv logs it).
    #[arg(long, requires = "session")]
    trial: Option<u32>,
    /// Frame size of a trial's video, `WIDTHxHEIGHT` (even numbers).
    #[arg(long, value_name = "WxH", default_value = "1280x720", value_parser = parse_frame)]
    size: (u32, u32),
    /// Output video, `.mp4`.
    #[arg(short, long, value_name = "OUT")]
    output: PathBuf,
    /// Replace the output if it exists (atomically); without it an existing output is
    /// refused.
    #[arg(long)]
    force: bool,
}

/// `--size WxH` of a trial's video.
fn parse_frame(s: &str) -> Result<(u32, u32), String> {
    let parsed = s
        .split_once('x')
        .and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)));
    parsed.ok_or_else(|| format!("{s:?}: expected WIDTHxHEIGHT, e.g. 1280x720"))
}

/// Arguments of `study clip render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    input: ClipInput,
    /// A study file with a `[scene]`: draw its crowd scenes (`--scenes`) instead of clips.
    #[arg(long, value_name = "TOML", requires = "scenes")]
    study: Option<PathBuf>,
    /// Crowd scene ids of the study's manifest, comma separated (e.g.
    /// `far/reference,far/spiht/front40-back80`), one pane each.
    #[arg(long, value_delimiter = ',', requires = "study")]
    scenes: Vec<String>,
    /// Clip times to draw, seconds (one row of panes per time).
    #[arg(long, value_delimiter = ',', default_value = "0")]
    times: Vec<f64>,
    /// Size of one pane, pixels (its height and width; crowd scenes are 16:9 wide, as the
    /// window shows them).
    #[arg(long, default_value_t = 480)]
    pane: u32,
    /// Pane names, one per clip (or scene) in order (default: each file's name without its
    /// folder and extension, `demo-walk` for the demo; the scene ids).
    #[arg(long, value_delimiter = ',')]
    labels: Vec<String>,
    /// Draw no ground shadow.
    #[arg(long)]
    no_shadow: bool,
    /// Output image: `.svg` (labelled) or `.png`.
    #[arg(short, long, value_name = "OUT")]
    output: PathBuf,
    /// Replace output files that exist (atomically); without it an existing output is
    /// refused.
    #[arg(long)]
    force: bool,
}

/// Runs a clip subcommand.
///
/// # Errors
/// Any read, write or argument error, with the file named.
pub fn run(cmd: ClipCommand) -> Result<()> {
    match cmd {
        ClipCommand::Info(input) => {
            let mut stdout = std::io::stdout().lock();
            for loaded in input.load()? {
                stdout.write_all(motion::info::describe(&loaded.name, &loaded.clip).as_bytes())?;
            }
            Ok(())
        }
        ClipCommand::Positions {
            input,
            csv,
            npy,
            cm,
            force,
        } => {
            let mode = files::Mode::from_force(force);
            let loaded = input.load_one()?;
            let pos = fk::positions(&loaded.clip);
            let scale = if cm { pos.cm_per_unit } else { 1.0 };
            if let Some(path) = npy {
                let names = path.with_extension("joints.txt");
                // Both refused before either is written.
                files::check_new(&path, mode)?;
                files::check_new(&names, mode)?;
                files::write(&path, lab::clips::positions_npy(&pos, scale)?, mode)?;
                files::write(&names, pos.names.join("\n") + "\n", mode)?;
                return Ok(());
            }
            let text = lab::clips::positions_csv(&pos, scale);
            match csv {
                Some(path) => files::write(&path, text, mode)?,
                None => std::io::stdout().lock().write_all(text.as_bytes())?,
            }
            Ok(())
        }
        ClipCommand::Convert {
            input,
            output,
            out_asf,
            force,
        } => {
            let loaded = input.load_one()?;
            let amc_out = output
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("amc"));
            if amc_out && out_asf.is_none() && loaded.clip.skeleton.format == SkeletonFormat::Asf {
                bail!("AMC output needs --out-asf for its skeleton");
            }
            io::write_clip(
                &loaded.clip,
                &output,
                out_asf.as_deref(),
                files::Mode::from_force(force),
            )?;
            eprintln!("wrote {}", output.display());
            Ok(())
        }
        ClipCommand::Render(args) => render_command(args),
        ClipCommand::Video(args) => video_command(&args),
    }
}

/// `study clip render`.
fn render_command(args: RenderArgs) -> Result<()> {
    let RenderArgs {
        input,
        study,
        scenes,
        times,
        pane,
        labels,
        no_shadow,
        output,
        force,
    } = args;
    let mode = files::Mode::from_force(force);
    let svg = match output.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("svg") => true,
        Some(e) if e.eq_ignore_ascii_case("png") => false,
        _ => bail!(
            "{}: expected an .svg (labelled) or .png output",
            output.display()
        ),
    };
    // Refused before the (slow) offscreen render.
    files::check_new(&output, mode)?;
    let still = window::stills::Still {
        times: &times,
        pane,
        wide: study.is_some(),
        shadow: !no_shadow,
    };
    let (image, names) = if let Some(study) = study {
        if !input.files.is_empty() || !input.amc.is_empty() || input.demo {
            bail!("--study draws its crowd scenes: give no clip files or --demo");
        }
        let names = if labels.is_empty() {
            scenes.clone()
        } else {
            pane_names_given(&labels, scenes.len(), "scene")?
        };
        (
            window::stills::crowd_scenes(&study, &scenes, &still)?,
            names,
        )
    } else {
        let clips = input.load()?;
        let names = pane_names(&clips, &labels)?;
        let clips: Vec<&Clip> = clips.iter().map(|c| &c.clip).collect();
        (window::stills::clips(&clips, &still)?, names)
    };
    if svg {
        let sizes = (still.width(), still.pane);
        let svg = window::render::labelled_svg(&image, &names, still.times, sizes)?;
        files::write(&output, svg, mode)?;
    } else {
        image.write_png(&output, mode)?;
    }
    eprintln!(
        "wrote {} ({} × {} panes)",
        output.display(),
        names.len(),
        times.len()
    );
    Ok(())
}

/// The name of each pane column: `--labels` when given (one per clip), else the file's stem.
fn pane_names(clips: &[Loaded], labels: &[String]) -> Result<Vec<String>> {
    if labels.is_empty() {
        return Ok(clips
            .iter()
            .map(|c| {
                Path::new(&c.name)
                    .file_stem()
                    .map_or_else(|| c.name.clone(), |s| s.to_string_lossy().into_owned())
            })
            .collect());
    }
    pane_names_given(labels, clips.len(), "clip")
}

/// `--labels`, one per pane: per clip, or per scene (`what` is `clip` or `scene`).
fn pane_names_given(labels: &[String], panes: usize, what: &str) -> Result<Vec<String>> {
    if labels.len() != panes {
        bail!(
            "--labels: {} names for {panes} {what}s (one per {what}, in order)",
            labels.len()
        );
    }
    Ok(labels.to_vec())
}

/// `study clip video` ([`window::video`]).
fn video_command(args: &VideoArgs) -> Result<()> {
    let mode = files::Mode::from_force(args.force);
    if !args
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mp4"))
    {
        bail!("{}: expected an .mp4 output", args.output.display());
    }
    let settings = window::video::Settings {
        pane: args.pane,
        fps: args.fps,
        shadow: !args.no_shadow,
    };
    settings.check()?;
    // Refused before the (slow) render.
    files::check_new(&args.output, mode)?;
    if let (Some(session), Some(index)) = (&args.session, args.trial) {
        if !args.input.files.is_empty() || !args.input.amc.is_empty() || args.input.demo {
            bail!("--session draws a logged trial: give no clip files or --demo");
        }
        let (study, trial) = window::video::logged_trial(session, index)?;
        let fps = args.fps.unwrap_or(60.0);
        let made = window::video::write_trial_mp4(&study, &trial, args.size, fps, &args.output)?;
        eprintln!(
            "wrote {} (trial {index} of {}: {} frames at {fps} fps, {} × {})",
            args.output.display(),
            session.display(),
            made.frames,
            made.width,
            made.height
        );
        return Ok(());
    }
    let clips = args.input.load()?;
    let clips: Vec<&Clip> = clips.iter().map(|c| &c.clip).collect();
    let made = window::video::write_mp4(&clips, &settings, &args.output)?;
    eprintln!(
        "wrote {} ({} frames at {} fps, {} × {}, {} pane(s))",
        args.output.display(),
        made.frames,
        made.fps,
        made.width,
        made.height,
        clips.len()
    );
    Ok(())
}
