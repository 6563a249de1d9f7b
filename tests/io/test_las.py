"""LAS/LAZ reading and writing through laspy."""

import contextlib
import sys

import numpy as np
import pytest

from skpcd.exceptions import PointCloudFileError
from skpcd.io import _las, read_point_cloud, write_point_cloud

EXTENSIONS = [".las", ".laz"]


@contextlib.contextmanager
def _raises(path, match):
    """Expect a PointCloudFileError about ``path`` matching ``match``."""
    with pytest.raises(PointCloudFileError, match=match) as excinfo:
        yield excinfo
    assert str(path) in str(excinfo.value)


def _cloud(n=200, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.uniform(0, 100, size=(n, 3)) + np.array([500_000.123, 4.2e6, -12.25])
    fields = {
        "intensity": rng.integers(0, 65535, n).astype(np.uint16),
        "classification": rng.integers(0, 256, n),
        "return_number": rng.integers(1, 16, n),
        "gps_time": rng.uniform(0, 1e6, n),
        "user_data": rng.integers(0, 256, n).astype(np.uint8),
        "normals": rng.normal(size=(n, 3)),
        "feature": rng.random((n, 5)).astype(np.float32),
        "segment": rng.integers(-(2**40), 2**40, n),
    }
    return points, fields


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_round_trip(tmp_path, ext):
    points, fields = _cloud()
    path = tmp_path / f"cloud{ext}"
    write_point_cloud(path, points, fields=fields)
    data, info = _las.read(path)
    assert info["version"] == "1.4" and info["point_format"] == 6
    assert info["compressed"] == (ext == ".laz")
    assert info["scales"] == (1e-4, 1e-4, 1e-4)
    assert info["offsets"] == tuple(np.floor(points.min(axis=0)))
    assert list(data)[:4] == ["x", "y", "z", "intensity"]
    assert data["x"].dtype == np.float64
    got, extras = read_point_cloud(path, fields=[*fields, "scan_angle"])
    assert np.abs(got - points).max() <= 0.5e-4 + 1e-9
    for name, values in fields.items():
        assert extras[name].shape == values.shape, name
        np.testing.assert_array_equal(extras[name], values, err_msg=name)
    assert extras["intensity"].dtype == np.uint16
    assert extras["classification"].dtype == np.uint8
    assert extras["feature"].dtype == np.float32
    assert extras["segment"].dtype == np.int64
    assert extras["scan_angle"].tolist() == [0] * 200  # standard dims, zero-filled


def test_laz_is_compressed(tmp_path):
    points = np.repeat(np.arange(5000.0)[:, None], 3, axis=1) / 100
    write_point_cloud(tmp_path / "a.las", points)
    write_point_cloud(tmp_path / "a.laz", points)
    assert (tmp_path / "a.laz").stat().st_size < (tmp_path / "a.las").stat().st_size / 3
    np.testing.assert_allclose(read_point_cloud(tmp_path / "a.laz"), points, atol=1e-9)


def test_colors_and_nir_choose_the_point_format(tmp_path):
    colors = np.array([[0, 65535, 7], [1, 2, 3]])
    path = tmp_path / "rgb.las"
    write_point_cloud(path, np.eye(2, 3), fields={"colors": colors})
    data, info = _las.read(path)
    assert info["point_format"] == 7
    assert data["red"].dtype == np.uint16
    got = read_point_cloud(path, fields=["colors"])[1]["colors"]
    np.testing.assert_array_equal(got, colors)
    path = tmp_path / "nir.las"
    write_point_cloud(path, np.eye(2, 3), fields={"nir": [5, 6], "red": [1, 2]})
    data, info = _las.read(path)
    assert info["point_format"] == 8
    assert data["nir"].tolist() == [5, 6] and data["red"].tolist() == [1, 2]
    # float colours in [0, 1] do not fit uint16 integers: kept as extra bytes
    path = tmp_path / "float.las"
    write_point_cloud(path, np.eye(2, 3), fields={"colors": colors / 65535})
    data, info = _las.read(path)
    assert info["point_format"] == 6 and data["colors"].shape == (2, 3)


def test_coordinates_kept_to_a_tenth_of_a_millimetre(tmp_path):
    rng = np.random.default_rng(3)
    points = rng.uniform(-1000, 1000, size=(500, 3)) + np.array([3e5, 5e6, 50])
    path = tmp_path / "c.las"
    write_point_cloud(path, points)
    assert np.abs(read_point_cloud(path) - points).max() <= 0.5e-4 + 1e-9
    # integers and negative offsets: exact
    path = tmp_path / "i.las"
    write_point_cloud(path, np.array([[-3, 7, 0], [2, -9, 1]]))
    _, info = _las.read(path)
    assert info["offsets"] == (-3, -9, 0)
    np.testing.assert_array_equal(read_point_cloud(path), [[-3, 7, 0], [2, -9, 1]])


def test_huge_extent_gets_a_coarser_scale(tmp_path):
    points = np.array([[0.0, 0, 0], [1e6, 1, 1]])  # 1000 km along x
    path = tmp_path / "big.las"
    write_point_cloud(path, points)
    _, info = _las.read(path)
    assert info["scales"] == (1e-3, 1e-4, 1e-4)
    np.testing.assert_allclose(read_point_cloud(path), points, atol=1e-3)


def test_write_errors(tmp_path):
    path = tmp_path / "w.las"
    with pytest.raises(ValueError, match="LAS files are always binary"):
        write_point_cloud(path, np.zeros((2, 3)), encoding="ascii")
    with pytest.raises(ValueError, match="NaN or infinite"):
        write_point_cloud(path, np.array([[0, 0, np.nan], [1, 1, 1]]))
    with pytest.raises(ValueError, match=r"'classification' does not fit .* 0 to 255"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"classification": [1, 256]})
    with pytest.raises(ValueError, match=r"'return_number' does not fit .*4-bit"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"return_number": [1, 16]})
    with pytest.raises(ValueError, match="'intensity' does not fit"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"intensity": [1.5, 2]})
    with pytest.raises(ValueError, match="'intensity' does not fit"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"intensity": [-1, 2]})
    with pytest.raises(ValueError, match="LAS cannot store it"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"s": np.array(["a", "b"])})
    with pytest.raises(ValueError, match="written twice"):
        write_point_cloud(
            path,
            np.zeros((2, 3)),
            fields={"normals": np.ones((2, 3)), "normal_x": [1, 2]},
        )
    with pytest.raises(ValueError, match="at most 32 bytes"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"n" * 40: [1, 2]})


