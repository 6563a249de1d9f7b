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
- ``segment_scene``: the three end to end (plus segment sizes);
- ``dbscan``: skpcd's grid DBSCAN of the non-ground points with that eps
  (``min_samples=5``), and with a wider, user-chosen eps (``--wide-eps``,
  1.2 m: the radius that keeps the DALES objects whole, see the tests);
- ``sklearn``: ``sklearn.cluster.DBSCAN(eps, min_samples=5, n_jobs=2)``,
  both eps;
- ``open3d``: ``PointCloud.cluster_dbscan(eps, min_points=5)``, both eps.

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
from bench_descriptors import versions  # noqa: E402
from measure import (  # noqa: E402
    cpu_model,
    import_open3d,
    loadavg,
    maxrss_mb,
    provenance,
    reset_peak,
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
        o3d = import_open3d()

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
    base = reset_peak()
    start = time.perf_counter()
    out.update(run())
    out["seconds"] = time.perf_counter() - start
    out["peak_mb"] = maxrss_mb() - base
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


def compare(rest, eps, tmp, tag, failed, skip, timeout, cap_gb):
    """skpcd's DBSCAN and the references on the non-ground points with one eps."""
    ours = str(Path(tmp) / f"ours_{tag}.npy")
    out = {"eps": eps}
    out["dbscan"] = run_stage(
        {"stage": "dbscan", "input": rest, "output": ours, "eps": eps}
    )
    mine = np.load(ours)
    for ref in ("sklearn", "open3d"):
        key = (ref, tag.split("_")[0])
        if ref in skip:
            out[ref] = {"failed": "skipped"}
            continue
        if key in failed:
            out[ref] = {"failed": "not run: failed at a smaller n"}
            continue
        theirs = str(Path(tmp) / f"{ref}_{tag}.npy")
        spec = {"stage": ref, "input": rest, "output": theirs, "eps": eps}
        out[ref] = run_stage(spec, timeout=timeout, cap_gb=cap_gb)
        if "failed" in out[ref]:
            failed.add(key)
        else:
            out[ref].update(agreement(mine, np.load(theirs)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument(
        "--sizes", default="1,5,10", help="millions of points (default 1,5,10)"
    )
    ap.add_argument(
        "--wide-eps",
        type=float,
        default=1.2,
        help="a second, user-chosen eps for the DBSCAN comparison (0: none)",
    )
    ap.add_argument("--timeout", type=float, default=240.0, help="per reference run")
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
            "cpu": cpu_model(),
            "cores": os.cpu_count(),
            "loadavg_start": loadavg(),
        },
        "versions": versions(),
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
            run["ground"] = run_stage(
                {"stage": "ground", "input": paths[n], "output": rest}
            )
            run["n_rest"] = n - run["ground"]["n_ground"]
            run["eps"] = run_stage({"stage": "eps", "input": rest})
            run["segment_scene"] = run_stage(
                {"stage": "segment_scene", "input": paths[n]}
            )
            limits = {"failed": failed, "skip": skip, "timeout": a.timeout}
            limits["cap_gb"] = a.cap_gb
            eps = run["eps"]["eps"]
            run["auto"] = compare(rest, eps, tmp, f"auto_{n}", **limits)
            if a.wide_eps:
                run["wide"] = compare(rest, a.wide_eps, tmp, f"wide_{n}", **limits)
            R["runs"].append(run)
            print(_row_text(run))
            sys.stdout.flush()
    R["machine"]["loadavg_end"] = loadavg()
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**provenance(), **R}, indent=1))
    text = report(R)
    out.with_suffix(".txt").write_text(text)
    print(text)
    return 0


def _cell(r):
    if "failed" in r:
        return f"{'-':>8} {'-':>9}"
    return f"{r['seconds']:>8.1f} {r['peak_mb']:>9.0f}"


STAGES = ("ground", "eps", "segment_scene")
COMPARED = ("dbscan", "sklearn", "open3d")


def _row_text(run):
    cells = [_cell(run[s]) for s in STAGES] + [_cell(run["auto"][s]) for s in COMPARED]
    return f"{run['n_points'] / 1e6:>5.1f}M " + " ".join(cells)


def report(R):
    m = R["machine"]
    head = " ".join(f"{s:>18}" for s in ("ground", "eps curve", "segment_scene"))
    sub = " ".join(f"{'s':>8} {'MB':>9}" for _ in range(3))
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
        "Stages of segment_scene: time (s) and peak memory above the loaded input "
        "(MB), one fresh process per stage",
        f"{'n':>6} {'non-ground':>10} " + head,
        f"{'':>17} " + sub,
    ]
    for run in R["runs"]:
        lines.append(
            f"{run['n_points'] / 1e6:>5.1f}M {run['n_rest']:>10} "
            + " ".join(_cell(run[s]) for s in STAGES)
        )
    head = " ".join(f"{s:>18}" for s in ("skpcd dbscan", "sklearn DBSCAN", "open3d"))
    for which, title in (("auto", "the estimated eps"), ("wide", "a wider eps")):
        if which not in R["runs"][0]:
            continue
        lines += [
            "",
            f"DBSCAN of the non-ground points with {title}: time (s), peak memory (MB)",
            f"{'n':>6} {'non-ground':>10} {'eps':>6} " + head,
            f"{'':>24} " + sub,
        ]
        for run in R["runs"]:
            c = run[which]
            lines.append(
                f"{run['n_points'] / 1e6:>5.1f}M {run['n_rest']:>10} {c['eps']:>6.3f} "
                + " ".join(_cell(c[s]) for s in COMPARED)
            )
    lines += ["", "references: outcome and agreement with skpcd's labels"]
    for which in ("auto", "wide"):
        for run in R["runs"]:
            if which not in run:
                continue
            c = run[which]
            for ref in ("sklearn", "open3d"):
                r = c[ref]
                if "failed" in r:
                    what = r["failed"]
                else:
                    ours = c["dbscan"]
                    what = (
                        f"{r['n_clusters']} clusters (skpcd {ours['n_clusters']}); "
                        f"ARI {r['ari']:.4f}, same noise status {r['same_noise']:.4f}; "
                        f"{r['seconds'] / ours['seconds']:.1f}x skpcd's time, "
                        f"{r['peak_mb'] / max(ours['peak_mb'], 1):.1f}x its memory"
                    )
                lines.append(
                    f"{run['n_points'] / 1e6:>5.1f}M eps {c['eps']:.3f} {ref:<8} {what}"
                )
    lines += ["", "growth with n (time and memory relative to the smallest n)"]
    first = R["runs"][0]
    for run in R["runs"][1:]:
        f = run["n_points"] / first["n_points"]
        parts = []
        pairs = [(s, first[s], run[s]) for s in STAGES]
        pairs += [
            (f"{s} ({w})", first[w][s], run[w][s])
            for w in ("auto", "wide")
            if w in run
            for s in COMPARED
        ]
        for name, x, y in pairs:
            if "failed" in x or "failed" in y:
                continue
            parts.append(
                f"{name} x{y['seconds'] / x['seconds']:.1f} time, "
                f"x{y['peak_mb'] / max(x['peak_mb'], 1):.1f} memory"
            )
        lines.append(f"n x{f:.0f}: " + "; ".join(parts))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
