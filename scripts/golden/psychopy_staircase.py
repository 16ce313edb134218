#!/usr/bin/env python3
"""Golden staircase sequences from PsychoPy's StairHandler.

Writes protocols/tests/data/psychopy_staircase.json: for random answer sequences, the level
(intensity) PsychoPy presents on every trial, which trials it marks as reversals, and whether it
finished. protocols/tests/staircase_psychopy.rs replays the same answers into
`protocols::Staircase` and requires identical levels (bit for bit) and reversals.

Install: pip install --no-deps psychopy && pip install six json-tricks i18next numpy packaging
Run from the repository root: python3 scripts/golden/psychopy_staircase.py
"""
import json
import random
import sys
import types

try:  # StairHandler never uses pandas; psychopy.data imports it at module level.
    import pandas  # noqa: F401
except ImportError:
    sys.modules["pandas"] = types.ModuleType("pandas")

import psychopy
from psychopy.data import StairHandler

SEED = 20260523
CASES_PER_RULE = 1000


def one_case(rng, apply_initial_rule):
    step = rng.choice([0.002, 0.5, 1.0, 0.1, 0.25, 3.0])
    start = step * rng.randint(2, 30)
    if rng.random() < 0.5:
        min_val, max_val = None, None
    else:
        min_val = start - step * rng.randint(1, 10)
        max_val = start + step * rng.randint(0, 8)
    n_reversals = rng.randint(1, 14)
    n_trials = rng.choice([0, 0, 10, 30, 60])
    p = rng.uniform(0.3, 0.95)
    answers = [1 if rng.random() < p else 0 for _ in range(rng.randint(1, 90))]
    s = StairHandler(start, nReversals=n_reversals, stepSizes=[step], nTrials=n_trials,
                     nUp=1, nDown=2, applyInitialRule=apply_initial_rule, stepType="lin",
                     minVal=min_val, maxVal=max_val, autoLog=False)
    levels, used = [], []
    for a in answers:
        if s.finished:
            break
        levels.append(float(next(s)))
        s.addResponse(a)
        used.append(a)
    reversals = [i in s.reversalPoints for i in range(len(levels))]
    return {
        "start": start, "step": step, "min": min_val, "max": max_val,
        "n_reversals": n_reversals, "n_trials": n_trials,
        "apply_initial_rule": apply_initial_rule,
        "answers": used, "levels": levels, "reversals": reversals,
        "reversal_levels": [float(x) for x in s.reversalIntensities],
        "finished": bool(s.finished),
    }


def main():
    rng = random.Random(SEED)
    cases = [one_case(rng, rule) for rule in (False, True) for _ in range(CASES_PER_RULE)]
    out = {"generator": "scripts/golden/psychopy_staircase.py", "seed": SEED,
           "psychopy_version": psychopy.__version__, "n_up": 1, "n_down": 2,
           "step_type": "lin", "cases": cases}
    with open("protocols/tests/data/psychopy_staircase.json", "w") as f:
        json.dump(out, f, separators=(",", ":"))
        f.write("\n")


if __name__ == "__main__":
    main()
