//! `[crowdsourcing]`: what a study served to participants' browsers (`study serve`) needs beyond a
//! lab session: the environment check, the completion code and redirect, the rule for a page
//! hidden during the stimuli, gold (catch) trials with their exclusion rule, and quotas of
//! participants per plan group. Every key has a default, so a study without the table serves
//! as it is; the window and simulation ignore it.

use serde::{Deserialize, Serialize};
use toml::{Table, Value};

use super::Condition;
use super::check::{Ctx, join};
use crate::record::{Answer, Block, Protocol, TrialRecord};

/// What happens to a trial during whose stimuli the page was hidden.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HiddenRule {
    /// The page shows the trial again from the start; an answer is taken only after an
    /// unbroken presentation.
    Repeat,
    /// The answer is taken and the trial is flagged; `study report` leaves it out.
    Exclude,
}

/// What `study report` does with a session that answered a trial sooner after its previous
/// answer than the trial's stimuli take to play (`[crowdsourcing] too_fast`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TooFastRule {
    /// The session is listed in the report's exclusions section, and kept.
    #[default]
    Flag,
    /// The session is listed and left out of every statistic.
    Exclude,
}

impl TooFastRule {
    /// The study file's word for the rule (`too_fast = "..."`).
    pub fn word(self) -> &'static str {
        match self {
            TooFastRule::Flag => "flag",
            TooFastRule::Exclude => "exclude",
        }
    }
}

/// A gold (catch) trial: a condition whose answer is known, e.g. an identical pair (a
/// lossless stimulus, rated at least `min`) or an obvious degradation (rated at most `max`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GoldTrial {
    /// The condition's test stimulus id.
    pub stimulus: String,
    /// Lowest rating of the test stimulus that passes.
    pub min: Option<f64>,
    /// Highest rating of the test stimulus that passes.
    pub max: Option<f64>,
}

impl GoldTrial {
    /// Whether `rating` (of the test stimulus: MOS's rating, DSCQS's test score) passes.
    pub fn passes(&self, rating: f64) -> bool {
        self.min.is_none_or(|m| rating >= m) && self.max.is_none_or(|m| rating <= m)
    }
}

/// Crowd settings (`[crowdsourcing]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CrowdsourcingSettings {
    /// Smallest browser window, CSS pixels.
    pub min_window_px: [u32; 2],
    /// Lowest display refresh rate, Hz (measured by the page).
    pub min_refresh_hz: f64,
    /// The study runs in fullscreen.
    pub fullscreen: bool,
    /// A page hidden during the stimuli.
    pub hidden: HiddenRule,
    /// Completion code shown at the end (Prolific, MTurk).
    pub completion_code: Option<String>,
    /// Where the end screen sends the participant (`https://...`).
    pub completion_url: Option<String>,
    /// Gold trials.
    pub gold: Vec<GoldTrial>,
    /// A session that fails more gold trials than this is excluded by `study report`.
    pub max_gold_failures: u32,
    /// Plan groups: participants take subject indices 0..groups in turn (each group one
    /// counterbalanced plan); `None`: each participant's own plan, as `study run` gives.
    pub groups: Option<u32>,
    /// Participants per group (or in all, without groups); the server refuses more. A quota
    /// counts the sessions that completed and the participants active within `lease_s`.
    pub quota: Option<u32>,
    /// How long a participant's place is kept since their last request, seconds: a
    /// participant idle longer no longer counts against the quota.
    #[serde(default = "default_lease_s")]
    pub lease_s: u32,
    /// Sessions with answers sooner than their stimuli play: flagged or excluded.
    #[serde(default)]
    pub too_fast: TooFastRule,
}

/// `[crowdsourcing] lease_s` unless the study sets it: 30 minutes.
pub const DEFAULT_LEASE_S: u32 = 1800;

/// Longest `[crowdsourcing] lease_s`: a week.
pub const MAX_LEASE_S: u32 = 7 * 24 * 3600;

fn default_lease_s() -> u32 {
    DEFAULT_LEASE_S
}

impl Default for CrowdsourcingSettings {
    fn default() -> Self {
        CrowdsourcingSettings {
            min_window_px: [800, 500],
            min_refresh_hz: 50.0,
            fullscreen: false,
            hidden: HiddenRule::Repeat,
            completion_code: None,
            completion_url: None,
            gold: Vec::new(),
            max_gold_failures: 0,
            groups: None,
            quota: None,
            lease_s: DEFAULT_LEASE_S,
            too_fast: TooFastRule::Flag,
        }
    }
}

