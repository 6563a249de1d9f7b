"""Does ``borrow`` (arrays without reference counting in the kernels) still pay?

:func:`skpcd.utils._numba.borrow` makes numba's reference counting of an
array a no-op inside the hot loops (see its module docstring). Each row
runs in a fresh process with a numba cache of its own: the kernels as
they are, and compiled with ``borrow`` replaced by the identity (reference
counting back), on the DALES objects (or ``--data``):

* the k-nearest search (k = 10) and the radius search (0.9) of all objects;
* FPFH k = 10 (search, normals, SPFH, FPFH);
* DBSCAN (the grid DBSCAN, eps 0.3) of all objects as one scene.

Times are the best of ``--repeat`` calls after one call that compiles.
``tests/utils/test_numba.py`` checks that no borrowed array escapes.

Usage::

    python benchmarks/bench_borrow.py --quick
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
DEFAULT_DATA = str(ROOT.parents[1] / "shared" / "data" / "dales_objects")


def _no_borrow():
    """Replace ``borrow`` by ``counted`` (the same arrays, reference counts
    kept) before the kernels are imported."""
    import skpcd.utils._numba as nb

    nb.borrow = nb.counted


def worker(spec):
    if spec["variant"] == "no borrow":
        _no_borrow()
    from skpcd.features import FPFHTransformer
    from skpcd.neighbors._neighbors import search_packed
    from skpcd.segmentation._clusters import grid_dbscan

    arrays = np.load(spec["data"])
    clouds = [arrays[k] for k in arrays.files]
    ptr = np.concatenate([[0], np.cumsum([len(c) for c in clouds])])
    xyz = np.ascontiguousarray(np.vstack(clouds))
    threads = spec["threads"]
    cases = {
        "knn k=10": lambda: search_packed(xyz, ptr, n_neighbors=10, n_threads=threads),
        "radius 0.9": lambda: search_packed(
            xyz, ptr, radius=0.9, n_threads=threads, with_sqdist=False
        ),
        "fpfh k=10": lambda: FPFHTransformer(10, n_jobs=threads).transform(clouds),
        "dbscan 0.3": lambda: grid_dbscan(xyz, 0.3, 5, n_jobs=threads),
    }
    out = {}
    for name, call in cases.items():
        call()  # compile
        best = np.inf
        for _ in range(spec["repeat"]):
            t0 = time.perf_counter()
            call()
            best = min(best, time.perf_counter() - t0)
        out[name] = best
    print(json.dumps(out))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=DEFAULT_DATA)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(json.loads(args.worker))
        return
    files = sorted(Path(args.data).glob("*.xyz"))[: 60 if args.quick else None]
    clouds = [np.loadtxt(f, usecols=(0, 1, 2)) for f in files]
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        data = str(Path(tmp) / "clouds.npz")
        np.savez(data, *clouds)
        for variant in ("borrow", "no borrow"):
            spec = {"variant": variant, "data": data}
            spec.update(threads=args.threads, repeat=args.repeat)
            env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / variant))
            run = subprocess.run(
                [sys.executable, __file__, "--worker", json.dumps(spec)],
                capture_output=True,
                text=True,
                check=True,
                env=env,
            )
            rows[variant] = json.loads(run.stdout.strip().splitlines()[-1])
    n = sum(map(len, clouds))
    print(f"{len(clouds)} clouds, {n} points, {args.threads} threads")
    print(f"{'case':<14}{'borrow s':>10}{'no borrow s':>13}{'ratio':>8}")
    for case, t in rows["borrow"].items():
        u = rows["no borrow"][case]
        print(f"{case:<14}{t:>10.3f}{u:>13.3f}{u / t:>8.2f}")


if __name__ == "__main__":
    main()
