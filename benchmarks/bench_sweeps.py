"""Single sweeps at the sensor's rate: segmentation in the range image against
skpcd's 3-D path and Open3D, times and quality on the same real sweeps.

Data (nothing here is shipped): the core sweeps of ``../shared/data/real_labelled``
(SemanticKITTI HDL-64E, nuScenes HDL-32E, PandaSet Pandar64; labelled point by
point; ``$SKPCD_REAL_LABELLED_DIR``) and the 12 sweeps of
``../shared/data/real_mobile`` (KITTI, PandaSet; objects boxed;
``$SKPCD_REAL_MOBILE``).

For each sweep, in one process, warm (every kernel compiled and the model
loaded before the first timed sweep), each time the best of ``--repeat`` runs:

- ``range image``: :class:`skpcd.segmentation.SweepSegmenter` (one thread: its
  kernels are sequential; one a sensor), no sensor given: rays from the origin of
  the file (the sensor for SemanticKITTI, nuScenes and the KITTI sweeps of
  real_mobile), or from 1.85 m above the ground under it when the origin is on the
  road (PandaSet's files, in a frame whose origin is the road under the car); a
  ``range image, sensor given`` row gives PandaSet of real_labelled the sensor
  1.7 m above the origin, where its README puts the optical centre; a ``range
  image, theta 3, gap 2`` row joins with a smaller angle and a longer gap than
  the defaults, a ``range image, structures`` row runs the structures step on
  all threads);
- ``3-D path``: ``segment_scene(points)`` with its defaults (scan kind, CSF and
  the bases pass, DBSCAN in sweep coordinates, structures), ``n_jobs=1`` and
  ``n_jobs=-1``;
- ``Open3D``: its largest plane as ground (``segment_plane``, 0.2 m, 1000
  iterations) and ``cluster_dbscan(eps, min_points=5)`` on the rest, eps the one
  of the 3-D path (all threads: Open3D's own); ``Open3D cluster_dbscan, every
  point``: its DBSCAN alone on the whole sweep, ground included, with that eps
  (times only).

Quality columns: ground precision and recall against the ground classes of the
truth (road, parking, sidewalk, other-ground, lane marking, terrain); per-point
mIoU of the shipped street model on the segments of each path (the classes and
maps of ``bench_scene_labels.py``); on real_mobile, the boxed objects kept, whole
and pure (as ``bench_scan_kinds.py``).

Whole identification, streamed (the model loaded once): segment, classify every
segment with the shipped model (``identify_segments``), spread the classes to the
points and write the labelled LAZ, each stage timed; sweeps a second against the
10 a second of the sensors.

The published anchor: Bogoslavskyi & Stachniss (IROS 2016), over 100 sweeps a
second for a 64-beam Velodyne on one core of a mobile CPU (C++).

    python benchmarks/bench_sweeps.py                 # about 15 minutes
    python benchmarks/bench_sweeps.py --quick         # 2 sweeps a source

Results: ``benchmarks/results/sweeps.{json,txt}``.
"""

import argparse
import csv
import os
import sys
import tempfile
import time
from itertools import pairwise
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bench_scan_kinds import objects_score, real_mobile  # noqa: E402
from measure import best_of, import_open3d, provenance, write_results  # noqa: E402

SHARED = HERE.parent.parent / "shared" / "data"
LABELLED = Path(os.environ.get("SKPCD_REAL_LABELLED_DIR", SHARED / "real_labelled"))
MAPS = HERE / "maps"
GROUND_CODES = (40, 44, 48, 49, 60, 72)
SOURCES = {
    "semantickitti": ("SemanticKITTI (HDL-64E)", "street_classes.csv"),
    "nuscenes": ("nuScenes (HDL-32E)", "street_classes_nuscenes.csv"),
    "pandaset": ("PandaSet (Pandar64)", "street_classes.csv"),
}
# PandaSet's files of real_labelled put the origin at the lidar pose, 0.2 to
# 0.35 m above the road; its README puts the optical centre about 2 m above it.
PANDASET_SENSOR = (0.0, 0.0, 1.7)
SENSOR_RATE = 10.0
RANGE_JOINED = "range image, theta 3, gap 2"
RANGE_STRUCTURES = "range image, structures"
OPEN3D_ALL = "Open3D cluster_dbscan, every point"
METHODS = ["range image", "range image, sensor given", RANGE_JOINED,
           RANGE_STRUCTURES, "3-D path (1 thread)", "3-D path (all threads)",
           "Open3D", OPEN3D_ALL]  # fmt: skip
