"""Euclidean clusters, and the grid DBSCAN both clusterers run on.

:func:`grid_dbscan` is DBSCAN (Ester et al., 1996) on the sorted voxel grid
of the radius search: core points are counted with the grid's ball kernel,
core points closer than ``eps`` are joined by union-find, and every other
point joins the cluster of its nearest core point within ``eps``. No
neighbourhood is stored, so memory is O(n_points) whatever ``eps``; the
neighbourhoods that scikit-learn's and Open3D's DBSCAN hold at once are what
exhausts memory on large clouds.

Euclidean clusters (PCL's ``EuclideanClusterExtraction``) are the connected
components of the graph of points closer than a distance: DBSCAN with
``min_samples=1``, then clusters outside a size range are dropped.
"""

import typing
from concurrent.futures import ThreadPoolExecutor
from numbers import Integral, Real

import numpy as np
from sklearn.base import ClusterMixin
from sklearn.utils._param_validation import Interval

from skpcd.neighbors._grid import ball_counts, build_grid, radius_grid
from skpcd.segmentation import _cluster_kernels as k
from skpcd.utils._compile import entry_point
from skpcd.utils._estimator import SceneEstimator
from skpcd.utils._parallel import effective_threads, parallel_rows, parallel_section

__all__ = [
    "EUCLIDEAN_EPS",
    "EuclideanClusters",
    "FineGrid",
    "euclidean_clusters",
    "fine_clusters",
    "fine_grid",
    "grid_dbscan",
]

# The default distance of the Euclidean clusters (metres), from the urban
# LiDAR study this library follows; also the tiled segmentation's.
EUCLIDEAN_EPS = 0.2
# Fewer points than this per thread: the union-find runs in one thread.
_MIN_UNION_POINTS = 50_000


