//! The whole analysis of a study, as `study report` runs it: from plain trial data to every
//! statistic, then to a [`Report`] of tables and figures.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::Serialize;

use crate::confidence::Confidence;
use crate::descriptive::{CiMethod, ConditionStats, Rating, condition_stats};
use crate::dmos::{DscqsPair, acr_hr_dmos, dscqs_dmos, zscore_by_subject};
use crate::error::AnalysisError;
use crate::findings::{ConditionInfo, Limit, RateFinding, rate_findings};
use crate::jnd::{EncodedLevel, JndAnalysis, jnd_analysis};
use crate::panel::Panel;
use crate::plots::{Figure, RateSeries};
use crate::psychometric::{
    BootstrapCi, BootstrapOptions, FitOptions, GroupedTrials, PsychometricFit, TwoAfcTrial,
    bootstrap_threshold,
};
use crate::report::Report;
use crate::screening::{
    RepeatConsistency, ScreeningReport, repeats_of_panel, screening_of_panel, without_subjects,
};
use crate::staircase::{StaircaseTrack, ThresholdSummary, staircase_thresholds};
use crate::tables::{self, ComparisonRow, fmt_opt};
use crate::ttest::{Alternative, holm, paired};

/// Everything a study logged, in the analysis crate's plain types.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StudyData {
    /// What each condition id is.
    pub conditions: Vec<ConditionInfo>,
    /// Opinion scores (ACR / side-by-side MOS studies, thesis ch. 3).
    pub ratings: Vec<Rating>,
    /// Test condition → hidden reference condition, for ACR-HR DMOS (P.910); may be empty.
    pub reference_of: HashMap<u32, u32>,
    /// DSCQS pairs (thesis ch. 6).
    pub dscqs: Vec<DscqsPair>,
    /// Staircase tracks (thesis ch. 5).
    pub staircases: Vec<StaircaseTrack>,
    /// All 2AFC trials, for the psychometric fit.
    pub two_afc: Vec<TwoAfcTrial>,
    /// Compression ratio (and error) reached at each staircase level on each clip, one entry
    /// per trial: logged by a live staircase, or the manifest's for prepared stimuli.
    pub encoded_levels: Vec<EncodedLevel>,
}

/// Options of the analysis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReportOptions {
    /// Confidence level of all intervals (the bootstrap's is set in [`Self::bootstrap`]).
    pub confidence: Confidence,
    /// Which interval decides findings and is printed in tables.
    pub ci_method: CiMethod,
    /// MOS limit for rate findings (4.5 in thesis §3.3).
    pub mos_limit: f64,
    /// DMOS limit for rate findings (0.2 in thesis §6.4.3).
    pub dmos_limit: f64,
    /// Codec every other codec is compared against with a one-tailed test ("A scores higher
    /// than the baseline"); `None` compares all pairs two-tailed. A method label
    /// (`wavelet-standard/qp9-window128`) names one variant; a codec name alone names the
    /// codec's one condition at a clip and ratio (none when it has several variants there).
    pub baseline_codec: Option<String>,
    /// Reversals averaged per staircase (3 in thesis §5.4).
    pub last_reversals: usize,
    /// Percent correct (fraction) at which the psychometric threshold is read.
    pub percent_correct: f64,
    /// Psychometric fit options.
    pub fit: FitOptions,
    /// Bootstrap options.
    pub bootstrap: BootstrapOptions,
    /// Also compute MOS on per-subject z-scores.
    pub zscore: bool,
    /// Draw figures.
    pub figures: bool,
    /// Name of the staircase level in tables and figures (e.g. `t_L`, `target CR`).
    pub level_label: String,
}

impl Default for ReportOptions {
    fn default() -> Self {
        Self {
            confidence: Confidence::default(),
            ci_method: CiMethod::StudentT,
            mos_limit: 4.5,
            dmos_limit: 0.2,
            baseline_codec: None,
            last_reversals: 3,
            percent_correct: 0.75,
            fit: FitOptions::default(),
            bootstrap: BootstrapOptions::default(),
            zscore: false,
            figures: true,
            level_label: "Level".to_owned(),
        }
    }
}

