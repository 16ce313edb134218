#!/usr/bin/env python3
"""Independent Bradley-Terry scale values of a pair comparison study (ITU-T P.910 PC), from
its results folder.

Reads every session's trials.csv (format versions 1 and 2) and the stimulus manifest with
Python's csv and json modules, and fits with choix (choix.ilsr_pairwise, alpha = 0: the
maximum-likelihood estimate, iterated to a change below 1e-12), without any of the project's
code:

- each scored row (familiarization left out, hidden repeats kept) is one comparison: the
  subject preferred the `reference` column's stimulus when `response` equals
  `reference_position`, else the `stimulus` column's;
- one fit per clip (items: its conditions) and, with two or more clips, one of all clips
  pooled (items: codec at a target ratio, the original as "reference");
- scale values natural-log strengths, shifted so that the anchor is 0: the original when it
  was compared, else the item of the lowest target ratio, then codec name;
- standard errors from the Fisher information of the log strengths at choix's estimate,
  the anchor's row and column removed, inverted with numpy.linalg.inv; the interval
  s +- z(0.975) * SE with scipy.stats.norm.

With ties (a `response` of "neither": no preference) every fit is Davidson's model instead,
by scripts/reference/davidson_reference.py (SciPy; it knows nothing of this script's
reading): the ties of each pair counted apart, a row gains its ties after its wins, and
comparisons count preferences and ties.

Prints JSON {"rows": [[clip or "all", codec, "10:1" or "ref", wins, (ties,) comparisons,
scale, se, lower, upper], ...]} with the numbers as floats, in the order of `study report`'s
tables/pc_scale.csv (clips by name, then "all"; each fit's anchor first, then by ratio and
codec), {"wins": {clip: matrix}} with the win counts (row preferred over column), and with
ties {"ties": {clip: matrix}, "nu": {clip: [ties, nu, se, lower, upper]}}.

Install: pip install choix numpy scipy (the tests use target/bayes-env, pinned in
scripts/reference/bayes-requirements.txt)
Run: python3 scripts/golden/pair_comparison.py RESULTS_DIR MANIFEST.json
"""
import csv
import json
import os
import sys

import choix
import numpy as np
from scipy import stats

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "reference"))
import davidson_reference  # noqa: E402

CONFIDENCE = 0.95


def read_choices(results, manifest):
    """[(clip, winner id, loser id, tie)] of every scored pair comparison row."""
    out = []
    for name in sorted(os.listdir(results)):
        path = os.path.join(results, name, "trials.csv")
        if not os.path.isfile(path):
            continue
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                if r["block"] == "familiarization":
                    continue
                if r["protocol"] != "pair_comparison":
                    raise SystemExit(f"{path}: protocol {r['protocol']} is not pair_comparison")
                a, b = r["stimulus"], r["reference"]
                tie = r["response"] == "neither"
                if r["response"] == r["reference_position"]:
                    winner, loser = b, a
                else:
                    winner, loser = a, b
                clip = manifest[a]["clip"]
                if manifest[b]["clip"] != clip:
                    raise SystemExit(f"{path}: {a} and {b} are of different clips")
                out.append((clip, winner, loser, tie))
    return out


def item_of(s):
    if s.get("variant"):
        raise SystemExit(f"{s['id']}: codec variants are not handled by this script")
    if s["codec"] == "reference":
        return ("reference", None)
    return (s["codec"], float(s["target_cr"]))


def order_key(item):
    codec, cr = item
    return (float("-inf") if cr is None else cr, codec)


