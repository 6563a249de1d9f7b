"""Descriptors of vertical structure: a height profile, the pole and what it carries."""

import numbers
import typing

import numpy as np
from sklearn.utils._param_validation import Interval

from skpcd.features._descriptor import SegmentDescriptor, check_size_extents
from skpcd.features._vertical_kernels import geometric_median

__all__ = ["VerticalProfile", "vertical_features"]

# The band of relative heights where the trunk (the pole, a tree's stem, the
# lower body of anything else) is looked for: above the clutter a
# segmentation leaves at the foot (kerb, grass, the ground around it), below
# the arms, heads and plates that poles carry.
TRUNK_BAND = (0.15, 0.45)
# Relative heights of the height percentiles (Pu et al., 2011).
PERCENTILES = (10, 25, 50, 75, 90)

_GLOBAL_NAMES = (
    "height",
    *(f"z_p{q}_ratio" for q in PERCENTILES),
    "reach",
    "trunk_radius_inner",
    "trunk_radius_outer",
    "trunk_lean",
    "trunk_share",
    "pole_height",
    "pole_height_ratio",
    "head_share",
    "head_extent_z",
    "head_centroid_height",
    "head_centroid_ratio",
    "head_reach",
    "head_offset",
    "head_asymmetry",
    "head_length",
    "head_width",
    "head_linearity",
    "head_planarity",
    "head_scattering",
    "head_verticality",
)
_SLICE_NAMES = ("share", "spread", "offset", "verticality")


def _feature_names(n_slices):
    names = list(_GLOBAL_NAMES)
    for what in _SLICE_NAMES:
        names += [f"slice{i}_{what}" for i in range(n_slices)]
    return names


def _centre_xy(x, y):
    """The geometric median of the points: robust to clutter, and it turns
    with the points (a coordinate-wise median would not be invariant to
    rotations about z)."""
    scale = float(np.ptp(x) + np.ptp(y))
    cx, cy = geometric_median(
        np.ascontiguousarray(x), np.ascontiguousarray(y), 500, 1e-10 * (1.0 + scale)
    )
    return float(cx), float(cy)


def _eigen_ratios(dx, dy, dz):
    """Linearity, planarity and scattering of centred coordinates."""
    if len(dx) < 3:
        return 0.0, 0.0, 0.0
    cov = np.cov(np.vstack([dx, dy, dz]), bias=True)
    ev = np.clip(np.linalg.eigvalsh(cov)[::-1], 0.0, None)  # l1 >= l2 >= l3
    if ev[0] <= 0:
        return 0.0, 0.0, 0.0
    return (ev[0] - ev[1]) / ev[0], (ev[1] - ev[2]) / ev[0], ev[2] / ev[0]


def _xy_extents(dx, dy):
    """Twice the standard deviations along the principal horizontal axes
    (the sides of a rectangle fitted to the points, rotation-free)."""
    if len(dx) < 2:
        return 0.0, 0.0
    sxx, syy = np.var(dx), np.var(dy)
    sxy = np.mean((dx - dx.mean()) * (dy - dy.mean()))
    mid, half = (sxx + syy) / 2, np.hypot((sxx - syy) / 2, sxy)
    return 2 * np.sqrt(mid + half), 2 * np.sqrt(max(mid - half, 0.0))


def _slice_profile(dx, dy, z, height, n_slices):
    """Per slice of relative height: share of points, horizontal spread about
    the slice's centroid, offset of the centroid from the axis, share of the
    variance that is vertical."""
    n = len(z)
    if height > 0:
        s = np.minimum((z / height * n_slices).astype(np.int64), n_slices - 1)
    else:
        s = np.zeros(n, dtype=np.int64)
    count = np.bincount(s, minlength=n_slices).astype(np.float64)
    safe = np.maximum(count, 1.0)

    def mean(v):
        return np.bincount(s, weights=v, minlength=n_slices) / safe

    mx, my, mz = mean(dx), mean(dy), mean(z)
    # variances about each slice's own centroid (two passes: exact enough
    # whatever the heights)
    vx = mean((dx - mx[s]) ** 2)
    vy = mean((dy - my[s]) ** 2)
    vz = mean((z - mz[s]) ** 2)
    horizontal = vx + vy
    total = horizontal + vz
    share = count / n
    spread = np.sqrt(horizontal)
    offset = np.where(count > 0, np.hypot(mx, my), 0.0)
    verticality = np.where(total > 0, vz / np.where(total > 0, total, 1.0), 0.0)
    return np.concatenate([share, spread, offset, verticality])


