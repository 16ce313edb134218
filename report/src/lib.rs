//! `study report`'s pipeline as one function, [`report`]: the sessions of a results folder or
//! of a database run, read and checked before any statistic (damaged logs refused, naming
//! the row), analyzed, and written as `report.md`, `report.html`, tables (CSV, Markdown,
//! LaTeX), figures (SVG, PNG) and the exports (`ratings.csv`, `trials_tidy.csv` with its data
//! dictionary `datapackage.json`, `sureal_dataset.py`). The
//! command line's options arrive as a plain [`Request`], so that any front end can ask for a
//! report.

#[cfg(feature = "postgres")]
mod database;
pub mod plan;
mod sections;
mod sessions;
mod tidy;

use std::path::{Path, PathBuf};

use analysis::psychometric::{BootstrapOptions, FitOptions, Lapse, Shape};
use analysis::study::{ReportOptions, analyze};
use analysis::{CiMethod, Confidence, export};
use anyhow::{Result, bail};
use codecs::codec::keys;
use lab::results_dir::Destination;
use protocols::StudyDefinition;

/// What to report and how: the analysis's settings, as `study report` takes them.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Codec every other codec is tested against, one-tailed; `None`: every pair two-tailed.
    pub baseline: Option<String>,
    /// Confidence level of every interval.
    pub confidence: Confidence,
    /// Interval used in tables and findings.
    pub ci: CiMethod,
    /// MOS a rate must keep (lower CI bound) to count as unnoticed; `None`: 87.5 % of the
    /// way up the study's scale (thesis §3.3's 4.5 on 1-5).
    pub mos_limit: Option<f64>,
    /// DMOS a rate must stay under (upper CI bound); `None`: 5 % of the scale's range
    /// (thesis §6.4.3's 0.2 on 1-5).
    pub dmos_limit: Option<f64>,
    /// Every rating one observation (n = ratings) instead of each subject's mean over its
    /// hidden repeats (n = subjects).
    pub pool_repeats: bool,
    /// Share of dropped frames (percent) above which the display section flags a session.
    pub drop_limit: f64,
    /// Reversals averaged per staircase; `None`: the study's `threshold_reversals`, else 3.
    pub reversals: Option<usize>,
    /// Percent correct (fraction) at which the psychometric threshold is read.
    pub percent_correct: f64,
    /// Psychometric function family.
    pub shape: Shape,
    /// Upper bound of the fitted lapse rate.
    pub lapse_max: f64,
    /// Bootstrap replicates of the threshold CI.
    pub bootstrap: usize,
    /// Seed of the bootstrap RNG.
    pub seed: u64,
    /// Also tabulate MOS of per-subject z-scores.
    pub zscore: bool,
}

impl Default for Settings {
    /// `study report`'s defaults.
    fn default() -> Self {
        Settings {
            baseline: None,
            confidence: Confidence::default(),
            ci: CiMethod::StudentT,
            mos_limit: None,
            dmos_limit: None,
            pool_repeats: false,
            drop_limit: 1.0,
            reversals: None,
            percent_correct: 0.75,
            shape: Shape::Weibull,
            lapse_max: 0.06,
            bootstrap: 1000,
            seed: 0x5EED,
            zscore: false,
        }
    }
}

/// A report to make.
#[derive(Debug)]
pub struct Request {
    /// The sessions: a results folder, or a database run.
    pub results: Destination,
    /// The study file (`None`: the copy the results keep).
    pub study: Option<PathBuf>,
    /// The output folder.
    pub output: PathBuf,
    /// Whether files of the output folder may be replaced (`--force`).
    pub mode: files::Mode,
    /// Report sessions with trials missing at the end (warned about and listed) instead of
    /// refusing them; damaged logs are refused either way.
    pub allow_incomplete: bool,
    /// Write PNG figures beside the SVG ones.
    pub png: bool,
    /// The analysis's settings.
    pub settings: Settings,
}

/// What a report wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Summary {
    /// The output folder.
    pub output: PathBuf,
    /// Files written.
    pub files: usize,
    /// MOS-style ratings analyzed.
    pub ratings: usize,
    /// DSCQS pairs.
    pub dscqs: usize,
    /// Staircases.
    pub staircases: usize,
    /// 2AFC trials.
    pub two_afc: usize,
    /// Pair comparison choices.
    pub pair_choices: usize,
    /// Comparison ratings (CCR).
    pub comparison_ratings: usize,
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let counted = |n: usize, what: &str| match n {
            0 => String::new(),
            n => format!(", {n} {what}"),
        };
        let choices = counted(self.pair_choices, "pair comparison choices")
            + &counted(self.comparison_ratings, "comparison ratings");
        write!(
            f,
            "{}: {} files ({} ratings, {} DSCQS pairs, {} staircases, {} 2AFC trials{choices}); open {}",
            self.output.display(),
            self.files,
            self.ratings,
            self.dscqs,
            self.staircases,
            self.two_afc,
            self.output.join("report.html").display()
        )
    }
}

