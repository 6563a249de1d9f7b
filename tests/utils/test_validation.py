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
