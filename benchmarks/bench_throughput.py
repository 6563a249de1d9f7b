"""Whole-job throughput: identifying segments and ``skpcd segment`` on a scan,
against the reference pipelines (issue 20).

Two parts (``--parts``), each measurement in a fresh process, the tools
interleaved round by round, best of ``--repeat`` rounds.

``identify``: segments per second of the default identification pipeline
(:func:`~skpcd.classification.make_default_pipeline`: shape features,
vertical profile and mean PFH k=10, random forest of 300 trees) and of the
25-global-feature random-forest baseline of
``bench_street_identification.py`` (its ``baseline_features`` and its
300-tree forest, imported from there), ``fit`` on all the segments of a data
set and then ``predict`` on the same segments (a throughput measure, not an
accuracy one), with ``n_jobs`` 2 and 1. Data: the 399 DALES objects
(``$SKPCD_DALES_DIR``) and the 400 simulated mobile street objects of
``bench_street_identification.py``
(``make_street_objects(40, scanner="mobile", random_state=0)``, cached in
``/tmp/skpcd_street_cache``). Each worker loads the data, fits and predicts
every tenth segment once (numba kernels loaded from the cache, untimed),
then times ``fit`` and ``predict``; the best fit and the best predict time of
the rounds are kept, each on its own.

``segment``: the whole job from a LAS file to written outputs, timed from
the start of the process to its end (interpreter start, imports, reading,
segmentation, writing), peak RSS of the process (``ru_maxrss`` of the child
from ``os.wait4``; the small driver's own peak, recorded, is its floor).
The scan: the first n points (scan order: a shorter street) of the
full-density 150 m mobile scan of ``bench_ground.py`` (``BIG``), which
``bench_street_segmentation.py`` times its stages on, written as LAS by
skpcd (9,759,047 points with the simulator of the first rows; 10 M or more
since, so the "10 M" row is 10 M points from 2026-12-03 on). The "50 M" row
is the first 50 M points of a 775 m street simulated the same way. Six
jobs:

- ``skpcd``: ``python -m skpcd segment SCAN -o FOLDER`` with the defaults
  (CSF, structures, DBSCAN with automatic eps, segments of 50 points or
  more, one PLY file per segment plus ``segments.csv``; all cores);
- ``skpcd --no-structures``: the same without facades, wires and trunk
  splitting: ground and DBSCAN, the job of the references;
- ``skpcd --tile-size 100``: the defaults on 100 m tiles (the scan spilled
  to temporary files and segmented tile by tile: memory bounded by the
  tile);
- ``skpcd identify``: ``python -m skpcd identify SCAN -o scan.las``: the
  defaults' segmentation, every segment classified by the shipped street
  model, and a LAS copy of the scan with each point's segment and class;
- ``csf+sklearn``: laspy reads the file; the ``CSF`` package with the
  parameters of ``GROUND_PRESETS["csf"]`` (1 m cloth, rigidness 3, slope
  smoothing, 0.3 m threshold, 500 iterations, time step 0.65; its own
  OpenMP threads); ``sklearn.cluster.DBSCAN(eps, min_samples=5,
  n_jobs=2)`` on the non-ground points with the eps skpcd estimated on that
  scan (read from its output); per-point labels written as ``.npy``;
- ``csf+open3d``: the same with Open3D's ``cluster_dbscan(eps, 5)``.

The references do less than skpcd's defaults (no facades, wires or trunk
splitting) and than either skpcd job (no size filter, one label file instead
of a file per segment). Every job
runs under an address-space cap (``--cap-gb``, 8 GB, ``RLIMIT_AS``) and a
timeout (``--timeout``, 20 minutes); a failure is reported as such and not
repeated in later rounds.

    python benchmarks/bench_throughput.py                          # both parts
    python benchmarks/bench_throughput.py --parts segment --sizes 5 --repeat 1 \\
        --merge benchmarks/results/throughput.json
    python benchmarks/bench_throughput.py --quick --out /tmp/throughput.json

Results: ``benchmarks/results/throughput.{json,txt}`` with, for each run, the
date, the load average at its start and end, the commit and the machine.
"""

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from measure import commit, machine

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

