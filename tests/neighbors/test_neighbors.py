import numpy as np
import pytest
from scipy.spatial.distance import cdist

from skpcd.neighbors import compute_neighborhoods


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


def _assert_same(a, b, ties_ok=False):
    np.testing.assert_array_equal(a.indptr, b.indptr)
    np.testing.assert_array_equal(a.sqdist, b.sqdist)
    if not ties_ok:
        np.testing.assert_array_equal(a.indices, b.indices)


@pytest.mark.parametrize(
    "search, brute_work",
    [
        ({"n_neighbors": 10}, None),  # isolated points by brute force
        ({"n_neighbors": 10}, 0),  # coarser grids, then cKDTree
        ({"radius": 0.15}, None),
    ],
)
def test_grid_equals_kd_tree_on_random_and_clustered_clouds(
    search, brute_work, monkeypatch
):
    from skpcd.neighbors import _neighbors

    if brute_work is not None:
        monkeypatch.setattr(_neighbors, "_BRUTE_WORK", brute_work)
    rng = np.random.default_rng(3)
    pts = np.vstack(
        [
            rng.uniform(0, 1, size=(800, 3)),  # volume
            np.column_stack([rng.uniform(5, 7, (600, 2)), np.full(600, 2.0)]),  # plane
            rng.normal(20, 0.01, size=(50, 3)),  # dense blob
            [[100.0, 100, 100], [-50, 3, 1]],  # isolated: beyond the grid's shells
        ]
    )
    grid = compute_neighborhoods(pts, algorithm="grid", **search)
    tree = compute_neighborhoods(pts, algorithm="kd_tree", **search)
    _assert_same(grid, tree)
    # ties broken by index, the point first
    for i in range(0, len(pts), 97):
        row = grid.indices[grid.indptr[i] : grid.indptr[i + 1]]
        d = grid.sqdist[grid.indptr[i] : grid.indptr[i + 1]]
        assert row[0] == i
        assert all((d[1:-1] < d[2:]) | ((d[1:-1] == d[2:]) & (row[1:-1] < row[2:])))


def test_a_few_isolated_queries_scan_farther_shells_of_the_same_grid(monkeypatch):
    """Three points 0.2-0.4 m off a dense plane (cells ~1.6 cm: beyond the
    first 8 shells, within 32): answered on the same grid, no coarser grid
    built, the same neighbours as the k-d tree."""
    from skpcd.neighbors import _neighbors

    built = []
    real = _neighbors.build_grid
    monkeypatch.setattr(
        _neighbors, "build_grid", lambda *a, **k: built.append(1) or real(*a, **k)
    )
    rng = np.random.default_rng(5)
    plane = np.column_stack([rng.uniform(0, 1, (20000, 2)), np.zeros(20000)])
    far = [[1.2, 0.5, 0.0], [0.5, -0.3, 0.0], [0.5, 0.5, 0.4]]
    pts = np.vstack([plane, far])
    grid = compute_neighborhoods(pts, n_neighbors=10, algorithm="grid", n_jobs=2)
    assert not built
    _assert_same(grid, compute_neighborhoods(pts, n_neighbors=10, algorithm="kd_tree"))
    # with the far pass off (and no brute force), a coarser grid answers
    monkeypatch.setattr(_neighbors, "_FEW_FAR", 0.0)
    monkeypatch.setattr(_neighbors, "_BRUTE_WORK", 0)
    again = compute_neighborhoods(pts, n_neighbors=10, algorithm="grid", n_jobs=2)
    assert built
    _assert_same(again, grid)


def test_grid_ties_on_a_lattice_keep_lowest_indices():
    # a centimetre lattice: many neighbours at exactly the same distance
    g = np.stack(np.meshgrid(*[np.arange(6) * 0.01] * 3, indexing="ij"), -1)
    pts = g.reshape(-1, 3)
    nb = compute_neighborhoods(pts, n_neighbors=9, algorithm="grid")
    e = pts[None, :, :] - pts[:, None, :]
    d = (e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1]) + e[..., 2] * e[..., 2]
    ids = np.arange(len(pts))
    for i in range(len(pts)):
        row = nb.indices[nb.indptr[i] : nb.indptr[i + 1]]
        order = np.lexsort((ids, np.where(ids == i, -1, d[i])))
        assert row.tolist() == order[:9].tolist()


def test_packed_search_never_crosses_clouds():
    from skpcd.neighbors._neighbors import search_packed

    rng = np.random.default_rng(0)
    a, b = rng.random((300, 3)), rng.random((5, 3))  # same place, two clouds
    xyz = np.vstack([a, b])
    ptr = np.array([0, 300, 305])
    for algorithm in ("grid", "kd_tree"):
        nb = search_packed(xyz, ptr, n_neighbors=8, algorithm=algorithm)
        assert nb.sizes.tolist() == [8] * 300 + [5] * 5
        assert (nb.indices[: 300 * 8] < 300).all() and (
            nb.indices[300 * 8 :] >= 300
        ).all()
        nb = search_packed(xyz, ptr, radius=0.3, algorithm=algorithm)
        rows = np.repeat(np.arange(305), nb.sizes)
        assert ((rows < 300) == (nb.indices < 300)).all()


