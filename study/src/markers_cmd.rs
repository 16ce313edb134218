//! `study markers ...`: synthetic marker captures and skeleton solving by GDKE (issue 9).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use markers::{acclaim, calibration::Calibration, data, gdke::JointKind, segments, synth};

use crate::clip_cmd::ClipInput;

/// Marker subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum MarkersCommand {
    /// Generate markers (C3D or CSV) from a clip: three per bone, Gaussian noise, gaps.
    Synth(SynthArgs),
    /// Solve a skeleton and joint rotations from markers and write them as BVH, or as ASF/AMC.
    Solve(SolveArgs),
}

/// Arguments of `study markers synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    #[command(flatten)]
    input: ClipInput,
    /// Output marker file (`.c3d` or `.csv`), in mm.
    #[arg(short, long, value_name = "OUT")]
    output: PathBuf,
    /// Noise σ on each coordinate, mm.
    #[arg(long, default_value_t = 2.0, value_name = "MM")]
    noise_mm: f64,
    /// Probability that a sample is missing.
    #[arg(long, default_value_t = 0.005, value_name = "P")]
    gap_probability: f64,
    /// Distance of the markers from the bone line, cm.
    #[arg(long, default_value_t = 6.0, value_name = "CM")]
    offset_cm: f64,
    /// Seed of the noise generator.
    #[arg(long, default_value_t = 9)]
    seed: u64,
    /// Also write the matching segment assignment file (TOML) here.
    #[arg(long, value_name = "TOML")]
    segments_out: Option<PathBuf>,
    /// Also write a range-of-motion (calibration) trial here (`.c3d` or `.csv`): the same
    /// markers, from the clip's first frame every joint swings through its range, one
    /// rotation axis at a time, for `solve --calibration`.
    #[arg(long, value_name = "ROM")]
    calibration_out: Option<PathBuf>,
    /// Range-of-motion swing each side of the base pose, degrees.
    #[arg(
        long,
        default_value_t = 40.0,
        value_name = "DEG",
        requires = "calibration_out"
    )]
    rom_amplitude_deg: f64,
    /// Duration of one axis's swing in the range-of-motion trial, seconds.
    #[arg(
        long,
        default_value_t = 2.0,
        value_name = "S",
        requires = "calibration_out"
    )]
    rom_seconds_per_axis: f64,
    /// Swing past the skeleton's joint limits (by default the swings stop at them).
    #[arg(long, requires = "calibration_out")]
    rom_ignore_limits: bool,
    /// Start the range-of-motion trial from the rest pose instead of the clip's first
    /// frame.
    #[arg(long, requires = "calibration_out")]
    rom_rest_pose: bool,
    /// Replace output files that exist (each atomically); without it an existing output is
    /// refused before anything is written.
    #[arg(long)]
    force: bool,
}

/// Arguments of `study markers solve`.
#[derive(Debug, clap::Args)]
pub struct SolveArgs {
    /// Marker file (`.c3d` or `.csv`).
    markers: PathBuf,
    /// Segment/marker assignment file (TOML).
    #[arg(long, value_name = "FILE")]
    segments: PathBuf,
    /// Output motion file: `.bvh`, or `.amc` with `--out-asf`.
    #[arg(short, long, value_name = "OUT")]
    output: PathBuf,
    /// Output skeleton (`.asf`) for `.amc` output.
    #[arg(long, value_name = "SKEL")]
    out_asf: Option<PathBuf>,
    /// Range-of-motion (calibration) trial with the same markers (`.c3d` or `.csv`): joint
    /// centres, hinge axes and classifications are estimated on it and applied to MARKERS.
    #[arg(long, value_name = "ROM")]
    calibration: Option<PathBuf>,
    /// Replace output files that exist (each atomically); without it an existing output is
    /// refused before the solve.
    #[arg(long)]
    force: bool,
}

/// Runs a markers subcommand.
///
/// # Errors
/// Any read, write, argument or solve error, with the file named.
pub fn run(cmd: MarkersCommand) -> Result<()> {
    match cmd {
        MarkersCommand::Synth(args) => synth(args),
        MarkersCommand::Solve(args) => solve(args),
    }
}

