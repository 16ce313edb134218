//! Monte Carlo: a 2-down-1-up staircase run against a simulated Weibull 2AFC observer
//! converges on the 70.7 % point (Levitt 1971), and with down/up step ratio 0.5488 on the
//! 80.35 % point (García-Pérez 1998). Threshold per run = mean of the last reversals (thesis
//! ch. 5); the mean over many runs must lie within a fifth of a step of the target level.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use protocols::observer::PsychometricFunction;
use protocols::rng::StudyRng;
use protocols::study::Psychometric;
use protocols::{Staircase, StaircaseSettings, StepType};

fn mean_threshold(
    ratio: f64,
    trials: u32,
    runs: u32,
    f: &PsychometricFunction,
    step: f64,
    start: f64,
) -> f64 {
    let mut rng = StudyRng::new(0x5eed, &[ratio.to_bits(), u64::from(trials)]);
    let mut sum = 0.0;
    let mut n = 0;
    for _ in 0..runs {
        let mut s = Staircase::new(StaircaseSettings {
            start,
            step,
            step_type: StepType::Linear,
            down_up_ratio: ratio,
            min: Some(0.0),
            max: None,
            n_up: 1,
            n_down: 2,
            apply_initial_rule: false,
            stop_reversals: None,
            min_trials: 0,
            max_trials: Some(trials),
            threshold_reversals: 6,
        })
        .unwrap();
        while let Some(level) = s.next_level() {
            let correct = rng.unit_f64() < f.p_correct(level);
            s.add_response(correct).unwrap();
        }
        if let Some(t) = s.threshold() {
            sum += t;
            n += 1;
        }
    }
    assert!(
        n as f64 > 0.95 * f64::from(runs),
        "most runs reach enough reversals: {n}"
    );
    sum / f64::from(n)
}

#[test]
fn two_down_one_up_converges_on_70_7_percent() {
    let f = PsychometricFunction {
        family: Psychometric::Weibull,
        threshold: 0.012,
        slope: 3.5,
        lapse: 0.0,
    };
    let target = f.level_for(0.5_f64.sqrt()).unwrap();
    let step = 0.002;
    let m = mean_threshold(1.0, 60, 4000, &f, step, 0.024);
    eprintln!(
        "2-down-1-up: mean threshold {m:.5}, 70.7 % point {target:.5}, off by {:.3} steps",
        (m - target) / step
    );
    assert!(
        (m - target).abs() < step / 5.0,
        "mean threshold {m}, 70.7 % point {target}"
    );
}

#[test]
fn ratio_0_5488_converges_on_80_35_percent() {
    let f = PsychometricFunction {
        family: Psychometric::Weibull,
        threshold: 0.012,
        slope: 3.5,
        lapse: 0.0,
    };
    let target = f.level_for(0.8035).unwrap();
    let target_707 = f.level_for(0.5_f64.sqrt()).unwrap();
    let step = 0.002;
    let m = mean_threshold(0.5488, 60, 4000, &f, step, 0.024);
    eprintln!(
        "ratio 0.5488: mean threshold {m:.5}, 80.35 % point {target:.5}, off by {:.3} steps",
        (m - target) / step
    );
    assert!(
        (m - target).abs() < step / 5.0,
        "mean threshold {m}, 80.35 % point {target}"
    );
    assert!(
        (m - target_707).abs() > step / 2.0,
        "distinguishable from the 70.7 % point"
    );
}
