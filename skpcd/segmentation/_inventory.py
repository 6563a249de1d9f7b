"""An inventory of the objects of a scene: where each stands, how big it is,
and for poles how much they lean and how high they carry what they carry.

:func:`segment_geometry` measures one segment; :class:`GroundHeight` gives
the height of the ground under a point from the ground points of the scan;
:func:`object_inventory` puts both together with the predicted classes into
one row per object (the columns of ``INVENTORY_COLUMNS``), which
:func:`skpcd.io._inventory.write_inventory` writes as GeoPackage, GeoJSON or
CSV.
"""

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

# the classes measured as poles (lean, height of what they carry): the
# pole-like classes of the street simulator and the shipped model
from skpcd.datasets._street._catalogue import POLE_CLASSES

__all__ = [
    "INVENTORY_COLUMNS",
    "POLE_CLASSES",
    "GroundHeight",
    "object_inventory",
    "segment_geometry",
]


#: The columns of an inventory, in order.
INVENTORY_COLUMNS = (
    "id",
    "class",
    "confidence",
    "x",
    "y",
    "z",
    "height",
    "width",
    "length",
    "heading",
    "n_points",
    "lean",
    "carried_height",
)

# the base of an object: its points this high above its lowest point (m)
BASE_SLICE = 0.5
# the shaft of a pole: from this high above its base (m) ...
SHAFT_START = 0.3
# ... to this high (m), or half the pole's height if less
SHAFT_LENGTH = 2.0
# a point farther than the shaft's radius plus this from its axis belongs
# to what the pole carries (m)
CARRIED_MARGIN = 0.15
# height of the slices searched for what a pole carries (m)
SLICE = 0.1
# points a slice needs beyond the margin to count as carried
CARRIED_MIN_POINTS = 3


def _min_area_rectangle(xy):
    """``(width, length, heading, centre)`` of the smallest rectangle around
    ``xy``: width <= length, heading the direction of the long side in
    degrees clockwise from north (+y), in [0, 180), centre its centre."""
    # the distinct points to 0.1 mm, sorted by (x, y): one complex number
    # each (np.unique of rows sorts a structured view, 10x slower)
    xy = np.round(xy, 4)
    distinct = np.unique(xy[:, 0] + 1j * xy[:, 1])
    xy = np.column_stack([distinct.real, distinct.imag])
    if len(xy) < 3:
        hull = xy
    else:
        try:
            hull = xy[ConvexHull(xy).vertices]
        except QhullError:  # collinear: a line of points
            hull = xy
    if len(hull) < 2:
        return 0.0, 0.0, 0.0, xy.mean(axis=0)
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    best = None
    for a in angles:
        c, s = math.cos(a), math.sin(a)
        u = hull @ np.array([c, s])
        v = hull @ np.array([-s, c])
        du, dv = np.ptp(u), np.ptp(v)
        if best is None or du * dv < best[0] - 1e-12:
            mid = np.array([u.min() + du / 2, v.min() + dv / 2])
            best = (du * dv, du, dv, a, mid)
    _, du, dv, a, mid = best
    c, s = math.cos(a), math.sin(a)
    centre = np.array([c * mid[0] - s * mid[1], s * mid[0] + c * mid[1]])
    if dv > du:  # the long side along v
        du, dv, a = dv, du, a + np.pi / 2
    # direction (cos a, sin a) to a bearing from +y, clockwise
    heading = math.degrees(math.atan2(math.cos(a), math.sin(a))) % 180.0
    return float(dv), float(du), float(heading), centre


