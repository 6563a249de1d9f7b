"""The base classes of skpcd's estimators: the transformers that take a list
of clouds and learn nothing (:class:`CloudTransformer`), and the estimators
fitted on one cloud, a scene (:class:`SceneEstimator`).

:class:`CloudTransformer` holds what every such transformer does the same
way: ``fit`` validates and records ``n_features_in_``, ``transform`` is a
template (validate the clouds, then :func:`~skpcd.utils._parallel.map_batches`
of the subclass's ``_transform_batch``), ``fit_transform`` validates once.
imbalanced-learn's ``SamplerMixin.fit_resample`` -> ``_fit_resample`` is the
model. A subclass writes two methods:

- ``_validate(X)``: the clouds, checked (extend the default,
  :func:`~skpcd.utils.check_point_clouds`, with the subclass's own checks);
- ``_transform_batch(clouds, n_threads)``: the output of a batch of
  validated clouds, its kernels on ``n_threads`` threads (an int: ``n_jobs``
  is resolved once, by ``map_batches``). A list (one entry per cloud), an
  array (one row per cloud) or a tuple of those.

A subclass may override ``transform`` for its docstring only (``return
super().transform(X)``). One that writes its own ``transform`` instead of
``_transform_batch`` (calling ``map_batches`` itself, as before this
template) still works: ``fit_transform`` then calls that ``transform``.
"""

from sklearn.base import BaseEstimator, TransformerMixin, _fit_context

from skpcd.utils._compile import entry_point
from skpcd.utils._parallel import map_batches
from skpcd.utils._progress import stage
from skpcd.utils._validation import check_point_clouds, check_scene

__all__ = ["CloudTransformer", "SceneEstimator"]


class CloudTransformer(TransformerMixin, BaseEstimator):
    """Stateless transformer of a list of point clouds.

    :meth:`fit` validates the parameters and the clouds (through
    :meth:`_validate`, which subclasses may extend) and records
    ``n_features_in_``; :meth:`transform` validates the clouds and maps
    ``_transform_batch`` over batches of them; the tags say that X is not
    a 2-D array and that :meth:`transform` needs no fit.
    """

    # pooled outputs are much smaller than their temporaries: run the
    # batches one after the other also in-process (bounded memory)
    _bounded_batches = False

    def _validate(self, X):
        return check_point_clouds(X)

    def _fit_clouds(self, X):
        """What :meth:`fit` checks and sets; returns the validated clouds."""
        clouds = self._validate(X)
        self.n_features_in_ = clouds[0].shape[1] if clouds else 3
        return clouds

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
        self._fit_clouds(X)
        return self

    @_fit_context(prefer_skip_nested_validation=True)
    def fit_transform(self, X, y=None):
        """Fit and transform, checking the clouds once.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds.
        y : None
            Ignored.

        Returns
        -------
        Xt : list of ndarray or ndarray
            As :meth:`transform`.
        """
        clouds = self._fit_clouds(X)
        if type(self)._transform_batch is CloudTransformer._transform_batch:
            return self.transform(X)  # a subclass with its own transform
        return self._map_batches(clouds)

    def transform(self, X):
        """Transform every cloud.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds.

        Returns
        -------
        Xt : list of ndarray or ndarray
            One array per cloud, or one row per cloud.
        """
        return self._map_batches(self._validate(X))

    @entry_point
    def _map_batches(self, clouds):
        """``_transform_batch`` over batches of validated clouds (a first
        call that compiles kernels says so on stderr, see
        :mod:`skpcd.utils._compile`)."""
        return map_batches(
            self._transform_batch,
            clouds,
            getattr(self, "n_jobs", None),
            bounded=self._bounded_batches,
        )

    def _transform_batch(self, clouds, n_threads):
        raise NotImplementedError(
            f"{type(self).__name__} must define _transform_batch (or transform)"
        )

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.requires_fit = False
        return tags


class SceneEstimator(BaseEstimator):
    """An estimator fitted on one cloud, a scene (a clusterer, a filter).

    :meth:`fit` validates the parameters and the cloud (an ``(n_points,
    3+)`` array, its xyz as contiguous float64 through
    :func:`~skpcd.utils._validation.check_scene`, ``n_features_in_``
    recorded) and hands the xyz to the subclass's ``_fit(xyz)``.
    ``_min_points(self)`` gives the fewest points it takes (1).
    """

    def _min_points(self):
        return 1

    @_fit_context(prefer_skip_nested_validation=True)
    @entry_point
    def fit(self, X, y=None):
        """Fit on one cloud.

        Parameters
        ----------
        X : array-like of shape (n_points, 3+)
            The cloud; columns beyond the third are ignored.
        y : None
            Ignored.

        Returns
        -------
        self : object
            The fitted estimator.
        """
        xyz = check_scene(X, self, min_points=self._min_points())
        method = getattr(self, "method", None)
        name = type(self).__name__ + (f" ({method})" if method else "")
        with stage(name):  # on the command's terminal only
            self._fit(xyz)
        return self
