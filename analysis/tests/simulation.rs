#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]
//! The analysis recovers what simulated observers put in.

use analysis::Confidence;
use analysis::power::{paired_one_tailed_power, paired_one_tailed_sample_size};
use analysis::psychometric::{
    BootstrapOptions, FitOptions, GroupedTrials, Lapse, PsychometricFit, Shape, bootstrap_threshold,
};
use analysis::synthetic::{staircase, standard_normal};
use analysis::ttest::{Alternative, paired};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Issue 6: "a simulated observer with a known threshold yields a fitted threshold whose 95 % CI
/// covers it in ≥ 90 % of 200 simulated studies". Each study: 20 subjects × 50-trial
/// two-down-one-up staircases from 0.024 in steps of 0.002 (thesis §5.4), Weibull observer
/// α = 0.012, β = 3, λ = 0.01; threshold read at 75 % correct.
#[test]
fn bootstrap_ci_covers_the_true_threshold_in_200_simulated_studies() {
    let observer = PsychometricFit {
        shape: Shape::Weibull,
        alpha: 0.012,
        beta: 3.0,
        guess_rate: 0.5,
        lapse: 0.01,
        log_likelihood: 0.0,
        trials: 0,
    };
    let truth = observer.threshold(0.75).unwrap();
    let options = FitOptions {
        shape: Shape::Weibull,
        guess_rate: 0.5,
        lapse: Lapse::Fixed(0.01),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let mut covered = 0;
    let studies = 200;
    for study in 0..studies {
        let mut trials = Vec::new();
        for subject in 0..20 {
            let (_, t) = staircase(&mut rng, &observer, subject, 0.024, 0.002, 50);
            trials.extend(t);
        }
        let data = GroupedTrials::from_trials(&trials);
        let boot = BootstrapOptions {
            replicates: 200,
            confidence: Confidence::new(0.95).unwrap(),
            seed: 1000 + study,
        };
        let (_, ci) = bootstrap_threshold(&data, &options, 0.75, &boot).unwrap();
        assert!(ci.lower <= ci.threshold && ci.threshold <= ci.upper);
        covered += usize::from(ci.lower <= truth && truth <= ci.upper);
    }
    eprintln!("true threshold {truth}: covered in {covered} of {studies} studies");
    assert!(
        covered * 100 >= 90 * studies as usize,
        "covered {covered} of {studies}"
    );
}

#[test]
fn bootstrap_is_reproducible_from_its_seed() {
    let observer = PsychometricFit {
        shape: Shape::Logistic,
        alpha: 0.01,
        beta: 500.0,
        guess_rate: 0.5,
        lapse: 0.0,
        log_likelihood: 0.0,
        trials: 0,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut trials = Vec::new();
    for s in 0..10 {
        trials.extend(staircase(&mut rng, &observer, s, 0.024, 0.002, 40).1);
    }
    let data = GroupedTrials::from_trials(&trials);
    let options = FitOptions {
        shape: Shape::Logistic,
        ..FitOptions::default()
    };
    let boot = BootstrapOptions {
        replicates: 50,
        confidence: Confidence::new(0.9).unwrap(),
        seed: 77,
    };
    let a = bootstrap_threshold(&data, &options, 0.75, &boot).unwrap();
    let b = bootstrap_threshold(&data, &options, 0.75, &boot).unwrap();
    assert_eq!(a, b);
    let c = bootstrap_threshold(
        &data,
        &options,
        0.75,
        &BootstrapOptions { seed: 78, ..boot },
    )
    .unwrap();
    assert_ne!(a.1, c.1);
}

/// Issue 6 §9: the noncentral-t power is checked by simulation. 4000 simulated panels of the
/// planned size; the rejection rate of the one-tailed paired test must match the computed
/// power within 3 binomial standard errors.
#[test]
fn power_matches_simulated_rejection_rate() {
    let (diff, sd, alpha) = (0.5, 0.8, 0.05);
    let plan = paired_one_tailed_sample_size(diff, sd, alpha, 0.8).unwrap();
    assert_eq!(plan.n_subjects, 18);
    let n = plan.n_subjects;
    let expected = paired_one_tailed_power(diff / sd, n as f64, alpha).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let reps = 4000;
    let mut rejections = 0;
    for _ in 0..reps {
        // Each subject scores A and B; the per-subject difference is N(diff, sd).
        let b: Vec<f64> = (0..n)
            .map(|_| 3.5 + 0.5 * standard_normal(&mut rng))
            .collect();
        let a: Vec<f64> = b
            .iter()
            .map(|x| x + diff + sd * standard_normal(&mut rng))
            .collect();
        let t = paired(&a, &b, Alternative::Greater).unwrap().unwrap();
        rejections += usize::from(t.p < alpha);
    }
    let rate = rejections as f64 / f64::from(reps);
    let se = (expected * (1.0 - expected) / f64::from(reps)).sqrt();
    assert!(
        (rate - expected).abs() < 3.0 * se,
        "simulated {rate} vs computed {expected}"
    );
}

#[test]
fn sample_size_rejects_bad_parameters() {
    assert!(paired_one_tailed_sample_size(0.0, 1.0, 0.05, 0.8).is_err());
    assert!(paired_one_tailed_sample_size(0.5, 0.0, 0.05, 0.8).is_err());
    assert!(paired_one_tailed_sample_size(0.5, 1.0, 0.05, 1.0).is_err());
    assert!(paired_one_tailed_power(0.5, 1.0, 0.05).is_err());
}
