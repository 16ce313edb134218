#!/usr/bin/env python3
"""The noncentral t of `analysis::jnd` against SciPy, far into its tails and at large n.

Used by analysis/tests/jnd.rs (`noncentral_t_and_share_intervals_equal_scipy`, issue 39): the
test sends points (t, df, delta) and JND share cases; this script answers with

- for each point: `scipy.stats.nct.cdf` and `.sf`, and the same probabilities by an
  independent quadrature over the normal numerator (SciPy's `quad` and `gammainc`):
      t > 0: P(T <= t) = Phi(-d) + int_{z > -d} phi(z) Q(df/2, df/2 ((z + d)/t)^2) dz
      t < 0: P(T <= t) =           int_{z < -d} phi(z) P(df/2, df/2 ((z + d)/t)^2) dz
  (P, Q: regularized lower/upper incomplete gamma; P(T > t | d) = P(T <= -t | -d)).
  SciPy 1.17's nct (Boost) loses relative accuracy for small probabilities at t < 0 (measured
  0.5 % at cdf(-5, 9, 5) = 6.7e-14, 0.8 % at cdf(-8, 199, 2) = 6.4e-21): the test takes
  nct's value where it agrees with the quadrature to 1e-8 and the quadrature's elsewhere, and
  says so;
- for each share case: thresholds drawn here (numpy, the case's seed), and at each level the
  observed t = sqrt(n) (mean - x)/sd, the noncentralities delta_lo, delta_hi solving
  nct.cdf(t, n-1, delta) = 1 - alpha/2 and = alpha/2 by brentq (xtol 1e-14), and the share
  interval Phi(delta/sqrt(n)) (in the form with t >= 0, nct.sf(-t, df, -delta), where nct is
  accurate: the targets are alpha/2, not small).

Usage: nct_golden.py CASES.json
  CASES.json: {"points": [[t, df, delta], ...],
               "shares": [{"n": n, "mean": mu, "sd": sigma, "seed": s, "confidence": c,
                           "levels": [x, ...]}, ...]}
"""
import json
import math
import sys

import numpy as np
import scipy
from scipy import integrate, optimize, special, stats


def log_integrand(t, df, d):
    """(log f(z), lower, upper) of the quadrature over the numerator z, on its side of -d."""
    a = 0.5 * df
    if t > 0:
        def logf(z):
            return stats.norm.logpdf(z) + np.log(special.gammaincc(a, a * ((z + d) / t) ** 2))
        return logf, -d, -d + 80.0 + abs(d)
    def logf(z):
        return stats.norm.logpdf(z) + np.log(special.gammainc(a, a * ((z + d) / t) ** 2))
    return logf, -d - 80.0 - abs(d), -d


def quad_cdf(t, df, d):
    if t == 0:
        return float(stats.norm.cdf(-d))
    logf, lo, hi = log_integrand(t, df, d)
    z = np.linspace(lo, hi, 40001)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = logf(z)
    v = np.where(np.isfinite(v), v, -np.inf)
    i = int(np.argmax(v))
    top = v[i]
    if not np.isfinite(top):
        return float(stats.norm.cdf(-d)) if t > 0 else 0.0
    # only where the integrand is within e^-60 of its peak
    keep = np.nonzero(v > top - 60.0)[0]
    a, b = z[max(keep[0] - 1, 0)], z[min(keep[-1] + 1, len(z) - 1)]

    def f(x):
        with np.errstate(divide="ignore", invalid="ignore"):
            r = logf(x) - top
        return math.exp(r) if np.isfinite(r) else 0.0

    val, _ = integrate.quad(f, a, b, points=[z[i]], limit=2000, epsabs=0, epsrel=1e-13)
    # log of the sum, the Phi(-d) part of t > 0 added
    out = math.exp(top) * val if top < 700 else math.inf
    if t > 0:
        out += float(stats.norm.cdf(-d))
    return out


def finite(v):
    """A float for JSON, None where SciPy gave NaN (its nct does, far in some tails)."""
    v = float(v)
    return v if math.isfinite(v) else None


def point(t, df, d):
    return {
        "t": t,
        "df": df,
        "delta": d,
        "scipy_cdf": finite(stats.nct.cdf(t, df, d)),
        "scipy_sf": finite(stats.nct.sf(t, df, d)),
        "quad_cdf": quad_cdf(t, df, d),
        "quad_sf": quad_cdf(-t, df, -d),
    }


def cdf_accurate(t, df, d):
    """nct's P(T <= t) in its accurate form: with t >= 0 (sf of the mirrored t)."""
    if t >= 0:
        return float(stats.nct.cdf(t, df, d))
    return float(stats.nct.sf(-t, df, -d))


def share_case(case):
    rng = np.random.default_rng(case["seed"])
    n = case["n"]
    x = rng.normal(case["mean"], case["sd"], n)
    m, s = float(np.mean(x)), float(np.std(x, ddof=1))
    a = 1 - case["confidence"]
    rows = []
    for level in case["levels"]:
        tobs = math.sqrt(n) * (m - level) / s

        def root(target):
            f = lambda d: cdf_accurate(tobs, n - 1, d) - target
            spread = math.sqrt(1 + tobs * tobs / (2 * (n - 1)))
            lo, hi, step = tobs - spread, tobs + spread, spread
            while f(lo) <= 0:
                lo -= step
                step *= 1.5
            step = spread
            while f(hi) >= 0:
                hi += step
                step *= 1.5
            return optimize.brentq(f, lo, hi, xtol=1e-14, rtol=1e-15, maxiter=500)

        dlo, dhi = root(1 - a / 2), root(a / 2)
        rows.append({
            "level": level,
            "t": tobs,
            "delta": [dlo, dhi],
            "model": float(stats.norm.cdf((m - level) / s)),
            "ci": [float(stats.norm.cdf(dlo / math.sqrt(n))), float(stats.norm.cdf(dhi / math.sqrt(n)))],
            # the share who notice, 1 - the above, without cancellation near 100 %
            "ci_notice": [float(stats.norm.sf(dhi / math.sqrt(n))), float(stats.norm.sf(dlo / math.sqrt(n)))],
        })
    return {"thresholds": x.tolist(), "rows": rows}


def main(argv):
    if len(argv) != 2:
        sys.exit(__doc__)
    with open(argv[1]) as f:
        cases = json.load(f)
    out = {
        "versions": {"numpy": np.__version__, "scipy": scipy.__version__},
        "points": [point(*p) for p in cases["points"]],
        "shares": [share_case(c) for c in cases["shares"]],
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv)
