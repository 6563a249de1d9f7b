"""numba kernels for density clustering on the sorted voxel grid.

The grid is the radius-search grid of :mod:`skpcd.neighbors._neighbors`:
cells at least ``eps`` wide, points sorted by cell key, so that the points
within ``eps`` of a point lie in the 27 cells around its cell, found as 9
runs of memory by :func:`skpcd.neighbors._grid_kernels.cell_block`.

Nothing here stores a neighbourhood. The kernels work on *sorted positions*
``t`` (the point ``order[t]``): a union-find forest ``parent`` over
positions links the core points closer than ``eps``, each pair tested once
(from its lower position), and every non-core point is attached to its
nearest core point within ``eps``. Memory is O(n_points).
"""

import numpy as np
from numba import njit

from skpcd.neighbors._grid_kernels import cell_block, sqdist_to
from skpcd.segmentation._union_find import find_root, union_lower
from skpcd.utils._numba import borrow, keep


@njit(cache=True, nogil=True)
def union_core(lo, hi, grid, core, r2, parent):
    """Link the core points of cells ``lo`` to ``hi`` to the core points
    within ``sqrt(r2)`` (inclusive) in ``parent``, the lower root kept.

    ``grid.xs`` holds the points in sorted order and ``core`` their core
    flags (sorted order too). A pair is tested from its lower position only.
    Threads each need a forest of their own (:func:`merge_forest` joins
    them): the links of a cell may reach any other cell's points.
    """
    _visit_cells(lo, hi, grid, core, r2, parent, False)


@njit(cache=True, nogil=True)
def merge_forest(parent, other):
    """Add the links of the forest ``other`` to ``parent`` (lower root kept)."""
    for t in range(len(other)):
        if other[t] != t:
            union_lower(parent, t, find_root(other, t))


@njit(cache=True, nogil=True)
def attach_border(lo, hi, grid, core, r2, nearest):
    """For every non-core point of cells ``lo`` to ``hi``, the position of
    its nearest core point within ``sqrt(r2)`` into ``nearest`` (ties by the
    lower point index), or -1. Rows are independent: safe in threads."""
    _visit_cells(lo, hi, grid, core, r2, nearest, True)


@njit(cache=True, nogil=True, inline="always")
def _visit_cells(lo, hi, grid, core, r2, out, border):
    """The walk of :func:`union_core` (``border`` False: each core point
    linked in the forest ``out``) and :func:`attach_border` (``border``
    True: each non-core point's nearest core point into ``out``) over the
    points of cells ``lo`` to ``hi``, each with the runs of the 27 cells
    around its cell. Inlined: ``border`` is a constant in each kernel."""
    grid, core, out = borrow(grid, core, out)
    xs, order, cell_start = grid.xs, grid.order, grid.cell_start
    i_own = np.empty(27, dtype=np.int64)
    cur, starts, stops = borrow(i_own[:9], i_own[9:18], i_own[18:])
    for cell in range(lo, hi):
        n_runs = cell_block(
            cell, cell - 1 if cell > lo else -1, grid, cur, starts, stops
        )
        for t0 in range(cell_start[cell], cell_start[cell + 1]):
            if core[t0] == border:  # the other kernel's point
                continue
            qx, qy, qz = xs[t0, 0], xs[t0, 1], xs[t0, 2]
            if border:
                out[t0] = _nearest_core(
                    xs, order, core, r2, qx, qy, qz, starts, stops, n_runs
                )
                continue
            for r in range(n_runs):
                for t in range(max(starts[r], t0 + 1), stops[r]):
                    if core[t] and sqdist_to(xs, t, qx, qy, qz) <= r2:
                        union_lower(out, t0, t)
    keep(i_own)


@njit(cache=True, nogil=True, inline="always")
def _nearest_core(xs, order, core, r2, qx, qy, qz, starts, stops, n_runs):
    """Sorted position of the nearest core point within ``sqrt(r2)`` of
    ``(qx, qy, qz)`` in the ``n_runs`` runs, ties by the lower point index;
    -1 if none. Inlined (arrays)."""
    best, best_d2, best_i = -1, r2, -1
    for r in range(n_runs):
        for t in range(starts[r], stops[r]):
            if not core[t]:
                continue
            d2 = sqdist_to(xs, t, qx, qy, qz)
            if d2 < best_d2 or (d2 == best_d2 and (best < 0 or order[t] < best_i)):
                best, best_d2, best_i = t, d2, order[t]
    return best


@njit(cache=True, nogil=True)
def component_labels(parent, core, nearest, order, labels):
    """Cluster labels by point index into ``labels``: clusters are numbered
    in the order of their lowest point index; points in no cluster get -1.

    ``parent`` is the forest over sorted positions (flattened here),
    ``nearest`` the core position each non-core point is attached to.
    """
    n = len(parent)
    root = np.empty(n, dtype=np.int64)
    for t in range(n):
        if core[t]:
            root[t] = find_root(parent, t)
        elif nearest[t] >= 0:
            root[t] = find_root(parent, nearest[t])
        else:
            root[t] = -1
    number = np.full(n, -1, dtype=np.int64)
    position = np.empty(n, dtype=np.int64)
    for t in range(n):
        position[order[t]] = t
    m = 0
    for i in range(n):
        r = root[position[i]]
        if r < 0:
            labels[i] = -1
            continue
        if number[r] < 0:
            number[r] = m
            m += 1
        labels[i] = number[r]
    return m
