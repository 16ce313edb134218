#!/usr/bin/env python3
"""Golden values for the report's tables (`analysis::analyze` + `StudyAnalysis::to_report`).

A small hand-made study: two codecs (A, B) on one clip at 10:1 and 20:1, six subjects, one
hidden repeat (subject 1 rates A at 10:1 twice) and one missing rating (subject 6 never saw
B at 20:1), plus staircase tracks of three subjects, one of them short of reversals. The
expected numbers come from SciPy / statsmodels / NumPy, independent of the Rust code, and
the expected table cells are those numbers formatted as the report prints them (3 decimals
for scores, 4 for staircase levels, p with two significant digits and "< 0.001" below).

What the analysis must do, as this script does it:
- MOS per condition over the subjects, each subject's repeats averaged first (the hidden
  repeat counts once, averaged; n = subjects), Student-t interval
  mean +- t(0.975, n - 1) * SD / sqrt(n).
- Codec comparisons at equal clip and ratio: paired t-test over the subjects who rated both,
  each subject's repeats averaged first; Holm over the table. Without a baseline every pair
  two-sided; with baseline B, "A scores higher than B" one-sided.
- Staircase: reversal = the level moves the other way after a trial than the last move
  before it; threshold = mean of the last 3 reversal levels; per subject the mean of its
  converged tracks; across subjects mean, SD, min, max and the Student-t interval. Beside it
  (issue 39) the mean of the last 4 reversals (the even count next to 3; a track with fewer
  takes its largest even count, at least 2) per track, and the threshold to cite per
  condition and over all: the even-count means averaged per subject, then mean, SD and
  Student-t interval across subjects, and the mean rounded to the level grid.

Install: pip install scipy statsmodels numpy
Run from the repository root: python3 scripts/golden/report_tables.py
"""
import json
import math

import numpy as np
import scipy
import statsmodels
from scipy import stats
from statsmodels.stats.multitest import multipletests

CONFIDENCE = 0.95
LAST_REVERSALS = 3

CONDITIONS = [  # id, codec, clip, compression ratio
    (1, "A", "walk", 10.0),
    (2, "B", "walk", 10.0),
    (3, "A", "walk", 20.0),
    (4, "B", "walk", 20.0),
]

# (subject, condition, score), in presentation order.
RATINGS = [
    (1, 1, 5), (1, 2, 4), (1, 3, 4), (1, 4, 3), (1, 1, 4),
    (2, 1, 4), (2, 2, 4), (2, 3, 4), (2, 4, 2),
    (3, 1, 5), (3, 2, 3), (3, 3, 3), (3, 4, 3),
    (4, 1, 4), (4, 2, 3), (4, 3, 4), (4, 4, 2),
    (5, 1, 5), (5, 2, 4), (5, 3, 3), (5, 4, 2),
    (6, 1, 4), (6, 2, 2), (6, 3, 3),
]

# Staircase tracks: subject, label, levels in units of 0.001 (t_L, thesis ch. 5).
TRACKS = [
    (1, "walk", [24, 22, 20, 18, 16, 18, 16, 14, 16, 14, 12, 14]),
    (2, "walk", [24, 22, 20, 18, 20, 18, 16, 14, 12, 14, 12, 10, 12, 14]),
    (2, "run", [24, 22, 20, 22, 20, 18, 16, 18, 20, 18, 16]),
    (3, "walk", [24, 22, 20, 18, 16, 14, 16, 18]),  # one reversal: unconverged
    (3, "run", [24, 22, 24, 22, 20, 22, 20, 18, 20, 22]),
]


def rust_fixed(x, decimals):
    return f"{x:.{decimals}f}"


def rust_p(p):
    """A p value as papers print it (APA): two significant digits, "< 0.001" below."""
    if p < 0.001:
        return "< 0.001"
    rounded = float(f"{p:.1e}")
    decimals = max(1, 1 - math.floor(math.log10(rounded)))
    return f"{rounded:.{decimals}f}"


TEST_KIND = {"two-sided": "paired t, two-tailed", "greater": "paired t, one-tailed (A > B)"}


