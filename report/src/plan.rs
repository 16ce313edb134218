//! `study plan`: how many subjects a study needs, from stated effect sizes or from a pilot's
//! results, and the "Sample size" section a pilot's report prints.
//!
//! The arithmetic is [`analysis::power`]'s (checked against statsmodels and SciPy): the n of
//! a paired t-test on per-subject MOS / DMOS differences for a power, and the n that keeps a
//! mean's Student-t interval (a threshold's, a difference's) within a half-width. A pilot is
//! read as `study report` reads results (its `sessions` module): each codec comparison's
//! observed mean difference and SD of the paired differences, each staircase track's SD of
//! the per-subject thresholds.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use analysis::power::{self, MAX_SUBJECTS, Sides};
use analysis::report::Report;
use analysis::study::{ReportOptions, StudyAnalysis, StudyData, analyze};
use analysis::tables::{ComparisonRow, Table, UNDEFINED, fmt_opt};
use analysis::{Alternative, Confidence};
use anyhow::{Result, bail};
use lab::results_dir::Destination;

/// Effect sizes stated by the user (`study plan`'s flags).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Stated {
    /// Mean difference to detect, in score units (`--difference`, with `sd`).
    pub difference: Option<f64>,
    /// SD of the paired differences, or of the thresholds for `ci_width` (`--sd`).
    pub sd: Option<f64>,
    /// Standardised effect, Cohen's d_z (`--dz`).
    pub dz: Option<f64>,
    /// Largest half-width of a mean's confidence interval (`--ci-width`).
    pub ci_width: Option<f64>,
}

impl Stated {
    /// The stated values, in the order of `study plan`'s flags.
    pub fn new(
        difference: Option<f64>,
        sd: Option<f64>,
        dz: Option<f64>,
        ci_width: Option<f64>,
    ) -> Self {
        Stated {
            difference,
            sd,
            dz,
            ci_width,
        }
    }

    fn is_empty(&self) -> bool {
        *self == Stated::default()
    }
}

/// What a plan must reach.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    /// Significance level of the test; intervals are at 1 − α.
    pub alpha: f64,
    /// Power to reach.
    pub power: f64,
    /// One- or two-sided test.
    pub sides: Sides,
}

impl Goal {
    /// α, power and whether the test is two-sided (`--alpha`, `--power`, not `--one-sided`).
    pub fn new(alpha: f64, power: f64, two_sided: bool) -> Self {
        Goal {
            alpha,
            power,
            sides: if two_sided { Sides::Two } else { Sides::One },
        }
    }

    /// The level of the intervals, 1 − α.
    fn confidence(&self) -> Result<Confidence> {
        Ok(Confidence::new(1.0 - self.alpha)?)
    }

    /// Refuses values out of range, naming the flag.
    fn check(&self) -> Result<()> {
        let Goal { alpha, power, .. } = *self;
        if !(alpha > 0.0 && alpha < 1.0) {
            bail!("--alpha {alpha}: must lie between 0 and 1");
        }
        if !(power > alpha && power < 1.0) {
            bail!("--power {power}: must lie between --alpha ({alpha}) and 1");
        }
        Ok(())
    }
}

/// `x` to four significant digits (thresholds can be 0.0009 or 90), `n/a` if undefined.
fn sig(x: Option<f64>) -> String {
    match x {
        Some(v) if v.is_finite() && v != 0.0 => {
            let decimals = (3 - v.abs().log10().floor() as i32).max(0) as usize;
            format!("{v:.decimals$}")
        }
        other => fmt_opt(other, 0),
    }
}

/// A table cell of whole subjects, or "> 100000" where the plan found none.
fn subjects_cell(n: Option<usize>) -> String {
    n.map_or_else(|| format!("> {MAX_SUBJECTS}"), |n| n.to_string())
}

