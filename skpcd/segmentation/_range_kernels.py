"""Numba kernels of the range image of a sweep: the points ordered by pixel,
the ground walked outwards column by column, the non-ground points joined
between neighbouring pixels by the angle between them."""

import numpy as np
from numba import njit

from skpcd.segmentation._union_find import find_root, union_lower

__all__ = ["cluster_image", "ground_columns", "pixel_order"]


@njit(cache=True, nogil=True)
def pixel_order(pixel, key, n_pixels):
    """The points ordered by pixel, and by ``key`` within a pixel.

    Returns ``(start, order)``: the points of pixel ``p`` are
    ``order[start[p]:start[p + 1]]``, smallest ``key`` first (a counting
    sort by pixel, then an insertion sort of each pixel's few points;
    equal keys keep the order of the points)."""
    n = len(pixel)
    start = np.zeros(n_pixels + 1, dtype=np.int64)
    for i in range(n):
        start[pixel[i] + 1] += 1
    for p in range(n_pixels):
        start[p + 1] += start[p]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[fill[pixel[i]]] = i
        fill[pixel[i]] += 1
    for p in range(n_pixels):
        for a in range(start[p] + 1, start[p + 1]):
            item = order[a]
            b = a - 1
            while b >= start[p] and key[order[b]] > key[item]:
                order[b + 1] = order[b]
                b -= 1
            order[b + 1] = item
    return start, order


@njit(cache=True, nogil=True)
def ground_columns(start, order, rho, z, z0, slope, step, max_step):
    """Ground flags walked outwards along each column of the image.

    ``start``/``order`` hold the points of each column, nearest first (by
    horizontal range ``rho``). Each column starts from the ground under
    the sensor, height ``z0`` at range 0; a point is ground when its
    height differs from the last ground point of its column by at most
    ``min(step + slope * d, max_step)``, ``d`` the horizontal distance
    between them: the ground rises or falls at most by ``slope`` and a
    little noise (``step``), a wall or the side of a car (points above one
    another) does not. The point then becomes the column's last ground
    point."""
    n_columns = len(start) - 1
    ground = np.zeros(len(rho), dtype=np.bool_)
    for c in range(n_columns):
        last_rho = 0.0
        last_z = z0
        for a in range(start[c], start[c + 1]):
            i = order[a]
            d = rho[i] - last_rho
            if d < 0.0:
                d = 0.0
            allowed = step + slope * d
            if allowed > max_step:
                allowed = max_step
            if abs(z[i] - last_z) <= allowed:
                ground[i] = True
                last_rho = rho[i]
                last_z = z[i]
    return ground


@njit(cache=True, nogil=True, inline="always")
def _joined(i, j, xyz, sensor, cos_theta_limit, max_gap):
    """Whether points ``i`` and ``j`` lie on one surface: the angle beta at
    the farther point, between the ray to it and the line to the nearer
    one, is above theta (Bogoslavskyi & Stachniss), and they are at most
    ``max_gap`` apart."""
    ax = xyz[i, 0] - sensor[0]
    ay = xyz[i, 1] - sensor[1]
    az = xyz[i, 2] - sensor[2]
    bx = xyz[j, 0] - sensor[0]
    by = xyz[j, 1] - sensor[1]
    bz = xyz[j, 2] - sensor[2]
    gx = ax - bx
    gy = ay - by
    gz = az - bz
    gap2 = gx * gx + gy * gy + gz * gz
    if gap2 > max_gap * max_gap:
        return False
    if gap2 == 0.0:
        return True
    da = ax * ax + ay * ay + az * az
    db = bx * bx + by * by + bz * bz
    # the farther point f and the line from it to the nearer one: beta is
    # the angle between -f (back along its ray) and (near - far)
    if da >= db:
        fx, fy, fz, f2 = ax, ay, az, da
        lx, ly, lz = -gx, -gy, -gz
    else:
        fx, fy, fz, f2 = bx, by, bz, db
        lx, ly, lz = gx, gy, gz
    if f2 == 0.0:
        return True
    cos_beta = -(fx * lx + fy * ly + fz * lz) / np.sqrt(f2 * gap2)
    return cos_beta < cos_theta_limit


@njit(cache=True, nogil=True, inline="always")
def _join_pixel(i, q, start, order, keep, xyz, sensor, cos_limit, max_gap, parent):
    """Join point ``i`` to the kept points of pixel ``q`` that lie on its
    surface (:func:`_joined`); whether ``q`` holds a kept point."""
    found = False
    for b in range(start[q], start[q + 1]):
        j = order[b]
        if keep[j]:
            found = True
            if _joined(i, j, xyz, sensor, cos_limit, max_gap):
                union_lower(parent, i, j)
    return found


@njit(cache=True, nogil=True)
def cluster_image(
    start,
    order,
    n_rows,
    n_cols,
    keep,
    xyz,
    sensor,
    theta,
    max_gap,
    reach,
    reach_columns,
):
    """Union-find roots of the kept points joined across the image.

    Each kept point is compared with the kept points of its own pixel, of
    the next pixel of its row (the columns wrap around) and of the next
    non-empty row above within ``reach`` rows, in its column and the two
    beside it; two points are joined when :func:`_joined` says so
    (``theta`` in radians). Returns the parent array (the root of each
    point; -1 for points not kept)."""
    n = len(keep)
    parent = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        if keep[i]:
            parent[i] = i
    cos_limit = np.cos(theta)
    for r in range(n_rows):
        for c in range(n_cols):
            p = r * n_cols + c
            for a in range(start[p], start[p + 1]):
                i = order[a]
                if not keep[i]:
                    continue
                # the points of the same pixel, farther than i
                for b in range(a + 1, start[p + 1]):
                    j = order[b]
                    if keep[j] and _joined(i, j, xyz, sensor, cos_limit, max_gap):
                        union_lower(parent, i, j)
                # the next pixels of the row, up to the first holding a
                # kept point
                for dc in range(1, reach_columns + 1):
                    q = r * n_cols + (c + dc) % n_cols
                    if _join_pixel(i, q, start, order, keep, xyz, sensor,
                                   cos_limit, max_gap, parent):  # fmt: skip
                        break
                # the next rows above, up to the first holding a kept point
                for up in range(r + 1, min(r + 1 + reach, n_rows)):
                    found = False
                    for dc in range(-1, 2):
                        q = up * n_cols + (c + dc) % n_cols
                        found |= _join_pixel(i, q, start, order, keep, xyz, sensor,
                                             cos_limit, max_gap, parent)  # fmt: skip
                    if found:
                        break
    for i in range(n):
        if parent[i] >= 0:
            parent[i] = find_root(parent, i)
    return parent
