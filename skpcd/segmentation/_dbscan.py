"""DBSCAN with eps estimated from the data (Wang et al., Sensors 2019).

For k = 1 .. ``n_neighbors``, the distance from a point to its k-th nearest
neighbour (the largest of its k nearest-neighbour distances) is averaged
over the points; a polynomial fitted to this curve of k is smooth, and its
knee (where it departs most from its chord) gives the knee distance: below
it the k nearest neighbours are on the point's own surface, beyond it they
reach farther. The radius is ``eps_scale`` times that distance, the factor
chosen by cross-validation on scenes of real objects
(``benchmarks/bench_segmentation_quality.py``). The clustering itself is the
grid DBSCAN of :mod:`skpcd.segmentation._clusters`, in O(n_points) memory.
"""

import typing
from numbers import Integral, Real

import numpy as np
from scipy.spatial import cKDTree
from sklearn.base import ClusterMixin
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval

from skpcd.neighbors._neighbors import search_packed
from skpcd.segmentation._clusters import grid_dbscan
from skpcd.utils._compile import entry_point
from skpcd.utils._estimator import SceneEstimator
from skpcd.utils._parallel import effective_threads
from skpcd.utils._validation import check_scene

__all__ = ["AutoEpsDBSCAN", "eps_from_knee", "estimate_eps", "fit_knee"]

# Points of the fitted curve searched for the knee.
_KNEE_GRID = 1000

# Default multiple of the knee distance: chosen by 4-fold cross-validation on
# scenes of development DALES objects, candidates 1 to 4 in steps of 0.25
# (benchmarks/bench_segmentation_quality.py; results in
# benchmarks/results/segmentation_quality.txt).
EPS_SCALE = 2.5


# A sampled point with a k-distance more than this many times the 99th
# percentile of the k-distances (for any k) is far from every surface of
# the scene, and left out of the mean of the curve. On the 12 real sweeps
# of ../shared/data/real_mobile the largest k-distance of any point is at
# most 52 times that percentile (k = 1; 4 to 14 times at k = 30), so no
# real point is left out; a point 100 m above a sweep is 400 times it at
# k = 1, one 100 km or 1e30 away far more.
_FAR_OUT = 100.0


def stable_draw(n, size, rng, *, chunk=1 << 22):
    """Indices of ``size`` of ``n`` points drawn without replacement, in
    the order of their draw: the points of the ``size`` smallest of ``n``
    uniform keys (``rng.random``, drawn ``chunk`` at a time so that memory
    stays O(size + chunk)), ordered by key.

    The keys of the first points do not depend on ``n``: appending points
    to a cloud (a few far outliers) changes a draw by at most the points
    appended and as many others, where a plain ``rng.choice(n, size)``
    draws an unrelated sample. The one place of this draw, for
    :func:`sample_queries` and :func:`~skpcd.segmentation.describe_scan`.
    """
    size = min(int(size), n)
    keys, rows = np.zeros(0), np.zeros(0, dtype=np.int64)
    for start in range(0, n, chunk):
        new = rng.random(min(chunk, n - start))
        keys = np.concatenate([keys, new])
        rows = np.concatenate([rows, np.arange(start, start + len(new))])
        if len(keys) > size:
            first = np.argpartition(keys, size - 1)[:size] if size else []
            keys, rows = keys[first], rows[first]
    return rows[np.argsort(keys, kind="stable")]


def sample_queries(n, max_samples, random_state):
    """The points whose k-distance curve is averaged: ``max_samples`` of the
    ``n`` drawn without replacement (:func:`stable_draw`), sorted (all of
    them when there are no more). The one place of this draw, for
    :class:`AutoEpsDBSCAN` and the tiled estimate of
    :func:`~skpcd.segmentation.segment_scene` (which draws the same sample,
    so finds the same eps)."""
    if max_samples is not None and n > max_samples:
        rng = check_random_state(random_state)
        return np.sort(stable_draw(n, int(max_samples), rng))
    return np.arange(n)


