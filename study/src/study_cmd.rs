//! `study check` and `study simulate`: validate a study file, and dry-run whole sessions with
//! simulated observers through the same engines and results store a real session uses.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use lab::StudyFile;
use lab::live::LiveStimuli;
use lab::simulate::SimulateOptions;
use protocols::{Protocol, StudyDefinition};

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
    pub output: Option<PathBuf>,
    /// Or a results store: a folder, or a PostgreSQL database several stations simulate into
    /// at once (subject numbers from the database).
    #[command(flatten)]
    pub store: crate::store_args::StoreArgs,
    /// Seconds to wait for an unreachable database before stopping (the session resumes
    /// where its committed answers end).
    #[arg(long, default_value_t = 300)]
    pub patience_s: u64,
    /// Pause before each answer, ms (paces trials for kill tests).
    #[arg(long, default_value_t = 0)]
    pub trial_delay_ms: u64,
    /// Continue an interrupted run in an existing results directory.
    #[arg(long)]
    pub resume: bool,
    /// Simulate one subject with this id instead of `S001`, `S002`, ...: its plan is the one
    /// `study run --subject ID` and `study serve` give that id (a results folder only).
    #[arg(long, value_name = "ID", conflicts_with = "subjects")]
    pub subject: Option<String>,
}

/// `study check STUDY.toml`: every problem at once, or a summary of the study.
///
/// # Errors
/// The study file's problems.
pub fn check(args: &CheckArgs) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let file = StudyFile::load(&args.study)?;
    // A live staircase's decoder context and source clips are read now: their problems are
    // the study file's too.
    let live = LiveStimuli::from_study(&file)?;
    // Every stimulus the plan can show, read now: a missing or broken file is the study's
    // problem before any subject sees anything.
    let checked = preflight(&file)?;
    let study = &file.definition;
    let mut text = String::new();
    writeln!(text, "{}: ok", args.study.display())?;
    writeln!(text, "  name: {}", study.name)?;
    writeln!(text, "  title (subjects see): {}", study.title())?;
    let instructions = study
        .session
        .instructions
        .clone()
        .unwrap_or_else(|| protocols::texts::default_instructions(study));
    writeln!(text, "  instructions (subjects read): {instructions}")?;
    writeln!(text, "  protocol: {}", study.protocol)?;
    writeln!(text, "  seed: {}", study.seed)?;
    match study.protocol {
        Protocol::Mos | Protocol::Dscqs | Protocol::Acr | Protocol::Dcr => {
            describe_ratings(&mut text, study)?;
        }
        Protocol::PairComparison => describe_pairs(&mut text, study)?,
        Protocol::Mushra => describe_mushra(&mut text, study)?,
        Protocol::Staircase => match &live {
            Some(live) => describe_live(&mut text, study, live)?,
            None => describe_staircase(&mut text, study)?,
        },
    }
    if let Some(ms) = study.session.time_limit_ms {
        writeln!(text, "  time limit: {:.1} min", ms as f64 / 60_000.0)?;
    }
    describe_design(&mut text, study)?;
    writeln!(text, "  stimuli: {checked}")?;
    std::io::Write::write_all(&mut std::io::stdout(), text.as_bytes())?;
    Ok(())
}

/// [`lab::preflight::verify`] with a progress line on stderr when it takes over a second.
///
/// # Errors
/// Every stimulus problem, each naming its file.
pub fn preflight(file: &StudyFile) -> anyhow::Result<lab::preflight::Checked> {
    let start = std::time::Instant::now();
    let shown = std::cell::Cell::new(false);
    let checked = lab::preflight::verify(file, &|done, total| {
        if start.elapsed() > Duration::from_secs(1) {
            shown.set(true);
            eprint!("\rchecking stimuli: {done}/{total}");
        }
    });
    if shown.get() {
        eprintln!();
    }
    Ok(checked?)
}

/// The trials of a session of between-subject group `group`.
fn group_trials(study: &StudyDefinition, group: &str) -> Option<u32> {
    let of_group = study.for_group(Some(group)).ok()?;
    protocols::texts::planned_trials(&of_group).exact()
}

