"""numba kernels of the pair features of PFH and FPFH, as PCL 1.13 computes them.

PCL's ``computePairFeatures`` (:func:`pair_features`), the bins of its
features, one pair at a time (:func:`_exact_code`) or without a branch in
SIMD lanes (:func:`_fast_code`), and the lanes' scratch: what the kernels of
the PFH (:mod:`skpcd.features._pfh_kernels`), the FPFH
(:mod:`skpcd.features._fpfh_kernels`) and the improved PFH
(:mod:`skpcd.features._improved_kernels`) share.

Everything that PCL computes in float is computed here in float32, in the
same order: Eigen's SSE dot product of 4-vectors with w = 0 sums
``(x0*y0 + x2*y2) + x1*y1``, and ``acos``/``atan2`` are the C library's
``acosf``/``atan2f``. Bin indices are computed in double as PCL does.
See ``docs/user_guide/local_descriptors.rst`` for the conventions.
"""

import math

import numpy as np
from numba import njit

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
    (:func:`~skpcd.features._pfh_kernels.pfh_rows`,
    :func:`~skpcd.features._fpfh_kernels.spfh_rows`): the gathered lanes,
    a column (position and normal) per point of the largest neighbourhood
    or per lane, and a code and a flag per pair. Inlined."""
    m_max = 1
    for i in range(lo, hi):
        m_max = max(m_max, indptr[i + 1] - indptr[i])
    q_own = np.empty((min(m_max, ROW_MIN), 6, LANES), dtype=np.float32)
    p_own = np.empty((6, max(LANES, m_max)), dtype=np.float32)
    code = np.empty(max(LANES, m_max), dtype=np.int64)
    good = np.empty(max(LANES, m_max), dtype=np.bool_)
    return q_own, p_own, code, good
