import numpy as np
import pytest

from skpcd.exceptions import MissingFileError, PointCloudFileError
from skpcd.io import read_segments, write_point_cloud


@pytest.fixture
def folder(tmp_path):
    for i, n in enumerate([3, 5, 4]):
        write_point_cloud(
            tmp_path / f"obj{[2, 10, 1][i]}.xyz", np.full((n, 3), float(i))
        )
    (tmp_path / "labels.csv").write_text(
        "file,label\nobj1.xyz,b\nobj2.xyz,a\nobj10.xyz,a\n"
    )
    return tmp_path


def test_natural_order_and_labels(folder):
    clouds, labels, names = read_segments(folder, folder / "labels.csv")
    assert names == ["obj1.xyz", "obj2.xyz", "obj10.xyz"]
    assert labels.tolist() == ["b", "a", "a"]
    assert [len(c) for c in clouds] == [4, 3, 5]


def test_without_labels_skips_labels_csv(folder):
    clouds, labels, names = read_segments(folder)
    assert labels is None and len(clouds) == 3 and "labels.csv" not in names


def test_glob(folder):
    clouds, labels, names = read_segments(str(folder / "obj1*.xyz"))
    assert names == ["obj1.xyz", "obj10.xyz"] and labels is None
    assert [len(c) for c in clouds] == [4, 5]


def test_labels_name_missing_file(folder):
    (folder / "labels.csv").write_text(
        "obj1.xyz,b\nobj2.xyz,a\nobj10.xyz,a\nghost.xyz,a\n"
    )
    with pytest.raises(
        MissingFileError, match=r"1 labelled file\(s\) not found.*ghost\.xyz"
    ):
        read_segments(folder, folder / "labels.csv")


def test_file_without_label(folder):
    (folder / "labels.csv").write_text("obj1.xyz,b\nobj2.xyz,a\n")
    with pytest.raises(
        PointCloudFileError, match=r"1 file\(s\) have no label: obj10\.xyz"
    ):
        read_segments(folder, folder / "labels.csv")


def test_bad_labels_files(folder):
    with pytest.raises(MissingFileError, match="no such file"):
        read_segments(folder, folder / "nolabels.csv")
    bad = folder / "bad.txt"
    bad.write_text("obj1.xyz,b,extra\n")
    with pytest.raises(PointCloudFileError, match="row 1 has 3 columns"):
        read_segments(str(folder / "*.xyz"), bad)
    twice = folder / "twice.txt"
    twice.write_text("obj1.xyz,b\nobj1.xyz,c\n")
    with pytest.raises(PointCloudFileError, match="labelled twice"):
        read_segments(str(folder / "*.xyz"), twice)


def test_missing_folder_and_empty_folder(tmp_path):
    with pytest.raises(MissingFileError, match="no such file or folder"):
        read_segments(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(PointCloudFileError, match="no point-cloud file found"):
        read_segments(tmp_path / "empty")


def test_a_bad_file_names_itself(folder):
    (folder / "obj2.xyz").write_text("1 2\n")
    with pytest.raises(
        PointCloudFileError, match=r"obj2\.xyz: each line needs at least 3"
    ):
        read_segments(folder, folder / "labels.csv")


def test_all_dales_objects(dales, dales_dir):
    clouds, labels, names = dales
    # the README says 400 objects, but file 060 is absent: 399 files, 399 label rows
    assert len(clouds) == len(labels) == len(names) == 399
    classes, counts = np.unique(labels, return_counts=True)
    assert classes.tolist() == ["building", "car", "fence", "pole", "tree"]
    assert counts.tolist() == [79, 80, 80, 80, 80]
    assert "060.xyz" not in names and "004.xyz" not in names
    assert names == sorted(names)
    # the label mapping follows the CSV, row by row
    rows = dict(
        line.split(",") for line in (dales_dir / "labels.csv").read_text().split()[1:]
    )
    assert [rows[n] for n in names] == labels.tolist()
    assert sum(len(c) for c in clouds) == 882_733
    assert all(c.dtype == np.float64 and c.shape[1] == 3 for c in clouds)
    first = np.loadtxt(dales_dir / names[0])
    np.testing.assert_array_equal(clouds[0], first)
