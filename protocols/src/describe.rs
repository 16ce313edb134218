//! `study check`'s description of a study file: what a subject will see and what the
//! experimenter should know before the first session (trials, presentation time, screens,
//! counterbalancing, viewing conditions). A live staircase's lines come from the stimulus
//! source that encodes them (`lab::live::LiveStimuli::describe`).

use std::fmt::Write as _;

use crate::{Protocol, StudyDefinition};

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
/// presentation time.
pub fn method(study: &StudyDefinition) -> String {
    let mut text = String::new();
    // Writing into a String cannot fail.
    let _ = match study.protocol {
        Protocol::Mos | Protocol::Dscqs | Protocol::Acr | Protocol::Dcr => {
            describe_ratings(&mut text, study)
        }
        Protocol::PairComparison => describe_pairs(&mut text, study),
        Protocol::Mushra => describe_mushra(&mut text, study),
        Protocol::Staircase => describe_staircase(&mut text, study),
    };
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

/// The trials of a session of between-subject group `group`.
fn group_trials(study: &StudyDefinition, group: &str) -> Option<u32> {
    let of_group = study.for_group(Some(group)).ok()?;
    crate::texts::planned_trials(&of_group).exact()
}

/// Counterbalancing: the order of the conditions and where the reference goes.
fn describe_design(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use crate::study::{ConditionOrder, ReferencePlacement};
    for g in &study.design.groups {
        let quota = g
            .quota
            .map_or_else(|| "no quota".into(), |q| format!("quota {q}"));
        let trials = group_trials(study, &g.name).unwrap_or(0);
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
        let items = match study.protocol {
            Protocol::PairComparison => study.pairs().len(),
            Protocol::Mushra => crate::study::mushra_screens(&study.conditions).len(),
            _ => study.conditions.len(),
        };
        let rows = crate::design::williams_rows(items);
        writeln!(
            text,
            "  order: balanced Latin square (Williams), {rows} rows: subject index k takes row \
             k mod {rows}; a complete block is {rows} subjects"
        )?;
    }
    let side = match study.presentation.reference_position {
        _ if study.protocol == Protocol::Mushra => {
            "a pane of its own, labelled; the rated stimuli shuffled over the lettered panes \
             per screen and subject"
                .to_string()
        }
        ReferencePlacement::Fixed(p) => format!("always {p}"),
        ReferencePlacement::Random => "random per trial".to_string(),
        ReferencePlacement::Balanced => match study.protocol {
            Protocol::Staircase => "balanced (each block of 4 trials, mirrored for the next \
                                    subject)"
                .to_string(),
            Protocol::PairComparison => {
                "balanced (per pair, mirrored for the next subject)".to_string()
            }
            _ => "balanced (per condition, mirrored for the next subject)".to_string(),
        },
    };
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

/// A MOS or DSCQS study's trials and presentation time.
fn describe_ratings(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    let n = study.familiarization.len()
        + study.conditions.len()
        + study.session.hidden_repeats as usize;
    if study.design.groups.is_empty() {
        writeln!(
            text,
            "  trials per session: {n} ({} familiarization, {} conditions, {} hidden repeats)",
            study.familiarization.len(),
            study.conditions.len(),
            study.session.hidden_repeats
        )?;
    } else {
        writeln!(
            text,
            "  conditions: {} in {} between-subject groups (each session sees its group's; \
             {} familiarization, {} hidden repeats)",
            study.conditions.len(),
            study.design.groups.len(),
            study.familiarization.len(),
            study.session.hidden_repeats
        )?;
    }
    let hidden = study
        .conditions
        .iter()
        .filter(|c| c.stimulus == c.reference)
        .count();
    if hidden > 0 {
        writeln!(
            text,
            "  hidden references: {hidden} (ACR-HR: DMOS = test - hidden reference + 5)"
        )?;
    }
    // A session of a between-subject group shows its group's trials: the largest group's.
    let n = if study.design.groups.is_empty() {
        n
    } else {
        study
            .design
            .groups
            .iter()
            .filter_map(|g| group_trials(study, &g.name))
            .max()
            .map_or(n, |t| t as usize)
    };
    let est_min = n as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
    writeln!(
        text,
        "  presentation time: {est_min:.1} min without answers"
    )
}

/// A pair comparison's pairs, trials and presentation time.
fn describe_pairs(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    let pairs = study.pairs().len();
    let n = pairs + study.session.hidden_repeats as usize;
    writeln!(
        text,
        "  trials per session: {n} ({pairs} pairs of {} conditions, {} hidden repeats with \
         the sides swapped)",
        study.conditions.len(),
        study.session.hidden_repeats
    )?;
    let anchors = study
        .conditions
        .iter()
        .filter(|c| c.stimulus == c.reference)
        .count();
    if anchors > 0 {
        writeln!(
            text,
            "  originals compared: {anchors} (unlabelled; each clip's scale is anchored at its \
             original)"
        )?;
    }
    let est_min = n as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
    writeln!(
        text,
        "  presentation time: {est_min:.1} min without answers"
    )
}

/// A MUSHRA study: its screens (one per clip) with their panes, the anchors and the
/// post-screening rules.
fn describe_mushra(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    use crate::study::AnchorRule;
    let Some(m) = &study.mushra else {
        return Ok(());
    };
    let screens = crate::study::mushra_screens(&study.conditions);
    let rated: usize = screens.iter().map(|(_, c)| c.len() + 2).sum();
    writeln!(
        text,
        "  screens per session: {} (one per clip), {rated} rated panes in all",
        screens.len()
    )?;
    if m.training_screens > 0 {
        writeln!(
            text,
            "  training (BS.1534-3): the screen(s) of the first {} clip(s) shown first, rated, \
             not analysed",
            m.training_screens
        )?;
    }
    for (reference, tests) in &screens {
        let anchor = m
            .anchors
            .iter()
            .find(|a| a.reference == *reference)
            .map_or("?", |a| a.stimulus.as_str());
        writeln!(
            text,
            "  screen {reference:?}: {} test conditions + hidden reference + anchor {anchor:?}",
            tests.len()
        )?;
    }
    writeln!(
        text,
        "  post-screening (BS.1534-3): excluded when the hidden reference is rated below {} on \
         more than {}% of the screens; the anchor rated above {} on more than {}%: {}",
        m.reference_below,
        100.0 * m.max_fraction,
        m.anchor_above,
        100.0 * m.max_fraction,
        match m.anchor_rule {
            AnchorRule::Report => "reported, kept",
            AnchorRule::Exclude => "excluded",
        }
    )?;
    let shown = screens.len() + m.training_screens as usize;
    let est_min = shown as f64 * study.trial_presentation_ms() as f64 / 60_000.0;
    writeln!(
        text,
        "  presentation time: {est_min:.1} min without answers"
    )
}

/// A staircase over the manifest's stimuli: each track's clip and levels.
fn describe_staircase(text: &mut String, study: &StudyDefinition) -> std::fmt::Result {
    let Some(sc) = &study.staircase else {
        return Ok(());
    };
    for t in &sc.tracks {
        writeln!(
            text,
            "  staircase {:?}: clip {:?}, {} stimulus levels of {} from {} to {}",
            t.name,
            t.clip,
            t.levels.len(),
            sc.param,
            t.levels.first().map_or(0.0, |l| l.0),
            t.levels.last().map_or(0.0, |l| l.0)
        )?;
    }
    Ok(())
}
