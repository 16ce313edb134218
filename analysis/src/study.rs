//! The whole analysis of a study, as `study report` runs it: from plain trial data to every
//! statistic, then to a [`Report`] of tables and figures.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::Serialize;

use crate::bayesian::{self, BayesFit, Sigmoid};
use crate::bradley_terry::{PairChoice, PairComparisonAnalysis, analyze_pairs};
use crate::confidence::Confidence;
use crate::crowd::CrowdDesign;
use crate::descriptive::{CiMethod, ConditionStats, Rating, condition_stats};
use crate::dmos::{DscqsPair, acr_hr_dmos, dscqs_dmos, zscore_screened};
use crate::error::AnalysisError;
use crate::findings::{ConditionInfo, Limit, RateFinding, rate_findings};
use crate::jnd::{EncodedLevel, JndAnalysis, jnd_analysis};
use crate::panel::Panel;
use crate::plots::{Figure, RateSeries};
use crate::psychometric::{
    BootstrapCi, BootstrapOptions, FitOptions, GroupedTrials, PsychometricFit, TwoAfcTrial,
    bootstrap_band, bootstrap_threshold,
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
    /// Subject ids (`S005`) indexed by the numeric subject of the ratings, pairs and tracks;
    /// tables and figures name subjects by them (by number where a name is missing).
    pub subjects: Vec<String>,
    /// The crowd scenes among the conditions (thesis 6.5), when the study rated any.
    pub crowd: Option<CrowdDesign>,
    /// Pair comparison answers (P.910 PC).
    pub pair_choices: Vec<PairChoice>,
    /// Ratings of one version against the other shown with it (P.910 CCR).
    pub comparison_ratings: Vec<ComparisonRating>,
    /// The protocol the sessions ran (`None` for data not read from results); its method's
    /// analysis adds the report sections only it has.
    pub protocol: Option<protocols::Protocol>,
}

/// A rating on a comparison scale (P.910 CCR: -3 "Much worse" to +3 "Much better") of the
/// second (or right) version of a trial against the first (or left), as the subject gave it;
/// one of the two is the reference, the other the test condition.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ComparisonRating {
    /// Subject.
    pub subject: u32,
    /// The test condition (its id in [`StudyData::conditions`]).
    pub condition: u32,
    /// Whether the reference was shown first (or on the left): the rating is then of the test
    /// against the reference, else of the reference against the test.
    pub reference_first: bool,
    /// The rating as given.
    pub score: f64,
}

impl StudyData {
    /// How tables name subject `id`: its id from the results, else its number.
    pub fn subject_name(&self, id: u32) -> String {
        subject_name(&self.subjects, id)
    }
}

fn subject_name(names: &[String], id: u32) -> String {
    match names.get(id as usize) {
        Some(n) if !n.is_empty() => n.clone(),
        _ => id.to_string(),
    }
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
    /// Treat every rating as an observation of its own (n = ratings) in the MOS tables,
    /// instead of each subject's mean over its repeats (n = subjects, the default). Tests are
    /// paired and always take the per-subject means; the BT.500 screening always takes every
    /// presentation, as the standard defines it.
    pub pool_repeats: bool,
    /// The rating scale (lowest, highest), printed with the limits so their unit is plain.
    pub scale: Option<(f64, f64)>,
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
            pool_repeats: false,
            scale: None,
        }
    }
}

/// Every statistic of a study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StudyAnalysis {
    /// MOS per condition, all observers: the mean over subjects of each subject's mean over
    /// its repeats (over every rating with [`ReportOptions::pool_repeats`]). In a DSCQS study,
    /// of the test scores.
    pub mos: Vec<ConditionStats>,
    /// BT.500 screening of the observers (when there are ratings): on every presentation's
    /// score, or in a DSCQS study on the reference − test differences.
    pub screening: Option<ScreeningReport>,
    /// MOS per condition without the rejected observers (when any were rejected).
    pub mos_screened: Option<Vec<ConditionStats>>,
    /// DMOS per condition without the rejected observers (when any were rejected; DSCQS).
    pub dmos_screened: Option<Vec<ConditionStats>>,
    /// MOS of per-subject z-scores (when asked for).
    pub mos_zscored: Option<Vec<ConditionStats>>,
    /// Subjects left out of the z-scores: one score for everything (or a single rating) has no
    /// z-score.
    pub zscore_excluded: BTreeSet<u32>,
    /// Hidden-repeat consistency per subject.
    pub repeats: Vec<RepeatConsistency>,
    /// Paired t-tests between codecs at the same clip and ratio, Holm-corrected: on the
    /// per-subject mean scores, or in a DSCQS study on the per-subject mean differences.
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
    /// Bayesian psychometric fits of every adaptive track, every subject and all subjects
    /// pooled (staircase and QUEST+ / Psi studies).
    pub bayes: Option<BayesianFits>,
    /// Subject bias and inconsistency by maximum likelihood (sureal's MLE model), for rating
    /// studies (not DSCQS) of at most [`MLE_MAX_RATINGS`] ratings.
    pub subject_model: Option<crate::mle::SubjectModel>,
    /// Bradley-Terry scale values of a pair comparison study.
    pub pair_comparison: Option<PairComparisonAnalysis>,
    /// Inter-rater reliability (ICC, Krippendorff's α) of the per-subject means of a rating
    /// study's scores, or of a DSCQS study's differences.
    pub reliability: Option<crate::reliability::Reliability>,
    /// Linear and ordinal mixed models of the ratings (subject and clip random effects).
    pub mixed: Option<crate::mixed::MixedAnalysis>,
}

/// Most ratings the report fits the subject model to: sureal's iteration passes over every
/// rating about a thousand times (a lab study's thousands of ratings take well under a second;
/// 10⁶ would take minutes), so larger sets are left to sureal itself (`sureal_dataset.py`).
pub const MLE_MAX_RATINGS: usize = 50_000;

