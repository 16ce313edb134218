//! Exclusions of a crowdsourced study (`[crowdsourcing]` in the study file, sessions from `study
//! serve`): sessions that failed more gold (catch) trials than the study allows are left out
//! of every statistic, and trials during whose stimuli the page was hidden are left out where
//! the study says so (`hidden = "exclude"`). The report lists each exclusion and why (ITU-T
//! P.808 and the P.910 crowd procedures ask for both the rules and who they removed).
//!
//! Every study, crowd or not, is also checked for answers that came implausibly fast: an
//! answer sooner after the one before it than its trial's stimuli take to play (by both the
//! runner's wall clock and its monotonic clock, so a clock step or a session taken over by
//! another server does not count). A runner never takes such an answer; a log that holds one
//! was not written by a subject watching the stimuli (a scripted client of an older server,
//! an edited file). Such sessions are flagged, or excluded where `too_fast = "exclude"`.

use protocols::TrialRecord;
use protocols::record::Arrangement;
use protocols::study::{CrowdsourcingSettings, HiddenRule, TooFastRule};
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

/// A trial answered sooner after the answer before it (or the session's start) than its
/// stimuli take to play.
#[derive(Debug, Clone, PartialEq)]
pub struct TooFast {
    /// Trial index.
    pub trial: u32,
    /// Time since the answer before it (the session's start for the first), ms: the longer of
    /// the wall-clock and the monotonic interval.
    pub after_ms: f64,
    /// Time the trial's stimuli take to play before answers open, ms.
    pub need_ms: f64,
}

/// Slack for clocks and rounding (the runners' own rule, `web`'s answer check, allows as
/// much), ms.
pub const TOO_FAST_SLACK_MS: f64 = 50.0;

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
    /// Trials answered sooner than their stimuli play ([`too_fast`]).
    pub too_fast: Vec<TooFast>,
    /// The whole session is left out (more gold failures than allowed, or answers too fast
    /// where the study excludes them).
    pub excluded: bool,
}

impl SessionExclusion {
    /// Whether the rules touch this session at all.
    pub fn any(&self) -> bool {
        self.excluded
            || !self.hidden_trials.is_empty()
            || !self.gold_failed.is_empty()
            || !self.too_fast.is_empty()
    }
}

/// The trials of session `s` answered sooner than their stimuli play: `need_ms(row)` is how
/// long the row's trial plays before answers open (`None`: not known, not checked). An
/// answer counts as too fast when both the wall-clock and the monotonic interval since the
/// answer before it (the session's start for the first) are shorter than that by more than
/// [`TOO_FAST_SLACK_MS`]. The rows of one MUSHRA screen are answered together: a grid row
/// after a grid row of the same reference counts as the same screen (two screens of one
/// reference in a row are then checked as one, which can only miss, never wrongly flag).
/// Simulated sessions are not checked (their clocks are not the subject's).
pub fn too_fast(s: &SessionResults, need_ms: &dyn Fn(&TrialRecord) -> Option<f64>) -> Vec<TooFast> {
    if s.manifest.observer_seed.is_some() {
        return Vec::new();
    }
    let mut out = Vec::new();
    let (mut wall, mut mono) = (s.manifest.started_ms as f64, 0.0);
    let mut screen: Option<(&str, protocols::record::Block)> = None;
    for r in &s.trials.records {
        let grid = r.trial.arrangement == Arrangement::Grid;
        let same_screen = grid
            && screen.is_some_and(|(reference, block)| {
                reference == r.trial.reference && block == r.trial.block
            });
        screen = grid.then_some((r.trial.reference.as_str(), r.trial.block));
        let (w, m) = (r.wall_clock_ms as f64, r.monotonic_ms as f64);
        let after_ms = (w - wall).max(m - mono);
        (wall, mono) = (w, m);
        if same_screen {
            continue;
        }
        if let Some(need_ms) = need_ms(r)
            && after_ms + TOO_FAST_SLACK_MS < need_ms
        {
            out.push(TooFast {
                trial: r.trial.index,
                after_ms,
                need_ms,
            });
        }
    }
    out
}

/// Applies `crowd`'s rules to session `s`; `need_ms` as [`too_fast`].
#[must_use]
pub fn session_exclusion(
    s: &SessionResults,
    crowd: &CrowdsourcingSettings,
    need_ms: &dyn Fn(&TrialRecord) -> Option<f64>,
) -> SessionExclusion {
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
    let too_fast = too_fast(s, need_ms);
    let m = &s.manifest;
    SessionExclusion {
        session: format!("{} session {}", m.subject, m.session),
        gold_trials,
        excluded: gold_failed.len() > crowd.max_gold_failures as usize
            || (crowd.too_fast == TooFastRule::Exclude && !too_fast.is_empty()),
        gold_failed,
        hidden_trials,
        too_fast,
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
            "Exclusions: a session failing more than {} of its gold trials is left out; trials with the page hidden during the stimuli are {}; a session with answers sooner than their stimuli play is {}",
            crowd.max_gold_failures,
            match crowd.hidden {
                HiddenRule::Exclude => "left out",
                HiddenRule::Repeat => "shown again (none reach the log)",
            },
            match crowd.too_fast {
                TooFastRule::Exclude => "left out",
                TooFastRule::Flag => "flagged and kept",
            }
        ),
        columns: [
            "Session",
            "Gold trials",
            "Gold failed",
            "Hidden trials left out",
            "Answered too fast",
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
                    too_fast_text(&e.too_fast),
                    if e.excluded { "yes" } else { "" }.to_owned(),
                ]
            })
            .collect(),
    }
}

/// "trial 3 (0.1 s of 4.2 s), ...": the first [`TOO_FAST_SHOWN`] too-fast trials and how many
/// more.
fn too_fast_text(t: &[TooFast]) -> String {
    let mut text: Vec<String> = t
        .iter()
        .take(TOO_FAST_SHOWN)
        .map(|f| {
            format!(
                "trial {} ({:.1} s of {:.1} s)",
                f.trial,
                f.after_ms.max(0.0) / 1e3,
                f.need_ms / 1e3
            )
        })
        .collect();
    if t.len() > TOO_FAST_SHOWN {
        text.push(format!("{} more", t.len() - TOO_FAST_SHOWN));
    }
    text.join("; ")
}

/// Too-fast trials named per session in the exclusions table.
const TOO_FAST_SHOWN: usize = 3;
