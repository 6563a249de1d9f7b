"""Does the order of the points change the speed? A cloud in recorded order
against the same cloud shuffled, for each local descriptor and the normals.

The 399 DALES objects concatenated as one cloud (882,733 points, k = 10), in
their recorded order and shuffled (seeded permutation). ``FPFHTransformer``
renumbers a shuffled cloud in grid order (``scattered`` decides); the rows
``renumbering off`` and ``renumbering forced`` switch that decision off for
the shuffled cloud and on for the recorded one, to show what it gains and
what it would cost. Every row is the best of ``--repeat`` runs after a
warm-up, two threads, all in one process (the same warm caches for all).
The outputs of the renumbered and the plain runs are compared bit for bit,
and FPFH's peak memory (VmHWM above a process warmed up on 2,000 points) is
measured on both clouds, each in a fresh process, against input and output.

Usage::

    python benchmarks/bench_point_order.py --out benchmarks/results/point_order.json
"""

import argparse
import datetime
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

from bench_threads import dales  # noqa: E402
from measure import (  # noqa: E402
    best_of,
    commit,
    maxrss_mb,
    reset_peak,
)

K = 10


def _best(call, repeat):
    call()  # warm-up: kernels loaded, pages of the pools touched
    out, best = best_of(repeat, call)
    return best, out


def _same(a, b):
    return all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))


def _clouds():
    cloud = np.vstack(dales())
    return cloud, cloud[np.random.default_rng(0).permutation(len(cloud))]


def peak_worker(variant, threads):
    """FPFH's peak memory (VmHWM above the process warmed up on 2,000
    points) on one cloud, in this fresh process; prints a JSON row."""
    from skpcd.features import FPFHTransformer

    cloud = _clouds()[variant == "shuffled"]
    est = FPFHTransformer(n_neighbors=K, n_jobs=threads)
    est.fit_transform([cloud[:2000]])
    base = reset_peak()
    out = est.fit_transform([cloud])
    peak = maxrss_mb() - base
    io = (cloud.nbytes + out[0].nbytes) / 2**20
    print(json.dumps({"variant": variant, "peak_mb": peak, "io_mb": io}))


def peaks(threads):
    """:func:`peak_worker` for both clouds, each in a fresh process."""
    rows = []
    for variant in ("recorded order", "shuffled"):
        cmd = [sys.executable, __file__, "--peak", variant]
        cmd += ["--threads", str(threads)]
        res = subprocess.run(cmd, capture_output=True, text=True, check=True)
        row = json.loads(res.stdout.strip().splitlines()[-1])
        print(f"FPFH peak, {variant}: {row['peak_mb']:.1f} MB", flush=True)
        rows.append(row)
    return rows


def run(repeat, threads):
    import skpcd.features._local_descriptor as pfh_module
    from skpcd.features import (
        FPFHTransformer,
        ImprovedPFHTransformer,
        PFHTransformer,
    )
    from skpcd.preprocessing import NormalEstimator

    cloud, shuffled = _clouds()
    rows = []

    def time_it(name, variant, X, est):
        t, out = _best(lambda: est.fit_transform(X), repeat)
        rows.append({"estimator": name, "variant": variant, "seconds": t})
        print(f"{name:24s} {variant:28s} {t:7.3f} s", flush=True)
        return out

    for cls in (FPFHTransformer, PFHTransformer, ImprovedPFHTransformer):
        est = cls(n_neighbors=K, n_jobs=threads)
        time_it(cls.__name__, "recorded order", [cloud], est)
        time_it(cls.__name__, "shuffled", [shuffled], est)
    est = NormalEstimator(n_neighbors=K, n_jobs=threads)
    time_it("NormalEstimator", "recorded order", [cloud], est)
    time_it("NormalEstimator", "shuffled", [shuffled], est)

    est = FPFHTransformer(n_neighbors=K, n_jobs=threads)
    scattered = pfh_module.scattered
    try:
        pfh_module.scattered = lambda nb: False
        plain = time_it("FPFHTransformer", "shuffled, renumbering off", [shuffled], est)
        pfh_module.scattered = lambda nb: True
        forced = time_it(
            "FPFHTransformer", "recorded, renumbering forced", [cloud], est
        )
    finally:
        pfh_module.scattered = scattered
    same = _same(plain, est.fit_transform([shuffled])) and _same(
        forced, est.fit_transform([cloud])
    )
    print(f"renumbered rows equal the plain ones bit for bit: {same}", flush=True)
    return rows, same


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", help="JSON results (and .txt beside)")
    ap.add_argument("--peak", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.peak:
        peak_worker(a.peak, a.threads)
        return
    load0 = os.getloadavg()
    memory = peaks(a.threads)
    rows, same = run(a.repeat, a.threads)
    R = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(
            timespec="minutes"
        ),
        "commit": commit(),
        "load_start": load0,
        "load_end": os.getloadavg(),
        "threads": a.threads,
        "repeat": a.repeat,
        "rows": rows,
        "renumbered_equal": same,
        "peak": memory,
    }
    by = {(r["estimator"], r["variant"]): r["seconds"] for r in rows}
    lines = [
        "Point order and speed (benchmarks/bench_point_order.py)",
        f"date {R['date']}; commit {R['commit']}; load average "
        f"{load0[0]:.2f} at start, {R['load_end'][0]:.2f} at end",
        "data: the 399 DALES objects as one cloud (882,733 points), k = 10, "
        f"{a.threads} threads, best of {a.repeat} after a warm-up",
        "",
        f"{'estimator':24s} {'recorded':>9s} {'shuffled':>9s} {'ratio':>6s}",
    ]
    for name in (
        "FPFHTransformer",
        "PFHTransformer",
        "ImprovedPFHTransformer",
        "NormalEstimator",
    ):
        r, s = by[(name, "recorded order")], by[(name, "shuffled")]
        lines.append(f"{name:24s} {r:8.3f}s {s:8.3f}s {s / r:5.2f}x")
    lines += [
        "",
        "FPFH, shuffled, renumbering off: "
        f"{by[('FPFHTransformer', 'shuffled, renumbering off')]:.3f} s; "
        "recorded order, renumbering forced: "
        f"{by[('FPFHTransformer', 'recorded, renumbering forced')]:.3f} s",
        f"renumbered rows equal the plain ones bit for bit: {same}",
    ]
    for r in memory:
        lines.append(
            f"FPFH peak, {r['variant']} (fresh process): {r['peak_mb']:.1f} MB "
            f"above the warmed-up process, {r['peak_mb'] / r['io_mb']:.2f}x input "
            f"+ output ({r['io_mb']:.1f} MB)"
        )
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        Path(a.out).write_text(json.dumps(R, indent=1))
        Path(a.out).with_suffix(".txt").write_text(text)


if __name__ == "__main__":
    main()
