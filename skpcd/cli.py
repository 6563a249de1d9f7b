"""The ``skpcd`` command line.

``skpcd info FILE`` describes a point-cloud file; ``skpcd evaluate [FOLDER]``
cross-validates the default identification pipeline on a folder of labelled
segments, or on the embedded synthetic objects when no folder is given;
``skpcd fit``, ``skpcd predict`` and ``skpcd describe`` fit and save a model,
label segments with it, and save segment descriptors.
Each subcommand is a ``_cmd_<name>(args)`` function registered in
:func:`build_parser`.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["build_parser", "main"]


def _cmd_info(args):
    from skpcd.io import read_point_cloud
    from skpcd.preprocessing import point_spacing

    points, extras = read_point_cloud(args.file, fields="all", nonfinite="keep")
    finite = np.isfinite(points).all(axis=1)
    valid = points[finite]
    out = [
        f"file      {args.file}",
        f"points    {len(points)}"
        + (
            f" ({len(points) - len(valid)} with NaN/inf coordinates)"
            if not finite.all()
            else ""
        ),
        "fields    x y z" + "".join(f" {n}" for n in extras),
    ]
    if len(valid):
        lo, hi = valid.min(axis=0), valid.max(axis=0)
        for axis, a, b in zip("xyz", lo, hi):
            out.append(f"{axis}         [{a:.4f}, {b:.4f}]  extent {b - a:.4f}")
        out.append(
            f"spacing   {point_spacing(valid, workers=-1):.4f} (median nearest distinct"
            " neighbour)"
        )
    print("\n".join(out))
    return 0


def _load_labelled(args):
    if args.folder is None:
        from skpcd.datasets import make_urban_objects

        clouds, labels = make_urban_objects(n_per_class=40, random_state=0)
        return clouds, labels, "embedded synthetic urban objects (make_urban_objects)"
    from skpcd.io import read_segments

    labels = args.labels
    if labels is None:
        default = Path(args.folder) / "labels.csv"
        if not default.is_file():
            raise SystemExit(
                f"skpcd evaluate: {args.folder} has no labels.csv; pass --labels CSV"
            )
        labels = default
    clouds, y, _ = read_segments(args.folder, labels, verbose=not args.quiet)
    return clouds, y, str(args.folder)


def format_report(y_true, y_pred, fold_scores):
    """The text printed by ``skpcd evaluate``.

    Parameters
    ----------
    y_true, y_pred : array-like of shape (n_predictions,)
        Pooled true and predicted labels of every test fold.
    fold_scores : array-like of shape (n_folds,)
        Accuracy of each test fold.

    Returns
    -------
    report : str
        Accuracy over folds, a per-class precision/recall table and the
        confusion matrix (rows: true class, columns: predicted class).
    """
    from sklearn.metrics import classification_report, confusion_matrix

    classes = np.unique(np.concatenate([np.asarray(y_true), np.asarray(y_pred)]))
    scores = np.asarray(fold_scores)
    lines = [
        f"accuracy  {scores.mean():.4f} +/- {scores.std():.4f} "
        f"over {len(scores)} folds",
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


def _cmd_evaluate(args):
    from sklearn.base import clone
    from sklearn.model_selection import RepeatedStratifiedKFold

    from skpcd.classification import make_default_pipeline
    from skpcd.utils._progress import progress

    clouds, y, source = _load_labelled(args)
    classes, counts = np.unique(y, return_counts=True)
    if counts.min() < args.folds:
        raise SystemExit(
            f"skpcd evaluate: class {classes[counts.argmin()]!r} has {counts.min()} "
            f"segment(s), fewer than --folds {args.folds}"
        )
    print(f"data      {source}: {len(clouds)} segments, {len(classes)} classes")
    print("pipeline  ShapeFeatures -> RandomForestClassifier(300 trees)")
    print(
        f"protocol  {args.folds}-fold stratified CV x {args.repeats}, "
        f"seed {args.random_state}"
    )
    model = make_default_pipeline(random_state=args.random_state, n_jobs=args.n_jobs)
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


def _check_output(path, overwrite, command):
    """Refuse to replace an existing output file without ``--overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise SystemExit(
            f"skpcd {command}: {path} exists; pass --overwrite to replace it"
        )
    return path