# Objects of real_labelled (SemanticKITTI's instances) scored when this big.
MIN_OBJECT_POINTS = 50


def labelled_sweeps(quick):
    """``(source, name, path)`` of the core sweeps of real_labelled."""
    with open(LABELLED / "scans.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["core"] == "1"]
    out = []
    for source in SOURCES:
        mine = [r for r in rows if r["kind"] == source]
        for r in mine[:2] if quick else mine:
            out.append((source, Path(r["file"]).stem, LABELLED / "scans" / r["file"]))
    return out


def instance_objects(instance, min_points=MIN_OBJECT_POINTS):
    """The labelled objects of a sweep (index arrays), from its instance ids
    (0: none), those of at least ``min_points`` points."""
    ids, inverse, counts = np.unique(instance, return_inverse=True, return_counts=True)
    order = np.argsort(inverse, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(counts)])
    return [
        order[a:b]
        for k, (a, b) in enumerate(pairwise(bounds))
        if ids[k] != 0 and counts[k] >= min_points
    ]


def open3d_segments(xyz, eps):
    """Open3D's plane as ground and its DBSCAN on the rest: labels, ground."""
    o3d = import_open3d()
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    _, inliers = pcd.segment_plane(0.2, 3, 1000)
    ground = np.zeros(len(xyz), dtype=bool)
    ground[np.asarray(inliers, dtype=np.int64)] = True
    rest = pcd.select_by_index(np.asarray(inliers), invert=True)
    lab = np.asarray(rest.cluster_dbscan(eps=eps, min_points=5))
    labels = np.full(len(xyz), -1, dtype=np.int64)
    labels[~ground] = lab
    return labels, ground


def open3d_dbscan(xyz, eps):
    """Open3D's DBSCAN on every point of the sweep, ground included (as a
    user who runs cluster_dbscan on a sweep): labels."""
    o3d = import_open3d()
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    return np.asarray(pcd.cluster_dbscan(eps=eps, min_points=5), dtype=np.int64)


def point_classes(model, xyz, seg):
    """The class name of every point under the shipped model: "ground",
    "unclassified" outside segments, else its segment's answer."""
    from skpcd.classification import identify_segments

    order = np.argsort(seg.labels, kind="stable")
    bounds = np.searchsorted(seg.labels[order], np.arange(seg.n_segments + 1))
    clouds = ((xyz[order[a:b]], {}) for a, b in pairwise(bounds))
    pred, *_ = identify_segments(model, clouds, kinds=seg.kinds)
    names = np.array([str(p) for p in pred] + ["unclassified"], dtype=object)
    out = names[seg.labels]  # -1: the last, unclassified
    out[seg.ground] = "ground"
    return out, pred


def scene_miou(truth_codes, names, class_map, classes):
    """mIoU of the per-point names against the truth under ``class_map``."""
    from skpcd.metrics import scan_scores

    codes = np.unique(truth_codes)
    lookup = class_map.names(codes, {})
    truth = np.array([lookup[int(c)] for c in codes], dtype=object)[
        np.searchsorted(codes, truth_codes)
    ]
    pred = np.array([class_map.by_name.get(n, n) for n in names], dtype=object)
    present = [c for c in classes if (truth == c).any()]
    return scan_scores(truth, pred, classes=present).miou