def vertical_features(points, *, n_slices=10):
    """Descriptors of the vertical structure of one segment.

    Parameters
    ----------
    points : ndarray of shape (n_points, 3+)
        The segment; only xyz is used. z must point up.
    n_slices : int, default=10
        Slices of equal relative height in the profile.

    Returns
    -------
    features : ndarray of shape (26 + 4 * n_slices,)
        In the order of :meth:`VerticalProfile.get_feature_names_out`; see
        :class:`VerticalProfile` for their definitions.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.features import vertical_features
    >>> rng = np.random.RandomState(0)
    >>> angle = rng.uniform(0, 2 * np.pi, 500)
    >>> pole = np.c_[0.1 * np.cos(angle), 0.1 * np.sin(angle), rng.uniform(0, 6, 500)]
    >>> features = vertical_features(pole)
    >>> features.shape
    (66,)
    >>> round(float(features[0]), 1)  # the height
    6.0
    """
    xyz = np.asarray(points, dtype=np.float64)[:, :3]
    check_size_extents([xyz], input_name="points")
    # relative to the lower corner, in float64: exact far from the origin
    xyz = xyz - xyz.min(axis=0)
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    n = len(z)
    height = float(z.max())
    rel = z / height if height > 0 else np.zeros(n)
    percentiles = np.percentile(rel, PERCENTILES) if n else np.zeros(5)

    # the main vertical axis: the geometric median of the trunk band (of the
    # lower half, or of everything, when the band is nearly empty)
    band = (rel >= TRUNK_BAND[0]) & (rel <= TRUNK_BAND[1])
    if band.sum() < 3:
        band = rel <= 0.5
        if band.sum() < 3:
            band = np.ones(n, dtype=bool)
    ax, ay = _centre_xy(x[band], y[band])
    dx, dy = x - ax, y - ay
    r = np.hypot(dx, dy)
    reach = float(np.percentile(r, 95))

    # the trunk: inner and outer radius (Cabo et al., 2014), lean
    rb, zb = r[band], z[band]
    inner, outer = float(np.median(rb)), float(np.percentile(rb, 90))
    lean = 0.0
    varz = float(np.var(zb))
    if varz > 0:
        zc = zb - zb.mean()
        bx = float(np.mean((dx[band] - dx[band].mean()) * zc)) / varz
        by = float(np.mean((dy[band] - dy[band].mean()) * zc)) / varz
        lean = float(np.hypot(bx, by))  # horizontal drift per metre of height

    # the pole ends where most points stand well outside the trunk: the
    # lowest heights (5th percentile) of the points wider than twice the
    # outer radius (and 0.15 m more) above the trunk band's foot
    threshold = max(2.0 * outer, outer + 0.15)
    wide = (r > threshold) & (rel >= TRUNK_BAND[0])
    pole_top = float(np.percentile(z[wide], 5)) if wide.sum() >= 3 else height

    # the head: what the pole carries (arms, lamps, plates, boxes, a crown)
    head = z >= pole_top
    if pole_top >= height or head.sum() < 3:
        head_stats = [0.0] * 13
    else:
        hx, hy, hz, hr = dx[head], dy[head], z[head], r[head]
        cx, cy = float(hx.mean()), float(hy.mean())
        out = hr > threshold
        if out.sum() > 0:
            ux, uy = hx[out] / hr[out], hy[out] / hr[out]
            asymmetry = float(np.hypot(ux.mean(), uy.mean()))
        else:
            asymmetry = 0.0
        length, width = _xy_extents(hx, hy)
        lin, pla, sca = _eigen_ratios(hx - cx, hy - cy, hz - hz.mean())
        vz = float(np.var(hz))
        vh = float(np.var(hx) + np.var(hy))
        head_stats = [
            float(head.mean()),
            float(hz.max() - hz.min()),
            float(hz.mean()),
            float(hz.mean()) / height,
            float(np.percentile(hr, 95)),
            float(np.hypot(cx, cy)),
            asymmetry,
            length,
            width,
            lin,
            pla,
            sca,
            vz / (vz + vh) if vz + vh > 0 else 0.0,
        ]
    profile = _slice_profile(dx, dy, z, height, n_slices)
    return np.concatenate(
        [
            [height, *percentiles, reach],
            [inner, outer, lean, float(band.mean())],
            [pole_top, pole_top / height if height > 0 else 0.0],
            head_stats,
            profile,
        ]
    )


