"""The raster of a scene's cells, shared by the ground filters.

Its corner and size (:func:`raster_extent`), the cell of every point
(:func:`cell_indices`), the lowest point of each cell of a window
(:func:`minimum_raster`) and the islands of occupied cells
(:func:`islands`): SMRF, CSF and the tiles all grid a scene the same way.
"""

import numpy as np
from scipy.sparse import coo_array
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from skpcd.segmentation.ground._raster_kernels import (
    cell_indices_rows,
    cell_minimum_parts,
    extent_parts,
    merge_minimum,
)
from skpcd.utils._parallel import parallel_rows

# Cells computed at most (a 1 km square at 7 cm): the rasters of the
# islands of occupied cells (each grown by twice the reach), summed; beyond,
# ask for a larger ``cell`` rather than allocating gigabytes. Also the
# largest ``dem_`` / ``objects_`` assembled as one array.
MAX_CELLS = 200_000_000

# Work per chunk of a threaded pass at least: cells of the raster for the
# passes over its rows, points per part of the minimum raster (each part
# has a raster of its own: at most one cell per point beyond the first).
_MIN_CELLS = 16384
_MIN_PART_POINTS = 65536

# Largest cell index along an axis: cell indices are computed in float64,
# exact up to 2**53.
_MAX_INDEX = 2**53


