"""numba kernels of SMRF, the morphological ground filter: the test of
the points against the terrain, the low-noise test, the opening and the two
interpolations of the raster, each cell from the cells within a fixed
distance of it.

The kernels named ``*_rows`` take a range of rows first, ``kernel(lo, hi,
*args)``, for :func:`~skpcd.utils._parallel.parallel_rows`: rows of points
or of the raster. Each row's result is computed by the same operations in
the same order whatever the range, so the result does not depend on the
threads."""

import math

import numpy as np
from numba import njit

from skpcd.segmentation.ground._raster_kernels import bilinear_value, bilinear_weights

# The 8 neighbour directions: edge neighbours first, then corners; each
# pair (2 k, 2 k + 1) opposite.
_DR = (-1, 1, 0, 0, -1, 1, -1, 1)
_DC = (0, 0, -1, 1, -1, 1, 1, -1)


@njit(cache=True, nogil=True)
def classify_rows(
    lo, hi, xyz, x0, y0, cell, nx, ny, c0, r0, dem, slope, threshold, scalar, out
):
    """Points ``lo`` to ``hi``: ground (``out`` True) when ``|z - DEM| <=
    threshold + scalar * slope``, both rasters interpolated bilinearly at
    the point (:func:`bilinear_weights`); False where the DEM is NaN."""
    wy, wx = dem.shape
    for i in range(lo, hi):
        at = bilinear_weights(
            xyz[i, 0], xyz[i, 1], x0, y0, cell, nx, ny, c0, r0, wx, wy
        )
        d = bilinear_value(dem, *at)
        out[i] = abs(xyz[i, 2] - d) <= threshold + scalar * bilinear_value(slope, *at)


# Each kernel below computes every cell of a raster from the cells within a
# fixed distance of it, visiting them in a fixed order: a window of the
# raster gives the cells of the whole raster bit for bit wherever that
# neighbourhood lies in the window (the tiled ground filter relies on it).
# Neighbours beyond the array are skipped (or, for the median, clamped to the
# edge as ``scipy.ndimage``'s ``mode="nearest"`` does).


@njit(cache=True, nogil=True)
def _nearest_known(zmin, known, r, c):
    """zmin at (r, c) if known, else at the nearest known cell of the 3x3
    around it (edge neighbours first, then corners, in a fixed order); NaN
    when there is none."""
    if known[r, c]:
        return zmin[r, c]
    ny, nx = zmin.shape
    for k in range(8):
        r2, c2 = r + _DR[k], c + _DC[k]
        if 0 <= r2 < ny and 0 <= c2 < nx and known[r2, c2]:
            return zmin[r2, c2]
    return math.nan


@njit(cache=True, nogil=True)
def drop_low_noise_rows(lo, hi, zmin, known, depth, out):
    """Rows ``lo`` to ``hi`` of ``out``: ``known`` without the cells more
    than ``depth`` below the median of their 8 neighbours, an empty
    neighbour counting as its nearest known cell (always within one cell:
    the centre is known), a neighbour beyond the edge as the edge cell next
    to it. The median of the 8 is the upper one (the 5th smallest, as
    ``scipy.ndimage.median_filter``)."""
    ny, nx = zmin.shape
    ring = np.empty(8)
    for r in range(lo, hi):
        for c in range(nx):
            if not known[r, c]:
                out[r, c] = False
                continue
            m = 0
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    if dr == 0 and dc == 0:
                        continue
                    r2 = min(max(r + dr, 0), ny - 1)
                    c2 = min(max(c + dc, 0), nx - 1)
                    ring[m] = _nearest_known(zmin, known, r2, c2)
                    m += 1
            ring.sort()
            out[r, c] = not (zmin[r, c] < ring[4] - depth)


@njit(cache=True, nogil=True)
def fill_surface(zmin, known, radius, out):
    """``out``: ``zmin`` on the known cells; elsewhere the inverse-square-
    distance mean of the known cells within ``radius`` cells (Euclidean),
    +inf when there is none. The whole raster on one thread."""
    fill_surface_rows(0, zmin.shape[0], zmin, known, radius, out)


