"""What the classifiers wrapping one fitted classifier share.

:class:`~skpcd.classification.RejectUnknown` and
:class:`~skpcd.classification.SimulationAugmented` each fit a clone of their
``estimator`` and answer through it: they take its classes and its input
width as their own and pass its class probabilities on.
"""

from sklearn.utils.validation import check_is_fitted

__all__ = []


class _WrappedClassifierMixin:
    """A classifier answering through its fitted ``estimator_``."""

    def _adopt(self, estimator):
        """Keep the fitted ``estimator`` as ``estimator_``, with its classes
        and (when it has one) its number of input features; returns self."""
        self.estimator_ = estimator
        self.classes_ = estimator.classes_
        if hasattr(estimator, "n_features_in_"):
            self.n_features_in_ = estimator.n_features_in_
        return self

    def predict_proba(self, X):
        """Class probabilities of each sample, as the fitted estimator gives them.

        Parameters
        ----------
        X : array-like or list of array-like
            What the wrapped classifier takes.

        Returns
        -------
        proba : ndarray of shape (n_samples, n_classes)
            Columns in the order of ``classes_``.
        """
        check_is_fitted(self)
        return self.estimator_.predict_proba(X)
