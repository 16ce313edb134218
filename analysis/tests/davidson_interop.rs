//! Davidson's model for pair comparisons with ties (`analysis::bradley_terry::fit_with_ties`)
//! against an independent fit with SciPy: `scripts/reference/davidson_reference.py` maximises
//! the same likelihood with `scipy.optimize.minimize` (BFGS, analytic gradient, then a Newton
//! polish) and takes its standard errors from a central-difference Hessian of the gradient,
//! where the Rust fit runs its own Newton-Raphson with the analytic information matrix.
//!
//! Both find the same maximum of the same likelihood, so they differ by the optimisers'
//! stopping points and the numerical Hessian's error: scale values and ln ν must agree to
//! 1e-6 (absolute; ν relative), the log-likelihood to 1e-6 of its size, the standard errors
//! (of the scale values and of ν) to 1e-5 relative. Cases: 3 items with many ties, 5 items
//! with few ties and unbalanced counts, 8 items with unbalanced counts, some pairs never
//! compared and a tie share in between.
//!
//! The Python is `$BAYES_PYTHON` (`scripts/test` points it at `target/bayes-env`, numpy and
//! scipy pinned in `scripts/reference/bayes-requirements.txt`), or that venv itself; under
//! `CI` a missing interpreter or package fails the test, elsewhere it skips.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::io::Write;
use std::process::{Command, Stdio};

use analysis::Confidence;
use analysis::bradley_terry::{TieMatrix, TiesOutcome, WinMatrix, fit_with_ties};
use serde_json::{Value, json};

#[path = "../../scripts/golden/venv_python.rs"]
mod venv_python;

const TOL_VALUE: f64 = 1e-6;
const TOL_SE: f64 = 1e-5;

/// A data set: name, anchor, wins (row preferred over column), ties (symmetric).
struct Case {
    name: &'static str,
    anchor: usize,
    wins: Vec<Vec<u64>>,
    ties: Vec<Vec<u64>>,
}

fn symmetric(n: usize, upper: &[(usize, usize, u64)]) -> Vec<Vec<u64>> {
    let mut t = vec![vec![0; n]; n];
    for &(i, j, k) in upper {
        t[i][j] = k;
        t[j][i] = k;
    }
    t
}

fn cases() -> Vec<Case> {
    // 8 items: counts from a fixed 64-bit LCG, each pair compared 0 to 24 times (every sixth
    // pair not at all), ties about a tenth to a third of a pair's comparisons, the items'
    // true strengths spread so that the counts are lopsided.
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut next = |m: u64| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 33) % m
    };
    let n8 = 8;
    let mut wins8 = vec![vec![0; n8]; n8];
    let mut ties8 = vec![vec![0; n8]; n8];
    let strength = [0.0, 0.6, -0.4, 1.3, -1.1, 0.2, 0.9, -0.2];
    let mut k = 0;
    for i in 0..n8 {
        for j in i + 1..n8 {
            k += 1;
            if k % 6 == 0 {
                continue;
            }
            let total = 4 + next(21);
            let tie_share = 10 + next(25);
            for _ in 0..total {
                let u = next(100);
                if u < tie_share {
                    ties8[i][j] += 1;
                    ties8[j][i] += 1;
                } else {
                    // i preferred with the Bradley-Terry odds of the remaining answers.
                    let p = 1.0 / (1.0 + f64::exp(strength[j] - strength[i]));
                    if (next(1000) as f64) < 1000.0 * p {
                        wins8[i][j] += 1;
                    } else {
                        wins8[j][i] += 1;
                    }
                }
            }
        }
    }
    vec![
        Case {
            name: "3 items, many ties",
            anchor: 0,
            wins: vec![vec![0, 5, 9], vec![3, 0, 6], vec![2, 4, 0]],
            ties: symmetric(3, &[(0, 1, 11), (0, 2, 7), (1, 2, 12)]),
        },
        Case {
            name: "5 items, few ties, unbalanced",
            anchor: 2,
            wins: vec![
                vec![0, 14, 3, 22, 1],
                vec![6, 0, 2, 9, 0],
                vec![11, 17, 0, 30, 4],
                vec![2, 3, 1, 0, 0],
                vec![9, 5, 8, 2, 0],
            ],
            ties: symmetric(5, &[(0, 1, 1), (0, 3, 2), (2, 4, 1), (1, 3, 1), (3, 4, 1)]),
        },
        Case {
            name: "8 items, unbalanced, some pairs not compared",
            anchor: 0,
            wins: wins8,
            ties: ties8,
        },
    ]
}

