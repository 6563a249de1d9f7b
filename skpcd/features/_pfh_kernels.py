"""numba kernels for PFH and FPFH, following PCL 1.13 bit for bit.

Everything that PCL computes in float is computed here in float32, in the
same order: Eigen's SSE dot product of 4-vectors with w = 0 sums
``(x0*y0 + x2*y2) + x1*y1``, and ``acos``/``atan2`` are the C library's
``acosf``/``atan2f``. Bin indices are computed in double as PCL does.
See ``docs/user_guide/local_descriptors.rst`` for the conventions.
"""

import math

import numpy as np
from numba import njit, prange

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
    points = np.empty((2, 3), dtype=np.float32)
    normals = np.empty((2, 3), dtype=np.float32)
    for c in range(3):
        points[0, c], points[1, c] = p1[c], p2[c]
        normals[0, c], normals[1, c] = n1[c], n2[c]
    return pair_features_at(points, normals, 0, 1)


@njit(cache=True, nogil=True)
def pair_features_at(points, normals, i, j):
    """:func:`pair_features` of rows ``i`` (first) and ``j`` of the arrays.

    Reads the rows in place: array views in the hot loop would cost an
    atomic reference-count update each, which serialises the threads.
    """
    dx = points[j, 0] - points[i, 0]
    dy = points[j, 1] - points[i, 1]
    dz = points[j, 2] - points[i, 2]
    f4 = np.float32(math.sqrt(_dot(dx, dy, dz, dx, dy, dz)))
    if f4 == F0:
        return F0, F0, F0, F0
    n1x, n1y, n1z = normals[i, 0], normals[i, 1], normals[i, 2]
    n2x, n2y, n2z = normals[j, 0], normals[j, 1], normals[j, 2]
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
        return F0, F0, F0, F0
    vx = vx / v_norm
    vy = vy / v_norm
    vz = vz / v_norm
    # w = u x v
    wx = uy * vz - uz * vy
    wy = uz * vx - ux * vz
    wz = ux * vy - uy * vx
    f2 = _dot(vx, vy, vz, tx, ty, tz)
    f1 = np.float32(
        math.atan2(_dot(wx, wy, wz, tx, ty, tz), _dot(ux, uy, uz, tx, ty, tz))
    )
    return f1, f2, f3, f4


@njit(cache=True, nogil=True)
def _bin_angle(f1, n_bins):
    # floor(nr * ((f1 + M_PI) * d_pi_)) in double; NaN goes to bin 0
    if f1 != f1:
        return 0
    b = math.floor(n_bins * ((np.float64(f1) + math.pi) * D_PI))
    return int(min(max(b, 0.0), n_bins - 1.0))


@njit(cache=True, nogil=True)
def _bin_cosine(f, n_bins):
    # floor(nr * ((f + 1.0) * 0.5)) in double; NaN goes to bin 0
    if f != f:
        return 0
    b = math.floor(n_bins * ((np.float64(f) + 1.0) * 0.5))
    return int(min(max(b, 0.0), n_bins - 1.0))


@njit(cache=True, nogil=True)
def pfh_point(points, normals, neighbors, n_bins, out):
    """PFH of one neighbourhood (point first), accumulated into ``out``."""
    m = len(neighbors)
    n_pairs = (m * (m - 1)) // 2
    if n_pairs == 0:
        return
    incr = F100 / np.float32(n_pairs)
    for a in range(m):
        i = neighbors[a]
        for b in range(a):
            j = neighbors[b]
            f1, f2, f3, _ = pair_features_at(points, normals, i, j)
            h = (
                _bin_angle(f1, n_bins)
                + n_bins * _bin_cosine(f2, n_bins)
                + n_bins * n_bins * _bin_cosine(f3, n_bins)
            )
            out[h] += incr


@njit(cache=True, nogil=True, parallel=True)
def pfh(points, normals, indptr, indices, n_bins):
    """PFH of every point: (n, n_bins**3) float32, PCL's layout (f1 fastest)."""
    n = len(indptr) - 1
    out = np.zeros((n, n_bins**3), dtype=np.float32)
    for i in prange(n):
        pfh_point(points, normals, indices[indptr[i] : indptr[i + 1]], n_bins, out[i])
    return out


@njit(cache=True, nogil=True, parallel=True)
def spfh(points, normals, indptr, indices, n_bins):
    """SPFH of every point: (n, 3 * n_bins) float32, blocks [f1 | f2 | f3]."""
    n = len(indptr) - 1
    out = np.zeros((n, 3 * n_bins), dtype=np.float32)
    for i in prange(n):
        start, stop = indptr[i], indptr[i + 1]
        if stop - start < 2:
            continue
        incr = F100 / np.float32(stop - start - 1)
        for t in range(start, stop):
            j = indices[t]
            if j == i:
                continue
            f1, f2, f3, _ = pair_features_at(points, normals, i, j)
            out[i, _bin_angle(f1, n_bins)] += incr
            out[i, n_bins + _bin_cosine(f2, n_bins)] += incr
            out[i, 2 * n_bins + _bin_cosine(f3, n_bins)] += incr
    return out


@njit(cache=True, nogil=True, parallel=True)
def fpfh_pcl(spfh_hist, indptr, indices, sqdist, n_bins):
    """PCL's FPFH: sum of neighbours' SPFH weighted by 1/squared distance.

    Neighbours at distance 0 (the point itself and duplicates) are left out;
    each block is rescaled to sum to 100 (scale in double, product in float).
    """
    n = len(indptr) - 1
    width = 3 * n_bins
    out = np.zeros((n, width), dtype=np.float32)
    for i in prange(n):
        s1 = s2 = s3 = 0.0
        for t in range(indptr[i], indptr[i + 1]):
            d = sqdist[t]
            if d == F0:
                continue
            weight = np.float32(1.0) / d
            j = indices[t]
            for b in range(width):
                val = spfh_hist[j, b] * weight
                if b < n_bins:
                    s1 += val
                elif b < 2 * n_bins:
                    s2 += val
                else:
                    s3 += val
                out[i, b] += val
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
    return out


@njit(cache=True, nogil=True, parallel=True)
def fpfh_paper(spfh_hist, indptr, indices, sqdist):
    """Rusu et al. (2009): SPFH(p) + (1/k) sum SPFH(q) / ||p - q||.

    k counts the neighbours at a non-zero distance; nothing is rescaled.
    Computed in float64.
    """
    n = len(indptr) - 1
    width = spfh_hist.shape[1]
    out = np.zeros((n, width), dtype=np.float64)
    for i in prange(n):
        k = 0
        for t in range(indptr[i], indptr[i + 1]):
            if sqdist[t] == F0:
                continue
            k += 1
            weight = 1.0 / math.sqrt(np.float64(sqdist[t]))
            j = indices[t]
            for b in range(width):
                out[i, b] += spfh_hist[j, b] * weight
        for b in range(width):
            if k > 0:
                out[i, b] /= k
            out[i, b] += spfh_hist[i, b]
    return out
