"""Descriptors far from the origin (UTM coordinates): issue 15, finding 4.

PCL computes in float32 on the coordinates it is given, 0.5 m coarse at
y = 4.2e6. skpcd takes an axis reaching beyond 1024 from the origin relative
to the cloud's minimum (in float64, :func:`skpcd.utils._geometry.local_frame`)
and leaves PCL's own coordinates as they are. See "Coordinates far from the
origin" in the user guide.
"""

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.datasets import make_primitives, make_urban_objects
from skpcd.features import (
    FPFHTransformer,
    ImprovedPFHTransformer,
    OverallDescriptor,
    PFHTransformer,
    ShapeFeatures,
    compute_fpfh,
    compute_pfh,
)
from skpcd.preprocessing import (
    GridSampler,
    NormalEstimator,
    compute_neighborhoods,
    estimate_normals,
    grid_sample,
)

UTM = np.array([5e5, 4.2e6, 0.0])
# How far apart mean-pooled rows (bins summing to 100) of a cloud and of its
# translate may be when the translation changes the float32 rounding of the
# coordinates (the user guide's bound). Largest seen: 0.67 on the DALES
# objects at UTM; 1.03 on the 129-point synthetic pole, whose PCA normals are
# ill-conditioned (a shift of 0.1 at the origin already moves it by 0.29).
POOLED_TOLERANCE = 1.5


def _pooled_local_descriptors(offset):
    """PFH, FPFH and improved PFH: with the default viewpoint, fixed to each
    cloud, and with a viewpoint moved with the cloud."""
    vp = tuple(float(v) for v in offset)
    return (
        PFHTransformer(n_neighbors=10, pooling="mean"),
        FPFHTransformer(n_neighbors=10, pooling="mean"),
        PFHTransformer(n_neighbors=10, pooling="mean", viewpoint=vp),
        FPFHTransformer(n_neighbors=10, pooling="mean", viewpoint=vp),
        ImprovedPFHTransformer(),
    )


@pytest.mark.slow
def test_dales_objects_at_utm_coordinates_keep_their_descriptors(dales):
    """The report: real objects moved to UTM coordinates (what ``skpcd
    segment`` writes) got mean-pooled bins up to 47 apart, and a case-based
    model changed a fifth of its answers."""
    from skpcd.classification import make_case_based_pipeline

    clouds, labels, _ = dales
    labels = np.asarray(labels)
    test = np.arange(len(clouds)) % 4 == 0
    near = [c for c, t in zip(clouds, test) if t]
    far = [c + UTM for c in near]
    for t0, t1 in zip(
        _pooled_local_descriptors(np.zeros(3)), _pooled_local_descriptors(UTM)
    ):
        a, b = t0.fit_transform(near), t1.fit_transform(far)
        assert np.isnan(a).sum() == np.isnan(b).sum()
        diff = np.nanmax(np.abs(a - b))
        assert diff <= POOLED_TOLERANCE, (type(t0).__name__, diff)
    train = [c for c, t in zip(clouds, test) if not t]
    model = make_case_based_pipeline().fit(train, labels[~test])
    answers = model.predict(near)
    np.testing.assert_array_equal(model.predict(far), answers)
    # and trained at UTM coordinates too
    model = make_case_based_pipeline().fit([c + UTM for c in train], labels[~test])
    np.testing.assert_array_equal(model.predict(far), answers)


@functools.cache
def _clouds(dyadic):
    """Synthetic objects (0-1000 m, as a DALES tile) and primitives (about the
    origin); ``dyadic``: on a 2**-10 grid, so that translates by multiples of
    2**-10 up to 1e7 are exact in float64 and every coordinate difference is
    exact in float32."""
    objects, _ = make_urban_objects(n_per_class=1, random_state=0)
    primitives, _ = make_primitives(1, n_points=150, random_state=1)
    clouds = [*objects, *primitives]
    if dyadic:
        clouds = [np.round(c * 1024) / 1024 for c in clouds]
    return clouds


def _estimators(vp):
    """Every estimator that sees coordinates; the first three with the
    default viewpoint, fixed to each cloud, the next with ``vp``."""
    return [
        PFHTransformer(n_neighbors=10),
        FPFHTransformer(radius=1.0),
        NormalEstimator(),
        PFHTransformer(n_neighbors=10, viewpoint=vp),
        PFHTransformer(radius=1.0, viewpoint=vp),
        FPFHTransformer(n_neighbors=10, viewpoint=vp),
        FPFHTransformer(radius=1.0, viewpoint=vp, convention="open3d"),
        ImprovedPFHTransformer(),
        ImprovedPFHTransformer(variant="fpfh", middle="bbox_center"),
        NormalEstimator(viewpoint=vp, include_curvature=True),
        GridSampler(voxel_size=0.5),
        ShapeFeatures(),
        OverallDescriptor(box="obb_xy"),
    ]


@functools.cache
def _at_origin(dyadic):
    clouds = _clouds(dyadic)
    return [t.fit_transform(clouds) for t in _estimators((0.0, 0.0, 0.0))]


