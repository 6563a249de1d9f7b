"""Files written by other tools of the field that the readers once refused:
PDAL's PCD and NPY test files (upper-case ``X Y Z``, comma- and
tab-separated ascii), a PLY whose first line is ``ply `` and a CSV with a
line of only spaces; and the neighbouring bad inputs, still refused."""

import contextlib
from pathlib import Path

import numpy as np
import pytest

from skpcd.exceptions import PointCloudFileError
from skpcd.io import read_point_cloud

PDAL = Path(__file__).parent / "data" / "pdal"


@contextlib.contextmanager
def _raises(path, match):
    """Expect a one-line PointCloudFileError about ``path`` matching ``match``."""
    with pytest.raises(PointCloudFileError, match=match) as excinfo:
        yield excinfo
    message = str(excinfo.value)
    assert str(path) in message
    assert "\n" not in message


def test_pdal_binary_pcd_is_the_las_it_was_written_from():
    # PDAL's own test checks autzen-utm.pcd against autzen-utm.las; so do we:
    # FIELDS X Y Z Intensity ... Classification ..., DATA binary
    points, extras = read_point_cloud(
        PDAL / "autzen-utm.pcd", fields=["Classification", "Intensity", "GpsTime"]
    )
    las, las_extras = read_point_cloud(
        PDAL / "autzen-utm.las", fields=["classification", "intensity", "gps_time"]
    )
    assert points.shape == (1065, 3)
    np.testing.assert_array_equal(points, las)
    np.testing.assert_array_equal(
        extras["Classification"], las_extras["classification"]
    )
    np.testing.assert_array_equal(extras["Intensity"], las_extras["intensity"])
    np.testing.assert_array_equal(extras["GpsTime"], las_extras["gps_time"])


@pytest.mark.parametrize("separator", ["space", "tab", "comma"])
def test_pdal_ascii_pcd_with_any_separator(separator):
    points = read_point_cloud(PDAL / f"utm17_{separator}.pcd")
    assert points.shape == (10, 3)
    # ascii values in F 4 fields: the text's own values (as float32 they
    # would be 289814.16 and 4320978.5, 11 cm off in y)
    np.testing.assert_array_equal(points[0], [289814.15, 4320978.61, 170.76])
    np.testing.assert_array_equal(points[-1], [289818.50, 4320980.59, 170.58])
    np.testing.assert_array_equal(points, read_point_cloud(PDAL / "utm17_space.pcd"))


def test_pdal_pcd_without_header_is_still_refused():
    path = PDAL / "missingheader.pcd"
    with _raises(path, "not a PCD file"):
        read_point_cloud(path)


def _pcd(path, fields, rows):
    n = len(rows)
    types = " ".join("F" for _ in fields)
    path.write_text(
        f"VERSION 0.7\nFIELDS {' '.join(fields)}\nSIZE {' '.join('4' for _ in fields)}"
        f"\nTYPE {types}\nCOUNT {' '.join('1' for _ in fields)}\nWIDTH {n}\n"
        f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA ascii\n"
        + "".join(row + "\n" for row in rows)
    )
    return path


def test_pcd_mixed_case_coordinates_and_bad_commas_still_refused(tmp_path):
    mixed = _pcd(tmp_path / "mixed.pcd", ["X", "Y", "z"], ["1 2 3"])
    with _raises(mixed, "no 'x', 'y' field"):
        read_point_cloud(mixed)
    # lower-case x y z win over X Y Z: a file with both keeps x y z
    both = _pcd(tmp_path / "both.pcd", ["x", "y", "z", "X"], ["1 2 3 4"])
    points, extras = read_point_cloud(both, fields="all")
    assert points.tolist() == [[1, 2, 3]] and extras["X"].tolist() == [4]
    # a comma leaving a value out is a column short, as before
    short = _pcd(tmp_path / "short.pcd", ["x", "y", "z"], ["1,,3"])
    with _raises(short, "the data lines have 2 values"):
        read_point_cloud(short)
    word = _pcd(tmp_path / "word.pcd", ["x", "y", "z"], ["1,a,3"])
    with _raises(word, "cannot parse the ascii data"):
        read_point_cloud(word)


def test_pdal_structured_npy_with_upper_case_xyz():
    path = PDAL / "1.2-with-color.npy"
    raw = np.load(path)
    assert raw.dtype.names[:3] == ("X", "Y", "Z")
    points, extras = read_point_cloud(path, fields="all")
    assert points.shape == (1065, 3)
    np.testing.assert_array_equal(points, np.column_stack([raw[c] for c in "XYZ"]))
    assert "X" not in extras
    np.testing.assert_array_equal(extras["intensity"], raw["intensity"])
    np.testing.assert_array_equal(extras["gps_time"], raw["gps_time"])


def test_npy_with_only_some_upper_case_coordinates_is_still_refused(tmp_path):
    path = PDAL / "twodim.npy"  # fields X, Health, Intensity
    with _raises(path, r"fields x, y, z \(or X, Y, Z\)"):
        read_point_cloud(path)
    mixed = tmp_path / "mixed.npy"
    np.save(mixed, np.zeros(3, dtype=[("X", "f8"), ("Y", "f8"), ("z", "f8")]))
    with _raises(mixed, "fields x, y, z"):
        read_point_cloud(mixed)


def test_ply_first_line_with_trailing_space():
    points = read_point_cloud(PDAL / "simple_text.ply")
    assert points.tolist() == [[-1, 0, 0], [0, 1, 0], [1, 0, 0]]


def test_ply_with_trailing_space_but_no_vertex_is_refused_clearly():
    path = PDAL / "no_vertex.ply"
    with _raises(path, "no 'vertex' element"):
        read_point_cloud(path)


@pytest.mark.parametrize("first", [b"ply x\n", b"plyx\n", b"ply2\n", b" ply\n"])
def test_ply_first_line_other_than_ply_is_still_refused(tmp_path, first):
    path = tmp_path / "bad.ply"
    path.write_bytes(
        first + b"format ascii 1.0\nelement vertex 1\nproperty float x\n"
        b"property float y\nproperty float z\nend_header\n1 2 3\n"
    )
    with _raises(path, "not a PLY file"):
        read_point_cloud(path)


@pytest.mark.parametrize("blank", ["   ", " \t ", "\t", "  # a comment"])
def test_csv_with_a_line_of_only_spaces_reads_as_xyz_does(tmp_path, blank):
    csv = tmp_path / "cloud.csv"
    csv.write_text(f"x,y,z,intensity\n1,2,3,7\n{blank}\n4,5,6,8\n")
    xyz = tmp_path / "cloud.xyz"
    xyz.write_text(f"1 2 3 7\n{blank}\n4 5 6 8\n")
    points, extras = read_point_cloud(csv, fields=["intensity"])
    assert points.tolist() == [[1, 2, 3], [4, 5, 6]]
    assert extras["intensity"].tolist() == [7, 8]
    np.testing.assert_array_equal(points, read_point_cloud(xyz))


def test_csv_with_a_line_of_empty_values_is_still_refused(tmp_path):
    path = tmp_path / "cloud.csv"
    path.write_text("1,2,3\n , , \n4,5,6\n")
    with _raises(path, "cannot parse the point lines"):
        read_point_cloud(path)