@njit(cache=True, nogil=True)
def fill_surface_rows(lo, hi, zmin, known, radius, out):
    """Rows ``lo`` to ``hi`` of :func:`fill_surface`."""
    ny, nx = zmin.shape
    r2max = radius * radius
    for r in range(lo, hi):
        for c in range(nx):
            if known[r, c]:
                out[r, c] = zmin[r, c]
                continue
            num, den = 0.0, 0.0
            for dr in range(-radius, radius + 1):
                rr = r + dr
                if rr < 0 or rr >= ny:
                    continue
                for dc in range(-radius, radius + 1):
                    cc = c + dc
                    d2 = dr * dr + dc * dc
                    if cc < 0 or cc >= nx or d2 > r2max or not known[rr, cc]:
                        continue
                    num += zmin[rr, cc] / d2
                    den += 1.0 / d2
            out[r, c] = num / den if den > 0 else math.inf


@njit(cache=True, nogil=True)
def _first_ground(ground, r, c, dr, dc, reach):
    """Steps to the first ground cell from (r, c) along (dr, dc), at most
    ``reach``; 0 when there is none."""
    ny, nx = ground.shape
    for s in range(1, reach + 1):
        rr, cc = r + s * dr, c + s * dc
        if rr < 0 or rr >= ny or cc < 0 or cc >= nx:
            return 0
        if ground[rr, cc]:
            return s
    return 0


@njit(cache=True, nogil=True)
def interpolate_terrain(zmin, ground, surface, near, reach, out):
    """``out``: the terrain model. ``zmin`` on the ground cells; elsewhere,
    along each of the 4 lines through the cell (row, column, diagonals), the
    first ground cell within ``reach`` steps on either side: the lines with
    both ends found give the linear interpolation between them, averaged
    with weights ``1 / d_a + 1 / d_b`` (exact on a plane); without such a
    line, the ends found on one side only, weighted ``1 / d``; with no
    ground cell found, ``surface`` (the filled minimum surface: the lowest
    points are the best terrain there is), NaN where that is not finite
    either (no point within its fill radius). ``near`` flags the cells with
    a point within ``reach`` cells (rows and columns): elsewhere no ground
    cell can be found and the search is skipped. The whole raster on one
    thread."""
    interpolate_terrain_rows(0, zmin.shape[0], zmin, ground, surface, near, reach, out)


@njit(cache=True, nogil=True)
def interpolate_terrain_rows(lo, hi, zmin, ground, surface, near, reach, out):
    """Rows ``lo`` to ``hi`` of :func:`interpolate_terrain`."""
    nx = zmin.shape[1]
    for r in range(lo, hi):
        for c in range(nx):
            if ground[r, c]:
                out[r, c] = zmin[r, c]
                continue
            if not near[r, c]:
                out[r, c] = surface[r, c] if math.isfinite(surface[r, c]) else math.nan
                continue
            num2, den2, num1, den1 = 0.0, 0.0, 0.0, 0.0
            za, zb, wa, wb = 0.0, 0.0, 0.0, 0.0
            for k in range(0, 8, 2):
                step = 1.0 if k < 4 else math.sqrt(2.0)
                sa = _first_ground(ground, r, c, _DR[k], _DC[k], reach)
                sb = _first_ground(ground, r, c, _DR[k + 1], _DC[k + 1], reach)
                if sa > 0:
                    za = zmin[r + sa * _DR[k], c + sa * _DC[k]]
                    wa = 1.0 / (sa * step)
                if sb > 0:
                    zb = zmin[r + sb * _DR[k + 1], c + sb * _DC[k + 1]]
                    wb = 1.0 / (sb * step)
                if sa > 0 and sb > 0:
                    num2 += wa * za + wb * zb
                    den2 += wa + wb
                elif sa > 0:
                    num1 += wa * za
                    den1 += wa
                elif sb > 0:
                    num1 += wb * zb
                    den1 += wb
            if den2 > 0:
                out[r, c] = num2 / den2
            elif den1 > 0:
                out[r, c] = num1 / den1
            elif math.isfinite(surface[r, c]):
                out[r, c] = surface[r, c]
            else:
                out[r, c] = math.nan


