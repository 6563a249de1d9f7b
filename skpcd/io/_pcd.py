"""PCD point clouds, the Point Cloud Library's format (v0.7, and older headers).

A text header (``VERSION``, ``FIELDS``, ``SIZE``, ``TYPE``, ``COUNT``,
``WIDTH``, ``HEIGHT``, ``VIEWPOINT``, ``POINTS``, then ``DATA``; ``#`` lines
are comments) followed by the data in one of three encodings:

- ``ascii``: one point per line, values apart by spaces, tabs or commas.
  The coordinates ``x``, ``y``, ``z`` are returned as float64 whatever
  their ``SIZE``, as PDAL reads them: the values the text holds
  (``289814.15 4320978.61`` in ``F 4`` fields would be 289814.16 and
  4320978.5 as float32, 11 cm off); other fields have their declared type.
- ``binary``: little-endian records, one per point, fields in header order.
- ``binary_compressed``: two little-endian uint32 (compressed and
  uncompressed size) then an LZF stream whose content is column-major: all
  values of the first field, then of the second, and so on.

Types ``I``/``U`` of 1, 2, 4 or 8 bytes and ``F`` of 4 or 8 bytes are
supported, with any ``COUNT``; fields with a count above one are returned as
``(n, count)`` arrays. Packed colours (``rgb`` or ``rgba``, 4 bytes) are
returned as float32, PCL's type for them, also when stored as ``U 4`` (as PCL
writes them in ascii, and so does :func:`write`): the bits are kept. PCL's
``_`` padding fields are skipped. Coordinates named ``X Y Z`` (as in PDAL's
test data) are read as ``x y z`` when the file has no ``x``, ``y``, ``z``.
Organized clouds (``HEIGHT`` > 1) are returned flat in row-major order,
invalid points as stored (NaN); ``info`` keeps ``width``, ``height``,
``viewpoint``, ``version`` and ``encoding``.

The data must hold exactly ``POINTS`` points: missing bytes, or a different
count of ascii lines, are errors; so are bytes after the binary data, unless
they are all zero (PCL pads its binary files with zeros).

Writing stores x, y, z as float32 when that is exact, else float64 (in
ascii, with the digits that give the float32 value back as a float64); other
fields keep their type (booleans become ``U 1``); ``normals`` is written as
``normal_x normal_y normal_z`` and any other ``(n, c)`` field with ``COUNT
c``. The cloud is written unorganized (``HEIGHT 1``).
"""

import mmap
import re

import numpy as np

from skpcd.exceptions import PointCloudFileError
from skpcd.io._common import (
    MAX_LINE_BYTES,
    ascii_rows,
    check_integral,
    coordinate_columns,
    coordinate_names,
    data_lines,
    distinct_columns,
    field_columns,
    float_format,
    float_rows,
    header_line,
    packed_records,
)
from skpcd.io._lzf import LZFError, lzf_compress, lzf_decompress_array

_ENCODINGS = ("ascii", "binary", "binary_compressed")
_KEYWORDS = (
    "VERSION",
    "FIELDS",
    "COLUMNS",
    "SIZE",
    "TYPE",
    "COUNT",
    "WIDTH",
    "HEIGHT",
    "VIEWPOINT",
    "POINTS",
    "DATA",
)
_KEYWORDS_B = {k.encode() for k in _KEYWORDS} | {b"COLUMNS"}
_MAX_HEADER_LINES = 1000
_PACKED_COLOR = ("rgb", "rgba")


def _fail(path, problem):
    return PointCloudFileError(path, problem)


def _parse_first_line(path, prefix):
    """Refuse a file whose first line is not a PCD header line."""
    end = prefix.find(b"\n")
    line = prefix if end < 0 else prefix[:end]
    if end < 0 and len(prefix) > MAX_LINE_BYTES:
        raise _fail(
            path,
            f"not a PCD file or a corrupt header: no line end in {MAX_LINE_BYTES} "
            "bytes at offset 0.",
        )
    key = line.strip().split(maxsplit=1)[:1]
    if key and not key[0].startswith(b"#") and key[0].upper() not in _KEYWORDS_B:
        raise _fail(
            path,
            "not a PCD file: expected a header starting with '# .PCD', VERSION or "
            f"FIELDS, found {line[:60]!r}.",
        )


