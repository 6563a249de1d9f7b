"""The overall descriptor of a segment: its extent, box and density."""

import typing
from numbers import Real

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions

from skpcd.features._descriptor import SegmentDescriptor

__all__ = ["OverallDescriptor", "box_dimensions"]

OVERALL_NAMES = (
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "length",
    "width",
    "height",
    "volume",
    "n_points",
    "density",
)


def box_dimensions(xyz, box="aabb"):
    """Length, width and height of a segment's bounding box.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The segment, z up, at least one point.
    box : {"aabb", "obb_xy"}, default="aabb"
        ``"aabb"``: the axis-aligned box (Wang et al., 2023); ``"obb_xy"``:
        the box aligned with the principal axes of the points' x, y
        coordinates (vertical sides, invariant to rotations about z).

    Returns
    -------
    length, width, height : float
        The horizontal sides, ``length >= width``, and the vertical extent.

    Notes
    -----
    Computed relative to the box's lower corner, in float64, so that the
    sides do not depend on where the segment lies; the principal axes of
    ``"obb_xy"`` come from the coordinates scaled to at most 1, so that no
    extent overflows the covariance.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if box not in ("aabb", "obb_xy"):
        raise ValueError(f'box must be "aabb" or "obb_xy", got {box!r}')
    xyz = xyz[:, :3] - xyz[:, :3].min(axis=0)
    if box == "aabb":
        ext = xyz[:, :2].max(axis=0)
    else:
        xy = xyz[:, :2] - xyz[:, :2].mean(axis=0)
        scale = np.abs(xy).max()
        if scale > 0:
            u = xy / scale
            _, vec = np.linalg.eigh(u.T @ u)
            ext = np.ptp(xy @ vec, axis=0)
        else:
            ext = np.zeros(2)
    return float(ext.max()), float(ext.min()), float(xyz[:, 2].max())


class OverallDescriptor(SegmentDescriptor):
    """The overall descriptor of each segment (Wang et al., 2023, section 3.4).

    Per segment: its extent (minimum and maximum x, y, z), the length, width
    and height of its bounding box, the box's volume (what
    :class:`~skpcd.classification.CaseBasedClassifier` compares), the point
    count and the density.

    Read more in the :ref:`User Guide <smooth_shapes>`.

    Parameters
    ----------
    box : {"aabb", "obb_xy"}, default="aabb"
        ``"aabb"``: the axis-aligned box, as in the paper; its volume
        changes when a segment turns about the vertical. ``"obb_xy"``: a box
        with vertical sides along the principal axes of the points' x, y
        coordinates, invariant to rotations about z.
    min_extent : float, default=0.1
        Sides shorter than this count as this long in the volume and the
        density, so that flat or thin segments (a facade, a pole) keep a
        non-zero volume and a finite density. In the units of the data.

    Attributes
    ----------
    n_features_in_ : int
        Columns of the clouds seen in :meth:`fit` (only xyz is used).

    See Also
    --------
    ShapeFeatures : Eigenvalue and height-profile features of a segment.

    Notes
    -----
    ``length >= width`` are the horizontal sides of the box, ``height``
    its vertical extent, ``volume = max(length, m) * max(width, m) *
    max(height, m)`` with ``m = min_extent``, and ``density = n_points /
    volume``. The extent columns depend on where the segment is; drop them
    (or use a :class:`~sklearn.compose.ColumnTransformer`) when only its
    shape should matter. The other columns are computed relative to the
    segment's lower corner, in float64: they do not depend on where it lies
    (UTM coordinates included). A segment spanning more than 1e100 along an
    axis, whose volume would overflow, is a ValueError.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.features import OverallDescriptor
    >>> box = np.array([[0, 0, 0], [4, 2, 1], [4, 0, 0], [0, 2, 1.0]])
    >>> OverallDescriptor().fit_transform([box])[0, 6:10].tolist()
    [4.0, 2.0, 1.0, 8.0]
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "box": [StrOptions({"aabb", "obb_xy"})],
        "min_extent": [Interval(Real, 0, None, closed="left")],
    }

    def __init__(self, box="aabb", min_extent=0.1):
        self.box = box
        self.min_extent = min_extent

    def _transform_batch(self, clouds, n_threads):
        """:meth:`transform` of validated clouds (one batch of them)."""
        rows = np.empty((len(clouds), len(OVERALL_NAMES)))
        m = float(self.min_extent)
        for r, c in enumerate(clouds):
            xyz = np.asarray(c[:, :3], dtype=np.float64)
            length, width, height = box_dimensions(xyz, self.box)
            volume = max(length, m) * max(width, m) * max(height, m)
            rows[r, :3] = xyz.min(axis=0)
            rows[r, 3:6] = xyz.max(axis=0)
            rows[r, 6:] = [length, width, height, volume, len(xyz), 0.0]
            rows[r, 11] = len(xyz) / volume if volume > 0 else np.inf
        return rows

    def _feature_names(self):
        return OVERALL_NAMES
