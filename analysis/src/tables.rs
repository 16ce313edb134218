//! Result tables shaped like the seeds' tables, written as CSV, Markdown and LaTeX (booktabs).
//!
//! Undefined statistics print as `n/a` (never `NaN`).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::descriptive::{CiMethod, ConditionStats};
use crate::findings::{ConditionInfo, RateFinding};
use crate::screening::ScreeningReport;
use crate::staircase::ThresholdSummary;
use crate::ttest::{Alternative, TTestOutcome};

/// Text printed for a statistic that is undefined for the data.
pub const UNDEFINED: &str = "n/a";

/// A rectangular table of already formatted cells.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Table {
    /// File stem, e.g. `mos` (written as `mos.csv`, `mos.md`, `mos.tex`).
    pub name: String,
    /// Caption, as in the seeds ("Table 3.1: Results of user study …").
    pub caption: String,
    /// Column headers.
    pub columns: Vec<String>,
    /// Rows; each has `columns.len()` cells.
    pub rows: Vec<Vec<String>>,
}

/// Formats a number with `decimals` decimals, or [`UNDEFINED`].
pub fn fmt_opt(value: Option<f64>, decimals: usize) -> String {
    match value {
        Some(v) if v.is_finite() => format!("{v:.decimals$}"),
        _ => UNDEFINED.to_owned(),
    }
}

/// Formats a p value as papers print it (APA): two significant digits, `< 0.001` below
/// 0.001 (`0.053`, `0.016`, `0.12`, `1.0`).
pub fn fmt_p(p: Option<f64>) -> String {
    match p {
        Some(v) if v.is_finite() && v < 0.001 => "< 0.001".to_owned(),
        Some(v) if v.is_finite() => {
            // Round to two significant digits first, so 0.0996 prints as 0.10, not 0.100.
            let rounded: f64 = format!("{v:.1e}").parse().unwrap_or(v);
            let decimals = (1 - rounded.log10().floor() as i32).max(1) as usize;
            format!("{rounded:.decimals$}")
        }
        _ => UNDEFINED.to_owned(),
    }
}

/// What a paired t-test was, as its table says it: kind and tails.
pub fn test_kind(alternative: Alternative) -> &'static str {
    match alternative {
        Alternative::TwoSided => "paired t, two-tailed",
        Alternative::Greater => "paired t, one-tailed (A > B)",
        Alternative::Less => "paired t, one-tailed (A < B)",
    }
}

/// `s` as one RFC 4180 CSV field, quoted by the `csv` crate (quotes doubled) when it holds a
/// comma, a quote or a line break: for cells made once and written on many rows.
pub(crate) fn csv_field(s: &str) -> String {
    let mut w = csv::WriterBuilder::new()
        .buffer_capacity(2 * s.len() + 2)
        .from_writer(Vec::new());
    // Writing into memory cannot fail.
    let _ = w.write_field(s);
    let bytes = w.into_inner().unwrap_or_default();
    String::from_utf8(bytes).unwrap_or_default()
}

/// Escapes `s` for Markdown (GitHub's) so that it reads as the text it is, in a paragraph or
/// a table cell: nothing in it starts markup (emphasis, code, a link or image, an HTML tag,
/// an entity, strikethrough, an address made a link) or ends a table cell, and line breaks
/// become spaces. A backslash goes before `\\`, `` ` ``, `*`, `~`, `|`, `@`, `_` unless it is
/// inside a word, `]` before `(` or `[`, `<` before a letter, `/`, `!` or `?`, `&` before a
/// letter, digit or `#`, `:` before `//` and `.` after `www`; text without them (ids,
/// numbers, "<0.001", "[0.2, 0.4]") is unchanged. For text a participant controls (subject
/// ids, a browser's user agent), which the HTML report escapes with [`html_escape`].
pub fn md_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    push_md_cell(&mut out, s);
    out
}

