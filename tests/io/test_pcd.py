"""PCD reading and writing: round trips, hand-written and PCL-written files, errors."""

import contextlib
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from skpcd.exceptions import NonFiniteWarning, PointCloudFileError
from skpcd.io import _pcd, read_point_cloud, write_point_cloud
from skpcd.io._lzf import lzf_compress

DATA = Path(__file__).parent / "data"
ENCODINGS = ["ascii", "binary", "binary_compressed"]


@contextlib.contextmanager
def _raises(path, match):
    """Expect a PointCloudFileError about ``path`` matching ``match``."""
    with pytest.raises(PointCloudFileError, match=match) as excinfo:
        yield excinfo
    assert str(path) in str(excinfo.value)


def _pcd_file(path, header, body=b"", *, version=True):
    lines = ["# .PCD v0.7 - Point Cloud Data file format"]
    if version:
        lines.append("VERSION 0.7")
    lines += header
    path.write_bytes(("\n".join(lines) + "\n").encode() + body)
    return path


XYZ_HEADER = [
    "FIELDS x y z",
    "SIZE 4 4 4",
    "TYPE F F F",
    "COUNT 1 1 1",
    "WIDTH 2",
    "HEIGHT 1",
    "VIEWPOINT 0 0 0 1 0 0 0",
    "POINTS 2",
]


def _cloud(n=40, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)).astype(np.float32).astype(np.float64)
    fields = {
        "intensity": rng.integers(0, 60000, n).astype(np.uint16),
        "label": rng.integers(-5, 5, n).astype(np.int8),
        "ids": rng.integers(-(2**62), 2**62, n),
        "normals": rng.normal(size=(n, 3)),
        "histogram": rng.random((n, 33)).astype(np.float32),
        "rgb": rng.integers(0, 2**24, n).astype(np.uint32).view(np.float32),
        "valid": rng.random(n) < 0.5,
    }
    return points, fields


# --- round trips ---------------------------------------------------------------


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_float32_points_and_extras(tmp_path, encoding):
    points, fields = _cloud()
    path = tmp_path / "cloud.pcd"
    write_point_cloud(path, points, fields=fields, encoding=encoding)
    data, info = _pcd.read(path)
    assert list(data) == [
        "x", "y", "z", "intensity", "label", "ids", "normal_x", "normal_y",
        "normal_z", "histogram", "rgb", "valid",
    ]  # fmt: skip
    assert b"SIZE 4 4 4 " in path.read_bytes()  # float32 is exact, so it is used
    # binary: float32, as stored; ascii: the float64 the text holds, the
    # float32 value itself (written with its every digit)
    assert data["x"].dtype == (np.float64 if encoding == "ascii" else np.float32)
    np.testing.assert_array_equal(data["x"], points[:, 0])
    assert info["encoding"] == encoding
    assert info["width"] == 40 and info["height"] == 1
    assert info["viewpoint"] == (0, 0, 0, 1, 0, 0, 0)
    got, extras = read_point_cloud(path, fields=[*fields, "normals"])
    np.testing.assert_array_equal(got, points)
    for name, values in fields.items():
        expected = values.astype(np.uint8) if name == "valid" else values
        assert extras[name].dtype == expected.dtype, name
        assert extras[name].shape == expected.shape, name
        np.testing.assert_array_equal(extras[name], expected, err_msg=name)
    # packed colours keep their exact bits
    np.testing.assert_array_equal(
        extras["rgb"].view(np.uint32), fields["rgb"].view(np.uint32)
    )


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_float64_points(tmp_path, encoding):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(25, 3)) * 1e5 + 4e6
    path = tmp_path / "cloud.pcd"
    write_point_cloud(path, points, encoding=encoding)
    assert b"TYPE F F F\n" in path.read_bytes()
    assert b"SIZE 8 8 8\n" in path.read_bytes()
    data, _ = _pcd.read(path)
    assert data["x"].dtype == np.float64
    np.testing.assert_array_equal(read_point_cloud(path), points)


def test_default_encoding_is_binary(tmp_path):
    path = tmp_path / "cloud.pcd"
    write_point_cloud(path, np.eye(3))
    assert b"DATA binary\n" in path.read_bytes()
    assert _pcd.read(path)[1]["encoding"] == "binary"