PIPELINES = ("default", "baseline25")
DATASETS = ("dales", "street")
TOOLS = (
    "skpcd",
    "skpcd --no-structures",
    "skpcd --tile-size 100",
    "skpcd identify",
    "csf+sklearn",
    "csf+open3d",
)
# the skpcd jobs: command and options
SKPCD = {
    "skpcd": ["segment"],
    "skpcd --no-structures": ["segment", "--no-structures"],
    "skpcd --tile-size 100": ["segment", "--tile-size", "100"],
    "skpcd identify": ["identify"],
}
STREET_OBJECTS = ("mobile", 40, 0)  # scanner, per class, seed (as in identification)
MIN_SAMPLES = 5  # skpcd's default, used by the references
WARM_SIZE = 0.1  # millions of points of the scan that warms the numba cache
LONG_STREET = 775.0  # metres of the street of the scans beyond 9.76 M points


def log(*a):
    print(time.strftime("%H:%M:%S"), *a, flush=True)


# --- identify -----------------------------------------------------------------


def load(dataset, quick=False):
    from bench_street_identification import (
        DEFAULT_CACHE,
        DEFAULT_DATA,
        load_dales,
        load_street,
    )

    if dataset == "dales":
        clouds, y = load_dales(DEFAULT_DATA)
    else:
        scanner, n, seed = STREET_OBJECTS
        clouds, y = load_street(DEFAULT_CACHE, scanner, 4 if quick else n, seed)
    return clouds, y


def make_pipeline(name, n_jobs):
    """The default pipeline, or the 25-feature baseline of the identification
    benchmark as a pipeline on the clouds."""
    from bench_street_identification import baseline_features, make_classifier
    from sklearn.pipeline import make_pipeline as pipe
    from sklearn.preprocessing import FunctionTransformer

    from skpcd.classification import make_default_pipeline

    if name == "default":
        return make_default_pipeline(n_jobs=n_jobs)
    return pipe(
        FunctionTransformer(baseline_features), make_classifier("RF300", None, n_jobs)
    )


def identify_worker(pipeline, dataset, n_jobs, quick):
    import numpy as np
    from measure import maxrss_mb, reset_peak

    clouds, y = load(dataset, quick)
    make_pipeline(pipeline, n_jobs).fit(clouds[::10], y[::10]).predict(clouds[::10])
    base = reset_peak()
    model = make_pipeline(pipeline, n_jobs)
    t = time.perf_counter()
    model.fit(clouds, y)
    fit = time.perf_counter() - t
    t = time.perf_counter()
    pred = model.predict(clouds)
    predict = time.perf_counter() - t
    print(
        json.dumps(
            {
                "fit_seconds": fit,
                "predict_seconds": predict,
                "segments": len(clouds),
                "points": int(sum(len(c) for c in clouds)),
                "train_accuracy": float(np.mean(np.asarray(pred) == y)),
                "peak_mb": maxrss_mb() - base,
            }
        )
    )


def identify(repeat, quick):
    runs = []
    for r in range(repeat):
        for dataset in DATASETS:
            for n_jobs in (2, 1):
                for pipeline in PIPELINES:
                    cmd = [sys.executable, __file__, "--identify-worker"]
                    cmd += [pipeline, dataset, str(n_jobs)] + ["--quick"] * quick
                    res = subprocess.run(cmd, capture_output=True, text=True)
                    key = {"dataset": dataset, "pipeline": pipeline, "n_jobs": n_jobs}
                    if res.returncode:
                        row = {**key, "error": res.stderr.strip()[-300:]}
                    else:
                        row = {**key, **json.loads(res.stdout.strip().splitlines()[-1])}
                    row["round"] = r
                    log(row)
                    runs.append(row)
    best = []
    for dataset in DATASETS:
        for n_jobs in (2, 1):
            for pipeline in PIPELINES:
                mine = [
                    r
                    for r in runs
                    if (r["dataset"], r["pipeline"], r["n_jobs"])
                    == (dataset, pipeline, n_jobs)
                    and "error" not in r
                ]
                if not mine:
                    continue
                fit = min(r["fit_seconds"] for r in mine)
                predict = min(r["predict_seconds"] for r in mine)
                n = mine[0]["segments"]
                best.append(
                    {
                        "dataset": dataset,
                        "pipeline": pipeline,
                        "n_jobs": n_jobs,
                        "segments": n,
                        "points": mine[0]["points"],
                        "fit_seconds": fit,
                        "predict_seconds": predict,
                        "fit_segments_per_s": n / fit,
                        "predict_segments_per_s": n / predict,
                        "peak_mb": max(r["peak_mb"] for r in mine),
                        "rounds": len(mine),
                    }
                )
    return {"best": best, "runs": runs}


