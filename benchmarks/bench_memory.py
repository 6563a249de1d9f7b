"""Does each memory measure of ``skpcd.utils._memory`` still pay?

Every row runs in a fresh process: the DALES objects (or ``--data``) as one
list, the descriptor computed twice in a row (the second call shows what
the first one left resident), with all measures on and with one of them
switched off by patching it out:

* ``no malloc_trim``: :func:`~skpcd.utils._memory.release_free_memory` does
  nothing;
* ``no own map``: outputs from ``np.zeros`` instead of
  :func:`~skpcd.utils._memory.unshared_zeros`;
* ``normals kept``: FPFH keeps the normals alive through its last stage
  instead of freeing them after the SPFH.

Reported: peak RSS of the worker (``ru_maxrss``) minus its RSS after loading
the data and a warm-up call on one object, and the wall time of the two
calls. ``heap_for_arrays`` (glibc's mmap threshold in a Dask worker) is
not measured here: it needs a ``dask.distributed`` nanny, see
``tests/utils/test_dask.py`` and its docstring.

Usage::

    python benchmarks/bench_memory.py            # k = 10 and radius PFH
    python benchmarks/bench_memory.py --quick    # fewer objects
"""

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
DEFAULT_DATA = str(ROOT.parents[1] / "shared" / "data" / "dales_objects")
VARIANTS = ("all measures", "no malloc_trim", "no own map", "normals kept")
CASES = {
    "fpfh k=10": ("FPFHTransformer", {"n_neighbors": 10}),
    "pfh k=10": ("PFHTransformer", {"n_neighbors": 10}),
    "pfh radius 0.9": ("PFHTransformer", {"radius": 0.9}),
}


def _rss_mib():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")  # pragma: no cover - not Linux


def _patch(variant):
    import skpcd.features._fpfh as fpfh
    import skpcd.features._local_descriptor as local
    import skpcd.utils._memory as memory

    if variant == "no malloc_trim":
        for mod in (memory, local, fpfh):
            mod.release_free_memory = lambda: None
    elif variant == "no own map":
        fpfh.unshared_zeros = local.unshared_zeros = np.zeros
    elif variant == "normals kept":
        kept = []
        pair_stage = fpfh.FPFHTransformer._pair_stage

        def keeping(self, p, n, *args):
            kept.append(n)
            return pair_stage(self, p, n, *args)

        def final(self, *args, _final=fpfh.FPFHTransformer._final_stage):
            try:
                return _final(self, *args)
            finally:
                kept.clear()

        fpfh.FPFHTransformer._pair_stage = keeping
        fpfh.FPFHTransformer._final_stage = final


def worker(spec):
    """One row: fresh process, patched, the case run twice."""
    import skpcd.features as features

    _patch(spec["variant"])
    arrays = np.load(spec["data"])
    clouds = [arrays[k] for k in arrays.files]
    name, params = CASES[spec["case"]]
    est = getattr(features, name)(n_jobs=spec["threads"], **params)
    est.transform(clouds[:1])  # warm-up: compile/load the kernels
    base = _rss_mib()
    t0 = time.perf_counter()
    for _ in range(2):
        out = est.transform(clouds)
        del out
    wall = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"peak_mib": peak - base, "wall_s": wall}))


def _load(data, quick):
    files = sorted(Path(data).glob("*.xyz"))
    if quick:
        files = files[:60]
    return [np.loadtxt(f, usecols=(0, 1, 2)) for f in files]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=DEFAULT_DATA)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated")
    parser.add_argument(
        "--variants", default=",".join(VARIANTS), help="comma-separated"
    )
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(json.loads(args.worker))
        return
    clouds = _load(args.data, args.quick)
    n_points = sum(map(len, clouds))
    with tempfile.TemporaryDirectory() as tmp:
        data = str(Path(tmp) / "clouds.npz")
        np.savez(data, *clouds)
        print(f"{len(clouds)} clouds, {n_points} points, {args.threads} threads")
        print(f"{'case':<16}{'variant':<16}{'peak MiB':>10}{'wall s':>9}")
        for case in args.cases.split(","):
            for variant in args.variants.split(","):
                if variant == "normals kept" and not case.startswith("fpfh"):
                    continue
                spec = {"case": case, "variant": variant, "data": data}
                spec["threads"] = args.threads
                run = subprocess.run(
                    [sys.executable, __file__, "--worker", json.dumps(spec)],
                    capture_output=True,
                    text=True,
                    check=True,
                )
                row = json.loads(run.stdout.strip().splitlines()[-1])
                print(
                    f"{case:<16}{variant:<16}{row['peak_mib']:>10.1f}"
                    f"{row['wall_s']:>9.2f}"
                )


if __name__ == "__main__":
    main()