/// `study plan`'s answer for stated effect sizes.
fn stated_plan(stated: &Stated, goal: &Goal, out: &mut String) -> Result<()> {
    let positive = |flag: &str, v: Option<f64>| -> Result<()> {
        match v {
            Some(x) if !(x > 0.0 && x.is_finite()) => bail!("{flag} {x}: must be > 0"),
            _ => Ok(()),
        }
    };
    positive("--sd", stated.sd)?;
    positive("--ci-width", stated.ci_width)?;
    if let Some(d) = stated.difference.or(stated.dz)
        && !(d != 0.0 && d.is_finite())
    {
        let flag = if stated.dz.is_some() {
            "--dz"
        } else {
            "--difference"
        };
        bail!("{flag} {d}: the effect to detect must be non-zero");
    }
    let effect = match (stated.difference, stated.sd, stated.dz) {
        (Some(_), _, Some(_)) => bail!("--dz and --difference both given: state the effect once"),
        (Some(_), None, None) => {
            bail!("--difference needs --sd (the SD of the paired differences), or give --dz")
        }
        (Some(d), Some(sd), None) => Some((d.abs() / sd, format!("difference {d} / SD {sd}"))),
        (None, _, Some(dz)) => Some((dz.abs(), "stated".to_owned())),
        (None, _, None) => None,
    };
    let confidence = goal.confidence()?;
    if let Some((dz, from)) = &effect {
        let dz = *dz;
        let _ = writeln!(
            out,
            "Paired t-test, {}, α = {}, power {}: d_z = {dz:.4} ({from}).",
            goal.sides.label(),
            goal.alpha,
            goal.power
        );
        match power::paired_sample_size(dz, goal.alpha, goal.power, goal.sides) {
            Ok(s) => {
                let _ = writeln!(
                    out,
                    "  {} subjects (power {:.3}; exact n {:.2}, as statsmodels' solve_power).",
                    s.n_subjects, s.achieved_power, s.n_exact
                );
            }
            Err(_) => bail!("the effect d_z = {dz} needs more than {MAX_SUBJECTS} subjects"),
        }
    }
    match (stated.ci_width, stated.sd) {
        (Some(w), Some(sd)) => match power::ci_sample_size(sd, w, confidence) {
            Ok(s) => {
                let _ = writeln!(
                    out,
                    "{:.0} % CI of a mean (a threshold, a difference) with SD {sd}, half-width ≤ {w}: {} subjects (half-width {}; exact n {:.2}).",
                    confidence.percent(),
                    s.n_subjects,
                    sig(Some(s.half_width)),
                    s.n_exact
                );
            }
            Err(_) => bail!("--ci-width {w}: needs more than {MAX_SUBJECTS} subjects"),
        },
        (Some(_), None) => bail!(
            "--ci-width needs --sd (the SD of the thresholds or differences), or a pilot folder"
        ),
        (None, Some(_)) if effect.is_none() => bail!("--sd needs --difference or --ci-width"),
        _ => {}
    }
    Ok(())
}

/// The sample-size tables of a pilot's analysis: one row per codec comparison and per
/// staircase track. `sides`: the test's sides per comparison; `ci_width`: the half-width the
/// interval rows aim at (`None`: the threshold rows aim at ±10 % of their mean, and the
/// comparison rows have no interval column).
fn pilot_tables(
    analysis: &StudyAnalysis,
    data: &StudyData,
    options: &ReportOptions,
    goal: &Goal,
    sides: &dyn Fn(&ComparisonRow) -> Sides,
    ci_width: Option<f64>,
) -> Result<Vec<Table>> {
    let confidence = goal.confidence()?;
    let mut tables = Vec::new();
    if !analysis.comparisons.is_empty() {
        tables.push(comparison_table(
            analysis, goal, sides, ci_width, confidence,
        ));
    }
    if let Some(t) = threshold_table(data, options, ci_width, confidence) {
        tables.push(t);
    }
    Ok(tables)
}

