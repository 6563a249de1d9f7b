"""What kind of scan a cloud is (airborne, car-mounted profiler, spinning
sensor, robot), read from the points themselves, and the segmentation
defaults for each kind."""

import typing

import numpy as np
from scipy.spatial import cKDTree

from skpcd.preprocessing._spacing import (
    LOCAL_RATIO,
    nearest_neighbours,
    spacing_of,
    spacing_queries,
)
from skpcd.segmentation._dbscan import stable_draw

__all__ = ["SCAN_KINDS", "ScanKind", "describe_scan", "sweep_coordinates"]

# The kinds and the defaults of segment_scene with ground="auto" for each:
# the ground preset (a key of GROUND_PRESETS), the largest automatic
# radius (max_eps, metres, that of the structures) and, for single sweeps,
# the clustering radius in sweep_coordinates, where a radius is a distance
# proportional to the range, as a multiple of the knee distance estimated
# there (relative_eps_scale). Chosen on real scans
# (benchmarks/bench_scan_kinds.py, table in the user guide): SMRF with the
# aerial preset on airborne tiles (CSF loses steep and forested terrain
# there); CSF followed by the pass that gives object bases back on the
# scans made from the street. A single sweep is dense near the sensor and
# sparse far away, and its automatic radius follows the far points (0.3
# to 2 m on the 12 real sweeps of ../shared/data/real_mobile): capped at
# 0.75 m, with the bases pass, 0.63 of the boxed objects are whole (mean
# over the sweeps) against 0.57 with the previous defaults. A radius
# proportional to the range does better: on those sweeps (all 64-beam),
# 1.4 times the knee distance in sweep coordinates (1.0 to 2.0 tried) gives
# the best mean of whole and purity, 0.698 (0.663 whole, 0.733 pure), and
# about 2 % of the range. (Measured with the sample drawn before the draw
# that appended points leave as it was: with it, as with another seed,
# 0.585 whole and 0.739 pure as means over the sweeps, one sweep's single
# object broken; 366 of the 657 objects whole against 365.) Estimated
# rather than fixed, the radius follows the rings of the sensor: on
# simulated 16-beam robot sweeps, whose rings are 2 degrees apart, it
# bridges them (0.71 of the objects kept against 0.26 with a fixed 2 %;
# benchmarks/results/scan_kinds.txt).
SCAN_KINDS = {
    "airborne": {"ground": "aerial"},
    "profiler": {"ground": "street"},
    "spinning": {"ground": "street", "max_eps": 0.75, "relative_eps_scale": 1.4},
    "robot": {"ground": "street", "max_eps": 0.75, "relative_eps_scale": 1.4},
}

# Points drawn for the measurements (the spacing, the shape of the
# neighbourhoods, the concentration around one position).
_SAMPLE = 20_000
_SHAPE_SAMPLE = 3_000
# Points of the sample tried as the position the points concentrate around.
_CENTRES = 200
# A cloud whose planar neighbourhoods are less often vertical (walls, car
# sides, trunks) than this was seen from above. Measured on 27 real
# airborne tiles (PDAL's and laspy's test files, the 15 ISPRS filter-test
# samples): at most 0.10; on the 12 real street sweeps of
# ../shared/data/real_mobile (KITTI, PandaSet) at least 0.29; on simulated
# robot sweeps (a 16 or 32 beam sensor 0.5 to 1 m up) 0.12 to 0.31 ...
_VERTICAL_AIRBORNE = 0.15
# ... so a cloud with few vertical surfaces is airborne only if its points
# are not concentrated around one position: concentration at least 0.37 on
# the real airborne tiles above (but one terrestrial file of laspy's tests,
# 0.01), at most 0.33 on those robot sweeps.
_CONCENTRATION_AIRBORNE = 0.30
# A single sweep from one position puts half its points within this
# fraction of the distance that holds 95 % of them (0.13-0.36 measured on
# real and simulated sweeps; 0.37-0.50 on profiler scans, which spread
# their points along the trajectory) ...
_CONCENTRATION_SWEEP = 0.40
# ... and holds at most this many points (one rotation of a 128-beam
# sensor: about 260 000; a profiler scan of a street holds millions) ...
_MAX_SWEEP_POINTS = 500_000
# ... and its points 3 to 20 m from that position lie all around it: at least
# this fraction of the 72 sectors of 5 degrees of azimuth hold 0.2 % of them
# or more (0.78 to 1.00 on the 71 real sweeps of ../shared/data/real_labelled
# and the 12 of real_mobile, occlusions included). A short stretch of a
# profiler, its scan planes across the street over a few metres of
# trajectory, also concentrates its points around one position but leaves
# them in two opposite bands of azimuth: 0.08 to 0.33 on real stretches of
# 0.1 s to 0.7 s of a RIEGL profiler on a van in Paris (Stereopolis II) and
# on a chunk of Paris-rue-Madame. The coverage tells only when at least a
# quarter of the points lie 3 to 20 m away (at least 0.32 of them on the
# real sweeps above, 0.48 to 0.57 on the profiler's stretches): a sweep
# taken close to its surroundings, on a bench or indoors, has too few there
# (0.10 to 0.17 on three bench recordings of Hesai and RoboSense sensors).
_AZIMUTH_SWEEP = 0.6
_AZIMUTH_NEAR = (3.0, 20.0)
_AZIMUTH_NEAR_SHARE = 0.25
_AZIMUTH_SECTORS = 72
_AZIMUTH_SHARE = 0.002
# A sensor lower than this above the ground (when given) is on a robot.
_ROBOT_HEIGHT = 1.2


