"""The square tiles of a scene: which tile owns a point, which buffered
tiles hold it, and the squares a tile's answers depend on."""

import math
import typing
from numbers import Real

import numpy as np

__all__ = ["TileGrid"]


class TileGrid(typing.NamedTuple):
    """Square tiles over the XY extent of a scene, with an overlap buffer.

    Tile ``t`` is row ``t // shape[0]``, column ``t % shape[0]``: its core
    square spans ``origin[0] + size * col`` to ``origin[0] + size * (col +
    1)`` in x, and likewise in y with the row. The core squares partition
    the plane: every point has exactly one *owner* tile (points beyond the
    grid belong to the nearest edge tile). The *buffered* tile is its core
    square grown by ``buffer`` on every side (a square, not a disk), so a
    point can be in the buffers of up to four tiles when ``buffer < size``.

    Build one with :meth:`cover`.

    Attributes
    ----------
    origin : tuple of float
        x and y of the corner of tile 0.
    size : float
        Side of the core squares.
    shape : tuple of int
        Tiles along x and along y.
    buffer : float
        Overlap added on every side of the core squares.
    """

    origin: tuple
    size: float
    shape: tuple
    buffer: float

    @classmethod
    def cover(cls, mins, maxs, size, buffer=0.0):
        """The grid of ``size`` squares covering ``mins`` to ``maxs`` in XY.

        Parameters
        ----------
        mins, maxs : array-like of shape (2+,)
            Lowest and highest x and y of the scene (z is ignored).
        size : float
            Side of the tiles, > 0.
        buffer : float, default=0.0
            Overlap, >= 0.

        Returns
        -------
        grid : TileGrid
            Tiles starting at ``mins``, enough of them to reach ``maxs``.

        Examples
        --------
        >>> from skpcd.segmentation import TileGrid
        >>> grid = TileGrid.cover([0, 0], [250, 90], 100, buffer=5)
        >>> grid.shape, grid.n_tiles
        ((3, 1), 3)
        """
        if not (isinstance(size, Real) and math.isfinite(size) and size > 0):
            raise ValueError(f"tile size must be a positive number, got {size!r}")
        if not (isinstance(buffer, Real) and math.isfinite(buffer) and buffer >= 0):
            raise ValueError(f"tile buffer must be a number >= 0, got {buffer!r}")
        lo = np.asarray(mins, dtype=np.float64)[:2]
        hi = np.asarray(maxs, dtype=np.float64)[:2]
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("the scene bounds must be finite")
        n = np.maximum(1, np.ceil((hi - lo) / size)).astype(np.int64)
        return cls(
            (float(lo[0]), float(lo[1])),
            float(size),
            (int(n[0]), int(n[1])),
            float(buffer),
        )

    @property
    def n_tiles(self):
        """Number of tiles."""
        return self.shape[0] * self.shape[1]

    def _cols(self, values, axis, shift=0.0):
        n = self.shape[axis]
        index = np.floor((values + shift - self.origin[axis]) / self.size)
        return np.clip(index, 0, n - 1).astype(np.int64)

    def owner(self, xy):
        """The tile owning each point (the one whose core square holds it).

        Parameters
        ----------
        xy : array-like of shape (n_points, 2+)
            Points; columns beyond the second are ignored.

        Returns
        -------
        tiles : ndarray of shape (n_points,), dtype int64
            Tile index of each point.
        """
        xy = np.asarray(xy, dtype=np.float64)
        return self._cols(xy[:, 1], 1) * self.shape[0] + self._cols(xy[:, 0], 0)

    def core_bounds(self, tile):
        """``(xmin, ymin, xmax, ymax)`` of a tile's core square."""
        row, col = divmod(int(tile), self.shape[0])
        x0 = self.origin[0] + self.size * col
        y0 = self.origin[1] + self.size * row
        return x0, y0, x0 + self.size, y0 + self.size

    def route(self, xy):
        """Every (point, tile) pair with the point in the buffered tile.

        Parameters
        ----------
        xy : array-like of shape (n_points, 2+)
            Points.

        Returns
        -------
        rows : ndarray of shape (n_pairs,), dtype int64
            Point of each pair, ascending within each tile.
        tiles : ndarray of shape (n_pairs,), dtype int64
            Tile of each pair. Pairs are sorted by tile, then by point.
        """
        xy = np.asarray(xy, dtype=np.float64)
        b = self.buffer
        lo = [self._cols(xy[:, a], a, -b) for a in (0, 1)]
        hi = [self._cols(xy[:, a], a, b) for a in (0, 1)]
        reach = math.ceil(2 * b / self.size) + 1
        rows, tiles = [], []
        every = np.arange(len(xy))
        for dy in range(reach + 1):
            ty = lo[1] + dy
            in_y = ty <= hi[1]
            for dx in range(reach + 1):
                tx = lo[0] + dx
                keep = in_y & (tx <= hi[0])
                rows.append(every[keep])
                tiles.append(ty[keep] * self.shape[0] + tx[keep])
        rows, tiles = np.concatenate(rows), np.concatenate(tiles)
        order = np.lexsort((rows, tiles))
        return rows[order], tiles[order]


def held_square(grid, tile, b):
    """``(xmin, ymin, xmax, ymax)`` of a tile's core square grown by ``b``
    (the buffer: the area whose points the buffered tile holds; 0: the
    points it owns), unbounded on the sides at the edge of the grid (edge
    tiles hold the points beyond)."""
    row, col = divmod(int(tile), grid.shape[0])
    x0, y0, x1, y1 = grid.core_bounds(tile)
    return (
        -np.inf if col == 0 else x0 - b,
        -np.inf if row == 0 else y0 - b,
        np.inf if col == grid.shape[0] - 1 else x1 + b,
        np.inf if row == grid.shape[1] - 1 else y1 + b,
    )


def reaches(grid, tile, queries, bounds):
    """Which queries have points of the tile's core square (unbounded at
    the grid's edges, where its own points may lie beyond) within their
    ``bounds`` (a square test: it holds every point of the ball)."""
    x0, y0, x1, y1 = held_square(grid, tile, 0.0)
    xy, r = queries[:, :2], bounds[:, None]
    return np.all(xy + r >= [x0, y0], axis=1) & np.all(xy - r <= [x1, y1], axis=1)
