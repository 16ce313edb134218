//! Sample-size planning against statsmodels 0.15 (`TTestPower().power` and
//! `TTestPower().solve_power`) over a grid of effect sizes, α, power and sidedness, and the
//! CI-width sample size against SciPy's t quantiles (scripts/reference/power_reference.py,
//! run at test time).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

use analysis::Confidence;
use analysis::power::{
    Sides, ci_half_width, ci_sample_size, paired_one_tailed_sample_size, paired_power,
    paired_sample_size,
};
use serde_json::json;

const EFFECTS: [f64; 6] = [0.2, 0.35, 0.5, 0.8, 1.2, 1.6];
const ALPHAS: [f64; 3] = [0.01, 0.05, 0.1];
const POWERS: [f64; 4] = [0.7, 0.8, 0.9, 0.95];
const SIDES: [(Sides, &str); 2] = [(Sides::One, "larger"), (Sides::Two, "two-sided")];

fn close(ours: f64, theirs: f64, tol: f64, what: &str) {
    assert!(
        (ours - theirs).abs() <= tol * theirs.abs().max(1.0),
        "{what}: ours {ours:.15e}, reference {theirs:.15e}"
    );
}

#[test]
fn power_and_sample_sizes_match_statsmodels_and_scipy() {
    let Some(python) = venv_python::STATS.python("statsmodels", "power interop test") else {
        return;
    };
    let mut power_cases = Vec::new();
    for d in EFFECTS {
        // SciPy's noncentral t gives NaN in the far tail (two-sided, d·√n = 8); power is ~1 there.
        for n in [3.0_f64, 7.5, 12.0, 25.0, 60.0, 200.0]
            .into_iter()
            .filter(|n: &f64| d * n.sqrt() < 7.5)
        {
            for alpha in ALPHAS {
                for (sides, alternative) in SIDES {
                    power_cases.push((d, n, alpha, sides, alternative));
                }
            }
        }
    }
    let mut solve_cases = Vec::new();
    for d in EFFECTS {
        for alpha in ALPHAS {
            for power in POWERS {
                for (sides, alternative) in SIDES {
                    solve_cases.push((d, alpha, power, sides, alternative));
                }
            }
        }
    }
    let mut ci_cases = Vec::new();
    for sd in [0.3, 0.7, 1.0, 1.5, 12.0] {
        for w in [0.1, 0.25, 0.5, 2.0] {
            for alpha in ALPHAS {
                ci_cases.push((sd, w, alpha));
            }
        }
    }
    let cases = json!({
        "power": power_cases.iter().map(|(d, n, a, _, alt)| json!({"effect_size": d, "n": n, "alpha": a, "alternative": alt})).collect::<Vec<_>>(),
        "solve": solve_cases.iter().map(|(d, a, p, _, alt)| json!({"effect_size": d, "alpha": a, "power": p, "alternative": alt})).collect::<Vec<_>>(),
        "ci": ci_cases.iter().map(|(sd, w, a)| json!({"sd": sd, "w": w, "alpha": a})).collect::<Vec<_>>(),
    });
    let want = venv_python::run_script(
        &python,
        "reference/power_reference.py",
        "power_interop",
        &cases,
    );
    for ((d, n, alpha, sides, alt), w) in power_cases.iter().zip(want["power"].as_array().unwrap())
    {
        let ours = paired_power(*d, *n, *alpha, *sides).unwrap();
        close(
            ours,
            w.as_f64().unwrap(),
            1e-9,
            &format!("power d={d} n={n} α={alpha} {alt}"),
        );
    }
    let mut large = 0;
    for ((d, alpha, power, sides, alt), w) in
        solve_cases.iter().zip(want["solve"].as_array().unwrap())
    {
        let what = format!("n for d={d} α={alpha} power={power} {alt}");
        let ours = paired_sample_size(*d, *alpha, *power, *sides).unwrap();
        let n = w["n"].as_f64().unwrap();
        // statsmodels' root finder stops at about 1e-8 relative in power (see golden.rs).
        if n > 2.0 {
            close(ours.n_exact, n, 1e-6, &what);
            let at_root = paired_power(*d, ours.n_exact, *alpha, *sides).unwrap();
            close(
                at_root,
                *power,
                1e-10,
                &format!("{what}: power at the root"),
            );
        }
        assert_eq!(
            ours.n_subjects as u64,
            w["ceiling"].as_u64().unwrap(),
            "{what}: whole subjects"
        );
        close(
            ours.achieved_power,
            w["achieved_at_ceiling"].as_f64().unwrap(),
            1e-9,
            &format!("{what}: achieved power"),
        );
        assert!(ours.achieved_power >= *power, "{what}");
        large += usize::from(ours.n_subjects > 100);
    }
    assert!(large >= 10, "the grid reaches large n ({large})");
    check_ci_widths(&ci_cases, &want["ci"]);
}

/// The CI-width plans against SciPy's (`want`: the script's "ci" list).
fn check_ci_widths(ci_cases: &[(f64, f64, f64)], want: &serde_json::Value) {
    // statrs' t quantile at 10⁴-10⁵ degrees of freedom agrees with SciPy to ~1e-9 relative.
    for ((sd, half, alpha), w) in ci_cases.iter().zip(want.as_array().unwrap()) {
        let what = format!("CI n for sd={sd} w={half} α={alpha}");
        let level = Confidence::new(1.0 - alpha).unwrap();
        let ours = ci_sample_size(*sd, *half, level).unwrap();
        assert_eq!(ours.n_subjects as u64, w["n"].as_u64().unwrap(), "{what}");
        close(
            ours.half_width,
            w["half_width"].as_f64().unwrap(),
            1e-9,
            &what,
        );
        assert!(ours.half_width <= *half, "{what}");
        if let Some(before) = w["half_width_before"].as_f64() {
            let b = ci_half_width(*sd, ours.n_subjects as f64 - 1.0, level).unwrap();
            close(b, before, 1e-9, &what);
            assert!(b > *half, "{what}: one subject fewer is too wide");
        }
    }
}

fn err<T: std::fmt::Debug>(r: Result<T, analysis::AnalysisError>) -> String {
    r.unwrap_err().to_string()
}

#[test]
fn bad_plans_are_refused_by_name() {
    assert!(err(paired_sample_size(0.0, 0.05, 0.8, Sides::Two)).contains("effect_size"));
    assert!(err(paired_sample_size(0.5, 0.0, 0.8, Sides::Two)).contains("alpha"));
    assert!(err(paired_sample_size(0.5, 0.05, 0.01, Sides::Two)).contains("power"));
    assert!(err(paired_sample_size(0.001, 0.05, 0.8, Sides::Two)).contains("100000"));
    assert!(err(paired_power(f64::NAN, 10.0, 0.05, Sides::One)).contains("effect_size"));
    assert!(err(ci_sample_size(0.0, 0.1, Confidence::default())).contains("sd"));
    assert!(err(ci_sample_size(1.0, -0.1, Confidence::default())).contains("half_width"));
    // The one-tailed wrapper the golden test checks is the same computation.
    let a = paired_one_tailed_sample_size(0.5, 1.25, 0.05, 0.8).unwrap();
    let b = paired_sample_size(0.4, 0.05, 0.8, Sides::One).unwrap();
    assert_eq!(a, b);
}
