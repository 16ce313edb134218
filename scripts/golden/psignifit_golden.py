#!/usr/bin/env python3
"""Bayesian psychometric fits of psignifit 4 (PyPI) on given 2AFC data.

Used by analysis/tests/psignifit_interop.rs to check `analysis::bayesian::fit` against
psignifit itself: for each case the test sends blocks (level, correct, trials) and a sigmoid;
this script fits them with psignifit's defaults for a 2AFC experiment (beta-binomial, default
priors, posterior-mean estimates, 'percentiles' credible intervals) and prints the posterior
mean and the interval of every parameter. For the Weibull the levels are passed as their
natural logarithm, as psignifit asks ('weibull' is its Gumbel on log levels).

Needs psignifit; scripts/test installs the pins of scripts/reference/bayes-requirements.txt
into target/bayes-env.

Usage: psignifit_golden.py CASES.json
  CASES.json: [{"sigmoid": "norm" | "logistic" | "weibull", "confidence": 0.95,
                "data": [[level, correct, trials], ...]}, ...]
  prints: {"versions": {...}, "cases": [{"mean": {param: value},
           "interval": {param: [lower, upper]}}, ...]}   (params: threshold, width, lambda, eta)
"""
import json
import math
import sys
import warnings


def run(case):
    import numpy as np
    import psignifit

    data = np.asarray(case["data"], dtype=float)
    if case["sigmoid"] == "weibull":
        data[:, 0] = np.log(data[:, 0])
    conf = case["confidence"]
    res = psignifit.psignifit(
        data,
        sigmoid=case["sigmoid"],
        experiment_type="2AFC",
        confP=(conf,),
        CI_method="percentiles",
        verbose=False,
    )
    params = ("threshold", "width", "lambda", "eta")
    return {
        "mean": {p: float(res.parameter_estimate_mean[p]) for p in params},
        "interval": {p: [float(v) for v in res.confidence_intervals[p][str(conf)]]
                     for p in params},
    }


def main(argv):
    if len(argv) != 2:
        sys.exit(__doc__)
    from importlib.metadata import version
    with open(argv[1]) as f:
        cases = json.load(f)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = {
            "versions": {n: version(n) for n in ("psignifit", "numpy", "scipy")},
            "cases": [run(c) for c in cases],
        }
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv)
