"""numba kernels of the streamed cloth (:mod:`~skpcd.segmentation.ground._cloth`).

Each repeats, point by point, an operation of the reference CSF code or of
:func:`~skpcd.segmentation.ground._csf.csf_ground`, with the same floating
point operations in the same order, so that a scene seen in chunks gives
the flags of the scene seen whole, bit for bit:

- :func:`sample_points`: the coordinates CSF sees (the points shifted to
  their group's corner), the lowest point of each cell (the raster of
  :func:`~skpcd.segmentation.ground._csf._far_fill`), and for every cloth
  particle the point CSF's rasterisation gives it (the nearest, the first
  of equally near ones);
- :func:`classify_points`: CSF's cloud-to-cloth test (``c2cdist``): the
  cloth's height bilinearly interpolated at the point, the difference in
  single precision, ground within the threshold.
"""

import math

import numpy as np
from numba import njit

__all__ = ["classify_points", "sample_points"]


@njit(cache=True, nogil=True, inline="always")
def _shifted(xyz, p, shift, g):
    """Point ``p`` in the frame CSF simulates its group ``g`` in (shifted
    to the group's lowest corner, as csf_ground shifts it)."""
    return xyz[p, 0] - shift[g, 0], xyz[p, 1] - shift[g, 1], xyz[p, 2] - shift[g, 2]


@njit(cache=True, nogil=True)
def sample_points(
    xyz, index, group, shift, res, zmin, z_start, z_width, z_height,
    best_d, best_i, best_xyz, p_start, p_width, extreme_v, extreme_i, extreme_xyz,
):  # fmt: skip
    """Fold points into the rasters of their groups (``group[p]`` -1: none).

    For group ``g``: ``zmin[z_start[g]:]`` is its ``z_height x z_width``
    raster of lowest shifted z (cells of ``res`` from the shifted corner,
    as ``_minimum_into``); ``best_*[p_start[g]:]`` its particles, of
    ``p_width[g]`` columns, each with the squared distance, scan index and
    shifted coordinates of its nearest point (ties: lower index);
    ``extreme_*[g]`` the points of lowest x, lowest y, highest x, highest y
    and lowest z (the cloth's bounding box)."""
    origin = 0.0 - 2 * res  # CSF's corner: bbMin - clothbuffer_d * resolution
    for p in range(len(xyz)):
        g = group[p]
        if g < 0:
            continue
        x, y, z = _shifted(xyz, p, shift, g)
        i = index[p]
        nx, ny = z_width[g], z_height[g]
        c = min(max(math.floor(x / res), 0), nx - 1)
        r = min(max(math.floor(y / res), 0), ny - 1)
        k = z_start[g] + r * nx + c
        if z < zmin[k]:
            zmin[k] = z
        # Rasterization::Rasterize: CSF's x is ours, its z our y
        dx = x - origin
        dz = y - origin
        col = int(dx / res + 0.5)
        row = int(dz / res + 0.5)
        px = origin + col * res
        pz = origin + row * res
        d = (x - px) * (x - px) + (y - pz) * (y - pz)
        k = p_start[g] + row * p_width[g] + col
        if d < best_d[k] or (d == best_d[k] and i < best_i[k]):
            best_d[k] = d
            best_i[k] = i
            best_xyz[k, 0] = x
            best_xyz[k, 1] = y
            best_xyz[k, 2] = z
        values = (x, y, -x, -y, z)
        for e in range(5):
            v = values[e]
            if v < extreme_v[g, e] or (v == extreme_v[g, e] and i < extreme_i[g, e]):
                extreme_v[g, e] = v
                extreme_i[g, e] = i
                extreme_xyz[g, e, 0] = x
                extreme_xyz[g, e, 1] = y
                extreme_xyz[g, e, 2] = z


@njit(cache=True, nogil=True)
def classify_points(xyz, group, shift, res, threshold, cloth, c_start, c_width, out):
    """CSF's ground test of each point against its group's cloth
    (``cloth[c_start[g]:]``, rows of ``c_width[g]`` particle heights in
    CSF's frame, z down); a point of group -2 (a group too small for a
    cloth) is ground, of group -1 left alone."""
    origin = 0.0 - 2 * res
    for p in range(len(xyz)):
        g = group[p]
        if g == -2:
            out[p] = True
            continue
        if g < 0:
            continue
        x, y, z = _shifted(xyz, p, shift, g)
        up = -z
        dx = x - origin
        dz = y - origin
        c0 = int(dx / res)
        r0 = int(dz / res)
        sx = (dx - c0 * res) / res
        sz = (dz - r0 * res) / res
        w = c_width[g]
        k = c_start[g] + r0 * w + c0
        fxy = (
            cloth[k] * (1 - sx) * (1 - sz)
            + cloth[k + w] * (1 - sx) * sz
            + cloth[k + w + 1] * sx * sz
            + cloth[k + 1] * sx * (1 - sz)
        )
        out[p] = abs(np.float32(fxy - up)) < threshold