def _cmd_fit(args):
    from skpcd.classification import make_default_pipeline
    from skpcd.io import save_model

    out = _check_output(args.output, args.overwrite, "fit")
    clouds, y, source = _load_labelled(args)
    classes, counts = np.unique(y, return_counts=True)
    print(f"data      {source}: {len(clouds)} segments, {len(classes)} classes")
    model = make_default_pipeline(random_state=args.random_state, n_jobs=args.n_jobs)
    start = time.perf_counter()
    model.fit(clouds, y)
    print(f"fit       {time.perf_counter() - start:.1f} s")
    metadata = {
        "data": source,
        "n_segments": len(clouds),
        "classes": {str(c): int(n) for c, n in zip(classes, counts)},
        "pipeline": repr(model),
    }
    save_model(model, out, metadata=metadata, overwrite=args.overwrite)
    print(f"model     {out}")
    return 0


def _scores(model, X, pred):
    """The confidence of each answer and its name: the similarity of the
    most similar case for a case-based model, otherwise the probability of
    the predicted class (None when the model gives neither)."""
    final = model.steps[-1][1] if hasattr(model, "steps") else model
    if hasattr(final, "retrieve"):
        return "similarity", model.decision_function(X).max(axis=1)
    if hasattr(model, "predict_proba"):
        proba = model.predict_proba(X)
        col = {c: j for j, c in enumerate(model.classes_)}
        rows = np.arange(len(pred))
        cols = np.array([col.get(p, -1) for p in pred])
        score = np.where(cols >= 0, proba[rows, np.maximum(cols, 0)], proba.max(1))
        return "probability", score
    return None, None


def _cmd_predict(args):
    import csv

    from skpcd.io import load_model, read_segments

    out = _check_output(args.output, args.overwrite, "predict")
    model = load_model(args.model)
    clouds, _, names = read_segments(args.folder, verbose=not args.quiet)
    pred = np.asarray(model.predict(clouds))
    kind, score = _scores(model, clouds, pred)
    with open(out, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["file", "label"] + ([kind] if kind else []))
        for i, name in enumerate(names):
            writer.writerow([name, pred[i]] + ([f"{score[i]:.6f}"] if kind else []))
    labels, counts = np.unique(pred.astype(str), return_counts=True)
    summary = ", ".join(f"{c} {n}" for c, n in zip(labels, counts))
    print(f"predicted {len(names)} segments ({summary}) -> {out}")
    return 0


# descriptor name -> (transformer factory, what it is)
def _segment_descriptors(n_neighbors, n_jobs):
    from skpcd.features import (
        FPFHTransformer,
        ImprovedPFHTransformer,
        OverallDescriptor,
        PFHTransformer,
        ShapeFeatures,
    )

    k = {"n_neighbors": n_neighbors, "n_jobs": n_jobs}
    return {
        "shape": ShapeFeatures(),
        "overall": OverallDescriptor(),
        "improved_pfh": ImprovedPFHTransformer("pfh", **k),
        "improved_fpfh": ImprovedPFHTransformer("fpfh", **k),
        "pfh_mean": PFHTransformer(pooling="mean", undefined="drop", **k),
        "fpfh_mean": FPFHTransformer(pooling="mean", undefined="drop", **k),
    }