/// The staircase level's name in tables and figures: the thesis's `t_L`, a target ratio, or
/// the parameter as the study names it (live staircases add the codec).
fn level_label(study: &StudyDefinition) -> String {
    let Some(sc) = &study.staircase else {
        return "Level".to_owned();
    };
    let name = match sc.param.as_str() {
        keys::T_L => "t_L".to_owned(),
        keys::CR => "target CR".to_owned(),
        p => p.to_owned(),
    };
    if sc.live.is_some() {
        format!("{name} ({})", sc.codec)
    } else {
        name
    }
}

/// Reversals averaged per staircase: the setting, else the study's `threshold_reversals`
/// (one setting shared by every track), else 3.
fn last_reversals(settings: &Settings, study: &StudyDefinition) -> usize {
    settings.reversals.unwrap_or_else(|| {
        study
            .staircase
            .as_ref()
            .and_then(|sc| sc.tracks.first())
            .map_or(3, |t| t.settings.threshold_reversals as usize)
    })
}

/// The MOS and DMOS limits, or their defaults from the study's scale (thesis §3.3's 4.5 and
/// §6.4.3's 0.2 on a 1-5 scale, scaled to the study's); a limit outside the scale is refused,
/// naming the option.
fn limits(settings: &Settings, study: &StudyDefinition) -> Result<(f64, f64)> {
    let (lo, hi) = (study.scale.min, study.scale.max);
    let range = hi - lo;
    let mos = settings.mos_limit.unwrap_or(lo + 0.875 * range);
    let dmos = settings.dmos_limit.unwrap_or(0.05 * range);
    if !(lo..=hi).contains(&mos) {
        bail!("--mos-limit {mos}: outside the study's scale {lo}-{hi}");
    }
    if !(dmos > -range && dmos <= range) {
        bail!(
            "--dmos-limit {dmos}: a difference on the study's scale {lo}-{hi} lies within ±{range}"
        );
    }
    Ok((mos, dmos))
}

/// The analysis options `settings` ask for.
fn report_options(settings: &Settings, study: &StudyDefinition) -> Result<ReportOptions> {
    let (mos_limit, dmos_limit) = limits(settings, study)?;
    Ok(ReportOptions {
        confidence: settings.confidence,
        ci_method: settings.ci,
        mos_limit,
        dmos_limit,
        baseline_codec: settings.baseline.clone(),
        last_reversals: last_reversals(settings, study),
        percent_correct: settings.percent_correct,
        fit: FitOptions {
            shape: settings.shape,
            guess_rate: 0.5,
            lapse: Lapse::Free {
                max: settings.lapse_max,
            },
        },
        bootstrap: BootstrapOptions {
            replicates: settings.bootstrap,
            confidence: settings.confidence,
            seed: settings.seed,
        },
        zscore: settings.zscore,
        figures: true,
        level_label: level_label(study),
        pool_repeats: settings.pool_repeats,
        scale: Some((study.scale.min, study.scale.max)),
    })
}

/// Files the exports write beside the report: `ratings.csv`, `trials_tidy.csv`,
/// `datapackage.json` and `sureal_dataset.py`.
const EXPORTS: usize = 4;

/// Writes `path` whole or not at all ([`files::AtomicFile`]) from `fill`, which streams it.
fn write_streamed(
    path: &Path,
    mode: files::Mode,
    fill: impl FnOnce(&mut files::AtomicFile) -> std::io::Result<()>,
) -> Result<()> {
    let mut file = files::AtomicFile::create(path, mode)?;
    fill(&mut file).map_err(|source| files::Error::Io {
        path: path.to_path_buf(),
        op: "write",
        source,
    })?;
    file.commit()?;
    Ok(())
}

/// Writes the exports beside the report: `trials_tidy.csv` from the spooled rows, the last
/// column whom `analysis`'s BT.500 screening rejected (empty where none ran), its
/// `datapackage.json`, `ratings.csv` and `sureal_dataset.py`.
fn write_exports(
    request: &Request,
    study: &StudyDefinition,
    name: &str,
    data: &analysis::study::StudyData,
    tidy: tidy::Spool,
    analysis: &analysis::study::StudyAnalysis,
) -> Result<()> {
    let (output, mode) = (&request.output, request.mode);
    // Whom BT.500 screening rejected, by id (the tidy export's last column).
    let screened: Option<std::collections::BTreeSet<String>> =
        analysis.screening.as_ref().map(|s| {
            s.rejected()
                .into_iter()
                .map(|i| {
                    data.subjects
                        .get(i as usize)
                        .cloned()
                        .unwrap_or_else(|| i.to_string())
                })
                .collect()
        });
    write_streamed(&output.join(tidy::TIDY_FILE), mode, |out| {
        tidy.write(out, study, screened.as_ref())
    })?;
    files::write(
        &output.join(tidy::PACKAGE_FILE),
        tidy::data_package(study),
        mode,
    )?;
    write_streamed(&output.join("ratings.csv"), mode, |out| {
        export::write_tidy_csv(out, &data.subjects, &data.ratings, &data.conditions)
    })?;
    write_streamed(&output.join("sureal_dataset.py"), mode, |out| {
        export::SurealDataset {
            name,
            subjects: &data.subjects,
            ratings: &data.ratings,
            dscqs: &data.dscqs,
            conditions: &data.conditions,
            ref_score: study.scale.max,
        }
        .write_python(out)
    })
}

