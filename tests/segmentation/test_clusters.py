"""Grid DBSCAN and Euclidean clusters: exact oracle, invariances, bad input,
memory, scikit-learn conventions."""

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import cdist
from sklearn.base import clone
from sklearn.cluster import DBSCAN
from sklearn.utils.estimator_checks import parametrize_with_checks

from skpcd.io import read_point_cloud
from skpcd.segmentation import (
    AutoEpsDBSCAN,
    EuclideanClusters,
    GroundFilter,
    _clusters,
    euclidean_clusters,
)
from skpcd.segmentation._clusters import filter_cluster_sizes, grid_dbscan


def reference_dbscan(xyz, eps, min_samples):
    """Slow, obvious DBSCAN: all distances, components of the core graph,
    border points to their nearest core point (ties: lower index), clusters
    numbered by their lowest point index."""
    d = cdist(xyz, xyz)
    near = d <= eps
    core = near.sum(axis=1) >= min_samples
    cc = np.flatnonzero(core)
    _, comp = connected_components(csr_matrix(near[np.ix_(cc, cc)]), directed=False)
    root = np.full(len(xyz), -1)
    root[cc] = comp
    for i in np.flatnonzero(~core):
        cand = cc[near[i, cc]]
        if len(cand):
            root[i] = root[cand[np.lexsort((cand, d[i, cand]))[0]]]
    labels = np.full(len(xyz), -1)
    seen = {}
    for i, r in enumerate(root):
        if r >= 0:
            labels[i] = seen.setdefault(r, len(seen))
    return labels, core


def canonical(labels):
    """Labels renumbered by first appearance (-1 kept)."""
    out = np.full(len(labels), -1)
    seen = {}
    for i, v in enumerate(labels):
        if v >= 0:
            out[i] = seen.setdefault(v, len(seen))
    return out