fn synth(args: SynthArgs) -> Result<()> {
    let SynthArgs {
        input,
        output,
        noise_mm,
        gap_probability,
        offset_cm,
        seed,
        segments_out,
        calibration_out,
        rom_amplitude_deg,
        rom_seconds_per_axis,
        rom_ignore_limits,
        rom_rest_pose,
        force,
    } = args;
    let mode = files::Mode::from_force(force);
    for p in std::iter::once(&output)
        .chain(&segments_out)
        .chain(&calibration_out)
    {
        files::check_new(p, mode)?;
    }
    let loaded = input.load_one()?;
    let options = synth::SynthOptions {
        noise_mm,
        gap_probability,
        offset_cm,
        seed,
    };
    let capture = synth::synth_capture(&loaded.clip, &options)?;
    data::write_markers(&capture.markers, &output, mode)?;
    eprintln!(
        "wrote {}: {} markers × {} frames, {} gaps",
        output.display(),
        capture.markers.marker_count(),
        capture.markers.frames(),
        capture.markers.gap_count()
    );
    if let Some(path) = segments_out {
        files::write(&path, synth::segment_map_toml(&loaded.clip), mode)?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(path) = calibration_out {
        let rom = synth::RomOptions {
            amplitude_deg: rom_amplitude_deg,
            seconds_per_axis: rom_seconds_per_axis,
            base: if rom_rest_pose {
                synth::RomBase::Rest
            } else {
                synth::RomBase::FirstFrame
            },
            respect_limits: !rom_ignore_limits,
        };
        let trial = synth::rom_capture(&loaded.clip, &rom, &options)?;
        data::write_markers(&trial.markers, &path, mode)?;
        eprintln!(
            "wrote {}: range-of-motion trial, {} markers × {} frames ({:.1} s), {} gaps",
            path.display(),
            trial.markers.marker_count(),
            trial.markers.frames(),
            trial.markers.frames() as f64 / trial.markers.frame_rate_hz,
            trial.markers.gap_count()
        );
    }
    Ok(())
}

fn solve(args: SolveArgs) -> Result<()> {
    let SolveArgs {
        markers,
        segments: seg_path,
        output,
        out_asf,
        calibration,
        force,
    } = args;
    let mode = files::Mode::from_force(force);
    let is = |p: &PathBuf, e: &str| p.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
    match (is(&output, "bvh"), is(&output, "amc"), &out_asf) {
        (true, _, None) => {}
        (true, _, Some(a)) => bail!(
            "{}: a BVH file carries its own skeleton; --out-asf is for .amc output",
            a.display()
        ),
        (_, true, Some(a)) if is(a, "asf") => {}
        (_, true, Some(a)) => bail!("{}: the skeleton is written as .asf", a.display()),
        (_, true, None) => bail!(
            "{}: AMC output needs --out-asf for its skeleton",
            output.display()
        ),
        _ => bail!(
            "{}: the solved clip is written as .bvh or .amc",
            output.display()
        ),
    }
    for p in std::iter::once(&output).chain(&out_asf) {
        files::check_new(p, mode)?;
    }
    let set = data::read_markers(&markers)?;
    let map = segments::read_segments(&seg_path)?;
    let solved = if let Some(rom_path) = &calibration {
        let rom = data::read_markers(rom_path)?;
        let cal = Calibration::estimate(&rom, &map)
            .with_context(|| format!("{}: calibration trial", rom_path.display()))?;
        let solved = cal.solve(&set).with_context(|| {
            format!(
                "{}: solving with the calibration from {}",
                markers.display(),
                rom_path.display()
            )
        })?;
        eprintln!(
            "joint centres, axes and kinds calibrated on {} ({} frames):",
            rom_path.display(),
            cal.frames
        );
        solved
    } else {
        segments::solve(&set, &map).with_context(|| {
            format!(
                "{}: solving with the segment map {}",
                markers.display(),
                seg_path.display()
            )
        })?
    };
    if out_asf.is_some() {
        let asf = acclaim::bvh_to_asf(&solved.clip)?;
        motion::io::write_clip(&asf.clip, &output, out_asf.as_deref(), mode)?;
    } else {
        motion::io::write_clip(&solved.clip, &output, None, mode)?;
    }
    for (i, j) in solved.joints.iter().enumerate() {
        let kind = match j.kind {
            _ if i == 0 => "root".to_string(),
            JointKind::Spherical => "spherical".to_string(),
            JointKind::Hinge { axis } => {
                format!(
                    "hinge, axis ({:.3}, {:.3}, {:.3})",
                    axis[0], axis[1], axis[2]
                )
            }
            JointKind::NotMoving => "not moving".to_string(),
        };
        let c = j.centre_parent_mm;
        eprintln!(
            "{:<14} {kind:<34} centre ({:.1}, {:.1}, {:.1}) mm, {} markers, {} held frames",
            j.segment, c[0], c[1], c[2], j.markers_used, j.held_frames
        );
    }
    if let Some(a) = &out_asf {
        eprintln!("wrote {}", a.display());
    }
    eprintln!(
        "wrote {}: {} segments, {} frames",
        output.display(),
        solved.clip.skeleton.joints.len(),
        solved.clip.frames()
    );
    Ok(())
}
