#!/usr/bin/env python3
"""Golden values for the `analysis` crate, computed with SciPy / statsmodels / NumPy.

Run:  pip install scipy statsmodels numpy pandas
      python3 scripts/golden/analysis_golden.py > analysis/tests/data/analysis_golden.json

Every input data set is generated here with a fixed seed and written into the JSON next to
the expected values, so the Rust tests need no Python.
"""
import json
import math
import sys

import numpy as np
import scipy
import statsmodels
from scipy import optimize, stats
from statsmodels.stats.multitest import multipletests
from statsmodels.stats.power import TTestPower

rng = np.random.default_rng(20261123)


def half_steps(x):
    """Scores on the seeds' 1-5 scale in 0.5 steps."""
    return np.clip(np.round(np.asarray(x) * 2) / 2, 1.0, 5.0)


def describe(values, conf=0.95):
    v = np.asarray(values, dtype=float)
    n = len(v)
    out = {"n": n, "mean": float(np.mean(v)), "median": float(np.median(v))}
    if n >= 2:
        sd = float(np.std(v, ddof=1))
        se = sd / math.sqrt(n)
        out["sd"] = sd
        out["se"] = se
        lo, hi = stats.t.interval(conf, n - 1, loc=out["mean"], scale=se)
        out["ci_t"] = [float(lo), float(hi)]
        lo, hi = stats.norm.interval(conf, loc=out["mean"], scale=se)
        out["ci_z"] = [float(lo), float(hi)]
    return out


samples = {
    "proposed_2_2_30": half_steps(rng.normal(4.16, 0.53, 22)).tolist(),
    "wavelet_2_2_30": half_steps(rng.normal(3.77, 0.6, 22)).tolist(),
    "proposed_49_14_40": half_steps(rng.normal(3.4, 0.46, 26)).tolist(),
    "wavelet_49_14_40": half_steps(rng.normal(2.3, 0.7, 26)).tolist(),
    "continuous_15": rng.normal(0.3, 1.2, 15).tolist(),
    "skewed_40": rng.exponential(0.7, 40).tolist(),
    "two": [3.0, 4.5],
    "one": [4.0],
}

descriptive = []
for name, v in samples.items():
    for conf in (0.95, 0.99):
        descriptive.append({"sample": name, "confidence": conf, "expected": describe(v, conf)})

pairs = [
    ("proposed_2_2_30", "wavelet_2_2_30"),
    ("proposed_49_14_40", "wavelet_49_14_40"),
    ("continuous_15", "skewed_40"),
]
ttests = []
for a, b in pairs:
    x = np.asarray(samples[a])
    y = np.asarray(samples[b])
    for alt in ("two-sided", "greater", "less"):
        if len(x) == len(y):
            r = stats.ttest_rel(x, y, alternative=alt)
            d = x - y
            ttests.append({"kind": "paired", "a": a, "b": b, "alternative": alt,
                           "t": float(r.statistic), "df": float(r.df), "p": float(r.pvalue),
                           "effect_size": float(np.mean(d) / np.std(d, ddof=1))})
        for equal_var, kind in ((False, "welch"), (True, "student")):
            r = stats.ttest_ind(x, y, equal_var=equal_var, alternative=alt)
            sp = math.sqrt(((len(x) - 1) * np.var(x, ddof=1) + (len(y) - 1) * np.var(y, ddof=1)) / (len(x) + len(y) - 2))
            ttests.append({"kind": kind, "a": a, "b": b, "alternative": alt,
                           "t": float(r.statistic), "df": float(r.df), "p": float(r.pvalue),
                           "effect_size": float((np.mean(x) - np.mean(y)) / sp)})

# Summary-statistics entry points (thesis Table 3.2 style rows: mean, SD, n).
from_stats = []
for m1, s1, n1, m2, s2, n2 in [(4.159, 0.525, 22, 3.773, 0.612, 22), (3.404, 0.455, 26, 2.308, 0.71, 26),
                               (3.727, 0.445, 15, 2.364, 0.5, 15)]:
    for alt in ("two-sided", "greater", "less"):
        for equal_var, kind in ((False, "welch"), (True, "student")):
            r = stats.ttest_ind_from_stats(m1, s1, n1, m2, s2, n2, equal_var=equal_var, alternative=alt)
            from_stats.append({"kind": kind, "a": [m1, s1, n1], "b": [m2, s2, n2], "alternative": alt,
                               "t": float(r.statistic), "p": float(r.pvalue)})

holm_in = [0.01, 0.04, 0.03, 0.005, 0.2, 0.04, 0.9]
holm = {"p": holm_in, "adjusted": multipletests(holm_in, method="holm")[1].tolist()}

