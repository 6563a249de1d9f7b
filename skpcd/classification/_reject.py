"""An "unknown" answer for any probabilistic classifier: reject below a confidence."""

import numbers
import typing

from sklearn.base import (
    BaseEstimator,
    ClassifierMixin,
    MetaEstimatorMixin,
    _fit_context,
    clone,
)
from sklearn.utils import get_tags
from sklearn.utils._param_validation import HasMethods, Interval

from skpcd.classification._unknown import best_or_unknown, unknown_label_for
from skpcd.classification._wrapped import _WrappedClassifierMixin

__all__ = ["RejectUnknown"]


class RejectUnknown(
    _WrappedClassifierMixin, MetaEstimatorMixin, ClassifierMixin, BaseEstimator
):
    """Answer "unknown" where a classifier's best class probability is low.

    Wraps a classifier with ``predict_proba``: :meth:`predict` gives its
    most probable class, or ``unknown_label`` when that class's probability
    is below ``threshold``, so that a segment of a class never seen in
    training (a bench among poles, a kiosk among cars) can be left
    unidentified instead of taking the nearest known class. It is the
    answer :class:`~skpcd.classification.CaseBasedClassifier` gives below
    its similarity threshold, for any classifier;
    :func:`~skpcd.classification.make_default_pipeline` ends in one when
    given ``unknown_threshold``.

    Read more in the :ref:`User Guide <unknown_answer>`.

    Parameters
    ----------
    estimator : classifier
        A classifier with ``predict_proba``; cloned in :meth:`fit`.
    threshold : float or None, default=0.5
        Least probability of the best class for an answer. None: always
        answer (the wrapped classifier's prediction). 0.5 answers only
        where one class is more likely than all the others together.
    unknown_label : str, int, float or None, default=None
        The prediction for rejected segments. None: ``"unknown"`` for
        string or object labels; for numeric ones ``-1``, or one less than
        the smallest class when that is below 0 (as
        :class:`~skpcd.classification.CaseBasedClassifier`). A given label
        must not be a training class.

    Attributes
    ----------
    estimator_ : classifier
        The fitted clone of ``estimator``.
    classes_ : ndarray of shape (n_classes,)
        The training classes (never ``unknown_label``).
    unknown_label_ : str, int or float
        The label of rejected segments.
    n_features_in_ : int
        Features seen in :meth:`fit` (when the estimator records it).

    See Also
    --------
    CaseBasedClassifier : Rejects below a similarity to the known cases.
    predict_with_confidence : The answer and the probability behind it.

    Notes
    -----
    The probability of a random forest is the share of its trees voting
    for the class: it is not calibrated, so the threshold is chosen by
    cross-validation on classes held out of training (leave one class
    out; ``benchmarks/bench_street_identification.py``), which measures
    what a threshold costs on known classes and what share of objects of
    unseen classes it rejects.

    Examples
    --------
    >>> from sklearn.tree import DecisionTreeClassifier
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> from skpcd.classification import RejectUnknown
    >>> X = [[0.0], [0.1], [1.0], [1.1]]
    >>> forest = RandomForestClassifier(n_estimators=50, random_state=0)
    >>> model = RejectUnknown(forest, threshold=0.9).fit(X, ["a", "a", "b", "b"])
    >>> model.predict([[0.05], [0.55], [1.05]]).tolist()
    ['a', 'unknown', 'b']
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "estimator": [HasMethods(["fit", "predict_proba"])],
        "threshold": [Interval(numbers.Real, 0, 1, closed="both"), None],
        "unknown_label": [str, numbers.Real, None],
    }

    def __init__(self, estimator, *, threshold=0.5, unknown_label=None):
        self.estimator = estimator
        self.threshold = threshold
        self.unknown_label = unknown_label

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y, **fit_params):
        """Fit the classifier.

        Parameters
        ----------
        X : array-like
            What the classifier takes.
        y : array-like of shape (n_samples,)
            The classes.
        **fit_params : dict
            Passed to the classifier's ``fit``.

        Returns
        -------
        self : RejectUnknown
            The fitted estimator.
        """
        self._adopt(clone(self.estimator).fit(X, y, **fit_params))
        self.unknown_label_ = unknown_label_for(self.classes_, self.unknown_label)
        return self

    def predict(self, X):
        """The most probable class, or ``unknown_label_`` below ``threshold``.

        Parameters
        ----------
        X : array-like
            What the classifier takes.

        Returns
        -------
        y : ndarray of shape (n_samples,)
            A class of ``classes_``, or ``unknown_label_``. Its dtype holds
            both (object when one is a string and the other a number).
        """
        return best_or_unknown(
            self.predict_proba(X), self.classes_, self.threshold, self.unknown_label_
        )

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags = get_tags(self.estimator).input_tags
        tags.target_tags.required = True
        return tags
