//! `study run`: one subject's session in the study window, and `study display-test`: the
//! window's frame timing on this display.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::{Context as _, bail};
use clap::Args;
use lab::StudyFile;
use lab::results_dir::Destination;
use lab::session::{self, Opened, Recorder};
use results::{FolderStore, Store};

use window::native::{self, WindowOptions};
use window::run;
use window::screens::{Exit, StudyUi};
use window::status::ExperimenterView;

/// Window size `WxH`.
fn parse_size(s: &str) -> Result<[f32; 2], String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("{s:?}: expected WIDTHxHEIGHT, e.g. 1280x720"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u16>()
            .ok()
            .filter(|v| *v >= 320)
            .map(f32::from)
            .ok_or_else(|| format!("{v:?}: expected a whole number of pixels ≥ 320"))
    };
    Ok([p(w)?, p(h)?])
}

/// Where the study window opens (`study run`, `study display-test`).
#[derive(Debug, Args)]
pub struct WindowArgs {
    /// Borderless fullscreen (on `--monitor`).
    #[arg(long)]
    pub fullscreen: bool,
    /// Monitor index for fullscreen.
    #[arg(long)]
    pub monitor: Option<usize>,
    /// Window size when not fullscreen.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub window_size: [f32; 2],
}

impl WindowArgs {
    fn options(&self, title: String) -> WindowOptions {
        WindowOptions {
            title,
            fullscreen: self.fullscreen,
            monitor: self.monitor,
            size: self.window_size,
        }
    }
}

/// Arguments of `study run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Study file (TOML).
    pub study: PathBuf,
    /// Subject id (letters, digits, `-` and `_`), or `auto` for the next subject number of a
    /// database run (`S001`, `S002`, ...: never given to two stations).
    #[arg(long)]
    pub subject: String,
    /// Session number of this subject.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=999))]
    pub session: u32,
    /// Continue an interrupted session of this subject.
    #[arg(long)]
    pub resume: bool,
    /// The subject's index in the study's counterbalancing (0, 1, 2, ...: subject k takes
    /// row k mod rows of a Latin square, and subjects 2j and 2j+1 see mirrored reference
    /// sides). Default: a hash of the subject id and session, which balances only on average.
    /// Give the same index to `--resume`.
    #[arg(long)]
    pub subject_index: Option<u32>,
    /// The between-subject group of a study with `[[design.groups]]`. Default: the store
    /// assigns the group with the fewest sessions among those under their quota (the same
    /// on every station), and the session's place in it is its subject index. A session keeps
    /// its group when resumed.
    #[arg(long)]
    pub group: Option<String>,
    /// What was measured of the study's `[viewing]` conditions before this session.
    #[command(flatten)]
    pub measured: MeasuredArgs,
    /// Where the window goes.
    #[command(flatten)]
    pub window: WindowArgs,
    /// Results directory (one per study; each subject's session is a folder inside).
    /// Default: `results-<study name>` beside the study file.
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Or a results store: a folder, or a PostgreSQL database several stations share.
    #[command(flatten)]
    pub store: crate::store_args::StoreArgs,
    /// Use a results directory that also holds files that are not this study's results
    /// (they are left as they are).
    #[arg(long)]
    pub force: bool,
    /// No experimenter's view on standard error (where the session stands: trial k of n,
    /// answers, dropped frames, elapsed time, breaks, pauses, the end).
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// What the experimenter measured of the viewing conditions (a study with `[viewing]`): stored
/// in `session.json` with the confirmation the window asks for, and shown on that screen for
/// the experimenter to check.
#[derive(Debug, Args, Default)]
pub struct MeasuredArgs {
    /// Measured viewing distance, cm.
    #[arg(long = "measured-distance-cm", value_name = "CM", value_parser = measurement)]
    pub distance_cm: Option<f64>,
    /// Measured peak luminance of the display, cd/m².
    #[arg(long = "measured-peak-cd-m2", value_name = "CD_M2", value_parser = measurement)]
    pub peak_cd_m2: Option<f64>,
    /// Measured background luminance, cd/m².
    #[arg(
        long = "measured-background-cd-m2",
        value_name = "CD_M2",
        value_parser = measurement
    )]
    pub background_cd_m2: Option<f64>,
    /// Measured room illumination, lux.
    #[arg(long = "measured-room-lux", value_name = "LUX", value_parser = measurement)]
    pub room_lux: Option<f64>,
}

