"""Neighbourhoods as CSR arrays, computed once and shared by normals and descriptors.

A neighbourhood of point ``i`` is ``indices[indptr[i]:indptr[i + 1]]``, sorted
by distance (ties by index), with the point itself first (at distance 0), as
PCL's k-d tree returns it. ``sqdist`` holds the squared distances, float32 as
in PCL.

Two search algorithms give the same neighbourhoods: ``"grid"``, numba kernels
on a sorted voxel grid (:mod:`skpcd.neighbors._grid_kernels`), and
``"kd_tree"``, :class:`scipy.spatial.cKDTree` with parallel queries. Both
take several clouds packed one after the other and never cross clouds.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from skpcd.neighbors import _grid_kernels as g
from skpcd.neighbors._grid import (
    VoxelGrid,
    ball_counts,
    ball_lists,
    build_grid,
    gather_points,
    grid_shape,
    sort_points,
)
from skpcd.utils._compile import entry_point
from skpcd.utils._geometry import cloud_bounds, max_extent
from skpcd.utils._parallel import effective_threads, parallel_rows
from skpcd.utils._validation import check_extents

__all__ = ["Neighborhoods", "compute_neighborhoods"]

ALGORITHMS = ("auto", "grid", "kd_tree")
# Target number of points per occupied cell for k-nearest searches, as a
# fraction of k: the 27 cells around a point then hold its k nearest. On
# the DALES objects (k = 10, one thread, CPU seconds, best of 5): 0.4 gives
# 40 candidates per query and 12.8 % of the queries scan a second shell of
# cells (1.6 us each against 0.6 us), 0.81 s / 0.78 s (objects / one
# cloud); 0.5: 6.7 %, 0.75 / 0.77 s; 0.6: 4.4 %, 0.69 / 0.90 s.
_OCCUPANCY = 0.5
# The cell sizes are adapted again only while the clouds whose occupancy is
# off hold more than this share of the points.
_OFF_SHARE = 0.01
# Shells of cells a k-nearest query may scan before a coarser grid takes over.
_MAX_SHELL = 8
# When at most this share of the queries needs more than _MAX_SHELL shells,
# they scan up to _FAR_SHELL shells of the same grid before a coarser grid
# is built.
_FEW_FAR = 1e-3
_FAR_SHELL = 32
# Passes on ever coarser grids before the remaining queries go to cKDTree.
_COARSER = 3
# Remaining isolated queries are answered by brute force when they need at
# most this many distances (the sizes of their clouds, summed).
_BRUTE_WORK = 20_000_000
# Neighbours farther apart than this in the points' order are far apart in
# memory; when more than _FAR_SHARE of them are (a shuffled cloud: 83 % of
# the DALES objects' k = 10 neighbours, 0 % in their own order), the
# descriptors renumber the points in grid order (see `scattered`).
_NEAR = 1 << 15
_FAR_SHARE = 0.25


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

    def renumbered(self, order, n_threads=1):
        """The same neighbourhoods with the points renumbered.

        Point ``order[t]`` becomes point ``t``: its row is row ``t``, and
        every index is renumbered alike. The rows keep their order (by
        distance, ties by the old index).

        Parameters
        ----------
        order : ndarray of shape (n_points,), int
            A permutation of the points: ``order[t]`` is the point that
            becomes point ``t``.
        n_threads : int, default=1
            Threads for the copy.

        Returns
        -------
        neighborhoods : Neighborhoods
            Row ``t`` holds the neighbours of point ``order[t]``, each given by
            its new number.

        Raises
        ------
        ValueError
            If ``order`` is not a permutation of the points.
        """
        order = np.asarray(order)
        n = self.n_points
        if (
            order.shape != (n,)
            or not np.issubdtype(order.dtype, np.integer)
            or (n and (order.min() < 0 or order.max() >= n))
        ):
            raise ValueError(
                f"order must be a permutation of the {n} points, got an array "
                f"of shape {order.shape} and dtype {order.dtype}"
            )
        order = order.astype(np.int64, copy=False)
        inv = np.full(n, -1, dtype=np.int32)
        inv[order] = np.arange(n, dtype=np.int32)
        if n and inv.min() < 0:
            raise ValueError(
                f"order must be a permutation of the {n} points: it repeats some"
            )
        indptr = np.zeros_like(self.indptr)
        np.cumsum(self.sizes[order], out=indptr[1:])
        nb = Neighborhoods(
            indptr,
            np.empty_like(self.indices),
            np.empty(len(self.indices) if len(self.sqdist) else 0, np.float32),
        )
        args = (order, inv, (self.indptr, self.indices, self.sqdist))
        args += (indptr, nb.indices, nb.sqdist)
        parallel_rows(g.renumber_rows, len(order), n_threads, *args)
        return nb


def scattered(nb, n_rows=4096):
    """Whether the neighbours lie far apart in the points' order.

    The kernels that read the neighbours' rows miss the cache at almost
    every read when they do (a shuffled cloud): the points are then better
    renumbered in grid order (:meth:`Neighborhoods.renumbered`) first.

    Parameters
    ----------
    nb : Neighborhoods
        The neighbourhoods, in the points' own numbering.
    n_rows : int, default=4096
        Rows looked at, spread evenly over the points.

    Returns
    -------
    far : bool
        True when more than a quarter (``_FAR_SHARE``) of the neighbours in
        those rows are more than 32,768 points (``_NEAR``) away from their
        point in the numbering; False for 32,768 points or fewer.
    """
    n = nb.n_points
    if n <= _NEAR:
        return False
    rows = np.linspace(0, n - 1, n_rows).astype(np.int64)
    starts, sizes = nb.indptr[rows], nb.sizes[rows]
    first = np.cumsum(sizes) - sizes
    slots = np.arange(sizes.sum()) - np.repeat(first - starts, sizes)
    gap = np.abs(nb.indices[slots] - np.repeat(rows, sizes))
    return bool(np.mean(gap > _NEAR) > _FAR_SHARE)


def check_points(points):
    """One cloud as a float64 C-contiguous ``(n_points, 3)`` array of its xyz.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        The cloud; columns beyond the third are dropped.

    Returns
    -------
    xyz : ndarray of shape (n_points, 3), float64

    Raises
    ------
    ValueError
        If ``points`` is not 2-D with 3 or more columns, or has a NaN or
        infinite coordinate.
    """
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] < 3:
        raise ValueError(f"points must have shape (n_points, 3+), got {points.shape}")
    xyz = np.ascontiguousarray(points[:, :3], dtype=np.float64)
    if not np.isfinite(xyz).all():
        raise ValueError("points contain NaN or infinite coordinates")
    return xyz


@entry_point
def compute_neighborhoods(
    points, *, n_neighbors=None, radius=None, n_jobs=None, algorithm="auto"
):
    """Find the k nearest neighbours or the radius neighbours of every point.

    Exactly one of ``n_neighbors`` and ``radius`` is given, as in PCL's
    ``setKSearch``/``setRadiusSearch``. Memory is O(n_points * neighbours).

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
    algorithm : {"auto", "grid", "kd_tree"}, default="auto"
        ``"grid"``: exact search on a sorted voxel grid (numba), several
        times faster than a k-d tree on LiDAR clouds; ``"kd_tree"``:
        :class:`scipy.spatial.cKDTree`. ``"auto"`` is ``"grid"``. Both give
        the same neighbourhoods, except which of several points tied at the
        k-th distance is kept.

    Returns
    -------
    neighborhoods : Neighborhoods
        CSR arrays ``indptr``, ``indices`` and ``sqdist``.

    Notes
    -----
    Distances are computed in float64 and stored as float32, from the
    differences of the coordinates (exact for points of one cloud far from
    the origin): the neighbourhoods do not depend on where the cloud lies,
    up to the float64 rounding of the coordinates given. When several
    points are at the same distance (coordinates quantised to a centimetre
    make this common), the lowest index comes first and is the one kept at
    the k-th place; PCL's FLANN tree may keep another; see the user guide.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.preprocessing import compute_neighborhoods
    >>> nb = compute_neighborhoods(np.arange(12.0).reshape(4, 3), n_neighbors=2)
    >>> nb.indices.reshape(4, 2).tolist()
    [[0, 1], [1, 0], [2, 1], [3, 2]]
    """
    xyz = check_points(points)
    return search_packed(
        xyz,
        np.array([0, len(xyz)], dtype=np.int64),
        n_neighbors=n_neighbors,
        radius=radius,
        n_threads=effective_threads(n_jobs),
        algorithm=algorithm,
    )


def _check_search(n_neighbors, radius, algorithm):
    if (n_neighbors is None) == (radius is None):
        raise ValueError("give exactly one of n_neighbors and radius")
    if n_neighbors is not None and (
        isinstance(n_neighbors, bool)
        or int(n_neighbors) != n_neighbors
        or n_neighbors < 1
    ):
        raise ValueError(f"n_neighbors must be a positive integer, got {n_neighbors}")
    if radius is not None and not (radius > 0 and np.isfinite(radius)):
        raise ValueError(f"radius must be positive and finite, got {radius}")
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")


def search_packed(
    xyz,
    offsets,
    *,
    n_neighbors=None,
    radius=None,
    n_threads=1,
    algorithm="auto",
    with_sqdist=True,
    return_order=False,
    rows=None,
    grid=None,
):
    """Neighbourhoods of several clouds packed in one array, never crossing clouds.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3), float64, C-contiguous, finite
        All points; cloud ``c`` is ``xyz[offsets[c]:offsets[c + 1]]``.
    offsets : ndarray of shape (n_clouds + 1,), int64
        Offsets of the clouds.
    n_neighbors, radius, algorithm
        As in :func:`compute_neighborhoods`.
    n_threads : int, default=1
        Threads for the queries.
    with_sqdist : bool, default=True
        False leaves ``sqdist`` empty (the grid search), to save memory when
        only the indices are needed.
    return_order : bool, default=False
        Also return the order of the points in the search's grid (sorted by
        cloud, then cell: neighbours close in that order): ``order[t]`` is
        the index in ``xyz`` of the ``t``-th point in that order, a
        permutation within each cloud; None for the k-d tree and for no
        points.
    rows : ndarray of int, default=None
        Only these points get their neighbours (the rows of the others are
        empty); all points when None. The k-nearest grid search only.
    grid : VoxelGrid, default=None
        A grid of ``xyz`` (one cloud; any cell size: the search is exact on
        any grid) for the k-nearest grid search, instead of one sized for
        ``n_neighbors`` (:func:`suits_knn` says whether it is as fast).

    Returns
    -------
    neighborhoods : Neighborhoods
        With indices into ``xyz``.
    order : ndarray of shape (n_points,), int64, or None
        Only with ``return_order``.
    """
    nb, order = _search_packed(
        xyz, offsets, n_neighbors, radius, n_threads, algorithm, with_sqdist, rows,
        grid,
    )  # fmt: skip
    return (nb, order) if return_order else nb


def _search_packed(
    xyz, offsets, n_neighbors, radius, n_threads, algorithm, with_sqdist, rows=None,
    grid=None,
):  # fmt: skip
    """:func:`search_packed`, returning ``(neighborhoods, grid order or None)``."""
    _check_search(n_neighbors, radius, algorithm)
    if rows is not None and (n_neighbors is None or algorithm == "kd_tree"):
        raise ValueError("rows is for the k-nearest grid search only")
    offsets = np.asarray(offsets, dtype=np.int64)
    # squared distances overflow beyond ~7.7e153: refused, not searched
    lo_hi = cloud_bounds(xyz, offsets)
    check_extents(
        *lo_hi,
        max_extent(np.float64),
        what="squared distances in float64 (the neighbour search)",
    )
    sizes = np.diff(offsets)
    indptr = np.zeros(len(xyz) + 1, dtype=np.int64)
    if n_neighbors is not None:
        counts = np.repeat(np.minimum(sizes, int(n_neighbors)), sizes)
        if rows is not None:
            asked = np.zeros(len(xyz), dtype=bool)
            asked[rows] = True
            counts[~asked] = 0
        np.cumsum(counts, out=indptr[1:])
    if len(xyz) == 0:
        empty = Neighborhoods(
            np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.float32)
        )
        return empty, None
    if algorithm == "kd_tree":
        if n_neighbors is not None:
            return _knn_kd_tree(xyz, offsets, indptr, None, n_threads), None
        return _radius_kd_tree(xyz, offsets, float(radius), n_threads), None
    n = len(xyz)
    if n_neighbors is not None:
        nb = Neighborhoods(
            indptr,
            np.empty(indptr[-1], dtype=np.int32),
            np.empty(indptr[-1] if with_sqdist else 0, dtype=np.float32),
        )
        hard = np.zeros(n, dtype=np.bool_)
        todo = np.zeros(0, dtype=np.bool_)
        if grid is None:
            grid = _knn_grid(xyz, offsets, int(n_neighbors), lo_hi, n_threads)
        order = grid.order
        if rows is None:
            rows = np.arange(grid.n_cells)
        else:  # the cells holding a query
            rows = g.cells_with(asked, grid)
            del asked
        for attempt in range(_COARSER):
            args = (rows, grid, indptr, _MAX_SHELL, todo, nb.indices, nb.sqdist, hard)
            parallel_rows(g.knn_cells, len(rows), n_threads, *args)
            if not hard.any():
                return nb, order
            todo, hard = hard, np.zeros(n, dtype=np.bool_)
            if attempt == 0 and todo.sum() <= _FEW_FAR * n:
                # a few isolated queries: farther shells of the same grid
                # cost less than sorting the cloud again on a coarser one
                rows = g.cells_with(todo, grid)
                args = (
                    rows,
                    grid,
                    indptr,
                    _FAR_SHELL,
                    todo,
                    nb.indices,
                    nb.sqdist,
                    hard,
                )
                parallel_rows(g.knn_cells, len(rows), n_threads, *args)
                if not hard.any():
                    return nb, order
                todo, hard = hard, np.zeros(n, dtype=np.bool_)
            which = np.flatnonzero(todo)
            cloud = np.searchsorted(offsets, which, side="right") - 1
            if sizes[cloud].sum() <= _BRUTE_WORK:
                args = (which, cloud, xyz, offsets, indptr, nb.indices, nb.sqdist)
                parallel_rows(g.knn_brute, len(which), n_threads, *args)
                return nb, order
            if attempt == _COARSER - 1:
                break
            # isolated points: again on cells four times wider
            grid = build_grid(xyz, offsets, 4 * grid.h, lo_hi, n_threads)
            rows = g.cells_with(todo, grid)
        _knn_kd_tree(xyz, offsets, indptr, np.flatnonzero(todo), n_threads, nb)
        return nb, order
    grid = build_grid(xyz, offsets, np.full(len(sizes), radius), lo_hi, n_threads)
    counts = ball_counts(grid, radius, n_threads)
    np.cumsum(counts, out=indptr[1:])
    nb = Neighborhoods(
        indptr,
        np.empty(indptr[-1], dtype=np.int32),
        np.empty(indptr[-1] if with_sqdist else 0, dtype=np.float32),
    )
    ball_lists(grid, radius, indptr, counts, nb.indices, nb.sqdist, n_threads)
    return nb, grid.order


def _occupancy_target(k):
    """Points a cell of a k-nearest search's grid is sized to hold."""
    return max(1.0, _OCCUPANCY * k)