class ScanKind(typing.NamedTuple):
    """What :func:`describe_scan` returns (a named tuple).

    Attributes
    ----------
    kind : str
        "airborne", "profiler" (a car-mounted mobile-mapping system whose
        profilers sweep planes as the vehicle drives), "spinning" (one
        sweep of a multi-beam sensor on a car, as in KITTI or PandaSet) or
        "robot" (a spinning sensor less than 1.2 m above the ground; told
        only when the sensor position is given).
    reason : str
        The measurement that decided, in words.
    spacing : float
        Median distance of a point to its nearest neighbour.
    vertical : float
        Fraction of planar neighbourhoods that are vertical.
    concentration : float
        Median distance of the points to the position around which they
        are the most concentrated, over the distance holding 95 % of them.
    sensor_height : float or None
        Height of the given sensor above the lowest points near it.
    centre : tuple of float
        x and y of the position around which the points concentrate (the
        given sensor's when there is one): for a single sweep, about the
        sensor's.
    azimuth_coverage : float or None
        Fraction of the 72 sectors of 5 degrees of azimuth around ``centre``
        that hold at least 0.2 % of the points 3 to 20 m from it (measured
        when the points concentrate around one position and a quarter of
        them or more lie that far; None otherwise).
    """

    kind: str
    reason: str
    spacing: float
    vertical: float
    concentration: float
    sensor_height: float | None = None
    centre: tuple = (0.0, 0.0)
    azimuth_coverage: float | None = None

    def summary(self):
        """One line for a log: the kind and the measurements."""
        coverage = (
            ""
            if self.azimuth_coverage is None
            else f", azimuth coverage {self.azimuth_coverage:.2f}"
        )
        return (
            f"{self.kind} scan ({self.reason}; spacing {self.spacing:.3g}, "
            f"vertical {self.vertical:.2f}, concentration {self.concentration:.2f}"
            f"{coverage})"
        )