def test_integer_points_are_written_as_floats(tmp_path):
    path = tmp_path / "cloud.pcd"
    write_point_cloud(path, np.arange(9).reshape(3, 3))
    data, _ = _pcd.read(path)
    assert data["x"].dtype == np.float32
    np.testing.assert_array_equal(read_point_cloud(path), np.arange(9).reshape(3, 3))


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_nonfinite_points(tmp_path, encoding):
    points = np.array([[1.0, 2, 3], [np.nan, 0, 0], [np.inf, -np.inf, 1]])
    path = tmp_path / "cloud.pcd"
    write_point_cloud(path, points, encoding=encoding)
    np.testing.assert_array_equal(read_point_cloud(path, nonfinite="keep"), points)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_empty_cloud(tmp_path, encoding):
    path = tmp_path / "cloud.pcd"
    write_point_cloud(path, np.empty((0, 3)), encoding=encoding)
    data, info = _pcd.read(path)
    assert info["width"] == 0 and all(len(v) == 0 for v in data.values())
    with _raises(path, "declares no points"):
        read_point_cloud(path)


def test_compressed_is_smaller_for_redundant_data(tmp_path):
    points = np.repeat(np.arange(1000.0)[:, None], 3, axis=1) // 10
    write_point_cloud(tmp_path / "a.pcd", points, encoding="binary")
    write_point_cloud(tmp_path / "b.pcd", points, encoding="binary_compressed")
    assert (tmp_path / "b.pcd").stat().st_size < (tmp_path / "a.pcd").stat().st_size / 3


def test_large_compressed_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    points = np.round(rng.uniform(0, 100, size=(200_000, 3)), 2)
    path = tmp_path / "big.pcd"
    write_point_cloud(path, points, encoding="binary_compressed", fields={
        "intensity": rng.integers(0, 255, len(points)).astype(np.uint8)
    })  # fmt: skip
    got, extras = read_point_cloud(path, fields=["intensity"])
    np.testing.assert_array_equal(got, points)
    assert extras["intensity"].dtype == np.uint8


@settings(max_examples=25, deadline=None)
@given(
    n=st.integers(1, 30),
    encoding=st.sampled_from(ENCODINGS),
    double=st.booleans(),
    extra=hnp.arrays(
        dtype=st.sampled_from([np.int16, np.uint32, np.float32, np.float64, np.int64]),
        shape=st.tuples(st.just(30), st.integers(1, 4)),
    ),
    seed=st.integers(0, 2**16),
)
def test_round_trip_hypothesis(tmp_path_factory, n, encoding, double, extra, seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)) * 100
    if not double:
        points = points.astype(np.float32).astype(np.float64)
    extra = extra[:n] if extra.shape[1] > 1 else extra[:n, 0]
    path = tmp_path_factory.mktemp("pcd") / "cloud.pcd"
    write_point_cloud(path, points, fields={"extra": extra}, encoding=encoding)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NonFiniteWarning)
        got, extras = read_point_cloud(path, fields=["extra"], nonfinite="keep")
    np.testing.assert_array_equal(got, points)
    assert extras["extra"].dtype == extra.dtype
    np.testing.assert_array_equal(extras["extra"], extra)


# --- hand-written files ----------------------------------------------------------


def test_ascii_with_comments_and_count(tmp_path):
    path = _pcd_file(
        tmp_path / "h.pcd",
        [
            "# a comment",
            "FIELDS x y z hist",
            "SIZE 4 4 4 2",
            "TYPE F F F U",
            "COUNT 1 1 1 3",
            "WIDTH 2",
            "HEIGHT 1",
            "",
            "POINTS 2",
            "DATA ascii",
        ],
        b"1 2 3 4 5 6\n\n7.5 8 9 10 11 12\n",
    )
    data, info = _pcd.read(path)
    assert info["viewpoint"] == (0, 0, 0, 1, 0, 0, 0)  # default
    np.testing.assert_array_equal(data["x"], np.float32([1, 7.5]))
    assert data["hist"].dtype == np.uint16
    np.testing.assert_array_equal(data["hist"], [[4, 5, 6], [10, 11, 12]])


def test_old_header_without_version_count_viewpoint(tmp_path):
    # v0.5/0.6 style: COLUMNS instead of FIELDS, no COUNT, POINTS without WIDTH
    path = tmp_path / "old.pcd"
    path.write_bytes(
        b"# .PCD v.5 - Point Cloud Data file format\n"
        b"COLUMNS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n"
    )
    _, info = _pcd.read(path)
    assert info["version"] is None and info["width"] == 2 and info["height"] == 1
    np.testing.assert_array_equal(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])


