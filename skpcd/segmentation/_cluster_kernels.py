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

from skpcd.neighbors._grid_kernels import cell_block, lower_cell, sqdist_to
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
    return _number(root, order, labels)


# The fine grid of the dense path: cells at most eps / sqrt(3) wide, so the
# points of a cell are all within eps of each other, and the points within
# eps of a cell lie in the 5 x 5 x 5 cells around it (two cells each way).
REACH = 2
_SIDE = 2 * REACH + 1


@njit(cache=True, nogil=True, inline="always")
def _near_cells(cell, prev, grid, forward, cur, starts, stops):
    """The cells within :data:`REACH` of ``cell`` on each axis, as runs of
    cell indices ``starts[r]`` to ``stops[r]`` (one per column of the 5 x 5
    columns around it, the cell itself included); with ``forward`` only the
    cells after ``cell`` in the grid's order. Returns the number of runs.

    ``cur`` holds one cursor per column, kept when ``cell`` follows
    ``prev`` (cursors then only move forward: the first cell of each
    column's run grows with the cell), otherwise found by bisection. A
    single cloud (its grid alone). Inlined (arrays)."""
    cell_key, dims = grid.cell_key, grid.dims
    n_cells = len(cell_key)
    ny, nz = dims[0, 1], dims[0, 2]
    key = cell_key[cell]
    x, y, z = key // (nz * ny), (key // nz) % ny, key % nz
    if prev < 0 or cell != prev + 1:
        cur[:] = -1
    n = 0
    for j in range(_SIDE * _SIDE):
        dx, dy = j // _SIDE - REACH, j % _SIDE - REACH
        if forward and (dx < 0 or (dx == 0 and dy < 0)):
            continue
        xx, yy = x + dx, y + dy
        if xx < 0 or xx >= dims[0, 0] or yy < 0 or yy >= ny:
            continue
        col = (xx * ny + yy) * nz
        z_lo = z + 1 if forward and dx == 0 and dy == 0 else max(z - REACH, 0)
        k_lo, k_hi = col + z_lo, col + min(z + REACH, nz - 1)
        if k_lo > k_hi:
            continue
        if cur[j] < 0:
            p = lower_cell(cell_key, 0, n_cells, k_lo)
        else:
            p = cur[j]
            while p < n_cells and cell_key[p] < k_lo:
                p += 1
        cur[j] = p
        e = p
        while e < n_cells and cell_key[e] <= k_hi:
            e += 1
        if e > p:
            starts[n] = p
            stops[n] = e
            n += 1
    return n


@njit(cache=True, nogil=True)
def _run_scratch():
    """Scratch arrays of :func:`_near_cells`: one cursor per column, and the
    starts and stops of the runs."""
    n = _SIDE * _SIDE
    return (
        np.full(n, -1, dtype=np.int64),
        np.empty(n, dtype=np.int64),
        np.empty(n, dtype=np.int64),
    )


@njit(cache=True, nogil=True)
def fine_core(lo, hi, grid, r2, min_samples, core):
    """Core flags (sorted positions) of the points of cells ``lo`` to
    ``hi`` of a fine grid: a point is core when at least ``min_samples``
    points (itself included) lie within ``sqrt(r2)``. A cell holding that
    many makes all its points core; otherwise a point counts its own
    cell's points, then the other near cells' within the radius, until
    the count is reached. Rows are independent: safe in threads."""
    grid, core = borrow(grid, core)
    xs, cell_start = grid.xs, grid.cell_start
    cur, starts, stops = _run_scratch()
    prev = -1
    for cell in range(lo, hi):
        a, b = cell_start[cell], cell_start[cell + 1]
        if b - a >= min_samples:
            core[a:b] = True
            continue
        n_runs = _near_cells(cell, prev, grid, False, cur, starts, stops)
        prev = cell
        for t0 in range(a, b):
            count = b - a
            qx, qy, qz = xs[t0, 0], xs[t0, 1], xs[t0, 2]
            for r in range(n_runs):
                for t in range(cell_start[starts[r]], cell_start[stops[r]]):
                    if count >= min_samples:
                        break
                    if (t < a or t >= b) and sqdist_to(xs, t, qx, qy, qz) <= r2:
                        count += 1
            core[t0] = count >= min_samples


