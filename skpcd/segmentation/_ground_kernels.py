"""numba kernels of the ground filter: the minimum-z raster and the lookup
of a raster at the points, in one pass over the points each (no
per-point temporaries)."""

import math

from numba import njit


@njit(cache=True, nogil=True)
def cell_minimum(xyz, x0, y0, cell, nx, ny, c0, r0, zmin):
    """Lowest z of the points in every cell of a raster of ``nx`` x ``ny``
    cells with origin ``x0, y0`` (cell ``(row, col)`` spans ``x0 + col *
    cell`` to ``x0 + (col + 1) * cell`` and likewise in y; points beyond it
    fall in its edge cells), kept in ``zmin`` (filled with +inf
    beforehand), a window of that raster starting at cell ``(r0, c0)``:
    the whole raster when ``(r0, c0) = (0, 0)`` and ``zmin`` is ``(ny,
    nx)``; the cells of a tile's window in the tiled path."""
    wy, wx = zmin.shape
    for i in range(len(xyz)):
        c = min(max(math.floor((xyz[i, 0] - x0) / cell), 0), nx - 1) - c0
        r = min(max(math.floor((xyz[i, 1] - y0) / cell), 0), ny - 1) - r0
        if 0 <= c < wx and 0 <= r < wy and xyz[i, 2] < zmin[r, c]:
            zmin[r, c] = xyz[i, 2]


@njit(cache=True, nogil=True)
def bilinear(xyz, x0, y0, cell, nx, ny, c0, r0, grid, out):
    """A raster of ``nx`` x ``ny`` cells (values at the cell centres, origin
    ``x0, y0``) interpolated bilinearly at the points' xy into ``out``;
    constant beyond the outer centres. ``grid`` is the window of that
    raster starting at cell ``(r0, c0)`` (the whole raster with ``(0, 0)``):
    the same cells and weights as on the whole raster wherever they fall in
    the window."""
    wy, wx = grid.shape
    for i in range(len(xyz)):
        u = (xyz[i, 0] - x0) / cell - 0.5
        v = (xyz[i, 1] - y0) / cell - 0.5
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
        top = grid[r, c] * (1.0 - fu) + grid[r, c1] * fu
        bottom = grid[r1, c] * (1.0 - fu) + grid[r1, c1] * fu
        out[i] = top * (1.0 - fv) + bottom * fv
