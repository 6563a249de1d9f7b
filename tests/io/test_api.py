import warnings

import numpy as np
import pytest

from skpcd.exceptions import MissingFileError, NonFiniteWarning, PointCloudFileError
from skpcd.io import SUPPORTED_EXTENSIONS, read_point_cloud, write_point_cloud


def test_missing_file_is_file_not_found(tmp_path):
    path = tmp_path / "nope.ply"
    with pytest.raises(FileNotFoundError) as info:
        read_point_cloud(path)
    assert isinstance(info.value, MissingFileError)
    assert isinstance(info.value, PointCloudFileError)
    assert str(path) in str(info.value) and "no such file" in str(info.value)


def test_directory_is_not_a_file(tmp_path):
    folder = tmp_path / "dir.xyz"
    folder.mkdir()
    with pytest.raises(MissingFileError, match="is a directory"):
        read_point_cloud(folder)


def test_unknown_extension(tmp_path):
    path = tmp_path / "cloud.obj"
    path.write_text("v 1 2 3\n")
    with pytest.raises(
        PointCloudFileError, match=r"unknown point-cloud extension '\.obj'"
    ):
        read_point_cloud(path)
    with pytest.raises(PointCloudFileError, match="unknown"):
        write_point_cloud(tmp_path / "out.obj", np.zeros((1, 3)))


@pytest.mark.parametrize(
    "ext", [e for e in SUPPORTED_EXTENSIONS if e not in (".las", ".laz")]
)
def test_empty_file(tmp_path, ext):
    path = tmp_path / f"empty{ext}"
    path.write_bytes(b"")
    with pytest.raises(PointCloudFileError) as info:
        read_point_cloud(path)
    assert str(path) in str(info.value) and "empty" in str(info.value)


def _with_nan(tmp_path):
    path = tmp_path / "nan.xyz"
    path.write_text("1 2 3 5\nnan 0 0 6\n4 inf 6 7\n7 8 9 8\n")
    return path


def test_nonfinite_dropped_with_counting_warning(tmp_path):
    path = _with_nan(tmp_path)
    with pytest.warns(NonFiniteWarning, match="dropped 2 of 4 points"):
        points, extras = read_point_cloud(path, fields=["field_3"])
    np.testing.assert_array_equal(points, [[1, 2, 3], [7, 8, 9]])
    np.testing.assert_array_equal(extras["field_3"], [5, 8])


def test_nonfinite_keep_and_raise(tmp_path):
    path = _with_nan(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_point_cloud(path, nonfinite="keep").shape == (4, 3)
    with pytest.raises(PointCloudFileError, match="2 of 4 points have NaN"):
        read_point_cloud(path, nonfinite="raise")
    with pytest.raises(ValueError, match="nonfinite must be"):
        read_point_cloud(path, nonfinite="zero")


def test_no_valid_point(tmp_path):
    path = tmp_path / "allnan.xyz"
    path.write_text("nan nan nan\ninf 0 0\n")
    with pytest.raises(PointCloudFileError, match="no valid point: all 2 points"):
        read_point_cloud(path)


def test_unknown_field_lists_available(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("x,y,z,intensity\n1,2,3,4\n")
    with pytest.raises(
        PointCloudFileError, match="no field 'normals'; the file has: intensity"
    ):
        read_point_cloud(path, fields=["normals"])


def test_write_never_overwrites_without_asking(tmp_path):
    path = tmp_path / "keep.xyz"
    path.write_text("1 2 3\n")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_point_cloud(path, np.zeros((2, 3)))
    assert path.read_text() == "1 2 3\n"
    write_point_cloud(path, np.zeros((2, 3)), overwrite=True)
    assert read_point_cloud(path).shape == (2, 3)


def test_write_checks_shapes(tmp_path):
    with pytest.raises(ValueError, match=r"shape \(n_points, 3\)"):
        write_point_cloud(tmp_path / "a.xyz", np.zeros((4, 2)))
    with pytest.raises(ValueError, match="field 'intensity'"):
        write_point_cloud(
            tmp_path / "a.xyz", np.zeros((4, 3)), fields={"intensity": [1, 2]}
        )


@pytest.mark.parametrize("ext", [".npy"])
def test_npy_round_trip_plain_and_structured(tmp_path, ext):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(30, 3))
    write_point_cloud(tmp_path / f"a{ext}", points)
    np.testing.assert_array_equal(read_point_cloud(tmp_path / f"a{ext}"), points)
    normals = rng.normal(size=(30, 3)).astype(np.float32)
    write_point_cloud(tmp_path / f"b{ext}", points, fields={"normals": normals})
    back, extras = read_point_cloud(tmp_path / f"b{ext}", fields=["normals"])
    np.testing.assert_array_equal(back, points)
    np.testing.assert_array_equal(extras["normals"], normals)


def test_npy_bad_shapes(tmp_path):
    np.save(tmp_path / "flat.npy", np.zeros(5))
    with pytest.raises(PointCloudFileError, match=r"shape \(n, 3\+\)"):
        read_point_cloud(tmp_path / "flat.npy")
    (tmp_path / "junk.npy").write_bytes(b"not numpy at all")
    with pytest.raises(PointCloudFileError, match=r"not a readable \.npy"):
        read_point_cloud(tmp_path / "junk.npy")


@pytest.mark.parametrize("kind", ["fifo", "loop", "broken", "folder"])
def test_files_that_are_not_regular_files_are_named_as_such(tmp_path, kind):
    # before: a FIFO and a symbolic-link loop were reported as "no such file"
    import os

    path = tmp_path / "cloud.xyz"
    expected = {
        "fifo": "is a FIFO \\(named pipe\\), not a regular file",
        "loop": "cannot be read: Too many levels of symbolic links",
        "broken": "a broken symbolic link",
        "folder": "is a directory, not a file",
    }[kind]
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "loop":
        path.symlink_to(tmp_path / "other.xyz")
        (tmp_path / "other.xyz").symlink_to(path)
    elif kind == "broken":
        path.symlink_to(tmp_path / "gone.xyz")
    else:
        path.mkdir()
    with pytest.raises(PointCloudFileError, match=f"{path}: {expected}") as info:
        read_point_cloud(path)  # never opened: a FIFO would block here
    assert isinstance(info.value, MissingFileError) == (kind in ("broken", "folder"))


@pytest.mark.parametrize(
    ("suffix", "message"),
    [(".ply", "not a PLY file"), (".pcd", "not a PCD file or a corrupt header")],
)
def test_a_large_file_of_zeros_is_refused_before_reading(tmp_path, suffix, message):
    # before: a 3 GB zero-filled .ply was read whole (3 GB of memory) before
    # its first bytes were checked; a sparse 4 GB file costs no disk here
    import subprocess
    import sys

    path = tmp_path / f"zeros{suffix}"
    with open(path, "wb") as f:
        f.truncate(4 << 30)
    script = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
        "from skpcd.io import read_point_cloud\n"
        "from skpcd.exceptions import PointCloudFileError\n"
        f"try:\n    read_point_cloud({str(path)!r})\n"
        "except PointCloudFileError as exc:\n    print(exc)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    assert message in proc.stdout and str(path) in proc.stdout