/// Appends [`md_escape`] of `s` to `out` (a table cell, a caption).
fn push_md_cell(out: &mut String, s: &str) {
    let b = s.as_bytes();
    let plain = !b.iter().any(|c| {
        matches!(
            c,
            b'\\' | b'`' | b'*' | b'~' | b'|' | b'@' | b'_' | b']' | b'<' | b'&' | b'\n' | b'\r'
        )
    }) && !s.contains("://")
        && !b.windows(4).any(|w| w.eq_ignore_ascii_case(b"www."));
    if plain {
        out.push_str(s);
        return;
    }
    let mut prev: Option<char> = None;
    for (i, c) in s.char_indices() {
        let rest = &s[i + c.len_utf8()..];
        let next = rest.chars().next();
        let escape = match c {
            '\n' | '\r' => {
                out.push(' ');
                prev = Some(' ');
                continue;
            }
            '\\' | '`' | '*' | '~' | '|' | '@' => true,
            '_' => {
                !(prev.is_some_and(char::is_alphanumeric)
                    && next.is_some_and(char::is_alphanumeric))
            }
            ']' => matches!(next, Some('(' | '[')),
            '<' => next.is_some_and(|n| n.is_ascii_alphabetic() || matches!(n, '/' | '!' | '?')),
            '&' => next.is_some_and(|n| n.is_ascii_alphanumeric() || n == '#'),
            ':' => rest.starts_with("//"),
            '.' => i >= 3 && b[i - 3..i].eq_ignore_ascii_case(b"www"),
            _ => false,
        };
        if escape {
            out.push('\\');
        }
        out.push(c);
        prev = Some(c);
    }
}

/// Escapes LaTeX special characters.
pub fn latex_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    push_latex_escaped(&mut out, s);
    out
}

/// Appends [`latex_escape`] of `s` to `out`.
fn push_latex_escaped(out: &mut String, s: &str) {
    for c in s.chars() {
        match c {
            '&' | '%' | '$' | '#' | '_' | '{' | '}' => {
                out.push('\\');
                out.push(c);
            }
            '~' => out.push_str("\\textasciitilde{}"),
            '^' => out.push_str("\\textasciicircum{}"),
            '\\' => out.push_str("\\textbackslash{}"),
            '±' => out.push_str("$\\pm$"),
            _ => out.push(c),
        }
    }
}

/// Appends `cells`, each written by `push` and separated by `between`.
fn push_joined(out: &mut String, cells: &[String], between: &str, push: fn(&mut String, &str)) {
    for (i, c) in cells.iter().enumerate() {
        if i > 0 {
            out.push_str(between);
        }
        push(out, c);
    }
}

impl Table {
    /// RFC 4180 CSV with a header row (written by the `csv` crate).
    pub fn to_csv(&self) -> String {
        let mut w = csv::WriterBuilder::new()
            .flexible(true)
            .from_writer(Vec::new());
        for cells in std::iter::once(&self.columns).chain(&self.rows) {
            // Writing into memory cannot fail.
            let _ = w.write_record(cells);
        }
        let bytes = w.into_inner().unwrap_or_default();
        String::from_utf8(bytes).unwrap_or_default()
    }

    /// GitHub-flavoured Markdown with the caption in bold above.
    pub fn to_markdown(&self) -> String {
        let mut out = String::from("**");
        push_md_cell(&mut out, &self.caption);
        out.push_str("**\n\n");
        for (i, cells) in std::iter::once(&self.columns).chain(&self.rows).enumerate() {
            out.push_str("| ");
            push_joined(&mut out, cells, " | ", push_md_cell);
            out.push_str(" |\n");
            if i == 0 {
                out.push('|');
                for _ in &self.columns {
                    out.push_str(" --- |");
                }
                out.push('\n');
            }
        }
        out
    }

    /// A LaTeX `table` with a booktabs `tabular` (needs `\usepackage{booktabs}`).
    pub fn to_latex(&self) -> String {
        let mut out = String::from("\\begin{table}[ht]\n\\centering\n");
        let _ = writeln!(out, "\\caption{{{}}}", latex_escape(&self.caption));
        let _ = writeln!(out, "\\label{{tab:{}}}", latex_escape(&self.name));
        let _ = writeln!(
            out,
            "\\begin{{tabular}}{{l{}}}",
            "r".repeat(self.columns.len().saturating_sub(1))
        );
        out.push_str("\\toprule\n");
        for (i, cells) in std::iter::once(&self.columns).chain(&self.rows).enumerate() {
            push_joined(&mut out, cells, " & ", push_latex_escaped);
            out.push_str(" \\\\\n");
            if i == 0 {
                out.push_str("\\midrule\n");
            }
        }
        out.push_str("\\bottomrule\n\\end{tabular}\n\\end{table}\n");
        out
    }

