//! The adaptive staircase of the 2AFC study (thesis ch. 5), step for step compatible with
//! PsychoPy's `StairHandler`.
//!
//! Thesis ch. 5 runs a two-down-one-up staircase on `t_L` (start 0.024, step 0.002, threshold =
//! mean of the last 3 reversal levels, after García-Pérez 1998). The counting rules, the
//! initial 1-up-1-down rule (`applyInitialRule`), reversal bookkeeping and the stop rule copy
//! `psychopy.data.StairHandler` (2026.2) so that a lab can compare the two; the golden test
//! `tests/staircase_psychopy.rs` checks level and reversal sequences on 2,000 random answer
//! sequences. Extension over PsychoPy: a down step that is `down_up_ratio` times the up step
//! (García-Pérez 1998: 0.5488 makes 2-down-1-up converge on 80.35 % correct), and a hard cap on
//! the number of trials.
//!
//! Levels lie on an exact grid ([`GridPoint`]): a level is computed from the value it started
//! from (the start, or the bound it was last clamped to) and the number of up and down steps
//! since (rounded to 12 significant digits), never accumulated step by step as PsychoPy does. Every path to one grid point gives
//! the same number, so logs and tables never hold 0.003999999999999993 beside 0.004; PsychoPy's
//! accumulated levels differ from ours by float rounding only (the golden tests compare within
//! 1e-12 relative for linear steps, 1e-9 for log and dB).

use serde::{Deserialize, Serialize};

/// How a step changes the level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepType {
    /// `level ± step` (PsychoPy `'lin'`).
    Linear,
    /// `level × 10^(±step)`, step in log10 units (PsychoPy `'log'`).
    Log,
    /// `level × 10^(±step/20)`, step in decibels (PsychoPy `'db'`).
    Db,
}

/// Settings of one staircase.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StaircaseSettings {
    /// First level shown.
    pub start: f64,
    /// Up step (and down step when `down_up_ratio` is 1), in the units of `step_type`.
    pub step: f64,
    /// Linear, log10 or dB steps.
    pub step_type: StepType,
    /// Down step / up step; 1 reproduces PsychoPy, 0.5488 targets 80.35 % for 2-down-1-up.
    pub down_up_ratio: f64,
    /// Lowest level (levels are clamped), if any.
    pub min: Option<f64>,
    /// Highest level (levels are clamped), if any.
    pub max: Option<f64>,
    /// Wrong answers in a row that move the level up (PsychoPy `nUp`).
    pub n_up: u32,
    /// Correct answers in a row that move the level down (PsychoPy `nDown`).
    pub n_down: u32,
    /// 1-up-1-down until the first reversal (PsychoPy `applyInitialRule`).
    pub apply_initial_rule: bool,
    /// Stop once this many reversals happened and `min_trials` were run (PsychoPy
    /// `nReversals`); `None`: reversals never stop the staircase.
    pub stop_reversals: Option<u32>,
    /// Trials required before the reversal rule may stop (PsychoPy `nTrials`).
    pub min_trials: u32,
    /// Stop after this many trials whatever the reversals (not in PsychoPy).
    pub max_trials: Option<u32>,
    /// The threshold is the mean level of the last this many reversals (thesis ch. 5: 3).
    pub threshold_reversals: u32,
}

impl Default for StaircaseSettings {
    /// Thesis ch. 5: start 0.024, step 0.002, two-down-one-up, last 3 reversals.
    fn default() -> Self {
        Self {
            start: 0.024,
            step: 0.002,
            step_type: StepType::Linear,
            down_up_ratio: 1.0,
            min: Some(0.0),
            max: None,
            n_up: 1,
            n_down: 2,
            apply_initial_rule: false,
            stop_reversals: Some(12),
            min_trials: 0,
            max_trials: Some(80),
            threshold_reversals: 3,
        }
    }
}

