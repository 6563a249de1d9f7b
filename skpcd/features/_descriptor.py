"""What the descriptor transformers share: their column names, and the checks
and ``transform`` of the descriptors of whole segments.

:class:`FeatureNamesMixin` writes ``get_feature_names_out`` once, from the
names a descriptor lists in ``_feature_names()``; :class:`SegmentDescriptor`
is the base of the transformers that give one row per segment from its xyz
alone (:class:`~skpcd.features.OverallDescriptor`,
:class:`~skpcd.features.ShapeFeatures`,
:class:`~skpcd.features.VerticalProfile`).
"""

import numpy as np

from skpcd.utils._estimator import CloudTransformer
from skpcd.utils._validation import check_extents

__all__ = ["FeatureNamesMixin", "SegmentDescriptor", "check_size_extents"]

# Extents up to this keep every size finite in float64 (a volume is the
# product of three sides, an area of two): larger ones are refused.
MAX_SIZE_EXTENT = 1e100


def numbered(prefix, n):
    """The names of ``n`` histogram bins: ``prefix0``, ``prefix1``..."""
    return [f"{prefix}{i}" for i in range(n)]


def check_size_extents(clouds, input_name="X"):
    """Refuse clouds whose sizes (area, volume) would overflow float64.

    Parameters
    ----------
    clouds : list of ndarray of shape (n_points_i, 3+)
        Validated clouds, at least one point each.
    input_name : str, default="X"
        Name used in the error message.

    Raises
    ------
    ValueError
        If a cloud spans more than ``MAX_SIZE_EXTENT`` (1e100) along an axis.
    """
    lo = np.array([c[:, :3].min(axis=0) for c in clouds], dtype=np.float64)
    hi = np.array([c[:, :3].max(axis=0) for c in clouds], dtype=np.float64)
    check_extents(
        lo.reshape(-1, 3),
        hi.reshape(-1, 3),
        MAX_SIZE_EXTENT,
        input_name=input_name,
        what="its box volume and shape features (float64)",
    )


class FeatureNamesMixin:
    """``get_feature_names_out`` from the column names a descriptor lists.

    A subclass writes ``_feature_names()``: the names of its output columns,
    in order (they may depend on its parameters, e.g. ``n_bins``).
    """

    def get_feature_names_out(self, input_features=None):
        """Names of the output columns, in order.

        A histogram's columns are its bins, named by the descriptor and the
        bin's number (``pfh0``, ``fpfh0``, ``improved_pfh0``...); the other
        descriptors name what each column holds (their Notes say how it is
        computed). A per-point descriptor with ``pooling`` names the columns
        of its one row per cloud (so that it composes in a
        :class:`~sklearn.pipeline.FeatureUnion`); without, the columns of
        every per-point array.

        Parameters
        ----------
        input_features : None
            Ignored: the names do not depend on the input columns.

        Returns
        -------
        names : ndarray of str
            One name per output column.
        """
        return np.asarray(self._feature_names(), dtype=object)


class SegmentDescriptor(FeatureNamesMixin, CloudTransformer):
    """Base of the descriptors of whole segments from their xyz.

    One row per segment, computed in float64 relative to the segment's
    lower corner; :meth:`_validate` refuses a segment whose sizes would
    overflow float64 (:func:`check_size_extents`). A subclass writes
    ``_transform_batch`` (the rows of a batch of validated segments) and
    ``_feature_names``.
    """

    def _validate(self, X):
        clouds = super()._validate(X)
        check_size_extents(clouds)
        return clouds

    def transform(self, X):
        """Compute the descriptor of each segment.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The segments, at least one point each; only xyz is read.

        Returns
        -------
        features : ndarray of shape (n_segments, n_features)
            One row per segment, its columns named by
            :meth:`get_feature_names_out`.
        """
        return super().transform(X)