# --- segment ------------------------------------------------------------------


def make_scans(folder, sizes):
    """The LAS files of the first n points of the big mobile scan (subprocess:
    keeps the driver's peak RSS, the floor of every child's, small); a size
    beyond its 9.76 M points is the first n points of a longer street
    simulated the same way (775 m: about 50 M points)."""
    import numpy as np
    from bench_ground import BIG, big_kw

    from skpcd.datasets import make_street_scene
    from skpcd.io import write_point_cloud

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    todo = [s for s in sizes if not (folder / f"scan_{s:g}M.las").exists()]
    for length in (BIG["length"], LONG_STREET):
        # BIG holds 9,759,047 points (the "10 M" scan); the longer street the
        # larger sizes
        mine = [s for s in todo if (s <= 10) == (length == BIG["length"])]
        if not mine:
            continue
        log(f"simulating a {length:g} m street scan...")
        points = make_street_scene(length, scanner="mobile", **big_kw()).points
        for s in mine:
            n = min(int(s * 1_000_000), len(points))
            scan = folder / f"scan_{s:g}M.las"
            write_point_cloud(scan, np.ascontiguousarray(points[:n]))
            log(f"{scan.name}: {n} points")
        del points


def reference_worker(tool, scan, out, eps):
    """CSF + a DBSCAN from a LAS file to a label file, as a user would write it."""
    import CSF
    import laspy
    import numpy as np

    from skpcd.segmentation import GROUND_PRESETS

    stages = {}
    t = time.perf_counter()
    las = laspy.read(scan)
    xyz = np.column_stack([las.x, las.y, las.z]).astype(np.float64)
    del las
    stages["read"] = time.perf_counter() - t

    t = time.perf_counter()
    preset = GROUND_PRESETS["csf"]
    csf = CSF.CSF()
    csf.params.cloth_resolution = preset["cell"]
    csf.params.class_threshold = preset["threshold"]
    csf.params.rigidness = preset["rigidness"]
    csf.params.bSloopSmooth = preset["slope_smooth"]
    csf.params.interations = 500  # GroundFilter's default iterations
    csf.params.time_step = 0.65  # and time step
    csf.setPointCloud(xyz)
    ground, rest = CSF.VecInt(), CSF.VecInt()
    csf.do_filtering(ground, rest, False)
    idx = np.fromiter(rest, dtype=np.int64, count=rest.size())
    del ground, rest, csf
    pts = np.ascontiguousarray(xyz[idx])
    stages["csf"] = time.perf_counter() - t

    t = time.perf_counter()
    if tool == "csf+sklearn":
        from sklearn.cluster import DBSCAN

        lab = DBSCAN(eps=eps, min_samples=MIN_SAMPLES, n_jobs=2).fit(pts).labels_
    else:
        from measure import import_open3d

        o3d = import_open3d()
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        lab = np.asarray(pc.cluster_dbscan(eps, MIN_SAMPLES, print_progress=False))
    stages["cluster"] = time.perf_counter() - t

    t = time.perf_counter()
    labels = np.full(len(xyz), -1, dtype=np.int64)
    labels[idx] = lab
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "labels.npy", labels)
    stages["write"] = time.perf_counter() - t
    info = {"stages": stages, "non_ground": len(idx), "clusters": int(lab.max()) + 1}
    (out / "stages.json").write_text(json.dumps(info))


