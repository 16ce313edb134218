//! How many trials QUEST+ and a two-down-one-up staircase need for the same precision
//! (issue 24). Not a timing benchmark: it simulates both procedures against one known observer
//! and prints the RMS error of each one's threshold estimate after n trials, and the trials
//! each needs to reach a given RMS error. Run with
//!
//! ```text
//! cargo bench -p protocols --bench adaptive_precision
//! ```
//!
//! Observer: the study files' default simulated 2AFC observer, Weibull α = 0.012, β = 3.5,
//! λ = 0.02 (thesis ch. 5's t_L scale). Both estimate the same quantity, the level at 70.71 %
//! correct (what a two-down-one-up staircase converges on, Levitt 1971): the staircase as the
//! mean of its last 6 reversal levels (all of them while it has fewer; its last level before
//! the first), QUEST+ as the posterior mean of that level over its parameter grid. Both use
//! the same levels, 0.002 to 0.040 in steps of 0.002; the staircase starts at 0.024 (thesis
//! ch. 5), QUEST+ has uniform priors over 40 thresholds (0.002-0.06, log spaced), 9 slopes and
//! 5 lapse rates. Every run answers from its own seeded stream; the estimates after n trials
//! are read from the same run at each n.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use protocols::observer::PsychometricFunction;
use protocols::quest::{QuestMethod, QuestPlus, QuestSettings};
use protocols::rng::StudyRng;
use protocols::study::Psychometric;
use protocols::{Staircase, StaircaseSettings, StepType};

const RUNS: u32 = 1000;
const CHECKPOINTS: [usize; 8] = [10, 15, 20, 30, 40, 60, 80, 120];
/// The point a two-down-one-up staircase converges on: 0.5^(1/2) correct (Levitt 1971).
const TARGET_P: f64 = std::f64::consts::FRAC_1_SQRT_2;

fn observer() -> PsychometricFunction {
    PsychometricFunction {
        family: Psychometric::Weibull,
        threshold: 0.012,
        slope: 3.5,
        lapse: 0.02,
    }
}

fn quest_settings() -> QuestSettings {
    let thresholds: Vec<f64> = (0..40)
        .map(|i| 0.002 * 30_f64.powf(f64::from(i) / 39.0))
        .collect();
    QuestSettings::uniform(
        QuestMethod::QuestPlus,
        Psychometric::Weibull,
        (1..=20).map(|k| f64::from(k) * 0.002).collect(),
        thresholds,
        vec![1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 8.0],
        vec![0.0, 0.01, 0.02, 0.03, 0.04],
        *CHECKPOINTS.last().unwrap() as u32,
    )
}

fn staircase_settings() -> StaircaseSettings {
    StaircaseSettings {
        start: 0.024,
        step: 0.002,
        step_type: StepType::Linear,
        down_up_ratio: 1.0,
        min: Some(0.002),
        max: Some(0.040),
        n_up: 1,
        n_down: 2,
        apply_initial_rule: false,
        stop_reversals: None,
        min_trials: 0,
        max_trials: Some(*CHECKPOINTS.last().unwrap() as u32),
        threshold_reversals: 6,
    }
}

/// The staircase's estimate after its trials so far.
fn staircase_estimate(s: &Staircase) -> f64 {
    let rev = s.reversal_levels();
    if rev.is_empty() {
        return s
            .next_level()
            .unwrap_or_else(|| *s.levels().last().unwrap());
    }
    let k = rev.len().min(6);
    rev[rev.len() - k..].iter().sum::<f64>() / k as f64
}

fn answer(seed: u64, run: u32, trial: usize, x: f64) -> bool {
    StudyRng::new(seed, &[u64::from(run), trial as u64]).unit_f64() < observer().p_correct(x)
}

/// Squared errors summed per checkpoint: (staircase, QUEST+).
fn simulate(truth: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut se_s, mut se_q) = (vec![0.0; CHECKPOINTS.len()], vec![0.0; CHECKPOINTS.len()]);
    for run in 0..RUNS {
        let mut s = Staircase::new(staircase_settings()).unwrap();
        let mut q = QuestPlus::new(quest_settings()).unwrap();
        for n in 1..=*CHECKPOINTS.last().unwrap() {
            let x = s.next_level().unwrap();
            s.add_response(answer(1, run, n, x)).unwrap();
            let x = q.next_level().unwrap();
            q.add_response(answer(2, run, n, x)).unwrap();
            if let Some(c) = CHECKPOINTS.iter().position(|&k| k == n) {
                se_s[c] += (staircase_estimate(&s) - truth).powi(2);
                se_q[c] += (q.level_for(TARGET_P).unwrap() - truth).powi(2);
            }
        }
    }
    (se_s, se_q)
}

/// Trials at which the RMS error curve first falls to `target` (linear between checkpoints).
fn trials_to(rmse: &[f64], target: f64) -> Option<f64> {
    if rmse[0] <= target {
        return Some(CHECKPOINTS[0] as f64);
    }
    for i in 1..rmse.len() {
        if rmse[i] <= target {
            let (a, b) = (rmse[i - 1], rmse[i]);
            let (na, nb) = (CHECKPOINTS[i - 1] as f64, CHECKPOINTS[i] as f64);
            return Some(na + (a - target) / (a - b) * (nb - na));
        }
    }
    None
}

fn main() {
    let truth = observer().level_for(TARGET_P).unwrap();
    let started = std::time::Instant::now();
    let (se_s, se_q) = simulate(truth);
    let rms = |v: &[f64]| -> Vec<f64> { v.iter().map(|s| (s / f64::from(RUNS)).sqrt()).collect() };
    let (rs, rq) = (rms(&se_s), rms(&se_q));
    println!(
        "level at {:.2} % correct: {truth:.5}; {RUNS} runs each ({:.1} s)",
        TARGET_P * 100.0,
        started.elapsed().as_secs_f64()
    );
    println!("| trials | RMS error, 2-down-1-up | RMS error, QUEST+ |");
    println!("| --- | --- | --- |");
    for (i, n) in CHECKPOINTS.iter().enumerate() {
        println!("| {n} | {:.5} | {:.5} |", rs[i], rq[i]);
    }
    println!("| RMS error reached | trials, 2-down-1-up | trials, QUEST+ | ratio |");
    println!("| --- | --- | --- | --- |");
    for target in [0.003, 0.0025, 0.002, 0.0015] {
        let (a, b) = (trials_to(&rs, target), trials_to(&rq, target));
        let show = |v: Option<f64>| v.map_or_else(|| "> 120".to_owned(), |n| format!("{n:.0}"));
        let ratio = match (a, b) {
            (Some(a), Some(b)) => format!("{:.1}×", a / b),
            _ => "—".to_owned(),
        };
        println!("| {target} | {} | {} | {ratio} |", show(a), show(b));
    }
}
