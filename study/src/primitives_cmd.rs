//! `study primitives ...`: build and inspect the primitive database of thesis ch. 5.

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use codecs::primitives::{Database, SegmentParams, TrainParams};
use motion::Clip;

/// Primitive-database subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum PrimitivesCommand {
    /// Train a database on clips (offline): `.bvh` files and `.amc` files with their `.asf`
    /// files, paired as every command pairs them.
    Train {
        /// Training clips.
        #[arg(required = true)]
        clips: Vec<PathBuf>,
        /// ASF skeleton of the AMC motions not named after one of the files.
        #[arg(long, value_name = "SKEL")]
        asf: Option<PathBuf>,
        /// Output database file.
        #[arg(short, long, value_name = "DB")]
        output: PathBuf,
        /// Largest number of primitives per joint (thesis: 25).
        #[arg(long, default_value_t = 25)]
        k_max: usize,
        /// Clustering error bound in radians (thesis: 0.01).
        #[arg(long, default_value_t = 0.01)]
        error_bound: f64,
        /// Longest segment in frames, S_M of Table 5.4 (16, 32, 64).
        #[arg(long, default_value_t = 32)]
        max_frames: usize,
        /// Seed of the k-means++ seeding.
        #[arg(long, default_value_t = 0x5EED)]
        seed: u64,
        /// Replace the database file if it exists (atomically); without it an existing
        /// file is refused before training.
        #[arg(long)]
        force: bool,
    },
    /// Print a database's joints, primitive counts and clustering errors.
    Info {
        /// The database file.
        db: PathBuf,
    },
}

/// Runs a primitives subcommand.
///
/// # Errors
/// Read, write and argument errors, with the file named.
pub fn run(cmd: PrimitivesCommand) -> Result<()> {
    match cmd {
        PrimitivesCommand::Train {
            clips,
            asf,
            output,
            k_max,
            error_bound,
            max_frames,
            seed,
            force,
        } => {
            let mode = files::Mode::from_force(force);
            if !(error_bound.is_finite() && error_bound > 0.0) {
                bail!("--error-bound must be a positive number of radians");
            }
            if !(16..=4096).contains(&max_frames) {
                bail!("--max-frames must be between 16 and 4096");
            }
            if !(1..=4096).contains(&k_max) {
                bail!("--k-max must be between 1 and 4096");
            }
            files::check_new(&output, mode)?;
            let options = lab::clips::ClipOptions {
                asf,
                bvh_unit_cm: None,
            };
            let loaded = lab::clips::load(&clips, &options)?;
            let refs: Vec<&Clip> = loaded.iter().map(|l| &l.clip).collect();
            let params = TrainParams {
                k_max,
                k_start: TrainParams::default().k_start.min(k_max),
                error_bound_rad: error_bound,
                segment: SegmentParams {
                    min_frames: 15,
                    max_frames,
                },
                seed,
                ..TrainParams::default()
            };
            let frames: usize = refs.iter().map(|c| c.frames()).sum();
            eprintln!("training on {} clips, {frames} frames", loaded.len());
            let db = Database::train(&refs, &params, |done, total| {
                eprint!("\r  joints clustered: {done}/{total}");
            });
            eprintln!();
            db.write(&output, mode)?;
            eprintln!(
                "wrote {} ({} bytes, fingerprint {:08x})",
                output.display(),
                db.to_bytes().len(),
                db.fingerprint()
            );
            Ok(())
        }
        PrimitivesCommand::Info { db } => {
            let d = Database::read(&db).with_context(|| "reading the primitive database")?;
            let mut out = std::io::stdout().lock();
            writeln!(out, "{}", db.display())?;
            writeln!(out, "  fingerprint  {:08x}", d.fingerprint())?;
            writeln!(
                out,
                "  segments     {}..{} frames, normalized to 16",
                d.segment.min_frames, d.segment.max_frames
            )?;
            writeln!(out, "  joint            K  segments  error_rad")?;
            for j in &d.joints {
                writeln!(
                    out,
                    "    {:<14} {:>2} {:>9} {:>10.5}",
                    j.joint,
                    j.primitives.len(),
                    j.segments,
                    j.error_rad
                )?;
            }
            Ok(())
        }
    }
}
