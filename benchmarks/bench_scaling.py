"""Scaling out: descriptors of 100 000 segments and a tiled scene of 50 M points,
plain local against a Dask ``LocalCluster`` of 1 and 2 worker processes.

Two parts, each configuration in a fresh process (``--worker SPEC``), run in
turn (interleaved) ``--repeat`` times; the best time of each is kept.

``segments``
    All DALES objects replicated to ``--n-segments`` segments (default
    100 000). Replica ``j`` is object ``j % 399`` moved by a random rigid
    motion (rotation about z around its centroid, translation of up to
    1 km in x and y and 10 m in z) and, when it has more than
    ``--max-points`` points (default 1024), a random subset of that many
    points; the generator of replica ``j`` is seeded by ``(seed, j)``, so the
    data do not depend on the batching. The cap keeps the run at ~57 M
    points instead of ~221 M (the objects average 2 212 points; 62 % of them
    have 1024 or fewer and are kept whole): about a minute per configuration
    on two cores, so that the three configurations interleaved three times
    fit in a quarter of an hour. The segments are generated ``--chunk`` at a
    time (10 000 segments, ~5.7 M points) and each chunk goes through one
    ``PFHTransformer(n_neighbors=10, pooling="mean").transform`` call: the
    driver never holds more than one chunk, and only the transform calls are
    timed (generation is reported apart). Configurations: ``local`` (no
    joblib backend, ``n_jobs=2``: two numba threads), ``dask1`` (a
    ``LocalCluster`` of one worker process with two threads) and ``dask2``
    (two worker processes of one thread each); the Dask ones run the same
    call inside ``joblib.parallel_config(backend="dask")``. The outputs of
    every run are hashed (SHA-256 of the float32 rows): they must be equal.

``scene``
    A LAS file of at least ``--scene-points`` points (default 50 M): the
    DALES objects on the synthetic terrain of
    :func:`skpcd.segmentation.make_scene` (10 ground points per m2), copied
    side by side on a grid with a different seed per copy; the copies are
    lifted onto one continuous terrain (ground and noise point by point,
    each object rigidly), so the copies join without steps. It is written
    copy by copy with laspy (the whole scene is never in memory). The file
    is segmented with ``segment_scene(path, tile_size=...)`` plain local
    and on 1 and 2 Dask workers with the first of ``--tile-sizes``, plain
    local with the others and on a smaller scan (``--small-scene-points``,
    same tile size: the peak should not grow with the scan), and once
    without tiles (the whole scan in memory) for contrast; the labels of
    every run on the large scan are compared (equal up to the numbering of
    the segments).

Memory: peak RSS (``VmHWM``, reset through ``/proc/self/clear_refs`` after
start-up and warm-up) of the driver process and of every worker process
(read with ``client.run``), in MB, absolute and above the RSS after
warm-up.

Usage::

    python benchmarks/bench_scaling.py                       # both parts
    python benchmarks/bench_scaling.py --parts segments --repeat 1
    python benchmarks/bench_scaling.py --quick --out /tmp/scaling.json
"""

import argparse
import datetime
import hashlib
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from measure import cpu_model, loadavg, reset_peak  # noqa: E402

DALES = Path(
    os.environ.get(
        "SKPCD_DALES_DIR", HERE.parents[1] / "shared" / "data" / "dales_objects"
    )
)
CONFIGS = {
    "local": {"n_workers": 0, "threads_per_worker": 0},
    "dask1": {"n_workers": 1, "threads_per_worker": 2},
    "dask2": {"n_workers": 2, "threads_per_worker": 1},
}
K = 10
N_JOBS = 2


# ----------------------------------------------------------------------------
# data


def load_objects():
    """The DALES objects (list of (n_i, 3) float64 arrays)."""
    from skpcd.io import read_segments

    clouds, _, _ = read_segments(DALES, DALES / "labels.csv")
    return clouds