def kdist_mean(dist):
    """The curve: the mean of each column of ``dist`` (the distances of the
    sampled points to their k-th neighbour, k = 1.. by column) over the
    points none of whose distances is more than ``_FAR_OUT`` times the 99th
    percentile of its column (a column whose percentile is 0 excludes
    none). A few outliers far from the scene are thus left out, as if they
    were not in the cloud, while every point of a real scan counts. The one
    place of this mean, for :class:`AutoEpsDBSCAN` and the tiled estimate
    of :func:`~skpcd.segmentation.segment_scene`."""
    if not len(dist):
        return dist.mean(axis=0)
    fence = _FAR_OUT * np.quantile(dist, 0.99, axis=0)
    fence[fence <= 0] = np.inf
    near = (dist <= fence).all(axis=1)
    return dist[near].mean(axis=0) if not near.all() else dist.mean(axis=0)


def _kdist_curve(xyz, n_neighbors, max_samples, random_state, n_jobs):
    """Mean k-th nearest-neighbour distance for k = 1..K over (a sample of)
    the points (:func:`kdist_mean`); neighbours among all points. Returns
    ``(k, mean)``."""
    n = len(xyz)
    k_max = min(int(n_neighbors), n - 1)
    rows = sample_queries(n, max_samples, random_state)
    threads = effective_threads(n_jobs)
    if len(rows) == n:  # every point: a k-d tree of them is the faster
        tree = cKDTree(xyz, balanced_tree=False, compact_nodes=False)
        dist, _ = tree.query(xyz, k=k_max + 1, workers=threads)
        dist = dist.reshape(n, -1)
    else:
        # a sample of a large cloud: its k nearest on the grid (no tree of
        # all points), their distances computed as cKDTree computes them:
        # the same curve, bit for bit, as a tree (and the tiled estimate's
        # trees) gives
        nb = search_packed(
            xyz, np.array([0, n]), n_neighbors=k_max + 1, n_threads=threads,
            algorithm="grid", with_sqdist=False, rows=rows,
        )  # fmt: skip
        near = nb.indices.reshape(len(rows), k_max + 1)
        e = xyz[near] - xyz[rows][:, None, :]
        dist = np.sqrt(
            (e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1]) + e[..., 2] * e[..., 2]
        )
        del e, near
    # column 0 is the point itself (or a duplicate of it: distance 0 either way)
    return np.arange(1, k_max + 1), kdist_mean(dist[:, 1:])


def eps_from_knee(knee_distance, eps_scale):
    """The radius: ``eps_scale`` times the knee distance, which must be > 0.

    The one place of this rule, for :class:`AutoEpsDBSCAN` and the tiled
    estimate of :func:`~skpcd.segmentation.segment_scene`.
    """
    if not knee_distance > 0:
        raise ValueError(
            "cannot estimate eps: the points' nearest-neighbour distances are "
            "all zero (duplicated points); give eps"
        )
    return float(eps_scale) * float(knee_distance)


def fit_knee(k, mean, degree):
    """Polynomial fitted to the curve, and the k where it is farthest from
    its chord (both axes scaled to [0, 1]): ``(poly, knee_k, eps)``."""
    poly = np.polynomial.Polynomial.fit(k, mean, deg=min(degree, len(k) - 1))
    grid = np.linspace(k[0], k[-1], _KNEE_GRID)
    y = poly(grid)
    span = y.max() - y.min()
    if not span > 1e-9 * np.abs(y).max():  # flat (up to rounding): no knee
        knee = grid[0]
    else:
        x = (grid - grid[0]) / (grid[-1] - grid[0])
        chord = (y[-1] - y[0]) / span * x
        knee = grid[np.argmax(np.abs((y - y[0]) / span - chord))]
    return poly, float(knee), float(poly(knee))


