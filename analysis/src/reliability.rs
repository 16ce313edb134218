//! Inter-rater reliability of a rating study: intraclass correlations (Shrout & Fleiss 1979,
//! McGraw & Wong 1996) and Krippendorff's α (interval and ordinal; Krippendorff 2011,
//! "Computing Krippendorff's alpha-reliability").
//!
//! Targets are the rated conditions, raters the subjects, and a value is a subject's mean over
//! the repeats of a condition (in a DSCQS study, of the reference − test difference).
//!
//! The ICCs are those of pingouin's `intraclass_corr` (0.7.0), with its F tests and F-based
//! confidence intervals, computed from the two-way ANOVA of a complete targets × raters table.
//! Like pingouin (`nan_policy="omit"`), targets not rated by every rater are left out of the
//! ICC (listwise deletion); the report says how many. Krippendorff's α needs no complete
//! design: every condition rated by at least two subjects counts, as in the `krippendorff`
//! package (0.9.0), whose ordinal metric ranks the values by their frequencies among the
//! pairable values.

use serde::Serialize;
use statrs::function::beta::checked_beta_reg;

use crate::confidence::Confidence;
use crate::descriptive::Rating;
use crate::report::Report;
use crate::study::StudyData;
use crate::tables::{Table, fmt_opt, fmt_p};

/// Most distinct values for the ordinal α (its expected disagreement takes V² steps).
pub const ORDINAL_MAX_VALUES: usize = 5_000;

/// One ICC form with its F test and confidence interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IccForm {
    /// Shrout & Fleiss's name: `ICC1`, `ICC2`, `ICC3`, `ICC1k`, `ICC2k`, `ICC3k`.
    pub name: &'static str,
    /// McGraw & Wong's name as pingouin prints it: `ICC(1,1)`, `ICC(A,1)`, `ICC(C,1)`, ….
    pub mcgraw_wong: &'static str,
    /// The coefficient.
    pub icc: f64,
    /// F statistic of the test of ICC = 0.
    pub f: f64,
    /// Numerator degrees of freedom.
    pub df1: f64,
    /// Denominator degrees of freedom.
    pub df2: f64,
    /// p value of the F test (upper tail).
    pub p: f64,
    /// Lower bound of the confidence interval.
    pub lower: f64,
    /// Upper bound of the confidence interval.
    pub upper: f64,
}

/// The six ICCs of a complete targets × raters table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Icc {
    /// Targets (rows) in the table.
    pub targets: usize,
    /// Raters (columns).
    pub raters: usize,
    /// ICC1, ICC2, ICC3, ICC1k, ICC2k, ICC3k, in pingouin's order.
    pub forms: Vec<IccForm>,
    /// Level of the intervals.
    pub confidence: Confidence,
}

impl Icc {
    /// The form named `name` (`ICC2`, `ICC2k`, …).
    pub fn form(&self, name: &str) -> Option<&IccForm> {
        self.forms.iter().find(|f| f.name == name)
    }
}

/// Upper tail P(F ≥ x) of Fisher's F with `d1`, `d2` degrees of freedom.
fn f_sf(x: f64, d1: f64, d2: f64) -> f64 {
    if x.is_nan() || !(d1 > 0.0 && d2 > 0.0) {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if x.is_infinite() {
        return 0.0;
    }
    checked_beta_reg(d2 / 2.0, d1 / 2.0, d2 / (d2 + d1 * x)).unwrap_or(f64::NAN)
}

/// The x with P(F ≥ x) = `q` (SciPy's `f.isf(q, d1, d2)` = `f.ppf(1 − q, d1, d2)`), by
/// bisection on y = d2 / (d2 + d1·x) to the last bit.
fn f_isf(q: f64, d1: f64, d2: f64) -> f64 {
    if !(q > 0.0 && q < 1.0 && d1 > 0.0 && d2 > 0.0 && d1.is_finite() && d2.is_finite()) {
        return f64::NAN;
    }
    // I_y(d2/2, d1/2) rises with y from 0 to 1; the root y gives x = d2·(1 − y)/(d1·y).
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..2_000 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        match checked_beta_reg(d2 / 2.0, d1 / 2.0, mid) {
            Ok(v) if v < q => lo = mid,
            Ok(_) => hi = mid,
            Err(_) => return f64::NAN,
        }
    }
    let y = 0.5 * (lo + hi);
    d2 * (1.0 - y) / (d1 * y)
}

