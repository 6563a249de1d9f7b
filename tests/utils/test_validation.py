import numpy as np
import pytest

from skpcd.utils import check_point_clouds


def test_accepts_list_tuple_object_array_and_3d():
    a, b = np.zeros((4, 3)), np.ones((2, 5))
    obj = np.empty(2, dtype=object)
    obj[0], obj[1] = a, b
    for X in ([a, b], (a, b), obj):
        out = check_point_clouds(X)
        assert [c.shape for c in out] == [(4, 3), (2, 5)]
    out = check_point_clouds(np.zeros((3, 4, 3)))
    assert len(out) == 3 and out[0].shape == (4, 3)


def test_lone_2d_array_says_wrap_it():
    with pytest.raises(ValueError, match=r"Wrap a single cloud in a list: \[cloud\]"):
        check_point_clouds(np.zeros((10, 3)))


@pytest.mark.parametrize("X", ["clouds.xyz", 3, None])
def test_not_a_sequence(X):
    with pytest.raises(TypeError, match="must be a sequence"):
        check_point_clouds(X)


def test_empty_collection():
    with pytest.raises(ValueError, match="X is empty"):
        check_point_clouds([])


def test_names_the_bad_cloud():
    good = np.zeros((4, 3))
    with pytest.raises(ValueError, match=r"X\[1\] has 2 column"):
        check_point_clouds([good, np.zeros((4, 2))])
    bad = good.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"X\[2\].*NaN"):
        check_point_clouds([good, good, bad])
    with pytest.raises(ValueError, match=r"X\[0\] must be a 2-D array"):
        check_point_clouds([np.zeros(3)])


def test_min_points_and_empty_clouds():
    with pytest.raises(ValueError, match=r"X\[0\] has 0 point\(s\); at least 1"):
        check_point_clouds([np.zeros((0, 3))])
    assert check_point_clouds([np.zeros((0, 3))], min_points=0)[0].shape == (0, 3)
    with pytest.raises(ValueError, match="at least 5 are required"):
        check_point_clouds([np.zeros((4, 3))], min_points=5)


def test_n_columns():
    assert check_point_clouds([np.zeros((2, 6))], n_columns=6)[0].shape == (2, 6)
    with pytest.raises(ValueError, match=r"6 column.*3 are required"):
        check_point_clouds([np.zeros((2, 6))], n_columns=(3, 3))
    with pytest.raises(ValueError, match="6 are required"):
        check_point_clouds([np.zeros((2, 3))], n_columns=6)


def test_dtype_kept_or_converted_and_no_copy_by_default():
    f32 = np.zeros((3, 3), dtype=np.float32)
    f64 = np.zeros((3, 3))
    ints = np.zeros((3, 3), dtype=int)
    out = check_point_clouds([f32, f64, ints])
    assert [c.dtype for c in out] == [np.float32, np.float64, np.float64]
    assert out[1] is f64
    assert check_point_clouds([f64], copy=True)[0] is not f64


def test_read_only_input_accepted():
    a = np.arange(12, dtype=float).reshape(4, 3)
    a.flags.writeable = False
    assert check_point_clouds([a])[0] is a


def test_nonfinite_allowed_on_request():
    a = np.full((2, 3), np.nan)
    assert np.isnan(check_point_clouds([a], ensure_all_finite=False)[0]).all()


def test_strings_rejected():
    with pytest.raises(ValueError, match=r"X\[0\]"):
        check_point_clouds([np.array([["a", "b", "c"]])])


def test_unit_normals_checked_nan_rows_undefined():
    from skpcd.utils._validation import NORMAL_ATOL, check_unit_normals

    n = np.tile([0.0, 0.6, 0.8], (6, 1))
    n[1] = np.nan
    n[2, 0] = np.nan  # one NaN component: undefined too
    n[3] *= 1 + 0.9 * NORMAL_ATOL  # within the tolerance
    assert check_unit_normals(n).tolist() == [0, 1, 1, 0, 0, 0]
    n[4] *= 1 + 1.1 * NORMAL_ATOL
    n[5] = [np.inf, 0, 0]
    with pytest.raises(ValueError, match=r"^normals: 2 of 6 normals are not unit"):
        check_unit_normals(n)
    with pytest.raises(ValueError, match=r"row 4, norm 1\.0011.*NaN where"):
        check_unit_normals(n)
    with pytest.raises(ValueError, match=r"row 0, norm 0\b"):
        check_unit_normals(np.zeros((1, 3)))


