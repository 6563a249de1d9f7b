"""``skpcd evaluate [FOLDER]``: cross-validate a pipeline; ``skpcd score
MODEL FOLDER``: how a saved model does on labelled segments."""

import csv
import json
import os
import time
from pathlib import Path

import numpy as np

from skpcd.cli._common import (
    QUIET_HELP,
    CommandError,
    add_n_jobs,
    add_output_options,
    add_skip_unreadable,
    add_trust_pickle,
    check_not_an_input,
    check_output,
    labels_path,
    load_labelled,
    load_model_for,
    predict_or_explain,
)


def format_report(y_true, y_pred, fold_scores=None):
    """The text printed by ``skpcd evaluate`` and ``skpcd score``.

    Parameters
    ----------
    y_true, y_pred : array-like of shape (n_predictions,)
        True and predicted labels (of every test fold, pooled).
    fold_scores : array-like of shape (n_folds,), default=None
        Accuracy of each test fold; None: one accuracy over all predictions.

    Returns
    -------
    report : str
        Accuracy, a per-class precision/recall table and the confusion
        matrix (rows: true class, columns: predicted class; a predicted
        label of no true class, such as ``"unknown"``, gets a column).
    """
    from sklearn.metrics import classification_report, confusion_matrix

    y_true, y_pred = np.asarray(y_true), np.asarray(y_pred)
    classes = np.unique(np.concatenate([y_true, y_pred]).astype(str))
    y_true, y_pred = y_true.astype(str), y_pred.astype(str)
    if fold_scores is None:
        head = f"accuracy  {np.mean(y_true == y_pred):.4f} on {len(y_true)} segments"
    else:
        scores = np.asarray(fold_scores)
        head = (
            f"accuracy  {scores.mean():.4f} +/- {scores.std():.4f} "
            f"over {len(scores)} folds"
        )
    lines = [
        head,
        "",
        classification_report(
            y_true, y_pred, labels=classes, digits=3, zero_division=0
        ),
        "confusion matrix (rows: true, columns: predicted)",
    ]
    cm = confusion_matrix(y_true, y_pred, labels=classes)
    width = max(6, *(len(str(c)) for c in classes), len(str(cm.max())))
    lines.append(" " * width + " " + " ".join(f"{c:>{width}}" for c in classes))
    for c, row in zip(classes, cm):
        lines.append(f"{c:>{width}} " + " ".join(f"{v:>{width}d}" for v in row))
    return "\n".join(lines)


def report_dict(y_true, y_pred):
    """What ``skpcd score -o REPORT.json`` writes: the numbers of
    :func:`format_report` (one accuracy over all predictions).

    Parameters
    ----------
    y_true, y_pred : array-like of shape (n_predictions,)
        True and predicted labels.

    Returns
    -------
    report : dict
        ``accuracy``, ``n_segments``, ``classes`` (true and predicted, as
        the rows and columns of the matrix), ``per_class`` (precision,
        recall, f1-score and support of each class, as
        :func:`sklearn.metrics.classification_report` gives them) and
        ``confusion_matrix`` (rows: true class, columns: predicted class).
    """
    from sklearn.metrics import classification_report, confusion_matrix

    y_true = np.asarray(y_true).astype(str)
    y_pred = np.asarray(y_pred).astype(str)
    classes = np.unique(np.concatenate([y_true, y_pred])).tolist()
    per_class = classification_report(
        y_true, y_pred, labels=classes, zero_division=0, output_dict=True
    )
    return {
        "accuracy": float(np.mean(y_true == y_pred)),
        "n_segments": len(y_true),
        "classes": classes,
        "per_class": {c: per_class[c] for c in classes},
        "confusion_matrix": confusion_matrix(y_true, y_pred, labels=classes).tolist(),
    }


# ``skpcd evaluate --data NAME`` without a folder: the scan pattern (None:
# make_urban_objects), its overrides, the default --n-per-class and what is
# printed. The mobile pattern is the Lynx-like one at half its angular and
# temporal resolution (0.2 degree, 100 rotations per second: 4 times fewer
# pulses, objects of 1 500 points at the median), so that the command stays
# within a few minutes.
_STREET_MOBILE = {"angular_step": 0.2, "rotation_rate": 100.0}
DATA = {
    "urban": (
        None,
        None,
        40,
        "embedded synthetic urban objects (make_urban_objects, aerial-like)",
    ),
    "street": (
        "mobile",
        _STREET_MOBILE,
        20,
        "street furniture from simulated mobile scans (make_street_objects, "
        "Lynx-like profilers at 0.2 deg and 100 rotations/s)",
    ),
    "street-ugv": (
        "ugv",
        None,
        20,
        "street furniture from simulated UGV scans (make_street_objects, "
        "one sweep of a 32-beam spinning sensor per street)",
    ),
}


