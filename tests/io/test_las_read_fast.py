"""The LAS reader's fast paths give what laspy's straightforward reading
gives, bit for bit: the records read as bytes, x, y, z scaled with numpy,
every other field decoded only when asked for; and the bounds of the
segment files are those of the reduction across the rows."""

from pathlib import Path

import laspy
import numpy as np
import pytest

from skpcd.exceptions import PointCloudFileError
from skpcd.io import _las_reader, iter_points, read_point_cloud, write_point_cloud
from skpcd.io._las_reader import read, scaled_xyz
from skpcd.io._segment_folder import _bounds

DATA = Path(__file__).resolve().parents[1] / "data"
# LAS 1.2 format 1 (GeoKeys), LAZ 1.4 format 6 with odd scales and EVLRs,
# LAZ format 3 with colours, COPC format 7
TEST_FILES = [
    DATA / "las" / "autzen_geokeys.las",
    DATA / "las" / "1_4_w_evlr.laz",
    DATA / "las" / "autzen_trim.laz",
    DATA / "copc" / "simple.copc.laz",
]


def _as_laspy_reads(path):
    """``{name: array}`` as laspy.read and numpy give them: the reading the
    fast paths replace."""
    las = laspy.read(str(path))
    fields = {c: np.asarray(las[c], dtype=np.float64) for c in "xyz"}
    for name in las.point_format.dimension_names:
        if name not in ("X", "Y", "Z"):
            fields[name] = np.array(las[name])
    return fields


def _assert_same_bits(got, expected):
    assert list(got) == list(expected)
    for name, values in expected.items():
        value = np.asarray(got[name])
        assert value.dtype == values.dtype, name
        assert value.shape == values.shape, name
        assert value.tobytes() == np.ascontiguousarray(values).tobytes(), name


@pytest.mark.parametrize("path", TEST_FILES, ids=lambda p: p.name)
def test_read_gives_laspys_fields_bit_for_bit(path):
    fields, info = read(path)
    _assert_same_bits(fields, _as_laspy_reads(path))
    points = read_point_cloud(path, nonfinite="keep")
    assert points.tobytes() == info["xyz"].tobytes()


def test_real_sweep_read_bit_for_bit(real_sweeps):
    path = real_sweeps[0]
    expected = _as_laspy_reads(path)
    points, extras = read_point_cloud(path, fields="all", nonfinite="keep")
    xyz = np.column_stack([expected.pop(c) for c in "xyz"])
    assert points.tobytes() == xyz.tobytes()
    _assert_same_bits(extras, expected)


def test_only_the_fields_asked_for_are_decoded(tmp_path):
    path = tmp_path / "scan.las"
    rng = np.random.default_rng(0)
    write_point_cloud(
        path,
        rng.uniform(0, 50, (1000, 3)),
        fields={"intensity": rng.integers(0, 999, 1000)},
    )
    fields, _ = read(path)
    assert "return_number" in fields
    assert set(fields._values) == {"x", "y", "z"}
    fields["return_number"]
    assert set(fields._values) == {"x", "y", "z", "return_number"}
    # asked for by name through the public reader
    points, extras = read_point_cloud(path, fields=["intensity", "x"])
    assert set(extras) == {"intensity", "x"}
    # a requested coordinate is a copy, not a column of the points
    extras["x"][:] = -1
    assert (points[:, 0] >= 0).all()


def test_grouped_extra_dimensions_decoded_on_demand(tmp_path):
    path = tmp_path / "scan.laz"
    rng = np.random.default_rng(1)
    normals = rng.normal(size=(500, 3))
    write_point_cloud(path, rng.uniform(0, 5, (500, 3)), fields={"feat": normals})
    fields, info = read(path)
    assert info["grouped"] == {"feat": ["feat_0", "feat_1", "feat_2"]}
    assert "feat_0" not in fields
    np.testing.assert_array_equal(fields["feat"], normals)
    _, extras = read_point_cloud(path, fields=["feat"])
    np.testing.assert_array_equal(extras["feat"], normals)


@pytest.mark.parametrize("n", [0, 1, 16383, 16384, 40000])
def test_scaled_xyz_is_laspys_scaling(n):
    rng = np.random.default_rng(n)
    dtype = laspy.PointFormat(6).dtype()
    records = np.zeros(n, dtype)
    for c in "XYZ":
        records[c] = rng.integers(-(2**31), 2**31 - 1, n, dtype=np.int64)
    scales = np.array([1.16451354e-06, 0.01, 3e-3])
    offsets = np.array([1692500.352, -31.0, 7350.194653])
    expected = laspy.ScaleAwarePointRecord(
        records, laspy.PointFormat(6), scales, offsets
    )
    xyz = scaled_xyz(records, scales, offsets)
    for j, c in enumerate("xyz"):
        assert xyz[:, j].tobytes() == np.asarray(expected[c]).tobytes()


@pytest.mark.parametrize("chunk_size", [7, 1000])
def test_iter_points_chunks_are_laspys(chunk_size):
    path = DATA / "las" / "autzen_geokeys.las"
    expected = _as_laspy_reads(path)
    chunks = list(iter_points(path, chunk_size=chunk_size, fields=["intensity"]))
    xyz = np.concatenate([c for c, _ in chunks])
    assert xyz.tobytes() == np.column_stack([expected[c] for c in "xyz"]).tobytes()
    intensity = np.concatenate([e["intensity"] for _, e in chunks])
    assert intensity.tobytes() == expected["intensity"].tobytes()


def test_file_cut_after_its_check_is_truncated(tmp_path, monkeypatch):
    path = tmp_path / "scan.las"
    write_point_cloud(path, np.random.default_rng(2).uniform(0, 9, (100, 3)))
    layout = _las_reader.checked_layout(path)
    with open(path, "r+b") as f:  # cut in the middle of the 41st record
        f.truncate(layout.offset + 40 * layout.record_length + 5)
    monkeypatch.setattr(_las_reader, "checked_layout", lambda path: layout)
    with pytest.raises(PointCloudFileError) as info:
        read(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    assert "truncated: the header declares 100 points, 40 could be read" in message


def test_bounds_are_the_reduction_across_rows():
    rng = np.random.default_rng(3)
    points = rng.normal(size=(1001, 3))
    points[::7, 1] = 0.0
    points[::11, 1] = -0.0
    points[:, 2] = np.abs(points[:, 2])
    points[5, 2], points[9, 2] = -0.0, 0.0
    points[3, 0] = np.nan
    for cloud in (points, points[:, [1, 2, 0]], np.abs(points[:, 1:2]) + 1):
        lo, hi = _bounds(cloud)
        expected_lo, expected_hi = cloud.min(axis=0), cloud.max(axis=0)
        assert lo.tobytes() == expected_lo.tobytes()
        assert hi.tobytes() == expected_hi.tobytes()