/// One adaptive track's thresholds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrackFit {
    /// Subject.
    pub subject: u32,
    /// Track name.
    pub label: String,
    /// A QUEST+ or Psi track (else an up-down staircase).
    pub bayesian: bool,
    /// Trials.
    pub trials: usize,
    /// Mean of the last reversals (up-down tracks with enough reversals).
    pub reversal_threshold: Option<f64>,
    /// The session's own threshold (`session.json`).
    pub logged_threshold: Option<f64>,
    /// The Bayesian fit of a QUEST+ / Psi track's trials (`None` for an up-down track, whose
    /// threshold is its reversal mean, or where the track has fewer than two levels).
    pub fit: Option<BayesFit>,
}

/// Bayesian psychometric fits ([`crate::bayesian`]) of 2AFC data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BayesianFits {
    /// The sigmoid (from [`ReportOptions::fit`]'s shape).
    pub sigmoid: Sigmoid,
    /// Every track of every subject, in subject order.
    pub per_track: Vec<TrackFit>,
    /// Every subject's trials of all tracks together.
    pub per_subject: Vec<(u32, Option<BayesFit>)>,
    /// All subjects' trials pooled.
    pub pooled: Option<BayesFit>,
}

/// The Bayesian fits of every track, every subject and all trials pooled.
fn bayesian_fits(data: &StudyData, options: &ReportOptions) -> BayesianFits {
    use crate::psychometric::Shape;
    let sigmoid = match options.fit.shape {
        Shape::Weibull => Sigmoid::Weibull,
        Shape::Logistic => Sigmoid::Logistic,
    };
    let fit_of = |trials: &[TwoAfcTrial]| {
        bayesian::fit(
            &GroupedTrials::from_trials(trials),
            sigmoid,
            options.confidence,
        )
        .ok()
    };
    // Each fit evaluates a posterior on some 10⁶ grid points: they run on two threads.
    let fit_all = |sets: &[Vec<TwoAfcTrial>]| -> Vec<Option<BayesFit>> {
        let half = sets.len().div_ceil(2).max(1);
        std::thread::scope(|scope| {
            let workers: Vec<_> = sets
                .chunks(half)
                .map(|part| scope.spawn(move || part.iter().map(|t| fit_of(t)).collect::<Vec<_>>()))
                .collect();
            workers
                .into_iter()
                .flat_map(|w| w.join().unwrap_or_default())
                .collect()
        })
    };
    let trials_of = |t: &StaircaseTrack| -> Vec<TwoAfcTrial> {
        t.steps
            .iter()
            .map(|s| TwoAfcTrial {
                level: s.level,
                correct: s.correct,
            })
            .collect()
    };
    let mut by_subject: BTreeMap<u32, Vec<TwoAfcTrial>> = BTreeMap::new();
    for t in &data.staircases {
        by_subject
            .entry(t.subject)
            .or_default()
            .extend(trials_of(t));
    }
    // One list of fits: the Bayesian tracks', every subject's, the pool's.
    let mut sets: Vec<Vec<TwoAfcTrial>> = data
        .staircases
        .iter()
        .filter(|t| t.bayesian)
        .map(trials_of)
        .collect();
    let tracks = sets.len();
    sets.extend(by_subject.values().cloned());
    sets.push(data.two_afc.clone());
    let mut fits = fit_all(&sets).into_iter();
    let mut per_track: Vec<TrackFit> = data
        .staircases
        .iter()
        .map(|t| TrackFit {
            subject: t.subject,
            label: t.label.clone(),
            bayesian: t.bayesian,
            trials: t.steps.len(),
            reversal_threshold: (!t.bayesian)
                .then(|| t.threshold(options.last_reversals))
                .flatten(),
            logged_threshold: t.logged_threshold,
            fit: if t.bayesian {
                fits.next().flatten()
            } else {
                None
            },
        })
        .collect();
    debug_assert_eq!(per_track.iter().filter(|t| t.bayesian).count(), tracks);
    per_track.sort_by(|a, b| {
        a.subject
            .cmp(&b.subject)
            .then_with(|| a.label.cmp(&b.label))
    });
    let per_subject = by_subject
        .keys()
        .map(|s| (*s, fits.next().flatten()))
        .collect();
    let pooled = fits.next().flatten();
    BayesianFits {
        sigmoid,
        per_track,
        per_subject,
        pooled,
    }
}

/// The DMOS of every test condition and its rate findings: DSCQS's (reference − test) where
/// there are DSCQS pairs, else ACR-HR's against the hidden references, else none.
fn dmos_statistics(
    data: &StudyData,
    options: &ReportOptions,
) -> Result<(Vec<ConditionStats>, Vec<RateFinding>), AnalysisError> {
    let dmos = if !data.dscqs.is_empty() {
        dscqs_dmos(&data.dscqs, options.confidence)?
    } else if !data.reference_of.is_empty() {
        acr_hr_dmos(&data.ratings, &data.reference_of, options.confidence)?
    } else {
        Vec::new()
    };
    let findings = rate_findings(
        &data.conditions,
        &dmos,
        Limit::DmosBelow(options.dmos_limit),
        options.ci_method,
    );
    Ok((dmos, findings))
}

