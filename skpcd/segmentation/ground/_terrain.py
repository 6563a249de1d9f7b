"""The terrain model a ground filter fits: patches of a raster of cells.

A patch is ``(c0, r0, objects, dem)``: the object flags and the terrain
height at the cell centres of a rectangle of cells whose first cell is
column ``c0``, row ``r0`` of the scene's raster. A scene that is one block
of cells has one patch, the whole raster; a scene of several islands of
occupied cells far apart has one patch per island and no terrain (NaN)
between them. The terrain is read at points by bilinear interpolation of
the cell centres, with the cells and weights of the whole raster.
"""

import numpy as np

from skpcd.segmentation.ground._raster import MAX_CELLS
from skpcd.segmentation.ground._raster_kernels import bilinear_rows
from skpcd.utils._parallel import parallel_rows

__all__ = ["Terrain", "slope_of"]


def slope_of(dem, cell):
    """Magnitude of the gradient of the terrain (central differences, one-
    sided at the edges; zero along an axis of a single cell)."""
    grads = [
        np.gradient(dem, cell, axis=a) if dem.shape[a] > 1 else np.zeros_like(dem)
        for a in (0, 1)
    ]
    return np.hypot(*grads)


class Terrain:
    """A fitted terrain model.

    Parameters
    ----------
    origin : ndarray of shape (2,)
        x and y of the corner of the first patch's raster (of the scene's
        raster when there are several patches).
    cell : float
        Side of the square cells.
    patches : list of tuple
        ``(c0, r0, objects, dem)`` each (see the module docstring).
    shape : tuple of int or None
        ``(n_rows, n_cols)`` of the scene's raster when the patches are
        islands of it; None when the one patch is the whole model.
    frame : tuple or None
        For one patch: where its cells lie, ``(x0, y0, nx, ny, c0, r0)``
        (the corner and size of the raster whose cells and weights the
        interpolation uses, and the patch's first cell in it); None for the
        patch's own raster, ``(*origin, n_cols, n_rows, 0, 0)``. A tile's
        window of a scene's raster gives the scene's raster here, so that
        it interpolates as the whole scene does.
    """

    def __init__(self, origin, cell, patches, shape=None, frame=None):
        self.origin = np.asarray(origin, dtype=np.float64)
        self.cell = float(cell)
        self.patches = patches
        self.shape = shape
        self._window = frame

    def frame(self, c0=0, r0=0, grid=None):
        """Where the cells of a patch lie: ``(x0, y0, nx, ny, c0, r0)``
        (see the class docstring); ``grid`` is the one patch's raster when
        the model is not made of islands."""
        x0, y0 = (float(v) for v in self.origin)
        if self.shape is not None:
            ny, nx = self.shape
            return (x0, y0, nx, ny, c0, r0)
        if self._window is not None:
            return self._window
        ny, nx = grid.shape
        return (x0, y0, nx, ny, 0, 0)

    def dense(self, k, fill):
        """Grid ``k`` of the patches (2: objects, 3: DEM) as one array of
        the scene's raster, ``fill`` between the islands."""
        if self.shape is None:
            return self.patches[0][k]
        ny, nx = self.shape
        if nx * ny > MAX_CELLS:
            raise ValueError(
                f"the raster of the scene has {nx * ny} cells (more than "
                f"{MAX_CELLS}), most far from every point; use height() or "
                "predict()"
            )
        out = np.full(self.shape, fill)
        for c0, r0, *grids in self.patches:
            g = grids[k - 2]
            out[r0 : r0 + g.shape[0], c0 : c0 + g.shape[1]] = g
        return out

    def at(self, frame, grid, xyz, n_threads):
        """``grid``, a raster placed by ``frame``, interpolated bilinearly at
        the points."""
        x0, y0, nx, ny, c0, r0 = frame
        out = np.empty(len(xyz))
        parallel_rows(
            bilinear_rows, len(xyz), n_threads,
            xyz, x0, y0, self.cell, nx, ny, c0, r0, grid, out,
        )  # fmt: skip
        return out

    def sample(self, xyz, slope, n_threads):
        """The DEM (or its slope, ``slope=True``) interpolated at the points;
        NaN at points outside every island."""
        if self.shape is None:
            dem = self.patches[0][3]
            grid = slope_of(dem, self.cell) if slope else dem
            return self.at(self.frame(grid=dem), grid, xyz, n_threads)
        out = np.full(len(xyz), np.nan)
        if not np.isfinite(xyz[:, :2]).all():
            raise ValueError("X contains NaN or infinite coordinates.")
        ny, nx = self.shape
        u = np.clip((xyz[:, :2] - self.origin) / self.cell, 0, [nx - 1, ny - 1])
        for c0, r0, _, dem in self.patches:
            h, w = dem.shape
            mine = np.flatnonzero(
                (u[:, 0] >= c0)
                & (u[:, 0] < c0 + w)
                & (u[:, 1] >= r0)
                & (u[:, 1] < r0 + h)
            )
            if len(mine):
                grid = slope_of(dem, self.cell) if slope else dem
                out[mine] = self.at(self.frame(c0, r0), grid, xyz[mine], n_threads)
        return out
