"""The automatic eps of a tiled scan, estimated once for the whole scan as
the untiled estimate is (step 2 of
:func:`~skpcd.segmentation.tiling._segment.segment_tiled`): the same sample
of non-ground points, their neighbours searched in their buffered tile, and
for the few whose neighbours the tile may not hold, in every tile within
reach."""

import numpy as np
from scipy.spatial import cKDTree
from sklearn.utils import check_random_state

from skpcd.segmentation._dbscan import (
    AutoEpsDBSCAN,
    eps_from_knee,
    fit_knee,
    kdist_mean,
    sample_queries,
    stable_draw,
)
from skpcd.segmentation.tiling._dispatch import map_tiles
from skpcd.segmentation.tiling._geometry import held_square, reaches

__all__ = ["chunked_sample_queries", "estimate_tiled_eps"]


def _eps_prepare(xyz, index, ground, tile, grid, queries):
    """The non-ground points of a buffered tile and, among its own points,
    the queries of the eps estimate with their distance to the edge of the
    area the tile holds; the scan indices of those queries."""
    mine = np.flatnonzero(grid.owner(xyz) == tile)
    mine = mine[np.isin(index[mine], queries)]
    if not len(mine):
        return (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)), index[mine]
    x0, y0, x1, y1 = held_square(grid, tile, grid.buffer)
    q = xyz[mine]
    margin = np.minimum(
        np.minimum(q[:, 0] - x0, x1 - q[:, 0]), np.minimum(q[:, 1] - y0, y1 - q[:, 1])
    )
    return (np.ascontiguousarray(xyz[~ground]), q, margin), index[mine]


def _eps_tile(points, queries, margin, k, n_threads):
    """Distances from each query to its ``k`` nearest ``points`` (itself
    first), and which are exact: those whose ``k``-th neighbour is nearer
    than the edge of the tile's area (``margin``), so that no point beyond
    it could be nearer; the others (isolated points, whose neighbours are
    far) come with their coordinates, for :func:`_eps_far_queries`."""
    if not len(queries):
        return np.zeros((0, k)), np.ones(0, dtype=bool), np.zeros((0, 3))
    tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
    d, _ = tree.query(queries, k=k, workers=n_threads)
    d = d.reshape(len(queries), -1)
    exact = d[:, -1] + 1e-6 < margin
    return d, exact, queries[~exact]


def _far_prepare(xyz, index, ground, tile, grid, queries, bounds):
    """The non-ground points a tile owns, and the queries (rows of
    ``queries``) whose ball of radius ``bounds`` reaches its core square
    (unbounded at the grid's edges, like the area its points come from)."""
    near = np.flatnonzero(reaches(grid, tile, queries, bounds))
    own = (grid.owner(xyz) == tile) & ~ground
    if not len(near) or not own.any():
        return (np.zeros((0, 3)), np.zeros((0, 3))), np.zeros(0, dtype=np.int64)
    return (np.ascontiguousarray(xyz[own]), queries[near]), near


def _far_tile(points, queries, k, n_threads):
    """Distances from each query to its ``k`` nearest ``points`` (+inf when
    there are fewer)."""
    if not len(queries):
        return np.zeros((0, k))
    tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
    d, _ = tree.query(queries, k=k, workers=n_threads)
    return d.reshape(len(queries), -1)


def _eps_far_queries(scene, tiles, ground, queries, bounds, k, n_jobs):
    """The exact distances from each query to its ``k`` nearest non-ground
    points, for queries whose neighbours their own tile may not hold:
    each tile whose core square is within ``bounds`` of a query (the
    distance of its ``k``-th neighbour found in its tile, which the true one
    cannot exceed) gives the ``k`` nearest of the points it owns, and the
    ``k`` smallest of those distances are the query's (every point is owned
    by one tile)."""
    near = [t for t in tiles if reaches(scene.grid, t, queries, bounds).any()]
    parts = [[] for _ in range(len(queries))]
    for rows, d in map_tiles(
        scene, near, _far_prepare, (scene.grid, queries, bounds), _far_tile,
        (k,), n_jobs, ground=ground,
    ):  # fmt: skip
        for row, dist in zip(rows.tolist(), d):
            parts[row].append(dist)
    found = np.empty((len(queries), k))
    for row, dists in enumerate(parts):
        found[row] = np.sort(np.concatenate(dists))[:k]
    return found