/// Every statistic of a study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StudyAnalysis {
    /// MOS per condition, all observers.
    pub mos: Vec<ConditionStats>,
    /// BT.500 screening of the rating panel (when there are ratings).
    pub screening: Option<ScreeningReport>,
    /// MOS per condition without the rejected observers (when any were rejected).
    pub mos_screened: Option<Vec<ConditionStats>>,
    /// MOS of per-subject z-scores (when asked for).
    pub mos_zscored: Option<Vec<ConditionStats>>,
    /// Hidden-repeat consistency per subject.
    pub repeats: Vec<RepeatConsistency>,
    /// Paired t-tests between codecs at the same clip and ratio, Holm-corrected.
    pub comparisons: Vec<ComparisonRow>,
    /// MOS rate findings.
    pub mos_findings: Vec<RateFinding>,
    /// DMOS per condition (DSCQS, or ACR-HR when references are given).
    pub dmos: Vec<ConditionStats>,
    /// DMOS rate findings.
    pub dmos_findings: Vec<RateFinding>,
    /// Staircase thresholds.
    pub thresholds: Option<ThresholdSummary>,
    /// Psychometric fit and bootstrap CI of its threshold.
    pub psychometric: Option<(PsychometricFit, BootstrapCi)>,
    /// Share of viewers who would notice each level, and the CR reached there (staircases).
    pub jnd: Option<JndAnalysis>,
}

/// Computes every statistic the data allow.
///
/// # Errors
/// Any input error of the underlying computations (non-finite scores, missing references,
/// invalid options).
pub fn analyze(data: &StudyData, options: &ReportOptions) -> Result<StudyAnalysis, AnalysisError> {
    let panel = Panel::new(&data.ratings)?;
    let mos = condition_stats(&data.ratings, options.confidence)?;
    let (screening, mos_screened) = if data.ratings.is_empty() {
        (None, None)
    } else {
        let s = screening_of_panel(&data.ratings, &panel);
        let rejected = s.rejected();
        let screened = if rejected.is_empty() {
            None
        } else {
            Some(condition_stats(
                &without_subjects(&data.ratings, &rejected),
                options.confidence,
            )?)
        };
        (Some(s), screened)
    };
    let mos_zscored = if options.zscore && !data.ratings.is_empty() {
        Some(condition_stats(
            &zscore_by_subject(&data.ratings)?,
            options.confidence,
        )?)
    } else {
        None
    };
    let repeats = repeats_of_panel(&data.ratings, &panel);
    let comparisons = compare_codecs(data, &panel, options)?;
    let mos_findings = rate_findings(
        &data.conditions,
        &mos,
        Limit::MosAtLeast(options.mos_limit),
        options.ci_method,
    );
    let dmos = if !data.dscqs.is_empty() {
        dscqs_dmos(&data.dscqs, options.confidence)?
    } else if !data.reference_of.is_empty() {
        acr_hr_dmos(&data.ratings, &data.reference_of, options.confidence)?
    } else {
        Vec::new()
    };
    let dmos_findings = rate_findings(
        &data.conditions,
        &dmos,
        Limit::DmosBelow(options.dmos_limit),
        options.ci_method,
    );
    let thresholds = if data.staircases.is_empty() {
        None
    } else {
        Some(staircase_thresholds(
            &data.staircases,
            options.last_reversals,
            options.confidence,
        )?)
    };
    let jnd = match &thresholds {
        Some(t) if !t.per_subject.is_empty() => Some(jnd_analysis(
            &t.per_subject,
            &data.encoded_levels,
            options.confidence,
        )?),
        _ => None,
    };
    let psychometric = if data.two_afc.is_empty() {
        None
    } else {
        let grouped = GroupedTrials::from_trials(&data.two_afc);
        Some(bootstrap_threshold(
            &grouped,
            &options.fit,
            options.percent_correct,
            &options.bootstrap,
        )?)
    };
    Ok(StudyAnalysis {
        mos,
        screening,
        mos_screened,
        mos_zscored,
        repeats,
        comparisons,
        mos_findings,
        dmos,
        dmos_findings,
        thresholds,
        psychometric,
        jnd,
    })
}

