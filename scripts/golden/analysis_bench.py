#!/usr/bin/env python3
"""The same computation as analysis/benches/report.rs (`analyze` on 1,000,000 rating rows),
in pandas + SciPy, for the issue-6 comparison ("≥ 10× faster than that script").

1000 subjects × 1000 conditions (10 clips × 4 codecs × 25 ratios), one rating each, 20
random observers. Times: per-condition n / mean / SD / SE / t and z 95 % CI / median, BT.500
screening (β2, ±2S or ±√20·S, P/Q, decision) and MOS without the rejected, paired one-tailed
t-tests of each codec against codec "d" at equal clip and ratio with Holm correction.
Data generation is not timed.

Run: python3 scripts/golden/analysis_bench.py
"""
import time

import numpy as np
import pandas as pd
from scipy import stats
from statsmodels.stats.multitest import multipletests

rng = np.random.default_rng(42)
subjects, clips, codecs, ratios = 1000, 10, [0.3, 0.5, 0.7, 0.9], 10 + 2 * np.arange(25)
cond = pd.MultiIndex.from_product([range(clips), range(len(codecs)), ratios], names=["clip", "codec", "cr"]).to_frame(index=False)
cond["condition"] = np.arange(len(cond))
truth = np.clip(5 - np.array(codecs)[cond["codec"]] * (cond["cr"] - 10) / 10, 1, 5)
bias = rng.normal(0, 0.15, subjects)
scores = truth.to_numpy()[None, :] + bias[:, None] + rng.normal(0, 0.4, (subjects, len(cond)))
scores[:20] = rng.uniform(1, 5, (20, len(cond)))
scores = np.clip(np.round(scores * 2) / 2, 1, 5)
df = pd.DataFrame({"subject": np.repeat(np.arange(subjects), len(cond)), "condition": np.tile(cond["condition"], subjects), "score": scores.ravel()})


def per_condition(d):
    g = d.groupby("condition")["score"]
    out = g.agg(["count", "mean", "std", "median"])
    out["se"] = out["std"] / np.sqrt(out["count"])
    tq = stats.t.ppf(0.975, out["count"] - 1)
    out["ci_t"] = tq * out["se"]
    out["ci_z"] = stats.norm.ppf(0.975) * out["se"]
    return out


def screening(d):
    g = d.groupby("condition")["score"]
    mean = g.transform("mean")
    sd = g.transform("std")
    beta2 = g.agg(lambda u: stats.kurtosis(u, fisher=False, bias=True))
    normal = d["condition"].map((beta2 >= 2) & (beta2 <= 4))
    width = np.where(normal, 2 * sd, np.sqrt(20) * sd)
    d = d.assign(P=(d["score"] >= mean + width) & (sd > 0), Q=(d["score"] <= mean - width) & (sd > 0))
    c = d.groupby("subject").agg(P=("P", "sum"), Q=("Q", "sum"), n=("score", "size"))
    frac = (c["P"] + c["Q"]) / c["n"]
    asym = (c["P"] - c["Q"]).abs() / (c["P"] + c["Q"]).replace(0, np.nan)
    return c.index[(frac > 0.05) & (asym < 0.3)]


def comparisons(d):
    wide = d.pivot_table(index="subject", columns="condition", values="score", aggfunc="mean")
    ps = []
    for (clip, cr), grp in cond.groupby(["clip", "cr"]):
        base = grp.loc[grp["codec"] == 3, "condition"].iloc[0]
        for c in grp.loc[grp["codec"] != 3, "condition"]:
            r = stats.ttest_rel(wide[c], wide[base], alternative="greater")
            ps.append(r.pvalue)
    return multipletests(ps, method="holm")[1]


times = []
for _ in range(5):
    t0 = time.perf_counter()
    per_condition(df)
    rejected = screening(df)
    per_condition(df[~df["subject"].isin(rejected)])
    comparisons(df)
    times.append(time.perf_counter() - t0)
print(f"rows={len(df)} rejected={len(rejected)} pandas+scipy analyze: min {min(times):.3f} s, median {np.median(times):.3f} s")
