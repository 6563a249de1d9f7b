"""PLY reading and writing: round trips, hand-written headers, errors."""

import contextlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.exceptions import PointCloudFileError
from skpcd.io import _ply, read_point_cloud, write_point_cloud

ENCODINGS = ["ascii", "binary", "binary_little_endian", "binary_big_endian"]
FORMATS = ["ascii", "binary_little_endian", "binary_big_endian"]


@contextlib.contextmanager
def _raises(path, match):
    """Expect a PointCloudFileError about ``path`` matching ``match``."""
    with pytest.raises(PointCloudFileError, match=match) as excinfo:
        yield excinfo
    assert str(path) in str(excinfo.value)


def _ply_file(path, header, body=b"", *, newline="\n"):
    text = newline.join(["ply", *header, "end_header"]) + newline
    path.write_bytes(text.encode() + body)
    return path


def _cloud(n=30, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)).astype(np.float32).astype(np.float64)
    fields = {
        "intensity": rng.integers(0, 60000, n).astype(np.uint16),
        "label": rng.integers(-100, 100, n).astype(np.int8),
        "tag": rng.integers(0, 255, n).astype(np.uint8),
        "count": rng.integers(-(2**15), 2**15, n).astype(np.int16),
        "id": rng.integers(0, 2**32, n).astype(np.uint32),
        "score": rng.normal(size=n),
        "normals": rng.normal(size=(n, 3)).astype(np.float32),
        "feature": rng.random((n, 4)),
    }
    return points, fields


# --- round trips ---------------------------------------------------------------


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_float32_points_and_extras(tmp_path, encoding):
    points, fields = _cloud()
    path = tmp_path / "cloud.ply"
    write_point_cloud(path, points, fields=fields, encoding=encoding)
    data, info = _ply.read(path)
    assert info["encoding"] == (
        "binary_little_endian" if encoding == "binary" else encoding
    )
    assert info["elements"] == {"vertex": 30}
    assert info["grouped"] == {"feature": [f"feature_{j}" for j in range(4)]}
    assert list(data) == [
        "x", "y", "z", "intensity", "label", "tag", "count", "id", "score",
        "nx", "ny", "nz", "feature",
    ]  # fmt: skip
    assert data["x"].dtype == np.float32
    assert all(v.dtype.isnative for v in data.values())
    got, extras = read_point_cloud(path, fields=list(fields))
    np.testing.assert_array_equal(got, points)
    for name, values in fields.items():
        assert extras[name].dtype == values.dtype, name
        assert extras[name].shape == values.shape, name
        np.testing.assert_array_equal(extras[name], values, err_msg=name)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_float64_points(tmp_path, encoding):
    points = np.random.default_rng(1).normal(size=(20, 3)) * 1e3 + 5e5
    path = tmp_path / "cloud.ply"
    write_point_cloud(path, points, encoding=encoding)
    assert b"property double x\n" in path.read_bytes()
    np.testing.assert_array_equal(read_point_cloud(path), points)


def test_default_is_binary_little_endian(tmp_path):
    path = tmp_path / "cloud.ply"
    write_point_cloud(path, np.eye(3))
    text = path.read_bytes()
    assert text.startswith(b"ply\nformat binary_little_endian 1.0\n")
    assert b"property float x\n" in text


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_round_trip_nonfinite_and_empty(tmp_path, encoding):
    points = np.array([[1.0, 2, 3], [np.nan, 0, 0], [np.inf, -np.inf, 1]])
    path = tmp_path / "cloud.ply"
    write_point_cloud(path, points, encoding=encoding)
    np.testing.assert_array_equal(read_point_cloud(path, nonfinite="keep"), points)
    empty = tmp_path / "empty.ply"
    write_point_cloud(empty, np.empty((0, 3)), encoding=encoding)
    data, _ = _ply.read(empty)
    assert all(len(v) == 0 for v in data.values())
    with _raises(empty, "declares no points"):
        read_point_cloud(empty)


def test_colors_written_as_red_green_blue(tmp_path):
    path = tmp_path / "c.ply"
    colors = np.array([[255, 0, 10], [1, 2, 3]], dtype=np.uint8)
    write_point_cloud(path, np.zeros((2, 3)), fields={"colors": colors})
    assert b"property uchar red\nproperty uchar green\nproperty uchar blue\n" in (
        path.read_bytes()
    )
    got = read_point_cloud(path, fields=["colors"])[1]["colors"]
    np.testing.assert_array_equal(got, colors)


