//! `study check` and `study simulate`: validate a study file, and dry-run whole sessions with
//! simulated observers through the same engines and results store a real session uses.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context as _, bail};
use clap::Args;
use protocols::observer::Observer;
use protocols::study::Metric;
use protocols::study::content_hash;
use protocols::{Detection, Protocol, StudyDefinition};
use results::store::{
    DisplayInfo, MANIFEST_FORMAT_VERSION, RUN_FILE, read_json, write_json, write_new,
};
use results::{RunManifest, SessionManifest};

use crate::live::{LiveStimuli, LiveStimulus};
use crate::session::{self, Opened, Recorder, SessionOf, now_ms};

/// Arguments of `study check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// Study file (TOML).
    pub study: PathBuf,
}

/// Arguments of `study simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Study file (TOML).
    pub study: PathBuf,
    /// Number of simulated subjects.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub subjects: u32,
    /// Seed of the simulated observers (the trial plans derive from the study file's seed).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Results directory to create (never overwritten).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Pause before each answer, ms (paces trials for kill tests).
    #[arg(long, default_value_t = 0)]
    pub trial_delay_ms: u64,
    /// Continue an interrupted run in an existing results directory.
    #[arg(long)]
    pub resume: bool,
}

/// `study check STUDY.toml`: every problem at once, or a summary of the study.
///
/// # Errors
/// The study file's problems.
pub fn check(args: &CheckArgs) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let study = StudyDefinition::load(&args.study)?;
    let mut text = String::new();
    writeln!(text, "{}: ok", args.study.display())?;
    writeln!(text, "  name: {}", study.name)?;
    writeln!(text, "  protocol: {}", study.protocol)?;
    writeln!(text, "  seed: {}", study.seed)?;
    match study.protocol {
        Protocol::Mos | Protocol::Dscqs => {
            let n = study.familiarization.len()
                + study.conditions.len()
                + study.session.hidden_repeats as usize;
            writeln!(
                text,
                "  trials per session: {n} ({} familiarization, {} conditions, {} hidden repeats)",
                study.familiarization.len(),
                study.conditions.len(),
                study.session.hidden_repeats
            )?;
            let est_min = n as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
            writeln!(
                text,
                "  presentation time: {est_min:.1} min without answers"
            )?;
        }
        Protocol::Staircase => {
            if study.staircase.as_ref().is_some_and(|sc| sc.live.is_some()) {
                describe_live(&mut text, &study, &args.study)?;
            } else if let Some(sc) = &study.staircase {
                for t in &sc.tracks {
                    writeln!(
                        text,
                        "  staircase {:?}: clip {:?}, {} stimulus levels of {} from {} to {}",
                        t.name,
                        t.clip,
                        t.levels.len(),
                        sc.param,
                        t.levels.first().map_or(0.0, |l| l.0),
                        t.levels.last().map_or(0.0, |l| l.0)
                    )?;
                }
            }
        }
    }
    if let Some(ms) = study.session.time_limit_ms {
        writeln!(text, "  time limit: {:.1} min", ms as f64 / 60_000.0)?;
    }
    std::io::Write::write_all(&mut std::io::stdout(), text.as_bytes())?;
    Ok(())
}

/// `study check` on a live staircase: its codec, clips and tracks, and every clip encoded
/// once at the first start level (proves the codec takes the settings and shows what a trial
/// will look like).
fn describe_live(text: &mut String, study: &StudyDefinition, path: &Path) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let (Some(sc), Some(live)) = (
        &study.staircase,
        study.staircase.as_ref().and_then(|s| s.live.as_ref()),
    ) else {
        return Ok(());
    };
    let stimuli = LiveStimuli::from_study(study, path)?;
    let names: Vec<&str> = live.clips.iter().map(|c| c.clip.as_str()).collect();
    writeln!(
        text,
        "  live staircase: codec {} encodes {} = level on the fly; clips {}: {}",
        stimuli.as_ref().map_or("?", LiveStimuli::codec_name),
        sc.param,
        match live.order {
            protocols::ClipOrder::InTurn => "in turn",
            protocols::ClipOrder::Shuffled => "in turn, order shuffled per subject",
        },
        names.join(", ")
    )?;
    for t in &sc.tracks {
        writeln!(
            text,
            "  staircase {:?}: start {} in [{}, {}]",
            t.name,
            t.settings.start,
            t.settings.min.unwrap_or(f64::NEG_INFINITY),
            t.settings.max.unwrap_or(f64::INFINITY)
        )?;
    }
    // Encode every clip once at the first start level: proves the codec takes the
    // settings and shows what a trial will look like.
    if let (Some(stimuli), Some(t)) = (stimuli, sc.tracks.first()) {
        let clips: Vec<(String, String)> = stimuli
            .clips()
            .map(|(c, r)| (c.to_string(), r.to_string()))
            .collect();
        for (clip, reference) in clips {
            let level = t.settings.start;
            let trial = protocols::Trial {
                index: 0,
                block: protocols::Block::Test,
                condition: t.name.clone(),
                stimulus: sc.live_stimulus_id(&clip, level),
                reference,
                arrangement: study.presentation.arrangement,
                reference_position: protocols::Position::Left,
                staircase: Some(0),
                level: Some(level),
                break_before: false,
            };
            let s = stimuli.resolve(&trial)?;
            writeln!(
                text,
                "  clip {clip:?}: {} frames; at {} = {level}: CR {:.2}:1, RMS {:.3} cm ({} decoded frames)",
                s.reference.frames(),
                sc.param,
                s.achieved_cr,
                s.rms_cm,
                s.test.frames()
            )?;
        }
    }
    Ok(())
}