/// The F-based intervals of the six ICCs (pingouin's formulas; ICC2's from McGraw & Wong
/// 1996, Table 7, with Satterthwaite's df v), from the mean squares [between targets, within
/// targets, raters, error], n targets, k raters, ICC2 and the upper tail `q` = α/2.
fn intervals(ms: [f64; 4], nf: f64, kf: f64, icc2: f64, q: f64) -> [(f64, f64); 6] {
    let [msb, msw, msj, mse] = ms;
    let (df1, df1kd, df2kd) = (nf - 1.0, nf * (kf - 1.0), (nf - 1.0) * (kf - 1.0));
    let (f1, f3) = (msb / msw, msb / mse);
    let f1l = f1 / f_isf(q, df1, df1kd);
    let f1u = f1 * f_isf(q, df1kd, df1);
    let f3l = f3 / f_isf(q, df1, df2kd);
    let f3u = f3 * f_isf(q, df2kd, df1);
    let single = |f: f64| (f - 1.0) / (f + kf - 1.0);
    let fj = msj / mse;
    let base = nf * (1.0 + (kf - 1.0) * icc2) - kf * icc2;
    let v = df2kd * (kf * icc2 * fj + base).powi(2)
        / (df1 * kf * kf * icc2 * icc2 * fj * fj + base * base);
    let f2u = f_isf(q, nf - 1.0, v);
    let f2l = f_isf(q, v, nf - 1.0);
    let spread = kf * msj + (kf * nf - kf - nf) * mse;
    let l2 = nf * (msb - f2u * mse) / (f2u * spread + nf * msb);
    let u2 = nf * (f2l * msb - mse) / (spread + nf * f2l * msb);
    let mean_of_k = |x: f64| x * kf / (1.0 + x * (kf - 1.0));
    [
        (single(f1l), single(f1u)),
        (l2, u2),
        (single(f3l), single(f3u)),
        (1.0 - 1.0 / f1l, 1.0 - 1.0 / f1u),
        (mean_of_k(l2), mean_of_k(u2)),
        (1.0 - 1.0 / f3l, 1.0 - 1.0 / f3u),
    ]
}

/// The six ICCs of `table` (one row per target, one value per rater in every row, at least
/// two of each), with intervals at `confidence`, as pingouin's `intraclass_corr` computes them.
/// `None` for fewer than two targets or raters or rows of unequal length.
pub fn icc(table: &[Vec<f64>], confidence: Confidence) -> Option<Icc> {
    let n = table.len();
    let k = table.first().map_or(0, Vec::len);
    if n < 2 || k < 2 || table.iter().any(|r| r.len() != k) {
        return None;
    }
    let (nf, kf) = (n as f64, k as f64);
    let grand = table.iter().flatten().sum::<f64>() / (nf * kf);
    let row_means: Vec<f64> = table.iter().map(|r| r.iter().sum::<f64>() / kf).collect();
    let col_means: Vec<f64> = (0..k)
        .map(|j| table.iter().map(|r| r[j]).sum::<f64>() / nf)
        .collect();
    let ss_targets = kf * row_means.iter().map(|m| (m - grand).powi(2)).sum::<f64>();
    let ss_raters = nf * col_means.iter().map(|m| (m - grand).powi(2)).sum::<f64>();
    let ss_error: f64 = table
        .iter()
        .zip(&row_means)
        .flat_map(|(r, rm)| {
            r.iter()
                .zip(&col_means)
                .map(move |(x, cm)| (x - rm - cm + grand).powi(2))
        })
        .sum();
    let msb = ss_targets / (nf - 1.0);
    let msw = (ss_raters + ss_error) / (nf * (kf - 1.0));
    let msj = ss_raters / (kf - 1.0);
    let mse = ss_error / ((nf - 1.0) * (kf - 1.0));
    let icc1 = (msb - msw) / (msb + (kf - 1.0) * msw);
    let icc2 = (msb - mse) / (msb + (kf - 1.0) * mse + kf * (msj - mse) / nf);
    let icc3 = (msb - mse) / (msb + (kf - 1.0) * mse);
    let icc1k = (msb - msw) / msb;
    let icc2k = (msb - mse) / (msb + (msj - mse) / nf);
    let icc3k = (msb - mse) / msb;
    let (df1, df1kd, df2kd) = (nf - 1.0, nf * (kf - 1.0), (nf - 1.0) * (kf - 1.0));
    let f1 = msb / msw;
    let f3 = msb / mse;
    let (p1, p3) = (f_sf(f1, df1, df1kd), f_sf(f3, df1, df2kd));
    let ci = intervals([msb, msw, msj, mse], nf, kf, icc2, confidence.alpha() / 2.0);
    let form = |i: usize, name, mcgraw_wong, icc, one_way: bool| IccForm {
        name,
        mcgraw_wong,
        icc,
        f: if one_way { f1 } else { f3 },
        df1,
        df2: if one_way { df1kd } else { df2kd },
        p: if one_way { p1 } else { p3 },
        lower: ci[i].0,
        upper: ci[i].1,
    };
    let forms = vec![
        form(0, "ICC1", "ICC(1,1)", icc1, true),
        form(1, "ICC2", "ICC(A,1)", icc2, false),
        form(2, "ICC3", "ICC(C,1)", icc3, false),
        form(3, "ICC1k", "ICC(1,k)", icc1k, true),
        form(4, "ICC2k", "ICC(A,k)", icc2k, false),
        form(5, "ICC3k", "ICC(C,k)", icc3k, false),
    ];
    Some(Icc {
        targets: n,
        raters: k,
        forms,
        confidence,
    })
}