/// Subjects per codec comparison.
fn comparison_table(
    analysis: &StudyAnalysis,
    goal: &Goal,
    sides: &dyn Fn(&ComparisonRow) -> Sides,
    ci_width: Option<f64>,
    confidence: Confidence,
) -> Table {
    let n_power = format!("n for power {}", goal.power);
    let mut columns: Vec<String> = [
        "Clip",
        "CR",
        "A vs B",
        "Pilot n",
        "Mean diff.",
        "SD of diff.",
        "d_z",
        "Test",
        "Pilot power",
        &n_power,
    ]
    .map(str::to_owned)
    .to_vec();
    if let Some(w) = ci_width {
        columns.push(format!("n for CI ±{w}"));
    }
    let rows = analysis
        .comparisons
        .iter()
        .map(|row| {
            let sides = sides(row);
            let mut cells = vec![
                row.clip.clone(),
                fmt_opt(row.compression_ratio, 0),
                format!("{} vs {}", row.first.0, row.second.0),
            ];
            let Ok(t) = &row.test else {
                cells.push(UNDEFINED.to_owned());
                cells.resize(columns.len(), "n/a (test undefined)".to_owned());
                return cells;
            };
            let n = t.df + 1.0;
            let sd = (t.effect_size != 0.0).then(|| t.mean_difference / t.effect_size);
            // A one-sided test against a baseline looks in its own direction ("less" flips
            // the effect); one asked of a two-sided comparison, in the direction observed.
            let dz = match (sides, row.alternative) {
                (Sides::One, Alternative::Less) => -t.effect_size,
                (Sides::One, Alternative::Greater) => t.effect_size,
                _ => t.effect_size.abs(),
            };
            cells.extend([
                format!("{n:.0}"),
                fmt_opt(Some(t.mean_difference), 3),
                fmt_opt(sd, 3),
                fmt_opt(Some(t.effect_size), 3),
                sides.label().to_owned(),
                fmt_opt(power::paired_power(dz, n, goal.alpha, sides).ok(), 3),
                if dz > 0.0 {
                    subjects_cell(
                        power::paired_sample_size(dz, goal.alpha, goal.power, sides)
                            .ok()
                            .map(|s| s.n_subjects),
                    )
                } else {
                    "n/a (no effect in the tested direction)".to_owned()
                },
            ]);
            if let Some(w) = ci_width {
                cells.push(match sd {
                    Some(sd) => subjects_cell(
                        power::ci_sample_size(sd.abs(), w, confidence)
                            .ok()
                            .map(|s| s.n_subjects),
                    ),
                    None => UNDEFINED.to_owned(),
                });
            }
            cells
        })
        .collect();
    Table {
        name: "sample_size_comparisons".to_owned(),
        caption: format!(
            "Subjects for each comparison's observed effect (paired t, α = {})",
            goal.alpha
        ),
        columns,
        rows,
    }
}

