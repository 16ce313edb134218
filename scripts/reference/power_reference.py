"""Reference sample sizes for analysis/tests/power_interop.rs.

Reads a JSON object {"power": [...], "solve": [...], "ci": [...]} and prints the same keys:
- power: statsmodels 0.15 `TTestPower().power(effect_size, nobs, alpha, alternative)`;
- solve: `TTestPower().solve_power(effect_size, nobs=None, alpha, power, alternative)` (the
  fractional n), and the power at its ceiling;
- ci: the smallest n >= 2 with scipy.stats.t.ppf(1 - alpha/2, n - 1) * sd / sqrt(n) <= w,
  and that half-width.
"""

import json
import math
import sys

from scipy import stats
from statsmodels.stats.power import TTestPower


def main():
    with open(sys.argv[1], encoding="utf-8") as f:
        cases = json.load(f)
    tp = TTestPower()
    out = {"power": [], "solve": [], "ci": []}
    for c in cases["power"]:
        p = tp.power(c["effect_size"], c["n"], c["alpha"], alternative=c["alternative"])
        if math.isnan(p):
            sys.exit(f"statsmodels gives NaN power for {c}")
        out["power"].append(float(p))
    for c in cases["solve"]:
        n = tp.solve_power(
            effect_size=c["effect_size"],
            nobs=None,
            alpha=c["alpha"],
            power=c["power"],
            alternative=c["alternative"],
        )
        n = float(n)
        whole = max(2, math.ceil(n))
        achieved = float(
            tp.power(c["effect_size"], whole, c["alpha"], alternative=c["alternative"])
        )
        out["solve"].append({"n": n, "achieved_at_ceiling": achieved, "ceiling": whole})
    for c in cases["ci"]:

        def half(n, c=c):
            return stats.t.ppf(1 - c["alpha"] / 2, n - 1) * c["sd"] / math.sqrt(n)

        # From the normal approximation, step to the smallest n that is narrow enough.
        z = stats.norm.ppf(1 - c["alpha"] / 2)
        n = max(2, math.floor((z * c["sd"] / c["w"]) ** 2))
        while half(n) > c["w"]:
            n += 1
        while n > 2 and half(n - 1) <= c["w"]:
            n -= 1
        before = float(half(n - 1)) if n > 2 else None
        out["ci"].append({"n": n, "half_width": float(half(n)), "half_width_before": before})
    json.dump(out, sys.stdout, allow_nan=False)


if __name__ == "__main__":
    main()
