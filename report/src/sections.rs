//! The report's sections that are not the analysis's own: incomplete sessions, display,
//! MUSHRA, exclusions.

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
            section.text(p.to_string());
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
    let flagged: Vec<&str> = displays
        .iter()
        .filter(|d| d.flagged)
        .map(|d| d.session.as_str())
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
    for f in &flagged {
        warn(&format!(
            "{f} dropped more than {drop_limit} % of its frames"
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
    let left_out: Vec<&str> = exclusions
        .iter()
        .filter(|e| e.excluded)
        .map(|e| e.session.as_str())
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
    section.table(analysis::exclusions::exclusions_table(exclusions, crowd));
}