def _pole(points, zmin, height):
    """``(lean, carried)`` of a pole: the angle of its shaft from vertical
    (degrees) and the height above ``zmin`` of the lowest part of what it
    carries (NaN: nothing found)."""
    top = min(SHAFT_START + SHAFT_LENGTH, SHAFT_START + height / 2)
    shaft = points[(points[:, 2] >= zmin + SHAFT_START) & (points[:, 2] <= zmin + top)]
    if len(shaft) < 5 or np.ptp(shaft[:, 2]) < 0.3:
        return math.nan, math.nan
    in_shaft = (points[:, 2] >= zmin + SHAFT_START) & (points[:, 2] <= zmin + top)
    for _ in range(3):
        # the shaft's axis: x, y as linear functions of z (least squares),
        # which a wide but short shaft cannot tip over as a principal axis
        # could; refitted without the points far from it (a sign's plate)
        centre = shaft.mean(axis=0)
        dz = shaft[:, 2] - centre[2]
        slope = (dz @ (shaft[:, :2] - centre[:2])) / (dz @ dz)
        offset = points[:, :2] - centre[:2] - np.outer(points[:, 2] - centre[2], slope)
        dist = np.hypot(offset[:, 0], offset[:, 1])
        near = in_shaft & (dist <= 2 * np.median(dist[in_shaft]) + 0.02)
        if near.sum() < 5 or np.ptp(points[near, 2]) < 0.3:
            break
        shaft = points[near]
    lean = math.degrees(math.atan(math.hypot(*slope)))
    radius = float(
        np.percentile(
            dist[in_shaft & (dist <= 2 * np.median(dist[in_shaft]) + 0.02)], 90
        )
    )
    far = (dist > radius + CARRIED_MARGIN) & (points[:, 2] > zmin + SHAFT_START)
    if far.sum() < CARRIED_MIN_POINTS:
        return lean, math.nan
    slices = np.floor((points[far, 2] - zmin) / SLICE).astype(np.int64)
    counts = np.bincount(slices)
    full = np.flatnonzero(counts >= CARRIED_MIN_POINTS)
    if len(full) == 0:
        return lean, math.nan
    lowest = full[0]
    carried = points[far, 2][slices == lowest].min() - zmin
    return lean, float(carried)


