"""Neighbourhoods as CSR arrays, computed once and shared by normals and descriptors.

A neighbourhood of point ``i`` is ``indices[indptr[i]:indptr[i + 1]]``, sorted
by distance, with the point itself first (at distance 0), as PCL's k-d tree
returns it. ``sqdist`` holds the squared distances, float32 as in PCL.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["Neighborhoods", "compute_neighborhoods"]

# Radius queries run in chunks so that the padded k-NN buffer stays small.
_CHUNK = 16384


@dataclass(frozen=True)
class Neighborhoods:
    """Neighbour lists of every point of a cloud, in CSR layout.

    Attributes
    ----------
    indptr : ndarray of shape (n_points + 1,), dtype int64
        Start of each point's list in ``indices``.
    indices : ndarray of shape (n_pairs,), dtype int32
        Neighbour indices, sorted by distance, the point itself included.
    sqdist : ndarray of shape (n_pairs,), dtype float32
        Squared distances to the neighbours.
    """

    indptr: np.ndarray
    indices: np.ndarray
    sqdist: np.ndarray

    @property
    def n_points(self):
        """Number of points."""
        return len(self.indptr) - 1

    @property
    def sizes(self):
        """Number of neighbours of each point (the point itself included)."""
        return np.diff(self.indptr)

    def offset(self, start):
        """The same neighbourhoods with every index shifted by ``start``."""
        return Neighborhoods(self.indptr, self.indices + np.int32(start), self.sqdist)


def _check_points(points):
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] < 3:
        raise ValueError(f"points must have shape (n_points, 3+), got {points.shape}")
    xyz = np.ascontiguousarray(points[:, :3], dtype=np.float64)
    if not np.isfinite(xyz).all():
        raise ValueError("points contain NaN or infinite coordinates")
    return xyz


def compute_neighborhoods(points, *, n_neighbors=None, radius=None, n_jobs=None):
    """Find the k nearest neighbours or the radius neighbours of every point.

    Exactly one of ``n_neighbors`` and ``radius`` is given, as in PCL's
    ``setKSearch``/``setRadiusSearch``. The search uses
    :class:`scipy.spatial.cKDTree` with parallel queries; memory is
    O(n_points * neighbours).

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        One cloud; columns beyond the third are ignored.
    n_neighbors : int, default=None
        k, the query point included (PCL's ``k``; Open3D's ``max_nn``). A
        cloud with fewer points gives every point all points.
    radius : float, default=None
        Search radius, inclusive (``distance <= radius``).
    n_jobs : int, default=None
        Threads for the queries; None means 1, -1 all cores.

    Returns
    -------
    neighborhoods : Neighborhoods
        CSR arrays ``indptr``, ``indices`` and ``sqdist``.

    Notes
    -----
    Distances are computed in float64 and stored as float32. When several
    points are at the same distance (coordinates quantised to a centimetre
    make this common), the neighbour kept at the k-th place may differ from
    PCL's FLANN tree; see the user guide.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.preprocessing import compute_neighborhoods
    >>> nb = compute_neighborhoods(np.arange(12.0).reshape(4, 3), n_neighbors=2)
    >>> nb.indices.reshape(4, 2).tolist()
    [[0, 1], [1, 0], [2, 1], [3, 2]]
    """
    if (n_neighbors is None) == (radius is None):
        raise ValueError("give exactly one of n_neighbors and radius")
    xyz = _check_points(points)
    n = len(xyz)
    workers = _workers(n_jobs)
    if n == 0:
        return Neighborhoods(
            np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.float32)
        )
    tree = cKDTree(xyz)
    if n_neighbors is not None:
        if int(n_neighbors) != n_neighbors or n_neighbors < 1:
            raise ValueError(
                f"n_neighbors must be a positive integer, got {n_neighbors}"
            )
        k = min(int(n_neighbors), n)
        dist, idx = tree.query(xyz, k=k, workers=workers)
        dist, idx = dist.reshape(n, k), idx.reshape(n, k)
        idx, dist = _self_first(idx, dist)
        indptr = np.arange(0, n * k + 1, k, dtype=np.int64)
        return Neighborhoods(
            indptr, idx.astype(np.int32).ravel(), (dist.ravel() ** 2).astype(np.float32)
        )
    if not radius > 0:
        raise ValueError(f"radius must be positive, got {radius}")
    counts = tree.query_ball_point(xyz, r=radius, workers=workers, return_length=True)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices = np.empty(indptr[-1], dtype=np.int32)
    sqdist = np.empty(indptr[-1], dtype=np.float32)
    bound = np.nextafter(radius, np.inf)
    for start in range(0, n, _CHUNK):
        stop = min(n, start + _CHUNK)
        k = int(counts[start:stop].max())
        dist, idx = tree.query(
            xyz[start:stop], k=k, distance_upper_bound=bound, workers=workers
        )
        dist, idx = dist.reshape(stop - start, k), idx.reshape(stop - start, k)
        idx, dist = _self_first(idx, dist)
        keep = dist <= radius
        # query and query_ball_point may disagree on points exactly at the radius
        got = keep.sum(axis=1)
        if not np.array_equal(got, counts[start:stop]):
            return _radius_from_ball_point(tree, xyz, radius, workers)
        indices[indptr[start] : indptr[stop]] = idx[keep]
        sqdist[indptr[start] : indptr[stop]] = dist[keep] ** 2
    return Neighborhoods(indptr, indices, sqdist)


def _self_first(idx, dist):
    """Put the query point first among the neighbours at distance zero."""
    rows = np.arange(len(idx))
    first = idx[:, 0] != rows
    if first.any():
        # duplicates of the query point tie with it at distance 0
        pos = np.argmax(idx == rows[:, None], axis=1)
        hit = first & (idx[rows, pos] == rows)
        for r in np.flatnonzero(hit):
            p = pos[r]
            idx[r, 1 : p + 1] = idx[r, :p].copy()
            idx[r, 0] = r
    return idx, dist


def _radius_from_ball_point(tree, xyz, radius, workers):
    """Slow, exact fallback for radius neighbourhoods."""
    lists = tree.query_ball_point(xyz, r=radius, workers=workers, return_sorted=True)
    indptr = np.zeros(len(xyz) + 1, dtype=np.int64)
    np.cumsum([len(x) for x in lists], out=indptr[1:])
    indices = np.fromiter(
        (j for x in lists for j in x), dtype=np.int32, count=int(indptr[-1])
    )
    rows = np.repeat(np.arange(len(xyz)), np.diff(indptr))
    d2 = ((xyz[indices] - xyz[rows]) ** 2).sum(axis=1)
    order = np.lexsort((indices != rows, d2, rows))
    return Neighborhoods(indptr, indices[order], d2[order].astype(np.float32))


def _workers(n_jobs):
    from joblib import effective_n_jobs

    return int(effective_n_jobs(n_jobs))
