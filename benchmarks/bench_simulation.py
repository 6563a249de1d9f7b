"""Speed of the street scan simulation (:func:`skpcd.datasets.make_street_scene`).

For each scan pattern (its default numbers, ``SCAN_PATTERNS``) over a
100 m street: the time to lay the street out (Python), to build the grid,
and to cast every pulse (numba, one thread unless said), best of
``--repeat``; returns per second is the headline (the brief asks for at
least a million on one core). CPU seconds of the process are reported
beside wall seconds: on a shared machine the wall clock includes waiting
for the core. Then the end-to-end :func:`make_street_objects` for a few
objects per class.

Run from the repository root::

    python benchmarks/bench_simulation.py            # about 3 minutes
    python benchmarks/bench_simulation.py --quick    # 30 m streets

The results go to ``benchmarks/results/simulation.{json,txt}``.
"""

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from measure import commit, provenance

from skpcd.datasets import make_street_objects
from skpcd.datasets._street._layout import Street, build_scene, furnish
from skpcd.datasets._street._scanners import (
    build_grid,
    plan_scan,
    resolve_pattern,
    scan,
)

HERE = Path(__file__).resolve().parent


def _timed(fn, repeat):
    """Best (wall, cpu) seconds of ``repeat`` calls, and the last result."""
    best_wall = best_cpu = np.inf
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        best_wall = min(best_wall, time.perf_counter() - w)
        best_cpu = min(best_cpu, time.process_time() - c)
    return best_wall, best_cpu, out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--length", type=float, default=100.0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=str(HERE / "results" / "simulation.json"))
    a = p.parse_args(argv)
    if a.quick:
        a.length, a.repeat = 30.0, 1

    # warm up: compile (or load from numba's cache) the kernels
    rng = np.random.RandomState(0)
    street = Street(rng, 20.0)
    scene, _ = build_scene(street, furnish(street, rng), rng)
    conf = resolve_pattern("ugv")
    scan(plan_scan("ugv", conf, street), conf, scene, build_grid(scene), 0)

    rows = []
    for pattern, n_jobs in (("mobile", 1), ("mobile", 2), ("aerial", 1), ("ugv", 1)):
        rng = np.random.RandomState(7)
        t = time.perf_counter()
        street = Street(rng, a.length)
        plan = furnish(street, rng)
        scene, frame = build_scene(street, plan, rng)
        t_layout = time.perf_counter() - t
        t = time.perf_counter()
        grid = build_grid(scene)
        t_grid = time.perf_counter() - t
        conf = resolve_pattern(pattern)
        sp = plan_scan(pattern, conf, street)
        wall, cpu, out = _timed(
            lambda sp=sp, conf=conf, scene=scene, grid=grid, n_jobs=n_jobs: scan(
                sp, conf, scene, grid, 5, n_jobs=n_jobs
            ),
            a.repeat,
        )
        n_ret = len(out[0])
        row = {
            "pattern": pattern,
            "n_jobs": n_jobs,
            "length_m": a.length,
            "primitives": len(scene["kind"]),
            "instances": len(frame),
            "pulses": sp["n_pulses"],
            "returns": n_ret,
            "layout_s": t_layout,
            "grid_s": t_grid,
            "scan_wall_s": wall,
            "scan_cpu_s": cpu,
            "returns_per_s_wall": n_ret / wall,
            "returns_per_cpu_s": n_ret / cpu,
            "pulses_per_s_wall": sp["n_pulses"] / wall,
        }
        rows.append(row)
        print(
            f"{pattern:7s} n_jobs={n_jobs} pulses {sp['n_pulses']:>10d} returns "
            f"{n_ret:>9d}  scan {wall:6.2f} s wall / {cpu:6.2f} s cpu  "
            f"{n_ret / wall / 1e6:5.2f} M returns/s wall, "
            f"{n_ret / cpu / 1e6:5.2f} M per cpu-s",
            flush=True,
        )

    n_obj = 1 if a.quick else 4
    wall, cpu, (clouds, _) = _timed(
        lambda: make_street_objects(n_obj, random_state=0), 1
    )
    objects = {
        "n_per_class": n_obj,
        "objects": len(clouds),
        "points": int(sum(len(c) for c in clouds)),
        "wall_s": wall,
        "cpu_s": cpu,
    }
    print(f"make_street_objects({n_obj}): {len(clouds)} objects in {wall:.1f} s")

    text = [
        f"skpcd street scan simulation, {a.length:g} m streets (random_state 7), "
        "default scan patterns (SCAN_PATTERNS)",
        f"machine: {platform.processor() or platform.machine()}, "
        f"nproc={os.cpu_count()}, load {tuple(round(x, 2) for x in os.getloadavg())}, "
        f"commit {commit()}",
        f"best of {a.repeat}; cpu = CPU seconds of the process (one thread unless "
        "n_jobs=2)",
        "",
        f"{'pattern':8s} {'n_jobs':>6s} {'prims':>6s} {'pulses':>10s} "
        f"{'returns':>9s} {'layout s':>8s} {'grid s':>7s} {'scan s':>7s} "
        f"{'cpu s':>7s} {'Mret/s':>7s} {'Mret/cpu-s':>10s}",
    ]
    text += [
        f"{r['pattern']:8s} {r['n_jobs']:6d} {r['primitives']:6d} {r['pulses']:10d} "
        f"{r['returns']:9d} {r['layout_s']:8.2f} {r['grid_s']:7.3f} "
        f"{r['scan_wall_s']:7.2f} {r['scan_cpu_s']:7.2f} "
        f"{r['returns_per_s_wall'] / 1e6:7.2f} {r['returns_per_cpu_s'] / 1e6:10.2f}"
        for r in rows
    ]
    text += [
        "",
        f"make_street_objects(n_per_class={n_obj}, default classes, mobile): "
        f"{objects['objects']} objects, {objects['points']} points, "
        f"{objects['wall_s']:.1f} s wall, {objects['cpu_s']:.1f} s cpu",
    ]
    print("\n".join(text))
    if a.out and not a.quick:
        out = Path(a.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(
            json.dumps(
                {
                    **provenance(),
                    "rows": rows,
                    "objects": objects,
                    "load": os.getloadavg(),
                },
                indent=1,
            )
            + "\n"
        )
        out.with_suffix(".txt").write_text("\n".join(text) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
