"""numba kernels of the ground filter: the minimum-z raster and the lookup
of a raster at the points, in one pass over the points each (no
per-point temporaries); the low-noise test, the opening and the two
interpolations of the raster, each cell from the cells within a fixed
distance of it.

The kernels named ``*_rows`` (and :func:`cell_minimum_parts`,
:func:`merge_minimum`) take a range of rows first, ``kernel(lo, hi,
*args)``, for :func:`~skpcd.utils._parallel.parallel_rows`: rows of points,
of the raster or, for :func:`cell_minimum_parts`, parts of the points. Each
row's result is computed by the same operations in the same order whatever
the range, so the result does not depend on the threads."""

import math

import numpy as np
from numba import njit

# The 8 neighbour directions: edge neighbours first, then corners; each
# pair (2 k, 2 k + 1) opposite.
_DR = (-1, 1, 0, 0, -1, 1, -1, 1)
_DC = (0, 0, -1, 1, -1, 1, 1, -1)


@njit(cache=True, nogil=True)
def _minimum_into(xyz, start, stop, x0, y0, cell, nx, ny, c0, r0, zmin):
    """The lowest z of points ``start`` to ``stop`` kept in ``zmin`` (see
    :func:`cell_minimum`): a point replaces a cell's value only when
    strictly lower, so the first of equal lowest points is kept."""
    wy, wx = zmin.shape
    for i in range(start, stop):
        c = min(max(math.floor((xyz[i, 0] - x0) / cell), 0), nx - 1) - c0
        r = min(max(math.floor((xyz[i, 1] - y0) / cell), 0), ny - 1) - r0
        if 0 <= c < wx and 0 <= r < wy and xyz[i, 2] < zmin[r, c]:
            zmin[r, c] = xyz[i, 2]


@njit(cache=True, nogil=True)
def cell_minimum(xyz, x0, y0, cell, nx, ny, c0, r0, zmin):
    """Lowest z of the points in every cell of a raster of ``nx`` x ``ny``
    cells with origin ``x0, y0`` (cell ``(row, col)`` spans ``x0 + col *
    cell`` to ``x0 + (col + 1) * cell`` and likewise in y; points beyond it
    fall in its edge cells), kept in ``zmin`` (filled with +inf
    beforehand), a window of that raster starting at cell ``(r0, c0)``:
    the whole raster when ``(r0, c0) = (0, 0)`` and ``zmin`` is ``(ny,
    nx)``; the cells of a tile's window in the tiled path. One thread; see
    :func:`cell_minimum_parts` for several."""
    _minimum_into(xyz, 0, len(xyz), x0, y0, cell, nx, ny, c0, r0, zmin)


@njit(cache=True, nogil=True)
def cell_minimum_parts(lo, hi, xyz, bounds, x0, y0, cell, nx, ny, c0, r0, zmin, others):
    """:func:`cell_minimum` of parts ``lo`` to ``hi`` of the points: part
    ``p`` (points ``bounds[p]`` to ``bounds[p + 1]``) into ``zmin`` for
    ``p = 0``, else into ``others[p - 1]`` (all filled with +inf
    beforehand); :func:`merge_minimum` then gives the raster of all the
    points in ``zmin``."""
    for p in range(lo, hi):
        out = zmin if p == 0 else others[p - 1]
        _minimum_into(xyz, bounds[p], bounds[p + 1], x0, y0, cell, nx, ny, c0, r0, out)


@njit(cache=True, nogil=True)
def merge_minimum(lo, hi, zmin, others):
    """Rows ``lo`` to ``hi`` of ``zmin``: the minimum over the parts'
    rasters, taken in the order of the parts and replaced only when
    strictly lower, as one pass over all the points in order keeps it (the
    first of equal lowest points, -0.0 or 0.0 alike)."""
    nx = zmin.shape[1]
    for p in range(len(others)):
        for r in range(lo, hi):
            for c in range(nx):
                if others[p, r, c] < zmin[r, c]:
                    zmin[r, c] = others[p, r, c]


@njit(cache=True, nogil=True)
def extent_parts(lo, hi, xyz, bounds, out):
    """Parts ``lo`` to ``hi`` of the points (part ``p``: points ``bounds[p]``
    to ``bounds[p + 1]``): ``out[p]`` is the lowest x and y, the highest x
    and y, and 1.0 when all their coordinates are finite (else 0.0)."""
    for p in range(lo, hi):
        x0, y0 = math.inf, math.inf
        x1, y1 = -math.inf, -math.inf
        finite = True
        for i in range(bounds[p], bounds[p + 1]):
            x, y, z = xyz[i, 0], xyz[i, 1], xyz[i, 2]
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
                finite = False
            x0 = min(x0, x)
            y0 = min(y0, y)
            x1 = max(x1, x)
            y1 = max(y1, y)
        out[p, 0], out[p, 1], out[p, 2], out[p, 3] = x0, y0, x1, y1
        out[p, 4] = 1.0 if finite else 0.0


