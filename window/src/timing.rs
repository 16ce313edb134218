//! Frame timing: intervals between presented frames, dropped frames, and the refresh period
//! they are counted against.
//!
//! The window calls [`FrameClock::tick`] once per frame at the start of the frame's update.
//! With FIFO presentation (vsync) and a frame latency of one, the event loop blocks in present
//! until the previous frame reached the display, so the interval between successive ticks is
//! the presentation interval. An interval over 1.5 refresh periods means a frame was missed.
//!
//! The period is first estimated over [`WARMUP_FRAMES`] frames drawn under a trial's load (the
//! window draws two skeletons while the clock is not calibrated), then re-checked on trial
//! frames: the median of the last [`RECHECK_FRAMES`] trial intervals is a running estimate,
//! and when it departs from the period by more than [`DRIFT_SHARE`] a [`Drift`] is recorded.
//! A measured period (software rendering, or a monitor whose report the intervals did not
//! confirm) is then re-based to the running estimate, so a trial's frames are not all counted
//! as drops against a period measured on a cheaper screen; a period the monitor confirmed is
//! the display's own and is kept (steady misses of a real refresh are real drops), the drift
//! is only reported.

use std::time::Instant;

/// Interval statistics over a set of frames.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct IntervalStats {
    /// Frames presented (intervals + 1 once a frame was seen).
    pub frames: u32,
    /// Intervals over 1.5 refresh periods.
    pub dropped: u32,
    /// Mean interval, ms.
    pub mean_ms: f64,
    /// Sample standard deviation of the intervals, ms.
    pub sd_ms: f64,
    /// Longest interval, ms.
    pub max_ms: f64,
}

#[derive(Debug, Clone, Copy, Default)]
struct Accumulator {
    frames: u32,
    dropped: u32,
    n: u64,
    mean: f64,
    m2: f64,
    max: f64,
}

impl Accumulator {
    fn frame(&mut self) {
        self.frames += 1;
    }

    fn interval(&mut self, ms: f64, period_ms: f64) {
        // Welford's update: stable for long sessions.
        self.n += 1;
        let d = ms - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (ms - self.mean);
        self.max = self.max.max(ms);
        if ms > 1.5 * period_ms {
            self.dropped += 1;
        }
    }

    fn stats(&self) -> IntervalStats {
        IntervalStats {
            frames: self.frames,
            dropped: self.dropped,
            mean_ms: self.mean,
            sd_ms: if self.n > 1 {
                (self.m2 / (self.n - 1) as f64).sqrt()
            } else {
                0.0
            },
            max_ms: self.max,
        }
    }
}

/// Where the refresh period came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeriodSource {
    /// The monitor's reported refresh rate, confirmed by the measured intervals.
    Monitor,
    /// The median of the measured intervals (no report, or the report disagreed).
    Measured,
}

/// Frames needed before the refresh period is estimated.
pub const WARMUP_FRAMES: usize = 30;
/// Trial intervals the running estimate is the median of.
pub const RECHECK_FRAMES: usize = 15;
/// Relative departure of the running estimate from the period that counts as a drift.
pub const DRIFT_SHARE: f64 = 0.1;

/// A departure of the running estimate (trial frames) from the refresh period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drift {
    /// Frames since calibration when it was seen.
    pub frame: u32,
    /// The period drops were counted against until then, ms.
    pub from_ms: f64,
    /// The running estimate, ms.
    pub to_ms: f64,
    /// Whether drops are counted against `to_ms` from then on (a measured period), or the
    /// period stays (a monitor-confirmed one).
    pub rebased: bool,
}

/// Per-frame clock of the window.
#[derive(Debug, Clone)]
pub struct FrameClock {
    last: Option<Instant>,
    monitor_hz: Option<f64>,
    warmup: Vec<f64>,
    period_ms: Option<(f64, PeriodSource)>,
    session: Accumulator,
    segment: Accumulator,
    recording: bool,
    intervals: Vec<f64>,
    software: bool,
    recent: Vec<f64>,
    next_recent: usize,
    /// The last running estimate reported (starts at the period).
    reported_ms: f64,
    drifts: Vec<Drift>,
    revision: u32,
}