/// Krippendorff's distance metric.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Metric {
    /// δ = (v − v')².
    Interval,
    /// δ = (Σ_{g between c and k} n_g − (n_c + n_k)/2)², n_g the pairable values equal to g.
    Ordinal,
}

/// Krippendorff's α of `units` (each unit's values, one per rater who rated it; missing
/// values are simply absent). `None` when it is undefined: no unit with two values, fewer
/// than two distinct pairable values, no expected disagreement, or (ordinal) more than
/// [`ORDINAL_MAX_VALUES`] distinct values.
pub fn krippendorff_alpha(units: &[Vec<f64>], metric: Metric) -> Option<f64> {
    let pairable: Vec<&Vec<f64>> = units.iter().filter(|u| u.len() >= 2).collect();
    if pairable.is_empty()
        || pairable
            .iter()
            .flat_map(|u| u.iter())
            .any(|v| !v.is_finite())
    {
        return None;
    }
    let n = pairable.iter().map(|u| u.len()).sum::<usize>() as f64;
    // Σ_{c,k} n_c n_k δ_ck over ordered pairs of the pairable values (D_e · n(n − 1)) and
    // Σ_u Σ_{c,k} n_uc n_uk δ_ck / (m_u − 1) (D_o · n).
    let (observed, expected) = match metric {
        Metric::Interval => {
            let squares = |values: &mut dyn Iterator<Item = f64>| {
                let v: Vec<f64> = values.collect();
                let mean = v.iter().sum::<f64>() / v.len() as f64;
                2.0 * v.len() as f64 * v.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
            };
            let observed: f64 = pairable
                .iter()
                .map(|u| squares(&mut u.iter().copied()) / (u.len() - 1) as f64)
                .sum();
            let expected = squares(&mut pairable.iter().flat_map(|u| u.iter().copied()));
            (observed, expected)
        }
        Metric::Ordinal => ordinal_disagreements(&pairable)?,
    };
    if expected.is_nan() || expected <= 0.0 {
        return None;
    }
    Some(1.0 - (n - 1.0) * observed / expected)
}

/// The observed and expected sums of [`krippendorff_alpha`] under the ordinal metric.
fn ordinal_disagreements(pairable: &[&Vec<f64>]) -> Option<(f64, f64)> {
    // x + 0.0 turns −0.0 into 0.0: one value, as NumPy's `unique` counts it.
    let mut domain: Vec<f64> = pairable
        .iter()
        .flat_map(|u| u.iter().map(|x| x + 0.0))
        .collect();
    domain.sort_by(f64::total_cmp);
    domain.dedup();
    let v = domain.len();
    if !(2..=ORDINAL_MAX_VALUES).contains(&v) {
        return None;
    }
    let index = |x: f64| {
        domain
            .binary_search_by(|d| d.total_cmp(&(x + 0.0)))
            .unwrap_or(0)
    };
    let mut counts = vec![0.0_f64; v];
    let units: Vec<Vec<(usize, f64)>> = pairable
        .iter()
        .map(|u| {
            let mut idx: Vec<usize> = u.iter().map(|x| index(*x)).collect();
            idx.sort_unstable();
            let mut grouped: Vec<(usize, f64)> = Vec::new();
            for i in idx {
                counts[i] += 1.0;
                match grouped.last_mut() {
                    Some((last, c)) if *last == i => *c += 1.0,
                    _ => grouped.push((i, 1.0)),
                }
            }
            grouped
        })
        .collect();
    // prefix[i] = n_0 + … + n_{i−1}.
    let mut prefix = vec![0.0; v + 1];
    for i in 0..v {
        prefix[i + 1] = prefix[i] + counts[i];
    }
    let delta = |c: usize, k: usize| {
        let (c, k) = (c.min(k), c.max(k));
        (prefix[k + 1] - prefix[c] - f64::midpoint(counts[c], counts[k])).powi(2)
    };
    let mut expected = 0.0;
    for c in 0..v {
        for k in c + 1..v {
            expected += 2.0 * counts[c] * counts[k] * delta(c, k);
        }
    }
    let mut observed = 0.0;
    for (u, unit) in units.iter().enumerate() {
        let m = pairable[u].len() as f64;
        let mut within = 0.0;
        for (a, &(c, nc)) in unit.iter().enumerate() {
            for &(k, nk) in &unit[a + 1..] {
                within += 2.0 * nc * nk * delta(c, k);
            }
        }
        observed += within / (m - 1.0);
    }
    Some((observed, expected))
}

