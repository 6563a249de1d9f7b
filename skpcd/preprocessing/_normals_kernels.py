"""numba kernels for normal estimation (PCA of each neighbourhood)."""

import math

import numpy as np
from numba import njit, prange

# Below this squared norm (of a cross product of rows of the scaled,
# shifted covariance) the smallest eigenvector is undefined: the
# neighbourhood is collinear or its points coincide.
_DEGENERATE = 1e-24


@njit(cache=True, nogil=True)
def smallest_eigenpair(a00, a01, a02, a11, a12, a22):
    """Smallest eigenvalue and its unit eigenvector of a symmetric 3x3 matrix.

    Eigenvalues by the trigonometric method, the eigenvector by the largest
    cross product of two rows of ``A - lambda_min I`` (as PCL's ``eigen33``).
    Returns NaN components when the eigenvector is undefined.
    """
    scale = max(abs(a00), abs(a01), abs(a02), abs(a11), abs(a12), abs(a22))
    nan = np.nan
    if scale == 0.0:
        return 0.0, 0.0, 0.0, nan, nan, nan
    a00 /= scale
    a01 /= scale
    a02 /= scale
    a11 /= scale
    a12 /= scale
    a22 /= scale
    q = (a00 + a11 + a22) / 3.0
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    if p2 <= 0.0:  # isotropic: every direction is an eigenvector
        return q * scale, q * scale, q * scale, nan, nan, nan
    p = math.sqrt(p2 / 6.0)
    det = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    )
    r = det / (2.0 * p * p * p)
    r = min(1.0, max(-1.0, r))
    phi = math.acos(r) / 3.0
    lam_max = q + 2.0 * p * math.cos(phi)
    lam_min = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    lam_mid = 3.0 * q - lam_max - lam_min
    # rows of A - lam_min I
    r0x, r0y, r0z = a00 - lam_min, a01, a02
    r1x, r1y, r1z = a01, a11 - lam_min, a12
    r2x, r2y, r2z = a02, a12, a22 - lam_min
    c1x, c1y, c1z = r0y * r1z - r0z * r1y, r0z * r1x - r0x * r1z, r0x * r1y - r0y * r1x
    c2x, c2y, c2z = r0y * r2z - r0z * r2y, r0z * r2x - r0x * r2z, r0x * r2y - r0y * r2x
    c3x, c3y, c3z = r1y * r2z - r1z * r2y, r1z * r2x - r1x * r2z, r1x * r2y - r1y * r2x
    l1 = c1x * c1x + c1y * c1y + c1z * c1z
    l2 = c2x * c2x + c2y * c2y + c2z * c2z
    l3 = c3x * c3x + c3y * c3y + c3z * c3z
    lam_min = max(lam_min, 0.0) * scale
    lam_mid = max(lam_mid, 0.0) * scale
    lam_max = max(lam_max, 0.0) * scale
    if l1 >= l2 and l1 >= l3:
        best, vx, vy, vz = l1, c1x, c1y, c1z
    elif l2 >= l3:
        best, vx, vy, vz = l2, c2x, c2y, c2z
    else:
        best, vx, vy, vz = l3, c3x, c3y, c3z
    if best <= _DEGENERATE:
        return lam_min, lam_mid, lam_max, nan, nan, nan
    norm = math.sqrt(best)
    return lam_min, lam_mid, lam_max, vx / norm, vy / norm, vz / norm


@njit(cache=True, nogil=True, parallel=True)
def normals_pca(points, indptr, indices, viewpoint, normals, curvature):
    """Normals and curvature of every point from its CSR neighbourhood.

    ``normals`` (n, 3) and ``curvature`` (n,) are filled in place. Fewer than
    three neighbours, or a collinear neighbourhood, give NaN normals; fewer
    than three neighbours also give NaN curvature (PCL's rules).
    """
    n = len(indptr) - 1
    for i in prange(n):
        start, stop = indptr[i], indptr[i + 1]
        m = stop - start
        if m < 3:
            normals[i, 0] = normals[i, 1] = normals[i, 2] = np.nan
            curvature[i] = np.nan
            continue
        # two passes: the mean, then the centred second moments
        mx = my = mz = 0.0
        for t in range(start, stop):
            j = indices[t]
            mx += points[j, 0]
            my += points[j, 1]
            mz += points[j, 2]
        mx /= m
        my /= m
        mz /= m
        cxx = cxy = cxz = cyy = cyz = czz = 0.0
        for t in range(start, stop):
            j = indices[t]
            dx = points[j, 0] - mx
            dy = points[j, 1] - my
            dz = points[j, 2] - mz
            cxx += dx * dx
            cxy += dx * dy
            cxz += dx * dz
            cyy += dy * dy
            cyz += dy * dz
            czz += dz * dz
        lam0, lam1, lam2, nx, ny, nz = smallest_eigenpair(
            cxx / m, cxy / m, cxz / m, cyy / m, cyz / m, czz / m
        )
        total = lam0 + lam1 + lam2
        curvature[i] = abs(lam0 / total) if total > 0.0 else 0.0
        vx = viewpoint[0] - points[i, 0]
        vy = viewpoint[1] - points[i, 1]
        vz = viewpoint[2] - points[i, 2]
        if vx * nx + vy * ny + vz * nz < 0.0:
            nx, ny, nz = -nx, -ny, -nz
        normals[i, 0] = nx
        normals[i, 1] = ny
        normals[i, 2] = nz
