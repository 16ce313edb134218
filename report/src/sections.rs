//! The report's sections that are not the analysis's own: incomplete sessions, display,
//! MUSHRA, exclusions. Text a participant controls (subject ids, so session names) goes into
//! their paragraphs through [`md_escape`], as the tables' cells do, so that `report.md` shows
//! it as it is and nothing in it is read as markup.

use analysis::tables::md_escape;

/// The "Incomplete sessions" section of a report made with `--allow-incomplete`.
pub(crate) fn incomplete(
    report: &mut analysis::report::Report,
    incomplete: &[lab::integrity::Problem],
) {
    if !incomplete.is_empty() {
        let section = report.section("Incomplete sessions");
        section.text(
            "Reported with --allow-incomplete: trials are missing at the end of these sessions; \
             the trials they logged are in every table.",
        );
        for p in incomplete {
            section.text(md_escape(&p.to_string()));
        }
    }
}

/// The "Display" section: every session's display and frame record, sessions over
/// `drop_limit` percent dropped frames flagged (and warned about).
pub(crate) fn display(
    report: &mut analysis::report::Report,
    displays: &[analysis::display::SessionDisplay],
    drop_limit: f64,
    warn: &mut dyn FnMut(&str),
) {
    let flagged: Vec<String> = displays
        .iter()
        .filter(|d| d.flagged)
        .map(|d| md_escape(&d.session))
        .collect();
    let display = report.section("Display");
    display.text(if flagged.is_empty() {
        format!(
            "The display each session ran on, as it measured it; no session dropped more than {drop_limit} % of its frames."
        )
    } else {
        format!(
            "The display each session ran on, as it measured it. Over {} % of the frames dropped (--drop-limit): {}; their stimuli did not play as made.",
            drop_limit,
            flagged.join(", ")
        )
    });
    display.table(analysis::display::display_table(displays, drop_limit));
    if let Some(t) = analysis::display::browser_table(displays) {
        display.table(t);
    }
    for d in displays.iter().filter(|d| d.flagged) {
        warn(&format!(
            "{} dropped more than {drop_limit} % of its frames",
            d.session
        ));
    }
}

/// A MUSHRA study's statistics and the rules they followed.
pub(crate) struct MushraReport {
    analysis: analysis::mushra::MushraAnalysis,
    rules: analysis::mushra::Rules,
}

impl MushraReport {
    /// Adds the "MUSHRA" section to `report`.
    pub(crate) fn add_to(
        &self,
        report: &mut analysis::report::Report,
        converted: &analysis::from_results::ConvertedResults,
    ) {
        let data = &converted.data;
        self.analysis.section(
            report,
            &converted.stimuli,
            &data.conditions,
            &|s| data.subject_name(s),
            &self.rules,
        );
    }
}

/// The MUSHRA statistics (BS.1534-3 post-screening, each stimulus over the assessors kept)
/// of a MUSHRA study, `None` for other protocols: its anchors are the study file's, found
/// among the rated stimuli by id.
pub(crate) fn mushra_analysis(
    study: &protocols::StudyDefinition,
    converted: &analysis::from_results::ConvertedResults,
    confidence: analysis::Confidence,
) -> anyhow::Result<Option<MushraReport>> {
    use analysis::mushra::{Rules, analyze};
    let Some(m) = &study.mushra else {
        return Ok(None);
    };
    let anchors: std::collections::BTreeSet<u32> = converted
        .stimuli
        .iter()
        .enumerate()
        .filter(|(_, s)| m.is_anchor(s))
        .map(|(i, _)| i as u32)
        .collect();
    let rules = Rules {
        reference_below: m.reference_below,
        anchor_above: m.anchor_above,
        max_fraction: m.max_fraction,
        exclude_on_anchor: m.anchor_rule == protocols::study::AnchorRule::Exclude,
    };
    let data = &converted.data;
    let analysis = analyze(
        &data.ratings,
        &data.conditions,
        &converted.stimuli,
        &anchors,
        &rules,
        confidence,
    )?;
    Ok(Some(MushraReport { analysis, rules }))
}

/// The "Exclusions" section of a crowd study (gold trials, or trials left out because the
/// page was hidden): who the `[crowdsourcing]` rules left out of the statistics, and why.
pub(crate) fn exclusions(
    report: &mut analysis::report::Report,
    exclusions: &[analysis::exclusions::SessionExclusion],
    crowd: &protocols::study::CrowdsourcingSettings,
) {
    if crowd.gold.is_empty()
        && !exclusions
            .iter()
            .any(analysis::exclusions::SessionExclusion::any)
    {
        return;
    }
    let left_out: Vec<String> = exclusions
        .iter()
        .filter(|e| e.excluded)
        .map(|e| md_escape(&e.session))
        .collect();
    let fast: Vec<String> = exclusions
        .iter()
        .filter(|e| !e.too_fast.is_empty())
        .map(|e| md_escape(&e.session))
        .collect();
    let section = report.section("Exclusions");
    section.text(format!(
        "The study's crowd rules ([crowdsourcing] in the study file) left out {} of {} sessions{}.",
        left_out.len(),
        exclusions.len(),
        if left_out.is_empty() {
            String::new()
        } else {
            format!(" ({})", left_out.join(", "))
        }
    ));
    if !fast.is_empty() {
        section.text(format!(
            "{} answered trials sooner after the answer before than their stimuli play, which \
             no subject watching them can ({}); {} (too_fast = \"{}\").",
            if fast.len() == 1 {
                "One session".to_owned()
            } else {
                format!("{} sessions", fast.len())
            },
            fast.join(", "),
            match crowd.too_fast {
                protocols::study::TooFastRule::Exclude => "they are left out",
                protocols::study::TooFastRule::Flag => "they are kept, flagged",
            },
            crowd.too_fast.word()
        ));
    }
    section.table(analysis::exclusions::exclusions_table(exclusions, crowd));
}

