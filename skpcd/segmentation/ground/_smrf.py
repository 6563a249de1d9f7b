"""SMRF, the simple morphological filter of Pingel et al. (2013).

The scene is rasterised into its minimum-z surface; a progressive
morphological opening with a growing disk flags the cells that rise above
the opened surface more than the terrain slope allows (objects); the
remaining cells are interpolated into a terrain model (DEM), and a point is
ground when it lies within a threshold of the DEM, the threshold growing
with the local slope of the DEM.

Every step computes a cell from the cells within a fixed distance of it
(:func:`reach_cells` in all), so that the filter run on a window of the
raster gives the answer of the whole raster away from the window's edges:
the tiled segmentation is exact because of it (:func:`smrf_fit` with
``window``). Pingel et al. fill the empty cells and the object cells by a
spring-metaphor inpainting, PDAL by inverse-distance weighting of the
nearest filled cells: both reach arbitrarily far across a large gap. Here
every fill is local: the empty cells of the minimum surface take the
inverse-square-distance mean of the cells within ``_FILL_CELLS`` (farther
ones take no part in the opening), and the terrain under an object is,
along each row, column and diagonal through the cell, the linear
interpolation between the nearest ground cells on either side within
``window`` plus ``_TERRAIN_EXTRA_CELLS`` cells (the lines found averaged,
weighted by the inverse distances; exact on a plane; one-sided ends only
when no line has both, the minimum surface when nothing is found).

The cost follows the occupied cells, not the bounding box of the scene:
the occupied cells are grouped into islands more than twice the reach
apart, and each island is filtered on its own raster (its bounding
rectangle grown by twice the reach), which gives the whole raster's answer,
bit for bit, on every cell within the reach of a point.
"""

import math

import numpy as np
from scipy import ndimage

from skpcd.segmentation.ground._raster import (
    MAX_CELLS,
    cell_indices,
    islands,
    minimum_raster,
    raster_extent,
    raster_rows,
)
from skpcd.segmentation.ground._smrf_kernels import (
    classify_rows,
    drop_low_noise_rows,
    fill_surface_rows,
    interpolate_terrain_rows,
    opening_objects_rows,
)
from skpcd.segmentation.ground._terrain import Terrain, slope_of
from skpcd.utils._parallel import parallel_rows

__all__ = [
    "opening_cells",
    "opening_objects",
    "reach_cells",
    "smrf_fit",
    "smrf_ground",
    "terrain_cells",
]

# Radius, in cells, of the fill of the minimum surface's empty cells before
# the opening; farther from every point a cell is left out of the opening.
_FILL_CELLS = 4
# Rows of a band of the threaded opening at least, in rows computed on
# either side of it (``2 * radius``): at most a quarter of extra rows.
_BAND_HALOS = 4
# Steps, in cells, the terrain interpolation looks for ground beyond the
# opening's largest radius (an object that the opening removes is at most
# that radius from the ground on its narrow side).
_TERRAIN_EXTRA_CELLS = 2


def opening_cells(filt):
    """The largest radius of the opening, in cells (``filt`` holds SMRF's
    parameters, as :class:`~skpcd.segmentation.GroundFilter` does)."""
    return max(1, math.ceil(filt.window / filt.cell))


def terrain_cells(filt):
    """How far, in cells, the terrain interpolation looks for ground."""
    return opening_cells(filt) + _TERRAIN_EXTRA_CELLS


def reach_cells(filt):
    """How far, in cells, the filter's answer at a point depends on the
    cells around the point's own: the classification reads the terrain and
    its slope at the cells next to the point (2), the terrain interpolation
    looks :func:`terrain_cells` away, the opening ``2 * opening_cells``, the
    surface fill ``_FILL_CELLS`` and the low-noise test 2 (a neighbour and
    its nearest known cell). Every step computes a cell from the cells
    within its own distance only, so the filter on a window of the raster
    gives the whole raster's answer on the cells this far from the window's
    edges (the tiled segmentation relies on it)."""
    return 2 + terrain_cells(filt) + 2 * opening_cells(filt) + _FILL_CELLS + 2


