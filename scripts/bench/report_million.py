#!/usr/bin/env python3
"""`study report` on 10^6 ratings, whole process, against the same report in pandas + SciPy.

Issue 18's target: `study report` on 10^6 ratings at least 10x faster than pandas + SciPy,
whole process, at most 200 MiB peak memory, both measured in one run.

  python3 scripts/bench/report_million.py make  DIR   # results directory (not timed)
  python3 scripts/bench/report_million.py peer  DIR   # the pandas + SciPy report of DIR
  python3 scripts/bench/report_million.py time  DIR [RUNS]  # both, timed with /usr/bin/time -v

`make` sweeps the examples' two generated motions through the paper-000 design (2 clips x 3
codecs x 7 ratios, into DIR-stimuli, the clips in DIR-clips) and runs `study simulate` on it
for 2,000 subjects (54 trials each, 50 of them rated tests or hidden repeats: 100,000 ratings)
under `eatmydata` (no fsync: generation is not what is measured), then copies every session nine times under new subject ids
(`S0001` -> `S0001-c1` ...). A copy keeps its `subject_index`, so it replays to the same
plan and passes `study report`'s log check; 20,000 sessions, 10^6 ratings.

`peer` does what `study report` does with the ratings, the way a lab would in Python: read
every `trials.csv` (pandas), check each session's trial indices run 0, 1, 2 ... and its
subject matches its folder, drop familiarization, average each subject's repeats, MOS per
condition with Student-t 95 % CIs, BT.500 Annex 2 screening per presentation (beta2,
+-2S or +-sqrt(20)S, P/Q, reject), MOS without the rejected, paired two-sided t-tests
between the codecs at every clip and ratio with Holm, and the tables as CSV.
Needs numpy, pandas, scipy, statsmodels (`pip install numpy pandas scipy statsmodels`).
"""
import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
STUDY = os.environ.get("STUDY_BIN", str(ROOT / "target/release/study"))


# The paper-000 design the ratings come from: 2 clips x 3 codecs x 7 ratios = 42 stimuli, 8
# hidden repeats, 4 familiarization trials (54 trials, 50 rated). The examples' study is smaller.
PAPER_STUDY = """format_version = 1
name = "mos-million"
title = "Motion quality study"
protocol = "mos"
stimuli = "stimuli.json"
seed = 20110512

[conditions]
clips = ["walk", "march"]
codecs = ["wavelet-perceptual", "wavelet-bone", "wavelet-standard"]
target_cr = [10, 20, 30, 40, 50, 60, 70]

[presentation]
arrangement = "side_by_side"
reference_position = "random"
stimulus_duration_ms = 6000

[scale]
kind = "categorical"
min = 1.0
max = 5.0
step = 0.5

[session]
time_limit_min = 40
familiarization = 4
hidden_repeats = 8

[simulation]
metric = "rms_cm"
quality_scale = 4.0
bias_sd = 0.3
noise_sd = 0.4
response_time_ms = 4000
"""