impl MeasuredArgs {
    fn any(&self) -> bool {
        self.distance_cm.is_some()
            || self.peak_cd_m2.is_some()
            || self.background_cd_m2.is_some()
            || self.room_lux.is_some()
    }

    /// Writes the given measurements into `v`, keeping what is not given.
    fn apply(&self, v: &mut results::ViewingRecord) {
        let set = |to: &mut Option<f64>, from: Option<f64>| {
            if from.is_some() {
                *to = from;
            }
        };
        set(&mut v.distance_cm, self.distance_cm);
        set(&mut v.peak_luminance_cd_m2, self.peak_cd_m2);
        set(&mut v.background_luminance_cd_m2, self.background_cd_m2);
        set(&mut v.room_illuminance_lux, self.room_lux);
    }
}

/// A measurement: a finite number, at least 0.
fn measurement(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (0.0..=1e6).contains(&v) => Ok(v),
        Ok(_) => Err(format!(
            "{s} is not a measurement (a number from 0 to 10^6)"
        )),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

/// Arguments of `study display-test`.
#[derive(Debug, Args)]
pub struct DisplayTestArgs {
    /// Seconds to measure (after the refresh period is estimated).
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Where the window goes.
    #[command(flatten)]
    pub window: WindowArgs,
    /// Clip to animate (`.bvh`, or `.amc` with `--asf`); default: the generated walk.
    #[arg(long)]
    pub clip: Option<PathBuf>,
    /// ASF skeleton of an `.amc` clip.
    #[arg(long)]
    pub asf: Option<PathBuf>,
    /// Also write the measurements as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Replace an existing `--json` file.
    #[arg(long)]
    pub force: bool,
}

/// `study run`: one subject's session in the window.
///
/// # Errors
/// A bad study file or subject id, an existing session without `--resume`, no display, or a
/// results folder that cannot be written.
pub fn run(args: &RunArgs) -> anyhow::Result<()> {
    let auto = args.subject == "auto";
    if !auto {
        session::check_subject(&args.subject)?;
    }
    let file = StudyFile::load(&args.study)?;
    check_measured(args, &file)?;
    let destination = args.store.destination(args.output.as_deref(), || {
        Some(file.dir().join(format!("results-{}", file.definition.name)))
    })?;
    if let Destination::Folder(out) = &destination {
        if auto {
            bail!(
                "--subject auto takes the next subject number from a database (--store); with a results folder, name the subject"
            );
        }
        // Before anything is shown or written: the results folder is this study's.
        lab::results_dir::check_for_subjects(out, &file, args.force)?;
    }
    if !native::display_available() {
        bail!(
            "no display (DISPLAY and WAYLAND_DISPLAY are unset): `study run` shows stimuli to a \
             subject in a window. Run it on the lab machine's display, or dry-run the study with \
             `study simulate {}`",
            args.study.display()
        );
    }
    // Every stimulus the plan can show, before anything is written or shown.
    let view = ExperimenterView::stderr(args.quiet);
    let checked = lab::preflight::verify(&file, &|done, total| view.checking(done, total))
        .with_context(|| format!("{}: nothing was written", args.study.display()))?;
    view.note(format!("stimuli checked: {checked}"));
    // SIGINT (Ctrl+C in the experimenter's terminal) and SIGTERM stop the session the way
    // "Quit and save" does: state saved, session marked interrupted, resume command printed.
    let signalled = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&signalled))
            .context("installing the SIGINT/SIGTERM handler")?;
    }
    let (store, location, subject) = open_store(args, &file, &destination)?;
    let mut store = view.tap(store);
    view.name(format!("{subject} s{}", args.session));
    let Some(recorder) = open_session(args, &file, store.as_mut(), &subject)? else {
        return Ok(());
    };
    let dir = recorder.path();
    let stimuli = lab::source::open(&file)?;
    let study = Arc::new(file.definition);
    let screens = StudyUi::new(Arc::clone(&study), stimuli, recorder, true);
    // The title bar shows what subjects may read: the study's title, not its internal name.
    let options = args.window.options(study.title().to_owned());
    let (report, exit) = match run::session(&options, screens, &signalled, view.watcher()) {
        Ok(r) => r,
        Err(e) => {
            // A window that never opened leaves no session behind (a resumed one is kept).
            if !args.resume
                && store
                    .discard_unstarted(&subject, args.session)
                    .unwrap_or(false)
            {
                return Err(e.context(format!(
                    "the window did not open; no session was recorded in {}",
                    dir.display()
                )));
            }
            return Err(e);
        }
    };
    view.finish();
    print!("{}", run::timing_text(&report));
    let resume = || {
        format!(
            "study run {} --subject {subject} --session {}{} --resume{}",
            args.study.display(),
            args.session,
            args.subject_index
                .map(|k| format!(" --subject-index {k}"))
                .unwrap_or_default(),
            where_args(args)
        )
    };
    match exit {
        Some(Exit::Finished(summary)) => {
            println!("{summary}");
            println!("results: {location}");
            Ok(())
        }
        Some(Exit::Quit { logged }) => {
            println!(
                "session stopped by the experimenter after {logged} trials; continue with: {}",
                resume()
            );
            Ok(())
        }
        Some(Exit::Signalled { logged }) => {
            println!(
                "session interrupted by a signal after {logged} trials, saved; continue with: {}",
                resume()
            );
            Ok(())
        }
        Some(Exit::Failed(e)) => bail!("{e} (the session is resumable with --resume)"),
        None => bail!("the window closed before the session ended (resumable with --resume)"),
    }
}

