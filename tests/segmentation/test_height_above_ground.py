"""height_above_ground: the ring search over the table of ground squares
answers as a k-d tree of the squares' representatives does, on a real
sweep, on a lattice full of ties, and for points far from any ground."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from skpcd.io import read_point_cloud
from skpcd.segmentation import GroundFilter, _structures
from skpcd.segmentation._structures import height_above_ground


def reference(xyz, ground, cell=1.0):
    """The obvious computation: a k-d tree of each square's first ground
    point, the nearest of them by plane distance."""
    ij = np.floor((ground[:, :2] - ground[:, :2].min(axis=0)) / cell).astype(int)
    key = ij[:, 0] * (ij[:, 1].max() + 1) + ij[:, 1]
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    zmean = np.bincount(inv, ground[:, 2]) / np.bincount(inv)
    dist, j = cKDTree(ground[first, :2]).query(xyz[:, :2])
    return (xyz[:, 2] - zmean[j]).astype(np.float32), dist


@pytest.fixture(scope="module")
def sweep(real_sweeps):
    xyz = read_point_cloud(real_sweeps[4])
    is_ground = GroundFilter().fit_predict(xyz).astype(bool)
    return np.ascontiguousarray(xyz[~is_ground]), xyz[is_ground]


@pytest.mark.parametrize("n_threads", [1, 2])
def test_equals_the_kd_tree_on_a_real_sweep(sweep, n_threads):
    rest, ground = sweep
    want, dist = reference(rest, ground)
    # points beyond the ring limit go to the k-d tree: both paths are used
    assert (dist > _structures._SQUARE_RINGS).any()
    assert (dist < 1).mean() > 0.5
    got = height_above_ground(rest, ground, n_threads=n_threads)
    np.testing.assert_array_equal(got, want)


def test_without_the_table_the_kd_tree_answers(sweep, monkeypatch):
    rest, ground = sweep
    monkeypatch.setattr(_structures, "_SQUARES_PER_POINT", 0)
    np.testing.assert_array_equal(
        height_above_ground(rest, ground), reference(rest, ground)[0]
    )


def test_a_far_ground_point_and_far_points():
    rng = np.random.default_rng(3)
    ground = np.column_stack([rng.uniform(0, 30, (2000, 2)), rng.normal(0, 0.1, 2000)])
    ground = np.vstack([ground, [[1e9, -1e9, 5.0]]])  # the table would be huge
    pts = np.column_stack([rng.uniform(-50, 80, (500, 2)), rng.uniform(0, 9, 500)])
    pts = np.vstack([pts, [[1e30, 0, 1], [-1e12, 3, 2]]])
    np.testing.assert_array_equal(
        height_above_ground(pts, ground), reference(pts, ground)[0]
    )
    np.testing.assert_array_equal(
        height_above_ground(pts, ground[:-1]), reference(pts, ground[:-1])[0]
    )


def test_ties_go_to_the_lower_square():
    """Representatives on a lattice, queries halfway between two: the
    nearest is the square first in (x, y) order."""
    g = np.array(
        [[x + 0.5, y + 0.5, float(x + 10 * y)] for x in range(4) for y in range(4)]
    )
    q = np.array([[1.0, 0.5, 50.0], [0.5, 1.0, 50.0], [1.0, 1.0, 50.0]])
    # (1, 0.5) is as near to the squares (0, 0) and (1, 0): the lower is (0, 0)
    np.testing.assert_array_equal(
        height_above_ground(q, g), np.float32([50.0, 50.0, 50.0])
    )
    far = np.array([[20.0, 20.0, 7.0]])
    assert height_above_ground(far, g)[0] == np.float32(7.0 - g[-1, 2])
