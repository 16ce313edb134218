//! `study stimuli ...`: stimulus sets made elsewhere (docs/codecs.md, "A codec of your own").

use std::path::PathBuf;

use anyhow::{Result, bail};
use lab::added::{Added, Size};

/// Stimulus-set subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum StimuliCommand {
    /// Add a clip decoded by a codec of your own (or a clip's reference) to a stimulus
    /// manifest, measured as `study sweep` measures its own: joint RMS and max error, the worst
    /// 1-s window and angle error against the clip's reference by the same FK, and the
    /// compression ratio 4 bytes × channels × frames / the stream's bytes.
    Add(AddArgs),
}

/// Arguments of `study stimuli add`.
#[derive(Debug, clap::Args)]
pub struct AddArgs {
    /// The manifest (`stimuli.json`); adding a clip's reference creates it. Every file it
    /// names must lie in its folder.
    pub manifest: PathBuf,
    /// The clip's name (the reference and every decoded version of it share it).
    #[arg(long)]
    pub clip: String,
    /// Add the clip's reference: its source motion file (BVH, or AMC with --skeleton).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["codec", "file", "stream", "bytes", "params", "id"])]
    pub reference: Option<PathBuf>,
    /// The codec that made the decoded clip.
    #[arg(long, requires = "file")]
    pub codec: Option<String>,
    /// The decoded motion file (BVH, or AMC with --skeleton).
    #[arg(long, value_name = "FILE", requires = "codec")]
    pub file: Option<PathBuf>,
    /// The ASF skeleton of an AMC file (--reference or --file).
    #[arg(long, value_name = "ASF")]
    pub skeleton: Option<PathBuf>,
    /// The stream the codec wrote: its size gives the compression ratio (its content is not
    /// read, only hashed).
    #[arg(long, value_name = "FILE", conflicts_with = "bytes")]
    pub stream: Option<PathBuf>,
    /// The stream's size in bytes, where the file is not at hand. Without --stream or
    /// --bytes the stimulus is added with its CR unknown: measured, previewable, not studied.
    #[arg(long, value_name = "N")]
    pub bytes: Option<u64>,
    /// A codec parameter the clip was made with (repeatable): `--param q=8`. Parameters tell
    /// variants of one codec apart (the id and the report's condition labels carry them).
    #[arg(long = "param", value_name = "KEY=VALUE")]
    pub params: Vec<String>,
    /// The stimulus id (default: CLIP/CODEC, then the parameters: `walk/mycodec/q8`).
    #[arg(long)]
    pub id: Option<String>,
}

/// Runs a stimuli subcommand.
///
/// # Errors
/// The refusals of [`lab::added::add`], each naming its file.
pub fn run(cmd: StimuliCommand) -> Result<()> {
    match cmd {
        StimuliCommand::Add(args) => add(&args),
    }
}

fn add(args: &AddArgs) -> Result<()> {
    let what = match (&args.reference, &args.codec, &args.file) {
        (Some(file), _, _) => Added::Reference {
            file: file.clone(),
            skeleton: args.skeleton.clone(),
        },
        (None, Some(codec), Some(file)) => {
            let size = match (&args.stream, args.bytes) {
                (Some(path), _) => Size::Stream(path.clone()),
                (None, Some(n)) => Size::Bytes(n),
                (None, None) => Size::Unknown,
            };
            Added::Decoded {
                codec: codec.clone(),
                file: file.clone(),
                skeleton: args.skeleton.clone(),
                size,
                params: lab::sweep::parse_params(&args.params)?,
                id: args.id.clone(),
            }
        }
        _ => bail!("give --reference FILE, or --codec NAME with --file FILE"),
    };
    let st = lab::added::add(&args.manifest, &args.clip, &what)?;
    match &st.metrics {
        Some(m) => println!(
            "{}: {} bytes, CR {}, joint RMS {:.3} cm, max {:.3} cm, worst 1-s window RMS {}, angle {:.3}°",
            st.id,
            st.bytes,
            st.achieved_cr
                .map_or_else(|| "unknown".to_string(), |c| format!("{c:.2}")),
            m.rms_cm,
            m.max_cm,
            m.worst_window_rms_cm
                .map_or_else(|| "none".to_string(), |w| format!("{w:.3} cm")),
            m.mean_angle_deg,
        ),
        None => println!("{}: reference of clip {:?}", st.id, st.clip),
    }
    println!("wrote {}", args.manifest.display());
    Ok(())
}
