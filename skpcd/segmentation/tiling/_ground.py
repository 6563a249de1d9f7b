"""The ground of a tiled scan: each tile's SMRF on a window of the scene's
raster, CSF's one cloth for the whole scan, the bases pass tile by tile, and
ground flags given in chunks (step 1 of
:func:`~skpcd.segmentation.tiling._segment.segment_tiled`)."""

import numpy as np

from skpcd.segmentation.ground._bases import BASE_THRESHOLD
from skpcd.segmentation.ground._cloth import StreamedCloth
from skpcd.segmentation.ground._filter import bases_filter, csf_params, fit_window
from skpcd.segmentation.ground._smrf import reach_cells
from skpcd.segmentation.tiling._dispatch import map_tiles
from skpcd.segmentation.tiling._spill import result_array
from skpcd.utils._memory import release_free_memory

__all__ = [
    "bases_tiled",
    "chunked_nanmedian",
    "csf_tiled",
    "fill_given",
    "ground_prepare",
    "ground_reach",
    "ground_tile",
    "windowed_filter",
]


# --- the ground filter on a window of the scene's raster -------------------


def ground_reach(filt):
    """How far (in metres) the ground filter's answer at a point depends on
    the points around it: :func:`~skpcd.segmentation.ground._smrf.reach_cells`
    cells beyond the point's own, plus one for the rounding of the tile and
    cell edges."""
    return (reach_cells(filt) + 1) * float(filt.cell)


def ground_prepare(xyz, index, ground, tile, grid, lo, nxy, cell, reach):
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


def ground_tile(xyz, owned, raster, filt, n_threads):
    """Ground flags of the owned points of a buffered tile."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=bool)
    return fit_window(filt, xyz, raster, n_threads).ground_[owned]


def _owned_prepare(xyz, index, ground, tile, grid):
    """The points a tile owns, and their scan indices."""
    own = grid.owner(xyz) == tile
    return (np.ascontiguousarray(xyz[own]),), index[own]


def _cloth_tile(xyz, cloth, n_threads):
    """CSF's flags of a tile's own points, and the bounds of its ground."""
    flags = cloth.classify(xyz)
    g = xyz[flags, :2]
    bounds = (g.min(axis=0), g.max(axis=0)) if len(g) else None
    return flags, bounds


def _owned_points(scene, tile):
    xyz, index = scene.load(tile)
    own = scene.grid.owner(xyz) == tile
    return xyz[own], index[own]


def csf_tiled(scene, tiles, filt, is_ground, n_jobs):
    """CSF's flags of the whole scan, tile by tile: the cloth of the whole
    scan from one point per particle (:class:`StreamedCloth`, two passes
    over the tiles here), then each tile's points tested against it.
    Returns the bounds of the ground points (None: no ground)."""
    cloth = StreamedCloth(csf_params(filt), scene.mins, scene.maxs, scene.n_points)
    if cloth.needs_cells:
        for t in tiles:
            cloth.add_cells(_owned_points(scene, t)[0])
            release_free_memory()
    for t in tiles:
        cloth.sample(*_owned_points(scene, t))
        release_free_memory()
    cloth.simulate()
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for index, (flags, bounds) in map_tiles(
        scene, tiles, _owned_prepare, (scene.grid,), _cloth_tile, (cloth,), n_jobs
    ):
        is_ground[index] = flags
        if bounds is not None:
            lo, hi = np.minimum(lo, bounds[0]), np.maximum(hi, bounds[1])
    return None if lo[0] > hi[0] else (lo, hi)


def _bases_prepare(xyz, index, ground, tile, grid, lo, nxy, cell, reach):
    """:func:`ground_prepare` of the tile's ground points."""
    return ground_prepare(
        np.ascontiguousarray(xyz[ground]), index[ground], None, tile, grid, lo, nxy,
        cell, reach,
    )  # fmt: skip