@njit(cache=True, nogil=True)
def fine_union(lo, hi, grid, core, r2, parent):
    """Link the cells ``lo`` to ``hi`` of a fine grid to the later near
    cells holding a core point within ``sqrt(r2)`` of one of theirs, in the
    forest ``parent`` over cells (lower root kept). The core points of one
    cell are joined already (all within the radius), so a pair of cells is
    tested only while their roots differ, and only until one close pair is
    found. Threads each need a forest of their own (:func:`merge_forest`)."""
    grid, core, parent = borrow(grid, core, parent)
    xs, cell_start = grid.xs, grid.cell_start
    cur, starts, stops = _run_scratch()
    prev = -1
    for cell in range(lo, hi):
        a, b = cell_start[cell], cell_start[cell + 1]
        if not _any_core(core, a, b):
            continue
        n_runs = _near_cells(cell, prev, grid, True, cur, starts, stops)
        prev = cell
        for r in range(n_runs):
            for other in range(starts[r], stops[r]):
                if find_root(parent, cell) == find_root(parent, other):
                    continue
                if _close_pair(
                    xs, core, a, b, cell_start[other], cell_start[other + 1], r2
                ):
                    union_lower(parent, cell, other)


@njit(cache=True, nogil=True, inline="always")
def _any_core(core, a, b):
    for t in range(a, b):
        if core[t]:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _close_pair(xs, core, a, b, c, d, r2):
    """Whether a core point of positions ``a`` to ``b`` lies within
    ``sqrt(r2)`` of a core point of ``c`` to ``d``. Inlined (arrays)."""
    for s in range(a, b):
        if not core[s]:
            continue
        qx, qy, qz = xs[s, 0], xs[s, 1], xs[s, 2]
        for t in range(c, d):
            if core[t] and sqdist_to(xs, t, qx, qy, qz) <= r2:
                return True
    return False


@njit(cache=True, nogil=True)
def fine_border(lo, hi, grid, core, r2, nearest):
    """For every non-core point of cells ``lo`` to ``hi`` of a fine grid,
    the sorted position of its nearest core point within ``sqrt(r2)`` (ties
    by the lower point index) into ``nearest``, or -1. Rows are
    independent: safe in threads."""
    grid, core, nearest = borrow(grid, core, nearest)
    xs, order, cell_start = grid.xs, grid.order, grid.cell_start
    cur, starts, stops = _run_scratch()
    _, p_starts, p_stops = _run_scratch()
    prev = -1
    for cell in range(lo, hi):
        a, b = cell_start[cell], cell_start[cell + 1]
        if _all_core(core, a, b):
            continue
        n_runs = _near_cells(cell, prev, grid, False, cur, starts, stops)
        prev = cell
        for r in range(n_runs):
            p_starts[r] = cell_start[starts[r]]
            p_stops[r] = cell_start[stops[r]]
        for t0 in range(a, b):
            if not core[t0]:
                nearest[t0] = _nearest_core(
                    xs, order, core, r2, xs[t0, 0], xs[t0, 1], xs[t0, 2],
                    p_starts, p_stops, n_runs,
                )  # fmt: skip


@njit(cache=True, nogil=True, inline="always")
def _all_core(core, a, b):
    for t in range(a, b):
        if not core[t]:
            return False
    return True


@njit(cache=True, nogil=True)
def fine_component_labels(parent, cell_start, core, nearest, order, labels):
    """Cluster labels by point index into ``labels`` from the forest
    ``parent`` over the cells of a fine grid: a core point takes its cell's
    component, a non-core point that of its ``nearest`` core point's cell;
    clusters are numbered in the order of their lowest point index, as
    :func:`component_labels` numbers them. Returns their number."""
    n = len(order)
    n_cells = len(cell_start) - 1
    cell_of = np.empty(n, dtype=np.int64)
    for c in range(n_cells):
        cell_of[cell_start[c] : cell_start[c + 1]] = c
    root = np.empty(n, dtype=np.int64)
    for t in range(n):
        if core[t]:
            root[t] = find_root(parent, cell_of[t])
        elif nearest[t] >= 0:
            root[t] = find_root(parent, cell_of[nearest[t]])
        else:
            root[t] = -1
    return _number(root, order, labels)


@njit(cache=True, nogil=True, inline="always")
def _number(root, order, labels):
    """Labels by point index from each sorted position's ``root`` (-1:
    none), numbered in the order of the lowest point index. Inlined."""
    n = len(order)
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
