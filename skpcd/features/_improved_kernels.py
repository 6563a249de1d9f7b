"""numba kernel of the improved PFH/FPFH (Wang et al., 2023).

One segment at a time: its middle point and farthest point give the
feature-level normal, and every point's pair with that normal is binned
with the pair features and bins of :mod:`skpcd.features._pair_kernels`
(PCL's, bit for bit).
"""

import math

import numpy as np
from numba import njit

from skpcd.features._pair_kernels import F0, _bin_cosine, _bin_theta, _pair

__all__ = ["improved_rows"]


@njit(cache=True, nogil=True)
def improved_rows(lo, hi, seg_ptr, xyz, points, normals, middle, n_bins, mode, out):
    """Improved PFH/FPFH (Wang et al., 2023) of segments ``lo`` to ``hi``.

    Segment ``s`` is ``seg_ptr[s]:seg_ptr[s + 1]`` of ``xyz`` (float64, for
    the middle point and the farthest point) and of ``points``/``normals``
    (float32, for the pair features). ``middle`` 0 is the centroid, 1 the
    centre of the axis-aligned box. The feature-level normal goes from the
    middle point to the farthest point (ties: the smallest (x, y, z)). Every
    point with a normal adds half a count with its normal and half with the
    opposite one (an estimated normal's sign is arbitrary): ``out[s]``
    (zeroed, float64) gets the counts, ``mode`` 0 in ``n_bins**3`` PFH bins
    (f1 fastest), 1 in three ``n_bins`` blocks. Returns nothing; the caller
    normalises. ``out[s, :]`` stays zero for a segment without a usable
    point or with all points at its middle point.
    """
    for s in range(lo, hi):
        a, b = seg_ptr[s], seg_ptr[s + 1]
        if b == a:
            continue
        mx = my = mz = 0.0
        if middle == 0:
            for i in range(a, b):
                mx += xyz[i, 0]
                my += xyz[i, 1]
                mz += xyz[i, 2]
            mx, my, mz = mx / (b - a), my / (b - a), mz / (b - a)
        else:
            lx, ly, lz = xyz[a, 0], xyz[a, 1], xyz[a, 2]
            ux, uy, uz = lx, ly, lz
            for i in range(a + 1, b):
                lx, ux = min(lx, xyz[i, 0]), max(ux, xyz[i, 0])
                ly, uy = min(ly, xyz[i, 1]), max(uy, xyz[i, 1])
                lz, uz = min(lz, xyz[i, 2]), max(uz, xyz[i, 2])
            mx, my, mz = 0.5 * (lx + ux), 0.5 * (ly + uy), 0.5 * (lz + uz)
        far = -1
        best = 0.0
        for i in range(a, b):
            ex, ey, ez = xyz[i, 0] - mx, xyz[i, 1] - my, xyz[i, 2] - mz
            d2 = ex * ex + ey * ey + ez * ez
            if d2 > best or (
                d2 == best
                and far >= 0
                and (xyz[i, 0], xyz[i, 1], xyz[i, 2])
                < (xyz[far, 0], xyz[far, 1], xyz[far, 2])
            ):
                best, far = d2, i
        if far < 0:
            continue  # every point at the middle point
        r = math.sqrt(best)
        pmx, pmy, pmz = np.float32(mx), np.float32(my), np.float32(mz)
        nmx = np.float32((xyz[far, 0] - mx) / r)
        nmy = np.float32((xyz[far, 1] - my) / r)
        nmz = np.float32((xyz[far, 2] - mz) / r)
        fx_, fy_, fz_ = xyz[far, 0], xyz[far, 1], xyz[far, 2]
        for i in range(a, b):
            nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
            if not (nx == nx and ny == ny and nz == nz):
                continue
            # the farthest point (and its duplicates) lies on the line of n_m:
            # its pair is degenerate by construction, (0, 0, 0) in PCL's
            # rule; computed, its bin would be float rounding's choice (and
            # change with the frame the cloud is computed in)
            on_line = xyz[i, 0] == fx_ and xyz[i, 1] == fy_ and xyz[i, 2] == fz_
            for sign in (np.float32(1.0), np.float32(-1.0)):
                # + 0 turns -0.0 into 0.0: n and -n give the same pair of
                # normals whichever sign the estimate had, even on exact
                # zeros (where atan2 would tell -0.0 from 0.0)
                if on_line:
                    fy = fx = f2 = f3 = F0
                else:
                    fy, fx, f2, f3, _ = _pair(
                        pmx, pmy, pmz, nmx, nmy, nmz,
                        points[i, 0], points[i, 1], points[i, 2],
                        sign * nx + F0, sign * ny + F0, sign * nz + F0,
                    )  # fmt: skip
                b1 = _bin_theta(fy, fx, n_bins)
                b2 = _bin_cosine(f2, n_bins)
                b3 = _bin_cosine(f3, n_bins)
                if mode == 0:
                    out[s, b1 + n_bins * (b2 + n_bins * b3)] += 0.5
                else:
                    out[s, b1] += 0.5
                    out[s, n_bins + b2] += 0.5
                    out[s, 2 * n_bins + b3] += 0.5
