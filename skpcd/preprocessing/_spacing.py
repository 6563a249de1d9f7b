"""Point spacing: the typical distance between neighbouring points."""

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "LOCAL_RATIO",
    "nearest_neighbours",
    "point_spacing",
    "spacing_of",
    "spacing_queries",
]


def point_spacing(
    points, *, quantile=0.5, max_points=200_000, random_state=0, workers=1
):
    """Typical distance from a point to its nearest distinct neighbour.

    Use it to choose a neighbourhood radius or a grid cell size in the
    units of the data: a radius of 5-10 spacings usually holds 20-80
    neighbours on a surface.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        One cloud; columns beyond the third are ignored.
    quantile : float, default=0.5
        Which quantile of the nearest-neighbour distances to return (0.5 is
        the median).
    max_points : int, default=200_000
        Larger clouds are estimated on this many randomly chosen query
        points (all points are still used as candidates).
    random_state : int, RandomState instance or None, default=0
        Seeds the choice of query points for large clouds.
    workers : int, default=1
        Threads for the nearest-neighbour queries (-1 for all cores).

    Returns
    -------
    spacing : float
        The quantile of the distances to the nearest neighbour at a
        non-zero distance; duplicate points are ignored. NaN if the cloud
        has fewer than two distinct points.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.preprocessing import point_spacing
    >>> grid = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0), [0.0]), -1)
    >>> float(point_spacing(0.5 * grid.reshape(-1, 3)))
    0.5
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] < 3:
        raise ValueError(f"points must have shape (n_points, 3+), got {points.shape}")
    xyz = points[:, :3]
    if len(xyz) < 2:
        return float("nan")
    rows = spacing_queries(len(xyz), max_points, random_state)
    queries = xyz if rows is None else xyz[rows]
    dist, _ = nearest_neighbours(xyz, queries, min(len(xyz), 8), workers=workers)
    return spacing_of(dist, quantile)


def spacing_queries(n, max_points, random_state):
    """The rows of the points whose nearest neighbours :func:`point_spacing`
    measures: ``max_points`` of ``n`` drawn without replacement, None (all)
    when there are no more."""
    if n <= max_points:
        return None
    rng = np.random.default_rng(
        random_state
        if not hasattr(random_state, "randint")
        else random_state.randint(2**31)
    )
    return rng.choice(n, max_points, replace=False)


def spacing_of(dist, quantile=0.5):
    """:func:`point_spacing` from the distances of the query points to their
    nearest neighbours (at least 8 of them, or all the points, ascending;
    duplicates at distance 0 are skipped)."""
    dist = np.where(dist[:, :8] > 0, dist[:, :8], np.inf).min(axis=1)
    dist = dist[np.isfinite(dist)]
    if len(dist) == 0:
        return float("nan")
    return float(np.quantile(dist, quantile))


# Clouds of at most this many points per query point are searched with one
# k-d tree of all their points; larger ones with a tree of the points near
# the queries (nearest_neighbours).
LOCAL_RATIO = 20
# The cubes of cells around a query reach this many cells on each side.
_REACH = 1
# The first cells' side, in spacings of the queries scaled to the cloud.
_FIRST_CELL = 5.0


def nearest_neighbours(xyz, queries, k, *, workers=1, local_ratio=LOCAL_RATIO):
    """The ``k`` nearest points of ``xyz`` to each query point: distances
    and rows, as ``scipy.spatial.cKDTree(xyz).query(queries, k)`` gives
    them, without a tree of the whole cloud when it is large.

    A cloud of more than ``local_ratio`` points per query is searched with
    a tree of only the points in the cubes of ``2 * _REACH + 1`` cells
    around the queries' cells: a point outside a query's cube is more than
    ``_REACH`` cells from it, so a query whose ``k``-th distance in that
    tree is less than that is answered (the same neighbours, at the same
    distances, computed by the same code); the others are searched again
    with cells twice as large, and with a tree of the whole cloud when the
    cubes would hold half of it. The side of the first cells is taken from
    the spacing of the queries among themselves, scaled to the density of
    the whole cloud.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The cloud, float64.
    queries : ndarray of shape (n_queries, 3)
        The query points, float64.
    k : int
        Neighbours of each query (at most ``n_points``).
    workers : int, default=1
        Threads of the queries (-1 for all cores).
    local_ratio : float, default=20
        Points per query above which the tree holds only the points near
        the queries.

    Returns
    -------
    dist : ndarray of shape (n_queries, k)
        Distances to the neighbours, ascending: those of a tree of the
        whole cloud, bit for bit.
    rows : ndarray of shape (n_queries, k), dtype int64
        The neighbours' rows in ``xyz``: those of a tree of the whole cloud
        except where several points lie at the same distance of a query
        (which of them a tree returns depends on its shape).
    """
    n, m = len(xyz), len(queries)
    if n <= local_ratio * max(m, 1) or m < 2:
        return _as_2d(*cKDTree(xyz).query(queries, k=k, workers=workers))
    # imported only here: the spacing of a small cloud (skpcd info loads
    # this module alone) needs neither numba nor the skpcd packages
    from skpcd.preprocessing._spacing_kernels import block_table, in_table
    from skpcd.utils._geometry import point_bounds

    corner, top = point_bounds(xyz)
    extent = float((top - corner).max())
    reach_of_coordinates = float(np.abs(np.concatenate([corner, top])).max()) + extent
    # the queries' spacing among themselves, at the density of the cloud
    # (as on a surface: the queries are a sample of m of n points)
    own, _ = cKDTree(queries).query(queries, k=2)
    h = float(np.median(own[:, 1])) * np.sqrt(m / n) * _FIRST_CELL
    dist = np.empty((m, k))
    rows = np.empty((m, k), dtype=np.int64)
    pending = np.arange(m)
    inside = np.empty(n, dtype=bool)
    while len(pending):
        # cells too small or too large to hold only the near points
        if not (h > 0 and reach_of_coordinates / h < 1e12 and h < extent):
            break
        cells, used = block_table(queries[pending], corner, h, _REACH)
        in_table(xyz, corner, h, cells, used, inside)
        near = np.flatnonzero(inside)
        if 2 * len(near) > n:
            break
        d, i = _as_2d(*cKDTree(xyz[near]).query(queries[pending], k=k, workers=workers))
        # a point outside a cube is at least _REACH cells away (a margin of
        # a hundredth of a cell for the rounding of the cells' indices)
        done = d[:, -1] < (_REACH - 0.01) * h
        dist[pending[done]] = d[done]
        rows[pending[done]] = near[i[done]]
        pending = pending[~done]
        h *= 2.0
    if len(pending):
        d, i = _as_2d(*cKDTree(xyz).query(queries[pending], k=k, workers=workers))
        dist[pending], rows[pending] = d, i
    return dist, rows


def _as_2d(dist, rows):
    """The answer of a k-d tree's query for k = 1 as (n, 1) arrays."""
    return np.asarray(dist).reshape(len(dist), -1), np.asarray(rows).reshape(
        len(rows), -1
    )
