"""Thread scaling of every parallel stage: one against two threads, and where
more cores would stop helping.

Each stage runs in a fresh process per thread count (``--worker SPEC``),
best of ``--repeat`` runs after a warm-up call on the same data (kernels
compiled and caches filled, so only the work is timed). The one-thread run
is also profiled: :func:`skpcd.utils._parallel.thread_profile` adds up the
wall time of the *parallel sections* (every ``parallel_rows`` kernel, the
parallel radix sort, DBSCAN's union of core points), and the rest of the
call is its *serial part* (Python, NumPy steps, allocation and page faults
of the outputs, the merge of the threads' results). Amdahl's law on that
measured profile, ``T(p) = serial + parallel / p``, projects the speed-up on
8, 16 and 64 cores; the measured two-thread speed-up against the projected
one shows what the second core loses beyond the serial part (memory
bandwidth, page faults, load imbalance).

Stages and data (the DALES objects: 399 real segmented objects, 882,733
points; the scene: those objects on the synthetic terrain of
:func:`skpcd.segmentation.make_scene`):

- ``search``: the k = 10 nearest neighbours of every point of the objects;
- ``normals``: PCL's normals from those neighbourhoods;
- ``pfh``, ``fpfh``, ``improved``: ``PFHTransformer``, ``FPFHTransformer``,
  ``ImprovedPFHTransformer`` (k = 10) on the list of objects, end to end;
- ``sampling``: ``GridSampler(voxel_size=0.1)`` on the objects concatenated
  and tiled three times (2.65 M points, one cloud);
- ``dbscan``: ``grid_dbscan`` (eps 1.2 m, min_samples 5) of the scene's
  points above the ground (the scene's own truth);
- ``ground``: ``GroundFilter(method="smrf")`` on four copies of the scene
  side by side (9.3 M points); the cloth
  simulation (the default ``method="csf"``) runs the reference CSF package
  on one thread on purpose (its results change with its OpenMP threads) and
  is not listed.

Usage::

    python benchmarks/bench_threads.py --out benchmarks/results/threads.json
    python benchmarks/bench_threads.py --stages search,pfh --repeat 2
"""

import argparse
import datetime
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
STAGES = (
    "search",
    "normals",
    "pfh",
    "fpfh",
    "improved",
    "sampling",
    "dbscan",
    "ground",
)
TARGET = 1.8
CORES = (8, 16, 64)
K = 10


def dales():
    from skpcd.datasets import load_dales_objects

    folder = os.environ.get(
        "SKPCD_DALES_DIR", str(ROOT.parents[1] / "shared" / "data" / "dales_objects")
    )
    X, _ = load_dales_objects(folder, return_X_y=True)
    return [np.ascontiguousarray(c[:, :3], dtype=np.float64) for c in X]


def _packed(clouds):
    offsets = np.zeros(len(clouds) + 1, dtype=np.int64)
    np.cumsum([len(c) for c in clouds], out=offsets[1:])
    return np.vstack(clouds), offsets


def _scene(clouds):
    from skpcd.segmentation import make_scene

    return make_scene(clouds, random_state=0)


def _stage(name, threads):
    """The call to time (a function of no argument) for ``name``."""
    clouds = dales()
    if name in ("search", "normals"):
        from skpcd.neighbors._neighbors import search_packed
        from skpcd.preprocessing._normals import normals_f32

        xyz, offsets = _packed(clouds)

        def search():
            return search_packed(
                xyz, offsets, n_neighbors=K, n_threads=threads, with_sqdist=False
            )

        if name == "search":
            return search
        nb = search()
        p = xyz.astype(np.float32)
        return lambda: normals_f32(p, nb, np.zeros(3), threads)
    if name in ("pfh", "fpfh", "improved"):
        from skpcd.features import (
            FPFHTransformer,
            ImprovedPFHTransformer,
            PFHTransformer,
        )

        cls = {
            "pfh": PFHTransformer,
            "fpfh": FPFHTransformer,
            "improved": ImprovedPFHTransformer,
        }[name]
        undefined = "nan" if name == "improved" else "keep"
        est = cls(n_neighbors=K, n_jobs=threads, undefined=undefined)
        return lambda: est.fit_transform(clouds)
    if name == "sampling":
        from skpcd.preprocessing import GridSampler

        xyz, _ = _packed(clouds)
        big = np.vstack([xyz + np.array([600.0 * t, 0.0, 0.0]) for t in range(3)])
        est = GridSampler(voxel_size=0.1, n_jobs=threads)
        return lambda: est.fit_transform([big])
    points, truth = _scene(clouds)
    if name == "dbscan":
        from skpcd.segmentation._clusters import grid_dbscan

        above = np.ascontiguousarray(points[truth >= 0])
        return lambda: grid_dbscan(above, 1.2, 5, n_jobs=threads)
    if name == "ground":
        from skpcd.segmentation import GroundFilter

        # four copies side by side (9 M points): one scene is too quick
        # (0.2 s) for the threads' start-up not to count
        step = np.ptp(points[:, 0]) + 10.0
        scene = np.vstack([points + np.array([step * t, 0.0, 0.0]) for t in range(4)])
        est = GroundFilter(method="smrf", n_jobs=threads)
        return lambda: est.fit_predict(scene)
    raise ValueError(name)