@entry_point
def estimate_eps(
    points,
    *,
    eps_scale=EPS_SCALE,
    n_neighbors=30,
    degree=3,
    max_samples=100_000,
    random_state=None,
    n_jobs=None,
):
    """The DBSCAN radius of a cloud from its k-nearest-neighbour distance curve.

    The estimate of :class:`AutoEpsDBSCAN`; read more there.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        One cloud; columns beyond the third are ignored.
    eps_scale : float, default=2.5
        The radius is this multiple of the curve's value at its knee; 1 gives
        the knee distance itself.
    n_neighbors : int, default=30
        Largest k of the curve.
    degree : int, default=3
        Degree of the polynomial fitted to the curve.
    max_samples : int or None, default=100_000
        The curve is averaged over this many random points (neighbours are
        still searched among all points); None uses every point.
    random_state : int, RandomState instance or None, default=None
        Draws the sample.
    n_jobs : int, default=None
        Threads for the neighbour queries; None means 1, -1 all cores.

    Returns
    -------
    eps : float
        The estimated radius: ``eps_scale`` times the knee distance.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import estimate_eps
    >>> g = np.stack(np.meshgrid(np.arange(40.0), np.arange(40.0), [0.0]), -1)
    >>> plane = 0.1 * g.reshape(-1, 3)
    >>> knee = estimate_eps(plane, eps_scale=1.0)  # a few point spacings
    >>> 0.1 < knee < 0.4, round(estimate_eps(plane) / knee, 6)
    (True, 2.5)
    """
    est = AutoEpsDBSCAN(
        eps_scale=eps_scale,
        n_neighbors=n_neighbors,
        degree=degree,
        max_samples=max_samples,
        random_state=random_state,
        n_jobs=n_jobs,
    )
    xyz = check_scene(points, min_points=2)
    return est._estimate(xyz)