/// Why staircase settings or a call were rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StaircaseError {
    /// A setting is out of its range.
    #[error("staircase setting `{key}`: {reason}")]
    BadSetting {
        /// Setting name as in the study file.
        key: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A response was added after the staircase finished.
    #[error("staircase already finished after {trials} trials")]
    Finished {
        /// Trials run.
        trials: usize,
    },
}

/// Direction of the last level change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    Start,
    Up,
    Down,
}

/// What one response did to the staircase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutcome {
    /// Level of the trial that was answered.
    pub level: f64,
    /// The answer made this trial a reversal point.
    pub reversal: bool,
    /// The staircase finished with this answer.
    pub finished: bool,
}

/// A running staircase (PsychoPy `StairHandler` state).
#[derive(Debug, Clone, PartialEq)]
pub struct Staircase {
    settings: StaircaseSettings,
    answers: Vec<bool>,
    levels: Vec<f64>,
    reversal_trials: Vec<usize>,
    reversal_levels: Vec<f64>,
    correct_counter: i64,
    direction: Direction,
    next: GridPoint,
    initial_rule: bool,
    finished: bool,
}

/// Checks staircase settings, returning every problem (setting name, reason).
pub fn check_settings(s: &StaircaseSettings) -> Vec<StaircaseError> {
    let mut errs = Vec::new();
    let mut bad =
        |key: &'static str, reason: String| errs.push(StaircaseError::BadSetting { key, reason });
    if !s.start.is_finite() {
        bad("start", "must be a finite number".into());
    }
    if !(s.step.is_finite() && s.step > 0.0) {
        bad("step", format!("must be a positive number, got {}", s.step));
    }
    if !(s.down_up_ratio.is_finite() && s.down_up_ratio > 0.0) {
        bad(
            "down_up_ratio",
            format!("must be a positive number, got {}", s.down_up_ratio),
        );
    }
    if matches!(s.step_type, StepType::Log | StepType::Db)
        && s.start.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
    {
        bad("start", "log and dB steps need a positive start".into());
    }
    if let (Some(lo), Some(hi)) = (s.min, s.max)
        && lo.partial_cmp(&hi) == Some(std::cmp::Ordering::Greater)
    {
        bad("min", format!("min {lo} is above max {hi}"));
    }
    if let Some(lo) = s.min {
        if !lo.is_finite() {
            bad("min", "must be finite".into());
        } else if s.start < lo {
            bad("start", format!("start {} is below min {lo}", s.start));
        }
    }
    if let Some(hi) = s.max {
        if !hi.is_finite() {
            bad("max", "must be finite".into());
        } else if s.start > hi {
            bad("start", format!("start {} is above max {hi}", s.start));
        }
    }
    if s.n_up == 0 {
        bad("n_up", "must be at least 1".into());
    }
    if s.n_down == 0 {
        bad("n_down", "must be at least 1".into());
    }
    if s.stop_reversals.is_none() && s.max_trials.is_none() {
        bad(
            "stop_reversals",
            "set stop_reversals and/or max_trials, or the staircase never ends".into(),
        );
    }
    if s.stop_reversals == Some(0) {
        bad("stop_reversals", "must be at least 1".into());
    }
    if s.max_trials == Some(0) {
        bad("max_trials", "must be at least 1".into());
    }
    if s.threshold_reversals == 0 {
        bad("threshold_reversals", "must be at least 1".into());
    }
    errs
}

