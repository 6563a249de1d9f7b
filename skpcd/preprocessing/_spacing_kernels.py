"""numba kernels of the neighbours of a few points among many: the cubes of
cells around the query points, in a hash table, and the points of a cloud
that fall in one of them, in one pass over the cloud."""

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _slot(cx, cy, cz, mask):
    """The first slot of a cell ``(cx, cy, cz)`` in a table of ``mask + 1``
    slots (a power of two)."""
    key = (cx * 73856093) ^ (cy * 19349663) ^ (cz * 83492791)
    return key & mask


@njit(cache=True, nogil=True)
def block_table(queries, corner, h, reach):
    """The cells within ``reach`` cells (along each axis) of the cell of
    each query point, in an open-addressing hash table.

    Parameters
    ----------
    queries : ndarray of shape (n_queries, 3)
        The query points.
    corner : ndarray of shape (3,)
        Origin of the cells: cell ``(i, j, l)`` holds the points whose
        ``floor((p - corner) / h)`` is ``(i, j, l)``.
    h : float
        Side of the cells.
    reach : int
        Cells on each side of a query's cell.

    Returns
    -------
    cells : ndarray of shape (n_slots, 3), dtype int64
        The cells of the table's slots.
    used : ndarray of shape (n_slots,), dtype bool
        Which slots hold a cell.
    """
    side = 2 * reach + 1
    size = 1
    while size < 2 * len(queries) * side**3:
        size *= 2
    cells = np.zeros((size, 3), dtype=np.int64)
    used = np.zeros(size, dtype=np.bool_)
    mask = size - 1
    for q in range(len(queries)):
        qx = math.floor((queries[q, 0] - corner[0]) / h)
        qy = math.floor((queries[q, 1] - corner[1]) / h)
        qz = math.floor((queries[q, 2] - corner[2]) / h)
        for cx in range(qx - reach, qx + reach + 1):
            for cy in range(qy - reach, qy + reach + 1):
                for cz in range(qz - reach, qz + reach + 1):
                    s = _slot(cx, cy, cz, mask)
                    while used[s] and not (
                        cells[s, 0] == cx and cells[s, 1] == cy and cells[s, 2] == cz
                    ):
                        s = (s + 1) & mask
                    if not used[s]:
                        used[s] = True
                        cells[s, 0] = cx
                        cells[s, 1] = cy
                        cells[s, 2] = cz
    return cells, used


@njit(cache=True, nogil=True)
def in_table(xyz, corner, h, cells, used, out):
    """Which points of ``xyz`` lie in a cell of the table of
    :func:`block_table` (same ``corner`` and ``h``), into ``out``."""
    mask = len(used) - 1
    for i in range(len(xyz)):
        cx = math.floor((xyz[i, 0] - corner[0]) / h)
        cy = math.floor((xyz[i, 1] - corner[1]) / h)
        cz = math.floor((xyz[i, 2] - corner[2]) / h)
        s = _slot(cx, cy, cz, mask)
        found = False
        while used[s]:
            if cells[s, 0] == cx and cells[s, 1] == cy and cells[s, 2] == cz:
                found = True
                break
            s = (s + 1) & mask
        out[i] = found
