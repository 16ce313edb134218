//! CCR rows (ITU-T P.910 comparison category rating): each the second version rated against
//! the first on -3 … +3, with which of the two was the reference. The analysis folds the
//! order (P.910, P.800 Annex E): a rating given with the reference first is the test's
//! against the reference as it stands, one given with the test first is negated, so that
//! every folded score is the test's against the reference; the comparison mean opinion
//! score (CMOS) of a condition is their mean, and the order effect is the difference of the
//! folded scores between the two orders.

use std::collections::BTreeMap;

use protocols::study::ReferencePlacement;
use protocols::{Answer, Position};

use super::MethodAnalysis;
use crate::descriptive::{CiMethod, summarize};
use crate::error::AnalysisError;
use crate::findings::ConditionInfo;
use crate::from_results::{Inputs, Row, bad, check_scale};
use crate::report::{Report, Section};
use crate::study::{ComparisonRating, ReportOptions, StudyData};
use crate::tables::{Table, fmt_opt};
use crate::ttest::{Alternative, paired};

/// Comparison category rating.
pub(super) struct Ccr;

impl MethodAnalysis for Ccr {
    fn add(&self, row: &Row<'_>, into: &mut Inputs<'_>) -> Result<(), AnalysisError> {
        let Row {
            record,
            path,
            index,
            subject,
            scale,
        } = *row;
        let Answer::Rating(score) = record.response.answer else {
            return Err(bad(path, index, "response", "a ccr trial needs one rating"));
        };
        check_scale(path, index, "score", score, scale)?;
        let reference_first = match record.trial.reference_position {
            Position::First | Position::Left => true,
            Position::Second | Position::Right => false,
            other => {
                return Err(bad(
                    path,
                    index,
                    "reference_position",
                    format!(
                        "a ccr trial shows the reference first or second (left or right), not \
                         {other}"
                    ),
                ));
            }
        };
        let condition = into.stimuli.id(&record.trial.stimulus);
        into.data.comparison_ratings.push(ComparisonRating {
            subject,
            condition,
            reference_first,
            score,
        });
        Ok(())
    }

    fn placement(&self, placement: ReferencePlacement) -> String {
        super::placement_line(placement, "the order of the original and the test")
    }

    fn no_screening(&self) -> Option<&'static str> {
        Some("CCR rates a difference, not a quality; BT.500 screening applies to ratings")
    }

    fn report_sections(&self, report: &mut Report, data: &StudyData, options: &ReportOptions) {
        if data.comparison_ratings.is_empty() {
            return;
        }
        let s = report.section("Comparison category rating (CCR)");
        let conf = format!("{}", options.confidence.percent());
        s.text(format!(
            "{} comparison ratings from {} subjects (ITU-T P.910 CCR: the original and a \
             compressed version in either order, unlabelled, the second rated against the first \
             from +3 \"Much better\" to -3 \"Much worse\"). Folded as P.910 asks: a rating given \
             with the compressed version first is negated, so every folded score rates the \
             compressed version against the original (negative: worse). CMOS is the mean of \
             each subject's mean folded score (n = subjects), with its {conf} % {} interval.",
            data.comparison_ratings.len(),
            subjects(&data.comparison_ratings).len(),
            match options.ci_method {
                CiMethod::StudentT => "Student t",
                CiMethod::NormalZ => "normal (z)",
            }
        ));
        cmos_table(s, data, options);
        order_tables(s, data, options);
    }
}

/// The folded score: the test's rating against the reference.
fn folded(r: &ComparisonRating) -> f64 {
    if r.reference_first { r.score } else { -r.score }
}

fn subjects(ratings: &[ComparisonRating]) -> Vec<u32> {
    let mut s: Vec<u32> = ratings.iter().map(|r| r.subject).collect();
    s.sort_unstable();
    s.dedup();
    s
}

