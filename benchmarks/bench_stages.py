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

Results: the best time of each stage for each checkout and their ratio,
with each checkout's commit, the machine, the date and the load.
"""

import argparse
import glob
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from measure import machine

STAGES = (
    "read_las", "ground_smrf", "ground_csf", "segment", "pfh", "fpfh",
    "identify", "simulate",
)  # fmt: skip
SCANS = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "real_mobile" / "scans"
)


def _best(f, n=3):
    f()
    times = []
    for _ in range(n):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times)


def run_stage(stage, scans):
    """The best time of one stage, in this process (see the module docstring)."""
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
    return float(done.stdout.split()[-1])


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
        print(run_stage(args.stage, args.scans))
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
        times = {"before": [], "after": []}
        for _ in range(args.rounds):
            for name, checkout in (("before", before), ("after", after)):
                times[name].append(_in_checkout(checkout, stage, args.scans))
        best = {k: min(v) for k, v in times.items()}
        result["stages"][stage] = {
            **best, "ratio": best["after"] / best["before"], "times": times,
            "date": result["date"],
        }  # fmt: skip
        ratio = best["after"] / best["before"]
        print(
            f"{stage:12s} before {best['before']:.3f} s  after {best['after']:.3f} s"
            f"  after/before {ratio:.2f}",
            flush=True,
        )
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
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