def make_replicas(objects, start, stop, *, max_points, seed=0):
    """Replicas ``start`` to ``stop - 1`` of the objects (see the module
    docstring): replica ``j`` is ``objects[j % len(objects)]`` under a
    random rigid motion, subsampled to at most ``max_points`` points, with
    its own generator seeded by ``(seed, j)``."""
    out = []
    for j in range(start, stop):
        obj = objects[j % len(objects)]
        rng = np.random.default_rng([seed, j])
        if len(obj) > max_points:
            obj = obj[np.sort(rng.choice(len(obj), max_points, replace=False))]
        angle = rng.uniform(0.0, 2.0 * np.pi)
        shift = rng.uniform([-1000.0, -1000.0, -10.0], [1000.0, 1000.0, 10.0])
        c, s = np.cos(angle), np.sin(angle)
        centre = obj.mean(axis=0)
        xyz = obj - centre
        moved = np.empty_like(xyz)
        moved[:, 0] = c * xyz[:, 0] - s * xyz[:, 1]
        moved[:, 1] = s * xyz[:, 0] + c * xyz[:, 1]
        moved[:, 2] = xyz[:, 2]
        out.append(moved + centre + shift)
    return out


def write_scene(path, n_points, *, seed=0):
    """Write the scene LAS file of at least ``n_points`` points; returns its
    description (copies, points, extent, seconds)."""
    import laspy

    from skpcd.datasets._object_scene import (
        terrain_height,  # the terrain make_scene uses
    )
    from skpcd.segmentation import make_scene

    start = time.perf_counter()
    objects = load_objects()
    # one copy first, for its size and extent
    base, truth = make_scene(objects, gap=3.0, ground_density=10.0, random_state=seed)
    size = base[:, :2].max(axis=0)
    n_copies = int(np.ceil(n_points / len(base)))
    nx = int(np.ceil(np.sqrt(n_copies)))
    ny = int(np.ceil(n_copies / nx))
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([0.0, 0.0, 0.0])
    total = 0
    with laspy.open(str(path), mode="w", header=header) as writer:
        for i in range(n_copies):
            if i:
                base, truth = make_scene(
                    objects, gap=3.0, ground_density=10.0, random_state=seed + i
                )
            dx, dy = (i % nx) * size[0], (i // nx) * size[1]
            xyz = base + np.array([dx, dy, 0.0])
            # lift the copy onto the terrain at its new place: ground and noise
            # point by point, objects rigidly (their largest lift, so that no
            # point ends below the terrain)
            lift = terrain_height(xyz[:, 0], xyz[:, 1], 1.0) - terrain_height(
                base[:, 0], base[:, 1], 1.0
            )
            obj = truth >= 0
            per_object = np.full(truth.max() + 1, -np.inf)
            np.maximum.at(per_object, truth[obj], lift[obj])
            lift[obj] = per_object[truth[obj]]
            xyz[:, 2] += lift
            rec = laspy.ScaleAwarePointRecord.zeros(len(xyz), header=header)
            rec.x, rec.y, rec.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
            rec.classification = np.where(truth == -1, 2, 1).astype(np.uint8)
            writer.write_points(rec)
            total += len(xyz)
            del xyz, rec, lift
    meta = {
        "path": str(path),
        "n_points": total,
        "copies": n_copies,
        "grid": [nx, ny],
        "copy_points": len(base),
        "extent_m": [float(nx * size[0]), float(ny * size[1])],
        "bytes": os.path.getsize(path),
        "seconds": time.perf_counter() - start,
    }
    Path(path).with_suffix(".json").write_text(json.dumps(meta))
    return meta


# ----------------------------------------------------------------------------
# measuring helpers (also run inside the Dask workers: defined here, not
# imported, so that they travel to the workers by value)


def _status_mb(field):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _worker_reset():
    """Reset the peak RSS of this process; its RSS now (MB)."""
    return reset_peak()


def _worker_peak():
    """Peak RSS of this process since the reset, and its RSS now (MB)."""
    return {
        "peak_mb": _status_mb("VmHWM"),
        "rss_mb": _status_mb("VmRSS"),
        "pid": os.getpid(),
    }


def _warm_pfh():
    """Load (or compile) the PFH kernels in this process."""
    from skpcd.features import PFHTransformer

    rng = np.random.default_rng(0)
    clouds = [rng.random((200, 3)) for _ in range(3)]
    PFHTransformer(n_neighbors=K, pooling="mean", n_jobs=N_JOBS).fit_transform(clouds)
    return os.getpid()


def _warm_scene():
    """Load (or compile) the segmentation kernels in this process."""
    from skpcd.segmentation import segment_scene

    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(0, 30, (5000, 2)), np.zeros(5000)])
    box = rng.uniform([5, 5, 0.6], [8, 8, 3], (500, 3))
    segment_scene(np.vstack([floor, box]), n_jobs=N_JOBS)
    return os.getpid()


