"""The sorted voxel grid: one type and the entry points other packages call.

The neighbour search (:mod:`skpcd.neighbors._neighbors`), the grid
DBSCAN (:mod:`skpcd.segmentation._clusters`) and the blocked radius PFH
(:mod:`skpcd.features._pfh`) all bucket packed clouds into cubic cells and
sort the points by (cloud, cell key); the kernels that walk the grid are in
:mod:`skpcd.neighbors._grid_kernels`. Outside ``neighbors`` the
grid is a :class:`VoxelGrid`, built by :func:`radius_grid` (or
:func:`build_grid`) and searched through :func:`ball_counts`,
:func:`ball_lists` and :func:`ball_block` (the normals of a block without
its neighbourhoods: ``skpcd.preprocessing._normals.ball_block_normals``);
the k-nearest search (:func:`~skpcd.neighbors._neighbors.search_packed`)
passes it to its own kernel. Nobody outside indexes tuples of cell arrays
or passes empty arrays as switches.
"""

import itertools
import typing
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from skpcd.neighbors import _grid_kernels as g
from skpcd.utils._geometry import cloud_bounds
from skpcd.utils._parallel import parallel_rows, parallel_section

__all__ = [
    "BLOCK_CHUNK",
    "VoxelGrid",
    "argsort_keys",
    "ball_block",
    "ball_counts",
    "ball_lists",
    "build_grid",
    "grid_shape",
    "radius_grid",
    "snake_order",
    "sort_points",
]


class VoxelGrid(typing.NamedTuple):
    """Packed clouds bucketed into cubic cells, points sorted by (cloud, key).

    A NamedTuple of arrays: numba kernels take it as one argument.

    Attributes
    ----------
    xs : ndarray of shape (n_points, 3), float64
        The points in sorted order (``xyz[order]``).
    order : ndarray of shape (n_points,), int64
        Point index at each sorted position.
    cell_cloud, cell_key : ndarray of shape (n_cells,), int64
        Each occupied cell's cloud and key ``(x * ny + y) * nz + z``.
    cell_start : ndarray of shape (n_cells + 1,), int64
        Sorted position of each cell's first point.
    cloud_cells : ndarray of shape (n_clouds + 1,), int64
        First cell of each cloud.
    origin : ndarray of shape (n_clouds, 3), float64
        Each cloud's minimum corner.
    h : ndarray of shape (n_clouds,), float64
        Each cloud's cell size.
    dims : ndarray of shape (n_clouds, 3), int64
        Cells per axis of each cloud's grid.
    """

    xs: np.ndarray
    order: np.ndarray
    cell_cloud: np.ndarray
    cell_key: np.ndarray
    cell_start: np.ndarray
    cloud_cells: np.ndarray
    origin: np.ndarray
    h: np.ndarray
    dims: np.ndarray

    @property
    def n_cells(self):
        """Number of occupied cells."""
        return len(self.cell_key)

    def cells_per_cloud(self):
        """Occupied cells of each cloud."""
        return np.diff(self.cloud_cells)


def grid_shape(xyz, offsets, h, lo_hi=None):
    """Origins, cell sizes (at least ``h``, above the radius) and grid shapes.

    Returns ``origin (n_clouds, 3), h (n_clouds,), dims (n_clouds, 3)``.
    """
    lo, hi = cloud_bounds(xyz, offsets) if lo_hi is None else lo_hi
    extent = hi - lo
    # cells a hair wider than asked: a radius query's 27 cells cover the ball
    # whatever the rounding of cell coordinates
    h = np.maximum(h * (1 + 1e-9), extent.max(axis=1) / (g.MAX_DIM - 2))
    h = np.where(h > 0, h, 1.0)
    dims = (np.floor(extent / h[:, None]) + 1).astype(np.int64)
    return lo, h, dims


# Keys below this many are sorted on one thread.
_PARALLEL_SORT = 1 << 16