@njit(cache=True, nogil=True)
def erode_step(z, square, tmp, out):
    """One 3x3 step of an erosion (minimum) of ``z`` into ``out``: over the
    3x3 square (a minimum along the rows into ``tmp``, then along the
    columns), or over the cross (the cell and its 4 edge neighbours);
    neighbours beyond the edge are skipped (the same as ``scipy.ndimage``'s
    ``mode="nearest"`` for these shapes). A dilation is the erosion of
    ``-z``, negated (both exact)."""
    if square:
        _min_pass(z, True, False, tmp)
        _min_pass(tmp, False, True, out)
    else:
        _min_pass(z, True, True, out)


@njit(cache=True, nogil=True, inline="always")
def _min_pass(z, along_rows, along_columns, out):
    """``out``: the minimum of each cell of ``z`` and its neighbours in its
    row (``along_rows``: left, then right) and in its column
    (``along_columns``: above, then below), those beyond the edge skipped.
    Inlined: the flags are constants at each call of :func:`erode_step`."""
    ny, nx = z.shape
    for r in range(ny):
        for c in range(nx):
            v = z[r, c]
            if along_rows:
                if c > 0:
                    v = min(v, z[r, c - 1])
                if c < nx - 1:
                    v = min(v, z[r, c + 1])
            if along_columns:
                if r > 0:
                    v = min(v, z[r - 1, c])
                if r < ny - 1:
                    v = min(v, z[r + 1, c])
            out[r, c] = v


@njit(cache=True, nogil=True)
def opening_objects_rows(lo, hi, surface, known, radius_max, slope, cell, objects):
    """Rows ``lo`` to ``hi`` of ``objects``: the cells not ``known``, and
    those that the opening of ``surface`` flags as objects (see
    ``skpcd.segmentation._ground._objects``).

    The opening of radius ``r`` is a chain of ``2 r`` 3x3 steps
    (:func:`erode_step`), so a row depends on the rows within ``2 *
    radius_max`` of it: the rows ``lo - 2 * radius_max`` to ``hi + 2 *
    radius_max`` are computed, each step as on the whole raster, and rows
    ``lo`` to ``hi`` kept (bit for bit the whole raster's, as for the
    windows of the tiled filter)."""
    if hi <= lo:
        return
    ny, nx = surface.shape
    halo = 2 * radius_max
    a0 = max(lo - halo, 0)
    a1 = min(hi + halo, ny)
    h = a1 - a0
    eroded = surface[a0:a1].copy()
    previous = eroded.copy()
    flags = np.empty((h, nx), dtype=np.bool_)
    for r in range(h):
        for c in range(nx):
            flags[r, c] = not known[a0 + r, c]
    a = np.empty((h, nx))
    b = np.empty((h, nx))
    tmp = np.empty((h, nx))
    for radius in range(1, radius_max + 1):
        # step s of the octagon is a square when s is even, else a cross
        erode_step(eroded, (radius - 1) % 2 == 0, tmp, a)
        eroded, a = a, eroded
        # the dilation, as the erosion of the negated surface; cells where
        # the erosion found no point (+inf) take no part (+inf)
        for r in range(h):
            for c in range(nx):
                v = -eroded[r, c]
                b[r, c] = math.inf if v == -math.inf else v
        for step in range(radius):
            erode_step(b, step % 2 == 0, tmp, a)
            a, b = b, a
        drop = slope * radius * cell
        for r in range(h):
            for c in range(nx):
                opened = -b[r, c]
                if previous[r, c] - opened > drop:
                    flags[r, c] = True
                previous[r, c] = opened
    for r in range(lo, hi):
        for c in range(nx):
            objects[r, c] = flags[r - a0, c]