# DSCQS: 12 subjects x 4 conditions, each condition shown twice to each subject.
dscqs_pairs = []
for subject in range(12):
    for condition in range(4):
        for _rep in range(2):
            ref = float(half_steps(rng.normal(4.6, 0.4)))
            test = float(half_steps(rng.normal(4.6 - 0.35 * condition, 0.5)))
            dscqs_pairs.append({"subject": subject, "condition": condition, "reference_score": ref, "test_score": test})
dscqs = []
for condition in range(4):
    per_subject = []
    for subject in range(12):
        d = [p["reference_score"] - p["test_score"] for p in dscqs_pairs if p["subject"] == subject and p["condition"] == condition]
        per_subject.append(np.mean(d))
    dscqs.append({"condition": condition, "expected": describe(per_subject)})

# ACR-HR: conditions 10, 11 are hidden references of clips A, B; 0-2 test A, 3-5 test B.
reference_of = {0: 10, 1: 10, 2: 10, 3: 11, 4: 11, 5: 11}
acr_ratings = []
for subject in range(9):
    for c in [10, 11, 0, 1, 2, 3, 4, 5]:
        base = 4.5 if c >= 10 else 4.3 - 0.4 * (c % 3)
        acr_ratings.append({"subject": subject, "condition": c, "score": float(half_steps(rng.normal(base, 0.6)))})
acr = []
for c in range(6):
    dv = []
    for r in acr_ratings:
        if r["condition"] != c:
            continue
        ref = [q["score"] for q in acr_ratings if q["subject"] == r["subject"] and q["condition"] == reference_of[c]]
        dv.append(r["score"] - np.mean(ref) + 5.0)
    acr.append({"condition": c, "expected": describe(dv)})
zscores = []
for r in acr_ratings:
    mine = np.array([q["score"] for q in acr_ratings if q["subject"] == r["subject"]])
    zscores.append(float((r["score"] - mine.mean()) / mine.std(ddof=1)))

# BT.500 Annex 2 screening: 14 observers x 10 conditions x 2 repetitions; observer 3 random,
# observer 3 erratic (far off the consensus in both directions), observer 7 offset (biased
# but consistent: BT.500 keeps such an observer), condition 5 heavy-tailed.
screen_ratings = []
for rep in range(2):
    for subject in range(14):
        for c in range(10):
            true = 1.5 + 0.35 * c
            if subject == 3:
                s = true + rng.choice([-1.8, 1.8])
            elif subject == 7:
                s = true + 1.2
            elif c == 5 and subject in (0, 1):
                s = true + (3 if subject == 0 else -3)
            else:
                s = rng.normal(true, 0.4)
            screen_ratings.append({"subject": subject, "condition": c, "score": float(half_steps(s))})
presentations = []
counts = {s: [0, 0, 0] for s in range(14)}
for c in range(10):
    for rep in range(2):
        rows = [r for r in screen_ratings if r["condition"] == c]
        # repetition index = order of appearance per subject
        by_subject = {}
        for r in rows:
            by_subject.setdefault(r["subject"], []).append(r["score"])
        u = np.array([by_subject[s][rep] for s in sorted(by_subject)])
        subs = sorted(by_subject)
        mean = u.mean()
        sd = u.std(ddof=1)
        beta2 = float(stats.kurtosis(u, fisher=False, bias=True)) if np.var(u) > 0 else None
        normal = beta2 is None or 2 <= beta2 <= 4
        width = 2 * sd if normal else math.sqrt(20) * sd
        for s, x in zip(subs, u):
            counts[s][2] += 1
            if sd > 0 and x >= mean + width:
                counts[s][0] += 1
            if sd > 0 and x <= mean - width:
                counts[s][1] += 1
        presentations.append({"condition": c, "repetition": rep, "mean": float(mean), "sd": float(sd), "beta2": beta2, "normal": bool(normal)})
observers = []
for s in range(14):
    p, q, jkr = counts[s]
    frac = (p + q) / jkr
    asym = abs(p - q) / (p + q) if p + q > 0 else None
    observers.append({"subject": s, "p": p, "q": q, "presentations": jkr,
                      "rejected": bool(frac > 0.05 and asym is not None and asym < 0.3)})

# Power of the paired one-tailed t-test (noncentral t), statsmodels TTestPower.
power = []
tp = TTestPower()
for d, n, alpha in [(0.5, 15, 0.05), (0.8, 10, 0.05), (0.3, 40, 0.01), (1.2, 6, 0.05), (0.65, 22, 0.025)]:
    power.append({"effect_size": d, "n": n, "alpha": alpha,
                  "power": float(tp.power(effect_size=d, nobs=n, alpha=alpha, alternative="larger"))})
