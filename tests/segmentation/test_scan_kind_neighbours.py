"""describe_scan's neighbourhoods from a tree of the points near the
queries: the same spacing and vertical fraction as one tree of all the
points, on real sweeps."""

import numpy as np
from scipy.spatial import cKDTree

from skpcd.io import read_point_cloud
from skpcd.preprocessing import point_spacing
from skpcd.preprocessing._spacing import nearest_neighbours
from skpcd.segmentation._scan_kind import _spacing_vertical, _vertical_fraction


def _sweep(path):
    return np.ascontiguousarray(read_point_cloud(path)[:, :3])


def test_nearest_neighbours_equal_a_whole_tree(real_sweeps):
    xyz = _sweep(real_sweeps[1])
    rng = np.random.default_rng(0)
    queries = xyz[rng.choice(len(xyz), 1500, replace=False)]
    # at most 4 points per query searched whole; this cloud has ~75
    dist, rows = nearest_neighbours(xyz, queries, 13, local_ratio=4)
    expected_dist, expected_rows = cKDTree(xyz).query(queries, k=13)
    np.testing.assert_array_equal(dist, expected_dist)
    # the same points where no two are at the same distance
    tied = (expected_dist[:, 1:] == expected_dist[:, :-1]).any(axis=1)
    np.testing.assert_array_equal(rows[~tied], expected_rows[~tied])


def test_spacing_and_vertical_equal_a_whole_tree(real_sweeps):
    for path in real_sweeps[:4]:
        xyz = _sweep(path)
        sample = xyz[np.random.default_rng(1).choice(len(xyz), 3000, replace=False)]
        tree = cKDTree(xyz)
        expected_vertical = _vertical_fraction(xyz, tree.query(sample, k=12)[1])
        expected_spacing = point_spacing(xyz, max_points=20_000, random_state=0)
        spacing, vertical = _spacing_vertical(xyz, sample, local_ratio=2)
        assert spacing == expected_spacing
        assert vertical == expected_vertical


def test_point_spacing_of_a_large_cloud_equals_a_whole_tree(real_sweeps):
    xyz = _sweep(real_sweeps[2])
    rng = np.random.default_rng(2)
    queries = rng.choice(len(xyz), 2000, replace=False)
    dist, _ = cKDTree(xyz).query(xyz[queries], k=8)
    dist = np.where(dist > 0, dist, np.inf).min(axis=1)
    expected = float(np.quantile(dist[np.isfinite(dist)], 0.5))
    assert point_spacing(xyz, max_points=2000, random_state=2) == expected