/// Counterbalancing: the order of the conditions and where the reference goes.
fn describe_design(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use protocols::study::{ConditionOrder, ReferencePlacement};
    use std::fmt::Write as _;
    for g in &study.design.groups {
        let quota = g
            .quota
            .map_or_else(|| "no quota".into(), |q| format!("quota {q}"));
        let trials = group_trials(study, &g.name).unwrap_or(0);
        writeln!(
            text,
            "  group {}: {} condition(s), {trials} trials per session, {quota}",
            g.name,
            g.stimuli.len()
        )?;
    }
    if study.design.order == ConditionOrder::LatinSquare && !study.design.groups.is_empty() {
        writeln!(
            text,
            "  order: balanced Latin square (Williams) over each group's conditions: a \
             session's place in its group takes that row"
        )?;
    } else if study.design.order == ConditionOrder::LatinSquare {
        // A pair comparison orders its pairs, a MUSHRA study its screens (one per clip), the
        // others their conditions.
        let items = match study.protocol {
            Protocol::PairComparison => study.pairs().len(),
            Protocol::Mushra => protocols::study::mushra_screens(&study.conditions).len(),
            _ => study.conditions.len(),
        };
        let rows = protocols::design::williams_rows(items);
        writeln!(
            text,
            "  order: balanced Latin square (Williams), {rows} rows: subject index k takes row \
             k mod {rows}; a complete block is {rows} subjects"
        )?;
    }
    let side = match study.presentation.reference_position {
        _ if study.protocol == Protocol::Mushra => {
            "a pane of its own, labelled; the rated stimuli shuffled over the lettered panes \
             per screen and subject"
                .to_string()
        }
        ReferencePlacement::Fixed(p) => format!("always {p}"),
        ReferencePlacement::Random => "random per trial".to_string(),
        ReferencePlacement::Balanced => match study.protocol {
            Protocol::Staircase => "balanced (each block of 4 trials, mirrored for the next \
                                    subject)"
                .to_string(),
            Protocol::PairComparison => {
                "balanced (per pair, mirrored for the next subject)".to_string()
            }
            _ => "balanced (per condition, mirrored for the next subject)".to_string(),
        },
    };
    writeln!(text, "  reference position: {side}")?;
    if let Some(sc) = &study.staircase
        && sc.practice_trials > 0
    {
        writeln!(
            text,
            "  practice: {} trial(s) before the staircases, not analysed",
            sc.practice_trials
        )?;
    }
    if let Some(v) = &study.viewing {
        let stated: Vec<String> = v
            .describe()
            .into_iter()
            .map(|(what, value)| format!("{what} {value}"))
            .collect();
        writeln!(
            text,
            "  viewing conditions (confirmed before each session): {}",
            stated.join(", ")
        )?;
    }
    Ok(())
}

/// A MOS or DSCQS study's trials and presentation time.
fn describe_ratings(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use std::fmt::Write as _;
    let n = study.familiarization.len()
        + study.conditions.len()
        + study.session.hidden_repeats as usize;
    if study.design.groups.is_empty() {
        writeln!(
            text,
            "  trials per session: {n} ({} familiarization, {} conditions, {} hidden repeats)",
            study.familiarization.len(),
            study.conditions.len(),
            study.session.hidden_repeats
        )?;
    } else {
        writeln!(
            text,
            "  conditions: {} in {} between-subject groups (each session sees its group's; \
             {} familiarization, {} hidden repeats)",
            study.conditions.len(),
            study.design.groups.len(),
            study.familiarization.len(),
            study.session.hidden_repeats
        )?;
    }
    let hidden = study
        .conditions
        .iter()
        .filter(|c| c.stimulus == c.reference)
        .count();
    if hidden > 0 {
        writeln!(
            text,
            "  hidden references: {hidden} (ACR-HR: DMOS = test - hidden reference + 5)"
        )?;
    }
    // A session of a between-subject group shows its group's trials: the largest group's.
    let n = if study.design.groups.is_empty() {
        n
    } else {
        study
            .design
            .groups
            .iter()
            .filter_map(|g| group_trials(study, &g.name))
            .max()
            .map_or(n, |t| t as usize)
    };
    let est_min = n as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
    writeln!(
        text,
        "  presentation time: {est_min:.1} min without answers"
    )
}

/// A pair comparison's pairs, trials and presentation time.
fn describe_pairs(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use std::fmt::Write as _;
    let pairs = study.pairs().len();
    let n = pairs + study.session.hidden_repeats as usize;
    writeln!(
        text,
        "  trials per session: {n} ({pairs} pairs of {} conditions, {} hidden repeats with \
         the sides swapped)",
        study.conditions.len(),
        study.session.hidden_repeats
    )?;
    let anchors = study
        .conditions
        .iter()
        .filter(|c| c.stimulus == c.reference)
        .count();
    if anchors > 0 {
        writeln!(
            text,
            "  originals compared: {anchors} (unlabelled; each clip's scale is anchored at its \
             original)"
        )?;
    }
    let est_min = n as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
    writeln!(
        text,
        "  presentation time: {est_min:.1} min without answers"
    )
}