/// `--measured-*` needs a study that states viewing conditions.
fn check_measured(args: &RunArgs, file: &StudyFile) -> anyhow::Result<()> {
    if args.measured.any() && file.definition.viewing.is_none() {
        bail!(
            "{}: --measured-* records the study's viewing conditions, but the study file has no \
             [viewing] table stating them",
            args.study.display()
        );
    }
    Ok(())
}

/// The options of a resume command that name where the results are, as the experimenter
/// gave them (a database by its URL without a password, `env` or the file).
fn where_args(args: &RunArgs) -> String {
    let mut out = String::new();
    if let Some(o) = &args.output {
        let _ = write!(out, " -o {}", o.display());
    }
    if let Some(s) = &args.store.store {
        let _ = write!(out, " --store {s}");
    }
    if let Some(f) = &args.store.store_file {
        let _ = write!(out, " --store-file {}", f.display());
    }
    if let Some(r) = &args.store.run {
        let _ = write!(out, " --run {r}");
    }
    out
}

/// The store the session goes to (created or checked as the first session of a run), where
/// it is for messages, and the subject's id (a new number from the database for `auto`).
fn open_store(
    args: &RunArgs,
    file: &StudyFile,
    destination: &Destination,
) -> anyhow::Result<(Box<dyn Store>, String, String)> {
    Ok(match destination {
        Destination::Folder(out) => {
            for note in lab::results_dir::open_for_subjects(out, file, args.force)? {
                eprintln!("{note}");
            }
            (
                Box::new(FolderStore::new(out)),
                out.display().to_string(),
                args.subject.clone(),
            )
        }
        Destination::Database { db, run } => {
            let (mut store, notes) =
                lab::results_dir::open_database_for_subjects(db, run.as_deref(), file)?;
            for note in notes {
                eprintln!("{note}");
            }
            let subject = if args.subject == "auto" {
                if args.resume {
                    bail!("--resume continues a named subject's session: give its id, not auto");
                }
                loop {
                    let id_of = |n: u32| lab::simulate::subject_id(n - 1);
                    let Some((_, id)) = store.take_subject_number(None, &id_of, None)? else {
                        bail!("{}: no subject number left", store.location());
                    };
                    if store.find_session(&id, args.session)? == results::backend::Found::Absent {
                        println!("subject number from {}: {id}", store.location());
                        break id;
                    }
                }
            } else {
                args.subject.clone()
            };
            let location = store.location();
            (Box::new(store), location, subject)
        }
    })
}

