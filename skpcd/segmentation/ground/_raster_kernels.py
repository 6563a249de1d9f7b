"""numba kernels of the rasters of the ground filters, one pass over the
points each (no per-point temporaries): the extent of the points, their
cells, the lowest z and the mean z of the points in each cell, and the
bilinear lookup of a raster at the points.

The kernels named ``*_rows`` (and :func:`cell_minimum_parts`,
:func:`merge_minimum`) take a range of rows first, ``kernel(lo, hi,
*args)``, for :func:`~skpcd.utils._parallel.parallel_rows`: rows of points,
of the raster or, for :func:`cell_minimum_parts`, parts of the points. Each
row's result is computed by the same operations in the same order whatever
the range, so the result does not depend on the threads."""

import math

from numba import njit


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
def bilinear_weights(x, y, x0, y0, cell, nx, ny, c0, r0, wx, wy):
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
def bilinear_value(grid, r, r1, c, c1, fv, fu):
    """The bilinear interpolation of ``grid`` at the cells and weights of
    :func:`bilinear_weights`."""
    top = grid[r, c] * (1.0 - fu) + grid[r, c1] * fu
    bottom = grid[r1, c] * (1.0 - fu) + grid[r1, c1] * fu
    return top * (1.0 - fv) + bottom * fv


@njit(cache=True, nogil=True)
def bilinear_rows(lo, hi, xyz, x0, y0, cell, nx, ny, c0, r0, grid, out):
    """Points ``lo`` to ``hi``: the raster interpolated bilinearly at their
    xy into ``out`` (see :func:`bilinear_weights`)."""
    wy, wx = grid.shape
    for i in range(lo, hi):
        at = bilinear_weights(
            xyz[i, 0], xyz[i, 1], x0, y0, cell, nx, ny, c0, r0, wx, wy
        )
        out[i] = bilinear_value(grid, *at)