def _parse_header(path, data):
    """Split the header into ``{KEYWORD: [tokens]}`` and the data offset."""
    header = {}
    pos = 0
    for _ in range(_MAX_HEADER_LINES):
        if pos >= len(data):
            break
        raw, pos = header_line(path, data, pos, "PCD")
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            if not header:
                raise _fail(
                    path, "not a PCD file: it does not start with a text header."
                ) from None
            raise _fail(
                path, f"corrupt PCD header: non-text bytes in line {raw[:40]!r}."
            ) from None
        if not line or line.startswith("#"):
            continue
        tokens = line.split()
        key = tokens[0].upper()
        if key not in _KEYWORDS:
            if not header:
                raise _fail(
                    path,
                    "not a PCD file: expected a header starting with '# .PCD', "
                    f"VERSION or FIELDS, found {line[:60]!r}.",
                )
            if re.match(r"[-+.\d]", key) or key.startswith("NAN"):
                raise _fail(
                    path,
                    "corrupt PCD header: no DATA line before the point data "
                    f"({line[:60]!r}).",
                )
            raise _fail(path, f"corrupt PCD header: unknown line {line[:60]!r}.")
        if key == "COLUMNS":
            key = "FIELDS"
        if key in header:
            raise _fail(path, f"corrupt PCD header: {key} appears twice.")
        header[key] = tokens[1:]
        if key == "DATA":
            return header, min(pos, len(data))
    if not header:
        raise _fail(path, "not a PCD file: no header found.")
    raise _fail(path, "corrupt PCD header: no DATA line ends it.")


def _ints(path, header, key, default=None):
    if key not in header:
        if default is None:
            raise _fail(path, f"corrupt PCD header: the {key} line is missing.")
        return default
    try:
        values = [int(t) for t in header[key]]
    except ValueError:
        raise _fail(
            path,
            f"corrupt PCD header: {key} must be integers, got "
            f"{' '.join(header[key])[:60]!r}.",
        ) from None
    if any(v < 0 for v in values):
        raise _fail(path, f"corrupt PCD header: negative value in {key}.")
    return values


def _one_int(path, header, key, default=None):
    values = _ints(path, header, key, None if default is None else [default])
    if len(values) != 1:
        raise _fail(path, f"corrupt PCD header: {key} needs one value.")
    return values[0]


