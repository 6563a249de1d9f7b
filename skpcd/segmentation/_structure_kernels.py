"""numba kernels of :mod:`skpcd.segmentation._structures`: the local shape of
every point's neighbourhood, and neighbour votes over the k-NN graph."""

import math

import numpy as np
from numba import njit

from skpcd.preprocessing._normals_kernels import add_products
from skpcd.segmentation._union_find import find_root, union_lower


@njit(cache=True, nogil=True)
def _eigenvalues(a00, a01, a02, a11, a12, a22):
    """Eigenvalues of a symmetric 3x3 matrix, largest first (the
    trigonometric solution of the characteristic cubic)."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    if p1 <= 1e-30 * max(q * q, 1e-300):
        e = sorted([a00, a11, a22])
        return e[2], e[1], e[0]
    p2 = (a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    b00, b11, b22 = (a00 - q) / p, (a11 - q) / p, (a22 - q) / p
    b01, b02, b12 = a01 / p, a02 / p, a12 / p
    r = 0.5 * (
        b00 * (b11 * b22 - b12 * b12)
        - b01 * (b01 * b22 - b12 * b02)
        + b02 * (b01 * b12 - b11 * b02)
    )
    r = min(max(r, -1.0), 1.0)
    phi = math.acos(r) / 3.0
    e1 = q + 2.0 * p * math.cos(phi)
    e3 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    e2 = 3.0 * q - e1 - e3
    return e1, e2, e3


@njit(cache=True, nogil=True)
def _vector(a00, a01, a02, a11, a12, a22, lam):
    """Unit eigenvector of ``lam`` (the largest cross product of the rows of
    ``A - lam I``); zeros when the eigenvalue is not simple."""
    m00, m11, m22 = a00 - lam, a11 - lam, a22 - lam
    best = 0.0
    vx = vy = vz = 0.0
    # rows (m00 a01 a02), (a01 m11 a12), (a02 a12 m22): cross products
    for x, y, z in (
        (a01 * a12 - a02 * m11, a02 * a01 - m00 * a12, m00 * m11 - a01 * a01),
        (a01 * m22 - a02 * a12, a02 * a02 - m00 * m22, m00 * a12 - a01 * a02),
        (m11 * m22 - a12 * a12, a12 * a02 - a01 * m22, a01 * a12 - m11 * a02),
    ):
        n = x * x + y * y + z * z
        if n > best:
            best = n
            vx, vy, vz = x, y, z
    if best <= 0.0:
        return 0.0, 0.0, 0.0
    r = math.sqrt(best)
    return vx / r, vy / r, vz / r


@njit(cache=True, nogil=True)
def local_shape(xyz, indptr, indices, linearity, planarity, normal, axis_z, spread):
    """Shape of the neighbourhood of every point, from the eigenvalues
    ``l1 >= l2 >= l3`` of its covariance: ``linearity`` (l1 - l2) / l1,
    ``planarity`` (l2 - l3) / l1, the ``normal`` (unit eigenvector of l3,
    sign arbitrary; shape (n, 3)), ``|z|`` of the main axis (eigenvector of
    l1), and ``spread`` sqrt(l2), the thickness across the main axis
    (metres). Neighbourhoods of fewer than 3 points get zeros (float32
    outputs). All rows of :func:`local_shape_rows`."""
    local_shape_rows(
        0, len(indptr) - 1, xyz, indptr, indices, linearity, planarity, normal,
        axis_z, spread,
    )  # fmt: skip


@njit(cache=True, nogil=True)
def local_shape_rows(
    lo, hi, xyz, indptr, indices, linearity, planarity, normal, axis_z, spread
):
    """Rows ``lo`` to ``hi`` of :func:`local_shape` (a chunk of
    :func:`~skpcd.utils._parallel.parallel_rows`): each row reads the
    neighbourhood of its point and writes its own outputs only."""
    for i in range(lo, hi):
        start, stop = indptr[i], indptr[i + 1]
        n = stop - start
        linearity[i] = 0.0
        planarity[i] = 0.0
        normal[i, 0] = 0.0
        normal[i, 1] = 0.0
        normal[i, 2] = 0.0
        axis_z[i] = 0.0
        spread[i] = 0.0
        if n < 3:
            continue
        mx = my = mz = 0.0
        for j in range(start, stop):
            k = indices[j]
            mx += xyz[k, 0] - xyz[i, 0]
            my += xyz[k, 1] - xyz[i, 1]
            mz += xyz[k, 2] - xyz[i, 2]
        mx /= n
        my /= n
        mz /= n
        c00 = c01 = c02 = c11 = c12 = c22 = 0.0
        for j in range(start, stop):
            k = indices[j]
            dx = xyz[k, 0] - xyz[i, 0] - mx
            dy = xyz[k, 1] - xyz[i, 1] - my
            dz = xyz[k, 2] - xyz[i, 2] - mz
            c00, c01, c02, c11, c12, c22 = add_products(
                c00, c01, c02, c11, c12, c22, dx, dy, dz
            )
        c00 /= n
        c01 /= n
        c02 /= n
        c11 /= n
        c12 /= n
        c22 /= n
        e1, e2, e3 = _eigenvalues(c00, c01, c02, c11, c12, c22)
        if e1 <= 0.0:
            continue
        e2 = max(e2, 0.0)
        e3 = max(e3, 0.0)
        linearity[i] = (e1 - e2) / e1
        planarity[i] = (e2 - e3) / e1
        nx, ny, nz = _vector(c00, c01, c02, c11, c12, c22, e3)
        normal[i, 0] = nx
        normal[i, 1] = ny
        normal[i, 2] = nz
        axis_z[i] = abs(_vector(c00, c01, c02, c11, c12, c22, e1)[2])
        spread[i] = math.sqrt(e2)


@njit(cache=True, nogil=True)
def neighbour_share(indptr, indices, flag, out):
    """Share of each point's neighbours (itself included) that are flagged."""
    for i in range(len(indptr) - 1):
        lo, hi = indptr[i], indptr[i + 1]
        c = 0
        for j in range(lo, hi):
            if flag[indices[j]]:
                c += 1
        out[i] = c / max(hi - lo, 1)


