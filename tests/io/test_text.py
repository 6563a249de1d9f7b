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


# issue 15, finding 6: the header's names are used, and a first line that is
# neither a header nor a point is an error, never dropped as a "header"


@pytest.mark.parametrize(
    "text, points, extras",
    [
        # was: read as x, y, z in file order
        ("z,y,x\n1,2,3\n4,5,6\n", [[3, 2, 1], [6, 5, 4]], {}),
        # was: points (id, x, z)
        ("id,x,y,z\n9,1,2,3\n", [[1, 2, 3]], {"id": [9]}),
        ("Intensity Z X Y\n7 3 1 2\n", [[1, 2, 3]], {"intensity": [7]}),
        ('"X","Y","Z","return"\n1,2,3,1\n', [[1, 2, 3]], {"return": [1]}),
        (
            "# export\n\n// more\nx y z _id # names\n1 2 3 4 # a point\n",
            [[1, 2, 3]],
            {"_id": [4]},
        ),
    ],
)
def test_header_columns_are_used_by_name(tmp_path, text, points, extras):
    path = _write(tmp_path, "a.csv" if "," in text else "a.txt", text)
    back, found = read_point_cloud(path, fields="all")
    np.testing.assert_array_equal(back, points)
    assert list(found) == list(extras)
    for name, values in extras.items():
        np.testing.assert_array_equal(found[name], values)


def test_a_column_named_twice_is_an_error(tmp_path):
    # was: the second x overwrote the first
    path = _write(tmp_path, "a.xyz", "x y z x\n1 2 3 4\n")
    with pytest.raises(PointCloudFileError, match=r"names column 'x' twice"):
        read_point_cloud(path)
    path = _write(tmp_path, "b.csv", "x,y,z,I,i\n1,2,3,4,5\n")
    with pytest.raises(PointCloudFileError, match=r"'i' twice \(columns 4 and 5\)"):
        read_point_cloud(path)


def test_header_without_coordinates_names_its_columns(tmp_path):
    # was: the first three columns taken as x, y, z whatever their names
    path = _write(tmp_path, "a.csv", "east,north,height,i\n1,2,3,4\n")
    with pytest.raises(
        PointCloudFileError,
        match=r"^.*a\.csv: line 1: the header names the columns east, north, "
        r"height, i but not x, y, z",
    ):
        read_point_cloud(path)
    with pytest.raises(PointCloudFileError, match="column 2 has no name"):
        read_point_cloud(_write(tmp_path, "b.csv", "x,,y,z\n1,2,3,4\n"))


@pytest.mark.parametrize("header", [b"", b"x y z\n"])
def test_byte_order_mark_is_skipped(tmp_path, header):
    # was: the BOM made the first point a "header" and it vanished
    path = tmp_path / "bom.xyz"
    path.write_bytes(b"\xef\xbb\xbf" + header + b"1 2 3\n4 5 6\n")
    np.testing.assert_array_equal(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize("first", ["Infinity", "-INF", "nan", "+.5", "1E3", "-0."])
def test_every_number_loadtxt_reads_starts_a_point(tmp_path, first):
    # was: 'Infinity' (and others) made the first point a "header"
    path = _write(tmp_path, "a.xyz", f"{first} 2 3\n4 5 6\n")
    points = read_point_cloud(path, nonfinite="keep")
    assert len(points) == 2
    np.testing.assert_array_equal(points[0], [float(first), 2, 3])


@pytest.mark.parametrize(
    "line, why",
    [
        ("1.2.3 2 3", "'1.2.3' is neither a number nor a name"),
        ("1_0 2 3", "'1_0' is neither a number nor a name"),
        ("\u0661 2 3", "is neither a number nor a name"),  # an Arabic-Indic 1
        ("x y 3", "it mixes numbers and names"),
        ("1 2 z", "it mixes numbers and names"),
        ("(x) (y) (z)", "'(x)' is neither a number nor a name"),
    ],
)
def test_a_first_line_neither_header_nor_point_is_an_error(tmp_path, line, why):
    # was: dropped silently as a header
    path = _write(tmp_path, "a.xyz", f"# comment\n{line}\n4 5 6\n")
    with pytest.raises(PointCloudFileError) as info:
        read_point_cloud(path)
    message = str(info.value)
    assert message.startswith(f"{path}: line 2 is neither a header nor a point")
    assert why in message


def test_bytes_that_are_not_utf8_are_no_crash(tmp_path):
    # was: UnicodeDecodeError from numpy.loadtxt
    path = tmp_path / "latin1.xyz"
    path.write_bytes(b"# M\xfcnchen\n1 2 3\n")
    np.testing.assert_array_equal(read_point_cloud(path), [[1, 2, 3]])
    path.write_bytes(b"1 2 3\n4 5 \xff\n")
    with pytest.raises(PointCloudFileError, match="cannot parse"):
        read_point_cloud(path)


def test_pts_count_line_is_not_a_header(tmp_path):
    path = _write(tmp_path, "a.pts", "1\n1 2 3\n")
    np.testing.assert_array_equal(read_point_cloud(path), [[1, 2, 3]])
    with pytest.raises(PointCloudFileError, match="point count but no point lines"):
        read_point_cloud(_write(tmp_path, "b.pts", "3\n"))


def test_writer_refuses_names_it_could_not_read_back(tmp_path):
    for name in ["1st", "a b", "a,b", "X", "#i"]:
        with pytest.raises(ValueError, match="cannot write a text column"):
            write_point_cloud(tmp_path / "a.csv", np.eye(3), fields={name: [1, 2, 3]})
    assert not list(tmp_path.iterdir())
    write_point_cloud(tmp_path / "a.csv", np.eye(3), fields={"_Return": [1, 2, 3]})
    _, extras = read_point_cloud(tmp_path / "a.csv", fields="all")
    assert list(extras) == ["_return"]
