#!/usr/bin/env python3
"""A sureal dataset file as Netflix sureal's subjective models see it.

Used by analysis/tests/sureal_interop.rs to check that the analysis crate's sureal export
(`analysis::export::SurealDataset`) is read by the real sureal unchanged and that sureal's MOS
and DMOS agree with the report's. Needs sureal; scripts/test installs the pinned versions of
scripts/reference/sureal-requirements.txt into target/sureal-env.

Usage:
  sureal_reference.py DATASET.py [--dmos]
      Runs MosModel, SubjrejMosModel and MaximumLikelihoodEstimationModel (and DmosModel with
      --dmos) on the file, each through `Model.from_dataset_file(...).run_modeling()`, and
      prints one JSON object: {"versions": {...}, "asset_ids": [...] (the dis_videos in file
      order, which is the order of every per-stimulus list), "content_ids": [...],
      "models": {NAME: RESULT}}. RESULT has "quality_scores" (one per dis_video) and
      "observers" (sureal's sorted subject names) for every model, "observer_rejected" for
      SubjrejMosModel, "observer_bias", "observer_inconsistency" and "content_ambiguity" for
      the MLE model. Non-finite numbers are printed as null. A model that raises gives
      {"error": "..."} instead.

The models' own progress output goes to stderr, so stdout holds only the JSON.
"""
import contextlib
import json
import math
import sys
import traceback
import warnings


def versions():
    from importlib.metadata import version
    return {name: version(name) for name in ("sureal", "numpy", "scipy")}


def plain(x):
    """numpy scalars and arrays to JSON values; NaN and infinities to None."""
    if hasattr(x, "tolist"):
        x = x.tolist()
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, bool) or x is None:
        return x
    if isinstance(x, (int, float)):
        x = float(x)
        return x if math.isfinite(x) else None
    return x


def run(model_class, path):
    keys = ("quality_scores", "observers", "observer_rejected", "observer_bias",
            "observer_inconsistency", "content_ambiguity")
    try:
        result = model_class.from_dataset_file(path).run_modeling()
    except Exception:  # noqa: BLE001 - the test wants to see what sureal said
        return {"error": traceback.format_exc()}
    return {k: plain(result[k]) for k in keys if k in result}


def main(argv):
    if len(argv) not in (2, 3) or (len(argv) == 3 and argv[2] != "--dmos"):
        sys.exit(__doc__)
    path = argv[1]
    from sureal.subjective_model import (DmosModel, MaximumLikelihoodEstimationModel,
                                         MosModel, SubjrejMosModel)
    from sureal.tools.misc import import_python_file

    models = [MosModel, SubjrejMosModel, MaximumLikelihoodEstimationModel]
    if "--dmos" in argv:
        models.append(DmosModel)
    out = {"versions": versions(), "models": {}}
    with contextlib.redirect_stdout(sys.stderr), warnings.catch_warnings():
        # sureal's loader uses the deprecated SourceFileLoader.load_module; its subject
        # rejection divides 0 by 0 for a subject with no outlying score.
        warnings.simplefilter("ignore")
        dataset = import_python_file(path)
        out["asset_ids"] = [v["asset_id"] for v in dataset.dis_videos]
        out["content_ids"] = [v["content_id"] for v in dataset.dis_videos]
        for model in models:
            out["models"][model.__name__] = run(model, path)
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv)
