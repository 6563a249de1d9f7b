"""Numba kernels of the range image of a sweep: the points ordered by pixel,
the ground walked outwards column by column, the non-ground points joined
between neighbouring pixels by the angle between them."""

import numpy as np
from numba import njit

from skpcd.segmentation._union_find import find_root, union_lower

__all__ = ["cluster_image", "ground_columns", "numbered_trees", "pixel_order"]

# Pixels holding more points than this are sorted by merge sort, fewer by
# insertion.
_FEW = 16


@njit(cache=True, nogil=True)
def pixel_order(pixel, key, n_pixels):
    """The points ordered by pixel, and by ``key`` within a pixel.

    Returns ``(start, order)``: the points of pixel ``p`` are
    ``order[start[p]:start[p + 1]]``, smallest ``key`` first (a counting
    sort by pixel, then an insertion sort of each pixel's points, a merge
    sort of pixels holding more than ``_FEW``; equal keys keep the order of
    the points)."""
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
        lo, hi = start[p], start[p + 1]
        if hi - lo > _FEW:
            items = order[lo:hi].copy()
            order[lo:hi] = items[np.argsort(key[items], kind="mergesort")]
            continue
        for a in range(lo + 1, hi):
            item = order[a]
            b = a - 1
            while b >= lo and key[order[b]] > key[item]:
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
def _wrapped(c, n_cols):
    """Column ``c`` wrapped around the image (``-n_cols <= c < 2 * n_cols``)."""
    if c >= n_cols:
        return c - n_cols
    if c < 0:
        return c + n_cols
    return c


@njit(cache=True, nogil=True)
def cluster_image(
    start, n_rows, n_cols, keep, xyz, sensor, theta, max_gap, reach, reach_columns
):
    """Union-find roots of the kept points joined across the image.

    The points are in pixel order (those of pixel ``p`` are
    ``start[p]:start[p + 1]``, nearest first), so that the neighbours of a
    point lie near it in memory. Each kept point is compared with the
    kept points of its own pixel, of the next pixel of its row holding a
    kept point within ``reach_columns`` (the columns wrap around) and of
    the next row above within ``reach`` rows holding one in its column or
    the two beside it; two points are joined when :func:`_joined` says so
    (``theta`` in radians). Returns the parent array (the root of each
    point, the first of its tree; -1 for points not kept)."""
    n = len(keep)
    parent = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        if keep[i]:
            parent[i] = i
    cos_limit = np.cos(theta)
    # the neighbour pixels of a point, in slots: first the next
    # ``reach_columns`` pixels of its row, one at a time, then the rows
    # above, three pixels at a time; the row's slots end at the first pixel
    # holding a kept point, the rows' at the first row holding one. (One
    # loop over the slots, not a helper called from two loops: numba
    # compiles the helper's loop some six times slower.)
    n_slots = reach_columns + 3 * reach
    for r in range(n_rows):
        for c in range(n_cols):
            p = r * n_cols + c
            for i in range(start[p], start[p + 1]):
                if not keep[i]:
                    continue
                # the points of the same pixel, farther than i
                for j in range(i + 1, start[p + 1]):
                    if keep[j] and _joined(i, j, xyz, sensor, cos_limit, max_gap):
                        union_lower(parent, i, j)
                found = False
                k = 0
                while k < n_slots:
                    if k < reach_columns:
                        q = r * n_cols + _wrapped(c + 1 + k, n_cols)
                        last = True
                    else:
                        m = k - reach_columns
                        up = r + 1 + m // 3
                        if up >= n_rows:
                            break
                        q = up * n_cols + _wrapped(c + m % 3 - 1, n_cols)
                        last = m % 3 == 2
                    for j in range(start[q], start[q + 1]):
                        if keep[j]:
                            found = True
                            if _joined(i, j, xyz, sensor, cos_limit, max_gap):
                                union_lower(parent, i, j)
                    if found and last and k >= reach_columns:
                        break
                    if found and last:  # the row done: on to the rows above
                        found = False
                        k = reach_columns
                    else:
                        k += 1
    for i in range(n):
        if parent[i] >= 0:
            parent[i] = find_root(parent, i)
    return parent


@njit(cache=True, nogil=True)
def numbered_trees(roots, min_size, max_size):
    """Segment of each point from the union-find roots (-1: none): the
    trees of ``min_size`` to ``max_size`` points (``max_size`` < 0: no
    bound), numbered in the order of their first point."""
    n = len(roots)
    sizes = np.zeros(n, dtype=np.int64)
    for i in range(n):
        if roots[i] >= 0:
            sizes[roots[i]] += 1
    number = np.full(n, -1, dtype=np.int64)
    labels = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):
        t = roots[i]
        if t < 0 or sizes[t] < min_size or (max_size >= 0 and sizes[t] > max_size):
            continue
        if number[t] < 0:
            number[t] = count
            count += 1
        labels[i] = number[t]
    return labels
