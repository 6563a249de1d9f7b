"""AutoEpsDBSCAN: the distance curve, its fit and knee, the estimate, the plot."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist
from sklearn.base import clone
from sklearn.cluster import DBSCAN
from sklearn.metrics import adjusted_rand_score

from skpcd.segmentation import AutoEpsDBSCAN, estimate_eps, plot_eps_curve
from skpcd.segmentation._dbscan import fit_knee


def _plane(n_side, spacing, z=0.0):
    g = np.stack(np.meshgrid(np.arange(n_side), np.arange(n_side), [0.0]), -1)
    return spacing * g.reshape(-1, 3).astype(float) + [0, 0, z]


def test_curve_is_the_mean_kth_neighbour_distance():
    xyz = np.random.default_rng(0).random((300, 3))
    db = AutoEpsDBSCAN(n_neighbors=12, max_samples=None).fit(xyz)
    d = np.sort(cdist(xyz, xyz), axis=1)[:, 1:13]
    np.testing.assert_array_equal(db.curve_k_, np.arange(1, 13))
    np.testing.assert_allclose(db.curve_distances_, d.mean(axis=0), rtol=1e-12)
    assert db.knee_distance_ == pytest.approx(db.curve_(db.knee_))
    assert db.eps_ == pytest.approx(db.eps_scale * db.knee_distance_)
    assert 1 <= db.knee_ <= 12


def test_knee_of_known_curves():
    k = np.arange(1, 31)
    # a concave curve (neighbours spread over a surface: sqrt(k)); the knee
    # of sqrt on [1, K] is where its slope equals the chord's
    expected = ((np.sqrt(30) + 1) / 2) ** 2
    _, knee, eps = fit_knee(k, np.sqrt(k), degree=8)
    assert knee == pytest.approx(expected, abs=0.3)
    assert eps == pytest.approx(np.sqrt(knee), rel=0.01)
    # the default cubic smooths the curve: the knee moves by about 1
    _, knee, eps = fit_knee(k, np.sqrt(k), degree=3)
    assert knee == pytest.approx(expected, abs=1.5)
    # a straight line has no knee worth the name; a flat curve gives k=1
    _, knee, eps = fit_knee(k, np.full(30, 0.5), degree=3)
    assert (knee, eps) == (1.0, pytest.approx(0.5))


def test_eps_scales_with_spacing_and_is_translation_invariant():
    a = estimate_eps(_plane(60, 0.1))
    b = estimate_eps(_plane(60, 0.3))
    # the knee distance: a few spacings; the default radius 2.5 times that
    knee = estimate_eps(_plane(60, 0.1), eps_scale=1.0)
    assert 0.1 < knee < 0.5
    assert a == pytest.approx(2.5 * knee, rel=1e-12)
    assert b == pytest.approx(3 * a, rel=1e-6)
    moved = estimate_eps(_plane(60, 0.1) + np.array([5e5, 4e6, 120.0]))
    assert moved == pytest.approx(a, rel=1e-6)


def test_sampled_curve_is_reproducible_and_close():
    xyz = np.random.default_rng(1).random((20_000, 3)) * [20, 20, 1]
    full = AutoEpsDBSCAN(max_samples=None).fit(xyz)
    s1 = AutoEpsDBSCAN(max_samples=3000, random_state=0).fit(xyz)
    s2 = AutoEpsDBSCAN(max_samples=3000, random_state=0).fit(xyz)
    assert s1.eps_ == s2.eps_
    np.testing.assert_array_equal(s1.labels_, s2.labels_)
    assert s1.eps_ == pytest.approx(full.eps_, rel=0.03)


def test_separates_planes_and_isolates_noise():
    rng = np.random.default_rng(0)
    plane = np.column_stack([rng.random((3000, 2)) * 5, np.zeros(3000)])
    noise = rng.uniform([-20, -20, 5], [30, 30, 30], (40, 3))
    xyz = np.vstack(
        [plane, plane + np.array([8, 0, 0]), plane + np.array([0, 0, 4]), noise]
    )
    db = AutoEpsDBSCAN(random_state=0).fit(xyz)
    assert db.n_clusters_ == 3
    assert (db.labels_[-40:] == -1).all()
    for i in range(3):
        assert len(np.unique(db.labels_[i * 3000 : (i + 1) * 3000])) == 1


def test_given_eps_is_plain_dbscan():
    xyz = np.random.default_rng(2).random((800, 3)) * 4
    db = AutoEpsDBSCAN(eps=0.3, min_samples=4).fit(xyz)
    sk = DBSCAN(eps=0.3, min_samples=4).fit(xyz)
    np.testing.assert_array_equal(db.core_sample_indices_, sk.core_sample_indices_)
    np.testing.assert_array_equal(db.labels_ < 0, sk.labels_ < 0)
    assert db.eps_ == 0.3 and db.curve_ is None and len(db.curve_k_) == 0


def test_tiny_and_degenerate_clouds():
    # fewer points than n_neighbors: the curve is shorter
    db = AutoEpsDBSCAN(min_samples=2).fit(_plane(3, 1.0))
    assert len(db.curve_k_) == 8
    assert db.n_clusters_ == 1
    db = AutoEpsDBSCAN(min_samples=1, eps_scale=1.0).fit([[0.0, 0, 0], [1.0, 0, 0]])
    assert db.eps_ == pytest.approx(1.0) and db.labels_.tolist() == [0, 0]
    with pytest.raises(ValueError, match="duplicated points"):
        AutoEpsDBSCAN().fit(np.zeros((50, 3)))


def test_clone_and_params():
    db = AutoEpsDBSCAN(min_samples=7, n_neighbors=20)
    again = clone(db)
    assert again.get_params() == db.get_params()
    assert not hasattr(again, "eps_")
    with pytest.raises(ValueError, match="n_neighbors"):
        AutoEpsDBSCAN(n_neighbors=1).fit(_plane(5, 1.0))


def test_plot_eps_curve():
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    db = AutoEpsDBSCAN().fit(_plane(30, 0.2))
    ax = plot_eps_curve(db)
    assert ax.get_ylabel() == "distance"
    assert len(ax.lines) == 4  # curve, fit, knee, radius
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert f"{db.knee_distance_:.3f}" in texts[2]
    assert f"eps = 2.5 x knee = {db.eps_:.3f}" == texts[3]
    plt.close("all")
    with pytest.raises(ValueError, match="no curve"):
        plot_eps_curve(AutoEpsDBSCAN(eps=1.0).fit(_plane(5, 1.0)))


def test_eps_scale_multiplies_the_knee_distance():
    xyz = np.random.default_rng(3).random((2000, 3)) * [10, 10, 0.5]
    one = AutoEpsDBSCAN(eps_scale=1.0).fit(xyz)
    wide = AutoEpsDBSCAN(eps_scale=2.5).fit(xyz)
    assert one.eps_ == pytest.approx(one.knee_distance_)
    assert one.knee_distance_ == pytest.approx(one.curve_(one.knee_))
    assert wide.knee_distance_ == one.knee_distance_
    assert wide.eps_ == pytest.approx(2.5 * one.eps_, rel=1e-12)
    assert estimate_eps(xyz) == pytest.approx(AutoEpsDBSCAN().fit(xyz).eps_)
    assert estimate_eps(xyz, eps_scale=1.0) == pytest.approx(one.eps_)
    # a given eps ignores eps_scale
    fixed = AutoEpsDBSCAN(eps=0.4, eps_scale=9.0).fit(xyz)
    assert fixed.eps_ == 0.4 and fixed.knee_distance_ is None
    with pytest.raises(ValueError, match="eps_scale"):
        AutoEpsDBSCAN(eps_scale=0.0).fit(xyz)


# --- quality on real objects -------------------------------------------------
# The default eps_scale was chosen by cross-validation on scenes of 2/3 of the
# DALES objects (benchmarks/bench_segmentation_quality.py); these scenes are
# made of objects of the other third, split the same way (by class, seed 0).


def _held_out(labels, fraction=1 / 3, seed=0):
    rng = np.random.default_rng(seed)
    held = []
    for c in np.unique(labels):
        idx = rng.permutation(np.flatnonzero(labels == c))
        held.extend(idx[: round(fraction * len(idx))].tolist())
    return np.sort(held)


def _segment(points, ground, **params):
    from skpcd.segmentation._clusters import filter_cluster_sizes

    labels = np.full(len(points), -1, dtype=np.int64)
    db = AutoEpsDBSCAN(random_state=0, **params).fit(points[~ground])
    labels[~ground] = filter_cluster_sizes(db.labels_, 30)
    return labels, db


def _whole(points, truth, labels, n_objects):
    from skpcd.datasets._object_scene import terrain_height

    height = points[:, 2] - terrain_height(points[:, 0], points[:, 1], 1.0)
    scored = (truth >= 0) & (height > 0.5)
    whole = []
    for i in range(n_objects):
        mine = labels[scored & (truth == i)]
        values, counts = np.unique(mine, return_counts=True)
        best = values[counts.argmax()]
        whole.append(
            best >= 0
            and counts.max() >= 0.9 * len(mine)
            and (truth[labels == best] == i).mean() >= 0.9
        )
    return adjusted_rand_score(truth[scored], labels[scored]), np.mean(whole)


@pytest.fixture(scope="module")
def held_out_scene(dales):
    from skpcd.segmentation import GROUND_PRESETS, GroundFilter, make_scene

    clouds, labels, _ = dales
    labels = np.asarray(labels)
    held = _held_out(labels)
    rng = np.random.default_rng(7)
    pick = np.concatenate(
        [
            rng.choice(held[labels[held] == c], 6, replace=False)
            for c in np.unique(labels)
        ]
    )
    points, truth = make_scene(
        [clouds[i] for i in pick], gap=3.0, resample=0.5, ground_density=10.0,
        random_state=7,
    )  # fmt: skip
    ground = GroundFilter(**GROUND_PRESETS["aerial"]).fit_predict(points)
    return points, truth, ground, len(pick)


def test_default_radius_keeps_real_objects_whole(held_out_scene):
    points, truth, ground, n_objects = held_out_scene
    labels, db = _segment(points, ground)
    ari, whole = _whole(points, truth, labels, n_objects)
    # the previous rule (the knee distance itself) breaks the objects up
    labels, db1 = _segment(points, ground, eps_scale=1.0)
    ari1, whole1 = _whole(points, truth, labels, n_objects)
    assert db.eps_ == pytest.approx(db.eps_scale * db1.eps_)
    # measured (30 held-out objects, aerial-like): eps 1.84 m, ARI 0.998,
    # 25 of 30 objects whole; with eps_scale=1 (0.73 m): ARI 0.814, 16 whole
    assert ari >= 0.95
    assert whole >= 0.7
    assert ari1 < 0.95
    assert whole1 < 0.7


def _tree_curve(xyz, k, rows):
    """The k-distance curve from a k-d tree of all points (the obvious way)."""
    from scipy.spatial import cKDTree

    from skpcd.segmentation._dbscan import kdist_mean

    d, _ = cKDTree(xyz).query(xyz[rows], k=k + 1)
    return kdist_mean(d[:, 1:])


@pytest.mark.parametrize("max_samples", [None, 500])
def test_kdist_curve_equals_a_kd_tree_bit_for_bit(real_sweeps, max_samples):
    """The grid's neighbours with their distances computed as cKDTree
    computes them: the same curve (so the same eps as the tiled estimate's
    trees), on a real sweep and on a lattice of duplicates and ties."""
    from skpcd.io import read_point_cloud
    from skpcd.segmentation._dbscan import _kdist_curve, sample_queries

    rng = np.random.default_rng(0)
    lattice = np.round(rng.normal(0, 1, (3000, 3)) * 4) / 4
    for xyz in (np.ascontiguousarray(read_point_cloud(real_sweeps[0])), lattice):
        rows = sample_queries(len(xyz), max_samples, 0)
        k, curve = _kdist_curve(xyz, 30, max_samples, 0, 2)
        np.testing.assert_array_equal(k, np.arange(1, 31))
        np.testing.assert_array_equal(curve, _tree_curve(xyz, 30, rows))
