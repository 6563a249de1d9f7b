"""Ground removal: the simple morphological filter (SMRF) of Pingel et al.

The scene is rasterised into its minimum-z surface; a progressive
morphological opening with a growing disk flags the cells that rise above
the opened surface more than the terrain slope allows (objects); the
remaining cells are interpolated into a terrain model (DEM), and a point is
ground when it lies within a threshold of the DEM, the threshold growing
with the local slope of the DEM.
"""

import typing
from numbers import Real

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.linalg import spsolve
from sklearn.base import BaseEstimator, _fit_context
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted, validate_data

__all__ = ["GROUND_PRESETS", "GroundFilter"]

# Parameters for the two kinds of scan; "aerial" are the defaults of
# GroundFilter (those of Pingel et al. and of PDAL's filters.smrf).
GROUND_PRESETS = {
    "aerial": {
        "cell": 1.0,
        "slope": 0.15,
        "window": 18.0,
        "threshold": 0.5,
        "scalar": 1.25,
    },
    "mobile": {
        "cell": 0.5,
        "slope": 0.15,
        "window": 10.0,
        "threshold": 0.25,
        "scalar": 1.25,
    },
}

# Cells of the raster at most (a 1 km square at 5 mm): beyond, ask for a
# larger ``cell`` rather than allocating gigabytes.
_MAX_CELLS = 200_000_000
_SQUARE = np.ones((3, 3), dtype=bool)
_CROSS = ndimage.generate_binary_structure(2, 1)


def _inpaint(z, known):
    """``z`` with the cells not ``known`` replaced by the harmonic (Laplace)
    interpolation of the known ones: every unknown cell is the mean of its
    4-neighbours (fewer at the border). Needs a known cell."""
    unknown = ~known
    if not unknown.any():
        return z.copy()
    ny, nx = z.shape
    index = np.full(z.shape, -1, dtype=np.int64)
    index[unknown] = np.arange(unknown.sum())
    n = int(unknown.sum())
    rows, cols, vals = [], [], []
    rhs = np.zeros(n)
    degree = np.zeros(n)
    rr, cc = np.nonzero(unknown)
    me = index[rr, cc]
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        r2, c2 = rr + dr, cc + dc
        inside = (r2 >= 0) & (r2 < ny) & (c2 >= 0) & (c2 < nx)
        a, r2, c2 = me[inside], r2[inside], c2[inside]
        degree[a] += 1
        other = index[r2, c2]
        free = other >= 0
        rows.append(a[free])
        cols.append(other[free])
        vals.append(-np.ones(free.sum()))
        np.add.at(rhs, a[~free], z[r2[~free], c2[~free]])
    rows.append(np.arange(n))
    cols.append(np.arange(n))
    vals.append(degree)
    A = sparse.csc_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(n, n),
    )
    out = z.copy()
    out[unknown] = spsolve(A, rhs)
    return out


def _opening(z, radius):
    """Grey opening with a disk of ``radius`` cells, approximated by an
    octagon: erosions (then dilations) alternating a 3x3 square and a
    cross, the square first."""
    steps = [_SQUARE if s % 2 == 0 else _CROSS for s in range(radius)]
    out = z
    for fp in steps:
        out = ndimage.grey_erosion(out, footprint=fp, mode="nearest")
    for fp in steps:
        out = ndimage.grey_dilation(out, footprint=fp, mode="nearest")
    return out