def test_64_bit_and_bool_fields(tmp_path):
    path = tmp_path / "i.ply"
    fields = {
        "small": np.array([-5, 7]),  # int64 that fits int32
        "unsigned": np.array([0, 2**32 - 1], dtype=np.int64),  # fits uint32
        "flag": np.array([True, False]),
        "half": np.array([0.5, 1.5], dtype=np.float16),
    }
    write_point_cloud(path, np.zeros((2, 3)), fields=fields)
    data, _ = _ply.read(path)
    assert data["small"].dtype == np.int32 and data["small"].tolist() == [-5, 7]
    assert data["unsigned"].dtype == np.uint32
    assert data["unsigned"].tolist() == [0, 2**32 - 1]
    assert data["flag"].dtype == np.uint8 and data["flag"].tolist() == [1, 0]
    assert data["half"].dtype == np.float32 and data["half"].tolist() == [0.5, 1.5]
    with pytest.raises(ValueError, match="beyond 32 bits"):
        write_point_cloud(
            tmp_path / "big.ply", np.zeros((2, 3)), fields={"big": np.array([0, 2**40])}
        )


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(1, 40),
    encoding=st.sampled_from(ENCODINGS),
    double=st.booleans(),
    dtype=st.sampled_from(
        [
            np.int8,
            np.uint8,
            np.int16,
            np.uint16,
            np.int32,
            np.uint32,
            np.float32,
            np.float64,
        ]
    ),
    width=st.integers(1, 3),
    seed=st.integers(0, 2**16),
)
def test_round_trip_hypothesis(
    tmp_path_factory, n, encoding, double, dtype, width, seed
):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)) * 1000
    if not double:
        points = points.astype(np.float32).astype(np.float64)
    if np.dtype(dtype).kind == "f":
        extra = rng.normal(size=(n, width)).astype(dtype)
    else:
        info = np.iinfo(dtype)
        extra = rng.integers(
            info.min, info.max, size=(n, width), endpoint=True, dtype=dtype
        )
    if width == 1:
        extra = extra[:, 0]
    path = tmp_path_factory.mktemp("ply") / "cloud.ply"
    write_point_cloud(path, points, fields={"extra": extra}, encoding=encoding)
    got, extras = read_point_cloud(path, fields=["extra"])
    np.testing.assert_array_equal(got, points)
    assert extras["extra"].dtype == extra.dtype
    np.testing.assert_array_equal(extras["extra"], extra)


# --- hand-written files ----------------------------------------------------------

# Every scalar type under both spellings: (old name, new name, values).
TYPES = [
    ("char", "int8", [-128, 127]),
    ("uchar", "uint8", [0, 255]),
    ("short", "int16", [-32768, 32767]),
    ("ushort", "uint16", [0, 65535]),
    ("int", "int32", [-(2**31), 2**31 - 1]),
    ("uint", "uint32", [0, 2**32 - 1]),
    ("float", "float32", [1.5, -2.25]),
    ("double", "float64", [0.1, -1e300]),
]


def _typed_file(path, fmt, spelling, **kwargs):
    names = [t[spelling] for t in TYPES]
    header = [f"format {fmt} 1.0", "comment all types", "obj_info made by hand",
              "element vertex 2", "property float x", "property float y",
              "property float z"]  # fmt: skip
    header += [f"property {name} p_{name}" for name in names]
    dtype = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    dtype += [(f"p_{t[spelling]}", _ply._TYPES[t[spelling]]) for t in TYPES]
    records = np.zeros(2, dtype=dtype)
    records["x"] = [1, 2]
    for t in TYPES:
        records[f"p_{t[spelling]}"] = t[2]
    if fmt == "ascii":
        body = "".join(
            " ".join(repr(v.item()) for v in row) + "\n" for row in records
        ).encode()
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        body = records.astype(records.dtype.newbyteorder(order)).tobytes()
    return _ply_file(path, header, body, **kwargs)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("spelling", [0, 1])
def test_all_scalar_types(tmp_path, fmt, spelling):
    path = _typed_file(tmp_path / "t.ply", fmt, spelling)
    data, info = _ply.read(path)
    assert info["comments"] == ["all types", "made by hand"]
    assert data["x"].tolist() == [1, 2]
    for t in TYPES:
        values = data[f"p_{t[spelling]}"]
        assert values.dtype == np.dtype(_ply._TYPES[t[0]]), t
        assert values.tolist() == t[2], t


