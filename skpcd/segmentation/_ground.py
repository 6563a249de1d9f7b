"""Ground removal: the simple morphological filter (SMRF) of Pingel et al.,
or the cloth simulation filter (CSF) of Zhang et al. (``method="csf"``).

The scene is rasterised into its minimum-z surface; a progressive
morphological opening with a growing disk flags the cells that rise above
the opened surface more than the terrain slope allows (objects); the
remaining cells are interpolated into a terrain model (DEM), and a point is
ground when it lies within a threshold of the DEM, the threshold growing
with the local slope of the DEM.

Every step computes a cell from the cells within a fixed distance of it
(:func:`reach_cells` in all), so that the filter run on a window of the
raster gives the answer of the whole raster away from the window's edges:
the tiled :func:`~skpcd.segmentation.segment_scene` is exact because of it.
CSF, a simulation over the whole scene, has no such reach (see
:func:`~skpcd.segmentation.segment_scene`).
"""

import math
import typing
from numbers import Integral, Real

import numpy as np
from scipy import ndimage
from sklearn.base import BaseEstimator, _fit_context
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

from skpcd.segmentation._raster import (
    MAX_CELLS,
    cell_indices,
    islands,
    minimum_raster,
    raster_extent,
    raster_rows,
)
from skpcd.utils._compile import entry_point
from skpcd.utils._parallel import effective_threads, parallel_rows

__all__ = ["GROUND_PRESETS", "GroundFilter"]

