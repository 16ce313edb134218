//! Frame timing: intervals between presented frames, dropped frames, and the refresh period
//! they are counted against.
//!
//! The window calls [`FrameClock::tick`] once per frame at the start of the frame's update.
//! With FIFO presentation (vsync) and a frame latency of one, the event loop blocks in present
//! until the previous frame reached the display, so the interval between successive ticks is
//! the presentation interval. An interval over 1.5 refresh periods means a frame was missed.

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
        }
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
                    self.period_ms = Some(estimate_period(&self.warmup, self.monitor_hz));
                }
            }
            Some((period, _)) => {
                self.session.frame();
                self.session.interval(ms, period);
                if self.recording {
                    self.segment.frame();
                    self.segment.interval(ms, period);
                    self.intervals.push(ms);
                }
            }
        }
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
    let mut v: Vec<f64> = intervals
        .iter()
        .copied()
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    v.sort_by(f64::total_cmp);
    let median = match v.len() {
        0 => monitor_hz.map_or(1000.0 / 60.0, |h| 1000.0 / h),
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    };
    if let Some(hz) = monitor_hz {
        let p = 1000.0 / hz;
        if (median - p).abs() <= 0.1 * p {
            return (p, PeriodSource::Monitor);
        }
    }
    (median, PeriodSource::Measured)
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
}
