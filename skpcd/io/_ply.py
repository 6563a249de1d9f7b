"""PLY point clouds (the Stanford polygon format), ascii and binary.

The header (``ply``, ``format``, ``element``, ``property``, ``comment`` and
``obj_info`` lines up to ``end_header``; LF or CRLF line ends) declares
elements in order, each with a count and properties; the body stores them in
that order, in ascii (one element per line) or binary, little or big endian.
All scalar types are read, under both spellings: ``char``/``int8``,
``uchar``/``uint8``, ``short``/``int16``, ``ushort``/``uint16``,
``int``/``int32``, ``uint``/``uint32``, ``float``/``float32``,
``double``/``float64``.

Only the ``vertex`` element is returned. Other elements (faces, edges...) may
come before or after it and are skipped, list properties included. Vertex
list properties are refused. Consecutive vertex properties named
``name_0 ... name_{c-1}`` of one type are returned as a single ``(n, c)``
field ``name`` (the way :func:`write` stores such fields); ``info["grouped"]``
lists them.

The body must hold exactly what the header declares: missing data is an
error, and so is any byte or ascii line left after the last element. List
properties (faces) are walked by a compiled loop, so a wrong vertex count is
found even when faces follow the vertices. The file is mapped, not read
whole, and its first bytes must be ``ply``: a large file that is not a PLY
file is refused before anything is read.

Writing stores x, y, z as ``float`` when float32 holds them exactly, else
``double``; ``normals`` as ``nx ny nz``, ``colors`` as ``red green blue``,
other ``(n, c)`` fields as ``name_0 ... name_{c-1}``. Integer fields keep an
integer type (64-bit integers need values within 32 bits: PLY has no 64-bit
type); booleans become ``uchar``.
"""

import mmap

import numba
import numpy as np

from skpcd.exceptions import PointCloudFileError
from skpcd.io._common import (
    ascii_rows,
    check_integral,
    coordinate_columns,
    data_lines,
    distinct_columns,
    field_columns,
    float_format,
    float_rows,
    group_fields,
    header_line,
    packed_records,
)

_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_NAMES = {
    "i1": "char",
    "u1": "uchar",
    "i2": "short",
    "u2": "ushort",
    "i4": "int",
    "u4": "uint",
    "f4": "float",
    "f8": "double",
}
_ENCODINGS = {
    "ascii": "ascii",
    "binary": "binary_little_endian",
    "binary_little_endian": "binary_little_endian",
    "binary_big_endian": "binary_big_endian",
}
_ORDER = {"binary_little_endian": "<", "binary_big_endian": ">"}
_MAX_HEADER_LINES = 10000


class _Element:
    def __init__(self, name, count):
        self.name = name
        self.count = count
        self.properties = []  # (name, type code, list count code or None)

    @property
    def fixed(self):
        return all(p[2] is None for p in self.properties)

    def dtype(self, order):
        return np.dtype([(p[0], order + p[1]) for p in self.properties])


def _fail(path, problem):
    return PointCloudFileError(path, problem)


def _type(path, name):
    if name not in _TYPES:
        raise _fail(
            path,
            f"unsupported PLY property type {name!r} (supported: "
            + ", ".join(_TYPES)
            + ").",
        )
    return _TYPES[name]