def opening_objects(surface, known, radius_max, slope, cell, n_threads=1):
    """Cells that the opening flags as objects (and the cells not known).

    The opening of radius ``r`` (a disk approximated by an octagon: ``r``
    3x3 steps alternating a square and a cross, the square first) is
    computed from ``surface`` itself for every ``r``, so that it depends on
    the cells within ``2 * r`` only; the erosions are chained (the one of
    radius ``r`` is one step on the one of ``r - 1``), the dilations redone.
    Cells of ``surface`` at +inf (no point near) take no part: they are
    skipped by the erosion, and where the erosion found nothing the
    dilation skips them too. A known cell is an object when it drops by more
    than ``slope * r * cell`` from the opening of radius ``r - 1`` to that
    of ``r``.

    On ``n_threads`` threads, each takes a band of rows and computes it
    with ``2 * radius_max`` rows on either side (:func:`opening_objects_rows
    <skpcd.segmentation.ground._smrf_kernels.opening_objects_rows>`): the
    same cells as on one thread, at the cost of those extra rows, so a band
    is at least ``_BAND_HALOS`` times as high (a thin raster runs on one
    thread).
    """
    ny = surface.shape[0]
    objects = np.empty(surface.shape, dtype=bool)
    band = max(-(-ny // n_threads), _BAND_HALOS * 2 * radius_max)
    parallel_rows(
        opening_objects_rows, ny, n_threads,
        surface, known, radius_max, float(slope), float(cell), objects,
        min_chunk=band,
    )  # fmt: skip
    return objects


def _drop_low_noise(zmin, known, low_noise, n_threads):
    """Unknown from now: cells far below the median of their 8 neighbours."""
    if low_noise is None:
        return known
    out = np.empty_like(known)
    parallel_rows(
        drop_low_noise_rows, len(zmin), n_threads,
        zmin, known, float(low_noise), out,
        min_chunk=raster_rows(zmin),
    )  # fmt: skip
    return out


def _terrain(zmin, filt, n_threads):
    """The object cells and the terrain model of a minimum surface."""
    rows = raster_rows(zmin)
    known = _drop_low_noise(zmin, np.isfinite(zmin), filt.low_noise, n_threads)
    surface = np.empty_like(zmin)
    parallel_rows(
        fill_surface_rows, len(zmin), n_threads, zmin, known, _FILL_CELLS,
        surface, min_chunk=rows,
    )  # fmt: skip
    objects = opening_objects(
        surface, known, opening_cells(filt), float(filt.slope), float(filt.cell),
        n_threads,
    )  # fmt: skip
    reach = terrain_cells(filt)
    near = ndimage.maximum_filter(known, size=2 * reach + 1, mode="constant")
    dem = np.empty_like(zmin)
    parallel_rows(
        interpolate_terrain_rows, len(zmin), n_threads,
        zmin, ~objects, surface, near, reach, dem, min_chunk=rows,
    )  # fmt: skip
    return objects, dem


def _classify(xyz, frame, dem, filt, n_threads):
    """SMRF's test of the points against a DEM (and its slope) whose cells
    are placed by ``frame`` (see :meth:`Terrain.frame
    <skpcd.segmentation.ground._terrain.Terrain.frame>`)."""
    x0, y0, nx, ny, c0, r0 = frame
    cell = float(filt.cell)
    out = np.empty(len(xyz), dtype=bool)
    parallel_rows(
        classify_rows, len(xyz), n_threads,
        xyz, x0, y0, cell, nx, ny, c0, r0,
        dem, slope_of(dem, cell),
        float(filt.threshold), float(filt.scalar), out,
    )  # fmt: skip
    return out


def smrf_ground(terrain, xyz, filt, n_threads):
    """Which points are ground by SMRF's test against a fitted terrain.

    Parameters
    ----------
    terrain : Terrain
        What :func:`smrf_fit` returned.
    xyz : ndarray of shape (n_points, 3)
        The points.
    filt : GroundFilter
        SMRF's parameters (``threshold`` and ``scalar`` are read here).
    n_threads : int
        Threads of the test.

    Returns
    -------
    ground : ndarray of shape (n_points,), dtype bool
    """
    if terrain.shape is not None:
        dz = np.abs(xyz[:, 2] - terrain.sample(xyz, False, n_threads))
        return dz <= filt.threshold + filt.scalar * terrain.sample(xyz, True, n_threads)
    dem = terrain.patches[0][3]
    return _classify(xyz, terrain.frame(grid=dem), dem, filt, n_threads)


def smrf_fit(xyz, filt, n_threads, window=None):
    """SMRF's terrain model of a scene and its ground points.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The scene, float64, C-contiguous.
    filt : GroundFilter
        SMRF's parameters: ``cell``, ``slope``, ``window``, ``threshold``,
        ``scalar`` and ``low_noise``.
    n_threads : int
        Threads of the passes over the points and the raster.
    window : tuple or None, default=None
        ``(x0, y0, nx, ny, c0, r0, wx, wy)``: the points are a tile of a
        larger scene whose raster has its corner at ``(x0, y0)`` and ``nx``
        x ``ny`` cells; the filter runs on the ``wx`` x ``wy`` cells from
        column ``c0``, row ``r0``, with the cells and interpolation weights
        of the scene's raster. None: the points are the scene.

    Returns
    -------
    ground : ndarray of shape (n_points,), dtype bool
        The ground points.
    terrain : Terrain
        The terrain model.
    """
    cell = float(filt.cell)
    if window is not None:
        x0, y0, nx, ny, c0, r0, wx, wy = window
        zmin = minimum_raster(
            xyz, (x0, y0), cell, (nx, ny), (c0, r0), (wy, wx), n_threads
        )
        lo = np.array([x0 + c0 * cell, y0 + r0 * cell])
        terrain = Terrain(
            lo, cell, [(0, 0, *_terrain(zmin, filt, n_threads))], frame=window[:6]
        )
        return smrf_ground(terrain, xyz, filt, n_threads), terrain
    lo, nx, ny = raster_extent(xyz, cell, n_threads)
    reach = reach_cells(filt) + 1
    if nx * ny <= len(xyz):
        # no larger than the points: the whole raster, no island search
        rects, label = np.array([[0, 0, nx - 1, ny - 1]]), None
    else:
        _, _, _, cells = cell_indices(xyz, cell, n_threads)
        rects, label = islands(cells, reach)
        del cells
    # each island's filter on its rectangle grown by twice the reach
    # gives the whole raster's answer on the rectangle grown by the
    # reach, which holds every cell with a point within the reach; the
    # other cells are NaN (no terrain) and objects (empty)
    size = [nx, ny]
    windows = [
        (np.maximum(r[:2] - 2 * reach, 0), np.minimum(r[2:] + 2 * reach, size))
        for r in rects
    ]
    n_cells = sum(int(np.prod(b - a + 1)) for a, b in windows)
    if n_cells > MAX_CELLS:
        raise ValueError(
            f"the occupied part of the scene needs {n_cells} cells of "
            f"{filt.cell} (more than {MAX_CELLS}); use a larger cell"
        )
    if len(rects) == 1:
        zmin = minimum_raster(xyz, lo, cell, (nx, ny), (0, 0), (ny, nx), n_threads)
        terrain = Terrain(lo, cell, [(0, 0, *_terrain(zmin, filt, n_threads))])
        return smrf_ground(terrain, xyz, filt, n_threads), terrain
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(len(rects) + 1))
    terrain = Terrain(lo, cell, [], shape=(ny, nx))
    ground = np.zeros(len(xyz), dtype=bool)
    for i, ((c0, r0), (c1, r1)) in enumerate(windows):
        mine = order[bounds[i] : bounds[i + 1]]
        pts = np.ascontiguousarray(xyz[mine])
        zmin = minimum_raster(
            pts, lo, cell, (nx, ny), (c0, r0), (r1 - r0 + 1, c1 - c0 + 1),
            n_threads,
        )  # fmt: skip
        objects, dem = _terrain(zmin, filt, n_threads)
        k0 = np.maximum(rects[i, :2] - reach, 0)
        k1 = np.minimum(rects[i, 2:] + reach, [nx - 1, ny - 1])
        part = (
            slice(k0[1] - r0, k1[1] - r0 + 1),
            slice(k0[0] - c0, k1[0] - c0 + 1),
        )
        c, r = int(k0[0]), int(k0[1])
        terrain.patches.append((c, r, objects[part], dem[part]))
        ground[mine] = _classify(pts, terrain.frame(c, r), dem[part], filt, n_threads)
    return ground, terrain
