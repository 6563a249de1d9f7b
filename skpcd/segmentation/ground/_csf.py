"""The cloth simulation filter (CSF) of Zhang et al., through its reference code.

The scene is turned upside down and a cloth of particles ``cloth_resolution``
apart falls onto it under gravity; particles stop where they meet the
inverted surface, and the internal springs (``rigidness``) keep the cloth
from sinking into the gaps between objects. A point is ground when it lies
within ``class_threshold`` of the settled cloth. The simulation itself is the
authors' C++ code, PyPI package ``cloth-simulation-filter`` (import ``CSF``),
a dependency of skpcd.
"""

import contextlib
import ctypes
import os
import sys

import numpy as np
from scipy import ndimage
from threadpoolctl import threadpool_limits

from skpcd.segmentation.ground._raster import (
    MAX_CELLS,
    cell_indices,
    islands,
    raster_extent,
)
from skpcd.segmentation.ground._raster_kernels import cell_mean, cell_minimum
from skpcd.segmentation.ground._terrain import Terrain
from skpcd.utils._geometry import point_bounds

__all__ = [
    "ISLAND_CELLS",
    "MIN_ISLAND_POINTS",
    "csf_ground",
    "csf_terrain",
    "fill_points",
    "simulate_cloth",
]

_MISSING = (
    "GroundFilter(method='csf') needs the reference cloth simulation filter, "
    "PyPI package 'cloth-simulation-filter' (import CSF), a dependency of "
    "skpcd: pip install cloth-simulation-filter"
)


def _import_csf():
    try:
        import CSF
    except ImportError as exc:  # pragma: no cover - the extra is in CI
        raise ImportError(_MISSING) from exc
    return CSF


