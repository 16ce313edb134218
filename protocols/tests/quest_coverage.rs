//! QUEST+ with a known simulated observer: the threshold's 95 % credible interval must cover
//! the observer's true threshold at the nominal rate over many independent runs (issue 24).
//!
//! One run is a whole QUEST+ track (40 trials, the grid of `examples/quest.toml` but uniform
//! priors over threshold, slope and lapse) answered by a Weibull observer with α = 0.012,
//! β = 3.5, λ = 0.02, every answer drawn from its own seeded stream. Over `RUNS` runs the number
//! of intervals that contain 0.012 is binomial(RUNS, p); the test asserts that p = 0.95 is not
//! rejected: the count lies within 4 standard deviations of 0.95 · RUNS (a false alarm about
//! once in 16,000 runs of the test if the intervals are exact). Measured: QUEST+ 385/400, Psi
//! 382/400. Intervals too narrow fail it: the 80 % intervals, labelled 95 %, covered 341 and
//! 308 of 400.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use protocols::observer::PsychometricFunction;
use protocols::quest::{QuestMethod, QuestPlus, QuestSettings};
use protocols::rng::StudyRng;
use protocols::study::Psychometric;

const RUNS: u32 = 400;
const TRIALS: u32 = 40;
const NOMINAL: f64 = 0.95;

fn settings(method: QuestMethod, lapses: Vec<f64>) -> QuestSettings {
    let n = 40;
    let thresholds: Vec<f64> = (0..n)
        .map(|i| 0.002 * 30_f64.powf(f64::from(i) / f64::from(n - 1)))
        .collect();
    let slopes = vec![1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 8.0];
    let levels = (1..=10).map(|k| f64::from(k) * 0.004).collect();
    let mut s = QuestSettings::uniform(
        method,
        Psychometric::Weibull,
        levels,
        thresholds,
        slopes,
        lapses,
        TRIALS,
    );
    s.credible = NOMINAL;
    s
}

/// Runs that covered the truth, and the mean interval width.
fn coverage(s: &QuestSettings, observer: PsychometricFunction, seed: u64) -> (u32, f64) {
    let mut covered = 0;
    let mut width = 0.0;
    for run in 0..RUNS {
        let mut q = QuestPlus::new(s.clone()).unwrap();
        let mut i = 0_u64;
        while let Some(x) = q.next_level() {
            let u = StudyRng::new(seed, &[u64::from(run), i]).unit_f64();
            q.add_response(u < observer.p_correct(x)).unwrap();
            i += 1;
        }
        let t = q.threshold();
        covered += u32::from(t.lower <= observer.threshold && observer.threshold <= t.upper);
        width += t.upper - t.lower;
    }
    (covered, width / f64::from(RUNS))
}

fn assert_nominal(what: &str, covered: u32, width: f64) {
    let n = f64::from(RUNS);
    let sd = (n * NOMINAL * (1.0 - NOMINAL)).sqrt();
    let rate = f64::from(covered) / n;
    eprintln!(
        "{what}: {covered}/{RUNS} intervals cover the truth ({rate:.3}), mean width {width:.5}"
    );
    assert!(
        (f64::from(covered) - n * NOMINAL).abs() <= 4.0 * sd,
        "{what}: {covered} of {RUNS} 95 % intervals cover the true threshold ({rate:.3}); \
         binomial tolerance {:.0}..={:.0}",
        n * NOMINAL - 4.0 * sd,
        n * NOMINAL + 4.0 * sd
    );
}

#[test]
fn quest_plus_intervals_cover_the_true_threshold_at_the_nominal_rate() {
    let observer = PsychometricFunction {
        family: Psychometric::Weibull,
        threshold: 0.012,
        slope: 3.5,
        lapse: 0.02,
    };
    let s = settings(QuestMethod::QuestPlus, vec![0.0, 0.01, 0.02, 0.03, 0.04]);
    let (covered, width) = coverage(&s, observer, 0x51_0b5e);
    assert_nominal("QUEST+", covered, width);
}

#[test]
fn psi_intervals_cover_the_true_threshold_at_the_nominal_rate() {
    let observer = PsychometricFunction {
        family: Psychometric::Weibull,
        threshold: 0.02,
        slope: 2.5,
        lapse: 0.02,
    };
    let s = settings(QuestMethod::Psi, vec![0.02]);
    let (covered, width) = coverage(&s, observer, 0x9_51);
    assert_nominal("Psi", covered, width);
}
