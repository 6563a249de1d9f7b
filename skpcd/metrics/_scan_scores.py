"""Per-point scores of a labelled scan: IoU, precision, recall, confusion.

The measures of the semantic-segmentation benchmarks (SemanticKITTI,
Toronto-3D, Paris-Lille-3D): for each class ``c`` of the truth, over the
points not ignored, ``IoU = TP / (TP + FP + FN)``, precision ``TP / (TP +
FP)`` and recall ``TP / (TP + FN)``; mIoU is their mean over the classes
scored, the overall accuracy the share of points whose class is right.
"""

import numpy as np
from sklearn.utils import Bunch

__all__ = ["format_scan_scores", "scan_scores"]


def _codes(values, table):
    """Index of each value in ``table`` (a sorted array of str)."""
    uniq, inverse = np.unique(values, return_inverse=True)
    return np.searchsorted(table, uniq)[inverse.reshape(-1)]


def scan_scores(y_true, y_pred, *, classes=None, ignore=("ignore",)):
    """Per-point scores of a labelling: per-class IoU, precision and recall,
    mIoU, overall accuracy and the confusion matrix.

    Read more in the :ref:`User Guide <labelled-scan-scoring>`.

    Parameters
    ----------
    y_true : array-like of shape (n_points,)
        The true class of each point (names or codes; compared as text).
    y_pred : array-like of shape (n_points,)
        The predicted class of each point, in the same order.
    classes : sequence of str, default=None
        The classes scored (the rows of the matrix, the classes of mIoU).
        None: every true class that has points. A predicted class outside
        them gets a column of the matrix: its points count as false
        positives of no scored class and lower the accuracy.
    ignore : sequence of str, default=("ignore",)
        True classes whose points are left out (unlabelled, outliers).

    Returns
    -------
    scores : :class:`~sklearn.utils.Bunch`
        With ``classes`` (the rows), ``predicted`` (the columns: the rows,
        then the other predicted classes), ``confusion`` (counts, rows the
        true class; ndarray of shape (n_classes, n_predicted)),
        ``confusion_normalized`` (each row divided by its count),
        ``iou``, ``precision``, ``recall`` and ``support`` (dicts by class),
        ``miou``, ``accuracy``, ``n_points`` (the points scored) and
        ``n_ignored``.

    Raises
    ------
    ValueError
        If the arrays differ in length, no point is left to score, or a
        class of ``classes`` has no true point (its IoU would be undefined:
        leave it out).

    See Also
    --------
    format_scan_scores : The scores as text.
    skpcd.io.read_point_labels : Read the true classes of a scan.

    Examples
    --------
    >>> from skpcd.metrics import scan_scores
    >>> s = scan_scores(["car", "car", "tree", "tree"], ["car", "tree", "tree", "tree"])
    >>> s.iou, round(s.miou, 3), s.accuracy
    ({'car': 0.5, 'tree': 0.6666666666666666}, 0.583, 0.75)
    """
    y_true = np.asarray(y_true).astype(str).astype(object)
    y_pred = np.asarray(y_pred).astype(str).astype(object)
    if y_true.shape != y_pred.shape or y_true.ndim != 1:
        raise ValueError(
            f"y_true and y_pred must be 1-D and of the same length; got shapes "
            f"{y_true.shape} and {y_pred.shape}"
        )
    keep = ~np.isin(y_true, list(map(str, ignore)))
    n_ignored = int(len(keep) - keep.sum())
    y_true, y_pred = y_true[keep], y_pred[keep]
    if not len(y_true):
        raise ValueError("no point left to score (all are ignored, or none given)")
    present = np.unique(y_true)
    if classes is None:
        rows = [str(c) for c in present]
    else:
        rows = list(dict.fromkeys(map(str, classes)))
        empty = [c for c in rows if c not in set(present)]
        if empty:
            raise ValueError(
                f"class {empty[0]!r} has no true point: its IoU is undefined; "
                "leave it out of the classes scored"
            )
    others = set(np.unique(y_pred)) | set(present)
    cols = rows + sorted(others - set(rows))
    table = np.array(sorted(cols), dtype=object)
    where = {c: j for j, c in enumerate(cols)}
    to_cols = np.array([where[c] for c in table])  # sorted position -> column
    t = to_cols[_codes(y_true, table)]
    p = to_cols[_codes(y_pred, table)]
    n = len(cols)
    full = np.bincount(t * n + p, minlength=n * n).reshape(n, n)
    confusion = full[: len(rows)]
    tp = np.diag(full)[: len(rows)]
    support = confusion.sum(axis=1)
    predicted = full[:, : len(rows)].sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = tp / (support + predicted - tp)
        precision = np.where(predicted > 0, tp / np.maximum(predicted, 1), 0.0)
        recall = tp / support
        normalized = confusion / support[:, None]
    return Bunch(
        classes=rows,
        predicted=cols,
        confusion=confusion,
        confusion_normalized=normalized,
        iou=dict(zip(rows, iou.tolist())),
        precision=dict(zip(rows, precision.tolist())),
        recall=dict(zip(rows, recall.tolist())),
        support=dict(zip(rows, support.tolist())),
        miou=float(iou.mean()),
        accuracy=float(np.trace(full) / len(y_true)),
        n_points=len(y_true),
        n_ignored=n_ignored,
    )


def format_scan_scores(scores):
    """The scores of :func:`scan_scores` as the text ``skpcd score-scan``
    prints: a per-class table, mIoU and accuracy, and the confusion matrix
    in counts and normalised by row.

    Parameters
    ----------
    scores : Bunch
        What :func:`scan_scores` returns.

    Returns
    -------
    text : str
    """
    rows, cols = scores.classes, scores.predicted
    width = max(9, *(len(c) for c in cols))
    lines = [
        f"mIoU      {scores.miou:.4f} over {len(rows)} classes",
        f"accuracy  {scores.accuracy:.4f} on {scores.n_points} points"
        + (f" ({scores.n_ignored} ignored)" if scores.n_ignored else ""),
        "",
        f"{'class':>{width}} {'IoU':>9} {'precision':>9} {'recall':>9} {'points':>10}",
    ]
    for c in rows:
        lines.append(
            f"{c:>{width}} {scores.iou[c]:9.4f} {scores.precision[c]:9.4f} "
            f"{scores.recall[c]:9.4f} {scores.support[c]:10d}"
        )
    count_width = max(width, len(str(scores.confusion.max())))
    head = " " * count_width + " " + " ".join(f"{c:>{count_width}}" for c in cols)
    lines += ["", "confusion matrix, points (rows: true, columns: predicted)", head]
    for c, row in zip(rows, scores.confusion):
        lines.append(
            f"{c:>{count_width}} " + " ".join(f"{v:>{count_width}d}" for v in row)
        )
    lines += ["", "confusion matrix, share of each true class", head]
    for c, row in zip(rows, scores.confusion_normalized):
        lines.append(
            f"{c:>{count_width}} " + " ".join(f"{v:>{count_width}.3f}" for v in row)
        )
    return "\n".join(lines)