# Parameters for the kinds of scan; "aerial" are the defaults of
# GroundFilter (those of Pingel et al. and of PDAL's filters.smrf); "csf"
# is the cloth simulation filter with the defaults of its authors (cloth
# 1 m, hard cloth, slope smoothing) but a 0.3 m threshold instead of 0.5
# (benchmarks/bench_ground.py: about half the object points taken as
# ground, for a ground recall 0.1 to 0.2 % lower, 99.6 % or more);
# "street" is "csf" followed by the pass that gives the bases of objects
# back (without_bases), the default of the scans made from the street
# (SCAN_KINDS in _scan_kind.py).
GROUND_PRESETS = {
    "csf": {
        "method": "csf",
        "cell": 1.0,
        "threshold": 0.3,
        "rigidness": 3,
        "slope_smooth": True,
    },
    "aerial": {
        "cell": 1.0,
        "slope": 0.15,
        "window": 18.0,
        "threshold": 0.5,
        "scalar": 1.25,
    },
    "street": {
        "method": "csf",
        "cell": 1.0,
        "threshold": 0.3,
        "rigidness": 3,
        "slope_smooth": True,
        "keep_bases": True,
    },
    "mobile": {
        "cell": 0.5,
        "slope": 0.15,
        "window": 10.0,
        "threshold": 0.25,
        "scalar": 1.25,
    },
}

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
    """The largest radius of the opening, in cells."""
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
    edges (the tiled :func:`~skpcd.segmentation.segment_scene` relies on
    it)."""
    return 2 + terrain_cells(filt) + 2 * opening_cells(filt) + _FILL_CELLS + 2


def _objects(surface, known, radius_max, slope, cell, n_threads=1):
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
    with ``2 * radius_max`` rows on either side
    (:func:`~skpcd.segmentation._ground_kernels.opening_objects_rows`): the
    same cells as on one thread, at the cost of those extra rows, so a band
    is at least ``_BAND_HALOS`` times as high (a thin raster runs on one
    thread).
    """
    from skpcd.segmentation._ground_kernels import opening_objects_rows

    ny = surface.shape[0]
    objects = np.empty(surface.shape, dtype=bool)
    band = max(-(-ny // n_threads), _BAND_HALOS * 2 * radius_max)
    parallel_rows(
        opening_objects_rows, ny, n_threads,
        surface, known, radius_max, float(slope), float(cell), objects,
        min_chunk=band,
    )  # fmt: skip
    return objects


def _slope(dem, cell):
    """Magnitude of the gradient of the terrain (central differences, one-
    sided at the edges; zero along an axis of a single cell)."""
    grads = [
        np.gradient(dem, cell, axis=a) if dem.shape[a] > 1 else np.zeros_like(dem)
        for a in (0, 1)
    ]
    return np.hypot(*grads)


# The second pass of ``keep_bases``: SMRF over the ground points alone, on
# cells of 0.5 m with a 2 m window (what rises over less than 4 m across, a
# car, a bin, the foot of a pole or a hedge, is not terrain), and a ground
# point more than BASE_THRESHOLD above its terrain, or 3 standard deviations
# of the terrain's roughness when the ground is rougher, is an object's
# base. Chosen on the real KITTI and PandaSet sweeps of
# benchmarks/bench_scan_kinds.py (cells 0.25 and 0.5 m, windows 1.5 to
# 3 m, thresholds 0.07 to 0.15 m compared; in benchmarks/results/
# scan_kinds.txt 5.5 % of the boxed car points are ground instead of
# 11.2 % with CSF alone).
BASES = {"cell": 0.5, "window": 2.0, "slope": 0.15, "scalar": 1.25}
BASE_THRESHOLD = 0.07


def without_bases(xyz, ground, n_threads=1):
    """Ground flags without the bases of objects.

    The ground points of a first filter are filtered again by SMRF with
    ``BASES`` (small cells and window); those above its terrain by more
    than ``max(BASE_THRESHOLD, 3 * sigma)``, ``sigma`` the robust standard
    deviation (1.4826 times the median absolute deviation) of the heights
    of the kept ground points above the terrain, are no longer ground.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The scene.
    ground : ndarray of shape (n_points,), dtype bool
        The first filter's flags.
    n_threads : int, default=1
        Threads of the second filter.

    Returns
    -------
    ground : ndarray of shape (n_points,), dtype bool
        A copy of ``ground`` with the bases of objects set to False.
    """
    idx = np.flatnonzero(ground)
    if len(idx) < 3:
        return ground.copy()
    pts = np.ascontiguousarray(xyz[idx])
    second = GroundFilter(
        **BASES, threshold=BASE_THRESHOLD, low_noise=None, n_jobs=n_threads
    ).fit(pts)
    kept = second.ground_
    height = second.height(pts)
    with np.errstate(invalid="ignore"):
        sigma = 1.4826 * np.nanmedian(np.abs(height[kept])) if kept.any() else 0.0
    if 3.0 * sigma > BASE_THRESHOLD:
        kept = second.set_params(threshold=3.0 * float(sigma)).predict(pts)
    out = ground.copy()
    out[idx[~kept]] = False
    return out


class GroundFilter(BaseEstimator):
    """Ground points of a LiDAR scene: morphological (SMRF) or cloth (CSF) filter.

    :meth:`fit` builds a terrain model (DEM) of the scene; :meth:`predict`
    says which points lie on it. With ``method="csf"`` the ground points
    are those of the cloth simulation filter (Zhang et al., 2016; the
    authors' code, the package ``cloth-simulation-filter``): the
    scene is turned upside down, a cloth of particles ``cell`` apart falls
    onto it and settles on the inverted terrain, held up over objects by
    its stiffness (``rigidness``); a point within ``threshold`` of the
    cloth is ground. The default, ``method="smrf"``, is SMRF (Pingel et
    al., 2013):

    1. the lowest z of each ``cell`` x ``cell`` square; empty cells, and
       cells more than ``low_noise`` below the median of their neighbours
       (low outliers), are interpolated from the cells within 4 cells;
    2. the surface is opened (erosion, then dilation) with disks of radius
       1, 2, ... up to ``window`` metres; a cell whose height drops by more
       than ``slope`` times the radius is an object;
    3. the non-object cells, interpolated over the object cells (along
       rows, columns and diagonals, up to ``window`` plus two cells), make
       the DEM;
    4. a point is ground when it lies within ``threshold + scalar * s`` of
       the DEM (above or below), ``s`` the slope of the DEM at the point.

    All lengths are in the units of the coordinates (metres).

    Read more in the :ref:`User Guide <segmentation>`.

    Parameters
    ----------
    method : {"smrf", "csf"}, default="smrf"
        The filter. "csf" runs the package ``cloth-simulation-filter``
        (a dependency of skpcd) and uses ``cell``, ``threshold``,
        ``rigidness``, ``slope_smooth``, ``iterations`` and ``time_step``;
        "smrf" uses ``cell``, ``slope``, ``window``, ``threshold``,
        ``scalar`` and ``low_noise``.
    cell : float, default=1.0
        Raster cell size (PDAL's ``cell``). Mobile scans: 0.5. With CSF,
        the spacing of the cloth particles (CSF's ``cloth_resolution``).
    slope : float, default=0.15
        Largest terrain slope (rise over run) kept as ground by the opening
        (PDAL's ``slope``).
    window : float, default=18.0
        Largest radius of the opening: half the width of the largest object
        to remove (PDAL's ``window``). Mobile scans (facades, vehicles): 10.
    threshold : float, default=0.5
        Largest height above (or below) the DEM of a ground point on flat
        terrain (PDAL's ``threshold``). Mobile scans: 0.25. With CSF, the
        largest distance of a ground point to the cloth (CSF's
        ``class_threshold``).
    scalar : float, default=1.25
        Growth of that height with the DEM slope (PDAL's ``scalar``).
    low_noise : float or None, default=1.0
        A cell whose lowest point is more than this below the median of its
        8 neighbours holds low noise (multipath, a point under the ground)
        and is left out of the minimum surface. None keeps every cell.
    rigidness : {1, 2, 3}, default=3
        CSF only: stiffness of the cloth, 3 for flat terrain (cities,
        streets), 2 for relief, 1 for steep slopes.
    slope_smooth : bool, default=True
        CSF only: the post-processing of steep slopes (CSF's
        ``bSloopSmooth``).
    iterations : int, default=500
        CSF only: largest number of simulation steps.
    time_step : float, default=0.65
        CSF only: step of the simulation.
    keep_bases : bool, default=False
        Give the bases of objects back: the ground points are filtered a
        second time by SMRF with 0.5 m cells and a 2 m window, and those
        more than 0.07 m (or three standard deviations of the ground's
        roughness, if more) above that terrain are not ground: the lowest
        0.1-0.4 m of cars, bins, hedges and poles that CSF or SMRF take
        for ground on street scans. ``ground_`` (and :meth:`fit_predict`)
        include this pass; the DEM is built from its ground points with
        CSF; :meth:`predict` on other points tests them against the DEM
        only.
    n_jobs : int, default=None
        Threads for SMRF: the passes over the points (the minimum raster,
        the test of each point against the DEM) in parts of the points, the
        passes over the raster (low noise, fill, opening, interpolation) in
        bands of rows; the result is the same, bit for bit, for every
        ``n_jobs``. None means 1 (unless in a :func:`joblib.parallel_config`
        context), -1 all cores. CSF runs on one thread whatever ``n_jobs``
        says: the package's OpenMP threads change its result from run to
        run (see ``skpcd.segmentation._csf``).

    Attributes
    ----------
    dem_ : ndarray of shape (n_rows, n_cols)
        Terrain height at the cell centres; row ``r``, column ``c`` is
        centred at ``origin_ + cell * (c + 0.5, r + 0.5)``. NaN far from
        the points (no ground cell within the reach of step 3, no point
        within 4 cells): :meth:`height` is NaN there and :meth:`predict`
        False. Assembled on access when the scene is several islands (see
        Notes); a ValueError when that array would exceed 200 million
        cells (:meth:`height` and :meth:`predict` still work).
    origin_ : ndarray of shape (2,)
        x and y of the raster corner.
    objects_ : ndarray of shape (n_rows, n_cols), dtype bool
        Cells flagged as objects (or empty, or low noise) by the opening.
    ground_ : ndarray of shape (n_points,), dtype bool
        Ground points of the fitted scene (:meth:`predict` of X).
    n_features_in_ : int
        Number of columns of X seen in :meth:`fit`.

    See Also
    --------
    segment_scene : Ground removal, then clustering.

    Notes
    -----
    The disk is approximated by an octagon (alternate 3x3 squares and
    crosses), which makes each opening a chain of 3x3 filters; the opening
    of each radius is computed from the minimum surface itself, so that it
    depends on the cells within twice its radius only.

    Pingel et al. fill the empty cells and the object cells by a
    spring-metaphor inpainting, PDAL by inverse-distance weighting of the
    nearest filled cells: both reach arbitrarily far across a large gap.
    Here every fill is local, so that the filter is a function of the cells
    within a fixed distance (:func:`reach_cells`, ``3 * ceil(window /
    cell) + 10`` cells) and gives the same answer on a window of the raster
    as on the whole raster, which makes the tiled
    :func:`~skpcd.segmentation.segment_scene` exact: the empty cells of the
    minimum surface take the inverse-square-distance mean of the cells
    within 4 cells (farther ones take no part in the opening), and the
    terrain under an object is, along each row, column and diagonal through
    the cell, the linear interpolation between the nearest ground cells on
    either side within ``window`` plus two cells (the lines found averaged,
    weighted by the inverse distances; exact on a plane; one-sided ends
    only when no line has both, the minimum surface when nothing is found).
    An object that the opening removes is at most ``window`` from the
    ground on its narrow side, so it is bridged. Earlier development
    versions filled both by harmonic (Laplace) interpolation of the whole
    raster; the results differ slightly near large gaps (the tests' quality
    bounds hold for both).

    The cost follows the occupied cells, not the bounding box of the
    scene: the occupied cells are grouped into islands more than twice
    :func:`reach_cells` apart, and each island is filtered on its own
    raster (its bounding rectangle grown by twice the reach), which gives
    the whole raster's answer, bit for bit, on every cell within the reach
    of a point; the other cells have no terrain (NaN). A point far from the
    scene (an outlier 100 km away) is thus its own island, ground or not by
    the same local rule (a lone point lies on its own terrain), at the cost
    of a few hundred thousand cells. The islands' cells, summed, may not
    exceed 200 million (a ValueError asks for a larger ``cell``), nor may
    the scene span more than 2**53 cells along an axis (coordinates of
    1e30: a ValueError). Remove outliers beforehand with
    :class:`~skpcd.preprocessing.StatisticalOutlierFilter` or
    :class:`~skpcd.preprocessing.RadiusOutlierFilter` when they are noise.

    ``GROUND_PRESETS["aerial"]`` are these defaults (those of Pingel et al.
    and PDAL's ``filters.smrf``); ``GROUND_PRESETS["mobile"]`` are for
    urban mobile scans, denser and lower; ``GROUND_PRESETS["csf"]`` is CSF
    with its authors' defaults (a 1 m cloth, rigidness 3, slope smoothing)
    but a 0.3 m threshold,
    the default of :func:`~skpcd.segmentation.segment_scene` because it
    holds on street scans where SMRF does not (at the scan's edges no
    ground lies beside the facades and trees, and the opening takes their
    lower parts for terrain; see the user guide for the measurements).

    With CSF, ``ground_`` is the simulation's answer; the DEM (``dem_``,
    :meth:`height`, :meth:`predict` on other points) is the mean height of
    the ground points in each ``cell``, the empty cells taking the value of
    the nearest cell with ground (``objects_`` marks the cells without
    ground points). CSF is a simulation over the whole scene: it has no
    bounded reach, so the tiled segmentation refuses it.

    References
    ----------
    .. [1] T. J. Pingel, K. C. Clarke, W. A. McBride, "An improved simple
       morphological filter for the terrain classification of airborne
       LIDAR data", ISPRS J. Photogramm. Remote Sens. 77, 21-30, 2013.
    .. [2] W. Zhang, J. Qi, P. Wan, H. Wang, D. Xie, X. Wang, G. Yan, "An
       easy-to-use airborne LiDAR data filtering method based on cloth
       simulation", Remote Sens. 8(6), 501, 2016.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import GroundFilter
    >>> rng = np.random.default_rng(0)
    >>> ground = np.column_stack([rng.uniform(0, 40, (4000, 2)), rng.normal(0, 0.03, 4000)])
    >>> box = rng.uniform([10, 10, 1], [16, 16, 4], (600, 3))
    >>> is_ground = GroundFilter().fit_predict(np.vstack([ground, box]))
    >>> int(is_ground[:4000].sum()), int(is_ground[4000:].sum())
    (4000, 0)
    """  # noqa: E501

    _parameter_constraints: typing.ClassVar[dict] = {
        "method": [StrOptions({"smrf", "csf"})],
        "cell": [Interval(Real, 0, None, closed="neither")],
        "slope": [Interval(Real, 0, None, closed="left")],
        "window": [Interval(Real, 0, None, closed="neither")],
        "threshold": [Interval(Real, 0, None, closed="left")],
        "scalar": [Interval(Real, 0, None, closed="left")],
        "low_noise": [Interval(Real, 0, None, closed="neither"), None],
        "rigidness": [Interval(Integral, 1, 3, closed="both")],
        "slope_smooth": ["boolean"],
        "iterations": [Interval(Integral, 1, None, closed="left")],
        "time_step": [Interval(Real, 0, None, closed="neither")],
        "keep_bases": ["boolean"],
        "n_jobs": [Integral, None],
    }

    def __init__(
        self,
        *,
        method="smrf",
        cell=1.0,
        slope=0.15,
        window=18.0,
        threshold=0.5,
        scalar=1.25,
        low_noise=1.0,
        rigidness=3,
        slope_smooth=True,
        iterations=500,
        time_step=0.65,
        keep_bases=False,
        n_jobs=None,
    ):
        self.method = method
        self.cell = cell
        self.slope = slope
        self.window = window
        self.threshold = threshold
        self.scalar = scalar
        self.low_noise = low_noise
        self.rigidness = rigidness
        self.slope_smooth = slope_smooth
        self.iterations = iterations
        self.time_step = time_step
        self.keep_bases = keep_bases
        self.n_jobs = n_jobs

    def _xyz(self, X, reset):
        from skpcd.segmentation._clusters import refuse_sequence

        refuse_sequence(X)
        X = validate_data(self, X, dtype=np.float64, reset=reset)
        if X.shape[1] < 3:
            raise ValueError(
                f"X has {X.shape[1]} feature(s); GroundFilter needs at least 3 "
                "columns (x, y, z)."
            )
        return np.ascontiguousarray(X[:, :3])

    def _minimum_surface(self, xyz):
        # the threads of the running fit: self._n_threads
        cell = float(self.cell)
        lo, nx, ny = raster_extent(xyz, cell, self._n_threads)
        if nx * ny > MAX_CELLS:
            raise ValueError(
                f"the scene needs {nx * ny} cells of {self.cell} (more than "
                f"{MAX_CELLS}); use a larger cell"
            )
        zmin = minimum_raster(
            xyz, lo, cell, (nx, ny), (0, 0), (ny, nx), self._n_threads
        )
        return lo, zmin

    def _drop_low_noise(self, zmin, known, n_threads):
        """Unknown from now: cells far below the median of their 8 neighbours."""
        from skpcd.segmentation._ground_kernels import drop_low_noise_rows

        if self.low_noise is None:
            return known
        out = np.empty_like(known)
        parallel_rows(
            drop_low_noise_rows, len(zmin), n_threads,
            zmin, known, float(self.low_noise), out,
            min_chunk=raster_rows(zmin),
        )  # fmt: skip
        return out

    def _terrain(self, zmin, n_threads):
        """The object cells and the terrain model of a minimum surface."""
        from skpcd.segmentation._ground_kernels import (
            fill_surface_rows,
            interpolate_terrain_rows,
        )

        rows = raster_rows(zmin)
        known = self._drop_low_noise(zmin, np.isfinite(zmin), n_threads)
        surface = np.empty_like(zmin)
        parallel_rows(
            fill_surface_rows, len(zmin), n_threads, zmin, known, _FILL_CELLS,
            surface, min_chunk=rows,
        )  # fmt: skip
        objects = _objects(
            surface, known, opening_cells(self), float(self.slope), float(self.cell),
            n_threads,
        )  # fmt: skip
        reach = terrain_cells(self)
        near = ndimage.maximum_filter(known, size=2 * reach + 1, mode="constant")
        dem = np.empty_like(zmin)
        parallel_rows(
            interpolate_terrain_rows, len(zmin), n_threads,
            zmin, ~objects, surface, near, reach, dem, min_chunk=rows,
        )  # fmt: skip
        return objects, dem

    @_fit_context(prefer_skip_nested_validation=True)
    @entry_point
    def fit(self, X, y=None):
        """Build the terrain model of a scene.

        Parameters
        ----------
        X : array-like of shape (n_points, 3+)
            The scene; columns beyond the third are ignored.
        y : None
            Ignored.

        Returns
        -------
        self : object
            The fitted filter.
        """
        xyz = self._xyz(X, reset=True)
        n_threads = self._n_threads = effective_threads(self.n_jobs)
        if self.method == "csf":
            return self._fit_csf(xyz)
        self._fit_smrf(xyz, n_threads)
        if self.keep_bases:
            self.ground_ = without_bases(xyz, self.ground_, n_threads)
        return self

    def _fit_smrf(self, xyz, n_threads):
        """SMRF's terrain model and ground flags (see :meth:`fit`)."""
        if type(self)._minimum_surface is not GroundFilter._minimum_surface:
            # a window of a larger raster (the tiled segmentation)
            lo, zmin = self._minimum_surface(xyz)
            patch = (0, 0, *self._terrain(zmin, n_threads))
            self._fit_patches(xyz, lo, [patch], n_threads)
            return self
        cell = float(self.cell)
        lo, nx, ny = raster_extent(xyz, cell, n_threads)
        reach = reach_cells(self) + 1
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
        window = [
            (np.maximum(r[:2] - 2 * reach, 0), np.minimum(r[2:] + 2 * reach, size))
            for r in rects
        ]
        n_cells = sum(int(np.prod(b - a + 1)) for a, b in window)
        if n_cells > MAX_CELLS:
            raise ValueError(
                f"the occupied part of the scene needs {n_cells} cells of "
                f"{self.cell} (more than {MAX_CELLS}); use a larger cell"
            )
        if len(rects) == 1:
            zmin = minimum_raster(xyz, lo, cell, (nx, ny), (0, 0), (ny, nx), n_threads)
            patch = (0, 0, *self._terrain(zmin, n_threads))
            self._fit_patches(xyz, lo, [patch], n_threads)
            return self
        order = np.argsort(label, kind="stable")
        bounds = np.searchsorted(label[order], np.arange(len(rects) + 1))
        patches = []
        self._shape = (ny, nx)
        self.origin_ = lo
        ground = np.zeros(len(xyz), dtype=bool)
        for i, ((c0, r0), (c1, r1)) in enumerate(window):
            mine = order[bounds[i] : bounds[i + 1]]
            pts = np.ascontiguousarray(xyz[mine])
            zmin = minimum_raster(
                pts, lo, cell, (nx, ny), (c0, r0), (r1 - r0 + 1, c1 - c0 + 1),
                n_threads,
            )  # fmt: skip
            objects, dem = self._terrain(zmin, n_threads)
            k0 = np.maximum(rects[i, :2] - reach, 0)
            k1 = np.minimum(rects[i, 2:] + reach, [nx - 1, ny - 1])
            part = (
                slice(k0[1] - r0, k1[1] - r0 + 1),
                slice(k0[0] - c0, k1[0] - c0 + 1),
            )
            patches.append((int(k0[0]), int(k0[1]), objects[part], dem[part]))
            ground[mine] = self._ground_patch(patches[-1], pts, n_threads)
        # patches (c0, r0, objects, dem) of the raster of _shape cells, NaN
        # and objects elsewhere
        self._patches = patches
        self.ground_ = ground
        return self

    def _fit_csf(self, xyz):
        """CSF's ground flags, and a DEM of the ground points (see Notes)."""
        from skpcd.segmentation._csf import csf_ground
        from skpcd.segmentation._ground_kernels import cell_mean

        ground = csf_ground(
            xyz,
            cloth_resolution=self.cell,
            class_threshold=self.threshold,
            rigidness=self.rigidness,
            slope_smooth=self.slope_smooth,
            iterations=self.iterations,
            time_step=self.time_step,
        )
        if self.keep_bases:
            ground = without_bases(xyz, ground, self._n_threads)
        cell = float(self.cell)
        lo, nx, ny, cells = cell_indices(xyz, cell, self._n_threads)
        if nx * ny <= len(xyz):
            rects, label = np.array([[0, 0, nx - 1, ny - 1]]), None
        else:  # the DEM of the occupied parts only (see GroundFilter.fit)
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
        self.origin_ = lo
        self._shape = None if label is None else (ny, nx)
        self._patches = patches
        self.ground_ = ground
        return self

    def _fit_patches(self, xyz, lo, patches, n_threads):
        """Store the fitted raster of one patch: the whole raster, or the
        tile's window."""
        self.origin_ = lo
        self._shape = None
        self._patches = patches
        self.ground_ = self._ground(xyz, n_threads)

    def _dense(self, k, fill):
        check_is_fitted(self)
        if self._shape is None:
            return self._patches[0][k]
        ny, nx = self._shape
        if nx * ny > MAX_CELLS:
            raise ValueError(
                f"the raster of the scene has {nx * ny} cells (more than "
                f"{MAX_CELLS}), most far from every point; use height() or "
                "predict()"
            )
        out = np.full(self._shape, fill)
        for c0, r0, *grids in self._patches:
            g = grids[k - 2]
            out[r0 : r0 + g.shape[0], c0 : c0 + g.shape[1]] = g
        return out

    @property
    def dem_(self):
        """Terrain height at the cell centres (see the class docstring)."""
        return self._dense(3, np.nan)

    @property
    def objects_(self):
        """Cells flagged as objects (or empty, or low noise)."""
        return self._dense(2, True)

    @entry_point
    def height(self, X):
        """Height of points above the terrain model.

        Parameters
        ----------
        X : array-like of shape (n_points, 3+)
            Points in the area of the fitted scene (beyond it the DEM is
            extended flat).

        Returns
        -------
        height : ndarray of shape (n_points,)
            ``z`` minus the DEM interpolated bilinearly at ``(x, y)``.
        """
        check_is_fitted(self)
        xyz = self._xyz(X, reset=False)
        return xyz[:, 2] - self._sample(xyz, False, effective_threads(self.n_jobs))

    def _sample(self, xyz, slope, n_threads):
        """The DEM (or its slope) interpolated at the points."""
        if self._shape is None:
            dem = self._patches[0][3]
            grid = _slope(dem, float(self.cell)) if slope else dem
            return self._at(grid, xyz, n_threads)
        out = np.full(len(xyz), np.nan)
        if not np.isfinite(xyz[:, :2]).all():
            raise ValueError("X contains NaN or infinite coordinates.")
        ny, nx = self._shape
        u = np.clip((xyz[:, :2] - self.origin_) / float(self.cell), 0, [nx - 1, ny - 1])
        for c0, r0, _, dem in self._patches:
            h, w = dem.shape
            mine = np.flatnonzero(
                (u[:, 0] >= c0)
                & (u[:, 0] < c0 + w)
                & (u[:, 1] >= r0)
                & (u[:, 1] < r0 + h)
            )
            if len(mine):
                out[mine] = self._patch_at(c0, r0, dem, xyz[mine], slope, n_threads)
        return out

    def _patch_frame(self, c0, r0):
        """The raster frame of a patch of the islands' raster (see
        :meth:`_frame`)."""
        ny, nx = self._shape
        return (*(float(v) for v in self.origin_), nx, ny, c0, r0)

    def _patch_at(self, c0, r0, dem, xyz, slope, n_threads):
        from skpcd.segmentation._ground_kernels import bilinear_rows

        grid = _slope(dem, float(self.cell)) if slope else dem
        out = np.empty(len(xyz))
        x0, y0, nx, ny, _, _ = self._patch_frame(c0, r0)
        parallel_rows(
            bilinear_rows, len(xyz), n_threads,
            xyz, x0, y0, float(self.cell), nx, ny, c0, r0, grid, out,
        )  # fmt: skip
        return out

    def _classify(self, xyz, frame, dem, n_threads):
        """SMRF's test of the points against a DEM (and its slope) whose
        cells are placed by ``frame`` (see :meth:`_frame`)."""
        from skpcd.segmentation._ground_kernels import classify_rows

        x0, y0, nx, ny, c0, r0 = frame
        out = np.empty(len(xyz), dtype=bool)
        parallel_rows(
            classify_rows, len(xyz), n_threads,
            xyz, x0, y0, float(self.cell), nx, ny, c0, r0,
            dem, _slope(dem, float(self.cell)),
            float(self.threshold), float(self.scalar), out,
        )  # fmt: skip
        return out

    def _ground_patch(self, patch, xyz, n_threads):
        c0, r0, _, dem = patch
        return self._classify(xyz, self._patch_frame(c0, r0), dem, n_threads)

    def _frame(self, grid):
        """Where the cells of ``grid``, the raster of the one patch, lie:
        ``(x0, y0, nx, ny, c0, r0)``, the corner and cells of the whole
        raster, and the first cell of ``grid`` in it."""
        ny, nx = grid.shape
        return (*(float(v) for v in self.origin_), nx, ny, 0, 0)

    def _at(self, grid, xyz, n_threads):
        from skpcd.segmentation._ground_kernels import bilinear_rows

        out = np.empty(len(xyz))
        x0, y0, nx, ny, c0, r0 = self._frame(grid)
        parallel_rows(
            bilinear_rows, len(xyz), n_threads,
            xyz, x0, y0, float(self.cell), nx, ny, c0, r0, grid, out,
        )  # fmt: skip
        return out

    def _ground(self, xyz, n_threads):
        if self.method == "csf":
            dem = (
                self._at(self._patches[0][3], xyz, n_threads)
                if self._shape is None
                else self._sample(xyz, False, n_threads)
            )
            with np.errstate(invalid="ignore"):
                return np.abs(xyz[:, 2] - dem) <= float(self.threshold)
        if self._shape is not None:
            dz = np.abs(xyz[:, 2] - self._sample(xyz, False, n_threads))
            return dz <= self.threshold + self.scalar * self._sample(
                xyz, True, n_threads
            )
        dem = self._patches[0][3]
        return self._classify(xyz, self._frame(dem), dem, n_threads)

    @entry_point
    def predict(self, X):
        """Which points are ground.

        Parameters
        ----------
        X : array-like of shape (n_points, 3+)
            Points in the area of the fitted scene.

        Returns
        -------
        ground : ndarray of shape (n_points,), dtype bool
            True for ground points.
        """
        check_is_fitted(self)
        return self._ground(self._xyz(X, reset=False), effective_threads(self.n_jobs))

    @entry_point
    def fit_predict(self, X, y=None):
        """Fit the terrain model of a scene and return its ground points.

        Parameters
        ----------
        X : array-like of shape (n_points, 3+)
            The scene.
        y : None
            Ignored.

        Returns
        -------
        ground : ndarray of shape (n_points,), dtype bool
            True for ground points.
        """
        return self.fit(X).ground_