def _threaded_forest(kernel, grid, n, args, n_threads):
    """The union-find forest over ``n`` nodes that ``kernel(lo, hi, *args,
    forest)`` links over the grid's cells ``lo`` to ``hi``: each thread
    links a share of the cells (by point count) in a forest of its own, and
    the forests are merged. Roots are the lowest nodes of their components,
    whatever the threads."""
    n_cells = grid.n_cells
    dtype = np.int32 if n < 2**31 - 1 else np.int64
    n_threads = min(n_threads, max(1, len(grid.order) // _MIN_UNION_POINTS))
    bounds = np.searchsorted(
        grid.cell_start, np.linspace(0, len(grid.order), n_threads + 1)[1:-1]
    )
    bounds = [0, *bounds.tolist(), n_cells]
    forests = [np.arange(n, dtype=dtype) for _ in range(n_threads)]
    name = getattr(kernel, "__name__", "union")
    if n_threads == 1:
        with parallel_section(name):
            kernel(0, n_cells, *args, forests[0])
        return forests[0]
    with parallel_section(name), ThreadPoolExecutor(n_threads) as pool:
        jobs = [
            pool.submit(kernel, bounds[i], bounds[i + 1], *args, forests[i])
            for i in range(n_threads)
        ]
        for job in jobs:
            job.result()
    for other in forests[1:]:
        k.merge_forest(forests[0], other)
    return forests[0]


# The fine grid is used when its cells hold this many points on average:
# below, the 125 cells around each cell cost more than they save.
_FINE_MIN_POINTS = 2.0


class FineGrid(typing.NamedTuple):
    """A cloud on cells at most ``eps / sqrt(3)`` wide (:func:`fine_grid`):
    the points of a cell are all within ``eps`` of each other, and the
    points within ``eps`` of a cell lie in the 5 x 5 x 5 cells around it."""

    grid: typing.Any  # VoxelGrid
    eps: float

    @property
    def dense(self):
        """Whether its cells hold :data:`_FINE_MIN_POINTS` points on
        average, so that clustering on it beats the radius grid."""
        return len(self.grid.order) >= _FINE_MIN_POINTS * self.grid.n_cells


def fine_grid(xyz, eps, n_threads):
    """The :class:`FineGrid` of ``xyz`` (C-contiguous float64) for ``eps``,
    or None when ``eps`` is not positive or the scene is too wide for such
    cells (a far outlier: over 2**20 cells to a side)."""
    if not eps > 0:
        return None
    n = len(xyz)
    h = eps / np.sqrt(3.0) * (1 - 1e-6)
    grid = build_grid(
        xyz, np.array([0, n], dtype=np.int64), np.array([h]), None, n_threads
    )
    if grid.h[0] * np.sqrt(3.0) > eps * (1 - 1e-7):
        return None
    return FineGrid(grid, float(eps))


def fine_clusters(fine, min_samples, n_threads, member=None):
    """:func:`grid_dbscan` of the points of a :class:`FineGrid`, or of the
    points ``member`` flags (bool, by point index; with ``min_samples`` 1
    only): labels and core flags by point index, the others -1 and not
    core, clusters numbered by their lowest point index.

    A cell holding ``min_samples`` points is all core, the core points of a
    cell form one cluster, and two cells are joined by the first close pair
    of core points found. The result is that of the radius grid: the same
    core points, clusters, and nearest core point of each other point."""
    grid, r2 = fine.grid, fine.eps * fine.eps
    n = len(grid.order)
    if member is not None:
        if min_samples > 1:
            raise ValueError("member is for min_samples 1 (components) only")
        core_sorted = np.ascontiguousarray(member[grid.order])
    elif min_samples <= 1:
        core_sorted = np.ones(n, dtype=np.bool_)
    else:
        core_sorted = np.zeros(n, dtype=np.bool_)
        args = (grid, r2, min_samples, core_sorted)
        parallel_rows(k.fine_core, grid.n_cells, n_threads, *args, min_chunk=1024)
    parent = _threaded_forest(
        k.fine_union, grid, grid.n_cells, (grid, core_sorted, r2), n_threads
    )
    nearest = np.full(n, -1, dtype=np.int64)
    if member is None and not core_sorted.all():
        args = (grid, core_sorted, r2, nearest)
        parallel_rows(k.fine_border, grid.n_cells, n_threads, *args, min_chunk=1024)
    labels = np.empty(n, dtype=np.int64)
    k.fine_component_labels(
        parent, grid.cell_start, core_sorted, nearest, grid.order, labels
    )
    core = np.empty(n, dtype=np.bool_)
    core[grid.order] = core_sorted
    return labels, core


@entry_point
def grid_dbscan(xyz, eps, min_samples, *, n_jobs=None):
    """DBSCAN of one cloud on a voxel grid, in O(n_points) memory.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3), float64, C-contiguous, finite
        The points.
    eps : float
        Neighbourhood radius, inclusive (``distance <= eps``), as in
        :class:`sklearn.cluster.DBSCAN`.
    min_samples : int
        Points within ``eps`` (the point itself included) that make a core
        point. 1 makes every point core: Euclidean clusters.
    n_jobs : int, default=None
        Threads for counting neighbours and attaching border points
        (resolved here, :func:`~skpcd.utils._parallel.effective_threads`).

    Returns
    -------
    labels : ndarray of shape (n_points,), dtype int64
        Cluster of each point, numbered in the order of their lowest point
        index; -1 for noise.
    core : ndarray of shape (n_points,), dtype bool
        Core points.

    Notes
    -----
    A border point (not core, within ``eps`` of a core point) joins the
    cluster of its nearest core point, ties going to the lower index; the
    partition therefore does not depend on the order of the points, unlike
    scikit-learn's, where a border point shared by two clusters goes to the
    one expanded first. Core points and their clusters are the same.
    """
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(
            f"xyz must be an array of shape (n_points, 3); got shape {xyz.shape}."
        )
    if not np.isfinite(xyz).all():
        raise ValueError("xyz contains NaN or infinite coordinates.")
    n = len(xyz)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.bool_)
    n_threads = effective_threads(n_jobs)
    r2 = float(eps) ** 2
    fine = fine_grid(xyz, float(eps), n_threads)
    if fine is not None and fine.dense:
        return fine_clusters(fine, int(min_samples), n_threads)
    grid = radius_grid(xyz, np.array([0, n], dtype=np.int64), eps, None, n_threads)
    if min_samples <= 1:
        core_sorted = np.ones(n, dtype=np.bool_)
    else:
        counts = ball_counts(grid, eps, n_threads)
        core_sorted = counts[grid.order] >= min_samples
        del counts
    parent = _threaded_forest(
        k.union_core, grid, len(grid.order), (grid, core_sorted, r2), n_threads
    )
    nearest = np.full(n, -1, dtype=np.int64)
    if not core_sorted.all():
        args = (grid, core_sorted, r2, nearest)
        parallel_rows(k.attach_border, grid.n_cells, n_threads, *args)
    labels = np.empty(n, dtype=np.int64)
    k.component_labels(parent, core_sorted, nearest, grid.order, labels)
    core = np.empty(n, dtype=np.bool_)
    core[grid.order] = core_sorted
    return labels, core


def filter_cluster_sizes(labels, min_size=1, max_size=None):
    """Clusters with fewer than ``min_size`` or more than ``max_size`` points
    become noise (-1); the others are renumbered 0, 1, ... in their order.

    Parameters
    ----------
    labels : ndarray of shape (n_points,), dtype int
        Cluster labels, -1 for noise.
    min_size : int, default=1
        Smallest cluster kept.
    max_size : int or None, default=None
        Largest cluster kept; None for no limit.

    Returns
    -------
    labels : ndarray of shape (n_points,), dtype int64
        The filtered labels.
    """
    labels = np.asarray(labels, dtype=np.int64)
    if len(labels) == 0 or labels.max() < 0:
        return labels.copy()
    sizes = np.bincount(labels[labels >= 0], minlength=labels.max() + 1)
    keep = sizes >= min_size
    if max_size is not None:
        keep &= sizes <= max_size
    new = np.full(len(sizes) + 1, -1, dtype=np.int64)  # the last maps -1 to -1
    new[:-1][keep] = np.arange(keep.sum())
    return new[labels]


@entry_point
def euclidean_clusters(
    points,
    *,
    eps=EUCLIDEAN_EPS,
    min_cluster_size=500,
    max_cluster_size=None,
    n_jobs=None,
):
    """Connected components of the points closer than a distance.

    The function form of :class:`EuclideanClusters`; read more there.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        One cloud; columns beyond the third are ignored.
    eps : float, default=0.2
        Two points closer than this (inclusive) are in the same cluster
        (PCL's ``cluster_tolerance``).
    min_cluster_size : int, default=500
        Smaller clusters become noise (PCL's ``min_cluster_size``).
    max_cluster_size : int or None, default=None
        Larger clusters become noise (PCL's ``max_cluster_size``).
    n_jobs : int, default=None
        Threads; None means 1, -1 all cores.

    Returns
    -------
    labels : ndarray of shape (n_points,), dtype int64
        Cluster of each point, -1 for points in no kept cluster.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import euclidean_clusters
    >>> points = [[0, 0, 0], [0.1, 0, 0], [5, 0, 0], [5.1, 0, 0], [9, 9, 9]]
    >>> euclidean_clusters(points, eps=0.2, min_cluster_size=2).tolist()
    [0, 0, 1, 1, -1]
    """
    est = EuclideanClusters(
        eps=eps,
        min_cluster_size=min_cluster_size,
        max_cluster_size=max_cluster_size,
        n_jobs=n_jobs,
    )
    return est.fit(points).labels_


class EuclideanClusters(ClusterMixin, SceneEstimator):
    """Euclidean cluster extraction: connected components within a distance.

    Two points belong to the same cluster when a chain of points links them
    in which consecutive points are at most ``eps`` apart; clusters with
    fewer than ``min_cluster_size`` or more than ``max_cluster_size`` points
    are dropped (their points get the label -1), as in PCL's
    ``EuclideanClusterExtraction``. The defaults are those of the mobile
    LiDAR study this library follows (0.2 m, at least 500 points).

    The search runs on a voxel grid with cells ``eps`` wide and the
    components are built by union-find: memory is O(n_points), whatever the
    density; no neighbourhood is stored.

    Read more in the :ref:`User Guide <segmentation>`.

    Parameters
    ----------
    eps : float, default=0.2
        Largest distance between neighbouring points of a cluster, in the
        units of the coordinates (metres). PCL's ``cluster_tolerance``.
    min_cluster_size : int, default=500
        Clusters with fewer points become noise. PCL's ``min_cluster_size``.
    max_cluster_size : int or None, default=None
        Clusters with more points become noise; None for no limit. PCL's
        ``max_cluster_size``.
    n_jobs : int, default=None
        Threads for the grid; None means 1, -1 all cores.

    Attributes
    ----------
    labels_ : ndarray of shape (n_points,), dtype int64
        Cluster of each point, numbered in the order of their lowest point
        index; -1 for points in no kept cluster.
    n_clusters_ : int
        Number of kept clusters.
    n_features_in_ : int
        Number of columns of X seen in :meth:`fit`.

    See Also
    --------
    AutoEpsDBSCAN : DBSCAN with a radius estimated from the data.
    segment_scene : Ground removal and clustering of a whole scene.
    sklearn.cluster.DBSCAN : The same partition with ``min_samples=1``,
        holding every neighbourhood in memory.

    Notes
    -----
    With ``min_cluster_size=1`` and no maximum this is
    ``DBSCAN(eps=eps, min_samples=1)``. Columns of X beyond the third are
    ignored; with fewer than three, the missing coordinates are zero.

    References
    ----------
    .. [1] R. B. Rusu, "Semantic 3D object maps for everyday manipulation in
       human living environments", PhD thesis, TU Munich, 2009, section 6.2.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import EuclideanClusters
    >>> rng = np.random.default_rng(0)
    >>> two_boxes = np.vstack([rng.random((600, 3)), rng.random((600, 3)) + 3])
    >>> ec = EuclideanClusters(eps=0.3).fit(two_boxes)
    >>> ec.n_clusters_, np.bincount(ec.labels_).tolist()
    (2, [600, 600])
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "eps": [Interval(Real, 0, None, closed="neither")],
        "min_cluster_size": [Interval(Integral, 1, None, closed="left")],
        "max_cluster_size": [Interval(Integral, 1, None, closed="left"), None],
        "n_jobs": [Integral, None],
    }

    def __init__(
        self,
        *,
        eps=EUCLIDEAN_EPS,
        min_cluster_size=500,
        max_cluster_size=None,
        n_jobs=None,
    ):
        self.eps = eps
        self.min_cluster_size = min_cluster_size
        self.max_cluster_size = max_cluster_size
        self.n_jobs = n_jobs

    def _fit(self, xyz):
        labels, _ = grid_dbscan(xyz, self.eps, 1, n_jobs=self.n_jobs)
        self.labels_ = filter_cluster_sizes(
            labels, self.min_cluster_size, self.max_cluster_size
        )
        self.n_clusters_ = int(self.labels_.max() + 1) if len(labels) else 0