def suits_knn(grid, k):
    """Whether a grid of one cloud holds about as many points a cell as
    the k-nearest search sizes its own for (within a factor 2): a search
    on it is as fast."""
    target = _occupancy_target(k)
    occupancy = len(grid.order) / max(grid.n_cells, 1)
    return target / 2 <= occupancy <= 2 * target


def _knn_grid(xyz, offsets, k, lo_hi=None, n_threads=1):
    """Grid for k-nearest searches, cell sizes adapted to each cloud's density.

    Returns the :class:`~skpcd.neighbors._grid.VoxelGrid`.
    """
    sizes = np.diff(offsets)
    target = _occupancy_target(k)
    lo, hi = cloud_bounds(xyz, offsets) if lo_hi is None else lo_hi
    e = np.sort(hi - lo, axis=1)
    # first guess: points spread over the largest face of the bounding box
    area = e[:, 2] * np.maximum(e[:, 1], 1e-3 * e[:, 2])
    h = np.sqrt(area * target / np.maximum(sizes, 1))
    for _ in range(3):
        origin, h, dims = grid_shape(xyz, offsets, h, (lo, hi))
        order, cells = sort_points(xyz, offsets, origin, h, dims, n_threads)
        cloud_cells = cells[3]
        occupancy = sizes / np.maximum(np.diff(cloud_cells), 1)
        off = (occupancy < target / 2) | (occupancy > target * 2)
        off &= sizes > 4 * target
        # another sort for a few clouds costs more than it saves: the
        # search is exact on any grid, only slower on a badly sized one
        if sizes[off].sum() <= _OFF_SHARE * len(xyz):
            break
        # occupancy grows like h**2 on the surfaces LiDAR samples
        h = h * np.where(off, np.clip(np.sqrt(target / occupancy), 0.25, 4.0), 1.0)
    xs = gather_points(xyz, order, n_threads)
    return VoxelGrid(xs, order, *cells, origin, h, dims)