/// Computes every statistic the data allow.
///
/// # Errors
/// Any input error of the underlying computations (non-finite scores, missing references,
/// invalid options).
pub fn analyze(data: &StudyData, options: &ReportOptions) -> Result<StudyAnalysis, AnalysisError> {
    let panel = Panel::new(&data.ratings)?;
    let means = panel.subject_means(&data.ratings);
    let scores: &[Rating] = if options.pool_repeats {
        &data.ratings
    } else {
        &means
    };
    let mos = condition_stats(scores, options.confidence)?;
    // DSCQS is judged on the difference each subject saw (reference − test): the observers
    // are screened and the codecs compared on it, as the DMOS is.
    let differences: Vec<Rating> = data
        .dscqs
        .iter()
        .map(|p| Rating {
            subject: p.subject,
            condition: p.condition,
            score: p.reference_score - p.test_score,
        })
        .collect();
    let difference_panel = Panel::new(&differences)?;
    let difference_means = difference_panel.subject_means(&differences);
    // BT.500's screening is defined per presentation, a repeat being a presentation of its
    // own (its J·K·R): it takes every rating, never the per-subject means, which would hide
    // an erratic observer's scatter.
    let (presented, presented_panel, judged_means): (&[Rating], &Panel, &[Rating]) =
        if data.dscqs.is_empty() {
            (&data.ratings, &panel, &means)
        } else {
            (&differences, &difference_panel, &difference_means)
        };
    let screening = (!presented.is_empty()).then(|| screening_of_panel(presented, presented_panel));
    let rejected = screening
        .as_ref()
        .map(ScreeningReport::rejected)
        .unwrap_or_default();
    // Rejected observers leave every table they are in: the MOS, and in DSCQS the DMOS.
    let mos_screened = if rejected.is_empty() || scores.is_empty() {
        None
    } else {
        let kept = without_subjects(scores, &rejected);
        Some(condition_stats(&kept, options.confidence)?)
    };
    let dmos_screened = if rejected.is_empty() || data.dscqs.is_empty() {
        None
    } else {
        let kept: Vec<DscqsPair> = data
            .dscqs
            .iter()
            .filter(|p| !rejected.contains(&p.subject))
            .copied()
            .collect();
        Some(dscqs_dmos(&kept, options.confidence)?)
    };
    let (mos_zscored, zscore_excluded) = if options.zscore && !scores.is_empty() {
        let (z, excluded) = zscore_screened(scores)?;
        (Some(condition_stats(&z, options.confidence)?), excluded)
    } else {
        (None, BTreeSet::new())
    };
    let repeats = repeats_of_panel(&data.ratings, &panel);
    let comparisons = compare_codecs(
        &data.conditions,
        judged_means,
        !data.dscqs.is_empty(),
        options,
    )?;
    let mos_findings = rate_findings(
        &data.conditions,
        &mos,
        Limit::MosAtLeast(options.mos_limit),
        options.ci_method,
    );
    let (dmos, dmos_findings) = dmos_statistics(data, options)?;
    let (thresholds, jnd, psychometric) = adaptive_statistics(data, options)?;
    Ok(StudyAnalysis {
        mos,
        screening,
        mos_screened,
        dmos_screened,
        mos_zscored,
        zscore_excluded,
        repeats,
        comparisons,
        mos_findings,
        dmos,
        dmos_findings,
        thresholds,
        psychometric,
        jnd,
        bayes: (!data.staircases.is_empty()).then(|| bayesian_fits(data, options)),
        subject_model: subject_model(data)?,
        pair_comparison: pair_comparison(data, options)?,
        reliability: crate::reliability::analyze(judged_means, options.confidence),
        mixed: crate::mixed::analyze(&data.ratings, &data.conditions, options.confidence),
    })
}

/// The Bradley-Terry fits of a pair comparison study's choices (none without choices).
fn pair_comparison(
    data: &StudyData,
    options: &ReportOptions,
) -> Result<Option<PairComparisonAnalysis>, AnalysisError> {
    if data.pair_choices.is_empty() {
        return Ok(None);
    }
    analyze_pairs(&data.conditions, &data.pair_choices, options.confidence).map(Some)
}

/// The maximum-likelihood subject model of a rating study (not DSCQS) of at most
/// [`MLE_MAX_RATINGS`] ratings.
fn subject_model(data: &StudyData) -> Result<Option<crate::mle::SubjectModel>, AnalysisError> {
    if data.dscqs.is_empty() && !data.ratings.is_empty() && data.ratings.len() <= MLE_MAX_RATINGS {
        Ok(Some(crate::mle::fit(&data.ratings, &data.conditions)?))
    } else {
        Ok(None)
    }
}

/// Optional outputs of the staircase and 2AFC data.
type Adaptive = (
    Option<ThresholdSummary>,
    Option<JndAnalysis>,
    Option<(PsychometricFit, BootstrapCi)>,
);

/// Staircase thresholds, the JND across viewers, and the psychometric fit with its bootstrap
/// interval, where the data have staircases and 2AFC trials.
fn adaptive_statistics(
    data: &StudyData,
    options: &ReportOptions,
) -> Result<Adaptive, AnalysisError> {
    // Only up-down tracks have reversals (QUEST+ / Psi tracks get Bayesian fits instead).
    let thresholds = if data.staircases.iter().all(|t| t.bayesian) {
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
            crate::jnd::LevelGrid::of_tracks(&data.staircases, options.last_reversals),
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
    Ok((thresholds, jnd, psychometric))
}

/// Paired comparisons between codecs that share a clip and compression ratio, on `means`
/// (one per subject and condition, in (subject, condition) order: each subject's repeats
/// averaged); only subjects who rated both conditions enter a test. `lower_is_better` for
/// differences (DSCQS): a baseline test then asks whether a codec's DMOS is lower.
fn compare_codecs(
    conditions: &[ConditionInfo],
    means: &[Rating],
    lower_is_better: bool,
    options: &ReportOptions,
) -> Result<Vec<ComparisonRow>, AnalysisError> {
    // Per condition: (subject, mean), subject-sorted since `means` runs in subject order.
    let mut by_condition: BTreeMap<u32, Vec<(u32, f64)>> = BTreeMap::new();
    for m in means {
        by_condition
            .entry(m.condition)
            .or_default()
            .push((m.subject, m.score));
    }
    // Group conditions by (clip, ratio bits).
    let mut groups: BTreeMap<(String, u64), Vec<&ConditionInfo>> = BTreeMap::new();
    for c in conditions {
        if let Some(cr) = c.compression_ratio
            && by_condition.contains_key(&c.id)
        {
            groups
                .entry((c.clip.clone(), cr.to_bits()))
                .or_default()
                .push(c);
        }
    }
    let better = if lower_is_better {
        Alternative::Less
    } else {
        Alternative::Greater
    };
    let mut rows = Vec::new();
    for ((clip, cr_bits), mut conds) in groups {
        conds.sort_by_key(|c| c.method());
        for (a, b, alt) in codec_pairs(&conds, options.baseline_codec.as_deref(), better) {
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
                alternative: alt,
                test,
                p_holm: None,
            });
        }
    }
    holm_adjust(&mut rows)?;
    Ok(rows)
}