#[cfg(test)]
mod tests {
    use super::*;
    use analysis::display::SessionDisplay;
    use analysis::exclusions::SessionExclusion;

    /// What a participant can put in a session's name (their subject id, in a folder written
    /// by hand or another tool) and in their browser's user agent.
    const NASTY: [&str; 9] = [
        "a|b",
        "*bold*",
        "<script>alert(1)</script>",
        "line\nbreak",
        "`code`",
        "[link](http://x)",
        "_em_",
        "www.example.org",
        "a@b.example",
    ];

    /// `|` not escaped by a backslash, in `line`.
    fn cell_breaks(line: &str) -> usize {
        let mut n = 0;
        let mut backslashes = 0;
        for c in line.chars() {
            if c == '|' && backslashes % 2 == 0 {
                n += 1;
            }
            backslashes = if c == '\\' { backslashes + 1 } else { 0 };
        }
        n
    }

    /// The display and exclusions sections (paragraphs naming sessions, the display and
    /// browser tables, the exclusions table) over sessions named and browsed with Markdown:
    /// in `report.md` every table row keeps its header's columns, line breaks stay inside
    /// their line, and every character that would start markup is escaped.
    #[test]
    fn participant_text_reads_as_text_in_report_md() {
        let displays: Vec<SessionDisplay> = NASTY
            .iter()
            .map(|s| SessionDisplay {
                session: format!("{s} session 1"),
                description: Some(format!("browser: {s}")),
                refresh_hz: Some(60.0),
                timed_trials: 1,
                frames_shown: 90,
                dropped: 10,
                mean_interval_sd_ms: Some(1.0),
                dropped_percent: Some(10.0),
                flagged: true,
                browser: Some(results::store::BrowserInfo {
                    user_agent: (*s).to_string(),
                    webgl_renderer: (*s).to_string(),
                    screen_px: [1920, 1080],
                    window_px: [1280, 800],
                    device_pixel_ratio: 1.0,
                    refresh_hz: 60.0,
                    fullscreen: false,
                    hidden_trials: Vec::new(),
                    windowed_trials: Vec::new(),
                }),
                viewing: None,
                group: None,
                subject: (*s).to_string(),
                subject_fields: std::collections::BTreeMap::new(),
            })
            .collect();
        let excluded: Vec<SessionExclusion> = displays
            .iter()
            .map(|d| SessionExclusion {
                session: d.session.clone(),
                gold_trials: 0,
                gold_failed: Vec::new(),
                hidden_trials: vec![1],
                too_fast: vec![analysis::exclusions::TooFast {
                    trial: 2,
                    after_ms: 10.0,
                    need_ms: 4000.0,
                }],
                excluded: true,
            })
            .collect();
        let mut report = analysis::report::Report::new("escaping");
        let mut warned = Vec::new();
        display(&mut report, &displays, 5.0, &mut |w| {
            warned.push(w.to_string());
        });
        exclusions(
            &mut report,
            &excluded,
            &protocols::study::CrowdsourcingSettings::default(),
        );
        // Warnings go to a terminal, not to Markdown: as they are.
        assert!(warned.iter().any(|w| w.starts_with("*bold* session 1")));
        let dir = std::env::temp_dir().join(format!("report-md-escape-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        report
            .write(&dir, false, files::Mode::Replace)
            .unwrap_or_else(|e| panic!("{e}"));
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap_or_default();
        let _ = std::fs::remove_dir_all(&dir);

        // Each table's rows have its header's columns.
        let mut tables = 0;
        let mut header: Option<usize> = None;
        for line in md.lines() {
            if line.starts_with('|') {
                let n = cell_breaks(line);
                let want = *header.get_or_insert(n);
                assert_eq!(n, want, "{line}\n{md}");
            } else if header.take().is_some() {
                tables += 1;
            }
        }
        assert_eq!(tables, 3, "display, browsers and exclusions: {md}");
        assert!(
            !md.contains("line\nbreak") && md.contains("line break"),
            "{md}"
        );
        // Every opening of markup is preceded by its escape, wherever the text went (both
        // paragraphs, every table).
        for (raw, escaped) in [
            ("<script", "\\<script"),
            ("</script", "\\</script"),
            ("*bold", "\\*bold"),
            ("bold*", "bold\\*"),
            ("`code", "\\`code"),
            ("code`", "code\\`"),
            ("](http", "\\](http"),
            ("://", "\\://"),
            ("_em", "\\_em"),
            ("em_", "em\\_"),
            ("www.", "www\\."),
            ("@b", "\\@b"),
        ] {
            let unescaped = md.replace(escaped, "").contains(raw);
            assert!(md.contains(escaped) && !unescaped, "{raw}\n{md}");
        }
        assert!(md.contains("Over 5 % of the frames dropped (--drop-limit): a\\|b session 1"));
    }
}
