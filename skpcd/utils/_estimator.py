"""The base class of the transformers that take a list of clouds and learn nothing."""

from sklearn.base import BaseEstimator, TransformerMixin, _fit_context

from skpcd.utils._validation import check_point_clouds

__all__ = ["CloudTransformer"]


class CloudTransformer(TransformerMixin, BaseEstimator):
    """Stateless transformer of a list of point clouds.

    :meth:`fit` validates the parameters and the clouds (through
    :meth:`_validate`, which subclasses may extend) and records
    ``n_features_in_``; the tags say that X is not a 2-D array and that
    :meth:`transform` needs no fit.
    """

    def _validate(self, X):
        return check_point_clouds(X)

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y=None):
        """Check the parameters and the clouds; nothing is learned.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds.
        y : None
            Ignored.

        Returns
        -------
        self : object
            The transformer.
        """
        clouds = self._validate(X)
        self.n_features_in_ = clouds[0].shape[1] if clouds else 3
        return self

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.requires_fit = False
        return tags
