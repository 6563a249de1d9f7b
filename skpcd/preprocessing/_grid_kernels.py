"""numba kernels for exact neighbour search on a hashed voxel grid.

The points of one or several clouds (packed one after the other) are bucketed
into cubic cells; every cloud has its own origin, cell size and grid shape,
and the cells of all clouds share one open-addressing hash table, so that
neighbours never cross clouds. Points are counting-sorted by cell, so the
points of a cell are contiguous and a query scans few, short runs of memory.

A k-nearest query scans shells of cells around the query point's cell until
the k-th distance found is no larger than the distance to the space not yet
scanned: the result is exact. A query that needs more than ``max_shell``
shells (an isolated point) is reported back to the caller, which answers it
with a k-d tree. A radius query uses cells at least as wide as the radius and
scans the 27 cells around the point once.

Neighbours come sorted by squared distance (float64, from float64
coordinates), ties by index, the query point itself first.
"""

import math

import numpy as np
from numba import njit

_MUL1 = np.uint64(0x9E3779B97F4A7C15)
_MUL2 = np.uint64(0xC2B2AE3D27D4EB4F)
_SHIFT = np.uint64(29)
# Cells per axis stay below this, so a cell key fits in an int64.
MAX_DIM = 1 << 20


@njit(cache=True, nogil=True)
def _slot(cloud, key, mask):
    h = (np.uint64(key) * _MUL1) ^ (np.uint64(cloud) * _MUL2)
    h ^= h >> _SHIFT
    return np.int64(h & mask)


@njit(cache=True, nogil=True)
def _coord(x, origin, h, dim):
    c = math.floor((x - origin) / h)
    return min(max(c, 0), dim - 1)


@njit(cache=True, nogil=True, inline="always")
def _find(table, cell_cloud, cell_key, cloud, key, mask):
    """Cell number of (cloud, key), or -1; inlined (it takes arrays)."""
    s = _slot(cloud, key, np.uint64(mask))
    while True:
        cell = table[s]
        if cell < 0 or (cell_key[cell] == key and cell_cloud[cell] == cloud):
            return cell
        s = (s + 1) & mask


@njit(cache=True, nogil=True)
def build_grid(xyz, cloud_ptr, origin, h, dims):
    """Bucket the points into cells.

    Returns ``(table, cell_cloud, cell_key, cell_start, order, n_cells_of)``:
    the hash table of cell numbers, each cell's cloud and key, the start of
    each cell's points in ``order`` (points sorted by cell, in index order
    within a cell) and the number of cells of every cloud.
    """
    n = len(xyz)
    size = 2
    while size < 2 * n:
        size *= 2
    table = np.full(size, -1, dtype=np.int64)
    mask = np.uint64(size - 1)
    cell_cloud = np.empty(n, dtype=np.int64)
    cell_key = np.empty(n, dtype=np.int64)
    counts = np.zeros(n + 1, dtype=np.int64)
    cell_of = np.empty(n, dtype=np.int64)
    n_cells_of = np.zeros(len(cloud_ptr) - 1, dtype=np.int64)
    m = 0
    for c in range(len(cloud_ptr) - 1):
        for i in range(cloud_ptr[c], cloud_ptr[c + 1]):
            ix = _coord(xyz[i, 0], origin[c, 0], h[c], dims[c, 0])
            iy = _coord(xyz[i, 1], origin[c, 1], h[c], dims[c, 1])
            iz = _coord(xyz[i, 2], origin[c, 2], h[c], dims[c, 2])
            key = (ix * dims[c, 1] + iy) * dims[c, 2] + iz
            s = _slot(c, key, mask)
            while True:
                cell = table[s]
                if cell < 0:
                    cell = m
                    table[s] = m
                    cell_cloud[m] = c
                    cell_key[m] = key
                    n_cells_of[c] += 1
                    m += 1
                    break
                if cell_key[cell] == key and cell_cloud[cell] == c:
                    break
                s = (s + 1) & (size - 1)
            cell_of[i] = cell
            counts[cell + 1] += 1
    cell_start = np.cumsum(counts[: m + 1])
    fill = cell_start[:m].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        cell = cell_of[i]
        order[fill[cell]] = i
        fill[cell] += 1
    cell_cloud = cell_cloud[:m].copy()
    cell_key = cell_key[:m].copy()
    return table, cell_cloud, cell_key, cell_start, order, n_cells_of