def _sqdist(xyz, rows, idx):
    d = xyz[idx] - xyz[rows]
    return (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]


def _knn_kd_tree(xyz, offsets, indptr, which, n_threads, nb=None):
    """k nearest with cKDTree, for all points or the points ``which``."""
    if nb is None:
        nb = Neighborhoods(
            indptr,
            np.empty(indptr[-1], dtype=np.int32),
            np.empty(indptr[-1], dtype=np.float32),
        )
    workers = n_threads
    for c in range(len(offsets) - 1):
        start, stop = int(offsets[c]), int(offsets[c + 1])
        if which is None:
            q = np.arange(start, stop)
        else:
            q = which[(which >= start) & (which < stop)]
        if stop == start or len(q) == 0:
            continue
        k = min(int(indptr[start + 1] - indptr[start]), stop - start)
        # one neighbour more: a duplicate of the query may push it out
        kq = min(k + 1, stop - start)
        _, idx = cKDTree(xyz[start:stop]).query(xyz[q], k=kq, workers=workers)
        idx = idx.reshape(len(q), kq) + start
        rows = np.repeat(q, kq)
        idx = idx.ravel()
        d2 = _sqdist(xyz, rows, idx)
        d2 = np.where(idx == rows, -1.0, d2)
        o = np.lexsort((idx, d2, rows)).reshape(len(q), kq)[:, :k].ravel()
        slots = (indptr[q][:, None] + np.arange(k)).ravel()
        nb.indices[slots] = idx[o]
        if len(nb.sqdist):
            nb.sqdist[slots] = np.maximum(d2[o], 0.0)
    return nb