def _layout(path, header):
    """The fields as ``(name, dtype, count)``, checked, and the header facts."""
    names = header.get("FIELDS")
    if not names:
        raise _fail(path, "corrupt PCD header: the FIELDS line is missing or empty.")
    n_fields = len(names)
    sizes = _ints(path, header, "SIZE")
    types = [t.upper() for t in header.get("TYPE", [])]
    if "TYPE" not in header:
        raise _fail(path, "corrupt PCD header: the TYPE line is missing.")
    counts = _ints(path, header, "COUNT", [1] * n_fields)
    for key, values in (("SIZE", sizes), ("TYPE", types), ("COUNT", counts)):
        if len(values) != n_fields:
            raise _fail(
                path,
                f"corrupt PCD header: {n_fields} FIELDS but {len(values)} {key} "
                "values.",
            )
    layout = []
    seen = set()
    for name, size, kind, count in zip(names, sizes, types, counts, strict=True):
        if (
            kind not in ("I", "U", "F")
            or size not in (1, 2, 4, 8)
            or (kind == "F" and size not in (4, 8))
        ):
            raise _fail(
                path,
                f"unsupported PCD type for field {name!r}: TYPE {kind} SIZE {size} "
                "(supported: I and U of 1, 2, 4, 8 bytes, F of 4 or 8 bytes).",
            )
        if count < 1:
            raise _fail(path, f"corrupt PCD header: field {name!r} has COUNT 0.")
        if name != "_":
            if name in seen:
                raise _fail(path, f"corrupt PCD header: field {name!r} appears twice.")
            seen.add(name)
        code = {"I": "i", "U": "u", "F": "f"}[kind]
        layout.append((name, np.dtype(f"<{code}{size}"), count))
    renamed = coordinate_names(seen)
    if renamed:  # PDAL's X Y Z
        layout = [(renamed.get(name, name), dt, c) for name, dt, c in layout]
        seen = {renamed.get(name, name) for name in seen}
    missing = [c for c in "xyz" if c not in seen]
    if missing:
        raise _fail(
            path,
            f"the PCD file has no {', '.join(repr(c) for c in missing)} field "
            f"(FIELDS {' '.join(names)[:80]}).",
        )
    height = _one_int(path, header, "HEIGHT", 1)
    if "WIDTH" in header:
        width = _one_int(path, header, "WIDTH")
        n_points = _one_int(path, header, "POINTS", width * height)
        if n_points != width * height:
            raise _fail(
                path,
                f"corrupt PCD header: POINTS {n_points} differs from WIDTH x HEIGHT "
                f"= {width} x {height}.",
            )
    elif "POINTS" in header:
        n_points = _one_int(path, header, "POINTS")
        width, height = n_points, 1
    else:
        raise _fail(path, "corrupt PCD header: neither WIDTH nor POINTS is given.")
    viewpoint = header.get("VIEWPOINT", ["0", "0", "0", "1", "0", "0", "0"])
    try:
        viewpoint = tuple(float(v) for v in viewpoint)
    except ValueError:
        viewpoint = ()
    if len(viewpoint) != 7:
        raise _fail(path, "corrupt PCD header: VIEWPOINT needs 7 numbers.")
    encoding = header["DATA"][0].lower() if len(header["DATA"]) == 1 else ""
    if encoding not in _ENCODINGS:
        raise _fail(
            path,
            f"unsupported PCD DATA {' '.join(header['DATA'])[:40]!r}; expected ascii, "
            "binary or binary_compressed.",
        )
    info = {
        "version": " ".join(header.get("VERSION", [])) or None,
        "encoding": encoding,
        "width": width,
        "height": height,
        "viewpoint": viewpoint,
    }
    return layout, n_points, info


def _shape(values, count):
    return values if count == 1 else values.reshape(-1, count)


def _check_tail(path, body, expected, what):
    """Bytes after the data are refused, unless zeros: PCL pads its files so."""
    if len(body) > expected and np.frombuffer(body[expected:], np.uint8).any():
        raise _fail(
            path,
            f"{len(body) - expected} bytes of extra data after the declared "
            f"{expected} bytes ({what}).",
        )


def _read_binary(path, body, layout, n):
    record = sum(dt.itemsize * count for _, dt, count in layout)
    expected = n * record
    if len(body) < expected:
        raise _fail(
            path,
            f"expected {expected} bytes of point data ({n} points x {record} bytes), "
            f"found {len(body)}.",
        )
    _check_tail(path, body, expected, f"{n} points x {record} bytes")
    names, formats, offsets = [], [], []
    offset = 0
    for name, dt, count in layout:
        if name != "_":
            names.append(name)
            formats.append(dt if count == 1 else (dt, (count,)))
            offsets.append(offset)
        offset += dt.itemsize * count
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": record}
    )
    records = np.frombuffer(body, dtype=dtype, count=n)
    return {name: records[name].astype(records.dtype[name].base) for name in names}


