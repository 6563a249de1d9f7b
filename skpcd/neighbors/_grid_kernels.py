"""numba kernels for exact neighbour search on a sorted voxel grid.

The points of one or several clouds (packed one after the other) are bucketed
into cubic cells; every cloud has its own origin, cell size and grid shape.
A cell's key is ``(x * ny + y) * nz + z``. Points are sorted by (cloud, key),
so the points of a cell are contiguous, and so are the points of the cells
``z - 1 .. z + 1`` of one ``(x, y)`` column: the 27 cells around a cell are
9 runs of memory. Queries are processed cell by cell, in key order, and each
of the 9 columns is found by a cursor that only moves forward: no hashing,
no random access into a large table (on LiDAR clouds the random lookups of
a hashed grid cost more than the distances themselves).

A k-nearest query scans shells of cells around the query point's cell until
the k-th distance found is no larger than the distance to the space not yet
scanned: the result is exact. A query that needs more than ``max_shell``
shells (an isolated point) is reported back to the caller, which answers it
on a coarser grid. A radius query uses cells at least as wide as the radius
and scans the 27 cells around the point once.

Neighbours come sorted by squared distance (float64, from float64
coordinates), ties by index, the query point itself first.

The kernels take the grid as one argument, a
:class:`~skpcd.neighbors._grid.VoxelGrid` (a NamedTuple of arrays,
which numba passes as a tuple); :mod:`skpcd.neighbors._grid` builds it
and holds the entry points that other packages call.
"""

import math

import numpy as np
from numba import njit

from skpcd.utils._numba import borrow, keep

# Cells per axis stay below this, so a cell key fits in an int64.
MAX_DIM = 1 << 20


@njit(cache=True, nogil=True)
def _coord(x, origin, h, dim):
    c = math.floor((x - origin) / h)
    return min(max(c, 0), dim - 1)


@njit(cache=True, nogil=True)
def _cell_xyz(key, ny, nz):
    """Cell coordinates of ``key = (x * ny + y) * nz + z``."""
    return key // (nz * ny), (key // nz) % ny, key % nz


@njit(cache=True, nogil=True, inline="always")
def sqdist_to(xs, t, qx, qy, qz):
    """Squared distance from row ``t`` of ``xs`` to ``(qx, qy, qz)`` as the
    searches compute it (``ex * ex + ey * ey + ez * ez``, ``e = xs[t] - q``,
    float64 for float64 ``xs``). Inlined (it takes an array)."""
    ex = xs[t, 0] - qx
    ey = xs[t, 1] - qy
    ez = xs[t, 2] - qz
    return ex * ex + ey * ey + ez * ez


@njit(cache=True, nogil=True, inline="always")
def cloud_of(offsets, i, c):
    """The cloud of point ``i`` (cloud ``c`` holds the points ``offsets[c]``
    to ``offsets[c + 1]``): searched forward from ``c``, the cloud of an
    earlier point, or by bisection when ``c`` is negative. Kernels walking
    points ``lo`` to ``hi`` start with ``c = -1``. Inlined (an array)."""
    if c < 0:
        return np.searchsorted(offsets, i, side="right") - 1
    while i >= offsets[c + 1]:
        c += 1
    return c


@njit(cache=True, nogil=True)
def cell_keys(lo, hi, xyz, offsets, origin, h, dims, base, keys):
    """Key of the cell of points ``lo`` to ``hi`` within their cloud, plus
    ``base[c]`` for cloud ``c`` (empty: nothing added), into ``keys``."""
    c = -1
    for i in range(lo, hi):
        c = cloud_of(offsets, i, c)
        ix = _coord(xyz[i, 0], origin[c, 0], h[c], dims[c, 0])
        iy = _coord(xyz[i, 1], origin[c, 1], h[c], dims[c, 1])
        iz = _coord(xyz[i, 2], origin[c, 2], h[c], dims[c, 2])
        keys[i] = (ix * dims[c, 1] + iy) * dims[c, 2] + iz
        if len(base):
            keys[i] += base[c]