def test_version_06_header(tmp_path):
    path = tmp_path / "v6.pcd"
    path.write_bytes(
        b"# .PCD v.6 - Point Cloud Data file format\nVERSION .6\nFIELDS x y z\n"
        b"SIZE 8 8 8\nTYPE F F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n"
        + np.array([1.5, 2.5, 3.5]).tobytes()
    )
    _, info = _pcd.read(path)
    assert info["version"] == ".6"
    np.testing.assert_array_equal(read_point_cloud(path), [[1.5, 2.5, 3.5]])


def test_crlf_header(tmp_path):
    path = tmp_path / "crlf.pcd"
    path.write_bytes(
        b"# .PCD v0.7\r\nVERSION 0.7\r\nFIELDS x y z\r\nSIZE 4 4 4\r\nTYPE F F F\r\n"
        b"COUNT 1 1 1\r\nWIDTH 1\r\nHEIGHT 1\r\nPOINTS 1\r\nDATA binary\r\n"
        + np.float32([1, 2, 3]).tobytes()
    )
    np.testing.assert_array_equal(read_point_cloud(path), [[1, 2, 3]])


def test_packed_rgb_stored_as_uint32_is_read_as_float32(tmp_path):
    bits = np.array([0xFF0000, 0xFFFFFF80], dtype=np.uint32)
    header = [*XYZ_HEADER[:-1], "POINTS 2", "DATA ascii"]
    header[0] += " rgb"
    header[1] += " 4"
    header[2] += " U"
    header[3] += " 1"
    path = _pcd_file(tmp_path / "u.pcd", header, b"0 0 0 16711680\n1 1 1 4294967168\n")
    data, _ = _pcd.read(path)
    assert data["rgb"].dtype == np.float32
    np.testing.assert_array_equal(data["rgb"].view(np.uint32), bits)
    header[2] = header[2][:-1] + "F"  # a float rgb in ascii is read as a float
    path = _pcd_file(tmp_path / "f.pcd", header, b"0 0 0 2.5\n1 1 1 16711680\n")
    data, _ = _pcd.read(path)
    np.testing.assert_array_equal(data["rgb"], np.float32([2.5, 16711680]))


def test_ascii_writes_packed_rgb_as_integer(tmp_path):
    path = tmp_path / "rgb.pcd"
    rgb = np.array([0x102030, 0xFF102030], np.uint32).view(np.float32)  # 2nd is NaN
    write_point_cloud(path, np.zeros((2, 3)), fields={"rgb": rgb}, encoding="ascii")
    text = path.read_bytes()
    assert b"TYPE F F F U\n" in text
    assert text.endswith(b"0 0 0 1056816\n0 0 0 4279246896\n")
    got = read_point_cloud(path, fields=["rgb"])[1]["rgb"]
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got.view(np.uint32), [0x102030, 0xFF102030])


def test_ascii_large_64_bit_integers_are_exact(tmp_path):
    header = [*XYZ_HEADER[:-1], "POINTS 2", "DATA ascii"]
    header[0] += " big"
    header[1] += " 8"
    header[2] += " U"
    header[3] += " 1"
    body = b"0 0 0 18446744073709551615\n1 1 1 9007199254740993\n"
    data, _ = _pcd.read(_pcd_file(tmp_path / "big.pcd", header, body))
    assert data["big"].dtype == np.uint64
    assert data["big"].tolist() == [2**64 - 1, 2**53 + 1]


def _padded_header(data_kind):
    return [
        "FIELDS x y z _ intensity _",
        "SIZE 4 4 4 1 4 1",
        "TYPE F F F U F U",
        "COUNT 1 1 1 4 1 12",
        "WIDTH 3",
        "HEIGHT 1",
        "VIEWPOINT 1 2 3 1 0 0 0",
        "POINTS 3",
        f"DATA {data_kind}",
    ]


XYZI = np.array([[1, 2, 3, 10], [4, 5, 6, 20], [7, 8, 9, 30]], dtype=np.float32)