def ground_pr(ground, codes):
    """Ground precision and recall against the truth's ground classes."""
    valid = codes > 1
    truth = np.isin(codes, GROUND_CODES)
    hit = (ground & truth & valid).sum()
    return (
        float(hit / max((ground & valid).sum(), 1)),
        float(hit / max((truth & valid).sum(), 1)),
    )


def identify_stream(model, path, xyz, segmenter, out_dir):
    """Seconds of each stage of the whole identification of one sweep."""
    from skpcd.classification import identify_segments
    from skpcd.io import write_labelled_scan
    from skpcd.segmentation._members import spread_to_points

    t0 = time.perf_counter()
    seg = segmenter(xyz)
    t1 = time.perf_counter()
    order = np.argsort(seg.labels, kind="stable")
    bounds = np.searchsorted(seg.labels[order], np.arange(seg.n_segments + 1))
    clouds = ((xyz[order[a:b]], {}) for a, b in pairwise(bounds))
    pred, *_ = identify_segments(model, clouds, kinds=seg.kinds)
    classes = sorted({str(p) for p in pred})
    index = {c: j for j, c in enumerate(classes)}
    seg_class = np.array([index[str(p)] for p in pred], dtype=np.int32)
    point_class = spread_to_points(
        seg.labels, seg_class, -1, np.empty(len(xyz), np.int32)
    )
    t2 = time.perf_counter()
    target = out_dir / f"{path.stem}.laz"
    target.unlink(missing_ok=True)
    write_labelled_scan(
        path, target, segment=seg.labels,
        class_index=point_class, class_names=classes, ground=seg.ground,
        keep_fields=True,
    )  # fmt: skip
    t3 = time.perf_counter()
    return {"segment": t1 - t0, "classify": t2 - t1, "write": t3 - t2}