@njit(cache=True, nogil=True, inline="always")
def _add_cell(
    table, cell_cloud, cell_key, cell_start, cloud, key, mask, starts, stops, n
):
    """Append the point range of cell (cloud, key), if it exists, to the
    ``n`` ranges in ``starts``/``stops``; returns the new count. Inlined."""
    cell = _find(table, cell_cloud, cell_key, cloud, key, mask)
    if cell < 0:
        return n
    starts[n] = cell_start[cell]
    stops[n] = cell_start[cell + 1]
    return n + 1


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
def knn_rows(
    lo, hi, queries, xyz, xs, cloud_ptr, origin, h, dims, table, cell_cloud,
    cell_key, cell_start, order, indptr, max_shell, indices, sqdist, hard,
):  # fmt: skip
    """k nearest neighbours of the points ``queries[lo:hi]``.

    ``xs`` holds the points sorted by cell (``xyz[order]``); ``indptr``
    gives each point's k. An empty ``sqdist`` is not filled. Rows of points
    that need more than ``max_shell`` shells are flagged in ``hard`` and not
    filled. Everything runs inline here: a helper taking arrays would cost
    atomic reference-count updates per call.
    """
    mask = len(table) - 1
    k_max = 1
    for p in range(lo, hi):
        i = queries[p]
        k_max = max(k_max, indptr[i + 1] - indptr[i])
    bd = np.empty(k_max)
    bi = np.empty(k_max, dtype=np.int64)
    q = np.empty(3)
    cc = np.empty(3, dtype=np.int64)
    # the 27 cells around the previous query's cell: queries come in cell
    # order, so the few points of a cell share these lookups
    block_start = np.empty(27, dtype=np.int64)
    block_stop = np.empty(27, dtype=np.int64)
    n_block = 0
    block_of = np.full(4, -1, dtype=np.int64)
    n_shell = (2 * max_shell + 1) ** 3
    shell_start = np.empty(n_shell, dtype=np.int64)
    shell_stop = np.empty(n_shell, dtype=np.int64)
    for p in range(lo, hi):
        i = queries[p]
        kc = indptr[i + 1] - indptr[i]
        if kc == 0:
            continue
        c = np.searchsorted(cloud_ptr, i, side="right") - 1
        hc = h[c]
        for a in range(3):
            q[a] = xyz[i, a]
            cc[a] = _coord(q[a], origin[c, a], hc, dims[c, a])
        if (
            c != block_of[0]
            or cc[0] != block_of[1]
            or cc[1] != block_of[2]
            or cc[2] != block_of[3]
        ):
            block_of[0], block_of[1], block_of[2], block_of[3] = c, cc[0], cc[1], cc[2]
            n_block = 0
            for x in range(max(cc[0] - 1, 0), min(cc[0] + 2, dims[c, 0])):
                for y in range(max(cc[1] - 1, 0), min(cc[1] + 2, dims[c, 1])):
                    for z in range(max(cc[2] - 1, 0), min(cc[2] + 2, dims[c, 2])):
                        key = (x * dims[c, 1] + y) * dims[c, 2] + z
                        n_block = _add_cell(
                            table, cell_cloud, cell_key, cell_start, c, key, mask,
                            block_start, block_stop, n_block,
                        )  # fmt: skip
        bd[0] = -1.0
        bi[0] = i
        count = 1
        s = 1
        starts, stops, n_ranges = block_start, block_stop, n_block
        while True:
            for r in range(n_ranges):
                for t in range(starts[r], stops[r]):
                    j = order[t]
                    if j == i:
                        continue
                    ex = xs[t, 0] - q[0]
                    ey = xs[t, 1] - q[1]
                    ez = xs[t, 2] - q[2]
                    d2 = ex * ex + ey * ey + ez * ez
                    # insertion into the sorted buffer of the k best
                    if count < kc:
                        pos = count
                        count += 1
                    elif d2 < bd[kc - 1] or (d2 == bd[kc - 1] and j < bi[kc - 1]):
                        pos = kc - 1
                    else:
                        continue
                    while pos > 0 and (
                        bd[pos - 1] > d2 or (bd[pos - 1] == d2 and bi[pos - 1] > j)
                    ):
                        bd[pos] = bd[pos - 1]
                        bi[pos] = bi[pos - 1]
                        pos -= 1
                    bd[pos] = d2
                    bi[pos] = j
            # distance from q to the space outside the scanned block
            bound = np.inf
            for a in range(3):
                if cc[a] - s > 0:
                    bound = min(bound, q[a] - (origin[c, a] + (cc[a] - s) * hc))
                if cc[a] + s < dims[c, a] - 1:
                    bound = min(bound, origin[c, a] + (cc[a] + s + 1) * hc - q[a])
            if bound == np.inf:
                break  # the whole cloud was scanned
            bound -= 1e-7 * hc  # cell coordinates are rounded
            if count == kc and bound > 0 and bd[kc - 1] <= bound * bound:
                break
            s += 1
            if s > max_shell:
                hard[i] = True
                break
            # the next shell: cells at Chebyshev distance s
            n_ranges = 0
            for dx in range(-s, s + 1):
                x = cc[0] + dx
                if x < 0 or x >= dims[c, 0]:
                    continue
                for dy in range(-s, s + 1):
                    y = cc[1] + dy
                    if y < 0 or y >= dims[c, 1]:
                        continue
                    step = 1 if abs(dx) == s or abs(dy) == s else 2 * s
                    for dz in range(-s, s + 1, step):
                        z = cc[2] + dz
                        if z < 0 or z >= dims[c, 2]:
                            continue
                        key = (x * dims[c, 1] + y) * dims[c, 2] + z
                        n_ranges = _add_cell(
                            table, cell_cloud, cell_key, cell_start, c, key, mask,
                            shell_start, shell_stop, n_ranges,
                        )  # fmt: skip
            starts, stops = shell_start, shell_stop
        if not hard[i]:
            _write_row(indices, sqdist, indptr[i], i, bi, bd, kc)