def chunked_sample_queries(n, max_samples, random_state, chunk_size):
    """:func:`~skpcd.segmentation._dbscan.sample_queries`, the same draw,
    with the ``n`` random keys drawn ``chunk_size`` at a time: the
    ``max_samples`` smallest keys so far are kept (with the rank of their
    point) and merged with each new chunk, so memory holds a chunk and the
    sample, not a key and a rank per non-ground point of the scan. A
    :class:`numpy.random.RandomState` draws the same keys in chunks as at
    once; equal keys at the cut (two of ``n`` 53-bit uniforms equal, and at
    the rank of the ``max_samples``-th) are the one case where the two
    could keep different points.

    Parameters
    ----------
    n : int
        Points to draw from.
    max_samples : int or None
        Points drawn (all ``n`` when None or not fewer than ``n``).
    random_state : int, RandomState instance or None
        As :func:`~skpcd.segmentation._dbscan.sample_queries`.
    chunk_size : int
        Keys drawn at a time.

    Returns
    -------
    ranks : ndarray of shape (n_samples,), dtype int64
        The ranks drawn, sorted.
    """
    if max_samples is None or n <= max_samples:
        return sample_queries(n, max_samples, random_state)
    rng = check_random_state(random_state)
    return np.sort(stable_draw(n, int(max_samples), rng, chunk=chunk_size))


def estimate_tiled_eps(
    scene, tiles, ground, min_samples, eps_scale, random_state, n_jobs,
    chunk_size,
):  # fmt: skip
    """The eps of :class:`AutoEpsDBSCAN` for the non-ground points of the
    whole scan, computed tile by tile: the same random sample of query points
    as the untiled estimate (drawn among all non-ground points, in scan
    order), their nearest neighbours searched among the non-ground points of
    their buffered tile, which holds all of them when the k-th neighbour is
    nearer than the edge of the tile's area; for the other queries (isolated
    points), among the points of every tile within that distance
    (:func:`_eps_far_queries`). The distances are those of the untiled
    search, so is the estimate."""
    is_ground = ground[0]
    est = AutoEpsDBSCAN(
        min_samples=min_samples, eps_scale=eps_scale, random_state=random_state
    )
    n = 0
    for start in range(0, scene.n_points, chunk_size):
        n += int((~is_ground[start : start + chunk_size]).sum())
    if n < 2:
        return 0.0
    k_max = min(int(est.n_neighbors), n - 1)
    ranks = chunked_sample_queries(n, est.max_samples, random_state, chunk_size)
    # scan index of each query: its rank among the non-ground points
    queries, seen = [], 0
    for start in range(0, scene.n_points, chunk_size):
        rest = np.flatnonzero(~is_ground[start : start + chunk_size])
        lo, hi = np.searchsorted(ranks, [seen, seen + len(rest)])
        queries.append(rest[ranks[lo:hi] - seen] + start)
        seen += len(rest)
    queries = np.concatenate(queries)
    dist = np.empty((len(queries), k_max + 1))
    far_rows, far_xyz, far_bounds = [], [], []
    for index, (d, exact, xyz) in map_tiles(
        scene, tiles, _eps_prepare, (scene.grid, queries), _eps_tile,
        (k_max + 1,), n_jobs, ground=ground,
    ):  # fmt: skip
        if len(index):
            rows = np.searchsorted(queries, index)
            dist[rows] = d
            far_rows.append(rows[~exact])
            far_xyz.append(xyz)
            far_bounds.append(d[~exact, -1])
    if far_rows and sum(map(len, far_rows)):
        # isolated queries: their neighbours searched in every tile near
        rows = np.concatenate(far_rows)
        dist[rows] = _eps_far_queries(
            scene, tiles, ground, np.concatenate(far_xyz),
            np.concatenate(far_bounds), k_max + 1, n_jobs,
        )  # fmt: skip
    mean = kdist_mean(dist[:, 1:])
    _, _, knee_distance = fit_knee(np.arange(1, k_max + 1), mean, est.degree)
    # as AutoEpsDBSCAN._estimate (test_tiling checks the two estimates agree)
    return eps_from_knee(knee_distance, est.eps_scale)
