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

/// `P(X <= x)` and `P(X >= x)` for `X ~ Binomial(n, q)`, summed exactly (the pmf in log
/// space: `q^n` underflows for the n here).
fn binomial_tails(n: u32, q: f64, x: u32) -> (f64, f64) {
    let mut log_pmf = f64::from(n) * (1.0 - q).ln();
    let (mut below, mut at, mut above) = (0.0, 0.0, 0.0);
    for k in 0..=n {
        let p = log_pmf.exp();
        match k.cmp(&x) {
            std::cmp::Ordering::Less => below += p,
            std::cmp::Ordering::Equal => at = p,
            std::cmp::Ordering::Greater => above += p,
        }
        log_pmf += (f64::from(n - k) / f64::from(k + 1)).ln() + (q / (1.0 - q)).ln();
    }
    (below + at, at + above)
}

#[test]
fn binomial_tails_by_hand() {
    // Binomial(4, 1/2): 1, 4, 6, 4, 1 sixteenths.
    let (lo, hi) = binomial_tails(4, 0.5, 1);
    assert!((lo - 5.0 / 16.0).abs() < 1e-15 && (hi - 15.0 / 16.0).abs() < 1e-15);
    let (lo, hi) = binomial_tails(4, 0.5, 4);
    assert!((lo - 1.0).abs() < 1e-15 && (hi - 1.0 / 16.0).abs() < 1e-15);
}

/// Long-run coverage of the bootstrap interval in this design: 3,738 of 4,000 studies
/// (seeds 10,000-11,999 and 20,000-21,999, this test's code with those seeds) = 0.9345,
/// SE 0.0039. The percentile interval of a parametric bootstrap on 20 staircases
/// under-covers its nominal 95 % a little.
const LONG_RUN_COVERAGE: f64 = 0.9345;

/// Issue 6: "a simulated observer with a known threshold yields a fitted threshold whose 95 % CI
/// covers it in ≥ 90 % of 200 simulated studies", as a rate with a binomial tolerance rather
/// than one draw against a bare 90 %: 300 studies, each from its own seed, and the number
/// covered must be (a) not significantly below 90 % (one-sided exact binomial p ≥ 1e-4) and
/// (b) in neither 1e-4 tail of the long-run coverage (an interval grown too wide, covering
/// every time, fails too). Each study: 20 subjects × 50-trial two-down-one-up staircases from
/// 0.024 in steps of 0.002 (thesis §5.4), Weibull observer α = 0.012, β = 3, λ = 0.01;
/// threshold read at 75 % correct.
#[test]
fn bootstrap_ci_covers_the_true_threshold_at_its_long_run_rate() {
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
    let mut covered = 0;
    let studies: u32 = 300;
    for study in 0..studies {
        let mut rng = ChaCha8Rng::seed_from_u64(u64::from(study));
        let mut trials = Vec::new();
        for subject in 0..20 {
            let (_, t) = staircase(&mut rng, &observer, subject, 0.024, 0.002, 50);
            trials.extend(t);
        }
        let data = GroupedTrials::from_trials(&trials);
        let boot = BootstrapOptions {
            replicates: 200,
            confidence: Confidence::new(0.95).unwrap(),
            seed: 1000 + u64::from(study),
        };
        let (_, ci) = bootstrap_threshold(&data, &options, 0.75, &boot).unwrap();
        assert!(ci.lower <= ci.threshold && ci.threshold <= ci.upper);
        covered += u32::from(ci.lower <= truth && truth <= ci.upper);
    }
    let (below_90, _) = binomial_tails(studies, 0.90, covered);
    let (lower, upper) = binomial_tails(studies, LONG_RUN_COVERAGE, covered);
    eprintln!(
        "true threshold {truth}: covered in {covered} of {studies} studies \
         (P(<=) {below_90:.2e} at 90 %; P(<=) {lower:.3}, P(>=) {upper:.3} at {LONG_RUN_COVERAGE})"
    );
    assert!(
        below_90 >= 1e-4,
        "covered {covered} of {studies}: below 90 % (p = {below_90:.2e})"
    );
    assert!(
        lower >= 1e-4 && upper >= 1e-4,
        "covered {covered} of {studies}, long-run rate {LONG_RUN_COVERAGE}: P(<=) {lower}, P(>=) {upper}"
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
/// power within 4 binomial standard errors (a false alarm once in about 16,000 runs; 3 SE
/// failed one seed in 370).
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
    eprintln!(
        "rejection rate {rate} vs power {expected} ({:+.2} SE)",
        (rate - expected) / se
    );
    assert!(
        (rate - expected).abs() < 4.0 * se,
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
