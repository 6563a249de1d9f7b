"""numba kernels for normal estimation, following PCL 1.13.0 in float32.

``NormalEstimation`` accumulates the covariance in float with coordinates
shifted by the first neighbour (``computeMeanAndCovarianceMatrix``), finds
the smallest eigenvalue with ``computeRoots`` and its eigenvector as the
longest cross product of two rows of ``A - lambda I`` (``eigen33``), and
flips the normal towards the viewpoint. The same operations in the same
order give normals equal to PCL's to the last bit or close to it, which
matters because PFH's swap rule turns last-bit differences into different
bins. A collinear neighbourhood makes every cross product zero and the
normal NaN, as in PCL 1.13.0.
"""

import math

import numpy as np
from numba import njit

from skpcd.neighbors._grid_kernels import ball, cloud_of
from skpcd.utils._numba import borrow, keep

F0 = np.float32(0.0)
F05 = np.float32(0.5)
F1 = np.float32(1.0)
F2 = np.float32(2.0)
FLT_EPS = np.float32(np.finfo(np.float32).eps)
FLT_MIN = np.float32(np.finfo(np.float32).tiny)
INV3 = np.float32(1.0 / 3.0)
SQRT3 = np.float32(math.sqrt(np.float32(3.0)))


@njit(cache=True, nogil=True)
def _roots2(b, c):
    # PCL computeRoots2: d = b*b - 4.0*c is evaluated in double
    d = np.float32(np.float64(b * b) - 4.0 * np.float64(c))
    if d < 0.0:
        d = F0
    sd = np.float32(math.sqrt(d))
    return F0, F05 * (b - sd), F05 * (b + sd)


@njit(cache=True, nogil=True)
def smallest_root(m00, m01, m02, m11, m12, m22):
    """PCL's ``computeRoots`` (float32): the smallest eigenvalue."""
    c0 = (
        (((m00 * m11) * m22 + ((F2 * m01) * m02) * m12) - (m00 * m12) * m12)
        - (m11 * m02) * m02
    ) - (m22 * m01) * m01
    c1 = ((((m00 * m11 - m01 * m01) + m00 * m22) - m02 * m02) + m11 * m22) - m12 * m12
    c2 = (m00 + m11) + m22
    if abs(c0) < FLT_EPS:
        return _roots2(c2, c1)[0]
    c2_over_3 = c2 * INV3
    a_over_3 = (c1 - c2 * c2_over_3) * INV3
    if a_over_3 > F0:
        a_over_3 = F0
    half_b = F05 * (c0 + c2_over_3 * ((F2 * c2_over_3) * c2_over_3 - c1))
    q = half_b * half_b + (a_over_3 * a_over_3) * a_over_3
    if q > F0:
        q = F0
    rho = np.float32(math.sqrt(-a_over_3))
    theta = np.float32(math.atan2(np.float32(math.sqrt(-q)), half_b)) * INV3
    cos_t = np.float32(math.cos(theta))
    sin_t = np.float32(math.sin(theta))
    r0 = c2_over_3 + (F2 * rho) * cos_t
    r1 = c2_over_3 - rho * (cos_t + SQRT3 * sin_t)
    r2 = c2_over_3 - rho * (cos_t - SQRT3 * sin_t)
    if r0 >= r1:
        r0, r1 = r1, r0
    if r1 >= r2:
        r1, r2 = r2, r1
        if r0 >= r1:
            r0, r1 = r1, r0
    if r0 <= F0:
        return _roots2(c2, c1)[0]
    return r0


@njit(cache=True, nogil=True, error_model="numpy")
def eigen33_smallest(c00, c01, c02, c11, c12, c22):
    """PCL 1.13.0's ``eigen33``: smallest eigenvalue and its eigenvector."""
    scale = max(abs(c00), abs(c01), abs(c02), abs(c11), abs(c12), abs(c22))
    if scale <= FLT_MIN:
        scale = F1
    m00, m01, m02 = c00 / scale, c01 / scale, c02 / scale
    m11, m12, m22 = c11 / scale, c12 / scale, c22 / scale
    lam = smallest_root(m00, m01, m02, m11, m12, m22)
    m00 -= lam
    m11 -= lam
    m22 -= lam
    # rows (m00 m01 m02), (m01 m11 m12), (m02 m12 m22); cross products 01, 02, 12
    ax, ay, az = m01 * m12 - m02 * m11, m02 * m01 - m00 * m12, m00 * m11 - m01 * m01
    bx, by, bz = m01 * m22 - m02 * m12, m02 * m02 - m00 * m22, m00 * m12 - m01 * m02
    cx, cy, cz = m11 * m22 - m12 * m12, m12 * m02 - m01 * m22, m01 * m12 - m11 * m02
    # Eigen's unrolled 3-term reduction sums x + (y + z)
    la = np.float32(math.sqrt(ax * ax + (ay * ay + az * az)))
    lb = np.float32(math.sqrt(bx * bx + (by * by + bz * bz)))
    lc = np.float32(math.sqrt(cx * cx + (cy * cy + cz * cz)))
    # Eigen's maxCoeff keeps the first maximum
    best, vx, vy, vz = la, ax, ay, az
    if lb > best:
        best, vx, vy, vz = lb, bx, by, bz
    if lc > best:
        best, vx, vy, vz = lc, cx, cy, cz
    if best == F0:  # rank 1 (collinear) or rank 0: PCL 1.13.0 divides 0 by 0
        return lam * scale, np.float32(np.nan), np.float32(np.nan), np.float32(np.nan)
    return lam * scale, vx / best, vy / best, vz / best