def _blobs(n, seed, spread=1.0):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, 10, (5, 3))
    pts = centres[rng.integers(0, 5, n)] + rng.normal(0, 0.3 * spread, (n, 3))
    return np.vstack([pts, rng.uniform(-2, 12, (n // 10, 3))])


@pytest.mark.parametrize("eps", [0.2, 0.5, 1.5])
@pytest.mark.parametrize("min_samples", [1, 3, 8])
def test_grid_dbscan_equals_reference(eps, min_samples):
    xyz = _blobs(400, seed=int(eps * 10) + min_samples)
    labels, core = grid_dbscan(xyz, eps, min_samples)
    ref_labels, ref_core = reference_dbscan(xyz, eps, min_samples)
    np.testing.assert_array_equal(core, ref_core)
    np.testing.assert_array_equal(labels, ref_labels)


def test_core_partition_equals_sklearn():
    xyz = _blobs(1500, seed=3)
    labels, core = grid_dbscan(xyz, 0.4, 6)
    sk = DBSCAN(eps=0.4, min_samples=6).fit(xyz)
    sk_core = np.zeros(len(xyz), bool)
    sk_core[sk.core_sample_indices_] = True
    np.testing.assert_array_equal(core, sk_core)
    np.testing.assert_array_equal(canonical(labels[core]), canonical(sk.labels_[core]))
    np.testing.assert_array_equal(labels < 0, sk.labels_ < 0)


def test_euclidean_clusters_are_connected_components():
    xyz = _blobs(600, seed=4)
    eps = 0.35
    _, comp = connected_components(csr_matrix(cdist(xyz, xyz) <= eps), directed=False)
    sizes = np.bincount(comp)
    kept = (sizes[comp] >= 20) & (sizes[comp] <= 100)
    labels = euclidean_clusters(xyz, eps=eps, min_cluster_size=20, max_cluster_size=100)
    np.testing.assert_array_equal(labels >= 0, kept)
    np.testing.assert_array_equal(canonical(labels[kept]), canonical(comp[kept]))
    assert labels.max() + 1 == len(np.unique(comp[kept]))


def test_euclidean_clusters_seed_defaults():
    ec = EuclideanClusters()
    assert (ec.eps, ec.min_cluster_size, ec.max_cluster_size) == (0.2, 500, None)


def test_filter_cluster_sizes():
    labels = np.array([0, 0, 1, -1, 2, 2, 2, 1, 0])
    np.testing.assert_array_equal(
        filter_cluster_sizes(labels, 3), [0, 0, -1, -1, 1, 1, 1, -1, 0]
    )
    np.testing.assert_array_equal(
        filter_cluster_sizes(labels, 2, 2), [-1, -1, 0, -1, -1, -1, -1, 0, -1]
    )
    assert filter_cluster_sizes(np.full(3, -1), 1).tolist() == [-1, -1, -1]


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    shift=st.tuples(*[st.floats(-1e4, 1e4, allow_nan=False)] * 3),
)
def test_partition_invariant_to_translation_and_order(seed, shift):
    rng = np.random.default_rng(seed)
    # coordinates on a 1/64 lattice: translated by a lattice multiple they
    # stay exact, so distances (and ties) are unchanged
    xyz = np.round(_blobs(300, seed) * 64) / 64
    shift = np.round(np.asarray(shift) * 64) / 64
    labels, core = grid_dbscan(xyz, 0.5, 4)
    moved, moved_core = grid_dbscan(np.ascontiguousarray(xyz + shift), 0.5, 4)
    np.testing.assert_array_equal(moved, labels)
    np.testing.assert_array_equal(moved_core, core)
    perm = rng.permutation(len(xyz))
    shuffled, shuffled_core = grid_dbscan(np.ascontiguousarray(xyz[perm]), 0.5, 4)
    np.testing.assert_array_equal(shuffled_core, core[perm])
    # core points: same clusters; border points: same unless tied
    np.testing.assert_array_equal(
        canonical(shuffled[shuffled_core]), canonical(labels[perm][core[perm]])
    )
    ec = EuclideanClusters(eps=0.5, min_cluster_size=1)
    np.testing.assert_array_equal(
        canonical(ec.fit(xyz[perm]).labels_), canonical(ec.fit(xyz).labels_[perm])
    )


def test_n_jobs_and_read_only_input(monkeypatch):
    from skpcd.segmentation import _clusters

    # split the union-find among threads even on this small cloud
    monkeypatch.setattr(_clusters, "_MIN_UNION_POINTS", 1000)
    xyz = _blobs(20_000, seed=5)
    one = AutoEpsDBSCAN(eps=0.3, n_jobs=1).fit(xyz).labels_
    frozen = xyz.copy()
    frozen.flags.writeable = False
    two = AutoEpsDBSCAN(eps=0.3, n_jobs=2).fit(frozen).labels_
    np.testing.assert_array_equal(one, two)
    many = AutoEpsDBSCAN(eps=0.3, n_jobs=5).fit(xyz).labels_
    np.testing.assert_array_equal(one, many)
    ec = EuclideanClusters(eps=0.3, min_cluster_size=1)
    np.testing.assert_array_equal(
        ec.set_params(n_jobs=1).fit(xyz).labels_,
        ec.set_params(n_jobs=3).fit(xyz).labels_,
    )


def test_fewer_columns_are_refused_and_extra_columns_ignored():
    # a scene has x, y and z: two columns are an error (issue 15), not a
    # plane at z = 0; columns beyond the third (intensity...) are ignored
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.random((300, 2)) * 5, np.zeros(300)])
    ec = EuclideanClusters(eps=0.3, min_cluster_size=1)
    for est in (ec, AutoEpsDBSCAN()):
        with pytest.raises(ValueError, match=r"2 feature.*needs at least 3"):
            est.fit(xyz[:, :2])
    with_intensity = np.column_stack([xyz, rng.random(300) * 100])
    np.testing.assert_array_equal(ec.fit(with_intensity).labels_, ec.fit(xyz).labels_)
    for bad in (xyz[:, :2], with_intensity, xyz[:, 0]):
        with pytest.raises(ValueError, match=r"shape \(n_points, 3\)"):
            grid_dbscan(bad, 0.3, 2)
    with pytest.raises(ValueError, match="NaN or infinite"):
        grid_dbscan(np.array([[0.0, 0, np.inf], [0, 0, 0]]), 0.3, 2)


def test_duplicated_points_are_one_cluster():
    xyz = np.repeat([[0.0, 0, 0], [5.0, 5, 5]], 10, axis=0)
    labels = euclidean_clusters(xyz, eps=0.1, min_cluster_size=1)
    assert labels.tolist() == [0] * 10 + [1] * 10


@pytest.mark.parametrize(
    ("X", "match"),
    [
        (np.zeros((0, 3)), r"0 sample\(s\)"),
        (np.array([[0.0, 0, np.nan]]), "NaN"),
        (np.array([[0.0, 0, np.inf]]), "infinity"),
        (np.zeros(3), "Expected 2D array"),
        (np.zeros((2, 3, 3)), "Found array with dim 3"),
        ([np.zeros((4, 3)), np.zeros((5, 3))], "sequence of clouds"),
    ],
)
@pytest.mark.parametrize(
    "est", [EuclideanClusters(), AutoEpsDBSCAN(), GroundFilter()], ids=type
)
def test_bad_input_is_a_clear_error(est, X, match):
    with pytest.raises(ValueError, match=match):
        clone(est).fit(X)


def test_auto_eps_needs_two_points():
    with pytest.raises(ValueError, match="minimum of 2 is required"):
        AutoEpsDBSCAN().fit([[0.0, 0.0, 0.0]])
    assert AutoEpsDBSCAN(eps=1.0, min_samples=1).fit([[0.0, 0, 0]]).labels_ == [0]


def test_memory_is_linear_not_neighbourhoods():
    # 60k points in a 2 m cube, eps 0.3: about 2000 neighbours per point,
    # 120 million pairs (a gigabyte as sklearn's neighbourhoods); the grid
    # DBSCAN allocates O(n_points)
    xyz = np.random.default_rng(0).random((60_000, 3)) * 2
    grid_dbscan(xyz, 0.3, 10)  # compile outside the measurement
    tracemalloc.start()
    labels, _ = grid_dbscan(xyz, 0.3, 10)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert labels.max() == 0
    assert peak < 120 * len(xyz), peak


# GroundFilter needs x, y and z: the checks that fit it on 2 features fail
# with its clear error.
# A scene has x, y and z (issue 15): the clusterers refuse the checks'
# 2-feature blobs with a clear error, as GroundFilter does.
SCENE_EXPECTED_FAILURES = dict.fromkeys(
    (
        "check_estimators_overwrite_params",
        "check_estimators_fit_returns_self",
        "check_readonly_memmap_input",
        "check_clustering",
        "check_clustering(readonly_memmap=True)",
        "check_fit_idempotent",
        "check_fit_check_is_fitted",
        "check_n_features_in",
    ),
    "a scene needs 3 columns (x, y, z); the check fits it on 2",
)
GROUND_EXPECTED_FAILURES = dict.fromkeys(
    (
        "check_estimators_overwrite_params",
        "check_estimators_fit_returns_self",
        "check_readonly_memmap_input",
        "check_fit_idempotent",
        "check_fit_check_is_fitted",
        "check_n_features_in",
    ),
    "GroundFilter needs 3 columns; the check fits it on 2",
)


@parametrize_with_checks(
    [
        AutoEpsDBSCAN(n_neighbors=5, random_state=0),
        EuclideanClusters(eps=0.5, min_cluster_size=1),
        GroundFilter(),
    ],
    expected_failed_checks=lambda est: (
        GROUND_EXPECTED_FAILURES
        if isinstance(est, GroundFilter)
        else SCENE_EXPECTED_FAILURES
    ),
)
def test_sklearn_compatible(estimator, check):
    check(estimator)


# The fine-grid path (cells at most eps / sqrt(3) wide, the dense scans'
# path) gives the same core points and labels as the obvious DBSCAN and as
# the radius-grid path, on lattices full of ties and on real sweeps.


def _path(monkeypatch, fine):
    """Force the fine grid (always) or the radius grid (never)."""
    monkeypatch.setattr(_clusters, "_FINE_MIN_POINTS", 0.0 if fine else np.inf)


def _dense(n, seed):
    """Dense blobs (many points to a fine cell) and sparse noise."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, 2, (4, 3))
    pts = centres[rng.integers(0, 4, n)] + rng.normal(0, 0.15, (n, 3))
    return np.vstack([pts, rng.uniform(-1, 3, (n // 10, 3))])


@pytest.mark.parametrize("eps", [0.05, 0.12, 0.3])
@pytest.mark.parametrize("min_samples", [1, 2, 5, 12])
def test_fine_path_equals_reference(monkeypatch, eps, min_samples):
    _path(monkeypatch, fine=True)
    xyz = _dense(700, seed=int(eps * 100) + min_samples)
    labels, core = grid_dbscan(xyz, eps, min_samples)
    ref_labels, ref_core = reference_dbscan(xyz, eps, min_samples)
    np.testing.assert_array_equal(core, ref_core)
    np.testing.assert_array_equal(labels, ref_labels)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    steps=st.integers(1, 6),
    min_samples=st.integers(1, 9),
    n_jobs=st.sampled_from([1, 2]),
)
def test_fine_path_on_a_lattice(seed, steps, min_samples, n_jobs):
    """Points on a 1/8 lattice (duplicates, pairs exactly ``eps`` apart,
    border points tied between clusters) with ``eps`` a lattice multiple."""
    rng = np.random.default_rng(seed)
    xyz = np.round(rng.normal(0, 0.4, (int(rng.integers(2, 400)), 3)) * 8) / 8
    eps = steps / 8
    with pytest.MonkeyPatch.context() as mp:
        _path(mp, fine=True)
        labels, core = grid_dbscan(xyz, eps, min_samples, n_jobs=n_jobs)
    ref_labels, ref_core = reference_dbscan(xyz, eps, min_samples)
    np.testing.assert_array_equal(core, ref_core)
    np.testing.assert_array_equal(labels, ref_labels)


@pytest.mark.parametrize("eps", [0.2, 0.5])
@pytest.mark.parametrize("min_samples", [1, 5])
def test_fine_and_radius_grids_agree_on_a_real_sweep(
    monkeypatch, real_sweeps, eps, min_samples
):
    xyz = np.ascontiguousarray(read_point_cloud(real_sweeps[3]))
    _path(monkeypatch, fine=False)
    want = grid_dbscan(xyz, eps, min_samples, n_jobs=2)
    _path(monkeypatch, fine=True)
    for n_jobs in (1, 2):
        got = grid_dbscan(xyz, eps, min_samples, n_jobs=n_jobs)
        np.testing.assert_array_equal(got[1], want[1])
        np.testing.assert_array_equal(got[0], want[0])


def test_the_fine_grid_is_taken_only_where_cells_hold_points():
    dense = _dense(3000, seed=1)
    assert _clusters.fine_grid(dense, 0.3, 1).dense
    sparse = np.random.default_rng(0).uniform(0, 100, (3000, 3))
    assert not _clusters.fine_grid(sparse, 0.3, 1).dense
    # cells that would need more than 2**20 to a side: the radius grid
    wide = np.vstack([dense, [[1e7, 0, 0]]])
    assert _clusters.fine_grid(wide, 0.3, 1) is None
    assert _clusters.fine_grid(dense, 0.0, 1) is None


def test_components_of_a_mask_on_the_shared_fine_grid(real_sweeps):
    """The structures step keeps one fine grid of all the non-ground points
    for the components of each kind of point (a mask) and for the k-nearest
    search: the same components and neighbours as a grid of their own."""
    from skpcd.neighbors._neighbors import search_packed
    from skpcd.segmentation._structures import _components

    xyz = np.ascontiguousarray(read_point_cloud(real_sweeps[5]))
    eps = 0.4
    fine = _clusters.fine_grid(xyz, eps, 2)
    rng = np.random.default_rng(1)
    for share in (0.3, 0.9):  # the shared grid is used from a quarter up
        mask = rng.random(len(xyz)) < share
        mask[: len(xyz) // 2] &= xyz[: len(xyz) // 2, 2] > xyz[:, 2].mean()
        want = _components(xyz, mask, eps, 2)
        got = _components(xyz, mask, eps, 2, fine)
        np.testing.assert_array_equal(got[0], want[0])
        assert got[1] == want[1]
    nb = search_packed(xyz, np.array([0, len(xyz)]), n_neighbors=12, n_threads=2)
    on_fine = search_packed(
        xyz, np.array([0, len(xyz)]), n_neighbors=12, n_threads=2, grid=fine.grid
    )
    np.testing.assert_array_equal(on_fine.indices, nb.indices)
    np.testing.assert_array_equal(on_fine.sqdist, nb.sqdist)