@njit(cache=True, nogil=True)
def sorted_cells(sorted_keys, offsets):
    """Cells from the keys of the points sorted by (cloud, key).

    Returns ``(cell_cloud, cell_key, cell_start, cloud_cells)``: each cell's
    cloud and key, the start of its points in the sorted order, and the
    first cell of every cloud (``cloud_cells[-1]`` is the number of cells).
    Sorted by (cloud, key), the points of cloud ``c`` are at the positions
    ``offsets[c]`` to ``offsets[c + 1]``.
    """
    n_clouds = len(offsets) - 1
    m = 0
    for c in range(n_clouds):
        for t in range(offsets[c], offsets[c + 1]):
            if t == offsets[c] or sorted_keys[t] != sorted_keys[t - 1]:
                m += 1
    cell_cloud = np.empty(m, dtype=np.int64)
    cell_key = np.empty(m, dtype=np.int64)
    cell_start = np.empty(m + 1, dtype=np.int64)
    cloud_cells = np.empty(n_clouds + 1, dtype=np.int64)
    m = 0
    for c in range(n_clouds):
        cloud_cells[c] = m
        for t in range(offsets[c], offsets[c + 1]):
            if t == offsets[c] or sorted_keys[t] != sorted_keys[t - 1]:
                cell_cloud[m] = c
                cell_key[m] = sorted_keys[t]
                cell_start[m] = t
                m += 1
    cloud_cells[n_clouds] = m
    cell_start[m] = offsets[n_clouds] if n_clouds else 0
    return cell_cloud, cell_key, cell_start, cloud_cells


@njit(cache=True, nogil=True)
def cells_with(flag, grid):
    """The cells holding at least one point flagged in ``flag``."""
    order, cell_start = grid.order, grid.cell_start
    m = len(cell_start) - 1
    keep = np.zeros(m, dtype=np.bool_)
    for cell in range(m):
        for t in range(cell_start[cell], cell_start[cell + 1]):
            if flag[order[t]]:
                keep[cell] = True
                break
    return np.flatnonzero(keep)


@njit(cache=True, nogil=True)
def _gap(q, origin, h, a):
    """Squared distance from coordinate ``q`` to cell ``a``'s slab, a little
    short (cell coordinates are rounded): 0 inside. Computed from ``q -
    origin`` (exact: the origin is the cloud's minimum), so that the
    rounding scales with the cloud's extent, not with its coordinates."""
    u = q - origin
    g = max(a * h - u, u - (a + 1) * h, 0.0) - 1e-7 * h
    return g * g if g > 0.0 else 0.0