/// The conditions rated, by clip, the original first, then ratio and method; with the
/// label columns (clip, codec, ratio) of each.
fn conditions(data: &StudyData) -> Vec<(u32, [String; 3])> {
    let info: BTreeMap<u32, &ConditionInfo> = data.conditions.iter().map(|c| (c.id, c)).collect();
    let mut ids: Vec<u32> = data
        .comparison_ratings
        .iter()
        .map(|r| r.condition)
        .collect();
    ids.sort_unstable();
    ids.dedup();
    let mut rows: Vec<(u32, &ConditionInfo)> = ids
        .into_iter()
        .filter_map(|id| info.get(&id).map(|c| (id, *c)))
        .collect();
    rows.sort_by(|(_, a), (_, b)| {
        let cr = |c: &ConditionInfo| c.compression_ratio.unwrap_or(f64::NEG_INFINITY);
        a.clip
            .cmp(&b.clip)
            .then(cr(a).total_cmp(&cr(b)))
            .then_with(|| a.method().cmp(&b.method()))
    });
    rows.into_iter()
        .map(|(id, c)| {
            let ratio = c
                .compression_ratio
                .map_or_else(|| "ref".to_owned(), |cr| format!("{cr}:1"));
            (id, [c.clip.clone(), c.method(), ratio])
        })
        .collect()
}

