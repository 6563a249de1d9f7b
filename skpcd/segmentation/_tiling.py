"""Out-of-core scenes: square tiles with an overlap buffer, spilled to disk.

A scan larger than memory is read chunk by chunk (:func:`skpcd.io.iter_points`)
and each chunk is routed to the tiles whose buffered square it falls in, by
appending it to one temporary file per tile. A tile can then be loaded on
its own, with its buffer, and processed; memory is bounded by the largest
buffered tile, not by the scan.

:func:`segment_tiled` is the tiled :func:`~skpcd.segmentation.segment_scene`:
see its docstring for why the tiled answer is the untiled one.
"""

import math
import os
import shutil
import tempfile
import typing
from numbers import Integral, Real
from pathlib import Path

import numpy as np

from skpcd.segmentation._ground_kernels import bilinear, cell_minimum

__all__ = ["TileGrid", "TiledScene", "tile_scene"]

# One record per (point, buffered tile): coordinates and the point's index in
# the scan.
_RECORD = np.dtype([("xyz", np.float64, (3,)), ("index", np.int64)])


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
        >>> from skpcd.segmentation._tiling import TileGrid
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

    def load(self, tile):
        """The points of a buffered tile, in scan order.

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
        return _load_tile(self.path(tile))

    def close(self):
        """Delete the temporary files."""
        shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _load_tile(path):
    """``(xyz, index)`` of a tile file (empty arrays when it does not exist)."""
    if not os.path.exists(path):
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    records = np.fromfile(path, dtype=_RECORD)
    return np.ascontiguousarray(records["xyz"]), records["index"].copy()


def _is_path(source):
    return isinstance(source, (str, os.PathLike))


def iter_chunks(source, chunk_size, *, fields=None):
    """Chunks of xyz (float64, ``(n, 3)``) of a path or an array; with
    ``fields`` True, ``(xyz, extras)`` chunks with every field of the file,
    named as :func:`~skpcd.io.read_point_cloud` with ``fields="all"`` names
    them."""
    if _is_path(source):
        suffix = Path(os.fspath(source)).suffix.lower()
        if suffix in (".las", ".laz"):
            from skpcd.io import iter_points, read_las_extent
            from skpcd.io._ply import _group

            if not fields:
                yield from iter_points(source, chunk_size=chunk_size)
                return
            names = [
                n
                for n in read_las_extent(source).dimensions
                if n not in ("X", "Y", "Z")
            ]
            for xyz, extras in iter_points(source, chunk_size=chunk_size, fields=names):
                yield xyz, _group(extras)[0]
            return
        from skpcd.io import read_point_cloud

        # not out of core: no chunked reader for this format
        if fields:
            source, extras = read_point_cloud(source, fields="all")
            for start in range(0, len(source), chunk_size):
                stop = start + chunk_size
                yield (
                    source[start:stop],
                    {k: v[start:stop] for k, v in extras.items()},
                )
            return
        source = read_point_cloud(source)
    from skpcd.segmentation._clusters import check_scene

    xyz = check_scene(source)
    for start in range(0, len(xyz), chunk_size):
        chunk = xyz[start : start + chunk_size]
        yield (chunk, {}) if fields else chunk


def scene_bounds(source, chunk_size):
    """``(mins, maxs)`` of a scene for laying out tiles: the LAS header for
    LAS/LAZ files (no pass over the points), else the points."""
    if _is_path(source) and Path(os.fspath(source)).suffix.lower() in (".las", ".laz"):
        from skpcd.io import read_las_extent

        extent = read_las_extent(source)
        return extent.mins, extent.maxs
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for xyz in iter_chunks(source, chunk_size):
        if len(xyz):
            lo = np.minimum(lo, xyz.min(axis=0))
            hi = np.maximum(hi, xyz.max(axis=0))
    return lo, hi


def _check_chunk_size(chunk_size):
    if (
        isinstance(chunk_size, bool)
        or not isinstance(chunk_size, Integral)
        or chunk_size < 1
    ):
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    return int(chunk_size)


def tile_scene(
    source,
    tile_size,
    *,
    buffer=0.0,
    chunk_size=1_000_000,
    temp_folder=None,
    _bounds=None,
):
    """Cut a scene into buffered square tiles spilled to temporary files.

    The scene is read chunk by chunk (a LAS/LAZ file through
    :func:`skpcd.io.iter_points`; other files are read whole) and every
    point is appended to the file of each buffered tile holding it, so
    memory holds one chunk at a time.

    Parameters
    ----------
    source : str, path-like or array-like of shape (n_points, 3+)
        A point-cloud file or the points.
    tile_size : float
        Side of the square tiles, in the units of the coordinates.
    buffer : float, default=0.0
        Overlap added on every side of each tile.
    chunk_size : int, default=1_000_000
        Points read at a time.
    temp_folder : str or path-like, default=None
        Where to create the temporary folder of tile files (the system's
        temporary folder when None). It needs room for the points of all
        buffered tiles: 32 bytes per point and tile.

    Returns
    -------
    scene : TiledScene
        The tiles; close it (or use it in a ``with`` block) to delete the
        files.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation._tiling import tile_scene
    >>> points = np.random.default_rng(0).uniform(0, 100, (1000, 3))
    >>> with tile_scene(points, 50, buffer=5) as scene:
    ...     xyz, index = scene.load(0)
    ...     print(scene.grid.shape, int(scene.owned_counts().sum()))
    ...     inside = np.all(xyz[:, :2] <= np.add(scene.grid.origin, 50 + 5))
    ...     print(bool(inside), bool(np.all(np.diff(index) > 0)))
    (2, 2) 1000
    True True
    """
    chunk_size = _check_chunk_size(chunk_size)
    mins, maxs = scene_bounds(source, chunk_size) if _bounds is None else _bounds
    if not np.all(mins <= maxs):
        raise ValueError("the scene has no points")
    grid = TileGrid.cover(mins, maxs, tile_size, buffer)
    folder = Path(tempfile.mkdtemp(prefix="skpcd_tiles_", dir=temp_folder))
    counts = np.zeros(grid.n_tiles, dtype=np.int64)
    owned = np.zeros(grid.n_tiles, dtype=np.int64)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    start = 0
    try:
        for xyz in iter_chunks(source, chunk_size):
            if not len(xyz):
                continue
            if not np.all(np.isfinite(xyz)):
                raise ValueError("the scene has NaN or infinite coordinates")
            lo = np.minimum(lo, xyz.min(axis=0))
            hi = np.maximum(hi, xyz.max(axis=0))
            owned += np.bincount(grid.owner(xyz), minlength=grid.n_tiles)
            rows, tiles = grid.route(xyz)
            records = np.empty(len(rows), dtype=_RECORD)
            records["xyz"] = xyz[rows]
            records["index"] = rows + start
            bounds = np.flatnonzero(np.diff(tiles)) + 1
            for part in np.split(np.arange(len(rows)), bounds):
                if len(part):
                    tile = int(tiles[part[0]])
                    with open(folder / f"tile_{tile}.bin", "ab") as f:
                        records[part[0] : part[-1] + 1].tofile(f)
                    counts[tile] += len(part)
            start += len(xyz)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    if start == 0:
        shutil.rmtree(folder, ignore_errors=True)
        raise ValueError("the scene has no points")
    end = np.array(grid.origin) + grid.size * np.array(grid.shape)
    if _bounds is None and not (
        np.all(lo[:2] >= grid.origin) and np.all(hi[:2] <= end)
    ):
        # a LAS header whose bounds do not hold the points: tile again on
        # the true bounds (edge tiles would own points beyond their square)
        shutil.rmtree(folder, ignore_errors=True)
        return tile_scene(
            source, tile_size, buffer=buffer, chunk_size=chunk_size,
            temp_folder=temp_folder, _bounds=(lo, hi),
        )  # fmt: skip
    return TiledScene(grid, folder, start, lo, hi, counts, owned)


# --- the ground filter on a window of the scene's raster -------------------


def _window_filter(base):
    """A GroundFilter class fitted on a window of the whole scene's raster."""
    from skpcd.segmentation._ground import GroundFilter

    class _WindowGroundFilter(GroundFilter):
        # Same parameters and steps as GroundFilter; only the raster is a
        # window (``_raster``: scene origin, scene cells, window start and
        # size) of the raster of the whole scene, so cells and
        # interpolation weights are those of the untiled filter.

        def _minimum_surface(self, xyz):
            x0, y0, nx, ny, c0, r0, wx, wy = self._raster
            zmin = np.full((wy, wx), np.inf)
            cell_minimum(xyz, x0, y0, float(self.cell), nx, ny, c0, r0, zmin)
            return np.array([x0 + c0 * self.cell, y0 + r0 * self.cell]), zmin

        def _at(self, grid, xyz):
            x0, y0, nx, ny, c0, r0, _, _ = self._raster
            out = np.empty(len(xyz))
            bilinear(xyz, x0, y0, float(self.cell), nx, ny, c0, r0, grid, out)
            return out

    return _WindowGroundFilter(**base.get_params())


