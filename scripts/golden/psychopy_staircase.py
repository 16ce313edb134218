#!/usr/bin/env python3
"""Golden staircase sequences from PsychoPy's StairHandler.

Writes protocols/tests/data/psychopy_staircase.json (linear steps, nUp=1, nDown=2) and
protocols/tests/data/psychopy_staircase_log_db.json (stepType 'log' and 'db', nUp and nDown
from 1 to 3): for random answer sequences, the level (intensity) PsychoPy presents on every
trial, which trials it marks as reversals, and whether it finished.
protocols/tests/staircase_psychopy.rs replays the same answers into `protocols::Staircase` and
requires the same levels and reversals. The two files have their own seeds, so adding the
second left the first byte for byte as it was.

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
LOG_DB_SEED = 20260701
LOG_DB_CASES_PER_TYPE_AND_RULE = 250


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
    levels, used = run(s, answers)
    reversals = [i in s.reversalPoints for i in range(len(levels))]
    return {
        "start": start, "step": step, "min": min_val, "max": max_val,
        "n_reversals": n_reversals, "n_trials": n_trials,
        "apply_initial_rule": apply_initial_rule,
        "answers": used, "levels": levels, "reversals": reversals,
        "reversal_levels": [float(x) for x in s.reversalIntensities],
        "finished": bool(s.finished),
    }


def run(s, answers):
    """Feeds answers until the staircase finishes: levels shown and the answers used."""
    levels, used = [], []
    for a in answers:
        if s.finished:
            break
        levels.append(float(next(s)))
        s.addResponse(a)
        used.append(a)
    return levels, used


def log_db_case(rng, step_type, apply_initial_rule):
    """Multiplicative steps: 'log' multiplies by 10**step, 'db' by 10**(step/20)."""
    if step_type == "log":
        step = rng.choice([0.05, 0.1, 0.2, 0.25, 0.5, 1.0])
        factor = 10.0 ** step
    else:
        step = rng.choice([0.5, 1.0, 2.0, 3.0, 6.0, 20.0])
        factor = 10.0 ** (step / 20.0)
    start = rng.choice([0.024, 0.012, 1.0, 0.5, 8.0, 100.0, 3e-4]) * rng.uniform(0.5, 2.0)
    if rng.random() < 0.5:
        min_val, max_val = None, None
    else:
        # Bounds off the grid of start * factor**k, so that clamping is exercised too.
        min_val = start / factor ** rng.uniform(0.5, 8.0)
        max_val = start * factor ** rng.uniform(0.0, 6.0)
    n_up = rng.randint(1, 3)
    n_down = rng.randint(1, 3)
    n_reversals = rng.randint(1, 14)
    n_trials = rng.choice([0, 0, 10, 30, 60])
    p = rng.uniform(0.3, 0.95)
    answers = [1 if rng.random() < p else 0 for _ in range(rng.randint(1, 90))]
    s = StairHandler(start, nReversals=n_reversals, stepSizes=[step], nTrials=n_trials,
                     nUp=n_up, nDown=n_down, applyInitialRule=apply_initial_rule,
                     stepType=step_type, minVal=min_val, maxVal=max_val, autoLog=False)
    levels, used = run(s, answers)
    reversals = [i in s.reversalPoints for i in range(len(levels))]
    return {
        "step_type": step_type, "start": start, "step": step, "min": min_val, "max": max_val,
        "n_up": n_up, "n_down": n_down,
        "n_reversals": n_reversals, "n_trials": n_trials,
        "apply_initial_rule": apply_initial_rule,
        "answers": used, "levels": levels, "reversals": reversals,
        "reversal_levels": [float(x) for x in s.reversalIntensities],
        "finished": bool(s.finished),
    }


def write(path, out):
    with open(path, "w") as f:
        json.dump(out, f, separators=(",", ":"))
        f.write("\n")


def main():
    rng = random.Random(SEED)
    cases = [one_case(rng, rule) for rule in (False, True) for _ in range(CASES_PER_RULE)]
    write("protocols/tests/data/psychopy_staircase.json",
          {"generator": "scripts/golden/psychopy_staircase.py", "seed": SEED,
           "psychopy_version": psychopy.__version__, "n_up": 1, "n_down": 2,
           "step_type": "lin", "cases": cases})
    rng = random.Random(LOG_DB_SEED)
    cases = [log_db_case(rng, step_type, rule)
             for step_type in ("log", "db") for rule in (False, True)
             for _ in range(LOG_DB_CASES_PER_TYPE_AND_RULE)]
    write("protocols/tests/data/psychopy_staircase_log_db.json",
          {"generator": "scripts/golden/psychopy_staircase.py", "seed": LOG_DB_SEED,
           "psychopy_version": psychopy.__version__, "cases": cases})


if __name__ == "__main__":
    main()