/// Paired comparisons between codecs that share a clip and compression ratio. Each subject's
/// repeats are averaged first; only subjects who rated both conditions enter a test.
fn compare_codecs(
    data: &StudyData,
    panel: &Panel,
    options: &ReportOptions,
) -> Result<Vec<ComparisonRow>, AnalysisError> {
    let by_condition = subject_means_by_condition(data, panel);
    // Group conditions by (clip, ratio bits).
    let mut groups: BTreeMap<(String, u64), Vec<&ConditionInfo>> = BTreeMap::new();
    for c in &data.conditions {
        if let Some(cr) = c.compression_ratio
            && by_condition.contains_key(&c.id)
        {
            groups
                .entry((c.clip.clone(), cr.to_bits()))
                .or_default()
                .push(c);
        }
    }
    let mut rows = Vec::new();
    for ((clip, cr_bits), mut conds) in groups {
        conds.sort_by_key(|c| c.method());
        for (a, b, alt) in codec_pairs(&conds, options.baseline_codec.as_deref()) {
            let (Some(sa), Some(sb)) = (by_condition.get(&a.id), by_condition.get(&b.id)) else {
                continue;
            };
            let (xa, xb) = common_subjects(sa, sb);
            let test = paired(&xa, &xb, alt)?;
            rows.push(ComparisonRow {
                clip: clip.clone(),
                compression_ratio: Some(f64::from_bits(cr_bits)),
                first: (a.method(), mean_or_nan(&xa)),
                second: (b.method(), mean_or_nan(&xb)),
                test,
                p_holm: None,
            });
        }
    }
    holm_adjust(&mut rows)?;
    Ok(rows)
}

/// Per condition id: (subject index, that subject's mean score over its repeats), sorted by
/// subject because the panel's cells run in (subject, condition) order.
fn subject_means_by_condition(data: &StudyData, panel: &Panel) -> BTreeMap<u32, Vec<(u32, f64)>> {
    let mut per_condition: Vec<Vec<(u32, f64)>> = vec![Vec::new(); panel.conditions.len()];
    for (start, end) in panel.cells() {
        let first = panel.order[start] as usize;
        let sum: f64 = panel.order[start..end]
            .iter()
            .map(|&r| data.ratings[r as usize].score)
            .sum();
        per_condition[panel.c[first] as usize].push((panel.s[first], sum / (end - start) as f64));
    }
    panel
        .conditions
        .iter()
        .copied()
        .zip(per_condition)
        .collect()
}

/// The tests to run among codecs at one clip and ratio (`conds` sorted by codec): each codec
/// against `baseline`, one-tailed ("scores higher than the baseline"), when the baseline is
/// among them (else none); without a baseline every pair, two-tailed.
fn codec_pairs<'a>(
    conds: &[&'a ConditionInfo],
    baseline: Option<&str>,
) -> Vec<(&'a ConditionInfo, &'a ConditionInfo, Alternative)> {
    let mut pairs = Vec::new();
    match baseline {
        Some(base) => {
            let by_codec: Vec<&&ConditionInfo> = conds.iter().filter(|c| c.codec == base).collect();
            let baseline =
                conds
                    .iter()
                    .find(|c| c.method() == base)
                    .or(match by_codec.as_slice() {
                        [one] => Some(*one),
                        _ => None,
                    });
            if let Some(b) = baseline {
                pairs.extend(
                    conds
                        .iter()
                        .filter(|c| c.id != b.id)
                        .map(|a| (*a, *b, Alternative::Greater)),
                );
            }
        }
        None => {
            for (i, a) in conds.iter().enumerate() {
                for b in &conds[i + 1..] {
                    pairs.push((*a, *b, Alternative::TwoSided));
                }
            }
        }
    }
    pairs
}

/// The paired samples of two conditions: the means of the subjects who rated both, by a merge
/// join on the subject-sorted lists.
fn common_subjects(a: &[(u32, f64)], b: &[(u32, f64)]) -> (Vec<f64>, Vec<f64>) {
    let (mut xa, mut xb) = (Vec::new(), Vec::new());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].0.cmp(&b[j].0) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                xa.push(a[i].1);
                xb.push(b[j].1);
                i += 1;
                j += 1;
            }
        }
    }
    (xa, xb)
}

/// Plain mean of a comparison's sample, NaN when no subject rated both conditions (the table
/// prints that test as undefined).
fn mean_or_nan(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Fills `p_holm` with the Holm correction across the family of defined tests in `rows`.
fn holm_adjust(rows: &mut [ComparisonRow]) -> Result<(), AnalysisError> {
    let defined: Vec<(usize, f64)> = rows
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.test.as_ref().ok().map(|t| (i, t.p)))
        .collect();
    let adjusted = holm(&defined.iter().map(|d| d.1).collect::<Vec<_>>())?;
    for ((i, _), p) in defined.iter().zip(adjusted) {
        rows[*i].p_holm = Some(p);
    }
    Ok(())
}