def ground_reach(filt):
    """How far (in metres) the ground filter's answer at a point depends on
    the points around it: :func:`~skpcd.segmentation._ground.reach_cells`
    cells beyond the point's own, plus one for the rounding of the tile and
    cell edges."""
    from skpcd.segmentation._ground import reach_cells

    return (reach_cells(filt) + 1) * float(filt.cell)


def _ground_prepare(xyz, index, ground, tile, grid, lo, nxy, cell, reach):
    """The points of a buffered tile in the cells of its core square grown by
    the ground filter's reach, with the window of the scene's raster they
    span; and the scan indices of the tile's own points."""
    owned = grid.owner(xyz) == tile
    x0, y0, x1, y1 = grid.core_bounds(tile)
    start = np.floor((np.array([x0, y0]) - reach - lo) / cell).astype(np.int64)
    stop = np.floor((np.array([x1, y1]) + reach - lo) / cell).astype(np.int64)
    start = np.clip(start, 0, nxy - 1)
    stop = np.clip(stop, 0, nxy - 1)
    cells = np.clip(np.floor((xyz[:, :2] - lo) / cell), 0, nxy - 1).astype(np.int64)
    sel = np.all((cells >= start) & (cells <= stop), axis=1)
    raster = (
        float(lo[0]), float(lo[1]), int(nxy[0]), int(nxy[1]),
        int(start[0]), int(start[1]),
        int(stop[0] - start[0] + 1), int(stop[1] - start[1] + 1),
    )  # fmt: skip
    return (np.ascontiguousarray(xyz[sel]), owned[sel], raster), index[owned]