def run(args):
    import laspy

    from skpcd.classification import load_street_model
    from skpcd.io import read_class_map
    from skpcd.segmentation import SweepSegmenter, segment_scene, segment_sweep

    model = load_street_model()
    maps = {s: read_class_map(MAPS / m) for s, (_, m) in SOURCES.items()}
    classes = {
        "semantickitti": ["ground", "building", "vegetation", "car", "person",
                          "pole_like", "traffic_sign"],
        "nuscenes": ["ground", "vegetation", "car", "person", "manmade"],
        "pandaset": ["ground", "building", "vegetation", "car", "person",
                     "traffic_sign"],
    }  # fmt: skip
    # one SweepSegmenter a sensor, as a stream of its sweeps would have (it
    # keeps the columns of the image found on the sensor's first sweep)
    per_sensor = {}

    def range_image_of(source):
        return per_sensor.setdefault(source, SweepSegmenter()).segment

    joined = {"theta": 3.0, "max_gap": 2.0}  # a smaller angle, a longer gap
    segmenters = {
        "range image": lambda xyz: SweepSegmenter().segment(xyz),
        RANGE_JOINED: lambda xyz: segment_sweep(xyz, **joined),
        RANGE_STRUCTURES: lambda xyz: segment_sweep(xyz, structures=True, n_jobs=-1),
        "3-D path (1 thread)": lambda xyz: segment_scene(xyz, n_jobs=1),
        "3-D path (all threads)": lambda xyz: segment_scene(xyz, n_jobs=-1),
    }
    rows = []
    out_dir = Path(tempfile.mkdtemp(prefix="bench_sweeps_"))
    labelled = labelled_sweeps(args.quick)
    # warm: kernels compiled or loaded, the model's first prediction made
    f = laspy.read(labelled[0][2])
    warm = np.column_stack([f.x, f.y, f.z])
    for seg in segmenters.values():
        point_classes(model, warm, seg(warm))
    open3d_segments(warm, 0.5)
    for source, name, path in labelled:
        f = laspy.read(path)
        xyz = np.column_stack([f.x, f.y, f.z])
        codes = np.asarray(f.semantic).astype(np.int64)
        objects = instance_objects(np.asarray(f.instance))
        row = {"set": "real_labelled", "source": source, "sweep": name,
               "points": len(xyz)}  # fmt: skip
        methods = {**segmenters, "range image": range_image_of(source)}
        if source == "pandaset":
            given = SweepSegmenter(sensor=PANDASET_SENSOR)
            methods["range image, sensor given"] = given.segment
        for key, func in methods.items():
            seg, secs = best_of(args.repeat, lambda: func(xyz))
            precision, recall = ground_pr(seg.ground, codes)
            names, _ = point_classes(model, xyz, seg)
            row[key] = {
                "seconds": secs, "segments": seg.n_segments,
                "ground_precision": precision, "ground_recall": recall,
                "miou": scene_miou(codes, names, maps[source], classes[source]),
                "eps": None if not np.isfinite(seg.eps) else float(seg.eps),
            }  # fmt: skip
            if objects:
                row[key].update(objects_score(seg.labels, objects))
        eps3 = row["3-D path (1 thread)"]["eps"] or 0.5
        (labels, ground), secs = best_of(
            args.repeat, lambda: open3d_segments(xyz, eps3)
        )
        precision, recall = ground_pr(ground, codes)
        row["Open3D"] = {
            "seconds": secs,
            "segments": int(labels.max()) + 1,
            "ground_precision": precision,
            "ground_recall": recall,
        }
        if objects:
            row["Open3D"].update(objects_score(labels, objects))
        labels, secs = best_of(args.repeat, lambda: open3d_dbscan(xyz, eps3))
        row[OPEN3D_ALL] = {"seconds": secs, "segments": int(labels.max()) + 1}
        row["identify, streamed"] = {
            key: identify_stream(model, path, xyz, func, out_dir)
            for key, func in (("range image", methods["range image"]),
                              ("3-D path", segmenters["3-D path (all threads)"]))
        }  # fmt: skip
        rows.append(row)
        progress(row)
    for name, xyz, objects, _ in real_mobile():
        if args.quick and len([r for r in rows if r["set"] == "real_mobile"]) >= 3:
            break
        row = {"set": "real_mobile", "source": name.split("_")[0], "sweep": name,
               "points": len(xyz)}  # fmt: skip
        methods = {**segmenters, "range image": range_image_of(row["source"])}
        for key, func in methods.items():
            seg, secs = best_of(args.repeat, lambda: func(xyz))
            row[key] = {"seconds": secs, **objects_score(seg.labels, objects)}
        eps3 = segment_scene(xyz).eps
        (labels, _), secs = best_of(args.repeat, lambda: open3d_segments(xyz, eps3))
        row["Open3D"] = {"seconds": secs, **objects_score(labels, objects)}
        rows.append(row)
        progress(row)
    for source in SOURCES:
        files = [path for s, _, path in labelled if s == source]
        for method in ("range-image --no-structures", "range-image", "dbscan"):
            rows.append(cli_stream(source, files, method, out_dir))
            progress(rows[-1])
    return rows


def progress(row):
    """One line of progress: the seconds of each method on a sweep."""
    secs = {
        k: round(v["seconds"], 4)
        for k, v in row.items()
        if isinstance(v, dict) and "seconds" in v
    }
    print(row.get("sweep", row["source"]), secs, flush=True)


def cli_stream(source, files, method, out_dir):
    """``skpcd identify`` over the sweeps of a source in one command (a new
    process: start-up, the model loaded once, every sweep written), and over
    the first sweep alone: the seconds of both and of each further sweep."""
    import subprocess

    def command(files, name):
        folder = out_dir / f"cli_{name}"
        folder.mkdir(exist_ok=True)
        for path in files:
            link = folder / path.name
            if not link.exists():
                link.symlink_to(path)
        cmd = [sys.executable, "-m", "skpcd", "identify", str(folder), "-o",
               str(out_dir / f"cli_{name}_{method.replace(' ', '')}"), "--quiet",
               "--overwrite", "--method", *method.split()]  # fmt: skip
        t = time.perf_counter()
        subprocess.run(cmd, check=True)
        return time.perf_counter() - t

    one = command(files[:1], f"{source}_one")
    every = command(files, source)
    further = (every - one) / max(len(files) - 1, 1)
    return {"set": "cli", "source": source, "method": method, "sweeps": len(files),
            "one_sweep_seconds": one, "command_seconds": every,
            "seconds": further}  # fmt: skip