def _worker(spec):
    from skpcd.utils._parallel import thread_profile

    fn = _stage(spec["stage"], spec["threads"])
    fn()  # warm-up: compiled kernels, filled caches
    runs = []
    for _ in range(spec["repeat"]):
        w0 = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - w0)
    res = {"runs": runs, "best": min(runs)}
    if spec["threads"] == 1:
        # the profile of the fastest kind of run: best total, its sections
        best = None
        for _ in range(spec["repeat"]):
            with thread_profile() as sections:
                w0 = time.perf_counter()
                fn()
                total = time.perf_counter() - w0
            if best is None or total < best[0]:
                best = (total, dict(sections))
        res["profile_total"], res["sections"] = best
    print(json.dumps(res))


def _run(spec):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", json.dumps(spec)]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        return {"error": p.stderr.strip().splitlines()[-1] if p.stderr else "failed"}
    return json.loads(p.stdout.strip().splitlines()[-1])


def _project(total, parallel, p):
    serial = max(total - parallel, 0.0)
    return total / (serial + parallel / p)


def _report(R):
    lines = [
        "Thread scaling of skpcd's parallel stages (benchmarks/bench_threads.py)",
        f"date     {R['date']}; commit {R['commit']}",
        f"machine  {R['machine']}; load average {R['load_start']} at start, "
        f"{R['load_end']} at end",
        "data     DALES objects (399, 882,733 points); sampling: them tiled 3x as "
        "one cloud (2.65 M); dbscan: them on make_scene's terrain (2.3 M), "
        "above the ground; ground: four such scenes (9.3 M)",
        f"times    best of {R['repeat']} after a warm-up, a fresh process per "
        "stage and thread count",
        "",
        f"{'stage':10s} {'1 thread':>9s} {'2 threads':>9s} {'speed-up':>8s} "
        f"{'target':>7s} {'serial':>7s} {'Amdahl 2':>8s} "
        + " ".join(f"{'x' + str(c):>6s}" for c in CORES)
        + "  serial part; largest parallel sections",
    ]
    for name, r in R["stages"].items():
        if "error" in r.get("1", {}) or "error" in r.get("2", {}):
            err = r.get("1", {}).get("error") or r.get("2", {}).get("error")
            lines.append(f"{name:10s} failed: {err}")
            continue
        t1, t2 = r["1"]["best"], r["2"]["best"]
        total = r["1"]["profile_total"]
        sections = r["1"]["sections"]
        parallel = min(sum(sections.values()), total)
        serial = total - parallel
        top = sorted(sections.items(), key=lambda kv: -kv[1])[:3]
        proj = [_project(total, parallel, c) for c in CORES]
        lines.append(
            f"{name:10s} {t1:8.3f}s {t2:8.3f}s {t1 / t2:7.2f}x "
            f"{'met' if t1 / t2 >= TARGET else 'NOT met':>7s} "
            f"{serial / total:6.0%} {_project(total, parallel, 2):7.2f}x "
            + " ".join(f"{x:5.1f}x" for x in proj)
            + f"  serial {serial:.3f} s; "
            + ", ".join(f"{k} {v:.3f}" for k, v in top)
        )
    lines += [
        "",
        "speed-up: 1-thread best / 2-thread best; target >= "
        f"{TARGET}x on an idle machine. serial: the share of the 1-thread time "
        "outside the parallel sections.",
        "Amdahl p: T(1) / (serial + parallel / p) from the 1-thread profile: "
        "what p cores give if the parallel sections scale perfectly; the "
        "measured 2-thread speed-up below 'Amdahl 2' is lost to memory "
        "bandwidth, page faults and load imbalance, which more cores would "
        "also meet.",
    ]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stages", default=",".join(STAGES))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", help="JSON results (and .txt beside)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        _worker(json.loads(a.worker))
        return 0
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    ).stdout.strip()
    R = {
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit,
        "machine": f"{os.cpu_count()} cores",
        "load_start": [round(x, 2) for x in os.getloadavg()],
        "repeat": a.repeat,
        "stages": {},
    }
    for name in a.stages.split(","):
        R["stages"][name] = {}
        for threads in (1, 2):
            spec = {"stage": name, "threads": threads, "repeat": a.repeat}
            R["stages"][name][str(threads)] = res = _run(spec)
            shown = res.get("best", res.get("error"))
            print(f"{name} x{threads}: {shown}", file=sys.stderr, flush=True)
    R["load_end"] = [round(x, 2) for x in os.getloadavg()]
    text = _report(R)
    print(text)
    if a.out:
        Path(a.out).write_text(json.dumps(R, indent=1))
        Path(a.out).with_suffix(".txt").write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