@njit(cache=True, nogil=True)
def ball_rows(
    lo, hi, xs, cloud_ptr, origin, h, dims, table, cell_cloud, cell_key,
    cell_start, order, r2, indptr, counts, indices, sqdist,
):  # fmt: skip
    """Radius neighbours of the points ``order[lo:hi]``.

    With ``indptr`` empty, writes the counts (the point included);
    otherwise fills ``indices`` and ``sqdist`` (unless empty), each row
    sorted by (distance, index), the point first.
    """
    mask = len(table) - 1
    fill = len(indptr) > 0
    k_max = 1
    if fill:
        for p in range(lo, hi):
            i = order[p]
            k_max = max(k_max, indptr[i + 1] - indptr[i])
    bd = np.empty(k_max)
    bi = np.empty(k_max, dtype=np.int64)
    for p in range(lo, hi):
        i = order[p]
        c = np.searchsorted(cloud_ptr, i, side="right") - 1
        hc = h[c]
        qx, qy, qz = xs[p, 0], xs[p, 1], xs[p, 2]
        cx = _coord(qx, origin[c, 0], hc, dims[c, 0])
        cy = _coord(qy, origin[c, 1], hc, dims[c, 1])
        cz = _coord(qz, origin[c, 2], hc, dims[c, 2])
        m = 0
        for x in range(max(cx - 1, 0), min(cx + 2, dims[c, 0])):
            for y in range(max(cy - 1, 0), min(cy + 2, dims[c, 1])):
                for z in range(max(cz - 1, 0), min(cz + 2, dims[c, 2])):
                    key = (x * dims[c, 1] + y) * dims[c, 2] + z
                    cell = _find(table, cell_cloud, cell_key, c, key, mask)
                    if cell < 0:
                        continue
                    for t in range(cell_start[cell], cell_start[cell + 1]):
                        ex = xs[t, 0] - qx
                        ey = xs[t, 1] - qy
                        ez = xs[t, 2] - qz
                        d2 = ex * ex + ey * ey + ez * ez
                        if d2 <= r2:
                            if fill:
                                j = order[t]
                                bi[m] = j
                                bd[m] = -1.0 if j == i else d2
                            m += 1
        if not fill:
            counts[i] = m
            continue
        # Shell sort by (distance, index), Ciura's gaps: no allocation
        for gap in (701, 301, 132, 57, 23, 10, 4, 1):
            for a in range(gap, m):
                d, j = bd[a], bi[a]
                b = a
                while b >= gap and (
                    bd[b - gap] > d or (bd[b - gap] == d and bi[b - gap] > j)
                ):
                    bd[b] = bd[b - gap]
                    bi[b] = bi[b - gap]
                    b -= gap
                bd[b] = d
                bi[b] = j
        _write_row(indices, sqdist, indptr[i], i, bi, bd, m)
