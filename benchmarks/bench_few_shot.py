"""Zero, a few and many real labels: the shipped model, SimulationAugmented, real only.

On a folder of real labelled objects (``read_segments`` layout), for each
``k`` of ``--shots``, ``--repeats`` times: draw ``k`` objects of every class
(the training set of a user who labelled a handful), and score on all the
others

- ``real only``: :func:`skpcd.classification.make_street_pipeline` fitted
  on the ``k`` per class;
- ``simulation + real``: :class:`skpcd.classification.SimulationAugmented`
  (its defaults unless ``--real-weight``/``--n-per-class``) on the same;

and, as ``k = 0``, the shipped street model
(:func:`skpcd.classification.load_street_model`, no real label) on every
object. Scores are the balanced accuracy over the classes of the folder
that the street model knows (labels are mapped: ``other_object`` ->
``other``; classes it does not know, and classes with fewer than
``max(shots) + 3`` objects, are left out), and the recall per class.

``../shared/data/real_mobile/objects`` is the set the defaults were chosen
on; the folders of ``../shared/data/extra_real`` (SemanticKITTI sequence
07, PandaSet semantic segmentation, nuScenes) were kept aside and are only
scored.

Run from the repository root (``EXTRA`` is ``../shared/data/extra_real``)::

    python benchmarks/bench_few_shot.py            # real_mobile
    python benchmarks/bench_few_shot.py --real EXTRA/objects_nuscenes

The results go to ``benchmarks/results/few_shot_<folder>.{json,txt}``.
"""

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from sklearn.metrics import balanced_accuracy_score

from skpcd.classification import (
    STREET_MODEL_CLASSES,
    SimulationAugmented,
    load_street_model,
    make_street_pipeline,
)
from skpcd.io import read_segments

HERE = Path(__file__).resolve().parent
REAL = HERE.parent.parent / "shared/data/real_mobile/objects"
ALIASES = {"other_object": "other"}


def load(folder, min_count):
    clouds, labels, _ = read_segments(folder, Path(folder) / "labels.csv")
    labels = np.array([ALIASES.get(lab, lab) for lab in labels])
    names, counts = np.unique(labels, return_counts=True)
    keep_classes = [
        c for c, n in zip(names, counts) if c in STREET_MODEL_CLASSES and n >= min_count
    ]
    keep = np.isin(labels, keep_classes)
    return [c for c, k in zip(clouds, keep) if k], labels[keep]


def scores(truth, pred):
    classes = np.unique(truth)
    return {
        "balanced_accuracy": float(balanced_accuracy_score(truth, pred)),
        "recall": {c: float((pred[truth == c] == c).mean()) for c in classes},
    }


def draw(labels, k, rng):
    train = np.concatenate(
        [
            rng.choice(np.flatnonzero(labels == c), k, replace=False)
            for c in np.unique(labels)
        ]
    )
    test = np.setdiff1d(np.arange(len(labels)), train)
    return train, test


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", default=str(REAL))
    ap.add_argument("--shots", type=int, nargs="+", default=[1, 3, 5, 10])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--real-weight", type=float, default=None)
    ap.add_argument("--n-per-class", type=int, default=None)
    ap.add_argument("--scanner", default="auto")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    folder = Path(args.real)
    clouds, labels = load(folder, max(args.shots) + 3)
    out = Path(args.out or HERE / "results" / f"few_shot_{folder.name}")
    shipped = np.asarray(load_street_model().predict(clouds))
    rows = [{"k": 0, "method": "shipped model", **scores(labels, shipped)}]
    print(f"k=0 shipped model {rows[0]['balanced_accuracy']:.3f}", flush=True)
    kw = {"scanner": args.scanner, "n_jobs": -1}
    if args.real_weight is not None:
        kw["real_weight"] = args.real_weight
    if args.n_per_class is not None:
        kw["n_per_class"] = args.n_per_class
    for k in args.shots:
        for rep in range(args.repeats):
            rng = np.random.RandomState(1000 * k + rep)
            train, test = draw(labels, k, rng)
            X = [clouds[i] for i in train]
            T = [clouds[i] for i in test]
            t0 = time.perf_counter()
            real_only = make_street_pipeline(n_jobs=-1).fit(X, labels[train])
            r = scores(labels[test], np.asarray(real_only.predict(T)))
            rows.append({"k": k, "repeat": rep, "method": "real only", **r})
            aug = SimulationAugmented(random_state=rep, **kw).fit(X, labels[train])
            a = scores(labels[test], np.asarray(aug.predict(T)))
            rows.append(
                {
                    "k": k,
                    "repeat": rep,
                    "method": "simulation + real",
                    "scanner": aug.scanner_,
                    "scanner_scores": aug.scanner_scores_,
                    **a,
                }
            )
            print(
                f"k={k} rep {rep}: real only {r['balanced_accuracy']:.3f}, "
                f"simulation + real {a['balanced_accuracy']:.3f} ({aug.scanner_}) "
                f"{time.perf_counter() - t0:.0f} s",
                flush=True,
            )
    meta = {
        "real": str(folder),
        "classes": {c: int((labels == c).sum()) for c in np.unique(labels)},
        "repeats": args.repeats,
        "augmented": {
            k: v
            for k, v in SimulationAugmented(**kw).get_params().items()
            if k != "estimator"
        },
        "machine": f"{platform.machine()} {os.cpu_count()} cores",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "street_model": load_street_model(return_info=True)[1]["metadata"][
            "model_version"
        ],
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(
        json.dumps({"meta": meta, "rows": rows}, indent=1)
    )
    classes = sorted(meta["classes"])
    lines = [
        f"Few-shot identification on {folder} ("
        + ", ".join(f"{c} {n}" for c, n in meta["classes"].items())
        + ")",
        f"k real objects per class drawn {args.repeats} times, scored on the others;"
        f" k = 0: the shipped model ({meta['street_model']}) on all; {meta['date']},"
        f" {meta['machine']}",
        f"SimulationAugmented: {meta['augmented']}",
        "",
        f"{'k':>3s} {'method':18s} {'balanced':>14s}  "
        + " ".join(f"{c[:8]:>8s}" for c in classes),
    ]
    for k in [0, *args.shots]:
        for method in ("shipped model", "real only", "simulation + real"):
            sel = [r for r in rows if r["k"] == k and r["method"] == method]
            if not sel:
                continue
            b = [r["balanced_accuracy"] for r in sel]
            rec = [np.mean([r["recall"][c] for r in sel]) for c in classes]
            lines.append(
                f"{k:3d} {method:18s} {np.mean(b):6.3f} +/- {np.std(b):.3f}  "
                + " ".join(f"{x:8.3f}" for x in rec)
            )
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
