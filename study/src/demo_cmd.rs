//! `study demo`: a short study on generated motion, end to end, with no files needed.
//!
//! It generates a walking figure, encodes it with two of the seeds' codecs at four rates
//! (`study sweep`), writes a MOS, a DSCQS and a 2AFC-staircase study over that stimulus set,
//! runs each with simulated observers (`study simulate`) and, where a display is available
//! (and `--simulate` is not given), one session of yours in the study window (`study run`,
//! subject `you`) into the same results, then writes the reports (`study report`), printing
//! their main tables. Without a display it says so and runs simulated observers only.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use clap::Parser;

use crate::{report_cmd, run_cmd, study_cmd};

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
    /// Simulated observers only, even where a display is available (no study window).
    #[arg(long)]
    pub simulate: bool,
}

/// The demo's studies in the window: short enough to sit through (about three minutes for all
/// three), long enough to show every screen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Simulated,
    Window,
}

const CODECS: &[&str] = &["wavelet-perceptual", "spiht"];
const RATES: &[f64] = &[10.0, 20.0, 30.0, 40.0];

fn study_text(protocol: &str, mode: Mode) -> String {
    let common = format!(
        "format_version = 1\nname = \"demo-{protocol}\"\nprotocol = \"{protocol}\"\n\
         stimuli = \"stimuli/stimuli.json\"\nseed = 7\n"
    );
    if protocol == "staircase" {
        // Thesis ch. 5 shape: start high, two-down-one-up, mean of the last reversals.
        let max_trials = if mode == Mode::Window { 12 } else { 40 };
        return common
            + &format!(
                "\n[staircase]\nparam = \"cr\"\ncodec = \"spiht\"\nstart = 40\nstep = 10\nmin = 10\n\
                 max = 40\nstop_reversals = 6\nmax_trials = {max_trials}\n\n[[staircase.tracks]]\n\
                 clip = \"walk\"\n\n[simulation]\nthreshold = 25\nslope = 3\n"
            );
    }
    let (rates, fam, repeats) = match mode {
        Mode::Simulated => ("10, 20, 30, 40", 2, 2),
        Mode::Window => ("10, 40", 1, 1),
    };
    common
        + &format!(
            "\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"wavelet-perceptual\", \"spiht\"]\n\
             target_cr = [{rates}]\n\n[session]\nfamiliarization = {fam}\nhidden_repeats = {repeats}\n"
        )
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
    fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    println!(
        "study demo: a short study on a generated walking figure, written to {}",
        out.display()
    );
    let mut mode = choose_mode(args);
    // In the window, a two-second walk keeps each trial short.
    let walk = motion::synth::WalkParams {
        duration_s: if mode == Mode::Window { 2.0 } else { 4.0 },
        ..motion::synth::WalkParams::default()
    };
    let s = |p: &Path| p.display().to_string();
    let rates: Vec<String> = RATES.iter().map(f64::to_string).collect();
    // Each study and the report section the terminal shows of it (its headline result).
    let studies = [
        ("mos", "## Mean opinion scores"),
        ("dscqs", "## Differential MOS"),
        ("staircase", "## Staircase thresholds"),
    ];
    let protocols = studies.map(|(p, _)| p);
    let steps = protocols.len() + 2;
    println!(
        "\n[1/{steps}] stimuli: codecs {} at CR {}",
        CODECS.join(","),
        rates.join(",")
    );
    let made =
        lab::generated::walk_stimuli(&out, &walk, CODECS, RATES).context("making the stimuli")?;
    println!(
        "{} stimuli ({} references) in {}",
        made.manifest.stimuli.len(),
        made.references,
        out.join("stimuli").display()
    );

    let subjects = args.subjects.to_string();
    let seed = args.seed.to_string();
    for (k, (protocol, headline)) in studies.into_iter().enumerate() {
        let study = out.join(format!("{protocol}.toml"));
        files::write(&study, study_text(protocol, mode), files::Mode::New)?;
        let results = out.join(format!("results-{protocol}"));
        println!(
            "\n[{}/{steps}] {protocol}: simulated sessions into {}",
            k + 2,
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
        if mode == Mode::Window {
            println!("       your {protocol} session in the study window…");
            let run: run_cmd::RunArgs =
                parse(&["run", &s(&study), "--subject", "you", "-o", &s(&results)])?;
            if let Err(e) = run_cmd::run(&run) {
                // The demo still reports the simulated sessions (e.g. DISPLAY set but no
                // server reachable, or no graphics adapter), and does not try again.
                println!(
                    "note: the study window did not run ({e:#}); simulated observers only from here"
                );
                mode = Mode::Simulated;
            }
        }
        let report_dir = out.join(format!("report-{protocol}"));
        // A demo user may close the window before the end: their session's trials so far are
        // reported, and listed as incomplete.
        let rep: report_cmd::ReportArgs = parse(&[
            "report",
            &s(&results),
            "-o",
            &s(&report_dir),
            "--allow-incomplete",
        ])?;
        report_cmd::run(&rep).with_context(|| format!("reporting the {protocol} study"))?;
        print_tables(&report_dir, headline)?;
    }
    println!("\n[{steps}/{steps}] done: the reports (tables, figures, findings) are");
    for protocol in protocols {
        println!(
            "  {}",
            out.join(format!("report-{protocol}/report.html")).display()
        );
    }
    Ok(())
}

/// Simulated observers only (`--simulate`, or no display), or also the window; says which.
fn choose_mode(args: &DemoArgs) -> Mode {
    if args.simulate {
        println!(
            "--simulate: every session runs with {} simulated observers.",
            args.subjects
        );
        Mode::Simulated
    } else if window::native::display_available() {
        println!(
            "A display is available: each study runs {} simulated observers, then one session of \
             yours in the study window (subject `you`; Ctrl+Shift+P pauses or quits).",
            args.subjects
        );
        Mode::Window
    } else {
        println!(
            "No display (DISPLAY and WAYLAND_DISPLAY are unset): every session runs with {} \
             simulated observers, none in the study window.",
            args.subjects
        );
        Mode::Simulated
    }
}

/// Prints the tables of one section of a report (its headline result; the rest is in
/// `report.html` and `report.md`).
fn print_tables(report_dir: &Path, section: &str) -> Result<()> {
    let md = fs::read_to_string(report_dir.join("report.md"))
        .with_context(|| format!("reading {}", report_dir.join("report.md").display()))?;
    println!("{}", tables_of(&md, section).trim_end());
    Ok(())
}

/// The tables under heading `section` of `md` (up to the next heading of its level or
/// above), after the heading itself; empty when there is no such section.
fn tables_of(md: &str, section: &str) -> String {
    let level = |h: &str| h.chars().take_while(|&c| c == '#').count();
    let mut out = String::new();
    let mut inside = None;
    let mut in_table = false;
    for line in md.lines() {
        if line.starts_with('#') {
            match inside {
                Some(l) if level(line) <= l => break,
                None if line == section => {
                    inside = Some(level(line));
                    out.push_str(line);
                    out.push('\n');
                }
                _ => {}
            }
        } else if inside.is_some() && line.starts_with('|') {
            out.push_str(line);
            out.push('\n');
            in_table = true;
        } else if in_table {
            out.push('\n');
            in_table = false;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::tables_of;

    #[test]
    fn the_tables_of_one_section_are_printed() {
        let md = "# Report\n\n## Method\n\nSix subjects.\n\n## Thresholds\n\n| a | b |\n| - | - |\n| 1 | 2 |\nNote.\n\n### Pooled\n\n| t |\n| - |\n\n## Display\n\n| d |\n";
        assert_eq!(
            tables_of(md, "## Thresholds"),
            "## Thresholds\n| a | b |\n| - | - |\n| 1 | 2 |\n\n| t |\n| - |\n\n"
        );
        assert_eq!(tables_of(md, "## Method"), "## Method\n");
        assert_eq!(tables_of(md, "## Nothing"), "");
    }
}
