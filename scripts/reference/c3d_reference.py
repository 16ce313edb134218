#!/usr/bin/env python3
"""C3D files as the two independent C3D readers on PyPI see them, and C3D files they write.

Used by markers/tests/c3d_interop.rs to check the markers crate's C3D writer and reader
against ezc3d (pyomeca, C++) and py-c3d (the `c3d` package, pure Python). Needs numpy, ezc3d
and c3d; scripts/test installs pinned versions into target/pyenv.

Usage:
  c3d_reference.py read FILE
      Prints one JSON object: {"versions": {...}, "ezc3d": READ, "py_c3d": READ}, where READ is
      {"labels", "rate_hz", "header_rate_hz", "units", "scale", "frames", "points",
       "analog_channels", "analog_rate_hz", "warnings"}; "points" is frame-major,
      points[frame][marker] = [x, y, z] in the file's units, or null where the reader marks the
      sample invalid. A reader that refuses the file gives {"error": "..."} instead.
  c3d_reference.py write DIR
      Writes reference files into DIR with ezc3d (float storage, with and without analog
      channels, in mm and in m) and with py-c3d (integer storage with POINT:SCALE > 0, with and
      without analog channels; ezc3d writes float storage only) and prints {"versions": ...,
      "files": [{"name", "writer", "storage", "scale", "labels", "rate_hz", "units",
      "analog_channels", "points"}]}, "points" being the values given to the writer (null: a
      gap).

Floats are printed with repr(), so a 32-bit value read back in Rust is exactly the one the
reader returned.
"""
import json
import math
import os
import sys
import warnings

import numpy as np


def versions():
    import ezc3d
    from importlib.metadata import version
    return {"ezc3d": getattr(ezc3d, "__version__", version("ezc3d")),
            "c3d": version("c3d"), "numpy": np.__version__}


def labels_of(group_get, n):
    """POINT:LABELS then LABELS2, LABELS3, ... (the C3D convention past 255 points)."""
    labels = []
    k = 1
    while True:
        got = group_get("LABELS" if k == 1 else "LABELS%d" % k)
        if got is None:
            break
        labels.extend(got)
        k += 1
    return [str(l).strip() for l in labels][:n] if n is not None else labels


def xyz_or_none(x, y, z, valid):
    if not valid or not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return None
    return [float(x), float(y), float(z)]


def read_ezc3d(path):
    import ezc3d
    # Strict: ezc3d's default refuses a parameter section whose offsets do not chain.
    c = ezc3d.c3d(path)
    p = c["parameters"]
    point = p["POINT"]
    pts = c["data"]["points"]  # (4, markers, frames); invalid samples are NaN
    markers, frames = pts.shape[1], pts.shape[2]

    def get(name):
        return list(point[name]["value"]) if name in point else None

    analog = p.get("ANALOG", {})
    units = point["UNITS"]["value"] if "UNITS" in point else []
    return {
        "labels": labels_of(get, markers),
        "rate_hz": float(point["RATE"]["value"][0]),
        "header_rate_hz": float(c["header"]["points"]["frame_rate"]),
        "units": str(units[0]).strip() if len(units) else "",
        "scale": float(point["SCALE"]["value"][0]),
        "frames": int(frames),
        "points": [[xyz_or_none(pts[0, m, f], pts[1, m, f], pts[2, m, f], True)
                    for m in range(markers)] for f in range(frames)],
        "analog_channels": int(analog["USED"]["value"][0]) if "USED" in analog else 0,
        "analog_rate_hz": float(c["header"]["analogs"]["frame_rate"]),
        "warnings": [],
    }


def read_py_c3d(path):
    import c3d
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with open(path, "rb") as handle:
            r = c3d.Reader(handle)

            def get(name):
                param = r.get("POINT:" + name)
                return list(param.string_array) if param is not None else None

            markers = r.point_used
            rows = []
            for _, points, _analog in r.read_frames():
                # Column 3 is -1 where the fourth word marks the sample invalid.
                rows.append([xyz_or_none(points[m, 0], points[m, 1], points[m, 2],
                                         points[m, 3] >= 0) for m in range(markers)])
            units = r.get("POINT:UNITS")
            out = {
                "labels": labels_of(get, markers),
                "rate_hz": float(r.point_rate),
                "header_rate_hz": float(r.header.frame_rate),
                "units": units.string_value.strip() if units is not None else "",
                "scale": float(r.point_scale),
                "frames": len(rows),
                "points": rows,
                "analog_channels": int(r.analog_used),
                "analog_rate_hz": float(r.analog_rate),
            }
    out["warnings"] = [str(w.message) for w in caught]
    return out


def guarded(read, path):
    try:
        return read(path)
    except Exception as e:  # a refusal is the finding, reported to the Rust test
        return {"error": "%s: %s" % (type(e).__name__, e)}


