"""Point spacing: the typical distance between neighbouring points."""

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["point_spacing", "tree_spacing"]


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
    return tree_spacing(
        cKDTree(xyz), quantile=quantile, max_points=max_points,
        random_state=random_state, workers=workers,
    )  # fmt: skip


def tree_spacing(tree, *, quantile=0.5, max_points=200_000, random_state=0, workers=1):
    """:func:`point_spacing` of the points of a k-d tree already built
    (``tree.data``, at least two), for a caller that queries the tree for
    other things too."""
    xyz = tree.data
    queries = xyz
    if len(xyz) > max_points:
        rng = np.random.default_rng(
            random_state
            if not hasattr(random_state, "randint")
            else random_state.randint(2**31)
        )
        queries = xyz[rng.choice(len(xyz), max_points, replace=False)]
    # ask for a few neighbours so that duplicates at distance 0 can be skipped
    k = min(len(xyz), 8)
    dist, _ = tree.query(queries, k=k, workers=workers)
    dist = np.where(dist > 0, dist, np.inf).min(axis=1)
    dist = dist[np.isfinite(dist)]
    if len(dist) == 0:
        return float("nan")
    return float(np.quantile(dist, quantile))
