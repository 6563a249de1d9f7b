"""Outlier removal: the statistical and radius filters of PCL and PDAL.

Both flag the points of one cloud from their neighbourhoods in that cloud
(found once by :func:`~skpcd.neighbors.compute_neighborhoods`), as PCL's
``StatisticalOutlierRemoval`` and ``RadiusOutlierRemoval`` and PDAL's
``filters.outlier`` do: a far point (a bird, a multipath echo, a point
1 km away) is removed before a step whose cost follows the extent of the
scene, like the ground filter's raster.
"""

import typing
from numbers import Integral, Real

import numpy as np
from sklearn.base import OutlierMixin
from sklearn.utils._param_validation import Interval

from skpcd.neighbors._neighbors import compute_neighborhoods
from skpcd.utils._compile import entry_point
from skpcd.utils._estimator import SceneEstimator

__all__ = ["RadiusOutlierFilter", "StatisticalOutlierFilter"]


class _OutlierFilter(OutlierMixin, SceneEstimator):
    """fit_predict as scikit-learn's outlier detectors: +1 inlier, -1 outlier."""

    @entry_point
    def fit_predict(self, X, y=None):
        """Flag the outliers of a cloud.

        Parameters
        ----------
        X : array-like of shape (n_points, 3+)
            The cloud; columns beyond the third are ignored.
        y : None
            Ignored.

        Returns
        -------
        labels : ndarray of shape (n_points,), dtype int64
            1 for an inlier, -1 for an outlier (scikit-learn's convention).
        """
        return np.where(self.fit(X).inlier_mask_, 1, -1)