impl CrowdsourcingSettings {
    /// The gold trial of test stimulus `id`, if it is one.
    pub fn gold_of(&self, id: &str) -> Option<&GoldTrial> {
        self.gold.iter().find(|g| g.stimulus == id)
    }

    /// For a logged trial of a gold condition (familiarization aside): the rating of its test
    /// stimulus (MOS's rating, DSCQS's test score) and whether it passes; `None` for any
    /// other trial.
    pub fn gold_verdict(&self, r: &TrialRecord) -> Option<(f64, bool)> {
        if r.trial.block == Block::Familiarization {
            return None;
        }
        let g = self.gold_of(&r.trial.stimulus)?;
        let rating = match r.response.answer {
            Answer::Rating(v) => v,
            Answer::Pair { .. } => r.outcome.score_test?,
            Answer::Choice(_) => return None,
        };
        Some((rating, g.passes(rating)))
    }
}

const C: &str = "crowdsourcing";

fn code_ok(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

fn url_ok(u: &str) -> bool {
    u.starts_with("https://")
        && u.len() <= 2000
        && !u.chars().any(|c| c.is_whitespace() || c.is_control())
}

pub(super) fn parse_crowdsourcing(
    t: &Table,
    protocol: Option<Protocol>,
    conditions: &[Condition],
    cx: &mut Ctx,
) -> CrowdsourcingSettings {
    cx.known(
        t,
        C,
        &[
            "min_window",
            "min_refresh_hz",
            "fullscreen",
            "hidden",
            "completion_code",
            "completion_url",
            "gold",
            "max_gold_failures",
            "groups",
            "quota",
            "lease_s",
            "too_fast",
        ],
    );
    let d = CrowdsourcingSettings::default();
    let min_window_px = match cx.floats(t, C, "min_window") {
        Some(v)
            if v.len() == 2
                && v.iter()
                    .all(|x| *x >= 0.0 && *x <= 16384.0 && x.fract() == 0.0) =>
        {
            [v[0] as u32, v[1] as u32]
        }
        Some(_) => {
            cx.err(
                join(C, "min_window"),
                "expected [width, height] in whole pixels, at most 16384",
            );
            d.min_window_px
        }
        None => d.min_window_px,
    };
    let min_refresh_hz = match cx.float(t, C, "min_refresh_hz") {
        Some(v) if (0.0..=1000.0).contains(&v) => v,
        Some(v) => {
            cx.err(
                join(C, "min_refresh_hz"),
                format!("{v} is outside 0..=1000"),
            );
            d.min_refresh_hz
        }
        None => d.min_refresh_hz,
    };
    let hidden = word(
        t,
        "hidden",
        [
            ("repeat", HiddenRule::Repeat),
            ("exclude", HiddenRule::Exclude),
        ],
        cx,
    );
    let too_fast = word(
        t,
        "too_fast",
        [TooFastRule::Flag, TooFastRule::Exclude].map(|r| (r.word(), r)),
        cx,
    );
    let completion_code = cx.string(t, C, "completion_code");
    if completion_code.as_deref().is_some_and(|c| !code_ok(c)) {
        cx.err(
            join(C, "completion_code"),
            "use 1-64 letters, digits, '-' or '_'",
        );
    }
    let completion_url = cx.string(t, C, "completion_url");
    if completion_url.as_deref().is_some_and(|u| !url_ok(u)) {
        cx.err(
            join(C, "completion_url"),
            "expected an https:// address without spaces",
        );
    }
    let gold = parse_gold(t, C, "gold", protocol, conditions, cx);
    let groups = positive(t, "groups", 1 << 20, cx);
    let quota = positive(t, "quota", 1 << 24, cx);
    let lease_s = positive(t, "lease_s", MAX_LEASE_S, cx);
    CrowdsourcingSettings {
        min_window_px,
        min_refresh_hz,
        fullscreen: cx.boolean(t, C, "fullscreen").unwrap_or(d.fullscreen),
        hidden,
        completion_code,
        completion_url,
        gold,
        max_gold_failures: cx.uint(t, C, "max_gold_failures", 1 << 20).unwrap_or(0),
        groups,
        quota,
        lease_s: lease_s.unwrap_or(DEFAULT_LEASE_S),
        too_fast,
    }
}

/// `[crowdsourcing] key`: one of two words, the first the default.
fn word<T: Copy>(t: &Table, key: &str, words: [(&str, T); 2], cx: &mut Ctx) -> T {
    match cx.string(t, C, key) {
        None => words[0].1,
        Some(w) => words.iter().find(|(name, _)| *name == w).map_or_else(
            || {
                cx.err(
                    join(C, key),
                    format!("expected {:?} or {:?}, got {w:?}", words[0].0, words[1].0),
                );
                words[0].1
            },
            |(_, v)| *v,
        ),
    }
}

/// `[crowdsourcing] key`: a whole number from 1 to `hi`, if given.
fn positive(t: &Table, key: &str, hi: u32, cx: &mut Ctx) -> Option<u32> {
    let v = cx.uint(t, C, key, hi);
    if v == Some(0) {
        cx.err(join(C, key), "must be at least 1");
    }
    v.filter(|v| *v > 0)
}

/// Catch (gold) trials at `table.key`: `[[crowdsourcing.gold]]`, or `[[design.catch]]`.
pub(super) fn parse_gold(
    t: &Table,
    table: &str,
    key: &str,
    protocol: Option<Protocol>,
    conditions: &[Condition],
    cx: &mut Ctx,
) -> Vec<GoldTrial> {
    let Some(v) = t.get(key) else {
        return Vec::new();
    };
    let Value::Array(items) = v else {
        cx.wrong(
            table,
            key,
            &format!("an array of tables ([[{table}.{key}]])"),
            v,
        );
        return Vec::new();
    };
    if protocol.is_some_and(|p| !crate::methods::of(p).gold_trials()) {
        cx.err(
            join(table, key),
            "catch (gold) trials are rated conditions of one-stimulus screens: MOS, DSCQS, ACR \
             and DCR only (a pair comparison rates nothing; a MUSHRA screen's hidden reference \
             and anchor are its checks)",
        );
        return Vec::new();
    }
    let mut out = Vec::new();
    for (i, item) in items.iter().enumerate() {
        let path = format!("{table}.{key}[{i}]");
        let Value::Table(g) = item else {
            cx.err(path, "expected a table with stimulus and min or max");
            continue;
        };
        cx.known(g, &path, &["stimulus", "min", "max"]);
        let stimulus = cx.string(g, &path, "stimulus");
        let (min, max) = (cx.float(g, &path, "min"), cx.float(g, &path, "max"));
        if min.is_none() && max.is_none() {
            cx.err(
                path.clone(),
                "give min (an identical pair) or max (an obvious degradation)",
            );
        }
        if let (Some(lo), Some(hi)) = (min, max)
            && lo > hi
        {
            cx.err(path.clone(), format!("min {lo} is above max {hi}"));
        }
        let Some(stimulus) = stimulus else {
            cx.err(join(&path, "stimulus"), "required");
            continue;
        };
        if !conditions.iter().any(|c| c.stimulus == stimulus) {
            cx.err(
                join(&path, "stimulus"),
                format!("{stimulus:?} is not one of the study's conditions (a gold trial is a condition whose answer is known)"),
            );
        }
        if out.iter().any(|g: &GoldTrial| g.stimulus == stimulus) {
            cx.err(
                join(&path, "stimulus"),
                format!("{stimulus:?} is a gold trial twice"),
            );
        }
        out.push(GoldTrial { stimulus, min, max });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> (CrowdsourcingSettings, Vec<String>) {
        let t: Table = text.parse().unwrap_or_else(|e| panic!("{e}"));
        let mut cx = Ctx::default();
        let c = parse_crowdsourcing(&t, None, &[], &mut cx);
        let issues = cx
            .issues
            .iter()
            .map(|i| format!("{}: {}", i.key, i.reason))
            .collect();
        (c, issues)
    }

    /// A quota's lease is 30 minutes unless the study sets it, in whole seconds from 1 s to
    /// a week; anything else is named by its key.
    #[test]
    fn the_lease_is_read_and_checked() {
        assert_eq!(read("").0.lease_s, DEFAULT_LEASE_S);
        assert_eq!(read("quota = 5\nlease_s = 2").0.lease_s, 2);
        for (bad, why) in [
            ("lease_s = 0", "crowdsourcing.lease_s: must be at least 1"),
            (
                "lease_s = 604801",
                "crowdsourcing.lease_s: 604801 is outside 0..=604800",
            ),
            ("lease_s = 1.5", "crowdsourcing.lease_s"),
        ] {
            let (c, issues) = read(bad);
            assert_eq!(c.lease_s, DEFAULT_LEASE_S, "{bad}");
            assert!(
                issues.len() == 1 && issues[0].starts_with(why),
                "{bad}: {issues:?}"
            );
        }
    }
}