def raster_extent(xyz, cell, n_threads=1):
    """The raster of a scene: its corner and its size in cells; a
    ValueError when the coordinates are not finite or span more cells than
    can be indexed."""

    n_parts = min(n_threads, max(1, len(xyz) // _MIN_PART_POINTS))
    bounds = np.linspace(0, len(xyz), n_parts + 1).astype(np.int64)
    parts = np.empty((n_parts, 5))
    parallel_rows(extent_parts, n_parts, n_threads, xyz, bounds, parts, min_chunk=1)
    if not parts[:, 4].all():
        raise ValueError("X contains NaN or infinite coordinates.")
    lo, hi = parts[:, :2].min(axis=0), parts[:, 2:4].max(axis=0)
    # a zero may be -0.0 or 0.0: the sign numpy's reductions choose
    for k in np.flatnonzero((lo == 0) | (hi == 0)):
        lo[k], hi[k] = xyz[:, k].min(), xyz[:, k].max()
    extent = hi - lo
    with np.errstate(over="ignore", invalid="ignore"):
        n = np.floor(extent / cell) + 1
    if not (np.isfinite(n).all() and (n <= _MAX_INDEX).all()):
        raise ValueError(
            f"the scene ({extent[0]:.6g} x {extent[1]:.6g}) spans more than "
            f"2**53 cells of {cell} along an axis: the cells are not "
            "representable; check the coordinates (a unit or a scale error?) "
            "or use a larger cell"
        )
    nx, ny = (int(v) for v in n)
    return lo, nx, ny


def cell_indices(xyz, cell, n_threads=1):
    """The raster of a scene (:func:`_raster`) and the (col, row) cell of
    every point."""

    lo, nx, ny = raster_extent(xyz, cell, n_threads)
    cells = np.empty((len(xyz), 2), dtype=np.int64)
    parallel_rows(
        cell_indices_rows, len(xyz), n_threads, xyz, lo[0], lo[1], cell, nx, ny,
        cells,
    )  # fmt: skip
    return lo, nx, ny, cells


def minimum_raster(xyz, origin, cell, size, start, shape, n_threads):
    """Lowest z of the points in the cells of a window of a raster.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The points, C-contiguous.
    origin : (float, float)
        x and y of the raster's corner.
    cell : float
        Cell size.
    size : (int, int)
        Columns and rows of the raster.
    start : (int, int)
        Column and row of the window's first cell.
    shape : (int, int)
        Rows and columns of the window.
    n_threads : int
        Threads: the points are cut into as many parts, each with a raster
        of its own (if the points are at least ``_MIN_PART_POINTS`` per part
        and per cell), merged by the minimum in the order of the parts: the
        raster of one pass over the points in order, bit for bit.

    Returns
    -------
    zmin : ndarray of shape ``shape``
        +inf in the cells without a point.
    """

    n_cells = int(shape[0]) * int(shape[1])
    n_parts = min(n_threads, max(1, len(xyz) // max(n_cells, _MIN_PART_POINTS)))
    bounds = np.linspace(0, len(xyz), n_parts + 1).astype(np.int64)
    zmin = np.full(shape, np.inf)
    others = np.full((n_parts - 1, *shape), np.inf)
    args = (float(origin[0]), float(origin[1]), float(cell), *size, *start)
    parallel_rows(
        cell_minimum_parts, n_parts, n_threads, xyz, bounds, *args, zmin, others,
        min_chunk=1,
    )  # fmt: skip
    if n_parts > 1:
        parallel_rows(
            merge_minimum, shape[0], n_threads, zmin, others,
            min_chunk=raster_rows(zmin),
        )  # fmt: skip
    return zmin


def raster_rows(grid):
    """Fewest rows per chunk of a threaded pass over a raster."""
    return max(1, _MIN_CELLS // max(grid.shape[1], 1))


def islands(cells, reach):
    """Rectangles of cells ``(c0, r0, c1, r1)`` (inclusive) around groups of
    occupied cells, each farther than ``2 * reach`` cells from the others,
    and the island of every point.

    The occupied cells are grouped by blocks of ``reach`` cells (touching
    blocks joined), then rectangles at most ``2 * reach`` apart merged until
    none is: the cost follows the occupied blocks, not the scene's bounding
    box."""

    # the occupied blocks (sorted by a key), their cells' bounds
    blk = cells // reach
    nb = int(blk[:, 1].max()) + 1
    if (int(blk[:, 0].max()) + 1) * nb < 2**62:
        key = blk[:, 0] * nb + blk[:, 1]
    else:  # too many blocks for one int64 key: rank each column first
        ranks = [np.unique(v, return_inverse=True)[1].ravel() for v in blk.T]
        key = ranks[0] * (int(ranks[1].max()) + 1) + ranks[1]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    starts = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
    block_of = np.empty(len(cells), dtype=np.int64)
    block_of[order] = np.cumsum(np.r_[False, sorted_key[1:] != sorted_key[:-1]])
    blocks = blk[order[starts]]
    sorted_cells = cells[order]
    block_lo = np.minimum.reduceat(sorted_cells, starts, axis=0)
    block_hi = np.maximum.reduceat(sorted_cells, starts, axis=0)
    del sorted_cells
    pairs = cKDTree(blocks).query_pairs(1, p=np.inf, output_type="ndarray")
    graph = coo_array(
        (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(blocks),) * 2
    )
    _, label = connected_components(graph, directed=False)
    while True:
        k = label.max() + 1
        lo = np.full((k, 2), np.iinfo(np.int64).max)
        hi = np.full((k, 2), -1)
        np.minimum.at(lo, label, block_lo)
        np.maximum.at(hi, label, block_hi)
        # rectangles at most 2 * reach apart (their grown rectangles meet)
        pr, pc = [], []
        step = max(1, 2**21 // k)
        for i in range(0, k, step):
            a, b = lo[i : i + step, None], hi[i : i + step, None]
            gap = np.maximum(np.maximum(lo[None] - b, a - hi[None]), 0)
            rows, cols = np.nonzero((gap <= 2 * reach).all(axis=2))
            pr.append(rows + i)
            pc.append(cols)
        pr, pc = np.concatenate(pr), np.concatenate(pc)
        if (pr == pc).all():
            return np.column_stack([lo, hi]), label[block_of]
        graph = coo_array((np.ones(len(pr)), (pr, pc)), shape=(k, k))
        _, joined = connected_components(graph, directed=False)
        label = joined[label]