def test_binary_with_padding_fields(tmp_path):
    records = np.zeros((3, 8), dtype=np.float32)  # 32 bytes: xyz _ i _ _ _
    records[:, :3] = XYZI[:, :3]
    records[:, 4] = XYZI[:, 3]
    records[:, 3] = np.nan  # garbage in the padding
    path = _pcd_file(tmp_path / "pad.pcd", _padded_header("binary"), records.tobytes())
    data, info = _pcd.read(path)
    assert list(data) == ["x", "y", "z", "intensity"]
    assert info["viewpoint"] == (1, 2, 3, 1, 0, 0, 0)
    np.testing.assert_array_equal(np.column_stack(list(data.values())), XYZI)


@pytest.mark.parametrize("with_padding", [True, False])
def test_binary_compressed_with_padding_fields(tmp_path, with_padding):
    columns = [XYZI[:, j].tobytes() for j in range(4)]
    pad4, pad12 = bytes(3 * 4), bytes(3 * 12)
    if with_padding:
        raw = b"".join([*columns[:3], pad4, columns[3], pad12])
    else:
        raw = b"".join(columns)
    packed = lzf_compress(raw)
    body = np.array([len(packed), len(raw)], "<u4").tobytes() + packed
    path = _pcd_file(tmp_path / "pad.pcd", _padded_header("binary_compressed"), body)
    data, _ = _pcd.read(path)
    assert list(data) == ["x", "y", "z", "intensity"]
    np.testing.assert_array_equal(np.column_stack(list(data.values())), XYZI)


def _organized(tmp_path, encoding):
    points = np.arange(18, dtype=np.float64).reshape(6, 3)
    points[[1, 4]] = np.nan
    header = [
        "FIELDS x y z",
        "SIZE 4 4 4",
        "TYPE F F F",
        "COUNT 1 1 1",
        "WIDTH 3",
        "HEIGHT 2",
        "VIEWPOINT 0 0 0 1 0 0 0",
        "POINTS 6",
        f"DATA {encoding}",
    ]
    f32 = points.astype(np.float32)
    if encoding == "binary":
        body = f32.tobytes()
    elif encoding == "ascii":
        body = "".join(" ".join(str(v) for v in row) + "\n" for row in f32).encode()
    else:
        raw = f32.T.copy().tobytes()
        packed = lzf_compress(raw)
        body = np.array([len(packed), len(raw)], "<u4").tobytes() + packed
    return _pcd_file(tmp_path / "org.pcd", header, body), points


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_organized_cloud_with_nan(tmp_path, encoding):
    path, points = _organized(tmp_path, encoding)
    data, info = _pcd.read(path)
    assert (info["width"], info["height"]) == (3, 2)
    np.testing.assert_array_equal(np.column_stack([data[c] for c in "xyz"]), points)
    with pytest.warns(NonFiniteWarning, match="dropped 2 of 6 points"):
        got = read_point_cloud(path)
    np.testing.assert_array_equal(got, points[[0, 2, 3, 5]])
    kept = read_point_cloud(path, nonfinite="keep")
    assert kept.shape == (3 * 2, 3)
    np.testing.assert_array_equal(kept, points)
    with _raises(path, "2 of 6 points have NaN"):
        read_point_cloud(path, nonfinite="raise")


# --- files written by PCL --------------------------------------------------------

PCL_FILES = ["pcl_ascii.pcd", "pcl_binary.pcd", "pcl_binary_compressed.pcd"]


@pytest.mark.parametrize("name", PCL_FILES)
def test_reads_files_written_by_pcl(name):
    """The same cloud, written by PCL in each encoding, reads exactly."""
    expected = np.load(DATA / "pcl_expected.npz")
    data, info = _pcd.read(DATA / name)
    assert info["encoding"] == name[4:-4]
    assert list(data) == list(expected.files)
    for field in expected.files:
        got = data[field]
        if info["encoding"] == "ascii" and field in ("x", "y", "z"):
            # the coordinates of ascii: the float64 the text holds, which
            # rounds to the float32 PCL wrote it from
            assert got.dtype == np.float64, field
            got = got.astype(np.float32)
        assert got.dtype == expected[field].dtype, field
        # compare bits: the packed colours are NaN as floats
        np.testing.assert_array_equal(
            got.view(np.uint8), expected[field].view(np.uint8), err_msg=field
        )
    points, extras = read_point_cloud(DATA / name, fields=["hist", "rgb"])
    assert points.shape == (30, 3) and extras["hist"].shape == (30, 5)