sample_size = []
for diff, sd, alpha, pw in [(0.5, 0.8, 0.05, 0.8), (0.3, 0.6, 0.05, 0.9), (1.0, 0.9, 0.01, 0.8)]:
    n = tp.solve_power(effect_size=diff / sd, nobs=None, alpha=alpha, power=pw, alternative="larger")
    n = float(np.asarray(n).ravel()[0])
    sample_size.append({"mean_difference": diff, "sd_difference": sd, "alpha": alpha, "power": pw,
                        "n_exact": n, "n_subjects": int(math.ceil(n))})


# Weibull / logistic ML fits on a fixed 2AFC data set (levels like the thesis' t_L).
def psi(shape, a, b, lam, x, gamma=0.5):
    if shape == "weibull":
        f = 1 - np.exp(-(x / a) ** b)
        fc = np.exp(-(x / a) ** b)
    else:
        f = 1 / (1 + np.exp(-b * (x - a)))
        fc = 1 / (1 + np.exp(b * (x - a)))
    return gamma + (1 - gamma - lam) * f, (1 - gamma - lam) * fc + lam


levels = np.round(np.arange(0.002, 0.0241, 0.002), 6)
n_per = 40
p_true, _ = psi("weibull", 0.012, 3.0, 0.02, levels)
k = rng.binomial(n_per, p_true)
fit_data = {"levels": levels.tolist(), "n": [n_per] * len(levels), "k": k.tolist()}


def nll(shape, a, b, lam):
    p, q = psi(shape, a, b, lam, levels)
    with np.errstate(divide="ignore"):
        v = -(np.sum(k * np.log(p)) + np.sum((n_per - k) * np.log(q)))
    return v if np.isfinite(v) else 1e300


fits = []
for shape in ("weibull", "logistic"):
    for lapse in ("free", 0.0, 0.02):
        best = None
        for a0 in (0.008, 0.012, 0.016):
            for b0 in ((1.0, 3.0, 8.0) if shape == "weibull" else (100.0, 300.0, 900.0)):
                if lapse == "free":
                    f = lambda v: nll(shape, math.exp(v[0]) if shape == "weibull" else v[0], math.exp(v[1]), v[2])
                    x0 = [math.log(a0) if shape == "weibull" else a0, math.log(b0), 0.01]
                    bounds = [(None, None), (None, None), (0.0, 0.06)]
                else:
                    f = lambda v: nll(shape, math.exp(v[0]) if shape == "weibull" else v[0], math.exp(v[1]), lapse)
                    x0 = [math.log(a0) if shape == "weibull" else a0, math.log(b0)]
                    bounds = [(None, None), (None, None)]
                r = optimize.minimize(f, x0, method="L-BFGS-B", bounds=bounds, options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10000})
                r = optimize.minimize(f, r.x, method="Nelder-Mead", bounds=bounds, options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 20000, "maxfev": 40000})
                if best is None or r.fun < best.fun:
                    best = r
        v = best.x
        a = math.exp(v[0]) if shape == "weibull" else v[0]
        b = math.exp(v[1])
        lam = v[2] if lapse == "free" else lapse
        F = (0.75 - 0.5) / (1 - 0.5 - lam)
        thr = a * (-math.log(1 - F)) ** (1 / b) if shape == "weibull" else a + math.log(F / (1 - F)) / b
        fits.append({"shape": shape, "lapse": lapse, "alpha": a, "beta": b, "lambda": lam,
                     "neg_log_likelihood": float(best.fun), "threshold_75": thr})

json.dump({
    "generator": "scripts/golden/analysis_golden.py",
    "versions": {"numpy": np.__version__, "scipy": scipy.__version__, "statsmodels": statsmodels.__version__},
    "samples": samples,
    "descriptive": descriptive,
    "ttests": ttests,
    "from_stats": from_stats,
    "holm": holm,
    "dscqs_pairs": dscqs_pairs,
    "dscqs": dscqs,
    "acr_ratings": acr_ratings,
    "reference_of": [[k_, v_] for k_, v_ in reference_of.items()],
    "acr_hr": acr,
    "zscores": zscores,
    "screen_ratings": screen_ratings,
    "presentations": presentations,
    "observers": observers,
    "power": power,
    "sample_size": sample_size,
    "fit_data": fit_data,
    "fits": fits,
}, sys.stdout, indent=1)
