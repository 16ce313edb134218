//! Bounds on what a request may cost: body size, requests per participant and joins per
//! second (token buckets), how long a client may take to send a request's head and body,
//! connections per client address, and the lengths and sizes of what a page reports.

use std::time::{Duration, Instant};

/// Request limits of a server.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest request body, bytes (an answer carries the trial's frame intervals).
    pub max_body_bytes: usize,
    /// Requests a participant may make per second, sustained.
    pub participant_rate: f64,
    /// Requests a participant may make at once before the rate applies.
    pub participant_burst: f64,
    /// New participants per second, sustained (all addresses together: behind a reverse
    /// proxy every request comes from the proxy).
    pub join_rate: f64,
    /// New participants at once before the rate applies.
    pub join_burst: f64,
    /// Most participants the server takes (the study's quota when it sets one is smaller).
    pub max_participants: usize,
    /// Longest a client may take to send a request's line and headers, from its first byte
    /// (or, on a kept-alive connection, from the end of the last reply): the connection is
    /// closed after it.
    pub header_timeout: Duration,
    /// Longest a client may take to send a request's body once its head is in (408 after).
    pub body_timeout: Duration,
    /// Most connections open at once from one client address; more are closed as soon as
    /// they are accepted. Behind a reverse proxy every connection comes from the proxy.
    pub max_connections_per_address: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_body_bytes: 256 << 10,
            participant_rate: 20.0,
            participant_burst: 60.0,
            join_rate: 20.0,
            join_burst: 200.0,
            max_participants: 100_000,
            header_timeout: Duration::from_secs(10),
            body_timeout: Duration::from_secs(30),
            max_connections_per_address: 512,
        }
    }
}

/// Most frame intervals one answer may carry (a 60-s presentation at 240 Hz is 14,400).
pub const MAX_INTERVALS: usize = 20_000;

/// Longest time an answer may report, ms (a day): each frame interval (a page left in a
/// background tab has one long interval), the time played and the response time. Finite
/// and not negative too, so that no sum over them overflows.
pub const MAX_REPORTED_MS: f64 = 86_400_000.0;

/// A token bucket: `burst` requests at once, then `rate` per second.
#[derive(Debug, Clone)]
pub struct Bucket {
    tokens: f64,
    last: Instant,
}

impl Bucket {
    /// A full bucket of `burst`.
    pub fn new(burst: f64) -> Bucket {
        Bucket {
            tokens: burst,
            last: Instant::now(),
        }
    }

    /// Takes one token if there is one.
    pub fn take(&mut self, rate: f64, burst: f64) -> bool {
        let now = Instant::now();
        let dt = now.duration_since(self.last).as_secs_f64();
        self.last = now;
        self.tokens = (self.tokens + dt * rate).min(burst);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bucket_allows_its_burst_then_refuses() {
        let mut b = Bucket::new(3.0);
        // A rate of zero never refills: exactly the burst passes.
        let passed = (0..10).filter(|_| b.take(0.0, 3.0)).count();
        assert_eq!(passed, 3);
    }
}