/// Makes the report `request` asks for; `warn` hears each warning (a session with trials
/// missing, a display that dropped frames) as it is found.
///
/// # Errors
/// Unreadable or malformed results (named by file, line and column), damaged logs, sessions
/// with trials missing without `allow_incomplete`, a study file that does not load, settings
/// outside the study's scale, or an output that cannot be written.
pub fn report(request: &Request, warn: &mut dyn FnMut(&str)) -> Result<Summary> {
    report_with_progress(request, warn, &|_, _| {})
}

/// As [`report`]; `progress(read, total)` is called (from the reader threads, in session
/// order) as each session has been read and checked, before the analysis and the writing.
///
/// # Errors
/// As [`report`].
pub fn report_with_progress(
    request: &Request,
    warn: &mut dyn FnMut(&str),
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Summary> {
    let (source, sessions, study_file) = sessions::open(request, warn)?;
    let run = &source.run;
    let options = report_options(&request.settings, &study_file.definition)?;
    let sessions::Logs {
        converted,
        incomplete,
        displays,
        exclusions,
        tidy,
    } = sessions::read_logs(
        request,
        &source,
        &study_file,
        &sessions,
        options.fit.shape == Shape::Weibull,
        warn,
        progress,
    )?;
    let study = &study_file.definition;
    let (output, mode) = (&request.output, request.mode);
    files::prepare_dir(output, mode)?;
    let analysis = analyze(&converted.data, &options)?;
    let mushra = sections::mushra_analysis(study, &converted, options.confidence)?;
    let data = &converted.data;
    // The exports (10⁶ rows each at a million ratings) are written on a second thread while
    // this one lays out and writes the report.
    let (written, exported) = std::thread::scope(|scope| {
        let exports =
            scope.spawn(|| write_exports(request, study, &run.study, data, tidy, &analysis));
        let title = format!(
            "Study {} ({} protocol, {} sessions)",
            run.study,
            converted.protocol,
            sessions.len()
        );
        let mut report = analysis.to_report(data, &options, &title);
        plan::section(&mut report, &analysis, data, &options);
        if let Some(m) = &mushra {
            m.add_to(&mut report, &converted);
        }
        analysis::method::method_section(
            &mut report,
            study,
            analysis::method::Observers {
                sessions: displays.len(),
                subjects: data.subjects.len(),
                excluded_sessions: exclusions.iter().filter(|e| e.excluded).count(),
                rejected: analysis.screening.as_ref().map(|s| s.rejected().len()),
            },
            &displays,
        );
        sections::incomplete(&mut report, &incomplete);
        sections::display(&mut report, &displays, request.settings.drop_limit, warn);
        sections::exclusions(&mut report, &exclusions, &study.crowdsourcing);
        let names = report.section("Subjects and stimuli");
        // A staircase study has no condition ids: its tracks are named instead (issue 39: it
        // printed "Condition ids: .").
        let conditions = if converted.stimuli.is_empty() {
            let tracks: std::collections::BTreeSet<&str> =
                data.staircases.iter().map(|t| t.label.as_str()).collect();
            if tracks.is_empty() {
                String::new()
            } else {
                let tracks: Vec<&str> = tracks.into_iter().collect();
                format!(" Staircase tracks: {}.", tracks.join(", "))
            }
        } else {
            let ids: Vec<String> = converted
                .stimuli
                .iter()
                .enumerate()
                .map(|(i, s)| format!("{i} = {s}"))
                .collect();
            format!(" Condition ids: {}.", ids.join(", "))
        };
        let subjects: Vec<String> = data
            .subjects
            .iter()
            .map(|s| analysis::tables::md_escape(s))
            .collect();
        names.text(format!(
            "Subjects ({}): {}.{conditions}",
            subjects.len(),
            subjects.join(", "),
        ));
        let written = report.write(output, request.png, mode);
        let exported = exports
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the export writer thread panicked")));
        (written, exported)
    });
    let written = written?;
    exported?;
    Ok(Summary {
        output: output.clone(),
        files: written.files.len() + EXPORTS,
        ratings: converted.data.ratings.len(),
        dscqs: converted.data.dscqs.len(),
        staircases: converted.data.staircases.len(),
        two_afc: converted.data.two_afc.len(),
        pair_choices: converted.data.pair_choices.len(),
        comparison_ratings: converted.data.comparison_ratings.len(),
    })
}