class VerticalProfile(SegmentDescriptor):
    """Descriptors of the vertical structure of each segment.

    Pole-like street furniture (street lights, traffic lights and signs,
    pedestrian signals, bare poles) differs in where the mass sits along
    the height and in what the pole carries: arms, lamp heads, plates,
    boxes. This transformer describes each segment by a stack of height
    slices (Brenner, 2009), its height percentiles (Pu et al., 2011), the
    trunk found in its lower part with an inner and an outer radius (Cabo
    et al., 2014), the height where the pole ends, and the part above it:
    its extent, reach, offset and one-sidedness, footprint and shape.

    Read more in the :ref:`User Guide <vertical_structure>`.

    Parameters
    ----------
    n_slices : int, default=10
        Slices of equal relative height in the profile (each adds four
        features).

    Attributes
    ----------
    n_features_in_ : int
        Columns of the clouds seen in :meth:`fit` (only xyz is used).

    See Also
    --------
    ShapeFeatures : Global size, eigenvalue and height-distribution features.
    skpcd.classification.make_default_pipeline : Uses both.

    Notes
    -----
    Heights are relative to the segment's lowest point; H is the height.
    The *axis* is the geometric median of the horizontal positions of
    the points between 0.15 H and 0.45 H (the trunk band, above the
    clutter at the foot and below what a pole carries); r is the
    horizontal distance of a point from it. Features, in the order of
    :meth:`get_feature_names_out`:

    - ``height`` (m), ``z_pXX_ratio``: the 10/25/50/75/90th percentiles
      of the relative height; ``reach``: the 95th percentile of r.
    - ``trunk_radius_inner`` / ``_outer``: median and 90th percentile of r
      in the trunk band; ``trunk_lean``: horizontal drift of the band per
      metre of height (a least-squares line); ``trunk_share``: the share of
      points in the band.
    - ``pole_height`` (m) and ``pole_height_ratio``: where the pole ends,
      the 5th height percentile of the points above 0.15 H with r above
      max(2 r_outer, r_outer + 0.15 m); H when fewer than 3 (a bare pole).
    - ``head_*``: the points above the pole's end. Share, vertical extent,
      centroid height (m and relative to H), ``head_reach`` (95th
      percentile of r: the length of an arm), ``head_offset`` (centroid
      from the axis), ``head_asymmetry`` (length of the mean direction from
      the axis of its points beyond the pole, 1 for a one-sided arm, near 0
      for a symmetric crown), ``head_length`` and ``head_width`` (twice the
      standard deviations along its principal horizontal axes: a plate or a
      lamp head against a box), the eigenvalue ratios of its 3-D
      covariance and the vertical share of its variance. Zeros without a
      head.
    - ``sliceI_*`` for I from the bottom: share of points, horizontal
      spread (m, root mean square distance from the slice's centroid),
      offset of that centroid from the axis (m) and the vertical share of
      the slice's variance.

    Every feature is a percentile, a mean or a variance of distances from
    the axis and of heights: invariant to rotations about z, to
    translations and to the order of the points. One-sided views (a
    mobile scanner sees one half of a pole) move the axis by a fraction of
    the trunk radius. Everything is computed relative to the segment's
    lower corner, in float64, so UTM coordinates change nothing. A segment
    of one point, or with no height, gets zeros where a ratio is
    undefined.

    References
    ----------
    .. [1] C. Brenner, "Extraction of features from mobile laser scanning
       data for future driver assistance systems", Advances in GIScience,
       2009.
    .. [2] S. Pu, M. Rutzinger, G. Vosselman, S. Oude Elberink,
       "Recognizing basic structures from mobile laser scanning data for
       road inventory studies", ISPRS J. Photogramm. Remote Sens. 66, 2011.
    .. [3] C. Cabo, C. Ordoñez, S. García-Cortés, J. Martínez, "An
       algorithm for automatic detection of pole-like street furniture
       objects from mobile laser scanner point clouds", ISPRS J.
       Photogramm. Remote Sens. 87, 2014.

    Examples
    --------
    >>> from skpcd.datasets import make_urban_objects
    >>> from skpcd.features import VerticalProfile
    >>> clouds, labels = make_urban_objects(n_per_class=2, random_state=0)
    >>> profile = VerticalProfile(n_slices=5)
    >>> profile.fit_transform(clouds).shape
    (10, 46)
    >>> profile.get_feature_names_out()[:3].tolist()
    ['height', 'z_p10_ratio', 'z_p25_ratio']
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "n_slices": [Interval(numbers.Integral, 1, None, closed="left")],
    }

    def __init__(self, *, n_slices=10):
        self.n_slices = n_slices

    def _transform_batch(self, clouds, n_threads):
        """:meth:`transform` of validated clouds (one batch of them)."""
        n_slices = int(self.n_slices)
        return np.vstack([vertical_features(c, n_slices=n_slices) for c in clouds])

    def _feature_names(self):
        return _feature_names(int(self.n_slices))