/// Reliability of a study's ratings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reliability {
    /// Subjects (raters).
    pub subjects: usize,
    /// Conditions rated (targets).
    pub conditions: usize,
    /// Conditions rated by every subject: the ICC's targets.
    pub complete_conditions: usize,
    /// The ICCs of the complete conditions (`None`: fewer than two subjects or complete
    /// conditions).
    pub icc: Option<Icc>,
    /// Krippendorff's α, interval metric, over every condition.
    pub alpha_interval: Option<f64>,
    /// Krippendorff's α, ordinal metric.
    pub alpha_ordinal: Option<f64>,
    /// Values in conditions rated by at least two subjects (α's pairable values).
    pub pairable_values: usize,
    /// Distinct values among them.
    pub distinct_values: usize,
}

/// Each subject's mean per condition of `ratings`: per condition (in id order), its
/// (subject, mean) pairs in subject order. A stable sort keeps each cell's scores in their
/// order, so a mean is the same sum whatever else the study holds.
fn means_by_condition(ratings: &[Rating]) -> Vec<Vec<(u32, f64)>> {
    let mut rows: Vec<(u32, u32, f64)> = ratings
        .iter()
        .map(|r| (r.condition, r.subject, r.score))
        .collect();
    rows.sort_by_key(|&(c, s, _)| (c, s));
    let mut out: Vec<Vec<(u32, f64)>> = Vec::new();
    let mut at = 0;
    while at < rows.len() {
        let (c, s, _) = rows[at];
        let end = at
            + rows[at..]
                .iter()
                .take_while(|r| r.0 == c && r.1 == s)
                .count();
        let mean = rows[at..end].iter().map(|r| r.2).sum::<f64>() / (end - at) as f64;
        match out.last_mut() {
            Some(unit) if at > 0 && rows[at - 1].0 == c => unit.push((s, mean)),
            _ => out.push(vec![(s, mean)]),
        }
        at = end;
    }
    out
}

/// The reliability of `ratings` (each subject's repeats of a condition averaged first), ICC
/// intervals at `confidence`; `None` without ratings.
pub fn analyze(ratings: &[Rating], confidence: Confidence) -> Option<Reliability> {
    if ratings.is_empty() || ratings.iter().any(|r| !r.score.is_finite()) {
        return None;
    }
    let by_condition = means_by_condition(ratings);
    let mut subjects: Vec<u32> = ratings.iter().map(|r| r.subject).collect();
    subjects.sort_unstable();
    subjects.dedup();
    let complete: Vec<Vec<f64>> = by_condition
        .iter()
        .filter(|m| m.len() == subjects.len())
        .map(|m| m.iter().map(|p| p.1).collect())
        .collect();
    let units: Vec<Vec<f64>> = by_condition
        .iter()
        .map(|m| m.iter().map(|p| p.1).collect())
        .collect();
    let mut pairable: Vec<f64> = units
        .iter()
        .filter(|u| u.len() >= 2)
        .flatten()
        .map(|x| x + 0.0)
        .collect();
    let pairable_values = pairable.len();
    pairable.sort_by(f64::total_cmp);
    pairable.dedup();
    Some(Reliability {
        subjects: subjects.len(),
        conditions: by_condition.len(),
        complete_conditions: complete.len(),
        icc: icc(&complete, confidence),
        alpha_interval: krippendorff_alpha(&units, Metric::Interval),
        alpha_ordinal: krippendorff_alpha(&units, Metric::Ordinal),
        pairable_values,
        distinct_values: pairable.len(),
    })
}