@njit(cache=True, nogil=True)
def aligned_components(indptr, indices, mask, normal, min_cos, labels):
    """Connected components of the masked points over the k-NN graph, an
    edge kept where the two normals are within ``acos(min_cos)`` (either
    sign); union-find, no graph built. ``labels``: the component of each
    masked point, numbered 0, 1, ... in order of first point; -1 elsewhere.
    Returns the number of components."""
    n = len(indptr) - 1
    parent = np.arange(n)
    for i in range(n):
        if not mask[i]:
            continue
        for j in range(indptr[i], indptr[i + 1]):
            k = indices[j]
            if k == i or not mask[k]:
                continue
            d = (
                normal[i, 0] * normal[k, 0]
                + normal[i, 1] * normal[k, 1]
                + normal[i, 2] * normal[k, 2]
            )
            if abs(d) >= min_cos:
                union_lower(parent, i, k)
    count = 0
    for i in range(n):
        labels[i] = -1
    for i in range(n):
        if mask[i]:
            r = find_root(parent, i)
            if labels[r] < 0:
                labels[r] = count
                count += 1
            labels[i] = labels[r]
    return count


@njit(cache=True, nogil=True)
def same_label_edges(indptr, indices, labels, mask, keep, counts):
    """``keep[j]`` for every pair ``(i, indices[j])`` of the k-NN graph: both
    ends masked, with the same label, and not the point itself; ``counts[i]``
    the pairs kept in row ``i``."""
    for i in range(len(indptr) - 1):
        c = 0
        for j in range(indptr[i], indptr[i + 1]):
            k = indices[j]
            keep[j] = k != i and mask[i] and mask[k] and labels[i] == labels[k]
            c += keep[j]
        counts[i] = c


@njit(cache=True, nogil=True)
def column_keys(lo, hi, xyz, ox, oy, side, ny, keys):
    """Key ``ix * ny + iy`` of the ``side`` x ``side`` column of points
    ``lo`` to ``hi`` (``ix = floor((x - ox) / side)``, the same for y), into
    ``keys``. Rows are independent: safe in threads."""
    for i in range(lo, hi):
        ix = np.int64(math.floor((xyz[i, 0] - ox) / side))
        iy = np.int64(math.floor((xyz[i, 1] - oy) / side))
        keys[i] = ix * ny + iy


@njit(cache=True, nogil=True)
def sort_columns(order, starts, zs):
    """Sort each column ``starts[c]:starts[c + 1]`` of ``zs`` by height,
    ``order`` alongside."""
    for c in range(len(starts) - 1):
        lo, hi = starts[c], starts[c + 1]
        if hi - lo < 2:
            continue
        by = np.argsort(zs[lo:hi])
        zs[lo:hi] = zs[lo:hi][by]
        order[lo:hi] = order[lo:hi][by]


