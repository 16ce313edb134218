#!/usr/bin/env python3
"""QUEST+ runs of the `questplus` package (PyPI) on given answer sequences.

Used by protocols/tests/questplus_golden.rs to check `protocols::quest::QuestPlus` against
an implementation nobody here wrote: for each case the test sends the stimulus domain, the
parameter grids with their prior weights and a fixed sequence of answers; this script asks
questplus for the next stimulus (`next_stim`, min_entropy), answers it with the next answer
of the sequence (`update`), and records after every trial the level it chose and the whole
posterior. The test requires the same level on every trial and the same posterior.

The psychometric function is questplus's `weibull` with `stim_scale="linear"`:
p = 1 - lapse - (1 - guess - lapse) exp(-(x / threshold)^slope), guess (lower asymptote)
fixed at 0.5 for 2AFC. Needs questplus; scripts/test installs the pins of
scripts/reference/bayes-requirements.txt into target/bayes-env.

Usage: questplus_golden.py CASES.json
  CASES.json: [{"levels": [...], "thresholds": [...], "slopes": [...], "lapses": [...],
                "threshold_prior": [...], "slope_prior": [...], "lapse_prior": [...],
                "answers": [true, false, ...]}, ...]
  prints: {"versions": {...}, "cases": [{"levels": [level of trial 1, ...],
           "posteriors": [[flattened C-order posterior after trial 1], ...],
           "estimate": {"threshold": mean, "slope": mean, "lapse_rate": mean},
           "threshold_marginal": [...]}, ...]}
"""
import json
import sys
import warnings


def run(case):
    import numpy as np
    from questplus import QuestPlus

    q = QuestPlus(
        stim_domain={"intensity": case["levels"]},
        param_domain={
            "threshold": case["thresholds"],
            "slope": case["slopes"],
            "lower_asymptote": [0.5],
            "lapse_rate": case["lapses"],
        },
        outcome_domain={"response": ["Correct", "Incorrect"]},
        prior={
            "threshold": np.asarray(case["threshold_prior"], dtype=float),
            "slope": np.asarray(case["slope_prior"], dtype=float),
            "lower_asymptote": np.asarray([1.0]),
            "lapse_rate": np.asarray(case["lapse_prior"], dtype=float),
        },
        func="weibull",
        stim_scale="linear",
        stim_selection_method="min_entropy",
        param_estimation_method="mean",
    )
    levels, posteriors = [], []
    for correct in case["answers"]:
        x = q.next_stim["intensity"]
        levels.append(float(x))
        q.update(stim={"intensity": x},
                 outcome={"response": "Correct" if correct else "Incorrect"})
        posteriors.append([float(v) for v in q.posterior.values.reshape(-1)])
    est = q.param_estimate
    return {
        "levels": levels,
        "posteriors": posteriors,
        "estimate": {k: float(est[k]) for k in ("threshold", "slope", "lapse_rate")},
        "threshold_marginal": [float(v) for v in q.marginal_posterior["threshold"]],
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
            "versions": {n: version(n) for n in ("questplus", "numpy", "xarray")},
            "cases": [run(c) for c in cases],
        }
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv)
