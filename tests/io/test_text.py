import numpy as np
import pytest

from skpcd.exceptions import PointCloudFileError
from skpcd.io import read_point_cloud, write_point_cloud


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_whitespace_no_header(tmp_path):
    path = _write(tmp_path, "a.xyz", "1 2 3\n4\t5  6\n\n7 8 9\n")
    np.testing.assert_array_equal(
        read_point_cloud(path), [[1, 2, 3], [4, 5, 6], [7, 8, 9]]
    )


def test_comma_header_extra_columns(tmp_path):
    path = _write(tmp_path, "a.csv", "X,Y,Z,Intensity\n1,2,3,10\n4,5,6,20\n")
    points, extras = read_point_cloud(path, fields=["intensity"])
    np.testing.assert_array_equal(points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(extras["intensity"], [10, 20])


def test_unnamed_extra_columns_and_comments(tmp_path):
    path = _write(
        tmp_path, "a.txt", "# scanner export\n1 2 3 0.5 7\n// note\n4 5 6 0.25 8\n"
    )
    points, extras = read_point_cloud(path, fields="all")
    assert points.shape == (2, 3)
    assert list(extras) == ["field_3", "field_4"]
    np.testing.assert_array_equal(extras["field_4"], [7, 8])


def test_pts_point_count_checked(tmp_path):
    good = _write(tmp_path, "good.pts", "2\n1 2 3 10 255 0 0\n4 5 6 11 0 255 0\n")
    assert read_point_cloud(good).shape == (2, 3)
    bad = _write(tmp_path, "bad.pts", "3\n1 2 3\n4 5 6\n")
    with pytest.raises(
        PointCloudFileError, match="declares 3 points but the file holds 2"
    ):
        read_point_cloud(bad)


def test_wrong_column_count(tmp_path):
    path = _write(tmp_path, "a.xyz", "1 2 3\n4 5\n")
    with pytest.raises(PointCloudFileError) as info:
        read_point_cloud(path)
    assert str(path) in str(info.value) and "columns" in str(info.value)
    two = _write(tmp_path, "b.xyz", "1 2\n3 4\n")
    with pytest.raises(PointCloudFileError, match="at least 3 columns"):
        read_point_cloud(two)


def test_header_with_wrong_number_of_names(tmp_path):
    path = _write(tmp_path, "a.csv", "x,y,z,i,j\n1,2,3,4\n")
    with pytest.raises(
        PointCloudFileError, match="names 5 columns but the lines have 4"
    ):
        read_point_cloud(path)


def test_header_only_and_comments_only(tmp_path):
    with pytest.raises(PointCloudFileError, match="header but no point lines"):
        read_point_cloud(_write(tmp_path, "h.csv", "x,y,z\n"))
    with pytest.raises(PointCloudFileError, match="empty"):
        read_point_cloud(_write(tmp_path, "c.xyz", "# nothing\n\n"))


def test_garbage_text(tmp_path):
    path = _write(tmp_path, "g.xyz", "1 2 3\nfoo bar baz\n")
    with pytest.raises(PointCloudFileError, match="cannot parse"):
        read_point_cloud(path)


@pytest.mark.parametrize("ext", [".xyz", ".txt", ".pts", ".csv"])
def test_round_trip_exact(tmp_path, ext):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3)) * 1000
    intensity = rng.integers(0, 65535, 50).astype(float)
    path = tmp_path / f"a{ext}"
    write_point_cloud(path, points, fields={"intensity": intensity})
    back, extras = read_point_cloud(path, fields=["intensity"])
    np.testing.assert_array_equal(back, points)
    np.testing.assert_array_equal(extras["intensity"], intensity)


def test_round_trip_normals_multi_column(tmp_path):
    points = np.arange(12.0).reshape(4, 3)
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    path = tmp_path / "n.xyz"
    write_point_cloud(path, points, fields={"normals": normals})
    back, extras = read_point_cloud(path, fields="all")
    assert list(extras) == ["normals_0", "normals_1", "normals_2"]
    np.testing.assert_array_equal(back, points)
