"""A scene cut into buffered square tiles, one temporary file per tile.

:class:`TiledScene` is what :func:`~skpcd.segmentation.tile_scene` returns:
the grid, the counts, and the tiles, each read from its spill file by
:func:`load_tile` (or, for a COPC file, from the file's octree: the subclass
:class:`~skpcd.segmentation.tiling._octree.OctreeScene`).
"""

import os
import shutil
import typing
from pathlib import Path

import numpy as np

__all__ = ["RECORD", "SpillTile", "TiledScene", "load_tile"]

# One record per (point, buffered tile): coordinates and the point's index in
# the scan.
RECORD = np.dtype([("xyz", np.float64, (3,)), ("index", np.int64)])


class TiledScene:
    """A scene spilled to disk, one temporary file per buffered tile.

    Made by :func:`tile_scene`; use it as a context manager (or call
    :meth:`close`) to delete the files.

    Attributes
    ----------
    grid : TileGrid
        The tiles.
    folder : pathlib.Path
        The temporary folder holding the tile files.
    n_points : int
        Points in the scene.
    mins, maxs : ndarray of shape (3,)
        Exact bounds of the points (computed while routing).
    counts : ndarray of shape (n_tiles,), dtype int64
        Points in each buffered tile.
    """

    def __init__(self, grid, folder, n_points, mins, maxs, counts, owned):
        self.grid = grid
        self.folder = Path(folder)
        self.n_points = int(n_points)
        self.mins = mins
        self.maxs = maxs
        self.counts = counts
        self._owned = owned

    def owned_counts(self):
        """Points owned by each tile (its core square); they sum to ``n_points``.

        Returns
        -------
        counts : ndarray of shape (n_tiles,), dtype int64
            Owned points per tile.
        """
        return self._owned.copy()

    def path(self, tile):
        """The file of a tile (it may not exist when the tile is empty)."""
        return self.folder / f"tile_{int(tile)}.bin"

    def tile_reader(self, tile):
        """What reads the tile (its ``load()`` returns what :meth:`load`
        returns): small, for a task that reads the tile itself."""
        return SpillTile(str(self.path(tile)))

    def load(self, tile):
        """The points of a buffered tile, in scan order (file order for a
        file; for a COPC file, read from its octree).

        Parameters
        ----------
        tile : int
            Tile index.

        Returns
        -------
        xyz : ndarray of shape (n_tile_points, 3), dtype float64
            Points in the buffered tile.
        index : ndarray of shape (n_tile_points,), dtype int64
            Their indices in the scan, ascending.
        """
        return self._load(tile)

    def _load(self, tile):
        """The tile read from its spill file."""
        return load_tile(self.path(tile))

    def close(self):
        """Delete the temporary files."""
        shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SpillTile(typing.NamedTuple):
    """A buffered tile to read from its spill file."""

    path: str

    def load(self):
        """``(xyz, index)`` of the tile (see :func:`load_tile`)."""
        return load_tile(self.path)


def load_tile(path):
    """``(xyz, index)`` of a tile file (empty arrays when it does not exist)."""
    if not os.path.exists(path):
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    records = np.fromfile(path, dtype=RECORD)
    return np.ascontiguousarray(records["xyz"]), records["index"].copy()
