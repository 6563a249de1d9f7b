"""Scenes read tile by tile from the octree of a COPC file.

A COPC file (:mod:`skpcd.io._copc`) is indexed by space: the points of a
buffered tile are in the octree nodes whose cube meets the tile's square, so
each tile is read from the file when it is needed, by its bounds, and
nothing is spilled to disk. One pass over the x, y and z of the nodes
(:func:`octree_scene`, the other layers of the chunks are not decoded)
counts the points of each tile and finds the exact bounds of the scan, as
the spill of :func:`~skpcd.segmentation.tiling._spill.tile_scene` does: a
COPC header's bounds need not be those of its points, and the ground filter's
raster starts at the lowest point.

A tile read from the octree holds the same points, with the same float64
coordinates and the same indices (file order), as the spilled tile of the
same file: the nodes are those whose cube (grown by one quantum of the
coordinates) meets the buffered square, and their points are kept by the
test :meth:`~skpcd.segmentation.TileGrid.route` applies.
"""

import collections
import tempfile
import typing
from pathlib import Path

import numpy as np

from skpcd.io._copc import read_copc_index, read_nodes
from skpcd.segmentation.tiling._geometry import TileGrid, held_square
from skpcd.segmentation.tiling._scene import TiledScene
from skpcd.utils._geometry import point_bounds

__all__ = ["NodeCache", "OctreeScene", "OctreeTile", "octree_scene"]


_CACHE_POINTS = 2**22


class OctreeTile(typing.NamedTuple):
    """A buffered tile to read from a COPC file: the index of the nodes that
    may hold its points, the grid and the tile. Small, so it can be sent to
    a task that reads the file itself."""

    index: object  # CopcIndex of the tile's nodes
    grid: TileGrid
    tile: int

    def load(self, cache=None):
        """``(xyz, index)`` of the tile's points, in file order (as
        :meth:`TiledScene.load`); ``cache`` (a :class:`NodeCache`) keeps
        decoded nodes for the next tiles."""
        grid, b = self.grid, self.grid.buffer
        row, col = divmod(self.tile, grid.shape[0])
        parts, indices = [], []
        for node in range(len(self.index.count)):
            key = int(self.index.offset[node])
            xyz = None if cache is None else cache.get(key)
            if xyz is None:
                ((_, xyz),) = read_nodes(self.index, [node])
                if cache is not None:
                    cache.put(key, xyz)
            # the buffered tiles holding a point, as TileGrid.route finds them
            keep = (grid._cols(xyz[:, 0], 0, -b) <= col) & (
                grid._cols(xyz[:, 0], 0, b) >= col
            )
            keep &= (grid._cols(xyz[:, 1], 1, -b) <= row) & (
                grid._cols(xyz[:, 1], 1, b) >= row
            )
            rows = np.flatnonzero(keep)
            parts.append(xyz[rows])
            indices.append(rows + self.index.start[node])
        if not parts:
            return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
        return np.concatenate(parts), np.concatenate(indices)


class NodeCache:
    """Decoded nodes kept for the next tiles loaded in this process, up to
    ``budget`` points, the least recently used dropped first: neighbouring
    tiles share the nodes across their border, and every tile the upper
    levels of the octree."""

    def __init__(self, budget):
        self.budget = int(budget)
        self._nodes = collections.OrderedDict()
        self._size = 0

    def get(self, key):
        """The points of node ``key`` (None when not kept)."""
        xyz = self._nodes.get(key)
        if xyz is not None:
            self._nodes.move_to_end(key)
        return xyz

    def put(self, key, xyz):
        """Keep the points of node ``key`` (not when larger than the budget)."""
        if len(xyz) > self.budget:
            return
        self._nodes[key] = xyz
        self._size += len(xyz)
        while self._size > self.budget:
            _, old = self._nodes.popitem(last=False)
            self._size -= len(old)


