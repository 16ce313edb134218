#!/usr/bin/env python3
"""Independent MUSHRA tables (ITU-R BS.1534-3, adapted to motion) from a results folder.

Reads, with the standard library only (csv, json, tomllib), every session's trials.csv (the
rows of training screens, block familiarization, left out), the copy of the study file
(study.toml: [mushra] anchors and post-screening rules) and of the stimulus manifest
(stimuli.json) that the results folder holds, and computes with SciPy, without any of the
project's code:

- BS.1534-3 post-screening: per subject, the screens rated (= hidden references rated, one
  per clip), how many hidden references were rated below reference_below (default 90), how
  many anchors above anchor_above (default 90); a subject whose share of missed hidden
  references exceeds max_fraction (default 0.15) is excluded, and with anchor_rule =
  "exclude" one whose share of high anchors exceeds it too.
- Per rated stimulus (tests, hidden references, anchors) over the subjects kept: n, mean,
  sample SD (ddof = 1) and the Student-t interval mean +- t(0.975, n - 1) * SD / sqrt(n)
  (scipy.stats.t.ppf).

Prints JSON {"screening": [[subject, screens, low, high, excluded], ...],
"conditions": [[stimulus, clip, role, n, mean, sd, half, lower, upper], ...]} with the cells
as `study report` writes tables/mushra_screening.csv and tables/mushra.csv (three decimals,
"n/a" where undefined).

Install: pip install scipy  (the tests use target/sureal-env, pinned in
scripts/reference/sureal-requirements.txt)
Run: python3 scripts/golden/mushra.py RESULTS_DIR
"""
import csv
import json
import math
import os
import sys
import tomllib

from scipy import stats

CONFIDENCE = 0.95
ROLE_ORDER = {"hidden reference": 0, "test": 1, "anchor": 2}


def fmt(x):
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.3f}"


def read_rows(results):
    rows = []
    for name in sorted(os.listdir(results)):
        path = os.path.join(results, name, "trials.csv")
        if not os.path.isfile(path):
            continue
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                if r["protocol"] != "mushra":
                    raise SystemExit(f"{path}: protocol {r['protocol']} is not mushra")
                if r["block"] == "familiarization":
                    continue  # a training screen: not analysed
                rows.append((r["subject"], r["stimulus"], r["reference"], float(r["response"])))
    return rows


def main():
    results = sys.argv[1]
    with open(os.path.join(results, "study.toml"), "rb") as f:
        m = tomllib.load(f)["mushra"]
    with open(os.path.join(results, "stimuli.json")) as f:
        manifest = {s["id"]: s for s in json.load(f)["stimuli"]}
    below = float(m.get("reference_below", 90))
    above = float(m.get("anchor_above", 90))
    share = float(m.get("max_fraction", 0.15))
    exclude_anchor = m.get("anchor_rule", "report") == "exclude"
    anchors = set(m["anchors"])
    rows = read_rows(results)

    def role(stimulus, reference):
        if stimulus in anchors:
            return "anchor"
        return "hidden reference" if stimulus == reference else "test"

    per = {}
    for subject, stimulus, reference, score in rows:
        e = per.setdefault(subject, [0, 0, 0])
        r = role(stimulus, reference)
        if r == "hidden reference":
            e[0] += 1
            e[1] += score < below
        elif r == "anchor":
            e[2] += score > above
    screening, excluded = [], set()
    for subject in sorted(per):
        screens, low, high = per[subject]
        fails_ref = screens > 0 and low / screens > share
        fails_anchor = screens > 0 and high / screens > share
        out = fails_ref or (exclude_anchor and fails_anchor)
        if out:
            excluded.add(subject)
        verdict = ("yes: hidden reference" if fails_ref else "yes: anchor") if out else (
            "no (anchor listed)" if fails_anchor else "no")
        screening.append([subject, str(screens), str(low), str(high), verdict])

    values, roles = {}, {}
    for subject, stimulus, reference, score in rows:
        values.setdefault(stimulus, [])
        roles[stimulus] = role(stimulus, reference)
        if subject not in excluded:
            values[stimulus].append(score)
    table = []
    for stimulus in sorted(values, key=lambda s: (manifest[s]["clip"], ROLE_ORDER[roles[s]], s)):
        v = values[stimulus]
        n = len(v)
        mean = sum(v) / n if n else None
        sd = math.sqrt(sum((x - mean) ** 2 for x in v) / (n - 1)) if n > 1 else None
        half = stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1) * sd / math.sqrt(n) if n > 1 else None
        lo = mean - half if half is not None else None
        hi = mean + half if half is not None else None
        table.append([stimulus, manifest[stimulus]["clip"], roles[stimulus], str(n)]
                     + [fmt(x) for x in (mean, sd, half, lo, hi)])
    print(json.dumps({"screening": screening, "conditions": table}))


if __name__ == "__main__":
    main()