def _parse_header(path, data):
    """``(format, version, elements, comments, body offset)``."""
    end = data.find(b"\n")
    if data[: end if end >= 0 else 10].strip() != b"ply":
        raise _fail(path, f"not a PLY file: it starts with {data[:10]!r}, not 'ply'.")
    pos = end + 1
    fmt = version = None
    elements, comments = [], []
    for _ in range(_MAX_HEADER_LINES):
        if pos >= len(data):
            break
        raw, pos = header_line(path, data, pos, "PLY")
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise _fail(
                path, f"corrupt PLY header: non-text bytes in line {raw[:40]!r}."
            ) from None
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "end_header":
            if fmt is None:
                raise _fail(path, "corrupt PLY header: no format line.")
            return fmt, version, elements, comments, min(pos, len(data))
        if key in ("comment", "obj_info"):
            comments.append(line[len(key) :].strip())
        elif key == "format":
            if len(tokens) != 3 or tokens[1] not in ("ascii", *_ORDER):
                raise _fail(
                    path,
                    f"unsupported PLY format line {line[:60]!r} (expected ascii, "
                    "binary_little_endian or binary_big_endian).",
                )
            fmt, version = tokens[1], tokens[2]
        elif key == "element":
            if len(tokens) != 3 or not tokens[2].isdigit():
                raise _fail(
                    path, f"corrupt PLY header: bad element line {line[:60]!r}."
                )
            elements.append(_Element(tokens[1], int(tokens[2])))
        elif key == "property":
            if not elements:
                raise _fail(path, "corrupt PLY header: a property before any element.")
            if len(tokens) == 5 and tokens[1] == "list":
                prop = (tokens[4], _type(path, tokens[3]), _type(path, tokens[2]))
                if prop[2][0] == "f":
                    raise _fail(
                        path,
                        f"corrupt PLY header: list {tokens[4]!r} has a float "
                        "count type.",
                    )
            elif len(tokens) == 3 and tokens[1] != "list":
                prop = (tokens[2], _type(path, tokens[1]), None)
            else:
                raise _fail(
                    path, f"corrupt PLY header: bad property line {line[:60]!r}."
                )
            element = elements[-1]
            if any(p[0] == prop[0] for p in element.properties):
                raise _fail(
                    path,
                    f"corrupt PLY header: {element.name} property {prop[0]!r} appears "
                    "twice.",
                )
            element.properties.append(prop)
        else:
            raise _fail(path, f"corrupt PLY header: unknown line {line[:60]!r}.")
    raise _fail(path, "corrupt PLY header: no end_header line.")


def _vertex(path, elements):
    vertices = [e for e in elements if e.name == "vertex"]
    if len(vertices) != 1:
        what = "no" if not vertices else "more than one"
        raise _fail(path, f"the PLY file has {what} 'vertex' element.")
    vertex = vertices[0]
    for name, _, count_type in vertex.properties:
        if count_type is not None:
            raise _fail(
                path,
                f"vertex property {name!r} is a list; only scalar vertex properties "
                "are supported.",
            )
    names = [p[0] for p in vertex.properties]
    missing = [c for c in "xyz" if c not in names]
    if missing:
        raise _fail(
            path,
            f"the vertex element has no {', '.join(repr(c) for c in missing)} "
            "property.",
        )
    return vertex


@numba.njit(cache=True)
def _walk_lists(data, pos, count, heads, items, signed, big):
    """Offset after ``count`` instances of an element with list properties
    (property ``j``: a count of ``heads[j]`` bytes then ``items[j]``-byte
    items; ``heads[j] == 0`` for a scalar of ``items[j]`` bytes); -1 - i
    when instance ``i`` runs past the end, -1 - count - i when its list
    length is negative."""
    end = len(data)
    for i in range(count):
        for j in range(len(heads)):
            head = heads[j]
            if head == 0:
                pos += items[j]
                continue
            if pos + head > end:
                return -1 - i
            k = 0
            for b in range(head):
                byte = data[pos + (b if big else head - 1 - b)]
                k = (k << 8) | byte
            if signed[j] and k >= 1 << (8 * head - 1):
                return -1 - count - i
            pos += head + k * items[j]
        if pos > end:
            return -1 - i
    return pos


