"""The geometry of packed clouds: bounds and local frames."""

import numpy as np
import pytest


def test_local_frame_keeps_coordinates_within_1024_and_moves_the_others():
    from skpcd.utils._geometry import LOCAL_LIMIT, local_frame

    rng = np.random.default_rng(0)
    near = rng.uniform(-500, 900, size=(50, 3))
    far = near + np.array([5e5, 0.0, -4.2e6])  # x and z far, y as given
    xyz = np.vstack([near, far])
    ptr = np.array([0, 50, 100])
    local, origins = local_frame(xyz, ptr)
    assert local.dtype == np.float32 and local.flags.c_contiguous
    # PCL's coordinates untouched: the same float32 values PCL reads
    np.testing.assert_array_equal(local[:50], near.astype(np.float32))
    np.testing.assert_array_equal(origins[0], 0.0)
    np.testing.assert_array_equal(origins[1], [far[:, 0].min(), 0.0, far[:, 2].min()])
    np.testing.assert_array_equal(local[50:], (far - origins[1]).astype(np.float32))
    # one rounding, in float64 first: the relative values keep float32's precision
    assert np.abs(local[50:] - (far - origins[1])).max() < 1e-4
    # an axis reaching the limit is moved
    edge = np.array([[1.0, 1.0, 1.0], [LOCAL_LIMIT, 2.0, 2.0]])
    _, o = local_frame(edge, np.array([0, 2]))
    np.testing.assert_array_equal(o, [[1.0, 0.0, 0.0]])
    _, o = local_frame(edge - np.array([0.5, 0, 0]), np.array([0, 2]))
    np.testing.assert_array_equal(o, [[0.0, 0.0, 0.0]])
    # keep_within=0: every axis relative to the minimum; float64 is a copy
    xyz_before = xyz.copy()
    local64, o = local_frame(xyz, ptr, dtype=np.float64, keep_within=0)
    np.testing.assert_array_equal(o[0], near.min(axis=0))
    np.testing.assert_array_equal(local64[:50], near - near.min(axis=0))
    np.testing.assert_array_equal(xyz, xyz_before)


@pytest.mark.parametrize("shift", [1024.0, 5e5, -4.2e6, 1e7])
def test_local_frame_of_exact_translates_is_the_same(shift):
    from skpcd.utils._geometry import local_frame

    cloud = np.round(np.random.default_rng(1).uniform(0, 50, (30, 3)) * 256) / 256
    ptr = np.array([0, 30])
    a, _ = local_frame(cloud + 2e6, ptr)
    b, _ = local_frame(cloud + 2e6 + shift, ptr)
    np.testing.assert_array_equal(a, b)


def test_local_frame_refuses_extents_float32_cannot_square():
    from skpcd.utils._geometry import local_frame, max_extent

    assert 1e19 < max_extent(np.float32) < 1.1e19
    ok = np.array([[0.0, 0, 0], [1e19, 0, 0]])
    local_frame(ok, np.array([0, 2]))
    bad = np.vstack([ok, [[0.0, 0, 0], [0, 2e19, 0]]])
    with pytest.raises(ValueError, match=r"X\[1\] spans 2e\+19 along y .*float32"):
        local_frame(bad, np.array([0, 2, 4]))
    # float64 holds it; an empty cloud has no extent
    local_frame(bad, np.array([0, 2, 2, 4]), dtype=np.float64)


def test_point_bounds_equals_min_and_max():
    from skpcd.utils._geometry import point_bounds

    a = np.random.default_rng(0).normal(size=(1000, 4)) * 1e6
    lo, hi = point_bounds(a)
    np.testing.assert_array_equal(lo, a.min(axis=0))
    np.testing.assert_array_equal(hi, a.max(axis=0))
    lo, hi = point_bounds(a[:, :2])
    np.testing.assert_array_equal(hi, a[:, :2].max(axis=0))