def test_given_normals_by_cloud():
    from skpcd.utils._validation import check_given_normals

    up = np.c_[np.zeros((4, 3)), np.tile([0.0, 0.0, 1.0], (4, 1))]
    clouds = [np.zeros((4, 3)), np.zeros((4, 5)), up, np.c_[up, np.ones(4)]]
    assert check_given_normals(clouds, "auto") == [False, False, True, True]
    assert check_given_normals(clouds, "estimate") == [False] * 4
    assert check_given_normals(clouds[2:], "columns") == [True, True]
    with pytest.raises(ValueError, match=r"X\[0\] has 5 columns; normals='columns'"):
        check_given_normals(clouds[1:], "columns")
    bad = up.copy()
    bad[2, 5] = 3.0
    with pytest.raises(ValueError, match=r"X\[1\]: 1 of 4 normals \(columns 3-5\)"):
        check_given_normals([up, bad], "auto")
    assert check_given_normals([up, bad], "estimate") == [False, False]
    with pytest.raises(ValueError, match=r"X\[0\] has normals .* k and r only set"):
        check_given_normals([up], "auto", estimation=["k", "r"])
    assert check_given_normals([clouds[0]], "auto", estimation=["k"]) == [False]


def test_local_frame_keeps_coordinates_within_1024_and_moves_the_others():
    from skpcd.utils._validation import LOCAL_LIMIT, local_frame

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
    from skpcd.utils._validation import local_frame

    cloud = np.round(np.random.default_rng(1).uniform(0, 50, (30, 3)) * 256) / 256
    ptr = np.array([0, 30])
    a, _ = local_frame(cloud + 2e6, ptr)
    b, _ = local_frame(cloud + 2e6 + shift, ptr)
    np.testing.assert_array_equal(a, b)


def test_local_frame_refuses_extents_float32_cannot_square():
    from skpcd.utils._validation import local_frame, max_extent

    assert 1e19 < max_extent(np.float32) < 1.1e19
    ok = np.array([[0.0, 0, 0], [1e19, 0, 0]])
    local_frame(ok, np.array([0, 2]))
    bad = np.vstack([ok, [[0.0, 0, 0], [0, 2e19, 0]]])
    with pytest.raises(ValueError, match=r"X\[1\] spans 2e\+19 along y .*float32"):
        local_frame(bad, np.array([0, 2, 4]))
    # float64 holds it; an empty cloud has no extent
    local_frame(bad, np.array([0, 2, 2, 4]), dtype=np.float64)


@pytest.mark.parametrize(
    "bad", [np.nan, np.inf, -np.inf, 1e308], ids=["nan", "inf", "-inf", "huge"]
)
def test_the_fast_path_for_float_arrays_answers_as_check_array(bad):
    # a finite float array is taken as it is; one with a non-finite value
    # (or whose sum overflows, 1e308 twice: still finite, so accepted)
    # goes through check_array and its message
    a = np.zeros((5, 3))
    a[2, 1] = bad
    a[3, 1] = bad
    if np.isfinite(bad):
        assert check_point_clouds([a])[0] is a
        return
    with pytest.raises(ValueError, match=r"X\[1\].*(NaN|infinity)"):
        check_point_clouds([np.zeros((2, 3)), a])
    assert check_point_clouds([a], ensure_all_finite=False)[0] is a


def test_point_bounds_equals_min_and_max():
    from skpcd.utils._validation import point_bounds

    a = np.random.default_rng(0).normal(size=(1000, 4)) * 1e6
    lo, hi = point_bounds(a)
    np.testing.assert_array_equal(lo, a.min(axis=0))
    np.testing.assert_array_equal(hi, a.max(axis=0))
    lo, hi = point_bounds(a[:, :2])
    np.testing.assert_array_equal(hi, a[:, :2].max(axis=0))