def _ground_tile(xyz, owned, raster, filt, n_threads):
    """Ground flags of the owned points of a buffered tile."""
    est = _window_filter(filt)
    est._raster = raster
    if len(xyz) == 0:
        return np.zeros(0, dtype=bool)
    est.fit(xyz)
    return est.ground_[owned]


def _cluster_prepare(xyz, index, ground, tile, grid, reach):
    """The non-ground points of a buffered tile within ``reach`` of its core
    square (and its own points); their scan indices and which are its own."""
    owned = grid.owner(xyz) == tile
    x0, y0, x1, y1 = grid.core_bounds(tile)
    x, y = xyz[:, 0], xyz[:, 1]
    sel = (
        (x >= x0 - reach) & (x <= x1 + reach)
        & (y >= y0 - reach) & (y <= y1 + reach)
    )  # fmt: skip
    sel |= owned
    sel &= ~ground
    return (np.ascontiguousarray(xyz[sel]), owned[sel]), (index[sel], owned[sel])


def _cluster_tile(xyz, owned, eps, min_samples, n_threads):
    """DBSCAN of the non-ground points of a buffered tile: labels of the
    owned points, and the positions and labels of the other core points."""
    from skpcd.segmentation._clusters import grid_dbscan

    labels, core = grid_dbscan(xyz, eps, min_samples, n_jobs=n_threads)
    shared = np.flatnonzero(core & ~owned)
    return labels[owned], shared, labels[shared]


def _held_square(grid, tile, b):
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


def _eps_prepare(xyz, index, ground, tile, grid, queries):
    """The non-ground points of a buffered tile and, among its own points,
    the queries of the eps estimate with their distance to the edge of the
    area the tile holds; the scan indices of those queries."""
    mine = np.flatnonzero(grid.owner(xyz) == tile)
    mine = mine[np.isin(index[mine], queries)]
    if not len(mine):
        return (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)), index[mine]
    x0, y0, x1, y1 = _held_square(grid, tile, grid.buffer)
    q = xyz[mine]
    margin = np.minimum(
        np.minimum(q[:, 0] - x0, x1 - q[:, 0]), np.minimum(q[:, 1] - y0, y1 - q[:, 1])
    )
    return (np.ascontiguousarray(xyz[~ground]), q, margin), index[mine]


