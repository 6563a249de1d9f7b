"""The range image of a single sweep (rings by azimuth), and the
segmentation made in it."""

import typing

import numpy as np

from skpcd.segmentation._range_kernels import (
    cluster_image,
    ground_columns,
    pixel_order,
)

__all__ = ["RangeImage", "ground_under", "range_image"]

# Rows of the image of a sweep without rings given: bands of the elevation
# angle this many degrees high, finer than the rings of any sensor.
_ROW_HEIGHT = 0.1
# The fewest and most columns (azimuth steps of 0.09 to 1 degree).
_MIN_COLUMNS, _MAX_COLUMNS = 360, 4096
# Ground under the sensor: the most common height (0.1 m bins) within 1 m
# above the 5 % lowest of the points 3 to 20 m away horizontally.
_GROUND_NEAR = (3.0, 20.0)
# A spinning sensor looks down at least 11 degrees (Ouster OS2; VLP-16 15,
# HDL-64E 25, HDL-32E 31): seen from the origin of a sweep in its sensor's
# frame, 1 % of the points lie 23 degrees or more below the horizon on the
# real sweeps measured (SemanticKITTI and KITTI HDL-64E, nuScenes HDL-32E).
# An origin from which that quantile is shallower than this many degrees is
# not the sensor (from the origin of the PandaSet files, the road under the
# car: 0.5 to 3.8 degrees) ...
_LOWEST_BEAMS = -8.0
# ... and the sensor is put this high above the ground under the origin, the
# height of a sensor on a car roof (KITTI 1.73 m, nuScenes 1.84 m, PandaSet
# about 2 m). With segment_sweep on the real PandaSet sweeps (3 of
# ../shared/data/real_labelled, 9 of real_mobile), 1.5 to 2.2 m all give
# 0.23 to 0.25 mIoU of the street model (0.18 from the origin) and 0.64 to
# 0.68 of the boxed objects kept (0.39 from the origin).
_CAR_SENSOR_HEIGHT = 1.85


class RangeImage(typing.NamedTuple):
    """What :func:`range_image` returns (a named tuple).

    Attributes
    ----------
    row : ndarray of shape (n_points,), dtype int64
        Row of each point, 0 the lowest: its ring, or its band of elevation.
    column : ndarray of shape (n_points,), dtype int64
        Azimuth column of each point, 0 .. n_columns - 1, counter-clockwise
        from the x axis.
    n_rows, n_columns : int
        The size of the image.
    row_height : float
        The elevation angle between two rows, in degrees (the mean between
        the rings when they are given).
    sensor : ndarray of shape (3,)
        The position the rays start from.
    sensor_from : str
        "given" when the sensor was given, "origin" when the rays start from
        the origin of the points, "above the origin" when the sensor was put
        1.85 m above the ground under the origin (see :func:`range_image`).
    rings_from : str
        "field" when the rings were given, "elevation" when found from the
        elevation angles of the points.
    """

    row: np.ndarray
    column: np.ndarray
    n_rows: int
    n_columns: int
    row_height: float
    sensor: np.ndarray
    sensor_from: str
    rings_from: str

    @property
    def pixel(self):
        """Pixel of each point, ``row * n_columns + column``."""
        return self.row * self.n_columns + self.column