def _moved_back(t, out, offset):
    """The part of an output that carries coordinates, moved back."""
    if isinstance(t, NormalEstimator | GridSampler):
        return [np.hstack([c[:, :3] - offset, c[:, 3:]]) for c in out]
    if isinstance(t, OverallDescriptor):
        out = out.copy()
        out[:, :6] -= np.tile(offset, 2)
    return out


@settings(max_examples=8, deadline=None)
@given(offset=st.tuples(*[st.integers(-(10**7) * 1024, 10**7 * 1024)] * 3))
def test_exact_translates_up_to_1e7_give_the_same_results_bit_for_bit(offset):
    """A cloud moved by up to 1e7 (exactly: a dyadic cloud and offset) gives
    the same descriptors, normals, samples and shape features as at the
    origin, bit for bit: computations depend on coordinate differences only,
    and the local frame keeps them exact."""
    offset = np.asarray(offset, dtype=np.float64) / 1024
    far = [c + offset for c in _clouds(True)]
    vp = tuple(float(v) for v in offset)
    for t, ref in zip(_estimators(vp), _at_origin(True)):
        got = _moved_back(t, t.fit_transform(far), offset)
        if isinstance(got, list):
            assert len(got) == len(ref)
            for a, b in zip(got, ref):
                np.testing.assert_array_equal(a, b, err_msg=type(t).__name__)
        else:
            np.testing.assert_array_equal(got, ref, err_msg=type(t).__name__)


@settings(max_examples=6, deadline=None)
@given(offset=st.tuples(*[st.floats(-1e7, 1e7)] * 3))
def test_any_translate_up_to_1e7_stays_within_the_documented_tolerance(offset):
    """Any offset, any cloud: the float32 rounding of the coordinates relative
    to the cloud changes, and so may a pair's bin where PCL's arithmetic is
    unstable (the same happens for a shift of 0.1 at the origin); mean-pooled
    rows stay within POOLED_TOLERANCE, float64 features within rounding."""
    offset = np.asarray(offset, dtype=np.float64)
    clouds = _clouds(False)
    far = [c + offset for c in clouds]
    vp = tuple(float(v) for v in offset)
    for t0, t1 in zip(
        _pooled_local_descriptors(np.zeros(3)), _pooled_local_descriptors(vp)
    ):
        a, b = t0.fit_transform(clouds), t1.fit_transform(far)
        assert np.nanmax(np.abs(a - b)) <= POOLED_TOLERANCE, type(t0).__name__
    ref = _at_origin(False)
    by_name = {type(t).__name__: (t, r) for t, r in zip(_estimators(vp), ref)}
    t, r = by_name["NormalEstimator"]
    for a, b in zip(t.fit_transform(far), r):
        np.testing.assert_allclose(a[:, :3] - offset, b[:, :3], atol=1e-8)
        cos = np.sum(a[:, 3:6] * b[:, 3:6], axis=1)
        assert np.nanmin(cos) > 0.999  # same axis, same sign
    for name in ("ShapeFeatures", "OverallDescriptor"):
        t, r = by_name[name]
        got = _moved_back(t, t.fit_transform(far), offset)
        np.testing.assert_allclose(got, r, rtol=1e-6, atol=1e-6, err_msg=name)


def test_the_viewpoint_is_a_point_in_the_clouds_coordinates():
    """Estimated normals face a viewpoint given as three numbers wherever the
    cloud lies (PCL's rule): a cloud at UTM coordinates with PCL's (0, 0, 0)
    is oriented towards a point 4.2e6 away, as PCL would orient it in exact
    arithmetic; the normals are translation invariant when the viewpoint
    moves with the cloud."""
    cloud = _clouds(True)[0]
    far = cloud + UTM
    origin = (0.0, 0.0, 0.0)
    n_far = estimate_normals(far, n_neighbors=10, viewpoint=origin)[0]
    n_ref = estimate_normals(cloud, n_neighbors=10, viewpoint=-UTM)[0]
    # (equal signs: no normal here is within float32 rounding of
    # perpendicular to the direction of the viewpoint)
    np.testing.assert_array_equal(n_far, n_ref)
    n_moved = estimate_normals(far, n_neighbors=10, viewpoint=UTM)[0]
    n_origin = estimate_normals(cloud, n_neighbors=10, viewpoint=origin)[0]
    np.testing.assert_array_equal(n_moved, n_origin)


