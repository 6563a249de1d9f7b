"""3D grid sampling: one point per occupied cell of a cubic grid."""

import typing
from concurrent.futures import ThreadPoolExecutor
from numbers import Integral, Real

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions

from skpcd.neighbors._grid import argsort_keys
from skpcd.neighbors._neighbors import check_points
from skpcd.preprocessing import _sampling_kernels as k
from skpcd.preprocessing._spacing import point_spacing
from skpcd.utils import check_point_clouds
from skpcd.utils._compile import entry_point
from skpcd.utils._estimator import CloudTransformer
from skpcd.utils._geometry import point_bounds
from skpcd.utils._parallel import effective_threads, parallel_rows

__all__ = ["GridSampler", "grid_sample"]


def _voxel_size(xyz, voxel_size, n_threads=1):
    if not (isinstance(voxel_size, str) and voxel_size == "auto"):
        if not (isinstance(voxel_size, Real) and 0 < voxel_size < np.inf):
            raise ValueError(
                f'voxel_size must be a positive number or "auto", got {voxel_size!r}'
            )
        return float(voxel_size)
    spacing = point_spacing(xyz, workers=n_threads)
    # a cloud without two distinct points: any cell size keeps one point
    return spacing if np.isfinite(spacing) else 1.0


# Clouds of at least this many points are sampled one at a time on all the
# threads, smaller ones several at a time.
_ALONE = 1 << 17

# Cells per axis stay below this: their indices fit in an int64.
_MAX_CELLS = 2.0**62