fn subject_id(index: u32) -> String {
    format!("S{:03}", index + 1)
}

/// Keeps the study file and its stimulus manifest inside the results directory, so that the
/// folder is self-contained: `study report RESULTS` finds both without the original files, and
/// a lab can archive one folder. The copy's `stimuli` key is pointed at the manifest copy.
///
/// # Errors
/// The study text is not TOML (it was validated already, so only a race could cause this) or
/// the copies cannot be written.
pub fn archive_study(
    out: &Path,
    original: &Path,
    study_bytes: &[u8],
    study: &StudyDefinition,
) -> anyhow::Result<()> {
    let copy = out.join("study.toml");
    if copy.exists() {
        return Ok(());
    }
    let text = std::str::from_utf8(study_bytes)
        .with_context(|| format!("{} is not UTF-8", original.display()))?;
    let mut table: toml::Table = text
        .parse()
        .with_context(|| format!("re-reading {}", original.display()))?;
    // The manifest's file paths are relative to its own folder: make them absolute in the
    // copy so they still name the clips from inside the results directory.
    let base = original.parent().unwrap_or(Path::new("."));
    let manifest_dir = table
        .get("stimuli")
        .and_then(toml::Value::as_str)
        .map(|m| base.join(m))
        .and_then(|m| m.parent().map(Path::to_path_buf))
        .unwrap_or_else(|| base.to_path_buf());
    let manifest_dir = fs::canonicalize(&manifest_dir).unwrap_or(manifest_dir);
    let mut manifest = study.manifest.clone();
    let absolute = |p: &str| manifest_dir.join(p).display().to_string();
    for st in &mut manifest.stimuli {
        st.file = absolute(&st.file);
        st.skeleton = st.skeleton.as_deref().map(absolute);
        st.bitstream = st.bitstream.as_deref().map(absolute);
    }
    table.insert("stimuli".into(), toml::Value::String("stimuli.json".into()));
    // A live staircase's decoder context is named relative to the study file: point the copy
    // at the original so the copy still loads it.
    if let Some(toml::Value::String(db)) = table
        .get_mut("staircase")
        .and_then(|s| s.get_mut("live"))
        .and_then(|l| l.get_mut("database"))
    {
        let p = base.join(db.as_str());
        *db = fs::canonicalize(&p).unwrap_or(p).display().to_string();
    }
    let body = toml::to_string(&table).context("writing the study copy")?;
    let header = format!(
        "# Copy of {} kept with its results; `stimuli` points at the manifest copy beside it.\n",
        original.display()
    );
    // A run killed between the two copies left a complete manifest copy (write_new is
    // atomic) but no study copy: keep an identical one instead of refusing the resume.
    let manifest_copy = out.join("stimuli.json");
    let manifest_bytes = serde_json::to_vec_pretty(&manifest)?;
    match fs::read(&manifest_copy) {
        Ok(existing) if existing == manifest_bytes => {}
        Ok(_) => bail!(
            "{} exists and differs from the manifest of {}; results are never overwritten",
            manifest_copy.display(),
            original.display()
        ),
        Err(_) => write_new(&manifest_copy, &manifest_bytes)?,
    }
    write_new(&copy, format!("{header}{body}").as_bytes())?;
    Ok(())
}