def _radius_kd_tree(xyz, offsets, radius, n_threads):
    """Radius neighbourhoods with cKDTree."""
    workers = n_threads
    lists = []
    for c in range(len(offsets) - 1):
        start, stop = int(offsets[c]), int(offsets[c + 1])
        if stop > start:
            part = xyz[start:stop]
            found = cKDTree(part).query_ball_point(
                part, r=radius * (1 + 1e-12), workers=workers
            )
            lists.extend(np.asarray(x, dtype=np.int64) + start for x in found)
    sizes = np.array([len(x) for x in lists], dtype=np.int64)
    indptr = np.zeros(len(xyz) + 1, dtype=np.int64)
    np.cumsum(sizes, out=indptr[1:])
    idx = np.concatenate(lists)
    rows = np.repeat(np.arange(len(xyz)), sizes)
    d2 = _sqdist(xyz, rows, idx)
    keep = d2 <= radius * radius  # the grid's test, in the same arithmetic
    d2 = np.where(idx == rows, -1.0, d2)
    o = np.lexsort((idx, d2, rows))
    o = o[keep[o]]
    counts = np.bincount(rows[o], minlength=len(xyz))
    indptr[1:] = np.cumsum(counts)
    return Neighborhoods(
        indptr, idx[o].astype(np.int32), np.maximum(d2[o], 0.0).astype(np.float32)
    )
