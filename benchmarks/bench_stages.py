"""Speed of each stage, one checkout against another (a before/after check
of a change that should not change speed).

Each stage runs in a fresh process with the checkout on ``PYTHONPATH``: one
untimed call (numba kernels compiled or loaded from the cache), then the
best of 3 timed calls (2 for ``identify``); the two checkouts alternate,
round by round, and the best time of the rounds is kept.

Stages and data (``../shared/data/real_mobile/scans``, the 12 real KITTI and
PandaSet sweeps, or ``--scans``):

- ``read_las``: ``read_point_cloud`` of the 12 sweeps;
- ``ground_smrf``: ``GroundFilter(**GROUND_PRESETS["mobile"], n_jobs=2)`` on 6
  sweeps; ``ground_csf``: the ``"street"`` preset (CSF and the bases pass) on
  2; ``segment``: ``segment_scene(n_jobs=2)`` with its defaults on 2;
- ``pfh``, ``fpfh``: ``PFHTransformer`` / ``FPFHTransformer(n_jobs=2)`` on
  ``make_urban_objects(random_state=0)`` (200 objects); ``identify``: fit and
  predict of ``make_default_pipeline(n_jobs=2)`` on them;
- ``simulate``: ``make_street_objects(3, random_state=0)``.

    python benchmarks/bench_stages.py BEFORE_CHECKOUT AFTER_CHECKOUT --rounds 3 \\
        --out benchmarks/results/stages.json

Results: the best wall-clock time and the best CPU time (all threads of the
process) of each stage for each checkout and their ratios, with each
checkout's commit, the machine, the date and the load. On a loaded machine
the CPU times are the steadier figure: another process takes cores from the
stage, not instructions.
"""

import argparse
import glob
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from measure import machine, write_results

STAGES = (
    "read_las", "ground_smrf", "ground_csf", "segment", "pfh", "fpfh",
    "identify", "simulate",
)  # fmt: skip
SCANS = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "real_mobile" / "scans"
)


def _best(f, n=3):
    """The best wall-clock and the best CPU time of ``n`` calls after one."""
    f()
    wall, cpu = [], []
    for _ in range(n):
        start, start_cpu = time.perf_counter(), time.process_time()
        f()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return min(wall), min(cpu)


def run_stage(stage, scans):
    """The best wall-clock and CPU times of one stage, in this process."""
    paths = sorted(glob.glob(os.path.join(scans, "*.las")))
    if stage == "read_las":
        from skpcd.io import read_point_cloud

        return _best(lambda: [read_point_cloud(p) for p in paths])
    if stage in ("ground_smrf", "ground_csf", "segment"):
        from skpcd.io import read_point_cloud
        from skpcd.segmentation import GROUND_PRESETS, GroundFilter, segment_scene

        clouds = [read_point_cloud(p) for p in paths[3:9]]
        if stage == "ground_smrf":
            preset = GROUND_PRESETS["mobile"]
            return _best(
                lambda: [GroundFilter(**preset, n_jobs=2).fit(c) for c in clouds]
            )
        clouds = clouds[:2]  # CSF: seconds a sweep
        if stage == "ground_csf":
            preset = GROUND_PRESETS["street"]
            return _best(
                lambda: [GroundFilter(**preset, n_jobs=2).fit(c) for c in clouds]
            )
        return _best(lambda: [segment_scene(c, n_jobs=2) for c in clouds])
    if stage == "simulate":
        from skpcd.datasets import make_street_objects

        return _best(lambda: make_street_objects(3, random_state=0), n=2)
    from skpcd.datasets import make_urban_objects

    X, y = make_urban_objects(random_state=0)
    if stage == "pfh":
        from skpcd.features import PFHTransformer

        return _best(lambda: PFHTransformer(n_jobs=2).fit_transform(X))
    if stage == "fpfh":
        from skpcd.features import FPFHTransformer

        return _best(lambda: FPFHTransformer(n_jobs=2).fit_transform(X))
    from skpcd.classification import make_default_pipeline

    model = make_default_pipeline(n_jobs=2)
    return _best(lambda: model.fit(X, y).predict(X), n=2)


