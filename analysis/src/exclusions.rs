//! Exclusions of a crowdsourced study (`[crowdsourcing]` in the study file, sessions from `study
//! serve`): sessions that failed more gold (catch) trials than the study allows are left out
//! of every statistic, and trials during whose stimuli the page was hidden are left out where
//! the study says so (`hidden = "exclude"`). The report lists each exclusion and why (ITU-T
//! P.808 and the P.910 crowd procedures ask for both the rules and who they removed).

use protocols::study::{CrowdsourcingSettings, HiddenRule};
use results::SessionResults;

use crate::tables::Table;

/// A gold trial a session failed.
#[derive(Debug, Clone, PartialEq)]
pub struct GoldFailure {
    /// Trial index.
    pub trial: u32,
    /// The gold condition's stimulus.
    pub stimulus: String,
    /// The rating given to the test stimulus.
    pub rating: f64,
}

/// What the study's exclusion rules say about one session.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionExclusion {
    /// `SUBJECT session N`.
    pub session: String,
    /// Gold trials answered.
    pub gold_trials: usize,
    /// Gold trials failed.
    pub gold_failed: Vec<GoldFailure>,
    /// Trials left out because the page was hidden during their stimuli.
    pub hidden_trials: Vec<u32>,
    /// The whole session is left out (more gold failures than allowed).
    pub excluded: bool,
}

impl SessionExclusion {
    /// Whether the rules touch this session at all.
    pub fn any(&self) -> bool {
        self.excluded || !self.hidden_trials.is_empty() || !self.gold_failed.is_empty()
    }
}

/// Applies `crowd`'s rules to session `s`.
#[must_use]
pub fn session_exclusion(s: &SessionResults, crowd: &CrowdsourcingSettings) -> SessionExclusion {
    let mut gold_trials = 0;
    let mut gold_failed = Vec::new();
    for r in &s.trials.records {
        let Some((rating, passed)) = crowd.gold_verdict(r) else {
            continue;
        };
        gold_trials += 1;
        if !passed {
            gold_failed.push(GoldFailure {
                trial: r.trial.index,
                stimulus: r.trial.stimulus.clone(),
                rating,
            });
        }
    }
    let hidden_trials = match (&s.manifest.browser, crowd.hidden) {
        (Some(b), HiddenRule::Exclude) => b.hidden_trials.clone(),
        _ => Vec::new(),
    };
    let m = &s.manifest;
    SessionExclusion {
        session: format!("{} session {}", m.subject, m.session),
        gold_trials,
        excluded: gold_failed.len() > crowd.max_gold_failures as usize,
        gold_failed,
        hidden_trials,
    }
}

/// `s` without the trials `e` leaves out (`None` when the whole session is excluded); `s`
/// itself, not a copy, when it keeps every trial (the common case, read once per session).
#[must_use]
pub fn apply<'s>(
    s: &'s SessionResults,
    e: &SessionExclusion,
) -> Option<std::borrow::Cow<'s, SessionResults>> {
    if e.excluded {
        return None;
    }
    if e.hidden_trials.is_empty() {
        return Some(std::borrow::Cow::Borrowed(s));
    }
    let mut kept = s.clone();
    kept.trials
        .records
        .retain(|r| !e.hidden_trials.contains(&r.trial.index));
    Some(std::borrow::Cow::Owned(kept))
}

/// The exclusions table: one row per session the rules touched.
#[must_use]
pub fn exclusions_table(rows: &[SessionExclusion], crowd: &CrowdsourcingSettings) -> Table {
    Table {
        name: "exclusions".to_owned(),
        caption: format!(
            "Exclusions: a session failing more than {} of its gold trials is left out; trials with the page hidden during the stimuli are {}",
            crowd.max_gold_failures,
            match crowd.hidden {
                HiddenRule::Exclude => "left out",
                HiddenRule::Repeat => "shown again (none reach the log)",
            }
        ),
        columns: [
            "Session",
            "Gold trials",
            "Gold failed",
            "Hidden trials left out",
            "Excluded",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .filter(|e| e.any())
            .map(|e| {
                vec![
                    e.session.clone(),
                    e.gold_trials.to_string(),
                    e.gold_failed
                        .iter()
                        .map(|f| format!("trial {} ({}: {})", f.trial, f.stimulus, f.rating))
                        .collect::<Vec<_>>()
                        .join("; "),
                    e.hidden_trials
                        .iter()
                        .map(ToString::to_string)
                        .collect::<Vec<_>>()
                        .join(" "),
                    if e.excluded { "yes" } else { "" }.to_owned(),
                ]
            })
            .collect(),
    }
}