impl FrameClock {
    /// A clock; `monitor_hz` is what the windowing system reports, if anything.
    pub fn new(monitor_hz: Option<f64>) -> FrameClock {
        FrameClock {
            last: None,
            monitor_hz: monitor_hz.filter(|h| h.is_finite() && *h > 1.0),
            warmup: Vec::new(),
            period_ms: None,
            session: Accumulator::default(),
            segment: Accumulator::default(),
            recording: false,
            intervals: Vec::new(),
            software: false,
            recent: Vec::with_capacity(RECHECK_FRAMES),
            next_recent: 0,
            reported_ms: 0.0,
            drifts: Vec::new(),
            revision: 0,
        }
    }

    /// Marks the adapter as a software rasteriser: its frames are paced by rasterisation, not
    /// by a display's refresh, so the monitor's report is never taken as the period.
    #[must_use]
    pub fn software(mut self, software: bool) -> FrameClock {
        self.software = software;
        self
    }

    /// Records a frame starting at `now`; returns the interval since the previous frame, ms.
    pub fn tick(&mut self, now: Instant) -> Option<f64> {
        let interval = self
            .last
            .map(|l| now.saturating_duration_since(l).as_secs_f64() * 1e3);
        self.last = Some(now);
        if let Some(ms) = interval {
            self.observe(ms);
        }
        interval
    }

    /// Feeds one measured interval (ms); `tick` calls it.
    pub fn observe(&mut self, ms: f64) {
        match self.period_ms {
            None => {
                self.warmup.push(ms);
                if self.warmup.len() >= WARMUP_FRAMES {
                    let monitor = self.monitor_hz.filter(|_| !self.software);
                    let estimate = estimate_period(&self.warmup, monitor);
                    self.reported_ms = estimate.0;
                    self.period_ms = Some(estimate);
                    self.revision += 1;
                }
            }
            Some((period, _)) => {
                self.session.frame();
                self.session.interval(ms, period);
                if self.recording {
                    self.segment.frame();
                    self.segment.interval(ms, period);
                    self.intervals.push(ms);
                    self.recheck(ms);
                }
            }
        }
    }

    /// Adds a trial interval to the running estimate and records a drift when the estimate
    /// departs from the last one reported.
    fn recheck(&mut self, ms: f64) {
        if !(ms.is_finite() && ms > 0.0) {
            return;
        }
        if self.recent.len() < RECHECK_FRAMES {
            self.recent.push(ms);
        } else if let Some(slot) = self.recent.get_mut(self.next_recent) {
            *slot = ms;
        }
        self.next_recent = (self.next_recent + 1) % RECHECK_FRAMES;
        if self.recent.len() < RECHECK_FRAMES {
            return;
        }
        let Some((period, source)) = self.period_ms else {
            return;
        };
        let estimate = median(&self.recent);
        if (estimate - self.reported_ms).abs() <= DRIFT_SHARE * self.reported_ms {
            return;
        }
        let rebased = source == PeriodSource::Measured;
        self.drifts.push(Drift {
            frame: self.session.frames,
            from_ms: period,
            to_ms: estimate,
            rebased,
        });
        self.reported_ms = estimate;
        self.revision += 1;
        if rebased {
            self.period_ms = Some((estimate, PeriodSource::Measured));
            // The next estimate is made of frames counted against the new period.
            self.recent.clear();
            self.next_recent = 0;
        }
    }

    /// Drifts seen on trial frames, in order.
    #[cfg(test)]
    pub fn drifts(&self) -> &[Drift] {
        &self.drifts
    }

    /// Changes each time the period is estimated or a drift is recorded (a session manifest
    /// written with an older revision is out of date).
    pub fn revision(&self) -> u32 {
        self.revision
    }

    /// The running estimate of the period from the last [`RECHECK_FRAMES`] trial intervals,
    /// once that many were seen since the last re-basing.
    #[cfg(test)]
    pub fn running_estimate(&self) -> Option<f64> {
        (self.recent.len() == RECHECK_FRAMES).then(|| median(&self.recent))
    }

    /// One line on the re-check for the session manifest: the drifts seen on trial frames,
    /// or `None` while there were none.
    pub fn drift_note(&self) -> Option<String> {
        let last = self.drifts.last()?;
        let what = if last.rebased {
            "drops counted against it from then on"
        } else {
            "the monitor's period kept, so these are missed refreshes"
        };
        Some(format!(
            "refresh re-checked on trial frames: {} drift(s), the last at frame {}: {:.2} ms → {:.2} ms \
             ({what})",
            self.drifts.len(),
            last.frame,
            last.from_ms,
            last.to_ms
        ))
    }

