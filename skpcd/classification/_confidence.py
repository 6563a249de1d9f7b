"""The answer of a fitted model and how sure it is, whatever its kind."""

import numpy as np

from skpcd.classification._case_based import CaseBasedClassifier
from skpcd.classification._reject import RejectUnknown
from skpcd.classification._unknown import best_or_unknown

__all__ = ["predict_with_confidence"]


def predict_with_confidence(model, X):
    """Predict, and say how sure each answer is.

    Parameters
    ----------
    model : estimator or sklearn.pipeline.Pipeline
        A fitted classifier (or a pipeline ending in one).
    X : list of array-like
        What ``model.predict`` takes (a list of clouds for skpcd's
        pipelines).

    Returns
    -------
    pred : ndarray of shape (n_samples,)
        ``model.predict(X)``; may hold a label outside ``classes_`` (the
        ``"unknown"`` of a case-based model or of a
        :class:`~skpcd.classification.RejectUnknown`, such as
        ``make_default_pipeline(unknown_threshold=0.5)``).
    kind : {"similarity", "probability"} or None
        ``"similarity"`` when the final step is a
        :class:`CaseBasedClassifier` (the best similarity over all cases,
        between -1 and 1), ``"probability"`` when the model has
        ``predict_proba`` (the probability of the predicted class; for an
        ``"unknown"`` answer, the best class probability, which is below
        the model's threshold), None otherwise.
    score : ndarray of shape (n_samples,) or None
        The confidence of each answer, None when ``kind`` is None.

    Examples
    --------
    >>> from sklearn.tree import DecisionTreeClassifier
    >>> from skpcd.classification import predict_with_confidence
    >>> model = DecisionTreeClassifier().fit([[0], [1]], ["a", "b"])
    >>> pred, kind, score = predict_with_confidence(model, [[0], [1]])
    >>> pred.tolist(), kind, score.tolist()
    (['a', 'b'], 'probability', [1.0, 1.0])
    """
    # the descriptors are computed once, for the answer and its confidence
    if getattr(model, "steps", None):
        final, Xt = model[-1], model[:-1].transform(X)
    else:
        final, Xt = model, X
    if isinstance(final, CaseBasedClassifier):
        return final.predict(Xt), "similarity", final.class_similarity(Xt).max(axis=1)
    if isinstance(final, RejectUnknown):  # its answer is read from proba: once
        proba = final.predict_proba(Xt)
        pred = best_or_unknown(
            proba, final.classes_, final.threshold, final.unknown_label_
        )
    elif not hasattr(final, "predict_proba"):
        return np.asarray(final.predict(Xt)), None, None
    else:
        pred = np.asarray(final.predict(Xt))
        proba = final.predict_proba(Xt)
    column = {c: j for j, c in enumerate(final.classes_)}
    cols = np.array([column.get(p, -1) for p in pred], dtype=np.int64)
    rows = np.arange(len(pred))
    score = np.where(cols >= 0, proba[rows, np.maximum(cols, 0)], proba.max(axis=1))
    return pred, "probability", score