def argsort_keys(keys, n_threads=1):
    """Stable argsort of non-negative int64 ``keys``, and the sorted keys.

    A least-significant-digit radix sort, 11 bits a pass, only as many
    passes as the largest key needs (a digit that every key shares is
    skipped); with several threads each pass counts and moves the keys of
    one chunk per thread (one histogram per chunk, the chunks' offsets
    stacked in order: the result is the same for every thread count).

    Returns
    -------
    order : ndarray of shape (n,), int64
    sorted_keys : ndarray of shape (n,), int64
    """
    n = len(keys)
    n_threads = max(1, min(int(n_threads), n // _PARALLEL_SORT))
    if n_threads == 1:
        with parallel_section("radix sort"):
            return g.radix_argsort(keys)
    bounds = np.linspace(0, n, n_threads + 1).astype(np.int64)
    chunks = list(enumerate(itertools.pairwise(bounds)))
    src = (keys.copy(), np.arange(n))
    dst = (np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64))
    hist = np.empty((n_threads, 2048), dtype=np.int64)
    top = int(keys.max())
    shift = 0
    with parallel_section("radix sort"), ThreadPoolExecutor(n_threads) as pool:

        def each(fn):
            for future in [pool.submit(fn, t, *c) for t, c in chunks]:
                future.result()

        while shift < 63 and (top >> shift) > 0:
            each(lambda t, lo, hi: g.radix_histogram(src[0], lo, hi, shift, hist[t]))
            total = hist.sum(axis=0)
            if total.max() < n:
                # chunk t's keys of digit d go after every key of a lower
                # digit and after the digit-d keys of the chunks before it
                first = np.cumsum(total) - total
                offsets = first + np.cumsum(hist, axis=0) - hist
                each(
                    lambda t, lo, hi: g.radix_scatter(
                        *src, lo, hi, shift, offsets[t], *dst
                    )
                )
                src, dst = dst, src
            shift += 11
    return src[1], src[0]


def sort_points(xyz, offsets, origin, h, dims, n_threads=1):
    """Points sorted by (cloud, cell key), and the cells.

    Returns ``order`` (point indices in that order) and the tuple
    ``(cell_cloud, cell_key, cell_start, cloud_cells)`` of
    :func:`~skpcd.neighbors._grid_kernels.sorted_cells`.
    """
    n = len(xyz)
    keys = np.empty(n, dtype=np.int64)
    n_keys = np.prod(dims.astype(np.float64), axis=1)
    if n_keys.sum() < 2.0**62:
        # one sort: cloud c's keys shifted past the keys of the clouds before;
        # a radix sort, a few passes of 11 bits (3x faster than np.argsort)
        base = np.concatenate([[0], np.cumsum(np.prod(dims, axis=1))[:-1]])
        keyed = (xyz, offsets, origin, h, dims, base, keys)
        parallel_rows(g.cell_keys, n, n_threads, *keyed)
        order, keys = argsort_keys(keys, n_threads)
        parallel_rows(g.shift_keys, n, n_threads, keys, offsets, base)
        return order, g.sorted_cells(keys, offsets)
    keyed = (xyz, offsets, origin, h, dims, np.zeros(0, np.int64), keys)
    parallel_rows(g.cell_keys, n, n_threads, *keyed)
    cloud = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    order = np.lexsort((keys, cloud))
    return order, g.sorted_cells(keys[order], offsets)


def gather_points(xyz, order, n_threads=1):
    """``xyz[order]`` for an (n, 3) array, rows copied on ``n_threads``."""
    xs = np.empty((len(order), 3), dtype=xyz.dtype)
    parallel_rows(g.gather_rows, len(order), n_threads, xyz, order, xs)
    return xs


def build_grid(xyz, offsets, h, lo_hi=None, n_threads=1):
    """The grid of cells at least ``h[c]`` wide over each cloud ``c``.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3), float64, C-contiguous
        The packed clouds.
    offsets : ndarray of shape (n_clouds + 1,), int64
        Offsets of the clouds.
    h : ndarray of shape (n_clouds,)
        Smallest cell size of each cloud.
    lo_hi : tuple of ndarray, default=None
        The clouds' bounds (:func:`~skpcd.utils._geometry.cloud_bounds`),
        if already known.
    n_threads : int, default=1
        Threads for the keys, the sort and the copy of the points.

    Returns
    -------
    grid : VoxelGrid
    """
    origin, h, dims = grid_shape(xyz, offsets, h, lo_hi)
    order, cells = sort_points(xyz, offsets, origin, h, dims, n_threads)
    xs = gather_points(xyz, order, n_threads)
    return VoxelGrid(xs, order, *cells, origin, h, dims)


def radius_grid(xyz, offsets, radius, lo_hi=None, n_threads=1):
    """The grid of a radius search: cells at least ``radius`` wide, so that
    the points within ``radius`` of a point lie in the 27 cells around it."""
    h = np.full(len(offsets) - 1, float(radius))
    return build_grid(xyz, offsets, h, lo_hi, n_threads)


def snake_order(points, h, cloud=None, n_threads=1):
    """The points in a snake walk over cubic cells ``h`` wide: by x, then y
    up and down, then z; cloud by cloud with ``cloud`` (each point's cloud).

    Consecutive points of the walk are near each other (the pair reuse of
    the PFH kernels visits neighbourhoods in this order). A stable radix
    sort of one key per point (:func:`~skpcd.neighbors._grid_kernels.\
snake_keys`), ten times faster than ``np.lexsort`` of the cell coordinates,
    which remains the fallback for keys beyond an int64; ``n_threads``
    for the sort.

    Returns
    -------
    order : ndarray of shape (n_points,), int64
    """
    if not h > 0 or len(points) == 0:
        return np.arange(len(points))
    cloud = np.zeros(0, np.int64) if cloud is None else cloud.astype(np.int64)
    keys = np.empty(len(points), dtype=np.int64)
    if g.snake_keys(points, cloud, float(h), keys):
        return argsort_keys(keys, n_threads)[0]
    c = np.floor((points - points.min(axis=0)) / h)  # float: beyond an int64
    snake = np.where(c[:, 0] % 2 == 0, c[:, 1], -c[:, 1])
    by = (c[:, 2], snake, c[:, 0]) + (() if not len(cloud) else (cloud,))
    return np.lexsort(by)


_NONE_I8 = np.empty(0, dtype=np.int64)
_NONE_I4 = np.empty(0, dtype=np.int32)
_NONE_F4 = np.empty(0, dtype=np.float32)


def ball_counts(grid, radius, n_threads, counts=None):
    """Points within ``radius`` of every point (itself included), by point.

    Parameters
    ----------
    grid : VoxelGrid
        A grid with cells at least ``radius`` wide (:func:`radius_grid`).
    radius : float
        Inclusive radius.
    n_threads : int
        Threads.
    counts : ndarray of shape (n_points,), int64, default=None
        Written into when given.

    Returns
    -------
    counts : ndarray of shape (n_points,), int64
    """
    if counts is None:
        counts = np.empty(len(grid.order), dtype=np.int64)
    r2 = float(radius) ** 2
    args = (grid, r2, _NONE_I8, counts, _NONE_I4, _NONE_F4)
    parallel_rows(g.ball_cells, grid.n_cells, n_threads, *args)
    return counts


def ball_lists(grid, radius, indptr, counts, indices, sqdist, n_threads):
    """Fill the CSR neighbourhoods ``indices`` (and ``sqdist`` unless empty)
    of every point, rows by point, sorted by (distance, index), the point
    first; ``indptr`` from the :func:`ball_counts` ``counts``."""
    args = (grid, float(radius) ** 2, indptr, counts, indices, sqdist)
    parallel_rows(g.ball_cells, grid.n_cells, n_threads, *args)


# cells per thread chunk of a block (blocks are small: split them anyway)
BLOCK_CHUNK = 64


def ball_block(grid, radius, cells, counts, n_threads, indptr=None, *, sort=True):
    """Radius neighbourhoods of the points of the cells ``cells[0]`` to
    ``cells[1]``, rows by sorted position from the block's first point.

    With ``indptr`` None, only their sizes, into ``counts``; otherwise also
    the CSR ``indices`` (returned), rows sorted by (distance, index) only
    with ``sort`` (unsorted: as found).
    """
    c0, c1 = cells
    t0 = int(grid.cell_start[c0])
    r2 = float(radius) ** 2
    if indptr is None:
        indptr, indices = _NONE_I8, _NONE_I4
    else:
        indices = np.empty(indptr[-1], dtype=np.int32)

    def run(lo, hi):
        g.ball_cells_local(
            c0 + lo, c0 + hi, t0, grid, r2, indptr, counts, indices, sort
        )

    parallel_rows(run, c1 - c0, n_threads, min_chunk=BLOCK_CHUNK)
    return indices