class GroundFilter(BaseEstimator):
    """Ground points of a LiDAR scene by the simple morphological filter (SMRF).

    :meth:`fit` builds a terrain model (DEM) of the scene; :meth:`predict`
    says which points lie on it. The method is SMRF (Pingel et al., 2013):

    1. the lowest z of each ``cell`` x ``cell`` square; empty cells, and
       cells more than ``low_noise`` below the median of their neighbours
       (low outliers), are interpolated;
    2. the surface is opened (erosion, then dilation) with disks of radius
       1, 2, ... up to ``window`` metres; a cell whose height drops by more
       than ``slope`` times the radius is an object;
    3. the non-object cells, interpolated over the object cells, make the
       DEM;
    4. a point is ground when it lies within ``threshold + scalar * s`` of
       the DEM (above or below), ``s`` the slope of the DEM at the point.

    All lengths are in the units of the coordinates (metres).

    Read more in the :ref:`User Guide <segmentation>`.

    Parameters
    ----------
    cell : float, default=1.0
        Raster cell size (PDAL's ``cell``). Mobile scans: 0.5.
    slope : float, default=0.15
        Largest terrain slope (rise over run) kept as ground by the opening
        (PDAL's ``slope``).
    window : float, default=18.0
        Largest radius of the opening: half the width of the largest object
        to remove (PDAL's ``window``). Mobile scans (facades, vehicles): 10.
    threshold : float, default=0.5
        Largest height above (or below) the DEM of a ground point on flat
        terrain (PDAL's ``threshold``). Mobile scans: 0.25.
    scalar : float, default=1.25
        Growth of that height with the DEM slope (PDAL's ``scalar``).
    low_noise : float or None, default=1.0
        A cell whose lowest point is more than this below the median of its
        8 neighbours holds low noise (multipath, a point under the ground)
        and is left out of the minimum surface. None keeps every cell.

    Attributes
    ----------
    dem_ : ndarray of shape (n_rows, n_cols)
        Terrain height at the cell centres; row ``r``, column ``c`` is
        centred at ``origin_ + cell * (c + 0.5, r + 0.5)``.
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
    crosses), which makes each opening a chain of separable 3x3 filters.
    Empty and object cells are filled by harmonic (Laplace) interpolation,
    where Pingel et al. use a spring-metaphor inpainting; both are smooth
    and exact on the known cells.

    ``GROUND_PRESETS["aerial"]`` are these defaults (those of Pingel et al.
    and PDAL's ``filters.smrf``); ``GROUND_PRESETS["mobile"]`` are for
    urban mobile scans, denser and lower.

    References
    ----------
    .. [1] T. J. Pingel, K. C. Clarke, W. A. McBride, "An improved simple
       morphological filter for the terrain classification of airborne
       LIDAR data", ISPRS J. Photogramm. Remote Sens. 77, 21-30, 2013.

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
        "cell": [Interval(Real, 0, None, closed="neither")],
        "slope": [Interval(Real, 0, None, closed="left")],
        "window": [Interval(Real, 0, None, closed="neither")],
        "threshold": [Interval(Real, 0, None, closed="left")],
        "scalar": [Interval(Real, 0, None, closed="left")],
        "low_noise": [Interval(Real, 0, None, closed="neither"), None],
    }

    def __init__(
        self,
        *,
        cell=1.0,
        slope=0.15,
        window=18.0,
        threshold=0.5,
        scalar=1.25,
        low_noise=1.0,
    ):
        self.cell = cell
        self.slope = slope
        self.window = window
        self.threshold = threshold
        self.scalar = scalar
        self.low_noise = low_noise

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
        from skpcd.segmentation._ground_kernels import cell_minimum

        lo = xyz[:, :2].min(axis=0)
        extent = xyz[:, :2].max(axis=0) - lo
        nx, ny = (np.floor(extent / self.cell) + 1).astype(np.int64)
        if nx * ny > _MAX_CELLS:
            raise ValueError(
                f"the scene ({extent[0]:.1f} x {extent[1]:.1f}) needs {nx * ny} "
                f"cells of {self.cell}; use a larger cell"
            )
        zmin = np.full((ny, nx), np.inf)
        cell_minimum(xyz, lo[0], lo[1], float(self.cell), nx, ny, 0, 0, zmin)
        return lo, zmin

    def _drop_low_noise(self, zmin, known):
        """Unknown from now: cells far below the median of their 8 neighbours."""
        if self.low_noise is None or known.sum() < 2:
            return known
        filled = _nearest_fill(zmin, known)
        ring = np.ones((3, 3), dtype=bool)
        ring[1, 1] = False
        median = ndimage.median_filter(filled, footprint=ring, mode="nearest")
        return known & ~(zmin < median - self.low_noise)

    @_fit_context(prefer_skip_nested_validation=True)
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
        lo, zmin = self._minimum_surface(xyz)
        known = self._drop_low_noise(zmin, np.isfinite(zmin))
        surface = _inpaint(np.where(known, zmin, 0.0), known)
        objects = ~known
        radius_max = max(1, int(np.ceil(self.window / self.cell)))
        last = surface
        for radius in range(1, radius_max + 1):
            opened = _opening(last, radius)
            objects |= last - opened > self.slope * radius * self.cell
            last = opened
        ground_cells = ~objects
        if not ground_cells.any():
            # nothing but objects (a scene smaller than the window on a
            # slope): the lowest surface is the best terrain there is
            ground_cells = known
        self.origin_ = lo
        self.objects_ = objects
        self.dem_ = _inpaint(np.where(ground_cells, zmin, 0.0), ground_cells)
        self.ground_ = self._ground(xyz)
        return self

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
        return xyz[:, 2] - self._at(self.dem_, xyz)

    def _at(self, grid, xyz):
        from skpcd.segmentation._ground_kernels import bilinear

        out = np.empty(len(xyz))
        ny, nx = grid.shape
        x0, y0 = self.origin_
        bilinear(xyz, x0, y0, float(self.cell), nx, ny, 0, 0, grid, out)
        return out

    def _ground(self, xyz):
        gy, gx = (
            np.gradient(self.dem_, self.cell)
            if min(self.dem_.shape) > 1
            else (
                np.zeros_like(self.dem_),
                np.zeros_like(self.dem_),
            )
        )
        slope = np.hypot(gx, gy)
        dz = np.abs(xyz[:, 2] - self._at(self.dem_, xyz))
        return dz <= self.threshold + self.scalar * self._at(slope, xyz)

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
        return self._ground(self._xyz(X, reset=False))

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


def _nearest_fill(z, known):
    """Unknown cells take the value of the nearest known cell."""
    if known.all():
        return z
    idx = ndimage.distance_transform_edt(
        ~known, return_distances=False, return_indices=True
    )
    return z[tuple(idx)]