class _Cluster:
    """No cluster (``n_workers=0``) or a LocalCluster with a Client, and the
    joblib backend that sends work to it."""

    def __init__(self, n_workers, threads_per_worker):
        self.n_workers = n_workers
        self.client = None
        self.start_s = 0.0
        if n_workers:
            from dask.distributed import Client, LocalCluster

            t0 = time.perf_counter()
            self.cluster = LocalCluster(
                n_workers=n_workers,
                threads_per_worker=threads_per_worker,
                processes=True,
                dashboard_address=":0",
                silence_logs=40,
            )
            self.client = Client(self.cluster)
            self.client.wait_for_workers(n_workers)
            self.start_s = time.perf_counter() - t0

    def run(self, func):
        """``func()`` in every worker: {address: result}."""
        return self.client.run(func) if self.client else {}

    def backend(self):
        import contextlib

        import joblib

        if self.client is None:
            return contextlib.nullcontext()
        return joblib.parallel_config(backend="dask")

    def close(self):
        if self.client is not None:
            self.client.close()
            self.cluster.close()


def _peaks(cluster, base_driver, base_workers):
    driver = _worker_peak()
    out = {
        "driver_peak_mb": driver["peak_mb"],
        "driver_above_warm_mb": driver["peak_mb"] - base_driver,
        "workers": [],
    }
    for addr, w in sorted(cluster.run(_worker_peak).items()):
        w["above_warm_mb"] = w["peak_mb"] - base_workers[addr]
        w["address"] = addr
        out["workers"].append(w)
    return out


# ----------------------------------------------------------------------------
# workers (one configuration in a fresh process)


def _run_segments(spec):
    from skpcd.features import PFHTransformer

    objects = load_objects()
    cluster = _Cluster(spec["n_workers"], spec["threads_per_worker"])
    try:
        _warm_pfh()
        cluster.run(_warm_pfh)
        est = PFHTransformer(n_neighbors=K, pooling="mean", n_jobs=N_JOBS)
        est.fit(objects[:2])
        base_workers = cluster.run(_worker_reset)
        base_driver = _worker_reset()
        digest = hashlib.sha256()
        n, chunk = spec["n_segments"], spec["chunk"]
        seconds = gen_seconds = 0.0
        n_points = 0
        first_row = None
        for lo in range(0, n, chunk):
            t0 = time.perf_counter()
            clouds = make_replicas(
                objects, lo, min(n, lo + chunk), max_points=spec["max_points"]
            )
            gen_seconds += time.perf_counter() - t0
            n_points += sum(map(len, clouds))
            t0 = time.perf_counter()
            with cluster.backend():
                rows = est.transform(clouds)
            seconds += time.perf_counter() - t0
            rows = np.ascontiguousarray(rows)
            digest.update(rows.tobytes())
            if first_row is None:
                first_row = rows[0, :5].tolist()
            del clouds, rows
        out = {
            "seconds": seconds,
            "generate_seconds": gen_seconds,
            "cluster_start_seconds": cluster.start_s,
            "n_segments": n,
            "n_points": n_points,
            "sha256": digest.hexdigest(),
            "first_row": first_row,
        }
        out.update(_peaks(cluster, base_driver, base_workers))
        return out
    finally:
        cluster.close()


