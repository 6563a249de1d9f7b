"""Zero, a few and many real labels: the shipped model, SimulationAugmented, real only.

On a folder of real labelled objects (``read_segments`` layout), for each
``k`` of ``--shots``, ``--repeats`` times: draw ``k`` objects of every class
(the training set of a user who labelled a handful), and score on all the
others

- ``real only``: :func:`skpcd.classification.make_street_pipeline` fitted
  on the ``k`` per class;
- ``simulation + real``: :class:`skpcd.classification.SimulationAugmented`
  (its defaults unless ``--real-weight``/``--n-per-class``) on the same;

and, as ``k = all``, 5-fold cross-validation of the default and the
street pipeline over every labelled object (a user with many labels); and,
as ``k = 0``, the shipped street model
(:func:`skpcd.classification.load_street_model`, no real label) on every
object. Scores are the balanced accuracy over the classes of the folder
that the street model knows with at least 3 objects (labels are mapped:
``other_object`` -> ``other``; the few-shot rows only over the classes with
at least ``max(shots) + 2``), and the recall per class.

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
import itertools
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from sklearn.metrics import balanced_accuracy_score
from sklearn.model_selection import StratifiedKFold, cross_val_predict

from skpcd.classification import (
    STREET_MODEL_CLASSES,
    SimulationAugmented,
    load_street_model,
    make_default_pipeline,
    make_street_pipeline,
)
from skpcd.io import read_segments

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from measure import commit  # noqa: E402

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


def reliability(proba, classes, truth, n_bins=10):
    """Expected calibration error, the reliability table (confidence bins:
    count, mean confidence, accuracy) and what asking for "unknown" below a
    threshold leaves: the share answered and its accuracy."""
    conf = proba.max(axis=1)
    correct = classes[proba.argmax(axis=1)] == truth
    edges = np.linspace(0, 1, n_bins + 1)
    table, ece = [], 0.0
    for lo, hi in itertools.pairwise(edges):
        m = (conf > lo) & (conf <= hi)
        if m.any():
            table.append([lo, hi, int(m.sum()), conf[m].mean(), correct[m].mean()])
            ece += m.mean() * abs(conf[m].mean() - correct[m].mean())
    unknown = {
        t: [float((conf >= t).mean()), float(correct[conf >= t].mean())]
        for t in (0.4, 0.5, 0.6, 0.7)
        if (conf >= t).any()
    }
    return {
        "ece": float(ece),
        "accuracy": float(correct.mean()),
        "mean_confidence": float(conf.mean()),
        "bins": table,
        "unknown_below": unknown,
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
    clouds, labels = load(folder, 3)
    out = Path(args.out or HERE / "results" / f"few_shot_{folder.name}")
    model = load_street_model()
    proba = model.predict_proba(clouds)
    shipped = model.classes_[proba.argmax(axis=1)]
    rows = [{"k": 0, "method": "shipped model", **scores(labels, shipped)}]
    print(f"k=0 shipped model {rows[0]['balanced_accuracy']:.3f}", flush=True)
    calibrated = model[-1].estimator_
    raw = calibrated.estimator.estimator.predict_proba(model[:-1].transform(clouds))
    calibration = {
        "calibrated": reliability(proba, model.classes_, labels),
        "uncalibrated": reliability(raw, model.classes_, labels),
    }
    # few shots: the classes with enough objects to draw max(shots) and test
    names, counts = np.unique(labels, return_counts=True)
    few = np.isin(labels, names[counts >= max(args.shots) + 2])
    few_shot_classes = sorted(names[counts >= max(args.shots) + 2].tolist())
    clouds = [c for c, k in zip(clouds, few) if k]
    all_labels, labels = labels, labels[few]
    kw = {"scanner": args.scanner, "n_jobs": -1}
    if args.real_weight is not None:
        kw["real_weight"] = args.real_weight
    if args.n_per_class is not None:
        kw["n_per_class"] = args.n_per_class
    # with fewer than two classes to learn there is nothing to compare
    shots = args.shots if len(few_shot_classes) >= 2 else []
    for k in shots:
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
    # many labels: 5-fold cross-validation over every labelled object
    folds = StratifiedKFold(5, shuffle=True, random_state=0)
    for name, make in (
        ("default pipeline", make_default_pipeline),
        ("street pipeline", make_street_pipeline),
    )[: 2 if shots else 0]:
        pred = cross_val_predict(make(n_jobs=-1), clouds, labels, cv=folds)
        rows.append({"k": "all", "method": name, **scores(labels, np.asarray(pred))})
        print(f"all labels, {name}: {rows[-1]['balanced_accuracy']:.3f}", flush=True)
    meta = {
        "real": str(folder),
        "classes": {c: int((all_labels == c).sum()) for c in np.unique(all_labels)},
        "few_shot_classes": few_shot_classes,
        "repeats": args.repeats,
        "augmented": {
            k: v
            for k, v in SimulationAugmented(**kw).get_params().items()
            if k != "estimator"
        },
        "commit": commit(),
        "machine": f"{platform.machine()} {os.cpu_count()} cores",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "street_model": load_street_model(return_info=True)[1]["metadata"][
            "model_version"
        ],
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(
        json.dumps({"meta": meta, "calibration": calibration, "rows": rows}, indent=1)
    )
    classes = sorted(meta["classes"])
    lines = [
        f"Few-shot identification on {folder} ("
        + ", ".join(f"{c} {n}" for c, n in meta["classes"].items())
        + ")",
        (
            f"k real objects per class of {', '.join(few_shot_classes)} drawn "
            f"{args.repeats} times, scored on the others"
            if shots
            else "no few-shot rows (fewer than two classes with enough objects)"
        )
        + "; k = 0: the shipped model "
        f"({meta['street_model']}) on every object; commit {meta['commit']}, "
        f"{meta['date']}, {meta['machine']}",
        f"SimulationAugmented: {meta['augmented']}",
        "",
        f"{'k':>3s} {'method':18s} {'balanced':>14s}  "
        + " ".join(f"{c[:8]:>8s}" for c in classes),
    ]
    methods = (
        "shipped model",
        "real only",
        "simulation + real",
        "default pipeline",
        "street pipeline",
    )
    for k in [0, *shots, "all"]:
        for method in methods:
            sel = [r for r in rows if r["k"] == k and r["method"] == method]
            if not sel:
                continue
            b = [r["balanced_accuracy"] for r in sel]
            rec = [np.mean([r["recall"].get(c, np.nan) for r in sel]) for c in classes]
            lines.append(
                f"{k!s:>3s} {method:18s} {np.mean(b):6.3f} +/- {np.std(b):.3f}  "
                + " ".join("       -" if np.isnan(x) else f"{x:8.3f}" for x in rec)
            )
    cal, unc = calibration["calibrated"], calibration["uncalibrated"]
    lines += [
        "",
        f"shipped model on all {len(all_labels)} objects: accuracy "
        f"{cal['accuracy']:.3f}, "
        f"mean confidence {cal['mean_confidence']:.3f}, expected calibration error "
        f"{cal['ece']:.3f} (uncalibrated forest {unc['ece']:.3f}, mean confidence "
        f"{unc['mean_confidence']:.3f})",
        "reliability: confidence bin, objects, mean confidence, accuracy",
        *(
            f"  {lo:.1f}-{hi:.1f} {n:5d} {c:6.3f} {a:6.3f}"
            for lo, hi, n, c, a in cal["bins"]
        ),
        "unknown below a threshold: share answered, accuracy of the answers",
        *(f"  {t:.1f}: {f:.3f} {a:.3f}" for t, (f, a) in cal["unknown_below"].items()),
    ]
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
