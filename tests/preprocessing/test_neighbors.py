import numpy as np
import pytest
from scipy.spatial.distance import cdist

from skpcd.preprocessing import compute_neighborhoods


def test_knn_self_first_sorted():
    pts = np.random.default_rng(0).normal(size=(200, 3))
    nb = compute_neighborhoods(pts, n_neighbors=7)
    idx = nb.indices.reshape(200, 7)
    assert (idx[:, 0] == np.arange(200)).all()
    d = cdist(pts, pts)
    ref = np.argsort(d, axis=1)[:, :7]
    assert (np.sort(idx, axis=1) == np.sort(ref, axis=1)).all()
    d2 = nb.sqdist.reshape(200, 7)
    assert (np.diff(d2, axis=1) >= 0).all()
    np.testing.assert_allclose(d2, np.take_along_axis(d, idx, 1) ** 2, rtol=1e-6)


def test_radius_matches_brute_force_and_is_inclusive():
    pts = np.random.default_rng(1).uniform(0, 3, size=(500, 3))
    pts[1] = pts[0] + [0.5, 0, 0]  # exactly at the radius
    nb = compute_neighborhoods(pts, radius=0.5)
    d = cdist(pts, pts)
    for i in range(len(pts)):
        got = nb.indices[nb.indptr[i] : nb.indptr[i + 1]]
        assert got[0] == i
        assert set(got) == set(np.flatnonzero(d[i] <= 0.5))
    assert 1 in nb.indices[nb.indptr[0] : nb.indptr[1]]


def test_duplicates_keep_query_first():
    pts = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, 0.0]])
    nb = compute_neighborhoods(pts, n_neighbors=3)
    assert nb.indices.reshape(4, 3)[:, 0].tolist() == [0, 1, 2, 3]
    nb = compute_neighborhoods(pts, radius=0.1)
    assert nb.sizes.tolist() == [3, 3, 3, 1]
    assert nb.indices[nb.indptr[2]] == 2


def test_small_cloud_and_errors():
    nb = compute_neighborhoods(np.array([[0, 0, 0], [1, 0, 0.0]]), n_neighbors=10)
    assert nb.sizes.tolist() == [2, 2]
    with pytest.raises(ValueError, match="exactly one"):
        compute_neighborhoods(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="positive integer"):
        compute_neighborhoods(np.zeros((3, 3)), n_neighbors=0)
    with pytest.raises(ValueError, match="radius must be positive"):
        compute_neighborhoods(np.zeros((3, 3)), radius=-1)
    with pytest.raises(ValueError, match="NaN"):
        compute_neighborhoods(np.full((3, 3), np.nan), n_neighbors=2)
