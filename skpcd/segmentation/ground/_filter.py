"""GroundFilter: the estimator that removes the ground of a scene, a thin
front over the filters of this package (SMRF in ``_smrf``, CSF in ``_csf``)
and the terrain model they fit (``_terrain``)."""

import typing
from numbers import Integral, Real

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from skpcd.segmentation.ground._bases import BASE_THRESHOLD, BASES, without_bases
from skpcd.segmentation.ground._csf import csf_ground, csf_terrain
from skpcd.segmentation.ground._smrf import smrf_fit, smrf_ground
from skpcd.utils._compile import entry_point
from skpcd.utils._estimator import SceneEstimator
from skpcd.utils._parallel import effective_threads
from skpcd.utils._validation import check_scene

__all__ = ["GroundFilter", "fit_window"]


class GroundFilter(SceneEstimator):
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
        run.

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
    Every step of SMRF computes a cell from the cells within a fixed
    distance of it (``3 * ceil(window / cell) + 10`` cells in all): the
    fills of empty and object cells are local, not the global inpainting of
    Pingel et al. or PDAL's inverse-distance weighting, so the filter on a
    window of the raster gives the whole raster's answer, and the tiled
    :func:`~skpcd.segmentation.segment_scene` is exact. The disk of the
    opening is approximated by an octagon (alternate 3x3 squares and
    crosses).

    The cost follows the occupied cells, not the bounding box of the
    scene: occupied cells far apart are filtered as separate islands, each
    on its own raster, with the whole raster's answer on every cell near a
    point and no terrain (NaN) between islands. A point far from the scene
    (an outlier 100 km away) is thus its own island, ground or not by the
    same local rule. The islands' cells, summed, may not exceed 200
    million (a ValueError asks for a larger ``cell``), nor may the scene
    span more than 2**53 cells along an axis. Remove outliers beforehand
    with :class:`~skpcd.preprocessing.StatisticalOutlierFilter` or
    :class:`~skpcd.preprocessing.RadiusOutlierFilter` when they are noise.

    ``GROUND_PRESETS`` holds the parameters for each kind of scan:
    ``"aerial"`` are these defaults (those of Pingel et al. and PDAL's
    ``filters.smrf``), ``"mobile"`` SMRF for urban mobile scans, ``"csf"``
    CSF with its authors' defaults but a 0.3 m threshold, and ``"street"``
    CSF with ``keep_bases``, the default of
    :func:`~skpcd.segmentation.segment_scene` on scans made from the street
    (the user guide gives the measurements behind these choices).

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

    def _fit(self, xyz):
        n_threads = effective_threads(self.n_jobs)
        if self.method == "csf":
            ground = csf_ground(xyz, **csf_params(self))
            if self.keep_bases:
                ground = without_bases(xyz, ground, n_threads)
            terrain = csf_terrain(xyz, ground, self.cell, n_threads)
        else:
            ground, terrain = smrf_fit(xyz, self, n_threads)
            if self.keep_bases:
                ground = without_bases(xyz, ground, n_threads)
        self._set_terrain(terrain, ground)

    def _set_terrain(self, terrain, ground):
        self._terrain = terrain
        self.origin_ = terrain.origin
        self.ground_ = ground

    @property
    def dem_(self):
        """Terrain height at the cell centres (see the class docstring)."""
        check_is_fitted(self)
        return self._terrain.dense(3, np.nan)

    @property
    def objects_(self):
        """Cells flagged as objects (or empty, or low noise)."""
        check_is_fitted(self)
        return self._terrain.dense(2, True)

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
        xyz = check_scene(X, self, reset=False)
        n_threads = effective_threads(self.n_jobs)
        return xyz[:, 2] - self._terrain.sample(xyz, False, n_threads)

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
        xyz = check_scene(X, self, reset=False)
        n_threads = effective_threads(self.n_jobs)
        if self.method == "smrf":
            return smrf_ground(self._terrain, xyz, self, n_threads)
        dem = self._terrain.sample(xyz, False, n_threads)
        with np.errstate(invalid="ignore"):
            return np.abs(xyz[:, 2] - dem) <= float(self.threshold)

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


def csf_params(filt):
    """The keyword arguments of :func:`~skpcd.segmentation.ground._csf.csf_ground`
    that a CSF :class:`GroundFilter` runs with."""
    return {
        "cloth_resolution": filt.cell,
        "class_threshold": filt.threshold,
        "rigidness": filt.rigidness,
        "slope_smooth": filt.slope_smooth,
        "iterations": filt.iterations,
        "time_step": filt.time_step,
    }


def bases_filter(threshold=BASE_THRESHOLD):
    """The SMRF :class:`GroundFilter` of the ``keep_bases`` pass
    (:func:`~skpcd.segmentation.ground._bases.without_bases`), for
    :func:`fit_window` on the ground points of a tile."""
    return GroundFilter(**BASES, threshold=threshold, low_noise=None)


def fit_window(filt, xyz, window, n_threads):
    """A copy of an SMRF :class:`GroundFilter` fitted on a tile of a scene.

    Parameters
    ----------
    filt : GroundFilter
        The filter (``method="smrf"``); its parameters are copied.
    xyz : ndarray of shape (n_points, 3+)
        The tile's points; columns beyond the third are ignored.
    window : tuple
        Where the tile's cells lie in the scene's raster (see
        :func:`~skpcd.segmentation.ground._smrf.smrf_fit`).
    n_threads : int
        Threads of the filter.

    Returns
    -------
    fitted : GroundFilter
        The copy, fitted: its ``ground_`` are those of the whole scene's
        filter at the points away from the window's edges.
    """
    est = GroundFilter(**{**filt.get_params(), "n_jobs": n_threads})
    xyz = np.ascontiguousarray(xyz[:, :3], dtype=np.float64)
    ground, terrain = smrf_fit(xyz, est, n_threads, window=window)
    if est.keep_bases:
        ground = without_bases(xyz, ground, n_threads)
    est.n_features_in_ = xyz.shape[1]
    est._set_terrain(terrain, ground)
    return est