def _in_checkout(checkout, stage, scans):
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    cmd = [sys.executable, __file__, "--stage", stage, "--scans", str(scans)]
    done = subprocess.run(cmd, cwd=checkout, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{stage} in {checkout}: {done.stderr[-500:]}")
    wall, cpu = done.stdout.split()[-2:]
    return {"wall": float(wall), "cpu": float(cpu)}


def _commit(checkout):
    return subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=checkout, capture_output=True,
        text=True,
    ).stdout.strip()  # fmt: skip


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkouts", nargs="*", help="BEFORE AFTER")
    parser.add_argument("--stages", nargs="+", default=STAGES, choices=STAGES)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--scans", default=str(SCANS))
    parser.add_argument("--stage", help=argparse.SUPPRESS)
    parser.add_argument("--out", default=None)
    parser.add_argument(
        "--merge",
        default=None,
        help="a results file of an earlier run of the same two commits: its stages "
        "not measured now are kept (each stage records the date of its run)",
    )
    args = parser.parse_args()
    if args.stage:
        print(*run_stage(args.stage, args.scans))
        return
    before, after = (Path(c).resolve() for c in args.checkouts)
    result = {
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "load_start": list(os.getloadavg()),
        "machine": machine(),
        "commit": {"before": _commit(before), "after": _commit(after)},
        "scans": str(args.scans),
        "rounds": args.rounds,
        "stages": {},
    }
    for stage in args.stages:
        for checkout in (before, after):
            _in_checkout(checkout, stage, args.scans)  # compile, untimed
        runs = {"before": [], "after": []}
        for _ in range(args.rounds):
            for name, checkout in (("before", before), ("after", after)):
                runs[name].append(_in_checkout(checkout, stage, args.scans))
        entry = {"date": result["date"]}
        for clock in ("wall", "cpu"):
            best = {k: min(r[clock] for r in v) for k, v in runs.items()}
            ratio = best["after"] / best["before"]
            entry[clock] = {**best, "ratio": ratio}
            print(
                f"{stage:12s} {clock:4s} before {best['before']:.3f} s  "
                f"after {best['after']:.3f} s  after/before {ratio:.2f}",
                flush=True,
            )
        result["stages"][stage] = {**entry, "runs": runs}
    result["load_end"] = list(os.getloadavg())
    if args.merge:
        earlier = json.loads(Path(args.merge).read_text())
        if earlier["commit"] != result["commit"]:
            raise SystemExit(
                f"{args.merge} compares other commits: {earlier['commit']}"
            )
        kept = {k: v for k, v in earlier["stages"].items() if k not in result["stages"]}
        result["stages"] = {**kept, **result["stages"]}
    if args.out:
        write_results(args.out, result, _text(result))


def _text(result):
    """The results as the table of ``stages.txt``."""
    lines = [
        "skpcd stage speed, before / after (benchmarks/bench_stages.py)",
        f"  run: {result['date']}, commits {result['commit']['before']} -> "
        f"{result['commit']['after']}, {result['rounds']} rounds, load "
        f"{result['load_start'][0]:.2f} -> {result['load_end'][0]:.2f}",
        f"  machine: {result['machine']}; data: {result['scans']} and "
        "make_urban_objects(random_state=0)",
        "",
        f"{'stage':12s}{'wall before':>12s}{'after':>8s}{'ratio':>7s}"
        f"{'CPU before':>12s}{'after':>8s}{'ratio':>7s}",
    ]
    for stage, e in result["stages"].items():
        w, c = e["wall"], e["cpu"]
        lines.append(
            f"{stage:12s}{w['before']:12.3f}{w['after']:8.3f}{w['ratio']:7.2f}"
            f"{c['before']:12.3f}{c['after']:8.3f}{c['ratio']:7.2f}"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