@njit(cache=True, nogil=True, inline="always")
def add_products(c00, c01, c02, c11, c12, c22, x, y, z):
    """The sums of the products ``xx, xy, xz, yy, yz, zz`` with those of
    ``(x, y, z)`` added, in the type of the arguments: one point's share of
    a covariance. Inlined."""
    return c00 + x * x, c01 + x * y, c02 + x * z, c11 + y * y, c12 + y * z, c22 + z * z


@njit(cache=True, nogil=True)
def normals_rows(
    lo, hi, points, indptr, indices, viewpoints, offsets, normals, curvature
):
    """Normals and curvature of points ``lo`` to ``hi`` from their neighbourhoods.

    ``points`` (in their clouds' local frames) and ``viewpoints`` (one row
    per cloud, in the same frames; cloud ``c`` is ``offsets[c]`` to
    ``offsets[c + 1]``) are float32; rows of ``normals`` (n, 3) and
    ``curvature`` (n,) are filled in place. Fewer than three neighbours give
    NaN normal and curvature (PCL's rule).
    """
    points, indptr, indices, viewpoints, offsets, normals, curvature = borrow(
        points, indptr, indices, viewpoints, offsets, normals, curvature
    )
    c = -1
    for i in range(lo, hi):
        c = cloud_of(offsets, i, c)
        vx, vy, vz = viewpoints[c, 0], viewpoints[c, 1], viewpoints[c, 2]
        _normal_row(points, indptr, indices, vx, vy, vz, normals, curvature, i, i)


@njit(cache=True, nogil=True, inline="always")
def _normal_row(points, indptr, indices, vpx, vpy, vpz, normals, curvature, r, i):
    """Normal and curvature of point ``i`` from CSR row ``r``, flipped to
    face the viewpoint ``(vpx, vpy, vpz)`` (float32). Inlined."""
    start, stop = indptr[r], indptr[r + 1]
    m = stop - start
    if m < 3:
        normals[i, 0] = normals[i, 1] = normals[i, 2] = np.nan
        curvature[i] = np.nan
        return
    k = indices[start]
    kx, ky, kz = points[k, 0], points[k, 1], points[k, 2]
    a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = F0
    for t in range(start, stop):
        j = indices[t]
        x = points[j, 0] - kx
        y = points[j, 1] - ky
        z = points[j, 2] - kz
        a0, a1, a2, a3, a4, a5 = add_products(a0, a1, a2, a3, a4, a5, x, y, z)
        a6 += x
        a7 += y
        a8 += z
    cnt = np.float32(m)
    a0, a1, a2, a3, a4 = a0 / cnt, a1 / cnt, a2 / cnt, a3 / cnt, a4 / cnt
    a5, a6, a7, a8 = a5 / cnt, a6 / cnt, a7 / cnt, a8 / cnt
    c00 = a0 - a6 * a6
    c01 = a1 - a6 * a7
    c02 = a2 - a6 * a8
    c11 = a3 - a7 * a7
    c12 = a4 - a7 * a8
    c22 = a5 - a8 * a8
    lam, nx, ny, nz = eigen33_smallest(c00, c01, c02, c11, c12, c22)
    trace = (c00 + c11) + c22
    curvature[i] = abs(lam / trace) if trace != F0 else F0
    vx = vpx - points[i, 0]
    vy = vpy - points[i, 1]
    vz = vpz - points[i, 2]
    if (vx * nx + vy * ny) + vz * nz < F0:
        nx, ny, nz = -nx, -ny, -nz
    normals[i, 0] = nx
    normals[i, 1] = ny
    normals[i, 2] = nz


@njit(cache=True, nogil=True, inline="always")
def _normal_sink(args, row, i, c, bi, bd, m):
    """The normal of point ``i`` from its sorted ball ``bi[:m]``."""
    points, viewpoints, normals, curvature, ends = args
    bi[0] = i  # the point first, as a stored neighbourhood has it
    ends[1] = m
    vx, vy, vz = viewpoints[c, 0], viewpoints[c, 1], viewpoints[c, 2]
    _normal_row(points, ends, bi, vx, vy, vz, normals, curvature, 0, i)


@njit(cache=True, nogil=True)
def ball_normals(
    lo, hi, base, grid, r2, counts, points, viewpoints, normals, curvature
):
    """Radius neighbourhood sizes and normals of the points of cells ``lo``
    to ``hi``, nothing else stored: each ball is searched on ``grid``
    (:func:`~skpcd.neighbors._grid_kernels.ball_cells_local`, rows by
    sorted position minus ``base``), sorted, and its normal and curvature
    estimated (:func:`normals_rows` on it). ``points`` are float32 in their
    clouds' local frames, ``viewpoints`` one row per cloud in the same
    frames."""
    ends_own = np.zeros(2, dtype=np.int64)
    args = borrow(points, viewpoints, normals, curvature, ends_own)
    none = np.empty(0, dtype=np.int64)
    ball(
        lo, hi, grid, r2, none, counts, none[:0].astype(np.int32),
        none[:0].astype(np.float32), base, True, _normal_sink, args, True,
    )  # fmt: skip
    keep(ends_own)
