"""numba kernels for PFH and FPFH, following PCL 1.13 bit for bit.

Everything that PCL computes in float is computed here in float32, in the
same order: Eigen's SSE dot product of 4-vectors with w = 0 sums
``(x0*y0 + x2*y2) + x1*y1``, and ``acos``/``atan2`` are the C library's
``acosf``/``atan2f``. Bin indices are computed in double as PCL does.
See ``docs/user_guide/local_descriptors.rst`` for the conventions.
"""

import math

import numpy as np
from numba import njit

from skpcd.utils._numba import borrow, keep

F0 = np.float32(0.0)
F100 = np.float32(100.0)
# PCL's d_pi_ = 1.0f / (2.0f * (float) M_PI), a float used in double arithmetic
D_PI = float(np.float32(1.0) / (np.float32(2.0) * np.float32(np.pi)))
# When |a1| and |a2| differ by more than this, acosf cannot reverse or tie
# their order (its error is below one ulp), so the swap needs no acosf.
_SWAP_MARGIN = np.float32(1e-6)


@njit(cache=True, nogil=True)
def _dot(ax, ay, az, bx, by, bz):
    # Eigen Vector4f::dot with SSE2 and w = 0: (x0*y0 + x2*y2) + (x1*y1 + 0)
    return (ax * bx + az * bz) + ay * by


@njit(cache=True, nogil=True)
def pair_features(p1, n1, p2, n2):
    """PCL's ``computePairFeatures`` in float32: returns (f1, f2, f3, f4).

    ``p1, n1, p2, n2`` are float32 arrays of 3 values. A zero distance or a
    zero ``v`` gives (0, 0, 0, 0), which PCL bins like a regular pair.
    """
    fy, fx, f2, f3, f4 = _pair(
        p1[0], p1[1], p1[2], n1[0], n1[1], n1[2],
        p2[0], p2[1], p2[2], n2[0], n2[1], n2[2],
    )  # fmt: skip
    return np.float32(math.atan2(fy, fx)), f2, f3, f4


@njit(cache=True, nogil=True)
def _pair(p1x, p1y, p1z, n1x, n1y, n1z, p2x, p2y, p2z, n2x, n2y, n2z):
    """:func:`pair_features` on scalars, f1 left as the arguments of its atan2.

    Returns ``(fy, fx, f2, f3, f4)`` with ``f1 = atan2f(fy, fx)``: kernels
    only need f1's bin, which :func:`_bin_theta` finds without ``atan2f``
    almost always. Kernels read the rows and pass scalars: a function taking
    arrays would cost atomic reference-count updates at every call.
    """
    dx = p2x - p1x
    dy = p2y - p1y
    dz = p2z - p1z
    f4 = np.float32(math.sqrt(_dot(dx, dy, dz, dx, dy, dz)))
    if f4 == F0:
        return F0, F0, F0, F0, F0
    a1 = _dot(n1x, n1y, n1z, dx, dy, dz) / f4
    a2 = _dot(n2x, n2y, n2z, dx, dy, dz) / f4
    b1 = abs(a1)
    b2 = abs(a2)
    if b1 + _SWAP_MARGIN < b2:
        swap = True
    elif b1 >= b2 or not (b1 == b1 and b2 == b2):
        # acosf is monotone: no swap for b1 >= b2; NaN compares false in PCL
        swap = False
    else:
        swap = math.acos(b1) > math.acos(b2)
    if swap:
        ux, uy, uz = n2x, n2y, n2z
        tx, ty, tz = n1x, n1y, n1z
        dx, dy, dz = -dx, -dy, -dz
        f3 = -a2
    else:
        ux, uy, uz = n1x, n1y, n1z
        tx, ty, tz = n2x, n2y, n2z
        f3 = a1
    vx, vy, vz = _cross(dx, dy, dz, ux, uy, uz)
    v_norm = np.float32(math.sqrt(_dot(vx, vy, vz, vx, vy, vz)))
    if v_norm == F0:
        return F0, F0, F0, F0, F0
    fy, fx, f2 = _frame_angles(ux, uy, uz, tx, ty, tz, vx, vy, vz, v_norm)
    return fy, fx, f2, f3, f4