def simulated_data(name, n_per_class, random_state=0, n_jobs=None):
    """The labelled objects of ``skpcd evaluate --data NAME``.

    Parameters
    ----------
    name : {"urban", "street", "street-ugv"}
        ``"urban"``: :func:`~skpcd.datasets.make_urban_objects` (five DALES
        classes, sampled, aerial-like). ``"street"``: the ten default classes
        of :func:`~skpcd.datasets.make_street_objects` cut from simulated
        mobile scans; ``"street-ugv"``: the same from UGV sweeps.
    n_per_class : int or None
        Objects per class; None: the default of ``name``.
    random_state : int, default=0
        Seeds the objects.
    n_jobs : int, default=None
        Threads casting rays (the objects do not depend on it).

    Returns
    -------
    clouds : list of ndarray
        The objects.
    labels : ndarray of str
        Their classes.
    source : str
        What the data is, as printed.
    """
    scanner, params, default_n, source = DATA[name]
    n = default_n if n_per_class is None else int(n_per_class)
    if scanner is None:
        from skpcd.datasets import make_urban_objects

        clouds, labels = make_urban_objects(n_per_class=n, random_state=random_state)
        return clouds, labels, source
    from skpcd.datasets import make_street_objects

    clouds, labels = make_street_objects(
        n,
        scanner=scanner,
        scanner_params=params,
        random_state=random_state,
        n_jobs=n_jobs,
    )
    return clouds, labels, source


# The pipelines of --pipeline and what they are, written out as
# skpcd.classification.PIPELINES has them (tests/cli/test_startup.py checks)
# so that building the parser loads no library.
PIPELINES = {
    "default": "shape features + vertical profile + mean PFH (k=10) -> "
    "random forest (300 trees)",
    "case-based": "improved FPFH (k=10) -> CaseBasedClassifier (threshold 0.8)",
}


def add_pipeline_option(parser):
    parser.add_argument(
        "--pipeline",
        choices=tuple(PIPELINES),
        default="default",
        help="; ".join(f"{k}: {v}" for k, v in PIPELINES.items())
        + " (default: default)",
    )


def add_parsers(sub):
    ev = sub.add_parser(
        "evaluate",
        help="cross-validate an identification pipeline (the default one unless "
        "--pipeline)",
        description="Cross-validate the default pipeline on labelled segments and "
        "print per-class precision/recall and a confusion matrix. Without FOLDER it "
        "runs on simulated objects generated on the fly (--data).",
    )
    ev.add_argument("folder", nargs="?", help="folder of per-segment files")
    add_pipeline_option(ev)
    ev.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv)"
    )
    ev.add_argument(
        "--data",
        choices=tuple(DATA),
        default=None,
        help="without FOLDER, the simulated objects to run on: urban (default; "
        "make_urban_objects, 5 aerial-like classes, 40 per class), street (10 "
        "classes of street furniture, trees, cars cut from simulated mobile "
        "scans, 20 per class; the first run compiles the simulator for about a "
        "minute) or street-ugv (the same from UGV sweeps)",
    )
    ev.add_argument(
        "--n-per-class",
        type=int,
        default=None,
        help="objects per class of --data (default: 40 urban, 20 street)",
    )
    ev.add_argument("--folds", type=int, default=5, help="number of folds (default 5)")
    ev.add_argument("--repeats", type=int, default=1, help="CV repetitions (default 1)")
    ev.add_argument(
        "--random-state",
        type=int,
        default=0,
        help="seed of the folds, the forest and the simulated objects (default 0)",
    )
    add_n_jobs(ev)
    add_skip_unreadable(ev)
    ev.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    ev.set_defaults(func=run_evaluate)

    sc = sub.add_parser(
        "score",
        help="accuracy, per-class precision/recall and confusion matrix of a "
        "saved model on labelled segments",
    )
    sc.add_argument("model", help="a model written by skpcd fit")
    sc.add_argument("folder", help="folder of per-segment files")
    sc.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv)"
    )
    sc.add_argument(
        "-o",
        "--output",
        help="also write the scores to this file: .csv, one row per segment "
        "(file, label, predicted, and the probability or similarity); .json, "
        "the accuracy, per-class precision, recall, f1-score and support and "
        "the confusion matrix; any other name, the report as printed",
    )
    add_skip_unreadable(sc)
    add_output_options(sc)
    add_trust_pickle(sc)
    sc.set_defaults(func=run_score)
    return ev, sc


