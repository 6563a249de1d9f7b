"""``skpcd info FILE|FOLDER``: what a point-cloud file or a folder of segments
holds.

A file: points, fields, bounds and spacing; for LAS/LAZ also what ``pdal
info`` and ``lasinfo`` show (version, point format, scales and offsets,
CRS, VLRs, extra dimensions, classification and return histograms). A
folder written by ``skpcd segment``: its segments, points, files and types,
what the run chose and, with a labels or predictions file, the classes. A
file is described without loading scikit-learn.
"""

import csv
import importlib.util
import json
import os
from collections import Counter
from pathlib import Path

import numpy as np


def add_parser(sub):
    p = sub.add_parser(
        "info",
        help="what a point-cloud file or a folder of segments holds",
        description="A file: points, fields, bounds and spacing; for LAS/LAZ "
        "also the LAS version, point format, scales, offsets, CRS, VLRs, extra "
        "dimensions and the classification and return histograms. A folder "
        "written by skpcd segment: segments, points, files, types and, with a "
        "labels or predictions CSV in it, the classes.",
    )
    p.add_argument(
        "file",
        help="a point-cloud file (.xyz .txt .pts .csv .npy .ply .pcd .las .laz) "
        "or a folder of segments",
    )
    p.add_argument(
        "--json", action="store_true", help="print one JSON object (for scripts)"
    )
    p.set_defaults(func=run)
    return p


