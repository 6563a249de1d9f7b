"""Rebuild the street model shipped in ``skpcd/classification/street_model.skpcd``.

Simulated objects only (:func:`skpcd.datasets.make_street_objects` with
``randomise=True`` and ``traffic=True``), so the file carries the project's
licence: for each scan pattern of ``--scanners``, ``--n-per-class`` objects
of every class of :data:`skpcd.classification.STREET_MODEL_CLASSES`,
fitted with :func:`skpcd.classification.make_street_pipeline`, its
probabilities calibrated by temperature scaling on simulated objects of
another seed. The recipe is the one ``bench_sim_to_real.py`` ranked first
on real scans; the file keeps it in
its metadata, with a model version and probe clouds whose answers
:func:`skpcd.classification.load_street_model` checks at every load.

Run from the repository root (about 5 minutes on two cores)::

    python benchmarks/build_street_model.py
"""

import argparse
import time

import numpy as np
from sklearn.calibration import CalibratedClassifierCV
from sklearn.frozen import FrozenEstimator

from skpcd import __version__
from skpcd.classification import (
    STREET_MODEL_CLASSES,
    STREET_MODEL_PATH,
    STREET_VOXEL,
    RejectUnknown,
    make_street_pipeline,
)
from skpcd.classification._augmented import simulate_objects
from skpcd.io import save_model

#: Bumped whenever the recipe or the simulator changes what the model learns.
MODEL_VERSION = "street-1"


def simulated(n_per_class, scanners, seed):
    clouds, labels = [], []
    for k, scanner in enumerate(scanners):
        c, y = simulate_objects(
            STREET_MODEL_CLASSES, n_per_class, scanner, seed + k, n_jobs=-1
        )
        clouds += c
        labels.append(y)
    return clouds, np.concatenate(labels).astype(str)


def build(n_per_class, scanners, seed):
    """The street pipeline fitted on simulated objects, its probabilities
    then calibrated by temperature scaling on other simulated objects (a
    held-out seed): the forest's votes spread over eleven classes and
    understate its confidence; a temperature keeps every answer."""
    clouds, labels = simulated(n_per_class, scanners, seed)
    model = make_street_pipeline(n_jobs=-1).fit(clouds, labels)
    held_out, held_labels = simulated(n_per_class, scanners, seed + 100)
    forest = model[-1].estimator_
    calibrated = CalibratedClassifierCV(FrozenEstimator(forest), method="temperature")
    model.steps[-1] = (
        "classifier",
        RejectUnknown(calibrated).fit(model[:-1].transform(held_out), held_labels),
    )
    return model, clouds, labels


def probe(model, clouds, labels, rng):
    """A few small training clouds (mm) and the model's answers on them."""
    picked = []
    for cls in ("car", "person", "pole", "tree"):
        i = int(rng.choice(np.flatnonzero(labels == cls)))
        c = clouds[i]
        c = c[rng.choice(len(c), size=min(len(c), 150), replace=False)]
        picked.append(np.round(c, 3))
    proba = model.predict_proba(picked)
    return {"clouds": [c.tolist() for c in picked], "proba": proba.tolist()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-per-class", type=int, default=40)
    ap.add_argument("--scanners", default="spinning,mobile")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--output", default=str(STREET_MODEL_PATH))
    args = ap.parse_args(argv)
    scanners = args.scanners.split(",")
    start = time.perf_counter()
    model, clouds, labels = build(args.n_per_class, scanners, args.seed)
    metadata = {
        "model_version": MODEL_VERSION,
        "skpcd_release": __version__,
        "data": "simulated streets only (skpcd.datasets.make_street_objects, "
        "randomise=True); no real scan",
        "recipe": {
            "scanners": scanners,
            "n_per_class": args.n_per_class,
            "randomise": True,
            "traffic": True,
            "seed": args.seed,
            "voxel_size": STREET_VOXEL,
            "calibration": "temperature scaling on simulated objects of seed + 100",
            "chosen_by": "benchmarks/bench_sim_to_real.py",
        },
        "classes": {c: int((labels == c).sum()) for c in STREET_MODEL_CLASSES},
        "probe": probe(model, clouds, labels, np.random.RandomState(args.seed)),
    }
    model.set_params(sample__n_jobs=None, features__pfh__n_jobs=None)
    model[-1].estimator_.estimator.estimator.set_params(n_jobs=None)
    save_model(model, args.output, metadata=metadata, overwrite=True)
    print(
        f"{args.output}: {len(labels)} simulated objects, "
        f"{time.perf_counter() - start:.0f} s"
    )


if __name__ == "__main__":
    main()