def reference_points(markers, frames, unit_mm, seed):
    """Deterministic trajectories in the file's units (circles around spread-out centres,
    a few gaps), frame-major, None for a gap."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1500.0, 1500.0, size=(markers, 3))
    centres[:, 2] = rng.uniform(50.0, 1800.0, size=markers)
    out = []
    for f in range(frames):
        t = f / 10.0
        row = []
        for m in range(markers):
            if (f * 7 + m * 3) % 11 == 5:
                row.append(None)
                continue
            x, y, z = centres[m] + 100.0 * np.array([math.cos(t + m), math.sin(t + m), 0.5 * math.sin(2 * t)])
            row.append([float(v) / unit_mm for v in (x, y, z)])
        out.append(row)
    return out


def write_ezc3d(path, labels, rate_hz, units, points, analog_channels, analog_per_frame):
    import ezc3d
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate_hz]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    frames, markers = len(points), len(labels)
    data = np.zeros((4, markers, frames))
    for f, row in enumerate(points):
        for m, p in enumerate(row):
            data[0:3, m, f] = p if p is not None else [np.nan] * 3
            data[3, m, f] = 1.0
    c["data"]["points"] = data
    if analog_channels:
        c["parameters"]["ANALOG"]["RATE"]["value"] = [rate_hz * analog_per_frame]
        c["parameters"]["ANALOG"]["LABELS"]["value"] = tuple("EMG%d" % (k + 1) for k in range(analog_channels))
        samples = frames * analog_per_frame
        c["data"]["analogs"] = np.sin(np.arange(samples)[None, None, :] / 7.0
                                      + np.arange(analog_channels)[None, :, None])
    c.write(path)


def write_py_c3d(path, labels, rate_hz, scale, points, analog_channels, analog_per_frame):
    import c3d
    w = c3d.Writer(point_rate=rate_hz, analog_rate=rate_hz * analog_per_frame,
                   point_scale=scale, point_units="mm  ")
    w.set_point_labels(labels)
    if analog_channels:
        w.set_analog_labels(["EMG%d" % (k + 1) for k in range(analog_channels)])
        # One scale and offset per channel: without them (py-c3d's default, empty arrays)
        # ezc3d 1.7.2 crashes reading the file.
        w.set_analog_scales([0.001] * analog_channels)
        w.set_analog_offsets([0] * analog_channels)
    frames = []
    for f, row in enumerate(points):
        pts = np.zeros((len(labels), 5), dtype=np.float32)
        for m, p in enumerate(row):
            if p is None:
                pts[m, 3] = -1.0
            else:
                pts[m, :3] = p
        analog = np.zeros((analog_channels, analog_per_frame), dtype=np.float32)
        for k in range(analog_channels):
            analog[k] = np.round(1000.0 * np.sin((f * analog_per_frame + np.arange(analog_per_frame)) / 7.0 + k))
        frames.append((pts, analog))
    w.add_frames(frames)
    with warnings.catch_warnings():
        # "No analog data found in file." and the like, about the file being written.
        warnings.simplefilter("ignore")
        with open(path, "wb") as handle:
            w.write(handle)


def write_all(folder):
    os.makedirs(folder, exist_ok=True)
    labels = ["LASI", "RASI", "LKNE", "RKNE", "LANK", "RANK", "C7"]
    rate_hz = 100.0
    files = []

    def record(name, writer, storage, scale, units, points, analog_channels):
        files.append({"name": name, "writer": writer, "storage": storage, "scale": scale,
                      "labels": labels, "rate_hz": rate_hz, "units": units,
                      "analog_channels": analog_channels, "points": points})

    mm = reference_points(len(labels), 40, 1.0, 20)
    write_ezc3d(os.path.join(folder, "ezc3d_float.c3d"), labels, rate_hz, "mm", mm, 0, 0)
    record("ezc3d_float.c3d", "ezc3d", "float", -1.0, "mm", mm, 0)
    write_ezc3d(os.path.join(folder, "ezc3d_float_analog.c3d"), labels, rate_hz, "mm", mm, 3, 10)
    record("ezc3d_float_analog.c3d", "ezc3d", "float", -1.0, "mm", mm, 3)
    metres = reference_points(len(labels), 40, 1000.0, 21)
    write_ezc3d(os.path.join(folder, "ezc3d_float_metres.c3d"), labels, rate_hz, "m", metres, 0, 0)
    record("ezc3d_float_metres.c3d", "ezc3d", "float", -1.0, "m", metres, 0)
    scale = 0.1  # mm per integer step; the trajectories stay within +-3200 mm
    write_py_c3d(os.path.join(folder, "pyc3d_integer.c3d"), labels, rate_hz, scale, mm, 0, 0)
    record("pyc3d_integer.c3d", "py-c3d", "integer", scale, "mm", mm, 0)
    write_py_c3d(os.path.join(folder, "pyc3d_integer_analog.c3d"), labels, rate_hz, scale, mm, 2, 4)
    record("pyc3d_integer_analog.c3d", "py-c3d", "integer", scale, "mm", mm, 2)
    return {"versions": versions(), "files": files}


def main(argv):
    if len(argv) == 3 and argv[1] == "read":
        out = {"versions": versions(), "ezc3d": guarded(read_ezc3d, argv[2]),
               "py_c3d": guarded(read_py_c3d, argv[2])}
    elif len(argv) == 3 and argv[1] == "write":
        out = write_all(argv[2])
    else:
        sys.stderr.write(__doc__)
        return 2
    json.dump(out, sys.stdout, allow_nan=False)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