    /// An HTML `<table>` with escaped cells.
    pub fn to_html(&self) -> String {
        let mut out = String::from("<table>\n<caption>");
        push_html_escaped(&mut out, &self.caption);
        out.push_str("</caption>\n<thead><tr>");
        for c in &self.columns {
            out.push_str("<th>");
            push_html_escaped(&mut out, c);
            out.push_str("</th>");
        }
        out.push_str("</tr></thead>\n<tbody>\n");
        for r in &self.rows {
            out.push_str("<tr>");
            for c in r {
                out.push_str("<td>");
                push_html_escaped(&mut out, c);
                out.push_str("</td>");
            }
            out.push_str("</tr>\n");
        }
        out.push_str("</tbody>\n</table>\n");
        out
    }
}

/// Escapes `&`, `<`, `>` and `"` for HTML.
pub fn html_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    push_html_escaped(&mut out, s);
    out
}

/// Appends [`html_escape`] of `s` to `out`.
fn push_html_escaped(out: &mut String, s: &str) {
    if s.contains(['&', '<', '>', '"']) {
        out.push_str(
            &s.replace('&', "&amp;")
                .replace('<', "&lt;")
                .replace('>', "&gt;")
                .replace('"', "&quot;"),
        );
    } else {
        out.push_str(s);
    }
}

fn ratio(cr: Option<f64>) -> String {
    cr.map_or_else(
        || "ref".to_owned(),
        |x| {
            if x.fract() == 0.0 {
                format!("{x:.0}:1")
            } else {
                format!("{x:.1}:1")
            }
        },
    )
}

/// Mean ± CI per condition, shaped like thesis Table 3.1 (clip, CR, average score, SD, CI).
pub fn mos_table(
    name: &str,
    caption: &str,
    conditions: &[ConditionInfo],
    stats: &[ConditionStats],
    method: CiMethod,
) -> Table {
    let by_id: BTreeMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
    let mut rows: Vec<(String, String, f64, Vec<String>)> = stats
        .iter()
        .map(|s| {
            let info = by_id.get(&s.condition);
            let codec = info.map_or_else(|| format!("condition {}", s.condition), |i| i.method());
            let clip = info.map_or_else(String::new, |i| i.clip.clone());
            let cr = info.and_then(|i| i.compression_ratio);
            let ci = s.summary.ci(method);
            let cells = vec![
                codec.clone(),
                clip.clone(),
                ratio(cr),
                s.summary.n.to_string(),
                format!("{:.3}", s.summary.mean),
                fmt_opt(s.summary.sd, 3),
                fmt_opt(ci.map(|c| c.half_width), 3),
                fmt_opt(ci.map(|c| c.lower), 3),
                fmt_opt(ci.map(|c| c.upper), 3),
            ];
            (codec, clip, cr.unwrap_or(0.0), cells)
        })
        .collect();
    rows.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.total_cmp(&b.2)));
    let ci_label = match method {
        CiMethod::StudentT => "CI ± (t)",
        CiMethod::NormalZ => "CI ± (z)",
    };
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: [
            "Codec", "Clip", "CR", "n", "Mean", "SD", ci_label, "Lower", "Upper",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows.into_iter().map(|r| r.3).collect(),
    }
}

/// One row of a comparison table (thesis Tables 3.2 and 3.3).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ComparisonRow {
    /// Clip.
    pub clip: String,
    /// Compression ratio.
    pub compression_ratio: Option<f64>,
    /// Label and mean of the first method.
    pub first: (String, f64),
    /// Label and mean of the second method.
    pub second: (String, f64),
    /// The alternative hypothesis tested (also in `test` when it is defined).
    pub alternative: Alternative,
    /// The test.
    pub test: TTestOutcome,
    /// Holm-adjusted p value within the table's family.
    pub p_holm: Option<f64>,
}