    /// The refresh period and where it came from, once estimated.
    pub fn period(&self) -> Option<(f64, PeriodSource)> {
        self.period_ms
    }

    /// True once the refresh period is known (the runner waits for it before a first trial).
    pub fn calibrated(&self) -> bool {
        self.period_ms.is_some()
    }

    /// Starts counting a trial's frames.
    pub fn start_segment(&mut self) {
        self.segment = Accumulator::default();
        self.intervals.clear();
        self.recording = true;
    }

    /// Stops counting and returns the trial's statistics.
    pub fn end_segment(&mut self) -> IntervalStats {
        self.recording = false;
        self.segment.stats()
    }

    /// The intervals of the current (or last) segment, ms, in order.
    pub fn segment_intervals(&self) -> &[f64] {
        &self.intervals
    }

    /// Statistics of the current segment so far.
    #[cfg(test)]
    pub fn segment(&self) -> IntervalStats {
        self.segment.stats()
    }

    /// Statistics since calibration.
    pub fn session(&self) -> IntervalStats {
        self.session.stats()
    }

    /// Forgets the previous frame time (after a pause in which no frames were drawn, so the
    /// gap is not counted as a drop).
    pub fn reset_last(&mut self) {
        self.last = None;
    }
}

/// The refresh period: the monitor's report when the measured median agrees within 10 %,
/// otherwise the median interval itself (software rendering, or a report that is wrong).
pub fn estimate_period(intervals: &[f64], monitor_hz: Option<f64>) -> (f64, PeriodSource) {
    let v: Vec<f64> = intervals
        .iter()
        .copied()
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    let median = if v.is_empty() {
        monitor_hz.map_or(1000.0 / 60.0, |h| 1000.0 / h)
    } else {
        median(&v)
    };
    if let Some(hz) = monitor_hz {
        let p = 1000.0 / hz;
        if (median - p).abs() <= 0.1 * p {
            return (p, PeriodSource::Monitor);
        }
    }
    (median, PeriodSource::Measured)
}