def _bases_tile(xyz, owned, raster, filt, n_threads):
    """The second filter of the ``keep_bases`` pass on a tile's ground
    points: which of its own it keeps, and their heights above its terrain
    (absolute)."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=bool), np.zeros(0)
    est = fit_window(filt, xyz, raster, n_threads)
    own = np.ascontiguousarray(xyz[owned])
    height = np.abs(own[:, 2] - est._terrain.sample(own, False, n_threads))
    return est.ground_[owned], height


def bases_tiled(scene, tiles, ground_bounds, reach, ground, out, n_jobs, chunk_size):
    """:func:`~skpcd.segmentation.ground._bases.without_bases` tile by tile:
    the bases filter on each tile's ground points in the window of the
    raster of all ground points grown by its reach; the robust spread of
    the heights of the kept points, over the whole scan; and, when that
    raises the threshold, the filter again with it. Clears the bases in
    the ground flags ``ground = (flags, path)``."""
    is_ground = ground[0]
    n_ground = 0
    for start in range(0, scene.n_points, chunk_size):
        n_ground += int(is_ground[start : start + chunk_size].sum())
    if ground_bounds is None or n_ground < 3:
        return
    filt = bases_filter()
    cell = float(filt.cell)
    lo, hi = ground_bounds
    nxy = (np.floor((hi - lo) / cell) + 1).astype(np.int64)
    pargs = (scene.grid, lo, nxy, cell, reach)
    n = scene.n_points
    kept = result_array(out, "bases_kept.npy", n, np.bool_, False)
    height = result_array(out, "bases_height.npy", n, np.float64, np.nan)
    for index, (k, h) in map_tiles(
        scene, tiles, _bases_prepare, pargs, _bases_tile, (filt,), n_jobs,
        ground=ground,
    ):  # fmt: skip
        kept[index] = k
        height[index] = h
    sigma = 1.4826 * chunked_nanmedian(height, kept, chunk_size)
    if 3.0 * sigma > BASE_THRESHOLD:
        filt = bases_filter(3.0 * float(sigma))
        for index, (k, _) in map_tiles(
            scene, tiles, _bases_prepare, pargs, _bases_tile, (filt,), n_jobs,
            ground=ground,
        ):  # fmt: skip
            kept[index] = k
    for start in range(0, n, chunk_size):
        part = slice(start, start + chunk_size)
        is_ground[part] &= kept[part]


def chunked_nanmedian(values, mask, chunk_size):
    """``np.nanmedian(values[mask])`` (NaN when empty), bit for bit, in
    passes over chunks: a histogram of the values' leading bits finds the
    bins of the middle ranks, then only the values in those bins are held.

    Parameters
    ----------
    values : ndarray of shape (n,), dtype float64
        Non-negative values or NaN (a memory map: read chunk by chunk).
    mask : ndarray of shape (n,), dtype bool
        Which values count.
    chunk_size : int
        Values read at a time.
    """

    def chunks():
        for start in range(0, len(values), chunk_size):
            v = np.asarray(values[start : start + chunk_size])
            v = v[np.asarray(mask[start : start + chunk_size]) & ~np.isnan(v)]
            # non-negative float64: their bit patterns sort as they do
            yield v, v.view(np.int64) >> 44

    counts = np.zeros(2**19, dtype=np.int64)
    for _, top in chunks():
        counts += np.bincount(top, minlength=len(counts))
    total = int(counts.sum())
    if total == 0:
        return np.nan
    ranks = sorted({(total - 1) // 2, total // 2})
    cum = np.cumsum(counts)
    bins = [int(np.searchsorted(cum, r, side="right")) for r in ranks]
    held = np.concatenate([v[np.isin(top, bins)] for v, top in chunks()])
    held.sort()
    first = int(cum[bins[0] - 1]) if bins[0] > 0 else 0
    middle = held[[r - first for r in ranks]]
    return float(np.mean(middle))


def fill_given(is_ground, chunks):
    """The ground flags given in chunks, copied into ``is_ground``; a
    ValueError unless they are one per point."""
    start = 0
    for flags in chunks:
        stop = start + len(flags)
        if stop <= len(is_ground):
            is_ground[start:stop] = flags
        start = stop
    if start != len(is_ground):
        raise ValueError(
            f"the ground flags given hold {start} values for {len(is_ground)} points"
        )


def windowed_filter(ground):
    """The filter the tiles run on windows of the scene's raster: SMRF, or
    with CSF (one cloth for the whole scan) the second filter of
    ``keep_bases``; None when there is none."""
    if ground is not None and ground.method == "csf":
        return bases_filter() if ground.keep_bases else None
    return ground
