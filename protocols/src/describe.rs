//! `study check`'s description of a study file: what a subject will see and what the
//! experimenter should know before the first session (trials, presentation time, screens,
//! counterbalancing, viewing conditions). A live staircase's lines come from the stimulus
//! source that encodes them (`lab::live::LiveStimuli::describe`).

use std::fmt::Write as _;

use crate::StudyDefinition;

/// The study's name, the title and instructions its subjects read, its protocol and seed.
pub fn header(study: &StudyDefinition) -> String {
    let mut text = String::new();
    let instructions = study
        .session
        .instructions
        .clone()
        .unwrap_or_else(|| crate::texts::default_instructions(study));
    // Writing into a String cannot fail.
    let _ = writeln!(text, "  name: {}", study.name);
    let _ = writeln!(text, "  title (subjects see): {}", study.title());
    let _ = writeln!(text, "  instructions (subjects read): {instructions}");
    let _ = writeln!(text, "  protocol: {}", study.protocol);
    let _ = writeln!(text, "  seed: {}", study.seed);
    text
}

/// What a session of the study's method holds: its trials (or screens, or staircases) and
/// presentation time ([`crate::methods::Method::describe`]).
pub fn method(study: &StudyDefinition) -> String {
    let mut text = String::new();
    // Writing into a String cannot fail.
    let _ = study.method().describe(study, &mut text);
    text
}

/// The session's time limit and the design: groups, order, reference position, practice,
/// viewing conditions.
pub fn design(study: &StudyDefinition) -> String {
    let mut text = String::new();
    // Writing into a String cannot fail.
    if let Some(ms) = study.session.time_limit_ms {
        let _ = writeln!(text, "  time limit: {:.1} min", ms as f64 / 60_000.0);
    }
    let _ = describe_design(&mut text, study);
    text
}

/// Counterbalancing: the order of the conditions and where the reference goes.
fn describe_design(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use crate::study::ConditionOrder;
    for g in &study.design.groups {
        let quota = g
            .quota
            .map_or_else(|| "no quota".into(), |q| format!("quota {q}"));
        let trials = crate::methods::common::group_trials(study, &g.name).unwrap_or(0);
        writeln!(
            text,
            "  group {}: {} condition(s), {trials} trials per session, {quota}",
            g.name,
            g.stimuli.len()
        )?;
    }
    if study.design.order == ConditionOrder::LatinSquare && !study.design.groups.is_empty() {
        writeln!(
            text,
            "  order: balanced Latin square (Williams) over each group's conditions: a \
             session's place in its group takes that row"
        )?;
    } else if study.design.order == ConditionOrder::LatinSquare {
        // A pair comparison orders its pairs, a MUSHRA study its screens (one per clip), the
        // others their conditions.
        let items = study.method().ordered_items(&study.conditions);
        let rows = crate::design::williams_rows(items);
        writeln!(
            text,
            "  order: balanced Latin square (Williams), {rows} rows: subject index k takes row \
             k mod {rows}; a complete block is {rows} subjects"
        )?;
    }
    let side = study
        .method()
        .describe_reference(study.presentation.reference_position);
    writeln!(text, "  reference position: {side}")?;
    if let Some(sc) = &study.staircase
        && sc.practice_trials > 0
    {
        writeln!(
            text,
            "  practice: {} trial(s) before the staircases, not analysed",
            sc.practice_trials
        )?;
    }
    if let Some(v) = &study.viewing {
        let stated: Vec<String> = v
            .describe()
            .into_iter()
            .map(|(what, value)| format!("{what} {value}"))
            .collect();
        writeln!(
            text,
            "  viewing conditions (confirmed before each session): {}",
            stated.join(", ")
        )?;
    }
    Ok(())
}