def range_image(points, *, sensor=None, rings=None, n_columns=None):
    """The range image of a sweep: the ring and the azimuth column of each point.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        One sweep of a spinning multi-beam sensor; columns beyond the third
        are ignored.
    sensor : array-like of shape (3,) or None, default=None
        The position of the sensor. None is the origin (a sweep in its
        sensor's frame, as KITTI, nuScenes and most drivers give them) when
        the points seen from there reach below the horizon as a spinning
        sensor's lowest beams do (1 % of them at least 8 degrees down); when
        they do not, the origin is not the sensor but a point on the ground
        (a vehicle's or the world's frame, as PandaSet's files) and the
        sensor is put above it, 1.85 m above the ground under the origin,
        the height of a sensor on a car's roof (``image.sensor_from`` says
        which).
    rings : array-like of shape (n_points,) or None, default=None
        The ring (laser, channel) of each point, in any numbering (LAS 1.4
        ``scanner_channel``, a PCD or PLY ``ring`` field); rows are the
        rings ordered by their median elevation. None lays the rows out as
        bands of the elevation angle 0.1 degree high, finer than the rings
        of any sensor (the ring pitch of a 128-beam sensor is about 0.2
        degrees): a ring falls in one or two bands, and the bands between
        rings stay empty (the segmentation looks past them, see
        :func:`segment_sweep`).
    n_columns : int or None, default=None
        Columns of the image; None takes the azimuth step of the sensor
        (the median step between the points of the fullest rings), 360 to
        4,096 columns.

    Returns
    -------
    image : RangeImage
        Every point has a pixel; several points can share one (several
        returns, duplicates, beams closer than the rings found): none is
        lost.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import range_image
    >>> az = np.tile(np.linspace(0, 2 * np.pi, 1000, endpoint=False), 16)
    >>> el = np.repeat(np.radians(np.linspace(-15, 15, 16)), 1000)
    >>> ray = np.column_stack(
    ...     [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    ... )
    >>> image = range_image(10 * ray)  # rows: bands of 0.1 degree
    >>> image.n_rows, image.n_columns, image.row_height
    (301, 1000, 0.1)
    >>> image = range_image(10 * ray, rings=np.repeat(np.arange(16), 1000))
    >>> image.n_rows, image.n_columns, round(image.row_height, 6)
    (16, 1000, 2.0)
    """
    xyz = np.asarray(points, dtype=np.float64)[:, :3]
    if sensor is None:
        sensor, sensor_from = np.zeros(3), "origin"
        elevation = _elevation(xyz, sensor)
        # (on every 16th point: thousands of them, enough for a 1 % quantile)
        if len(xyz) and np.quantile(elevation[::16], 0.01) > _LOWEST_BEAMS:
            sensor_from = "above the origin"
            z = ground_under(xyz, sensor) + _CAR_SENSOR_HEIGHT
            sensor = np.array([0.0, 0.0, z])
            elevation = _elevation(xyz, sensor)
    else:
        sensor = np.asarray(sensor, dtype=np.float64).reshape(3)
        sensor_from = "given"
        elevation = _elevation(xyz, sensor)
    d = xyz - sensor
    azimuth = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    if rings is not None:
        rings = np.asarray(rings).ravel()
        if rings.shape != (len(xyz),):
            raise ValueError(f"rings has {rings.size} values for {len(xyz)} points")
        values, inverse = np.unique(rings, return_inverse=True)
        median = np.array(
            [np.median(elevation[inverse == k]) for k in range(len(values))]
        )
        rank = np.empty(len(values), dtype=np.int64)
        rank[np.argsort(median, kind="stable")] = np.arange(len(values))
        row = rank[inverse]
        n_rows, found = len(values), "field"
        height = float(np.ptp(median)) / max(n_rows - 1, 1)
    else:
        row, n_rows = _rings_from_elevation(elevation)
        found, height = "elevation", _ROW_HEIGHT
    if n_columns is None:
        n_columns = _azimuth_columns(azimuth, row, n_rows)
    column = np.minimum(
        (azimuth * (n_columns / (2 * np.pi))).astype(np.int64), n_columns - 1
    )
    return RangeImage(
        row, column, int(n_rows), int(n_columns), height, sensor, sensor_from, found
    )


def _elevation(xyz, sensor):
    """Elevation angle of the points seen from the sensor, in degrees."""
    d = xyz - sensor
    return np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))


def ground_under(xyz, sensor):
    """Height of the ground under the sensor: the most common height (0.1 m
    bins) within 1 m above the 5 % lowest points 3 to 20 m away
    horizontally (all the points when none is)."""
    rho = np.hypot(xyz[:, 0] - sensor[0], xyz[:, 1] - sensor[1])
    z = xyz[(rho >= _GROUND_NEAR[0]) & (rho <= _GROUND_NEAR[1]), 2]
    if len(z) < 10:
        z = xyz[:, 2]
    low = np.quantile(z, 0.05)
    near = z[z < low + 1.0]
    counts = np.bincount(((near - near.min()) / 0.1).astype(np.int64))
    return float(near.min() + (np.argmax(counts) + 0.5) * 0.1)


def _rings_from_elevation(elevation):
    """Row of each point and the number of rows: bands of the elevation
    angle ``_ROW_HEIGHT`` degrees high, from the lowest point."""
    low = float(elevation.min())
    row = ((elevation - low) / _ROW_HEIGHT).astype(np.int64)
    return row, int(row.max()) + 1


def _azimuth_columns(azimuth, row, n_rows):
    """Columns of one azimuth step of the sensor: the median step between
    consecutive points of the fullest rows."""
    counts = np.bincount(row, minlength=n_rows)
    steps = []
    for r in np.argsort(counts)[::-1][:5]:
        a = np.sort(azimuth[row == r])
        d = np.diff(a)
        d = d[d > 1e-6]
        if len(d):
            steps.append(np.median(d))
    if not steps:
        return _MIN_COLUMNS
    n = round(2 * np.pi / float(np.median(steps)))
    return int(np.clip(n, _MIN_COLUMNS, _MAX_COLUMNS))


def image_ground(xyz, image, *, z0, slope, step, max_step, column_width):
    """Ground flags walked outwards along azimuth columns ``column_width``
    image columns wide (see :func:`ground_columns`)."""
    d = xyz - image.sensor
    rho = np.hypot(d[:, 0], d[:, 1])
    n_cols = -(-image.n_columns // column_width)
    start, order = pixel_order(image.column // column_width, rho, n_cols)
    return ground_columns(start, order, rho, xyz[:, 2], z0, slope, step, max_step)


def image_clusters(xyz, image, keep, *, theta, max_gap, reach, reach_columns):
    """Union-find roots of the kept points (see :func:`cluster_image`),
    each the index of a point of its tree; -1 for the points not kept."""
    d = xyz - image.sensor
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    start, order = pixel_order(image.pixel, r, image.n_rows * image.n_columns)
    parent = cluster_image(
        start, image.n_rows, image.n_columns, keep[order],
        np.ascontiguousarray(xyz[order]), image.sensor, np.radians(theta),
        max_gap, reach, reach_columns,
    )  # fmt: skip
    roots = np.full(len(xyz), -1, dtype=np.int64)
    kept = parent >= 0
    roots[order[kept]] = order[parent[kept]]
    return roots