def _read_compressed(path, body, layout, n):
    if len(body) < 8:
        raise _fail(
            path,
            f"expected 8 bytes of compressed and uncompressed sizes after the header, "
            f"found {len(body)}.",
        )
    compressed, uncompressed = (int(v) for v in np.frombuffer(body[:8], "<u4"))
    if len(body) - 8 < compressed:
        raise _fail(
            path,
            f"expected {compressed} bytes of compressed data, found {len(body) - 8} "
            "(truncated).",
        )
    _check_tail(path, body, 8 + compressed, f"8 + {compressed} compressed bytes")
    full = [n * dt.itemsize * count for _, dt, count in layout]
    if uncompressed == sum(full):
        kept = layout
    else:
        # Some writers leave the '_' padding out of the compressed columns.
        kept = [f for f in layout if f[0] != "_"]
        if uncompressed != n * sum(dt.itemsize * c for _, dt, c in kept):
            raise _fail(
                path,
                f"the compressed data holds {uncompressed} bytes once decompressed, "
                f"but {n} points of the declared fields need {sum(full)}.",
            )
    try:
        buffer = lzf_decompress_array(body[8 : 8 + compressed], uncompressed)
    except LZFError as exc:
        raise _fail(path, str(exc)) from None
    fields = {}
    offset = 0
    for name, dt, count in kept:
        size = n * dt.itemsize * count
        if name != "_":
            values = buffer[offset : offset + size].view(dt).copy()
            fields[name] = _shape(values, count)
        offset += size
    return fields


def _read_ascii(path, body, layout, n):
    # values apart by spaces, tabs or commas (PDAL reads all three)
    lines = [line.replace(",", " ") for line in data_lines(body)]
    if len(lines) != n:
        raise _fail(
            path,
            f"the header declares {n} points but the data has {len(lines)} lines.",
        )
    n_columns = sum(count for _, _, count in layout)
    values = float_rows(
        path, lines, n_columns, data="the ascii data", rows="the data lines"
    )
    fields = {}
    column = 0
    for name, dt, count in layout:
        columns = list(range(column, column + count))
        column += count
        if name == "_":
            continue
        if dt.kind in "iu" and dt.itemsize == 8 and n:
            # Beyond 2**53 float64 would round: parse these columns as integers.
            try:
                block = np.loadtxt(lines, dtype=dt, usecols=columns, ndmin=2)
            except (ValueError, OverflowError) as exc:
                raise _fail(path, f"cannot parse field {name!r}: {exc}") from None
        else:
            block = values[:, columns]
            if dt.kind in "iu":
                check_integral(path, block, dt, f"field {name!r}", f"its {dt} range")
            if not (dt.kind == "f" and name in ("x", "y", "z")):
                block = block.astype(dt)
            # else float64: the coordinate the text holds, not its rounding
        fields[name] = np.ascontiguousarray(block[:, 0] if count == 1 else block)
    return fields


def read(path):
    """Read a PCD cloud into ``(fields, info)``; see the module docstring.

    Parameters
    ----------
    path : path-like
        The ``.pcd`` file.

    Returns
    -------
    fields : dict of str to ndarray
        Every field but the ``_`` padding, in file order: ``(n,)`` arrays, or
        ``(n, count)`` for fields with a count above one.
    info : dict
        ``version``, ``encoding`` (the DATA type), ``width``, ``height`` and
        ``viewpoint`` (7 floats).

    Raises
    ------
    PointCloudFileError
        If the file is not a PCD file, its header is corrupt or uses an
        unsupported type, or the data does not hold exactly the declared
        points.
    """
    with open(path, "rb") as fh:
        # the first header line is checked on a prefix, then the file is
        # mapped, not read: a large file that is not a PCD file costs one
        # line; the map is closed when the last view goes
        _parse_first_line(path, fh.read(MAX_LINE_BYTES + 1))
        try:
            data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        except OSError as exc:
            raise _fail(path, f"cannot map the file: {exc.strerror}") from None
    header, start = _parse_header(path, data)
    layout, n, info = _layout(path, header)
    body = memoryview(data)[start:]
    if info["encoding"] == "binary":
        fields = _read_binary(path, body, layout, n)
    elif info["encoding"] == "binary_compressed":
        fields = _read_compressed(path, body, layout, n)
    else:
        fields = _read_ascii(path, bytes(body), layout, n)
    for name in _PACKED_COLOR:
        values = fields.get(name)
        if values is not None and values.dtype == np.uint32 and values.ndim == 1:
            fields[name] = values.view(np.float32)
    return fields, info