/// What each ICC form is, for the table.
fn describe(name: &str) -> &'static str {
    match name {
        "ICC1" => "one-way random, single rater",
        "ICC2" => "two-way random, absolute agreement, single rater",
        "ICC3" => "two-way mixed, consistency, single rater",
        "ICC1k" => "one-way random, mean of k raters",
        "ICC2k" => "two-way random, absolute agreement, mean of k raters",
        _ => "two-way mixed, consistency, mean of k raters",
    }
}

/// The ICC table.
fn icc_table(icc: &Icc) -> Table {
    let conf = format!("{:.0} % CI", icc.confidence.percent());
    Table {
        name: "icc".to_owned(),
        caption: format!(
            "Intraclass correlations ({} conditions × {} subjects; pingouin's forms)",
            icc.targets, icc.raters
        ),
        columns: [
            "Form",
            "McGraw & Wong",
            "Model",
            "ICC",
            "F",
            "df1",
            "df2",
            "p",
            &conf,
        ]
        .map(str::to_owned)
        .to_vec(),
        rows: icc
            .forms
            .iter()
            .map(|f| {
                vec![
                    f.name.to_owned(),
                    f.mcgraw_wong.to_owned(),
                    describe(f.name).to_owned(),
                    fmt_opt(Some(f.icc), 3),
                    fmt_opt(Some(f.f), 2),
                    fmt_opt(Some(f.df1), 0),
                    fmt_opt(Some(f.df2), 0),
                    fmt_p(Some(f.p)),
                    if f.lower.is_finite() && f.upper.is_finite() {
                        format!("{:.3} to {:.3}", f.lower, f.upper)
                    } else {
                        crate::tables::UNDEFINED.to_owned()
                    },
                ]
            })
            .collect(),
    }
}

/// The "Inter-rater reliability" section of a rating study's report (none without
/// `reliability`, i.e. without ratings).
pub fn section(report: &mut Report, reliability: Option<&Reliability>, data: &StudyData) {
    let Some(r) = reliability else { return };
    let (on, mean) = if data.dscqs.is_empty() {
        ("its score", "MOS")
    } else {
        ("its reference − test difference", "DMOS")
    };
    let s = report.section("Inter-rater reliability");
    s.text(format!(
        "Targets are the {} rated conditions, raters the {} subjects, and a value is a subject's mean over the repeats of a condition ({on}). BT.500 / P.910 users usually report the two-way random, absolute-agreement ICC: ICC(2,1) for one subject's ratings and ICC(2,k) for the mean of the k subjects (the reliability of the {mean}).",
        r.conditions, r.subjects
    ));
    let left_out = r.conditions - r.complete_conditions;
    let design = if left_out == 0 {
        "Every subject rated every condition, so the ICC uses them all.".to_owned()
    } else {
        format!(
            "The ICC needs every subject's value of every target: {left_out} of {} conditions not rated by every subject are left out of it (listwise deletion, as pingouin's nan_policy=\"omit\"); Krippendorff's α uses every condition rated by at least two subjects.",
            r.conditions
        )
    };
    match &r.icc {
        Some(icc) => {
            let pick = |name: &str| icc.form(name).map(|f| f.icc);
            s.text(format!(
                "{design} ICC(2,1) = {}, ICC(2,k) = {} (k = {}).",
                fmt_opt(pick("ICC2"), 3),
                fmt_opt(pick("ICC2k"), 3),
                icc.raters
            ));
            if icc.forms.iter().any(|f| !f.icc.is_finite()) {
                s.text("Some ICCs are undefined (n/a): the values do not vary between conditions or within them (all equal, or no error variance).");
            }
            s.table(icc_table(icc));
        }
        None => {
            s.text(format!(
                "{design} No ICC: it needs at least two subjects and two conditions rated by every subject ({} subjects, {} such conditions).",
                r.subjects, r.complete_conditions
            ));
        }
    }
    let alpha_row = |metric: &str, value: Option<f64>| {
        vec![
            metric.to_owned(),
            fmt_opt(value, 3),
            r.pairable_values.to_string(),
            r.distinct_values.to_string(),
        ]
    };
    if r.alpha_interval.is_none() {
        s.text("Krippendorff's α is undefined (n/a) here: it needs a condition rated by two subjects and values that differ.");
    }
    s.table(Table {
        name: "krippendorff_alpha".to_owned(),
        caption: "Krippendorff's α over every condition (missing values allowed)".to_owned(),
        columns: ["Metric", "α", "Pairable values", "Distinct values"]
            .map(str::to_owned)
            .to_vec(),
        rows: vec![
            alpha_row("interval", r.alpha_interval),
            alpha_row("ordinal", r.alpha_ordinal),
        ],
    });
}