/// The tests to run among codecs at one clip and ratio (`conds` sorted by codec): each codec
/// against `baseline`, one-tailed (`better`: "scores higher than the baseline", or for
/// differences "lower"), when the baseline is among them (else none); without a baseline
/// every pair, two-tailed.
fn codec_pairs<'a>(
    conds: &[&'a ConditionInfo],
    baseline: Option<&str>,
    better: Alternative,
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
                        .map(|a| (*a, *b, better)),
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

/// One curve per method and clip: the figure draws a panel per clip, so a curve is labelled
/// by its method alone.
fn rate_series(findings: &[RateFinding], method: CiMethod) -> Vec<RateSeries> {
    findings
        .iter()
        .map(|f| RateSeries {
            label: f.codec.clone(),
            clip: f.clip.clone(),
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
            comparisons_section(&mut report, &self.comparisons, data, options);
        }
        if let Some(screening) = &self.screening {
            screening_section(&mut report, screening, &self.repeats, data);
        }
        crate::reliability::section(&mut report, self.reliability.as_ref(), data);
        if let Some(m) = &self.subject_model {
            subject_model_section(&mut report, m, data);
        }
        if !self.dmos.is_empty() {
            self.dmos_section(&mut report, data, options);
        }
        crate::mixed::report_section(
            &mut report,
            self.mixed.as_ref(),
            options.confidence,
            options.figures,
        );
        if let Some(pc) = &self.pair_comparison {
            crate::bradley_terry::report_section(&mut report, pc, options.confidence);
        }
        if let Some(protocol) = data.protocol {
            crate::methods::of(protocol).report_sections(&mut report, data, options);
        }
        if let Some(crowd) = &data.crowd {
            self.crowd_section(&mut report, crowd, data, options, title);
        }
        if let Some(t) = &self.thresholds {
            thresholds_section(&mut report, t, data, options);
        }
        if let Some(j) = &self.jnd {
            jnd_section(&mut report, j, data, options);
        }
        if let Some((fit, ci)) = &self.psychometric {
            psychometric_section(&mut report, fit, ci, data, options);
        }
        if let Some(b) = &self.bayes {
            bayes_section(&mut report, b, data, options, self.thresholds.is_none());
        }
        report
    }

    /// The MOS section: all observers, without the rejected ones, of z-scores (thesis Table
    /// 3.1 layout), the MOS rate findings, and the MOS-vs-CR and per-subject score figures.
    fn mos_section(&self, report: &mut Report, data: &StudyData, options: &ReportOptions) {
        let conf = percent_label(options.confidence);
        let dscqs = !data.dscqs.is_empty();
        let subjects = data
            .ratings
            .iter()
            .map(|r| r.subject)
            .collect::<BTreeSet<_>>()
            .len();
        let s = report.section("Mean opinion scores");
        s.text(format!(
            "{} ratings{} from {subjects} subjects. {} Mean ± {conf} confidence interval ({:?}); thesis Table 3.1 layout.",
            data.ratings.len(),
            if dscqs { " of the test versions" } else { "" },
            repeats_treatment(options.pool_repeats),
            options.ci_method
        ));
        s.table(tables::mos_table(
            "mos",
            if dscqs {
                "MOS of the test versions per condition (all observers)"
            } else {
                "MOS per condition (all observers)"
            },
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
            if !self.zscore_excluded.is_empty() {
                s.text(format!(
                    "Left out of the z-scores (one score for every stimulus, so no z-score): {}.",
                    names_of(data, &self.zscore_excluded)
                ));
            }
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
                "Highest CR whose lower CI bound stays ≥ MOS {}{}",
                options.mos_limit,
                scale_unit(options)
            ),
            &self.mos_findings,
        ));
        if options.figures {
            s.figure(
                "mos_vs_cr",
                Figure::RateCurves {
                    title: "MOS vs compression ratio".to_owned(),
                    y_label: format!("MOS (mean ± {conf} CI)"),
                    series: rate_series(&self.mos_findings, options.ci_method),
                    limit: Some(options.mos_limit),
                    y_range: options.scale,
                },
            );
            s.figure(
                "score_distributions",
                Figure::ScoreDistributions {
                    title: "Scores per subject".to_owned(),
                    per_subject: scores_per_subject(data),
                    y_range: options.scale,
                },
            );
        }
    }

    /// The crowd section (thesis 6.5): every scene's characters' ratios with its MOS and
    /// DMOS, and the MOS against the varied characters' ratio, one curve per distance level
    /// (thesis Fig. 6.9; a study file per run, so a report per panel).
    fn crowd_section(
        &self,
        report: &mut Report,
        crowd: &CrowdDesign,
        data: &StudyData,
        options: &ReportOptions,
        title: &str,
    ) {
        let conf = percent_label(options.confidence);
        let s = report.section("Crowd scenes");
        s.text(format!(
            "{} crowd scenes rated at {} distance level(s). x is the {}. MOS of the compressed \
             scene (mean ± {conf} CI); Reference is the mean rating of the reference scene shown \
             before it; DMOS = reference − compressed, averaged per subject, then over subjects.",
            crowd.conditions.len(),
            crowd
                .conditions
                .iter()
                .map(|c| c.level.as_str())
                .collect::<BTreeSet<_>>()
                .len(),
            crowd.x_label().to_lowercase(),
        ));
        s.table(crowd.table(&self.mos, &self.dmos, &data.dscqs, options.ci_method));
        if options.figures {
            s.figure(
                "crowd_mos",
                Figure::CrowdCurves {
                    title: "Crowd scenes: MOS vs compression ratio per distance level".to_owned(),
                    y_label: format!("MOS (mean ± {conf} CI)"),
                    x_label: crowd.x_label(),
                    panel: title.to_owned(),
                    series: crowd.series(&self.mos, options.ci_method, title),
                    y_range: options.scale,
                },
            );
        }
    }

    /// The DMOS section: the thesis Table 6.3 grid, DMOS with intervals, the DMOS rate
    /// findings and the DMOS-vs-CR figure.
    fn dmos_section(&self, report: &mut Report, data: &StudyData, options: &ReportOptions) {
        let s = report.section("Differential MOS");
        s.text(if data.dscqs.is_empty() {
            "DMOS = test − hidden reference + 5 per subject (P.910 ACR-HR), averaged per subject over repeats, then over subjects."
                .to_owned()
        } else {
            format!(
                "DMOS = reference − test score of each DSCQS pair{}, averaged per subject over repeats, then over subjects; the screening and the t-tests use the same differences.",
                scale_unit(options)
            )
        });
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
        if let Some(screened) = &self.dmos_screened {
            s.table(tables::mos_table(
                "dmos_screened",
                "DMOS per condition without rejected observers",
                &data.conditions,
                screened,
                options.ci_method,
            ));
        }
        s.table(tables::findings_table(
            "dmos_findings",
            &format!(
                "Highest CR whose upper CI bound stays < DMOS {}{}",
                options.dmos_limit,
                scale_unit(options)
            ),
            &self.dmos_findings,
        ));
        if options.figures {
            s.figure(
                "dmos_vs_cr",
                Figure::RateCurves {
                    title: "DMOS vs compression ratio".to_owned(),
                    y_label: format!("DMOS (mean ± {} CI)", percent_label(options.confidence)),
                    series: rate_series(&self.dmos_findings, options.ci_method),
                    limit: Some(options.dmos_limit),
                    y_range: dmos_range(options.scale, !data.dscqs.is_empty()),
                },
            );
        }
    }
}