def segment_geometry(points, *, pole=False):
    """Where a segment stands and how big it is.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        The segment, z up.
    pole : bool, default=False
        Also measure it as a pole: the lean of its shaft and the height of
        what it carries.

    Returns
    -------
    geometry : dict
        ``x``, ``y``: the centre of its base (the mean of its points less
        than 0.5 m above its lowest point); ``z_min``, ``z_max``: its lowest
        and highest point; ``width``, ``length``: the sides of the smallest
        rectangle around its points seen from above (width <= length),
        ``heading``: the direction of the long side, degrees clockwise from
        north (+y), in [0, 180), ``centre``: its centre (ndarray of shape
        (2,)); ``n_points``; ``lean``: the angle of the
        pole's shaft (its points 0.3 to 2.3 m above its base, a line fitted
        to them) from vertical, degrees; ``carried_height``: the height
        above its lowest point of the lowest part of what the pole carries
        (points more than 0.15 m beyond the shaft's radius from its axis),
        NaN for a bare pole. ``lean`` and ``carried_height`` are NaN when
        ``pole`` is False or the shaft cannot be measured.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation._inventory import segment_geometry
    >>> z = np.linspace(0, 4, 200)
    >>> shaft = np.column_stack([0.05 * np.cos(z * 40), 0.05 * np.sin(z * 40), z])
    >>> plate = np.column_stack([np.linspace(-0.4, 0.4, 50), np.full(50, 0.1),
    ...                          np.repeat(np.linspace(2.5, 3.0, 5), 10)])
    >>> g = segment_geometry(np.vstack([shaft, plate]), pole=True)
    >>> round(g["lean"]), round(g["carried_height"], 1), g["n_points"]
    (0, 2.5, 250)
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) == 0:
        raise ValueError("a segment without finite points has no geometry")
    z = points[:, 2]
    zmin, zmax = float(z.min()), float(z.max())
    base = points[z <= zmin + BASE_SLICE, :2].mean(axis=0)
    width, length, heading, centre = _min_area_rectangle(points[:, :2])
    lean, carried = _pole(points, zmin, zmax - zmin) if pole else (math.nan,) * 2
    return {
        "x": float(base[0]),
        "y": float(base[1]),
        "z_min": zmin,
        "z_max": zmax,
        "width": width,
        "length": length,
        "heading": heading,
        "centre": centre,
        "n_points": len(points),
        "lean": lean,
        "carried_height": carried,
    }


class GroundHeight:
    """The height of the ground under any point, from the scan's ground points.

    The ground points are binned into square cells and each cell keeps the
    median height of its points; the ground under ``(x, y)`` is the cell
    that holds it, or the nearest cell with ground points.

    Parameters
    ----------
    cell : float, default=1.0
        Side of the cells (metres).

    Attributes
    ----------
    n_cells_ : int
        Cells holding ground points.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation._inventory import GroundHeight
    >>> xy = np.random.default_rng(0).uniform(0, 10, (2000, 2))
    >>> ground = np.column_stack([xy, 0.2 * xy[:, 0]])
    >>> g = GroundHeight().fit(ground)
    >>> np.round(g.at([[5.2, 5.0], [30.0, 5.0]]), 1)
    array([1.1, 1.9])
    """

    def __init__(self, cell=1.0):
        self.cell = cell

    def fit(self, points):
        """Bin the ground points.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Ground points (all of them at once).

        Returns
        -------
        self : GroundHeight
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        points = points[np.isfinite(points).all(axis=1)]
        keys = np.floor(points[:, :2] / self.cell).astype(np.int64)
        order = np.lexsort((points[:, 2], keys[:, 1], keys[:, 0]))
        keys, z = keys[order], points[order, 2]
        if len(keys):
            new = np.ones(len(keys), dtype=bool)
            new[1:] = (keys[1:] != keys[:-1]).any(axis=1)
            starts = np.flatnonzero(new)
            ends = np.append(starts[1:], len(keys))
            # z is sorted within each cell: the median is its middle
            heights = (z[(starts + ends - 1) // 2] + z[(starts + ends) // 2]) / 2
            self.cells_ = keys[starts]
            self.heights_ = heights
        else:
            self.cells_ = np.empty((0, 2), dtype=np.int64)
            self.heights_ = np.empty(0)
        self.n_cells_ = len(self.cells_)
        return self

    def at(self, xy):
        """The ground height under each point (NaN without ground points).

        Parameters
        ----------
        xy : array-like of shape (n, 2)
            Positions.

        Returns
        -------
        z : ndarray of shape (n,)
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self.n_cells_ == 0:
            return np.full(len(xy), np.nan)
        centres = (self.cells_ + 0.5) * self.cell
        _, nearest = cKDTree(centres).query(xy)
        return self.heights_[nearest]


def object_inventory(
    geometries, predictions, scores=None, *, ground=None, pole_classes=POLE_CLASSES
):
    """One row per object: class, position of its base, size, and for poles
    their lean and the height of what they carry.

    Read more in the :ref:`User Guide <review>`.

    Parameters
    ----------
    geometries : sequence of dict
        :func:`segment_geometry` of each segment.
    predictions : sequence of str
        The class of each segment.
    scores : sequence of float, default=None
        The confidence of each class (NaN: none).
    ground : GroundHeight, default=None
        The ground of the scan; None: the base of each object is its lowest
        point.
    pole_classes : sequence of str, default=POLE_CLASSES
        The classes whose lean and carried height are given (measured with
        ``segment_geometry(..., pole=True)``); NaN for the others.

    Returns
    -------
    inventory : dict of str to ndarray
        The columns of ``INVENTORY_COLUMNS``: ``id`` (the segment), ``class``,
        ``confidence``, ``x``, ``y``, ``z`` (the centre of the base, on the
        ground under it), ``height`` (of the highest point above that
        ground), ``width``, ``length``, ``heading`` (degrees clockwise from
        north), ``n_points``, ``lean`` (degrees from vertical) and
        ``carried_height`` (above the ground; NaN but for poles). Empty
        columns without segments.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation._inventory import object_inventory, segment_geometry
    >>> box = np.array([[0, 0, 1], [2, 0, 1], [2, 1, 1], [0, 1, 3.0]])
    >>> table = object_inventory([segment_geometry(box)], ["bench"], [0.8])
    >>> table["class"].tolist(), table["height"].tolist(), table["length"].tolist()
    (['bench'], [2.0], [2.0])
    """
    n = len(geometries)
    if len(predictions) != n:
        raise ValueError(f"{len(predictions)} predictions for {n} segments")
    names = ("x", "y", "z_min", "z_max", "width", "length", "heading")
    col = {k: np.array([g[k] for g in geometries], dtype=float) for k in names}
    classes = np.array([str(p) for p in predictions], dtype=object)
    is_pole = np.isin(classes, [str(c) for c in pole_classes])
    for k in ("lean", "carried_height"):
        values = np.array([g[k] for g in geometries], dtype=float)
        col[k] = np.where(is_pole, values, np.nan)
    base_z = col["z_min"].copy()
    if ground is not None and ground.n_cells_:
        under = ground.at(np.column_stack([col["x"], col["y"]]))
        # the ground under an object, unless the object starts below it
        base_z = np.minimum(under, col["z_min"])
    lift = col["z_min"] - base_z
    return {
        "id": np.arange(n),
        "class": classes,
        "confidence": (
            np.full(n, np.nan) if scores is None else np.asarray(scores, dtype=float)
        ),
        "x": col["x"],
        "y": col["y"],
        "z": base_z,
        "height": col["z_max"] - base_z,
        "width": col["width"],
        "length": col["length"],
        "heading": col["heading"],
        "n_points": np.array([g["n_points"] for g in geometries], dtype=np.int64),
        "lean": col["lean"],
        "carried_height": col["carried_height"] + lift,
    }
