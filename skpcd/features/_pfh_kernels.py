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
    # v = d x u (Eigen cross3), normalised
    vx = dy * uz - dz * uy
    vy = dz * ux - dx * uz
    vz = dx * uy - dy * ux
    v_norm = np.float32(math.sqrt(_dot(vx, vy, vz, vx, vy, vz)))
    if v_norm == F0:
        return F0, F0, F0, F0, F0
    vx = vx / v_norm
    vy = vy / v_norm
    vz = vz / v_norm
    # w = u x v
    wx = uy * vz - uz * vy
    wy = uz * vx - ux * vz
    wz = ux * vy - uy * vx
    f2 = _dot(vx, vy, vz, tx, ty, tz)
    return _dot(wx, wy, wz, tx, ty, tz), _dot(ux, uy, uz, tx, ty, tz), f2, f3, f4


@njit(cache=True, nogil=True)
def _bin_angle(f1, n_bins):
    # floor(nr * ((f1 + M_PI) * d_pi_)) in double; NaN goes to bin 0
    if f1 != f1:
        return 0
    b = math.floor(n_bins * ((np.float64(f1) + math.pi) * D_PI))
    return int(min(max(b, 0.0), n_bins - 1.0))


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
        z = a * a
        r = a * (
            0.9998660
            + z * (-0.3302995 + z * (0.1801410 + z * (-0.0851330 + z * 0.0208351)))
        )
        if ay > ax:
            r = 0.5 * math.pi - r
        if fx < 0:
            r = math.pi - r
        if fy < 0:
            r = -r
        v = n_bins * ((r + math.pi) * D_PI)
        margin = n_bins * D_PI * 1e-4
        b = math.floor(v)
        if v - b > margin and b + 1.0 - v > margin:
            return int(b)
    return _bin_angle(np.float32(math.atan2(fy, fx)), n_bins)


@njit(cache=True, nogil=True)
def _bin_cosine(f, n_bins):
    # floor(nr * ((f + 1.0) * 0.5)) in double; NaN goes to bin 0
    if f != f:
        return 0
    b = math.floor(n_bins * ((np.float64(f) + 1.0) * 0.5))
    return int(min(max(b, 0.0), n_bins - 1.0))


@njit(cache=True, nogil=True)
def pfh_rows(lo, hi, points, normals, indptr, indices, n_bins, out):
    """PFH of points ``lo`` to ``hi`` into the zeroed rows of ``out``.

    Pairs run as in PCL: for each neighbour ``a`` (the point first), with
    every earlier neighbour ``b``, ``a`` is the first point of the pair.
    Layout ``(n, n_bins**3)``, f1 fastest.
    """
    for i in range(lo, hi):
        start, stop = indptr[i], indptr[i + 1]
        n_pairs = ((stop - start) * (stop - start - 1)) // 2
        if n_pairs == 0:
            continue
        incr = F100 / np.float32(n_pairs)
        for a in range(start, stop):
            ia = indices[a]
            pax, pay, paz = points[ia, 0], points[ia, 1], points[ia, 2]
            nax, nay, naz = normals[ia, 0], normals[ia, 1], normals[ia, 2]
            for b in range(start, a):
                ib = indices[b]
                fy, fx, f2, f3, _ = _pair(
                    pax, pay, paz, nax, nay, naz,
                    points[ib, 0], points[ib, 1], points[ib, 2],
                    normals[ib, 0], normals[ib, 1], normals[ib, 2],
                )  # fmt: skip
                h = (
                    _bin_theta(fy, fx, n_bins)
                    + n_bins * _bin_cosine(f2, n_bins)
                    + n_bins * n_bins * _bin_cosine(f3, n_bins)
                )
                out[i, h] += incr


