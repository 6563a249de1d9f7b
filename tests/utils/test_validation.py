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