def _eps_tile(points, queries, margin, k, n_threads):
    """Distances from each query to its ``k`` nearest ``points`` (itself
    first), and which are exact: those whose ``k``-th neighbour is nearer
    than the edge of the tile's area (``margin``), so that no point beyond
    it could be nearer; the others (isolated points, whose neighbours are
    far) come with their coordinates, for :func:`_eps_far_queries`."""
    from scipy.spatial import cKDTree

    if not len(queries):
        return np.zeros((0, k)), np.ones(0, dtype=bool), np.zeros((0, 3))
    tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
    d, _ = tree.query(queries, k=k, workers=n_threads)
    d = d.reshape(len(queries), -1)
    exact = d[:, -1] + 1e-6 < margin
    return d, exact, queries[~exact]


def _reaches(grid, tile, queries, bounds):
    """Which queries have points of the tile's core square (unbounded at
    the grid's edges, where its own points may lie beyond) within their
    ``bounds`` (a square test: it holds every point of the ball)."""
    x0, y0, x1, y1 = _held_square(grid, tile, 0.0)
    xy, r = queries[:, :2], bounds[:, None]
    return np.all(xy + r >= [x0, y0], axis=1) & np.all(xy - r <= [x1, y1], axis=1)


def _far_prepare(xyz, index, ground, tile, grid, queries, bounds):
    """The non-ground points a tile owns, and the queries (rows of
    ``queries``) whose ball of radius ``bounds`` reaches its core square
    (unbounded at the grid's edges, like the area its points come from)."""
    near = np.flatnonzero(_reaches(grid, tile, queries, bounds))
    own = (grid.owner(xyz) == tile) & ~ground
    if not len(near) or not own.any():
        return (np.zeros((0, 3)), np.zeros((0, 3))), np.zeros(0, dtype=np.int64)
    return (np.ascontiguousarray(xyz[own]), queries[near]), near


def _far_tile(points, queries, k, n_threads):
    """Distances from each query to its ``k`` nearest ``points`` (+inf when
    there are fewer)."""
    from scipy.spatial import cKDTree

    if not len(queries):
        return np.zeros((0, k))
    tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
    d, _ = tree.query(queries, k=k, workers=n_threads)
    return d.reshape(len(queries), -1)


def _eps_far_queries(scene, tiles, ground, queries, bounds, k, n_jobs):
    """The exact distances from each query to its ``k`` nearest non-ground
    points, for queries whose neighbours their own tile may not hold:
    each tile whose core square is within ``bounds`` of a query (the
    distance of its ``k``-th neighbour found in its tile, which the true one
    cannot exceed) gives the ``k`` nearest of the points it owns, and the
    ``k`` smallest of those distances are the query's (every point is owned
    by one tile)."""
    near = [t for t in tiles if _reaches(scene.grid, t, queries, bounds).any()]
    parts = [[] for _ in range(len(queries))]
    for rows, d in _map_tiles(
        scene, near, _far_prepare, (scene.grid, queries, bounds), _far_tile,
        (k,), n_jobs, ground=ground,
    ):  # fmt: skip
        for row, dist in zip(rows.tolist(), d):
            parts[row].append(dist)
    found = np.empty((len(queries), k))
    for row, dists in enumerate(parts):
        found[row] = np.sort(np.concatenate(dists))[:k]
    return found


# --- tiled segmentation ---------------------------------------------------
#
# Each pass (ground, eps, clusters) maps a function over the tiles in two
# steps: ``prepare(xyz, index, ground, tile, *pargs)`` cuts from the buffered
# tile what the pass needs, returning ``(args, info)``, and
# ``compute(*args, *cargs, n_threads)`` does the work; ``info`` (scan
# indices) tells the driver where the result goes. In this process, or when
# the tasks of a joblib backend see this machine's files, each task reads
# its tile from the spill file and prepares it itself (the driver only
# sends the tile's name); else the driver reads and prepares the tile and
# ships the prepared arrays.