def make(out: Path) -> None:
    if out.exists():
        sys.exit(f"{out} exists")
    # Stimuli of the paper's design from the examples' generated motions, beside `out`.
    stim, clips = (out.parent / (out.name + tail) for tail in ("-stimuli", "-clips"))
    for d in (stim, clips):
        if d.exists():
            sys.exit(f"{d} exists")
    clips.mkdir()
    for clip in ("walk", "march"):
        shutil.copy(ROOT / "examples/stimuli" / clip / "reference.bvh", clips / f"{clip}.bvh")
    quiet = {"check": True, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    subprocess.run(
        [STUDY, "sweep", "--clips", str(clips / "walk.bvh"), str(clips / "march.bvh"),
         "--codecs", "wavelet-perceptual,wavelet-bone,wavelet-standard",
         "--cr", "10,20,30,40,50,60,70", "--quiet", "-o", str(stim)], **quiet)
    (stim / "mos.toml").write_text(PAPER_STUDY)
    subprocess.run(
        ["eatmydata", STUDY, "simulate", str(stim / "mos.toml"), "--subjects", "2000",
         "--seed", "1", "-o", str(out)], **quiet)
    originals = sorted(p for p in out.iterdir() if (p / "session.json").is_file())
    for copy in range(1, 10):
        for src in originals:
            m = json.loads((src / "session.json").read_text())
            old = m["subject"]
            new = f"{old}-c{copy}"
            m["subject"] = new
            dst = out / f"{new}_s{m['session']}"
            dst.mkdir()
            (dst / "session.json").write_text(json.dumps(m, indent=2))
            lines = (src / "trials.csv").read_text().splitlines(keepends=True)
            rows = [lines[0]]
            for line in lines[1:]:
                # format_version,study,subject,...
                f = line.split(",", 3)
                assert f[2] == old
                rows.append(f"{f[0]},{f[1]},{new},{f[3]}")
            (dst / "trials.csv").write_text("".join(rows))
    print(f"{out}: {len(originals) * 10} sessions")


def peer(res: Path, out: Path) -> None:
    import numpy as np
    import pandas as pd
    from scipy import stats
    from statsmodels.stats.multitest import multipletests

    manifest = json.loads((res / "stimuli.json").read_text())
    info = {s["id"]: s for s in manifest["stimuli"]}
    frames = []
    for d in sorted(p for p in res.iterdir() if (p / "session.json").is_file()):
        m = json.loads((d / "session.json").read_text())
        t = pd.read_csv(d / "trials.csv", usecols=["subject", "trial_index", "block",
                                                   "stimulus", "score"])
        if not (t["trial_index"].to_numpy() == np.arange(len(t))).all():
            sys.exit(f"{d}/trials.csv: trial indices out of order")
        if (t["subject"] != m["subject"]).any():
            sys.exit(f"{d}/trials.csv: a row of another subject")
        if len(t) != m["trials_logged"]:
            sys.exit(f"{d}/session.json: trial count")
        frames.append(t[t["block"] != "familiarization"])
    df = pd.concat(frames, ignore_index=True)
    df["codec"] = df["stimulus"].map(lambda s: info[s]["codec"])
    df["clip"] = df["stimulus"].map(lambda s: info[s]["clip"])
    df["cr"] = df["stimulus"].map(lambda s: info[s].get("target_cr") or info[s]["achieved_cr"])
    out.mkdir(exist_ok=True)

    means = df.groupby(["subject", "stimulus"], sort=False)["score"].mean().reset_index()

    def mos_table(frame):
        g = frame.groupby("stimulus")["score"]
        t = pd.DataFrame({"n": g.count(), "mean": g.mean(), "sd": g.std(ddof=1)})
        t["ci"] = stats.t.ppf(0.975, t["n"] - 1) * t["sd"] / np.sqrt(t["n"])
        t["lower"], t["upper"] = t["mean"] - t["ci"], t["mean"] + t["ci"]
        return t

    mos_table(means).to_csv(out / "mos.csv")

    # BT.500 screening, per presentation: repetition r = showing number of (subject, stimulus).
    df["rep"] = df.groupby(["subject", "stimulus"]).cumcount()
    g = df.groupby(["stimulus", "rep"])["score"]
    mean, std = g.transform("mean"), g.transform(lambda x: x.std(ddof=1))
    m2 = g.transform(lambda x: ((x - x.mean()) ** 2).mean())
    m4 = g.transform(lambda x: ((x - x.mean()) ** 4).mean())
    beta2 = m4 / (m2 ** 2)
    band = np.where((beta2 >= 2) & (beta2 <= 4), 2.0, math.sqrt(20.0)) * std
    df["p"] = df["score"] >= mean + band
    df["q"] = df["score"] <= mean - band
    per = df.groupby("subject").agg(p=("p", "sum"), q=("q", "sum"), n=("score", "count"))
    frac = (per["p"] + per["q"]) / per["n"]
    asym = (per["p"] - per["q"]).abs() / (per["p"] + per["q"]).replace(0, np.nan)
    per["rejected"] = (frac > 0.05) & (asym < 0.3)
    per.to_csv(out / "screening.csv")
    kept = means[~means["subject"].isin(per.index[per["rejected"]])]
    mos_table(kept).to_csv(out / "mos_screened.csv")

    # Paired two-sided t-tests between codecs at equal clip and ratio, Holm over the table.
    means = means.merge(df[["stimulus", "codec", "clip", "cr"]].drop_duplicates(), on="stimulus")
    wide = means.pivot_table(index="subject", columns=["clip", "cr", "codec"], values="score")
    rows = []
    for (clip, cr), block in wide.T.groupby(level=[0, 1]):
        codecs = sorted(block.index.get_level_values(2))
        for i, a in enumerate(codecs):
            for b in codecs[i + 1:]:
                x, y = wide[(clip, cr, a)], wide[(clip, cr, b)]
                ok = x.notna() & y.notna()
                r = stats.ttest_rel(x[ok], y[ok])
                rows.append({"clip": clip, "cr": cr, "a": a, "b": b, "mean_a": x[ok].mean(),
                             "mean_b": y[ok].mean(), "t": r.statistic, "df": r.df,
                             "p": r.pvalue})
    tests = pd.DataFrame(rows)
    tests["p_holm"] = multipletests(tests["p"], method="holm")[1]
    tests.to_csv(out / "ttests.csv", index=False)
    print(f"{out}: {len(df)} ratings")


def timed(cmd):
    t = subprocess.run(["/usr/bin/time", "-v", *cmd], capture_output=True, text=True)
    if t.returncode != 0:
        sys.exit(t.stderr)
    wall = rss = None
    for line in t.stderr.splitlines():
        if "Elapsed (wall clock)" in line:
            parts = line.rsplit(" ", 1)[1].split(":")
            wall = sum(float(x) * 60 ** i for i, x in enumerate(reversed(parts)))
        if "Maximum resident set size" in line:
            rss = int(line.rsplit(" ", 1)[1]) / 1024
    return wall, rss


def main():
    what, res = sys.argv[1], Path(sys.argv[2])
    if what == "make":
        make(res)
    elif what == "peer":
        peer(res, Path(sys.argv[3]) if len(sys.argv) > 3 else res.parent / "peer-report")
    elif what == "time":
        # RUNS pairs, each side right after the other; on a busy machine the median ratio
        # and its spread say more than one pair.
        runs = int(sys.argv[3]) if len(sys.argv) > 3 else 1
        ratios = []
        for run in range(1, runs + 1):
            for d in (res.parent / "study-report", res.parent / "peer-report"):
                shutil.rmtree(d, ignore_errors=True)
            # Warm the page cache, so neither side pays for the first read.
            for f in (*res.glob("*/trials.csv"), *res.glob("*/session.json")):
                f.read_bytes()
            ours = timed([STUDY, "report", str(res), "-o", str(res.parent / "study-report"),
                          "--no-png"])
            theirs = timed([sys.executable, __file__, "peer", str(res),
                            str(res.parent / "peer-report")])
            ratios.append(theirs[0] / ours[0])
            print(f"run {run}: study report {ours[0]:.2f} s, {ours[1]:.0f} MiB peak; "
                  f"pandas + SciPy {theirs[0]:.2f} s, {theirs[1]:.0f} MiB peak; "
                  f"ratio {ratios[-1]:.1f}x", flush=True)
        ratios.sort()
        print(f"ratio: {ratios[len(ratios) // 2]:.1f}x median of {runs} "
              f"({ratios[0]:.1f}x to {ratios[-1]:.1f}x)")
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