class StatisticalOutlierFilter(_OutlierFilter):
    """Outliers by their mean distance to their neighbours (PCL, PDAL).

    The mean distance of each point to its ``n_neighbors`` nearest
    neighbours (the point itself excluded) is computed; a point is an
    outlier when that mean is larger than ``mean + std_ratio * std`` of the
    means of all points (``std`` the sample standard deviation), the rule
    of PCL's ``StatisticalOutlierRemoval`` and PDAL's ``filters.outlier``
    (``method="statistical"``).

    The filter is transductive, like
    :class:`~sklearn.neighbors.LocalOutlierFactor`: it flags the points of
    the cloud it is fitted on (:meth:`fit_predict`, ``inlier_mask_``) and
    has no ``predict`` for other points.

    Parameters
    ----------
    n_neighbors : int, default=8
        Neighbours of each point, itself excluded (PCL's ``MeanK``, PDAL's
        ``mean_k``).
    std_ratio : float, default=2.0
        Multiple of the standard deviation above the mean distance beyond
        which a point is an outlier (PCL's ``StddevMulThresh``, PDAL's
        ``multiplier``).
    n_jobs : int, default=None
        Threads for the neighbour search; None means 1, -1 all cores.

    Attributes
    ----------
    mean_distances_ : ndarray of shape (n_points,)
        Mean distance of each point to its neighbours.
    threshold_ : float
        The largest mean distance of an inlier.
    inlier_mask_ : ndarray of shape (n_points,), dtype bool
        True for the inliers.
    n_features_in_ : int
        Number of columns of X seen in :meth:`fit`.

    See Also
    --------
    RadiusOutlierFilter : Outliers by their number of neighbours in a radius.

    Notes
    -----
    Distances are those of :func:`~skpcd.neighbors.compute_neighborhoods`
    (squared distances stored in float32, as PCL's). A cloud of at most
    ``n_neighbors`` points gives each point all the others; a cloud of one
    point keeps it.

    References
    ----------
    .. [1] R. B. Rusu, Z. C. Marton, N. Blodow, M. Dolha, M. Beetz, "Towards
       3D Point cloud based object maps for household environments",
       Robotics and Autonomous Systems 56(11), 927-941, 2008.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.preprocessing import StatisticalOutlierFilter
    >>> rng = np.random.default_rng(0)
    >>> plane = np.column_stack([rng.uniform(0, 10, (2000, 2)), np.zeros(2000)])
    >>> X = np.vstack([plane, [[1000.0, 0.0, 0.0]]])
    >>> labels = StatisticalOutlierFilter().fit_predict(X)
    >>> int((labels == -1).sum()), int(labels[-1])
    (1, -1)
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "n_neighbors": [Interval(Integral, 1, None, closed="left")],
        "std_ratio": [Interval(Real, None, None, closed="neither")],
        "n_jobs": [Integral, None],
    }

    def __init__(self, *, n_neighbors=8, std_ratio=2.0, n_jobs=None):
        self.n_neighbors = n_neighbors
        self.std_ratio = std_ratio
        self.n_jobs = n_jobs

    def _fit(self, xyz):
        n = len(xyz)
        if n == 1:
            self.mean_distances_ = np.zeros(1)
            self.threshold_ = 0.0
            self.inlier_mask_ = np.ones(1, dtype=bool)
            return
        k = min(int(self.n_neighbors), n - 1) + 1
        nb = compute_neighborhoods(xyz, n_neighbors=k, n_jobs=self.n_jobs)
        dist = np.sqrt(nb.sqdist.reshape(n, k).astype(np.float64))
        # the first is the point itself (or a duplicate of it: distance 0)
        self.mean_distances_ = dist[:, 1:].mean(axis=1)
        std = self.mean_distances_.std(ddof=1) if n > 1 else 0.0
        self.threshold_ = float(self.mean_distances_.mean() + self.std_ratio * std)
        self.inlier_mask_ = self.mean_distances_ <= self.threshold_


class RadiusOutlierFilter(_OutlierFilter):
    """Outliers by their number of neighbours within a radius (PCL, PDAL).

    A point with fewer than ``min_neighbors`` other points within
    ``radius`` (inclusive) is an outlier, the rule of PCL's
    ``RadiusOutlierRemoval`` and PDAL's ``filters.outlier``
    (``method="radius"``).

    The filter is transductive, like
    :class:`~sklearn.neighbors.LocalOutlierFactor`: it flags the points of
    the cloud it is fitted on (:meth:`fit_predict`, ``inlier_mask_``) and
    has no ``predict`` for other points.

    Parameters
    ----------
    radius : float, default=1.0
        Search radius (PCL's ``RadiusSearch``, PDAL's ``radius``).
    min_neighbors : int, default=2
        Fewest other points within ``radius`` of an inlier (PCL's
        ``MinNeighborsInRadius``).
    n_jobs : int, default=None
        Threads for the neighbour search; None means 1, -1 all cores.

    Attributes
    ----------
    n_neighbors_ : ndarray of shape (n_points,), dtype int64
        Other points within ``radius`` of each point.
    inlier_mask_ : ndarray of shape (n_points,), dtype bool
        True for the inliers.
    n_features_in_ : int
        Number of columns of X seen in :meth:`fit`.

    See Also
    --------
    StatisticalOutlierFilter : Outliers by their mean neighbour distance.

    Notes
    -----
    The neighbours are counted by
    :func:`~skpcd.neighbors.compute_neighborhoods` (memory
    O(n_points * neighbours): choose a radius of a few point spacings).

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.preprocessing import RadiusOutlierFilter
    >>> rng = np.random.default_rng(0)
    >>> plane = np.column_stack([rng.uniform(0, 10, (2000, 2)), np.zeros(2000)])

    A lone point and a pair of points 0.2 apart, far from a plane: with
    ``min_neighbors=2`` the pair is flagged too, with 1 it is kept.

    >>> X = np.vstack([plane, [[1000.0, 0, 0], [50.0, 0, 0], [50.2, 0, 0]]])
    >>> RadiusOutlierFilter(radius=0.5).fit_predict(X)[-3:]
    array([-1, -1, -1])
    >>> RadiusOutlierFilter(radius=0.5, min_neighbors=1).fit_predict(X)[-3:]
    array([-1,  1,  1])
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "radius": [Interval(Real, 0, None, closed="neither")],
        "min_neighbors": [Interval(Integral, 0, None, closed="left")],
        "n_jobs": [Integral, None],
    }

    def __init__(self, *, radius=1.0, min_neighbors=2, n_jobs=None):
        self.radius = radius
        self.min_neighbors = min_neighbors
        self.n_jobs = n_jobs

    def _fit(self, xyz):
        nb = compute_neighborhoods(xyz, radius=float(self.radius), n_jobs=self.n_jobs)
        # the point itself is among its neighbours
        self.n_neighbors_ = nb.sizes.astype(np.int64) - 1
        self.inlier_mask_ = self.n_neighbors_ >= self.min_neighbors
