"""numba kernels for FPFH, following PCL 1.13 bit for bit.

The SPFH of every point as pair counts per bin (:func:`spfh_rows`, the
pairs binned by :mod:`skpcd.features._pair_kernels`), PCL's float32 sums of
those counts (:func:`increment_sums`, :func:`spfh_values`) and the FPFH,
the neighbours' SPFH weighted (:func:`fpfh_rows`). The conventions are
those of ``docs/user_guide/local_descriptors.rst``.
"""

import math

import numpy as np
from numba import njit

from skpcd.features._pair_kernels import (
    F0,
    F100,
    ROW_MIN,
    _exact_code,
    _fast_bins,
    _fast_code,
    _gather_run,
    _lane_scratch,
    _run_end,
)
from skpcd.utils._numba import borrow, keep


@njit(cache=True, nogil=True, error_model="numpy")
def spfh_rows(lo, hi, points, normals, indptr, indices, n_bins, counts):
    """SPFH of points ``lo`` to ``hi`` as pair counts per bin.

    ``counts`` (n, 3 * n_bins), blocks ``[f1 | f2 | f3]``, zeroed, of an
    unsigned type wide enough for the largest neighbourhood; or, when no
    point has more than 15 pairs, uint8 of shape (n, (3 * n_bins + 1) // 2)
    with two 4-bit counts per byte (bin ``b`` in byte ``b // 2``, the odd
    bins in the high half): half the memory. PCL adds
    ``100 / n_pairs`` once per pair; :func:`spfh_values` turns counts into
    those sums exactly. The point is the first of each pair; neighbours
    with the point's own index are skipped. Pairs run in SIMD lanes as in
    :func:`~skpcd.features._pfh_kernels.pfh_rows`.
    """
    points, normals, indptr, indices, counts = borrow(
        points, normals, indptr, indices, counts
    )
    nb, margin = _fast_bins(n_bins)
    q_own, a_own, code, good = _lane_scratch(indptr, lo, hi)
    Q, A = borrow(q_own, a_own)
    # each code's three columns (bytes, and what to add there), looked up:
    # integer division is slow
    packed = counts.shape[1] < 3 * n_bins
    col = np.empty((n_bins**3, 3), dtype=np.int64)
    inc = np.ones((n_bins**3, 3), dtype=counts.dtype)
    for c in range(n_bins**3):
        col[c, 0] = c % n_bins
        col[c, 1] = n_bins + (c // n_bins) % n_bins
        col[c, 2] = 2 * n_bins + c // (n_bins * n_bins)
        if packed:
            for q in range(3):
                inc[c, q] = 16 if col[c, q] % 2 else 1
                col[c, q] //= 2
    i = lo
    while i < hi:
        m = indptr[i + 1] - indptr[i]
        if m >= ROW_MIN:
            start = indptr[i]
            pix, piy, piz = points[i, 0], points[i, 1], points[i, 2]
            nix, niy, niz = normals[i, 0], normals[i, 1], normals[i, 2]
            for t in range(m):
                j = indices[start + t]
                code[t], good[t] = _fast_code(
                    pix, piy, piz, nix, niy, niz,
                    points[j, 0], points[j, 1], points[j, 2],
                    normals[j, 0], normals[j, 1], normals[j, 2],
                    nb, margin,
                )  # fmt: skip
            for t in range(m):
                j = indices[start + t]
                if j == i:
                    continue
                c = code[t]
                if not good[t]:
                    c = _exact_code(
                        pix, piy, piz, nix, niy, niz,
                        points[j, 0], points[j, 1], points[j, 2],
                        normals[j, 0], normals[j, 1], normals[j, 2],
                        n_bins,
                    )  # fmt: skip
                counts[i, col[c, 0]] += inc[c, 0]
                counts[i, col[c, 1]] += inc[c, 1]
                counts[i, col[c, 2]] += inc[c, 2]
            i += 1
            continue
        e = _run_end(indptr, i, hi)
        _gather_run(points, normals, indptr, indices, i, e - i, m, Q)
        # the points themselves, lane by lane too: strided reads would keep
        # the loop below out of SIMD registers
        for lane in range(e - i):
            for d in range(3):
                A[d, lane] = points[i + lane, d]
                A[3 + d, lane] = normals[i + lane, d]
        for t in range(m):
            for lane in range(e - i):
                code[lane], good[lane] = _fast_code(
                    A[0, lane], A[1, lane], A[2, lane],
                    A[3, lane], A[4, lane], A[5, lane],
                    Q[t, 0, lane], Q[t, 1, lane], Q[t, 2, lane],
                    Q[t, 3, lane], Q[t, 4, lane], Q[t, 5, lane],
                    nb, margin,
                )  # fmt: skip
            for lane in range(e - i):
                k = i + lane
                if indices[indptr[k] + t] == k:
                    continue
                c = code[lane]
                if not good[lane]:
                    c = _exact_code(
                        points[k, 0], points[k, 1], points[k, 2],
                        normals[k, 0], normals[k, 1], normals[k, 2],
                        Q[t, 0, lane], Q[t, 1, lane], Q[t, 2, lane],
                        Q[t, 3, lane], Q[t, 4, lane], Q[t, 5, lane],
                        n_bins,
                    )  # fmt: skip
                counts[k, col[c, 0]] += inc[c, 0]
                counts[k, col[c, 1]] += inc[c, 1]
                counts[k, col[c, 2]] += inc[c, 2]
        i = e
    keep(q_own, a_own)


def increment_sums(max_pairs):
    """``table[p, c]``: ``100 / p`` added ``c`` times in float32, as PCL does.

    Parameters
    ----------
    max_pairs : int
        Largest number of pairs tabulated.

    Returns
    -------
    table : ndarray of shape (max_pairs + 1, max_pairs + 1), float32
    """
    table = np.zeros((max_pairs + 1, max_pairs + 1), dtype=np.float32)
    for p in range(1, max_pairs + 1):
        incr = np.float32(100.0) / np.float32(p)
        # add.accumulate is sequential, in float32: PCL's repeated +=
        table[p, 1 : p + 1] = np.cumsum(np.full(p, incr, dtype=np.float32))
    return table


@njit(cache=True, nogil=True, inline="always")
def _spfh_value(table, n_pairs, c):
    """PCL's float32 sum of ``c`` increments of ``100 / n_pairs``. Inlined:
    a function taking an array costs atomic reference counting per call."""
    if c == 0:
        return F0
    if n_pairs < len(table):
        return table[n_pairs, c]
    incr = F100 / np.float32(n_pairs)
    acc = F0
    for _ in range(c):
        acc += incr
    return acc


@njit(cache=True, nogil=True)
def spfh_values(lo, hi, counts, indptr, table, out):
    """Rows ``lo`` to ``hi`` of the SPFH as PCL's float32 values."""
    counts, indptr, table, out = borrow(counts, indptr, table, out)
    for i in range(lo, hi):
        n_pairs = indptr[i + 1] - indptr[i] - 1
        for b in range(counts.shape[1]):
            out[i, b] = _spfh_value(table, n_pairs, counts[i, b])


@njit(cache=True, nogil=True, inline="always")
def _sqdist32(points, i, j):
    """FLANN's ``L2_Simple`` in float32: ((0 + dx**2) + dy**2) + dz**2.
    Inlined (it takes an array)."""
    dx = points[i, 0] - points[j, 0]
    dy = points[i, 1] - points[j, 1]
    dz = points[i, 2] - points[j, 2]
    return (dx * dx + dy * dy) + dz * dz


@njit(cache=True, nogil=True, inline="always")
def _count(counts, j, b, packed):
    """Bin ``b`` of point ``j``'s pair counts, 4-bit packed or not (see
    :func:`spfh_rows`). Inlined (arrays)."""
    if packed:
        return (np.int64(counts[j, b >> 1]) >> ((b & 1) << 2)) & 15
    return np.int64(counts[j, b])


@njit(cache=True, nogil=True, inline="always")
def _add_bins(out, o, b, n_bins, v1, v2, v3, s1, s2, s3):
    """Add ``v1, v2, v3`` to bin ``b`` of the three blocks of row ``o`` of
    ``out`` and return the blocks' sums ``s1, s2, s3`` with them added
    (:func:`fpfh_rows`). Inlined (an array)."""
    out[o, b] += v1
    out[o, n_bins + b] += v2
    out[o, 2 * n_bins + b] += v3
    return s1 + v1, s2 + v2, s3 + v3


@njit(cache=True, nogil=True)
def fpfh_rows(lo, hi, points, counts, indptr, indices, table, n_bins, mode, rows, out):
    """FPFH of points ``lo`` to ``hi`` into the zeroed rows of ``out``.

    ``mode`` 0, PCL: the neighbours' SPFH weighted by 1/squared distance
    (float32, as FLANN computes it), neighbours at distance 0 (the point and
    its duplicates) left out, each block rescaled to sum to 100 (scale in
    double, product in float). Mode 1, Open3D: the same plus the point's own
    SPFH. Mode 2, Rusu et al. (2009): SPFH(p) + (1/k) sum SPFH(q) / d in
    float64 (``out`` float64), k counting the neighbours at a non-zero
    distance, not rescaled. Point ``i``'s row is ``rows[i]`` (empty: ``i``).
    """
    points, counts, indptr, indices, table, rows, out = borrow(
        points, counts, indptr, indices, table, rows, out
    )
    width = 3 * n_bins
    n_table = len(table)
    # 4-bit counts, two per byte (see spfh_rows), or one count per element
    packed = counts.shape[1] < width
    for i in range(lo, hi):
        o = rows[i] if len(rows) else i
        s1 = s2 = s3 = 0.0
        k = 0
        for t in range(indptr[i], indptr[i + 1]):
            j = indices[t]
            d = _sqdist32(points, i, j)
            if d == F0:
                continue
            k += 1
            n_pairs = indptr[j + 1] - indptr[j] - 1
            if mode == 2:
                w64 = 1.0 / math.sqrt(np.float64(d))
                for b in range(width):
                    out[o, b] += (
                        _spfh_value(table, n_pairs, _count(counts, j, b, packed)) * w64
                    )
                continue
            weight = np.float32(1.0) / d
            if n_pairs < n_table and packed:
                # as below, the counts unpacked on the way
                for b in range(n_bins):
                    b2 = n_bins + b
                    b3 = 2 * n_bins + b
                    c1 = (counts[j, b >> 1] >> ((b & 1) << 2)) & 15
                    c2 = (counts[j, b2 >> 1] >> ((b2 & 1) << 2)) & 15
                    c3 = (counts[j, b3 >> 1] >> ((b3 & 1) << 2)) & 15
                    v1 = table[n_pairs, c1] * weight
                    v2 = table[n_pairs, c2] * weight
                    v3 = table[n_pairs, c3] * weight
                    s1, s2, s3 = _add_bins(out, o, b, n_bins, v1, v2, v3, s1, s2, s3)
                continue
            if n_pairs < n_table:
                # the three blocks side by side: three independent sums, each
                # in PCL's order (neighbour by neighbour, bin by bin), and no
                # branch on the counts (table[p, 0] is 0)
                for b in range(n_bins):
                    v1 = table[n_pairs, counts[j, b]] * weight
                    v2 = table[n_pairs, counts[j, n_bins + b]] * weight
                    v3 = table[n_pairs, counts[j, 2 * n_bins + b]] * weight
                    s1, s2, s3 = _add_bins(out, o, b, n_bins, v1, v2, v3, s1, s2, s3)
                continue
            for b in range(n_bins):
                v1 = _spfh_value(table, n_pairs, _count(counts, j, b, packed)) * weight
                v2 = (
                    _spfh_value(table, n_pairs, _count(counts, j, n_bins + b, packed))
                    * weight
                )
                v3 = (
                    _spfh_value(
                        table, n_pairs, _count(counts, j, 2 * n_bins + b, packed)
                    )
                    * weight
                )
                s1, s2, s3 = _add_bins(out, o, b, n_bins, v1, v2, v3, s1, s2, s3)
        n_own = indptr[i + 1] - indptr[i] - 1
        if mode == 2:
            for b in range(width):
                if k > 0:
                    out[o, b] /= k
                out[o, b] += _spfh_value(table, n_own, _count(counts, i, b, packed))
            continue
        k1 = np.float32(100.0 / s1) if s1 != 0.0 else np.float32(s1)
        k2 = np.float32(100.0 / s2) if s2 != 0.0 else np.float32(s2)
        k3 = np.float32(100.0 / s3) if s3 != 0.0 else np.float32(s3)
        for b in range(n_bins):
            out[o, b] *= k1
            out[o, n_bins + b] *= k2
            out[o, 2 * n_bins + b] *= k3
        if mode == 1:
            for b in range(width):
                out[o, b] += _spfh_value(table, n_own, _count(counts, i, b, packed))