def fit(clip, comparisons):
    """Rows and win matrix of one fit over [(winner item, loser item)]."""
    items = sorted({i for c in comparisons for i in c}, key=order_key)
    index = {item: k for k, item in enumerate(items)}
    data = [(index[w], index[l]) for w, l in comparisons]
    n = len(items)
    wins = np.zeros((n, n), dtype=int)
    for w, l in data:
        wins[w, l] += 1
    params = choix.ilsr_pairwise(n, data, alpha=0.0, max_iter=10000, tol=1e-12)
    scale = params - params[0]
    p = np.exp(scale)
    info = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            count = wins[i, j] + wins[j, i]
            pij = p[i] / (p[i] + p[j])
            v = count * pij * (1.0 - pij)
            info[i, i] += v
            info[i, j] -= v
    cov = np.linalg.inv(info[1:, 1:])
    se = np.concatenate([[0.0], np.sqrt(np.diag(cov))])
    z = stats.norm.ppf(0.5 + CONFIDENCE / 2)
    rows = []
    for k, (codec, cr) in enumerate(items):
        ratio = "ref" if cr is None else f"{cr:g}:1"
        rows.append([clip, codec, ratio, int(wins[k].sum()), int(wins[k].sum() + wins[:, k].sum()),
                     float(scale[k]), float(se[k]), float(scale[k] - z * se[k]),
                     float(scale[k] + z * se[k])])
    return rows, wins.tolist()


def fit_ties(clip, comparisons):
    """Rows, win and tie matrices and [ties, nu, se, lower, upper] of one Davidson fit over
    [(winner item, loser item, tie)]."""
    items = sorted({i for c in comparisons for i in c[:2]}, key=order_key)
    index = {item: k for k, item in enumerate(items)}
    n = len(items)
    wins = np.zeros((n, n), dtype=int)
    ties = np.zeros((n, n), dtype=int)
    for w, l, tie in comparisons:
        if tie:
            ties[index[w], index[l]] += 1
            ties[index[l], index[w]] += 1
        else:
            wins[index[w], index[l]] += 1
    f = davidson_reference.fit({"n": n, "anchor": 0, "wins": wins.tolist(),
                                "ties": ties.tolist(), "confidence": CONFIDENCE})
    z = stats.norm.ppf(0.5 + CONFIDENCE / 2)
    rows = []
    for k, (codec, cr) in enumerate(items):
        ratio = "ref" if cr is None else f"{cr:g}:1"
        t = int(ties[k].sum())
        rows.append([clip, codec, ratio, int(wins[k].sum()), t,
                     int(wins[k].sum() + wins[:, k].sum()) + t,
                     f["scale"][k], f["se"][k], f["lower"][k], f["upper"][k]])
    theta, se_theta = f["log_nu"], f["log_nu_se"]
    nu = [int(ties.sum() // 2), f["nu"], f["nu_se"], float(np.exp(theta - z * se_theta)),
          float(np.exp(theta + z * se_theta))]
    return rows, wins.tolist(), ties.tolist(), nu


def main():
    results, manifest_path = sys.argv[1], sys.argv[2]
    with open(manifest_path) as f:
        manifest = {s["id"]: s for s in json.load(f)["stimuli"]}
    choices = read_choices(results, manifest)
    clips = sorted({c for c, _, _, _ in choices})
    with_ties = any(t for _, _, _, t in choices)
    rows, wins, ties, nus = [], {}, {}, {}
    groups = [(clip, [(item_of(manifest[w]), item_of(manifest[l]), t)
                      for c, w, l, t in choices if c == clip]) for clip in clips]
    if len(clips) > 1:
        groups.append(("all", [(item_of(manifest[w]), item_of(manifest[l]), t)
                               for _, w, l, t in choices]))
    for clip, comparisons in groups:
        if with_ties:
            r, m, t, nu = fit_ties(clip, comparisons)
            ties[clip] = t
            nus[clip] = nu
        else:
            r, m = fit(clip, [(w, l) for w, l, _ in comparisons])
        rows += r
        wins[clip] = m
    out = {"rows": rows, "wins": wins}
    if with_ties:
        out["ties"] = ties
        out["nu"] = nus
    print(json.dumps(out))


if __name__ == "__main__":
    main()
