"""numba kernels of the ground filter: the minimum-z raster and the lookup
of a raster at the points, in one pass over the points each (no
per-point temporaries)."""

import math

from numba import njit


@njit(cache=True, nogil=True)
def cell_minimum(xyz, x0, y0, cell, zmin):
    """Lowest z of the points in every cell of ``zmin`` (``(ny, nx)``,
    filled with +inf beforehand); cell ``(row, col)`` spans
    ``x0 + col * cell`` to ``x0 + (col + 1) * cell`` and likewise in y."""
    ny, nx = zmin.shape
    for i in range(len(xyz)):
        c = min(max(math.floor((xyz[i, 0] - x0) / cell), 0), nx - 1)
        r = min(max(math.floor((xyz[i, 1] - y0) / cell), 0), ny - 1)
        if xyz[i, 2] < zmin[r, c]:
            zmin[r, c] = xyz[i, 2]


@njit(cache=True, nogil=True)
def bilinear(xyz, x0, y0, cell, grid, out):
    """``grid`` (values at the cell centres) interpolated bilinearly at the
    points' xy into ``out``; constant beyond the outer centres."""
    ny, nx = grid.shape
    for i in range(len(xyz)):
        u = (xyz[i, 0] - x0) / cell - 0.5
        v = (xyz[i, 1] - y0) / cell - 0.5
        u = min(max(u, 0.0), nx - 1.0)
        v = min(max(v, 0.0), ny - 1.0)
        c = min(int(u), max(nx - 2, 0))
        r = min(int(v), max(ny - 2, 0))
        fu = u - c if nx > 1 else 0.0
        fv = v - r if ny > 1 else 0.0
        c1 = min(c + 1, nx - 1)
        r1 = min(r + 1, ny - 1)
        top = grid[r, c] * (1.0 - fu) + grid[r, c1] * fu
        bottom = grid[r1, c] * (1.0 - fu) + grid[r1, c1] * fu
        out[i] = top * (1.0 - fv) + bottom * fv
