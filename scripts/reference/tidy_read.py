"""Reads a report's trials_tidy.csv with pandas as a user would (pandas.read_csv, types
inferred) and prints what it read as JSON: the columns in order, each column's dtype and
missing count, the row count, and every column's values row by row. Used by
the study tests that report the examples (scripts/golden/tidy_readers.rs)."""
import json
import math
import sys

import pandas

frame = pandas.read_csv(sys.argv[1])


def plain(v):
    if isinstance(v, float) and math.isnan(v):
        return None
    if hasattr(v, "item"):
        return v.item()
    return v


print(json.dumps({
    "pandas": pandas.__version__,
    "columns": list(frame.columns),
    "dtypes": {c: str(frame[c].dtype) for c in frame.columns},
    "missing": {c: int(frame[c].isna().sum()) for c in frame.columns},
    "rows": len(frame),
    "values": {c: [plain(v) for v in frame[c].tolist()] for c in frame.columns},
}))