def test_not_a_las_file(tmp_path):
    path = tmp_path / "bad.las"
    path.write_bytes(b"ply\nformat ascii 1.0\n" * 40)
    with _raises(path, "cannot read as LAS/LAZ"):
        read_point_cloud(path)


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_truncated_file(tmp_path, ext):
    path = tmp_path / f"t{ext}"
    write_point_cloud(path, np.random.default_rng(0).normal(size=(1000, 3)))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with _raises(path, "cannot read as LAS/LAZ"):
        read_point_cloud(path)
    path.write_bytes(data[:100])  # inside the header
    with _raises(path, "cannot read as LAS/LAZ"):
        read_point_cloud(path)


def test_missing_laspy(tmp_path, monkeypatch):
    path = tmp_path / "cloud.las"
    write_point_cloud(path, np.eye(3))
    monkeypatch.setitem(sys.modules, "laspy", None)
    # a core dependency: the hint is laspy itself, not the old las extra
    message = r"needs laspy, a dependency of skpcd .*: pip install laspy lazrs$"
    with pytest.raises(ImportError, match=message):
        read_point_cloud(path)
    with pytest.raises(ImportError, match=message):
        write_point_cloud(tmp_path / "other.laz", np.eye(3))


# --- chunked reading: iter_points and read_las_extent -------------------------


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_iter_points_chunks_are_the_whole_file(tmp_path, ext):
    from skpcd.io import iter_points, read_las_extent

    points, fields = _cloud(n=2503)
    path = tmp_path / f"cloud{ext}"
    write_point_cloud(path, points, fields=fields)
    whole, extras = read_point_cloud(path, fields=["intensity", "gps_time"])
    chunks = list(iter_points(path, chunk_size=1000))
    assert [len(c) for c in chunks] == [1000, 1000, 503]
    assert all(c.dtype == np.float64 and c.shape[1] == 3 for c in chunks)
    assert np.array_equal(np.vstack(chunks), whole)
    chunks = list(iter_points(path, chunk_size=700, fields=["intensity", "gps_time"]))
    assert np.array_equal(np.vstack([c for c, _ in chunks]), whole)
    for name in ("intensity", "gps_time"):
        got = np.concatenate([e[name] for _, e in chunks])
        assert got.dtype == extras[name].dtype
        assert np.array_equal(got, extras[name])
    assert len(list(iter_points(path, chunk_size=10**7))) == 1
    extent = read_las_extent(path)
    assert extent.n_points == 2503
    assert np.array_equal(extent.mins, whole.min(axis=0))
    assert np.array_equal(extent.maxs, whole.max(axis=0))
    assert extent.dimensions[:3] == ("X", "Y", "Z")
    assert "intensity" in extent.dimensions


@pytest.mark.parametrize("chunk_size", [0, -5, 2.5, True, "10", None])
def test_iter_points_refuses_a_bad_chunk_size(tmp_path, chunk_size):
    from skpcd.io import iter_points

    path = tmp_path / "cloud.las"
    write_point_cloud(path, _cloud(n=10)[0])
    with pytest.raises(ValueError, match="chunk_size must be a positive integer"):
        iter_points(path, chunk_size=chunk_size)


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_iter_points_unreadable_files(tmp_path, ext):
    from skpcd.exceptions import MissingFileError
    from skpcd.io import iter_points, read_las_extent

    garbage = tmp_path / f"garbage{ext}"
    garbage.write_bytes(b"not a las file at all" * 20)
    for reader in (lambda p: list(iter_points(p)), read_las_extent):
        with _raises(garbage, "cannot read as LAS/LAZ"):
            reader(garbage)
    with pytest.raises(MissingFileError):
        iter_points(tmp_path / f"missing{ext}")
    with _raises(tmp_path / "cloud.ply", "not a LAS/LAZ file"):
        iter_points(tmp_path / "cloud.ply")
    # truncated in the middle: refused before the first chunk
    path = tmp_path / f"cut{ext}"
    write_point_cloud(path, _cloud(n=5000)[0])
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with _raises(path, "cannot read as LAS/LAZ: truncated.* declares 5000 points"):
        iter_points(path, chunk_size=500)
    path.write_bytes(data)
    with _raises(path, "no field 'nope'"):
        next(iter_points(path, fields=["nope"]))