def _skip_lists(path, data, pos, element, order):
    """Offset after ``element``, whose instances hold list properties."""
    heads, items, signed = [], [], []
    for _, code, count_code in element.properties:
        if count_code is None:
            heads.append(0)
            items.append(np.dtype(code).itemsize)
            signed.append(False)
        else:
            heads.append(np.dtype(count_code).itemsize)
            items.append(np.dtype(code).itemsize)
            signed.append(np.dtype(count_code).kind == "i")
    end = _walk_lists(
        np.frombuffer(data, dtype=np.uint8),
        pos,
        element.count,
        np.array(heads, dtype=np.int64),
        np.array(items, dtype=np.int64),
        np.array(signed, dtype=np.bool_),
        order == ">",
    )
    if end < -element.count:
        raise _fail(
            path,
            f"corrupt data: {element.name} {-1 - element.count - end} has a "
            "negative list length.",
        )
    if end < 0:
        raise _fail(
            path,
            f"truncated data: {element.name} {-1 - end} of {element.count} runs "
            "past the end of the file.",
        )
    return end


def _read_binary(path, data, start, elements, vertex, order):
    pos = start
    records = None
    for element in elements:
        if element is vertex:
            dtype = element.dtype(order)
            need = element.count * dtype.itemsize
            if len(data) - pos < need:
                raise _fail(
                    path,
                    f"expected {need} bytes of vertex data ({element.count} vertices x "
                    f"{dtype.itemsize} bytes), found {len(data) - pos}.",
                )
            records = np.frombuffer(data, dtype=dtype, count=element.count, offset=pos)
            pos += need
        elif element.fixed:
            need = element.count * element.dtype(order).itemsize
            if len(data) - pos < need:
                raise _fail(
                    path,
                    f"expected {need} bytes of {element.name} data, found "
                    f"{len(data) - pos}.",
                )
            pos += need
        else:
            pos = _skip_lists(path, data, pos, element, order)
    if pos != len(data):
        raise _fail(
            path,
            f"{len(data) - pos} bytes of data after the last element (the header "
            f"declares {vertex.count} vertices).",
        )
    return {
        name: records[name].astype(records.dtype[name].newbyteorder("="))
        for name in records.dtype.names
    }


def _read_ascii(path, data, start, elements, vertex):
    lines = data_lines(data[start:])
    total = sum(e.count for e in elements)
    if len(lines) != total:
        others = total - vertex.count
        extra = f" and {others} other elements" if others else ""
        raise _fail(
            path,
            f"the header declares {vertex.count} vertices{extra}, one per line, but "
            f"the data has {len(lines)} lines.",
        )
    first = 0
    for element in elements:
        if element is vertex:
            break
        first += element.count
    rows = lines[first : first + vertex.count]
    n_props = len(vertex.properties)
    values = float_rows(
        path,
        rows,
        n_props,
        data="the vertex lines",
        rows="the vertex lines",
        unit=" vertex properties",
    )
    fields = {}
    for j, (name, code, _) in enumerate(vertex.properties):
        column = values[:, j]
        dtype = np.dtype(code)
        if dtype.kind in "iu":
            what = f"vertex property {name!r}"
            check_integral(path, column, dtype, what, f"the {dtype} range")
        fields[name] = column.astype(dtype)
    return fields


def read(path):
    """Read the vertices of a PLY file into ``(fields, info)``.

    Parameters
    ----------
    path : path-like
        The ``.ply`` file.

    Returns
    -------
    fields : dict of str to ndarray
        The vertex properties in file order, each of shape ``(n,)`` in its
        own dtype (native byte order), except runs ``name_0 ...
        name_{c-1}`` merged into ``(n, c)`` arrays.
    info : dict
        ``encoding`` (``"ascii"``, ``"binary_little_endian"`` or
        ``"binary_big_endian"``), ``version``, ``comments`` (comment and
        obj_info lines), ``elements`` (``{name: count}`` in file order) and
        ``grouped`` (``{name: [property names]}``).

    Raises
    ------
    PointCloudFileError
        If the file does not start with ``ply``, the header is corrupt, uses
        an unsupported type or has no vertex x, y, z, a vertex property is a
        list, or the body is shorter or longer than the header declares.
    """
    with open(path, "rb") as fh:
        magic = fh.read(4)
        # "ply" ends its line, maybe after spaces ("ply " in PDAL's test data)
        if magic[:3] != b"ply" or magic[3:] not in (b"\n", b"\r", b" ", b"\t"):
            raise _fail(path, f"not a PLY file: it starts with {magic!r}, not 'ply'.")
        # mapped, not read: closed when the last view goes (an error's
        # traceback may hold views of it)
        data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    fmt, version, elements, comments, start = _parse_header(path, data)
    vertex = _vertex(path, elements)
    if fmt == "ascii":
        fields = _read_ascii(path, data, start, elements, vertex)
    else:
        fields = _read_binary(path, data, start, elements, vertex, _ORDER[fmt])
    fields, grouped = group_fields(fields)
    info = {
        "encoding": fmt,
        "version": version,
        "comments": comments,
        "elements": {e.name: e.count for e in elements},
        "grouped": grouped,
    }
    return fields, info