def measure(cmd, logfile, cap_gb, timeout):
    """Wall time and peak RSS of ``cmd`` run under an address-space cap."""
    lim = str(int(cap_gb * 2**30))
    capped = [
        sys.executable,
        "-S",
        "-c",
        "import os, resource, sys; lim = int(sys.argv[1]); "
        "resource.setrlimit(resource.RLIMIT_AS, (lim, lim)); "
        "os.execv(sys.argv[2], sys.argv[2:])",
        lim,
        *cmd,
    ]
    with open(logfile, "w") as f:
        t = time.perf_counter()
        proc = subprocess.Popen(capped, stdout=f, stderr=subprocess.STDOUT)
        timed_out = False
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t > timeout:
                proc.kill()
                pid, status, usage = os.wait4(proc.pid, 0)
                timed_out = True
                break
            time.sleep(0.05)
        seconds = time.perf_counter() - t
    proc.returncode = os.waitstatus_to_exitcode(status)
    out = {"seconds": seconds, "peak_mb": usage.ru_maxrss / 1024, "rc": proc.returncode}
    text = Path(logfile).read_text(errors="replace")
    if timed_out:
        out["error"] = f"timeout ({timeout / 60:.0f} min)"
    elif proc.returncode:
        lines = [s for s in text.strip().splitlines() if s.strip()]
        out["error"] = lines[-1][-200:] if lines else f"exit code {proc.returncode}"
    return out, text


def segment(sizes, repeat, scans, cap_gb, timeout, tools=TOOLS):
    make = [sys.executable, __file__, "--make-scans", str(scans)]
    subprocess.run([*make, *map(str, sizes), str(WARM_SIZE)], check=True)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # warm the numba cache of this checkout (not timed)
        warm = scans / f"scan_{WARM_SIZE:g}M.las"
        subprocess.run(
            [sys.executable, "-m", "skpcd", "segment", str(warm), "-o", str(tmp / "w")],
            check=True,
            capture_output=True,
        )
        shutil.rmtree(tmp / "w")
        for size in sizes:
            scan = scans / f"scan_{size:g}M.las"
            eps, failed = None, set()
            for r in range(repeat):
                for tool in tools:
                    if tool in failed:
                        continue
                    out = tmp / "out"
                    if tool in SKPCD:
                        command, *options = SKPCD[tool]
                        target = out
                        if command == "identify":  # a labelled copy of the scan
                            out.mkdir()
                            target = out / "identified.las"
                        cmd = [sys.executable, "-m", "skpcd", command, str(scan)]
                        cmd += ["-o", str(target), *options]
                    else:
                        if eps is None:
                            eps = skpcd_eps(scans, scan, tmp)
                        cmd = [sys.executable, __file__, "--reference-worker", tool]
                        cmd += [str(scan), str(out), repr(eps)]
                    row, text = measure(cmd, tmp / "log.txt", cap_gb, timeout)
                    row.update(tool=tool, size=size, round=r)
                    if "error" in row:
                        failed.add(tool)
                    elif tool in SKPCD:
                        row.update(parse_skpcd(text))
                        eps = row["eps"]
                    else:
                        row.update(json.loads((out / "stages.json").read_text()))
                        row["eps"] = eps
                    if "error" not in row:
                        row["points"] = n_points(scan)
                    row["load"] = os.getloadavg()[0]
                    log(row)
                    runs.append(row)
                    shutil.rmtree(out, ignore_errors=True)
    return summarise_segment(runs)


def n_points(scan):
    import laspy

    with laspy.open(scan) as f:
        return int(f.header.point_count)


def parse_skpcd(text):
    m = re.search(r"segments\s+(\d+) \(\w+, eps ([\d.]+)\).*\(([\d.]+) s\)", text)
    return {
        "segments": int(m.group(1)),
        "eps": float(m.group(2)),
        "segment_scene_seconds": float(m.group(3)),
    }


def skpcd_eps(scans, scan, tmp):
    """skpcd's eps of a scan when the skpcd job did not run in this round."""
    cmd = [sys.executable, "-m", "skpcd", "segment", str(scan), "-o", str(tmp / "e")]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    shutil.rmtree(tmp / "e")
    return parse_skpcd(res.stdout)["eps"]


def summarise_segment(runs):
    best = []
    for size in sorted({r["size"] for r in runs}):
        for tool in TOOLS:
            mine = [r for r in runs if r["size"] == size and r["tool"] == tool]
            if not mine:
                continue
            ok = [r for r in mine if "error" not in r]
            if not ok:
                best.append(
                    {
                        "tool": tool,
                        "size": size,
                        "error": mine[0]["error"],
                        "seconds": mine[0]["seconds"],
                        "peak_mb": mine[0]["peak_mb"],
                    }
                )
                continue
            b = min(ok, key=lambda r: r["seconds"])
            row = {k: v for k, v in b.items() if k not in ("round", "rc", "load")}
            row["points_per_s"] = b["points"] / b["seconds"]
            row["peak_mb_max"] = max(r["peak_mb"] for r in ok)
            row["rounds"] = len(ok)
            best.append(row)
    return {"best": best, "runs": runs}