class _TileRef(typing.NamedTuple):
    """A tile for a task to read itself: its spill file, the scene's token
    (file, content) that proves the task sees this machine's files, and
    the scene's ground flags file (None when the pass does not need it)."""

    path: str
    token: tuple
    ground: str | None


def _read_ref(ref):
    """``(xyz, index, ground)`` of a tile reference, or None when the token
    file is not there with the same content (another machine's files)."""
    try:
        with open(ref.token[0], encoding="ascii") as f:
            if f.read() != ref.token[1]:
                return None
        xyz, index = _load_tile(ref.path)
        ground = None
        if ref.ground is not None:
            ground = np.asarray(np.load(ref.ground, mmap_mode="r")[index])
    except OSError:
        return None
    return xyz, index, ground


_HEAP = []


def _heap_for_arrays():
    """Let glibc serve array temporaries from the heap in a Dask worker.

    A Dask nanny starts its worker with ``MALLOC_TRIM_THRESHOLD_`` set,
    which also fixes glibc's mmap threshold at 128 KiB: every temporary
    array above that is then a fresh mapping whose pages the kernel faults
    in and zeroes, which made the tile steps two to three times slower on a
    worker than in the driver. Raising the threshold to glibc's own upper
    bound (32 MiB) undoes that; the heap is still trimmed after each tile
    (:func:`~skpcd.utils._parallel.release_free_memory`), which is what the
    setting is for. Once per process, and only where the variable is set.
    """
    if _HEAP:
        return _HEAP[0]
    ok = False
    if "MALLOC_TRIM_THRESHOLD_" in os.environ:
        try:
            import ctypes

            ok = bool(ctypes.CDLL("libc.so.6").mallopt(-3, 32 * 2**20))
        except (OSError, AttributeError):  # not glibc
            ok = False
    _HEAP.append(ok)
    return ok


def _tile_call(job, n_threads):
    """One tile of :func:`_map_tiles`: ``(info, result)``; ``info`` is None
    for a shipped tile (the driver has it), and None is returned for a
    tile reference the task cannot read."""
    if _heap_for_arrays():
        from skpcd.utils._parallel import release_free_memory

        try:
            return _tile_call_inner(job, n_threads)
        finally:
            release_free_memory()
    return _tile_call_inner(job, n_threads)


def _tile_call_inner(job, n_threads):
    tile, t, prepare, pargs, compute, cargs = job
    if isinstance(tile, _TileRef):
        data = _read_ref(tile)
        if data is None:
            return None
        tile, info = prepare(*data, t, *pargs)
        return info, compute(*tile, *cargs, n_threads)
    return None, compute(*tile, *cargs, n_threads)


_LOCAL_BACKENDS = ("ThreadingBackend", "LokyBackend", "MultiprocessingBackend")


def _local_hosts():
    """Names and addresses of this machine."""
    import socket

    names = {"127.0.0.1", "localhost", "::1", "0.0.0.0"}
    try:
        host = socket.gethostname()
        names.add(host)
        names.update(socket.gethostbyname_ex(host)[2])
    except OSError:  # pragma: no cover - no name resolution
        pass
    return names


def _shares_files(backend):
    """Whether the tasks of a joblib ``backend`` run on this machine, so that
    they can read the tile files: joblib's own backends (threads and
    processes here), and Dask when every worker has an address of this
    machine (a ``LocalCluster``). Any other backend gets shipped tiles."""
    from skpcd.utils._parallel import _dask_hosts

    if type(backend).__name__ in _LOCAL_BACKENDS:
        return True
    hosts = _dask_hosts(backend)
    return bool(hosts) and set(hosts) <= _local_hosts()


def _scene_token(scene):
    """``(file, content)`` of a random token written in the scene's folder."""
    token = getattr(scene, "_token", None)
    if token is None:
        import secrets

        token = (str(scene.folder / "token"), secrets.token_hex(16))
        with open(token[0], "w", encoding="ascii") as f:
            f.write(token[1])
        scene._token = token
    return token