@pytest.mark.parametrize("encoding", ["ascii", "binary_compressed"])
def test_reads_organized_files_written_by_pcl(encoding):
    path = DATA / f"pcl_organized_{encoding}.pcd"
    data, info = _pcd.read(path)
    assert (info["width"], info["height"]) == (4, 3)
    nan = np.isnan(data["x"])
    assert nan.tolist() == [i in (1, 5, 6) for i in range(12)]
    np.testing.assert_array_equal(data["intensity"], np.arange(12))
    with pytest.warns(NonFiniteWarning, match="dropped 3 of 12 points"):
        _, extras = read_point_cloud(path, fields=["intensity"])
    np.testing.assert_array_equal(extras["intensity"], [0, 2, 3, 4, 7, 8, 9, 10, 11])
    kept = read_point_cloud(path, nonfinite="keep")
    assert kept.shape == (12, 3)
    np.testing.assert_array_equal(np.isnan(kept).all(axis=1), nan)


PCL_CONVERT = shutil.which("pcl_convert_pcd_ascii_binary")


@pytest.mark.skipif(PCL_CONVERT is None, reason="PCL's pcl-tools are not installed")
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_pcl_reads_our_files(tmp_path, encoding):
    rng = np.random.default_rng(5)
    points = np.round(rng.normal(size=(5000, 3)), 2)
    fields = {
        "intensity": rng.integers(0, 4, 5000).astype(np.uint8),
        "hist": np.repeat(rng.random((500, 3)), 10, axis=0).astype(np.float32),
        "rgb": rng.integers(0, 2**32, 5000, dtype=np.uint32).view(np.float32),
    }
    ours = tmp_path / "ours.pcd"
    write_point_cloud(ours, points, fields=fields, encoding=encoding)
    theirs = tmp_path / "theirs.pcd"
    subprocess.run(
        [PCL_CONVERT, str(ours), str(theirs), "1"], check=True, capture_output=True
    )
    got, extras = read_point_cloud(theirs, fields=list(fields))
    np.testing.assert_array_equal(got, points)
    for name, values in fields.items():
        np.testing.assert_array_equal(
            extras[name].view(np.uint8), values.view(np.uint8)
        )


# --- bad files ---------------------------------------------------------------------


def test_not_a_pcd_file(tmp_path):
    path = tmp_path / "bad.pcd"
    path.write_bytes(b"ply\nformat ascii 1.0\n")
    with _raises(path, "not a PCD file"):
        read_point_cloud(path)
    path.write_bytes(bytes(range(128, 256)) * 4)
    with _raises(path, "not a PCD file"):
        _pcd.read(path)
    path.write_bytes(b"# only a comment\n")
    with _raises(path, "not a PCD file: no header"):
        _pcd.read(path)