@pytest.mark.parametrize("fmt", FORMATS)
def test_crlf_header(tmp_path, fmt):
    path = _typed_file(tmp_path / "t.ply", fmt, 0, newline="\r\n")
    data, _ = _ply.read(path)
    assert data["x"].tolist() == [1, 2]
    assert data["p_double"].tolist() == [0.1, -1e300]


MESH_VERTICES = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float32)
FACES = [[0, 1, 2], [0, 2, 3, 1], [1, 3]]


def _mesh(path, fmt, *, vertex_first, edges=False, tail=b""):
    """A mesh whose face element has a list property and a scalar after it."""
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    vertex_header = ["element vertex 4", "property float x", "property float y",
                     "property float z", "property uchar quality"]  # fmt: skip
    face_header = ["element face 3", "property list uchar int vertex_indices",
                   "property short flags"]  # fmt: skip
    edge_header = ["element edge 2", "property int vertex1", "property int vertex2"]
    if fmt == "ascii":
        vertex_body = b"".join(
            f"{x} {y} {z} {i}\n".encode() for i, (x, y, z) in enumerate(MESH_VERTICES)
        )
        face_body = b"".join(
            f"{len(f)} {' '.join(map(str, f))} -{k}\n".encode()
            for k, f in enumerate(FACES)
        )
        edge_body = b"0 1\n2 3\n"
    else:
        rec = np.zeros(4, dtype=[("p", order + "f4", 3), ("q", "u1")])
        rec["p"] = MESH_VERTICES
        rec["q"] = np.arange(4)
        vertex_body = rec.tobytes()
        face_body = b"".join(
            np.uint8(len(f)).tobytes()
            + np.array(f, dtype=order + "i4").tobytes()
            + np.array(-k, dtype=order + "i2").tobytes()
            for k, f in enumerate(FACES)
        )
        edge_body = np.array([0, 1, 2, 3], dtype=order + "i4").tobytes()
    parts = [(vertex_header, vertex_body), (face_header, face_body)]
    if not vertex_first:
        parts.reverse()
    if edges:
        parts.append((edge_header, edge_body))
    header = [f"format {fmt} 1.0"] + [line for h, _ in parts for line in h]
    return _ply_file(path, header, b"".join(b for _, b in parts) + tail)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("vertex_first", [True, False])
@pytest.mark.parametrize("edges", [False, True])
def test_other_elements_are_skipped(tmp_path, fmt, vertex_first, edges):
    path = _mesh(tmp_path / "m.ply", fmt, vertex_first=vertex_first, edges=edges)
    data, info = _ply.read(path)
    assert list(info["elements"])[-1] == ("edge" if edges else "face" if vertex_first
                                          else "vertex")  # fmt: skip
    assert info["elements"]["vertex"] == 4 and info["elements"]["face"] == 3
    assert list(data) == ["x", "y", "z", "quality"]
    np.testing.assert_array_equal(
        np.column_stack([data[c] for c in "xyz"]), MESH_VERTICES
    )
    assert data["quality"].tolist() == [0, 1, 2, 3]
    np.testing.assert_array_equal(read_point_cloud(path), MESH_VERTICES)


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian"])
def test_list_element_after_vertices_is_checked(tmp_path, fmt):
    # before: the faces after the vertices were neither parsed nor checked,
    # so trailing bytes and a wrong vertex count went unnoticed
    path = _mesh(tmp_path / "m.ply", fmt, vertex_first=True)
    np.testing.assert_array_equal(read_point_cloud(path), MESH_VERTICES)
    path = _mesh(tmp_path / "m.ply", fmt, vertex_first=True, tail=b"trailing bytes")
    with _raises(path, "14 bytes of data after the last element"):
        read_point_cloud(path)
    path = _mesh(tmp_path / "m.ply", fmt, vertex_first=True)
    data = path.read_bytes()
    n = len(MESH_VERTICES)
    path.write_bytes(
        data.replace(b"element vertex %d" % n, b"element vertex %d" % (n - 1))
    )
    with pytest.raises(PointCloudFileError, match=str(path)):
        read_point_cloud(path)


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian"])
def test_truncated_list_element_before_vertices(tmp_path, fmt):
    path = _mesh(tmp_path / "m.ply", fmt, vertex_first=False)
    data = path.read_bytes()
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    path.write_bytes(data[: header_end + 20])  # in the middle of the second face
    with _raises(path, "truncated data: face 1 of 3 runs past the end of the file"):
        read_point_cloud(path)
    path.write_bytes(data[: header_end + 55])  # the 45 bytes of faces, 10 of vertices
    with _raises(path, "expected 52 bytes of vertex data .*, found 10"):
        read_point_cloud(path)