def _columns(fields):
    """``(name, values, TYPE, SIZE, COUNT)`` for each PCD field to write."""
    columns = coordinate_columns(fields) + field_columns(
        fields, {"normals": ("normal_x", "normal_y", "normal_z")}, split=False
    )
    out = []
    for name, values in distinct_columns(columns, "field"):
        if not name or any(ch.isspace() for ch in name) or name == "_":
            raise ValueError(f"{name!r} is not a valid PCD field name.")
        if values.dtype == np.bool_:
            values = values.astype(np.uint8)
        elif values.dtype == np.float16:
            values = values.astype(np.float32)
        kind = {"f": "F", "i": "I", "u": "U"}.get(values.dtype.kind)
        if kind is None or values.dtype.itemsize not in (1, 2, 4, 8):
            raise ValueError(
                f"field {name!r} has dtype {values.dtype}; PCD cannot store it."
            )
        values = values.astype(values.dtype.newbyteorder("<"), copy=False)
        count = 1 if values.ndim == 1 else values.shape[1]
        out.append((name, values, kind, values.dtype.itemsize, count))
    return out


def _header(columns, n, encoding):
    names = " ".join(c[0] for c in columns)
    return (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        f"FIELDS {names}\n"
        f"SIZE {' '.join(str(c[3]) for c in columns)}\n"
        f"TYPE {' '.join(c[2] for c in columns)}\n"
        f"COUNT {' '.join(str(c[4]) for c in columns)}\n"
        f"WIDTH {n}\n"
        "HEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {n}\n"
        f"DATA {encoding}\n"
    ).encode("ascii")


def _ascii_body(columns, n):
    formats, flat = [], []
    for name, values, kind, size, count in columns:
        block = values.reshape(n, count)
        # coordinates are read back as float64 (see the module docstring):
        # the digits of the float32 value itself, not only those that
        # round-trip through float32
        coordinate = name in ("x", "y", "z")
        fmt = float_format(8 if coordinate else size) if kind == "F" else "%d"
        for j in range(count):
            formats.append(fmt)
            flat.append(block[:, j])
    return ascii_rows(formats, flat)


def write(path, fields, *, encoding="binary"):
    """Write ``fields`` as a PCD cloud; see the module docstring.

    Parameters
    ----------
    path : path-like
        The destination ``.pcd`` file.
    fields : dict of str to ndarray
        ``x``, ``y``, ``z`` then extra fields of shape ``(n,)`` or ``(n, c)``.
    encoding : {"binary", "ascii", "binary_compressed"}, default="binary"
        The DATA type.

    Raises
    ------
    ValueError
        For an unknown encoding, a field name PCD cannot hold (empty, with
        spaces, or twice the same) or a non-numeric field.
    """
    if encoding not in _ENCODINGS:
        raise ValueError(
            f"PCD encoding must be 'ascii', 'binary' or 'binary_compressed', got "
            f"{encoding!r}"
        )
    n = len(fields["x"])
    columns = _columns(fields)
    if encoding == "ascii":
        # As PCL: packed colours as integers (their float may print as nan).
        columns = [
            (c[0], c[1].view(np.uint32), "U", 4, 1)
            if c[0] in _PACKED_COLOR and c[1].dtype == np.float32 and c[4] == 1
            else c
            for c in columns
        ]
    header = _header(columns, n, encoding)
    if encoding == "ascii":
        body = _ascii_body(columns, n)
    elif encoding == "binary":
        dtype = [
            (name, values.dtype, (count,)) if count > 1 else (name, values.dtype)
            for name, values, _, _, count in columns
        ]
        body = packed_records((c[:2] for c in columns), dtype, n)
    else:
        raw = b"".join(np.ascontiguousarray(c[1]).tobytes() for c in columns)
        packed = lzf_compress(raw)
        sizes = np.array([len(packed), len(raw)], dtype="<u4").tobytes()
        body = sizes + packed
    with open(path, "wb") as fh:
        fh.write(header)
        fh.write(body)
