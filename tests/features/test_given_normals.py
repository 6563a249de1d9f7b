"""Normals given in the clouds (columns 3-5): used as given, as PCL does, never
ignored without being asked to, refused when they are not unit vectors."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.pipeline import make_pipeline

from skpcd.datasets import make_point_clouds, make_primitives
from skpcd.features import (
    FPFHTransformer,
    ImprovedPFHTransformer,
    PFHTransformer,
    compute_fpfh,
    compute_pfh,
)
from skpcd.preprocessing import NormalEstimator, estimate_normals

F = np.float32
LOCAL = (PFHTransformer, FPFHTransformer)
SEARCHES = ({"n_neighbors": 9}, {"radius": 1.0})  # radius: PFH's blocked path


def _with_normals(seed=0, n=150, **estimate):
    """A cloud with normals that the transformers' own estimate would not give
    (another k, another viewpoint), as ``(xyz, xyz + normals)``."""
    pts = make_point_clouds(1, n_points=n, noise=0.01, random_state=seed)[0]
    normals, _ = estimate_normals(
        pts, **(estimate or {"n_neighbors": 25, "viewpoint": (0, 0, 1e3)})
    )
    return pts, np.hstack([pts, normals])


def _assert_rows_equal(a, b):
    assert len(a) == len(b)
    for u, v in zip(a, b, strict=True):
        np.testing.assert_array_equal(u, v)


@pytest.mark.parametrize("search", SEARCHES, ids=["knn", "radius"])
@pytest.mark.parametrize("cls", LOCAL)
def test_six_column_cloud_uses_its_normals_by_default(cls, search):
    pts, cloud = _with_normals(1)
    t = cls(**search, undefined="keep")  # the rows of PCL, as compute_pfh's
    default = t.fit_transform([cloud])
    cols = t.set_params(normals="columns").fit_transform([cloud])
    _assert_rows_equal(default, cols)
    compute = compute_pfh if cls is PFHTransformer else compute_fpfh
    ref = compute(pts, cloud[:, 3:6], **search)
    np.testing.assert_array_equal(default[0], ref)
    # not the descriptor of the bare xyz, whose normals are estimated
    xyz_only = t.set_params(normals="auto").fit_transform([pts])
    assert not np.array_equal(default[0], xyz_only[0])


@pytest.mark.parametrize("search", SEARCHES, ids=["knn", "radius"])
@pytest.mark.parametrize("cls", LOCAL)
def test_auto_decides_cloud_by_cloud(cls, search):
    # a 7-column cloud (NormalEstimator with the curvature) has normals too; a
    # 4-column one (xyz + intensity) has them estimated
    a, six = _with_normals(2, 120)
    _, seven = _with_normals(3, 90)
    seven = np.c_[seven, np.zeros(len(seven))]
    four = np.c_[a, np.ones(len(a))]
    got = cls(**search).fit_transform([four, six, seven, a])
    est = cls(**search, normals="estimate").fit_transform([a, a])
    cols = cls(**search, normals="columns").fit_transform([six, seven])
    _assert_rows_equal(got, [est[0], cols[0], cols[1], est[1]])


def test_normal_estimator_in_a_pipeline_keeps_its_normals():
    # before: PFHTransformer re-estimated the normals (k = 10), silently
    # dropping NormalEstimator's k = 20
    clouds = make_point_clouds(3, n_points=(60, 90), random_state=4)
    for curvature in (False, True):
        pipe = make_pipeline(
            NormalEstimator(n_neighbors=20, include_curvature=curvature),
            PFHTransformer(n_neighbors=10),
        )
        ref = PFHTransformer(n_neighbors=10, normal_n_neighbors=20)
        _assert_rows_equal(pipe.fit_transform(clouds), ref.fit_transform(clouds))


@pytest.mark.parametrize("cls", [*LOCAL, ImprovedPFHTransformer])
def test_estimate_ignores_the_columns_when_asked(cls):
    pts, cloud = _with_normals(5)
    t = cls(normals="estimate")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # asked for: no warning
        got = t.fit_transform([cloud])
    _assert_rows_equal(got, t.fit_transform([pts]))


def test_improved_pfh_uses_given_normals():
    clouds, _ = make_primitives(1, shapes=["cylinder", "cone"], random_state=3)
    given = []
    for c in clouds:
        # the line of each normal is what counts (the descriptor symmetrises
        # the sign): normals estimated with k = 30, signs flipped at random
        n, _ = estimate_normals(c, n_neighbors=30)
        n *= np.where(np.random.default_rng(0).random(len(c)) < 0.5, -1, 1)[:, None]
        given.append(np.hstack([c, n]))
    t = ImprovedPFHTransformer()
    got = t.fit_transform(given)
    np.testing.assert_array_equal(
        got, ImprovedPFHTransformer(normals="columns").fit_transform(given)
    )
    assert not np.array_equal(got, t.fit_transform(clouds))
    # normals estimated as the transformer would: the same descriptor
    same = [np.hstack([c, estimate_normals(c, n_neighbors=10)[0]]) for c in clouds]
    np.testing.assert_array_equal(t.fit_transform(same), t.fit_transform(clouds))
    with pytest.raises(ValueError, match="columns 3-5"):
        ImprovedPFHTransformer(normals="columns").fit(clouds)


def _spoil(cloud, rows, value):
    bad = cloud.copy()
    bad[rows, 3:6] = value
    return bad


@pytest.mark.parametrize("normals", ["auto", "columns"])
@pytest.mark.parametrize("cls", [*LOCAL, ImprovedPFHTransformer])
def test_non_unit_normals_are_refused(cls, normals):
    pts, cloud = _with_normals(6, 50)
    bad = cloud.copy()
    bad[4, 3:6] *= 2.0
    bad[7, 3:6] = 0.0
    bad[9, 3:6] = [np.inf, 0, 0]
    t = cls(normals=normals)
    msg = (
        r"X\[1\]: 3 of 50 normals \(columns 3-5\) are not unit vectors .* row 4, "
        r"norm 2\b.*normals='estimate'"
    )
    for method in ("fit", "fit_transform", "transform"):
        with pytest.raises(ValueError, match=msg):
            getattr(t, method)([cloud, bad])
    # random vectors, as the issue reported
    noise = np.c_[pts, np.random.default_rng(0).normal(size=(50, 3))]
    with pytest.raises(ValueError, match=r"X\[0\]: \d+ of 50 normals"):
        t.fit_transform([noise])
    # estimate: the columns are not read, so not checked
    assert len(cls(normals="estimate").fit_transform([bad])) == 1


@pytest.mark.parametrize("compute", [compute_pfh, compute_fpfh])
def test_function_forms_refuse_non_unit_normals(compute):
    pts, cloud = _with_normals(7, 40)
    normals = cloud[:, 3:6].copy()
    normals[3] *= 1.01
    with pytest.raises(ValueError, match=r"normals: 1 of 40 normals are not unit"):
        compute(pts, normals, n_neighbors=8)


def test_nearly_unit_normals_are_used_as_given():
    # normals written with 4 decimals (|norm - 1| up to ~1e-4): accepted and
    # used as they are, not renormalised (PCL's setInputNormals)
    _, cloud = _with_normals(8, 80)
    rounded = np.round(cloud, 4)
    assert np.abs(np.linalg.norm(rounded[:, 3:6], axis=1) - 1).max() > 1e-6
    got = PFHTransformer(n_neighbors=9).fit_transform([rounded])[0]
    ref = compute_pfh(rounded[:, :3], rounded[:, 3:6], n_neighbors=9)
    np.testing.assert_array_equal(got, ref)
    # a pair with f2 = -0.6 on a bin edge: the normal 5e-4 short of unit
    # length puts it in bin 1 for f2 (0.6 * 0.9995 < 0.6), the unit one in 0
    pts = np.array([[0, 0, 0], [1, 0, 0.0]])
    for scale, code in ((0.9995, 2 + 5 * 1 + 25 * 2), (1.0, 2 + 5 * 0 + 25 * 2)):
        n = np.array([[0, 0, 1], [0, 0.6 * scale, 0.8 * scale]])
        h = PFHTransformer(n_neighbors=2).fit_transform([np.hstack([pts, n])])[0]
        assert np.flatnonzero(h[0]).tolist() == [code]


@pytest.mark.parametrize("search", SEARCHES, ids=["knn", "radius"])
@pytest.mark.parametrize("cls", LOCAL)
def test_nan_normals_are_undefined_points_as_in_pcl(cls, search):
    pts, cloud = _with_normals(9, 150)
    nan_rows = [3, 40, 41, 100]
    cloud = _spoil(cloud, nan_rows, np.nan)
    cloud[120, 4] = np.nan  # one NaN component: an undefined normal too
    nan_rows.append(120)
    t = cls(**search)
    mask = t.undefined_mask([cloud])[0]
    assert mask[nan_rows].all()
    assert mask.sum() == len(nan_rows)  # this cloud has no isolated point
    rows = t.fit_transform([cloud])[0]
    assert np.isnan(rows[nan_rows]).all() and np.isfinite(rows[~mask]).all()
    assert len(t.set_params(undefined="drop").fit_transform([cloud])[0]) == 145
    # "keep": PCL's values, the NaN normal used as given; as a neighbour its
    # pairs' NaN angles land in bin 0, which the other rows keep
    kept = t.set_params(undefined="keep").fit_transform([cloud])[0]
    compute = compute_pfh if cls is PFHTransformer else compute_fpfh
    np.testing.assert_array_equal(kept, compute(pts, cloud[:, 3:6], **search))
    np.testing.assert_array_equal(kept[~mask], rows[~mask])
    pooled = t.set_params(undefined="nan", pooling="mean").fit_transform([cloud])
    np.testing.assert_allclose(pooled[0], rows[~mask].mean(axis=0), rtol=1e-5)


@pytest.mark.parametrize("cls", LOCAL)
def test_given_nan_normals_equal_pcls_own_nan_normals(cls):
    # a pole: its vertical runs have collinear neighbourhoods, whose normal
    # PCL 1.13 estimates as NaN; handing those normals back (NormalEstimator's
    # output) gives the same descriptors as estimating them
    clouds, _ = make_primitives(1, shapes=["cylinder"], random_state=0)
    pole = np.c_[np.zeros((12, 2)), np.arange(12.0)]
    xyz = np.vstack([clouds[0], pole + np.array([5.0, 5.0, 0.0])])
    normals, _ = estimate_normals(xyz, n_neighbors=8)
    assert np.isnan(normals).any()
    for undefined in ("nan", "keep", "zero"):
        t = cls(n_neighbors=8, undefined=undefined)
        _assert_rows_equal(
            t.fit_transform([np.hstack([xyz, normals])]), t.fit_transform([xyz])
        )


def test_improved_pfh_leaves_out_points_with_nan_normals():
    clouds, _ = make_primitives(1, shapes=["plane"], random_state=1)
    c = clouds[0]
    n, _ = estimate_normals(c, n_neighbors=10)
    cloud = np.hstack([c, n])
    t = ImprovedPFHTransformer()
    np.testing.assert_array_equal(t.fit_transform([cloud]), t.fit_transform([c]))
    none = _spoil(cloud, slice(None), np.nan)
    assert np.isnan(t.fit_transform([none])).all()
    assert (t.set_params(undefined="zero").fit_transform([none]) == 0).all()


@pytest.mark.parametrize(
    ("cls", "param"),
    [
        (PFHTransformer, {"normal_n_neighbors": 15}),
        (FPFHTransformer, {"normal_radius": 0.5}),
        (PFHTransformer, {"viewpoint": (0, 0, 100)}),
        (ImprovedPFHTransformer, {"n_neighbors": 15}),
        (ImprovedPFHTransformer, {"radius": 0.5}),
    ],
)
def test_estimation_parameters_with_given_normals_are_refused(cls, param):
    # they would be ignored: an error says so, and what to do
    pts, cloud = _with_normals(10, 40)
    name = next(iter(param))
    t = cls(**param)
    with pytest.raises(ValueError, match=rf"X\[1\] has normals .*{name}"):
        t.fit([pts, cloud])
    t.fit_transform([pts])  # estimated: used
    cls(**param, normals="estimate").fit_transform([pts, cloud])


def _quantised(seed, n=150):
    """A cloud on a 2**-8 grid: translated by integers, its float32 coordinates
    and differences stay exact, so descriptors can be compared bit for bit."""
    pts = make_point_clouds(1, n_points=n, noise=0.01, random_state=seed)[0]
    pts = np.round((pts - pts.mean(axis=0)) * 256) / 256
    normals, _ = estimate_normals(pts, n_neighbors=10, viewpoint=(0, 0, 1e3))
    return np.hstack([pts, normals])


@settings(max_examples=10, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    shift=st.tuples(*[st.integers(-5000, 5000)] * 3),
)
def test_given_normals_make_descriptors_translation_and_order_invariant(seed, shift):
    # estimated normals face the viewpoint, so their signs (and the PFH)
    # change with the cloud's position; given normals are the cloud's own
    cloud = _quantised(seed)
    moved = cloud + np.r_[shift, 0, 0, 0]
    order = np.random.default_rng(seed).permutation(len(cloud))
    # the point order is compared on unquantised coordinates (no distance ties,
    # which the k nearest break by index)
    _, free = _with_normals(seed, 150, n_neighbors=10)
    for t in (
        PFHTransformer(n_neighbors=10),
        FPFHTransformer(n_neighbors=10),
        PFHTransformer(radius=0.5),
        ImprovedPFHTransformer(),
    ):
        base, there = t.fit_transform([cloud]), t.fit_transform([moved])
        if isinstance(t, ImprovedPFHTransformer):
            # its middle point is a mean: rounded differently once moved
            assert np.abs(there - base).sum() < 3.0
            continue
        np.testing.assert_array_equal(there[0], base[0])
        ref = t.fit_transform([free])[0]
        shuffled = t.fit_transform([free[order]])[0][np.argsort(order)]
        np.testing.assert_array_equal(shuffled, ref)
