//! The display record of each session, as the report's "Display" section shows it: the
//! adapter and refresh rate the session measured, and over its timed trials the frames shown,
//! the frames dropped and the spread of the frame intervals; sessions whose share of dropped
//! frames is over a limit are flagged (BT.500 and P.910 ask a report to state the viewing
//! conditions; a study with stutter in its stimuli is not the study it claims to be).

use results::SessionResults;

use crate::tables::{Table, fmt_opt};

/// One session's display figures.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionDisplay {
    /// `SUBJECT session N`.
    pub session: String,
    /// Adapter or monitor as the session recorded it; `None` when it recorded none.
    pub description: Option<String>,
    /// Refresh rate the session measured, Hz.
    pub refresh_hz: Option<f64>,
    /// Trials with frame timing (shown in a window; familiarization included).
    pub timed_trials: usize,
    /// Frames presented over those trials.
    pub frames_shown: u64,
    /// Frames dropped over those trials.
    pub dropped: u64,
    /// Mean over the trials of each trial's frame-interval SD, ms.
    pub mean_interval_sd_ms: Option<f64>,
    /// Dropped over shown + dropped, percent.
    pub dropped_percent: Option<f64>,
    /// Over the drop limit.
    pub flagged: bool,
    /// What the participant's browser measured (`study serve` sessions).
    pub browser: Option<results::store::BrowserInfo>,
    /// The viewing conditions the experimenter confirmed and measured (a study with
    /// `[viewing]`).
    pub viewing: Option<results::ViewingRecord>,
    /// The session's between-subject group (`[[design.groups]]`).
    pub group: Option<String>,
    /// The subject's id.
    pub subject: String,
    /// What the subject answered on the welcome screen (`[session] subject_fields`).
    pub subject_fields: std::collections::BTreeMap<String, String>,
}

/// One session's display figures, flagged when it dropped more than `drop_limit_percent` of
/// its frames.
#[must_use]
pub fn session_display(s: &SessionResults, drop_limit_percent: f64) -> SessionDisplay {
    let m = &s.manifest;
    let (mut timed, mut shown, mut dropped, mut sd_sum) = (0usize, 0u64, 0u64, 0.0);
    for r in &s.trials.records {
        let Some(t) = r.timing else { continue };
        timed += 1;
        shown += u64::from(t.frames_shown);
        dropped += u64::from(r.response.dropped_frames);
        sd_sum += t.interval_sd_ms;
    }
    let total = shown + dropped;
    let dropped_percent = (total > 0).then(|| 100.0 * dropped as f64 / total as f64);
    SessionDisplay {
        session: format!("{} session {}", m.subject, m.session),
        description: m.display.as_ref().map(|d| d.description.clone()),
        refresh_hz: m
            .display
            .as_ref()
            .map(|d| d.refresh_hz)
            .filter(|hz| *hz > 0.0),
        timed_trials: timed,
        frames_shown: shown,
        dropped,
        mean_interval_sd_ms: (timed > 0).then(|| sd_sum / timed as f64),
        dropped_percent,
        flagged: dropped_percent.is_some_and(|p| p > drop_limit_percent),
        browser: m.browser.clone(),
        viewing: m.viewing.clone(),
        group: m.group.clone(),
        subject: m.subject.clone(),
        subject_fields: m.subject_fields.clone(),
    }
}

/// The browsers of sessions served to browsers (`study serve`): user agent, screen and
/// window, device pixel ratio, measured refresh, fullscreen, and the trials during whose
/// stimuli the page was hidden or not fullscreen; `None` when no session ran in a browser.
#[must_use]
pub fn browser_table(rows: &[SessionDisplay]) -> Option<Table> {
    let rows: Vec<Vec<String>> = rows
        .iter()
        .filter_map(|r| r.browser.as_ref().map(|b| (r, b)))
        .map(|(r, b)| {
            let list = |v: &[u32]| {
                v.iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(" ")
            };
            vec![
                r.session.clone(),
                b.user_agent.clone(),
                format!("{}×{}", b.screen_px[0], b.screen_px[1]),
                format!("{}×{}", b.window_px[0], b.window_px[1]),
                format!("{:.2}", b.device_pixel_ratio),
                format!("{:.1}", b.refresh_hz),
                if b.fullscreen { "yes" } else { "no" }.to_owned(),
                list(&b.hidden_trials),
                list(&b.windowed_trials),
            ]
        })
        .collect();
    (!rows.is_empty()).then(|| Table {
        name: "browsers".to_owned(),
        caption: "Browser per session (study serve): screen and window in CSS pixels, refresh measured from requestAnimationFrame".to_owned(),
        columns: [
            "Session",
            "User agent",
            "Screen",
            "Window",
            "Pixel ratio",
            "Refresh (Hz)",
            "Fullscreen",
            "Hidden during stimuli (trials)",
            "Not fullscreen (trials)",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    })
}

/// The display table: one row per session.
#[must_use]
pub fn display_table(rows: &[SessionDisplay], drop_limit_percent: f64) -> Table {
    Table {
        name: "display".to_owned(),
        caption: format!(
            "Display per session: frames over the timed trials; flagged above {drop_limit_percent} % dropped"
        ),
        columns: [
            "Session",
            "Display",
            "Refresh (Hz)",
            "Timed trials",
            "Frames shown",
            "Dropped",
            "Dropped (%)",
            "Interval SD (ms)",
            "Flag",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    r.session.clone(),
                    r.description
                        .clone()
                        .unwrap_or_else(|| "not recorded".to_owned()),
                    fmt_opt(r.refresh_hz, 1),
                    r.timed_trials.to_string(),
                    r.frames_shown.to_string(),
                    r.dropped.to_string(),
                    fmt_opt(r.dropped_percent, 2),
                    fmt_opt(r.mean_interval_sd_ms, 2),
                    if r.flagged { "over the limit" } else { "" }.to_owned(),
                ]
            })
            .collect(),
    }
}