def test_the_default_viewpoint_moves_with_the_cloud():
    """The default viewpoint ("corner") is fixed to each cloud: the normals
    of a cloud and of its translate are the same, bit for bit, and differ
    from those PCL's (0, 0, 0) gives at UTM coordinates; the point is
    min - (max - min) - 1."""
    cloud = _clouds(True)[0]
    far = cloud + UTM
    n = estimate_normals(cloud, n_neighbors=10)[0]
    np.testing.assert_array_equal(estimate_normals(far, n_neighbors=10)[0], n)
    lo, hi = cloud.min(axis=0), cloud.max(axis=0)
    point = lo - (hi - lo) - 1.0
    same = estimate_normals(cloud, n_neighbors=10, viewpoint=point)[0]
    np.testing.assert_array_equal(n, same)
    fixed = estimate_normals(far, n_neighbors=10, viewpoint=(0.0, 0.0, 0.0))[0]
    assert not np.array_equal(np.sign(fixed), np.sign(n))
    for t in (PFHTransformer(n_neighbors=10), FPFHTransformer(n_neighbors=10)):
        np.testing.assert_array_equal(
            t.fit_transform([far])[0], t.fit_transform([cloud])[0]
        )


def test_function_forms_far_from_the_origin():
    cloud = _clouds(True)[1]
    far = cloud + UTM
    normals = estimate_normals(cloud, n_neighbors=10)[0]
    for f in (compute_pfh, compute_fpfh):
        np.testing.assert_array_equal(
            f(far, normals, n_neighbors=10), f(cloud, normals, n_neighbors=10)
        )
    nb, nb_far = (compute_neighborhoods(c, n_neighbors=10) for c in (cloud, far))
    np.testing.assert_array_equal(nb_far.indices, nb.indices)
    np.testing.assert_array_equal(nb_far.sqdist, nb.sqdist)
    np.testing.assert_array_equal(grid_sample(far, 0.3) - UTM, grid_sample(cloud, 0.3))


def test_several_clouds_each_in_its_own_frame():
    """A batch mixing clouds near and far from the origin: every cloud gets
    what it gets alone, its viewpoint moved into its own frame."""
    from sklearn.base import clone

    clouds = _clouds(True)[:4]
    shifts = [np.zeros(3), UTM, -3 * UTM, np.array([0.0, 0.0, 2e6])]
    mixed = [c + s for c, s in zip(clouds, shifts)]
    origin = (0.0, 0.0, 0.0)
    for t in (
        PFHTransformer(radius=1.0),  # normals estimated in the radius search
        PFHTransformer(n_neighbors=10),
        FPFHTransformer(n_neighbors=10),
        PFHTransformer(radius=1.0, viewpoint=origin),
        PFHTransformer(n_neighbors=10, viewpoint=origin),
        FPFHTransformer(n_neighbors=10, viewpoint=origin),
    ):
        for c, s, got in zip(clouds, shifts, t.fit_transform(mixed)):
            alone = clone(t)
            if t.viewpoint == origin:  # a point in space: moved with the cloud
                alone.set_params(viewpoint=tuple(-s))
            alone = alone.fit_transform([c])[0]
            np.testing.assert_array_equal(got, alone, err_msg=repr(t))


@pytest.mark.parametrize(
    "make",
    [
        lambda: PFHTransformer(n_neighbors=5),
        lambda: FPFHTransformer(radius=1e29),
        lambda: ImprovedPFHTransformer(),
        lambda: NormalEstimator(n_neighbors=5),
    ],
)
def test_extents_float32_cannot_hold_are_a_clear_error(make):
    cloud = np.random.default_rng(0).random((40, 3)) * 1e30
    with pytest.raises(ValueError, match=r"X\[1\] spans .* float32"):
        make().fit_transform([_clouds(True)[5], cloud])


@pytest.mark.parametrize(
    "make",
    [
        lambda: ShapeFeatures(),
        lambda: OverallDescriptor(box="obb_xy"),
        lambda: PFHTransformer(n_neighbors=5),
        lambda: GridSampler(),
    ],
)
def test_coordinates_of_1e200_are_a_clear_error(make):
    """Finding 8: ShapeFeatures raised LinAlgError on 1e200 coordinates."""
    cloud = np.random.default_rng(0).random((40, 3)) * 1e200
    with pytest.raises(ValueError, match=r"spans|cells"):
        make().fit_transform([cloud])


def test_a_representable_cloud_at_1e200_gets_a_correct_result():
    """A cloud far out but with a representable extent is computed as at the
    origin: here all its points coincide in float64."""
    at = np.full((5, 3), 1e200) + np.arange(5.0)[:, None]  # 1e200 + 4 == 1e200
    at_origin = np.zeros((5, 3))
    np.testing.assert_array_equal(
        ShapeFeatures().fit_transform([at]), ShapeFeatures().fit_transform([at_origin])
    )
    got = OverallDescriptor().fit_transform([at])[0]
    np.testing.assert_array_equal(
        got[6:], OverallDescriptor().fit_transform([at_origin])[0, 6:]
    )
    # a sheet of 1e100 on a side: finite sizes, the same ratios as at scale 1
    sheet = np.random.default_rng(0).random((50, 3)) * [1, 1, 0.1]
    big = ShapeFeatures().fit_transform([sheet * 1e90 + 1e95])[0]
    ref = ShapeFeatures().fit_transform([sheet])[0]
    assert np.isfinite(big).all()
    ratios = slice(7, 18)
    np.testing.assert_allclose(big[ratios], ref[ratios], rtol=1e-9, atol=1e-12)
