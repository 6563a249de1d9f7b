import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.preprocessing import GridSampler, grid_sample


def _brute(points, h):
    lo = points.min(axis=0)
    cell = np.floor((points - lo) / h).astype(int)
    best = {}
    for i, (c, p) in enumerate(zip(map(tuple, cell), points)):
        d = ((p - (lo + (np.array(c) + 0.5) * h)) ** 2).sum()
        if c not in best or d < best[c][0]:
            best[c] = (d, i)
    return np.sort([i for _, i in best.values()])


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), h=st.floats(0.05, 2.0))
def test_keeps_the_point_nearest_each_cell_centre(seed, h):
    pts = np.random.default_rng(seed).uniform(0, 3, size=(400, 3))
    sampled, idx = grid_sample(pts, h, return_index=True)
    np.testing.assert_array_equal(idx, _brute(pts, h))
    np.testing.assert_array_equal(sampled, pts[idx])


def test_translation_invariant_columns_kept_and_ties_keep_lower_index():
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(0, 5, (1000, 3)), rng.uniform(size=1000)]
    _, a = grid_sample(pts, 0.5, return_index=True)
    _, b = grid_sample(pts + np.array([1e3, -7, 2, 0]), 0.5, return_index=True)
    np.testing.assert_array_equal(a, b)
    assert grid_sample(pts, 0.5).shape[1] == 4
    dup = np.zeros((5, 3))
    np.testing.assert_array_equal(grid_sample(dup, 1.0, return_index=True)[1], [0])


def test_auto_voxel_size_from_spacing():
    g = np.stack(np.meshgrid(*[np.arange(20) * 0.1] * 2, [0.0]), -1).reshape(-1, 3)
    # cells one spacing wide: a regular grid keeps about all its points
    assert len(grid_sample(g)) >= 0.9 * len(g)
    assert len(grid_sample(np.zeros((3, 3)))) == 1


def test_bad_input_and_transformer():
    with pytest.raises(ValueError, match="voxel_size"):
        grid_sample(np.zeros((3, 3)), 0)
    with pytest.raises(ValueError, match="NaN"):
        grid_sample(np.full((3, 3), np.nan), 1.0)
    with pytest.raises(ValueError, match="shape"):
        grid_sample(np.zeros(3), 1.0)
    clouds = [np.random.default_rng(1).uniform(0, 2, (300, 3)), np.zeros((0, 3))]
    out = GridSampler(voxel_size=0.5).fit_transform(clouds)
    assert 0 < len(out[0]) <= 64 and len(out[1]) == 0


def test_far_from_the_origin_the_same_points_ties_included():
    # a grid of points: many exact ties to the cell centres
    g = np.stack(np.meshgrid(*[np.arange(8) * 0.25] * 3), -1).reshape(-1, 3)
    for shift in ([5e5, 4.2e6, 0.0], [1e7, -1e7, 1e7]):
        moved = g + np.array(shift)
        np.testing.assert_array_equal(
            grid_sample(moved, 0.5, return_index=True)[1],
            grid_sample(g, 0.5, return_index=True)[1],
        )


def test_voxel_size_too_small_for_the_extent_is_a_clear_error():
    pts = np.array([[0.0, 0, 0], [1e7, 0, 0]])
    with pytest.raises(ValueError, match=r"cuts the cloud's extent along x .*2\*\*62"):
        grid_sample(pts, 1e-12)
    assert len(grid_sample(pts, 1e-9)) == 2
    with pytest.raises(ValueError, match="cells"):
        GridSampler().fit_transform([np.random.default_rng(0).random((9, 3)) * 1e200])


def test_the_same_points_for_every_thread_count_and_as_the_lexsort():
    from skpcd.preprocessing._sampling import _grid_sample_lexsort

    rng = np.random.default_rng(3)
    # centimetre coordinates: many points tie at the same distance to a centre
    pts = np.round(rng.uniform(0, 30, (300_000, 3)), 2) + np.array([5e5, 4.2e6, 10.0])
    h = 0.25
    _, one = grid_sample(pts, h, return_index=True)
    _, two = grid_sample(pts, h, return_index=True, n_jobs=2)
    np.testing.assert_array_equal(one, two)
    np.testing.assert_array_equal(one, _grid_sample_lexsort(pts - pts.min(axis=0), h))
    clouds = [rng.uniform(0, 3, (n, 3)) for n in (0, 1, 50, 2000, 150_000)]
    a = GridSampler(voxel_size=0.2).fit_transform(clouds)
    b = GridSampler(voxel_size=0.2, n_jobs=2).fit_transform(clouds)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