def _run_scene(spec):
    from skpcd.segmentation import segment_scene

    cluster = _Cluster(spec["n_workers"], spec["threads_per_worker"])
    try:
        _warm_scene()
        cluster.run(_warm_scene)
        base_workers = cluster.run(_worker_reset)
        base_driver = _worker_reset()
        # the tiled path takes an SMRF preset and no structures (issue 19)
        kwargs = {"random_state": 0, "n_jobs": N_JOBS}
        kwargs.update(ground="aerial", structures=False)
        if spec.get("eps"):
            kwargs["eps"] = spec["eps"]
        t0 = time.perf_counter()
        if spec["tile_size"]:
            with cluster.backend():
                seg = segment_scene(spec["path"], tile_size=spec["tile_size"], **kwargs)
        else:
            from skpcd.io import read_point_cloud

            seg = segment_scene(read_point_cloud(spec["path"]), **kwargs)
        seconds = time.perf_counter() - t0
        out = {
            "seconds": seconds,
            "cluster_start_seconds": cluster.start_s,
            "n_segments": int(seg.n_segments),
            "n_ground": int(np.count_nonzero(seg.ground)),
            "eps": float(seg.eps),
        }
        out.update(_peaks(cluster, base_driver, base_workers))
        if spec.get("labels_out"):
            np.save(spec["labels_out"], _canonical(np.asarray(seg.labels)))
        return out
    finally:
        cluster.close()


def _canonical(labels):
    """Labels renumbered by first appearance (-1 kept): equal arrays mean the
    same partition."""
    labels = np.asarray(labels, dtype=np.int64)
    seg = labels >= 0
    if not seg.any():
        return labels.copy()
    uniq, first, inverse = np.unique(
        labels[seg], return_index=True, return_inverse=True
    )
    rank = np.empty(len(uniq), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(uniq))
    out = np.full(len(labels), -1, dtype=np.int64)
    out[seg] = rank[inverse]
    return out


def _worker(spec):
    run = _run_segments if spec["part"] == "segments" else _run_scene
    print("RESULT " + json.dumps(run(spec)))