def _map_tiles(scene, tiles, prepare, pargs, compute, cargs, n_jobs, ground=None):
    """``(info, compute(*args, *cargs, n_threads))`` for each tile of
    ``tiles``, ``(args, info) = prepare(xyz, index, ground[index], tile,
    *pargs)``, in order, lazily (one tile in memory at a time, or one per
    running task).

    As :func:`skpcd.utils._parallel.map_batches`, of which this is the
    streaming form for tiles: in this process with ``n_jobs`` threads per
    call unless a joblib backend was chosen (``parallel_config``); then
    through :class:`sklearn.utils.parallel.Parallel` (on a Dask cluster
    inside ``parallel_config(backend="dask")``), ``n_jobs`` tiles at once
    (None: the context's), each with the cores left to its task.

    On a backend whose tasks run on this machine (:func:`_shares_files`),
    a task gets the tile's name and reads and prepares the tile itself,
    and up to two tiles per running task are sent ahead; the driver reads
    nothing. A task that does not find the scene's token (a worker with
    other files under the same name) returns None: that tile, and those
    already sent, are then computed here, and the following ones shipped.
    Elsewhere the driver reads and prepares each tile and ships its arrays,
    one tile per running task in flight. ``ground`` is ``(flags, path)``:
    the scan's ground flags and the file they are mapped from (flushed
    before the tasks read it), or None.
    """
    import collections

    from skpcd.utils._parallel import (
        _chosen_backend,
        _dask_hosts,
        _run_batch,
        effective_threads,
    )

    flags, flags_path = (None, None) if ground is None else ground

    def here(t, n_threads):
        xyz, index = scene.load(t)
        g = None if flags is None else np.asarray(flags[index])
        args, info = prepare(xyz, index, g, t, *pargs)
        return info, compute(*args, *cargs, n_threads)

    backend = _chosen_backend()
    if backend is None:
        for t in tiles:
            yield here(t, n_jobs)
        return
    from joblib import cpu_count, effective_n_jobs
    from sklearn.utils.parallel import Parallel, delayed

    n_tasks = max(1, int(effective_n_jobs(n_jobs)))
    inner = getattr(backend, "inner_max_num_threads", None)
    n_threads = inner or max(1, cpu_count() // n_tasks)
    hosts = None if inner else _dask_hosts(backend)
    shared = [_shares_files(backend)]
    if shared[0]:
        token = _scene_token(scene)
        if flags is not None:
            flags.flush()
    pending = collections.deque()

    def jobs():
        for t in tiles:
            if shared[0]:
                tile = _TileRef(str(scene.path(t)), token, flags_path)
                job = (tile, t, prepare, pargs, compute, cargs)
                pending.append((t, None))
            else:
                xyz, index = scene.load(t)
                g = None if flags is None else np.asarray(flags[index])
                tile, info = prepare(xyz, index, g, t, *pargs)
                del xyz, index, g
                job = (tile, t, None, (), compute, cargs)
                pending.append((t, info))
            yield delayed(_run_batch)(_tile_call, job, n_threads, hosts)

    pre_dispatch = "2 * n_jobs" if shared[0] else "n_jobs"
    for out in Parallel(
        n_jobs=n_jobs, batch_size=1, pre_dispatch=pre_dispatch, return_as="generator"
    )(jobs()):
        t, info = pending.popleft()
        if out is None:  # the task did not see our files: here, then ship
            shared[0] = False
            yield here(t, effective_threads(n_jobs))
            continue
        mine, result = out
        yield (info if mine is None else mine), result


def _estimate_eps(
    scene, tiles, ground, min_samples, eps_scale, random_state, n_jobs,
    chunk_size,
):  # fmt: skip
    """The eps of :class:`AutoEpsDBSCAN` for the non-ground points of the
    whole scan, computed tile by tile: the same random sample of query points
    as the untiled estimate (drawn among all non-ground points, in scan
    order), their nearest neighbours searched among the non-ground points of
    their buffered tile, which holds all of them when the k-th neighbour is
    nearer than the edge of the tile's area; for the other queries (isolated
    points), among the points of every tile within that distance
    (:func:`_eps_far_queries`). The distances are those of the untiled
    search, so is the estimate."""
    from sklearn.utils import check_random_state

    from skpcd.segmentation._dbscan import AutoEpsDBSCAN, _fit_knee, eps_from_knee

    is_ground = ground[0]
    est = AutoEpsDBSCAN(
        min_samples=min_samples, eps_scale=eps_scale, random_state=random_state
    )
    n = 0
    for start in range(0, scene.n_points, chunk_size):
        n += int((~is_ground[start : start + chunk_size]).sum())
    if n < 2:
        return 0.0
    k_max = min(int(est.n_neighbors), n - 1)
    if est.max_samples is not None and n > est.max_samples:
        rng = check_random_state(random_state)
        ranks = np.sort(rng.choice(n, int(est.max_samples), replace=False))
    else:
        ranks = np.arange(n)
    # scan index of each query: its rank among the non-ground points
    queries, seen = [], 0
    for start in range(0, scene.n_points, chunk_size):
        rest = np.flatnonzero(~is_ground[start : start + chunk_size])
        lo, hi = np.searchsorted(ranks, [seen, seen + len(rest)])
        queries.append(rest[ranks[lo:hi] - seen] + start)
        seen += len(rest)
    queries = np.concatenate(queries)
    dist = np.empty((len(queries), k_max + 1))
    far_rows, far_xyz, far_bounds = [], [], []
    for index, (d, exact, xyz) in _map_tiles(
        scene, tiles, _eps_prepare, (scene.grid, queries), _eps_tile,
        (k_max + 1,), n_jobs, ground=ground,
    ):  # fmt: skip
        if len(index):
            rows = np.searchsorted(queries, index)
            dist[rows] = d
            far_rows.append(rows[~exact])
            far_xyz.append(xyz)
            far_bounds.append(d[~exact, -1])
    if far_rows and sum(map(len, far_rows)):
        # isolated queries: their neighbours searched in every tile near
        rows = np.concatenate(far_rows)
        dist[rows] = _eps_far_queries(
            scene, tiles, ground, np.concatenate(far_xyz),
            np.concatenate(far_bounds), k_max + 1, n_jobs,
        )  # fmt: skip
    mean = dist[:, 1:].mean(axis=0)
    _, _, knee_distance = _fit_knee(np.arange(1, k_max + 1), mean, est.degree)
    # as AutoEpsDBSCAN._estimate (test_tiling checks the two estimates agree)
    return eps_from_knee(knee_distance, est.eps_scale)


def _result_array(folder, name, n, dtype, fill):
    arr = np.lib.format.open_memmap(folder / name, mode="w+", dtype=dtype, shape=(n,))
    arr[:] = fill
    return arr


def _detach(arr, path):
    """``arr`` (a memory map of ``path``) with the file unlinked where the
    system allows (the mapping keeps the data); else a copy in memory."""
    arr.flush()
    if os.name == "posix":
        os.unlink(path)
        return arr
    return np.array(arr)


def segment_tiled(
    source,
    *,
    tile_size,
    tile_buffer,
    ground,
    method,
    eps,
    min_samples,
    min_cluster_size,
    max_cluster_size,
    random_state,
    n_jobs,
    eps_scale,
    chunk_size=1_000_000,
    temp_folder=None,
):
    """The tiled path of :func:`~skpcd.segmentation.segment_scene`.

    ``ground`` is a GroundFilter (the preset resolved) or None; the other
    arguments are those of ``segment_scene``, validated. Returns
    ``(labels, ground, eps)`` as memory-mapped arrays (file already
    unlinked on POSIX systems).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    chunk_size = _check_chunk_size(chunk_size)
    if method == "euclidean":
        eps, min_samples = (0.2 if eps is None else float(eps)), 1
    reach = 0.0 if ground is None else ground_reach(ground)
    margin = 0.0 if ground is None else 2 * float(ground.cell)
    if tile_buffer is None:
        need = [reach + margin]
        if eps is not None:
            need.append(2 * eps)
        elif ground is None:
            need.append(0.25 * tile_size)
        buffer = 1.01 * max(need) + 1e-6
    else:
        buffer = float(tile_buffer)
    ground_buffer = max(0.0, min(reach, buffer - margin))
    if eps is not None and 2 * eps > buffer:
        raise ValueError(
            f"tile_buffer={buffer:g} is too small for eps={eps:g}: the stitching "
            f"of segments across tiles needs at least 2 * eps = {2 * eps:g}"
        )
    scene = tile_scene(
        source, tile_size, buffer=buffer, chunk_size=chunk_size,
        temp_folder=temp_folder,
    )  # fmt: skip
    out = Path(tempfile.mkdtemp(prefix="skpcd_labels_", dir=temp_folder))
    try:
        grid, n = scene.grid, scene.n_points
        tiles = np.flatnonzero(scene.owned_counts())
        is_ground = _result_array(out, "ground.npy", n, np.bool_, False)
        labels = _result_array(out, "labels.npy", n, np.int64, -1)

        ground_flags = (is_ground, str(out / "ground.npy"))

        # 1. ground: each tile's filter on the cells of its core square grown
        # by the filter's reach, cut from the raster of the whole scene
        if ground is not None:
            cell = float(ground.cell)
            lo = scene.mins[:2]
            nxy = (np.floor((scene.maxs[:2] - lo) / cell) + 1).astype(np.int64)
            for index, flags in _map_tiles(
                scene, tiles, _ground_prepare, (grid, lo, nxy, cell, ground_buffer),
                _ground_tile, (ground,), n_jobs,
            ):  # fmt: skip
                is_ground[index] = flags

        # 2. eps, once for the whole scan (see _estimate_eps)
        if eps is None:
            eps = _estimate_eps(
                scene, tiles, ground_flags, min_samples, eps_scale,
                random_state, n_jobs, chunk_size,
            )  # fmt: skip
            if 2 * eps > buffer:
                raise ValueError(
                    f"the estimated eps={eps:g} needs a tile buffer of at least "
                    f"2 * eps = {2 * eps:g}, more than tile_buffer={buffer:g}; "
                    "pass a larger tile_buffer or give eps"
                )

        # 3. clusters: each tile's DBSCAN on its non-ground points within
        # 2 * eps of its core square; owned points keep its labels, core
        # points shared with another tile link the two tiles' clusters
        if eps > 0:
            reach_c = 2 * eps * (1 + 1e-9) + 1e-9
            n_local, links = 0, []
            for (index, owned), (own_labels, shared, shared_labels) in _map_tiles(
                scene, tiles, _cluster_prepare, (grid, reach_c), _cluster_tile,
                (eps, min_samples), n_jobs, ground=ground_flags,
            ):  # fmt: skip
                labels[index[owned]] = np.where(
                    own_labels >= 0, own_labels + n_local, -1
                )
                links.append(np.column_stack([index[shared], shared_labels + n_local]))
                n_top = max(
                    int(own_labels.max(initial=-1)), int(shared_labels.max(initial=-1))
                )
                n_local += n_top + 1
            # union of the clusters through their shared core points
            links = np.concatenate(links) if links else np.zeros((0, 2), np.int64)
            other = labels[links[:, 0]] if len(links) else np.zeros(0, np.int64)
            if np.any(other < 0):  # pragma: no cover - the buffer rule forbids it
                raise RuntimeError("a shared core point is not core in its own tile")
            graph = coo_matrix(
                (np.ones(len(links)), (links[:, 1], other)), shape=(n_local, n_local)
            )
            _, component = connected_components(graph, directed=False)
            # sizes and first point of each segment, then the size range and
            # the numbering of the untiled run (order of the first point)
            n_comp = int(component.max(initial=-1)) + 1
            sizes = np.zeros(n_comp, dtype=np.int64)
            first = np.full(n_comp, n, dtype=np.int64)
            for start in range(0, n, chunk_size):
                part = labels[start : start + chunk_size]
                comp = component[part[part >= 0]]
                sizes += np.bincount(comp, minlength=n_comp)
                pos = np.flatnonzero(part >= 0) + start
                np.minimum.at(first, comp, pos)
            keep = sizes >= min_cluster_size
            if max_cluster_size is not None:
                keep &= sizes <= max_cluster_size
            number = np.full(n_comp, -1, dtype=np.int64)
            kept = np.flatnonzero(keep)
            number[kept[np.argsort(first[kept], kind="stable")]] = np.arange(len(kept))
            final = np.append(number[component], -1)  # index -1: no cluster
            for start in range(0, n, chunk_size):
                part = labels[start : start + chunk_size]
                part[:] = final[part]
        result = (
            _detach(labels, out / "labels.npy"),
            _detach(is_ground, out / "ground.npy"),
            float(eps),
        )
    finally:
        scene.close()
        shutil.rmtree(out, ignore_errors=True)
    return result
