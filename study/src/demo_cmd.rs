//! `study demo`: a short study on generated motion, end to end, with no files needed.
//!
//! It generates a walking figure, encodes it with two of the seeds' codecs at four rates
//! (`study sweep`), writes a MOS, a DSCQS and a 2AFC-staircase study over that stimulus set,
//! runs each with simulated observers (`study simulate`; the subject window is not part of
//! this build yet, so observers are always simulated, and the demo says so) and writes the
//! reports (`study report`), printing their main tables.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use clap::Parser;

use crate::{codec_cmd, report_cmd, study_cmd};

/// Arguments of `study demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Output folder (default: `study-demo` in the current folder, or `study-demo-N` if that
    /// exists; nothing is ever overwritten).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Simulated subjects per study.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(2..=200))]
    pub subjects: u32,
    /// Seed of the simulated observers.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run with simulated observers (the only mode of this build; kept so scripts that pass it
    /// keep working once the study window exists).
    #[arg(long)]
    pub simulate: bool,
}

const CODECS: &str = "wavelet-perceptual,spiht";
const RATES: &str = "10,20,30,40";

fn study_text(protocol: &str) -> String {
    let common = format!(
        "format_version = 1\nname = \"demo-{protocol}\"\nprotocol = \"{protocol}\"\n\
         stimuli = \"stimuli/stimuli.json\"\nseed = 7\n"
    );
    if protocol == "staircase" {
        // Thesis ch. 5 shape: start high, two-down-one-up, mean of the last reversals.
        return common
            + "\n[staircase]\nparam = \"cr\"\ncodec = \"spiht\"\nstart = 40\nstep = 10\nmin = 10\n\
               max = 40\nstop_reversals = 6\nmax_trials = 40\n\n[[staircase.tracks]]\n\
               clip = \"walk\"\n\n[simulation]\nthreshold = 25\nslope = 3\n";
    }
    common
        + "\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"wavelet-perceptual\", \"spiht\"]\n\
           target_cr = [10, 20, 30, 40]\n\n[session]\nfamiliarization = 2\nhidden_repeats = 2\n"
        // DSCQS on the 5-grade scale of thesis ch. 6.4, so DMOS reads against its 0.2 limit.
        + if protocol == "dscqs" { "\n[scale]\nkind = \"categorical\"\n" } else { "" }
}

/// Parses `args` as one command's arguments (so every default stays the command's own).
fn parse<T: clap::Args>(args: &[&str]) -> Result<T> {
    #[derive(Parser)]
    struct Wrap<A: clap::Args> {
        #[command(flatten)]
        inner: A,
    }
    Ok(Wrap::<T>::try_parse_from(args)?.inner)
}

fn free_folder(requested: Option<&Path>) -> PathBuf {
    if let Some(p) = requested {
        return p.to_path_buf();
    }
    let mut p = PathBuf::from("study-demo");
    let mut n = 2;
    while p.exists() {
        p = PathBuf::from(format!("study-demo-{n}"));
        n += 1;
    }
    p
}

/// Runs the demo.
///
/// # Errors
/// When the output folder exists or any step fails; the message names the step.
pub fn run(args: &DemoArgs) -> Result<()> {
    let out = free_folder(args.output.as_deref());
    if out.exists() {
        anyhow::bail!(
            "{} already exists; the demo never overwrites results",
            out.display()
        );
    }
    fs::create_dir_all(out.join("clips")).with_context(|| format!("creating {}", out.display()))?;
    println!(
        "study demo: a short study on a generated walking figure, written to {}",
        out.display()
    );
    println!(
        "No study window in this build: every session runs with {} simulated observers.",
        args.subjects
    );
    let clip = codecs::synth::walking_clip(&codecs::synth::WalkParams::default());
    let (asf, amc) = (out.join("clips/walk.asf"), out.join("clips/walk.amc"));
    codecs::io::write_clip(&clip, &amc, Some(&asf))?;

    let s = |p: &Path| p.display().to_string();
    let stimuli = out.join("stimuli");
    println!("\n[1/3] stimuli: codecs {CODECS} at CR {RATES}");
    let sweep: codec_cmd::SweepArgs = parse(&[
        "sweep",
        "--clips",
        &s(&amc),
        &s(&asf),
        "--codecs",
        CODECS,
        "--cr",
        RATES,
        "--quiet",
        "-o",
        &s(&stimuli),
    ])?;
    codec_cmd::sweep(&sweep).context("making the stimuli")?;

    let subjects = args.subjects.to_string();
    let seed = args.seed.to_string();
    for protocol in ["mos", "dscqs", "staircase"] {
        let study = out.join(format!("{protocol}.toml"));
        fs::write(&study, study_text(protocol))
            .with_context(|| format!("writing {}", study.display()))?;
        let results = out.join(format!("results-{protocol}"));
        println!(
            "\n[2/3] {protocol}: simulated sessions into {}",
            results.display()
        );
        let sim: study_cmd::SimulateArgs = parse(&[
            "simulate",
            &s(&study),
            "--subjects",
            &subjects,
            "--seed",
            &seed,
            "-o",
            &s(&results),
        ])?;
        study_cmd::simulate(&sim).with_context(|| format!("simulating the {protocol} study"))?;
        let report_dir = out.join(format!("report-{protocol}"));
        let rep: report_cmd::ReportArgs = parse(&["report", &s(&results), "-o", &s(&report_dir)])?;
        report_cmd::run(&rep).with_context(|| format!("reporting the {protocol} study"))?;
        print_tables(&report_dir)?;
    }
    println!(
        "\n[3/3] done: open {}",
        out.join("report-mos/report.html").display()
    );
    Ok(())
}

/// Prints the Markdown tables of a report (the part a reader wants first).
fn print_tables(report_dir: &Path) -> Result<()> {
    let md = fs::read_to_string(report_dir.join("report.md"))
        .with_context(|| format!("reading {}", report_dir.join("report.md").display()))?;
    let mut in_table = false;
    for line in md.lines() {
        let table = line.starts_with('|');
        if line.starts_with('#') || table || (in_table && !line.is_empty()) {
            println!("{line}");
        } else if in_table {
            println!();
        }
        in_table = table;
    }
    Ok(())
}