impl Staircase {
    /// A staircase at its start level.
    ///
    /// # Errors
    /// The first problem [`check_settings`] finds.
    pub fn new(settings: StaircaseSettings) -> Result<Self, StaircaseError> {
        if let Some(e) = check_settings(&settings).into_iter().next() {
            return Err(e);
        }
        Ok(Self {
            next: GridPoint::start(&settings),
            settings,
            answers: Vec::new(),
            levels: Vec::new(),
            reversal_trials: Vec::new(),
            reversal_levels: Vec::new(),
            correct_counter: 0,
            direction: Direction::Start,
            initial_rule: false,
            finished: false,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &StaircaseSettings {
        &self.settings
    }

    /// Level of the next trial, or `None` once finished.
    pub fn next_level(&self) -> Option<f64> {
        (!self.finished).then_some(self.next.level(&self.settings))
    }

    /// Whether the stop rule has fired.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// Levels of the trials run so far.
    pub fn levels(&self) -> &[f64] {
        &self.levels
    }

    /// Levels at the reversal points, in order.
    pub fn reversal_levels(&self) -> &[f64] {
        &self.reversal_levels
    }

    /// Trial indices (0-based, within this staircase) that were reversal points.
    pub fn reversal_trials(&self) -> &[usize] {
        &self.reversal_trials
    }

    /// Mean level of the last `threshold_reversals` reversals (thesis ch. 5), or `None` when
    /// fewer reversals happened.
    pub fn threshold(&self) -> Option<f64> {
        let k = self.settings.threshold_reversals as usize;
        if k == 0 || self.reversal_levels.len() < k {
            return None;
        }
        let last = &self.reversal_levels[self.reversal_levels.len() - k..];
        Some(last.iter().sum::<f64>() / k as f64)
    }

    /// Records the answer to a trial at [`Self::next_level`] and moves the level
    /// (PsychoPy `next()` + `addResponse()` + `calculateNextIntensity()`).
    ///
    /// # Errors
    /// [`StaircaseError::Finished`] when the staircase has already stopped.
    pub fn add_response(&mut self, correct: bool) -> Result<StepOutcome, StaircaseError> {
        if self.finished {
            return Err(StaircaseError::Finished {
                trials: self.levels.len(),
            });
        }
        let level = self.next.level(&self.settings);
        self.levels.push(level);
        let trial = self.levels.len() - 1;
        let previous = self.answers.last().copied();
        self.answers.push(correct);
        // PsychoPy counts runs: +n after n correct in a row, -n after n wrong in a row.
        self.correct_counter = match (correct, previous) {
            (true, Some(true)) => self.correct_counter + 1,
            (true, _) => 1,
            (false, Some(false)) => self.correct_counter - 1,
            (false, _) => -1,
        };
        let n_down = i64::from(self.settings.n_down);
        let n_up = i64::from(self.settings.n_up);
        let initial = self.reversal_levels.is_empty() && self.settings.apply_initial_rule;
        let reversal = if initial {
            let rev = if correct {
                self.direction == Direction::Up
            } else {
                self.direction == Direction::Down
            };
            self.direction = if correct {
                Direction::Down
            } else {
                Direction::Up
            };
            rev
        } else if self.correct_counter >= n_down {
            let rev = self.direction == Direction::Up;
            self.direction = Direction::Down;
            rev
        } else if self.correct_counter <= -n_up {
            let rev = self.direction == Direction::Down;
            self.direction = Direction::Up;
            rev
        } else {
            false
        };
        if reversal {
            self.reversal_trials.push(trial);
            if self.reversal_levels.is_empty() && self.settings.apply_initial_rule {
                self.initial_rule = true;
            }
            self.reversal_levels.push(level);
        }
        let by_reversals = self.settings.stop_reversals.is_some_and(|n| {
            self.reversal_levels.len() >= n as usize
                && self.levels.len() >= self.settings.min_trials as usize
        });
        let by_trials = self
            .settings
            .max_trials
            .is_some_and(|n| self.levels.len() >= n as usize);
        if by_reversals || by_trials {
            self.finished = true;
        }
        if (self.reversal_levels.is_empty() || self.initial_rule)
            && self.settings.apply_initial_rule
        {
            self.initial_rule = false;
            self.step(!correct);
        } else if self.correct_counter >= n_down {
            self.step(false);
        } else if self.correct_counter <= -n_up {
            self.step(true);
        }
        Ok(StepOutcome {
            level,
            reversal,
            finished: self.finished,
        })
    }

    /// Moves the next level one step up or down and starts counting answers afresh.
    fn step(&mut self, up: bool) {
        self.next = self.next.stepped(&self.settings, up);
        self.correct_counter = 0;
    }
}

/// Digits a grid level keeps: enough for any study's levels, few enough that `0.024 − 9 ×
/// 0.002` reads as the 0.006 the study file means (not 0.005999999999999998) and equals a bound
/// written as that decimal.
const LEVEL_DIGITS: usize = 12;

/// `x` rounded to 12 significant digits (through its decimal form, so the result
/// is the nearest double to that decimal): the level a grid point has. Readers of logs written
/// before the exact grid (levels accumulated step by step) key them with this, so that
/// 0.003999999999999993 and 0.004 are one level in every table.
pub fn canonical_level(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    format!("{x:.prec$e}", prec = LEVEL_DIGITS - 1)
        .parse()
        .unwrap_or(x)
}

/// A point of a staircase's level grid: the level it started from (the start level, or the
/// bound it was last clamped to) and the up and down steps taken since.
///
/// The level is `base + (ups − downs × down_up_ratio) × step` for linear steps, and `base ×
/// 10^((ups − downs × ratio) × step)` (log10 units) or `base × 10^((ups − downs × ratio) ×
/// step / 20)` (dB) otherwise, computed from the counts each time and rounded to 12
/// significant digits: with `down_up_ratio` 1 every path with the same net count gives the
/// same number, bit for bit, and a linear level is the decimal the start and step make. A step that would leave
/// `[min, max]` lands on the bound, which becomes the new base (PsychoPy clamps the same way).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GridPoint {
    /// `f64::to_bits` of the base level (bits, so the point can be a map key).
    base: u64,
    ups: i64,
    downs: i64,
}

impl GridPoint {
    /// The start level of `settings`.
    pub fn start(settings: &StaircaseSettings) -> Self {
        Self {
            base: settings.start.to_bits(),
            ups: 0,
            downs: 0,
        }
    }

    /// The level at this point.
    pub fn level(&self, settings: &StaircaseSettings) -> f64 {
        let base = f64::from_bits(self.base);
        #[expect(
            clippy::cast_precision_loss,
            reason = "step counts are at most a session's trials, far below 2^52"
        )]
        let k = self.ups as f64 - self.downs as f64 * settings.down_up_ratio;
        let x = match settings.step_type {
            StepType::Linear => base + k * settings.step,
            StepType::Log => base * 10_f64.powf(k * settings.step),
            StepType::Db => base * 10_f64.powf(k * settings.step / 20.0),
        };
        canonical_level(x)
    }