/// Subjects per staircase track for a threshold CI of half-width `ci_width` (else ±10 % of
/// the track's mean threshold); `None` without up-down tracks.
fn threshold_table(
    data: &StudyData,
    options: &ReportOptions,
    ci_width: Option<f64>,
    confidence: Confidence,
) -> Option<Table> {
    // Per track label: each subject's mean threshold over its converged tracks.
    let mut by_label: BTreeMap<&str, BTreeMap<u32, Vec<f64>>> = BTreeMap::new();
    for t in data.staircases.iter().filter(|t| !t.bayesian) {
        if let Some(x) = t.threshold(options.last_reversals) {
            by_label
                .entry(&t.label)
                .or_default()
                .entry(t.subject)
                .or_default()
                .push(x);
        }
    }
    if by_label.is_empty() {
        return None;
    }
    // Several tracks: also each subject's mean over all of them, the threshold the report's
    // summary cites.
    if by_label.len() > 1 {
        let mut all: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
        for subjects in by_label.values() {
            for (s, v) in subjects {
                all.entry(*s).or_default().extend(v);
            }
        }
        by_label.insert("all tracks", all);
    }
    let rows = by_label
        .iter()
        .map(|(label, subjects)| {
            let x: Vec<f64> = subjects
                .values()
                .map(|v| v.iter().sum::<f64>() / v.len() as f64)
                .collect();
            let n = x.len() as f64;
            let mean = x.iter().sum::<f64>() / n;
            let sd = (x.len() >= 2)
                .then(|| (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt());
            let w = ci_width.unwrap_or(0.1 * mean.abs());
            let needed = match sd {
                Some(sd) if sd > 0.0 && w > 0.0 => subjects_cell(
                    power::ci_sample_size(sd, w, confidence)
                        .ok()
                        .map(|s| s.n_subjects),
                ),
                Some(_) => "n/a (no spread)".to_owned(),
                None => "n/a (one subject)".to_owned(),
            };
            vec![
                (*label).to_owned(),
                x.len().to_string(),
                sig(Some(mean)),
                sig(sd),
                sig(sd.and_then(|s| power::ci_half_width(s, n, confidence).ok())),
                sig(Some(w)),
                needed,
            ]
        })
        .collect();
    let conf = format!("{:.0} %", confidence.percent());
    Some(Table {
        name: "sample_size_thresholds".to_owned(),
        caption: format!(
            "Subjects for a {conf} CI of each track's mean threshold within ±{} (last {} reversals)",
            if ci_width.is_some() {
                "the stated half-width"
            } else {
                "10 % of the pilot's mean"
            },
            options.last_reversals
        ),
        columns: [
            "Track",
            "Pilot n",
            "Mean threshold",
            "SD",
            &format!("Pilot CI ± ({conf})"),
            "Target ±",
            "n needed",
        ]
        .map(str::to_owned)
        .to_vec(),
        rows,
    })
}

/// The "Sample size" section of a pilot's report: the tables `study plan RESULTS` prints
/// with its defaults (power 0.8, α = 1 − the report's confidence, each comparison with the
/// sides it was tested with). None when the study has no paired comparisons or staircases.
pub(crate) fn section(
    report: &mut Report,
    analysis: &StudyAnalysis,
    data: &StudyData,
    options: &ReportOptions,
) {
    // 1 − 0.95 is 0.050000000000000044 in binary: α as the level was written.
    let alpha = (options.confidence.alpha() * 1e9).round() / 1e9;
    let goal = Goal::new(alpha, 0.8, true);
    let sides = |row: &ComparisonRow| match row.alternative {
        Alternative::TwoSided => Sides::Two,
        _ => Sides::One,
    };
    let Ok(tables) = pilot_tables(analysis, data, options, &goal, &sides, None) else {
        return;
    };
    if tables.is_empty() {
        return;
    }
    let mut aims = Vec::new();
    if !analysis.comparisons.is_empty() {
        aims.push(format!("to detect each observed effect with power 0.8 at α = {} (paired t on the per-subject means, with the sides tested above)", goal.alpha));
    }
    if tables.len() > aims.len() {
        aims.push("for each track's threshold CI within ±10 % of its mean".to_owned());
    }
    let s = report.section("Sample size");
    s.text(format!(
        "Read as a pilot: the subjects a study needs {} (analysis::power, checked against statsmodels and SciPy). `study plan RESULTS` prints the same, and takes other goals (--power, --alpha, --ci-width, --one-sided).",
        aims.join(", and ")
    ));
    for t in tables {
        s.table(t);
    }
}

/// `study plan`'s answer: for the stated effect sizes, and for each comparison and staircase
/// track of the pilot results folder `pilot` (read and checked as `study report` does), the
/// subjects `goal` needs. Errors name the flag or file and the reason, once.
///
/// # Errors
/// A flag out of range or missing its partner, nothing to plan, or a pilot that cannot be
/// read (named as `study report` names it).
pub fn plan(pilot: Option<&Path>, stated: &Stated, goal: &Goal) -> Result<String> {
    goal.check()?;
    if pilot.is_none() && stated.is_empty() {
        bail!(
            "nothing to plan: give --difference with --sd, --dz, --ci-width with --sd, or a pilot results folder"
        );
    }
    let mut out = String::new();
    // A pilot alone takes --ci-width for its own rows; anything else is a stated plan.
    let own = Stated {
        ci_width: None,
        ..*stated
    };
    if !own.is_empty() || pilot.is_none() {
        stated_plan(stated, goal, &mut out)?;
    }
    if let Some(folder) = pilot {
        pilot_plan(folder, stated.ci_width, goal, &mut out)?;
    }
    Ok(out)
}

/// The pilot part of [`plan`].
fn pilot_plan(folder: &Path, ci_width: Option<f64>, goal: &Goal, out: &mut String) -> Result<()> {
    let request = crate::Request {
        results: Destination::Folder(folder.to_path_buf()),
        study: None,
        output: folder.join("unused"),
        mode: files::Mode::New,
        allow_incomplete: false,
        png: false,
        settings: crate::Settings {
            bootstrap: 2,
            ..crate::Settings::default()
        },
    };
    let (source, sessions, study_file) = crate::sessions::open(&request, &mut |_| {})?;
    let options = crate::report_options(&request.settings, &study_file.definition)?;
    let logs = crate::sessions::read_logs(
        &request,
        &source,
        &study_file,
        &sessions,
        options.fit.shape == analysis::psychometric::Shape::Weibull,
        &mut |_| {},
        &|_, _| {},
    )?;
    let data = &logs.converted.data;
    // The comparisons need the ratings only: the adaptive fits (seconds) are left out.
    let ratings_only = StudyData {
        staircases: Vec::new(),
        two_afc: Vec::new(),
        ..data.clone()
    };
    let analysis = analyze(&ratings_only, &options)?;
    let sides = |_: &ComparisonRow| goal.sides;
    let tables = pilot_tables(&analysis, data, &options, goal, &sides, ci_width)?;
    let _ = writeln!(
        out,
        "Pilot {} ({} sessions):",
        folder.display(),
        sessions.len()
    );
    if tables.is_empty() {
        let _ = writeln!(
            out,
            "no paired codec comparisons or staircase thresholds in it: nothing to plan from."
        );
    }
    for t in tables {
        let _ = write!(out, "\n{}", t.to_markdown());
    }
    Ok(())
}