@njit(cache=True, nogil=True)
def cell_indices_rows(lo, hi, xyz, x0, y0, cell, nx, ny, cells):
    """Points ``lo`` to ``hi``: their (col, row) cell of the raster of
    :func:`cell_minimum` into ``cells``."""
    for i in range(lo, hi):
        cells[i, 0] = min(max(math.floor((xyz[i, 0] - x0) / cell), 0), nx - 1)
        cells[i, 1] = min(max(math.floor((xyz[i, 1] - y0) / cell), 0), ny - 1)


@njit(cache=True, nogil=True)
def cell_mean(xyz, mask, x0, y0, cell, nx, ny, mean, count):
    """Mean z of the points with ``mask`` in every cell of the raster of
    :func:`cell_minimum` (``mean`` and ``count`` zeroed beforehand; cells
    without such a point keep 0 and count 0)."""
    for i in range(len(xyz)):
        if not mask[i]:
            continue
        c = min(max(math.floor((xyz[i, 0] - x0) / cell), 0), nx - 1)
        r = min(max(math.floor((xyz[i, 1] - y0) / cell), 0), ny - 1)
        mean[r, c] += xyz[i, 2]
        count[r, c] += 1
    for r in range(ny):
        for c in range(nx):
            if count[r, c] > 0:
                mean[r, c] /= count[r, c]


@njit(cache=True, nogil=True)
def _bilinear_weights(x, y, x0, y0, cell, nx, ny, c0, r0, wx, wy):
    """Where a raster of ``nx`` x ``ny`` cells (values at the cell centres,
    origin ``x0, y0``) is interpolated bilinearly at ``(x, y)``: the rows
    and columns ``r, r1, c, c1`` of the four cells and the weights ``fv,
    fu`` of ``r1`` and ``c1``; constant beyond the outer centres. The cells
    are those of the window of ``wx`` x ``wy`` cells starting at cell
    ``(r0, c0)`` (the whole raster with ``(0, 0)``): the same cells and
    weights as on the whole raster wherever they fall in the window."""
    u = (x - x0) / cell - 0.5
    v = (y - y0) / cell - 0.5
    u = min(max(u, 0.0), nx - 1.0)
    v = min(max(v, 0.0), ny - 1.0)
    c = min(int(u), max(nx - 2, 0))
    r = min(int(v), max(ny - 2, 0))
    fu = u - c if nx > 1 else 0.0
    fv = v - r if ny > 1 else 0.0
    c1 = min(max(min(c + 1, nx - 1) - c0, 0), wx - 1)
    r1 = min(max(min(r + 1, ny - 1) - r0, 0), wy - 1)
    c = min(max(c - c0, 0), wx - 1)
    r = min(max(r - r0, 0), wy - 1)
    return r, r1, c, c1, fv, fu


@njit(cache=True, nogil=True)
def _bilinear_value(grid, r, r1, c, c1, fv, fu):
    """The bilinear interpolation of ``grid`` at the cells and weights of
    :func:`_bilinear_weights`."""
    top = grid[r, c] * (1.0 - fu) + grid[r, c1] * fu
    bottom = grid[r1, c] * (1.0 - fu) + grid[r1, c1] * fu
    return top * (1.0 - fv) + bottom * fv


@njit(cache=True, nogil=True)
def bilinear_rows(lo, hi, xyz, x0, y0, cell, nx, ny, c0, r0, grid, out):
    """Points ``lo`` to ``hi``: the raster interpolated bilinearly at their
    xy into ``out`` (see :func:`_bilinear_weights`)."""
    wy, wx = grid.shape
    for i in range(lo, hi):
        at = _bilinear_weights(
            xyz[i, 0], xyz[i, 1], x0, y0, cell, nx, ny, c0, r0, wx, wy
        )
        out[i] = _bilinear_value(grid, *at)


@njit(cache=True, nogil=True)
def classify_rows(
    lo, hi, xyz, x0, y0, cell, nx, ny, c0, r0, dem, slope, threshold, scalar, out
):
    """Points ``lo`` to ``hi``: ground (``out`` True) when ``|z - DEM| <=
    threshold + scalar * slope``, both rasters interpolated bilinearly at
    the point (:func:`_bilinear_weights`); False where the DEM is NaN."""
    wy, wx = dem.shape
    for i in range(lo, hi):
        at = _bilinear_weights(
            xyz[i, 0], xyz[i, 1], x0, y0, cell, nx, ny, c0, r0, wx, wy
        )
        d = _bilinear_value(dem, *at)
        out[i] = abs(xyz[i, 2] - d) <= threshold + scalar * _bilinear_value(slope, *at)


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
    ny, nx = z.shape
    if square:
        for r in range(ny):
            for c in range(nx):
                v = z[r, c]
                if c > 0:
                    v = min(v, z[r, c - 1])
                if c < nx - 1:
                    v = min(v, z[r, c + 1])
                tmp[r, c] = v
        for r in range(ny):
            for c in range(nx):
                v = tmp[r, c]
                if r > 0:
                    v = min(v, tmp[r - 1, c])
                if r < ny - 1:
                    v = min(v, tmp[r + 1, c])
                out[r, c] = v
        return
    for r in range(ny):
        for c in range(nx):
            v = z[r, c]
            if c > 0:
                v = min(v, z[r, c - 1])
            if c < nx - 1:
                v = min(v, z[r, c + 1])
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
