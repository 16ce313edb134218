#!/usr/bin/env python3
"""The MOS-vs-CR figure as matplotlib draws it with its defaults, to compare with the report's.

Run:  FIGURES_OUT=/tmp/figs cargo test -p analysis --test figures png_is_the_print_size
      python3 -m venv /tmp/mpl && /tmp/mpl/bin/pip install matplotlib
      /tmp/mpl/bin/python scripts/compare/figures_matplotlib.py /tmp/figs

The test writes every figure of a simulated study (12 subjects, 3 codecs, 2 clips, CR 20-40,
scale 1-5) as SVG, PNG and the figure's data as JSON. This script reads
`mos_vs_cr.json` and draws the same curves the way a first matplotlib script does: one axes,
`errorbar` per codec x clip labelled "codec / clip", default colours, ticks, legend and
`savefig` resolution, as `mos_vs_cr_matplotlib.png`; and again under matplotlib's bundled
seaborn style (`seaborn-v0_8`, what `sns.set_theme()` gives, without seaborn installed) as
`mos_vs_cr_seaborn_style.png`. Nothing here is tuned: the point is what the defaults give.
"""
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def draw(figure, out):
    rate = figure["RateCurves"]
    fig, ax = plt.subplots()
    for s in rate["series"]:
        xs = [p[0] for p in s["points"]]
        ys = [p[1] for p in s["points"]]
        err = [[p[1] - p[2] for p in s["points"]], [p[3] - p[1] for p in s["points"]]]
        ax.errorbar(xs, ys, yerr=err, marker="o", label=f"{s['label']} / {s['clip']}")
    if rate["limit"] is not None:
        ax.axhline(rate["limit"], color="grey")
    ax.set_xlabel("Compression ratio (x:1)")
    ax.set_ylabel(rate["y_label"])
    ax.set_title(rate["title"])
    ax.legend()
    fig.savefig(out)
    plt.close(fig)
    return out


def main():
    folder = Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/figs")
    figure = json.loads((folder / "mos_vs_cr.json").read_text())
    print(draw(figure, folder / "mos_vs_cr_matplotlib.png"))
    with plt.style.context("seaborn-v0_8"):
        print(draw(figure, folder / "mos_vs_cr_seaborn_style.png"))


if __name__ == "__main__":
    main()