HEADER_ERRORS = [
    (["FIELDS x y z", "SIZE 4 4 4", "TYPE F F F", "WIDTH 2"], "no DATA line"),
    (
        ["SIZE 4 4 4", "TYPE F F F", "WIDTH 2", "DATA ascii"],
        "FIELDS line is missing",
    ),
    (["FIELDS x y z", "TYPE F F F", "WIDTH 2", "DATA ascii"], "SIZE line is missing"),
    (["FIELDS x y z", "SIZE 4 4 4", "WIDTH 2", "DATA ascii"], "TYPE line is missing"),
    (
        ["FIELDS x y z", "SIZE 4 4", "TYPE F F F", "WIDTH 2", "DATA ascii"],
        "3 FIELDS but 2 SIZE values",
    ),
    (
        [
            "FIELDS x y z",
            "SIZE 4 4 4",
            "TYPE F F F",
            "COUNT 1 1",
            "WIDTH 2",
            "DATA ascii",
        ],
        "3 FIELDS but 2 COUNT values",
    ),
    (
        ["FIELDS x y z", "SIZE 4 4 2", "TYPE F F F", "WIDTH 2", "DATA ascii"],
        "unsupported PCD type for field 'z': TYPE F SIZE 2",
    ),
    (
        ["FIELDS x y z", "SIZE 4 4 4", "TYPE F F Q", "WIDTH 2", "DATA ascii"],
        "unsupported PCD type for field 'z': TYPE Q",
    ),
    (
        ["FIELDS x y z", "SIZE 4 4 4", "TYPE F F F", "WIDTH two", "DATA ascii"],
        "WIDTH must be integers",
    ),
    (
        [
            "FIELDS x y z",
            "SIZE 4 4 4",
            "TYPE F F F",
            "WIDTH 2",
            "HEIGHT -1",
            "DATA ascii",
        ],
        "negative value in HEIGHT",
    ),
    (
        [
            "FIELDS x y z",
            "SIZE 4 4 4",
            "TYPE F F F",
            "WIDTH 2",
            "HEIGHT 2",
            "POINTS 2",
            "DATA ascii",
        ],
        "POINTS 2 differs from WIDTH x HEIGHT = 2 x 2",
    ),
    (["FIELDS x y z", "SIZE 4 4 4", "TYPE F F F", "DATA ascii"], "neither WIDTH nor"),
    (
        [
            "FIELDS x y z",
            "SIZE 4 4 4",
            "TYPE F F F",
            "WIDTH 2",
            "VIEWPOINT 0 0",
            "DATA ascii",
        ],
        "VIEWPOINT needs 7 numbers",
    ),
    (
        ["FIELDS x y z", "SIZE 4 4 4", "TYPE F F F", "WIDTH 2", "DATA binary_zipped"],
        "unsupported PCD DATA 'binary_zipped'",
    ),
    (
        ["FIELDS x y x", "SIZE 4 4 4", "TYPE F F F", "WIDTH 2", "DATA ascii"],
        "field 'x' appears twice",
    ),
    (
        [
            "FIELDS x y z",
            "FIELDS x y z",
            "SIZE 4 4 4",
            "TYPE F F F",
            "WIDTH 2",
            "DATA ascii",
        ],
        "FIELDS appears twice",
    ),
    (
        [
            "FIELDS x y z",
            "SIZE 4 4 4",
            "TYPE F F F",
            "WIDTH 2",
            "COLOUR red",
            "DATA ascii",
        ],
        "unknown line 'COLOUR red'",
    ),
    (
        ["FIELDS x y intensity", "SIZE 4 4 4", "TYPE F F F", "WIDTH 2", "DATA ascii"],
        "no 'z' field",
    ),
    (
        [
            "FIELDS x y z",
            "SIZE 4 4 4",
            "TYPE F F F",
            "COUNT 1 0 1",
            "WIDTH 2",
            "DATA ascii",
        ],
        "field 'y' has COUNT 0",
    ),
]


@pytest.mark.parametrize(
    ("header", "message"), HEADER_ERRORS, ids=lambda v: str(v)[:30]
)
def test_corrupt_headers(tmp_path, header, message):
    path = _pcd_file(tmp_path / "bad.pcd", header, b"1 2 3\n4 5 6\n")
    with _raises(path, message):
        read_point_cloud(path)


def test_garbled_header_bytes(tmp_path):
    path = _pcd_file(tmp_path / "bad.pcd", ["FIELDS x y z", "SIZE \xff\xfe"], b"")
    path.write_bytes(path.read_bytes().replace(b"\xc3\xbf\xc3\xbe", b"\xff\xfe"))
    with _raises(path, "corrupt PCD header: non-text bytes"):
        read_point_cloud(path)


def test_binary_truncated_and_too_long(tmp_path):
    header = [*XYZ_HEADER, "DATA binary"]
    path = _pcd_file(tmp_path / "t.pcd", header, np.zeros(5, np.float32).tobytes())
    with _raises(path, r"expected 24 bytes of point data \(2 points x 12 bytes\), "
                 r"found 20\."):  # fmt: skip
        read_point_cloud(path)
    path = _pcd_file(tmp_path / "t.pcd", header, np.ones(9, np.float32).tobytes())
    with _raises(path, r"12 bytes of extra data after the declared 24 bytes"):
        read_point_cloud(path)
    # zero bytes after the data are PCL's padding: accepted
    path = _pcd_file(tmp_path / "t.pcd", header, np.ones(6, np.float32).tobytes())
    path.write_bytes(path.read_bytes() + bytes(3000))
    np.testing.assert_array_equal(read_point_cloud(path), np.ones((2, 3)))