def test_fixed_element_after_vertices_is_checked(tmp_path):
    fmt = "binary_little_endian"
    header = [f"format {fmt} 1.0", "element vertex 1", "property float x",
              "property float y", "property float z", "element edge 2",
              "property int a", "property int b"]  # fmt: skip
    vertex = np.float32([1, 2, 3]).tobytes()
    path = _ply_file(tmp_path / "e.ply", header, vertex + bytes(12))
    with _raises(path, "expected 16 bytes of edge data, found 12"):
        read_point_cloud(path)
    path = _ply_file(tmp_path / "e.ply", header, vertex + bytes(20))
    with _raises(path, "4 bytes of data after the last element"):
        read_point_cloud(path)
    path = _ply_file(tmp_path / "e.ply", header, vertex + bytes(16))
    np.testing.assert_array_equal(read_point_cloud(path), [[1, 2, 3]])


def test_grouping_rules(tmp_path):
    header = ["format ascii 1.0", "element vertex 1"] + [
        f"property {t} {name}"
        for t, name in [
            ("float", "x"), ("float", "y"), ("float", "z"),
            ("float", "f_0"), ("float", "f_1"),  # grouped
            ("float", "g_0"),  # a single one: kept
            ("float", "h_0"), ("double", "h_1"),  # mixed types: kept
            ("uchar", "k_1"), ("uchar", "k_2"),  # not starting at 0: kept
            ("float", "m_0"), ("float", "m_1"), ("float", "m"),  # clash: kept
        ]
    ]  # fmt: skip
    path = _ply_file(tmp_path / "g.ply", header, b" ".join([b"1"] * 13) + b"\n")
    data, info = _ply.read(path)
    assert list(data) == ["x", "y", "z", "f", "g_0", "h_0", "h_1", "k_1", "k_2",
                          "m_0", "m_1", "m"]  # fmt: skip
    assert data["f"].shape == (1, 2)
    assert info["grouped"] == {"f": ["f_0", "f_1"]}


# --- bad files ---------------------------------------------------------------------


def test_wrong_magic(tmp_path):
    path = tmp_path / "bad.ply"
    path.write_bytes(b"# .PCD v0.7\nVERSION 0.7\n")
    with _raises(path, "not a PLY file"):
        read_point_cloud(path)
    path.write_bytes(b"plyformat ascii 1.0\n")
    with _raises(path, "not a PLY file"):
        read_point_cloud(path)


XYZ = ["element vertex 1", "property float x", "property float y", "property float z"]

HEADER_ERRORS = [
    (
        ["format ascii 1.0", *XYZ, "property float128 w"],
        "unsupported PLY property type 'float128'",
    ),
    (
        ["format ascii 1.0", *XYZ, "property list uchar int128 w"],
        "unsupported PLY property type",
    ),
    (["format binary_middle_endian 1.0", *XYZ], "unsupported PLY format line"),
    (["format ascii", *XYZ], "unsupported PLY format line"),
    (XYZ, "no format line"),
    (["format ascii 1.0", "property float x", *XYZ], "a property before any element"),
    (["format ascii 1.0", "element vertex many", *XYZ[1:]], "bad element line"),
    (["format ascii 1.0", *XYZ, "property float"], "bad property line"),
    (
        ["format ascii 1.0", *XYZ, "property float x"],
        "vertex property 'x' appears twice",
    ),
    (["format ascii 1.0", *XYZ, "colour red"], "unknown line 'colour red'"),
    (["format ascii 1.0", *XYZ, "property list float int w"], "float count type"),
    (
        ["format ascii 1.0", "element face 0", "property int a"],
        "has no 'vertex' element",
    ),
    (["format ascii 1.0", *XYZ, *XYZ], "more than one 'vertex' element"),
    (["format ascii 1.0", *XYZ[:3]], "the vertex element has no 'z' property"),
    (
        ["format ascii 1.0", *XYZ, "property list uchar float extra"],
        "vertex property 'extra' is a list",
    ),
]