def _point_spacing():
    """:func:`skpcd.preprocessing.point_spacing`, loaded from its module
    alone: the package ``skpcd.preprocessing`` loads scikit-learn."""
    import skpcd

    path = Path(skpcd.__file__).parent / "preprocessing" / "_spacing.py"
    spec = importlib.util.spec_from_file_location("_skpcd_info_spacing", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.point_spacing


def describe_file(path):
    """What ``skpcd info FILE`` reports, as a dict."""
    from skpcd.io._api import read_point_cloud

    points, extras = read_point_cloud(path, fields="all", nonfinite="keep")
    finite = np.isfinite(points).all(axis=1)
    valid = points[finite]
    info = {
        "file": str(path),
        "points": len(points),
        "nonfinite": int(len(points) - len(valid)),
        "fields": ["x", "y", "z", *extras],
    }
    if len(valid):
        lo, hi = valid.min(axis=0), valid.max(axis=0)
        info["bounds"] = {
            axis: [float(a), float(b)] for axis, a, b in zip("xyz", lo, hi, strict=True)
        }
        info["spacing"] = _point_spacing()(valid, workers=-1)
    if Path(path).suffix.lower() in (".las", ".laz"):
        from skpcd.io._las_info import describe_las

        info["las"] = describe_las(path, extras)
    return info


def _read_csv(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _label_files(folder):
    """The CSV files of ``file,label`` rows in ``folder`` (labels.csv, the
    output of ``skpcd predict``), by name."""
    out = {}
    for path in sorted(Path(folder).glob("*.csv")):
        with open(path, newline="", encoding="utf-8") as fh:
            head = next(csv.reader(fh), [])
        if [c.strip().lower() for c in head[:2]] == ["file", "label"]:
            out[path.name] = path
    return out


def describe_folder(folder):
    """What ``skpcd info FOLDER`` reports, as a dict."""
    from skpcd.exceptions import PointCloudFileError
    from skpcd.io._api import SUPPORTED_EXTENSIONS
    from skpcd.io._segment_folder import (
        SEGMENTATION_METADATA,
        SEGMENTS_SUMMARY,
        check_segment_run,
    )

    folder = Path(folder)
    names = sorted(os.listdir(folder))
    files = [
        n
        for n in names
        if Path(n).suffix.lower() in SUPPORTED_EXTENSIONS
        and not n.startswith(".")
        and n not in (SEGMENTS_SUMMARY, "labels.csv")
        and (folder / n).is_file()
    ]
    info = {"folder": str(folder), "segment_run": False}
    sizes = {}
    if (folder / SEGMENTS_SUMMARY).is_file():
        rows = _read_csv(folder / SEGMENTS_SUMMARY)
        sizes = {r["file"]: int(r["n_points"]) for r in rows}
        info.update(
            segment_run=True,
            segments=len(rows),
            points=sum(sizes.values()),
            types=dict(Counter(r["type"] for r in rows)),
        )
        try:
            check_segment_run(folder, names)
            info["complete"] = True
        except PointCloudFileError as exc:
            info["complete"] = False
            info["problem"] = exc.problem
        files = [f for f in files if f in sizes]
        metadata = folder / SEGMENTATION_METADATA
        if metadata.is_file():
            run = json.loads(metadata.read_text())
            info["run"] = {
                k: run.get(k) for k in ("scene", "ground", "method", "eps", "n_ground")
            }
    info["files"] = len(files)
    info["formats"] = dict(Counter(Path(f).suffix.lower().lstrip(".") for f in files))
    classes = {}
    for name, path in _label_files(folder).items():
        counts = Counter()
        points = Counter()
        for row in _read_csv(path):
            counts[row["label"]] += 1
            points[row["label"]] += sizes.get(row["file"], 0)
        classes[name] = {
            label: {"segments": counts[label], "points": points[label]}
            for label in sorted(counts)
        }
    info["classes"] = classes
    return info


def _text_file(info):
    bad = info["nonfinite"]
    out = [
        f"file      {info['file']}",
        f"points    {info['points']}"
        + (f" ({bad} with NaN/inf coordinates)" if bad else ""),
        "fields    " + " ".join(info["fields"]),
    ]
    for axis, (a, b) in info.get("bounds", {}).items():
        out.append(f"{axis}         [{a:.4f}, {b:.4f}]  extent {b - a:.4f}")
    if "spacing" in info:
        out.append(
            f"spacing   {info['spacing']:.4f} (median nearest distinct neighbour)"
        )
    las = info.get("las")
    if las:
        out += _text_las(las)
    return out


def _text_las(las):
    out = [
        f"las       version {las['version']}, point format {las['point_format']} "
        f"({las['record_length']} bytes a point"
        + (", LAZ" if las["compressed"] else "")
        + f"), {las['n_points']} points",
        "scale     " + " ".join(f"{s:g}" for s in las["scales"]),
        "offset    " + " ".join(f"{o:g}" for o in las["offsets"]),
        f"software  {las['generating_software'] or '-'} "
        f"(system {las['system_identifier'] or '-'}; created "
        f"{las['creation_date'] or '-'})",
    ]
    crs = las["crs"]
    if crs is None:
        out.append("crs       none")
    else:
        epsg = f"EPSG:{crs['epsg']}; " if crs["epsg"] else ""
        out.append(f"crs       {crs['name'] or '(unnamed)'} ({epsg}{crs['from']})")
    for key, label in (("vlrs", "vlr"), ("evlrs", "evlr")):
        for v in las[key]:
            out.append(
                f"{label:<10}{v['user_id']} {v['record_id']}: "
                f"{v['description'] or '-'} ({v['bytes']} bytes)"
            )
    for d in las["extra_dimensions"]:
        description = f" ({d['description']})" if d["description"] else ""
        out.append(f"extra     {d['name']} {d['type']}{description}")
    if las["classification"]:
        out.append(
            "classes   "
            + ", ".join(
                f"{c['code']} {c['name'] or '?'}: {c['points']}"
                for c in las["classification"]
            )
        )
    if las["returns"]:
        out.append(
            "returns   "
            + ", ".join(f"{r['code']}: {r['points']}" for r in las["returns"])
        )
    return out


def _text_folder(info):
    out = [f"folder    {info['folder']}"]
    if info["segment_run"]:
        types = ", ".join(f"{n} {t}" for t, n in sorted(info["types"].items()))
        out.append(
            f"segments  {info['segments']} ({types or 'none'}), {info['points']} points"
        )
        if not info["complete"]:
            out.append(f"problem   {info['problem']}")
        run = info.get("run")
        if run:
            eps = run["eps"]
            out.append(
                f"run       scene {run['scene']}, ground {run['ground']}, "
                f"{run['method']}"
                + (f" eps {eps:.3f}" if isinstance(eps, (int, float)) else "")
            )
    formats = ", ".join(f"{n} {f}" for f, n in sorted(info["formats"].items()))
    out.append(f"files     {info['files']} point-cloud files ({formats or 'none'})")
    for name, classes in info["classes"].items():
        points = info["segment_run"]
        out.append(
            f"classes   {name}: "
            + ", ".join(
                f"{label} {c['segments']}"
                + (f" ({c['points']} points)" if points else "")
                for label, c in classes.items()
            )
        )
    return out


def run(args):
    path = Path(args.file)
    info = describe_folder(path) if path.is_dir() else describe_file(path)
    if args.json:
        print(json.dumps(info, indent=1))
    elif path.is_dir():
        print("\n".join(_text_folder(info)))
    else:
        print("\n".join(_text_file(info)))
    return 0