def run_worker(spec, timeout=None):
    """One configuration in a fresh process: its JSON result or the failure."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", json.dumps(spec)]
    start = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"failed": f"timeout after {timeout:.0f} s"}
    for line in reversed(p.stdout.splitlines()):
        if line.startswith("RESULT "):
            out = json.loads(line[len("RESULT ") :])
            out["load_after"] = loadavg()
            return out
    return {
        "failed": f"exit {p.returncode} after {time.perf_counter() - start:.0f} s",
        "stderr": "\n".join(p.stderr.strip().splitlines()[-8:]),
    }


# ----------------------------------------------------------------------------
# driver


def _best(runs):
    ok = [r for r in runs if "failed" not in r]
    return min(ok, key=lambda r: r["seconds"]) if ok else runs[-1]


def bench_segments(a):
    configs = [c for c in a.configs.split(",") if c]
    runs = {c: [] for c in configs}
    for rep in range(a.repeat):
        for name in configs if rep % 2 == 0 else configs[::-1]:
            spec = {
                "part": "segments",
                "config": name,
                "n_segments": a.n_segments,
                "max_points": a.max_points,
                "chunk": a.chunk,
                **CONFIGS[name],
            }
            r = run_worker(spec, timeout=a.timeout)
            runs[name].append(r)
            print(f"segments {name} run {rep + 1}: {_brief(r)}", flush=True)
    best = {c: _best(rs) for c, rs in runs.items()}
    hashes = {r["sha256"] for rs in runs.values() for r in rs if "sha256" in r}
    return {
        "n_segments": a.n_segments,
        "max_points": a.max_points,
        "chunk": a.chunk,
        "estimator": f"PFHTransformer(n_neighbors={K}, pooling='mean', "
        f"n_jobs={N_JOBS})",
        "configs": {c: CONFIGS[c] for c in configs},
        "runs": runs,
        "best": best,
        "identical_outputs": len(hashes) == 1
        and all("sha256" in r for rs in runs.values() for r in rs),
    }


def _scene_file(path, n_points, reuse):
    if reuse and path.exists():
        import laspy

        meta = path.with_suffix(".json")
        scene = json.loads(meta.read_text()) if meta.exists() else {}
        with laspy.open(str(path)) as f:
            scene.update(path=str(path), n_points=int(f.header.point_count))
        print(f"scene: reusing {path} ({scene['n_points']} points)", flush=True)
        return scene
    scene = write_scene(path, n_points)
    print(
        f"scene: {scene['n_points']} points, {scene['bytes'] / 2**30:.2f} GB, "
        f"written in {scene['seconds']:.0f} s",
        flush=True,
    )
    return scene


def bench_scene(a, tmp):
    folder = Path(a.scene_folder) if a.scene_folder else Path(tmp)
    folder.mkdir(parents=True, exist_ok=True)
    scenes = {
        "large": _scene_file(folder / "scene.las", a.scene_points, a.scene_folder)
    }
    tiles = [float(t) for t in a.tile_sizes.split(",") if t]
    configs = [c for c in a.configs.split(",") if c]
    # every configuration with the first tile size; the other tile sizes, the
    # smaller scan and the untiled run on the plain local path only
    cases = [("large", c, tiles[0]) for c in configs]
    cases += [("large", "local", t) for t in tiles[1:]]
    if a.small_scene_points:
        scenes["small"] = _scene_file(
            folder / "scene_small.las", a.small_scene_points, a.scene_folder
        )
        cases.append(("small", "local", tiles[0]))
    if a.untiled:
        cases.append(("large", "local", 0.0))
    runs = {f"{s}:{c}@{t:g}": [] for s, c, t in cases}
    labels = {}
    for rep in range(a.scene_repeat):
        for s, c, t in cases if rep % 2 == 0 else cases[::-1]:
            key = f"{s}:{c}@{t:g}"
            out = Path(tmp) / f"labels_{s}_{c}_{t:g}.npy"
            spec = {
                "part": "scene",
                "config": c,
                "path": scenes[s]["path"],
                "tile_size": t,
                "eps": a.eps,
                "labels_out": str(out) if rep == 0 and s == "large" else None,
                **CONFIGS[c],
            }
            r = run_worker(spec, timeout=a.timeout)
            r["n_points"] = scenes[s]["n_points"]
            runs[key].append(r)
            if spec["labels_out"] and "failed" not in r:
                labels[key] = out
            print(f"scene {key} run {rep + 1}: {_brief(r)}", flush=True)
    # partitions of the large scan: every run against the first one
    same = {}
    keys = list(labels)
    if keys:
        ref = np.load(labels[keys[0]], mmap_mode="r")
        for k in keys[1:]:
            same[k] = bool(np.array_equal(ref, np.load(labels[k], mmap_mode="r")))
        same["reference"] = keys[0]
    return {
        "scenes": scenes,
        "eps": a.eps,
        "tile_sizes": tiles,
        "runs": runs,
        "best": {k: _best(rs) for k, rs in runs.items()},
        "same_partition_as_reference": same,
    }


def _brief(r):
    if "failed" in r:
        return f"FAILED {r['failed']}: {r.get('stderr', '')}"
    w = ", ".join(f"{x['above_warm_mb']:.0f}" for x in r["workers"])
    extra = f", {r['n_segments']} segments, eps {r['eps']:.4f}" if "eps" in r else ""
    return (
        f"{r['seconds']:.1f} s, driver peak +{r['driver_above_warm_mb']:.0f} MB"
        + (f", workers +[{w}] MB" if w else "")
        + extra
    )


def commit():
    """HEAD of the repository, and whether skpcd/ has uncommitted changes."""

    def git(*args):
        return subprocess.run(
            ["git", *args], cwd=HERE.parent, capture_output=True, text=True
        ).stdout.strip()

    return {
        "head": git("rev-parse", "--short", "HEAD"),
        "skpcd_dirty": bool(git("status", "--porcelain", "--", "skpcd")),
    }


def _versions():
    import dask
    import distributed
    import joblib
    import laspy
    import numba
    import sklearn

    import skpcd

    return {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "numba": numba.__version__,
        "scikit-learn": sklearn.__version__,
        "joblib": joblib.__version__,
        "dask": dask.__version__,
        "distributed": distributed.__version__,
        "laspy": laspy.__version__,
        "skpcd": skpcd.__version__,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--parts", default="segments,scene")
    ap.add_argument("--configs", default="local,dask1,dask2")
    ap.add_argument("--n-segments", type=int, default=100_000)
    ap.add_argument("--max-points", type=int, default=1024)
    ap.add_argument("--chunk", type=int, default=10_000, help="segments per call")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each segments case")
    ap.add_argument(
        "--segments-key",
        default="segments",
        help="key of the segments results in the JSON (several runs side by side)",
    )
    ap.add_argument("--scene-points", type=float, default=50e6)
    ap.add_argument(
        "--small-scene-points",
        type=float,
        default=20e6,
        help="a smaller scan tiled the same way (0: none)",
    )
    ap.add_argument(
        "--scene-folder",
        help="keep the LAS scenes here and reuse them (default: a temporary folder)",
    )
    ap.add_argument("--tile-sizes", default="400,200", help="metres, comma list")
    ap.add_argument("--eps", type=float, default=None, help="fixed eps (None: auto)")
    ap.add_argument("--scene-repeat", type=int, default=1)
    ap.add_argument(
        "--no-untiled", dest="untiled", action="store_false", help="skip the untiled"
    )
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--quick", action="store_true", help="small sizes, a smoke test")
    ap.add_argument("--out", default=str(HERE / "results" / "scaling.json"))
    a = ap.parse_args(argv)
    if a.worker:
        _worker(json.loads(a.worker))
        return 0
    if a.quick:
        a.n_segments, a.chunk, a.repeat = 2000, 1000, 1
        a.scene_points, a.small_scene_points, a.tile_sizes = 3e6, 1e6, "100"
    out = Path(a.out)
    R = json.loads(out.read_text()) if out.exists() else {}
    R["machine"] = {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "memory_gb": round(
            os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1
        ),
    }
    R["versions"] = _versions()
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cmd = "python benchmarks/bench_scaling.py " + shlex.join(
        sys.argv[1:] if argv is None else argv
    )
    parts = set(a.parts.split(","))
    with tempfile.TemporaryDirectory() as tmp:
        for part, key, bench in (
            ("segments", a.segments_key, lambda: bench_segments(a)),
            ("scene", "scene", lambda: bench_scene(a, tmp)),
        ):
            if part not in parts:
                continue
            start = {"date": stamp, "command": cmd, "loadavg_start": loadavg()}
            start["commit"] = commit()
            R[key] = bench()
            R[key].update(start)
            R[key]["loadavg_end"] = loadavg()
            _write(out, R)
    print(report(R))
    return 0


def _write(out, R):
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(R, indent=1))
    out.with_suffix(".txt").write_text(report(R))


# ----------------------------------------------------------------------------
# report


def _code(part):
    c = part.get("commit") or {}
    dirty = (
        " (skpcd/ with uncommitted changes at the start)"
        if c.get("skpcd_dirty")
        else ""
    )
    note = f"; {c['note']}" if c.get("note") else ""
    return f"code     commit {c.get('head', '?')}{dirty}{note}"


def _workers_cell(r):
    if not r.get("workers"):
        return "-"
    return " / ".join(
        f"{w['peak_mb']:.0f} (+{w['above_warm_mb']:.0f})" for w in r["workers"]
    )


def report(R):
    m, v = R["machine"], R["versions"]
    lines = [
        "Scaling out: plain local against a Dask LocalCluster (1 and 2 workers)",
        f"machine  {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB",
        "versions " + ", ".join(f"{k} {x}" for k, x in v.items()),
        "memory   peak RSS in MB (VmHWM, reset after start-up and warm-up), "
        "with the rise above the warm RSS in parentheses",
    ]
    for key in sorted(k for k in R if k.startswith("segments")):
        S = R[key]
        b = S["best"]
        lines += [
            "",
            f"Descriptors of {S['n_segments']} segments (DALES objects under random "
            f"rigid motions, at most {S['max_points']} points each), "
            f"{S['estimator']}, {S['chunk']} segments per call",
            f"{S['date']}; load average {S['loadavg_start']} at start, "
            f"{S['loadavg_end']} at end; best of {len(next(iter(S['runs'].values())))}",
            f"command  {S['command']}",
            _code(S),
            f"{'config':<8} {'workers':>7} {'threads':>7} {'s':>7} {'segments/s':>10} "
            f"{'Mpoints/s':>9} {'vs local':>8} {'start s':>7} "
            f"{'driver MB':>14}  workers MB",
        ]
        local = b.get("local", {}).get("seconds")
        for c, r in b.items():
            conf = S["configs"][c]
            if "failed" in r:
                lines.append(f"{c:<8} failed: {r['failed']}")
                continue
            ratio = f"{r['seconds'] / local:.2f}x" if local else "-"
            threads = conf["threads_per_worker"] or N_JOBS
            lines.append(
                f"{c:<8} {conf['n_workers']:>7} {threads:>7} "
                f"{r['seconds']:>7.1f} {r['n_segments'] / r['seconds']:>10.0f} "
                f"{r['n_points'] / r['seconds'] / 1e6:>9.2f} {ratio:>8} "
                f"{r['cluster_start_seconds']:>7.1f} "
                f"{r['driver_peak_mb']:>6.0f} (+{r['driver_above_warm_mb']:.0f})"
                f"  {_workers_cell(r)}"
            )
        any_ok = next((r for r in b.values() if "failed" not in r), None)
        if any_ok:
            lines.append(
                f"points {any_ok['n_points']}; generation "
                f"{any_ok['generate_seconds']:.1f} s "
                "(not timed); outputs identical in every run (SHA-256): "
                f"{S['identical_outputs']}"
            )
        lines.append(
            "all runs (s): "
            + "; ".join(
                f"{c} "
                + ", ".join(
                    f"{r['seconds']:.1f}" if "seconds" in r else "fail" for r in rs
                )
                for c, rs in S["runs"].items()
            )
        )
    C = R.get("scene")
    if C:
        lines += ["", "Tiled segmentation of LAS scenes (DALES copies on one terrain)"]
        for name, sc in C["scenes"].items():
            lines.append(
                f"{name:<6} {sc['n_points'] / 1e6:.1f} M points"
                + (
                    f", {sc['copies']} copies of the DALES scene of "
                    f"{sc['copy_points'] / 1e6:.2f} M points, "
                    f"{sc['extent_m'][0]:.0f} x {sc['extent_m'][1]:.0f} m, "
                    f"{sc['bytes'] / 2**30:.2f} GB, written in {sc['seconds']:.0f} s"
                    if "copies" in sc
                    else ""
                )
            )
        lines += [
            f"{C['date']}; load average {C['loadavg_start']} at start, "
            f"{C['loadavg_end']} at end; eps "
            + ("estimated once per scan" if C["eps"] is None else f"{C['eps']}"),
            f"command  {C['command']}",
            _code(C),
            f"{'scan':<6} {'config':<8} {'tile m':>6} {'s':>7} {'Mpoints/s':>9} "
            f"{'segments':>8} {'vs local':>8} {'start s':>7} {'driver MB':>14}  "
            "workers MB",
        ]
        for key, r in C["best"].items():
            scan, rest = key.split(":")
            c, t = rest.split("@")
            local = C["best"].get(f"{scan}:local@{t}", {}).get("seconds")
            t = "none" if float(t) == 0 else t
            if "failed" in r:
                lines.append(f"{scan:<6} {c:<8} {t:>6} failed: {r['failed']}")
                continue
            ratio = f"{r['seconds'] / local:.2f}x" if local and c != "local" else "-"
            lines.append(
                f"{scan:<6} {c:<8} {t:>6} {r['seconds']:>7.1f} "
                f"{r['n_points'] / r['seconds'] / 1e6:>9.2f} {r['n_segments']:>8} "
                f"{ratio:>8} {r['cluster_start_seconds']:>7.1f} "
                f"{r['driver_peak_mb']:>6.0f} (+{r['driver_above_warm_mb']:.0f})"
                f"  {_workers_cell(r)}"
            )
        same = C["same_partition_as_reference"]
        if same:
            ref = same.get("reference")
            lines.append(
                f"same partition as {ref}: "
                + ", ".join(f"{k} {v}" for k, v in same.items() if k != "reference")
            )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