/// Mean of `values` (`None` when empty).
fn mean(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// Each subject's mean of the folded scores `keep` selects, by subject.
fn subject_means(
    ratings: &[ComparisonRating],
    keep: impl Fn(&ComparisonRating) -> bool,
) -> BTreeMap<u32, f64> {
    let mut by: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for r in ratings.iter().filter(|r| keep(r)) {
        by.entry(r.subject).or_default().push(folded(r));
    }
    by.into_iter()
        .filter_map(|(s, v)| mean(&v).map(|m| (s, m)))
        .collect()
}

/// `ccr_cmos`: each condition's CMOS over subjects, its SD and interval.
fn cmos_table(s: &mut Section, data: &StudyData, options: &ReportOptions) {
    let conf = format!("{}", options.confidence.percent());
    let mut rows = Vec::new();
    for (id, labels) in conditions(data) {
        let of = |r: &ComparisonRating| r.condition == id;
        let ratings = data.comparison_ratings.iter().filter(|r| of(r)).count();
        let means: Vec<f64> = subject_means(&data.comparison_ratings, of)
            .into_values()
            .collect();
        let summary = summarize(&means, options.confidence).ok();
        let ci = summary.as_ref().and_then(|m| m.ci(options.ci_method));
        let mut row = labels.to_vec();
        row.extend([
            means.len().to_string(),
            ratings.to_string(),
            fmt_opt(summary.as_ref().map(|m| m.mean), 6),
            fmt_opt(summary.as_ref().and_then(|m| m.sd), 6),
            fmt_opt(ci.map(|c| c.lower), 6),
            fmt_opt(ci.map(|c| c.upper), 6),
        ]);
        rows.push(row);
    }
    s.table(Table {
        name: "ccr_cmos".to_owned(),
        caption: format!(
            "CMOS per condition: the mean over subjects of each subject's mean folded score \
             (the compressed version against the original, -3 … +3), SD over subjects, {conf} \
             % CI"
        ),
        columns: [
            "Clip", "Codec", "CR", "Subjects", "Ratings", "CMOS", "SD", "Lower", "Upper",
        ]
        .map(str::to_owned)
        .to_vec(),
        rows,
    });
}

/// `ccr_order`: each condition's mean folded score in each order; `ccr_order_effect`: the
/// paired t-test over subjects of their mean folded score with the original first against
/// with it second.
fn order_tables(s: &mut Section, data: &StudyData, options: &ReportOptions) {
    let conf = format!("{}", options.confidence.percent());
    let mut rows = Vec::new();
    for (id, labels) in conditions(data) {
        let in_order = |first: bool| -> Vec<f64> {
            data.comparison_ratings
                .iter()
                .filter(|r| r.condition == id && r.reference_first == first)
                .map(folded)
                .collect()
        };
        let (a, b) = (in_order(true), in_order(false));
        let (ma, mb) = (mean(&a), mean(&b));
        let mut row = labels.to_vec();
        row.extend([
            a.len().to_string(),
            fmt_opt(ma, 6),
            b.len().to_string(),
            fmt_opt(mb, 6),
            fmt_opt(ma.zip(mb).map(|(x, y)| x - y), 6),
        ]);
        rows.push(row);
    }
    s.table(Table {
        name: "ccr_order".to_owned(),
        caption: "Folded scores by order: the mean with the original shown first (or left) and \
                  with it second (or right), over every rating, and their difference"
            .to_owned(),
        columns: [
            "Clip",
            "Codec",
            "CR",
            "Original first",
            "Mean",
            "Original second",
            "Mean",
            "Difference",
        ]
        .map(str::to_owned)
        .to_vec(),
        rows,
    });
    let ratings = &data.comparison_ratings;
    let first = subject_means(ratings, |r| r.reference_first);
    let second = subject_means(ratings, |r| !r.reference_first);
    let both: Vec<u32> = first
        .keys()
        .filter(|k| second.contains_key(k))
        .copied()
        .collect();
    let a: Vec<f64> = both.iter().map(|k| first[k]).collect();
    let b: Vec<f64> = both.iter().map(|k| second[k]).collect();
    let diffs: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x - y).collect();
    let test = paired(&a, &b, Alternative::TwoSided)
        .ok()
        .and_then(Result::ok);
    let summary = summarize(&diffs, options.confidence).ok();
    let ci = summary.as_ref().and_then(|m| m.ci_t);
    s.text(format!(
        "Order effect: over the {} subjects who saw both orders, each subject's mean folded \
         score with the original first minus with it second, tested against 0 with a \
         two-sided paired t-test (scipy.stats.ttest_rel). A difference means the order moved \
         the ratings: half of it is a leaning towards the second version, which folding \
         cancels from CMOS when each condition is seen equally often in both orders \
         (reference_position = \"balanced\").",
        both.len()
    ));
    s.table(Table {
        name: "ccr_order_effect".to_owned(),
        caption: format!(
            "Order effect: original first minus original second, paired over subjects, {conf} \
             % CI"
        ),
        columns: [
            "Subjects",
            "Difference",
            "SD",
            "Lower",
            "Upper",
            "t",
            "df",
            "p",
        ]
        .map(str::to_owned)
        .to_vec(),
        rows: vec![vec![
            both.len().to_string(),
            fmt_opt(summary.as_ref().map(|m| m.mean), 6),
            fmt_opt(summary.as_ref().and_then(|m| m.sd), 6),
            fmt_opt(ci.map(|c| c.lower), 6),
            fmt_opt(ci.map(|c| c.upper), 6),
            fmt_opt(test.as_ref().map(|t| t.t), 6),
            fmt_opt(test.as_ref().map(|t| t.df), 0),
            fmt_opt(test.as_ref().map(|t| t.p), 6),
        ]],
    });
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use std::collections::BTreeMap;

    use super::*;

    /// Three subjects rate one condition once in each order. The test is one category worse
    /// than the original (Δ = -1) and subject k leans towards the second version by
    /// b_k = 1, 1, 2: with the original first they answer Δ + b, with it second -Δ + b.
    /// Folded, each subject's mean is exactly Δ (CMOS -1), the means by order are Δ + mean b
    /// and Δ - mean b, and the order effect per subject is 2 b_k = 2, 2, 4: mean 8/3, SD
    /// sqrt(4/3), t = (8/3) / (sqrt(4/3) / sqrt(3)) = 4 on 2 df, two-sided p 0.057191 and the
    /// interval 8/3 ± t(0.975, 2) · 2/3 (t quantile 4.302653), as SciPy gives them.
    #[test]
    fn folding_and_the_order_effect_by_hand() {
        let mut data = StudyData {
            conditions: vec![ConditionInfo {
                id: 0,
                codec: "x".to_owned(),
                params: BTreeMap::new(),
                clip: "walk".to_owned(),
                compression_ratio: Some(10.0),
            }],
            ..StudyData::default()
        };
        for (subject, b) in [(0, 1.0), (1, 1.0), (2, 2.0)] {
            for (reference_first, score) in [(true, -1.0 + b), (false, 1.0 + b)] {
                data.comparison_ratings.push(ComparisonRating {
                    subject,
                    condition: 0,
                    reference_first,
                    score,
                });
            }
        }
        let mut report = Report::new("t");
        Ccr.report_sections(&mut report, &data, &ReportOptions::default());
        let table = |name: &str| {
            report
                .tables()
                .find(|t| t.name == name)
                .unwrap()
                .rows
                .clone()
        };
        let cmos = table("ccr_cmos");
        assert_eq!(cmos.len(), 1);
        assert_eq!(&cmos[0][..6], ["walk", "x", "10:1", "3", "6", "-1.000000"]);
        let order = table("ccr_order");
        assert_eq!(
            &order[0][3..],
            ["3", "0.333333", "3", "-2.333333", "2.666667"]
        );
        let effect = table("ccr_order_effect");
        assert_eq!(
            effect[0],
            [
                "3",
                "2.666667",
                "1.154701",
                "-0.201768",
                "5.535102",
                "4.000000",
                "2",
                "0.057191"
            ]
        );
    }
}