fn rate_series(findings: &[RateFinding], method: CiMethod) -> Vec<RateSeries> {
    findings
        .iter()
        .map(|f| RateSeries {
            label: format!("{} / {}", f.codec, f.clip),
            points: f
                .points
                .iter()
                .map(|p| {
                    let ci = p.summary.ci(method);
                    (
                        p.compression_ratio,
                        p.summary.mean,
                        ci.map_or(p.summary.mean, |c| c.lower),
                        ci.map_or(p.summary.mean, |c| c.upper),
                    )
                })
                .collect(),
        })
        .collect()
}

impl StudyAnalysis {
    /// Lays the statistics out as a report: tables shaped like the seeds' and the figures.
    ///
    /// Sections come in this order, each only when the data gave it something to show.
    pub fn to_report(&self, data: &StudyData, options: &ReportOptions, title: &str) -> Report {
        let mut report = Report::new(title);
        if !self.mos.is_empty() {
            self.mos_section(&mut report, data, options);
        }
        if !self.comparisons.is_empty() {
            comparisons_section(&mut report, &self.comparisons);
        }
        if let Some(screening) = &self.screening {
            screening_section(&mut report, screening, &self.repeats);
        }
        if !self.dmos.is_empty() {
            self.dmos_section(&mut report, data, options);
        }
        if let Some(t) = &self.thresholds {
            thresholds_section(&mut report, t, data, options);
        }
        if let Some(j) = &self.jnd {
            jnd_section(&mut report, j, options);
        }
        if let Some((fit, ci)) = &self.psychometric {
            psychometric_section(&mut report, fit, ci, data, options);
        }
        report
    }

    /// The MOS section: all observers, without the rejected ones, of z-scores (thesis Table
    /// 3.1 layout), the MOS rate findings, and the MOS-vs-CR and per-subject score figures.
    fn mos_section(&self, report: &mut Report, data: &StudyData, options: &ReportOptions) {
        let conf = percent_label(options.confidence);
        let s = report.section("Mean opinion scores");
        s.text(format!(
            "{} ratings from {} subjects. Mean ± {conf} confidence interval ({:?}); thesis Table 3.1 layout.",
            data.ratings.len(),
            data.ratings.iter().map(|r| r.subject).collect::<BTreeSet<_>>().len(),
            options.ci_method
        ));
        s.table(tables::mos_table(
            "mos",
            "MOS per condition (all observers)",
            &data.conditions,
            &self.mos,
            options.ci_method,
        ));
        if let Some(screened) = &self.mos_screened {
            s.table(tables::mos_table(
                "mos_screened",
                "MOS per condition without rejected observers",
                &data.conditions,
                screened,
                options.ci_method,
            ));
        }
        if let Some(z) = &self.mos_zscored {
            s.table(tables::mos_table(
                "mos_zscored",
                "Mean of per-subject z-scores per condition",
                &data.conditions,
                z,
                options.ci_method,
            ));
        }
        s.table(tables::findings_table(
            "mos_findings",
            &format!(
                "Highest CR whose lower CI bound stays ≥ MOS {}",
                options.mos_limit
            ),
            &self.mos_findings,
        ));
        if options.figures {
            s.figure(
                "mos_vs_cr",
                Figure::RateCurves {
                    title: "MOS vs compression ratio".to_owned(),
                    y_label: "MOS".to_owned(),
                    series: rate_series(&self.mos_findings, options.ci_method),
                    limit: Some(options.mos_limit),
                },
            );
            s.figure(
                "score_distributions",
                Figure::ScoreDistributions {
                    title: "Scores per subject".to_owned(),
                    per_subject: scores_per_subject(&data.ratings),
                },
            );
        }
    }