/// A t-test table like thesis Table 3.2: clip, CR, both means, t, df, p, Holm p, effect size.
pub fn ttest_table(name: &str, caption: &str, rows: &[ComparisonRow]) -> Table {
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: [
            "Clip",
            "CR",
            "Method A",
            "Mean A",
            "Method B",
            "Mean B",
            "Test",
            "t",
            "df",
            "p",
            "p (Holm)",
            "Effect size",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                let (t, df, p, d) = match &r.test {
                    Ok(t) => (
                        fmt_opt(Some(t.t), 3),
                        fmt_opt(Some(t.df), 2),
                        fmt_p(Some(t.p)),
                        fmt_opt(Some(t.effect_size), 3),
                    ),
                    Err(u) => {
                        let why = u.to_string();
                        (
                            why,
                            UNDEFINED.to_owned(),
                            UNDEFINED.to_owned(),
                            UNDEFINED.to_owned(),
                        )
                    }
                };
                vec![
                    r.clip.clone(),
                    ratio(r.compression_ratio),
                    r.first.0.clone(),
                    format!("{:.3}", r.first.1),
                    r.second.0.clone(),
                    format!("{:.3}", r.second.1),
                    test_kind(r.alternative).to_owned(),
                    t,
                    df,
                    p,
                    fmt_p(r.p_holm),
                    d,
                ]
            })
            .collect(),
    }
}

/// DMOS per codec (rows) and clip (columns), shaped like thesis Table 6.3 (weightings × motions).
pub fn dmos_table(
    name: &str,
    caption: &str,
    conditions: &[ConditionInfo],
    stats: &[ConditionStats],
) -> Table {
    let by_id: BTreeMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
    let mut clips: Vec<String> = Vec::new();
    let mut grid: BTreeMap<String, BTreeMap<String, f64>> = BTreeMap::new();
    for s in stats {
        let Some(info) = by_id.get(&s.condition) else {
            continue;
        };
        let row = match info.compression_ratio {
            Some(cr) => format!("{} @ {}", info.method(), ratio(Some(cr))),
            None => info.method(),
        };
        if !clips.contains(&info.clip) {
            clips.push(info.clip.clone());
        }
        grid.entry(row)
            .or_default()
            .insert(info.clip.clone(), s.summary.mean);
    }
    clips.sort();
    let mut columns = vec!["Condition".to_owned()];
    columns.extend(clips.iter().cloned());
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns,
        rows: grid
            .into_iter()
            .map(|(row, cells)| {
                let mut r = vec![row];
                r.extend(clips.iter().map(|c| fmt_opt(cells.get(c).copied(), 2)));
                r
            })
            .collect(),
    }
}

/// Staircase threshold summary like thesis §5.4 (subjects, mean, SD, min, max, CI) of the
/// study's k, to the grid's decimals plus one ([`ThresholdSummary::decimals`]).
pub fn threshold_table(name: &str, caption: &str, t: &ThresholdSummary) -> Table {
    let s = t.summary.as_ref();
    let ci = s.and_then(|s| s.ci_t);
    let d = t.decimals;
    let percent = s.map_or(95.0, |s| s.confidence.percent());
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: [
            "Subjects",
            "Unconverged",
            "Last k reversals",
            "Mean",
            "SD",
            "Min",
            "Max",
        ]
        .map(String::from)
        .into_iter()
        .chain([
            format!("{percent:.0}% CI lower"),
            format!("{percent:.0}% CI upper"),
        ])
        .collect(),
        rows: vec![vec![
            t.per_subject.len().to_string(),
            t.unconverged.len().to_string(),
            t.last_reversals.to_string(),
            fmt_opt(s.map(|s| s.mean), d),
            fmt_opt(s.and_then(|s| s.sd), d),
            fmt_opt(t.min, d),
            fmt_opt(t.max, d),
            fmt_opt(ci.map(|c| c.lower), d),
            fmt_opt(ci.map(|c| c.upper), d),
        ]],
    }
}