/// `study simulate`: runs `--subjects` complete simulated sessions into a results directory.
///
/// # Errors
/// Study file problems, an existing output without `--resume`, a resume whose logged trials
/// the study no longer regenerates, I/O errors.
pub fn simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let study_bytes =
        fs::read(&args.study).with_context(|| format!("reading {}", args.study.display()))?;
    let study = StudyDefinition::load(&args.study)?;
    let hash = content_hash(&study_bytes);
    let out = &args.output;
    let run = RunManifest {
        format_version: MANIFEST_FORMAT_VERSION,
        study: study.name.clone(),
        study_hash: hash.clone(),
        study_file: "study.toml".into(),
        plan_seed: study.seed,
        observer_seed: Some(args.seed),
        subjects: args.subjects,
        software_version: env!("CARGO_PKG_VERSION").into(),
        created_ms: now_ms(),
    };
    if args.resume {
        if !out.is_dir() {
            bail!("{}: no results directory to resume", out.display());
        }
        let run_path = out.join(RUN_FILE);
        if run_path.exists() {
            let old: RunManifest = read_json(&run_path)?;
            if old.observer_seed != run.observer_seed
                || old.subjects != run.subjects
                || old.plan_seed != run.plan_seed
            {
                bail!(
                    "{}: recorded with --seed {:?}, {} subjects, study seed {}; resume with the same values",
                    run_path.display(),
                    old.observer_seed,
                    old.subjects,
                    old.plan_seed
                );
            }
            if old.study_hash != hash {
                eprintln!(
                    "note: the study file changed since this run started (hash {} -> {hash}); logged trials are checked by replay",
                    old.study_hash
                );
            }
        } else {
            write_json(&run_path, &run)?;
        }
    } else {
        if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        fs::create_dir(out).map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                anyhow::anyhow!(
                    "{} already exists; results are never overwritten (use --resume to continue)",
                    out.display()
                )
            } else {
                anyhow::anyhow!("creating {}: {e}", out.display())
            }
        })?;
        write_new(&out.join(RUN_FILE), &serde_json::to_vec_pretty(&run)?)?;
    }
    archive_study(out, &args.study, &study_bytes, &study)?;
    // One cache of encoded levels for every simulated subject of the run.
    let mut live = LiveStimuli::from_study(&study, &args.study)?;
    if live.is_some()
        && study.simulation.detection == Detection::Error
        && study.simulation.metric != Metric::RmsCm
    {
        bail!(
            "{}: simulation.metric: a live staircase measures rms_cm on the decoded clip; set metric = \"rms_cm\"",
            args.study.display()
        );
    }
    for subject in 0..args.subjects {
        let dir = out.join(format!("{}_s1", subject_id(subject)));
        let summary = run_subject(&study, &hash, args, subject, &dir, live.as_mut())
            .with_context(|| format!("session {}", dir.display()))?;
        eprintln!("{summary}");
    }
    if let Some(l) = &live {
        eprintln!(
            "live staircase: {} clip × level stimuli encoded with {}",
            l.cached(),
            l.codec_name()
        );
    }
    Ok(())
}

fn new_manifest(
    study: &StudyDefinition,
    hash: &str,
    args: &SimulateArgs,
    subject: u32,
) -> SessionManifest {
    let mut m = session::new_manifest(
        study,
        SessionOf {
            study_hash: hash,
            subject: subject_id(subject),
            subject_index: subject,
            session: 1,
            observer_seed: Some(args.seed),
        },
    );
    m.subject_fields = study
        .session
        .subject_fields
        .iter()
        .map(|f| (f.clone(), "simulated".to_string()))
        .collect();
    m.display = Some(DisplayInfo {
        description: "simulated".into(),
        width_px: 0,
        height_px: 0,
        refresh_hz: 0.0,
    });
    m
}

fn run_subject(
    study: &StudyDefinition,
    hash: &str,
    args: &SimulateArgs,
    subject: u32,
    dir: &Path,
    mut live: Option<&mut LiveStimuli>,
) -> anyhow::Result<String> {
    let fresh = new_manifest(study, hash, args, subject);
    let mut rec = match Recorder::open(study, subject, dir, args.resume, fresh)? {
        Opened::Finished(m) => {
            return Ok(format!(
                "{}: already {:?}, {} trials",
                m.subject, m.status, m.trials_logged
            ));
        }
        Opened::Ready { recorder, .. } => recorder,
    };
    let observer = Observer::new(study, args.seed, subject);
    let mut clock_ms = rec.logged_clock_ms();
    let per_trial_ms = study.trial_presentation_ms();
    while let Some(trial) = rec.next_trial(clock_ms)? {
        // A live trial's stimulus is encoded now; the observer sees its measured error.
        let made = match live.as_deref_mut() {
            Some(l) => Some(l.resolve(&trial)?),
            None => None,
        };
        let response = observer.respond_measured(&trial, made.as_ref().map(|m| m.rms_cm))?;
        if args.trial_delay_ms > 0 {
            std::thread::sleep(Duration::from_millis(args.trial_delay_ms));
        }
        // Simulated session clock: the presentation (again for each replay), the answer and
        // the gap before the next trial; deterministic, so the time limit replays exactly.
        clock_ms += per_trial_ms * (1 + u64::from(response.replays))
            + response.response_time_ms
            + study.presentation.gap_ms;
        rec.record(
            trial,
            response,
            clock_ms,
            made.as_ref().map(LiveStimulus::encoding),
            None,
        )?;
    }
    rec.finish()?;
    Ok(rec.summary())
}
