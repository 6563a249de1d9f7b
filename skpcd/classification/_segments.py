"""The class of each segment of a segmented scene, predicted in batches."""

import numpy as np

from skpcd.classification._confidence import predict_with_confidence

__all__ = ["identify_segments"]

# points of the segments predicted at a time (a bound on the memory)
BATCH_POINTS = 2_000_000


def identify_segments(
    model, segments, *, kinds=None, batch_points=BATCH_POINTS, predict=None
):
    """Predict the class of each segment, and how sure each answer is.

    The segments are read one at a time from ``segments`` and predicted in
    batches of about ``batch_points`` points, so that a scene's segments
    need not all be in memory; the answers do not depend on the batches.

    Parameters
    ----------
    model : estimator or sklearn.pipeline.Pipeline
        A fitted classifier of clouds (for example the model written by
        ``skpcd fit``, or :func:`~skpcd.classification.load_street_model`).
    segments : iterable of (ndarray of shape (n_points_i, 3), dict)
        The points of each segment and their fields (ignored), in order, as
        :func:`~skpcd.segmentation.segment_scene`'s labels give them.
    kinds : sequence of str, default=None
        Type of each segment (``SceneSegmentation.kinds``): segments whose
        type is not ``"object"`` (facades, wires) are not predicted, their
        answer is their type with no score. None: every segment is an
        object.
    batch_points : int, default=2_000_000
        Points predicted at a time, at least (a batch ends with the segment
        that reaches it).
    predict : callable, default=None
        ``predict(model, clouds) -> (pred, kind, score)``;
        None is :func:`~skpcd.classification.predict_with_confidence`.

    Returns
    -------
    pred : ndarray of object of shape (n_segments,)
        The answer of each segment.
    kind : {"similarity", "probability"} or None
        What the scores are (see
        :func:`~skpcd.classification.predict_with_confidence`).
    score : ndarray of shape (n_segments,)
        The confidence of each answer; NaN where there is none.
    sizes : ndarray of int of shape (n_segments,)
        Points of each segment.

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.pipeline import make_pipeline
    >>> from sklearn.preprocessing import FunctionTransformer
    >>> from sklearn.tree import DecisionTreeClassifier
    >>> from skpcd.classification import identify_segments
    >>> height = FunctionTransformer(lambda X: [[np.ptp(c[:, 2])] for c in X])
    >>> model = make_pipeline(height, DecisionTreeClassifier())
    >>> low, tall = np.zeros((5, 3)), np.column_stack([np.zeros((5, 2)), np.arange(5)])
    >>> model = model.fit([low, tall], ["kerb", "pole"])
    >>> segments = [(tall, {}), (low, {}), (low, {})]
    >>> kinds = ["object", "object", "facade"]
    >>> pred, kind, score, sizes = identify_segments(model, segments, kinds=kinds)
    >>> pred.tolist(), kind, sizes.tolist()
    (['pole', 'kerb', 'facade'], 'probability', [5, 5, 5])
    """
    predict = predict_with_confidence if predict is None else predict
    preds, scores, sizes, kind, batch, size = [], [], [], None, [], 0
    fixed = {}

    def flush():
        nonlocal kind
        pred, kind, score = predict(model, batch)
        preds.append(np.asarray(pred))
        scores.append(np.full(len(batch), np.nan) if score is None else score)
        batch.clear()

    for i, (seg, _) in enumerate(segments):
        sizes.append(len(seg))
        if kinds is not None and kinds[i] != "object":
            fixed[i] = str(kinds[i])
            continue
        batch.append(seg)
        size += len(seg)
        if size >= batch_points:
            flush()
            size = 0
    if batch:
        flush()
    n = len(sizes)
    pred = np.empty(n, dtype=object)
    score = np.full(n, np.nan)
    predicted = np.setdiff1d(np.arange(n), list(fixed)) if fixed else np.arange(n)
    if preds:
        pred[predicted] = np.concatenate(preds)
        score[predicted] = np.concatenate(scores)
    for i, name in fixed.items():
        pred[i] = name
    return pred, kind, score, np.array(sizes, dtype=int)