@contextlib.contextmanager
def _quiet_stdout():
    """Silence the C++ progress messages written to file descriptor 1."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        fd = 1
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), fd)
            yield
    finally:
        # the C++ stream writes through C stdio: flush it while silenced
        with contextlib.suppress(Exception):
            ctypes.CDLL(None).fflush(None)
        sys.stdout.flush()
        os.dup2(saved, fd)
        os.close(saved)


def _indices(vec):
    """The integers of a SWIG ``std::vector<int>`` (``CSF.VecInt``), int64.

    The vector is copied in one piece from its memory: a ``std::vector``
    of the C++ libraries CSF is built with (libstdc++, libc++) begins with
    the pointers to its first element and past its last. The copy is used
    only when those pointers span exactly ``vec.size()`` ints and the
    first, middle and last integers are those the vector's own accessors
    give; otherwise (another layout) the vector is read element by element,
    about 80 ns an element against a few milliseconds for 10 million."""
    n = vec.size()
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    width = ctypes.sizeof(ctypes.c_int)
    first, last = (ctypes.c_size_t * 2).from_address(int(vec.this))
    if last >= first and last - first == n * width and width == 4:
        values = np.ctypeslib.as_array((ctypes.c_int * n).from_address(first))
        values = values.astype(np.int64)
        if all(int(values[i]) == vec[i] for i in {0, n // 2, n - 1}):
            return values
    return np.fromiter(vec, dtype=np.int64, count=n)


def csf_ground(
    xyz, *, cloth_resolution, class_threshold, rigidness, slope_smooth, iterations,
    time_step,
):  # fmt: skip
    """Ground flags of a scene by the reference CSF.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The scene, float64, z up.
    cloth_resolution, class_threshold : float
        Spacing of the cloth particles and the largest distance of a ground
        point to the cloth, in metres.
    rigidness : int
        1, 2 or 3: how stiff the cloth is (3 for flat terrain).
    slope_smooth : bool
        Post-process steep slopes (CSF's ``bSloopSmooth``).
    iterations : int
        Largest number of simulation steps.
    time_step : float
        Simulation time step.

    Returns
    -------
    ground : ndarray of shape (n_points,), dtype bool

    Notes
    -----
    Groups of points more than ``2 * ISLAND_CELLS`` cloth cells (20 m at
    1 m) apart are filtered separately, each under its own cloth; a group
    of fewer than 10 points is ground. Empty parts of a group's bounding
    box far from its points are filled (:func:`_far_fill`).
    """
    _import_csf()
    ground = np.zeros(len(xyz), dtype=bool)
    if len(xyz) == 0:
        return ground
    kw = {
        "cloth_resolution": cloth_resolution,
        "class_threshold": class_threshold,
        "rigidness": rigidness,
        "slope_smooth": slope_smooth,
        "iterations": iterations,
        "time_step": time_step,
    }
    # the points' cells only when the scene may be islands
    _, nx, ny = raster_extent(xyz, float(cloth_resolution))
    if nx * ny <= max(len(xyz), 4 * ISLAND_CELLS**2):
        rects, label = np.array([[0, 0, nx - 1, ny - 1]]), None
    else:
        _, nx, ny, cells = cell_indices(xyz, float(cloth_resolution))
        rects, label = islands(cells, ISLAND_CELLS)
        del cells
    sizes = (rects[:, 2:] - rects[:, :2] + 1).prod(axis=1)
    if sizes.sum() > MAX_CELLS:
        raise ValueError(
            f"the occupied part of the scene needs {int(sizes.sum())} cloth "
            f"particles of {cloth_resolution} (more than {MAX_CELLS}); use a "
            "larger cell"
        )
    if label is None:
        return _csf_once(xyz, **kw)
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(len(rects) + 1))
    for i in range(len(rects)):  # a loop over islands, not points
        mine = order[bounds[i] : bounds[i + 1]]
        if len(mine) < MIN_ISLAND_POINTS:
            # a lone point (an outlier far away) lies on its own terrain
            ground[mine] = True
            continue
        ground[mine] = _csf_once(np.ascontiguousarray(xyz[mine]), **kw)
    return ground


# Groups of points more than twice this many cloth cells apart are filtered
# on their own (each with its own cloth), so that the cloth covers the
# occupied parts of the scene, not its bounding box (an outlier 100 km
# away would make a cloth of 10**10 particles, which the reference code
# aborts on).
ISLAND_CELLS = 10
# An island of fewer points is ground (a lone point lies on its terrain).
MIN_ISLAND_POINTS = 10


def _csf_once(
    xyz, *, cloth_resolution, class_threshold, rigidness, slope_smooth, iterations,
    time_step,
):  # fmt: skip
    """The reference CSF on one group of points."""
    params = {
        "cloth_resolution": cloth_resolution, "class_threshold": class_threshold,
        "rigidness": rigidness, "slope_smooth": slope_smooth,
        "iterations": iterations, "time_step": time_step,
    }  # fmt: skip
    ground = np.zeros(len(xyz), dtype=bool)
    n = len(xyz)
    # CSF works in float64 but loses precision on large coordinates (UTM):
    # simulate around the scene's corner. The shifted points and the fill
    # points after them are written into one array (CSF reads it as it is,
    # C-contiguous float64), with no other copy of the scene.
    corner = point_bounds(xyz)[0]
    fill = _far_fill(xyz, float(cloth_resolution), corner)
    shifted = np.empty((n + len(fill), 3))
    np.subtract(xyz, corner, out=shifted[:n])
    shifted[n:] = fill
    del fill
    csf = _configured(params)
    on, off = _import_csf().VecInt(), _import_csf().VecInt()
    with _reference_run():
        csf.setPointCloud(shifted)
        del shifted
        csf.do_filtering(on, off, False)
    # read back the shorter list; the fill points (indices from len(xyz))
    # are left out
    if on.size() <= off.size():
        idx = _indices(on)
        ground[idx[idx < n]] = True
    else:
        ground[:] = True
        idx = _indices(off)
        ground[idx[idx < n]] = False
    return ground


def simulate_cloth(pts, params):
    """The settled cloth of the reference CSF over a cloud.

    Parameters
    ----------
    pts : ndarray of shape (n, 3)
        The cloud, shifted to its corner (as :func:`_csf_once` gives it).
    params : dict
        The keyword arguments of :func:`csf_ground`.

    Returns
    -------
    heights : ndarray of shape (n_particles,)
        Each particle's height in CSF's frame (z down), rows of ``width``.
    width : int
        Particles per row.
    """
    csf = _configured(params)
    with _reference_run():
        csf.setPointCloud(np.ascontiguousarray(pts, dtype=np.float64))
        nodes = np.asarray(csf.do_cloth_export()).reshape(-1, 3)
    # exported as (x, y, -height) per particle, row after row
    width = int(np.count_nonzero(nodes[:, 1] == nodes[0, 1]))
    return -nodes[:, 2], width


def _configured(params):
    """A reference CSF object with ``params`` (those of :func:`csf_ground`)."""
    csf = _import_csf().CSF()
    csf.params.cloth_resolution = float(params["cloth_resolution"])
    csf.params.class_threshold = float(params["class_threshold"])
    csf.params.rigidness = int(params["rigidness"])
    csf.params.bSloopSmooth = bool(params["slope_smooth"])
    csf.params.interations = int(params["iterations"])
    csf.params.time_step = float(params["time_step"])
    return csf


@contextlib.contextmanager
def _reference_run():
    """Around a run of the reference code: its progress messages silenced,
    one OpenMP thread (with several, its parallel loops race and the ground
    flags change from run to run: tens of points of a 90 k point scene,
    measured with 2 threads)."""
    with _quiet_stdout(), threadpool_limits(limits=1, user_api="openmp"):
        yield


# Empty cells at least this many cloth cells from every point are filled
# (see _far_fill); the cells nearer are left to CSF itself.
_FILL_DISTANCE = 3
# Largest raster (cells) of the fill; beyond it, no fill.
_MAX_FILL_CELLS = 50_000_000


def _far_fill(xyz, cell, corner=None):
    """Points that stand in for the terrain in the empty parts of the
    scene's bounding box, in the frame whose origin is ``corner`` (the
    lowest x, y and z of ``xyz``; None when ``xyz`` is already shifted
    there): those of ``xyz - corner``, bit for bit, without that copy.

    The reference code gives every cloth particle with no point below it
    the height of the nearest particle with points, found along its row
    and column; over a bounding box that is mostly empty (a street that
    bends, an L-shaped survey) this search makes the simulation grow much
    faster than the area (measured: 200 k points of a street cut into steps
    along a diagonal, 1.1 s over 51 x 48 m, 48 s over 251 x 248 m). The
    empty cells at least ``_FILL_DISTANCE`` cells from every point get one
    point each, at the cell centre and the lowest height of the nearest
    cell with points: what the reference fill would give them, found by a
    distance transform. The cells near the points are left to CSF, so a
    scene without large empty areas gets no fill point and CSF's own
    answer.

    Subtracting the corner keeps the order of the coordinates, so the
    largest shifted x is the largest x minus the corner's, the lowest
    shifted z of a cell its lowest z minus the corner's, and a point's cell
    is computed from ``x - corner`` either way: the same values as from
    the shifted points."""
    corner = np.zeros(3) if corner is None else np.asarray(corner, dtype=np.float64)
    extent = point_bounds(xyz[:, :2])[1] - corner[:2]
    nx, ny = (int(v) for v in np.floor(extent / cell) + 1)
    if nx * ny > _MAX_FILL_CELLS or nx * ny <= 1:
        return np.zeros((0, 3))
    zmin = np.full((ny, nx), np.inf)
    cell_minimum(xyz, corner[0], corner[1], cell, nx, ny, 0, 0, zmin)
    zmin -= corner[2]
    return fill_points(zmin, cell)


def fill_points(zmin, cell):
    """The fill points of :func:`_far_fill` from the lowest z of each cell
    (``zmin``, +inf where empty, cells of ``cell`` from the scene's corner).
    """
    ny, nx = zmin.shape
    if nx * ny > _MAX_FILL_CELLS or nx * ny <= 1:
        return np.zeros((0, 3))
    empty = ~np.isfinite(zmin)
    dist, (ri, ci) = ndimage.distance_transform_edt(empty, return_indices=True)
    far = dist >= _FILL_DISTANCE
    del dist
    if not far.any():
        return np.zeros((0, 3))
    r, c = np.nonzero(far)
    z = zmin[ri[r, c], ci[r, c]]
    return np.column_stack([(c + 0.5) * cell, (r + 0.5) * cell, z])


def csf_terrain(xyz, ground, cell, n_threads=1):
    """A terrain model of the ground points of a scene.

    The DEM is the mean height of the ground points in each ``cell``; the
    cells without ground take the value of the nearest cell with ground
    (their ``objects`` flag is set). A scene of islands of occupied cells
    far apart has one patch per island (its bounding rectangle grown by a
    cell).

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The scene.
    ground : ndarray of shape (n_points,), dtype bool
        Its ground points.
    cell : float
        Side of the cells.
    n_threads : int, default=1
        Threads of the pass that finds the points' cells.

    Returns
    -------
    terrain : Terrain
    """
    cell = float(cell)
    lo, nx, ny = raster_extent(xyz, cell, n_threads)
    if nx * ny <= len(xyz):
        rects, label = np.array([[0, 0, nx - 1, ny - 1]]), None
    else:  # the DEM of the occupied parts only
        lo, nx, ny, cells = cell_indices(xyz, cell, n_threads)
        rects, label = islands(cells, 2)
        del cells
    patches = []
    order = None if label is None else np.argsort(label, kind="stable")
    bounds = (
        None
        if label is None
        else np.searchsorted(label[order], np.arange(len(rects) + 1))
    )
    for i, r in enumerate(rects):  # a loop over islands, not points
        c0, r0 = np.maximum(r[:2] - 1, 0)
        c1, r1 = np.minimum(r[2:] + 1, [nx - 1, ny - 1])
        mine = slice(None) if label is None else order[bounds[i] : bounds[i + 1]]
        pts, g = xyz[mine], ground[mine]
        shape = (int(r1 - r0 + 1), int(c1 - c0 + 1))
        mean = np.zeros(shape)
        count = np.zeros(shape, dtype=np.int64)
        x0, y0 = lo + cell * np.array([c0, r0])
        cell_mean(
            np.ascontiguousarray(pts), g, x0, y0, cell, shape[1], shape[0],
            mean, count,
        )  # fmt: skip
        empty = count == 0
        if empty.all():  # no ground: the lowest point's height
            dem = np.full(shape, pts[:, 2].min())
        elif empty.any():
            nearest = ndimage.distance_transform_edt(
                empty, return_distances=False, return_indices=True
            )
            dem = mean[tuple(nearest)]
        else:
            dem = mean
        patches.append((int(c0), int(r0), empty, dem))
    return Terrain(lo, cell, patches, shape=None if label is None else (ny, nx))
