"""Scene segmentation at 1, 5 and 10 million points: skpcd against
scikit-learn's DBSCAN and Open3D's ``cluster_dbscan`` with the same eps.

The scene is the DALES objects on a synthetic terrain
(:func:`skpcd.segmentation.make_scene`, 10 ground points per m2), tiled
side by side and cropped along x to the wanted number of points, so the
density stays the same and the area grows with n. For each n, every stage
runs in a fresh process (its peak RSS is its own; the input is loaded before
the peak is reset):

- ``ground``: ``GroundFilter().fit_predict`` on the scene;
- ``eps``: ``estimate_eps`` on the non-ground points (the distance curve);
- ``dbscan``: skpcd's grid DBSCAN on them with that eps (``min_samples=5``);
- ``segment_scene``: the three end to end (plus segment sizes);
- ``sklearn``: ``sklearn.cluster.DBSCAN(eps, min_samples=5, n_jobs=2)``;
- ``open3d``: ``PointCloud.cluster_dbscan(eps, min_points=5)``.

The two references run with a cap on their address space (``--cap-gb``)
and a timeout; one that fails at some n is not tried at larger n. Their
labels are compared with skpcd's (adjusted Rand index over all points, and
the share of points with the same noise/cluster status).

    python benchmarks/bench_segmentation.py                 # 1, 5, 10 M
    python benchmarks/bench_segmentation.py --sizes 0.2 --out /tmp/s.json
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
# the measuring helpers of the descriptor benchmark: VmHWM peak reset by
# clear_refs, Open3D import without its viewer, machine description
from bench_descriptors import (  # noqa: E402
    _cpu_model,
    _import_open3d,
    _loadavg,
    _maxrss_mb,
    _reset_peak,
    _versions,
)

DALES = Path(
    os.environ.get(
        "SKPCD_DALES_DIR", HERE.parents[1] / "shared" / "data" / "dales_objects"
    )
)
MIN_SAMPLES = 5
N_JOBS = 2


# ----------------------------------------------------------------------------
# data


def make_data(sizes, folder):
    """Write ``scene_<n>.npy`` for every n (points cropped along x from the
    tiled scene) and return their paths."""
    from skpcd.io import read_segments
    from skpcd.segmentation import make_scene

    clouds, _, _ = read_segments(DALES, DALES / "labels.csv")
    base, _ = make_scene(clouds, gap=3.0, ground_density=10.0, random_state=0)
    width = np.ptp(base[:, 0]) + 3.0
    n_max = max(sizes)
    tiles = int(np.ceil(n_max / len(base)))
    scene = np.vstack([base + np.array([i * width, 0.0, 0.0]) for i in range(tiles)])
    scene = scene[np.argsort(scene[:, 0], kind="stable")]
    paths = {}
    for n in sizes:
        path = Path(folder) / f"scene_{n}.npy"
        np.save(path, np.ascontiguousarray(scene[:n]))
        paths[n] = str(path)
    return paths, len(base)


# ----------------------------------------------------------------------------
# workers (one stage in a fresh process)


def _worker(spec):
    points = np.load(spec["input"])
    stage = spec["stage"]
    eps = spec.get("eps")
    out = {}
    if stage in ("ground", "eps", "dbscan", "segment_scene"):
        from skpcd.segmentation import (
            AutoEpsDBSCAN,
            GroundFilter,
            estimate_eps,
            segment_scene,
        )

        # compile (or load) the kernels on a small cloud first
        small = points[:5000]
        AutoEpsDBSCAN(eps=1.0).fit(small)
        GroundFilter().fit(small)

        def run():
            if stage == "ground":
                g = GroundFilter().fit_predict(points)
                np.save(spec["output"], np.ascontiguousarray(points[~g]))
                return {"n_ground": int(g.sum())}
            if stage == "eps":
                return {
                    "eps": estimate_eps(points, random_state=0, n_jobs=N_JOBS),
                }
            if stage == "dbscan":
                db = AutoEpsDBSCAN(eps=eps, min_samples=MIN_SAMPLES, n_jobs=N_JOBS)
                labels = db.fit(points).labels_
                np.save(spec["output"], labels)
                return {"n_clusters": int(db.n_clusters_)}
            seg = segment_scene(points, random_state=0, n_jobs=N_JOBS)
            return {"n_segments": seg.n_segments, "eps": seg.eps}

    elif stage == "sklearn":
        from sklearn.cluster import DBSCAN

        def run():
            labels = DBSCAN(eps=eps, min_samples=MIN_SAMPLES, n_jobs=N_JOBS).fit(points)
            np.save(spec["output"], labels.labels_)
            return {"n_clusters": int(labels.labels_.max() + 1)}

    elif stage == "open3d":
        o3d = _import_open3d()

        def run():
            pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
            labels = np.asarray(
                pcd.cluster_dbscan(
                    eps=eps, min_points=MIN_SAMPLES, print_progress=False
                )
            )
            np.save(spec["output"], labels)
            return {"n_clusters": int(labels.max() + 1)}

    else:
        raise ValueError(stage)
    base = _reset_peak()
    start = time.perf_counter()
    out.update(run())
    out["seconds"] = time.perf_counter() - start
    out["peak_mb"] = _maxrss_mb() - base
    out["input_mb"] = points.nbytes / 2**20
    print(json.dumps(out))


def _limit(cap_gb):
    def set_cap():
        if cap_gb:
            cap = int(cap_gb * 2**30)
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    return set_cap


def run_stage(spec, timeout=None, cap_gb=None):
    """One stage in a fresh process: its JSON result, or the failure."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", json.dumps(spec)]
    start = time.perf_counter()
    try:
        p = subprocess.run(
            cmd,
            capture_output=True,
            text=True,
            timeout=timeout,
            preexec_fn=_limit(cap_gb),
        )
    except subprocess.TimeoutExpired:
        return {"failed": f"timeout after {timeout:.0f} s"}
    if p.returncode != 0:
        err = p.stderr.strip().splitlines()
        memory = any("MemoryError" in e or "bad_alloc" in e for e in err)
        why = "out of memory (cap)" if memory or p.returncode < 0 else "error"
        return {
            "failed": f"{why}, exit {p.returncode} after "
            f"{time.perf_counter() - start:.0f} s",
            "stderr": "\n".join(err[-5:]),
        }
    return json.loads(p.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------
# driver


def agreement(ours, theirs):
    """ARI over all points and the share with the same noise status."""
    from sklearn.metrics import adjusted_rand_score

    return {
        "ari": float(adjusted_rand_score(ours, theirs)),
        "same_noise": float(np.mean((ours < 0) == (theirs < 0))),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument(
        "--sizes", default="1,5,10", help="millions of points (default 1,5,10)"
    )
    ap.add_argument("--timeout", type=float, default=300.0, help="per reference run")
    ap.add_argument("--cap-gb", type=float, default=8.0, help="references' memory cap")
    ap.add_argument(
        "--skip", default="", help="comma list of stages to skip (sklearn, open3d)"
    )
    ap.add_argument("--out", default=str(HERE / "results" / "segmentation.json"))
    a = ap.parse_args(argv)
    if a.worker:
        _worker(json.loads(a.worker))
        return 0
    sizes = [round(float(s) * 1_000_000) for s in a.sizes.split(",")]
    skip = set(filter(None, a.skip.split(",")))
    R = {
        "machine": {
            "cpu": _cpu_model(),
            "cores": os.cpu_count(),
            "loadavg_start": _loadavg(),
        },
        "versions": _versions(),
        "min_samples": MIN_SAMPLES,
        "n_jobs": N_JOBS,
        "cap_gb": a.cap_gb,
        "timeout_s": a.timeout,
        "runs": [],
    }
    import sklearn

    R["versions"]["scikit-learn"] = sklearn.__version__
    failed = set()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        paths, n_base = make_data(sizes, tmp)
        R["base_scene_points"] = n_base
        print(f"data: base scene {n_base} points, {time.perf_counter() - t0:.0f} s")
        for n in sizes:
            run = {"n_points": n}
            rest = str(Path(tmp) / f"rest_{n}.npy")
            ours = str(Path(tmp) / f"ours_{n}.npy")
            run["ground"] = run_stage(
                {"stage": "ground", "input": paths[n], "output": rest}
            )
            run["n_rest"] = n - run["ground"]["n_ground"]
            run["eps"] = run_stage({"stage": "eps", "input": rest})
            eps = run["eps"]["eps"]
            run["dbscan"] = run_stage(
                {"stage": "dbscan", "input": rest, "output": ours, "eps": eps}
            )
            run["segment_scene"] = run_stage(
                {"stage": "segment_scene", "input": paths[n]}
            )
            mine = np.load(ours)
            for ref in ("sklearn", "open3d"):
                if ref in skip or ref in failed:
                    run[ref] = {"failed": "skipped (failed at a smaller n)"}
                    if ref in skip:
                        run[ref] = {"failed": "skipped"}
                    continue
                theirs = str(Path(tmp) / f"{ref}_{n}.npy")
                spec = {"stage": ref, "input": rest, "output": theirs, "eps": eps}
                run[ref] = run_stage(spec, timeout=a.timeout, cap_gb=a.cap_gb)
                if "failed" in run[ref]:
                    failed.add(ref)
                else:
                    run[ref].update(agreement(mine, np.load(theirs)))
            R["runs"].append(run)
            print(_row_text(run))
            sys.stdout.flush()
    R["machine"]["loadavg_end"] = _loadavg()
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(R, indent=1))
    text = report(R)
    out.with_suffix(".txt").write_text(text)
    print(text)
    return 0


def _cell(r):
    if "failed" in r:
        return f"{'-':>8} {'-':>9}"
    return f"{r['seconds']:>8.1f} {r['peak_mb']:>9.0f}"


def _row_text(run):
    stages = ("ground", "eps", "dbscan", "segment_scene", "sklearn", "open3d")
    return f"{run['n_points'] / 1e6:>5.1f}M " + " ".join(_cell(run[s]) for s in stages)


def report(R):
    m = R["machine"]
    lines = [
        "Scene segmentation: skpcd vs scikit-learn DBSCAN and Open3D cluster_dbscan",
        f"machine  {m['cpu']}, {m['cores']} cores, load average "
        f"{m['loadavg_start']} at start, {m['loadavg_end']} at end",
        "versions " + ", ".join(f"{k} {v}" for k, v in R["versions"].items()),
        f"scene    DALES objects on a synthetic terrain (base {R['base_scene_points']} "
        "points), tiled and cropped along x: same density, area grows with n",
        f"dbscan   min_samples {R['min_samples']}, n_jobs {R['n_jobs']}; references "
        f"capped at {R['cap_gb']:.0f} GB of address space, {R['timeout_s']:.0f} s",
        "",
        "time (s) and peak memory above the loaded input (MB), one fresh process "
        "per stage",
        f"{'n':>6} {'non-ground':>10} {'eps':>6} "
        + " ".join(
            f"{s:>18}"
            for s in (
                "ground",
                "eps curve",
                "dbscan",
                "segment_scene",
                "sklearn",
                "open3d",
            )
        ),
        f"{'':>24} " + " ".join(f"{'s':>8} {'MB':>9}" for _ in range(6)),
    ]
    for run in R["runs"]:
        lines.append(
            f"{run['n_points'] / 1e6:>5.1f}M {run['n_rest']:>10} "
            f"{run['eps'].get('eps', float('nan')):>6.3f} "
            + " ".join(
                _cell(run[s])
                for s in (
                    "ground",
                    "eps",
                    "dbscan",
                    "segment_scene",
                    "sklearn",
                    "open3d",
                )
            )
        )
    lines += ["", "references: outcome and agreement with skpcd's labels"]
    for run in R["runs"]:
        for ref in ("sklearn", "open3d"):
            r = run[ref]
            if "failed" in r:
                what = r["failed"]
            else:
                what = (
                    f"{r['n_clusters']} clusters "
                    f"(skpcd {run['dbscan']['n_clusters']}); "
                    f"ARI {r['ari']:.4f}, same noise status {r['same_noise']:.4f}; "
                    f"{r['seconds'] / run['dbscan']['seconds']:.1f}x skpcd's time, "
                    f"{r['peak_mb'] / max(run['dbscan']['peak_mb'], 1):.1f}x its memory"
                )
            lines.append(f"{run['n_points'] / 1e6:>5.1f}M {ref:<8} {what}")
    lines += ["", "growth with n (time and memory relative to the smallest n)"]
    first = R["runs"][0]
    for run in R["runs"][1:]:
        f = run["n_points"] / first["n_points"]
        parts = []
        for s in ("ground", "eps", "dbscan", "segment_scene"):
            a, b = first[s], run[s]
            if "failed" in a or "failed" in b:
                continue
            parts.append(
                f"{s} x{b['seconds'] / a['seconds']:.1f} time, "
                f"x{b['peak_mb'] / max(a['peak_mb'], 1):.1f} memory"
            )
        lines.append(f"n x{f:.0f}: " + "; ".join(parts))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