/// The subject's session in `store`: new, or resumed with `--resume`; `None` (said on
/// stdout) when it is already finished.
fn open_session(
    args: &RunArgs,
    file: &StudyFile,
    store: &mut dyn Store,
    subject: &str,
) -> anyhow::Result<Option<Box<Recorder>>> {
    let who = session::SessionFor {
        subject,
        session: args.session,
        group: args.group.as_deref(),
        subject_index: args.subject_index,
        observer_seed: None,
        resume: args.resume,
    };
    let (opened, group) = session::open_subject(file, store, &who, &|_| {})?;
    if let Some(g) = &group {
        println!("{subject} session {}: group {g}", args.session);
    }
    let dir = store.session_path(subject, args.session);
    Ok(match opened {
        Opened::Finished(m) => {
            println!(
                "{}: session already {:?} with {} trials; nothing to do",
                dir.display(),
                m.status,
                m.trials_logged
            );
            None
        }
        Opened::Ready {
            mut recorder,
            resumed,
        } => {
            if args.measured.any() {
                recorder.update_manifest(|m| {
                    args.measured.apply(m.viewing.get_or_insert_default());
                })?;
            }
            if resumed > 0 {
                println!("{}: resuming after {resumed} logged trials", dir.display());
            }
            Some(recorder)
        }
    })
}

/// `study display-test`: two animated skeletons side by side for `--seconds`, then the
/// frame-interval statistics.
///
/// # Errors
/// No display or adapter, an unreadable clip, or the JSON cannot be written.
pub fn display_test(args: &DisplayTestArgs) -> anyhow::Result<()> {
    if !native::display_available() {
        bail!("no display (DISPLAY and WAYLAND_DISPLAY are unset): nothing to measure");
    }
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 3600.0) {
        bail!("--seconds {}: expected 0 < seconds ≤ 3600", args.seconds);
    }
    // Refused before the measurement, not after it.
    let mode = files::Mode::from_force(args.force);
    if let Some(path) = &args.json {
        files::check_new(path, mode)?;
    }
    let clip = match &args.clip {
        Some(p) => motion::io::read_clip(args.asf.as_deref(), p)?,
        None => motion::synth::walking_clip(&motion::synth::WalkParams::default()),
    };
    let options = args.window.options("study: display test".into());
    let report = run::display_test(&options, &clip, args.seconds)?;
    let text = run::timing_text(&report);
    print!("{text}");
    if let Some(path) = &args.json {
        let mut cpu = report.cpu_ms.clone();
        cpu.sort_by(f64::total_cmp);
        let s = report.session;
        let json = serde_json::json!({
            "display": report.facts.describe(report.period),
            "adapter": report.facts.adapter,
            "device_type": report.facts.device_type,
            "driver": report.facts.driver,
            "present_mode": report.facts.present_mode,
            "width_px": report.facts.width_px,
            "height_px": report.facts.height_px,
            "refresh_hz": report.period.map(|(p, _)| 1000.0 / p),
            "frames": s.frames,
            "dropped": s.dropped,
            "interval_mean_ms": s.mean_ms,
            "interval_sd_ms": s.sd_ms,
            "interval_max_ms": s.max_ms,
            "cpu_p50_ms": run::percentile(&cpu, 0.5),
            "cpu_p99_ms": run::percentile(&cpu, 0.99),
        });
        files::write(path, serde_json::to_vec_pretty(&json)?, mode)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_checked() {
        assert_eq!(parse_size("1280x720"), Ok([1280.0, 720.0]));
        assert!(parse_size("1280").is_err() && parse_size("100x100").is_err());
    }
}