class OctreeScene(TiledScene):
    """A scene read tile by tile from a COPC file (:func:`octree_scene`).

    As :class:`TiledScene`, but :meth:`load` reads the tile from the file's
    octree; :attr:`folder` holds no tile files (only what the tasks of a
    parallel backend use to check that they see this machine's files).

    Attributes
    ----------
    index : CopcIndex
        The file's octree.
    """

    def __init__(self, index, grid, folder, mins, maxs, counts, owned):
        super().__init__(grid, folder, index.n_points, mins, maxs, counts, owned)
        self.index = index
        # nodes decoded here are kept for the next tiles, up to twice the
        # points of the largest buffered tile or 4 M points (96 MB), which
        # holds the nodes shared by a row of tiles of most scans
        self._cache = NodeCache(max(2 * int(counts.max(initial=0)), _CACHE_POINTS))

    def path(self, tile):
        """The COPC file (every tile is read from it)."""
        return Path(self.index.path)

    def tile_reader(self, tile):
        """What reads the tile: an :class:`OctreeTile` with the nodes whose
        cube meets the buffered square (unbounded on the sides at the edge of
        the grid, whose tiles hold the points beyond)."""
        rows = self.index.nodes_in(*held_square(self.grid, tile, self.grid.buffer))
        return OctreeTile(self.index.subset(rows), self.grid, int(tile))

    def _load(self, tile):
        """The tile read from the octree, nodes decoded for earlier tiles reused."""
        return self.tile_reader(tile).load(self._cache)

    def close(self):
        """Drop the decoded nodes and delete the temporary folder."""
        self._cache = NodeCache(0)
        super().close()


def _census(index, grid):
    """Exact bounds of the points, and the points each tile owns and holds
    in its buffer: one pass over the x, y, z of every node (the bounds only
    when ``grid`` is None)."""
    n_tiles = 1 if grid is None else grid.n_tiles
    counts = np.zeros(n_tiles, dtype=np.int64)
    owned = np.zeros(n_tiles, dtype=np.int64)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for _, xyz in read_nodes(index, range(len(index.count))):
        lo_c, hi_c = point_bounds(xyz)
        lo, hi = np.minimum(lo, lo_c), np.maximum(hi, hi_c)
        if grid is None:
            continue
        owned += np.bincount(grid.owner(xyz), minlength=grid.n_tiles)
        counts += _held_counts(grid, xyz)
    return lo, hi, counts, owned


def _held_counts(grid, xyz):
    """Points in each buffered tile: each point adds one to the rectangle of
    tiles :meth:`TileGrid.route` puts it in, summed as a difference array
    (without listing the pairs)."""
    b, (nx, ny) = grid.buffer, grid.shape
    x0, x1 = grid._cols(xyz[:, 0], 0, -b), grid._cols(xyz[:, 0], 0, b) + 1
    y0, y1 = grid._cols(xyz[:, 1], 1, -b), grid._cols(xyz[:, 1], 1, b) + 1
    n = (nx + 1) * (ny + 1)
    diff = np.bincount(y0 * (nx + 1) + x0, minlength=n)
    diff -= np.bincount(y0 * (nx + 1) + x1, minlength=n)
    diff -= np.bincount(y1 * (nx + 1) + x0, minlength=n)
    diff += np.bincount(y1 * (nx + 1) + x1, minlength=n)
    held = diff.reshape(ny + 1, nx + 1).cumsum(axis=0).cumsum(axis=1)
    return held[:ny, :nx].ravel()


def octree_scene(path, tile_size, *, buffer=0.0, temp_folder=None):
    """The tiles of a COPC file, read from its octree when loaded.

    The grid is laid on the header's bounds, as :func:`tile_scene` lays it
    (on the points' bounds when the header's do not hold them).

    Parameters
    ----------
    path : str or path-like
        A COPC file.
    tile_size : float
        Side of the square tiles.
    buffer : float, default=0.0
        Overlap added on every side of each tile.
    temp_folder : str or path-like, default=None
        Where to create the scene's (nearly empty) temporary folder.

    Returns
    -------
    scene : OctreeScene
        The tiles; close it to delete its folder.
    """
    index = read_copc_index(path)
    if index.n_points == 0:
        raise ValueError("the scene has no points")
    mins, maxs = index.mins, index.maxs
    if not (np.all(np.isfinite(mins + maxs)) and np.all(mins <= maxs)):
        mins, maxs, _, _ = _census(index, None)  # a header without bounds
    grid = TileGrid.cover(mins, maxs, tile_size, buffer)
    lo, hi, counts, owned = _census(index, grid)
    end = np.array(grid.origin) + grid.size * np.array(grid.shape)
    if not (np.all(lo[:2] >= grid.origin) and np.all(hi[:2] <= end)):
        # a header whose bounds do not hold the points: tile on the true ones
        grid = TileGrid.cover(lo, hi, tile_size, buffer)
        lo, hi, counts, owned = _census(index, grid)
    folder = Path(tempfile.mkdtemp(prefix="skpcd_tiles_", dir=temp_folder))
    return OctreeScene(index, grid, folder, lo, hi, counts, owned)