/// The span of the DMOS axis on `scale`: a DSCQS difference (reference − test) from 0 to the
/// scale's range; an ACR-HR DMOS (test − reference + 5) on the scale itself.
fn dmos_range(scale: Option<(f64, f64)>, dscqs: bool) -> Option<(f64, f64)> {
    scale.map(|(lo, hi)| if dscqs { (0.0, hi - lo) } else { (lo, hi) })
}

/// How the tables treat hidden repeats, in words.
fn repeats_treatment(pooled: bool) -> &'static str {
    if pooled {
        "Repeats pooled (--pool-repeats): every rating counts as an observation, n = ratings."
    } else {
        "Each subject's repeats of a condition are averaged first: n = subjects."
    }
}

/// The scale a limit is in, as a caption says it: ` (scale 1–5)`.
fn scale_unit(options: &ReportOptions) -> String {
    options
        .scale
        .map_or_else(String::new, |(lo, hi)| format!(" (scale {lo}–{hi})"))
}

/// Subject ids, comma-separated, for a paragraph (each escaped for Markdown: an id is text a
/// participant may control).
fn names_of(data: &StudyData, subjects: &BTreeSet<u32>) -> String {
    subjects
        .iter()
        .map(|&s| tables::md_escape(&data.subject_name(s)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A confidence level as the report's text prints it: `95 %`.
fn percent_label(confidence: Confidence) -> String {
    format!("{:.0} %", confidence.percent())
}

/// Every subject's scores in rating order, by subject: the score-distribution figure.
fn scores_per_subject(data: &StudyData) -> Vec<(String, Vec<f64>)> {
    let mut per: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for r in &data.ratings {
        per.entry(r.subject).or_default().push(r.score);
    }
    per.into_iter()
        .map(|(s, v)| (data.subject_name(s), v))
        .collect()
}

/// The comparisons section: the paired t-tests between codecs (thesis Tables 3.2, 3.3), with
/// their kind and tails in the caption and in every row.
fn comparisons_section(
    report: &mut Report,
    comparisons: &[ComparisonRow],
    data: &StudyData,
    options: &ReportOptions,
) {
    let on = if data.dscqs.is_empty() {
        "per-subject mean scores"
    } else {
        "per-subject mean differences (reference − test; DMOS, lower is better)"
    };
    let tails = match (&options.baseline_codec, data.dscqs.is_empty()) {
        (Some(b), true) => format!("one-tailed against {b} (H1: A scores higher than B = {b})"),
        (Some(b), false) => format!("one-tailed against {b} (H1: A has a lower DMOS than B = {b})"),
        (None, _) => "two-tailed between every pair of methods (H1: the means differ)".to_owned(),
    };
    let s = report.section("Comparisons");
    s.text(format!(
        "Paired t-tests on {on} at equal clip and ratio, {tails}; only subjects who rated both enter a test; p values Holm-corrected across the table (thesis Tables 3.2, 3.3, which are one-tailed: pass --baseline for that design)."
    ));
    s.table(tables::ttest_table(
        "ttests",
        &format!("Paired t-tests between codecs, {tails}"),
        comparisons,
    ));
}

/// The observer-screening section: who BT.500 rejects and why, and hidden-repeat consistency.
fn screening_section(
    report: &mut Report,
    screening: &ScreeningReport,
    repeats: &[RepeatConsistency],
    data: &StudyData,
) {
    let s = report.section("Observer screening");
    let rejected = screening.rejected();
    let on = if data.dscqs.is_empty() {
        "scores"
    } else {
        "reference − test differences"
    };
    let treatment = "Every presentation counts, a hidden repeat as repetition r of its condition, as BT.500 defines the screening.";
    s.text(if rejected.is_empty() {
        format!("BT.500 Annex 2 §2.3.1 on the {on}: no observer rejected. {treatment}")
    } else {
        format!(
            "BT.500 Annex 2 §2.3.1 on the {on}: rejected {} ((P+Q)/JKR > 0.05 and |P−Q|/(P+Q) < 0.3); {} reported with and without them. {treatment}",
            names_of(data, &rejected),
            if data.dscqs.is_empty() { "MOS is" } else { "DMOS is" }
        )
    });
    s.table(tables::screening_table(
        "screening",
        "BT.500 observer screening",
        screening,
        &|id| data.subject_name(id),
    ));
    if let Some(table) = repeats_table(repeats, data) {
        s.table(table);
    }
}

/// Hidden-repeat consistency of the subjects who met a repeat; `None` when nobody did.
fn repeats_table(repeats: &[RepeatConsistency], data: &StudyData) -> Option<tables::Table> {
    let rows: Vec<Vec<String>> = repeats
        .iter()
        .filter(|r| r.pairs > 0)
        .map(|r| {
            vec![
                data.subject_name(r.subject),
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
    s.text(staircase_rule_text(t, options));
    s.table(tables::staircase_tracks_table(
        "staircase_tracks",
        &format!(
            "Threshold ({}) of every up-down track: the last {} and the last {} reversals",
            options.level_label, t.last_reversals, t.even_k
        ),
        t,
        &|id| data.subject_name(id),
    ));
    s.table(tables::cited_threshold_table(
        "threshold_to_cite",
        &format!(
            "Threshold ({}) to cite per condition and over all conditions: the last {} reversals' mean across subjects",
            options.level_label, t.even_k
        ),
        t,
    ));
    s.table(tables::threshold_table(
        "thresholds",
        &format!(
            "Staircase thresholds across subjects, last {} reversals (thesis §5.4)",
            t.last_reversals
        ),
        t,
    ));
    if options.figures {
        s.figure(
            "staircases",
            Figure::Staircases {
                title: "Staircase tracks".to_owned(),
                level_label: options.level_label.clone(),
                tracks: data.staircases.clone(),
                last_reversals: t.last_reversals,
                subjects: data.subjects.clone(),
            },
        );
    }
}

/// The staircase section's opening: the rule the tracks follow, the bias of an odd count of
/// reversals, the two estimates, and which threshold to cite.
fn staircase_rule_text(t: &ThresholdSummary, options: &ReportOptions) -> String {
    let k = t.last_reversals;
    let even = t.even_k;
    let label = &options.level_label;
    // How far apart the two estimates came out here, over all conditions, in steps.
    let here = match (t.cited.last(), t.grid) {
        (Some(c), Some(g)) => c.last_k_mean.map_or_else(String::new, |m| {
            let steps = (m - c.even.mean) / g.step;
            format!(
                " Here the last {k} reversals' mean over all conditions is {:.2} of a step {} the last {even}'s.",
                steps.abs(),
                if steps < 0.0 { "below" } else { "above" }
            )
        }),
        _ => String::new(),
    };
    let parity = if k % 2 == 1 {
        format!(
            "Mean of the last {k} reversals per staircase, averaged per subject (thesis §5.4), and beside it the mean of the last {even}. Two-down-one-up tracks converge on the {label} answered correctly 70.7 % of the time (Levitt 1971). Their reversals alternate between peaks and troughs, and an odd count holds one more of one kind: the mean of the last {k} sits a fraction of a step off the 70.7 % point (about a sixth of a step below it with the thesis's settings, where the extra one is a trough). The mean of an even count holds as many peaks as troughs and centres on it: the last {even} reversals (a track with fewer gives the mean of its largest even count, noted beside it).{here}"
        )
    } else {
        format!(
            "Mean of the last {k} reversals per staircase, averaged per subject (thesis §5.4 takes 3). Two-down-one-up tracks converge on the {label} answered correctly 70.7 % of the time (Levitt 1971); an even count of reversals holds as many peaks as troughs and centres on that point (an odd one sits a fraction of a step off it), so both columns below give the last {k}."
        )
    };
    let grid = t.grid.filter(|g| g.linear).map_or_else(
        || "the grid is not linear, so no level is given".to_owned(),
        |g| {
            format!(
                "the level grid steps by {:.d$}",
                g.step,
                d = t.decimals.saturating_sub(1)
            )
        },
    );
    format!(
        "{parity} The threshold to cite per condition is the last {even} reversals' mean across subjects (each subject's tracks of the condition averaged) with its {conf} t interval, and beside it the nearest level the staircase presents ({grid}); over all conditions, the row 'all conditions'. Of the pooled thresholds in this report (this one, the maximum-likelihood psychometric fit and the pooled Bayesian fit), cite this one: the fits pool every subject's trials as if from one observer, so their intervals leave out the spread between subjects, and they read the {pc:.0} % point, not the 70.7 % one. Thresholds are printed to one decimal more than the level grid has.",
        conf = percent_label(options.confidence),
        pc = options.percent_correct * 100.0,
    )
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
    let levels: Vec<f64> = data.two_afc.iter().map(|t| t.level).collect();
    let d = crate::staircase::decimals_of_levels(&levels);
    s.text(format!(
        "Maximum-likelihood {:?} fit to {} 2AFC trials of all subjects pooled (guess rate {}, lapse {:.4}); threshold at {:.0} % correct = {:.d$}, {:.0} % parametric bootstrap CI [{:.d$}, {:.d$}] from {} replicates (seed {}). It describes the pooled psychometric function; the threshold to cite of a staircase study is in the staircase section.",
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
        let grouped = GroupedTrials::from_trials(&data.two_afc);
        // The curve's band refits the bootstrap's replicates (same seed): it agrees with the
        // threshold interval. Where it cannot be had the figure goes without it.
        let band = match (grouped.levels.first(), grouped.levels.last()) {
            (Some(first), Some(last)) => {
                let (lo, hi) = (first.0, last.0);
                let pad = 0.1 * (hi - lo);
                let levels: Vec<f64> = (0..=80)
                    .map(|i| lo - pad + (hi - lo + 2.0 * pad) * f64::from(i) / 80.0)
                    .filter(|x| *x > 0.0 || fit.shape != crate::psychometric::Shape::Weibull)
                    .collect();
                bootstrap_band(&grouped, &options.fit, &options.bootstrap, &levels).ok()
            }
            _ => None,
        };
        s.figure(
            "psychometric",
            Figure::Psychometric {
                title: "Psychometric function".to_owned(),
                level_label: options.level_label.clone(),
                data: grouped,
                fit: *fit,
                threshold: Some((options.percent_correct, ci.threshold, ci.lower, ci.upper)),
                band,
            },
        );
    }
}

/// The subject-model section: each subject's bias and inconsistency and each condition's
/// quality by maximum likelihood (sureal's MLE model).
fn subject_model_section(report: &mut Report, m: &crate::mle::SubjectModel, data: &StudyData) {
    let s = report.section("Subject bias and inconsistency");
    s.text(format!(
        "Maximum-likelihood subject model (Li & Bampis 2017; sureal's MaximumLikelihoodEstimationModel, its iteration, {} passes): every rating = quality of the stimulus + the subject's bias + noise with the subject's inconsistency (SD) and the clip's ambiguity (SD). Biases have mean 0; intervals 95 % (bias and quality ±1.96 standard errors, inconsistency χ² on the subject's ratings). Content ambiguity: {}.",
        m.passes,
        m.contents
            .iter()
            .map(|(c, a)| format!("{c} {a:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    let degenerate: Vec<String> = m
        .subjects
        .iter()
        .filter(|e| e.inconsistency < 1e-6)
        .map(|e| tables::md_escape(&data.subject_name(e.subject)))
        .chain(
            m.contents
                .iter()
                .filter(|c| c.1 < 1e-6)
                .map(|c| c.0.clone()),
        )
        .collect();
    if !degenerate.is_empty() {
        s.text(format!(
            "Warning: the fit reached a standard deviation of 0 for {}: the likelihood grows without bound there, so those ratings are fitted exactly and the intervals that depend on them collapse. Too few ratings for this model; the MOS tables do not depend on it.",
            degenerate.join(", ")
        ));
    }
    s.table(tables::Table {
        name: "subject_model".to_owned(),
        caption: "Subject bias and inconsistency (maximum likelihood)".to_owned(),
        columns: vec![
            "Subject".to_owned(),
            "Ratings".to_owned(),
            "Bias".to_owned(),
            "Bias 95 % interval".to_owned(),
            "Inconsistency".to_owned(),
            "Inconsistency 95 % interval".to_owned(),
        ],
        rows: m
            .subjects
            .iter()
            .map(|e| {
                vec![
                    data.subject_name(e.subject),
                    e.ratings.to_string(),
                    format!("{:.3}", e.bias),
                    format!("{:.3} – {:.3}", e.bias - e.bias_ci, e.bias + e.bias_ci),
                    format!("{:.3}", e.inconsistency),
                    format!("{:.3} – {:.3}", e.inconsistency_ci.0, e.inconsistency_ci.1),
                ]
            })
            .collect(),
    });
    let name = |id: u32| {
        data.conditions.iter().find(|c| c.id == id).map_or_else(
            || id.to_string(),
            |c| {
                c.compression_ratio.map_or_else(
                    || format!("{} reference", c.clip),
                    |cr| format!("{} {} {cr}:1", c.clip, c.method()),
                )
            },
        )
    };
    s.table(tables::Table {
        name: "mle_quality".to_owned(),
        caption: "Quality per condition by maximum likelihood".to_owned(),
        columns: vec![
            "Condition".to_owned(),
            "Quality".to_owned(),
            "95 % interval".to_owned(),
        ],
        rows: m
            .quality
            .iter()
            .map(|&(c, q, ci)| {
                vec![
                    name(c),
                    format!("{q:.3}"),
                    format!("{:.3} – {:.3}", q - ci, q + ci),
                ]
            })
            .collect(),
    });
}

/// The Bayesian section: every adaptive track's thresholds (reversals, the session's own,
/// the Bayesian fit with its credible interval), then the fit per subject and pooled.
fn bayes_section(
    report: &mut Report,
    b: &BayesianFits,
    data: &StudyData,
    options: &ReportOptions,
    track_figure: bool,
) {
    let conf = percent_label(options.confidence);
    let label = &options.level_label;
    let d = crate::staircase::level_decimals(&data.staircases);
    let s = report.section("Bayesian psychometric fits");
    s.text(format!(
        "Beta-binomial fits of ψ(x) = 0.5 + (0.5 − λ)·S(x) with a {} sigmoid S, by psignifit 4's procedure (posterior on a grid, posterior means, equal-tailed {conf} credible intervals). Threshold: S = 0.5 (75 % correct without lapses){}; width: S from 0.05 to 0.95{}. Priors: {}. Every track's threshold: an up-down staircase's is the mean of its last {} reversals; a QUEST+ / Psi track's own estimate is the posterior mean of its Weibull or logistic α (session.json; a Weibull's α is its point of about 80 % correct, not the 75 % point the fit reports), and it is also fitted here.",
        match b.sigmoid {
            Sigmoid::Weibull => "Weibull (Gumbel in ln level)",
            Sigmoid::Logistic => "logistic",
            Sigmoid::Normal => "normal",
        },
        if b.sigmoid == Sigmoid::Weibull {
            ", fitted on ln level (its mean is exp of the posterior mean of ln threshold)"
        } else {
            ""
        },
        if b.sigmoid == Sigmoid::Weibull { ", in ln units" } else { "" },
        bayesian::PRIORS,
        options.last_reversals
    ));
    s.text(
        "The pooled fit treats every subject's trials as one observer's: it describes the pooled psychometric function, its interval leaves out the spread between subjects, and it is not the threshold to cite (of an up-down study, the staircase section gives that; of a QUEST+ or Psi study, cite the fits per subject).",
    );
    s.table(tracks_table(b, data, &conf, label, d));
    let row = |who: String, f: &Option<BayesFit>| {
        let (m, i) = threshold_cells(f.as_ref(), d);
        let est = |e: Option<bayesian::Estimate>| {
            e.map_or_else(String::new, |e| {
                format!("{:.4} ({:.4} – {:.4})", e.mean, e.lower, e.upper)
            })
        };
        vec![
            who,
            f.map_or_else(String::new, |f| f.trials.to_string()),
            m,
            i,
            est(f.map(|f| f.width)),
            est(f.map(|f| f.lapse)),
            est(f.map(|f| f.eta)),
        ]
    };
    let mut rows: Vec<Vec<String>> = b
        .per_subject
        .iter()
        .map(|(subject, f)| row(data.subject_name(*subject), f))
        .collect();
    rows.push(row("pooled".to_owned(), &b.pooled));
    s.table(tables::Table {
        name: "bayes_fits".to_owned(),
        caption: format!("Bayesian psychometric fit per subject and pooled ({label})"),
        columns: vec![
            "Subject".to_owned(),
            "Trials".to_owned(),
            "Threshold".to_owned(),
            format!("{conf} credible interval"),
            "Width (interval)".to_owned(),
            "Lapse λ (interval)".to_owned(),
            "Overdispersion η (interval)".to_owned(),
        ],
        rows,
    });
    if track_figure && options.figures {
        s.figure(
            "staircases",
            Figure::Staircases {
                title: "Adaptive tracks".to_owned(),
                level_label: options.level_label.clone(),
                tracks: data.staircases.clone(),
                last_reversals: options.last_reversals,
                subjects: data.subjects.clone(),
            },
        );
    }
}

/// A fit's threshold and its credible interval as table cells to `d` decimals (`n/a`
/// without a fit).
fn threshold_cells(f: Option<&BayesFit>, d: usize) -> (String, String) {
    f.map_or_else(
        || ("n/a".to_owned(), String::new()),
        |f| {
            (
                format!("{:.d$}", f.threshold.mean),
                format!("{:.d$} – {:.d$}", f.threshold.lower, f.threshold.upper),
            )
        },
    )
}

/// The threshold of every adaptive track: reversal mean, session estimate, Bayesian fit.
fn tracks_table(
    b: &BayesianFits,
    data: &StudyData,
    conf: &str,
    label: &str,
    d: usize,
) -> tables::Table {
    tables::Table {
        name: "adaptive_tracks".to_owned(),
        caption: format!("Threshold ({label}) of every adaptive track"),
        columns: vec![
            "Subject".to_owned(),
            "Track".to_owned(),
            "Procedure".to_owned(),
            "Trials".to_owned(),
            "Reversal mean".to_owned(),
            "Session estimate".to_owned(),
            "Bayesian threshold".to_owned(),
            format!("{conf} credible interval"),
        ],
        rows: b
            .per_track
            .iter()
            .map(|t| {
                let (m, i) = threshold_cells(t.fit.as_ref(), d);
                vec![
                    data.subject_name(t.subject),
                    t.label.clone(),
                    if t.bayesian { "QUEST+/Psi" } else { "up-down" }.to_owned(),
                    t.trials.to_string(),
                    fmt_opt(t.reversal_threshold, d),
                    fmt_opt(t.logged_threshold, d),
                    m,
                    i,
                ]
            })
            .collect(),
    }
}

/// The JND section: thresholds over viewers, and at each level the share who would notice
/// with the CR the codec reached there on each clip.
fn jnd_section(report: &mut Report, j: &JndAnalysis, data: &StudyData, options: &ReportOptions) {
    let conf = percent_label(j.confidence);
    let label = &options.level_label;
    let s = report.section("Just-noticeable difference across viewers");
    let d = crate::staircase::level_decimals(&data.staircases);
    let sd = j
        .summary
        .sd
        .map_or_else(|| "n/a".to_owned(), |v| format!("{v:.d$}"));
    let ci = j.summary.ci_t.map_or_else(
        || "n/a".to_owned(),
        |c| format!("[{:.d$}, {:.d$}]", c.lower, c.upper),
    );
    let ties = j.grid.map_or_else(
        || "by the thresholds' values".to_owned(),
        |g| {
            format!(
                "on the level grid (a threshold within {:.1e} of a level, half the smallest difference a mean of {} reversal levels on steps of {:.prec$} can have, equals it)",
                g.tie_tolerance(),
                g.levels_per_threshold,
                g.step,
                prec = d.saturating_sub(1)
            )
        },
    );
    s.text(format!(
        "{} viewers, each viewer's threshold the mean of the last {} reversals of their tracks (the thesis's estimate; see the staircase section for the even count): mean JND {label} = {:.d$} (SD {sd}, {conf} CI of the mean {ci}), smallest {:.d$}, largest {:.d$} (thesis §5.4 layout). A viewer notices a level at or above their threshold, ties decided {ties}; the share who would notice is read from the thresholds (empirical) and from a normal model of them, with the exact normal-theory {conf} interval (noncentral t).",
        j.thresholds.len(),
        options.last_reversals,
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
            .map(|(subject, t)| vec![data.subject_name(*subject), format!("{t:.d$}")])
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
                    // A grid level to the grid's decimals (0.010, not 0.0100); any other to d.
                    {
                        let v = format!("{:.d$}", r.share.level);
                        match v.strip_suffix('0') {
                            Some(short) if v.contains('.') => short.to_owned(),
                            _ => v,
                        }
                    },
                    pct(1.0 - r.share.empirical),
                    r.share.notice.map_or_else(String::new, pct),
                    r.share.notice_ci.map_or_else(String::new, |(lo, hi)| {
                        format!("{} – {}", pct(lo), pct(hi))
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
