"""numba kernels for PFH, following PCL 1.13 bit for bit.

Every pair of a neighbourhood binned into ``n_bins ** 3`` bins
(:func:`pfh_rows`), and the same with the codes of the pairs that
consecutive neighbourhoods share reused (:func:`pfh_rows_reuse`): PCL's
``PFHEstimation``, with the pair features and bins of
:mod:`skpcd.features._pair_kernels` (see
``docs/user_guide/local_descriptors.rst``).
"""

import math

import numpy as np
from numba import njit

from skpcd.features._pair_kernels import (
    _SWAP_MARGIN,
    F0,
    F100,
    ROW_MIN,
    _dot,
    _exact_code,
    _fast_bins,
    _fast_code,
    _gather_run,
    _lane_scratch,
    _run_end,
)
from skpcd.utils._numba import borrow, keep


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _column_codes(P, a, nb, margin, symmetric, code, good):
    """``code[b], good[b]`` (:func:`_fast_code`) of the pairs of column
    ``a`` of ``P`` (position and normal of a point in rows 0-5), first in
    the pair, with the columns ``b < a``: in SIMD lanes. With
    ``symmetric``, ``good`` is also False where the pair's code depends on
    which point comes first (:func:`_symmetric`). Inlined: ``symmetric``
    is a constant at each call."""
    pax, pay, paz = P[0, a], P[1, a], P[2, a]
    nax, nay, naz = P[3, a], P[4, a], P[5, a]
    for b in range(a):
        code[b], good[b] = _fast_code(
            pax, pay, paz, nax, nay, naz,
            P[0, b], P[1, b], P[2, b], P[3, b], P[4, b], P[5, b],
            nb, margin,
        )  # fmt: skip
        if symmetric:
            good[b] &= _symmetric(
                pax, pay, paz, nax, nay, naz,
                P[0, b], P[1, b], P[2, b], P[3, b], P[4, b], P[5, b],
            )  # fmt: skip