def test_unknown_algorithm_is_refused():
    with pytest.raises(ValueError, match="algorithm"):
        compute_neighborhoods(np.zeros((3, 3)), n_neighbors=2, algorithm="ball")


def test_grid_equals_kd_tree_on_objects(labelled_objects):
    clouds = labelled_objects[0][:25]
    from skpcd.neighbors._neighbors import search_packed
    from skpcd.preprocessing._normals import pack_neighborhoods

    xyz, ptr, grid = pack_neighborhoods(clouds, n_neighbors=10, n_threads=2)
    tree = search_packed(xyz, ptr, n_neighbors=10, algorithm="kd_tree")
    _assert_same(grid, tree, ties_ok=True)
    # ties aside, the neighbour sets agree: same distances row by row
    assert (grid.indices == tree.indices).mean() > 0.99


@pytest.mark.parametrize("algorithm", ["grid", "kd_tree"])
def test_far_from_the_origin_exact_and_the_same_as_at_the_origin(algorithm):
    """At 1e7 the grid's shell bounds are computed from offsets to the cloud's
    minimum (exact), not from absolute cell edges (rounded to 2e-9, more
    than the 1e-7 cell margin of millimetre cells); an exact translate has
    the same neighbourhoods, ties included."""
    rng = np.random.default_rng(5)
    pts = np.round(rng.uniform(0, 0.05, size=(600, 3)) * 2**16) / 2**16
    far = pts + np.array([1e7, -1e7, 3e6])
    for search in ({"n_neighbors": 9}, {"radius": 0.004}):
        a = compute_neighborhoods(pts, algorithm=algorithm, **search)
        b = compute_neighborhoods(far, algorithm=algorithm, **search)
        np.testing.assert_array_equal(a.indptr, b.indptr)
        np.testing.assert_array_equal(a.indices, b.indices)
        np.testing.assert_array_equal(a.sqdist, b.sqdist)
    # and equal to brute force on the far coordinates
    d = cdist(far, far) ** 2
    nb = compute_neighborhoods(far, n_neighbors=9, algorithm=algorithm)
    idx = nb.indices.reshape(-1, 9)
    kth = np.sort(d, axis=1)[:, 8]
    np.testing.assert_array_equal(np.take_along_axis(d, idx, 1).max(axis=1), kth)


def test_extents_whose_squares_overflow_are_refused():
    pts = np.random.default_rng(0).random((20, 3)) * 1e200
    with pytest.raises(ValueError, match=r"X\[0\] spans .* float64 \(the neighbour"):
        compute_neighborhoods(pts, n_neighbors=3)
    # a cloud far out with a representable extent is searched
    compute_neighborhoods(pts * 1e-60 + 1e250, n_neighbors=3)


def _scan_like(n, seed=0):
    """A cloud in scan order: points along a few long strips, each strip
    swept in order (neighbours close in the points' order)."""
    rng = np.random.default_rng(seed)
    s = np.sort(rng.random(n)) * 200.0
    return np.column_stack([s, rng.random(n) * 2.0, rng.random(n) * 0.1])


def test_grid_order_is_a_permutation_within_clouds_and_renumbering_is_exact():
    from skpcd.neighbors._neighbors import search_packed

    rng = np.random.default_rng(3)
    xyz = np.vstack([rng.random((700, 3)), rng.random((300, 3)) + 5.0])
    ptr = np.array([0, 700, 1000])
    for search in ({"n_neighbors": 9}, {"radius": 0.15}):
        nb, order = search_packed(xyz, ptr, return_order=True, **search)
        assert sorted(order.tolist()) == list(range(1000))
        assert (order[:700] < 700).all() and (order[700:] >= 700).all()
        new = nb.renumbered(order, n_threads=2)
        inv = np.argsort(order)
        for t in range(1000):
            i = order[t]
            old_row = nb.indices[nb.indptr[i] : nb.indptr[i + 1]]
            new_row = new.indices[new.indptr[t] : new.indptr[t + 1]]
            # the same neighbours, renumbered, in the same order
            assert new_row.tolist() == inv[old_row].tolist()
            old_d = nb.sqdist[nb.indptr[i] : nb.indptr[i + 1]]
            assert new.sqdist[new.indptr[t] : new.indptr[t + 1]].tolist() == (
                old_d.tolist()
            )
    _, order = search_packed(xyz, ptr, n_neighbors=9, algorithm="kd_tree",
                             return_order=True)  # fmt: skip
    assert order is None


def test_scattered_tells_a_shuffled_cloud_from_one_in_scan_order():
    from skpcd.neighbors._neighbors import _NEAR, scattered, search_packed

    n = 3 * _NEAR
    xyz = _scan_like(n)
    one = np.array([0, n])
    assert not scattered(search_packed(xyz, one, n_neighbors=10))
    shuffled = xyz[np.random.default_rng(1).permutation(n)]
    assert scattered(search_packed(shuffled, one, n_neighbors=10))
    # small clouds fit in the cache whatever their order
    small = shuffled[: _NEAR // 2]
    assert not scattered(
        search_packed(small, np.array([0, len(small)]), n_neighbors=10)
    )
