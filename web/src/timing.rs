//! What a trial's frame intervals say, as the study window counts it: frames presented, the
//! intervals' sample standard deviation, and dropped frames (intervals over 1.5 refresh
//! periods of the rate the page measured before the session).

/// A trial's frame timing from the page's `requestAnimationFrame` intervals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stats {
    /// Frames presented (intervals + 1).
    pub frames: u32,
    /// Intervals over 1.5 refresh periods.
    pub dropped: u32,
    /// Sample standard deviation of the intervals, ms.
    pub sd_ms: f64,
}

/// The statistics of `intervals` (ms) against a refresh period of `period_ms`; `None` for
/// fewer than two intervals. Finite intervals can still overflow the sums (`[1e308, 0,
/// 1e308]` has an infinite mean and deviation), so the server takes only intervals
/// from 0 to [`crate::limits::MAX_REPORTED_MS`], at most [`crate::limits::MAX_INTERVALS`] of
/// them: their sums stay far below `f64`'s range.
pub fn stats(intervals: &[f64], period_ms: f64) -> Option<Stats> {
    if intervals.len() < 2 {
        return None;
    }
    let n = intervals.len() as f64;
    let mean = intervals.iter().sum::<f64>() / n;
    let var = intervals
        .iter()
        .map(|v| (v - mean) * (v - mean))
        .sum::<f64>()
        / (n - 1.0);
    let dropped = if period_ms > 0.0 {
        intervals.iter().filter(|v| **v > 1.5 * period_ms).count() as u32
    } else {
        0
    };
    Some(Stats {
        frames: intervals.len() as u32 + 1,
        dropped,
        sd_ms: var.sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_intervals_are_drops_and_the_sd_is_the_sample_sd() {
        let s = stats(&[16.7, 16.7, 33.4, 16.7, 50.0], 16.7).unwrap_or_else(|| panic!());
        assert_eq!((s.frames, s.dropped), (6, 2));
        // Python: statistics.stdev([16.7, 16.7, 33.4, 16.7, 50.0])
        assert!((s.sd_ms - 14.897_818_632).abs() < 1e-6, "{}", s.sd_ms);
        assert!(stats(&[16.7], 16.7).is_none());
    }
}
