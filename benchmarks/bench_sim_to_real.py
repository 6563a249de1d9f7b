"""Does a model trained on simulated streets recognise real objects?

Each *recipe* is a way of simulating the training objects (scan pattern,
domain randomisation) and of describing them (the identification
pipeline). A model is fitted on the recipe's simulated objects of the
street model's classes (:data:`skpcd.classification.STREET_MODEL_CLASSES`)
and asked about the real objects of ``../shared/data/real_mobile/objects``
(PandaSet and KITTI sweeps of 64-beam spinning sensors, cut from their
labelled boxes): its recall on real cars, people and traffic signs, their
balanced accuracy (the figure that ranks the recipes), and what the real
cones and barriers (``other_object``) are called ("other" is right).
Nothing real is used for training: this is the zero-shot score, the one a
user with no labels gets.

The recipes add one change at a time, so that each row is the measured
gain of one realism change on real data:

- ``profiler``: the simulator as it was, a Lynx-like pair of profilers
  (``scanner="mobile"``), the default pipeline.
- ``spinning``: one sweep of a 64-beam spinning sensor on a car's roof
  (``scanner="spinning"``, HDL-64E-like).
- ``randomised``: domain randomisation (``randomise=True``): sensors of 16
  to 128 beams, heights, positions along the street (ranges), noise, the
  lowest 0-0.35 m of each object cut, ground at the foot of half of them.
- ``mixed``: half spinning, half profiler streets, both randomised (a
  model for users of either kind of scanner).
- ``mixed+spacing``: the same objects, each segment first sampled on a
  grid of :data:`~skpcd.classification.STREET_VOXEL` metres
  (:func:`skpcd.classification.make_street_pipeline`).
- ``mixed+spacing+traffic``: half the simulated cars drive in the lanes
  (``make_street_objects(traffic=True)``), seen from behind and ahead as
  the traffic around a car-mounted sensor is.

Run from the repository root (about 15 minutes; simulated sets are cached
in ``--cache``)::

    python benchmarks/bench_sim_to_real.py
    python benchmarks/bench_sim_to_real.py --n-per-class 20 --recipes spinning

The results go to ``benchmarks/results/sim_to_real.{json,txt}``.
"""

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from skpcd.classification import (
    STREET_MODEL_CLASSES,
    STREET_VOXEL,
    make_default_pipeline,
    make_street_pipeline,
)
from skpcd.classification._augmented import simulate_objects
from skpcd.datasets import make_street_objects
from skpcd.io import read_segments

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from measure import commit  # noqa: E402

REAL = Path(
    os.environ.get(
        "SKPCD_REAL_MOBILE_DIR", HERE.parent.parent / "shared/data/real_mobile"
    )
)
# real label -> the street model's class that is right for it
TRUTH = {
    "car": "car",
    "person": "person",
    "traffic_sign": "traffic_sign",
    "other_object": "other",
}
SCORED = ("car", "person", "traffic_sign")


def load_real(folder=REAL):
    """The real objects whose class the street model has, and their labels."""
    objects = folder / "objects"
    clouds, labels, _ = read_segments(objects, objects / "labels.csv")
    keep = [i for i, lab in enumerate(labels) if lab in TRUTH]
    return [clouds[i] for i in keep], np.array([TRUTH[labels[i]] for i in keep])


def simulate(kind, n_per_class, seed, cache):
    """The simulated training objects of one kind, cached on disk."""
    path = Path(cache) / f"{kind}_{n_per_class}_{seed}.npz"
    if path.exists():
        data = np.load(path, allow_pickle=False)
        sizes = data["sizes"]
        return np.split(data["points"], np.cumsum(sizes)[:-1]), data["labels"]
    common = {
        "classes": STREET_MODEL_CLASSES,
        "min_points": 20,
        "n_jobs": -1,
        "random_state": seed,
    }
    if kind == "profiler":
        clouds, labels = make_street_objects(n_per_class, scanner="mobile", **common)
    elif kind == "spinning":
        clouds, labels = make_street_objects(n_per_class, scanner="spinning", **common)
    elif kind.startswith("randomised-"):
        scanner = kind.split("-")[-1]
        clouds, labels = simulate_objects(
            STREET_MODEL_CLASSES,
            n_per_class,
            scanner,
            seed,
            n_jobs=-1,
            traffic="-traffic-" in kind,
        )
    else:
        raise ValueError(kind)
    clouds = [c - c.mean(axis=0) for c in clouds]
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        path,
        points=np.vstack(clouds),
        sizes=np.array([len(c) for c in clouds]),
        labels=np.asarray(labels, dtype=str),
    )
    return clouds, np.asarray(labels)


RECIPES = {
    "profiler": (["profiler"], "default"),
    "spinning": (["spinning"], "default"),
    "randomised": (["randomised-spinning"], "default"),
    "randomised+spacing": (["randomised-spinning"], "street"),
    "mixed": (["randomised-spinning", "randomised-mobile"], "default"),
    "mixed+spacing": (["randomised-spinning", "randomised-mobile"], "street"),
    "mixed+spacing+traffic": (
        ["randomised-traffic-spinning", "randomised-traffic-mobile"],
        "street",
    ),
}


