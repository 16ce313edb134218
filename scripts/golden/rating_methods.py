#!/usr/bin/env python3
"""Independent tables of an ACR, ACR-HR or DCR study (ITU-T P.910), from its results folder.

Reads every session's trials.csv (format versions 1 and 2) and the stimulus manifest with the
standard library, and computes with NumPy and SciPy, without any of the project's code:

- MOS per test condition (familiarization trials left out, hidden repeats kept): each
  subject's ratings of the condition averaged first, then the mean over the subjects, the
  sample SD (ddof = 1) and the Student-t interval mean +- t(0.975, n - 1) * SD / sqrt(n).
  For a DCR study this is the mean of the impairment categories (5 imperceptible ... 1 very
  annoying).
- ACR-HR DMOS (P.910 hidden reference removal) per test condition whose clip's reference was
  rated as a condition too: DV = V(test) - V(hidden reference) + 5 per rating, V(hidden
  reference) the same subject's mean rating of that reference; each subject's DVs averaged,
  then summarised over the subjects as above.

Prints the rows as `study report` writes tables/mos.csv and tables/dmos_ci.csv (codec, clip,
ratio as "10:1" or "ref", n, mean, SD, CI half-width, lower, upper; three decimals), as JSON
{"mos": [...], "dmos": [...]}.

Install: pip install numpy scipy  (the tests use target/sureal-env, pinned in
scripts/reference/sureal-requirements.txt)
Run: python3 scripts/golden/rating_methods.py RESULTS_DIR MANIFEST.json
"""
import csv
import json
import math
import os
import sys

import numpy as np
from scipy import stats

CONFIDENCE = 0.95


def read_rows(results):
    rows = []
    for name in sorted(os.listdir(results)):
        path = os.path.join(results, name, "trials.csv")
        if not os.path.isfile(path):
            continue
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                if r["block"] == "familiarization":
                    continue
                if r["protocol"] not in ("acr", "dcr", "mos"):
                    raise SystemExit(f"{path}: protocol {r['protocol']} is not a rating method")
                rows.append((r["subject"], r["stimulus"], float(r["response"])))
    return rows


def summary(values):
    v = np.asarray(values, dtype=float)
    n = len(v)
    mean = float(v.mean())
    sd = float(v.std(ddof=1)) if n > 1 else float("nan")
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1) * sd / math.sqrt(n)) if n > 1 else float("nan")
    return n, mean, sd, half, mean - half, mean + half


def subject_means(pairs):
    """{condition: [mean of each subject's values]} from (subject, condition, value)."""
    per = {}
    for subject, condition, value in pairs:
        per.setdefault(condition, {}).setdefault(subject, []).append(value)
    return {c: [float(np.mean(v)) for _, v in sorted(s.items())] for c, s in per.items()}


def row(stimulus, manifest, values):
    s = manifest[stimulus]
    ratio = "ref" if s["codec"] == "reference" else f"{s['target_cr']:g}:1"
    n, mean, sd, half, lo, hi = summary(values)
    return [s["codec"], s["clip"], ratio, str(n)] + [f"{x:.3f}" for x in (mean, sd, half, lo, hi)]


def main():
    results, manifest_path = sys.argv[1], sys.argv[2]
    with open(manifest_path) as f:
        manifest = {s["id"]: s for s in json.load(f)["stimuli"]}
    rows = read_rows(results)
    mos = subject_means(rows)
    # Hidden references: reference stimuli rated as conditions; each test's is its clip's.
    rated_refs = {manifest[c]["clip"]: c for c in mos if manifest[c]["codec"] == "reference"}
    ref_mean = {}
    for subject, stimulus, score in rows:
        if stimulus in rated_refs.values():
            ref_mean.setdefault((subject, stimulus), []).append(score)
    dvs = []
    for subject, stimulus, score in rows:
        s = manifest[stimulus]
        ref = rated_refs.get(s["clip"])
        if s["codec"] == "reference" or ref is None:
            continue
        dvs.append((subject, stimulus, score - float(np.mean(ref_mean[(subject, ref)])) + 5.0))
    dmos = subject_means(dvs)
    order = lambda c: (manifest[c]["codec"], manifest[c]["clip"], manifest[c].get("target_cr") or 0)
    print(json.dumps({
        "mos": [row(c, manifest, mos[c]) for c in sorted(mos, key=order)],
        "dmos": [row(c, manifest, dmos[c]) for c in sorted(dmos, key=order)],
    }))


if __name__ == "__main__":
    main()
