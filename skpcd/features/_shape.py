"""Global shape features of a segment: size, eigenvalue ratios, height profile."""

import typing

import numpy as np

from skpcd.features._descriptor import SegmentDescriptor, check_size_extents
from skpcd.features._overall import box_dimensions

__all__ = ["ShapeFeatures", "shape_features"]

FEATURE_NAMES = (
    "log10_n_points",
    "length",
    "width",
    "height",
    "footprint_area",
    "box_volume",
    "point_density",
    "linearity",
    "planarity",
    "scattering",
    "omnivariance",
    "eigenentropy",
    "main_axis_verticality",
    "normal_verticality",
    "z_std_ratio",
    "z_mean_ratio",
    "z_skewness",
    "top_fraction",
)


def _safe_div(a, b):
    return a / b if b > 0 else 0.0


def shape_features(points):
    """Global shape features of one segment.

    Parameters
    ----------
    points : ndarray of shape (n_points, 3+)
        The segment; only xyz is used. z must point up.

    Returns
    -------
    features : ndarray of shape (18,)
        In the order of :attr:`ShapeFeatures.feature_names`; see
        :class:`ShapeFeatures` for their definitions.

    Raises
    ------
    ValueError
        If the segment spans more than 1e100 along an axis (its box volume
        would overflow).
    """
    xyz = np.asarray(points, dtype=np.float64)[:, :3]
    n = len(xyz)
    check_size_extents([xyz], input_name="points")
    # relative to the lower corner (exact far from the origin): nothing
    # below depends on where the segment lies
    xyz = xyz - xyz.min(axis=0)
    centred = xyz - xyz.mean(axis=0)
    # horizontal principal axes give an oriented footprint
    length, width, height = box_dimensions(xyz, "obb_xy")
    z = xyz[:, 2]
    area = length * width
    # the eigenvalue features are ratios: the covariance of the coordinates
    # scaled to at most 1, which no extent overflows
    scale = np.abs(centred).max()
    unit = centred / scale if scale > 0 else centred
    cov = unit.T @ unit / n
    evals, evecs = np.linalg.eigh(cov)
    evals = np.clip(evals[::-1], 0.0, None)  # l1 >= l2 >= l3
    total = evals.sum()
    if total > 0:
        e = evals / total
        l1, l2, l3 = e
        linearity = _safe_div(l1 - l2, l1)
        planarity = _safe_div(l2 - l3, l1)
        scattering = _safe_div(l3, l1)
        omnivariance = float(np.cbrt(l1 * l2 * l3))
        nz = e[e > 0]
        eigenentropy = float(-(nz * np.log(nz)).sum())
        main_vertical = abs(evecs[2, 2])
        normal_vertical = abs(evecs[2, 0])
    else:
        linearity = planarity = scattering = omnivariance = eigenentropy = 0.0
        main_vertical = normal_vertical = 0.0
    z_std = z.std()
    if height > 0:
        z_rel = (z - z.min()) / height
        top_fraction = float(np.mean(z_rel >= 0.8))
        z_mean = float(z_rel.mean())
    else:
        top_fraction, z_mean = 1.0, 0.0
    skew = float(np.mean(((z - z.mean()) / z_std) ** 3)) if z_std > 0 else 0.0
    return np.array(
        [
            np.log10(n),
            length,
            width,
            height,
            area,
            area * height,
            _safe_div(n, area),
            linearity,
            planarity,
            scattering,
            omnivariance,
            eigenentropy,
            main_vertical,
            normal_vertical,
            _safe_div(z_std, height),
            z_mean,
            skew,
            top_fraction,
        ]
    )


class ShapeFeatures(SegmentDescriptor):
    """Global shape features of each segment (size, eigenvalues, height profile).

    A fixed-length description of a whole segment that needs no
    neighbourhood: the oriented footprint (length and width along the
    principal horizontal axes), the height, the box volume and point
    density, the eigenvalue ratios of the 3-D covariance (linearity,
    planarity, scattering, omnivariance, eigenentropy), how vertical the
    main axis and the normal of the best plane are, and the distribution of
    heights inside the segment. All features are invariant to translation,
    to rotation about the vertical axis and to the order of the points.

    Read more in the :ref:`User Guide <quickstart>`.

    Attributes
    ----------
    n_features_in_ : int
        Columns of the clouds seen in :meth:`fit` (only xyz is used).

    See Also
    --------
    skpcd.classification.make_default_pipeline : Uses these features.

    Notes
    -----
    With l1 >= l2 >= l3 the eigenvalues of the covariance normalised to sum
    1: linearity = (l1 - l2) / l1, planarity = (l2 - l3) / l1, scattering
    = l3 / l1, omnivariance = (l1 l2 l3)^(1/3), eigenentropy = -sum l log l
    (Weinmann et al., 2015). Heights are relative to the segment's lowest
    point: ``z_std_ratio`` is std(z) / height, ``z_mean_ratio`` the mean
    relative height, ``top_fraction`` the share of points in the top 20 %.
    A segment with zero extent gets zeros where a ratio is undefined.
    Everything is computed relative to the segment's lower corner, in
    float64, so the features are the same wherever it lies (UTM coordinates
    included); a segment spanning more than 1e100 along an axis is a
    ValueError (its volume would overflow).

    References
    ----------
    .. [1] M. Weinmann, B. Jutzi, S. Hinz, C. Mallet, "Semantic point cloud
       interpretation based on optimal neighborhoods, relevant features and
       efficient classifiers", ISPRS J. Photogramm. Remote Sens. 105, 2015.

    Examples
    --------
    >>> from skpcd.datasets import make_urban_objects
    >>> from skpcd.features import ShapeFeatures
    >>> clouds, labels = make_urban_objects(n_per_class=2, random_state=0)
    >>> ShapeFeatures().fit_transform(clouds).shape
    (10, 18)
    """

    _parameter_constraints: typing.ClassVar[dict] = {}

    feature_names = FEATURE_NAMES

    def __init__(self):
        pass

    def _transform_batch(self, clouds, n_threads):
        """The features of a batch of clouds, one row each."""
        return np.vstack([shape_features(c) for c in clouds])

    def _feature_names(self):
        return FEATURE_NAMES
