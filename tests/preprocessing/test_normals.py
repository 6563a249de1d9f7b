import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.datasets import make_point_clouds
from skpcd.preprocessing import (
    NormalEstimator,
    compute_neighborhoods,
    estimate_normals,
)


def _reference(points, nb, viewpoint):
    """Slow NumPy PCA normals."""
    normals = np.full((len(points), 3), np.nan)
    curv = np.full(len(points), np.nan)
    for i in range(len(points)):
        idx = nb.indices[nb.indptr[i] : nb.indptr[i + 1]]
        if len(idx) < 3:
            continue
        q = points[idx] - points[idx].mean(axis=0)
        w, v = np.linalg.eigh(q.T @ q / len(idx))
        n = v[:, 0]
        if np.dot(viewpoint - points[i], n) < 0:
            n = -n
        normals[i] = n
        curv[i] = w[0] / w.sum()
    return normals, curv


def test_matches_numpy_reference():
    pts = make_point_clouds(1, n_points=300, noise=0.02, random_state=0)[0]
    nb = compute_neighborhoods(pts, n_neighbors=12)
    normals, curv = estimate_normals(pts, neighborhoods=nb, viewpoint=(1, 2, 3))
    ref_n, ref_c = _reference(pts, nb, np.array([1.0, 2, 3]))
    # float32 arithmetic, as PCL
    np.testing.assert_allclose(normals, ref_n, atol=1e-4)
    np.testing.assert_allclose(curv, ref_c, atol=1e-5)


def test_plane_faces_viewpoint():
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0), [0.0]), -1).reshape(-1, 3)
    up, c = estimate_normals(g, n_neighbors=9, viewpoint=(0, 0, 10))
    np.testing.assert_allclose(up, np.tile([0, 0, 1.0], (36, 1)), atol=1e-6)
    np.testing.assert_allclose(c, 0, atol=1e-7)
    down, _ = estimate_normals(g, n_neighbors=9, viewpoint=(0, 0, -10))
    np.testing.assert_allclose(down, -up)


def test_sphere_normals_are_radial():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    normals, _ = estimate_normals(5 * d, n_neighbors=15, viewpoint=(0, 0, 0))
    # viewpoint at the centre: normals point inwards
    assert np.min(np.sum(normals * -d, axis=1)) > 0.99


def test_degenerate_neighbourhoods_give_nan():
    line = np.column_stack([np.zeros(20), np.zeros(20), np.arange(20.0)])
    normals, curv = estimate_normals(line, n_neighbors=5)
    assert np.isnan(normals).all()
    assert np.isfinite(curv).all()
    dup = np.zeros((6, 3))
    normals, curv = estimate_normals(dup, n_neighbors=4)
    assert np.isnan(normals).all() and (curv == 0).all()
    sparse = np.array([[0, 0, 0], [0.1, 0, 0], [10, 0, 0.0], [20, 5, 1.0]])
    normals, curv = estimate_normals(sparse, radius=0.5)
    assert np.isnan(normals).all() and np.isnan(curv).all()


def test_argument_errors():
    pts = np.random.default_rng(0).normal(size=(10, 3))
    with pytest.raises(ValueError, match="exactly one"):
        estimate_normals(pts, n_neighbors=3, radius=1.0)
    with pytest.raises(ValueError, match="viewpoint"):
        estimate_normals(pts, n_neighbors=3, viewpoint=(0, 0))
    with pytest.raises(ValueError, match="viewpoint must be 'corner'"):
        estimate_normals(pts, n_neighbors=3, viewpoint="centre")
    nb = compute_neighborhoods(pts[:5], n_neighbors=3)
    with pytest.raises(ValueError, match="cover 5 points"):
        estimate_normals(pts, neighborhoods=nb)
    bad = pts.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        estimate_normals(bad, n_neighbors=3)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 1000), angle=st.floats(0, 6.28))
def test_rotation_equivariance(seed, angle):
    pts = make_point_clouds(1, n_points=80, random_state=seed)[0]
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    vp = np.array([3.0, -2.0, 40.0])
    n0, c0 = estimate_normals(pts, n_neighbors=10, viewpoint=vp)
    n1, c1 = estimate_normals(pts @ rot.T + 7, n_neighbors=10, viewpoint=vp @ rot.T + 7)
    np.testing.assert_allclose(n1, n0 @ rot.T, atol=1e-4)
    np.testing.assert_allclose(c1, c0, atol=1e-5)


def test_estimator_layout():
    clouds = make_point_clouds(3, n_points=(20, 40), n_columns=4, random_state=1)
    out = NormalEstimator(n_neighbors=6, include_curvature=True).fit_transform(clouds)
    for c, o in zip(clouds, out):
        assert o.shape == (len(c), 7)
        np.testing.assert_array_equal(o[:, :3], c[:, :3])
        n, k = estimate_normals(c, n_neighbors=6)
        np.testing.assert_array_equal(o[:, 3:6], n)
        np.testing.assert_array_equal(o[:, 6], k)


def test_estimator_replaces_given_normals():
    # NormalEstimator always estimates: normals already in columns 3-5 are
    # replaced (the descriptors, by default, use given normals instead)
    clouds = make_point_clouds(2, n_points=(30, 40), random_state=2)
    given = [np.c_[c, np.tile([0.0, 0.0, 1.0], (len(c), 1))] for c in clouds]
    est = NormalEstimator(n_neighbors=8)
    for a, b in zip(est.fit_transform(given), est.fit_transform(clouds)):
        np.testing.assert_array_equal(a, b)
    # its output has unit (or NaN) normals, as the descriptors require
    for o in est.fit_transform(clouds):
        norm = np.linalg.norm(o[:, 3:6], axis=1)
        assert np.all(np.isnan(norm) | (np.abs(norm - 1) < 1e-6))


def test_normals_at_utm_coordinates():
    """Float32 of absolute UTM coordinates is 0.5 m coarse at y = 4.2e6: the
    normals of a 5 cm grid were noise. In the cloud's local frame they are
    those of the cloud at the origin (the viewpoint moved along)."""
    g = np.stack(np.meshgrid(np.arange(20) * 0.05, np.arange(20) * 0.05, [0.0]), -1)
    plane = g.reshape(-1, 3) @ np.array([[1, 0, 0], [0, 1, 0.3], [0, 0, 1]])
    utm = np.array([5e5, 4.2e6, 30.0])
    above = tuple(utm + np.array([0, 0, 10]))
    ref, curv = estimate_normals(plane, n_neighbors=10, viewpoint=(0, 0, 10))
    got, got_curv = estimate_normals(plane + utm, n_neighbors=10, viewpoint=above)
    # float32 rounding of the coordinates relative to the cloud (z = 30 is
    # kept as given): within 1e-4 of the plane's normal, as at the origin
    true = np.array([0.0, -0.3, 1.0]) / np.hypot(0.3, 1.0)
    np.testing.assert_allclose(ref, np.broadcast_to(true, ref.shape), atol=1e-4)
    np.testing.assert_allclose(got, ref, atol=1e-4)
    np.testing.assert_allclose(got_curv, curv, atol=1e-6)
    est = NormalEstimator(n_neighbors=10, viewpoint=above)
    out = est.fit_transform([plane + utm])[0]
    np.testing.assert_array_equal(out[:, :3], plane + utm)
    np.testing.assert_array_equal(out[:, 3:], got)