@njit(cache=True, nogil=True)
def column_counts(order, starts, zs, mask, dz_lo, dz_hi, out):
    """For every masked point: how many points of its column lie between
    ``dz_lo`` and ``dz_hi`` above or below it. The points ``order[starts[c]:
    starts[c + 1]]`` make column ``c``, sorted by height, ``zs`` their
    heights in that order."""
    for c in range(len(starts) - 1):
        lo, hi = starts[c], starts[c + 1]
        col = zs[lo:hi]
        for a in range(lo, hi):
            i = order[a]
            if not mask[i]:
                continue
            z = zs[a]
            n = np.searchsorted(col, z + dz_hi, side="right") - np.searchsorted(
                col, z + dz_lo, side="left"
            )
            n += np.searchsorted(col, z - dz_lo, side="right") - np.searchsorted(
                col, z - dz_hi, side="left"
            )
            out[i] = n


@njit(cache=True, nogil=True)
def segment_extents(labels, xyz, n, lo, hi, count):
    """Per label ``0 .. n - 1``: bounding box ``lo``/``hi`` (filled with
    +inf / -inf beforehand) and point count (zeroed beforehand)."""
    for i in range(len(labels)):
        g = labels[i]
        if g < 0:
            continue
        count[g] += 1
        for a in range(3):
            v = xyz[i, a]
            if v < lo[g, a]:
                lo[g, a] = v
            if v > hi[g, a]:
                hi[g, a] = v


@njit(cache=True, nogil=True)
def component_covariance(labels, xy, n, mean, cov, count):
    """Per label: mean and covariance of the xy coordinates (two passes;
    ``mean``, ``cov`` and ``count`` zeroed beforehand)."""
    for i in range(len(labels)):
        g = labels[i]
        if g < 0:
            continue
        count[g] += 1
        mean[g, 0] += xy[i, 0]
        mean[g, 1] += xy[i, 1]
    for g in range(n):
        if count[g] > 0:
            mean[g, 0] /= count[g]
            mean[g, 1] /= count[g]
    for i in range(len(labels)):
        g = labels[i]
        if g < 0:
            continue
        dx = xy[i, 0] - mean[g, 0]
        dy = xy[i, 1] - mean[g, 1]
        cov[g, 0] += dx * dx
        cov[g, 1] += dx * dy
        cov[g, 2] += dy * dy
    for g in range(n):
        if count[g] > 0:
            cov[g, 0] /= count[g]
            cov[g, 1] /= count[g]
            cov[g, 2] /= count[g]


@njit(cache=True, nogil=True)
def first_rows(key, first):
    """The lowest row of each key into ``first`` (-1 beforehand: none)."""
    for i in range(len(key)):
        if first[key[i]] < 0:
            first[key[i]] = i


@njit(cache=True, nogil=True)
def nearest_square(lo, hi, xyz, table, rep, ox, oy, cell, max_ring, out):
    """For points ``lo`` to ``hi``: the square whose representative point
    (``rep[j]``, x and y) is nearest in the plane, into ``out`` (ties: the
    lower ``j``), or -1 when it lies beyond ``max_ring`` rings of squares.

    ``table`` (shape (nx, ny)) holds each square's ``j`` (-1: none); the
    squares ``cell`` wide start at ``(ox, oy)``, and a square's
    representative lies in it. Rings of squares around the point's own are
    scanned until the nearest found is closer than any square outside them
    can be: after ring ``r``, ``r`` squares' widths. Rows are independent:
    safe in threads."""
    nx, ny = table.shape
    for i in range(lo, hi):
        qx, qy = xyz[i, 0], xyz[i, 1]
        fx, fy = (qx - ox) / cell, (qy - oy) / cell
        out[i] = -1
        if not (abs(fx) < 1e15 and abs(fy) < 1e15):
            continue  # far away: left to the caller
        ci, cj = math.floor(fx), math.floor(fy)
        best, best_d2 = -1, np.inf
        for r in range(max_ring + 1):
            for a in range(ci - r, ci + r + 1):
                if a < 0 or a >= nx:
                    continue
                edge = a == ci - r or a == ci + r
                step = 1 if edge else 2 * r
                b = cj - r
                while b <= cj + r:
                    if b >= 0 and b < ny:
                        j = table[a, b]
                        if j >= 0:
                            ex = rep[j, 0] - qx
                            ey = rep[j, 1] - qy
                            d2 = ex * ex + ey * ey
                            if d2 < best_d2 or (d2 == best_d2 and j < best):
                                best, best_d2 = j, d2
                    if step == 0:
                        break
                    b += step
            # squares beyond ring r are at least r widths away (less a
            # margin for the rounding of the point's square)
            bound = (r - 1e-6) * cell
            if best >= 0 and bound > 0 and best_d2 < bound * bound:
                out[i] = best
                break