/// Runs `scripts/reference/davidson_reference.py` with `python` on `input` (on stdin) and
/// returns the JSON it prints; a failing script fails the test with its stderr.
fn run_reference(python: &std::path::Path, input: &Value) -> Value {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scripts/reference/davidson_reference.py");
    let mut child = Command::new(python)
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(serde_json::to_string(input).unwrap().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "davidson_reference.py failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Fits `c` here and compares with SciPy's `r`, raising `worst` to the differences (scale
/// absolute; SE, ν, SE(ν), log-likelihood relative).
fn compare(c: &Case, r: &Value, worst: &mut [f64; 5]) {
    let wins = WinMatrix {
        wins: c.wins.clone(),
    };
    let ties = TieMatrix {
        ties: c.ties.clone(),
    };
    let e = match fit_with_ties(&wins, &ties, c.anchor, Confidence::default()).unwrap() {
        TiesOutcome::Fitted(e) => e,
        other => panic!("{}: {other:?}", c.name),
    };
    assert!(e.converged, "{}: {e:?}", c.name);
    let name = c.name;
    for (what, mine, theirs) in [
        ("scale", &e.scale, numbers(&r["scale"])),
        ("lower", &e.lower, numbers(&r["lower"])),
        ("upper", &e.upper, numbers(&r["upper"])),
    ] {
        for (i, (m, t)) in mine.iter().zip(&theirs).enumerate() {
            let d = (m - t).abs();
            worst[0] = worst[0].max(if what == "scale" { d } else { 0.0 });
            let tol = if what == "scale" {
                TOL_VALUE
            } else {
                TOL_SE * 2.0 * (1.0 + t.abs())
            };
            assert!(
                d <= tol,
                "{name}: {what}[{i}]: {m} here, {t} in SciPy (tolerance {tol})"
            );
        }
    }
    for (i, (m, t)) in e.se.iter().zip(numbers(&r["se"])).enumerate() {
        let rel = if i == c.anchor {
            assert!(t.to_bits() == 0.0_f64.to_bits() && m.to_bits() == t.to_bits());
            0.0
        } else {
            (m - t).abs() / t
        };
        worst[1] = worst[1].max(rel);
        assert!(
            rel <= TOL_SE,
            "{name}: se[{i}]: {m} here, {t} in SciPy (relative {rel:e})"
        );
    }
    let nu = r["nu"].as_f64().unwrap();
    let rel = (e.tie_parameter - nu).abs() / nu;
    worst[2] = worst[2].max(rel);
    assert!(
        rel <= TOL_VALUE,
        "{name}: ν {} here, {nu} in SciPy",
        e.tie_parameter
    );
    let nu_se = r["nu_se"].as_f64().unwrap();
    let rel = (e.tie_se - nu_se).abs() / nu_se;
    worst[3] = worst[3].max(rel);
    assert!(
        rel <= TOL_SE,
        "{name}: SE(ν) {} here, {nu_se} in SciPy",
        e.tie_se
    );
    let ll = r["log_likelihood"].as_f64().unwrap();
    let rel = (e.log_likelihood - ll).abs() / ll.abs().max(1.0);
    worst[4] = worst[4].max(rel);
    assert!(
        rel <= TOL_VALUE,
        "{name}: log-likelihood {} here, {ll} in SciPy",
        e.log_likelihood
    );
    eprintln!(
        "{name}: ν = {:.6} (SciPy {nu:.6}), ℓ = {:.6}, SciPy's largest score component \
         {:e}, its BFGS: {}",
        e.tie_parameter,
        e.log_likelihood,
        r["gradient_norm"].as_f64().unwrap(),
        r["bfgs_message"]
    );
}

#[test]
fn davidson_fit_equals_scipys() {
    let Some(python) = venv_python::BAYES.python("scipy", "Davidson interop test") else {
        return;
    };
    let cases = cases();
    let input: Vec<Value> = cases
        .iter()
        .map(|c| {
            json!({
                "n": c.wins.len(),
                "anchor": c.anchor,
                "wins": c.wins,
                "ties": c.ties,
                "confidence": 0.95,
            })
        })
        .collect();
    let reference = run_reference(&python, &Value::from(input));
    let mut worst = [0.0_f64; 5];
    for (c, r) in cases.iter().zip(reference.as_array().unwrap()) {
        compare(c, r, &mut worst);
    }
    eprintln!(
        "largest differences: scale {:e} (absolute), SE {:e}, ν {:e}, SE(ν) {:e}, \
         log-likelihood {:e} (relative)",
        worst[0], worst[1], worst[2], worst[3], worst[4]
    );
}