/// The median of a non-empty series (0 for an empty one).
fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn calibrated(monitor: Option<f64>, period: f64) -> FrameClock {
        let mut c = FrameClock::new(monitor);
        for _ in 0..WARMUP_FRAMES {
            c.observe(period);
        }
        c
    }

    #[test]
    fn a_monitor_report_is_used_only_when_the_intervals_agree() {
        assert_eq!(
            estimate_period(&[16.9, 16.5, 16.7], Some(60.0)).1,
            PeriodSource::Monitor
        );
        // Software rendering at 21 fps on a "60 Hz" X screen: the measured period wins.
        let (p, src) = estimate_period(&[47.0, 46.0, 48.0, 200.0], Some(60.0));
        assert_eq!(src, PeriodSource::Measured);
        assert!((p - 47.5).abs() < 1e-9);
        assert_eq!(estimate_period(&[], None).1, PeriodSource::Measured);
    }

    #[test]
    fn intervals_over_one_and_a_half_periods_are_dropped_frames() {
        let mut c = calibrated(Some(60.0), 16.7);
        c.start_segment();
        for ms in [16.6, 16.8, 25.1, 24.9, 33.4, 16.7] {
            c.observe(ms);
        }
        let s = c.end_segment();
        assert_eq!(s.frames, 6);
        assert_eq!(c.segment_intervals(), [16.6, 16.8, 25.1, 24.9, 33.4, 16.7]);
        // 1.5 × 16.667 = 25.0: 25.1 is over, 24.9 is not.
        assert_eq!(s.dropped, 2);
        assert!((s.max_ms - 33.4).abs() < 1e-12);
        let v = [16.6, 16.8, 25.1, 24.9, 33.4, 16.7];
        let mean = v.iter().sum::<f64>() / 6.0;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 5.0).sqrt();
        assert!((s.mean_ms - mean).abs() < 1e-9 && (s.sd_ms - sd).abs() < 1e-9);
        // Outside a segment only the session counts.
        c.observe(100.0);
        assert_eq!(c.segment().frames, 6);
        assert_eq!(c.session().dropped, 3);
    }

    #[test]
    fn nothing_is_counted_before_calibration() {
        let mut c = FrameClock::new(None);
        c.start_segment();
        for _ in 0..WARMUP_FRAMES - 1 {
            c.observe(40.0);
        }
        assert!(!c.calibrated());
        assert_eq!(c.segment().frames, 0);
        c.observe(40.0);
        assert_eq!(c.period(), Some((40.0, PeriodSource::Measured)));
    }

    /// Intervals of a calibration on the welcome screen at `welcome` ms, then one trial of
    /// `trial` intervals at `trial_ms`; returns the trial's statistics.
    fn welcome_then_trial(
        clock: FrameClock,
        welcome: f64,
        trial_ms: f64,
        trial: usize,
    ) -> (FrameClock, IntervalStats) {
        let mut c = clock;
        for k in 0..WARMUP_FRAMES {
            // A little jitter, as measured intervals have.
            c.observe(welcome + 0.1 * (k % 3) as f64);
        }
        c.start_segment();
        for k in 0..trial {
            c.observe(trial_ms + 0.5 * (k % 4) as f64 - 0.75);
        }
        let s = c.end_segment();
        (c, s)
    }

    #[test]
    fn a_fast_welcome_screen_does_not_make_every_software_trial_frame_a_drop() {
        // lavapipe: the welcome screen at 16.7 ms, a trial with two skeletons at 47 ms, for
        // 5 s (106 frames). With no monitor report, and with a 60 Hz report on a software
        // adapter, the period is measured and re-based once the trial's frames show it.
        for clock in [
            FrameClock::new(None),
            FrameClock::new(Some(60.0)).software(true),
        ] {
            let (c, s) = welcome_then_trial(clock, 16.7, 47.0, 106);
            assert_eq!(s.frames, 106);
            assert!(
                s.dropped <= RECHECK_FRAMES as u32,
                "{} of 106 frames counted as dropped",
                s.dropped
            );
            let (p, src) = c.period().unwrap();
            assert_eq!(src, PeriodSource::Measured);
            assert!((p - 47.0).abs() < 1.0, "re-based to {p}");
            let d = c.drifts();
            assert_eq!(d.len(), 1, "{d:?}");
            assert!(d[0].rebased && (d[0].from_ms - 16.8).abs() < 0.2);
            let note = c.drift_note().unwrap();
            assert!(note.contains("16.80 ms → 4"), "{note:?}");
            // A second trial at the same rate: nothing dropped, no new drift.
            let mut c = c;
            c.start_segment();
            for _ in 0..50 {
                c.observe(47.2);
            }
            assert_eq!(c.end_segment().dropped, 0);
            assert_eq!(c.drifts().len(), 1);
        }
    }

    #[test]
    fn a_monitor_confirmed_period_is_kept_and_its_misses_are_drops_with_a_drift_reported() {
        // A GPU on a 60 Hz monitor whose trial misses every other refresh: real drops.
        let (c, s) = welcome_then_trial(FrameClock::new(Some(60.0)), 16.7, 33.4, 60);
        assert_eq!(c.period().unwrap().1, PeriodSource::Monitor);
        assert!((c.period().unwrap().0 - 1000.0 / 60.0).abs() < 1e-9);
        assert_eq!(s.dropped, 60);
        let d = c.drifts();
        assert_eq!(d.len(), 1, "reported once, not once per window: {d:?}");
        assert!(!d[0].rebased);
        assert!(c.drift_note().unwrap().contains("missed refreshes"));
    }

    #[test]
    fn a_steady_trial_at_the_calibrated_rate_reports_no_drift_and_isolated_drops_count() {
        let (c, s) = welcome_then_trial(FrameClock::new(None), 47.0, 47.0, 100);
        assert_eq!((s.dropped, c.drifts().len()), (0, 0));
        assert!(c.drift_note().is_none());
        let rev = c.revision();
        let mut c = c;
        c.start_segment();
        for k in 0..60 {
            c.observe(if k % 10 == 0 { 95.0 } else { 47.0 });
        }
        // One long interval in ten leaves the median, and the period, where they were.
        assert_eq!(c.end_segment().dropped, 6);
        assert_eq!((c.drifts().len(), c.revision()), (0, rev));
        assert!((c.running_estimate().unwrap() - 47.0).abs() < 1e-9);
    }
}