def _cmd_describe(args):
    from skpcd.features import FPFHTransformer, PFHTransformer
    from skpcd.io import read_segments

    out = _check_output(args.output, args.overwrite, "describe")
    available = _segment_descriptors(args.n_neighbors, args.n_jobs)
    wanted = [d.strip() for d in args.descriptors.split(",") if d.strip()]
    unknown = sorted(set(wanted) - set(available))
    if unknown:
        raise SystemExit(
            f"skpcd describe: unknown descriptor(s) {', '.join(unknown)}; "
            f"choose from {', '.join(available)}"
        )
    labels = args.labels
    if labels is None and (Path(args.folder) / "labels.csv").is_file():
        labels = Path(args.folder) / "labels.csv"
    clouds, y, names = read_segments(args.folder, labels, verbose=not args.quiet)
    arrays = {"names": np.asarray(names)}
    if y is not None:
        arrays["labels"] = np.asarray(y)
    for name in wanted:
        start = time.perf_counter()
        est = available[name]
        arrays[name] = np.asarray(est.fit_transform(clouds), dtype=np.float64)
        arrays[f"{name}_columns"] = np.asarray(est.get_feature_names_out(), dtype=str)
        print(f"{name:<14}{arrays[name].shape}  {time.perf_counter() - start:.1f} s")
    if args.local:
        cls = {"pfh": PFHTransformer, "fpfh": FPFHTransformer}[args.local]
        start = time.perf_counter()
        rows = cls(n_neighbors=args.n_neighbors, n_jobs=args.n_jobs).fit_transform(
            clouds
        )
        arrays[args.local] = np.vstack(rows)
        arrays[f"{args.local}_offsets"] = np.cumsum([0] + [len(r) for r in rows])
        print(
            f"{args.local:<14}{arrays[args.local].shape} per point (rows of segment "
            f"i: {args.local}_offsets[i]:{args.local}_offsets[i + 1])  "
            f"{time.perf_counter() - start:.1f} s"
        )
    tmp = out.with_name(f".{out.name}.tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(out)
    print(f"written   {out}")
    return 0


def build_parser():
    """The argument parser of the ``skpcd`` command, one subparser per command.

    Returns
    -------
    parser : argparse.ArgumentParser
        The parser; each subparser sets ``func`` to the function to run.
    """
    from skpcd import __version__

    parser = argparse.ArgumentParser(
        prog="skpcd", description="Describe and identify segmented LiDAR point clouds."
    )
    parser.add_argument("--version", action="version", version=f"skpcd {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    info = sub.add_parser("info", help="points, fields, bounds and spacing of a file")
    info.add_argument(
        "file", help="a point-cloud file (.xyz .txt .pts .csv .npy .ply .pcd .las .laz)"
    )
    info.set_defaults(func=_cmd_info)

    ev = sub.add_parser(
        "evaluate",
        help="cross-validate the default identification pipeline",
        description="Cross-validate the default pipeline on labelled segments and "
        "print per-class precision/recall and a confusion matrix. Without FOLDER it "
        "runs on the embedded synthetic urban objects.",
    )
    ev.add_argument("folder", nargs="?", help="folder of per-segment files")
    ev.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv)"
    )
    ev.add_argument("--folds", type=int, default=5, help="number of folds (default 5)")
    ev.add_argument("--repeats", type=int, default=1, help="CV repetitions (default 1)")
    ev.add_argument("--random-state", type=int, default=0, help="seed (default 0)")
    ev.add_argument("--n-jobs", type=int, default=None, help="threads (-1: all cores)")
    ev.add_argument("--quiet", action="store_true", help="no progress bars")
    ev.set_defaults(func=_cmd_evaluate)

    fit = sub.add_parser(
        "fit",
        help="fit the default identification pipeline and save it",
        description="Fit the default pipeline on labelled segments and save it "
        "with joblib, with the skpcd and scikit-learn versions.",
    )
    fit.add_argument("folder", help="folder of per-segment files")
    fit.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv)"
    )
    fit.add_argument("-o", "--output", required=True, help="model file (.joblib)")
    fit.add_argument("--random-state", type=int, default=0, help="seed (default 0)")

    pred = sub.add_parser(
        "predict",
        help="label segments with a saved model",
        description="Predict the class of every segment of a folder; the CSV has "
        "file, label and the probability (or, for a case-based model, the "
        "similarity) of each answer.",
    )
    pred.add_argument("model", help="a model written by skpcd fit")
    pred.add_argument("folder", help="folder of per-segment files")
    pred.add_argument("-o", "--output", required=True, help="predictions CSV")

    desc = sub.add_parser(
        "describe",
        help="compute segment descriptors into an .npz file",
        description="Compute descriptors of every segment of a folder and save "
        "them with numpy.savez_compressed: 'names', 'labels' (when labelled), one "
        "(n_segments, n_features) array per descriptor with its '<name>_columns', "
        "and with --local the per-point descriptors packed with offsets.",
    )
    desc.add_argument("folder", help="folder of per-segment files")
    desc.add_argument("-o", "--output", required=True, help="output .npz file")
    desc.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv if any)"
    )
    desc.add_argument(
        "--descriptors",
        default="shape,overall,improved_pfh",
        help="comma list of shape, overall, improved_pfh, improved_fpfh, pfh_mean, "
        "fpfh_mean (default: shape,overall,improved_pfh)",
    )
    desc.add_argument(
        "--local", choices=("pfh", "fpfh"), help="also store per-point descriptors"
    )
    desc.add_argument(
        "--n-neighbors", type=int, default=10, help="k of the local descriptors"
    )
    fit.set_defaults(func=_cmd_fit)
    pred.set_defaults(func=_cmd_predict)
    desc.set_defaults(func=_cmd_describe)
    for p in (fit, pred, desc):
        if p is not pred:
            p.add_argument(
                "--n-jobs", type=int, default=None, help="threads (-1: all cores)"
            )
        p.add_argument("--overwrite", action="store_true", help="replace the output")
        p.add_argument("--quiet", action="store_true", help="no progress bars")
    return parser


def main(argv=None):
    """Run the ``skpcd`` command.

    Parameters
    ----------
    argv : list of str, default=None
        Arguments; ``sys.argv[1:]`` when None.

    Returns
    -------
    status : int
        0 on success, 1 when an input file cannot be used.
    """
    from skpcd.exceptions import PointCloudFileError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (PointCloudFileError, FileExistsError) as exc:  # bad input files
        print(f"skpcd {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