    /// The DMOS section: the thesis Table 6.3 grid, DMOS with intervals, the DMOS rate
    /// findings and the DMOS-vs-CR figure.
    fn dmos_section(&self, report: &mut Report, data: &StudyData, options: &ReportOptions) {
        let s = report.section("Differential MOS");
        s.table(tables::dmos_table(
            "dmos",
            "DMOS per condition and clip (thesis Table 6.3 layout)",
            &data.conditions,
            &self.dmos,
        ));
        s.table(tables::mos_table(
            "dmos_ci",
            "DMOS with confidence intervals",
            &data.conditions,
            &self.dmos,
            options.ci_method,
        ));
        s.table(tables::findings_table(
            "dmos_findings",
            &format!(
                "Highest CR whose upper CI bound stays < DMOS {}",
                options.dmos_limit
            ),
            &self.dmos_findings,
        ));
        if options.figures {
            s.figure(
                "dmos_vs_cr",
                Figure::RateCurves {
                    title: "DMOS vs compression ratio".to_owned(),
                    y_label: "DMOS".to_owned(),
                    series: rate_series(&self.dmos_findings, options.ci_method),
                    limit: Some(options.dmos_limit),
                },
            );
        }
    }
}

/// A confidence level as the report's text prints it: `95 %`.
fn percent_label(confidence: Confidence) -> String {
    format!("{:.0} %", confidence.percent())
}

/// Every subject's scores in rating order, by subject id: the score-distribution figure.
fn scores_per_subject(ratings: &[Rating]) -> Vec<(u32, Vec<f64>)> {
    let mut per: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for r in ratings {
        per.entry(r.subject).or_default().push(r.score);
    }
    per.into_iter().collect()
}

/// The comparisons section: the paired t-tests between codecs (thesis Tables 3.2, 3.3).
fn comparisons_section(report: &mut Report, comparisons: &[ComparisonRow]) {
    let s = report.section("Comparisons");
    s.text("Paired t-tests on per-subject mean scores at equal clip and ratio; p values Holm-corrected across the table (thesis Tables 3.2, 3.3).");
    s.table(tables::ttest_table(
        "ttests",
        "Paired t-tests between codecs",
        comparisons,
    ));
}

/// The observer-screening section: who BT.500 rejects and why, and hidden-repeat consistency.
fn screening_section(
    report: &mut Report,
    screening: &ScreeningReport,
    repeats: &[RepeatConsistency],
) {
    let s = report.section("Observer screening");
    let rejected = screening.rejected();
    s.text(if rejected.is_empty() {
        "BT.500 Annex 2 §2.3.1: no observer rejected.".to_owned()
    } else {
        format!(
            "BT.500 Annex 2 §2.3.1: rejected {} ((P+Q)/JKR > 0.05 and |P−Q|/(P+Q) < 0.3); MOS is reported with and without them.",
            rejected.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ")
        )
    });
    s.table(tables::screening_table(
        "screening",
        "BT.500 observer screening",
        screening,
    ));
    if let Some(table) = repeats_table(repeats) {
        s.table(table);
    }
}

/// Hidden-repeat consistency of the subjects who met a repeat; `None` when nobody did.
fn repeats_table(repeats: &[RepeatConsistency]) -> Option<tables::Table> {
    let rows: Vec<Vec<String>> = repeats
        .iter()
        .filter(|r| r.pairs > 0)
        .map(|r| {
            vec![
                r.subject.to_string(),
                r.pairs.to_string(),
                fmt_opt(r.mean_abs_difference, 3),
            ]
        })
        .collect();
    (!rows.is_empty()).then(|| tables::Table {
        name: "repeats".to_owned(),
        caption: "Hidden-repeat consistency (mean |repeat − first|)".to_owned(),
        columns: vec![
            "Subject".to_owned(),
            "Repeats".to_owned(),
            "Mean abs. difference".to_owned(),
        ],
        rows,
    })
}

/// The staircase section: thresholds from the last reversals (thesis §5.4) and the tracks.
fn thresholds_section(
    report: &mut Report,
    t: &ThresholdSummary,
    data: &StudyData,
    options: &ReportOptions,
) {
    let s = report.section("Staircase thresholds");
    s.text(format!(
        "Mean of the last {} reversals per staircase, averaged per subject (thesis §5.4).",
        t.last_reversals
    ));
    s.table(tables::threshold_table(
        "thresholds",
        "Staircase thresholds across subjects",
        t,
    ));
    if options.figures {
        s.figure(
            "staircases",
            Figure::Staircases {
                title: "Staircase tracks".to_owned(),
                level_label: options.level_label.clone(),
                tracks: data.staircases.clone(),
            },
        );
    }
}