def run_evaluate(args):
    from sklearn.base import clone
    from sklearn.model_selection import RepeatedStratifiedKFold

    from skpcd.classification import PIPELINES, make_named_pipeline
    from skpcd.utils._progress import progress

    if args.folds < 2 or args.repeats < 1:
        raise CommandError(
            "evaluate",
            f"--folds must be at least 2 and --repeats at least 1, got {args.folds} "
            f"and {args.repeats}",
        )
    if args.folder is None:
        if args.n_per_class is not None and args.n_per_class < 1:
            raise CommandError(
                "evaluate", f"--n-per-class must be at least 1, got {args.n_per_class}"
            )
        clouds, y, source = simulated_data(
            args.data or "urban",
            args.n_per_class,
            random_state=args.random_state,
            n_jobs=args.n_jobs,
        )
        source = f"{args.data or 'urban'}: {source}"
    elif args.data is not None or args.n_per_class is not None:
        raise CommandError(
            "evaluate",
            "--data and --n-per-class choose simulated objects; they do not "
            "apply with a FOLDER",
        )
    else:
        clouds, y, source, _ = load_labelled(args)
    classes, counts = np.unique(y, return_counts=True)
    if len(classes) < 2:
        raise CommandError(
            "evaluate",
            f"every segment is labelled {str(classes[0])!r}; cross-validating "
            "needs at least 2 classes",
        )
    if counts.min() < args.folds:
        raise CommandError(
            "evaluate",
            f"class {str(classes[counts.argmin()])!r} has {counts.min()} "
            f"segment(s), fewer than --folds {args.folds}",
        )
    print(f"data      {source}: {len(clouds)} segments, {len(classes)} classes")
    print(f"pipeline  {args.pipeline}: {PIPELINES[args.pipeline]}")
    print(
        f"protocol  {args.folds}-fold stratified CV x {args.repeats}, "
        f"seed {args.random_state}"
    )
    model = make_named_pipeline(
        args.pipeline, random_state=args.random_state, n_jobs=args.n_jobs
    )
    cv = RepeatedStratifiedKFold(
        n_splits=args.folds, n_repeats=args.repeats, random_state=args.random_state
    )
    splits = list(cv.split(np.zeros(len(y)), y))
    y_true, y_pred, scores = [], [], []
    start = time.perf_counter()
    for train, test in progress(
        splits, desc="folds", enabled=False if args.quiet else None
    ):
        fitted = clone(model).fit([clouds[i] for i in train], y[train])
        pred = fitted.predict([clouds[i] for i in test])
        y_true.append(y[test])
        y_pred.append(pred)
        scores.append(np.mean(pred == y[test]))
    print(f"time      {time.perf_counter() - start:.1f} s")
    print()
    print(format_report(np.concatenate(y_true), np.concatenate(y_pred), scores))
    return 0


def run_score(args):
    out = None
    if args.output is not None:
        out = check_output(args.output, args, "score", inputs=[args.model])
    labels_path(args)  # the folder and its labels exist
    clouds, y, source, files = load_labelled(args)
    if out is not None:
        check_not_an_input(out, "score", files)
    model = load_model_for(args, "score")
    start = time.perf_counter()
    pred, kind, score = predict_or_explain(model, clouds, args, "score")
    report = format_report(y, pred)
    print(f"model     {args.model}")
    print(f"data      {source}: {len(clouds)} segments")
    print(f"time      {time.perf_counter() - start:.1f} s")
    print()
    print(report)
    if out is not None:
        names = [Path(os.path.relpath(f, args.folder)).as_posix() for f in files[1:]]
        if len(names) != len(y):  # not a folder: the segments by number
            names = [str(i) for i in range(len(y))]
        _write_scores(out, args, report, (names, y, pred, kind, score))
        print(f"\nwritten   {out}")
    return 0


def _write_scores(out, args, report, scores):
    """``skpcd score -o``: by the extension of ``out``, the per-segment
    rows (.csv), the numbers (.json) or the report; written whole or not at
    all."""
    from skpcd.io._atomic import atomic_path

    names, y, pred, kind, score = scores
    suffix = out.suffix.lower()
    with atomic_path(out, overwrite=args.overwrite) as tmp:
        with open(tmp, "w", newline="") as f:
            if suffix == ".csv":
                writer = csv.writer(f)
                writer.writerow(
                    ["file", "label", "predicted"] + ([kind] if kind else [])
                )
                for i, name in enumerate(names):
                    extra = [f"{score[i]:.6f}"] if kind else []
                    writer.writerow([name, y[i], pred[i], *extra])
            elif suffix == ".json":
                numbers = {"model": str(args.model), "data": str(args.folder)}
                json.dump({**numbers, **report_dict(y, pred)}, f, indent=1)
                f.write("\n")
            else:
                f.write(report + "\n")