def describe_scan(points, *, sensor=None, scan_angle=None, random_state=0):
    """Tell the kind of a scan (airborne, profiler, spinning, robot) from its points.

    :func:`~skpcd.segmentation.segment_scene` uses it with
    ``ground="auto"`` to pick its ground filter (``SCAN_KINDS[kind]``).
    The decision, in order:

    1. A ``sensor`` position more than 30 m above the lowest points within
       50 m of it: airborne. One less than 1.2 m above them: robot.
    2. ``scan_angle`` (degrees, the LAS field) spread between -45 and 45
       degrees and not all equal: airborne (a street scanner's angles
       cover the whole rotation).
    3. Airborne when fewer than 15 % of the planar neighbourhoods (12
       nearest neighbours, on 3,000 points) are vertical (seen from above,
       walls, car sides and trunks get few points), unless the points are
       concentrated around one position (concentration, below, under
       0.3: a sensor low on a robot also sees few walls).
    4. Otherwise, a single sweep from one position (spinning) when the
       points concentrate around one position (half of them within 0.4 of
       the distance that holds 95 %), there are at most 500,000 of them and
       those 3 to 20 m from that position lie all around it (at least 60 %
       of the sectors of 5 degrees of azimuth hold 0.2 % of them: a short
       stretch of a profiler leaves them in two bands across the
       trajectory; not asked when fewer than a quarter of the points are
       that far, as in a sweep taken close to its surroundings); else a
       profiler scan.

    The thresholds were measured on real scans (PDAL's and laspy's aerial
    test files, the ISPRS filter-test samples, KITTI and PandaSet sweeps)
    and simulated ones of every pattern; see the user guide.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        The scan; columns beyond the third are ignored.
    sensor : array-like of shape (3,) or None, default=None
        The sensor position (for a single sweep), if known.
    scan_angle : array-like of shape (n_points,) or None, default=None
        Scan angle of each point in degrees (LAS ``scan_angle``), if known.
    random_state : int, RandomState instance or None, default=0
        Draws the points measured.

    Returns
    -------
    scan : ScanKind
        The kind, the reason and the measurements.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import describe_scan
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(0, 200, (20000, 2))
    >>> tile = np.column_stack([xy, rng.normal(0, 0.05, 20000)])
    >>> describe_scan(tile).kind
    'airborne'
    """
    xyz = np.asarray(points, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] < 3 or len(xyz) < 13:
        raise ValueError(
            "describe_scan needs an (n_points, 3+) array of at least 13 points, "
            f"got shape {xyz.shape}"
        )
    xyz = xyz[:, :3]
    rng = np.random.default_rng(
        random_state
        if not hasattr(random_state, "randint")
        else random_state.randint(2**31)
    )
    # a draw that points appended to the cloud (far outliers) leave as it was
    drawn = stable_draw(len(xyz), min(len(xyz), _SAMPLE), rng)
    sample = xyz[np.sort(drawn)]
    spacing, vertical = _spacing_vertical(xyz, sample[:_SHAPE_SAMPLE])
    concentration, centre = _concentration(sample, xyz[drawn[:_CENTRES], :2])
    measured = {
        "spacing": float(spacing),
        "vertical": vertical,
        "concentration": concentration,
        "centre": centre,
    }
    if sensor is not None:
        sensor = np.asarray(sensor, dtype=np.float64).ravel()
        if sensor.shape != (3,) or not np.isfinite(sensor).all():
            raise ValueError(
                f"sensor must be a finite (x, y, z) position, got {sensor}"
            )
        measured["centre"] = (float(sensor[0]), float(sensor[1]))
        near = np.hypot(*(xyz[:, :2] - sensor[:2]).T) < 50.0
        if near.any():
            height = float(sensor[2] - np.quantile(xyz[near, 2], 0.02))
            measured["sensor_height"] = height
            if height > 30.0:
                return ScanKind("airborne", f"sensor {height:.0f} m up", **measured)
            if height < _ROBOT_HEIGHT:
                return ScanKind("robot", f"sensor {height:.2f} m up", **measured)
    if scan_angle is not None:
        angle = np.asarray(scan_angle, dtype=np.float64)
        if len(angle) and np.ptp(angle) > 0 and np.abs(angle).max() <= 45.0:
            return ScanKind("airborne", "scan angles within 45 degrees", **measured)
    if vertical < _VERTICAL_AIRBORNE and concentration >= _CONCENTRATION_AIRBORNE:
        return ScanKind("airborne", "few vertical surfaces", **measured)
    if concentration < _CONCENTRATION_SWEEP and len(xyz) <= _MAX_SWEEP_POINTS:
        coverage = _azimuth_coverage(sample, centre)
        measured["azimuth_coverage"] = coverage
        if coverage is None or coverage >= _AZIMUTH_SWEEP:
            return ScanKind("spinning", "points around one position", **measured)
        return ScanKind("profiler", "points in bands across a short path", **measured)
    return ScanKind("profiler", "points spread along a path", **measured)


def _spacing_vertical(xyz, shape_queries, local_ratio=LOCAL_RATIO):
    """The spacing of the points (:func:`~skpcd.preprocessing.point_spacing`
    on ``_SAMPLE`` of them, seed 0) and the fraction of vertical planar
    neighbourhoods (:func:`_vertical_fraction`) around ``shape_queries``.

    Both are those of one k-d tree of all the points. A cloud of more than
    ``local_ratio`` points per query point has its neighbourhoods found by
    :func:`~skpcd.preprocessing._spacing.nearest_neighbours` instead (a
    tree of the points near the queries, 13 neighbours each): the same
    distances; the same neighbourhoods, in the same order, unless a
    query's 13 nearest points hold two at the same distance and not at the
    same place (which of them a tree returns depends on its shape): then
    the neighbourhoods are those of the tree of all the points, as
    before."""
    rows = spacing_queries(len(xyz), _SAMPLE, 0)
    spacing_queries_ = xyz if rows is None else xyz[rows]
    m = len(spacing_queries_)
    queries = np.concatenate([spacing_queries_, shape_queries])
    if len(xyz) <= local_ratio * len(queries):
        tree = cKDTree(xyz)
        dist, _ = tree.query(spacing_queries_, k=min(len(xyz), 8))
        _, idx = tree.query(shape_queries, k=min(12, len(xyz)))
        return spacing_of(dist), _vertical_fraction(xyz, idx)
    dist, idx = nearest_neighbours(
        xyz, queries, min(13, len(xyz)), local_ratio=local_ratio
    )
    spacing = spacing_of(dist[:m])
    dist, idx = dist[m:], idx[m:]
    near = xyz[idx]
    tied = (dist[:, 1:] == dist[:, :-1]) & (near[:, 1:] != near[:, :-1]).any(axis=2)
    if tied.any():
        _, idx = cKDTree(xyz).query(shape_queries, k=min(12, len(xyz)))
    return spacing, _vertical_fraction(xyz, idx[:, :12])