@njit(cache=True, nogil=True, error_model="numpy")
def pfh_rows(lo, hi, points, normals, indptr, indices, n_bins, out):
    """PFH of points ``lo`` to ``hi`` into the zeroed rows of ``out``.

    Pairs as in PCL: for each neighbour ``a`` (the point first), with every
    earlier neighbour ``b``, ``a`` is the first point of the pair. Every
    pair adds the same ``100 / n_pairs``, so the order of the additions
    does not change the float32 sums, and pairs run in SIMD lanes
    (:func:`_fast_code`), across the pairs of one point in large
    neighbourhoods and across points in small ones. Layout
    ``(n, n_bins**3)``, f1 fastest.
    """
    points, normals, indptr, indices, out = borrow(
        points, normals, indptr, indices, out
    )
    nb, margin = _fast_bins(n_bins)
    q_own, p_own, code, good = _lane_scratch(indptr, lo, hi)
    Q, P = borrow(q_own, p_own)
    i = lo
    while i < hi:
        m = indptr[i + 1] - indptr[i]
        if m < 2:
            i += 1
            continue
        incr = F100 / np.float32((m * (m - 1)) // 2)
        if m >= ROW_MIN:
            for t in range(m):
                j = indices[indptr[i] + t]
                for d in range(3):
                    P[d, t] = points[j, d]
                    P[3 + d, t] = normals[j, d]
            for a in range(1, m):
                _column_codes(P, a, nb, margin, False, code, good)
                for b in range(a):
                    c = code[b]
                    if not good[b]:
                        c = _exact_code(
                            P[0, a], P[1, a], P[2, a], P[3, a], P[4, a], P[5, a],
                            P[0, b], P[1, b], P[2, b], P[3, b], P[4, b], P[5, b],
                            n_bins,
                        )  # fmt: skip
                    out[i, c] += incr
            i += 1
            continue
        e = _run_end(indptr, i, hi)
        _gather_run(points, normals, indptr, indices, i, e - i, m, Q)
        for a in range(1, m):
            for b in range(a):
                for lane in range(e - i):
                    code[lane], good[lane] = _fast_code(
                        Q[a, 0, lane], Q[a, 1, lane], Q[a, 2, lane],
                        Q[a, 3, lane], Q[a, 4, lane], Q[a, 5, lane],
                        Q[b, 0, lane], Q[b, 1, lane], Q[b, 2, lane],
                        Q[b, 3, lane], Q[b, 4, lane], Q[b, 5, lane],
                        nb, margin,
                    )  # fmt: skip
                for lane in range(e - i):
                    c = code[lane]
                    if not good[lane]:
                        c = _exact_code(
                            Q[a, 0, lane], Q[a, 1, lane], Q[a, 2, lane],
                            Q[a, 3, lane], Q[a, 4, lane], Q[a, 5, lane],
                            Q[b, 0, lane], Q[b, 1, lane], Q[b, 2, lane],
                            Q[b, 3, lane], Q[b, 4, lane], Q[b, 5, lane],
                            n_bins,
                        )  # fmt: skip
                    out[i + lane, c] += incr
        i = e
    keep(q_own, p_own)


@njit(cache=True, nogil=True, inline="always")
def _symmetric(pax, pay, paz, nax, nay, naz, pbx, pby, pbz, nbx, nby, nbz):
    """Whether a pair's features do not depend on which point comes first.

    With (a, b) swapped, d changes sign exactly, so |a1| and |a2| trade
    places exactly; when they differ by more than ``_SWAP_MARGIN`` both
    orders pick the same source point and compute the same float32 values.
    Ties, near-ties, zero distances and NaN return False. Inlined."""
    dx = pbx - pax
    dy = pby - pay
    dz = pbz - paz
    f4 = np.float32(math.sqrt(_dot(dx, dy, dz, dx, dy, dz)))
    b1 = abs(_dot(nax, nay, naz, dx, dy, dz) / f4)
    b2 = abs(_dot(nbx, nby, nbz, dx, dy, dz) / f4)
    return (f4 > F0) & ((b1 + _SWAP_MARGIN < b2) | (b2 + _SWAP_MARGIN < b1))


@njit(cache=True, nogil=True, inline="always")
def _ordered_code(points, normals, indices, start, perm, u, v, n_bins, xs, inv, i):
    """:func:`_exact_code` of the pair at positions ``u`` and ``v`` of
    :func:`pfh_rows_reuse`'s order, the entry later in the neighbourhood
    first, as PCL. With ``inv`` non-empty the neighbourhood is not sorted:
    "later" is then the larger (squared distance to point ``i``, index),
    the distance computed as the search computes it (float64 ``xs``, the
    points in grid order, point ``j`` at row ``inv[j]``; the point itself
    first). Inlined (arrays)."""
    a, b = perm[u], perm[v]
    ja = indices[start + a]
    jb = indices[start + b]
    if len(inv):
        if _after(xs, inv, i, jb, ja):
            ja, jb = jb, ja
    elif a < b:
        ja, jb = jb, ja
    return _exact_code(
        points[ja, 0], points[ja, 1], points[ja, 2],
        normals[ja, 0], normals[ja, 1], normals[ja, 2],
        points[jb, 0], points[jb, 1], points[jb, 2],
        normals[jb, 0], normals[jb, 1], normals[jb, 2],
        n_bins,
    )  # fmt: skip


@njit(cache=True, nogil=True, inline="always")
def _after(xs, inv, i, ja, jb):
    """Whether point ``ja`` comes after ``jb`` in point ``i``'s sorted
    neighbourhood (see :func:`_ordered_code`). Inlined (arrays)."""
    if ja == i:
        return False
    if jb == i:
        return True
    q = inv[i]
    ta, tb = inv[ja], inv[jb]
    ex = xs[ta, 0] - xs[q, 0]
    ey = xs[ta, 1] - xs[q, 1]
    ez = xs[ta, 2] - xs[q, 2]
    da = ex * ex + ey * ey + ez * ez
    ex = xs[tb, 0] - xs[q, 0]
    ey = xs[tb, 1] - xs[q, 1]
    ez = xs[tb, 2] - xs[q, 2]
    db = ex * ex + ey * ey + ez * ez
    return da > db or (da == db and ja > jb)


@njit(cache=True, nogil=True, error_model="numpy")
def pfh_rows_reuse(
    lo, hi, rows, point_of, pos, xs, inv, points, normals, indptr, indices, n_bins,
    out,
):  # fmt: skip
    """PFH of the rows ``rows[lo:hi]``, reusing pair codes between queries.

    The same as :func:`pfh_rows` (every row bit-identical), for large
    neighbourhoods (radius searches) visited in a spatially coherent order
    (``rows``): consecutive neighbourhoods share most of their points, and a
    pair (a, b) gets the same bin in every neighbourhood that holds both,
    unless its bin depends on which point comes first (:func:`_symmetric`
    is False; PCL takes the point farther from the query first). The codes
    of a neighbourhood's pairs are kept in a matrix; the next neighbourhood
    looks up its pairs of points already seen there and computes only the
    pairs with a new point (in SIMD lanes, as :func:`pfh_rows`) and the
    order-dependent ones (with the scalar path, in PCL's order).

    Row ``r`` of the CSR ``indptr``/``indices`` is the neighbourhood of
    point ``point_of[r]`` (of point ``r`` if ``point_of`` is empty), whose
    PFH goes to that row of ``out``. ``pos`` (one int32 per point, all -1)
    is scratch, all -1 again on return. With ``inv`` non-empty, the
    neighbourhoods need not be sorted (see :func:`_ordered_code`).
    """
    if hi <= lo:
        return
    rows, point_of, pos, xs, inv = borrow(rows, point_of, pos, xs, inv)
    points, normals, indptr, indices, out = borrow(
        points, normals, indptr, indices, out
    )
    nb, margin = _fast_bins(n_bins)
    m_max = 1
    for r in range(lo, hi):
        li = rows[r]
        m_max = max(m_max, indptr[li + 1] - indptr[li])
    c_own = np.empty((2, m_max, m_max), dtype=np.int16)
    i_own = np.empty((5, m_max), dtype=np.int64)
    # the previous neighbourhood's points; the new order (position u holds
    # entry perm[u]); entry u's position in the previous matrix
    prev_pts, perm, old, code = borrow(i_own[0], i_own[1], i_own[2], i_own[3])
    good_own = np.empty(m_max, dtype=np.bool_)
    p_own = np.empty((6, m_max), dtype=np.float32)
    good, P = borrow(good_own, p_own)
    n_prev = 0
    cur = 0
    for r in range(lo, hi):
        li = rows[r]
        i = point_of[li] if len(point_of) else li
        start = indptr[li]
        m = indptr[li + 1] - start
        if m < 2:
            continue
        incr = F100 / np.float32((m * (m - 1)) // 2)
        Cp = borrow(c_own[1 - cur])
        Cc = borrow(c_own[cur])
        # points seen in the previous neighbourhood first, then the new ones
        n_old = 0
        for t in range(m):
            if pos[indices[start + t]] >= 0:
                perm[n_old] = t
                n_old += 1
        u = n_old
        for t in range(m):
            if pos[indices[start + t]] < 0:
                perm[u] = t
                u += 1
        for u in range(m):
            j = indices[start + perm[u]]
            old[u] = pos[j]
            for d in range(3):
                P[d, u] = points[j, d]
                P[3 + d, u] = normals[j, d]
        # pairs of two old points: the previous matrix, where usable
        for u in range(1, n_old):
            ou = old[u]
            for v in range(u):
                ov = old[v]
                c = Cp[max(ou, ov), min(ou, ov)]
                Cc[u, v] = c
                if c < 0:
                    c = _ordered_code(
                        points, normals, indices, start, perm, u, v, n_bins, xs, inv, i
                    )
                out[i, c] += incr
        # pairs with a new point: in SIMD lanes
        for u in range(max(n_old, 1), m):
            _column_codes(P, u, nb, margin, True, code, good)
            for v in range(u):
                if good[v]:
                    c = code[v]
                    Cc[u, v] = c
                else:
                    Cc[u, v] = -1
                    c = _ordered_code(
                        points, normals, indices, start, perm, u, v, n_bins, xs, inv, i
                    )
                out[i, c] += incr
        # this neighbourhood's positions, for the next one
        for t in range(n_prev):
            pos[prev_pts[t]] = -1
        for u in range(m):
            j = indices[start + perm[u]]
            pos[j] = u
            prev_pts[u] = j
        n_prev = m
        cur = 1 - cur
    for t in range(n_prev):
        pos[prev_pts[t]] = -1
    keep(c_own, i_own, good_own, p_own)