@njit(cache=True, nogil=True)
def spfh_rows(lo, hi, points, normals, indptr, indices, n_bins, counts):
    """SPFH of points ``lo`` to ``hi`` as pair counts per bin.

    ``counts`` (n, 3 * n_bins), blocks ``[f1 | f2 | f3]``, zeroed, of an
    unsigned type wide enough for the largest neighbourhood. PCL adds
    ``100 / n_pairs`` once per pair; :func:`spfh_values` turns counts into
    those sums exactly. The point is the first of each pair.
    """
    for i in range(lo, hi):
        start, stop = indptr[i], indptr[i + 1]
        pix, piy, piz = points[i, 0], points[i, 1], points[i, 2]
        nix, niy, niz = normals[i, 0], normals[i, 1], normals[i, 2]
        for t in range(start, stop):
            j = indices[t]
            if j == i:
                continue
            fy, fx, f2, f3, _ = _pair(
                pix, piy, piz, nix, niy, niz,
                points[j, 0], points[j, 1], points[j, 2],
                normals[j, 0], normals[j, 1], normals[j, 2],
            )  # fmt: skip
            counts[i, _bin_theta(fy, fx, n_bins)] += 1
            counts[i, n_bins + _bin_cosine(f2, n_bins)] += 1
            counts[i, 2 * n_bins + _bin_cosine(f3, n_bins)] += 1


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


@njit(cache=True, nogil=True)
def _spfh_value(table, n_pairs, c):
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
    for i in range(lo, hi):
        n_pairs = indptr[i + 1] - indptr[i] - 1
        for b in range(counts.shape[1]):
            out[i, b] = _spfh_value(table, n_pairs, counts[i, b])


@njit(cache=True, nogil=True)
def _sqdist32(points, i, j):
    """FLANN's ``L2_Simple`` in float32: ((0 + dx**2) + dy**2) + dz**2."""
    dx = points[i, 0] - points[j, 0]
    dy = points[i, 1] - points[j, 1]
    dz = points[i, 2] - points[j, 2]
    return (dx * dx + dy * dy) + dz * dz


@njit(cache=True, nogil=True)
def fpfh_rows(lo, hi, points, counts, indptr, indices, table, n_bins, mode, out):
    """FPFH of points ``lo`` to ``hi`` into the zeroed rows of ``out``.

    ``mode`` 0, PCL: the neighbours' SPFH weighted by 1/squared distance
    (float32, as FLANN computes it), neighbours at distance 0 (the point and
    its duplicates) left out, each block rescaled to sum to 100 (scale in
    double, product in float). Mode 1, Open3D: the same plus the point's own
    SPFH. Mode 2, Rusu et al. (2009): SPFH(p) + (1/k) sum SPFH(q) / d in
    float64 (``out`` float64), k counting the neighbours at a non-zero
    distance, not rescaled.
    """
    width = 3 * n_bins
    for i in range(lo, hi):
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
                    out[i, b] += _spfh_value(table, n_pairs, counts[j, b]) * w64
                continue
            weight = np.float32(1.0) / d
            for b in range(width):
                val = _spfh_value(table, n_pairs, counts[j, b]) * weight
                if b < n_bins:
                    s1 += val
                elif b < 2 * n_bins:
                    s2 += val
                else:
                    s3 += val
                out[i, b] += val
        n_own = indptr[i + 1] - indptr[i] - 1
        if mode == 2:
            for b in range(width):
                if k > 0:
                    out[i, b] /= k
                out[i, b] += _spfh_value(table, n_own, counts[i, b])
            continue
        k1 = np.float32(100.0 / s1) if s1 != 0.0 else np.float32(s1)
        k2 = np.float32(100.0 / s2) if s2 != 0.0 else np.float32(s2)
        k3 = np.float32(100.0 / s3) if s3 != 0.0 else np.float32(s3)
        for b in range(width):
            if b < n_bins:
                out[i, b] *= k1
            elif b < 2 * n_bins:
                out[i, b] *= k2
            else:
                out[i, b] *= k3
            if mode == 1:
                out[i, b] += _spfh_value(table, n_own, counts[i, b])