def mean(rows, key, field):
    """Mean of ``row[key][field]`` over the rows that have it, a number (an
    object score is NaN on a sweep that kept none of its objects); None if
    none has."""
    values = [r[key].get(field) for r in rows if key in r]
    values = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(values)) if values else None


QUALITY = ("ground_precision", "ground_recall", "miou", "kept", "whole", "purity")


def summarize(rows):
    """The means the report and the Performance page show: per source and
    method on real_labelled, per source on real_mobile, the streamed stages
    and the commands."""
    budget = 1 / SENSOR_RATE
    out = {
        "sensor_rate": SENSOR_RATE,
        "real_labelled": {},
        "real_mobile": {},
        "streamed": {},
        "command": [
            {**r, "sweeps_per_s": 1 / r["seconds"]} for r in rows if r["set"] == "cli"
        ],
    }
    for source, (label, _) in SOURCES.items():
        mine = [
            r for r in rows if r["set"] == "real_labelled" and r["source"] == source
        ]
        if not mine:
            continue
        o3d = mean(mine, "Open3D", "seconds")
        o3d_all = mean(mine, OPEN3D_ALL, "seconds")
        out["real_labelled"][source] = {
            "sensor": label,
            "sweeps": len(mine),
            "points": float(np.mean([r["points"] for r in mine])),
            "methods": {
                m: {
                    "seconds": mean(mine, m, "seconds"),
                    "x_open3d": o3d / mean(mine, m, "seconds"),
                    "x_open3d_every_point": o3d_all / mean(mine, m, "seconds"),
                    **{k: mean(mine, m, k) for k in QUALITY},
                }
                for m in METHODS
                if any(m in r for r in mine)
            },
        }
        streamed = {}
        for m in ("range image", "3-D path"):
            stages = {
                k: float(np.mean([r["identify, streamed"][m][k] for r in mine]))
                for k in ("segment", "classify", "write")
            }
            total = sum(stages.values())
            worst = max(stages, key=stages.get)
            streamed[m] = {**stages, "total": total, "sweeps_per_s": 1 / total,
                           "held_back_by": None if total <= budget else worst,
                           "over_s": max(total - budget, 0.0)}  # fmt: skip
        out["streamed"][source] = streamed
    for source in ("kitti", "pandaset"):
        part = [r for r in rows if r["set"] == "real_mobile" and r["source"] == source]
        if part:
            out["real_mobile"][source] = {
                "sweeps": len(part),
                "methods": {
                    m: {
                        k: mean(part, m, k)
                        for k in ("seconds", "kept", "whole", "purity")
                    }
                    for m in METHODS
                    if any(m in r for r in part)
                },
            }
    return out


def _cell(value, width, digits=3):
    return f"{'-':>{width}s}" if value is None else f"{value:{width}.{digits}f}"