def _grid_sample_indices(xyz, h, n_threads=1):
    """Indices (ascending) of the point nearest its cell's centre, per cell."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=np.intp)
    lo, hi = point_bounds(xyz)
    # everything relative to the grid's corner (exact for a cloud far from
    # the origin): cells and distances to their centres do not depend on
    # where the cloud lies, ties included
    with np.errstate(over="ignore"):
        extent = hi - lo
        n_cells = extent / h
    if not (n_cells < _MAX_CELLS).all():
        axis = int(np.argmax(~(n_cells < _MAX_CELLS)))
        raise ValueError(
            f"voxel_size={h:.6g} cuts the cloud's extent along {'xyz'[axis]} "
            f"({extent[axis]:.6g}) into {n_cells[axis]:.3g} cells, more than "
            "cell indices can hold (2**62): choose a larger voxel_size."
        )
    dims = np.floor(n_cells).astype(np.int64) + 1
    if np.prod(dims.astype(np.float64)) >= 2.0**62:
        return _grid_sample_lexsort(xyz - lo, h)
    # one key per cell, a stable radix sort (ties stay in index order), and
    # in every run of one key the point nearest the centre
    n = len(xyz)
    keys = np.empty(n, dtype=np.int64)
    d2 = np.empty(n, dtype=np.float64)
    parallel_rows(k.cell_keys_centres, n, n_threads, xyz, lo, h, dims, keys, d2)
    order, sorted_keys = argsort_keys(keys, n_threads)
    del keys
    chosen = np.zeros(n, dtype=np.bool_)
    parallel_rows(k.nearest_in_cells, n, n_threads, sorted_keys, order, d2, chosen)
    return np.flatnonzero(chosen)


def _grid_sample_lexsort(u, h):
    """:func:`_grid_sample_indices` for grids of 2**62 cells or more (keys
    as three coordinates, a lexsort), from ``u``, the points minus their
    minimum."""
    cell = np.floor(u / h).astype(np.int64)
    with np.errstate(over="ignore", invalid="ignore"):
        d2 = ((u - (cell + 0.5) * h) ** 2).sum(axis=1)
    keys = [cell[:, 2], cell[:, 1], cell[:, 0]]
    # by cell, then distance to the centre, then index (lexsort is stable)
    order = np.lexsort([d2, *keys])
    sorted_keys = np.column_stack([c[order] for c in keys])
    first = np.ones(len(order), dtype=bool)
    first[1:] = (sorted_keys[1:] != sorted_keys[:-1]).any(axis=1)
    return np.sort(order[first])


@entry_point
def grid_sample(points, voxel_size="auto", *, return_index=False, n_jobs=None):
    """3D grid sampling of one cloud: in every occupied cell, the point
    closest to the cell's centre.

    The grid starts at the cloud's minimum corner, so the result does not
    change when the cloud is translated. O(n) (a radix sort of the cells).

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        The cloud; all columns are kept for the chosen points.
    voxel_size : float or "auto", default="auto"
        Edge of the cubic cells, in the units of the data. ``"auto"`` uses
        the cloud's median nearest-neighbour spacing
        (:func:`~skpcd.preprocessing.point_spacing`): cells about one
        point apart, which removes duplicates and clumps of noise but keeps
        the resolution of the surfaces (a cloud without two distinct points
        is reduced to one point).
    return_index : bool, default=False
        Also return the indices of the kept points.
    n_jobs : int, default=None
        Threads for the cell keys, the sort and the choice in each cell;
        None means 1, -1 all cores. The result is the same for every value.

    Returns
    -------
    sampled : ndarray of shape (n_kept, n_columns)
        The kept points, in their original order.
    index : ndarray of shape (n_kept,)
        Their indices in ``points``, ascending; only with ``return_index``.

    Raises
    ------
    ValueError
        If ``voxel_size`` is not positive, or so small against the cloud's
        extent that a cell index would overflow an int64 (more than 2**62
        cells along an axis; PCL's ``VoxelGrid``, in int32, warns and
        returns its input unchanged beyond 2**31 cells in all).

    Notes
    -----
    Ties (two points equally close to a centre) keep the lower index.
    Cells and distances are computed relative to the grid's corner, so the
    result is the same wherever the cloud lies (UTM coordinates included).
    Wang et al. (2023) use this sampling with 0.5 m cells on segments whose
    point spacing is 0.35-2 m.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.preprocessing import grid_sample
    >>> pts = np.array([[0.1, 0.1, 0.1], [0.5, 0.5, 0.5], [1.5, 0.5, 0.5]])
    >>> grid_sample(pts, voxel_size=1.0).tolist()
    [[0.5, 0.5, 0.5], [1.5, 0.5, 0.5]]
    """
    points = np.asarray(points)
    xyz = check_points(points)
    n_threads = effective_threads(n_jobs)
    h = _voxel_size(xyz, voxel_size, n_threads)
    index = _grid_sample_indices(xyz, h, n_threads)
    if return_index:
        return points[index], index
    return points[index]


class GridSampler(CloudTransformer):
    """3D grid sampling of each cloud (Wang et al., 2023, section 3).

    Keeps, in every occupied cell of a cubic grid, the point closest to the
    cell's centre: it evens out the density, removes duplicates and noise
    clumps, and makes descriptors cheaper. See :func:`grid_sample`.

    Read more in the :ref:`User Guide <smooth_shapes>`.

    Parameters
    ----------
    voxel_size : float or "auto", default="auto"
        Cell edge in the units of the data, or ``"auto"`` for each cloud's
        median nearest-neighbour spacing.
    n_jobs : int, default=None
        Threads; None means 1, -1 all cores. A large cloud is sampled on
        all of them; a list of small clouds, several clouds at a time. The
        result is the same for every value.

    Attributes
    ----------
    n_features_in_ : int
        Columns of the clouds seen in :meth:`fit`.

    See Also
    --------
    grid_sample : The same on one array.

    Examples
    --------
    >>> from skpcd.datasets import make_point_clouds
    >>> from skpcd.preprocessing import GridSampler
    >>> clouds = make_point_clouds(2, n_points=500, random_state=0)
    >>> sampled = GridSampler(voxel_size=0.5).fit_transform(clouds)
    >>> [len(c) < 500 for c in sampled]
    [True, True]
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "voxel_size": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "n_jobs": [Integral, None],
    }

    def __init__(self, voxel_size="auto", n_jobs=None):
        self.voxel_size = voxel_size
        self.n_jobs = n_jobs

    def _validate(self, X):
        return check_point_clouds(X, min_points=0)

    def transform(self, X):
        """Sample every cloud.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds (empty clouds stay empty).

        Returns
        -------
        sampled : list of ndarray of shape (n_kept_i, n_columns_i)
            The kept points of each cloud, in their original order.
        """
        X = self._validate(X)
        n_threads = effective_threads(self.n_jobs)
        small = [i for i, c in enumerate(X) if len(c) < _ALONE]
        out = [None] * len(X)
        for i in range(len(X)):
            if len(X[i]) >= _ALONE:  # on all threads, one at a time
                out[i] = grid_sample(X[i], self.voxel_size, n_jobs=n_threads)
        if n_threads == 1 or len(small) < 2:
            for i in small:
                out[i] = grid_sample(X[i], self.voxel_size)
            return out
        # the small clouds, several at a time, each on one thread
        with ThreadPoolExecutor(n_threads) as pool:
            done = pool.map(lambda i: grid_sample(X[i], self.voxel_size), small)
            for i, sampled in zip(small, done, strict=True):
                out[i] = sampled
        return out