/// The psychometric section: the maximum-likelihood fit, its threshold with the bootstrap
/// interval, and the fitted curve over the grouped 2AFC data.
fn psychometric_section(
    report: &mut Report,
    fit: &PsychometricFit,
    ci: &BootstrapCi,
    data: &StudyData,
    options: &ReportOptions,
) {
    let s = report.section("Psychometric function");
    s.text(format!(
        "Maximum-likelihood {:?} fit to {} 2AFC trials (guess rate {}, lapse {:.4}); threshold at {:.0} % correct = {:.5}, {:.0} % parametric bootstrap CI [{:.5}, {:.5}] from {} replicates (seed {}).",
        fit.shape,
        fit.trials,
        fit.guess_rate,
        fit.lapse,
        options.percent_correct * 100.0,
        ci.threshold,
        ci.confidence.percent(),
        ci.lower,
        ci.upper,
        ci.replicates,
        ci.seed
    ));
    if options.figures {
        s.figure(
            "psychometric",
            Figure::Psychometric {
                title: "Psychometric function".to_owned(),
                level_label: options.level_label.clone(),
                data: GroupedTrials::from_trials(&data.two_afc),
                fit: *fit,
                threshold: Some((options.percent_correct, ci.threshold, ci.lower, ci.upper)),
            },
        );
    }
}

/// The JND section: thresholds over viewers, and at each level the share who would notice
/// with the CR the codec reached there on each clip.
fn jnd_section(report: &mut Report, j: &JndAnalysis, options: &ReportOptions) {
    let conf = percent_label(j.confidence);
    let label = &options.level_label;
    let s = report.section("Just-noticeable difference across viewers");
    let sd = j
        .summary
        .sd
        .map_or_else(|| "n/a".to_owned(), |v| format!("{v:.4}"));
    let ci = j.summary.ci_t.map_or_else(
        || "n/a".to_owned(),
        |c| format!("[{:.4}, {:.4}]", c.lower, c.upper),
    );
    s.text(format!(
        "{} viewers: mean JND {label} = {:.4} (SD {sd}, {conf} CI of the mean {ci}), smallest {:.4}, largest {:.4} (thesis §5.4 layout). A viewer notices a level at or above their threshold; the share who would not notice is read from the thresholds (empirical) and from a normal model of them, with the exact normal-theory {conf} interval (noncentral t).",
        j.thresholds.len(),
        j.summary.mean,
        j.min,
        j.max
    ));
    s.table(tables::Table {
        name: "jnd_thresholds".to_owned(),
        caption: format!("JND threshold ({label}) per viewer"),
        columns: vec!["Subject".to_owned(), format!("Threshold ({label})")],
        rows: j
            .thresholds
            .iter()
            .map(|(subject, t)| vec![subject.to_string(), format!("{t:.4}")])
            .collect(),
    });
    let mut columns = vec![
        label.clone(),
        "Notice, empirical (%)".to_owned(),
        "Notice, normal model (%)".to_owned(),
        format!("{conf} CI (%)"),
    ];
    columns.extend(j.clips.iter().map(|c| format!("CR on {c}")));
    let pct = |v: f64| format!("{:.1}", 100.0 * v);
    s.table(tables::Table {
        name: "jnd_notice".to_owned(),
        caption: format!(
            "Share of viewers who would notice each {label}, and the compression ratio reached there"
        ),
        columns,
        rows: j
            .rows
            .iter()
            .map(|r| {
                let mut row = vec![
                    format!("{:.4}", r.share.level),
                    pct(1.0 - r.share.empirical),
                    r.share.model.map_or_else(String::new, |m| pct(1.0 - m)),
                    r.share.model_ci.map_or_else(String::new, |(lo, hi)| {
                        format!("{} – {}", pct(1.0 - hi), pct(1.0 - lo))
                    }),
                ];
                row.extend(r.cr_per_clip.iter().map(|c| fmt_opt(*c, 1)));
                row
            })
            .collect(),
    });
    if options.figures {
        s.figure(
            "jnd",
            Figure::Jnd {
                title: "Share of viewers who notice".to_owned(),
                level_label: label.clone(),
                thresholds: j.thresholds.iter().map(|t| t.1).collect(),
                model: j.notice_curve(120),
            },
        );
    }
}