def text_report(summary, prov):
    budget = 1 / summary["sensor_rate"]
    lines = [
        "Single sweeps: segmentation in the range image, the 3-D path and Open3D",
        f"commit {prov['commit']}; {prov['machine']}; {prov['date']}",
        "times: warm, in one process, best of the repeats, seconds a sweep (mean);",
        "the range image runs on one thread (its kernels are sequential)",
        "anchor: Bogoslavskyi & Stachniss (IROS 2016), over 100 sweeps/s for a",
        "64-beam Velodyne on one core of a mobile CPU (C++): under 0.010 s a sweep",
        "",
        "real_labelled (per-point truth): segmentation time, ground, mIoU of the",
        "shipped model on the segments; objects (SemanticKITTI's instances of 50",
        "points or more) kept, whole, purity",
        "(xOpen3D: Open3D's time over the method's; xDBSCAN: that of Open3D's",
        "cluster_dbscan on every point)",
        f"{'source':15s} {'method':34s} {'s/sweep':>7s} {'xOpen3D':>7s} "
        f"{'xDBSCAN':>7s} {'grndP':>5s} {'grndR':>5s} {'mIoU':>5s} {'kept':>5s} "
        f"{'whole':>5s} {'pure':>5s}",
    ]
    for block in summary["real_labelled"].values():
        for m, v in block["methods"].items():
            lines.append(
                f"{block['sensor'][:15]:15s} {m:34s} {v['seconds']:7.4f} "
                f"{v['x_open3d']:7.1f} {v['x_open3d_every_point']:7.1f} "
                + " ".join(_cell(v[k], 5) for k in QUALITY)
            )
        lines.append(
            f"{'':15s} ({block['sweeps']} sweeps, {block['points']:.0f} points a sweep)"
        )
    lines += [
        "",
        "real_mobile (boxed objects): kept, whole, purity (means over the sweeps)",
        f"{'method':34s} {'s/sweep':>8s} {'kept':>6s} {'whole':>6s} {'purity':>6s}",
    ]
    for source, block in summary["real_mobile"].items():
        lines.append(f"{source} ({block['sweeps']} sweeps)")
        for m, v in block["methods"].items():
            lines.append(
                f"  {m:32s} {v['seconds']:8.4f} "
                + " ".join(_cell(v[k], 6) for k in ("kept", "whole", "purity"))
            )
    lines += [
        "",
        "whole identification, streamed (model loaded once): seconds a sweep by",
        f"stage; the sensor's rate ({summary['sensor_rate']:.0f} sweeps/s) leaves "
        f"{budget:.3f} s a sweep",
        f"{'source':15s} {'segmentation':12s} {'segment':>8s} {'classify':>8s} "
        f"{'write':>8s} {'total':>8s} {'sweeps/s':>8s}  held back by",
    ]
    for source, block in summary["streamed"].items():
        label = summary["real_labelled"][source]["sensor"]
        for m, v in block.items():
            held = v["held_back_by"]
            held = (
                "-"
                if held is None
                else (f"{held} ({v[held]:.3f} s; {v['over_s']:.3f} s over)")
            )
            lines.append(
                f"{label[:15]:15s} {m:12s} {v['segment']:8.4f} {v['classify']:8.4f} "
                f"{v['write']:8.4f} {v['total']:8.4f} {v['sweeps_per_s']:8.2f}  {held}"
            )
    if summary["command"]:
        lines += [
            "",
            "skpcd identify FOLDER -o OUT (one command: start-up and the model",
            "loaded once, then each sweep segmented, classified and written):",
            "seconds of the command on the first sweep alone, on all, and of",
            "each sweep after the first",
            f"{'source':15s} {'--method':28s} {'sweeps':>6s} {'1 sweep':>8s} "
            f"{'all':>8s} {'s/sweep':>8s} {'sweeps/s':>8s}",
        ]
        for r in summary["command"]:
            lines.append(
                f"{SOURCES[r['source']][0][:15]:15s} {r['method']:28s} "
                f"{r['sweeps']:6d} {r['one_sweep_seconds']:8.2f} "
                f"{r['command_seconds']:8.2f} {r['seconds']:8.4f} "
                f"{r['sweeps_per_s']:8.2f}"
            )
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 sweeps a source")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(HERE / "results" / "sweeps.json"))
    ap.add_argument(
        "--summarize",
        action="store_true",
        help="no run: summarize the rows of the --out file again (its commit, "
        "machine and date kept)",
    )
    args = ap.parse_args(argv)
    if args.summarize:
        import json

        old = json.loads(Path(args.out).read_text())
        rows = old["rows"]
        prov = {k: old[k] for k in ("commit", "machine", "date")}
    else:
        rows = run(args)
        prov = provenance()
    summary = summarize(rows)
    text = text_report(summary, prov)
    write_results(Path(args.out), {**prov, "summary": summary, "rows": rows}, text)
    print(text)


if __name__ == "__main__":
    main()