/// A MUSHRA study: its screens (one per clip) with their panes, the anchors and the
/// post-screening rules.
fn describe_mushra(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use protocols::study::AnchorRule;
    use std::fmt::Write as _;
    let Some(m) = &study.mushra else {
        return Ok(());
    };
    let screens = protocols::study::mushra_screens(&study.conditions);
    let rated: usize = screens.iter().map(|(_, c)| c.len() + 2).sum();
    writeln!(
        text,
        "  screens per session: {} (one per clip), {rated} rated panes in all",
        screens.len()
    )?;
    if m.training_screens > 0 {
        writeln!(
            text,
            "  training (BS.1534-3): the screen(s) of the first {} clip(s) shown first, rated, \
             not analysed",
            m.training_screens
        )?;
    }
    for (reference, tests) in &screens {
        let anchor = m
            .anchors
            .iter()
            .find(|a| a.reference == *reference)
            .map_or("?", |a| a.stimulus.as_str());
        writeln!(
            text,
            "  screen {reference:?}: {} test conditions + hidden reference + anchor {anchor:?}",
            tests.len()
        )?;
    }
    writeln!(
        text,
        "  post-screening (BS.1534-3): excluded when the hidden reference is rated below {} on \
         more than {}% of the screens; the anchor rated above {} on more than {}%: {}",
        m.reference_below,
        100.0 * m.max_fraction,
        m.anchor_above,
        100.0 * m.max_fraction,
        match m.anchor_rule {
            AnchorRule::Report => "reported, kept",
            AnchorRule::Exclude => "excluded",
        }
    )?;
    let shown = screens.len() + m.training_screens as usize;
    let est_min = shown as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
    writeln!(
        text,
        "  presentation time: {est_min:.1} min without answers"
    )
}

/// A staircase over the manifest's stimuli: each track's clip and levels.
fn describe_staircase(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use std::fmt::Write as _;
    let Some(sc) = &study.staircase else {
        return Ok(());
    };
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
    Ok(())
}

/// A live staircase: its codec, clips and tracks, and every clip encoded once at the first
/// start level (proves the codec takes the settings and shows what a trial will look like).
fn describe_live(
    text: &mut String,
    study: &StudyDefinition,
    stimuli: &LiveStimuli,
) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let (Some(sc), Some(live)) = (
        &study.staircase,
        study.staircase.as_ref().and_then(|s| s.live.as_ref()),
    ) else {
        return Ok(());
    };
    let names: Vec<&str> = live.clips.iter().map(|c| c.clip.as_str()).collect();
    writeln!(
        text,
        "  live staircase: codec {} encodes {} = level on the fly; clips {}: {}",
        stimuli.codec_name(),
        sc.param,
        match live.order {
            protocols::ClipOrder::InTurn => "in turn",
            protocols::ClipOrder::Shuffled => "in turn, order shuffled per subject",
        },
        names.join(", ")
    )?;
    for t in &sc.tracks {
        let lo = t.settings.min.unwrap_or(f64::NEG_INFINITY);
        let hi = t.settings.max.unwrap_or(f64::INFINITY);
        match &sc.quest {
            // A Bayesian track has no start: it picks each level from its posterior.
            Some(q) => writeln!(
                text,
                "  {} track {:?}: {} levels in [{lo}, {hi}], each chosen from the posterior",
                match q.method {
                    protocols::QuestMethod::QuestPlus => "QUEST+",
                    protocols::QuestMethod::Psi => "Psi",
                },
                t.name,
                q.levels.len()
            )?,
            None => writeln!(
                text,
                "  staircase {:?}: start {} in [{lo}, {hi}]",
                t.name, t.settings.start
            )?,
        }
    }
    let Some(t) = sc.tracks.first() else {
        return Ok(());
    };
    let level = t.settings.start;
    for (i, (clip, _)) in stimuli.clips().enumerate() {
        let s = stimuli.at_level(i, level)?;
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
    Ok(())
}

/// `study simulate`: runs `--subjects` complete simulated sessions into a results directory.
///
/// # Errors
/// Study file problems, an existing output without `--resume`, a resume whose logged trials
/// the study no longer regenerates, I/O errors.
pub fn simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    preflight(&StudyFile::load(&args.study)?)?;
    let options = SimulateOptions {
        study: args.study.clone(),
        subjects: args.subjects,
        seed: args.seed,
        output: args.store.destination(args.output.as_deref(), || None)?,
        trial_delay: Duration::from_millis(args.trial_delay_ms),
        resume: args.resume,
        patience: Duration::from_secs(args.patience_s),
    };
    match &args.subject {
        Some(id) => lab::simulate::simulate_subject(&options, id, &mut |line| eprintln!("{line}"))?,
        None => lab::simulate::simulate(&options, &mut |line| eprintln!("{line}"))?,
    }
    Ok(())
}