    /// The point one step up (`up`) or down from this one, clamped to `[min, max]`: where a
    /// staircase with `settings` goes after `n_up` wrong or `n_down` correct answers in a row.
    /// The study file's check that every reachable level has a stimulus walks the grid with
    /// this same function, so it sees exactly the levels a session will show.
    #[must_use]
    pub fn stepped(&self, settings: &StaircaseSettings, up: bool) -> Self {
        let mut next = *self;
        if up {
            next.ups += 1;
        } else {
            next.downs += 1;
        }
        if settings.down_up_ratio.to_bits() == 1.0_f64.to_bits() {
            // One net count per level: paths that reach it compare equal as points too.
            let common = next.ups.min(next.downs);
            next.ups -= common;
            next.downs -= common;
        }
        let x = next.level(settings);
        let bound = |b: f64| Self {
            base: b.to_bits(),
            ups: 0,
            downs: 0,
        };
        match (settings.min, settings.max) {
            (Some(lo), _) if x < lo => bound(lo),
            (_, Some(hi)) if x > hi => bound(hi),
            _ => next,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thesis_example_two_down_one_up() {
        let mut s = Staircase::new(StaircaseSettings {
            max_trials: None,
            ..StaircaseSettings::default()
        })
        .unwrap();
        // correct, correct -> down one step; wrong -> up one step (reversal at the wrong answer).
        assert!((s.add_response(true).unwrap().level - 0.024).abs() < 1e-15);
        assert!((s.add_response(true).unwrap().level - 0.024).abs() < 1e-15);
        assert!((s.next_level().unwrap() - 0.022).abs() < 1e-12);
        let o = s.add_response(false).unwrap();
        assert!(o.reversal);
        assert!((s.next_level().unwrap() - 0.024).abs() < 1e-12);
    }

    #[test]
    fn grid_points_step_by_the_step_type_and_clamp() {
        let lin = StaircaseSettings {
            start: 0.024,
            step: 0.002,
            down_up_ratio: 0.5,
            min: Some(0.001),
            max: Some(0.03),
            ..StaircaseSettings::default()
        };
        let p = GridPoint::start(&lin);
        assert!((p.stepped(&lin, true).level(&lin) - 0.026).abs() < 1e-15);
        assert!(
            (p.stepped(&lin, false).level(&lin) - 0.023).abs() < 1e-15,
            "half a step down"
        );
        let mut low = p;
        for _ in 0..60 {
            low = low.stepped(&lin, false);
        }
        assert_eq!(
            low.level(&lin).to_bits(),
            0.001_f64.to_bits(),
            "clamped to min"
        );
        assert!(
            (low.stepped(&lin, true).level(&lin) - 0.003).abs() < 1e-15,
            "from the bound"
        );
        let mut high = p;
        for _ in 0..4 {
            high = high.stepped(&lin, true);
        }
        assert_eq!(
            high.level(&lin).to_bits(),
            0.03_f64.to_bits(),
            "clamped to max"
        );
        let log = StaircaseSettings {
            start: 2.0,
            step_type: StepType::Log,
            step: 1.0,
            down_up_ratio: 1.0,
            min: None,
            max: None,
            ..StaircaseSettings::default()
        };
        let p = GridPoint::start(&log);
        assert!((p.stepped(&log, true).level(&log) - 20.0).abs() < 1e-12);
        assert!((p.stepped(&log, false).level(&log) - 0.2).abs() < 1e-15);
        let db = StaircaseSettings {
            step_type: StepType::Db,
            step: 20.0,
            ..log
        };
        assert!((GridPoint::start(&db).stepped(&db, false).level(&db) - 0.2).abs() < 1e-15);
    }

    #[test]
    fn every_path_to_a_grid_point_gives_the_same_level() {
        // The thesis staircase: accumulated, 0.024 - 10 x 0.002 went 0.003999999999999993 on
        // one path and 0.004 on another; on the grid both are one number.
        let s = StaircaseSettings {
            min: Some(0.002),
            max: Some(0.04),
            ..StaircaseSettings::default()
        };
        let mut rng = 0x5eed_u64;
        let mut by_net: std::collections::HashMap<i64, u64> = std::collections::HashMap::new();
        for _ in 0..500 {
            let mut p = GridPoint::start(&s);
            let mut net = 0_i64;
            for _ in 0..14 {
                rng = rng.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                let up = rng >> 63 == 1;
                // Stay inside the bounds, where the net count alone decides the level.
                if (up && net < 7) || (!up && net > -10) {
                    p = p.stepped(&s, up);
                    net += if up { 1 } else { -1 };
                }
                let bits = p.level(&s).to_bits();
                assert_eq!(*by_net.entry(net).or_insert(bits), bits, "net {net}");
            }
        }
        assert_eq!(by_net.len(), 18, "every net count from -10 to 7 reached");
        let accumulated = (0..10).fold(0.024_f64, |x, _| x - 0.002);
        assert_ne!(
            accumulated.to_bits(),
            0.004_f64.to_bits(),
            "the defect being fixed"
        );
    }

    #[test]
    fn bad_settings_are_all_reported() {
        let s = StaircaseSettings {
            step: 0.0,
            start: -1.0,
            n_down: 0,
            stop_reversals: None,
            max_trials: None,
            ..StaircaseSettings::default()
        };
        assert_eq!(check_settings(&s).len(), 4);
        assert!(Staircase::new(s).is_err());
    }
}