@njit(cache=True, nogil=True, inline="always")
def lower_cell(cell_key, lo, hi, key):
    """First cell in ``[lo, hi)`` whose key is >= ``key``; inlined (arrays)."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if cell_key[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True, inline="always")
def _add_run(cell_key, cell_start, p, c_hi, k_hi, starts, stops, n):
    """Append the points of the cells from ``p`` while their key is at most
    ``k_hi`` to the ``n`` runs in ``starts``/``stops``; returns the new
    count. Inlined (it takes arrays)."""
    e = p
    while e < c_hi and cell_key[e] <= k_hi:
        e += 1
    if e == p:
        return n
    starts[n] = cell_start[p]
    stops[n] = cell_start[e]
    return n + 1


@njit(cache=True, nogil=True, inline="always")
def cell_block(cell, prev, grid, cur, starts, stops):
    """The runs of points of the 27 cells around ``cell`` of ``grid`` (a
    borrowed VoxelGrid, :func:`~skpcd.utils._numba.borrow`), into
    ``starts``/``stops``; returns their number (internal API, also used by
    :mod:`skpcd.segmentation._cluster_kernels`). ``cur`` holds one cursor per
    column, kept when ``cell`` follows ``prev`` in the same cloud (cursors
    then only move forward), otherwise found again by bisection. Inlined."""
    cell_cloud, cell_key, cell_start = grid.cell_cloud, grid.cell_key, grid.cell_start
    cloud_cells, dims = grid.cloud_cells, grid.dims
    c = cell_cloud[cell]
    c_lo, c_hi = cloud_cells[c], cloud_cells[c + 1]
    nx, ny, nz = dims[c, 0], dims[c, 1], dims[c, 2]
    x, y, z = _cell_xyz(cell_key[cell], ny, nz)
    if prev < 0 or cell != prev + 1 or cell_cloud[prev] != c:
        cur[:] = -1  # unknown: found by bisection when first needed
    n = 0
    for r in range(9):
        # the cell's own column first: the nearest points come early, and
        # fewer of the others enter a k-nearest query's sorted buffer
        j = (r + 4) % 9
        xx = x + j // 3 - 1
        yy = y + j % 3 - 1
        if xx < 0 or xx >= nx or yy < 0 or yy >= ny:
            continue
        col = (xx * ny + yy) * nz
        k_lo = col + max(z - 1, 0)
        if cur[j] < 0:
            p = lower_cell(cell_key, c_lo, c_hi, k_lo)
        else:
            p = cur[j]
            while p < c_hi and cell_key[p] < k_lo:
                p += 1
        cur[j] = p
        n = _add_run(
            cell_key, cell_start, p, c_hi, col + min(z + 1, nz - 1), starts, stops, n
        )
    return n


@njit(cache=True, nogil=True, inline="always")
def _insert(bd, bi, count, k, d2, j):
    """Insert (d2, j) into the buffer of the ``count`` best of at most ``k``,
    sorted by (distance, index); returns the new count. Inlined (arrays)."""
    if count < k:
        pos = count
        count += 1
    elif d2 < bd[k - 1] or (d2 == bd[k - 1] and j < bi[k - 1]):
        pos = k - 1
    else:
        return count
    _sift_down(bd, bi, pos, d2, j)
    return count


@njit(cache=True, nogil=True, inline="always")
def _sift_down(bd, bi, pos, d2, j):
    """Put (d2, j) at ``pos`` of the buffer sorted by (distance, index)
    below it, after moving the larger entries up one place: the step of an
    insertion sort. Inlined (arrays)."""
    while pos > 0 and (bd[pos - 1] > d2 or (bd[pos - 1] == d2 and bi[pos - 1] > j)):
        bd[pos] = bd[pos - 1]
        bi[pos] = bi[pos - 1]
        pos -= 1
    bd[pos] = d2
    bi[pos] = j


@njit(cache=True, nogil=True)
def knn_brute(lo, hi, which, cloud, xyz, offsets, indptr, indices, sqdist):
    """k nearest neighbours of the points ``which[lo:hi]`` (of clouds
    ``cloud``) by scanning their whole cloud: for a few isolated points."""
    which, cloud, xyz, offsets, indptr, indices, sqdist = borrow(
        which, cloud, xyz, offsets, indptr, indices, sqdist
    )
    k_max = 1
    for p in range(lo, hi):
        i = which[p]
        k_max = max(k_max, indptr[i + 1] - indptr[i])
    f_own = np.empty(k_max)
    i_own = np.empty(k_max, dtype=np.int64)
    bd, bi = borrow(f_own), borrow(i_own)
    for p in range(lo, hi):
        i = which[p]
        c = cloud[p]
        kc = indptr[i + 1] - indptr[i]
        bd[0] = -1.0
        bi[0] = i
        count = 1
        for j in range(offsets[c], offsets[c + 1]):
            if j != i:
                d2 = sqdist_to(xyz, j, xyz[i, 0], xyz[i, 1], xyz[i, 2])
                if count < kc or d2 <= bd[kc - 1]:
                    count = _insert(bd, bi, count, kc, d2, j)
        _write_row(indices, sqdist, indptr[i], i, bi, bd, kc)
    keep(f_own, i_own)


@njit(cache=True, nogil=True, inline="always")
def _write_row(indices, sqdist, base, i, bi, bd, m):
    """Store a sorted row, the point first at distance 0; inlined (arrays)."""
    indices[base] = i
    for r in range(1, m):
        indices[base + r] = bi[r]
    if len(sqdist):
        sqdist[base] = 0.0
        for r in range(1, m):
            sqdist[base + r] = bd[r]


@njit(cache=True, nogil=True)
def knn_cells(lo, hi, cells, grid, indptr, max_shell, todo, indices, sqdist, hard):
    """k nearest neighbours of the points of the cells ``cells[lo:hi]``.

    ``grid.xs`` holds the points sorted by cell; ``indptr`` gives each
    point's k. With ``todo`` non-empty, only the points flagged
    there are answered. An empty ``sqdist`` is not filled. Rows of points
    that need more than ``max_shell`` shells are flagged in ``hard`` and not
    filled. Arrays are borrowed (:func:`~skpcd.utils._numba.borrow`): the
    inlined helpers that take them cost no atomic reference counting.
    """
    cells, grid, indptr, todo, indices, sqdist, hard = borrow(
        cells, grid, indptr, todo, indices, sqdist, hard
    )
    xs, order, cell_cloud, cell_key, cell_start, cloud_cells, origin, h, dims = grid
    k_max = 1
    for p in range(lo, hi):
        cell = cells[p]
        for t in range(cell_start[cell], cell_start[cell + 1]):
            i = order[t]
            k_max = max(k_max, indptr[i + 1] - indptr[i])
    n_shell = 2 * (2 * max_shell + 1) ** 2
    # scratch: the k best, 9 column cursors, the runs of a block and a shell
    f_own = np.empty(k_max)
    i_own = np.empty(k_max + 27 + 2 * n_shell, dtype=np.int64)
    bd, bi, cur = borrow(f_own, i_own[:k_max], i_own[k_max : k_max + 9])
    block_start, block_stop = borrow(
        i_own[k_max + 9 : k_max + 18], i_own[k_max + 18 : k_max + 27]
    )
    shell_start, shell_stop = borrow(
        i_own[k_max + 27 : k_max + 27 + n_shell], i_own[k_max + 27 + n_shell :]
    )
    # the block's points side by side (x, y, z, sorted position), shared by
    # the queries of a cell: their distances are computed in SIMD lanes
    cap = 64
    g_own = np.empty((4, cap))
    t_own = np.empty(cap, dtype=np.int64)
    blk_x, blk_y, blk_z, blk_d, blk_t = borrow(
        g_own[0], g_own[1], g_own[2], g_own[3], t_own
    )
    prev = -1
    for p in range(lo, hi):
        cell = cells[p]
        n_block = cell_block(cell, prev, grid, cur, block_start, block_stop)
        prev = cell
        n_cand = 0
        for r in range(n_block):
            n_cand += block_stop[r] - block_start[r]
        if n_cand > cap:
            cap = max(n_cand, 2 * cap)
            g_own = np.empty((4, cap))
            t_own = np.empty(cap, dtype=np.int64)
            blk_x, blk_y, blk_z, blk_d, blk_t = borrow(
                g_own[0], g_own[1], g_own[2], g_own[3], t_own
            )
        # the cell's own points first, then the rest of the block (its own
        # column first): the nearest come early, fewer insertions follow
        n_cand = 0
        own_lo, own_hi = cell_start[cell], cell_start[cell + 1]
        for t in range(own_lo, own_hi):
            blk_x[n_cand] = xs[t, 0]
            blk_y[n_cand] = xs[t, 1]
            blk_z[n_cand] = xs[t, 2]
            blk_t[n_cand] = t
            n_cand += 1
        for r in range(n_block):
            for t in range(block_start[r], block_stop[r]):
                if t >= own_lo and t < own_hi:
                    continue
                blk_x[n_cand] = xs[t, 0]
                blk_y[n_cand] = xs[t, 1]
                blk_z[n_cand] = xs[t, 2]
                blk_t[n_cand] = t
                n_cand += 1
        c = cell_cloud[cell]
        c_lo, c_hi = cloud_cells[c], cloud_cells[c + 1]
        nx, ny, nz = dims[c, 0], dims[c, 1], dims[c, 2]
        cx, cy, cz = _cell_xyz(cell_key[cell], ny, nz)
        hc = h[c]
        for t0 in range(cell_start[cell], cell_start[cell + 1]):
            i = order[t0]
            kc = indptr[i + 1] - indptr[i]
            if kc == 0 or (len(todo) and not todo[i]):
                continue
            qx, qy, qz = xs[t0, 0], xs[t0, 1], xs[t0, 2]
            ux, uy, uz = qx - origin[c, 0], qy - origin[c, 1], qz - origin[c, 2]
            bd[0] = -1.0
            bi[0] = i
            count = 1
            s = 1
            # the block: distances in SIMD lanes, then the few insertions
            for u in range(n_cand):
                ex = blk_x[u] - qx
                ey = blk_y[u] - qy
                ez = blk_z[u] - qz
                blk_d[u] = ex * ex + ey * ey + ez * ez
            # the k-th distance so far, in a register (infinite until k)
            worst = np.inf
            for u in range(n_cand):
                d2 = blk_d[u]
                # most candidates fail this test: the call stays rare
                if d2 <= worst and blk_t[u] != t0:
                    count = _insert(bd, bi, count, kc, d2, order[blk_t[u]])
                    if count == kc:
                        worst = bd[kc - 1]
            starts, stops, n_runs = block_start, block_stop, 0
            while True:
                for r in range(n_runs):
                    for t in range(starts[r], stops[r]):
                        d2 = sqdist_to(xs, t, qx, qy, qz)
                        if t != t0 and (count < kc or d2 <= bd[kc - 1]):
                            count = _insert(bd, bi, count, kc, d2, order[t])
                # distance from the query to the space outside the scanned
                # cells, from the query's offset to the cloud's minimum
                # (exact), not from absolute cell edges (rounded to the ulp
                # of the coordinates: 2e-9 at 1e7, more than the margin)
                bound = np.inf
                if cx - s > 0:
                    bound = min(bound, ux - (cx - s) * hc)
                if cx + s < nx - 1:
                    bound = min(bound, (cx + s + 1) * hc - ux)
                if cy - s > 0:
                    bound = min(bound, uy - (cy - s) * hc)
                if cy + s < ny - 1:
                    bound = min(bound, (cy + s + 1) * hc - uy)
                if cz - s > 0:
                    bound = min(bound, uz - (cz - s) * hc)
                if cz + s < nz - 1:
                    bound = min(bound, (cz + s + 1) * hc - uz)
                if bound == np.inf:
                    break  # the whole cloud was scanned
                bound -= 1e-7 * hc  # cell coordinates are rounded
                if count == kc and bound > 0 and bd[kc - 1] <= bound * bound:
                    break
                s += 1
                if s > max_shell:
                    hard[i] = True
                    break
                # the next shell, cells at Chebyshev distance s, by columns:
                # whole columns on its sides, two cells elsewhere; once k
                # points are found, cells farther than the k-th are skipped
                worst = bd[kc - 1] if count == kc else np.inf
                n_runs = 0
                for dx in range(-s, s + 1):
                    xx = cx + dx
                    if xx < 0 or xx >= nx:
                        continue
                    gx = _gap(qx, origin[c, 0], hc, xx)
                    for dy in range(-s, s + 1):
                        yy = cy + dy
                        if yy < 0 or yy >= ny:
                            continue
                        gxy = gx + _gap(qy, origin[c, 1], hc, yy)
                        if gxy > worst:
                            continue
                        col = (xx * ny + yy) * nz
                        side = abs(dx) == s or abs(dy) == s
                        for zz in (cz - s, cz + s):
                            if side:
                                if zz > cz:
                                    break
                                z_lo, z_hi = max(cz - s, 0), min(cz + s, nz - 1)
                                while (
                                    z_lo < cz
                                    and gxy + _gap(qz, origin[c, 2], hc, z_lo) > worst
                                ):
                                    z_lo += 1
                                while (
                                    z_hi > cz
                                    and gxy + _gap(qz, origin[c, 2], hc, z_hi) > worst
                                ):
                                    z_hi -= 1
                            elif zz < 0 or zz >= nz:
                                continue
                            elif gxy + _gap(qz, origin[c, 2], hc, zz) > worst:
                                continue
                            else:
                                z_lo = z_hi = zz
                            q = lower_cell(cell_key, c_lo, c_hi, col + z_lo)
                            n_runs = _add_run(
                                cell_key, cell_start, q, c_hi, col + z_hi,
                                shell_start, shell_stop, n_runs,
                            )  # fmt: skip
                starts, stops = shell_start, shell_stop
            if not hard[i]:
                _write_row(indices, sqdist, indptr[i], i, bi, bd, kc)
    keep(f_own, i_own, g_own, t_own)


@njit(cache=True, nogil=True)
def ball_cells(lo, hi, grid, r2, indptr, counts, indices, sqdist):
    """Radius neighbours of the points of cells ``lo`` to ``hi``.

    With ``indptr`` empty, writes the counts (the point included);
    otherwise fills ``indices`` and ``sqdist`` (unless empty), each row
    sorted by (distance, index), the point first.
    """
    ball(
        lo, hi, grid, r2, indptr, counts, indices, sqdist, -1, True,
        _no_sink, (), False,
    )  # fmt: skip


@njit(cache=True, nogil=True)
def ball_cells_local(lo, hi, base, grid, r2, indptr, counts, indices, sort):
    """:func:`ball_cells` with rows numbered by sorted position: the point
    at position ``t`` of ``grid.order`` is row ``t - base`` of ``counts``
    and of the CSR ``indptr``/``indices`` (no squared distances), so that a
    block of cells gets its own small neighbourhood arrays. With ``indptr``
    empty, only the counts. Rows are sorted only with ``sort``."""
    sqdist = indices[:0].astype(np.float32)
    ball(
        lo, hi, grid, r2, indptr, counts, indices, sqdist, base, sort,
        _no_sink, (), False,
    )  # fmt: skip


@njit(cache=True, nogil=True, inline="always")
def _no_sink(args, row, i, c, bi, bd, m):
    """The sink of the kernels that store the balls: never called."""


@njit(cache=True, nogil=True, inline="always")
def ball(
    lo, hi, grid, r2, indptr, counts, indices, sqdist, base, sort, sink, sink_args,
    with_sink,
):  # fmt: skip
    """The body of :func:`ball_cells` (rows by point, ``base`` < 0) and
    :func:`ball_cells_local` (rows by sorted position minus ``base``).

    With ``with_sink``, nothing is stored: each sorted ball goes to
    ``sink(sink_args, row, i, cloud, bi, bd, m)`` (the point first in
    ``bi[:m]``, squared distances in ``bd``), e.g. a normal estimated from
    it (:func:`~skpcd.preprocessing._normals_kernels.ball_normals`)."""
    fill = len(indptr) > 0 or with_sink
    sort = sort or with_sink
    grid, indptr, counts, indices, sqdist = borrow(
        grid, indptr, counts, indices, sqdist
    )
    xs, order, cell_cloud, cell_start = (
        grid.xs,
        grid.order,
        grid.cell_cloud,
        grid.cell_start,
    )
    # scratch for a ball, grown to the points of the 27 cells when needed
    cap = 64
    f_own = np.empty((2, cap))
    b_own = np.empty((2, cap), dtype=np.int64)
    bd, bi, td, ti = borrow(f_own[0], b_own[0], f_own[1], b_own[1])
    k_own = np.zeros(33, dtype=np.int64)
    scale = 32.0 / r2 if r2 > 0.0 else 0.0
    i_own = np.empty(27, dtype=np.int64)
    nbk, cur, starts, stops = borrow(k_own, i_own[:9], i_own[9:18], i_own[18:])
    for cell in range(lo, hi):
        n_runs = cell_block(
            cell, cell - 1 if cell > lo else -1, grid, cur, starts, stops
        )
        total = 0
        for r in range(n_runs):
            total += stops[r] - starts[r]
        if fill and total > cap:
            cap = max(total, 2 * cap)
            f_own = np.empty((2, cap))
            b_own = np.empty((2, cap), dtype=np.int64)
            bd, bi, td, ti = borrow(f_own[0], b_own[0], f_own[1], b_own[1])
        for t0 in range(cell_start[cell], cell_start[cell + 1]):
            i = order[t0]
            row = i if base < 0 else t0 - base
            qx, qy, qz = xs[t0, 0], xs[t0, 1], xs[t0, 2]
            m = 0
            for r in range(n_runs):
                for t in range(starts[r], stops[r]):
                    d2 = sqdist_to(xs, t, qx, qy, qz)
                    if d2 <= r2:
                        if fill:
                            j = order[t]
                            bi[m] = j
                            bd[m] = -1.0 if j == i else d2
                        m += 1
            if not fill:
                counts[row] = m
                continue
            if not sort:  # the ball as found (pfh_rows_reuse orders pairs itself)
                for r in range(m):
                    indices[indptr[row] + r] = bi[r]
                continue
            # sorted by (distance, index): distances first bucketed (a
            # counting sort over 32 slices of [0, r2]), then an insertion
            # sort, short on nearly sorted data (3-4x faster than a Shell
            # sort on balls of 50-100 points)
            if m > 16:
                nbk[:] = 0
                for a in range(m):
                    nbk[min(max(int(bd[a] * scale), 0), 31) + 1] += 1
                for b in range(32):
                    nbk[b + 1] += nbk[b]
                for a in range(m):
                    b = min(max(int(bd[a] * scale), 0), 31)
                    q = nbk[b]
                    nbk[b] = q + 1
                    td[q] = bd[a]
                    ti[q] = bi[a]
                for a in range(m):
                    bd[a] = td[a]
                    bi[a] = ti[a]
            for a in range(1, m):
                _sift_down(bd, bi, a, bd[a], bi[a])
            if with_sink:
                counts[row] = m
                sink(sink_args, row, i, cell_cloud[cell], bi, bd, m)
                continue
            _write_row(indices, sqdist, indptr[row], i, bi, bd, m)
    keep(f_own, b_own, i_own, k_own)


@njit(cache=True, nogil=True)
def radix_argsort(keys):
    """Stable argsort of non-negative int64 ``keys``, and the sorted keys.

    Least significant digit first, 11 bits a pass, only as many passes as
    the largest key needs (digits that every key shares are skipped):
    several times faster than ``np.argsort`` on the cell keys of a cloud.
    """
    n = len(keys)
    order = np.arange(n)
    out = keys.copy()
    if n < 2:
        return order, out
    top = out.max()
    k2 = np.empty(n, dtype=np.int64)
    o2 = np.empty(n, dtype=np.int64)
    count = np.empty(2049, dtype=np.int64)
    shift = 0
    while shift < 63 and (top >> shift) > 0:
        count[:] = 0
        for t in range(n):
            count[((out[t] >> shift) & 2047) + 1] += 1
        if count.max() < n:
            for b in range(2048):
                count[b + 1] += count[b]
            for t in range(n):
                d = (out[t] >> shift) & 2047
                p = count[d]
                count[d] = p + 1
                k2[p] = out[t]
                o2[p] = order[t]
            out, k2 = k2, out
            order, o2 = o2, order
        shift += 11
    return order, out


@njit(cache=True, nogil=True)
def snake_keys(points, cloud, h, keys):
    """Keys of a snake walk over cubic cells ``h`` wide, into ``keys``.

    Cell ``(x, y, z)`` of point ``i`` (from the minimum of ``points``) in
    cloud ``cloud[i]`` (all 0 if ``cloud`` is empty): ordered by cloud,
    then x, then y up in even x columns and down in odd ones, then z.
    Returns False, keys unset, when they would not fit in an int64 (the
    caller then sorts the coordinates themselves).
    """
    n = len(points)
    if n == 0:
        return True
    lo = np.empty(3)
    hi = np.empty(3)
    for d in range(3):
        lo[d] = hi[d] = points[0, d]
    for i in range(n):
        for d in range(3):
            lo[d] = min(lo[d], points[i, d])
            hi[d] = max(hi[d], points[i, d])
    n_clouds = 1
    for i in range(len(cloud)):
        n_clouds = max(n_clouds, cloud[i] + 1)
    size = float(n_clouds)
    for d in range(3):
        size *= np.floor((hi[d] - lo[d]) / h) + 1.0
    if not size < 2.0**62:
        return False
    dims = np.empty(3, dtype=np.int64)
    for d in range(3):
        dims[d] = math.floor((hi[d] - lo[d]) / h) + 1
    ny, nz = dims[1], dims[2]
    for i in range(n):
        cx = min(math.floor((points[i, 0] - lo[0]) / h), dims[0] - 1)
        cy = min(math.floor((points[i, 1] - lo[1]) / h), ny - 1)
        cz = min(math.floor((points[i, 2] - lo[2]) / h), nz - 1)
        if cx % 2:
            cy = ny - 1 - cy
        c = cloud[i] if len(cloud) else 0
        keys[i] = ((c * dims[0] + cx) * ny + cy) * nz + cz
    return True


@njit(cache=True, nogil=True)
def radix_histogram(keys, lo, hi, shift, hist):
    """Counts of the 11-bit digit ``shift`` of ``keys[lo:hi]``, into
    ``hist`` (2048,): one chunk of a parallel radix pass."""
    hist[:] = 0
    for t in range(lo, hi):
        hist[(keys[t] >> shift) & 2047] += 1


@njit(cache=True, nogil=True)
def radix_scatter(keys, order, lo, hi, shift, offsets, keys_out, order_out):
    """Move ``keys[lo:hi]`` and ``order[lo:hi]`` to their places for the
    digit ``shift``, from ``offsets`` (2048,; advanced in place): one
    chunk of a parallel, stable radix pass."""
    for t in range(lo, hi):
        d = (keys[t] >> shift) & 2047
        q = offsets[d]
        offsets[d] = q + 1
        keys_out[q] = keys[t]
        order_out[q] = order[t]


@njit(cache=True, nogil=True)
def gather_rows(lo, hi, xyz, order, xs):
    """Rows ``lo`` to ``hi`` of ``xs = xyz[order]`` for (n, 3) arrays."""
    for t in range(lo, hi):
        j = order[t]
        xs[t, 0] = xyz[j, 0]
        xs[t, 1] = xyz[j, 1]
        xs[t, 2] = xyz[j, 2]


@njit(cache=True, nogil=True)
def renumber_rows(lo, hi, order, inv, nb, new_indptr, new_indices, new_sqdist):
    """Rows ``lo`` to ``hi`` of neighbourhoods ``nb`` (indptr, indices,
    sqdist) renumbered: new row ``t`` is old row ``order[t]``, every index
    ``j`` in it becomes ``inv[j]``; distances copied when ``new_sqdist``
    is not empty."""
    indptr, indices, sqdist = nb
    for t in range(lo, hi):
        s = indptr[order[t]]
        d = new_indptr[t]
        for r in range(new_indptr[t + 1] - d):
            new_indices[d + r] = inv[indices[s + r]]
        if len(new_sqdist):
            for r in range(new_indptr[t + 1] - d):
                new_sqdist[d + r] = sqdist[s + r]


@njit(cache=True, nogil=True)
def shift_keys(lo, hi, keys, offsets, base):
    """Subtract ``base[c]`` from the keys ``lo`` to ``hi`` of cloud ``c``
    (cloud ``c`` at ``offsets[c]`` to ``offsets[c + 1]``), in place."""
    c = -1
    for i in range(lo, hi):
        c = cloud_of(offsets, i, c)
        keys[i] -= base[c]