def ratio(cr):
    return f"{cr:.0f}:1" if cr == int(cr) else f"{cr:.1f}:1"


def interval(values):
    v = np.asarray(values, dtype=float)
    n = len(v)
    mean = float(np.mean(v))
    sd = float(np.std(v, ddof=1))
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1) * sd / math.sqrt(n))
    return {"n": n, "mean": mean, "sd": sd, "half_width": half,
            "lower": mean - half, "upper": mean + half}


def mos_table():
    rows = []
    for cid, codec, clip, cr in sorted(CONDITIONS, key=lambda c: (c[1], c[2], c[3])):
        s = interval(list(subject_means(cid).values()))
        cells = [codec, clip, ratio(cr), str(s["n"]), rust_fixed(s["mean"], 3),
                 rust_fixed(s["sd"], 3), rust_fixed(s["half_width"], 3),
                 rust_fixed(s["lower"], 3), rust_fixed(s["upper"], 3)]
        rows.append({"condition": cid, "numbers": s, "cells": cells})
    return rows


def subject_means(cid):
    per = {}
    for subject, c, score in RATINGS:
        if c == cid:
            per.setdefault(subject, []).append(score)
    return {s: float(np.mean(v)) for s, v in per.items()}


def ttest_table(baseline):
    rows = []
    for cr in (10.0, 20.0):
        by_codec = {codec: cid for cid, codec, _, r in CONDITIONS if r == cr}
        if baseline is None:
            pairs = [("A", "B", "two-sided")]
        else:
            pairs = [(c, baseline, "greater") for c in sorted(by_codec) if c != baseline]
        for first, second, alternative in pairs:
            ma, mb = subject_means(by_codec[first]), subject_means(by_codec[second])
            common = sorted(set(ma) & set(mb))
            a = np.array([ma[s] for s in common])
            b = np.array([mb[s] for s in common])
            r = stats.ttest_rel(a, b, alternative=alternative)
            d = a - b
            rows.append({"clip": "walk", "cr": cr, "first": first, "second": second,
                         "alternative": alternative,
                         "n": len(common), "mean_first": float(a.mean()),
                         "mean_second": float(b.mean()), "t": float(r.statistic),
                         "df": float(r.df), "p": float(r.pvalue),
                         "effect_size": float(d.mean() / d.std(ddof=1))})
    holm = multipletests([r["p"] for r in rows], method="holm")[1]
    for r, p in zip(rows, holm):
        r["p_holm"] = float(p)
        r["cells"] = ["walk", ratio(r["cr"]), r["first"], rust_fixed(r["mean_first"], 3),
                      r["second"], rust_fixed(r["mean_second"], 3), TEST_KIND[r["alternative"]],
                      rust_fixed(r["t"], 3),
                      rust_fixed(r["df"], 2), rust_p(r["p"]), rust_p(r["p_holm"]),
                      rust_fixed(r["effect_size"], 3)]
    return rows


def reversal_levels(levels):
    moves = np.sign(np.diff(levels))
    out, last = [], 0
    for i, m in enumerate(moves):
        if m == 0:
            continue
        if last != 0 and m != last:
            out.append(levels[i])
        last = m
    return out


def threshold_table():
    per, unconverged = {}, []
    for subject, label, units in TRACKS:
        levels = [u * 0.001 for u in units]
        rev = reversal_levels(levels)
        if len(rev) < LAST_REVERSALS:
            unconverged.append([subject, label])
            continue
        per.setdefault(subject, []).append(float(np.mean(rev[-LAST_REVERSALS:])))
    per_subject = {s: float(np.mean(v)) for s, v in sorted(per.items())}
    values = list(per_subject.values())
    s = interval(values)
    s["min"], s["max"] = min(values), max(values)
    cells = [str(len(values)), str(len(unconverged)), str(LAST_REVERSALS),
             rust_fixed(s["mean"], 4), rust_fixed(s["sd"], 4), rust_fixed(s["min"], 4),
             rust_fixed(s["max"], 4), rust_fixed(s["lower"], 4), rust_fixed(s["upper"], 4)]
    return {"per_subject": [[k, v] for k, v in per_subject.items()],
            "unconverged": unconverged, "numbers": s, "cells": cells}


