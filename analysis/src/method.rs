//! The report's "Method" section: what ITU-R BT.500 and ITU-T P.910 ask a report to state
//! about how the study was run: the number of observers (and how many the screening and the
//! exclusion rules left), the screening applied, the viewing distance, the display, its
//! luminance and the environment, each as the study file states it and as the experimenters
//! confirmed and measured it before the sessions (`session.json` `viewing`); plus the design
//! (order of conditions, reference placement, between-subject groups) and practice trials.

use protocols::StudyDefinition;
use protocols::study::ConditionOrder;

use crate::display::SessionDisplay;
use crate::report::Report;

/// How many observers each stage left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Observers {
    /// Sessions read.
    pub sessions: usize,
    /// Distinct subjects whose ratings or choices were analysed.
    pub subjects: usize,
    /// Sessions the study's exclusion rules left out (catch trials).
    pub excluded_sessions: usize,
    /// Observers the BT.500 screening rejected (`None`: not applicable).
    pub rejected: Option<usize>,
}

/// `min`–`max` (or the one value) of the measured values, with `unit`, and in how many of
/// `n` sessions it was measured; `None` when no session measured it.
fn measured(values: &[f64], n: usize, unit: &str) -> Option<String> {
    let range = measured_range(values)?;
    Some(format!(
        "measured {range} {unit} in {} of {n} sessions",
        values.len()
    ))
}

/// The method's sentences, in BT.500's order. Pure text: `method_section` puts it in the
/// report.
#[must_use]
pub fn method_text(
    study: &StudyDefinition,
    observers: Observers,
    displays: &[SessionDisplay],
) -> Vec<String> {
    let mut out = Vec::new();
    let mut who = format!(
        "Observers: {} ({} sessions).",
        observers.subjects, observers.sessions
    );
    if observers.excluded_sessions > 0 {
        who = format!(
            "{who} {} session(s) excluded by the study's catch-trial rules.",
            observers.excluded_sessions
        );
    }
    out.push(who);
    if let Some(p) = participants_line(study, displays) {
        out.push(p);
    }
    let no_screening = crate::methods::of(study.protocol).no_screening();
    out.push(match (no_screening, observers.rejected) {
        (Some(why), _) => format!("Screening: none ({why})."),
        (None, Some(r)) => format!(
            "Screening: ITU-R BT.500 observer screening (β2 kurtosis test on every \
             presentation); {r} observer(s) rejected, {} retained.",
            observers.subjects.saturating_sub(r)
        ),
        (None, None) => "Screening: BT.500 observer screening not applicable (too few \
                      observers or presentations)."
            .into(),
    });
    viewing_lines(study, displays, &mut out);
    out.push(design_line(study));
    if let Some(cr) = cr_line(study) {
        out.push(cr);
    }
    if let Some(groups) = groups_line(study, displays) {
        out.push(groups);
    }
    out
}

