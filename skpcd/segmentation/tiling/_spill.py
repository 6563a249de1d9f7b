"""Out-of-core scenes: buffered square tiles spilled to temporary files.

A scan larger than memory is read chunk by chunk
(:func:`skpcd.io._chunks.iter_file_chunks`) and each chunk is routed to the
tiles whose buffered square it falls in (:class:`TileGrid`), by appending it
to one temporary file per tile. A tile can then be loaded on its own, with
its buffer, and processed; memory is bounded by the largest buffered tile,
not by the scan (the scene and its tile files: :mod:`._scene`). A COPC
file is not spilled: its tiles are read from its octree (:mod:`._octree`).
The per-tile results go to memory-mapped arrays (:func:`result_array`,
:func:`detach`).
"""

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from skpcd.io._api import read_point_cloud
from skpcd.io._chunks import file_bounds, is_path, is_streamed, iter_file_chunks
from skpcd.io._common import check_chunk_size
from skpcd.io._copc import is_copc
from skpcd.segmentation.tiling._geometry import TileGrid
from skpcd.segmentation.tiling._octree import octree_scene
from skpcd.segmentation.tiling._scene import RECORD, SpillTile, TiledScene, load_tile
from skpcd.utils._geometry import point_bounds
from skpcd.utils._validation import check_scene

__all__ = [
    "SpillTile",
    "TiledScene",
    "detach",
    "iter_chunks",
    "load_tile",
    "result_array",
    "scene_bounds",
    "tile_scene",
]


def iter_chunks(source, chunk_size, *, fields=None):
    """Chunks of xyz (float64, ``(n, 3)``) of a path or an array; with
    ``fields`` True, ``(xyz, extras)`` chunks with every field of the file,
    named as :func:`~skpcd.io.read_point_cloud` with ``fields="all"`` names
    them."""
    if is_path(source):
        if fields or is_streamed(source):
            yield from iter_file_chunks(source, chunk_size, fields=fields)
            return
        source = read_point_cloud(source)  # read whole: no chunked reader
    xyz = check_scene(source)
    for start in range(0, len(xyz), chunk_size):
        chunk = xyz[start : start + chunk_size]
        yield (chunk, {}) if fields else chunk


def scene_bounds(source, chunk_size):
    """``(mins, maxs)`` of a scene for laying out tiles: the LAS header for
    LAS/LAZ files (no pass over the points), else the points."""
    if is_path(source):
        bounds = file_bounds(source)
        if bounds is not None:
            return bounds
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for xyz in iter_chunks(source, chunk_size):
        if len(xyz):
            lo_c, hi_c = point_bounds(xyz)
            lo, hi = np.minimum(lo, lo_c), np.maximum(hi, hi_c)
    return lo, hi


def tile_scene(
    source,
    tile_size,
    *,
    buffer=0.0,
    chunk_size=1_000_000,
    temp_folder=None,
    unit=1.0,
    _bounds=None,
):
    """Cut a scene into buffered square tiles spilled to temporary files.

    The scene is read chunk by chunk (a LAS/LAZ file through
    :func:`skpcd.io.iter_points`; other files are read whole) and every
    point is appended to the file of each buffered tile holding it, so
    memory holds one chunk at a time. A COPC file (a LAZ file with a COPC
    info VLR) is not spilled: its tiles are read from its octree, by their
    bounds, each time they are loaded (after one pass over the x, y and z of
    the points that counts them); they hold the same points, in the same
    order.

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
    unit : float, default=1.0
        The coordinates are multiplied by this as they are read (the
        length of a coordinate unit in metres, to tile a scan in feet in
        metres); ``tile_size`` and ``buffer`` are in the scaled units. A
        COPC file is then spilled as any LAZ file.

    Returns
    -------
    scene : TiledScene
        The tiles; close it (or use it in a ``with`` block) to delete the
        files.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import tile_scene
    >>> points = np.random.default_rng(0).uniform(0, 100, (1000, 3))
    >>> with tile_scene(points, 50, buffer=5) as scene:
    ...     xyz, index = scene.load(0)
    ...     print(scene.grid.shape, int(scene.owned_counts().sum()))
    ...     inside = np.all(xyz[:, :2] <= np.add(scene.grid.origin, 50 + 5))
    ...     print(bool(inside), bool(np.all(np.diff(index) > 0)))
    (2, 2) 1000
    True True
    """
    chunk_size = check_chunk_size(chunk_size)
    if _bounds is None and unit == 1.0 and is_path(source) and is_copc(source):
        return octree_scene(source, tile_size, buffer=buffer, temp_folder=temp_folder)
    if _bounds is None:
        mins, maxs = (np.asarray(b) * unit for b in scene_bounds(source, chunk_size))
    else:
        mins, maxs = _bounds
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
            if unit != 1.0:
                xyz = xyz * unit
            if not np.all(np.isfinite(xyz)):
                raise ValueError("the scene has NaN or infinite coordinates")
            lo_c, hi_c = point_bounds(xyz)
            lo, hi = np.minimum(lo, lo_c), np.maximum(hi, hi_c)
            owned += np.bincount(grid.owner(xyz), minlength=grid.n_tiles)
            rows, tiles = grid.route(xyz)
            records = np.empty(len(rows), dtype=RECORD)
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
            temp_folder=temp_folder, unit=unit, _bounds=(lo, hi),
        )  # fmt: skip
    return TiledScene(grid, folder, start, lo, hi, counts, owned)


def result_array(folder, name, n, dtype, fill):
    arr = np.lib.format.open_memmap(folder / name, mode="w+", dtype=dtype, shape=(n,))
    arr[:] = fill
    return arr


def detach(arr, path):
    """``arr`` (a memory map of ``path``) with the file unlinked where the
    system allows (the mapping keeps the data); else a copy in memory."""
    arr.flush()
    if os.name == "posix":
        os.unlink(path)
        return arr
    return np.array(arr)
