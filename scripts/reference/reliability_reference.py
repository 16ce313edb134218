"""Reference inter-rater reliability for analysis/tests/reliability_interop.rs.

Reads a JSON list of cases, each {"ratings": [[subject, condition, score], ...]} (repeats
allowed, missing subject-condition pairs allowed), and prints per case:
- pingouin 0.7.0 `intraclass_corr` (targets = conditions, raters = subjects, a subject's
  repeats averaged by pandas' pivot, targets with a missing rater dropped: nan_policy="omit"):
  every form's ICC, F, df1, df2, p and 95 % CI (unrounded: pingouin rounds the CI to two
  decimals unless `options["round.column.CI95"]` is None);
- krippendorff 0.9.0 `alpha` (interval and ordinal) of the subjects x conditions table of
  those means, NaN where a subject did not rate a condition.
"""

import json
import sys

import krippendorff
import numpy as np
import pandas as pd
import pingouin as pg


def one(case):
    df = pd.DataFrame(case["ratings"], columns=["subject", "condition", "score"])
    icc = pg.intraclass_corr(
        data=df, targets="condition", raters="subject", ratings="score", nan_policy="omit"
    )
    forms = [
        {
            "type": row["Type"],
            "icc": float(row["ICC"]),
            "f": float(row["F"]),
            "df1": float(row["df1"]),
            "df2": float(row["df2"]),
            "p": float(row["pval"]),
            "lower": float(row["CI95"][0]),
            "upper": float(row["CI95"][1]),
        }
        for _, row in icc.iterrows()
    ]
    wide = df.pivot_table(index="subject", columns="condition", values="score", aggfunc="mean")
    complete = int(wide.notna().all(axis=0).sum())
    data = wide.to_numpy(dtype=float)
    return {
        "icc": forms,
        "complete": complete,
        "alpha_interval": float(krippendorff.alpha(data, level_of_measurement="interval")),
        "alpha_ordinal": float(krippendorff.alpha(data, level_of_measurement="ordinal")),
    }


def main():
    with open(sys.argv[1], encoding="utf-8") as f:
        cases = json.load(f)
    json.dump([one(c) for c in cases], sys.stdout)


if __name__ == "__main__":
    np.seterr(all="ignore")
    pg.options["round"] = None
    pg.options["round.column.CI95"] = None
    main()