/// What the subjects stated on the welcome screen, one clause per `[session] subject_fields`
/// entry and counted once per subject (their first session read): a number field's range,
/// mean and count, a choice's or yes/no's count per option in the study file's order, and how
/// many answered a free-text field (its answers are not printed: they may identify someone).
/// Answers the field's rules refuse (a log written before the field was typed) are counted
/// apart, never folded into the figures. `None` for a study with no subject fields.
fn participants_line(study: &StudyDefinition, displays: &[SessionDisplay]) -> Option<String> {
    use protocols::study::FieldKind;
    if study.session.subject_fields.is_empty() {
        return None;
    }
    let mut seen = std::collections::BTreeSet::new();
    let subjects: Vec<&SessionDisplay> = displays
        .iter()
        .filter(|d| seen.insert(d.subject.as_str()))
        .collect();
    let clauses: Vec<String> = study
        .session
        .subject_fields
        .iter()
        .map(|f| {
            let mut valid = Vec::new();
            let mut invalid = 0usize;
            for d in &subjects {
                match d.subject_fields.get(&f.name).map(|v| f.check(v)) {
                    Some(Ok(v)) => valid.push(v),
                    Some(Err(_)) => invalid += 1,
                    None => {}
                }
            }
            let n = valid.len();
            let what = match &f.kind {
                FieldKind::Number { .. } => {
                    let xs: Vec<f64> = valid.iter().filter_map(|v| v.parse().ok()).collect();
                    let mean = xs.iter().sum::<f64>() / xs.len().max(1) as f64;
                    measured_range(&xs).map_or_else(
                        || "no answers".to_string(),
                        |r| format!("{r} (mean {}, n = {n})", trim_number(mean, 1)),
                    )
                }
                FieldKind::Choice { .. } | FieldKind::YesNo => {
                    let counts: Vec<String> = f
                        .options()
                        .iter()
                        .map(|o| format!("{o} {}", valid.iter().filter(|v| *v == o).count()))
                        .collect();
                    counts.join(", ")
                }
                FieldKind::Text => format!("answered by {n}"),
            };
            let bad = if invalid > 0 {
                format!(" (and {invalid} answer(s) outside the field's rules, left out)")
            } else {
                String::new()
            };
            format!("{}: {what}{bad}", f.label)
        })
        .collect();
    Some(format!(
        "Participants ({} subject(s), as stated before the session): {}.",
        subjects.len(),
        clauses.join("; ")
    ))
}

