#!/usr/bin/env python3
"""Independent CCR analysis (ITU-T P.910 comparison category rating) of a results folder.

Reads every session's trials.csv and the stimulus manifest with Python's csv and json
modules, without any of the project's code, and computes with NumPy and SciPy:

- each scored row (familiarization left out, hidden repeats kept) is one rating of the
  second (or right) version against the first (or left); `reference_position` "first" or
  "left" means the original came first, and the folded score is the rating itself,
  "second" or "right" means it came second, and the folded score is the rating negated
  (P.910: every folded score rates the test against the original);
- per condition (the `stimulus` column): each subject's mean folded score, then CMOS = the
  mean of those, SD with ddof = 1, and the Student t interval mean +- t(0.975, n - 1) * SD /
  sqrt(n) (scipy.stats.t.ppf);
- per condition and order: the mean folded score over every rating with the original first,
  and with it second, and their difference;
- the order effect: each subject's mean folded score over all its ratings with the original
  first, and with it second (subjects with both), scipy.stats.ttest_rel of the two, the mean
  and SD of the differences and their t interval.

Conditions are ordered by clip, then the original first, then by target ratio and codec;
a condition is labelled [clip, codec, "10:1" or "ref"].

Prints JSON {"cmos": [[clip, codec, ratio, subjects, ratings, cmos, sd, lower, upper]],
"order": [[clip, codec, ratio, n_first, mean_first, n_second, mean_second, difference]],
"order_effect": [subjects, difference, sd, lower, upper, t, df, p]}.

Install: pip install numpy scipy (the tests use target/bayes-env, pinned in
scripts/reference/bayes-requirements.txt)
Run: python3 scripts/golden/ccr.py RESULTS_DIR MANIFEST.json
"""
import csv
import json
import os
import sys
from collections import defaultdict

import numpy as np
from scipy import stats

CONFIDENCE = 0.95


def read(results):
    """[(subject, stimulus, reference first, rating)] of every scored CCR row."""
    out = []
    for name in sorted(os.listdir(results)):
        path = os.path.join(results, name, "trials.csv")
        if not os.path.isfile(path):
            continue
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                if r["block"] == "familiarization":
                    continue
                if r["protocol"] != "ccr":
                    raise SystemExit(f"{path}: protocol {r['protocol']} is not ccr")
                position = r["reference_position"]
                if position in ("first", "left"):
                    first = True
                elif position in ("second", "right"):
                    first = False
                else:
                    raise SystemExit(f"{path}: reference_position {position}")
                out.append((r["subject"], r["stimulus"], first, float(r["response"])))
    return out


def folded(first, rating):
    return rating if first else -rating


def t_interval(values):
    n = len(values)
    m = float(np.mean(values))
    if n < 2:
        return m, None, None, None
    sd = float(np.std(values, ddof=1))
    h = stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1) * sd / np.sqrt(n)
    return m, sd, m - h, m + h


def label(s):
    if s["codec"] == "reference":
        return [s["clip"], "reference", "ref"]
    return [s["clip"], s["codec"], f"{float(s['target_cr']):g}:1"]


def order_key(s):
    cr = float("-inf") if s["codec"] == "reference" else float(s["target_cr"])
    return (s["clip"], cr, s["codec"])


def main():
    results, manifest_path = sys.argv[1], sys.argv[2]
    with open(manifest_path) as f:
        manifest = {s["id"]: s for s in json.load(f)["stimuli"]}
    rows = read(results)
    stimuli = sorted({s for _, s, _, _ in rows}, key=lambda i: order_key(manifest[i]))
    cmos, order = [], []
    for stim in stimuli:
        mine = [r for r in rows if r[1] == stim]
        by_subject = defaultdict(list)
        for subject, _, first, rating in mine:
            by_subject[subject].append(folded(first, rating))
        means = [float(np.mean(v)) for _, v in sorted(by_subject.items())]
        m, sd, lo, hi = t_interval(means)
        cmos.append(label(manifest[stim]) + [len(means), len(mine), m, sd, lo, hi])
        a = [folded(f, r) for _, _, f, r in mine if f]
        b = [folded(f, r) for _, _, f, r in mine if not f]
        ma = float(np.mean(a)) if a else None
        mb = float(np.mean(b)) if b else None
        diff = ma - mb if a and b else None
        order.append(label(manifest[stim]) + [len(a), ma, len(b), mb, diff])
    first, second = defaultdict(list), defaultdict(list)
    for subject, _, f, rating in rows:
        (first if f else second)[subject].append(folded(f, rating))
    both = sorted(set(first) & set(second))
    xa = np.array([np.mean(first[s]) for s in both])
    xb = np.array([np.mean(second[s]) for s in both])
    test = stats.ttest_rel(xa, xb)
    m, sd, lo, hi = t_interval(list(xa - xb))
    effect = [len(both), m, sd, lo, hi, float(test.statistic), len(both) - 1, float(test.pvalue)]
    print(json.dumps({"cmos": cmos, "order": order, "order_effect": effect}))


if __name__ == "__main__":
    main()