# --- report -------------------------------------------------------------------


def write(results, out):
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(results, indent=1))
    lines = ["skpcd whole-job throughput (benchmarks/bench_throughput.py)"]
    for run in results["runs"]:
        lines.append(
            f"  {run['part']}: {run['date']}, load {run['load_start']} -> "
            f"{run['load_end']}, commit {run['commit']}, {run['command']}"
        )
    lines.append(f"  machine: {results['machine']}")
    if "identify" in results:
        idf = results["identify"]
        lines += [
            "",
            "identify: fit on all segments, then predict on the same segments; "
            "best of the rounds (fit and predict each), fresh process each; "
            "seg/s = segments per second; peak MB: VmHWM above the process after "
            "loading the data and a warm-up fit",
            f"{'data':<8}{'pipeline':<12}{'n_jobs':>7}{'segments':>9}{'points':>10}"
            f"{'fit s':>8}{'fit seg/s':>10}{'pred s':>8}{'pred seg/s':>11}"
            f"{'peak MB':>8}",
        ]
        for r in idf["best"]:
            lines.append(
                f"{r['dataset']:<8}{r['pipeline']:<12}{r['n_jobs']:>7}"
                f"{r['segments']:>9}{r['points']:>10}{r['fit_seconds']:>8.2f}"
                f"{r['fit_segments_per_s']:>10.1f}{r['predict_seconds']:>8.2f}"
                f"{r['predict_segments_per_s']:>11.1f}{r['peak_mb']:>8.0f}"
            )
        lines.append(
            "baseline25 / default time ratios (how much faster the baseline is):"
        )
        for d in DATASETS:
            for j in (2, 1):
                rows = {
                    r["pipeline"]: r
                    for r in idf["best"]
                    if r["dataset"] == d and r["n_jobs"] == j
                }
                if len(rows) == 2:
                    a, b = rows["default"], rows["baseline25"]
                    lines.append(
                        f"  {d} n_jobs={j}: fit "
                        f"{a['fit_seconds'] / b['fit_seconds']:.1f}x, predict "
                        f"{a['predict_seconds'] / b['predict_seconds']:.1f}x"
                    )
    if "segment" in results:
        seg = results["segment"]
        lines += [
            "",
            "segment: the whole job from a LAS file to its outputs in a fresh "
            "process (wall time from start to exit), peak RSS of the process "
            f"(ru_maxrss; the driver's floor {results.get('driver_peak_mb', 0):.0f} "
            f"MB), cap {results.get('cap_gb')} GB; best of the rounds",
            f"{'size':>5}{'points':>10}  {'job':<22}{'seconds':>8}{'Mpts/s':>8}"
            f"{'peak MB':>8}{'B/pt':>6}{'eps':>7}  stages (s) / error",
        ]
        for r in seg["best"]:
            head = f"{r['size']:>4g}M{r.get('points', 0):>10}  {r['tool']:<22}"
            if "error" in r:
                lines.append(
                    f"{head}{r['seconds']:>8.1f}{'-':>8}{r['peak_mb']:>8.0f}{'':>13}"
                    f"  FAILED: {r['error']}"
                )
                continue
            if r["tool"] in SKPCD:
                extra = f"segment_scene {r['segment_scene_seconds']:.1f}, "
                extra += f"{r['segments']} segments"
            else:
                extra = ", ".join(f"{k} {v:.1f}" for k, v in r["stages"].items())
                extra += f", {r['clusters']} clusters"
            lines.append(
                f"{head}{r['seconds']:>8.1f}{r['points_per_s'] / 1e6:>8.3f}"
                f"{r['peak_mb']:>8.0f}{r['peak_mb'] * 2**20 / r['points']:>6.0f}"
                f"{r['eps']:>7.3f}  {extra}"
            )
        lines.append(
            "reference / skpcd ratios (time, peak memory; above 1: skpcd faster, "
            "smaller), against skpcd's defaults and against --no-structures (the "
            "same job as the references)"
        )
        for size in sorted({r["size"] for r in seg["best"]}):
            rows = {r["tool"]: r for r in seg["best"] if r["size"] == size}
            for base in SKPCD:
                sk = rows.get(base)
                if not sk or "error" in sk:
                    continue
                parts = []
                for tool in ("csf+sklearn", "csf+open3d"):
                    r = rows.get(tool)
                    if r is None:
                        continue
                    if "error" in r:
                        parts.append(f"{tool} failed")
                    else:
                        parts.append(
                            f"{tool} {r['seconds'] / sk['seconds']:.2f}x, "
                            f"{r['peak_mb'] / sk['peak_mb']:.2f}x"
                        )
                lines.append(f"  {size:g} M, vs {base}: " + "; ".join(parts))
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def merge(old, new):
    """``new`` with the rows of ``old`` it did not rerun."""
    out = dict(old)
    out["runs"] = old.get("runs", []) + new["runs"]
    for key in ("machine", "cap_gb", "driver_peak_mb"):
        out[key] = new.get(key, old.get(key))
    if "identify" in new:
        out["identify"] = new["identify"]
    if "segment" in new:
        done = {(r["size"], r["tool"]) for r in new["segment"]["best"]}
        keep = [
            r for r in old.get("segment", {}).get("best", [])
            if (r["size"], r["tool"]) not in done
        ]  # fmt: skip
        runs = [
            r for r in old.get("segment", {}).get("runs", [])
            if (r["size"], r["tool"]) not in done
        ]  # fmt: skip
        out["segment"] = {
            "best": sorted(
                keep + new["segment"]["best"],
                key=lambda r: (r["size"], TOOLS.index(r["tool"])),
            ),
            "runs": runs + new["segment"]["runs"],
        }
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--parts", nargs="*", default=["identify", "segment"])
    p.add_argument("--sizes", type=float, nargs="*", default=[1, 5, 10])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--tools", nargs="*", default=list(TOOLS), choices=TOOLS)
    p.add_argument("--cap-gb", type=float, default=8.0)
    p.add_argument("--timeout", type=float, default=1200.0)
    p.add_argument(
        "--scans", type=Path, default=Path(tempfile.gettempdir()) / "skpcd_scans"
    )
    p.add_argument("--quick", action="store_true", help="0.2 M points, 40 objects")
    p.add_argument("--out", type=Path, default=HERE / "results" / "throughput.json")
    p.add_argument("--merge", type=Path, help="keep the rows of this JSON not rerun")
    p.add_argument("--identify-worker", nargs=3, help=argparse.SUPPRESS)
    p.add_argument("--reference-worker", nargs=4, help=argparse.SUPPRESS)
    p.add_argument("--make-scans", nargs="+", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.identify_worker:
        pipeline, dataset, n_jobs = args.identify_worker
        identify_worker(pipeline, dataset, int(n_jobs), args.quick)
        return
    if args.reference_worker:
        tool, scan, out, eps = args.reference_worker
        reference_worker(tool, scan, out, float(eps))
        return
    if args.make_scans:
        make_scans(args.make_scans[0], [float(s) for s in args.make_scans[1:]])
        return
    sizes = [0.2] if args.quick else args.sizes
    results = {"machine": machine(), "runs": [], "cap_gb": args.cap_gb}
    for part in args.parts:
        run = {
            "part": part,
            "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
            "load_start": [round(x, 2) for x in os.getloadavg()],
            "commit": commit(),
            "command": " ".join(["bench_throughput.py", *sys.argv[1:]]),
        }
        if part == "identify":
            results["identify"] = identify(args.repeat, args.quick)
        else:
            results["segment"] = segment(
                sizes, args.repeat, args.scans, args.cap_gb, args.timeout, args.tools
            )
            results["driver_peak_mb"] = (
                resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            )
        run["load_end"] = [round(x, 2) for x in os.getloadavg()]
        results["runs"].append(run)
    if args.merge and args.merge.exists():
        results = merge(json.loads(args.merge.read_text()), results)
    write(results, args.out)


if __name__ == "__main__":
    main()