/// `v` to at most `places` decimals, without trailing zeros.
fn trim_number(v: f64, places: usize) -> String {
    let s = format!("{v:.places$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// `min–max` of `xs` (or the one value); `None` when empty.
fn measured_range(xs: &[f64]) -> Option<String> {
    let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if xs.is_empty() {
        None
    } else if (hi - lo).abs() < 1e-9 {
        Some(trim_number(lo, 2))
    } else {
        Some(format!("{}–{}", trim_number(lo, 2), trim_number(hi, 2)))
    }
}

/// The between-subject groups: each one's conditions, the sessions read of it and its quota.
fn groups_line(study: &StudyDefinition, displays: &[SessionDisplay]) -> Option<String> {
    if study.design.groups.is_empty() {
        return None;
    }
    let each: Vec<String> = study
        .design
        .groups
        .iter()
        .map(|g| {
            let n = displays
                .iter()
                .filter(|d| d.group.as_deref() == Some(g.name.as_str()))
                .count();
            let quota = g
                .quota
                .map_or_else(String::new, |q| format!(" of a quota of {q}"));
            format!(
                "{} ({} condition(s), {n} session(s){quota})",
                g.name,
                g.stimuli.len()
            )
        })
        .collect();
    Some(format!(
        "Between-subject groups, each session assigned one by the results store (the group \
         with the fewest sessions first) and shown its conditions and the catch trials: {}.",
        each.join("; ")
    ))
}

/// The viewing distance, display, luminance and environment: targets, measurements, and how
/// many sessions confirmed them.
fn viewing_lines(study: &StudyDefinition, displays: &[SessionDisplay], out: &mut Vec<String>) {
    let n = displays.len();
    let confirmed = displays
        .iter()
        .filter(|d| d.viewing.as_ref().is_some_and(|v| v.confirmed))
        .count();
    let pick = |f: fn(&results::ViewingRecord) -> Option<f64>| -> Vec<f64> {
        displays
            .iter()
            .filter_map(|d| d.viewing.as_ref().and_then(f))
            .collect()
    };
    match &study.viewing {
        None => out.push(
            "Viewing conditions: not stated by the study file ([viewing]); BT.500 and P.910 \
             ask for viewing distance, display, luminance and room illumination."
                .into(),
        ),
        Some(v) => {
            let stated = v.describe();
            let target = |what: &str| {
                stated
                    .iter()
                    .find(|(w, _)| *w == what)
                    .map_or_else(|| "not stated".to_string(), |(_, s)| s.clone())
            };
            let line = |what: &str, m: Option<String>| match m {
                Some(m) => format!("{what}: {} (target); {m}.", target(what)),
                None => format!("{what}: {} (target); not measured.", target(what)),
            };
            let cap = |s: String| {
                let mut c = s.chars();
                c.next()
                    .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
                    .unwrap_or_default()
            };
            out.push(cap(line(
                "viewing distance",
                measured(&pick(|r| r.distance_cm), n, "cm"),
            )));
            let mut display = format!("Display: {}", target("display"));
            let hz: Vec<f64> = displays.iter().filter_map(|d| d.refresh_hz).collect();
            if let Some(m) = measured(&hz, n, "Hz refresh") {
                display = format!("{display}; {m}");
            }
            display.push('.');
            out.push(display);
            out.push(cap(line(
                "peak luminance",
                measured(&pick(|r| r.peak_luminance_cd_m2), n, "cd/m²"),
            )));
            out.push(cap(line(
                "background luminance",
                measured(&pick(|r| r.background_luminance_cd_m2), n, "cd/m²"),
            )));
            out.push(format!(
                "Environment: room illumination {} (target); {}.",
                target("room illumination"),
                measured(&pick(|r| r.room_illuminance_lux), n, "lux")
                    .unwrap_or_else(|| "not measured".into())
            ));
            out.push(format!(
                "Viewing conditions confirmed by the experimenter before {confirmed} of {n} \
                 sessions."
            ));
        }
    }
}

/// The order of the conditions, the reference placement, and the trials not analysed.
fn design_line(study: &StudyDefinition) -> String {
    let mut design = Vec::new();
    let method = study.method();
    let (items, n) = (
        method.ordered_item_name(),
        method.ordered_items(&study.conditions),
    );
    if !method.adaptive() {
        design.push(match study.design.order {
            ConditionOrder::Random => format!("{items} in a random order per subject"),
            ConditionOrder::LatinSquare => format!(
                "{items} ordered by a balanced Latin square (Williams design, {} rows)",
                protocols::design::williams_rows(n)
            ),
        });
    }
    design
        .push(crate::methods::of(study.protocol).placement(study.presentation.reference_position));
    if let Some(sc) = &study.staircase
        && sc.practice_trials > 0
    {
        design.push(format!(
            "{} practice trial(s) before the staircases, not analysed",
            sc.practice_trials
        ));
    }
    if !study.familiarization.is_empty() {
        design.push(format!(
            "{} familiarization trial(s), not analysed",
            study.familiarization.len()
        ));
    }
    if let Some(m) = &study.mushra
        && m.training_screens > 0
    {
        design.push(format!(
            "{} training screen(s) first (BS.1534-3's training phase), not analysed",
            m.training_screens
        ));
    }
    format!("Design: {}.", design.join("; "))
}

/// Which channels the compression ratios count, where the study shows coded stimuli: the
/// manifest's basis, or every channel of the file for a live staircase (its stimuli are coded
/// per trial, on the file basis).
fn cr_line(study: &StudyDefinition) -> Option<String> {
    let live = study.staircase.as_ref().is_some_and(|s| s.live.is_some());
    let coded = study
        .manifest
        .stimuli
        .iter()
        .any(|s| s.codec != protocols::manifest::REFERENCE_CODEC);
    if !(live || coded) {
        return None;
    }
    let basis = if live {
        protocols::manifest::CrBasis::File
    } else {
        study.manifest.cr_basis
    };
    Some(format!(
        "Compression ratios (CR): 4 bytes × channels × frames / stream bytes, on the {}.",
        basis.words()
    ))
}

/// Adds the "Method" section, before the results.
pub fn method_section(
    report: &mut Report,
    study: &StudyDefinition,
    observers: Observers,
    displays: &[SessionDisplay],
) {
    let section = report.section_first("Method");
    for line in method_text(study, observers, displays) {
        section.text(line);
    }
}