def pipeline(name, voxel_size=STREET_VOXEL):
    if name == "default":
        return make_default_pipeline(n_jobs=-1)
    return make_street_pipeline(voxel_size=voxel_size, n_jobs=-1)


def score(pred, truth):
    rows = {}
    for c in (*SCORED, "other"):
        m = truth == c
        rows[c] = {
            "n": int(m.sum()),
            "recall": float((pred[m] == c).mean()) if m.any() else None,
            "called": dict(
                zip(*[a.tolist() for a in np.unique(pred[m], return_counts=True)])
            ),
        }
    rows["balanced_accuracy"] = float(np.mean([rows[c]["recall"] for c in SCORED]))
    return rows


def run(name, args, real, truth):
    """One recipe over the seeds: the mean recalls and their spread."""
    kinds, pipe = RECIPES[name]
    runs, t_sim, t_fit = [], 0.0, 0.0
    for seed in args.seeds:
        t0 = time.perf_counter()
        parts = [simulate(k, args.n_per_class, seed, args.cache) for k in kinds]
        clouds = [c for p in parts for c in p[0]]
        labels = np.concatenate([p[1] for p in parts])
        t_sim += time.perf_counter() - t0
        t0 = time.perf_counter()
        model = pipeline(pipe, args.voxel).fit(clouds, labels)
        runs.append(score(np.asarray(model.predict(real)), truth))
        t_fit += time.perf_counter() - t0
    balanced = [r["balanced_accuracy"] for r in runs]
    called = {}
    for r in runs:
        for k, v in r["car"]["called"].items():
            called[k] = called.get(k, 0) + v
    return {
        "simulated": kinds,
        "pipeline": pipe,
        "voxel_size": None if pipe == "default" else args.voxel,
        "seeds": args.seeds,
        "n_train": len(clouds),
        "seconds_simulate": round(t_sim, 1),
        "seconds_fit_predict": round(t_fit, 1),
        "balanced_accuracy": float(np.mean(balanced)),
        "balanced_accuracy_std": float(np.std(balanced)),
        **{
            c: {
                "n": runs[0][c]["n"],
                "recall": float(np.mean([r[c]["recall"] for r in runs])),
            }
            for c in (*SCORED, "other")
        },
        "cars_called": called,
        "runs": runs,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-per-class", type=int, default=40)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--voxel", type=float, default=STREET_VOXEL)
    ap.add_argument("--recipes", default=",".join(RECIPES))
    ap.add_argument("--cache", default=str(HERE / ".cache" / "sim_to_real"))
    ap.add_argument("--out", default=str(HERE / "results" / "sim_to_real"))
    ap.add_argument("--merge", action="store_true", help="keep other recipes' rows")
    args = ap.parse_args(argv)
    real, truth = load_real()
    out = Path(args.out)
    results = {}
    if args.merge and out.with_suffix(".json").exists():
        results = json.loads(out.with_suffix(".json").read_text())["recipes"]
    for name in args.recipes.split(","):
        key = name if RECIPES[name][1] == "default" else f"{name} {args.voxel:g}"
        results[key] = r = run(name, args, real, truth)
        print(
            f"{key:22s} balanced {r['balanced_accuracy']:.3f} "
            f"+/- {r['balanced_accuracy_std']:.3f}  "
            + "  ".join(f"{c} {r[c]['recall']:.3f}" for c in (*SCORED, "other")),
            flush=True,
        )
    meta = {
        "commit": commit(),
        "machine": f"{platform.machine()} {os.cpu_count()} cores",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "n_per_class": args.n_per_class,
        "real": f"{REAL}/objects ({len(real)} objects: "
        + ", ".join(f"{c} {int((truth == c).sum())}" for c in np.unique(truth))
        + ")",
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(
        json.dumps({"meta": meta, "recipes": results}, indent=1)
    )
    lines = [
        "Zero-shot: trained on simulated objects only, scored on real objects",
        f"real: {meta['real']}",
        f"simulated: {args.n_per_class} per class of {len(STREET_MODEL_CLASSES)}"
        f" per kind; commit {meta['commit']}, {meta['machine']}, {meta['date']}",
        "recall per real class, mean over the simulation seeds; balanced = mean "
        "recall of car, person, sign (+/- its std over the seeds)",
        "",
        f"{'recipe':22s} {'balanced':>14s} {'car':>6s} {'person':>6s} "
        f"{'sign':>6s} {'other':>6s}  real cars called (all seeds)",
    ]
    for name, r in results.items():
        cars = sorted(r["cars_called"].items(), key=lambda kv: -kv[1])[:3]
        lines.append(
            f"{name:22s} {r['balanced_accuracy']:6.3f} +/- "
            f"{r['balanced_accuracy_std']:.3f} {r['car']['recall']:6.3f} "
            f"{r['person']['recall']:6.3f} {r['traffic_sign']['recall']:6.3f} "
            f"{r['other']['recall']:6.3f}  " + ", ".join(f"{k} {v}" for k, v in cars)
        )
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
