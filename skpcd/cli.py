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
                f"skpcd {args.command}: {args.folder} has no labels.csv; pass "
                "--labels CSV"
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

    from skpcd.utils._progress import progress

    if args.folds < 2 or args.repeats < 1:
        raise SystemExit(
            f"skpcd evaluate: --folds must be at least 2 and --repeats at least 1, "
            f"got {args.folds} and {args.repeats}"
        )
    clouds, y, source = _load_labelled(args)
    classes, counts = np.unique(y, return_counts=True)
    if len(classes) < 2:
        raise SystemExit(
            f"skpcd evaluate: every segment is labelled {str(classes[0])!r}; "
            "cross-validating needs at least 2 classes"
        )
    if counts.min() < args.folds:
        raise SystemExit(
            f"skpcd evaluate: class {str(classes[counts.argmin()])!r} has "
            f"{counts.min()} segment(s), fewer than --folds {args.folds}"
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


# --pipeline name -> what it is, as printed by evaluate
PIPELINES = {
    "default": "shape features + mean PFH (k=10) -> random forest (300 trees)",
    "case-based": "improved FPFH (k=10) -> CaseBasedClassifier (threshold 0.8)",
}


def make_named_pipeline(name, *, random_state=0, n_jobs=None):
    """The pipeline ``--pipeline NAME`` selects in ``evaluate`` and ``fit``.

    Parameters
    ----------
    name : {"default", "case-based"}
        ``"default"``: :func:`~skpcd.classification.make_default_pipeline`.
        ``"case-based"``: the improved FPFH of each segment and a
        :class:`~skpcd.classification.CaseBasedClassifier` answering
        ``"unknown"`` below a similarity of 0.8 (the paper's); without the
        volume term, which cost accuracy at the paper's equal weights on
        the DALES objects.
    random_state : int, default=0
        Seeds the forest of the default pipeline.
    n_jobs : int, default=None
        Threads; None means 1, -1 all cores.

    Returns
    -------
    pipeline : sklearn.pipeline.Pipeline
        An unfitted pipeline.
    """
    from skpcd.classification import make_case_based_pipeline, make_default_pipeline
    from skpcd.features import ImprovedPFHTransformer

    if name == "default":
        return make_default_pipeline(random_state=random_state, n_jobs=n_jobs)
    if name == "case-based":
        descriptor = ImprovedPFHTransformer("fpfh", undefined="zero", n_jobs=n_jobs)
        return make_case_based_pipeline(descriptor, volume=False, n_jobs=n_jobs)
    raise ValueError(f"unknown pipeline {name!r}; choose from {', '.join(PIPELINES)}")


def _check_output(path, overwrite, command):
    """Refuse to replace an existing output file without ``--overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise SystemExit(
            f"skpcd {command}: {path} exists; pass --overwrite to replace it"
        )
    return path


def _check_output_place(out, command):
    """Refuse, before any work, an output that is a folder or in no folder."""
    if out.is_dir():
        raise SystemExit(f"skpcd {command}: {out} is a folder; give a file name")
    if not out.parent.is_dir():
        raise SystemExit(
            f"skpcd {command}: the folder {out.parent} of {out.name} does not exist"
        )
    return out


def _check_not_an_input(out, command, inputs):
    """Refuse an output that is one of the files read (even with --overwrite)."""
    target = out.resolve()
    for path in inputs:
        if path is not None and Path(path).resolve() == target:
            raise SystemExit(f"skpcd {command}: the output {out} is an input file")


def _segment_files(folder, names):
    """The files of ``names`` when FOLDER is a folder (not a glob)."""
    return [Path(folder) / n for n in names] if Path(folder).is_dir() else []


def _cmd_fit(args):
    from skpcd.io import save_model

    out = _check_output_place(_check_output(args.output, args.overwrite, "fit"), "fit")
    if args.folder is not None:
        labels = args.labels or Path(args.folder) / "labels.csv"
        _check_not_an_input(out, "fit", [labels])
    clouds, y, source = _load_labelled(args)
    classes, counts = np.unique(y, return_counts=True)
    if len(classes) < 2 and args.pipeline == "default":
        raise SystemExit(
            f"skpcd fit: every segment is labelled {str(classes[0])!r}, so the "
            "default pipeline would give that label to everything; label at least 2 "
            "classes (--pipeline case-based accepts one: that class or unknown)"
        )
    print(f"data      {source}: {len(clouds)} segments, {len(classes)} classes")
    model = make_named_pipeline(
        args.pipeline, random_state=args.random_state, n_jobs=args.n_jobs
    )
    start = time.perf_counter()
    model.fit(clouds, y)
    print(f"fit       {time.perf_counter() - start:.1f} s")
    metadata = {
        "data": source,
        "n_segments": len(clouds),
        "classes": {str(c): int(n) for c, n in zip(classes, counts)},
        "pipeline": f"{args.pipeline}: {PIPELINES[args.pipeline]}",
        "estimator": repr(model),
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
    _check_output_place(out, "predict")
    _check_not_an_input(out, "predict", [args.model])
    model = load_model(args.model)
    if not hasattr(model, "predict"):
        raise SystemExit(
            f"skpcd predict: {args.model} holds a {type(model).__name__}, not a "
            "fitted model; write one with skpcd fit"
        )
    clouds, _, names = read_segments(args.folder, verbose=not args.quiet)
    _check_not_an_input(out, "predict", _segment_files(args.folder, names))
    try:
        pred = np.asarray(model.predict(clouds))
    except ValueError as exc:  # e.g. a model of 2-D features, not of clouds
        raise SystemExit(
            f"skpcd predict: the model in {args.model} cannot label these "
            f"segments ({type(model).__name__}: {exc}); write one with skpcd fit"
        ) from exc
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
    _check_output_place(out, "describe")
    available = _segment_descriptors(args.n_neighbors, args.n_jobs)
    wanted = [d.strip() for d in args.descriptors.split(",") if d.strip()]
    if not wanted and not args.local:
        raise SystemExit(
            f"skpcd describe: no descriptor asked for (--descriptors "
            f"{args.descriptors!r}); choose from {', '.join(available)}"
        )
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
    _check_not_an_input(out, "describe", [labels, *_segment_files(args.folder, names)])
    arrays = {"names": np.asarray(names)}
    if y is not None:
        arrays["labels"] = np.asarray(y)
    for name in wanted:
        start = time.perf_counter()
        est = available[name]
        try:
            arrays[name] = np.asarray(est.fit_transform(clouds), dtype=np.float64)
        except ValueError as exc:  # e.g. --n-neighbors out of range
            raise SystemExit(f"skpcd describe: {name}: {exc}") from exc
        arrays[f"{name}_columns"] = np.asarray(est.get_feature_names_out(), dtype=str)
        print(f"{name:<14}{arrays[name].shape}  {time.perf_counter() - start:.1f} s")
    if args.local:
        cls = {"pfh": PFHTransformer, "fpfh": FPFHTransformer}[args.local]
        start = time.perf_counter()
        try:
            rows = cls(n_neighbors=args.n_neighbors, n_jobs=args.n_jobs)
            rows = rows.fit_transform(clouds)
        except ValueError as exc:
            raise SystemExit(f"skpcd describe: {args.local}: {exc}") from exc
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


# --- scene segmentation: ``skpcd segment`` and ``skpcd identify`` ---------


def _add_segmentation_options(p):
    """The options of :func:`skpcd.segment_scene`, shared by segment/identify."""
    p.add_argument(
        "--ground",
        choices=("aerial", "mobile", "none"),
        default="aerial",
        help="ground removal preset (GroundFilter, SMRF), or none (default aerial)",
    )
    p.add_argument(
        "--method",
        choices=("dbscan", "euclidean"),
        default="dbscan",
        help="dbscan: AutoEpsDBSCAN, eps from the data unless --eps; euclidean: "
        "EuclideanClusters, eps 0.2 unless --eps (default dbscan)",
    )
    p.add_argument("--eps", type=float, default=None, help="clustering radius (m)")
    p.add_argument(
        "--eps-scale",
        type=float,
        default=2.5,
        help="dbscan without --eps: the radius is this multiple of the knee "
        "distance of the k-distance curve (default 2.5)",
    )
    p.add_argument(
        "--min-samples", type=int, default=5, help="DBSCAN core count (default 5)"
    )
    p.add_argument(
        "--min-size", type=int, default=50, help="smallest segment kept (default 50)"
    )
    p.add_argument("--max-size", type=int, default=None, help="largest segment kept")
    p.add_argument("--random-state", type=int, default=0, help="seed (default 0)")
    p.add_argument("--n-jobs", type=int, default=None, help="threads (-1: all cores)")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def _segment_file(args, command, fields=None):
    """Read SCENE and segment it; returns ``(points, extras, result)``.

    With ``--tile-size`` the scene is not read here (segment_scene streams
    it tile by tile): ``points`` is None and ``extras`` empty."""
    from skpcd.io import read_point_cloud
    from skpcd.segmentation import segment_scene

    tiled = getattr(args, "tile_size", None) is not None
    if tiled:
        points, extras, source = None, {}, args.scene
    else:
        read = read_point_cloud(args.scene, fields=fields)
        points, extras = read if fields else (read, {})
        source = points
    tiling = (
        {"tile_size": args.tile_size, "tile_buffer": args.tile_buffer} if tiled else {}
    )
    start = time.perf_counter()
    try:
        result = segment_scene(
            source,
            ground=None if args.ground == "none" else args.ground,
            method=args.method,
            eps=args.eps,
            eps_scale=args.eps_scale,
            min_samples=args.min_samples,
            min_cluster_size=args.min_size,
            max_cluster_size=args.max_size,
            random_state=args.random_state,
            n_jobs=args.n_jobs,
            **tiling,
        )
    except ValueError as exc:
        raise SystemExit(f"skpcd {command}: {exc}") from exc
    if not args.quiet:
        labels = result.labels
        print(
            f"scene     {args.scene}: {len(labels)} points, "
            f"{int(result.ground.sum())} ground"
        )
        print(
            f"segments  {result.n_segments} ({args.method}, eps {result.eps:.3f}); "
            f"{int(((labels < 0) & ~result.ground).sum())} points in none "
            f"({time.perf_counter() - start:.1f} s)"
        )
    return points, extras, result


def _segment_members(labels, n_segments):
    """Point indices of each segment, in one sort."""
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n_segments + 1))
    return [order[bounds[i] : bounds[i + 1]] for i in range(n_segments)]


def _streamed_segments(scene, labels, n_segments, keep_fields, out):
    """``(points, fields)`` of each segment, gathered in one pass over the
    scene's chunks into one temporary file per segment (in a hidden folder
    of ``out``), so that the scene is never in memory."""
    import shutil
    import tempfile

    from skpcd.segmentation._tiling import iter_chunks

    spill = Path(tempfile.mkdtemp(prefix=".skpcd_segments_", dir=out))
    try:
        dtype, start = None, 0
        chunks = iter_chunks(scene, 1_000_000, fields=keep_fields)
        if not keep_fields:
            chunks = ((xyz, {}) for xyz in chunks)
        for xyz, extras in chunks:
            if dtype is None:
                dtype = np.dtype(
                    [("xyz", np.float64, (3,))]
                    + [(k, v.dtype, v.shape[1:]) for k, v in extras.items()]
                )
            part = np.asarray(labels[start : start + len(xyz)])
            start += len(xyz)
            order = np.argsort(part, kind="stable")
            bounds = np.searchsorted(part[order], np.arange(n_segments + 1))
            records = np.empty(len(xyz), dtype=dtype)
            records["xyz"] = xyz
            for k, v in extras.items():
                records[k] = v
            for i in np.flatnonzero(np.diff(bounds)):
                with open(spill / f"{i}.bin", "ab") as f:
                    records[order[bounds[i] : bounds[i + 1]]].tofile(f)
        for i in range(n_segments):
            records = np.fromfile(spill / f"{i}.bin", dtype=dtype)
            yield (
                np.ascontiguousarray(records["xyz"]),
                {k: records[k] for k in dtype.names[1:]},
            )
    finally:
        shutil.rmtree(spill, ignore_errors=True)


def _cmd_segment(args):
    import csv

    from skpcd.io import write_point_cloud

    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise SystemExit(f"skpcd segment: {out} exists and is not a folder")
    if (out / "segments.csv").exists() and not args.overwrite:
        raise SystemExit(
            f"skpcd segment: {out} already holds segments.csv; pass --overwrite "
            "to replace its files"
        )
    points, extras, result = _segment_file(
        args, "segment", "all" if args.keep_fields else None
    )
    n = result.n_segments
    width = max(4, len(str(n - 1)))
    names = [f"segment_{i:0{width}d}.{args.format}" for i in range(n)]
    summary = out / "segments.csv"
    clash = [p for p in [summary, *(out / f for f in names)] if p.exists()]
    if clash and not args.overwrite:
        shown = ", ".join(str(p) for p in clash[:3]) + (
            " ..." if len(clash) > 3 else ""
        )
        raise SystemExit(
            f"skpcd segment: {len(clash)} output file(s) exist ({shown}); pass "
            "--overwrite to replace them"
        )
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if points is None:  # tiled: the segments gathered in one pass over the scene
        segments = _streamed_segments(
            args.scene, result.labels, n, args.keep_fields, out
        )
    else:
        segments = (
            (points[idx], {name: values[idx] for name, values in extras.items()})
            for idx in _segment_members(result.labels, n)
        )
    for i, (seg, fields) in enumerate(segments):
        try:
            write_point_cloud(
                out / names[i], seg, fields=fields or None, overwrite=args.overwrite
            )
        except ValueError as exc:  # a field the format cannot hold
            raise SystemExit(f"skpcd segment: {exc}") from exc
        lo, hi = seg.min(axis=0), seg.max(axis=0)
        rows.append([names[i], i, len(seg), *lo, *hi, *(hi - lo)])
    tmp = summary.with_name(f".{summary.name}.tmp")
    with open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(
            ["file", "segment", "n_points"]
            + [f"{a}_{c}" for a in ("min", "max", "extent") for c in "xyz"]
        )
        for row in rows:
            writer.writerow(row[:3] + [f"{v:.4f}" for v in row[3:]])
    tmp.replace(summary)
    if not args.quiet:
        print(f"written   {n} {args.format} files and {summary.name} -> {out}")
    return 0


def _cmd_identify(args):
    import csv

    from skpcd.io import load_model, write_point_cloud

    out = _check_output(args.output, args.overwrite, "identify")
    _check_output_place(out, "identify")
    _check_not_an_input(out, "identify", [args.scene, args.model])
    legend = out.with_name(f"{out.stem}_classes.csv")
    _check_output(legend, args.overwrite, "identify")
    _check_not_an_input(legend, "identify", [args.scene, args.model])
    model = load_model(args.model)
    points, _, result = _segment_file(args, "identify")
    n = result.n_segments
    members = _segment_members(result.labels, n)
    classes = np.asarray(getattr(model, "classes_", []))
    segment_class = np.full(n, -1, dtype=np.int64)
    segment_score = np.full(n, np.nan)
    kind = None
    if n:
        clouds = [points[idx] for idx in members]
        pred = np.asarray(model.predict(clouds))
        kind, score = _scores(model, clouds, pred)
        if len(classes) == 0:
            classes = np.unique(pred)
        index = {c: j for j, c in enumerate(classes)}
        segment_class = np.array([index[p] for p in pred], dtype=np.int64)
        if kind:
            segment_score = np.asarray(score, dtype=np.float64)
    labels = result.labels
    inside = labels >= 0
    point_class = np.full(len(points), -1, dtype=np.int32)
    point_class[inside] = segment_class[labels[inside]]
    fields = {
        "segment": labels.astype(np.int32),
        "class": point_class,
        "ground": result.ground.astype(np.uint8),
    }
    if kind:
        score = np.full(len(points), np.nan, dtype=np.float32)
        score[inside] = segment_score[labels[inside]]
        fields[kind] = score
    try:
        write_point_cloud(out, points, fields=fields, overwrite=args.overwrite)
    except ValueError as exc:  # a field the format cannot hold
        raise SystemExit(f"skpcd identify: {exc}") from exc
    tmp = legend.with_name(f".{legend.name}.tmp")
    with open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["class", "name", "n_segments", "n_points"])
        writer.writerow([-1, "(no segment)", 0, int((~inside).sum())])
        for j, c in enumerate(classes):
            writer.writerow(
                [j, c, int((segment_class == j).sum()), int((point_class == j).sum())]
            )
    tmp.replace(legend)
    if not args.quiet:
        counts = ", ".join(
            f"{c} {int((segment_class == j).sum())}" for j, c in enumerate(classes)
        )
        print(f"classes   {counts or 'none'}")
        print(
            f"written   {out} (fields segment, class, ground"
            + (f", {kind}" if kind else "")
            + f"); class names in {legend.name}"
        )
    return 0


def _add_pipeline_option(parser):
    parser.add_argument(
        "--pipeline",
        choices=tuple(PIPELINES),
        default="default",
        help="; ".join(f"{k}: {v}" for k, v in PIPELINES.items())
        + " (default: default)",
    )


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
        help="cross-validate an identification pipeline (the default one unless "
        "--pipeline)",
        description="Cross-validate the default pipeline on labelled segments and "
        "print per-class precision/recall and a confusion matrix. Without FOLDER it "
        "runs on the embedded synthetic urban objects.",
    )
    ev.add_argument("folder", nargs="?", help="folder of per-segment files")
    _add_pipeline_option(ev)
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
        help="fit an identification pipeline (the default one unless --pipeline) "
        "and save it",
        description="Fit the default pipeline on labelled segments and save it "
        "with joblib, with the skpcd and scikit-learn versions.",
    )
    fit.add_argument("folder", help="folder of per-segment files")
    _add_pipeline_option(fit)
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

    seg = sub.add_parser(
        "segment",
        help="cut a scene into segments, one file each",
        description="Remove the ground (SMRF), cluster the rest (DBSCAN with "
        "automatic eps, or Euclidean clusters), keep segments within the size "
        "range and write one file per segment plus segments.csv (points and "
        "extents of each). Existing files are kept unless --overwrite.",
    )
    seg.add_argument("scene", help="a point-cloud file (.ply .pcd .las .laz .xyz ...)")
    seg.add_argument("-o", "--output", required=True, help="output folder")
    seg.add_argument(
        "--format",
        default="ply",
        choices=("ply", "pcd", "las", "laz", "xyz", "txt", "csv", "npy"),
        help="format of the segment files (default ply)",
    )
    seg.add_argument(
        "--keep-fields",
        action="store_true",
        help="copy the scene's extra fields (intensity...) into the segments",
    )
    seg.add_argument(
        "--tile-size",
        type=float,
        default=None,
        help="process the scene in square tiles of this side (metres), streaming "
        "LAS/LAZ input, so that memory is bounded by the tile, not the scene; "
        "same segments as without",
    )
    seg.add_argument(
        "--tile-buffer",
        type=float,
        default=None,
        help="overlap around each tile (m); default: the smallest that keeps "
        "the result exact (see segment_scene)",
    )
    _add_segmentation_options(seg)
    seg.set_defaults(func=_cmd_segment)

    ident = sub.add_parser(
        "identify",
        help="segment a scene and label each segment with a saved model",
        description="Segment a scene as 'skpcd segment' does, predict the class "
        "of each segment with a model written by 'skpcd fit', and write the "
        "scene with per-point fields segment (-1: none), class (index, -1: "
        "none), ground (1/0) and the probability or similarity of the answer. "
        "Class names go to OUTPUT_classes.csv beside the output.",
    )
    ident.add_argument("scene", help="a point-cloud file")
    ident.add_argument("--model", required=True, help="a model written by skpcd fit")
    ident.add_argument(
        "-o", "--output", required=True, help="labelled scene (.ply, .pcd, .las...)"
    )
    _add_segmentation_options(ident)
    ident.set_defaults(func=_cmd_identify)
    for p in (desc, fit, pred, seg):
        p.add_argument(
            "--scheduler",
            metavar="ADDRESS",
            help="run on an existing Dask cluster: the scheduler's address, e.g. "
            "tcp://host:8786 (needs pip install 'skpcd[dask]')",
        )
    return parser


# Seconds to wait for a Dask scheduler before giving up.
_SCHEDULER_TIMEOUT = 10


def _on_cluster(args):
    """Run the command inside ``joblib.parallel_config(backend="dask")``
    with a client of the scheduler at ``args.scheduler``."""
    try:
        from distributed import Client
    except ImportError as exc:
        raise SystemExit(
            f"skpcd {args.command}: --scheduler needs dask.distributed: pip "
            "install 'skpcd[dask]'"
        ) from exc
    import joblib

    try:
        client = Client(args.scheduler, timeout=_SCHEDULER_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SystemExit(
            f"skpcd {args.command}: cannot reach the Dask scheduler at "
            f"{args.scheduler} ({type(exc).__name__}: {exc})"
        ) from exc
    with client, joblib.parallel_config(backend="dask"):
        return args.func(args)


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
        if getattr(args, "scheduler", None):
            return _on_cluster(args)
        return args.func(args)
    except (PointCloudFileError, FileExistsError) as exc:  # bad input files
        print(f"skpcd {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