def _storable(name, values):
    """``values`` in a dtype PLY has."""
    dtype = values.dtype
    if dtype == np.bool_:
        return values.astype(np.uint8)
    if dtype == np.float16:
        return values.astype(np.float32)
    if dtype.kind in "iu" and dtype.itemsize == 8:
        for target in (np.int32, np.uint32):
            limits = np.iinfo(target)
            if not len(values) or (
                values.min() >= limits.min and values.max() <= limits.max
            ):
                return values.astype(target)
        raise ValueError(
            f"field {name!r} has {dtype} values beyond 32 bits; PLY has no 64-bit "
            "integer type."
        )
    if dtype.kind not in "iuf" or dtype.itemsize > 8:
        raise ValueError(f"field {name!r} has dtype {dtype}; PLY cannot store it.")
    return values


def _columns(fields):
    """``[(property name, 1-D values)]`` in the order to write them."""
    components = {"normals": ("nx", "ny", "nz"), "colors": ("red", "green", "blue")}
    columns = coordinate_columns(fields) + field_columns(fields, components)
    out = []
    for name, values in distinct_columns(columns, "property"):
        if not name or any(ch.isspace() for ch in name) or not name.isascii():
            raise ValueError(f"{name!r} is not a valid PLY property name.")
        out.append((name, _storable(name, values)))
    return out


def _ascii_body(columns):
    formats = [
        float_format(v.dtype.itemsize) if v.dtype.kind == "f" else "%d"
        for _, v in columns
    ]
    return ascii_rows(formats, [v for _, v in columns])


def write(path, fields, *, encoding="binary"):
    """Write ``fields`` as the vertices of a PLY file; see the module docstring.

    Parameters
    ----------
    path : path-like
        The destination ``.ply`` file.
    fields : dict of str to ndarray
        ``x``, ``y``, ``z`` then extra fields of shape ``(n,)`` or ``(n, c)``.
    encoding : {"binary", "binary_little_endian", "binary_big_endian", \
"ascii"}, default="binary"
        ``"binary"`` is little endian.

    Raises
    ------
    ValueError
        For an unknown encoding, a name PLY cannot hold (empty, with spaces,
        or twice the same), a non-numeric field or 64-bit integers beyond 32
        bits.
    """
    if encoding not in _ENCODINGS:
        raise ValueError(
            "PLY encoding must be 'ascii', 'binary', 'binary_little_endian' or "
            f"'binary_big_endian', got {encoding!r}"
        )
    fmt = _ENCODINGS[encoding]
    n = len(fields["x"])
    columns = _columns(fields)
    header = [
        "ply",
        f"format {fmt} 1.0",
        "comment written by skpcd",
        f"element vertex {n}",
    ]
    for name, values in columns:
        header.append(f"property {_NAMES[values.dtype.str[1:]]} {name}")
    header.append("end_header\n")
    if fmt == "ascii":
        body = _ascii_body(columns)
    else:
        order = _ORDER[fmt]
        dtype = [(name, values.dtype.newbyteorder(order)) for name, values in columns]
        body = packed_records(columns, dtype, n)
    with open(path, "wb") as fh:
        fh.write("\n".join(header).encode("ascii"))
        fh.write(body)