@njit(cache=True, nogil=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    """``a x b``, as Eigen's ``cross3``. Inlined."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, nogil=True, inline="always")
def _frame_angles(ux, uy, uz, tx, ty, tz, vx, vy, vz, v_norm):
    """The Darboux frame of a pair and the target normal ``t`` in it: ``u``
    the source normal, ``v = d x u`` (its norm ``v_norm``, not zero)
    normalised, ``w = u x v``. Returns ``(w . t, u . t, v . t)``: the
    arguments of f1's ``atan2f`` and f2. Inlined."""
    vx = vx / v_norm
    vy = vy / v_norm
    vz = vz / v_norm
    wx, wy, wz = _cross(ux, uy, uz, vx, vy, vz)
    return (
        _dot(wx, wy, wz, tx, ty, tz),
        _dot(ux, uy, uz, tx, ty, tz),
        _dot(vx, vy, vz, tx, ty, tz),
    )


@njit(cache=True, nogil=True)
def _bin_angle(f1, n_bins):
    # floor(nr * ((f1 + M_PI) * d_pi_)) in double; NaN goes to bin 0
    if f1 != f1:
        return 0
    b = math.floor(n_bins * ((np.float64(f1) + math.pi) * D_PI))
    return int(min(max(b, 0.0), n_bins - 1.0))


@njit(cache=True, nogil=True, inline="always")
def _atan01(a, z):
    """atan(a) for 0 <= a <= 1 within 1e-5 rad, ``z = a * a``
    (Abramowitz and Stegun 4.4.49)."""
    p = -0.0851330 + z * 0.0208351
    return a * (0.9998660 + z * (-0.3302995 + z * (0.1801410 + z * p)))


@njit(cache=True, nogil=True)
def _bin_theta(fy, fx, n_bins):
    """``_bin_angle(atan2f(fy, fx))``, mostly without calling ``atan2f``.

    A polynomial gives the angle within 1e-5 rad (Abramowitz and Stegun
    4.4.49); only when that puts it within 1e-4 rad of a bin edge, or for
    zeros and NaN, is the exact ``atan2f`` called. The bin is therefore
    always the one PCL computes.
    """
    ax, ay = abs(np.float64(fx)), abs(np.float64(fy))
    big = max(ax, ay)
    if big > 0.0 and big < np.inf and fx == fx and fy == fy:
        a = min(ax, ay) / big
        r = _atan01(a, a * a)
        if ay > ax:
            r = 0.5 * math.pi - r
        if fx < 0:
            r = math.pi - r
        if fy < 0:
            r = -r
        v = n_bins * ((r + math.pi) * D_PI)
        b = math.floor(v)
        margin = _fast_bins(n_bins)[1]
        if v - b > margin and b + 1.0 - v > margin:
            return int(b)
    return _bin_angle(np.float32(math.atan2(fy, fx)), n_bins)


@njit(cache=True, nogil=True, inline="always")
def _fast_bins(n_bins):
    """``n_bins`` as a float, and the margin in bins (1e-4 rad) within which
    :func:`_bin_theta` and :func:`_fast_code` leave f1 to ``atan2f``."""
    nb = np.float64(n_bins)
    return nb, nb * D_PI * 1e-4


@njit(cache=True, nogil=True)
def _bin_cosine(f, n_bins):
    # floor(nr * ((f + 1.0) * 0.5)) in double; NaN goes to bin 0
    if f != f:
        return 0
    b = math.floor(n_bins * ((np.float64(f) + 1.0) * 0.5))
    return int(min(max(b, 0.0), n_bins - 1.0))


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _fast_code(
    pax, pay, paz, nax, nay, naz, pbx, pby, pbz, nbx, nby, nbz, nb, margin
):  # fmt: skip
    """:func:`_pair` and the three bins without a branch, so loops over
    pairs run in SIMD lanes. Returns ``(code, good)``, ``code`` the bin
    ``b1 + nb * (b2 + nb * b3)``; where ``good`` is False (a swap too close
    to call without ``acosf``, f1 near a bin edge, a zero distance or cross
    product, NaN) the caller computes the pair again with :func:`_pair`.
    Where it is True the code is the one :func:`_pair` gives: the same
    float32 operations in the same order."""
    dx = pbx - pax
    dy = pby - pay
    dz = pbz - paz
    f4 = np.float32(math.sqrt(_dot(dx, dy, dz, dx, dy, dz)))
    a1 = _dot(nax, nay, naz, dx, dy, dz) / f4
    a2 = _dot(nbx, nby, nbz, dx, dy, dz) / f4
    b1 = abs(a1)
    b2 = abs(a2)
    swap = b1 + _SWAP_MARGIN < b2
    unsure = (b1 < b2) & (not swap)
    ux = nbx if swap else nax
    uy = nby if swap else nay
    uz = nbz if swap else naz
    tx = nax if swap else nbx
    ty = nay if swap else nby
    tz = naz if swap else nbz
    sx = -dx if swap else dx
    sy = -dy if swap else dy
    sz = -dz if swap else dz
    f3 = -a2 if swap else a1
    vx, vy, vz = _cross(sx, sy, sz, ux, uy, uz)
    v_norm = np.float32(math.sqrt(_dot(vx, vy, vz, vx, vy, vz)))
    fy, fx, f2 = _frame_angles(ux, uy, uz, tx, ty, tz, vx, vy, vz, v_norm)
    # f2, f3 as _bin_cosine; f1 as _bin_theta's polynomial
    g2 = np.floor(nb * ((np.float64(f2) + 1.0) * 0.5))
    g3 = np.floor(nb * ((np.float64(f3) + 1.0) * 0.5))
    ax = abs(np.float64(fx))
    ay = abs(np.float64(fy))
    big = ax if ax > ay else ay
    q = (ay if ax > ay else ax) / big
    r = _atan01(q, q * q)
    r = 0.5 * math.pi - r if ay > ax else r
    r = math.pi - r if fx < 0 else r
    r = -r if fy < 0 else r
    v = nb * ((r + math.pi) * D_PI)
    g1 = np.floor(v)
    good = (
        (f4 > F0)
        & (v_norm > F0)
        & (big > 0.0)
        & (big < np.inf)
        & (v - g1 > margin)
        & (g1 + 1.0 - v > margin)
        & (f2 == f2)
        & (f3 == f3)
        & (not unsure)
    )
    g1 = g1 if good else 0.0
    g2 = min(max(g2, 0.0), nb - 1.0) if g2 == g2 else 0.0
    g3 = min(max(g3, 0.0), nb - 1.0) if g3 == g3 else 0.0
    n = int(nb)
    return int(g1) + n * (int(g2) + n * int(g3)), good


@njit(cache=True, nogil=True, inline="always")
def _exact_code(
    pax, pay, paz, nax, nay, naz, pbx, pby, pbz, nbx, nby, nbz, n_bins
):  # fmt: skip
    """The bin code of a pair through :func:`_pair`, :func:`_bin_theta`."""
    fy, fx, f2, f3, _ = _pair(
        pax, pay, paz, nax, nay, naz, pbx, pby, pbz, nbx, nby, nbz
    )  # fmt: skip
    b2 = _bin_cosine(f2, n_bins)
    return _bin_theta(fy, fx, n_bins) + n_bins * (b2 + n_bins * _bin_cosine(f3, n_bins))


# Neighbourhoods of this many points or more run one point at a time (the
# pairs of a point ``a`` with all earlier points fill the SIMD lanes);
# smaller ones run LANES points of the same size side by side.
ROW_MIN = 24
LANES = 32


@njit(cache=True, nogil=True, inline="always")
def _gather_run(points, normals, indptr, indices, i, n_lanes, m, Q):
    """``Q[t, 0:6, l]``: position and normal of neighbour ``t`` of point
    ``i + l``. Inlined (arrays)."""
    for lane in range(n_lanes):
        start = indptr[i + lane]
        for t in range(m):
            j = indices[start + t]
            for d in range(3):
                Q[t, d, lane] = points[j, d]
                Q[t, 3 + d, lane] = normals[j, d]


@njit(cache=True, nogil=True, inline="always")
def _run_end(indptr, i, hi):
    """End of the run of at most LANES points from ``i`` with ``i``'s size."""
    m = indptr[i + 1] - indptr[i]
    e = i + 1
    while e < hi and e - i < LANES and indptr[e + 1] - indptr[e] == m:
        e += 1
    return e


@njit(cache=True, nogil=True, inline="always")
def _lane_scratch(indptr, lo, hi):
    """The scratch of the pairs in SIMD lanes of rows ``lo`` to ``hi``
    (:func:`pfh_rows`, :func:`spfh_rows`): the gathered lanes, a column
    (position and normal) per point of the largest neighbourhood or per
    lane, and a code and a flag per pair. Inlined."""
    m_max = 1
    for i in range(lo, hi):
        m_max = max(m_max, indptr[i + 1] - indptr[i])
    q_own = np.empty((min(m_max, ROW_MIN), 6, LANES), dtype=np.float32)
    p_own = np.empty((6, max(LANES, m_max)), dtype=np.float32)
    code = np.empty(max(LANES, m_max), dtype=np.int64)
    good = np.empty(max(LANES, m_max), dtype=np.bool_)
    return q_own, p_own, code, good


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
    :func:`pfh_rows`.
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