def test_ascii_line_count_must_match(tmp_path):
    header = [*XYZ_HEADER, "DATA ascii"]
    path = _pcd_file(tmp_path / "a.pcd", header, b"1 2 3\n")
    with _raises(path, "declares 2 points but the data has 1 lines"):
        read_point_cloud(path)
    path = _pcd_file(tmp_path / "a.pcd", header, b"1 2 3\n4 5 6\n7 8 9\n")
    with _raises(path, "declares 2 points but the data has 3 lines"):
        read_point_cloud(path)


def test_ascii_bad_values(tmp_path):
    header = [*XYZ_HEADER, "DATA ascii"]
    path = _pcd_file(tmp_path / "a.pcd", header, b"1 2 3\n4 5\n")
    with _raises(path, "cannot parse the ascii data"):
        read_point_cloud(path)
    path = _pcd_file(tmp_path / "a.pcd", header, b"1 2 3 4\n4 5 6 7\n")
    with _raises(path, "the data lines have 4 values, but the header declares 3"):
        read_point_cloud(path)
    path = _pcd_file(tmp_path / "a.pcd", header, b"1 2 3\n4 five 6\n")
    with _raises(path, "cannot parse the ascii data"):
        read_point_cloud(path)
    int_header = ["FIELDS x y z i", "SIZE 4 4 4 1", "TYPE F F F U", "WIDTH 2",
                  "DATA ascii"]  # fmt: skip
    path = _pcd_file(tmp_path / "a.pcd", int_header, b"1 2 3 4\n4 5 6 7.5\n")
    with _raises(path, "field 'i' has non-integer values"):
        read_point_cloud(path)
    path = _pcd_file(tmp_path / "a.pcd", int_header, b"1 2 3 4\n4 5 6 256\n")
    with _raises(path, "field 'i' has values out of its uint8 range"):
        read_point_cloud(path)


def _compressed_body(raw, *, declared=None, cut=0):
    packed = lzf_compress(raw)
    sizes = [len(packed), len(raw) if declared is None else declared]
    body = np.array(sizes, "<u4").tobytes() + packed
    return body[: len(body) - cut] if cut else body


def test_binary_compressed_errors(tmp_path):
    header = [*XYZ_HEADER, "DATA binary_compressed"]
    raw = np.arange(6, dtype=np.float32).tobytes()
    path = tmp_path / "c.pcd"
    _pcd_file(path, header, b"\x01\x00")
    with _raises(path, "expected 8 bytes of compressed and uncompressed sizes"):
        read_point_cloud(path)
    _pcd_file(path, header, _compressed_body(raw, cut=3))
    with _raises(path, r"bytes of compressed data, found \d+ \(truncated\)"):
        read_point_cloud(path)
    _pcd_file(path, header, _compressed_body(raw) + b"xx")
    with _raises(path, r"2 bytes of extra data after the declared"):
        read_point_cloud(path)
    _pcd_file(path, header, _compressed_body(raw) + bytes(100))  # PCL's padding
    np.testing.assert_array_equal(read_point_cloud(path), np.arange(6).reshape(3, 2).T)
    _pcd_file(path, header, _compressed_body(raw, declared=20))
    with _raises(path, "holds 20 bytes once decompressed, but 2 points of the "
                 "declared fields need 24"):  # fmt: skip
        read_point_cloud(path)
    # a corrupt LZF stream: a back-reference before the start
    _pcd_file(path, header, np.array([2, 24], "<u4").tobytes() + b"\x20\x00")
    with _raises(path, "LZF stream is corrupt"):
        read_point_cloud(path)
    # a stream that decodes to fewer bytes than announced
    short = lzf_compress(raw[:20])
    _pcd_file(path, header, np.array([len(short), 24], "<u4").tobytes() + short)
    with _raises(path, "decompresses to 20 bytes, expected 24"):
        read_point_cloud(path)


# --- writing errors ------------------------------------------------------------------


def test_write_rejects_bad_input(tmp_path):
    path = tmp_path / "w.pcd"
    with pytest.raises(ValueError, match="PCD encoding must be"):
        write_point_cloud(path, np.zeros((2, 3)), encoding="binary_big_endian")
    with pytest.raises(ValueError, match="not a valid PCD field name"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"my field": [1, 2]})
    with pytest.raises(ValueError, match="PCD cannot store it"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"c": np.ones(2, complex)})
    with pytest.raises(ValueError, match="written twice"):
        write_point_cloud(
            path,
            np.zeros((2, 3)),
            fields={"normals": np.ones((2, 3)), "normal_x": [1, 2]},
        )
