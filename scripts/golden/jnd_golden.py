#!/usr/bin/env python3
"""Golden values for `analysis::jnd`: share of viewers who would not notice a level.

Run:  pip install scipy numpy
      python3 scripts/golden/jnd_golden.py > analysis/tests/data/jnd_golden.json

For per-viewer thresholds T_1..T_n and a level x:
  empirical share not noticing = #{T_i > x} / n
  normal model: Phi((mean - x) / sd), sd with ddof=1
  exact normal-theory CI: t = sqrt(n) (mean - x) / sd ~ nct(n - 1, delta), delta = sqrt(n) z;
  delta_lo solves nct.cdf(t, n-1, delta) = 1 - alpha/2, delta_hi solves ... = alpha/2;
  bounds Phi(delta / sqrt(n)).
Inputs are generated here with a fixed seed and written next to the expected values.
"""
import json
import math
import sys

import numpy as np
import scipy
from scipy import optimize, stats

rng = np.random.default_rng(20261124)


def share(thresholds, x, conf):
    t = np.asarray(thresholds, dtype=float)
    n = len(t)
    out = {"level": x, "empirical": float(np.sum(t > x) / n)}
    if n >= 2 and np.std(t, ddof=1) > 0:
        m, s = float(np.mean(t)), float(np.std(t, ddof=1))
        out["model"] = float(stats.norm.cdf((m - x) / s))
        tobs = math.sqrt(n) * (m - x) / s
        a = 1 - conf

        def root(target):
            # nct.cdf falls in delta; Boost returns NaN far in its tails, so widen a bracket
            # around t step by step instead of starting wide.
            f = lambda d: stats.nct.cdf(tobs, n - 1, d) - target
            lo, hi, step = tobs - 1, tobs + 1, 1.0
            while f(lo) <= 0:
                lo -= step
                step *= 1.5
            step = 1.0
            while f(hi) >= 0:
                hi += step
                step *= 1.5
            return optimize.brentq(f, lo, hi, xtol=1e-14, rtol=1e-14, maxiter=500)

        lo, hi = root(1 - a / 2), root(a / 2)
        out["ci"] = [float(stats.norm.cdf(lo / math.sqrt(n))), float(stats.norm.cdf(hi / math.sqrt(n)))]
    return out


samples = {
    # thesis ch. 5 shape: t_L thresholds around 0.012, min 0.010, max 0.016, 20 subjects
    "thesis_tl_20": np.round(rng.normal(0.012, 0.0016, 20), 4).tolist(),
    # target compression ratios at threshold, 8 subjects
    "cr_8": np.round(rng.normal(34.0, 3.5, 8), 3).tolist(),
    "three": [30.0, 36.0, 41.0],
    "skewed_15": (20 + rng.exponential(6.0, 15)).tolist(),
}
levels = {
    "thesis_tl_20": [0.006, 0.01, 0.011, 0.012, 0.013, 0.016, 0.02],
    "cr_8": [20.0, 28.0, 32.0, 34.0, 36.0, 40.0, 48.0],
    "three": [25.0, 30.0, 35.5, 41.0, 50.0],
    "skewed_15": [18.0, 22.0, 25.0, 30.0, 45.0],
}
cases = []
for name, t in samples.items():
    for conf in (0.95, 0.9):
        for x in levels[name]:
            cases.append({"sample": name, "confidence": conf, "expected": share(t, x, conf)})

json.dump(
    {
        "generator": "scripts/golden/jnd_golden.py",
        "versions": {"python": sys.version.split()[0], "numpy": np.__version__, "scipy": scipy.__version__},
        "samples": samples,
        "cases": cases,
    },
    sys.stdout,
    indent=1,
)
sys.stdout.write("\n")
