"""Segments per second of the segment-level steps on the DALES objects.

Grid sampling (:class:`~skpcd.preprocessing.GridSampler`), normals
(:class:`~skpcd.preprocessing.NormalEstimator`), the improved PFH and FPFH
(:class:`~skpcd.features.ImprovedPFHTransformer`, normals included) and the
overall descriptor, on every object of ``../shared/data/dales_objects``, with
``n_jobs`` 1 and 2. Each step is timed after a warm-up call on a few segments
(numba compiled and cached), best of ``--repeat`` runs.

Usage::

    python benchmarks/bench_segments.py --out benchmarks/results/segments.json
"""

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from measure import provenance

ROOT = Path(__file__).resolve().parent
DEFAULT_DATA = str(ROOT.parents[1] / "shared" / "data" / "dales_objects")


def _steps(n_jobs):
    from skpcd.features import ImprovedPFHTransformer, OverallDescriptor
    from skpcd.preprocessing import GridSampler, NormalEstimator

    return {
        "grid sampling (0.5 m)": GridSampler(voxel_size=0.5),
        "grid sampling (auto)": GridSampler(),
        "normals (k=10)": NormalEstimator(n_neighbors=10, n_jobs=n_jobs),
        "improved PFH (k=10)": ImprovedPFHTransformer(n_neighbors=10, n_jobs=n_jobs),
        "improved FPFH (k=10)": ImprovedPFHTransformer(
            "fpfh", n_neighbors=10, n_jobs=n_jobs
        ),
        "improved PFH (r=0.9)": ImprovedPFHTransformer(radius=0.9, n_jobs=n_jobs),
        "overall descriptor": OverallDescriptor(),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", help="write the results as JSON (and .txt alongside)")
    a = ap.parse_args(argv)

    from skpcd.io import read_segments

    clouds, _, _ = read_segments(a.data)
    n_points = sum(len(c) for c in clouds)
    rows = []
    for n_jobs in (1, 2):
        for name, est in _steps(n_jobs).items():
            est.fit_transform(clouds[:5])  # compile or load the kernels
            best = np.inf
            for _ in range(a.repeat):
                t = time.perf_counter()
                est.fit_transform(clouds)
                best = min(best, time.perf_counter() - t)
            rows.append(
                {
                    "step": name,
                    "n_jobs": n_jobs,
                    "seconds": best,
                    "segments_per_s": len(clouds) / best,
                    "points_per_s": n_points / best,
                }
            )
            print(
                f"{name:24s} n_jobs={n_jobs}  {best:7.2f} s  "
                f"{len(clouds) / best:8.1f} segments/s  {n_points / best:10.0f} pts/s",
                flush=True,
            )
    text = [
        f"skpcd segment-level steps, {len(clouds)} DALES objects, {n_points} points",
        f"machine: {platform.processor() or platform.machine()}, "
        f"nproc={os.cpu_count()}, load {os.getloadavg()}",
        "",
        f"{'step':24s} {'n_jobs':>6s} {'seconds':>8s} {'segments/s':>11s}",
    ]
    text += [
        f"{r['step']:24s} {r['n_jobs']:6d} {r['seconds']:8.2f} "
        f"{r['segments_per_s']:11.1f}"
        for r in rows
    ]
    print("\n".join(text))
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(
            json.dumps(
                {**provenance(), "n_segments": len(clouds), "rows": rows}, indent=1
            )
            + "\n"
        )
        Path(a.out).with_suffix(".txt").write_text("\n".join(text) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