@pytest.mark.parametrize(
    ("header", "message"), HEADER_ERRORS, ids=lambda v: str(v)[:40]
)
def test_corrupt_headers(tmp_path, header, message):
    path = _ply_file(tmp_path / "bad.ply", header, b"1 2 3\n")
    with _raises(path, message):
        read_point_cloud(path)


def test_no_end_header_and_garbled_header(tmp_path):
    path = tmp_path / "bad.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n")
    with _raises(path, "no end_header line"):
        read_point_cloud(path)
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\n\xff\xfe\x00\x01\n")
    with _raises(path, "non-text bytes"):
        read_point_cloud(path)


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian"])
def test_binary_truncated_and_too_long(tmp_path, fmt):
    header = [f"format {fmt} 1.0", *XYZ[:1], "property double x", "property double y",
              "property double z"]  # fmt: skip
    header[1] = "element vertex 3"
    path = _ply_file(tmp_path / "t.ply", header, bytes(50))
    with _raises(path, r"expected 72 bytes of vertex data \(3 vertices x 24 bytes\), "
                 "found 50"):  # fmt: skip
        read_point_cloud(path)
    path = _ply_file(tmp_path / "t.ply", header, bytes(80))
    with _raises(path, "8 bytes of data after the last element"):
        read_point_cloud(path)


def test_ascii_line_counts(tmp_path):
    header = ["format ascii 1.0", *XYZ]
    header[1] = "element vertex 2"
    path = _ply_file(tmp_path / "a.ply", header, b"1 2 3\n")
    with _raises(path, "declares 2 vertices, one per line, but the data has 1 lines"):
        read_point_cloud(path)
    path = _ply_file(tmp_path / "a.ply", header, b"1 2 3\n\n4 5 6\n7 8 9\n")
    with _raises(path, "but the data has 3 lines"):
        read_point_cloud(path)
    path = _mesh(tmp_path / "m.ply", "ascii", vertex_first=True, tail=b"3 0 1 2 0\n")
    with _raises(path, "declares 4 vertices and 3 other elements, one per line, but "
                 "the data has 8 lines"):  # fmt: skip
        read_point_cloud(path)


def test_ascii_bad_values(tmp_path):
    header = ["format ascii 1.0", *XYZ, "property uchar q"]
    header[1] = "element vertex 2"
    path = _ply_file(tmp_path / "a.ply", header, b"1 2 3 4\n4 5 6\n")
    with _raises(path, "cannot parse the vertex lines"):
        read_point_cloud(path)
    path = _ply_file(tmp_path / "a.ply", header, b"1 2 3 4 5\n4 5 6 7 8\n")
    with _raises(path, "the vertex lines have 5 values, but the header declares 4"):
        read_point_cloud(path)
    path = _ply_file(tmp_path / "a.ply", header, b"1 2 3 4\n4 5 six 7\n")
    with _raises(path, "cannot parse the vertex lines"):
        read_point_cloud(path)
    path = _ply_file(tmp_path / "a.ply", header, b"1 2 3 4\n4 5 6 7.5\n")
    with _raises(path, "vertex property 'q' has non-integer values"):
        read_point_cloud(path)
    path = _ply_file(tmp_path / "a.ply", header, b"1 2 3 4\n4 5 6 256\n")
    with _raises(path, "vertex property 'q' has values out of the uint8 range"):
        read_point_cloud(path)


# --- writing errors ------------------------------------------------------------------


def test_write_rejects_bad_input(tmp_path):
    path = tmp_path / "w.ply"
    with pytest.raises(ValueError, match="PLY encoding must be"):
        write_point_cloud(path, np.zeros((2, 3)), encoding="binary_compressed")
    with pytest.raises(ValueError, match="not a valid PLY property name"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"my field": [1, 2]})
    with pytest.raises(ValueError, match="PLY cannot store it"):
        write_point_cloud(path, np.zeros((2, 3)), fields={"s": np.array(["a", "b"])})
    with pytest.raises(ValueError, match="written twice"):
        write_point_cloud(
            path, np.zeros((2, 3)), fields={"normals": np.ones((2, 3)), "nx": [1, 2]}
        )