class AutoEpsDBSCAN(ClusterMixin, SceneEstimator):
    """DBSCAN whose radius is estimated from the data (Wang et al., 2019).

    The radius comes from the curve of the mean distance of the points to
    their k-th nearest neighbour against k (the average of the k nearest
    neighbours' maximum distances), k = 1 .. ``n_neighbors``: a polynomial
    of degree ``degree`` is fitted to it, and its value at the knee, where
    the curve departs most from its chord (Satopää et al.), is the *knee
    distance*: the scale at which neighbourhoods stop growing along the
    sampled surfaces, a measure of the point spacing. Real objects have
    parts sampled more sparsely than their main surfaces (the arm of a
    lamp post, the gaps of a fence, thin canopy): at the knee distance they
    break off. The radius ``eps_`` is therefore ``eps_scale`` times the knee
    distance; the default factor was chosen by cross-validation on scenes
    of real objects (see Notes). DBSCAN then runs with that radius and
    ``min_samples``.

    The clustering runs on a voxel grid with cells ``eps`` wide: core points
    are counted, joined by union-find, and every other point joins its
    nearest core point within ``eps``. Memory is O(n_points) plus
    O(max_samples * n_neighbors) for the curve: no neighbourhood is stored,
    unlike :class:`sklearn.cluster.DBSCAN` and Open3D's ``cluster_dbscan``,
    which hold all of them and run out of memory on large clouds.

    Read more in the :ref:`User Guide <segmentation>`.

    Parameters
    ----------
    eps : float or None, default=None
        None estimates the radius (the method); a number skips the estimate
        (plain DBSCAN).
    eps_scale : float, default=2.5
        The estimated radius is this multiple of the knee distance. 1 gives
        the knee distance itself (the radius of earlier versions): it keeps
        close objects apart but breaks objects into pieces. The radius must
        stay below the gaps between objects: lower it for objects closer
        than the estimated ``eps_``. Ignored when ``eps`` is given.
    min_samples : int, default=5
        Points within ``eps`` of a point, itself included, that make it a
        core point (Open3D's ``min_points``).
    n_neighbors : int, default=30
        Largest k of the distance curve.
    degree : int, default=3
        Degree of the polynomial fitted to the curve.
    max_samples : int or None, default=100_000
        The curve is averaged over this many random points, their
        neighbours searched among all points; None uses every point.
    random_state : int, RandomState instance or None, default=None
        Draws that sample (clouds with at most ``max_samples`` points use
        them all and need no seed).
    n_jobs : int, default=None
        Threads; None means 1, -1 all cores.

    Attributes
    ----------
    eps_ : float
        The radius used: ``eps``, or ``eps_scale * knee_distance_``.
    curve_k_ : ndarray of shape (n_k,)
        k = 1 .. ``n_neighbors`` (fewer for tiny clouds); empty when ``eps``
        was given.
    curve_distances_ : ndarray of shape (n_k,)
        Mean distance to the k-th nearest neighbour.
    curve_ : numpy.polynomial.Polynomial or None
        The fitted curve (call it with k).
    knee_ : float or None
        The k of the knee.
    knee_distance_ : float or None
        The fitted curve at the knee, ``curve_(knee_)``; None when ``eps``
        was given.
    labels_ : ndarray of shape (n_points,), dtype int64
        Cluster of each point, numbered in the order of their lowest point
        index; -1 for noise.
    core_sample_indices_ : ndarray of shape (n_core,)
        Indices of the core points.
    n_clusters_ : int
        Number of clusters.
    n_features_in_ : int
        Number of columns of X seen in :meth:`fit`.

    See Also
    --------
    EuclideanClusters : Connected components within a fixed distance.
    segment_scene : Ground removal and clustering of a whole scene.
    plot_eps_curve : Draw the curve, its fit and the knee.

    Notes
    -----
    Core points and their clusters are those of
    :class:`sklearn.cluster.DBSCAN` with the same ``eps`` and
    ``min_samples``. A border point within ``eps`` of two clusters joins
    the one of its nearest core point (scikit-learn: the one expanded
    first), so the partition does not depend on the order of the points.

    What follows the paper and what does not. Wang et al. compute the same
    curve (the mean over the points of the largest of the k nearest
    distances) and fit a polynomial to it; their section 3.2.3 then adds
    corrections to the fit and reads the radius from its first derivative.
    The text of those two steps was not available to us (only their
    outline), so the knee criterion here, the largest distance to the chord
    of the fitted curve, is our choice, as is ``eps_scale``. The paper's
    clustering (its Algorithm 1) grows a cluster from every point within
    the radius and keeps the clusters of minPts to maxPts points: that is
    :class:`EuclideanClusters` (``min_samples=1`` here) with a size range,
    not a core-point count; ``min_samples=5`` (scikit-learn's default) keeps
    isolated noise points from linking objects (on development scenes it
    scored the same as ``min_samples=1``; 10 or 20 scored lower).

    A few points far from the scene (a spurious return kilometres away)
    must not move the radius: a sampled point with a k-distance more than
    100 times the 99th percentile of the k-distances is left out of the
    mean of the curve (no point of the real sweeps of the user guide comes
    near that), and the sample is drawn so that appending points to a cloud
    leaves the draw of the others as it was. Such points then end as noise.

    The default ``eps_scale`` was chosen without looking at the scenes it
    is judged on (``benchmarks/bench_segmentation_quality.py``): the DALES
    objects were split once, by object and stratified by class, into a
    development two thirds and a held-out third; scenes of 15 development
    objects, 3 m apart on a rolling terrain with holes and noise, sampled
    aerial-like (0.35 to 0.75 of the DALES density) and mobile-like (2 to 3
    times denser), were segmented with factors 1 to 4 (steps of 0.25) and
    the factor with the best mean of the adjusted Rand index and the
    fraction of objects recovered whole was chosen by 4-fold
    cross-validation (by object). On scenes of 30 held-out objects 3 m
    apart, factor 2.5 recovers 82 % (aerial-like) and 76 % (mobile-like) of
    the objects whole (adjusted Rand index 0.998 and 0.984), against 48 %
    and 31 % (0.889 and 0.749) with the knee distance itself.

    The radius must stay below the gaps between objects: objects closer
    than ``eps_`` are merged. With the default it was about 1.9 m for the
    aerial-like sampling (half the DALES density) and 0.8 m for the
    mobile-like one; it grows as the sampling gets sparser (2 to 3.2 m at
    0.35 of the DALES density: objects 3 m apart merged in 2 of 9 such
    development scenes).
    The default thus assumes objects some 2 to 3 m apart in aerial scans,
    1 m in mobile ones; lower ``eps_scale``, or give ``eps``, for denser
    layouts. Columns of X beyond the third are ignored.

    References
    ----------
    .. [1] C. Wang, M. Ji, J. Wang, W. Wen, T. Li, Y. Sun, "An improved DBSCAN
       method for LiDAR data segmentation with automatic Eps estimation",
       Sensors 19(1), 172, 2019.
    .. [2] V. Satopää, J. Albrecht, D. Irwin, B. Raghavan, "Finding a
       'kneedle' in a haystack", ICDCS Workshops, 2011.
    .. [3] M. Ester, H.-P. Kriegel, J. Sander, X. Xu, "A density-based
       algorithm for discovering clusters in large spatial databases with
       noise", KDD, 1996.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import AutoEpsDBSCAN
    >>> rng = np.random.default_rng(0)
    >>> plane = np.column_stack([rng.random((2000, 2)) * 4, np.zeros(2000)])
    >>> scene = np.vstack([plane, plane + [6, 0, 0], [[3, 9, 9]]])
    >>> db = AutoEpsDBSCAN(random_state=0).fit(scene)
    >>> db.n_clusters_, int(db.labels_[-1])
    (2, -1)
    >>> 0.05 < db.eps_ < 0.5
    True
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "eps": [Interval(Real, 0, None, closed="neither"), None],
        "eps_scale": [Interval(Real, 0, None, closed="neither")],
        "min_samples": [Interval(Integral, 1, None, closed="left")],
        "n_neighbors": [Interval(Integral, 2, None, closed="left")],
        "degree": [Interval(Integral, 1, None, closed="left")],
        "max_samples": [Interval(Integral, 1, None, closed="left"), None],
        "random_state": ["random_state"],
        "n_jobs": [Integral, None],
    }

    def __init__(
        self,
        *,
        eps=None,
        eps_scale=EPS_SCALE,
        min_samples=5,
        n_neighbors=30,
        degree=3,
        max_samples=100_000,
        random_state=None,
        n_jobs=None,
    ):
        self.eps = eps
        self.eps_scale = eps_scale
        self.min_samples = min_samples
        self.n_neighbors = n_neighbors
        self.degree = degree
        self.max_samples = max_samples
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _estimate(self, xyz):
        """Set the curve attributes; return the estimated eps."""
        k, mean = _kdist_curve(
            xyz, self.n_neighbors, self.max_samples, self.random_state, self.n_jobs
        )
        poly, knee, knee_distance = fit_knee(k, mean, self.degree)
        self.curve_k_, self.curve_distances_ = k, mean
        self.curve_, self.knee_ = poly, knee
        self.knee_distance_ = knee_distance
        return eps_from_knee(knee_distance, self.eps_scale)

    def _min_points(self):
        return 1 if self.eps is not None else 2

    def _fit(self, xyz):
        if self.eps is None:
            self.eps_ = self._estimate(xyz)
        else:
            self.eps_ = float(self.eps)
            self.curve_k_ = np.zeros(0, dtype=np.int64)
            self.curve_distances_ = np.zeros(0)
            self.curve_, self.knee_, self.knee_distance_ = None, None, None
        self.labels_, core = grid_dbscan(
            xyz, self.eps_, self.min_samples, n_jobs=self.n_jobs
        )
        self.core_sample_indices_ = np.flatnonzero(core)
        self.n_clusters_ = int(self.labels_.max() + 1) if len(xyz) else 0
