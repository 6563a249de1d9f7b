"""The "unknown" answer of the classifiers that may refuse to name a class.

:class:`~skpcd.classification.CaseBasedClassifier` (below a similarity) and
:class:`~skpcd.classification.RejectUnknown` (below a probability) answer
the same label in the same way: one place for its default, for the check
that it is not a class, and for where it replaces the best class.
"""

import numpy as np

__all__ = ["best_or_unknown", "unknown_label_for"]


def unknown_label_for(classes, unknown_label, *, answered=True):
    """The label of the "unknown" answer for these classes.

    Parameters
    ----------
    classes : ndarray of shape (n_classes,)
        The sorted training classes.
    unknown_label : str, int, float or None
        The label asked for; None: ``"unknown"`` for string (or object)
        classes, ``-1`` for numbers, or one below the smallest class when
        ``-1`` is a class.
    answered : bool, default=True
        Whether predictions may answer it: then a label that is one of the
        classes is an error.

    Returns
    -------
    unknown_label : str, int or float
        The label.
    """
    if unknown_label is None:
        if classes.dtype.kind in "OUS":
            unknown_label = "unknown"
        else:
            low = classes.min().item() - 1  # a Python number: no unsigned wrap
            unknown_label = -1 if low >= -1 else low
    if answered and unknown_label in classes.tolist():
        raise ValueError(
            f"unknown_label={unknown_label!r} is a training class; "
            "pass another unknown_label"
        )
    return unknown_label


def best_or_unknown(scores, classes, threshold, unknown_label):
    """The class of the best score, or ``unknown_label`` where it is below
    ``threshold``.

    Parameters
    ----------
    scores : ndarray of shape (n_samples, n_classes)
        Scores of the classes (probabilities, similarities), columns in the
        order of ``classes``.
    classes : ndarray of shape (n_classes,)
        The classes.
    threshold : float or None
        The least best score that names a class; None names one always.
    unknown_label : str, int or float
        The answer below ``threshold``.

    Returns
    -------
    y : ndarray of shape (n_samples,)
        The answers, in a dtype that holds both the classes and
        ``unknown_label`` (object when one is a string and the other a
        number).
    """
    pred = classes[np.argmax(scores, axis=1)]
    if threshold is None:
        return pred
    unknown = np.asarray(unknown_label)
    kinds = pred.dtype.kind + unknown.dtype.kind
    if set(kinds) <= set("biuf") or set(kinds) <= set("U"):
        pred = pred.astype(np.result_type(pred, unknown))
    else:  # e.g. integer classes and a string label
        pred = pred.astype(object)
    pred[scores.max(axis=1) < threshold] = unknown_label
    return pred