def _vertical_fraction(xyz, idx):
    """Fraction of the planar neighbourhoods (the rows ``idx`` of ``xyz``:
    the 12 nearest neighbours of each query point, nearest first) whose
    normal is within 17 degrees of the horizontal."""
    nb = xyz[idx] - xyz[idx].mean(axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    planar = (values[:, 1] - values[:, 0]) > 0.3 * np.maximum(values[:, 2], 1e-300)
    vertical = np.abs(vectors[:, 2, 0]) < 0.3
    return float((vertical & planar).sum() / max(int(planar.sum()), 1))


def _concentration(sample, candidates):
    """Median horizontal distance of the points to the candidate (x, y)
    around which that median is smallest, over the 95 % quantile of the
    distances to it; and that candidate."""
    xy = sample[:, :2]
    best, ratio, centre = np.inf, 1.0, candidates[0]
    for c in candidates:
        d = np.hypot(*(xy - c).T)
        median = np.median(d)
        if median < best:
            best, ratio = median, median / max(np.quantile(d, 0.95), 1e-300)
            centre = c
    return float(ratio), (float(centre[0]), float(centre[1]))


def _azimuth_coverage(sample, centre):
    """Fraction of the sectors of azimuth around ``centre`` holding at least
    ``_AZIMUTH_SHARE`` of the points ``_AZIMUTH_NEAR`` from it horizontally;
    None when fewer than 100 points, or than ``_AZIMUTH_NEAR_SHARE`` of
    them, are that near."""
    d = sample[:, :2] - np.asarray(centre, dtype=np.float64)
    r = np.hypot(d[:, 0], d[:, 1])
    near = (r >= _AZIMUTH_NEAR[0]) & (r <= _AZIMUTH_NEAR[1])
    if near.sum() < max(100, _AZIMUTH_NEAR_SHARE * len(sample)):
        return None
    azimuth = np.arctan2(d[near, 1], d[near, 0]) + np.pi
    sector = (azimuth * (_AZIMUTH_SECTORS / (2 * np.pi))).astype(np.int64)
    counts = np.bincount(sector % _AZIMUTH_SECTORS, minlength=_AZIMUTH_SECTORS)
    return float((counts >= _AZIMUTH_SHARE * near.sum()).mean())


def sweep_coordinates(xyz, centre, z0):
    """Coordinates of a sweep in which the point spacing is about constant.

    A sensor that turns at one position leaves points farther apart the
    farther they are: ``(log rho, azimuth, (z - z0) / rho)``, ``rho`` the
    horizontal distance to ``centre`` (at least 1), turns a distance ``d``
    at range ``rho`` into about ``d / rho``, so that one radius in these
    coordinates is a radius proportional to the range. The azimuth starts
    at the largest gap between the points' azimuths (where the turn is
    cut, no object is).

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The points.
    centre : (float, float)
        x and y of the sensor.
    z0 : float
        A height near the sensor's ground.

    Returns
    -------
    coordinates : ndarray of shape (n_points, 3)
    """
    d = xyz[:, :2] - np.asarray(centre, dtype=np.float64)
    rho = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1.0)
    azimuth = np.arctan2(d[:, 1], d[:, 0])
    if len(azimuth) > 1:
        ordered = np.sort(azimuth)
        gaps = np.diff(np.r_[ordered, ordered[0] + 2 * np.pi])
        start = ordered[(int(np.argmax(gaps)) + 1) % len(ordered)]
        azimuth = np.mod(azimuth - start, 2 * np.pi)
    return np.column_stack([np.log(rho), azimuth, (xyz[:, 2] - z0) / rho])