EVEN_K = LAST_REVERSALS + LAST_REVERSALS % 2  # the even count next to k: 4 for 3


def even_estimate(rev):
    """(count, mean) of the last EVEN_K reversals, or of the largest even count below it
    (at least 2); None with fewer than 2."""
    k = EVEN_K if len(rev) >= EVEN_K else len(rev) - len(rev) % 2
    if k < 2:
        return None
    return k, float(np.mean(rev[-k:]))


def staircase_tracks_table():
    """Every track: reversals, the last-3 mean and the even-k mean side by side."""
    rows = []
    for subject, label, units in TRACKS:
        rev = reversal_levels([u * 0.001 for u in units])
        last = float(np.mean(rev[-LAST_REVERSALS:])) if len(rev) >= LAST_REVERSALS else None
        even = even_estimate(rev)
        rows.append({"cells": [
            str(subject), label, str(len(rev)),
            rust_fixed(last, 4) if last is not None else "n/a",
            "n/a" if even is None else (
                rust_fixed(even[1], 4) if even[0] == EVEN_K
                else f"{rust_fixed(even[1], 4)} (last {even[0]})"),
        ]})
    return rows


def threshold_cite_table():
    """The threshold to cite per condition (labels sorted) and over all: per subject the mean
    of its tracks' even-k estimates, then across subjects mean, SD, Student-t interval; the
    last-3 mean beside it; the mean rounded to the grid (origin: the smallest level, step: the
    smallest move)."""
    levels = [u * 0.001 for _, _, units in TRACKS for u in units]
    origin = min(levels)
    step = min(abs(b - a) * 0.001 for _, _, units in TRACKS
               for a, b in zip(units, units[1:]) if b != a)
    rows = []
    for condition in sorted({label for _, label, _ in TRACKS}) + [None]:
        even, last = {}, {}
        for subject, label, units in TRACKS:
            if condition is not None and label != condition:
                continue
            rev = reversal_levels([u * 0.001 for u in units])
            e = even_estimate(rev)
            if e is not None:
                even.setdefault(subject, []).append(e[1])
            if len(rev) >= LAST_REVERSALS:
                last.setdefault(subject, []).append(float(np.mean(rev[-LAST_REVERSALS:])))
        values = [float(np.mean(v)) for _, v in sorted(even.items())]
        lasts = [float(np.mean(v)) for _, v in sorted(last.items())]
        mean = float(np.mean(values))
        if len(values) >= 2:
            s = interval(values)
            sd, ci = rust_fixed(s["sd"], 4), f"{rust_fixed(s['lower'], 4)} – {rust_fixed(s['upper'], 4)}"
        else:
            sd, ci = "n/a", "n/a"
        nearest = origin + round((mean - origin) / step) * step
        rows.append({"mean": mean, "cells": [
            condition if condition is not None else "all conditions", str(len(values)),
            rust_fixed(float(np.mean(lasts)), 4) if lasts else "n/a",
            rust_fixed(mean, 4), sd, ci, rust_fixed(nearest, 3),
        ]})
    return rows


def main():
    out = {
        "generator": "scripts/golden/report_tables.py",
        "versions": {"scipy": scipy.__version__, "statsmodels": statsmodels.__version__,
                     "numpy": np.__version__},
        "confidence": CONFIDENCE,
        "last_reversals": LAST_REVERSALS,
        "conditions": [{"id": i, "codec": c, "clip": k, "compression_ratio": r}
                       for i, c, k, r in CONDITIONS],
        "ratings": [{"subject": s, "condition": c, "score": float(x)} for s, c, x in RATINGS],
        "tracks": [{"subject": s, "label": label, "levels": [u * 0.001 for u in units]}
                   for s, label, units in TRACKS],
        "mos": mos_table(),
        "ttests_two_sided": ttest_table(None),
        "ttests_baseline_b": ttest_table("B"),
        "thresholds": threshold_table(),
        "staircase_tracks": staircase_tracks_table(),
        "threshold_to_cite": threshold_cite_table(),
    }
    with open("analysis/tests/data/report_tables_golden.json", "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
