//! `study preview`: a manifest's stimuli beside their references in the study window
//! ([`window::preview`]).

use std::path::PathBuf;

use anyhow::Result;
use window::preview::PreviewSet;

/// Arguments of `study preview`.
#[derive(Debug, clap::Args)]
pub struct PreviewArgs {
    /// The stimulus manifest (`stimuli.json`, as `study sweep` or `study stimuli add` write it).
    pub manifest: PathBuf,
    /// A stimulus to show (repeatable, in order); default: every stimulus but the references.
    #[arg(long = "stimulus", value_name = "ID")]
    pub stimuli: Vec<String>,
}

/// `study preview`.
///
/// # Errors
/// The manifest or a stimulus is refused ([`PreviewSet::open`]), or no window can be opened.
pub fn run(args: &PreviewArgs) -> Result<()> {
    let set = PreviewSet::open(&args.manifest, &args.stimuli, |text| {
        serde_json::from_str(text).map_err(|e| e.to_string())
    })?;
    window::preview::run(set, |l| println!("{l}"))?;
    Ok(())
}