/// Every up-down track's reversals and its two estimates side by side: the mean of the
/// study's last k reversals and of the last even number (with the count used).
pub fn staircase_tracks_table(
    name: &str,
    caption: &str,
    t: &ThresholdSummary,
    subject: &dyn Fn(u32) -> String,
) -> Table {
    let d = t.decimals;
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: vec![
            "Subject".to_owned(),
            "Track".to_owned(),
            "Reversals".to_owned(),
            format!("Last {} reversals", t.last_reversals),
            format!("Last {} reversals (even)", t.even_k),
        ],
        rows: t
            .tracks
            .iter()
            .map(|r| {
                vec![
                    subject(r.subject),
                    r.label.clone(),
                    r.reversals.to_string(),
                    fmt_opt(r.last_k, d),
                    r.even.map_or_else(
                        || UNDEFINED.to_owned(),
                        |(k, v)| {
                            if k == t.even_k {
                                format!("{v:.d$}")
                            } else {
                                format!("{v:.d$} (last {k})")
                            }
                        },
                    ),
                ]
            })
            .collect(),
    }
}

/// The threshold to cite per condition and across conditions: the even-k estimate's mean
/// across subjects with its t interval and its nearest grid level, the study's k mean beside
/// it.
pub fn cited_threshold_table(name: &str, caption: &str, t: &ThresholdSummary) -> Table {
    let d = t.decimals;
    let percent = t
        .cited
        .first()
        .map_or(95.0, |c| c.even.confidence.percent());
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: vec![
            "Condition".to_owned(),
            "Subjects".to_owned(),
            format!("Last {} reversals", t.last_reversals),
            format!("Last {} reversals (cite)", t.even_k),
            "SD".to_owned(),
            format!("{percent:.0} % CI"),
            "Nearest level".to_owned(),
        ],
        rows: t
            .cited
            .iter()
            .map(|c| {
                let ci = c.even.ci_t;
                vec![
                    c.condition
                        .clone()
                        .unwrap_or_else(|| "all conditions".to_owned()),
                    c.even.n.to_string(),
                    fmt_opt(c.last_k_mean, d),
                    format!("{:.d$}", c.even.mean),
                    fmt_opt(c.even.sd, d),
                    ci.map_or_else(
                        || UNDEFINED.to_owned(),
                        |ci| format!("{:.d$} – {:.d$}", ci.lower, ci.upper),
                    ),
                    fmt_opt(c.on_grid, d - 1),
                ]
            })
            .collect(),
    }
}

/// BT.500 screening counts and decisions per observer, subjects named by `subject`.
pub fn screening_table(
    name: &str,
    caption: &str,
    report: &ScreeningReport,
    subject: &dyn Fn(u32) -> String,
) -> Table {
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: [
            "Subject",
            "P",
            "Q",
            "Presentations",
            "(P+Q)/JKR",
            "|P−Q|/(P+Q)",
            "Rejected",
        ]
        .map(String::from)
        .to_vec(),
        rows: report
            .observers
            .iter()
            .map(|o| {
                vec![
                    subject(o.subject),
                    o.p.to_string(),
                    o.q.to_string(),
                    o.presentations.to_string(),
                    format!("{:.3}", o.outlier_fraction),
                    fmt_opt(o.asymmetry, 3),
                    if o.rejected {
                        "yes".to_owned()
                    } else {
                        "no".to_owned()
                    },
                ]
            })
            .collect(),
    }
}

/// The rate findings: per codec and clip, the highest CR within the limit.
pub fn findings_table(name: &str, caption: &str, findings: &[RateFinding]) -> Table {
    Table {
        name: name.to_owned(),
        caption: caption.to_owned(),
        columns: ["Codec", "Clip", "Ratios tested", "Highest passing CR"]
            .map(String::from)
            .to_vec(),
        rows: findings
            .iter()
            .map(|f| {
                vec![
                    f.codec.clone(),
                    f.clip.clone(),
                    f.points.len().to_string(),
                    f.highest_passing_ratio
                        .map_or_else(|| "none".to_owned(), |x| ratio(Some(x))),
                ]
            })
            .collect(),
    }
}
