import numpy as np
import pytest
from sklearn.utils.estimator_checks import parametrize_with_checks

from skpcd.preprocessing import RadiusOutlierFilter, StatisticalOutlierFilter


def _plane_and_far_point(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    plane = np.column_stack([rng.uniform(0, 20, (n, 2)), rng.normal(0, 0.01, n)])
    return np.vstack([plane, [[1000.0, 20.0, 5.0]]])


@pytest.mark.parametrize(
    "filt", [StatisticalOutlierFilter(), RadiusOutlierFilter(radius=1.0)]
)
def test_far_point_found_and_dense_plane_kept(filt):
    X = _plane_and_far_point()
    labels = filt.fit_predict(X)
    assert labels.dtype.kind == "i" and set(np.unique(labels)) <= {-1, 1}
    assert labels[-1] == -1
    assert np.array_equal(labels == 1, filt.inlier_mask_)
    # a uniform dense plane: (almost) every point kept
    assert filt.inlier_mask_[:-1].mean() > 0.97


def _statistical_reference(xyz, k, ratio):
    # PCL's StatisticalOutlierRemoval: mean distance to the k nearest
    # neighbours, the point itself excluded; mean + ratio * sample std
    d = np.sqrt(((xyz[:, None] - xyz[None]) ** 2).sum(axis=2))
    d = np.sort(d, axis=1)[:, 1 : k + 1]
    mean = d.mean(axis=1)
    return mean <= mean.mean() + ratio * mean.std(ddof=1), mean


def _radius_reference(xyz, radius, min_neighbors):
    d = np.sqrt(((xyz[:, None] - xyz[None]) ** 2).sum(axis=2))
    return (d <= radius).sum(axis=1) - 1 >= min_neighbors


@pytest.mark.parametrize("seed", range(3))
def test_filters_match_brute_force_reference(seed):
    rng = np.random.default_rng(seed)
    xyz = np.vstack([rng.normal(0, 1, (150, 3)), rng.uniform(-8, 8, (10, 3))])
    for k, ratio in [(8, 2.0), (3, 1.0), (20, 0.5)]:
        est = StatisticalOutlierFilter(n_neighbors=k, std_ratio=ratio).fit(xyz)
        mask, mean = _statistical_reference(xyz, k, ratio)
        np.testing.assert_allclose(est.mean_distances_, mean, rtol=1e-6)
        # float32 distances: equal away from the threshold
        clear = np.abs(mean - est.threshold_) > 1e-5
        assert np.array_equal(est.inlier_mask_[clear], mask[clear])
    for radius, m in [(0.5, 1), (1.0, 2), (2.0, 10)]:
        est = RadiusOutlierFilter(radius=radius, min_neighbors=m).fit(xyz)
        assert np.array_equal(est.inlier_mask_, _radius_reference(xyz, radius, m))


def test_extra_columns_ignored_and_two_columns_refused():
    X = _plane_and_far_point(500)
    extra = np.column_stack([X, np.arange(len(X))])
    for filt in (StatisticalOutlierFilter(), RadiusOutlierFilter()):
        assert np.array_equal(filt.fit_predict(extra), filt.fit_predict(X))
        with pytest.raises(ValueError, match="needs at least 3"):
            filt.fit(X[:, :2])
        with pytest.raises(ValueError, match="sequence of clouds"):
            filt.fit([X, X])


def test_tiny_clouds():
    one = np.zeros((1, 3))
    assert StatisticalOutlierFilter().fit_predict(one).tolist() == [1]
    assert RadiusOutlierFilter(min_neighbors=1).fit_predict(one).tolist() == [-1]
    three = np.array([[0.0, 0, 0], [1, 0, 0], [50, 0, 0]])
    # fewer points than n_neighbors: each point's neighbours are all others
    est = StatisticalOutlierFilter(n_neighbors=8, std_ratio=0.5).fit(three)
    np.testing.assert_allclose(est.mean_distances_, [25.5, 25, 49.5], rtol=1e-6)
    assert est.inlier_mask_.tolist() == [True, True, False]


# sklearn's checks that fit on 2-column data cannot run on a cloud, which
# needs x, y and z (as for GroundFilter in tests/segmentation/test_clusters.py)
OUTLIER_EXPECTED_FAILURES = dict.fromkeys(
    (
        "check_estimators_overwrite_params",
        "check_estimators_fit_returns_self",
        "check_readonly_memmap_input",
        "check_outliers_fit_predict",
        "check_fit_idempotent",
        "check_fit_check_is_fitted",
        "check_n_features_in",
    ),
    "a cloud needs 3 columns (x, y, z); the check fits it on 2",
)


@parametrize_with_checks(
    [RadiusOutlierFilter(), StatisticalOutlierFilter()],
    expected_failed_checks=lambda est: OUTLIER_EXPECTED_FAILURES,
)
def test_sklearn_compatible(estimator, check):
    check(estimator)
